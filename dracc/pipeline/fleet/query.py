"""The fleet query layer: SQL (DuckDB) over the Hive-partitioned tables of ``dracc fleet``.

``dracc fleet`` writes, beside fleet.parquet, trends.parquet and ranking.parquet, the same
rows as a Hive-partitioned dataset (:func:`dracc.report.fleet_tables.write_tables`)::

    DIR/tables/fleet/vessel=<v>/night=<YYYY-MM-DD>/part-0.parquet
    DIR/tables/trends/vessel=<v>/night=<YYYY-MM-DD>/part-0.parquet
    DIR/tables/ranking/vessel=<v>/part-0.parquet
    DIR/tables/findings/vessel=<v>/night=<YYYY-MM-DD>/part-0.parquet
    DIR/tables/integrity/vessel=<v>/night=<YYYY-MM-DD>/part-0.parquet

A partition value is escaped as Hive does (``FileUtils.escapePathName``: ``%``, ``/``,
``=``, control characters and a few more become ``%XX``; Unicode stays; Spark and DuckDB >= 1.1 decode
it); a missing value is ``__HIVE_DEFAULT_PARTITION__`` (read back as NULL).  ``night`` is
the fleet and trend tables' ``day`` column (the UTC night), the findings and integrity
tables' ``night``; timestamps are stored in microseconds with
time zone UTC (Parquet TIMESTAMP(isAdjustedToUTC, MICROS): DuckDB's TIMESTAMPTZ, Spark's
TIMESTAMP).  Each file keeps the table's column order in its key-value metadata
(:data:`COLUMNS_KEY`), so the views show the columns of fleet.parquet, in its order.

:func:`run_query` opens DuckDB in memory (nothing is written in DIR), makes the views
``fleet``, ``trends``, ``ranking``, ``findings`` and ``integrity`` (those whose files
exist) and returns the result.
"""

from __future__ import annotations

import json
import os
import warnings
from datetime import date
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow as pa

from dracc.core.errors import FleetError, OptionError

#: the folder of the partitioned dataset inside ``--out``
TABLES = "tables"
#: per table: its partitions, outermost first, as (key in the path, column of the table,
#: DuckDB type of the key)
PARTITIONS: dict[str, tuple[tuple[str, str, str], ...]] = {
    "fleet": (("vessel", "vessel", "VARCHAR"), ("night", "day", "DATE")),
    "trends": (("vessel", "vessel", "VARCHAR"), ("night", "day", "DATE")),
    "ranking": (("vessel", "vessel", "VARCHAR"),),
    "findings": (("vessel", "vessel", "VARCHAR"), ("night", "night", "DATE")),
    "integrity": (("vessel", "vessel", "VARCHAR"), ("night", "night", "DATE")),
}
#: the file name inside a partition
PART_FILE = "part-0.parquet"
#: key of the Parquet key-value metadata holding the table's columns in order (JSON list)
COLUMNS_KEY = b"dracc.columns"
#: Hive's partition value for NULL
HIVE_NULL = "__HIVE_DEFAULT_PARTITION__"
#: DuckDB decodes percent-escaped partition values from 1.1 on (duckdb/duckdb#12974)
MIN_DUCKDB = (1, 1)
_INSTALL = "pip install 'dracc[fleet]'"

#: the characters Hive escapes in a partition value (FileUtils.escapePathName, with the
#: ones it adds on Windows but the space)
_HIVE_ESCAPED = frozenset('"#%*/:=?\\{[]^<>|\x7f' + "'" + "".join(map(chr, range(1, 32))))


def hive_value(value: Any) -> str:
    """A partition value as it is written in a folder name ``key=<value>``: a date as
    ``YYYY-MM-DD``, NULL as ``__HIVE_DEFAULT_PARTITION__``, Hive's special characters as
    ``%XX`` (a name that *is* ``__HIVE_DEFAULT_PARTITION__`` gets its first ``_`` escaped,
    so that DuckDB does not read it as NULL)."""
    if value is None or (not isinstance(value, str) and pd.isna(value)):
        return HIVE_NULL
    text = value.isoformat() if isinstance(value, date) else str(value)
    text = "".join(f"%{ord(c):02X}" if c in _HIVE_ESCAPED else c for c in text)
    return "%5F" + text[1:] if text == HIVE_NULL else text


def _duckdb() -> Any:
    """The duckdb module (imported here: only ``dracc fleet query`` needs it)."""
    try:
        import duckdb
    except ImportError:
        raise FleetError(
            f"dracc fleet query needs DuckDB, which is not installed: {_INSTALL}"
        ) from None
    have = tuple(int(p) if p.isdigit() else 0 for p in duckdb.__version__.split(".")[:2])
    if have < MIN_DUCKDB:
        raise FleetError(
            f"dracc fleet query needs DuckDB 1.1 or later (installed: {duckdb.__version__}): "
            f"{_INSTALL}"
        )
    return duckdb


