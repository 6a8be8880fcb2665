"""Batch fleet reports: many vessels' logs analysed in parallel, resumable.

The modules, in reading order:

``tasks``   the ``[fleet]`` settings, safe output names, :func:`discover` (one task per log)
``batch``   :func:`run_fleet`: analyse every log on a local pool or on Dask, with a cache
``tables``  the fleet table, the a priori rule per vessel, the per-day trends, publication
``findings`` each night's findings and integrity counts (raw logs, audit documents alike)
``query``   the Hive-partitioned layout of ``--out/tables`` and :func:`run_query` (DuckDB SQL)

The names below are the package's API, importable from ``dracc.pipeline.fleet``.
"""

from __future__ import annotations

from dracc.core.errors import FleetError
from dracc.core.vocabulary import CHANNELS
from dracc.pipeline.fleet.batch import CACHE_SCHEMA, analyse_log, cache_path, run_fleet, summarise
from dracc.pipeline.fleet.query import run_query
from dracc.pipeline.fleet.tables import (
    TABLE_COLUMNS,
    TREND_COLUMNS,
    FleetResult,
    count_logs,
    fleet_table,
    fleet_trends,
)
from dracc.pipeline.fleet.tasks import (
    FleetConfig,
    LogTask,
    check_scheduler,
    discover,
    fleet_config,
    inside,
    safe_name,
)

__all__ = [
    "CACHE_SCHEMA",
    "CHANNELS",
    "TABLE_COLUMNS",
    "TREND_COLUMNS",
    "FleetConfig",
    "FleetError",
    "FleetResult",
    "LogTask",
    "analyse_log",
    "cache_path",
    "check_scheduler",
    "count_logs",
    "discover",
    "fleet_config",
    "fleet_table",
    "fleet_trends",
    "inside",
    "run_fleet",
    "run_query",
    "safe_name",
    "summarise",
]
