"""The audit's state between nights: one SQLite file per ship (or shared by several).

What is kept
------------
``nights``
    One row per vessel and night (``UNIQUE(vessel, night)``), with the SHA-256 of the
    night's log content and of the analysis settings, the period, the DR consistency
    (containment and the analysis' verdict), the calibration, the rejected-line rate,
    the sources and the findings.
``unit_stats``
    Per night, unit (``ins1``..``ins3``) and channel (``lat``, ``lon``, ``course``):
    ``n``, ``m_u``, ``m_y``, kurtosis and limiting error in the channel's unit
    (``measure``: ``m`` for latitude/longitude, ``deg`` for course), the a priori RMS
    before and after the night and the verdict of the monitoring rule.
``apriori``
    The history of the a priori RMS per vessel, unit and channel: every night on which
    the value was established or raised, with the previous value and the evidence.

Concurrency and crashes
-----------------------
The database runs in WAL mode with a busy timeout; every change is one
``BEGIN IMMEDIATE`` transaction (:meth:`StateStore.transaction`), so two audits on one
file queue up instead of failing, readers never block the writer, and a process killed
half-way leaves the previous state intact (SQLite rolls the open transaction back).
Creating a new file is as safe: the busy timeout is set first, the switch to WAL (which
SQLite may refuse at once, without waiting, while another process switches the same new
file) is retried with a randomised back-off up to the busy timeout, and the tables are
created inside one ``BEGIN IMMEDIATE`` transaction.

Schema versions
---------------
1. the first release.
2. ``nights`` gained ``dr_verdict`` (the verdict word), ``dr_verdict_text`` (the
   sentence), ``dr_consistent`` (1/0/NULL) and ``dr_nees``.  A version-1 file is migrated
   in place when opened (the columns are added, NULL for the nights already stored), in
   the same ``BEGIN IMMEDIATE`` transaction as the check, so two audits opening an old
   file at once migrate it once.
3. ``nights`` gained ``measures_json``: the night's measures for the fleet ranking
   (:mod:`dracc.pipeline.audit.measures`), NULL for nights stored before.  Migrated in
   place the same way (from 1 or 2).

This module stores and reads; the rules (what the a priori becomes, what is a finding)
live in :mod:`dracc.pipeline.audit`.
"""

from __future__ import annotations

import json
import random
import sqlite3
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from dracc.core import jsonbound
from dracc.core.errors import ConfigError, StateError

SCHEMA_VERSION = 3

#: columns added to ``nights`` after version 1: (name, SQL type), in order
_NIGHT_COLUMNS_V2 = (
    ("dr_verdict", "TEXT"),
    ("dr_verdict_text", "TEXT"),
    ("dr_consistent", "INTEGER"),
    ("dr_nees", "REAL"),
)

#: channels in the paper's order (latitude, longitude, course), for ORDER BY
_CHANNEL_ORDER = "CASE channel WHEN 'lat' THEN 0 WHEN 'lon' THEN 1 WHEN 'course' THEN 2 ELSE 3 END"

#: the unit of the statistics of each channel
CHANNEL_MEASURE = {"lat": "m", "lon": "m", "course": "deg"}

