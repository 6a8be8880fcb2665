"""Interruptions: SIGINT (Ctrl-C), SIGTERM (a kill) and SIGKILL during ``analyze``,
``audit`` and ``fleet``, in real processes with bounded waits.

An interrupted run exits 130 with one line on stderr and leaves no partial report (every
file is written atomically: the old file or none, and no temporary ``.part`` file) and no
half-recorded night; a re-run completes the work.  SIGKILL cannot be caught: it may leave
a hidden ``.*.part`` temporary file, but never a partial file under the report's name and
never a partial night (SQLite rolls the transaction back).
"""

from __future__ import annotations

import json
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

WAIT_S = 120.0  #: bound on every wait for a process


def _main(*args) -> int:
    return main([str(a) for a in args])


def _env() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k != TEST_SLEEP_ENV}


def _start(args: list[str], env: dict | None = None, stdout=subprocess.DEVNULL) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "dracc", *map(str, args)],
        stdout=stdout,
        stderr=subprocess.PIPE,
        env=env or _env(),
    )


def _finish(p: subprocess.Popen) -> tuple[int, str]:
    try:
        _, err = p.communicate(timeout=WAIT_S)
    except subprocess.TimeoutExpired:
        p.kill()
        p.communicate()
        pytest.fail("process did not end within the bound after the signal")
    return p.returncode, err.decode("utf-8", "replace")


def _assert_interrupted(code: int, err: str) -> None:
    assert code == 130, err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert lines and lines[-1].startswith("error: interrupted"), err


def _no_leftovers(folder: Path) -> None:
    left = [p.name for p in folder.rglob("*") if p.name.endswith(".part")]
    assert not left, f"temporary files left behind: {left}"


def _children(pid: int) -> list[int]:
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as fh:
            return [int(x) for x in fh.read().split()]
    except OSError:
        return []


def _gone(pids: list[int], timeout_s: float = 30.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        alive = []
        for p in pids:
            try:
                with open(f"/proc/{p}/stat") as fh:
                    if fh.read().split(") ")[-1][0] != "Z":
                        alive.append(p)
            except OSError:
                pass
        if not alive:
            return True
        time.sleep(0.1)
    return False


# ------------------------------------------------------------------------ analyze


@pytest.fixture(scope="module")
def voyage(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("voyage")
    assert (
        main(
            [
                "simulate",
                "--out",
                str(root),
                "--hours",
                "2",
                "--seed",
                "8",
                "--name",
                "v",
                "--truth-hz",
                "0.01",
            ]
        )
        == 0
    )
    return root / "v.nmea"


def _analyze_args(log: Path, out: Path, json_to: str) -> list:
    return [
        "analyze",
        log,
        "--json",
        json_to,
        "--html",
        out / "report.html",
        "--out",
        out / "tables",
    ]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_analyze_interrupted_while_writing_reports(voyage, tmp_path, sig):
    """Deterministic: the JSON goes to a pipe nobody reads, so the process blocks inside
    the report writing (after the analysis); the signal arrives there.  No HTML, no
    tables, exit 130, one line on stderr."""
    out = tmp_path / "out"
    p = _start(_analyze_args(voyage, out, "-"), stdout=subprocess.PIPE)
    try:
        first = p.stdout.read(1)  # the analysis is done, the JSON is being written
        assert first == b"{"
        time.sleep(0.5)  # the 64 KiB pipe is full: the writer is blocked
        p.send_signal(sig)
        code, err = _finish(p)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    _assert_interrupted(code, err)
    assert not (out / "report.html").exists()
    assert not (out / "tables").exists() or not any((out / "tables").iterdir())
    if out.exists():
        _no_leftovers(out)


def test_analyze_interrupted_mid_run_then_rerun_completes(voyage, tmp_path):
    """SIGINT, SIGTERM and SIGKILL during the run (timed from a full run), then a re-run."""
    out = tmp_path / "out"
    # A warm-up first: in a fresh clone the first run also compiles every module, which
    # would make the timed run (and so every signal) far too late for the runs after it.
    _finish(_start(["--version"]))
    t0 = time.monotonic()
    code, err = _finish(_start(_analyze_args(voyage, out, str(out / "report.json"))))
    full_s = time.monotonic() - t0
    assert code == 0, err
    # Start-up (interpreter and imports) is a large share of a short run: time the signals
    # from its end, so that they land inside the work, wherever the machine's load puts it.
    t0 = time.monotonic()
    subprocess.run([sys.executable, "-c", "import dracc.cli.main"], check=True, env=_env())
    startup_s = min(time.monotonic() - t0, full_s)
    reference = json.loads((out / "report.json").read_text())
    interrupted = 0
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        # a few points inside the run; stop at the first signal that lands in it
        for frac in (0.5, 0.3, 0.7, 0.15, 0.85):
            for f in [*out.glob("report.*"), *(out / "tables").glob("*")]:
                f.unlink()
            p = _start(_analyze_args(voyage, out, str(out / "report.json")))
            time.sleep(startup_s + frac * (full_s - startup_s))
            p.send_signal(sig)
            code, err = _finish(p)
            # each report is whole or absent (they are written one after the other, each atomically)
            if (out / "report.json").exists():
                assert (
                    json.loads((out / "report.json").read_text())["period"] == reference["period"]
                )
            if (out / "report.html").exists():
                assert (out / "report.html").read_text().rstrip().endswith("</html>")
            if code == 0:  # it finished before the signal: try earlier or later
                continue
            if sig == signal.SIGKILL:
                assert code == -signal.SIGKILL
                for f in out.rglob(".*.part"):  # what a SIGKILL may leave: hidden, never the report
                    f.unlink()
                break
            if code == -sig:
                # the signal came while the interpreter was starting or finishing, outside main():
                # the default action, with nothing half-written
                assert "Traceback" not in err
                _no_leftovers(out)
                continue
            _assert_interrupted(code, err)
            _no_leftovers(out)
            interrupted += 1
            break
    assert interrupted >= 1  # SIGINT or SIGTERM landed inside the run at least once
    code, err = _finish(_start(_analyze_args(voyage, out, str(out / "report.json"))))
    assert code == 0, err
    again = json.loads((out / "report.json").read_text())
    assert again["period"] == reference["period"] and again["deviation"] == reference["deviation"]
    assert (out / "report.html").read_text().rstrip().endswith("</html>")


# ------------------------------------------------------------------------ audit


@pytest.fixture(scope="module")
def night_logs(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("nights")
    out = {}
    for night, seed in (("2026-11-19", 41), ("2026-11-20", 42)):
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
                    f"n-{night}",
                    *SPARSE_RATES,
                ]
            )
            == 0
        )
        out[night] = root / f"n-{night}.nmea"
    return out


