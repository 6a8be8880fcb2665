"""Time you can trust (issue 30), the long form: each source's clock learned over random
clocked voyages, and what it does to the deviation statistics and the estimated position.

Run:  python benchmarks/bench_clock.py [--voyages 30] [--hours 12] [--noiseless 10] [--jobs 2]

Each voyage (``tests/clock_voyages.py``) draws a compass of 1-10 Hz (gyro, magnetic or
both), a random sample phase and a latency of 0-2 s for every source, speed changes at
the turns, and is written as the NMEA log a logger with whole-second TAG ``c:`` stamps
writes, and as MCAP with exact times; both are analysed with ``Config()``.  Printed:

- the learned offset of every source without a time of fix against its truth (error,
  σ, the share within 1σ, 2σ, 3σ), by method, and how many were not determinable;
- the deviation statistics: m_u of the NMEA analysis over m_u of the MCAP analysis, and
  the RMS of the NMEA analysis's deviation samples over the RMS of the true deviations at
  the same instants, per channel (worst over units and voyages);
- on noiseless voyages (no sensor error, no current), the learned DR's largest distance
  from the truth at its epochs, from the whole-second NMEA and from the exact-time MCAP.
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from clock_voyages import CHANNELS, run_voyage  # noqa: E402


def _one(args: tuple[int, float, bool]):
    seed, hours, noiseless = args
    t0 = time.perf_counter()
    return run_voyage(seed, hours, noiseless), time.perf_counter() - t0


def _offsets(runs) -> None:
    by: dict[str, list[tuple[float, float]]] = collections.defaultdict(list)
    undetermined: collections.Counter[str] = collections.Counter()
    for r in runs:
        for key, (off, sig, method, truth) in r.offsets.items():
            if method in ("time_of_fix", "own_time"):
                continue
            kind = "log" if key == "LOG" else "compass"
            if np.isfinite(off):
                by[f"{kind} {method}"].append((off - truth, sig))
            else:
                undetermined[kind] += 1
    print("learned offsets against the truth (seconds):")
    for name, rows in sorted(by.items()):
        e, s = np.array(rows).T
        within = [np.mean(np.abs(e) <= k * s) for k in (1, 2, 3)]
        print(
            f"  {name:22s} n={len(e):3d}  |err| median {np.median(np.abs(e)):.3f} max "
            f"{np.abs(e).max():.3f}  σ median {np.median(s):.3f}  within 1/2/3σ "
            f"{within[0]:.2f}/{within[1]:.2f}/{within[2]:.2f}"
        )
    for kind, n in sorted(undetermined.items()):
        print(f"  {kind:22s} not determinable in {n} voyages")


def _deviations(runs) -> None:
    print("deviation statistics (worst |ratio - 1| over units and voyages):")
    for ch in CHANNELS:
        mcap = [abs(v[ch][0] / v[ch][1] - 1) for r in runs for v in r.m_u.values()]
        true = [abs(v[ch][2] / v[ch][3] - 1) for r in runs for v in r.m_u.values()]
        print(
            f"  {ch:6s} NMEA m_u / MCAP m_u: {max(mcap):.4f}   "
            f"NMEA samples / true deviations (RMS): {max(true):.4f}"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--voyages", type=int, default=30)
    ap.add_argument("--hours", type=float, default=12.0)
    ap.add_argument("--noiseless", type=int, default=10)
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args()
    t0 = time.perf_counter()
    with ProcessPoolExecutor(a.jobs) as ex:
        noisy = list(ex.map(_one, [(s, a.hours, False) for s in range(a.voyages)]))
        quiet = list(ex.map(_one, [(1000 + s, a.hours, True) for s in range(a.noiseless)]))
    runs = [r for r, _ in noisy]
    print(f"{a.voyages} voyages of {a.hours:g} h, whole-second TAG stamps, latencies 0-2 s")
    _offsets(runs)
    _deviations(runs)
    ep = np.array([r.ep_max_error_m for r, _ in quiet])
    ex = np.array([r.ep_exact_max_error_m for r, _ in quiet])
    print(
        f"noiseless voyages ({a.noiseless}): learned DR's largest distance from the truth "
        f"median {np.median(ep):.1f} m, max {ep.max():.1f} m (whole-second NMEA); "
        f"median {np.median(ex):.1f} m, max {ex.max():.1f} m (exact-time MCAP)"
    )
    per = [s for _, s in noisy + quiet]
    print(f"{np.mean(per):.1f} s per voyage, {time.perf_counter() - t0:.0f} s in all")


if __name__ == "__main__":
    main()
