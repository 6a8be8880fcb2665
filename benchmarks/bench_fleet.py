"""Fleet speed: small simulated voyage logs on 1 and 2 local workers, and on a local Dask cluster.

    python benchmarks/bench_fleet.py [--logs 20,100] [--hours 1] [--workdir DIR] [--repeat N]
                                     [--no-dask] [--sweep]

Simulates the largest of ``--logs`` voyages with ``dracc simulate`` (five vessels, one
folder each, 1 to 2 h at 0.2-1 Hz: 0.7-3 MB), then, for each fleet size, runs the batch
(:func:`dracc.pipeline.fleet.run_fleet`, ``force=True`` so every log is analysed) on a
local pool of 1 worker, of 2 workers one log per task and with batches of logs
(:mod:`dracc.pipeline.fleet.engines`), and on a Dask scheduler with two single-threaded
workers started as subprocesses on 127.0.0.1, one log per task and batched, each on a
fresh cluster (the workers' imports included), then batched again on the warm cluster.
Prints wall times, the speed-ups against 1 worker, the Dask overhead against the pool,
whether every table equals the 1-worker one, and a resume from the cache (exact, and
how fast).  ``--sweep`` times batch sizes on a warm cluster and on the pool.  The
target of issue 7: 2 local workers at least 1.8x faster than 1 worker.  Wall times depend
on what else runs on the machine: the load average and the CPU seconds (this process and
its pool workers; the Dask workers' CPU is not counted) are printed beside them.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import resource
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

from dracc.cli.main import main as dracc
from dracc.core.config import Config
from dracc.pipeline.fleet import discover, engines, run_fleet

VESSELS = ("Aurora", "Borealis", "Caledonia", "Dagny", "Eiderstedt")
#: low rates (Hz): small logs, a fraction of a second of analysis each
RATES = ("--compass-hz", "1", "--log-hz", "0.5", "--ins-hz", "0.2", "--gnss-hz", "0.5")


def _name(i: int) -> tuple[str, str]:
    return VESSELS[i % len(VESSELS)], f"2026-03-{1 + i // len(VESSELS):02d}"


def simulate(root: Path, n_logs: int, hours: float) -> list[Path]:
    for i in range(n_logs):
        vessel, name = _name(i)
        if (root / vessel / f"{name}.nmea").exists():  # a --workdir from an earlier run
            continue
        code = dracc(
            [
                "simulate",
                "--out",
                str(root / "sim"),
                "--hours",
                str(hours * (1 + (i % 3) / 2)),  # 1, 1.5, 2 x --hours
                "--seed",
                str(100 + i),
                "--start",
                f"{name}T00:00:00Z",
                "--name",
                f"{vessel}-{name}",
                *RATES,
                "--aux-hz",
                "0",
                "--truth-hz",
                "0.01",
                "--lat",
                str(50 + 2 * (i % 5)),
                "--lon",
                str(-5 + i % 40),
            ]
        )
        if code != 0:
            raise SystemExit(f"dracc simulate failed ({code})")
        (root / vessel).mkdir(exist_ok=True)
        (root / "sim" / f"{vessel}-{name}.nmea").rename(root / vessel / f"{name}.nmea")
    return [root / v for v in VESSELS]


def _cpu_s() -> float:
    """CPU seconds of this process and its reaped children (the pool's workers)."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + ch.ru_utime + ch.ru_stime


def _rusage_s() -> float:
    """CPU seconds of the calling process (run on the Dask workers and the scheduler)."""
    me = resource.getrusage(resource.RUSAGE_SELF)
    return me.ru_utime + me.ru_stime


def dask_cpu_s(addr: str) -> float:
    """CPU seconds so far of the Dask scheduler and workers at ``addr``."""
    from distributed import Client

    with Client(addr, timeout=30) as c:
        return sum(c.run(_rusage_s).values()) + c.run_on_scheduler(_rusage_s)


def timed(label: str, fn, addr: str | None = None):
    """Run ``fn``; print its wall time, the CPU seconds (this process, its pool workers, and
    the Dask scheduler and workers at ``addr``) and the load average before it."""
    load = os.getloadavg()[0]
    d0 = dask_cpu_s(addr) if addr else 0.0
    c0 = _cpu_s()
    t0 = time.perf_counter()
    res = fn()
    dt = time.perf_counter() - t0
    cpu = _cpu_s() - c0 + ((dask_cpu_s(addr) - d0) if addr else 0.0)
    print(
        f"  {label:<40s} {dt:7.2f} s wall, {cpu:6.1f} s CPU  (load average before {load:.1f})",
        flush=True,
    )
    CPU[label] = cpu
    return res, dt


#: CPU seconds of each timed run, by label
CPU: dict[str, float] = {}


@contextlib.contextmanager
def batch_bytes(n: int):
    """Run with :data:`dracc.pipeline.fleet.engines.BATCH_BYTES` = ``n`` (0: one log per task)."""
    old = engines.BATCH_BYTES
    engines.BATCH_BYTES = n
    try:
        yield
    finally:
        engines.BATCH_BYTES = old


@contextlib.contextmanager
def dask_cluster(n_workers: int):
    """A scheduler and ``n_workers`` single-threaded workers on 127.0.0.1 (subprocesses,
    bounded waits, always torn down)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    addr = f"tcp://127.0.0.1:{port}"
    kw = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "start_new_session": True}
    dask = [sys.executable, "-m", "dask"]
    procs = []
    try:
        procs.append(
            subprocess.Popen(
                [*dask, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                **kw,
            )
        )
        procs.append(
            subprocess.Popen(
                [*dask, "worker", addr, "--host", "127.0.0.1", "--nworkers", str(n_workers)]
                + ["--nthreads", "1", "--no-dashboard"],
                **kw,
            )
        )
        from distributed import Client

        with Client(addr, timeout=60) as c:
            c.wait_for_workers(n_workers, timeout=120)
        yield addr
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in procs:
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


def fleet_size(tasks, n: int, root: Path, args, cfg: Config) -> None:
    days = {_name(i)[1] for i in range(n)}
    tasks = [t for t in tasks if Path(t.log).stem in days]
    size_mb = sum(Path(t.path).stat().st_size for t in tasks) / 1e6
    print(f"\n{len(tasks)} logs, {len({t.vessel for t in tasks})} vessels, {size_mb:.0f} MB")
    out = root / f"out-{n}"
    runs: dict[str, tuple] = {}

    def keep(label: str, fn):
        res = timed(label, fn)
        if label not in runs or res[1] < runs[label][1]:
            runs[label] = res
        return res

    # interleaved (1, 2, 2 batched, ...) so that a burst of load elsewhere hits them alike
    for _ in range(args.repeat):
        keep(
            "local pool, 1 worker", lambda: run_fleet(tasks, cfg, out / "p1", workers=1, force=True)
        )
        with batch_bytes(0):
            keep(
                "local pool, 2 workers, 1 log per task",
                lambda: run_fleet(tasks, cfg, out / "p2", workers=2, force=True),
            )
        keep(
            "local pool, 2 workers, batched",
            lambda: run_fleet(tasks, cfg, out / "p2b", workers=2, force=True),
        )
    r1, t1 = runs["local pool, 1 worker"]
    assert not r1.failures, r1.failures
    for label, (r, _) in runs.items():
        pd.testing.assert_frame_equal(r.table, r1.table, obj=label)
    t2, t2b = (
        runs["local pool, 2 workers, 1 log per task"][1],
        runs["local pool, 2 workers, batched"][1],
    )
    print(
        f"  speed-up 2 workers / 1 worker: {t1 / t2:.2f}x one log per task, {t1 / t2b:.2f}x "
        f"batched (target >= 1.8x); {t1 / len(tasks):.3f} s per log on 1 worker"
    )
    r3, tr = timed("resume (all cached)", lambda: run_fleet(tasks, cfg, out / "p2b", workers=2))
    pd.testing.assert_frame_equal(r3.table, r1.table)
    print(
        f"  resume: {r3.analysed} analysed, {r3.cached} from the cache, table equal: "
        f"{r3.table.equals(r1.table)}, {1e3 * tr / len(tasks):.1f} ms per log"
    )
    if args.no_dask:
        return
    dask: dict[str, float] = {}
    for label, nbytes in (("1 log per task", 0), ("batched", engines.BATCH_BYTES)):
        with dask_cluster(2) as addr, batch_bytes(nbytes):
            rd, dask[label] = timed(
                f"dask (fresh cluster), {label}",
                lambda addr=addr: run_fleet(tasks, cfg, out / "d", scheduler=addr, force=True),
                addr,
            )
            pd.testing.assert_frame_equal(rd.table, r1.table)
            if label == "batched":
                rw, dask["warm"] = timed(
                    "dask (warm cluster), batched",
                    lambda addr=addr: run_fleet(tasks, cfg, out / "d", scheduler=addr, force=True),
                    addr,
                )
                pd.testing.assert_frame_equal(rw.table, r1.table)
    print(
        "  dask tables equal the 1-worker one: True; speed-up against 1 worker: "
        f"{t1 / dask['1 log per task']:.2f}x one log per task, {t1 / dask['batched']:.2f}x "
        f"batched, {t1 / dask['warm']:.2f}x batched on the warm cluster"
    )
    print(
        f"  dask overhead against the 2-worker pool: {dask['1 log per task'] - t2:+.2f} s one log "
        f"per task, {dask['batched'] - t2b:+.2f} s batched, {dask['warm'] - t2b:+.2f} s warm "
        f"({1e3 * (dask['warm'] - t2b) / len(tasks):+.1f} ms per log)"
    )
    c2 = CPU["local pool, 2 workers, batched"]
    print(
        "  dask CPU seconds against the 2-worker pool (batched): "
        f"{CPU['dask (fresh cluster), batched'] - c2:+.1f} s fresh, "
        f"{CPU['dask (warm cluster), batched'] - c2:+.1f} s warm "
        f"({1e3 * (CPU['dask (warm cluster), batched'] - c2) / len(tasks):+.0f} ms per log)"
    )
    if args.sweep and n == max(int(k) for k in args.logs.split(",")):  # the largest fleet
        sizes = (0, 1_000_000, 2_000_000, 4_000_000, 8_000_000, 16_000_000)
        with dask_cluster(2) as addr:
            run_fleet(tasks[:4], cfg, out / "warm", scheduler=addr, force=True)  # warm it up
            for nbytes in sizes:
                with batch_bytes(nbytes):
                    timed(
                        f"dask (warm), batches of {nbytes / 1e6:g} MB",
                        lambda addr=addr: run_fleet(
                            tasks, cfg, out / "s", scheduler=addr, force=True
                        ),
                    )
        for nbytes in sizes:
            with batch_bytes(nbytes):
                timed(
                    f"pool 2 workers, batches of {nbytes / 1e6:g} MB",
                    lambda: run_fleet(tasks, cfg, out / "s", workers=2, force=True),
                )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", default="20,100", help="fleet sizes, comma-separated")
    ap.add_argument(
        "--hours", type=float, default=1.0, help="shortest log (the logs are 1, 1.5, 2 x this)"
    )
    ap.add_argument("--workdir", type=Path, default=None)
    ap.add_argument("--no-dask", action="store_true")
    ap.add_argument("--sweep", action="store_true", help="also time batch sizes (largest fleet)")
    ap.add_argument(
        "--repeat", type=int, default=1, help="best of N (interleaved) runs per local pool"
    )
    args = ap.parse_args()
    sizes = sorted({int(n) for n in args.logs.split(",")})
    with tempfile.TemporaryDirectory(prefix="bench_fleet_") as tmp:
        root = args.workdir or Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        print(
            f"machine: {os.cpu_count()} CPUs; simulating {sizes[-1]} logs of "
            f"{args.hours:g}-{2 * args.hours:g} h; batches of {engines.BATCH_BYTES / 1e6:g} MB ...",
            flush=True,
        )
        folders, _ = timed("simulate", lambda: simulate(root, sizes[-1], args.hours))
        tasks = discover(folders)
        cfg = Config()
        # the parent's imports once, outside the timings (every run after the first has them)
        print(f"  preload in this process: {engines.preload()['preload_s']:.2f} s")
        for n in sizes:
            fleet_size(tasks, n, root, args, cfg)


if __name__ == "__main__":
    main()
