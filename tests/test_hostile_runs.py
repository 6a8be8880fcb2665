"""Issue 15, hostile and damaged input (fleet, audit, the CLI's start, the state file,
what reaches a terminal or a spreadsheet).  One test (or group) per reported case:

1. ``fleet`` skipped a FIFO among the logs without listing it as failed (exit 0
   possible): every input that is not a regular readable file is listed as failed, with
   why, without being opened, and the exit code is 3.
2. SIGTERM while ``fleet`` wrote its tables said "nothing partial was written" with most
   outputs already new: the outputs are published together (one rename), and the
   message says which set ``--out`` holds.
3. SIGTERM in the first moments of a run exited 143 instead of 130.
4. Two audits creating a new ``--db`` at once failed with "database is locked".
5. Control characters from a log reached the terminal raw; vessel names starting with
   ``=``, ``+``, ``-``, ``@`` went into ``fleet.csv`` as formulas; symbolic links in an
   audit (or fleet) folder were followed out of it.

Processes are real where the case is about a process (signals, two audits), with
bounded waits; a FIFO that dracc opened would block, so those tests run under an alarm.
"""

from __future__ import annotations

import contextlib
import json
import multiprocessing as mp
import os
import random
import signal
import socket
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import SPARSE_RATES
from test_fleet import CFG, fake_analyser

from dracc.cli.main import main
from dracc.core import atomic
from dracc.core.errors import ExitCode
from dracc.core.safetext import csv_cell, printable
from dracc.pipeline.audit import TEST_SLEEP_ENV as AUDIT_SLEEP_ENV
from dracc.pipeline.audit import choose_logs, input_problem
from dracc.pipeline.fleet import discover, run_fleet
from dracc.report.fleet_tables import TEST_SLEEP_ENV, write_tables

WAIT_S = 120.0  #: bound on every wait for a process
EVIL = "INS2\x1b]0;pwned\x07\x1b[2J\x9b31m"  #: OSC (window title), clear screen, C1 CSI


class _Hung(Exception):
    pass


@contextlib.contextmanager
def _bounded(seconds: int = 60):
    """Fail instead of hanging (opening a FIFO blocks until a writer comes)."""

    def ring(signum, frame):
        raise _Hung(f"still running after {seconds} s: something blocked")

    old = signal.signal(signal.SIGALRM, ring)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def _env(**extra) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in (TEST_SLEEP_ENV, AUDIT_SLEEP_ENV)}
    env.update({k: str(v) for k, v in extra.items()})
    return env


def _start(args, env=None) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "dracc", *map(str, args)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        env=env or _env(),
    )


def _finish(p: subprocess.Popen) -> tuple[int, str]:
    try:
        _, err = p.communicate(timeout=WAIT_S)
    except subprocess.TimeoutExpired:
        p.kill()
        p.communicate()
        pytest.fail("process did not end within the bound")
    return p.returncode, err.decode("utf-8", "replace")


def _wait_for(p: subprocess.Popen, text: bytes) -> bytes:
    deadline = time.monotonic() + WAIT_S
    seen = b""
    while text not in seen:
        if time.monotonic() > deadline or p.poll() is not None:
            p.kill()
            pytest.fail(f"the process never said {text!r}: {seen!r}")
        seen += p.stderr.read1(4096)
    return seen


def _fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


def _socket(path: Path) -> socket.socket:
    s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    s.bind(str(path))
    return s


def _fake_fleet(tmp_path: Path) -> Path:
    """Fake logs (read by ``fake_analyser``) for two vessels."""
    root = tmp_path / "fleet"
    for vessel, nights in (
        ("Aurora", [("2026-11-19", 100.0), ("2026-11-20", 130.0)]),
        ("Borealis", [("2026-11-20", 90.0)]),
    ):
        (root / vessel).mkdir(parents=True)
        for night, lat in nights:
            (root / vessel / f"{night}.nmea").write_text(json.dumps({"night": night, "lat": lat}))
    return root


# ------------------------------------------------------- 1. a FIFO among the logs


