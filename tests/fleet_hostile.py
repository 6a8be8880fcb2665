"""Hostile fleet inputs (issue 33): a good audit document and a good audit database, the
hostile ones the issue lists, and random mutations of both for the fuzzer
(``tests/test_fleet_fuzz.py``, ``benchmarks/bench_fleet_fuzz.py``).

Every mutation is a function of a seeded :class:`random.Random`: a case is repeated by
its seed.
"""

from __future__ import annotations

import json
import os
import random
import sqlite3
from collections.abc import Callable
from pathlib import Path
from typing import Any

from test_fleet_documents import MEASURES, _record

from dracc.pipeline.state import StateStore

NIGHT = "2026-05-01"
GOOD = "Good"  #: the good document's vessel
BAD = "Bad"  #: the hostile input's vessel (when it gets that far)


def good_document(vessel: str = GOOD, night: str = NIGHT) -> dict:
    """A brief audit document (``dracc.audit/1``) that the JSON Schema accepts, with a
    finding (and its consequence), a check not made and the integrity counts."""
    return {
        "schema": "dracc.audit/1",
        "dracc_version": "0.0.0",
        "vessel": vessel,
        "night": night,
        "verdict": "findings",
        "exit_code": 1,
        "state": "recorded",
        "audited_utc": f"{night}T23:59:00Z",
        "logs": {
            "files": ["x.nmea"],
            "lines": 1000,
            "rejected": 2,
            "ignored": {},
            "period": {"start_utc": f"{night}T00:00:00Z", "end_utc": f"{night}T23:59:59Z"},
        },
        "sources": {"ins1": "INS1"},
        "findings": [
            {
                "check": "plausibility",
                "source": "INS2",
                "role": "ins2",
                "clause": "",
                "statistic": {"name": "jump", "value": 1.2, "unit": "nmi"},
                "threshold": {"value": 0.5, "unit": "nmi", "rule": ">"},
                "window": {"start_utc": f"{night}T03:00:00Z", "end_utc": f"{night}T03:10:00Z"},
                "evidence": [],
                "message": "INS2 jumped 1.2 nmi",
                "kind": "jump",
                "subject": "ins2 lat",
                "consequences": [{"name": "contradiction", "source": "INS2", "message": "m"}],
            }
        ],
        "not_checked": [
            {"check": "latency", "name": "latency", "source": None, "role": None, "why": "no"}
        ],
        "integrity": {
            "checks_made": 10,
            "checks_passed": 9,
            "checks_failed": 1,
            "checks_not_checked": 1,
        },
        "ins": [
            {
                "unit": "ins1",
                "channel": "lat",
                "n": 25,
                "m_u": 170.0,
                "m_y": 224.0,
                "kurtosis": 0.1,
                "limit_error": 500.0,
            }
        ],
        "dead_reckoning": {"containment_2m": 0.96, "n_scored": 100, "consistent": True},
        "calibration": {
            "compass_error_deg": 0.3,
            "compass_error_sigma_deg": 0.1,
            "log_scale": 0.021,
            "log_scale_sigma": 0.006,
        },
        "missing": [],
        "measures": json.loads(json.dumps(MEASURES)),
        "analysis": None,
    }


def write_good_database(path: Path, vessel: str = BAD, night: str = NIGHT) -> Path:
    """An audit database (WAL, closed: no -wal or -shm left) holding one night."""
    with StateStore(path) as store, store.transaction():
        store.insert_night(_record(vessel, night))
    return path


def hostile_database(path: Path, sql: str) -> Path:
    """A good database, then ``sql`` run on it by a plain connection (as a hand or
    another program would)."""
    write_good_database(path)
    con = sqlite3.connect(path)
    try:
        con.executescript(sql)
    finally:
        con.close()
    return path


def inbox(root: Path) -> Path:
    """A folder holding the good document."""
    folder = root / "inbox"
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "good.json").write_text(json.dumps(good_document()), encoding="utf-8")
    return folder


def _with(**fields: Any) -> Callable[[dict], str]:
    def text(doc: dict) -> str:
        return json.dumps({**doc, **fields})

    return text


def _deep(doc: dict) -> str:
    return json.dumps(doc)[:-1] + ', "extra": ' + "[" * 200_000 + "]" * 200_000 + "}"


