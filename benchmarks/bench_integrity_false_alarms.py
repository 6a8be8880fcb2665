"""False alarms of the integrity checks on clean nights, and how close healthy sources come.

Run:  python benchmarks/bench_integrity_false_alarms.py [--nights 200] [--seed0 0]

Each night draws a ship and sensors as ``tests/test_integrity.py`` does (3.2-4 h, speed
6-18 kn, current 0-1.5 kn, gyro error -1..+1 deg, INS error scale 0.5-1.5, any latitude),
is simulated without faults and checked with the default ``[integrity]`` configuration.
Printed: per check, the nights it failed against its stated false-alarm probability
(binomial 99 % interval of the observed rate), the union bound per night and the
observed rate of nights with any failed check; for the gated checks the largest
statistic / gate ratio a healthy source reached (the margin); the seconds per night.
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_integrity import _params, voyage_from_sim  # noqa: E402

from dracc.core.distributions import beta_ppf  # noqa: E402
from dracc.math.integrity import check_night  # noqa: E402
from dracc.sim import simulate  # noqa: E402


def _interval(k: int, n: int, conf: float = 0.99) -> tuple[float, float]:
    """Clopper-Pearson interval of a binomial rate."""
    a = (1 - conf) / 2
    lo = 0.0 if k == 0 else float(beta_ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(beta_ppf(1 - a, k + 1, n - k))
    return lo, hi


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nights", type=int, default=200)
    ap.add_argument("--seed0", type=int, default=0)
    args = ap.parse_args()
    fails: collections.Counter = collections.Counter()
    stated: dict[str, list[float]] = collections.defaultdict(list)
    ratio: dict[str, float] = collections.defaultdict(float)
    any_fail, bound, secs = 0, [], []
    for i in range(args.nights):
        t0 = time.perf_counter()
        r = check_night(voyage_from_sim(simulate(_params(args.seed0 + i))))
        secs.append(time.perf_counter() - t0)
        bound.append(r.false_alarm_per_night)
        night_fail = set()
        for c in r.checks:
            key = f"{c.check}/{c.name}"
            if c.status == "not_checked":
                continue
            stated[key].append(c.false_alarm)
            if c.status == "fail":
                night_fail.add(key)
            v, g = c.statistic.get("value"), c.threshold.get("value")
            if c.name in ("jump", "velocity", "heading", "speed") and v is not None and g:
                ratio[key] = max(ratio[key], v / g)
        fails.update(night_fail)
        any_fail += bool(night_fail)
    n = args.nights
    print(f"{n} clean nights, {np.mean(secs):.2f} s per night (simulate + check)")
    print(
        f"{'check':<28} {'failed':>7} {'rate 99 % CI':>22} {'stated/source':>14} {'max stat/gate':>14}"
    )
    for key in sorted(stated):
        k = fails[key]
        lo, hi = _interval(k, n)
        print(
            f"{key:<28} {k:>7} {f'{k / n:.4f} [{lo:.4f}, {hi:.4f}]':>22} "
            f"{np.mean(stated[key]):>14.4g} {ratio.get(key, float('nan')):>14.3f}"
        )
    lo, hi = _interval(any_fail, n)
    print(
        f"nights with any failed check: {any_fail} of {n} = {any_fail / n:.4f} "
        f"(99 % CI [{lo:.4f}, {hi:.4f}]); stated union bound {np.mean(bound):.4f} per night"
    )


if __name__ == "__main__":
    main()
