"""The fleet's engines (dracc.pipeline.fleet.engines): batches by folder and size, one
result per log whatever a batch holds, batched equal to unbatched, and a real Dask
scheduler with a worker on loopback (subprocesses, bounded waits, always torn down)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
from test_fleet import CFG, _fleet, fake_analyser
from test_fleet_cli import _free_port, _stop
from test_interrupt import _children, _gone

from dracc.pipeline.fleet import LogTask, discover, engines, run_fleet
from dracc.pipeline.fleet.engines import plan_batches, run_local


def raising_analyser(path: str, cfg) -> dict:
    """``fake_analyser``, but a log reading RAISE makes it raise (as a dracc bug would)."""
    if Path(path).read_text(encoding="utf-8").startswith("RAISE"):
        raise RuntimeError("an unforeseen state")
    return fake_analyser(path, cfg)


def dying_analyser(path: str, cfg) -> dict:
    """A log reading DIE kills its worker process (a segfault, the OOM killer)."""
    if Path(path).read_text(encoding="utf-8").startswith("DIE"):
        os._exit(3)
    return fake_analyser(path, cfg)


def _files(root: Path, sizes: dict[str, list[int]]) -> list[LogTask]:
    tasks = []
    for folder, ss in sizes.items():
        (root / folder).mkdir(parents=True)
        for i, n in enumerate(ss):
            p = root / folder / f"{i}.log"
            p.write_bytes(b"x" * n)
            tasks.append(LogTask(folder, str(p), p.name, None))
    return tasks


def _names(batches) -> list[list[str]]:
    return [[f"{Path(t.path).parent.name}/{t.log}" for t in b] for b in batches]


def test_batches_by_folder_first_fit_decreasing_largest_first(tmp_path):
    tasks = _files(tmp_path, {"A": [300, 500, 100, 300, 200], "B": [50, 900]})
    # 500 bytes a batch (above it: alone); first-fit decreasing inside each folder, by hand:
    # A: 500 | 300+200 | 300+100;  B: 900 | 50;  then by bytes: 900, 500, 500, 400, 50
    batches = plan_batches(tasks, workers=1, batch_bytes=500)
    assert _names(batches) == [["B/1.log"], ["A/1.log"], ["A/0.log", "A/4.log"]] + [
        ["A/3.log", "A/2.log"],
        ["B/0.log"],
    ]
    assert _names(plan_batches(tasks, workers=1, batch_bytes=0)) == [
        [n] for n in ("B/1.log", "A/1.log", "A/0.log", "A/3.log", "A/4.log", "A/2.log", "B/0.log")
    ]


def test_batches_leave_every_worker_enough_tasks(tmp_path):
    # 16 x 100 bytes, 2 workers: at least TASKS_PER_WORKER (4) tasks each, so 200-byte batches
    tasks = _files(tmp_path, {"A": [100] * 16})
    batches = plan_batches(tasks, workers=2, batch_bytes=10_000)
    assert engines.TASKS_PER_WORKER == 4
    assert [len(b) for b in batches] == [2] * 8
    assert sorted(t.path for b in batches for t in b) == sorted(t.path for t in tasks)


@pytest.fixture
def mixed(tmp_path, monkeypatch):
    """The fleet of test_fleet with a log whose analyser raises, every folder one batch."""
    root = _fleet(tmp_path)
    (root / "Borealis" / "odd.nmea").write_text("RAISE")
    monkeypatch.setattr(engines, "BATCH_BYTES", 1_000_000)
    monkeypatch.setattr(engines, "TASKS_PER_WORKER", 1)
    return root, discover([root / "Aurora", root / "Borealis"])


def test_every_log_one_result_with_a_failing_and_a_raising_log_in_a_batch(mixed):
    _, tasks = mixed
    assert sorted(len(b) for b in plan_batches(tasks, workers=1)) == [3, 4]  # really batched
    got: list[tuple[str, dict]] = []
    path = {(t.vessel, t.log): t.path for t in tasks}
    run_local(tasks, CFG, 1, raising_analyser, lambda t, r: got.append((t.path, r)))
    assert sorted(p for p, _ in got) == sorted(t.path for t in tasks)  # each exactly once
    res = dict(got)
    broken = path["Borealis", "broken.nmea"]
    assert res[broken] == {"ok": False, "error": f"{broken}: line 1: not a log"}
    assert res[path["Borealis", "odd.nmea"]] == {
        "ok": False,
        "error": "internal error (RuntimeError: an unforeseen state)",
    }
    assert sum(r["ok"] for r in res.values()) == 5


def test_batched_equals_one_log_per_task(mixed, tmp_path, monkeypatch):
    _, tasks = mixed
    batched = run_fleet(tasks, CFG, tmp_path / "b", workers=2, analyser=raising_analyser)
    monkeypatch.setattr(engines, "BATCH_BYTES", 0)
    single = run_fleet(tasks, CFG, tmp_path / "s", workers=2, analyser=raising_analyser)
    pd.testing.assert_frame_equal(batched.table, single.table)
    assert batched.failures == single.failures and len(batched.failures) == 2
    assert batched.analysed == single.analysed == 5  # and 2 failed
    resumed = run_fleet(tasks, CFG, tmp_path / "b", workers=2, analyser=raising_analyser)
    pd.testing.assert_frame_equal(resumed.table, batched.table)
    assert (resumed.analysed, resumed.cached) == (0, 5)  # only the failed logs again (they fail)


def test_a_dying_worker_fails_logs_never_the_run(mixed):
    root, tasks = mixed
    (root / "Aurora" / "2026-11-19.nmea").write_text("DIE")
    got: list[tuple[str, dict]] = []
    path = {(t.vessel, t.log): t.path for t in tasks}
    run_local(tasks, CFG, 1, dying_analyser, lambda t, r: got.append((t.path, r)))
    assert sorted(p for p, _ in got) == sorted(t.path for t in tasks)
    res = dict(got)
    died = res[path["Aurora", "2026-11-19.nmea"]]
    assert not died["ok"] and died["error"].startswith("worker process died")


@pytest.mark.slow
def test_dask_batched_equals_local_and_preloads_the_workers(mixed, tmp_path):
    pytest.importorskip("distributed")
    from distributed import Client

    _, tasks = mixed
    local = run_fleet(tasks, CFG, tmp_path / "local", workers=1, analyser=raising_analyser)
    port = _free_port()
    addr = f"tcp://127.0.0.1:{port}"
    # the worker unpickles this module's analyser: it must find the tests folder
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).parent), *sys.path])}
    common = {
        "stdout": subprocess.DEVNULL,
        "stderr": subprocess.DEVNULL,
        "start_new_session": True,
        "env": env,
    }
    dask = [sys.executable, "-m", "dask"]
    procs = []
    try:
        procs.append(
            subprocess.Popen(
                [*dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                **common,
            )
        )
        procs.append(
            subprocess.Popen(
                [*dask, "worker", addr, "--host", "127.0.0.1", "--nworkers", "1"]
                + ["--nthreads", "1", "--no-dashboard"],
                **common,
            )
        )
        with Client(addr, timeout=60) as c:  # bounded waits for the scheduler and the worker
            c.wait_for_workers(1, timeout=90)
            assert not any(s["preloaded"] for s in c.run(engines.worker_state).values())
        res = run_fleet(tasks, CFG, tmp_path / "dask", scheduler=addr, analyser=raising_analyser)
        with Client(addr, timeout=60) as c:
            states = list(c.run(engines.worker_state).values())
    finally:
        _stop(procs)
    pd.testing.assert_frame_equal(res.table, local.table)
    assert res.failures == local.failures and len(res.failures) == 2
    # the worker imported the pipeline before it ran its first batch
    assert len(states) == 1 and states[0]["preloaded"] and states[0]["first_batch_preloaded"]
    assert states[0]["preload_s"] > 0


def sleeping_analyser(path: str, cfg) -> dict:
    """A long log's analysis: says it started (``<log>.started``), then takes ten minutes."""
    Path(path + ".started").touch()
    time.sleep(600)
    return fake_analyser(path, cfg)


