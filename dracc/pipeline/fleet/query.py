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

:func:`run_query` opens DuckDB in memory, makes the views ``fleet``, ``trends``,
``ranking``, ``findings`` and ``integrity`` (those whose files exist) over pyarrow
datasets of the files, and returns the result.  The query is untrusted text (issue 33: a
``COPY … TO`` replaced the published fleet.csv, ``read_text`` read private files): its
DuckDB has no file system, no network and no extensions, spills nothing to disk, and its
settings are locked (:data:`LOCKED`), so it reads the fleet's tables and writes nothing.
"""

from __future__ import annotations

import json
import os
import re
import threading
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
    set meanwhile does not mix two runs in one query.  A ``tables`` that leads out of
    ``out_dir``, or a file in it that is a link, is a FleetError: nothing outside is read."""
    out = Path(out_dir)
    if not out.is_dir():
        raise FleetError(f"{out}: no such folder")
    if not (out / TABLES).is_dir():
        raise FleetError(
            f"{out} holds no fleet tables ({out / TABLES} is missing): write them with "
            f"'dracc fleet LOG… --out {out}'"
        )
    root = Path(os.path.realpath(out / TABLES))
    if not root.is_relative_to(os.path.realpath(out)):  # a link planted in OUT: not read
        raise FleetError(f"{out / TABLES} leads out of {out} (to {root}); not read")
    files = {}
    for name in PARTITIONS:
        found = sorted((root / name).rglob("*.parquet")) if (root / name).is_dir() else []
        for f in found:  # rglob enters no linked folder; a linked file is no table's
            if f.is_symlink() or not f.is_file():
                raise FleetError(f"{f}: not a file dracc wrote (a link or no file); not read")
        if found:
            files[name] = (root / name, found)
    if not files:
        raise FleetError(f"the fleet tables in {out / TABLES} hold no rows")
    return files


def _ident(name: str) -> str:
    return '"' + name.replace('"', '""') + '"'


_ESCAPE = re.compile("%([0-9A-Fa-f]{2})")


def _partition(key: str, kind: str, part: str, where: Path) -> Any:
    """The value of the folder ``part`` (``key=<escaped value>``, :func:`hive_value`) as
    the column's type: NULL for ``__HIVE_DEFAULT_PARTITION__``, the text unescaped, a
    date parsed.  FleetError for a folder dracc does not write."""
    prefix = f"{key}="
    if not part.startswith(prefix):
        raise FleetError(f"{where}: not a fleet table's file ({part!r} is no {key}=… folder)")
    text = part[len(prefix) :]
    if text == HIVE_NULL:
        return None
    value = _ESCAPE.sub(lambda m: chr(int(m.group(1), 16)), text)
    if kind != "DATE":
        return value
    try:
        return date.fromisoformat(value)
    except ValueError:
        raise FleetError(f"{where}: {part!r} is no date") from None


def _dataset(name: str, folder: Path, files: list[Path]) -> tuple[Any, str]:
    """The Parquet files of the table ``name`` as one pyarrow dataset, each file with its
    partition keys' values (read from its folders, typed as :data:`PARTITIONS` says:
    ``vessel`` text, ``night`` a date, never guessed from the values); and the columns of
    the table in its order (:data:`COLUMNS_KEY`).  pyarrow reads the files, not DuckDB:
    the query's DuckDB has no file access at all (:func:`connect`)."""
    import pyarrow.dataset as ds
    import pyarrow.fs as pafs
    import pyarrow.parquet as pq

    depth = len(files[0].relative_to(folder).parts) - 1
    keys = PARTITIONS[name][:depth]
    arrow = {"VARCHAR": pa.string(), "DATE": pa.date32()}
    schema = pq.read_schema(files[0])
    order = (
        json.loads(schema.metadata[COLUMNS_KEY]) if COLUMNS_KEY in (schema.metadata or {}) else []
    )
    for key, _, kind in keys:
        schema = schema.append(pa.field(key, arrow[kind]))
    exprs = []
    for f in files:
        parts = f.relative_to(folder).parts[:-1]
        if len(parts) != len(keys):
            raise FleetError(f"{f}: not a fleet table's file (at the wrong depth)")
        expr = ds.scalar(True)
        for (key, _, kind), part in zip(keys, parts, strict=True):
            value = _partition(key, kind, part, f)
            field = ds.field(key)
            expr = expr & (
                field.is_null() if value is None else field == pa.scalar(value, arrow[kind])
            )
        exprs.append(expr)
    dataset = ds.FileSystemDataset.from_paths(
        [str(f) for f in files],
        schema=schema,
        format=ds.ParquetFileFormat(),
        filesystem=pafs.LocalFileSystem(),
        partitions=exprs,
    )
    as_column = {key: column for key, column, _ in keys}
    shown = {as_column.get(c, c): c for c in schema.names}  # column of the table -> in the files
    cols = [c for c in order if c in shown] + [c for c in shown if c not in order]
    select = ", ".join(
        _ident(shown[c]) + ("" if shown[c] == c else f" AS {_ident(c)}") for c in cols
    )
    return dataset, select


