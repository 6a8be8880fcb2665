"""The fix-interval study (``--fix-interval``) on the learned model covers at its stated
probability: Monte Carlo over random voyages, default configuration (issue 31, item 5).

Each voyage draws its errors as ``tests/test_ep_montecarlo.py`` does (a current of 0.1-2 kn
whose variation has a time constant of 1-24 h, log scale, gyro error, leeway, gyro or
magnetic compass, latitude, speed, courses), is simulated with known truth and analysed
with ``Config()`` (learn = true) and the fix intervals 15, 30 and 60 min.  What is scored
is the study's own figure: the fraction of the GNSS fixes, before they are used, inside
the 95 % ellipse of their predicted innovation (``containment``), against the probability
the model puts there (``expected_containment``, about 0.94: the learned grid's mixture and
the uncertainty of the covariance-matching factor).  The GNSS noise (1.5 m) is small beside
the 2M before an update (hundreds of metres): the fix's containment is the truth's.

Bounds.  The updates of one interval are not independent: runs start every 15 min, so the
60 min runs overlap, and one voyage's errors are shared.  The effective number of trials
is about the number of voyage-hours (one per interval-long stretch and voyage), 24 voyages
x 6 h = 144 here: at p = 0.94 the binomial standard deviation is 2 points, so the test
asserts the issue's 2 points where its sample can show it (15 and 30 min: 552 and 528
updates) and, at 60 min, no under-coverage beyond 2 points.  The long form (more voyages,
the per-interval table) is ``benchmarks/bench_fix_interval.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_ep_montecarlo import random_voyage
from test_pipeline import voyage_from_sim

from dracc.core.config import Config
from dracc.pipeline.analysis import analyse_voyage
from dracc.pipeline.results import EPOptions
from dracc.sim import simulate

INTERVALS_S = (900.0, 1800.0, 3600.0)
SEEDS = range(1000, 1024)  # not the seeds the method was developed on (0-39, 100-139, 200-239)
HOURS = 6.0


def _rows(seed: int):
    p = random_voyage(seed, HOURS)
    sv = simulate(p)
    a = analyse_voyage(
        voyage_from_sim(sv, drop_roles=("ins1", "ins2", "ins3")),
        Config(),
        ep=EPOptions((), INTERVALS_S),
    )
    assert a.estimated_position is not None
    return p.compass, a.estimated_position


@pytest.fixture(scope="module")
def study():
    return [_rows(s) for s in SEEDS]


def _pooled(study, i):
    rows = [e.interval_study[i] for _, e in study]
    n = np.array([r.n_updates for r in rows])
    inside = np.array([r.containment for r in rows]) @ n / n.sum()
    stated = np.array([r.expected_containment for r in rows]) @ n / n.sum()
    return inside, stated, int(n.sum())


def test_the_study_runs_on_the_learned_model_and_says_so(study):
    assert {c for c, _ in study} == {"gyro", "magnetic"}  # both compass kinds
    for _, e in study:
        assert [r.interval_s for r in e.interval_study] == list(INTERVALS_S)
        assert all(r.model == "learned" for r in e.interval_study)
        assert any("fix-interval study: on the learned model" in n for n in e.notes)
        assert all(0.85 < r.expected_containment < 0.96 for r in e.interval_study)


@pytest.mark.parametrize("i", [0, 1])
def test_pooled_containment_within_2_points_of_stated(study, i):
    inside, stated, n = _pooled(study, i)
    assert n >= 500
    assert abs(inside - stated) <= 0.02, (INTERVALS_S[i], inside, stated, n)


def test_one_hour_does_not_under_cover(study):
    """The configured model held 91-92 % at 30-60 min (the issue's Monte Carlo); the learned
    one must not fall below its stated probability by more than 2 points.  (It over-covers
    at 60 min by about 3 points: see the report of issue 31, item 5.)"""
    inside, stated, n = _pooled(study, 2)
    assert inside >= stated - 0.02, (inside, stated, n)