def _nights(db: Path) -> list[str]:
    con = sqlite3.connect(db)
    try:
        assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        return [r[0] for r in con.execute("SELECT night FROM nights ORDER BY night")]
    finally:
        con.close()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_audit_interrupted_inside_its_transaction(night_logs, tmp_path, sig):
    """The audit's test hook holds it inside the recording transaction; the signal rolls
    it back: no half-recorded night; tonight's summary says the run was interrupted and
    nothing recorded (issue 32: never last night's); a re-run records the night."""
    db = tmp_path / "state.sqlite"
    summary = tmp_path / "summary.txt"
    assert _main(
        "audit",
        night_logs["2026-11-20"],
        "--db",
        db,
        "--vessel",
        "Aurora",
        "--summary",
        tmp_path / "before.txt",
    ) in (0, 1)
    env = {**_env(), TEST_SLEEP_ENV: "120"}
    p = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "dracc",
            "audit",
            str(night_logs["2026-11-19"]),
            "--db",
            str(db),
            "--vessel",
            "Aurora",
            "--summary",
            str(summary),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        env=env,
    )
    try:
        deadline = time.monotonic() + WAIT_S
        seen = b""
        while b"inside the transaction" not in seen:  # the hook announces itself on stderr
            if time.monotonic() > deadline or p.poll() is not None:
                pytest.fail(f"audit never reached its transaction: {seen!r}")
            seen += p.stderr.read1(4096)
        assert _nights(db) == ["2026-11-20"]  # a reader sees only committed nights
        p.send_signal(sig)
        code, err = _finish(p)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    _assert_interrupted(code, err)
    assert _nights(db) == ["2026-11-20"]
    assert summary.read_text().startswith(f"dracc audit: FAILED, exit {code} (")
    _no_leftovers(tmp_path)
    code = _main(
        "audit", night_logs["2026-11-19"], "--db", db, "--vessel", "Aurora", "--summary", summary
    )
    assert code in (0, 1)
    assert "state: recorded" in summary.read_text()
    assert _nights(db) == ["2026-11-19", "2026-11-20"]


# ------------------------------------------------------------------------ fleet


@pytest.fixture(scope="module")
def fleet_dir(night_logs, tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("fleet")
    for i, vessel in enumerate(("Aurora", "Borealis")):
        (root / vessel).mkdir()
        for night, log in night_logs.items():
            # distinct bytes per vessel (the cache is keyed by content)
            (root / vessel / f"{night}.nmea").write_bytes(log.read_bytes() + b"\r\n" * (i + 1))
    return root


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_fleet_interrupted_after_its_first_log(fleet_dir, tmp_path, sig):
    """Signal once the first log's result is cached: exit 130, no fleet tables, the
    worker processes end; a re-run takes the finished log from the cache and completes."""
    out = tmp_path / "report"
    p = _start(
        ["fleet", fleet_dir / "Aurora", fleet_dir / "Borealis", "--workers", "1", "--out", out]
    )
    try:
        deadline = time.monotonic() + WAIT_S
        kids: set[int] = set()
        while not list((out / "cache").rglob("*.json")) if (out / "cache").exists() else True:
            kids.update(_children(p.pid))
            if time.monotonic() > deadline or p.poll() is not None:
                pytest.fail("fleet never cached a log")
            time.sleep(0.02)
        kids.update(_children(p.pid))
        t0 = time.monotonic()
        p.send_signal(sig)
        code, err = _finish(p)
        took_s = time.monotonic() - t0
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    _assert_interrupted(code, err)
    # at once, not after the worker's running log (issue 32: 39 s); the engine's own test
    # is test_fleet_engines.test_sigint_to_the_main_process_stops_the_run_within_seconds
    assert took_s < 10.0, f"{took_s:.1f} s from the signal to the end"
    for name in ("fleet.parquet", "fleet.csv", "fleet.json", "fleet.html", "trends.parquet"):
        assert not (out / name).exists(), name
    _no_leftovers(out)
    assert _gone(sorted(kids)), "worker processes outlived the interrupted fleet run"
    cached = len(list((out / "cache").rglob("*.json")))
    assert 1 <= cached < 4
    code, err = _finish(
        _start(
            ["fleet", fleet_dir / "Aurora", fleet_dir / "Borealis", "--workers", "1", "--out", out]
        )
    )
    assert code == 0, err
    summary = json.loads((out / "fleet.json").read_text())
    assert summary["analysed"] == 4 - cached
