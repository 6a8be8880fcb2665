"""The estimated position and its learned error model (dracc.math.ep), against known truth.

The voyages here are written in this file: a water track on chosen courses, a known
current, compass and log errors, and fixes with known noise; dracc's dead reckoning
runs on the measured heading and speed, dracc.math.ep learns from the fixes.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dracc.core.config import DeadReckoningConfig
from dracc.core.geodesy import add_offset_ne, offset_ne_m
from dracc.core.units import DEG_RAD, KN_MPS
from dracc.math.deadreckoning import covered_span_s, dead_reckon, dr_schedule, integrate_ne
from dracc.math.ep import (
    DELTA,
    EPS,
    SCALE,
    ErrorPrior,
    Hyperparameters,
    estimate_position,
    heading_prior_rad,
    hyperparameter_grid,
    sensitivities,
    step_ok_of,
)

LAT0, LON0 = 50.0 * DEG_RAD, -4.0 * DEG_RAD
PRIOR = ErrorPrior(
    current_sigma_mps=0.7 * KN_MPS,
    heading_sigma_rad=0.8 * DEG_RAD,
    scale_sigma=0.013,
    fix_sigma_m=10.0,
)


def _voyage(
    hours=6.0,
    current_ne=(0.4, -0.3),
    eps_deg=0.6,
    scale=0.03,
    fix_noise_m=3.0,
    seed=0,
    turn_every_s=5400.0,
):
    """True and measured series on a 1 s grid; courses change every ``turn_every_s``.

    Measured heading = true course through the water + eps (reads high), measured speed =
    (1 + scale) x true; the ground velocity adds the constant current."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, hours * 3600.0 + 1.0)
    legs = (t // turn_every_s).astype(int)
    course = (np.radians(rng.uniform(0, 360, legs.max() + 1)))[legs]
    course = np.convolve(np.pad(course, 60, mode="edge"), np.ones(121) / 121, "valid")
    speed = np.full(t.size, 6.0)
    vn = speed * np.cos(course) + current_ne[0]
    ve = speed * np.sin(course) + current_ne[1]
    lat, lon = integrate_ne(t, vn, ve, LAT0, LON0)
    noise = rng.normal(0.0, fix_noise_m, (2, t.size))
    flat, flon = add_offset_ne(lat, lon, noise[0], noise[1])
    heading = np.mod(course + eps_deg * DEG_RAD, 2 * math.pi)
    log = (1.0 + scale) * speed
    return t, heading, log, (t, flat, flon), lat, lon


def _ep(t, heading, log, fixes, **kw):
    tr = dead_reckon(
        t,
        heading,
        log,
        fixes=fixes,
        reset_s=kw.pop("reset_s", "1h"),
        epoch_interval_s=600.0,
        covariance=False,
    )
    return tr, estimate_position(tr, *fixes, PRIOR, ref_max_gap_s=5.0, **kw)


def test_sensitivities_are_the_jacobian_of_the_water_velocity():
    c, v = 0.7, 5.0
    J = sensitivities(np.array([v * math.cos(c)]), np.array([v * math.sin(c)]))[0]
    h = 1e-6
    d_eps = (
        np.array([v * math.cos(c + h), v * math.sin(c + h)]) - [v * math.cos(c), v * math.sin(c)]
    ) / h
    d_s = np.array([v * math.cos(c), v * math.sin(c)])  # d/ds of (1 + s) v
    np.testing.assert_allclose(J[:, 0], d_eps, rtol=1e-5)
    np.testing.assert_allclose(J[:, 1], d_s, rtol=1e-12)


def test_learns_current_heading_and_scale_corrections_of_a_known_voyage():
    """Constant current 0.4 N / -0.3 E m/s, heading reads 0.6 deg high, log 3 % high: after
    6 h with course changes the filter's corrections are the true ones within 3 sigma."""
    t, hdg, log, fixes, _lat, _lon = _voyage()
    _, est = _ep(t, hdg, log, fixes)
    m = est.model
    w = m.final_weights
    x = w @ m.final_x
    var = np.einsum("m,mii->i", w, m.final_P) + w @ (m.final_x - x) ** 2
    sd = np.sqrt(var)
    cur = x[2:4] + x[4:6]
    np.testing.assert_allclose(cur, [0.4, -0.3], atol=3 * math.hypot(sd[2], sd[4]) + 0.01)
    assert (
        abs(x[EPS] + x[DELTA] - (-0.6 * DEG_RAD))
        < 3 * math.hypot(sd[EPS], sd[DELTA]) + 0.05 * DEG_RAD
    )
    assert abs(x[SCALE] - (1 / 1.03 - 1)) < 3 * sd[SCALE] + 0.002
    h = m.history
    assert h.updated.sum() > 50 and np.all(np.isfinite(h.current_ne_mps))


def test_estimated_position_follows_the_truth_and_the_water_track_does_not():
    t, hdg, log, fixes, lat, lon = _voyage(current_ne=(0.8, 0.5))
    tr, est = _ep(t, hdg, log, fixes)
    late = (tr.leg >= 2) & (tr.since_fix_s > 1800)
    n_w, e_w = offset_ne_m(tr.lat_rad[late], tr.lon_rad[late], lat[late], lon[late])
    n_e, e_e = offset_ne_m(est.track.lat_rad[late], est.track.lon_rad[late], lat[late], lon[late])
    water_err = np.hypot(n_w, e_w)
    ep_err = np.hypot(n_e, e_e)
    assert np.median(water_err) > 1500.0  # 1.8 kn of current unaccounted for, 30-60 min
    assert np.median(ep_err) < 0.1 * np.median(water_err)
    # the EP's own 2M holds its error
    assert np.mean(ep_err <= est.track.radius_2m_m[late]) > 0.9


def test_causal_a_leg_uses_nothing_from_after_its_start():
    """Moving every fix after 3 h by 2 km changes nothing in the legs that started before."""
    t, hdg, log, fixes, _, _ = _voyage()
    ft, flat, flon = fixes
    late = ft > 3 * 3600.0 + 0.5
    flat2, flon2 = flat.copy(), flon.copy()
    flat2[late], flon2[late] = add_offset_ne(flat[late], flon[late], 2000.0, -1500.0)
    tr1, e1 = _ep(t, hdg, log, fixes)
    _tr2, e2 = _ep(t, hdg, log, (ft, flat2, flon2))
    early = np.isin(tr1.leg, np.flatnonzero(tr1.leg_start_s <= 3 * 3600.0 - 1))
    assert early.sum() > 3 * 3600 - 10
    np.testing.assert_array_equal(e1.track.lat_rad[early], e2.track.lat_rad[early])
    np.testing.assert_array_equal(e1.track.P_m2[early], e2.track.P_m2[early])
    np.testing.assert_array_equal(e1.model.weights[:3], e2.model.weights[:3])
    assert not np.array_equal(e1.track.lat_rad[~early], e2.track.lat_rad[~early])


def test_the_first_leg_learns_nothing_and_is_not_scored():
    t, hdg, log, fixes, _, _ = _voyage(hours=3.0)
    _, est = _ep(t, hdg, log, fixes)
    assert not est.learned_leg[0] and est.learned_leg[1:].all()
    np.testing.assert_allclose(est.model.weights[0], 1.0 / est.model.hyper.size)
    # before anything is learned the circle is honest about the unknown current: a knot
    # or so persists for the whole first hour
    tr = est.track
    k = np.flatnonzero(tr.leg == 0)[-1]
    assert tr.radius_2m_m[k] > 2 * 0.7 * KN_MPS * 3600.0


def test_trace_parts_add_up_to_the_covariance_trace():
    t, hdg, log, fixes, _, _ = _voyage(hours=3.0)
    tr, est = _ep(t, hdg, log, fixes)
    on = tr.leg >= 0
    total = sum(est.forecast.components_m2.values())[on]
    trace = np.trace(est.track.P_m2[on], axis1=1, axis2=2)
    np.testing.assert_allclose(total, trace, rtol=1e-6)


def test_single_point_grid_gives_that_points_covariance_and_no_mixture_spread():
    t, hdg, log, fixes, _, _ = _voyage(hours=3.0)
    one = Hyperparameters(
        *(np.array([v]) for v in (0.1 * KN_MPS, 7200.0, 0.05 * KN_MPS, 300.0, 0.0, 3.0))
    )
    tr, est = _ep(t, hdg, log, fixes, hyper=one)
    assert est.model.hyper.size == 1 and np.all(est.model.weights == 1.0)
    P = est.track.P_m2[tr.leg >= 0]
    assert np.all(np.isfinite(P)) and np.all(np.linalg.eigvalsh(P) > 0)


def test_a_gnss_jump_is_left_out_as_an_outlier():
    t, hdg, log, fixes, _lat, _lon = _voyage(hours=4.0)
    ft, flat, flon = fixes
    jump = (ft > 9000) & (ft < 9030)
    flat2, flon2 = flat.copy(), flon.copy()
    flat2[jump], flon2[jump] = add_offset_ne(flat[jump], flon[jump], 670.0, 0.0)
    step_s = 10.0  # the filter sees the jump at three steps
    _, est = _ep(t, hdg, log, (ft, flat2, flon2), step_s=step_s)
    assert est.model.n_outliers >= 1


def test_step_ok_breaks_at_gaps_not_at_resets():
    t, hdg, log, fixes, _, _ = _voyage(hours=3.0)
    hdg = hdg.copy()
    hdg[5000:5100] = np.nan  # 100 s without heading: the track breaks (max gap 30 s)
    tr = dead_reckon(t, hdg, log, fixes=fixes, reset_s="1h", covariance=False)
    ok = step_ok_of(tr)
    assert not ok[5050] and ok[3599] and ok[3600]  # reset at 3600 s keeps the track running
    assert tr.leg_start_reason[-1] == "reset" and "after-gap" in tr.leg_start_reason


def test_heading_prior_uses_sec_phi_for_a_gyro_only():
    bias, lee = 0.75 / 1.96 * DEG_RAD, 0.5 * DEG_RAD
    at_54 = heading_prior_rad(bias, lee, 54.6 * DEG_RAD, gyro=True)
    assert at_54 == pytest.approx(math.hypot(bias / math.cos(54.6 * DEG_RAD), lee))
    assert heading_prior_rad(bias, lee, 54.6 * DEG_RAD, gyro=False) == pytest.approx(
        math.hypot(bias, lee)
    )
    # METHODS section 7: +-0.75 deg sec phi at 54.6 N is 1.30 deg (95 %), sigma 0.66 deg
    assert bias / math.cos(54.6 * DEG_RAD) / DEG_RAD == pytest.approx(0.66, abs=0.005)


def test_grid_spans_the_documented_ranges():
    g = hyperparameter_grid(10.0)
    assert g.size == 4 * 3 * 3 * 2 * 2 * 4
    assert set(np.round(g.fix_sigma_m, 6)) == {1.0, 3.0, 10.0, 30.0}
    np.testing.assert_allclose(g.noise_psd_m2ps, 2 * g.noise_sigma_mps**2 * g.noise_tau_s)


@pytest.mark.parametrize(
    "span_h, reset_s, epoch_s",
    [
        (24.0, 3600.0, 600.0),
        (8.0, 3600.0, 600.0),
        (6.0, 1800.0, 300.0),
        (0.37, 120.0, 20.0),
        (0.04, 30.0, 5.0),
    ],
)
def test_auto_schedule(span_h, reset_s, epoch_s):
    r, label, e = dr_schedule(DeadReckoningConfig(), span_h * 3600.0)
    assert (r, e) == (reset_s, epoch_s) and label.startswith("auto (")
    assert dr_schedule(DeadReckoningConfig(reset="4h"), 3600.0) == (14400.0, "4h", 600.0)
    assert dr_schedule(DeadReckoningConfig(epoch_interval_s=60.0), 36000.0)[2] == 60.0


def test_covered_span_ignores_a_stray_record_years_away():
    t = np.r_[0.0, 4 * 365 * 86400.0 + np.arange(3000.0)]
    assert covered_span_s(t, 30.0) == 2999.0