#: the audit documents of the issue (and those the fuzzer found): what to write beside
#: the good document, and the reason the failed row gives
DOCUMENT_CASES: dict[str, tuple[Callable[[dict], str], str]] = {
    "logs-an-array": (_with(logs=[1, 2, 3]), "logs: expected an object or null, got an array"),
    "measures-a-text": (_with(measures="x"), "measures: expected an object or null, got a text"),
    "ins-an-object": (
        _with(ins={"unit": "ins1", "channel": "lat"}),
        "ins: expected an array or null, got an object",
    ),
    "array-200000-deep": (_deep, "nested 200,001 levels deep (at most 64)"),
    "night-9999-12-31": (
        _with(night="9999-12-31"),
        "night: 9999-12-31 is not a night between 1980-01-01 and 2099-12-31",
    ),
    "vessel-name-5000-characters": (
        _with(vessel="V" * 5000),
        "vessel: a vessel name of 5,000 characters (1 to 100)",
    ),
    # found by the fuzzer: the page had no panel for it (matplotlib: 0 rows)
    "ins-channel-unknown": (
        _with(ins=[{"unit": "ins1", "channel": "9999-12-31", "n": 25, "m_y": 224.0}]),
        "ins[0].channel: '9999-12-31' is not one of lat, lon, course",
    ),
}

#: an endless recursive query, and one that would take gigabytes
ENDLESS = "WITH RECURSIVE r(i) AS (SELECT 1 UNION ALL SELECT i + 1 FROM r) "
LARGE = "WITH RECURSIVE r(i) AS (SELECT 1 UNION ALL SELECT i + 1 FROM r WHERE i < 100000000) "
_NIGHT_COLUMNS = (
    "i AS id, 'Bad' AS vessel, '2026-05-01' AS night, 'c' AS content_sha256, "
    "'s' AS settings_sha256, 'x' AS audited_utc, '2026-05-01T00:00:00Z' AS period_start_utc, "
    "'2026-05-01T23:00:00Z' AS period_end_utc, '[]' AS inputs_json, '{}' AS sources_json, "
    "1 AS lines, 0 AS rejected, 0.0 AS rejected_rate, NULL AS dr_containment_2m, "
    "NULL AS dr_n_scored, NULL AS compass_error_deg, NULL AS compass_error_sigma_deg, "
    "NULL AS log_scale, NULL AS log_scale_sigma, '[]' AS findings_json, '[]' AS missing_json, "
    "NULL AS dr_verdict, NULL AS dr_verdict_text, NULL AS dr_consistent, NULL AS dr_nees, "
    "NULL AS measures_json"
)
_STATS_COLUMNS = (
    "i AS night_id, printf('%.*c', 1000, 'u') AS unit, 'lat' AS channel, 'm' AS measure, "
    "i AS n, 1.0 AS m_u, 1.0 AS m_y, 0.0 AS kurtosis, 1.0 AS limit_error, "
    "NULL AS apriori_before, NULL AS apriori_after, NULL AS verdict"
)

#: the audit databases of the issue: (SQL run on a good database, the failed row's reason)
DATABASE_CASES: dict[str, tuple[str, str]] = {
    "unparseable-measures-json": (
        'UPDATE nights SET measures_json = \'{"position": {"lat_deg": 54.5,\';',
        "measures_json of 'Bad' on 2026-05-01 is not readable JSON",
    ),
    "dropped-table": (
        "DROP TABLE unit_stats;",
        "unit_stats is missing, not a table of the audit database",
    ),
    "text-in-a-number-column": (
        "UPDATE unit_stats SET m_y = 'abc';",
        "unit_stats.m_y holds 1 value(s) of type text where REAL is declared",
    ),
    "view-over-a-large-recursive-query": (
        f"DROP TABLE unit_stats; CREATE VIEW unit_stats AS {LARGE}"
        f"SELECT {_STATS_COLUMNS} FROM r ORDER BY random();",
        "unit_stats is a view, not a table of the audit database",
    ),
    "view-over-an-endless-recursive-query": (
        f"DROP TABLE nights; CREATE VIEW nights AS {ENDLESS}SELECT {_NIGHT_COLUMNS} FROM r;",
        "nights is a view, not a table of the audit database",
    ),
    # found by the fuzzer (as its document twin)
    "unit-stats-channel-unknown": (
        "UPDATE unit_stats SET channel = 'heading';",
        "channels[0].channel: 'heading' is not one of lat, lon, course",
    ),
}