#: the settings that make the query's DuckDB a reader of the fleet's tables only: no file,
#: no network, no extension installed or loaded, nothing spilled to disk (a query that
#: needs more memory fails), and no SET that would give any of it back
#: (duckdb.org/docs/stable/operations_manual/securing_duckdb/overview)
LOCKED = {
    "enable_external_access": False,
    "autoinstall_known_extensions": False,
    "autoload_known_extensions": False,
    "allow_community_extensions": False,
    "temp_directory": "",
}
#: what a query may do, said when it tries more
ALLOWED = (
    "dracc fleet query only reads the views fleet, trends, ranking, findings and integrity: "
    "no files, ATTACH, COPY, EXPORT, INSTALL, LOAD or SET"
)
#: prefix of the DuckDB relation each view reads (a pyarrow dataset)
_SOURCE = "_dracc_"


def connect(out_dir: str | Path) -> tuple[Any, list[str]]:
    """An in-memory DuckDB connection (time zone UTC) with a view per table of
    ``out_dir/tables``, and no access to anything else (:data:`LOCKED`, then
    ``lock_configuration``); returns it and the views' names."""
    duckdb = _duckdb()
    files = table_files(out_dir)
    sources = {name: _dataset(name, folder, found) for name, (folder, found) in files.items()}
    con = duckdb.connect(":memory:", config=dict(LOCKED))
    try:
        con.execute("SET TimeZone = 'UTC'")
        for name, (dataset, select) in sources.items():
            con.register(_SOURCE + name, dataset)
            con.execute(f"CREATE VIEW {_ident(name)} AS SELECT {select} FROM {_SOURCE + name}")
        con.execute("SET lock_configuration = true")
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
    outputs in ``out_dir``, with nothing else in reach (:func:`connect`).  A
    statement without rows gives an empty frame.  A bad or refused query is an
    :class:`OptionError` of one line with DuckDB's message (a refused one says what is
    allowed, :data:`ALLOWED`); a folder without tables a :class:`FleetError`.  The query
    runs in a thread: an interrupt (Ctrl-C, SIGTERM) stops it at once
    (``interrupt()``) and is raised here."""
    duckdb = _duckdb()
    con, views = connect(out_dir)
    done: dict[str, Any] = {}

    def work() -> None:
        try:
            rel = con.sql(sql)
            if rel is None:
                done["frame"] = pd.DataFrame()
                return
            arrow = getattr(rel, "to_arrow_table", None) or rel.fetch_arrow_table
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", DeprecationWarning)
                done["frame"] = _plain(arrow())
        except BaseException as e:  # handed to the caller's thread, without this frame:
            done["error"] = e.with_traceback(None)  # its relation would keep ``con`` busy
        finally:
            finished.set()

    finished = threading.Event()
    worker = threading.Thread(target=work, name="dracc-fleet-query", daemon=True)
    try:
        worker.start()
        # short waits on an Event, not Thread.join: the main thread takes signals between
        # them, and an interrupted join can take a running thread for ended (Python 3.11)
        while not finished.wait(0.1):
            pass
    except BaseException:
        con.interrupt()
        while not finished.wait(0.1):  # an interrupt before the query started is lost
            con.interrupt()
        raise
    finally:
        if finished.is_set():
            con.close()
    e = done.get("error")
    if e is None:
        return done["frame"]
    if not isinstance(e, duckdb.Error):
        raise e
    raise OptionError(f"the query failed: {_one_line(duckdb, e, out_dir, views)}") from None


def _one_line(duckdb: Any, e: Exception, out_dir: str | Path, views: list[str]) -> str:
    """DuckDB's message on one line, with what the user can do: the views there (an unknown
    table), what is allowed (a refused statement), no disk to spill to (out of memory)."""
    msg = " ".join(str(e).split())
    if isinstance(e, duckdb.CatalogException):
        msg += f" (the views in {out_dir}: {', '.join(views)})"
    elif isinstance(e, duckdb.PermissionException) or "configuration has been locked" in msg:
        msg = f"{msg.split(' - ')[0]}: refused; {ALLOWED}"
    elif isinstance(e, duckdb.OutOfMemoryException):
        msg = (
            f"{msg.split('. ')[0]}: the query needs more memory than there is, and it "
            "spills nothing to disk; narrow it (WHERE, fewer columns)"
        )
    return msg
