"""Honest 2M by default: Monte Carlo over randomised voyages, default configuration.

Each voyage draws its own errors over realistic ranges (log scale -5..+5 %, gyro error
-1..+1 deg, a persistent current of 0.1-2 kn whose variation has a time constant of
1-24 h, leeway on or off, gyro or magnetic compass, latitude, speed, courses), is
simulated with known truth (dracc.sim) and analysed with ``Config()``, nothing typed in.
The truth (not the GNSS) is compared with the estimated position's 2M circle at the
epochs scored out of sample (legs whose model was learned from earlier fixes only).

Bounds.  2M of a correct Gaussian error holds it with p between 0.954 and 0.982.  The
pooled fraction over ~2000 epochs of 40 voyages must lie in [0.93, 0.995].  Per voyage
(~50 epochs in ~10 correlated legs) the fraction is noisy; a correct model puts it
below 0.90 in few voyages (binomial over legs), so at least 90 % of the voyages must be
at 0.90 or above.  A circle "absurdly large" shows as a median error/M far below the
0.83 of a circular Gaussian: at least 90 % of the voyages must have it in [0.4, 1.4].
(The issue's upper band of 99.5 % per voyage cannot hold for a correct 2M: with p = 0.98
and ~50 epochs, P(every epoch inside) = 0.98^50 = 36 %.  The test instead bounds the
median error/M, which catches a circle 2.5x too large.)  The long form with more and
longer voyages is ``benchmarks/bench_ep_consistency.py``.
"""

from __future__ import annotations

import numpy as np
from test_pipeline import voyage_from_sim

from dracc.core.config import Config
from dracc.core.geodesy import offset_ne_m
from dracc.pipeline.analysis import analyse_voyage
from dracc.sim import GM, SimParams, simulate

N_VOYAGES = 40
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


def truth_inside(seed: int, hours: float = HOURS):
    """(inside flags, error/M) of the truth at the scored epochs of one voyage."""
    sv = simulate(random_voyage(seed, hours))
    a = analyse_voyage(voyage_from_sim(sv, drop_roles=("ins1", "ins2", "ins3")), Config())
    e = a.dead_reckoning.epochs
    t = sv.truth["time_ns"].to_numpy()
    i = np.searchsorted(t, e.time_ns)
    dn, de = offset_ne_m(
        e.lat_rad, e.lon_rad, sv.truth["lat_rad"].to_numpy()[i], sv.truth["lon_rad"].to_numpy()[i]
    )
    d = np.hypot(dn, de)[e.scored]
    radius = e.radius_2m_m[e.scored]
    return d <= radius, d / (0.5 * radius)


def test_truth_inside_2m_out_of_sample_on_random_voyages_default_config():
    runs = [truth_inside(s) for s in range(N_VOYAGES)]
    inside = np.concatenate([r[0] for r in runs])
    per_voyage = np.array([r[0].mean() for r in runs])
    median_ratio = np.array([np.median(r[1]) for r in runs])
    assert all(r[0].size >= 20 for r in runs)  # every voyage has out-of-sample epochs
    pooled = inside.mean()
    assert 0.93 <= pooled <= 0.995, pooled
    assert np.mean(per_voyage >= 0.90) >= 0.90, np.round(per_voyage, 3)
    assert np.mean((median_ratio >= 0.4) & (median_ratio <= 1.4)) >= 0.90, np.round(median_ratio, 2)


def test_shipped_sample_and_simulate_seed_11_are_judged_consistent():
    """The issue's two cases, default configuration: the shipped day at sea and the voyage
    `dracc simulate --seed 11` writes (its defaults: 4 h), against their GNSS."""
    from pathlib import Path

    from dracc.pipeline.analysis import analyse

    sample = Path(__file__).resolve().parents[1] / "sample_logs" / "day" / "voyage_day.mcap"
    for a in (
        analyse([sample], Config()),
        analyse_voyage(voyage_from_sim(simulate(SimParams(seed=11))), Config()),
    ):
        dr = a.dead_reckoning
        assert dr.scored_out_of_sample and dr.n_scored >= 30
        assert dr.verdict.startswith("consistent"), dr.verdict
        assert dr.containment_2m >= 0.9
