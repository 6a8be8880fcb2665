"""An audit database from elsewhere (a ship's ``--db``, read ashore by ``dracc fleet``),
read defensively (issue 33).

A ship's database may be damaged, hand-edited or hostile: a table replaced by a view
over an endless recursive query used to hang the fleet at 100 % CPU, deaf to SIGTERM
and Ctrl-C; one over a large recursive query took 6.3 GB before a ``MemoryError``; a
text in a number column or a damaged JSON column was an internal error.  So:

- the file is opened read-only and *immutable* (``file:…?mode=ro&immutable=1``): SQLite
  takes no lock and creates no ``-shm``/``-wal`` beside it, so a read-only inbox works
  and nothing appears in it.  A database with a non-empty ``-wal`` beside it is being
  written (or was copied with its log): it is opened ``mode=ro`` instead, sharing the
  writer's locks, so that the nights committed in the log are read;
- nothing in it runs: ``query_only``, ``trusted_schema`` off (no function with side
  effects in a view or trigger), a value of at most 16 MiB (``SQLITE_LIMIT_LENGTH``),
  a file of at most 1 GiB;
- its schema is checked before any query on its data: ``meta``, ``nights`` and
  ``unit_stats`` are ordinary tables (a view, a virtual table or a generated column is
  refused) with every column of the schema version it states, each of its declared type
  (:func:`dracc.pipeline.state.schema_columns`); then every value is of its column's
  type (``typeof``): a text in a REAL column is refused;
- every statement is bounded in time: a progress handler aborts it once the read's
  budget (:data:`READ_BUDGET_S` for the whole database) is spent, and lets a signal
  through: SIGTERM or Ctrl-C during a query stops it and the run is interrupted.

Any of these makes the database one failed input (:class:`StateError`, its reason).
"""

from __future__ import annotations

import sqlite3
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from dracc.core.errors import StateError
from dracc.pipeline.state import SCHEMA_VERSION, NightRecord, StateStore, schema_columns

#: the largest database read (a night takes a few kB: a ship's 10 years, tens of MB)
MAX_DATABASE_BYTES = 1 << 30
#: the largest value of any column (a night's JSON columns take a few kB)
MAX_VALUE_BYTES = 16 << 20
#: the time a whole database may take to read (a ship's 10 years: well under a second)
READ_BUDGET_S = 10.0
#: the tables the fleet reads
TABLES = ("meta", "nights", "unit_stats")
#: virtual-machine steps between two looks at the clock (a fraction of a millisecond)
_STEPS = 10_000
#: SQLite's SQLITE_LIMIT_LENGTH (sqlite3.SQLITE_LIMIT_LENGTH from Python 3.11)
_LIMIT_LENGTH = 0
#: the storage classes (``typeof``) a declared type admits
_STORED = {"INTEGER": ("integer",), "REAL": ("real", "integer"), "TEXT": ("text",)}


class Budget:
    """The time a read may take: SQLite's progress handler, aborting the running
    statement once ``seconds`` have passed since the start."""

    def __init__(self, seconds: float) -> None:
        self.seconds = float(seconds)
        self.end = time.monotonic() + self.seconds
        self.spent = False

    def __call__(self) -> int:
        if time.monotonic() > self.end:
            self.spent = True
            return 1  # SQLite aborts the statement: "interrupted"
        return 0


def connect(path: Path, budget: Budget) -> sqlite3.Connection:
    """``path`` opened read-only (immutable unless a ``-wal`` beside it is in use), with
    the limits above and ``budget`` as its progress handler."""
    size = path.stat().st_size
    if size > MAX_DATABASE_BYTES:
        raise StateError(
            f"{path}: {size:,} bytes is not an audit database (at most "
            f"{MAX_DATABASE_BYTES:,}); not read"
        )
    wal = Path(f"{path}-wal")
    live = wal.is_file() and wal.stat().st_size > 0
    mode = "mode=ro" if live else "mode=ro&immutable=1"
    conn = sqlite3.connect(f"{path.resolve().as_uri()}?{mode}", uri=True, isolation_level=None)
    try:
        conn.set_progress_handler(budget, _STEPS)
        if hasattr(conn, "setlimit"):  # Python >= 3.11
            conn.setlimit(_LIMIT_LENGTH, MAX_VALUE_BYTES)
        conn.execute("PRAGMA query_only = ON")
        conn.execute("PRAGMA trusted_schema = OFF")
    except BaseException:
        conn.close()
        raise
    return conn


def _interrupted(err: sqlite3.OperationalError) -> bool:
    code = getattr(err, "sqlite_errorcode", None)  # Python >= 3.11
    return code == 9 if code is not None else str(err) == "interrupted"  # SQLITE_INTERRUPT


