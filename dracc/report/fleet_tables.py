"""The fleet's outputs: fleet, trend, ranking, findings and integrity tables (Parquet and
CSV), the same as a Hive-partitioned dataset under ``tables/`` (the layout of
:mod:`dracc.pipeline.fleet.query`), per vessel CSVs and ``fleet.json``, published together
so that a reader never sees a mix of two runs; and the forms of a ``dracc fleet query``
result (table, CSV, JSON lines).  The tables themselves are computed in
:mod:`dracc.pipeline.fleet.tables` and :mod:`dracc.pipeline.fleet.findings`."""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from dracc import __version__
from dracc.core import atomic
from dracc.core.errors import FleetError
from dracc.core.numbers import jsonable
from dracc.core.safetext import printable
from dracc.core.timefmt import iso_utc
from dracc.pipeline.fleet.query import COLUMNS_KEY, PART_FILE, PARTITIONS, TABLES, hive_value
from dracc.pipeline.fleet.tables import FleetResult
from dracc.pipeline.fleet.tasks import inside
from dracc.report.output import json_text
from dracc.report.tables import csv_ready
from dracc.report.textout import Layout, table

#: test hook: seconds to sleep half-way through writing the outputs (interruption tests)
TEST_SLEEP_ENV = "DRACC_FLEET_TEST_SLEEP_S"


def csv_text(df: pd.DataFrame) -> str:
    """``df`` as CSV for a spreadsheet (:func:`dracc.report.tables.csv_ready`): times as
    ISO 8601 UTC with ``Z``, dates ``YYYY-MM-DD``, and a text cell starting with ``=``,
    ``+``, ``-``, ``@``, a tab or a CR (a vessel or file name, an error message) with a
    leading single quote, so that no cell is read as a formula; every control character
    of a text (ESC, a line break, bidi controls) escaped as on the terminal
    (:func:`dracc.core.safetext.printable`: ``\x1b``), so that a ship's name reaches
    no terminal, ``grep`` or line-based reader raw (issue 33).  Numbers are left alone
    (-0.5 stays a number); Parquet keeps the raw text and the typed columns."""
    return csv_ready(_printable_texts(df)).to_csv(index=False)


