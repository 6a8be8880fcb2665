"""The fix-interval study on the learned model, the long form of
``tests/test_fix_interval_montecarlo.py`` (issue 31, item 5).

Run:  python benchmarks/bench_fix_interval.py [--voyages 100] [--hours 6] [--seed0 2000]

Random voyages as ``tests/test_ep_montecarlo.py`` draws them (current 0.1-2 kn whose
variation has a time constant of 1-24 h, both compass kinds), default configuration,
``--fix-interval 15min,30min,1h``.  Printed per interval: updates, the pooled containment
of the GNSS fix in its 95 % innovation ellipse, the probability the model states, their
difference, the smallest per-voyage containment, and the seconds per voyage.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_ep_montecarlo import random_voyage  # noqa: E402
from test_pipeline import voyage_from_sim  # noqa: E402

from dracc.core.config import Config  # noqa: E402
from dracc.pipeline.analysis import analyse_voyage  # noqa: E402
from dracc.pipeline.results import EPOptions  # noqa: E402
from dracc.sim import simulate  # noqa: E402

INTERVALS_S = (900.0, 1800.0, 3600.0)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--voyages", type=int, default=100)
    ap.add_argument("--hours", type=float, default=6.0)
    ap.add_argument("--seed0", type=int, default=2000)
    a = ap.parse_args()
    rows = []
    t0 = time.perf_counter()
    for s in range(a.seed0, a.seed0 + a.voyages):
        sv = simulate(random_voyage(s, a.hours))
        an = analyse_voyage(
            voyage_from_sim(sv, drop_roles=("ins1", "ins2", "ins3")),
            Config(),
            ep=EPOptions((), INTERVALS_S),
        )
        assert an.estimated_position is not None
        rows.append(an.estimated_position.interval_study)
    dt = (time.perf_counter() - t0) / a.voyages
    model = {r.model for rs in rows for r in rs}
    print(
        f"{a.voyages} voyages of {a.hours:g} h (seeds {a.seed0}-{a.seed0 + a.voyages - 1}), "
        f"model {', '.join(sorted(model))}, {dt:.2f} s per voyage"
    )
    print(
        f"{'interval':>9} {'updates':>8} {'inside':>8} {'stated':>8} {'diff':>7} {'worst voyage':>13}"
    )
    for i, iv in enumerate(INTERVALS_S):
        r = [rs[i] for rs in rows]
        n = np.array([x.n_updates for x in r])
        inside = np.array([x.containment for x in r]) @ n / n.sum()
        stated = np.array([x.expected_containment for x in r]) @ n / n.sum()
        worst = min(x.containment for x in r)
        print(
            f"{iv / 60:>6.0f} min {n.sum():>8} {100 * inside:>7.1f}% {100 * stated:>7.1f}% "
            f"{100 * (inside - stated):>+6.1f} {100 * worst:>12.0f}%"
        )


if __name__ == "__main__":
    main()
