"""Two audits at once on one database, and an audit killed inside its transaction.

Real processes (``python -m dracc audit``); the test hook ``DRACC_AUDIT_TEST_SLEEP_S``
makes an audit announce itself on stderr and sleep inside its recording transaction.
"""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import SPARSE_RATES

from dracc.cli.main import main
from dracc.pipeline.audit import TEST_SLEEP_ENV

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("nights")
    out = {}
    for night, seed in (("2026-11-19", 21), ("2026-11-20", 22)):
        assert (
            main(
                [
                    "simulate",
                    "--out",
                    str(root),
                    "--hours",
                    "2",
                    "--seed",
                    str(seed),
                    "--start",
                    f"{night}T00:00:00Z",
                    "--name",
                    f"nav-{night}",
                    *SPARSE_RATES,
                ]
            )
            == 0
        )
        out[night] = root / f"nav-{night}.nmea"
    return out


def _start(log: Path, db: Path, tmp: Path, tag: str, sleep_s: float | None = None):
    env = {k: v for k, v in os.environ.items() if k != TEST_SLEEP_ENV}
    if sleep_s is not None:
        env[TEST_SLEEP_ENV] = str(sleep_s)
    errf = open(tmp / f"{tag}.err", "w+")  # noqa: SIM115 - closed in _finish
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "dracc",
            "audit",
            str(log),
            "--db",
            str(db),
            "--vessel",
            "Aurora",
            "--summary",
            str(tmp / f"{tag}.txt"),
        ],
        stdout=subprocess.DEVNULL,
        stderr=errf,
        env=env,
    )
    proc.errfile = errf
    proc.tag = tag
    return proc


def _wait_in_transaction(proc, timeout_s: float = 90.0) -> None:
    """Until the process says it sleeps inside its transaction (bounded)."""
    deadline = time.monotonic() + timeout_s
    path = Path(proc.errfile.name)
    while time.monotonic() < deadline:
        if "inside the transaction" in path.read_text():
            return
        if proc.poll() is not None:
            pytest.fail(f"{proc.tag} ended early ({proc.returncode}): {path.read_text()}")
        time.sleep(0.05)
    proc.kill()
    pytest.fail(f"{proc.tag} never reached its transaction")


def _finish(proc, tmp: Path, timeout_s: float = 120.0) -> tuple[int, str, str]:
    try:
        code = proc.wait(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.errfile.close()
    summary = tmp / f"{proc.tag}.txt"
    return (
        code,
        summary.read_text() if summary.exists() else "",
        Path(proc.errfile.name).read_text(),
    )


def _nights(db: Path) -> list[tuple]:
    con = sqlite3.connect(db)
    try:
        assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        return con.execute("SELECT id, night FROM nights ORDER BY id").fetchall()
    finally:
        con.close()


def _inprocess(log: Path, db: Path, tmp: Path, tag: str) -> tuple[int, str]:
    summary = tmp / f"{tag}.txt"
    code = main(
        ["audit", str(log), "--db", str(db), "--vessel", "Aurora", "--summary", str(summary)]
    )
    return code, summary.read_text()


def test_two_audits_at_once_on_one_database(logs, tmp_path):
    db = tmp_path / "state.sqlite"
    first = _start(logs["2026-11-19"], db, tmp_path, "first", sleep_s=3)
    try:
        _wait_in_transaction(first)
        # while the other process holds the write lock, this process audits another night
        # (it waits on the busy timeout), then the same night again
        t0 = time.monotonic()
        other = _inprocess(logs["2026-11-20"], db, tmp_path, "other")
        waited_s = time.monotonic() - t0
        same = _inprocess(logs["2026-11-19"], db, tmp_path, "same")
        code, summary, err = _finish(first, tmp_path)
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
    assert code in (0, 1) and "error" not in err.lower(), err
    assert other[0] in (0, 1) and same[0] in (0, 1)
    assert "state: recorded" in summary and "state: recorded" in other[1]
    assert "state: unchanged" in same[1]  # recorded once
    rows = _nights(db)
    # the first audit committed before the other could write: it has the first row id
    assert [n for _, n in rows] == ["2026-11-19", "2026-11-20"]
    assert waited_s > 0.5  # (not a timing test: the other audit had to queue behind the lock)


def test_killed_audit_leaves_no_partial_night(logs, tmp_path):
    db = tmp_path / "state.sqlite"
    code, _ = _inprocess(logs["2026-11-20"], db, tmp_path, "before")
    assert code in (0, 1)
    victim = _start(logs["2026-11-19"], db, tmp_path, "victim", sleep_s=120)
    try:
        _wait_in_transaction(victim)
        # a reader during the open transaction sees only committed nights (WAL)
        assert [n for _, n in _nights(db)] == ["2026-11-20"]
        victim.send_signal(signal.SIGKILL)
        victim.wait(timeout=30)
    finally:
        if victim.poll() is None:
            victim.kill()
            victim.wait()
        victim.errfile.close()
    assert victim.returncode == -signal.SIGKILL
    assert [n for _, n in _nights(db)] == ["2026-11-20"]  # no partial night
    con = sqlite3.connect(db)
    assert (
        con.execute(
            "SELECT COUNT(*) FROM unit_stats us JOIN nights n ON n.id = us.night_id "
            "WHERE n.night = '2026-11-19'"
        ).fetchone()[0]
        == 0
    )
    con.close()
    # a re-run completes and records the night as new
    code, summary = _inprocess(logs["2026-11-19"], db, tmp_path, "rerun")
    assert code in (0, 1)
    assert "state: recorded" in summary
    assert sorted(n for _, n in _nights(db)) == ["2026-11-19", "2026-11-20"]
