"""Honest 2M by default, the long form: random voyages, default configuration, truth vs 2M.

Run:  python benchmarks/bench_ep_consistency.py [--voyages 100] [--hours 24] [--seed0 0]

Each voyage draws its errors as ``tests/test_ep_montecarlo.py`` does (log scale -5..+5 %,
gyro error -1..+1 deg, a current of 0.1-2 kn whose variation has a time constant of
1-24 h, leeway on or off, gyro or magnetic compass, random latitude, speed and courses),
is simulated with known truth and analysed with ``Config()``.  Printed: the pooled
fraction of out-of-sample epochs with the truth inside the estimated position's 2M, its
binomial 99 % interval, the per-voyage fractions (quantiles, share >= 0.90 and in
[0.90, 0.995]), the median error/M, containment by time since the fix, by compass and by
whether the ship turned during the leg, and the seconds per voyage.
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_ep_montecarlo import random_voyage  # noqa: E402
from test_pipeline import voyage_from_sim  # noqa: E402

from dracc.core.config import Config  # noqa: E402
from dracc.core.distributions import binom_cdf  # noqa: E402
from dracc.core.geodesy import offset_ne_m  # noqa: E402
from dracc.pipeline.analysis import analyse_voyage  # noqa: E402
from dracc.sim import simulate  # noqa: E402
from dracc.sim.truth import generated_legs


def one(seed: int, hours: float):
    p = random_voyage(seed, hours)
    sv = simulate(p)
    t0 = time.perf_counter()
    a = analyse_voyage(voyage_from_sim(sv, drop_roles=("ins1", "ins2", "ins3")), Config())
    el = time.perf_counter() - t0
    e = a.dead_reckoning.epochs
    tt = sv.truth["time_ns"].to_numpy()
    i = np.searchsorted(tt, e.time_ns)
    dn, de = offset_ne_m(
        e.lat_rad, e.lon_rad, sv.truth["lat_rad"].to_numpy()[i], sv.truth["lon_rad"].to_numpy()[i]
    )
    d = np.hypot(dn, de)
    s = e.scored
    turns = np.array([t for t, _ in generated_legs(p)][1:])
    t_rel = (e.time_ns - tt[0]) / 1e9
    start = t_rel - e.since_fix_s
    turned = np.array(
        [np.any((turns > a0) & (turns <= b0)) for a0, b0 in zip(start, t_rel, strict=True)]
    )
    return {
        "inside": (d <= e.radius_2m_m)[s],
        "ratio": (d / (0.5 * e.radius_2m_m))[s],
        "since": e.since_fix_s[s],
        "turned": turned[s],
        "compass": p.compass,
        "seconds": el,
        "verdict": a.dead_reckoning.verdict.split(":")[0],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--voyages", type=int, default=100)
    ap.add_argument("--hours", type=float, default=24.0)
    ap.add_argument("--seed0", type=int, default=0)
    args = ap.parse_args()
    runs = []
    for k in range(args.voyages):
        runs.append(one(args.seed0 + k, args.hours))
        r = runs[-1]
        print(
            f"voyage {args.seed0 + k:4d} {r['compass']:8s} inside {r['inside'].mean():.3f} of "
            f"{r['inside'].size:3d}, median error/M {np.median(r['ratio']):.2f}, "
            f"{r['verdict']}, {r['seconds']:.2f} s",
            flush=True,
        )
    inside = np.concatenate([r["inside"] for r in runs])
    k, n = int(inside.sum()), inside.size
    lo = next(x for x in range(n + 1) if binom_cdf(x, n, k / n) > 0.005) / n
    hi = next(x for x in range(n + 1) if binom_cdf(x, n, k / n) >= 0.995) / n
    per = np.array([r["inside"].mean() for r in runs])
    med = np.array([np.median(r["ratio"]) for r in runs])
    print(f"\n{args.voyages} voyages of {args.hours:g} h, default configuration")
    print(
        f"pooled: truth inside 2M at {k / n:.4f} of {n} out-of-sample epochs "
        f"(binomial 99 % interval of the rate if epochs were independent: {lo:.3f}-{hi:.3f})"
    )
    print(
        "per voyage: quantiles 5/25/50/75/95 %:",
        np.round(np.quantile(per, [0.05, 0.25, 0.5, 0.75, 0.95]), 3),
        f"; >= 0.90: {np.mean(per >= 0.9):.2f}; in [0.90, 0.995]: {np.mean((per >= 0.9) & (per <= 0.995)):.2f}",
    )
    print(
        "median error/M per voyage (0.83 for a circular Gaussian): quantiles 5/50/95 %:",
        np.round(np.quantile(med, [0.05, 0.5, 0.95]), 2),
    )
    since = np.concatenate([r["since"] for r in runs])
    by_h = collections.defaultdict(list)
    for h, x in zip(since, inside, strict=True):
        by_h[int(h // 600) * 10].append(x)
    print(
        "by minutes since the fix:",
        {f"{k}-{k + 10}": round(float(np.mean(v)), 3) for k, v in sorted(by_h.items())},
    )
    for key in ("gyro", "magnetic"):
        sel = [r["inside"] for r in runs if r["compass"] == key]
        if sel:
            print(f"{key}: {np.concatenate(sel).mean():.4f}")
    turned = np.concatenate([r["turned"] for r in runs])
    print(
        f"legs with a turn: {inside[turned].mean():.4f} of {turned.sum()}; without: "
        f"{inside[~turned].mean():.4f} of {(~turned).sum()}"
    )
    print("verdicts:", dict(collections.Counter(r["verdict"] for r in runs)))
    print(
        f"analysis: {np.mean([r['seconds'] for r in runs]):.2f} s per voyage (median "
        f"{np.median([r['seconds'] for r in runs]):.2f})"
    )


if __name__ == "__main__":
    main()