def test_fleet_fifo_among_the_logs_is_listed_as_failed(tmp_path):
    """A FIFO, a socket, a device, a dangling link, a folder where a log is expected and
    a link out of the vessel folder are failed tasks with why; none is opened (a FIFO's
    open would block this test until the alarm) and the analyser never sees them."""
    root = _fake_fleet(tmp_path)
    a = root / "Aurora"
    _fifo(a / "2026-11-21.nmea")
    sock = _socket(a / "gps.sock")
    (a / "gone.nmea").symlink_to(a / "never-written.nmea")
    (a / "archive.nmea").mkdir()  # a folder where *.nmea names files
    (tmp_path / "elsewhere.nmea").write_text("root:x:0:0:SECRET\n")
    (a / "other-ship.nmea").symlink_to(tmp_path / "elsewhere.nmea")
    (a / "link-inside.nmea").symlink_to(a / "2026-11-19.nmea")  # inside: followed, once
    try:
        with _bounded():
            tasks = discover([a, "/dev/zero"], "**/*.nmea")
            failed = {t.log: t.error for t in tasks if t.error}
            assert set(failed) == {
                "2026-11-21.nmea",
                "gone.nmea",
                "archive.nmea",
                "other-ship.nmea",
                "zero",
            }
            assert "is a FIFO (named pipe), not a log file" in failed["2026-11-21.nmea"]
            assert "dangling symbolic link" in failed["gone.nmea"]
            assert "is a directory, not a log file" in failed["archive.nmea"]
            assert "outside the vessel folder" in failed["other-ship.nmea"]
            assert "not followed" in failed["other-ship.nmea"]
            assert "is a device" in failed["zero"]
            assert all(t.sha256 is None for t in tasks if t.error)
            # the default pattern ** /* : the socket too (a folder is walked, not failed)
            every = {t.log: t.error for t in discover([a]) if t.error}
            assert "is a socket" in every["gps.sock"] and "archive.nmea" not in every
            res = run_fleet(tasks, CFG, tmp_path / "out", workers=1, analyser=fake_analyser)
    finally:
        sock.close()
    assert {f["log"] for f in res.failures} == set(failed)
    t = res.table
    assert set(t.loc[t["status"] == "failed", "log"]) == set(failed)
    assert t.loc[t["status"] == "failed", "error"].str.len().min() > 20
    ok = t[t["status"] == "ok"].drop_duplicates("log")
    assert sorted(ok["log"]) == ["2026-11-19.nmea", "2026-11-20.nmea"]  # the inside link: once
    calls = (root / "calls.log").read_text().split()
    assert sorted(calls) == ["2026-11-19.nmea", "2026-11-20.nmea"]  # nothing else was opened
    assert "SECRET" not in t.to_csv()


def test_fleet_unreadable_log_is_listed_as_failed(tmp_path, monkeypatch):
    """An unreadable file (permission denied; root reads everything, so the refusal is
    simulated) is listed as failed instead of ending the batch."""
    root = _fake_fleet(tmp_path)
    locked = root / "Aurora" / "2026-11-21.nmea"
    locked.write_text("{}")
    real_open = os.open

    def refusing(path, flags, *a, **kw):
        if os.fspath(path) == str(locked):
            raise PermissionError(13, "Permission denied", str(path))
        return real_open(path, flags, *a, **kw)

    monkeypatch.setattr(os, "open", refusing)
    tasks = discover([root / "Aurora"])
    bad = [t for t in tasks if t.error]
    assert [t.log for t in bad] == ["2026-11-21.nmea"]
    assert "cannot read: Permission denied" in bad[0].error


def test_input_problem_never_opens_what_could_block(tmp_path):
    with _bounded():
        assert input_problem(_fifo(tmp_path / "f")).startswith("is a FIFO")
        assert input_problem("/dev/null").startswith("is a device")
        assert input_problem(tmp_path) == "is a directory, not a log file"
        assert input_problem(tmp_path / "nope") == "no such file"
        (tmp_path / "loop").symlink_to(tmp_path / "loop")
        assert input_problem(tmp_path / "loop").startswith("cannot read")
        (tmp_path / "log.nmea").write_text("$GPGGA\n")
        assert input_problem(tmp_path / "log.nmea") is None