def table_files(out_dir: str | Path) -> dict[str, tuple[Path, list[Path]]]:
    """Each table's folder and Parquet files under ``out_dir/tables`` (tables without files
    left out), through the published set's real path: a ``dracc fleet`` publishing a new
    set meanwhile does not mix two runs in one query."""
    out = Path(out_dir)
    if not out.is_dir():
        raise FleetError(f"{out}: no such folder")
    if not (out / TABLES).is_dir():
        raise FleetError(
            f"{out} holds no fleet tables ({out / TABLES} is missing): write them with "
            f"'dracc fleet LOG… --out {out}'"
        )
    root = Path(os.path.realpath(out / TABLES))
    files = {}
    for name in PARTITIONS:
        found = sorted((root / name).rglob("*.parquet")) if (root / name).is_dir() else []
        if found:
            files[name] = (root / name, found)
    if not files:
        raise FleetError(f"the fleet tables in {out / TABLES} hold no rows")
    return files


def _literal(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"


def _ident(name: str) -> str:
    return '"' + name.replace('"', '""') + '"'


def _view_sql(con: Any, name: str, folder: Path, files: list[Path]) -> str:
    """``SELECT`` of the table ``name`` over its partitioned ``files``: the partition keys
    typed, ``night`` shown as the table's ``day``, the columns in the table's order."""
    import pyarrow.parquet as pq

    parts = files[0].relative_to(folder).parts[:-1]
    keys = [k for k, p in zip(PARTITIONS[name], parts, strict=False) if p.startswith(f"{k[0]}=")]
    pattern = str(folder / ("**/*.parquet" if keys else "*.parquet"))
    # a glob character in DIR itself (the partition names are escaped): list the files
    where = (
        "[" + ", ".join(_literal(str(f)) for f in files) + "]"
        if set(str(folder)) & set("*?[{")
        else _literal(pattern)
    )
    types = ", ".join(f"{_literal(k)}: {t}" for k, _, t in keys)
    source = (
        f"read_parquet({where}, hive_partitioning = {'true' if keys else 'false'}, "
        f"union_by_name = true{f', hive_types = {{{types}}}' if keys else ''})"
    )
    have = [r[0] for r in con.sql(f"DESCRIBE SELECT * FROM {source}").fetchall()]
    meta = pq.read_schema(files[0]).metadata or {}
    order = json.loads(meta[COLUMNS_KEY]) if COLUMNS_KEY in meta else have
    as_column = {key: column for key, column, _ in keys}
    shown = {as_column.get(c, c): c for c in have}  # column of the table -> in the files
    cols = [c for c in order if c in shown] + [c for c in shown if c not in order]
    select = ", ".join(
        _ident(shown[c]) + ("" if shown[c] == c else f" AS {_ident(c)}") for c in cols
    )
    return f"SELECT {select} FROM {source}"


def connect(out_dir: str | Path) -> tuple[Any, list[str]]:
    """An in-memory DuckDB connection (time zone UTC) with a view per table of
    ``out_dir/tables``; returns it and the views' names."""
    duckdb = _duckdb()
    files = table_files(out_dir)
    con = duckdb.connect(":memory:")
    try:
        con.execute("SET TimeZone = 'UTC'")
        for name, (folder, found) in files.items():
            view = _view_sql(con, name, folder, found)
            con.execute(f"CREATE VIEW {_ident(name)} AS {view}")
    except duckdb.Error as e:
        con.close()
        raise FleetError(
            f"the fleet tables in {Path(out_dir) / TABLES} cannot be read: {e}"
        ) from None
    return con, list(files)


def _plain(table: pa.Table) -> pd.DataFrame:
    """DuckDB's Arrow result as a DataFrame with the fleet tables' dtypes: text as
    ``string``, integers as ``Int64``, dates as pyarrow ``date32``, times in UTC; a
    DECIMAL (DuckDB's SUM of integers is HUGEINT) as an integer when it fits, else float."""
    for i, f in enumerate(table.schema):
        if pa.types.is_decimal(f.type):
            col = table.column(i)
            try:
                col = col.cast(pa.int64()) if f.type.scale == 0 else col.cast(pa.float64())
            except (pa.ArrowInvalid, OverflowError):
                col = col.cast(pa.float64(), safe=False)
            table = table.set_column(i, f.name, col)

    def mapper(t: pa.DataType) -> Any:
        if pa.types.is_string(t) or pa.types.is_large_string(t):
            return pd.StringDtype()
        if pa.types.is_integer(t):
            return pd.Int64Dtype()
        if pa.types.is_boolean(t):
            return pd.BooleanDtype()
        if pa.types.is_date(t):
            return pd.ArrowDtype(t)
        return None

    return table.to_pandas(types_mapper=mapper)


def run_query(out_dir: str | Path, sql: str) -> pd.DataFrame:
    """Run ``sql`` (DuckDB's dialect; several statements: the last one's rows) over the
    views ``fleet``, ``trends``, ``ranking``, ``findings`` and ``integrity`` of the fleet
    outputs in ``out_dir``.  A
    statement without rows gives an empty frame.  A bad query is an :class:`OptionError`
    with DuckDB's message; a folder without tables a :class:`FleetError`."""
    duckdb = _duckdb()
    con, views = connect(out_dir)
    try:
        rel = con.sql(sql)
        if rel is None:
            return pd.DataFrame()
        arrow = getattr(rel, "to_arrow_table", None) or rel.fetch_arrow_table
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            return _plain(arrow())
    except duckdb.Error as e:
        msg = str(e).strip()
        if isinstance(e, duckdb.CatalogException):
            msg += f"\n(the views in {out_dir}: {', '.join(views)})"
        raise OptionError(f"the query failed: {msg}") from None
    finally:
        con.close()
