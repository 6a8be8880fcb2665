"""Issue 33: one ship's file no longer takes down the fleet.

Each hostile input the issue lists lies beside one good audit document.  Before, each
stopped the whole batch (no table for any vessel: exit 5, or a hang only SIGKILL ended);
now it is one failed row with its reason, the good vessel's tables are written, and the
run ends within its bound:

- audit documents: ``"logs": [1, 2, 3]``, ``"measures": "x"``, ``"ins": {…}``, a
  200,000-deep array, ``"night": "9999-12-31"``, a 5,000-character vessel name;
- audit databases: an unparseable ``measures_json``, a dropped table, a text in a number
  column, a view over a large recursive query (6.3 GB then MemoryError), a view over an
  endless recursive query (100 % CPU, deaf to SIGTERM and SIGINT);
- a database read leaves no ``-shm``/``-wal`` beside it, and reads in a read-only inbox;
- SIGTERM or SIGINT during a runaway query ends the run (exit 130), and the time budget
  ends one (a failed row).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import jsonschema
import pandas as pd
import pytest
from fleet_hostile import (
    BAD,
    DATABASE_CASES,
    DOCUMENT_CASES,
    ENDLESS,
    GOOD,
    good_document,
    hostile_database,
    inbox,
    side_files,
    write_good_database,
)

from dracc.core import jsonbound
from dracc.core.config import Config
from dracc.core.errors import ExitCode, StateError
from dracc.pipeline.fleet import discover, run_fleet
from dracc.pipeline.fleet.documents import expand_documents
from dracc.pipeline.state_read import Budget, connect, guarded, read_nights
from dracc.report.audit_json import load_schema
from dracc.report.fleet_tables import write_tables

BOUND_S = 30.0  #: every run here ends well within this (the slowest takes about 1 s)
WAIT_S = 120.0  #: bound on a child process (the CLI starts in seconds on a busy machine)


def _run(folder: Path, out: Path):
    """The batch over ``folder`` (as ``dracc fleet`` runs it), its outputs written."""
    t0 = time.monotonic()
    res = run_fleet(discover([str(folder)]), Config(), out, workers=1)
    write_tables(res, out)
    return res, time.monotonic() - t0


def _assert_one_failed_row(res, out: Path, bad: Path, reason: str, elapsed_s: float) -> None:
    assert elapsed_s < BOUND_S
    assert [f["path"] for f in res.failures] == [str(bad)]
    assert reason in res.failures[0]["error"], res.failures[0]["error"]
    t = res.table
    assert (t.loc[t.vessel == GOOD, "status"] == "ok").all() and (t.vessel == GOOD).any()
    failed = t[t.status == "failed"]
    assert len(failed) == 1 and reason in failed.iloc[0]["error"]
    written = json.loads((out / "fleet.json").read_text())
    assert len(written["failures"]) == 1
    assert (out / "vessels" / GOOD / "fleet.csv").is_file()
    assert set(pd.read_parquet(out / "fleet.parquet").vessel) == {GOOD, "inbox"}


@pytest.mark.parametrize("case", list(DOCUMENT_CASES))
def test_a_hostile_audit_document_is_one_failed_row(tmp_path, case):
    write, reason = DOCUMENT_CASES[case]
    folder = inbox(tmp_path)
    bad = folder / "bad.json"
    bad.write_text(write(good_document(BAD)), encoding="utf-8")
    res, elapsed = _run(folder, tmp_path / "out")
    _assert_one_failed_row(res, tmp_path / "out", bad, reason, elapsed)


@pytest.mark.parametrize("case", list(DATABASE_CASES))
def test_a_hostile_audit_database_is_one_failed_row(tmp_path, case):
    sql, reason = DATABASE_CASES[case]
    folder = inbox(tmp_path)
    bad = hostile_database(folder / "bad.sqlite", sql)
    res, elapsed = _run(folder, tmp_path / "out")
    _assert_one_failed_row(res, tmp_path / "out", bad, reason, elapsed)


def test_the_good_document_and_every_hostile_one_against_the_json_schema():
    """The fleet's checks agree with dracc/report/audit.schema.json: the good document is
    valid, and every document of the wrong type is invalid there too; the schema states
    no bounds on dates and names, the fleet does (9999-12-31, 5,000 characters)."""
    validator = jsonschema.Draft202012Validator(load_schema())
    assert list(validator.iter_errors(good_document())) == []
    for case in ("logs-an-array", "measures-a-text", "ins-an-object"):
        doc = json.loads(DOCUMENT_CASES[case][0](good_document(BAD)))
        assert list(validator.iter_errors(doc)), case


def test_a_database_read_leaves_no_side_files_and_changes_nothing(tmp_path):
    """A read-only open of a WAL database used to create -shm and -wal beside it (and
    leave them); immutable, nothing appears and not a byte changes."""
    db = write_good_database(tmp_path / "ship.sqlite")
    before = (db.read_bytes(), db.stat().st_mtime_ns)
    assert side_files(tmp_path) == []
    nights = read_nights(db)
    assert [n.vessel for n in nights] == [BAD]
    assert side_files(tmp_path) == [] and (db.read_bytes(), db.stat().st_mtime_ns) == before


def test_a_database_being_written_is_read_with_its_log(tmp_path):
    """A non-empty -wal beside the database: an audit is writing it (or it was copied
    with its log).  It is read through the log (mode=ro, not immutable), so the night
    committed there is read, not a stale file."""
    db = write_good_database(tmp_path / "ship.sqlite")
    writer = __import__("sqlite3").connect(db)
    try:
        writer.execute("PRAGMA wal_autocheckpoint = 0")
        writer.execute("UPDATE nights SET vessel = 'Renamed'")
        writer.commit()
        assert (tmp_path / "ship.sqlite-wal").stat().st_size > 0
        assert [n.vessel for n in read_nights(db)] == ["Renamed"]
    finally:
        writer.close()


def _read_only(folder: Path) -> list[str] | None:
    """A command prefix that runs with ``folder`` read-only: nothing (not root: the
    folder's mode is enough), a read-only bind mount in a mount namespace (root), or
    None when neither is possible here."""
    if os.geteuid() != 0:
        return []
    if shutil.which("unshare") is None:
        return None
    probe = subprocess.run(["unshare", "-m", "true"], capture_output=True)
    if probe.returncode != 0:
        return None
    q = f"'{folder}'"
    return [
        "unshare",
        "-m",
        "sh",
        "-c",
        f'mount --bind {q} {q} && mount -o remount,ro,bind {q} {q} && exec "$0" "$@"',
    ]


def test_fleet_reads_a_database_in_a_read_only_inbox(tmp_path):
    """The shore inbox is read-only: the database's nights are read (before: "unable to
    open database file", one failed row), nothing is written beside it, exit 0."""
    folder = inbox(tmp_path)
    write_good_database(folder / "ship.sqlite")
    prefix = _read_only(folder)
    if prefix is None:
        pytest.skip("no way to make a folder read-only for root here (unshare -m)")
    folder.chmod(0o555)
    try:
        args = [sys.executable, "-m", "dracc", "fleet", str(folder), "--workers", "1"]
        args += ["--out", str(tmp_path / "out")]
        p = subprocess.run([*prefix, *args], capture_output=True, text=True, timeout=WAIT_S)
    finally:
        folder.chmod(0o755)
    assert p.returncode == ExitCode.OK, p.stderr
    assert side_files(folder) == []
    t = pd.read_parquet(tmp_path / "out" / "fleet.parquet")
    assert set(t.vessel) == {GOOD, BAD} and (t.status == "ok").all()


def test_every_hostile_input_beside_a_good_one_through_the_cli(tmp_path):
    """All of them at once through ``dracc fleet``: one line each on stderr, the good
    vessel's tables written, exit 3 (some inputs failed), never 5, within the bound."""
    folder = inbox(tmp_path)
    for case, (write, _) in DOCUMENT_CASES.items():
        (folder / f"{case}.json").write_text(write(good_document(BAD)), encoding="utf-8")
    for case, (sql, _) in DATABASE_CASES.items():
        hostile_database(folder / f"{case}.sqlite", sql)
    out = tmp_path / "out"
    t0 = time.monotonic()
    p = subprocess.run(
        [sys.executable, "-m", "dracc", "fleet", str(folder), "--workers", "1", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=WAIT_S,
    )
    assert time.monotonic() - t0 < WAIT_S
    assert p.returncode == ExitCode.INPUT, p.stderr
    assert "Traceback" not in p.stderr and "internal error" not in p.stderr
    cases = len(DOCUMENT_CASES) + len(DATABASE_CASES)
    assert p.stderr.count("failed: inbox/") == cases
    for _, reason in (*DOCUMENT_CASES.values(), *DATABASE_CASES.values()):
        assert reason.split(" (")[0] in p.stderr.replace("\n  ", " ")
    assert len(json.loads((out / "fleet.json").read_text())["failures"]) == cases
    assert (out / "vessels" / GOOD / "fleet.csv").is_file()


def test_the_time_budget_ends_a_runaway_query(tmp_path):
    """A query that never ends (an endless recursive CTE) is aborted once the read's
    budget is spent: a StateError that says so, in about the budget."""
    db = write_good_database(tmp_path / "ship.sqlite")
    budget = Budget(0.5)
    t0 = time.monotonic()
    with pytest.raises(StateError, match=r"took longer than 0\.5 s"), guarded(db, budget):
        connect(db, budget).execute(f"{ENDLESS}SELECT count(*) FROM r").fetchone()
    assert time.monotonic() - t0 < 5.0


_RUNAWAY = textwrap.dedent(
    """
    import sys
    import dracc.pipeline.state_read as state_read
    from fleet_hostile import ENDLESS

    def endless(conn, path):  # past the schema check, a query that never ends
        print("querying", flush=True)
        conn.execute(ENDLESS + "SELECT count(*) FROM r").fetchone()

    state_read.check_schema = endless
    state_read.READ_BUDGET_S = 600.0
    from dracc.cli.main import main
    sys.argv = ["dracc", "fleet", *sys.argv[1:]]
    main()
    """
)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_a_signal_during_a_runaway_query_ends_the_run(tmp_path, signum):
    """A query running inside SQLite used to hold the process: SIGTERM and SIGINT were
    never acted on (only SIGKILL ended it).  The progress handler lets the signal
    through: the run ends at once, interrupted (exit 130), nothing written."""
    folder = inbox(tmp_path)
    write_good_database(folder / "ship.sqlite")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).parent)}
    p = subprocess.Popen(
        [
            sys.executable,
            "-c",
            _RUNAWAY,
            str(folder),
            "--workers",
            "1",
            "--out",
            str(tmp_path / "o"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
    )
    try:
        assert p.stdout is not None and p.stdout.readline() == b"querying\n"
        time.sleep(0.5)  # inside the query
        t0 = time.monotonic()
        p.send_signal(signum)
        _, err = p.communicate(timeout=WAIT_S)
    finally:
        p.kill()
    assert time.monotonic() - t0 < 10.0
    assert p.returncode == ExitCode.INTERRUPTED, err
    assert b"interrupted" in err and b"Traceback" not in err
    assert not (tmp_path / "o" / "fleet.json").exists()


def test_a_deep_document_is_refused_before_the_parser_recurses():
    """The depth is measured without recursion (200,000 levels: no RecursionError),
    strings do not count, and the audit document's own 10 levels pass."""
    with pytest.raises(ValueError, match="nested 200,000 levels deep"):
        jsonbound.loads(b"[" * 200_000 + b"]" * 200_000)
    assert jsonbound.nesting_depth(b'{"a": "[[[[\\"[[[", "b": [[1]]}') == 3
    assert jsonbound.loads(json.dumps(good_document())) == good_document()
    with pytest.raises(ValueError, match="NaN is not a JSON number"):
        jsonbound.loads(b"[NaN]")


def test_a_night_without_its_rejected_count_is_read(tmp_path):
    """Found by the fuzzer: a stored night whose ``rejected`` is NULL (the column allows
    it) ended the batch (``None / int``); it is read, its rejected rate empty."""
    folder = inbox(tmp_path)
    hostile_database(folder / "ship.sqlite", "UPDATE nights SET rejected = NULL;")
    res, elapsed = _run(folder, tmp_path / "out")
    assert not res.failures and elapsed < BOUND_S
    bad = res.table[res.table.vessel == BAD]
    assert len(bad) == 1 and bad.rejected_rate_pct.isna().all() and (bad.lines == 1000).all()


def test_a_unit_without_some_figures_is_read_and_one_without_its_channel_is_not(tmp_path):
    """Found by the fuzzer: an ``ins`` row without ``m_u`` ended the batch (KeyError);
    an absent figure is read as none, like a null one.  A row without its channel
    cannot be placed: one failed row."""
    folder = inbox(tmp_path)
    partial = {"unit": "ins1", "channel": "lat", "n": 25, "m_y": 224.0}
    (folder / "partial.json").write_text(json.dumps({**good_document(BAD), "ins": [partial]}))
    no_channel = {"unit": "ins1", "n": 25, "m_y": 224.0}
    bad = folder / "bad.json"
    bad.write_text(json.dumps({**good_document("Other"), "ins": [no_channel]}))
    res, elapsed = _run(folder, tmp_path / "out")
    assert [f["path"] for f in res.failures] == [str(bad)] and elapsed < BOUND_S
    assert "ins[0].channel: missing" in res.failures[0]["error"]
    row = res.table[res.table.vessel == BAD]
    assert len(row) == 1 and row.m_u.isna().all() and (row.m_y == 224.0).all()


def test_a_night_without_data_is_skipped_before_its_fields_are_checked(tmp_path):
    """A 'no data' document is skipped before its fields are read (a failed night's
    document may hold nulls anywhere), as before."""
    doc = {**good_document(BAD), "verdict": "no data", "ins": {"x": 1}}
    (tmp_path / "n.json").write_text(json.dumps(doc))
    assert expand_documents(discover([str(tmp_path / "n.json")])) == ([], {}, {})