_DDL = """
CREATE TABLE IF NOT EXISTS meta (
    key   TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS nights (
    id                INTEGER PRIMARY KEY,
    vessel            TEXT NOT NULL,
    night             TEXT NOT NULL,           -- YYYY-MM-DD (UTC)
    content_sha256    TEXT NOT NULL,           -- the night's log bytes
    settings_sha256   TEXT NOT NULL,           -- the analysis settings
    audited_utc       TEXT NOT NULL,
    period_start_utc  TEXT,
    period_end_utc    TEXT,
    inputs_json       TEXT NOT NULL,
    sources_json      TEXT NOT NULL,
    lines             INTEGER,
    rejected          INTEGER,
    rejected_rate     REAL,
    dr_containment_2m REAL,
    dr_n_scored       INTEGER,
    compass_error_deg       REAL,
    compass_error_sigma_deg REAL,
    log_scale               REAL,
    log_scale_sigma         REAL,
    findings_json     TEXT NOT NULL,
    missing_json      TEXT NOT NULL,
    dr_verdict        TEXT,                    -- consistent/conservative/inconsistent/undetermined
    dr_verdict_text   TEXT,
    dr_consistent     INTEGER,                 -- 1, 0 or NULL (undetermined)
    dr_nees           REAL,
    measures_json     TEXT,                    -- the fleet ranking's measures (schema 3)
    UNIQUE (vessel, night)
);
CREATE TABLE IF NOT EXISTS unit_stats (
    night_id       INTEGER NOT NULL REFERENCES nights(id) ON DELETE CASCADE,
    unit           TEXT NOT NULL,
    channel        TEXT NOT NULL,
    measure        TEXT NOT NULL,              -- 'm' or 'deg'
    n              INTEGER NOT NULL,
    m_u            REAL,
    m_y            REAL,
    kurtosis       REAL,
    limit_error    REAL,
    apriori_before REAL,
    apriori_after  REAL,
    verdict        TEXT,
    PRIMARY KEY (night_id, unit, channel)
);
CREATE TABLE IF NOT EXISTS apriori (
    vessel        TEXT NOT NULL,
    unit          TEXT NOT NULL,
    channel       TEXT NOT NULL,
    night         TEXT NOT NULL,
    value         REAL NOT NULL,
    previous      REAL,
    reason        TEXT NOT NULL,               -- 'established' or 'raised'
    evidence_json TEXT NOT NULL,
    PRIMARY KEY (vessel, unit, channel, night)
);
CREATE INDEX IF NOT EXISTS nights_vessel_night ON nights (vessel, night);
"""


@dataclass(frozen=True)
class ChannelRow:
    """One unit and channel of one night, in the channel's unit (``measure``)."""

    unit: str
    channel: str
    n: int
    m_u: float | None
    m_y: float | None
    kurtosis: float | None
    limit_error: float | None
    apriori_before: float | None = None
    apriori_after: float | None = None
    verdict: str | None = None

    @property
    def measure(self) -> str:
        return CHANNEL_MEASURE.get(self.channel, "")


@dataclass(frozen=True)
class NightRecord:
    """Everything kept about one audited night."""

    vessel: str
    night: str
    content_sha256: str
    settings_sha256: str
    audited_utc: str
    period_start_utc: str | None
    period_end_utc: str | None
    inputs: tuple[str, ...]
    sources: dict[str, str]
    lines: int | None
    rejected: int | None
    rejected_rate: float | None
    dr_containment_2m: float | None
    dr_n_scored: int | None
    compass_error_deg: float | None
    compass_error_sigma_deg: float | None
    log_scale: float | None
    log_scale_sigma: float | None
    findings: tuple[dict, ...]
    missing: tuple[str, ...]
    channels: tuple[ChannelRow, ...]
    #: the analysis' DR verdict word (None for nights stored before schema 2)
    dr_verdict: str | None = None
    dr_verdict_text: str | None = None
    dr_consistent: bool | None = None
    dr_nees: float | None = None
    #: the fleet ranking's measures (:func:`dracc.pipeline.audit.measures.night_measures`);
    #: None for nights stored before schema 3
    measures: dict | None = None


@dataclass(frozen=True)
class AprioriEvent:
    """The a priori RMS of one unit and channel was established or raised on ``night``."""

    vessel: str
    unit: str
    channel: str
    night: str
    value: float
    previous: float | None
    reason: str
    evidence: dict


#: SQLite's primary result codes for "another connection holds the lock"
_SQLITE_BUSY, _SQLITE_LOCKED = 5, 6


def _is_busy(err: sqlite3.OperationalError) -> bool:
    code = getattr(err, "sqlite_errorcode", None)  # Python >= 3.11
    if code is not None:
        return code & 0xFF in (_SQLITE_BUSY, _SQLITE_LOCKED)
    text = str(err).lower()
    return "locked" in text or "busy" in text


