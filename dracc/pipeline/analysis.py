"""``analyse``: the library API behind ``dracc analyze``.

One call reads the logs, runs dead reckoning, calibration, the current estimate and
the INS deviation statistics, and returns one frozen :class:`Analysis` holding
everything the reports show.  Everything is computed here, once; the renderers in
:mod:`dracc.report` only format what they are given.

This module only orchestrates; the work is in

- :mod:`.results`            the typed results (:class:`Analysis` and its sections)
- :mod:`.overview`           what the ingest saw: files, sources, time base, tracks
- :mod:`.clock_stage`        each source's clock, learned and applied first
- :mod:`.selection`          which sensors feed the DR; true heading; the DR grid
- :mod:`.faults_stage`       sensor faults
- :mod:`.dr_stage`           dead reckoning and its consistency (:mod:`.dr_model`, :mod:`.notes`)
- :mod:`.current_stage`      set and drift
- :mod:`.calibration_stage`  compass error, log scale and offset (learned or least squares)
- :mod:`.deviation_stage`    INS deviation statistics

What a log lacks (no INS triple, no heading, no speed log, no reference) is not an
error: the section concerned is ``None``, and :attr:`Analysis.missing` says why in a
sentence a navigator reads.  Only a log with nothing usable at all raises
:class:`~dracc.core.errors.InsufficientDataError`.

Units follow the package conventions: radians, metres, seconds and int64 UTC
nanoseconds inside.  The deviation samples and statistics keep the units of the
paper's channels: metres north/east for latitude/longitude, degrees for course
(``CHANNEL_UNITS``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from dracc import __version__
from dracc.core.config import Config
from dracc.frames import Voyage
from dracc.math.integrity import check_night, dr_innovation_check, with_dr_check
from dracc.math.integrity.causes import jump_spans
from dracc.pipeline import overview, selection
from dracc.pipeline.calibration_stage import calibration as calibration_section
from dracc.pipeline.calibration_stage import log_measures_transverse
from dracc.pipeline.clock_stage import learn_clocks
from dracc.pipeline.current_stage import current as current_section
from dracc.pipeline.current_stage import estimated_position
from dracc.pipeline.deviation_stage import deviation as deviation_section
from dracc.pipeline.dr_stage import dead_reckoning
from dracc.pipeline.faults_stage import sensor_faults
from dracc.pipeline.results import SCHEMA, Analysis, EPOptions

__all__ = ["analyse", "analyse_voyage"]

#: ``progress(stage, fraction)``: called with a stage name and 0..1 while work goes on
Progress = Callable[[str, float], None]


def _noop(stage: str, fraction: float) -> None:
    return None


def analyse(
    paths: Sequence[str | Path],
    cfg: Config | None = None,
    progress: Progress | None = None,
    total_bytes: int | None = None,
    ep: EPOptions | None = None,
) -> Analysis:
    """Read the logs ``paths`` (several files of one voyage merge by time) and analyse them.

    ``cfg`` defaults to :class:`~dracc.core.config.Config` (); ``progress(stage, fraction)``
    is called as the work goes on (reading as a fraction of ``total_bytes``, by default
    the size of the files).  Raises :class:`~dracc.core.errors.IngestError` for unreadable
    input and :class:`~dracc.core.errors.InsufficientDataError` when the logs hold no
    record at all; everything else that is missing is reported in :attr:`Analysis.missing`.
    """
    from dracc.ingest import read_logs  # the readers are heavy; import on use

    cfg = cfg or Config()
    report = progress or _noop
    if total_bytes is None:
        total_bytes = sum(Path(p).stat().st_size for p in paths if Path(p).is_file())
    report("reading logs", 0.0)
    read = {"n": 0}

    def on_bytes(n: int) -> None:
        read["n"] += n
        if total_bytes:
            report("reading logs", read["n"] / total_bytes)

    voyage = read_logs([Path(p) for p in paths], cfg.ingest, progress=on_bytes)
    report("reading logs", 1.0)
    return analyse_voyage(voyage, cfg, report, ep)


def analyse_voyage(
    voyage: Voyage,
    cfg: Config | None = None,
    progress: Progress | None = None,
    ep: EPOptions | None = None,
) -> Analysis:
    """Analyse an ingested :class:`~dracc.frames.Voyage` (see :func:`analyse`; ``ep``: the
    observation file's updates and the fix-interval study of the estimated position)."""
    cfg = cfg or Config()
    report = progress or _noop
    missing: list[str] = []

    inputs = overview.input_files(voyage)
    voyage, clocks = learn_clocks(voyage, cfg)
    sources = overview.source_rows(voyage, clocks)
    start_ns, end_ns = overview.time_span(voyage, inputs, sources)
    time = overview.time_summary(voyage)
    notes = overview.voyage_notes(voyage, inputs, sources)
    voyage = selection.without_rapid_positions(voyage, notes)
    tracks = overview.tracks(voyage)
    headings = overview.heading_tracks(voyage)

    report("integrity checks", 0.0)
    integrity = check_night(voyage, cfg.integrity, cfg.faults)
    if integrity is not None:  # the witnesses' evidence (failures are in the integrity list)
        notes.extend(
            c.message
            for c in integrity.checks
            if c.name.endswith("_witness") and c.status == "pass"
        )
    report("integrity checks", 1.0)
    report("sensor faults", 0.0)
    faults, voyage = sensor_faults(voyage, cfg, notes)
    report("sensor faults", 1.0)

    report("dead reckoning", 0.0)
    dr, fixes, dr_inputs = dead_reckoning(
        voyage, cfg.dead_reckoning, missing, notes, jump_spans(integrity)
    )
    report("dead reckoning", 1.0)
    if integrity is not None and dr is not None and dr.fix_innovations is not None:
        integrity = with_dr_check(
            integrity,
            dr_innovation_check(
                dr.fix_source_key, dr.reference_role, *dr.fix_innovations, cfg.integrity
            ),
        )

    report("current", 0.0)
    current = est = None
    if dr is not None and dr_inputs is not None and fixes is not None:
        current = current_section(dr_inputs, fixes, cfg.dead_reckoning, missing)
        ep = ep or EPOptions()
        est = estimated_position(
            dr_inputs, fixes, cfg.dead_reckoning, ep.observations, ep.intervals_s, missing
        )
    report("current", 1.0)

    report("deviation statistics", 0.0)
    deviation, dev_ref = deviation_section(voyage, cfg, missing)
    report("deviation statistics", 1.0)

    report("calibration", 0.0)
    calibration = None
    if dr_inputs is not None and fixes is not None:
        calibration = calibration_section(
            dr_inputs, fixes, missing, log_measures_transverse(voyage)
        )
    report("calibration", 1.0)

    return Analysis(
        schema=SCHEMA,
        dracc_version=__version__,
        inputs=inputs,
        sources=sources,
        rejected={str(k): int(v) for k, v in voyage.rejects.counts.items()},
        reject_examples={str(k): tuple(v) for k, v in voyage.rejects.examples.items()},
        time=time,
        start_ns=start_ns,
        end_ns=end_ns,
        lines=int(voyage.lines),
        tracks=tracks,
        deviation=deviation,
        dead_reckoning=dr,
        calibration=calibration,
        current=current,
        deviation_reference=dev_ref,
        missing=tuple(missing),
        notes=tuple(notes),
        settings=_settings(cfg),
        faults=faults,
        ignored={str(k): int(v) for k, v in getattr(voyage, "ignored", {}).items()},
        integrity=integrity,
        headings=headings,
        estimated_position=est,
    )


def _settings(cfg: Config) -> dict[str, object]:
    """The options that shaped the result, for the report header."""
    return {
        "interval_s": cfg.deviation.interval_s,
        "window_s": cfg.deviation.window_s,
        "probability": cfg.deviation.probability,
        "reset": cfg.dead_reckoning.reset,
        "fix_role": cfg.dead_reckoning.fix_role,
        "epoch_interval_s": cfg.dead_reckoning.epoch_interval_s,
        "max_gap_s": cfg.dead_reckoning.max_gap_s,
        "variation_deg": cfg.dead_reckoning.variation_deg,
        "roles": dict(cfg.ingest.sources),
        "strict": cfg.ingest.strict,
        "ignore_checksum": cfg.ingest.ignore_checksum,
        "date": cfg.ingest.date,
        "faults_exclude": cfg.faults.exclude,
    }
