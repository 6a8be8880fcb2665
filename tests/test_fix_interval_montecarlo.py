"""The fix-interval study (``--fix-interval``) on the learned model covers at its stated
probability: Monte Carlo over random voyages, default configuration (issue 31, item 5).

Each voyage draws its errors as ``tests/test_ep_montecarlo.py`` did when the study was
written (:func:`random_voyage`: a current of 0.1-2 kn whose variation has a time constant
of 1-24 h, log scale, gyro error, leeway, gyro or magnetic compass, latitude, speed), is
simulated with known truth and analysed with ``Config()`` (learn = true) and the fix
intervals 15, 30 and 60 min.  What is scored is the study's own figure: the fraction of
the GNSS fixes, before they are used, inside the 95 % ellipse of their predicted
innovation (``containment``), against the probability the study states
(``expected_containment``: the coverage its earlier updates achieved, shrunk to the
model's own probability, :func:`dracc.math.ep.interval.stated_containment`).  The GNSS
noise (1.5 m) is small beside the 2M before an update (hundreds of metres): the fix's
containment is the truth's.

Bounds.  The updates of one interval are not independent: runs start every 15 min, so the
60 min runs overlap, and one voyage's errors are shared.  The effective number of trials
is about the number of voyage-hours, 24 voyages x 6 h = 144 here; the stated probability
follows the coverage each voyage achieved, which takes out most of the voyage-to-voyage
spread of the difference.  The issue's bar, 2 points at each interval, is asserted.  The
long form (100 voyages, the per-interval table, the worst voyages) is
``benchmarks/bench_fix_interval.py``.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_pipeline import voyage_from_sim

from dracc.core.config import Config
from dracc.pipeline.analysis import analyse_voyage
from dracc.pipeline.results import EPOptions
from dracc.sim import GM, SimParams, simulate

INTERVALS_S = (900.0, 1800.0, 3600.0)
SEEDS = range(1000, 1024)  # not the seeds the method was developed on (0-39, 100-139, 200-239)
HOURS = 6.0


def random_voyage(seed: int, hours: float = HOURS) -> SimParams:
    """One voyage's errors drawn over the issue's ranges (simulator defaults elsewhere)."""
    r = np.random.default_rng(7919 + seed)
    leeway = r.random() < 0.5
    return SimParams(
        duration_s=hours * 3600.0,
        seed=seed,
        compass="gyro" if r.random() < 0.5 else "magnetic",
        compass_hz=1.0,
        aux_hz=0.0,
        ins_hz=0.1,
        start_lat_deg=r.uniform(-60.0, 60.0),
        start_lon_deg=r.uniform(-180.0, 180.0),
        speed_kn=r.uniform(6.0, 20.0),
        initial_heading_deg=r.uniform(0.0, 360.0),
        log_scale=r.uniform(-0.05, 0.05),
        gyro_offset_deg=r.uniform(-1.0, 1.0),
        current_drift_kn=r.uniform(0.1, 2.0),
        current_set_deg=r.uniform(0.0, 360.0),
        current_noise_kn=GM(r.uniform(0.05, 0.5), r.uniform(1.0, 24.0) * 3600.0),
        leeway_deg=r.uniform(-3.0, 3.0) if leeway else 0.0,
        leeway_noise_deg=GM(0.3, 600.0) if leeway else GM(0.0, 600.0),
    )


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
        assert all(0.8 < r.expected_containment <= 1.0 for r in e.interval_study)


@pytest.mark.parametrize("i", [0, 1, 2])
def test_pooled_containment_within_2_points_of_stated(study, i):
    inside, stated, n = _pooled(study, i)
    assert n >= 400
    assert abs(inside - stated) <= 0.02, (INTERVALS_S[i], inside, stated, n)
