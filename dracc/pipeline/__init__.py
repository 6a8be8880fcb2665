"""Orchestration: read the logs, run the methods, hand typed results to the reports.

- :mod:`.analysis` one voyage's logs → :class:`~dracc.pipeline.results.Analysis`
- :mod:`.audit`    a night's audit against the limits, with state between nights
- :mod:`.fleet`    many vessels' logs, on a local pool or a Dask cluster
- :mod:`.state`    the SQLite store that survives between nights
"""
