"""Ingest benchmark: dracc's NMEA reader against pynmea2, and streaming memory 1 day vs 7 days.

Run:  python benchmarks/bench_ingest.py [--workdir DIR] [--baseline-lines N] [--skip-memory]
[--repeat N]

1. Generates the simulated 24 h log with ``dracc simulate --hours 24 --seed 1 --form tag``
   (compass 10 Hz, log 1 Hz, three INS GGA+HDT+VTG 1 Hz, GNSS GGA+RMC+ZDA 1 Hz; about
   2.3 M lines, 143 MB), unless DIR already holds it.
2. Throughput, side by side in this run:
   * pynmea2: every line's TAG block split off with ``str.rpartition('\\\\')`` (pynmea2
     has no TAG block support), ``pynmea2.parse(sentence, check=True)`` and every field
     read through its attribute (``getattr(msg, name)`` for each ``msg.fields`` entry),
     on the first ``--baseline-lines`` lines (default 300 000; ``0`` = the whole file),
     scaled per line;
   * dracc: ``read_nmea`` on the whole file (checksums, TAG blocks, every field of the
     14 sentence types to SI, time base, frames sorted by time), two worker processes.
   * dracc inspect: ``inspect_logs`` on the whole file (the streaming path of ``dracc
     inspect``: blocks, per-source summaries on categorical codes, every sentence type
     counted, ZDA included), in this process after the imports.
   The ratios are of lines per second (wall clock): read_nmea / pynmea2 and inspect /
   pynmea2, each with its target (>= 20x).
3. Memory: ``dracc inspect``'s streaming path (``iter_nmea_blocks`` + per-source
   summaries) on the 1-day log and on a 7-day log, each in a fresh subprocess; peak RSS
   of the main process and of the worker processes (``ru_maxrss``).  The 7-day log is the
   1-day log written seven times one after the other (the content repeats; the
   streaming reader's memory depends on block size, not on content).

The machine is shared: figures vary with load; run it when the machine is quiet, or with
``--repeat N``: each side runs N times, alternating, and its best time counts.
``DRACC_NMEA_ENGINE=numpy`` runs the numpy path only (the figures before the kernel).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))
from _common import ensure_day_log  # noqa: E402


def ensure_log(workdir: Path) -> Path:
    return ensure_day_log(workdir, quiet=False)


def ensure_week(day: Path, workdir: Path) -> Path:
    week = workdir / "week.nmea"
    if week.exists() and week.stat().st_size == 7 * day.stat().st_size:
        return week
    with week.open("wb") as out:
        for _ in range(7):
            with day.open("rb") as fh:
                while chunk := fh.read(64 << 20):
                    out.write(chunk)
    return week


def _cpu() -> float:
    """CPU seconds of this process and of its finished children (the worker pool)."""
    a = resource.getrusage(resource.RUSAGE_SELF)
    b = resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


def bench_pynmea2(path: Path, max_lines: int) -> tuple[int, float, int, float]:
    import pynmea2

    n = ok = 0
    c0 = _cpu()
    t0 = time.perf_counter()
    with path.open("r", encoding="ascii", errors="replace") as fh:
        for line in fh:
            n += 1
            _, _, sentence = line.rstrip("\r\n").rpartition("\\")
            try:
                msg = pynmea2.parse(sentence, check=True)
            except pynmea2.ParseError:
                continue
            for f in msg.fields:
                getattr(msg, f[1], None)
            ok += 1
            if max_lines and n >= max_lines:
                break
    return n, time.perf_counter() - t0, ok, _cpu() - c0


def bench_dracc(path: Path) -> tuple[int, float, int, float]:
    from dracc.core.config import IngestConfig
    from dracc.ingest.nmea import read_nmea

    c0 = _cpu()
    t0 = time.perf_counter()
    res = read_nmea(path, IngestConfig())
    return res.lines, time.perf_counter() - t0, res.records, _cpu() - c0


def bench_inspect(path: Path) -> tuple[int, float, float]:
    from dracc.core.config import IngestConfig
    from dracc.ingest.inspect import inspect_logs

    c0 = _cpu()
    t0 = time.perf_counter()
    rep = inspect_logs([path], IngestConfig())
    return rep["lines"], time.perf_counter() - t0, _cpu() - c0


_MEM_CHILD = r"""
import json, resource, sys, time
from pathlib import Path
from dracc.core.config import IngestConfig
from dracc.ingest.inspect import inspect_logs
t = time.perf_counter()
rep = inspect_logs([Path(sys.argv[1])], IngestConfig())
dt = time.perf_counter() - t
me = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
print(json.dumps({"lines": rep["lines"], "seconds": dt, "main_kib": me, "worker_kib": kids}))
"""


def memory(path: Path) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", _MEM_CHILD, str(path)],
        check=True,
        cwd=REPO,
        capture_output=True,
        text=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--workdir",
        type=Path,
        default=Path(os.environ.get("TMPDIR", "/tmp")) / "dracc-bench-ingest",
    )
    ap.add_argument("--baseline-lines", type=int, default=300_000)
    ap.add_argument("--skip-memory", action="store_true")
    ap.add_argument("--repeat", type=int, default=1, help="best of N timings (see the doc)")
    args = ap.parse_args()
    args.workdir.mkdir(parents=True, exist_ok=True)
    log = ensure_log(args.workdir)
    size_mb = log.stat().st_size / 1e6
    print(f"log: {log} ({size_mb:.1f} MB)")
    from dracc.ingest import nmea

    print(
        "engine:",
        "compiled kernel + numpy for the other lines"
        if nmea.engine_available()
        else "numpy (DRACC_NMEA_ENGINE=numpy or the kernel not built)",
    )

    load = os.getloadavg()[0]
    # best of --repeat, alternating, so that load from other jobs hits every side alike
    runs = [
        (bench_dracc(log), bench_inspect(log), bench_pynmea2(log, args.baseline_lines))
        for _ in range(args.repeat)
    ]
    n_d, t_d, rec, c_d = min((r[0] for r in runs), key=lambda x: x[1])
    n_i, t_i, c_i = min((r[1] for r in runs), key=lambda x: x[1])
    n_p, t_p, ok, c_p = min((r[2] for r in runs), key=lambda x: x[1])
    rate_d = n_d / t_d
    rate_p = n_p / t_p
    print(f"load average before the run: {load:.1f} on {os.cpu_count()} cores")
    print(
        f"dracc read_nmea : {n_d} lines, {rec} records in {t_d:.2f} s wall, {c_d:.2f} s CPU "
        f"(main + 2 workers) -> {rate_d / 1e3:.0f} k lines/s, {size_mb / t_d:.1f} MB/s"
    )
    print(
        f"pynmea2         : {n_p} lines ({ok} parsed) in {t_p:.2f} s wall, {c_p:.2f} s CPU -> "
        f"{rate_p / 1e3:.1f} k lines/s (whole file would take ~{n_d / rate_p:.0f} s)"
    )
    print(
        f"dracc inspect   : {n_i} lines in {t_i:.2f} s wall, {c_i:.2f} s CPU "
        f"-> {n_i / t_i / 1e3:.0f} k lines/s"
    )
    print(f"throughput ratio dracc / pynmea2, wall clock: {rate_d / rate_p:.1f}x (target >= 20x)")
    print(
        f"throughput ratio dracc inspect / pynmea2, wall clock: {n_i / t_i / rate_p:.1f}x "
        "(target >= 20x)"
    )
    cpu_ratio = (n_d / c_d) / (n_p / c_p)
    print(
        f"throughput ratio per CPU second: {cpu_ratio:.1f}x (an idle 2-core machine can give at most "
        f"{2 * cpu_ratio:.1f}x wall clock, the two workers keeping both cores busy)"
    )

    if not args.skip_memory:
        week = ensure_week(log, args.workdir)
        m1 = memory(log)
        m7 = memory(week)
        for name, m in (("1 day ", m1), ("7 days", m7)):
            print(
                f"inspect {name}: {m['lines']} lines in {m['seconds']:.1f} s; peak RSS main "
                f"{m['main_kib'] / 1024:.0f} MiB, workers {m['worker_kib'] / 1024:.0f} MiB"
            )
        r_main = m7["main_kib"] / m1["main_kib"]
        r_work = m7["worker_kib"] / max(m1["worker_kib"], 1)
        print(f"peak memory 7 d / 1 d: main {r_main:.2f}x, workers {r_work:.2f}x (target <= 1.5x)")


if __name__ == "__main__":
    main()