def _printable_texts(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with the text cells that hold a control character escaped (each distinct
    value once: the names repeat on every row)."""
    out = df
    for col in df.columns:
        c = df[col]
        if not (pd.api.types.is_string_dtype(c) or c.dtype == object):
            continue
        raw = [v for v in pd.unique(c.dropna()) if isinstance(v, str) and not v.isprintable()]
        if raw:
            out = out.copy() if out is df else out
            out[col] = c.replace({v: printable(v) for v in raw})
    return out


#: the longest file name most file systems take (bytes)
_NAME_MAX = 255


def hive_parts(name: str, df: pd.DataFrame) -> Iterator[tuple[Path, pa.Table]]:
    """``df`` split into the Hive partitions of ``tables/<name>/``
    (:data:`dracc.pipeline.fleet.query.PARTITIONS`): the partition columns in the folder
    names only, timestamps in microseconds UTC (DuckDB's TIMESTAMPTZ, Spark's TIMESTAMP),
    the table's column order in the metadata.  An empty table has no partition."""
    if len(df) == 0:
        return
    keys = [(key, col) for key, col, _ in PARTITIONS[name] if col in df.columns]
    data = pa.Table.from_pandas(
        df.drop(columns=[c for _, c in keys]).reset_index(drop=True), preserve_index=False
    )
    for i, f in enumerate(data.schema):
        if pa.types.is_timestamp(f.type) and f.type.unit == "ns":
            us = pa.timestamp("us", tz=f.type.tz)
            data = data.set_column(i, f.name, data.column(i).cast(us, safe=False))
    meta = {**(data.schema.metadata or {}), COLUMNS_KEY: json.dumps(list(map(str, df.columns)))}
    data = data.replace_schema_metadata(meta)
    folders = pd.Series([""] * len(df), dtype=object)
    for key, col in keys:
        values = df[col].astype(object).reset_index(drop=True)
        names = {v: f"{key}={hive_value(v)}" for v in pd.unique(values)}
        for part in set(names.values()):
            if len(part.encode("utf-8")) > _NAME_MAX:
                raise FleetError(
                    f"{name}: the partition folder {part[:60]}… would be longer than "
                    f"{_NAME_MAX} bytes; shorten the vessel folder's name"
                )
        folders = folders + "/" + values.map(names)
    for folder, rows in folders.groupby(folders, sort=True).indices.items():
        yield Path(TABLES, name, *folder.strip("/").split("/"), PART_FILE), data.take(rows)


def write_tables(
    result: FleetResult,
    out: Path,
    extra: Mapping[str, str] | None = None,
    published: list | None = None,
) -> list[Path]:
    """fleet, trends, ranking, findings and integrity .parquet/.csv, the same tables
    Hive-partitioned under ``tables/`` (:func:`hive_parts`), failures in fleet.json, per
    vessel ``vessels/<safe name>/fleet.csv``, ``trends.csv`` and ``findings.csv``, and the ``extra`` files
    (name -> text, e.g. ``fleet.html``), published together (:func:`dracc.core.atomic.file_set`):
    a reader, an interrupt or a kill at any moment finds the previous complete set in
    ``out`` or the new complete set, never a mix (``published``: see
    :func:`~dracc.core.atomic.file_set`).  Returns the paths of the outputs."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rels: list[Path] = []
    sleep_s = os.environ.get(TEST_SLEEP_ENV)
    with atomic.file_set(out, published) as stage:

        def put(rel: Path, data: str | pd.DataFrame | pa.Table) -> None:
            # a partition folder is key=<escaped value> (hive_parts): its own safe name
            path = stage.resolve().joinpath(*rel.parts) if rel.parts[0] == TABLES else None
            path = path or inside(stage, *rel.parts)
            path.parent.mkdir(parents=True, exist_ok=True)
            if isinstance(data, str):
                path.write_text(data, encoding="utf-8")
            elif isinstance(data, pa.Table):
                pq.write_table(data, path)
            elif path.suffix == ".parquet":
                data.to_parquet(path, index=False)
            else:
                path.write_text(csv_text(data), encoding="utf-8")
            rels.append(path.relative_to(stage.resolve()))

        tables = (
            ("fleet", result.table),
            ("trends", result.trends),
            ("ranking", result.ranking),
            ("findings", result.findings),
            ("integrity", result.integrity),
        )
        for name, df in tables:
            put(Path(f"{name}.parquet"), df)
            put(Path(f"{name}.csv"), df)
        for name, df in tables:  # the same rows, Hive-partitioned (dracc fleet query)
            for rel, part in hive_parts(name, df):
                put(rel, part)
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
            if len(result.findings):
                put(
                    Path("vessels", vessel, "findings.csv"),
                    result.findings[result.findings["vessel"] == vessel],
                )
        summary = {
            "schema": "dracc.fleet/2",
            "dracc_version": __version__,
            # analysed + cached + documents + failed = logs; skipped files are no logs
            "logs": result.logs,
            "vessels": sorted(result.table["vessel"].dropna().unique().tolist()),
            "analysed": result.analysed,
            "cached": result.cached,
            "documents": result.documents,
            "failed": len(result.failures),
            "skipped": len(result.skipped),
            "duplicates": len(result.duplicates),
            "failures": list(result.failures),
            "skipped_files": list(result.skipped),
            "duplicate_inputs": list(result.duplicates),
        }
        put(Path("fleet.json"), json.dumps(summary, indent=1, ensure_ascii=False) + "\n")
        for name, text in (extra or {}).items():
            put(Path(name), text)
    root = out.resolve()
    return [root / r for r in rels]


def counts_text(res: FleetResult) -> str:
    """'fleet: 52 logs: 50 analysed, 0 from the cache, 2 failed; 1 file skipped (not a
    log); 1 night given twice left out': the terms add up to the logs; the skipped files
    and the nights given twice (:func:`~dracc.pipeline.fleet.tables.drop_duplicate_nights`)
    are apart."""
    docs = f"{res.documents} from audit documents, " if res.documents else ""
    skipped = (
        f"; {len(res.skipped)} file{'s' if len(res.skipped) != 1 else ''} skipped (not a log)"
        if res.skipped
        else ""
    )
    n = len(res.duplicates)
    twice = f"; {n} night{'s' if n != 1 else ''} given twice left out" if n else ""
    return (
        f"fleet: {res.logs} log{'s' if res.logs != 1 else ''}: {res.analysed} analysed, "
        f"{res.cached} from the cache, {docs}{len(res.failures)} failed{skipped}{twice}"
    )


def input_lines(res: FleetResult) -> list[str]:
    """What stderr says of the inputs after the table: one line per file skipped (no log),
    per night given twice and left out, and per log or document that failed, each a single
    line (a line break or ESC in a ship's name escaped, :func:`dracc.core.safetext.printable`)."""
    said = [f"skipped: {f['vessel']}/{f['log']} — not a log: {f['why']}" for f in res.skipped]
    said += [f"left out: {f['vessel']}/{f['log']} — {f['why']}" for f in res.duplicates]
    said += [f"failed: {f['vessel']}/{f['log']}: {f['error']}" for f in res.failures]
    return [printable(line) for line in said]


# ------------------------------------------------------------- dracc fleet query results


def _time_text(t: pd.Timestamp) -> str:
    """ISO 8601 with the fewest fractional digits that write ``t`` exactly; UTC with ``Z``
    for a time with a zone, as it is for a time without one."""
    if t.tz is None:
        return t.isoformat()
    ns = t.tz_convert("UTC").value
    steps = (("s", 10**9), ("ms", 10**6), ("us", 10**3))
    return iso_utc(ns, next((u for u, step in steps if ns % step == 0), "ns"))


def _cell(value: Any) -> Any:
    """A result cell in JSON types: NULL and NaN as None, a timestamp as ISO 8601
    (:func:`_time_text`), a date as ``YYYY-MM-DD``, a list as a list
    (:func:`dracc.core.numbers.jsonable`)."""
    if isinstance(value, pd.Timestamp):
        return None if pd.isna(value) else _time_text(value)
    if isinstance(value, np.ndarray):
        return jsonable([_cell(v) for v in value.tolist()])
    if isinstance(value, (list, tuple, dict)):
        return jsonable(value)
    if pd.isna(value):
        return None
    return jsonable(value.item() if isinstance(value, np.generic) else value)


def json_lines(df: pd.DataFrame, ascii_only: bool = False) -> str:
    """A query result as JSON lines: one object per row, column -> value (:func:`_cell`)."""
    cols = list(map(str, df.columns))
    return "".join(
        json_text(dict(zip(cols, map(_cell, row), strict=True)), None, ascii_only)
        for row in df.itertuples(index=False, name=None)
    )


def result_text(df: pd.DataFrame, lay: Layout) -> str:
    """A query result as a plain table laid out for ``lay`` (:func:`dracc.report.textout.table`):
    numbers right-aligned (floats to 6 significant digits), NULL shown as ``NULL``; on a
    narrow terminal the last columns are left out first.  Ends with the row count."""
    right = [
        pd.api.types.is_numeric_dtype(df[c]) and not pd.api.types.is_bool_dtype(df[c])
        for c in df.columns
    ]

    def text(v: Any) -> str:
        v = _cell(v)
        if v is None:
            return "NULL"
        if isinstance(v, float):
            return f"{v:.6g}"
        # one line per row: a line break in a name is escaped like any control character
        return printable(v if isinstance(v, str) else json.dumps(v, ensure_ascii=False))

    rows = [[text(v) for v in row] for row in df.itertuples(index=False, name=None)]
    n = len(rows)
    count = f"({n} row{'' if n == 1 else 's'})"
    if not len(df.columns):
        return count + "\n"
    grid = table(
        list(map(str, df.columns)), rows, right=right, priorities=range(len(right)), lay=lay
    )
    return f"{grid}\n{count}\n"
