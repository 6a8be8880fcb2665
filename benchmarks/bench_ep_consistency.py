"""Honest as stated, the long form: random voyages, default configuration, truth vs 2M.

Run:  python benchmarks/bench_ep_consistency.py [--voyages 200] [--hours H] [--seed0 0]
      [--workers 2]

Each voyage is drawn as ``tests/ep_voyages.py`` draws it (log scale -5..+5 %, gyro error
-1..+1 deg, a current of 0.1-2 kn whose variation has a time constant of 1-24 h, gyro or
magnetic compass with a residual deviation curve, latitudes 30-65 deg, 6-24 h unless
``--hours``), simulated with known truth and its DR run with ``Config()``.  Printed: one
row per voyage (compass, hours, epochs, truth inside 2M, stated, first scored leg, epochs
beyond the 99 % radius, the analysis's verdict against the GNSS), then the pooled figures
against the issue's bounds, containment by time since the fix and by compass, the PIT
histogram and the seconds per voyage.
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

from ep_voyages import ScoredVoyage, score_voyage  # noqa: E402


def _timed(args: tuple[int, float | None]) -> tuple[ScoredVoyage, float]:
    t0 = time.perf_counter()
    r = score_voyage(*args)
    return r, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--voyages", type=int, default=200)
    ap.add_argument("--hours", type=float, default=None)
    ap.add_argument("--seed0", type=int, default=1000)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    seeds = range(args.seed0, args.seed0 + args.voyages)
    print("seed  compass   hours  epochs  inside  stated  first-leg  >99%  verdict")
    runs: list[ScoredVoyage] = []
    secs: list[float] = []
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        for seed, (r, s) in zip(
            seeds, pool.map(_timed, [(k, args.hours) for k in seeds]), strict=True
        ):
            runs.append(r)
            secs.append(s)
            print(
                f"{seed:5d} {r.compass:8s} {r.hours:6.1f} {r.inside.size:7d} "
                f"{r.inside.mean():7.3f} {r.stated.mean():7.3f} "
                f"{r.inside[r.first_leg].mean():10.3f} {int(np.sum(r.pit > 0.99)):5d}  {r.verdict}",
                flush=True,
            )
    inside = np.concatenate([r.inside for r in runs])
    stated = np.concatenate([r.stated for r in runs])
    pit = np.concatenate([r.pit for r in runs])
    per = np.array([r.inside.mean() for r in runs])
    first = np.concatenate([r.inside[r.first_leg] for r in runs])
    print(f"\n{len(runs)} voyages, {inside.size} scored epochs, default configuration")
    print(
        f"pooled: truth inside 2M {inside.mean():.4f}, stated {stated.mean():.4f} "
        f"(difference {100 * (inside.mean() - stated.mean()):+.2f} points; bound 1.5, >= 93 %)"
    )
    print(f"voyages at >= 90 %: {np.mean(per >= 0.9):.3f} (bound 0.95)")
    print(f"first scored legs pooled: {first.mean():.4f} of {first.size} (bound 0.90)")
    print(f"beyond the 99 % radius: {np.mean(pit > 0.99):.4f} (1 % expected; bound 2 %)")
    print("PIT histogram (10 bins, flat when honest):", np.histogram(pit, 10, (0, 1))[0].tolist())
    since = np.concatenate([r.since_fix_s for r in runs])
    by_h: dict[int, list[bool]] = collections.defaultdict(list)
    for h, x in zip(since, inside, strict=True):
        by_h[int(h // 900) * 15].append(bool(x))
    print(
        "by minutes since the fix:",
        {f"{k}-{k + 15}": round(float(np.mean(v)), 3) for k, v in sorted(by_h.items())},
    )
    for key in ("gyro", "magnetic"):
        sel = [r for r in runs if r.compass == key]
        if sel:
            a = np.concatenate([r.inside for r in sel]).mean()
            b = np.concatenate([r.stated for r in sel]).mean()
            print(f"{key}: inside {a:.4f}, stated {b:.4f} ({len(sel)} voyages)")
    print("verdicts:", dict(collections.Counter(r.verdict for r in runs)))
    print(
        f"{np.mean(secs):.2f} s per voyage (simulation and DR stage; median {np.median(secs):.2f})"
    )


if __name__ == "__main__":
    main()