def test_fleet_cli_fifo_among_the_logs_exits_3(tmp_path):
    """The whole command on a vessel folder holding only inputs that cannot be read: no
    hang, each listed as failed on stderr, in the table and in fleet.json; exit 3."""
    v = tmp_path / "fleet" / "Aurora"
    v.mkdir(parents=True)
    _fifo(v / "2026-11-20.nmea")
    (v / "gone.nmea").symlink_to(v / "missing.nmea")
    out = tmp_path / "out"
    code, err = _finish(_start(["fleet", v, "/dev/zero", "--workers", "1", "--out", out]))
    assert code == ExitCode.INPUT, err
    assert (
        "is a FIFO (named pipe)" in err and "dangling symbolic link" in err and "is a device" in err
    )
    assert "3 failed" in err and "Traceback" not in err
    summary = json.loads((out / "fleet.json").read_text())
    assert len(summary["failures"]) == 3 and summary["analysed"] == 0
    t = pd.read_parquet(out / "fleet.parquet")
    assert (t["status"] == "failed").all() and len(t) == 3


# ------------------------------------------- 2. the fleet outputs appear together


def _snapshot(out: Path) -> dict[str, bytes]:
    """Every output as a reader sees it (through the links), without the cache and the sets."""
    got = {}
    for p in sorted(out.rglob("*")):
        rel = p.relative_to(out)
        if rel.parts[0] in ("cache", atomic.RUNS, atomic.CURRENT) or not p.is_file():
            continue
        got[rel.as_posix()] = p.read_bytes()
    for folder in ("vessels", "tables"):  # rglob does not descend into a linked folder
        if (out / folder).is_dir():
            for p in sorted((out / folder).rglob("*")):
                if p.is_file():
                    got[f"{folder}/{p.relative_to(out / folder).as_posix()}"] = p.read_bytes()
    return got