def _retry_busy(step, deadline: float):
    """``step()``, again after a short randomised wait while SQLite says the database is
    busy or locked, until ``deadline`` (``time.monotonic``).  For the statements SQLite
    may refuse without waiting for the busy timeout (``journal_mode = WAL`` on a new file,
    a ``BEGIN IMMEDIATE`` that meets a WAL recovery)."""
    wait_s = 0.002
    while True:
        try:
            return step()
        except StateError as err:  # transaction() wraps a refused BEGIN
            cause = err.__cause__
            if not (isinstance(cause, sqlite3.OperationalError) and _is_busy(cause)):
                raise
            if time.monotonic() >= deadline:
                raise
        except sqlite3.OperationalError as err:
            if not _is_busy(err) or time.monotonic() >= deadline:
                raise
        time.sleep(min(wait_s * (0.5 + random.random()), max(0.0, deadline - time.monotonic())))
        wait_s = min(2 * wait_s, 0.2)


def _json_column(path: Path, r: sqlite3.Row, name: str, kind: type):
    """The JSON document in column ``name`` of a night's row: a ``kind`` (list or dict),
    parsed within bounds (:func:`dracc.core.jsonbound.loads`); StateError otherwise (a
    damaged or hand-edited database)."""
    where = f"{path}: {name} of {str(r['vessel'])[:40]!r} on {str(r['night'])[:20]}"
    value = r[name]
    if not isinstance(value, (str, bytes)):
        raise StateError(f"{where} holds {type(value).__name__}, not JSON text")
    try:
        doc = jsonbound.loads(value)
    except ValueError as err:
        raise StateError(f"{where} is not readable JSON: {err}") from None
    if not isinstance(doc, kind):
        want = "an array" if kind is list else "an object"
        raise StateError(f"{where} holds {type(doc).__name__}, not {want}")
    return doc


def schema_columns(version: int) -> dict[str, dict[str, tuple[str, bool]]]:
    """table -> column -> (declared type, NOT NULL) of an audit database of schema
    ``version`` (1 to :data:`SCHEMA_VERSION`), as the DDL creates them: what a database
    read from elsewhere must hold (:mod:`dracc.pipeline.state_read`)."""
    later = {name for name, _ in _NIGHT_COLUMNS_V2} if version < 2 else set()
    if version < 3:
        later.add("measures_json")
    mem = sqlite3.connect(":memory:")
    try:
        mem.executescript(_DDL)
        tables = [r[0] for r in mem.execute("SELECT name FROM sqlite_master WHERE type='table'")]
        return {
            t: {
                c[1]: (str(c[2]).upper(), bool(c[3]))
                for c in mem.execute(f"PRAGMA table_info({t})")
                if not (t == "nights" and c[1] in later)
            }
            for t in tables
        }
    finally:
        mem.close()


def _none_if_nan(x):
    if x is None:
        return None
    try:
        xf = float(x)
    except (TypeError, ValueError):
        return None
    return None if xf != xf else xf