# ------------------------------------------------------------------------ the fuzzer

#: values put in place of a field (types, sizes, ranges, dates, control characters)
VALUES: tuple[Any, ...] = (
    None,
    None,
    True,
    0,
    0.0,
    12.5,
    -3,
    "ins1",
    "lat",
    -1,
    1.5,
    -1e308,
    1e308,
    2**70,
    "",
    "x",
    "9999-12-31",
    "0001-01-01T00:00:00Z",
    "2026-05-01T00:00:00",  # no zone
    "2026-13-45",
    "\x1b[2J\nall within limits",
    [],
    [1, 2, 3],
    [None],
    {},
    {"a": 1},
    {"start_utc": "x"},
)


def _paths(x: Any, at: tuple = ()) -> list[tuple]:
    """Every path to a value inside ``x`` (keys and indices)."""
    out = [at]
    if isinstance(x, dict):
        for k, v in x.items():
            out += _paths(v, (*at, k))
    elif isinstance(x, list):
        for i, v in enumerate(x):
            out += _paths(v, (*at, i))
    return out


def _set(doc: Any, path: tuple, value: Any, delete: bool = False) -> Any:
    if not path:
        return value
    parent = doc
    for k in path[:-1]:
        parent = parent[k]
    if delete and isinstance(parent, dict):
        del parent[path[-1]]
    else:
        parent[path[-1]] = value
    return doc


def _nested(depth: int) -> Any:
    x: Any = 1
    for _ in range(min(depth, 500)):  # deeper: written as text (json.dumps recurses)
        x = [x]
    return x


def mutate_value(doc: Any, rng: random.Random) -> Any:
    """``doc`` (a copy) with one value replaced, deleted, nested deep or made large."""
    doc = json.loads(json.dumps(doc))
    path = rng.choice(_paths(doc)[1:] or [()])
    how = rng.choice(("value",) * 6 + ("delete", "delete", "deep", "list", "text"))
    if how == "value":
        return _set(doc, path, rng.choice(VALUES))
    if how == "delete":
        return _set(doc, path, None, delete=True)
    if how == "deep":
        return _set(doc, path, _nested(rng.choice((65, 300))))
    if how == "list":
        return _set(doc, path, [rng.choice(VALUES[:8])] * rng.choice((3, 10_001)))
    return _set(doc, path, "x" * rng.choice((101, 10_001)))


def mutate_document(rng: random.Random) -> bytes:
    """The bytes of a mutated copy of :func:`good_document` (vessel ``Bad``)."""
    doc = good_document(BAD)
    how = rng.choice(("fields",) * 6 + ("cut", "flip", "deep", "constant"))
    if how == "fields":
        for _ in range(rng.choice((1, 1, 1, 2, 3))):
            doc = mutate_value(doc, rng)
        return json.dumps(doc).encode()
    raw = json.dumps(doc).encode()
    if how == "cut":
        return raw[: rng.randrange(len(raw))]
    if how == "flip":
        b = bytearray(raw)
        for _ in range(rng.randint(1, 8)):
            b[rng.randrange(len(b))] = rng.randrange(256)
        return bytes(b)
    if how == "deep":
        depth = rng.choice((65, 5_000, 200_000))
        return raw[:-1] + b', "x": ' + b"[" * depth + b"]" * depth + b"}"
    return raw.replace(b"224.0", rng.choice((b"NaN", b"Infinity", b"1e999")))


#: SQL values put in a column (storage classes, sizes, JSON that is not the expected)
SQL_VALUES: tuple[str, ...] = (
    "NULL",
    "NULL",
    "0",
    "12.5",
    "'ins1'",
    "'abc'",
    "x'00ff'",
    "-1",
    "1e308",
    "9223372036854775807",
    "2.5",
    "'9999-12-31'",
    "'{not json'",
    "'[1, 2, 3]'",
    "'\"x\"'",
    "printf('%.*c', 100000, '[')",
    "zeroblob(20000000)",
)


def _columns(con: sqlite3.Connection, table: str) -> list[str]:
    return [r[1] for r in con.execute(f"PRAGMA table_info({table})")]


