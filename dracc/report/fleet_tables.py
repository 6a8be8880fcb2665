"""The fleet's outputs: fleet and trend tables (Parquet and CSV), per vessel CSVs and
``fleet.json``, published together so that a reader never sees a mix of two runs.
The tables themselves are computed in :mod:`dracc.pipeline.fleet.tables`."""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Mapping
from pathlib import Path

import pandas as pd

from dracc import __version__
from dracc.core import atomic
from dracc.pipeline.fleet.tables import FleetResult, count_logs
from dracc.pipeline.fleet.tasks import inside
from dracc.report.tables import csv_ready

#: test hook: seconds to sleep half-way through writing the outputs (interruption tests)
TEST_SLEEP_ENV = "DRACC_FLEET_TEST_SLEEP_S"


def csv_text(df: pd.DataFrame) -> str:
    """``df`` as CSV for a spreadsheet (:func:`dracc.report.tables.csv_ready`): times as
    ISO 8601 UTC with ``Z``, dates ``YYYY-MM-DD``, and a text cell starting with ``=``,
    ``+``, ``-``, ``@``, a tab or a CR (a vessel or file name, an error message) with a
    leading single quote, so that no cell is read as a formula.  Numbers are left alone
    (-0.5 stays a number); Parquet keeps the raw text and the typed columns."""
    return csv_ready(df).to_csv(index=False)


def write_tables(
    result: FleetResult,
    out: Path,
    extra: Mapping[str, str] | None = None,
    published: list | None = None,
) -> list[Path]:
    """fleet.parquet/.csv, trends.parquet/.csv, failures in fleet.json, per vessel
    ``vessels/<safe name>/fleet.csv`` and ``trends.csv``, and the ``extra`` files
    (name -> text, e.g. ``fleet.html``), published together (:func:`dracc.core.atomic.file_set`):
    a reader, an interrupt or a kill at any moment finds the previous complete set in
    ``out`` or the new complete set, never a mix (``published``: see
    :func:`~dracc.core.atomic.file_set`).  Returns the paths of the outputs."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rels: list[Path] = []
    sleep_s = os.environ.get(TEST_SLEEP_ENV)
    with atomic.file_set(out, published) as stage:

        def put(rel: Path, data: str | pd.DataFrame) -> None:
            path = inside(stage, *rel.parts)
            path.parent.mkdir(parents=True, exist_ok=True)
            if isinstance(data, str):
                path.write_text(data, encoding="utf-8")
            elif path.suffix == ".parquet":
                data.to_parquet(path, index=False)
            else:
                path.write_text(csv_text(data), encoding="utf-8")
            rels.append(path.relative_to(stage.resolve()))

        for name, df in (("fleet", result.table), ("trends", result.trends)):
            put(Path(f"{name}.parquet"), df)
            put(Path(f"{name}.csv"), df)
        if sleep_s:  # test hook: a run interrupted here must leave the old set whole
            print(
                f"dracc fleet: test hook: sleeping {sleep_s} s while writing the outputs",
                file=sys.stderr,
                flush=True,
            )
            time.sleep(float(sleep_s))
        for vessel in sorted(result.table["vessel"].dropna().unique()):
            put(
                Path("vessels", vessel, "fleet.csv"), result.table[result.table["vessel"] == vessel]
            )
            put(
                Path("vessels", vessel, "trends.csv"),
                result.trends[result.trends["vessel"] == vessel],
            )
        summary = {
            "schema": "dracc.fleet/1",
            "dracc_version": __version__,
            "logs": count_logs(result.table),
            "vessels": sorted(result.table["vessel"].dropna().unique().tolist()),
            "analysed": result.analysed,
            "cached": result.cached,
            "failures": list(result.failures),
        }
        put(Path("fleet.json"), json.dumps(summary, indent=1, ensure_ascii=False) + "\n")
        for name, text in (extra or {}).items():
            put(Path(name), text)
    root = out.resolve()
    return [root / r for r in rels]