_INTERRUPTED_RUN = """
import sys
sys.path.insert(0, {tests!r})
from test_fleet import CFG
from test_fleet_engines import sleeping_analyser
from dracc.pipeline.fleet import discover, run_fleet
try:
    run_fleet(discover({inputs!r}), CFG, {out!r}, workers=2, analyser=sleeping_analyser)
except KeyboardInterrupt:
    sys.stderr.write("interrupted\\n")
    sys.exit(130)
"""


def _catches(pid: int, sig: int) -> bool:
    """The process catches ``sig`` (/proc/PID/status SigCgt): its handler is installed."""
    try:
        lines = Path(f"/proc/{pid}/status").read_text().splitlines()
    except OSError:
        return False
    caught = next((ln.split()[1] for ln in lines if ln.startswith("SigCgt:")), "0")
    return bool(int(caught, 16) & (1 << (sig - 1)))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_sigint_to_the_main_process_stops_the_run_within_seconds(tmp_path):
    """Issue 32: SIGINT to the fleet's main process alone, its two workers each ten
    minutes into a log: the run ends within seconds (the workers are killed, not waited
    for: a pool's shutdown, and the interpreter's exit, wait for the running calls) and
    no worker outlives it."""
    root = _fleet(tmp_path)
    inputs = [str(root / "Aurora"), str(root / "Borealis")]
    script = _INTERRUPTED_RUN.format(
        tests=str(Path(__file__).parent), inputs=inputs, out=str(tmp_path / "out")
    )
    p = subprocess.Popen([sys.executable, "-c", script], stderr=subprocess.PIPE)
    workers: list[int] = []
    try:
        deadline = time.monotonic() + 120  # a loaded CI: the start alone may take seconds
        while len(list(root.rglob("*.started"))) < 2 or not _catches(p.pid, signal.SIGINT):
            if time.monotonic() > deadline or p.poll() is not None:
                pytest.fail("the workers never started their logs")
            time.sleep(0.05)
        workers = _children(p.pid)
        assert len(workers) == 2
        t0 = time.monotonic()
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=60)
        took_s = time.monotonic() - t0
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 130 and err.decode().strip().endswith("interrupted"), err
    assert took_s < 10.0, f"{took_s:.1f} s from SIGINT to the end of the run"
    assert _gone(workers, timeout_s=10.0), "worker processes outlived the interrupted run"