def _database_sql(con: sqlite3.Connection, rng: random.Random) -> str:
    """One random change of an audit database, as SQL."""
    how = rng.choice(
        ("value",) * 5 + ("json",) * 4
        + ("drop", "view", "trigger", "generated", "retype", "schema", "rows")
    )  # fmt: skip
    table = rng.choice(("nights", "unit_stats", "meta"))
    if how == "value":
        col = rng.choice(_columns(con, table) or ["gone"])  # a dropped table: no change
        return f"UPDATE {table} SET {col} = {rng.choice(SQL_VALUES)};"
    if how == "json":
        col = rng.choice(("measures_json", "findings_json", "sources_json", "missing_json"))
        base = {
            "measures_json": MEASURES,
            "findings_json": good_document()["findings"],
            "sources_json": {"ins1": "INS1"},
            "missing_json": ["x"],
        }[col]
        text = json.dumps(mutate_value(base, rng)).replace("'", "''")
        return f"UPDATE nights SET {col} = '{text}';"
    if how == "drop":
        return f"DROP TABLE {table};"
    if how == "view":
        body = rng.choice((f"{ENDLESS}SELECT * FROM r", f"{LARGE}SELECT * FROM r", "SELECT 1"))
        return f"DROP TABLE {table}; CREATE VIEW {table} AS {body};"
    if how == "trigger":
        return "CREATE TRIGGER t AFTER INSERT ON nights BEGIN DELETE FROM unit_stats; END;"
    if how == "generated":
        return f"ALTER TABLE {table} ADD COLUMN g AS (zeroblob(100000000)) VIRTUAL;"
    if how == "retype":
        return (
            "CREATE TABLE s2 (night_id INTEGER, unit TEXT, channel TEXT, measure TEXT, "
            "n INTEGER, m_u REAL, m_y TEXT, kurtosis REAL, limit_error REAL, "
            "apriori_before REAL, apriori_after REAL, verdict TEXT); "
            "INSERT INTO s2 SELECT * FROM unit_stats; DROP TABLE unit_stats; "
            "ALTER TABLE s2 RENAME TO unit_stats;"
        )
    if how == "schema":
        return f"UPDATE meta SET value = {rng.choice(SQL_VALUES)} WHERE key = 'schema';"
    return (  # many nights (500)
        f"{LARGE.replace('100000000', '500')}INSERT INTO nights (vessel, night, content_sha256, "
        "settings_sha256, audited_utc, period_start_utc, inputs_json, sources_json, "
        "findings_json, missing_json) SELECT 'Bad', date('2020-01-01', '+' || i || ' days'), "
        "'c', 's', 'a', '2026-05-01T00:00:00Z', '[]', '{}', '[]', '[]' FROM r;"
    )


def mutate_database(path: Path, rng: random.Random) -> str:
    """A good database at ``path`` changed by one to three random SQL changes, or with
    its bytes damaged; returns what was done."""
    write_good_database(path)
    if rng.random() < 0.1:  # damaged bytes: flipped past the header, or cut
        data = bytearray(path.read_bytes())
        if rng.random() < 0.5:
            for _ in range(rng.randint(1, 30)):
                data[rng.randrange(100, len(data))] = rng.randrange(256)
            done = "bytes flipped"
        else:
            data = data[: rng.randrange(100, len(data))]
            done = "cut"
        path.write_bytes(bytes(data))
        return done
    done = []
    con = sqlite3.connect(path)
    try:
        for _ in range(rng.choice((1, 1, 2, 3))):
            sql = _database_sql(con, rng)
            try:
                con.executescript(sql)
                done.append(sql[:80])
            except sqlite3.DatabaseError:  # the change does not apply (a table gone)
                pass
        con.execute("PRAGMA journal_mode = DELETE")  # no -wal left beside it
    finally:
        con.close()
    return "; ".join(done) or "unchanged"


def write_case(folder: Path, seed: int) -> Path:
    """The fuzz case ``seed``: a mutated document (even seeds) or database (odd) in
    ``folder``, beside nothing else; returns its path."""
    rng = random.Random(seed)
    folder.mkdir(parents=True, exist_ok=True)
    if seed % 2 == 0:
        p = folder / f"case-{seed}.json"
        p.write_bytes(mutate_document(rng))
    else:
        p = folder / f"case-{seed}.sqlite"
        mutate_database(p, rng)
    return p


def side_files(folder: Path) -> list[str]:
    """SQLite's files beside a database (``-wal``, ``-shm``, ``-journal``)."""
    return sorted(n for n in os.listdir(folder) if n.endswith(("-wal", "-shm", "-journal")))
