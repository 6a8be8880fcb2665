"""Timings of fix fusion and the EP/current filter (short: a few seconds on one core).

Prints: fuse_fix for one fix of 4 LOPs (scalar) and per fix in a batch of 10 000;
the filter per epoch for one run and per run-epoch over 500 runs.

Run:  python benchmarks/bench_fusion_current.py
"""

from __future__ import annotations

import time

import numpy as np

from dracc.core.geodesy import add_offset_ne, range_azimuth
from dracc.math.current import CurrentModel, estimate_current, simulate_voyage
from dracc.math.fusion import BearingLOP, PositionFix, RangeLOP, fuse_fix

LAT0, LON0 = np.deg2rad(54.52), np.deg2rad(18.55)


def _best(fn, repeat=5):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    rng = np.random.default_rng(0)
    ship = add_offset_ne(LAT0, LON0, 1200.0, -800.0)
    marks = [
        add_offset_ne(LAT0, LON0, n, e)
        for n, e in ((6000, 1000), (-2000, 5000), (-4000, -6000), (3000, -7000))
    ]
    dist = [range_azimuth(*ship, *m) for m in marks]

    def obs(runs):
        size = None if runs == 1 else runs
        out = [
            RangeLOP(*m, d[0] + rng.normal(0, 10.0, size), 10.0)
            for m, d in zip(marks[:3], dist[:3], strict=True)
        ]
        out.append(BearingLOP(*marks[3], dist[3][1] + rng.normal(0, 0.01, size), 0.01))
        return out

    one = obs(1)
    t_one = _best(lambda: fuse_fix(one, *ship))
    batch = obs(10_000)
    t_batch = _best(lambda: fuse_fix(batch, *ship), repeat=3)
    print(
        f"fuse_fix, 3 ranges + 1 bearing: {t_one * 1e6:.0f} us per fix (scalar); "
        f"{t_batch / 10_000 * 1e6:.1f} us per fix in a batch of 10 000"
    )

    model = CurrentModel()
    t = np.arange(0.0, 6 * 3600.0 + 1, 10.0)
    course = np.full(t.size, 0.5)
    voyage = simulate_voyage(rng, t, course, np.full(t.size, 6.0), LAT0, LON0, model, 500)
    fix_at = range(60, t.size, 60)
    fixes1 = [
        (t[i], PositionFix.from_sigma(voyage.lat_rad[0, i], voyage.lon_rad[0, i], 10.0))
        for i in fix_at
    ]
    fixes = [
        (t[i], PositionFix.from_sigma(voyage.lat_rad[:, i], voyage.lon_rad[:, i], 10.0))
        for i in fix_at
    ]
    start1 = PositionFix.from_sigma(LAT0, LON0, 10.0)
    start = PositionFix.from_sigma(np.full(500, LAT0), np.full(500, LON0), 10.0)
    t1 = _best(
        lambda: estimate_current(t, course, voyage.speed_mps, start1, fixes1, model), repeat=3
    )
    t500 = _best(
        lambda: estimate_current(t, course, voyage.speed_mps, start, fixes, model), repeat=2
    )
    print(
        f"estimate_current, 6 h at 10 s ({t.size} epochs, fix every 10 min): {t1 * 1e3:.0f} ms for one run "
        f"({t1 / t.size * 1e6:.0f} us/epoch); 500 runs {t500:.2f} s "
        f"({t500 / t.size / 500 * 1e6:.2f} us per run-epoch)"
    )


if __name__ == "__main__":
    main()