class StateStore:
    """A connection to the audit database; use as a context manager.

    ``busy_timeout_s`` is how long a writer waits for another audit's transaction.
    """

    def __init__(self, path: str | Path, busy_timeout_s: float = 60.0):
        self.path = Path(path)
        self.busy_timeout_s = float(busy_timeout_s)
        if self.path.is_dir():
            raise ConfigError(f"audit database path is a directory: {self.path}")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.conn = sqlite3.connect(self.path, timeout=busy_timeout_s, isolation_level=None)
        except (OSError, sqlite3.DatabaseError) as err:
            raise StateError(f"{self.path}: cannot create the audit database: {err}") from err
        try:
            # the busy timeout before anything else touches the file
            self.conn.execute(f"PRAGMA busy_timeout = {int(busy_timeout_s * 1000)}")
            self.conn.row_factory = sqlite3.Row
            deadline = time.monotonic() + self.busy_timeout_s
            # Switching a new file to WAL takes an exclusive lock, and SQLite answers
            # SQLITE_BUSY at once, without the busy handler, when another process holds
            # it (two audits creating the same new database): retried until the deadline.
            mode = _retry_busy(
                lambda: self.conn.execute("PRAGMA journal_mode = WAL").fetchone()[0], deadline
            )
            self.conn.execute("PRAGMA synchronous = FULL")
            self.conn.execute("PRAGMA foreign_keys = ON")
            _retry_busy(self._init_schema, deadline)
        except BaseException as err:
            self.conn.close()
            if isinstance(err, sqlite3.DatabaseError):
                raise StateError(f"{self.path}: cannot open the audit database: {err}") from err
            raise
        self.journal_mode = str(mode).lower()

    @classmethod
    def reading(cls, path: str | Path, conn: sqlite3.Connection) -> StateStore:
        """A store over ``conn``, a database opened for reading only elsewhere (a ship's,
        read ashore: :func:`dracc.pipeline.state_read.read_nights`, which checks its
        schema first); only the reads are used."""
        store = cls.__new__(cls)
        store.path, store.conn, store.busy_timeout_s = Path(path), conn, 0.0
        store.journal_mode = "read-only"
        conn.row_factory = sqlite3.Row
        return store

    # -- plumbing ------------------------------------------------------------------

    def close(self) -> None:
        self.conn.close()

    def __enter__(self) -> StateStore:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @contextmanager
    def transaction(self) -> Iterator[sqlite3.Connection]:
        """``BEGIN IMMEDIATE`` … ``COMMIT``; rolled back on any exception.

        IMMEDIATE takes the write lock up front, so two audits never both read the old
        state and then race to write (they wait for each other up to the busy timeout).
        """
        try:
            _retry_busy(
                lambda: self.conn.execute("BEGIN IMMEDIATE"), time.monotonic() + self.busy_timeout_s
            )
        except sqlite3.OperationalError as err:
            raise StateError(f"{self.path}: database busy or locked: {err}") from err
        try:
            yield self.conn
        except BaseException:
            self.conn.execute("ROLLBACK")
            raise
        else:
            self.conn.execute("COMMIT")

    def _init_schema(self) -> None:
        """Create the tables (or check and migrate them) in one ``BEGIN IMMEDIATE``
        transaction: two audits creating a new file at once create it once."""
        with self.transaction() as c:
            # statement by statement: executescript() would COMMIT the open transaction
            for stmt in _DDL.split(";"):
                if stmt.strip():
                    c.execute(stmt)
            row = c.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone()
            if row is None:
                c.execute(
                    "INSERT INTO meta (key, value) VALUES ('schema', ?)", (str(SCHEMA_VERSION),)
                )
                return
            try:
                version = int(row[0])
            except ValueError:
                version = -1
            if version in (1, 2):
                self._migrate(c)
            elif version != SCHEMA_VERSION:
                raise StateError(
                    f"{self.path}: audit database schema {row[0]} is not the supported "
                    f"{SCHEMA_VERSION}"
                )

    @staticmethod
    def _migrate(c: sqlite3.Connection) -> None:
        """Add the columns of versions 2 and 3 to ``nights`` (inside the open transaction)."""
        have = {r[1] for r in c.execute("PRAGMA table_info(nights)")}
        for name, sql_type in (*_NIGHT_COLUMNS_V2, ("measures_json", "TEXT")):
            if name not in have:
                c.execute(f"ALTER TABLE nights ADD COLUMN {name} {sql_type}")
        c.execute("UPDATE meta SET value = ? WHERE key = 'schema'", (str(SCHEMA_VERSION),))

    # -- reads ---------------------------------------------------------------------

    def night(self, vessel: str, night: str) -> NightRecord | None:
        """The stored record of one night, or None."""
        row = self.conn.execute(
            "SELECT * FROM nights WHERE vessel = ? AND night = ?", (vessel, night)
        ).fetchone()
        return None if row is None else self._record(row)

    def nights(self, vessel: str | None = None) -> list[NightRecord]:
        """All stored nights (of one vessel), in order of vessel and night."""
        if vessel is None:
            rows = self.conn.execute("SELECT * FROM nights ORDER BY vessel, night").fetchall()
        else:
            rows = self.conn.execute(
                "SELECT * FROM nights WHERE vessel = ? ORDER BY night", (vessel,)
            ).fetchall()
        return [self._record(r) for r in rows]

    def vessels(self) -> list[str]:
        return [
            r[0] for r in self.conn.execute("SELECT DISTINCT vessel FROM nights ORDER BY vessel")
        ]

    def history(
        self, vessel: str | None = None, unit: str | None = None, channel: str | None = None
    ) -> list[dict]:
        """Per-night statistics, one dict per vessel, night, unit and channel, in time order."""
        sql = (
            "SELECT n.vessel, n.night, s.unit, s.channel, s.measure, s.n, s.m_u, s.m_y, "
            "s.kurtosis, s.limit_error, s.apriori_before, s.apriori_after, s.verdict, "
            "n.dr_containment_2m, n.compass_error_deg, n.log_scale "
            "FROM unit_stats s JOIN nights n ON n.id = s.night_id WHERE 1 = 1"
        )
        args: list = []
        for col, val in (("n.vessel", vessel), ("s.unit", unit), ("s.channel", channel)):
            if val is not None:
                sql += f" AND {col} = ?"
                args.append(val)
        sql += (
            f" ORDER BY n.vessel, s.unit, {_CHANNEL_ORDER.replace('channel', 's.channel')}, n.night"
        )
        return [dict(r) for r in self.conn.execute(sql, args)]

    def apriori_events(self, vessel: str | None = None) -> list[AprioriEvent]:
        sql = "SELECT * FROM apriori"
        args: tuple = ()
        if vessel is not None:
            sql += " WHERE vessel = ?"
            args = (vessel,)
        sql += f" ORDER BY vessel, unit, {_CHANNEL_ORDER}, night"
        return [
            AprioriEvent(
                r["vessel"],
                r["unit"],
                r["channel"],
                r["night"],
                r["value"],
                r["previous"],
                r["reason"],
                json.loads(r["evidence_json"]),
            )
            for r in self.conn.execute(sql, args)
        ]

    def _channels(self, night_id: int) -> tuple[ChannelRow, ...]:
        rows = self.conn.execute(
            f"SELECT * FROM unit_stats WHERE night_id = ? ORDER BY unit, {_CHANNEL_ORDER}",
            (night_id,),
        ).fetchall()
        return tuple(
            ChannelRow(
                r["unit"],
                r["channel"],
                r["n"],
                r["m_u"],
                r["m_y"],
                r["kurtosis"],
                r["limit_error"],
                r["apriori_before"],
                r["apriori_after"],
                r["verdict"],
            )
            for r in rows
        )

    def _record(self, r: sqlite3.Row) -> NightRecord:
        have = set(r.keys())  # a database read-only at schema 1 or 2 lacks later columns

        def col(name: str):
            return r[name] if name in have else None

        def js(name: str, kind: type):
            return _json_column(self.path, r, name, kind)

        measures = col("measures_json")
        return NightRecord(
            vessel=r["vessel"],
            night=r["night"],
            content_sha256=r["content_sha256"],
            settings_sha256=r["settings_sha256"],
            audited_utc=r["audited_utc"],
            period_start_utc=r["period_start_utc"],
            period_end_utc=r["period_end_utc"],
            inputs=tuple(js("inputs_json", list)),
            sources=js("sources_json", dict),
            lines=r["lines"],
            rejected=r["rejected"],
            rejected_rate=r["rejected_rate"],
            dr_containment_2m=r["dr_containment_2m"],
            dr_n_scored=r["dr_n_scored"],
            compass_error_deg=r["compass_error_deg"],
            compass_error_sigma_deg=r["compass_error_sigma_deg"],
            log_scale=r["log_scale"],
            log_scale_sigma=r["log_scale_sigma"],
            findings=tuple(js("findings_json", list)),
            missing=tuple(js("missing_json", list)),
            channels=self._channels(r["id"]),
            dr_verdict=col("dr_verdict"),
            dr_verdict_text=col("dr_verdict_text"),
            dr_consistent=None if col("dr_consistent") is None else bool(r["dr_consistent"]),
            dr_nees=col("dr_nees"),
            measures=None if measures is None else js("measures_json", dict),
        )

    # -- writes (call inside :meth:`transaction`) ------------------------------------

    def delete_night(self, vessel: str, night: str) -> bool:
        """Remove one night (its statistics go with it); True if there was one."""
        cur = self.conn.execute(
            "DELETE FROM nights WHERE vessel = ? AND night = ?", (vessel, night)
        )
        return cur.rowcount > 0

    def insert_night(self, rec: NightRecord) -> int:
        """Insert one night and its statistics; returns the row id."""
        cur = self.conn.execute(
            "INSERT INTO nights (vessel, night, content_sha256, settings_sha256, audited_utc, "
            "period_start_utc, period_end_utc, inputs_json, sources_json, lines, rejected, "
            "rejected_rate, dr_containment_2m, dr_n_scored, compass_error_deg, "
            "compass_error_sigma_deg, log_scale, log_scale_sigma, findings_json, missing_json, "
            "dr_verdict, dr_verdict_text, dr_consistent, dr_nees, measures_json) "
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (
                rec.vessel,
                rec.night,
                rec.content_sha256,
                rec.settings_sha256,
                rec.audited_utc,
                rec.period_start_utc,
                rec.period_end_utc,
                json.dumps(list(rec.inputs)),
                json.dumps(rec.sources, sort_keys=True),
                rec.lines,
                rec.rejected,
                _none_if_nan(rec.rejected_rate),
                _none_if_nan(rec.dr_containment_2m),
                rec.dr_n_scored,
                _none_if_nan(rec.compass_error_deg),
                _none_if_nan(rec.compass_error_sigma_deg),
                _none_if_nan(rec.log_scale),
                _none_if_nan(rec.log_scale_sigma),
                json.dumps(list(rec.findings), sort_keys=True),
                json.dumps(list(rec.missing)),
                rec.dr_verdict,
                rec.dr_verdict_text,
                None if rec.dr_consistent is None else int(bool(rec.dr_consistent)),
                _none_if_nan(rec.dr_nees),
                None
                if rec.measures is None
                else json.dumps(rec.measures, sort_keys=True, allow_nan=False),
            ),
        )
        assert cur.lastrowid is not None  # an INSERT sets it
        night_id = int(cur.lastrowid)
        self.conn.executemany(
            "INSERT INTO unit_stats (night_id, unit, channel, measure, n, m_u, m_y, kurtosis, "
            "limit_error, apriori_before, apriori_after, verdict) "
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            [
                (
                    night_id,
                    c.unit,
                    c.channel,
                    c.measure,
                    int(c.n),
                    _none_if_nan(c.m_u),
                    _none_if_nan(c.m_y),
                    _none_if_nan(c.kurtosis),
                    _none_if_nan(c.limit_error),
                    _none_if_nan(c.apriori_before),
                    _none_if_nan(c.apriori_after),
                    c.verdict,
                )
                for c in rec.channels
            ],
        )
        return night_id

    def set_channel_apriori(
        self,
        vessel: str,
        night: str,
        unit: str,
        channel: str,
        before: float | None,
        after: float | None,
        verdict: str,
    ) -> None:
        """Store the outcome of the monitoring rule for one night, unit and channel."""
        self.conn.execute(
            "UPDATE unit_stats SET apriori_before = ?, apriori_after = ?, verdict = ? "
            "WHERE unit = ? AND channel = ? AND night_id = "
            "(SELECT id FROM nights WHERE vessel = ? AND night = ?)",
            (_none_if_nan(before), _none_if_nan(after), verdict, unit, channel, vessel, night),
        )

    def replace_apriori_events(self, vessel: str, events: Sequence[AprioriEvent]) -> None:
        """Replace the a priori history of one vessel (it is recomputed from all its nights)."""
        self.conn.execute("DELETE FROM apriori WHERE vessel = ?", (vessel,))
        self.conn.executemany(
            "INSERT INTO apriori (vessel, unit, channel, night, value, previous, reason, evidence_json) "
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
            [
                (
                    e.vessel,
                    e.unit,
                    e.channel,
                    e.night,
                    float(e.value),
                    _none_if_nan(e.previous),
                    e.reason,
                    json.dumps(e.evidence, sort_keys=True),
                )
                for e in events
            ],
        )