def test_fleet_outputs_appear_together_or_not_at_all(tmp_path, monkeypatch):
    """An interrupt half-way through writing the new outputs leaves every old output
    exactly as it was, and nothing of the new set; a complete run replaces them all."""
    root = _fake_fleet(tmp_path)
    out = tmp_path / "out"
    one = run_fleet(discover([root / "Aurora"]), CFG, out, workers=1, analyser=fake_analyser)
    write_tables(one, out, extra={"fleet.html": "<html>one</html>"})
    old = _snapshot(out)
    assert {
        "fleet.parquet",
        "fleet.csv",
        "trends.parquet",
        "trends.csv",
        "fleet.json",
        "fleet.html",
        "vessels/Aurora/fleet.csv",
        "vessels/Aurora/trends.csv",
    } <= set(old)
    both = run_fleet(
        discover([root / "Aurora", root / "Borealis"]), CFG, out, workers=1, analyser=fake_analyser
    )
    import dracc.report.fleet_tables as fleet_mod  # write_tables looks csv_text up here

    real_csv = fleet_mod.csv_text
    calls = []

    def interrupted(df):
        calls.append(1)
        if len(calls) == 3:  # parquet and CSV of both tables, then the vessels: stop there
            raise KeyboardInterrupt
        return real_csv(df)

    monkeypatch.setattr(fleet_mod, "csv_text", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_tables(both, out, extra={"fleet.html": "<html>both</html>"})
    assert _snapshot(out) == old
    assert [e for e in os.listdir(out / atomic.RUNS) if e.startswith("tmp-")] == []
    monkeypatch.setattr(fleet_mod, "csv_text", real_csv)
    written = write_tables(both, out, extra={"fleet.html": "<html>both</html>"})
    new = _snapshot(out)
    assert set(new) == {p.relative_to(out.resolve()).as_posix() for p in written}
    assert "vessels/Borealis/fleet.csv" in new and new["fleet.html"] == b"<html>both</html>"
    assert json.loads(new["fleet.json"])["vessels"] == ["Aurora", "Borealis"]
    # the current set and the previous one are kept, nothing else
    assert len(os.listdir(out / atomic.RUNS)) == 2


def test_fleet_outputs_written_by_an_older_dracc_are_replaced_whole(tmp_path):
    """A folder holding plain files from before (no .current link) is taken over
    without a moment in which it holds part of either set."""
    root = _fake_fleet(tmp_path)
    out = tmp_path / "out"
    (out / "vessels" / "Gone").mkdir(parents=True)
    (out / "vessels" / "Gone" / "fleet.csv").write_text("old\n")
    for name in ("fleet.csv", "fleet.json", "fleet.html", "trends.csv"):
        (out / name).write_text(f"old {name}\n")
    res = run_fleet(discover([root / "Aurora"]), CFG, out, workers=1, analyser=fake_analyser)
    write_tables(res, out, extra={"fleet.html": "<html>new</html>"})
    snap = _snapshot(out)
    assert snap["fleet.html"] == b"<html>new</html>" and "vessels/Gone/fleet.csv" not in snap
    assert all(not v.startswith(b"old") for v in snap.values())
    for name in ("fleet.csv", "vessels"):
        assert os.readlink(out / name) == os.path.join(atomic.CURRENT, name)


def test_fleet_outputs_without_symbolic_links_are_renamed_with_signals_held(tmp_path, monkeypatch):
    """Where the file system has no symbolic links, the outputs are renamed into place."""
    root = _fake_fleet(tmp_path)
    out = tmp_path / "out"
    monkeypatch.setattr(atomic, "_symlinks_work", lambda folder: False)
    res = run_fleet(
        discover([root / "Aurora", root / "Borealis"]), CFG, out, workers=1, analyser=fake_analyser
    )
    write_tables(res, out, extra={"fleet.html": "<html/>"})
    write_tables(res, out, extra={"fleet.html": "<html>2</html>"})
    assert (
        not (out / "fleet.csv").is_symlink()
        and (out / "fleet.html").read_text() == "<html>2</html>"
    )
    assert (out / "vessels" / "Borealis" / "trends.csv").is_file()
    assert os.listdir(out / atomic.RUNS) == []


def _hostile_vessels(root: Path, names: list[str]) -> list[Path]:
    """Vessel folders holding one FIFO each: a run lists them as failed without analysing
    anything, so it is quick, yet writes a complete set of outputs."""
    folders = []
    for n in names:
        (root / n).mkdir(parents=True, exist_ok=True)
        if not (root / n / "log.nmea").exists():
            _fifo(root / n / "log.nmea")
        folders.append(root / n)
    return folders


def _which_set(out: Path, sets: dict[str, set[str]]) -> str | None:
    """Which input set every output of ``out`` belongs to ('old', 'new' or None when
    there are none); fails on a mix."""
    snap = _snapshot(out)
    if not snap:
        return None
    names = {
        "fleet.parquet",
        "fleet.csv",
        "trends.parquet",
        "trends.csv",
        "fleet.json",
        "fleet.html",
    }
    assert names <= set(snap), f"incomplete set: {sorted(snap)}"
    seen = {
        "fleet.json": set(json.loads(snap["fleet.json"])["vessels"]),
        "fleet.parquet": set(pd.read_parquet(out / "fleet.parquet")["vessel"]),
        "fleet.csv": set(pd.read_csv(out / "fleet.csv")["vessel"]),
        "vessels/": {k.split("/")[1] for k in snap if k.startswith("vessels/")},
        "fleet.html": {
            v for s in sets.values() for v in s if f"<li>{v} / " in snap["fleet.html"].decode()
        },
    }
    kinds = {k: [name for name, s in sets.items() if s == v] for k, v in seen.items()}
    assert all(len(v) == 1 for v in kinds.values()), f"outputs of different runs: {seen}"
    found = {v[0] for v in kinds.values()}
    assert len(found) == 1, f"outputs of different runs: {kinds}"
    return found.pop()


@pytest.mark.slow
def test_fleet_sigterm_or_sigkill_while_writing_leaves_the_old_set_whole(tmp_path):
    """The test hook holds the run half-way through writing its outputs (the tables are
    written, the per-vessel files and the page not yet): SIGTERM says the outputs are the
    previous run's, and they are; SIGKILL leaves them whole too; a re-run publishes the
    new set whole."""
    root = tmp_path / "fleet"
    sets = {"old": {"Aurora", "Borealis"}, "new": {"Aurora", "Borealis", "Cetus"}}
    old_in = _hostile_vessels(root, sorted(sets["old"]))
    new_in = _hostile_vessels(root, sorted(sets["new"]))
    out = tmp_path / "out"
    code, err = _finish(_start(["fleet", *old_in, "--out", out]))
    assert code == ExitCode.INPUT, err
    before = _snapshot(out)
    assert _which_set(out, sets) == "old"
    for sig in (signal.SIGTERM, signal.SIGKILL):
        p = _start(["fleet", *new_in, "--out", out], env=_env(**{TEST_SLEEP_ENV: 60}))
        _wait_for(p, b"while writing the outputs")
        p.send_signal(sig)
        code, err = _finish(p)
        if sig == signal.SIGTERM:
            assert code == ExitCode.INTERRUPTED, err
            last = err.strip().splitlines()[-1]
            assert last.startswith("error: interrupted; nothing partial was written"), err
            assert "previous run" in last
        else:
            assert code == -signal.SIGKILL
        assert _snapshot(out) == before
    code, err = _finish(_start(["fleet", *new_in, "--out", out]))
    assert code == ExitCode.INPUT, err
    assert _which_set(out, sets) == "new"
    left = [e for e in os.listdir(out / atomic.RUNS) if e.startswith("tmp-")]
    assert left == []  # the killed run's staging folder was collected


@pytest.mark.slow
def test_fleet_killed_at_random_moments_never_mixes_old_and_new(tmp_path):
    """SIGTERM or SIGKILL at random moments of runs that alternate between two input sets:
    after each, every output belongs to one run; after a SIGTERM the message names the
    set that is there."""
    root = tmp_path / "fleet"
    sets = {"a": {f"V{i:03d}" for i in range(60)}, "b": {f"V{i:03d}" for i in range(30, 100)}}
    inputs = {k: _hostile_vessels(root, sorted(v)) for k, v in sets.items()}
    out = tmp_path / "out"
    t0 = time.monotonic()
    code, err = _finish(_start(["fleet", *inputs["a"], "--out", out]))
    full_s = time.monotonic() - t0
    assert code == ExitCode.INPUT, err
    rng = random.Random(15)
    there = "a"
    outcomes = []
    for trial in range(8):
        want = "b" if there == "a" else "a"
        sig = (signal.SIGTERM, signal.SIGKILL)[trial % 2]
        p = _start(["fleet", *inputs[want], "--out", out])
        time.sleep(rng.uniform(0.3, 1.1) * full_s)
        p.send_signal(sig)
        code, err = _finish(p)
        now = _which_set(out, sets)
        assert now in (there, want)
        if code == ExitCode.INTERRUPTED:
            last = err.strip().splitlines()[-1]
            if "new fleet outputs were already complete" in last:
                assert now == want, err
            elif last == "error: interrupted; nothing partial was written":
                assert now == there, err  # before the command began (loading, parsing)
            elif "interrupted while starting" not in last:
                assert "previous run" in last and now == there, err
        outcomes.append((sig.name, code, now != there))
        there = now
    assert _which_set(out, sets) == there
    assert any(code in (ExitCode.INTERRUPTED, -signal.SIGKILL) for _, code, _ in outcomes), outcomes


# --------------------------------------------- 3. SIGTERM in the first moments


def _bare_start_s() -> float:
    """How long this interpreter takes to start and end with nothing to do."""
    best = 10.0
    for _ in range(3):
        t0 = time.monotonic()
        subprocess.run([sys.executable, "-c", "pass"], check=True)
        best = min(best, time.monotonic() - t0)
    return best


def _wait_for_sigterm_handler(pid: int, timeout_s: float = 30.0) -> None:
    """Until the process catches SIGTERM (/proc/PID/status SigCgt): dracc installs its
    handler first thing; under a loaded CI the interpreter alone could take longer than
    the earliest delay (one run killed by the signal at 0.13 s)."""
    status = Path(f"/proc/{pid}/status")
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            lines = status.read_text().splitlines()
        except OSError:
            return  # gone, or no /proc: the caller's poll() says which
        caught = next((ln.split()[1] for ln in lines if ln.startswith("SigCgt:")), "0")
        if int(caught, 16) & (1 << (signal.SIGTERM - 1)):
            return
        time.sleep(0.002)


@pytest.mark.slow
@pytest.mark.parametrize("entry", ["module", "script"])
def test_sigterm_in_the_first_moments_exits_130(tmp_path, entry):
    """A SIGTERM while the libraries load (or just after) ends the run with exit 130 and
    one 'error: interrupted' line, not by the signal (143).  The command, once loaded,
    sleeps in the fleet test hook, so every signal lands in dracc's own code."""
    v = tmp_path / "fleet" / "Aurora"
    v.mkdir(parents=True)
    _fifo(v / "log.nmea")
    if entry == "script":
        script = Path(sys.executable).parent / "dracc"
        if not script.exists():
            pytest.skip("no dracc script beside this interpreter")
        cmd = [str(script)]
    else:
        cmd = [sys.executable, "-m", "dracc"]
    bare = _bare_start_s()
    env = _env(**{TEST_SLEEP_ENV: 60})
    for delay in (2 * bare + 0.02, 0.15, 0.25, 0.4, 0.7, 1.2):
        p = subprocess.Popen(
            [*cmd, "fleet", v, "--out", tmp_path / "out"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            env=env,
        )
        t0 = time.monotonic()
        _wait_for_sigterm_handler(p.pid)  # before it, the signal is not dracc's to answer
        time.sleep(max(delay - (time.monotonic() - t0), 0.0))
        assert p.poll() is None
        p.send_signal(signal.SIGTERM)
        code, err = _finish(p)
        assert code == ExitCode.INTERRUPTED, (delay, code, err)
        assert "Traceback" not in err
        assert err.strip().splitlines()[-1].startswith("error: interrupted"), err


# ------------------------------------------- 4. two audits creating a new database


def _open_new_db(path: str, barrier, results) -> None:
    from dracc.pipeline.state import StateStore

    barrier.wait()
    try:
        with StateStore(path, busy_timeout_s=30) as store:
            results.put(("ok", store.journal_mode, store.vessels()))
    except Exception as err:  # the failure is the result
        results.put(("failed", repr(err), None))


@pytest.mark.slow
def test_two_audits_creating_a_new_database_at_once(tmp_path):
    """Four processes released together open one new database, 30 times: none fails
    ("database is locked" used to hit 27 % of such opens), each sees WAL and the schema."""
    ctx = mp.get_context("fork")
    failures = []
    for k in range(30):
        db = str(tmp_path / f"new-{k}.sqlite")
        barrier = ctx.Barrier(4)
        results = ctx.Queue()
        procs = [ctx.Process(target=_open_new_db, args=(db, barrier, results)) for _ in range(4)]
        for p in procs:
            p.start()
        got = [results.get(timeout=WAIT_S) for _ in procs]
        for p in procs:
            p.join(WAIT_S)
        failures += [g for g in got if g[0] != "ok"]
        assert all(g[1] == "wal" for g in got if g[0] == "ok")
        con = sqlite3.connect(db)
        try:
            assert con.execute("SELECT value FROM meta WHERE key = 'schema'").fetchall() == [("3",)]
        finally:
            con.close()
    assert failures == []


@pytest.mark.slow
def test_two_audit_processes_creating_a_new_database_at_once(tmp_path):
    """The CLI variant: two `dracc audit` on an empty folder (a night without logs, quick)
    creating the same new database at once, three times: both record or find the night."""
    empty = tmp_path / "logs"
    empty.mkdir()
    for k in range(3):
        db = tmp_path / f"cli-{k}.sqlite"
        procs = [
            _start(
                [
                    "audit",
                    empty,
                    "--date",
                    "2026-11-20",
                    "--db",
                    db,
                    "--vessel",
                    "Aurora",
                    "--summary",
                    tmp_path / f"s-{k}-{i}.txt",
                ]
            )
            for i in range(2)
        ]
        for p in procs:
            code, err = _finish(p)
            assert code == ExitCode.INPUT, err  # no logs for the night: exit 3, recorded
            assert "locked" not in err and "busy" not in err, err
        con = sqlite3.connect(db)
        try:
            assert con.execute("SELECT count(*) FROM nights").fetchone()[0] == 1
        finally:
            con.close()


# ------------------------------------------------------------------- 5. escaping


def test_printable_escapes_control_characters_and_keeps_text():
    assert printable("GYRO") == "GYRO"
    assert printable("Nordlys ★ 北斗丸 ä") == "Nordlys ★ 北斗丸 ä"
    assert printable(EVIL) == "INS2\\x1b]0;pwned\\x07\\x1b[2J\\x9b31m"
    assert printable("a\rb\nc\td\x00\x7f") == "a\\x0db\\x0ac\\x09d\\x00\\x7f"
    assert printable("abc\u202egpj.exe") == "abc\\u202egpj.exe"  # right-to-left override
    assert printable("log\udcff.nmea") == "log\\udcff.nmea"  # an undecodable byte of a name
    assert printable("\u00a0non-breaking") == "\u00a0non-breaking"


def _hostile_mcap(tmp_path: Path) -> Path:
    """A simulated hour as MCAP whose INS2 topics carry terminal escape sequences."""
    from dracc.core.config import IngestConfig
    from dracc.ingest.mcap import read_mcap
    from dracc.sim.mcap_out import write_mcap

    assert (
        main(
            [
                "simulate",
                "--out",
                str(tmp_path / "sim"),
                "--hours",
                "1",
                "--seed",
                "3",
                "--format",
                "mcap-json",
                "--name",
                "v",
                *SPARSE_RATES,
            ]
        )
        == 0
    )
    r = read_mcap(tmp_path / "sim" / "v.mcap", IngestConfig())
    frames = {}
    for kind, df in r.frames.items():
        src = np.array(df["source"].astype(object).to_numpy(), dtype=object)
        src[src == "INS2"] = EVIL
        frames[kind] = df.assign(source=src)
    return write_mcap(
        frames, {"GYRO": "compass", "LOG": "log", "GNSS": "gnss"}, tmp_path / "evil.mcap"
    )


@pytest.mark.slow
def test_control_characters_in_mcap_topics_never_reach_the_terminal(tmp_path, run_cli):
    log = _hostile_mcap(tmp_path)
    for args in (["inspect", log], ["analyze", log]):
        code, stdout, stderr = run_cli(*args)
        assert code == 0, stderr
        for text in (stdout, stderr):
            assert "\x1b" not in text and "\x07" not in text and "\x9b" not in text, args
        assert "INS2\\x1b]0;pwned\\x07\\x1b[2J\\x9b31m" in stdout, args
    # an error line naming the source keys (every message goes through the same consoles)
    code, stdout, stderr = run_cli("analyze", log, "--role", "NOPE=ins1")
    assert code != 0 and "\x1b" not in stderr and "\x07" not in stderr
    assert "INS2\\x1b]0;pwned" in stderr


def test_fleet_csv_neutralises_formula_injection(tmp_path):
    """Vessel and log names starting like a formula are quoted in every CSV (per OWASP:
    a leading single quote); Parquet keeps them raw; numbers stay numbers."""
    root = tmp_path / "fleet"
    names = ["=HYPERLINK(1)", "+SUM(A1)", "-2+3", "@cmd", "\tTab"]
    for i, vessel in enumerate(names):
        (root / vessel).mkdir(parents=True)
        (root / vessel / "=1+1.nmea").write_text(
            json.dumps({"night": "2026-11-20", "lat": 100.0 + i})
        )
    out = tmp_path / "out"
    res = run_fleet(
        discover([root / n for n in names]), CFG, out, workers=1, analyser=fake_analyser
    )
    write_tables(res, out)
    raw = pd.read_parquet(out / "fleet.parquet")
    assert set(raw["vessel"]) == set(names) and set(raw["log"]) == {"=1+1.nmea"}
    assert csv_cell("-0.5") == "'-0.5" and csv_cell(-0.5) == -0.5
    for rel in [
        "fleet.csv",
        "trends.csv",
        *(f"vessels/{d}/fleet.csv" for d in os.listdir(out / "vessels")),
    ]:
        df = pd.read_csv(out / rel, dtype=str, keep_default_na=False)
        for col in ("vessel", "log"):
            if col in df:
                assert df[col].map(lambda s: s[:1] not in "=+-@\t\r").all(), (rel, df[col].tolist())
    csv = pd.read_csv(out / "fleet.csv", dtype=str, keep_default_na=False)
    # a control character is escaped as on the terminal (issue 33): a tab starts no formula
    shown = {"'" + n if n[0] != "\t" else printable(n) for n in names}
    assert set(csv["vessel"]) == shown and set(csv["log"]) == {"'=1+1.nmea"}
    num = pd.read_csv(out / "fleet.csv")
    assert num["m_y"].dtype == "float64"


@pytest.fixture(scope="module")
def night_log(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("night")
    assert (
        main(
            [
                "simulate",
                "--out",
                str(root),
                "--hours",
                "2",
                "--seed",
                "41",
                "--start",
                "2026-11-20T00:00:00Z",
                "--name",
                "nav-2026-11-20",
                *SPARSE_RATES,
            ]
        )
        == 0
    )
    return root / "nav-2026-11-20.nmea"


@pytest.mark.slow
def test_audit_folder_symlink_outside_is_not_followed(tmp_path, night_log):
    """A link in the audit folder to a file outside it is not read (its first lines used
    to be copied into the report as rejected examples): the summary and the JSON list it
    under 'not checked' with why; a FIFO there is skipped the same way, without a hang; a
    link to a file inside the folder is followed (once)."""
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / night_log.name).write_bytes(night_log.read_bytes())
    (logs / "copy-2026-11-20.nmea").symlink_to(logs / night_log.name)
    secret = tmp_path / "secret.txt"
    secret.write_text("root:x:0:0:SECRET-PASSWORD-LINE\n" * 3)
    (logs / "evil-2026-11-20.nmea").symlink_to(secret)
    _fifo(logs / "pipe-2026-11-20.nmea")
    summary, doc = tmp_path / "summary.txt", tmp_path / "audit.json"
    with _bounded(300):
        code = main(
            [
                "audit",
                str(logs),
                "--date",
                "2026-11-20",
                "--db",
                str(tmp_path / "a.sqlite"),
                "--vessel",
                "Aurora",
                "--summary",
                str(summary),
                "--json",
                str(doc),
            ]
        )
    assert code in (0, 1)
    text = summary.read_text()
    assert "evil-2026-11-20.nmea: symbolic link to" in text and "not followed" in text
    assert "pipe-2026-11-20.nmea: is a FIFO (named pipe)" in text
    d = json.loads(doc.read_text())
    skipped = {Path(n["name"]).name: n["why"] for n in d["not_checked"] if n["check"] == "logs"}
    assert set(skipped) == {"evil-2026-11-20.nmea", "pipe-2026-11-20.nmea"}
    assert str(secret) in skipped["evil-2026-11-20.nmea"]
    assert d["logs"]["files"] == [str((logs / night_log.name).resolve())]
    for t in (text, doc.read_text()):
        assert "SECRET-PASSWORD" not in t


def test_audit_folder_holding_only_outside_links_is_a_night_without_data(tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    (tmp_path / "secret.txt").write_text("SECRET\n")
    (logs / "nav-2026-11-20.nmea").symlink_to(tmp_path / "secret.txt")
    choice_err = None
    try:
        choose_logs([logs], "2026-11-20", "*")
    except Exception as err:  # NoLogsError: the skipped link is named in the message
        choice_err = str(err)
    assert choice_err and "skipped" in choice_err and "not followed" in choice_err
    summary = tmp_path / "s.txt"
    code = main(
        [
            "audit",
            str(logs),
            "--date",
            "2026-11-20",
            "--db",
            str(tmp_path / "a.sqlite"),
            "--summary",
            str(summary),
        ]
    )
    assert code == ExitCode.INPUT
    assert "not followed" in summary.read_text() and "SECRET" not in summary.read_text()


def test_audit_given_a_fifo_says_what_it_is(tmp_path, run_cli):
    fifo = _fifo(tmp_path / "nav.nmea")
    with _bounded():
        code, _, err = run_cli("audit", fifo, "--db", tmp_path / "a.sqlite")
    assert code == ExitCode.INPUT
    assert "is a FIFO (named pipe), not a log file" in err


def test_analyze_tables_csv_quote_formula_cells(tmp_path, monkeypatch):
    """`analyze --out` CSVs: a source key that starts like a formula is quoted; numbers
    (a negative one too) stay numbers; Parquet keeps the raw text."""
    import pandas as pd

    from dracc.report import tables

    df = pd.DataFrame({"source": ['=HYPERLINK("x")', "GNSS"], "value": [-0.5, 1.0]})
    monkeypatch.setattr(tables, "frames", lambda a: {"t": df})
    tables.write_tables(None, tmp_path)
    text = (tmp_path / "t.csv").read_text()
    assert "'=HYPERLINK" in text and "-0.5" in text
    assert pd.read_parquet(tmp_path / "t.parquet")["source"][0].startswith("=HYPERLINK")