@contextmanager
def guarded(path: Path, budget: Budget) -> Iterator[None]:
    """SQLite's errors inside as :class:`StateError` naming ``path``; a statement the
    budget stopped says so; one a signal stopped is the interrupt (KeyboardInterrupt).

    A signal's handler runs in the progress handler, whose exception SQLite's module
    swallows after aborting the statement: "interrupted" with time left is that."""
    try:
        yield
    except sqlite3.OperationalError as err:
        if _interrupted(err) and not budget.spent:
            raise KeyboardInterrupt("signal during a database query") from None
        if _interrupted(err):
            raise StateError(
                f"{path}: reading the database took longer than {budget.seconds:g} s "
                "(a runaway query?); not read"
            ) from None
        raise StateError(f"{path}: not a readable audit database: {err}") from None
    except sqlite3.DatabaseError as err:
        raise StateError(f"{path}: not a readable audit database: {err}") from None
    except OSError as err:
        raise StateError(f"{path}: cannot read the audit database: {err}") from None


def check_schema(conn: sqlite3.Connection, path: Path) -> int:
    """The schema version of the database on ``conn``, once its tables, columns and
    values are as that version's (:class:`StateError` otherwise)."""
    kinds = dict(conn.execute("SELECT lower(name), type FROM sqlite_master").fetchall())
    sql = dict(conn.execute("SELECT lower(name), sql FROM sqlite_master WHERE type = 'table'"))
    if kinds.get("meta") != "table":
        raise StateError(f"{path}: not an audit database (no table meta)")
    _check_table(conn, path, "meta", sql, schema_columns(SCHEMA_VERSION)["meta"])
    row = conn.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone()
    version = str(row[0]) if row else None
    if version not in [str(v) for v in range(1, SCHEMA_VERSION + 1)]:
        raise StateError(f"{path}: audit database schema {version} is not 1 to {SCHEMA_VERSION}")
    expected = schema_columns(int(str(version)))
    for table in TABLES[1:]:
        if kinds.get(table) != "table":
            what = f"a {kinds[table]}" if table in kinds else "missing"
            raise StateError(f"{path}: {table} is {what}, not a table of the audit database")
        _check_table(conn, path, table, sql, expected[table])
    return int(str(version))


def _check_table(
    conn: sqlite3.Connection,
    path: Path,
    table: str,
    sql: dict,
    want: dict[str, tuple[str, bool]],
) -> None:
    """``table`` ordinary, with the columns ``want`` of their declared types, none
    generated; then every value of its column's type."""
    if str(sql.get(table) or "").lstrip().upper().startswith("CREATE VIRTUAL"):
        raise StateError(f"{path}: {table} is a virtual table, not a table of the audit database")
    have = {c[1]: c for c in conn.execute(f'PRAGMA table_xinfo("{table}")')}
    generated = [n for n, c in have.items() if c[6]]  # hidden 2 or 3: a generated column
    if generated:
        raise StateError(f"{path}: {table}.{generated[0]} is a generated column, not a stored one")
    for name, (decl, _) in want.items():
        if name not in have:
            raise StateError(f"{path}: {table} has no column {name}")
        if str(have[name][2]).upper() != decl:
            got = have[name][2] or "without a type"
            raise StateError(f"{path}: {table}.{name} is declared {got}, not {decl}")
    wrong = {  # a value of another storage class than the declared type admits
        name: f'typeof("{name}") NOT IN '
        f"({', '.join(repr(a) for a in _STORED[decl] + (() if not_null else ('null',)))})"
        for name, (decl, not_null) in want.items()
    }
    counts = conn.execute(
        f'SELECT {", ".join(f"SUM({w})" for w in wrong.values())} FROM "{table}"'
    ).fetchone()
    for (name, test), bad in zip(wrong.items(), counts, strict=True):
        if bad:
            (kind,) = conn.execute(
                f'SELECT typeof("{name}") FROM "{table}" WHERE {test}'
            ).fetchone()
            raise StateError(
                f"{path}: {table}.{name} holds {bad:,} value(s) of type {kind} where "
                f"{want[name][0]} is declared"
            )


def read_nights(path: str | Path, budget_s: float | None = None) -> list[NightRecord]:
    """Every night stored in the audit database ``path``, read as this module says
    (:class:`StateError` for a database that is not one, or is damaged or hostile), in
    ``budget_s`` (default :data:`READ_BUDGET_S`)."""
    path = Path(path)
    budget = Budget(READ_BUDGET_S if budget_s is None else budget_s)
    with guarded(path, budget):
        conn = connect(path, budget)
        try:
            conn.execute("BEGIN")  # one snapshot of a database being written (mode=ro)
            check_schema(conn, path)
            return StateStore.reading(path, conn).nights()
        finally:
            conn.close()
