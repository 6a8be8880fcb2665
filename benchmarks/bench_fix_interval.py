"""The fix-interval study on the learned model, the long form of
``tests/test_fix_interval_montecarlo.py`` (issue 31, item 5).

Run:  python benchmarks/bench_fix_interval.py [--voyages 100] [--hours 6] [--seed0 2000]
      [--jobs 2]

Random voyages as the test draws them (``random_voyage``: current 0.1-2 kn whose
variation has a time constant of 1-24 h, both compass kinds), default configuration,
``--fix-interval 15min,30min,1h``.  Printed per interval: updates, the pooled containment
of the GNSS fix in its 95 % innovation ellipse, the probability the study states, their
difference, and the three voyages of least containment (seed: inside/stated); then the
seconds per voyage.
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_fix_interval_montecarlo import random_voyage  # noqa: E402
from test_pipeline import voyage_from_sim  # noqa: E402

from dracc.core.config import Config  # noqa: E402
from dracc.pipeline.analysis import analyse_voyage  # noqa: E402
from dracc.pipeline.results import EPOptions  # noqa: E402
from dracc.sim import simulate  # noqa: E402

INTERVALS_S = (900.0, 1800.0, 3600.0)


def study(seed: int, hours: float):
    """One voyage's fix-interval table."""
    sv = simulate(random_voyage(seed, hours))
    an = analyse_voyage(
        voyage_from_sim(sv, drop_roles=("ins1", "ins2", "ins3")),
        Config(),
        ep=EPOptions((), INTERVALS_S),
    )
    assert an.estimated_position is not None
    return an.estimated_position.interval_study


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--voyages", type=int, default=100)
    ap.add_argument("--hours", type=float, default=6.0)
    ap.add_argument("--seed0", type=int, default=2000)
    ap.add_argument("--jobs", type=int, default=1)
    a = ap.parse_args()
    seeds = list(range(a.seed0, a.seed0 + a.voyages))
    t0 = time.perf_counter()
    with ProcessPoolExecutor(a.jobs) as ex:
        rows = list(ex.map(study, seeds, [a.hours] * len(seeds)))
    dt = (time.perf_counter() - t0) * a.jobs / a.voyages
    model = {r.model for rs in rows for r in rs}
    print(
        f"{a.voyages} voyages of {a.hours:g} h (seeds {seeds[0]}-{seeds[-1]}), "
        f"model {', '.join(sorted(model))}, {dt:.2f} s per voyage (per job)"
    )
    print(f"{'interval':>9} {'updates':>8} {'inside':>8} {'stated':>8} {'diff':>7}  worst voyages")
    for i, iv in enumerate(INTERVALS_S):
        r = [rs[i] for rs in rows]
        n = np.array([x.n_updates for x in r])
        inside = np.array([x.containment for x in r]) @ n / n.sum()
        stated = np.array([x.expected_containment for x in r]) @ n / n.sum()
        worst = sorted(range(len(r)), key=lambda j: r[j].containment)[:3]
        print(
            f"{iv / 60:>6.0f} min {n.sum():>8} {100 * inside:>7.1f}% {100 * stated:>7.1f}% "
            f"{100 * (inside - stated):>+6.1f}  "
            + ", ".join(
                f"{seeds[j]}: {100 * r[j].containment:.0f}/{100 * r[j].expected_containment:.0f}%"
                for j in worst
            )
        )


if __name__ == "__main__":
    main()
