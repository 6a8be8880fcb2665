"""Random voyages for the honesty of the learned 2M (issue 31): the test and the benchmark.

Each voyage draws its errors over realistic ranges: log scale -5..+5 %, gyro error
-1..+1 deg, a persistent current of 0.1-2 kn plus a Gauss-Markov variation of 0.05-0.5 kn
with a time constant of 1-24 h, leeway on or off, a gyro or a magnetic compass (with its
own residual deviation curve, A-E each -2..+2 deg, written in HDG or not), latitude
30-65 deg north or south, 6-24 h, 6-20 kn, a new course every 0.5-4 h.  It is simulated
with known truth (dracc.sim) and its DR stage run with ``Config()``, nothing typed in.

At each scored epoch (out of sample: legs whose model was learned from earlier fixes):
the truth inside the drawn 2M, the probability the model states for the truth (its
predictive, dracc.math.uncertainty) and the PIT of the truth's error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from test_pipeline import voyage_from_sim

from dracc.core.config import Config
from dracc.core.geodesy import offset_ne_m
from dracc.math.uncertainty import predictive_cdf, prob_inside
from dracc.pipeline.dr_stage import dead_reckoning
from dracc.sim import GM, SimParams, simulate


def _courses(r: np.random.Generator, hours: float) -> tuple[tuple[float, float], ...]:
    t, out = 0.0, []
    while t < hours * 3600.0:
        out.append((t, float(r.uniform(0.0, 360.0))))
        t += r.uniform(0.5, 4.0) * 3600.0
    return tuple(out)


def random_voyage(seed: int, hours: float | None = None) -> SimParams:
    """One voyage's errors drawn over the ranges of the module doc."""
    r = np.random.default_rng([31, seed])
    h = float(r.uniform(6.0, 24.0)) if hours is None else hours
    leeway = r.random() < 0.5
    magnetic = r.random() < 0.5
    return SimParams(
        duration_s=h * 3600.0,
        seed=seed,
        compass="magnetic" if magnetic else "gyro",
        compass_hz=1.0,
        aux_hz=0.0,
        ins_hz=0.1,
        start_lat_deg=float(r.uniform(30.0, 65.0) * r.choice([-1.0, 1.0])),
        start_lon_deg=float(r.uniform(-180.0, 180.0)),
        speed_kn=float(r.uniform(6.0, 20.0)),
        legs=_courses(r, h),
        log_scale=float(r.uniform(-0.05, 0.05)),
        gyro_offset_deg=float(r.uniform(-1.0, 1.0)),
        deviation_deg=tuple(float(x) for x in r.uniform(-2.0, 2.0, 5)),
        hdg_deviation_field=bool(r.random() < 0.5),
        current_drift_kn=float(r.uniform(0.1, 2.0)),
        current_set_deg=float(r.uniform(0.0, 360.0)),
        current_noise_kn=GM(float(r.uniform(0.05, 0.5)), float(r.uniform(1.0, 24.0)) * 3600.0),
        leeway_deg=float(r.uniform(-3.0, 3.0)) if leeway else 0.0,
        leeway_noise_deg=GM(0.3, 600.0) if leeway else GM(0.0, 600.0),
    )


@dataclass(frozen=True)
class ScoredVoyage:
    """One voyage's scored epochs against the truth."""

    compass: str
    hours: float
    inside: np.ndarray  #: bool: the truth inside the drawn 2M
    stated: np.ndarray  #: the probability the model states for it
    pit: np.ndarray  #: the predictive's P(error below the truth's)
    first_leg: np.ndarray  #: bool: the epoch is in the voyage's first scored leg
    since_fix_s: np.ndarray
    verdict: str  #: the analysis's verdict against the GNSS


def score_voyage(seed: int, hours: float | None = None) -> ScoredVoyage:
    """Simulate voyage ``seed``, run the DR stage with Config(), judge the truth."""
    p = random_voyage(seed, hours)
    sv = simulate(p)
    voyage = voyage_from_sim(sv, drop_roles=("ins1", "ins2", "ins3"))
    section, _, inputs = dead_reckoning(voyage, Config().dead_reckoning, [], [])
    assert section is not None and inputs is not None and inputs.estimated is not None
    est = inputs.estimated
    tr = est.track
    ei = np.asarray(tr.epoch_index)
    ei = ei[(tr.since_fix_s[ei] > 0) & (tr.leg[ei] >= 0)]
    ei = ei[est.learned_leg[tr.leg[ei]]]
    t_ns = inputs.t0_ns + np.round(tr.time_s[ei] * 1e9).astype(np.int64)
    truth_t = sv.truth["time_ns"].to_numpy()
    i = np.clip(np.searchsorted(truth_t, t_ns), 0, truth_t.size - 1)
    dn, de = offset_ne_m(
        tr.lat_rad[ei],
        tr.lon_rad[ei],
        sv.truth["lat_rad"].to_numpy()[i],
        sv.truth["lon_rad"].to_numpy()[i],
    )
    d = np.hypot(dn, de)
    P, shape, radius = tr.P_m2[ei], est.forecast.sample_shape[ei], tr.radius_2m_m[ei]
    legs = tr.leg[ei]
    return ScoredVoyage(
        compass=p.compass,
        hours=p.duration_s / 3600.0,
        inside=d <= radius,
        stated=prob_inside(P, radius, shape),
        pit=predictive_cdf(P, d, shape),
        first_leg=legs == legs.min() if legs.size else np.zeros(0, bool),
        since_fix_s=tr.since_fix_s[ei],
        verdict=section.verdict.split(":")[0],
    )
