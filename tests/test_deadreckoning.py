"""Dead reckoning (B1-B31): course made good, velocities, WGS-84 integration, covariance.

Independent values: hand calculations, GeographicLib (geodesic Direct; meridian arcs for
an isometric-latitude rhumb line, as the Python GeographicLib has no Rhumb class), brute
force double sums, and numerical Jacobians.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

from dracc.core.config import DeadReckoningConfig, ErrorSource
from dracc.core.durations import WATCH_S, parse_reset_s
from dracc.core.errors import ConfigError, InsufficientDataError
from dracc.core.geodesy import A_M, E2, distance_m, k_lambda, k_phi
from dracc.math.deadreckoning import (
    course_gyro_rad,
    course_magnetic_rad,
    covariance_b23_rad2,
    covariance_m2_from_rad2,
    dead_reckon,
    deviation_curve_rad,
    deviation_table_rad,
    error_processes,
    gauss_markov_position_covariance_m2,
    honest_covariance_m2,
    integrate_ne,
    interp_deviation_rad,
    leeway_from_log_rad,
    mean_error_m,
    sigma_course_rad,
    speed_covariance_rad2,
    speed_from_components_mps,
    total_leeway_rad,
    true_heading_rad,
    velocity_ground_ne_mps,
    velocity_water_ne_mps,
)
from dracc.math.ellipse import error_ellipse
from dracc.math.uncertainty import prob_inside_2m

geographiclib = pytest.importorskip("geographiclib.geodesic")
GEOD = geographiclib.Geodesic.WGS84
D = math.pi / 180.0

# ---------------------------------------------------------------- course and speed (B1-B14)


def test_b1_speed_from_two_component_log():
    assert speed_from_components_mps(3.0, 4.0) == pytest.approx(5.0)


def test_b5_b6_leeway_angle_starboard_positive_and_sternway_kept():
    assert leeway_from_log_rad(5.0, 5.0) == pytest.approx(math.pi / 4)
    assert leeway_from_log_rad(5.0, -0.5) == pytest.approx(math.atan(-0.1))
    # going astern (Vx < 0) the velocity points aft, not forward as arctg(Vy/Vx) would say
    assert leeway_from_log_rad(-1.0, 0.0) == pytest.approx(math.pi)


def test_b4_total_leeway_is_drift_plus_leeway():
    assert total_leeway_rad(0.02, 0.03) == pytest.approx(0.05)


def test_b2_magnetic_course_made_good_hand_value_and_wrap():
    # KK 355, d +3 E, delta +4, z -1  ->  361 -> 1 degree
    got = course_magnetic_rad(355 * D, 3 * D, 4 * D, -1 * D)
    assert got == pytest.approx(1 * D)


def test_b3_gyro_course_made_good_hand_value():
    assert course_gyro_rad(10 * D, -0.5 * D, 2 * D) == pytest.approx(11.5 * D)


def test_deviation_curve_hand_value():
    coef = np.array([1.0, 2.0, -1.0, 0.5, 0.25]) * D
    k = 30 * D
    want = (1 + 2 * 0.5 - math.cos(k) + 0.5 * math.sin(2 * k) + 0.25 * math.cos(2 * k)) * D
    assert deviation_curve_rad(k, coef) == pytest.approx(want)


def test_deviation_table_interpolates_across_north():
    h, dev = deviation_table_rad({"350": 2.0, "10": -2.0, "180": 1.0})
    assert interp_deviation_rad(0.0, h, dev) == pytest.approx(0.0, abs=1e-12)
    assert interp_deviation_rad(355 * D, h, dev) == pytest.approx(1.0 * D)
    assert interp_deviation_rad(95 * D, h, dev) == pytest.approx(-0.5 * D)


@pytest.mark.parametrize("table", [{"north": 1.0}, {"400": 1.0}, {"0": 1.0, "360": 2.0}, {}])
def test_deviation_table_rejects_bad_entries(table):
    with pytest.raises(ConfigError, match="deviation_table"):
        deviation_table_rad(table)


def test_b10_misprint_east_component_of_current_is_sin_kp():
    # Current 1 m/s setting east (Kp = 90 deg), ship stopped: all of it must go east.
    # The paper's (B10) prints Vp cos Kp, which would give 0 east.
    vn, ve = velocity_water_ne_mps(0.0, 0.0, 1.0, 90 * D)
    assert vn == pytest.approx(0.0, abs=1e-15)
    assert ve == pytest.approx(1.0)
    vn, ve = velocity_water_ne_mps(5.0, 30 * D, 0.5, 168 * D)
    assert vn == pytest.approx(5 * math.cos(30 * D) + 0.5 * math.cos(168 * D))
    assert ve == pytest.approx(5 * math.sin(30 * D) + 0.5 * math.sin(168 * D))


def test_b13_b14_ground_log_components():
    vn, ve = velocity_ground_ne_mps(2.0, 120 * D)
    assert (vn, ve) == pytest.approx((-1.0, math.sqrt(3.0)))


# ------------------------------------------------------------- integration (B16-B22)


def _meridian_arc_m(lat_rad: float) -> float:
    """Signed distance along the meridian from the equator (GeographicLib)."""
    s = GEOD.Inverse(0.0, 0.0, abs(lat_rad) / D, 0.0)["s12"]
    return math.copysign(s, lat_rad)


def _isometric_lat(lat_rad: float) -> float:
    e = math.sqrt(E2)
    return math.asinh(math.tan(lat_rad)) - e * math.atanh(e * math.sin(lat_rad))


def _rhumb_direct(lat1_rad, lon1_rad, azi_rad, s_m):
    """Rhumb line on the ellipsoid: meridian arc for latitude, isometric latitude for longitude."""
    mu2 = _meridian_arc_m(lat1_rad) + s_m * math.cos(azi_rad)
    lat2 = brentq(lambda x: _meridian_arc_m(x) - mu2, -1.5, 1.5, xtol=1e-14)
    if abs(math.cos(azi_rad)) > 1e-9:
        dlon = math.tan(azi_rad) * (_isometric_lat(lat2) - _isometric_lat(lat1_rad))
    else:  # along a parallel
        dlon = (
            s_m
            * math.sin(azi_rad)
            * math.sqrt(1 - E2 * math.sin(lat1_rad) ** 2)
            / (A_M * math.cos(lat1_rad))
        )
    return lat2, lon1_rad + dlon


@pytest.mark.parametrize("lat_deg", [0.0, 45.0, 70.0, -33.0])
@pytest.mark.parametrize("azi_deg", [0.0, 37.0, 90.0, 200.0, 315.0])
def test_short_leg_matches_geographiclib_geodesic(lat_deg, azi_deg):
    """300 m at 5 m/s, 1 Hz, against the geodesic: they part only by the rhumb line's
    curvature, s^2 tan(phi) sin(azi) / (2 R) (19 mm at 70 deg); over 2 km the end points
    are still 2000 m apart along the geodesic (to a few mm)."""
    t = np.arange(0.0, 400.0 + 0.5, 1.0)
    vn, ve = velocity_ground_ne_mps(np.full(t.size, 5.0), azi_deg * D)
    lat, lon = integrate_ne(t, vn, ve, lat_deg * D, 11 * D)
    g = GEOD.Direct(lat_deg, 11.0, azi_deg, 300.0)
    bend_m = 300.0**2 * abs(math.tan(lat_deg * D) * math.sin(azi_deg * D)) / (2 * 6.37e6)
    assert distance_m(lat[60], lon[60], g["lat2"] * D, g["lon2"] * D) < 1.1 * bend_m + 0.002
    inv = GEOD.Inverse(lat_deg, 11.0, lat[-1] / D, lon[-1] / D)
    assert inv["s12"] == pytest.approx(2000.0, abs=0.005)


@pytest.mark.parametrize("lat_deg", [10.0, 57.0, -60.0])
@pytest.mark.parametrize("azi_deg", [0.0, 28.0, 90.0, 135.0, 251.0])
def test_long_leg_matches_rhumb_line(lat_deg, azi_deg):
    """100 km on a constant course at 10 s steps: a rhumb line, within 0.5 m."""
    t = np.arange(0.0, 10000.0 + 1.0, 10.0)
    vn, ve = velocity_ground_ne_mps(np.full(t.size, 10.0), azi_deg * D)
    lat, lon = integrate_ne(t, vn, ve, lat_deg * D, -5 * D)
    lat2, lon2 = _rhumb_direct(lat_deg * D, -5 * D, azi_deg * D, 100_000.0)
    assert distance_m(lat[-1], lon[-1], lat2, lon2) < 0.5


def test_integration_crosses_the_antimeridian():
    t = np.arange(0.0, 1001.0)
    _lat, lon = integrate_ne(t, np.zeros(t.size), np.full(t.size, 10.0), 0.0, 179.99 * D)
    assert -math.pi < lon[-1] < -179.9 * D


def test_integration_broadcasts_over_runs():
    t = np.arange(0.0, 101.0)
    vn = np.stack([np.full(t.size, 1.0), np.full(t.size, 2.0)])
    lat, _ = integrate_ne(t, vn, np.zeros_like(vn), np.array([0.1, 0.2]), 0.0)
    one, _ = integrate_ne(t, vn[1], np.zeros(t.size), 0.2, 0.0)
    assert lat.shape == (2, t.size)
    np.testing.assert_allclose(lat[1], one, rtol=0, atol=1e-15)


def test_noiseless_voyage_no_current_within_5m_after_6h():
    """Twelve legs of 30 min on changing courses at 1 Hz; truth from rhumb lines per leg."""
    rng = np.random.default_rng(7)
    courses = rng.uniform(0, 2 * math.pi, 12)
    speeds = rng.uniform(3.0, 8.0, 12)
    leg_s = 1800.0
    t = np.arange(0.0, 12 * leg_s + 0.5, 1.0)
    leg = np.minimum((t // leg_s).astype(int), 11)
    lat_t, lon_t = 54.3 * D, 10.1 * D
    truth = [(lat_t, lon_t)]
    for c, v in zip(courses, speeds, strict=True):
        lat_t, lon_t = _rhumb_direct(lat_t, lon_t, c, v * leg_s)
        truth.append((lat_t, lon_t))
    tr = dead_reckon(
        t,
        courses[leg],
        speeds[leg],
        lat0_rad=54.3 * D,
        lon0_rad=10.1 * D,
        reset_s="never",
        mode="ground",
    )
    ends = (np.arange(1, 13) * leg_s).astype(int)
    err = distance_m(tr.lat_rad[ends], tr.lon_rad[ends], *np.array(truth[1:]).T)
    assert err.max() < 5.0
    assert tr.n_legs == 1 and tr.gaps == ()


# ---------------------------------------------------------- the paper's covariance (B23-B31)


def test_b23_two_step_hand_example_reproduces_b26_to_b31():
    """Two steps by hand, every term written out from (B26)-(B31)."""
    lat = 54.0 * D
    kp = (1 - E2 * math.sin(lat) ** 2) ** 1.5 / (A_M * (1 - E2))  # (B18)
    kl = (1 - E2 * math.sin(lat) ** 2) ** 0.5 / (A_M * math.cos(lat))  # (B19)
    v, s_v = 6.0, 0.1
    s_c = math.sqrt((0.5 * D) ** 2 + (0.2 * D) ** 2 + (1.0 * D) ** 2)  # (B29)
    assert sigma_course_rad(0.5 * D, 0.2 * D, 1.0 * D) == pytest.approx(s_c)
    P0 = np.diag([(10 * kp) ** 2, (10 * kl) ** 2])  # 10 m per axis
    steps = [(60.0, 30 * D), (120.0, 120 * D)]  # (dt, course)
    P = P0.copy()
    for dt, c in steps:
        var_phi = kp**2 * ((s_v * math.cos(c)) ** 2 + (v * s_c * math.sin(c)) ** 2)
        var_lam = kl**2 * ((s_v * math.sin(c)) ** 2 + (v * s_c * math.cos(c)) ** 2)
        cov = 0.5 * kp * kl * (s_v**2 - v**2 * s_c**2) * math.sin(2 * c)
        P = P + dt**2 * np.array([[var_phi, cov], [cov, var_lam]])
    M = math.sqrt(P[0, 0] / kp**2 + P[1, 1] / kl**2)
    t = np.array([0.0, 60.0, 180.0])
    course = np.array([30 * D, 120 * D, 120 * D])
    got = covariance_b23_rad2(t, lat, v, course, s_v, s_c, P0)
    np.testing.assert_allclose(got[-1], P, rtol=1e-12)
    assert mean_error_m(got[-1], lat) == pytest.approx(M, rel=1e-12)  # (B30)
    # the numbers, so that a change of convention shows: M and 2M (B31) in metres
    assert (
        pytest.approx(
            math.sqrt(
                200
                + (60 * 0.1) ** 2
                + (120 * 0.1) ** 2
                + (60 * 6 * s_c) ** 2
                + (120 * 6 * s_c) ** 2
            ),
            rel=1e-12,
        )
        == M
    )
    P_m2 = covariance_m2_from_rad2(got[-1], lat)
    assert 2 * math.sqrt(np.trace(P_m2)) == pytest.approx(2 * M, rel=1e-12)  # (B31)


def test_b28_misprint_common_factor_kphi_klambda():
    """(B28) as printed, 1/2 (k_phi^2 sV^2 - k_lambda^2 V^2 sC^2) sin 2C, is wrong; the
    Jacobian of [k_phi V cos C, k_lambda V sin C] gives 1/2 k_phi k_lambda (sV^2 - V^2 sC^2) sin 2C."""
    lat, v, c, s_v, s_c = 60 * D, 7.0, 50 * D, 0.2, 1.5 * D
    kp, kl = k_phi(lat), k_lambda(lat)
    J = np.array(
        [[kp * math.cos(c), -kp * v * math.sin(c)], [kl * math.sin(c), kl * v * math.cos(c)]]
    )
    want = J @ np.diag([s_v**2, s_c**2]) @ J.T
    got = speed_covariance_rad2(lat, v, c, s_v, s_c)
    np.testing.assert_allclose(got, want, rtol=1e-12)
    printed = 0.5 * (kp**2 * s_v**2 - kl**2 * v**2 * s_c**2) * math.sin(2 * c)
    assert abs(printed - want[0, 1]) > 0.5 * abs(want[0, 1])


def test_error_ellipse_against_eigh_and_orientation():
    P = np.array([[400.0, 120.0], [120.0, 100.0]])
    a, b, th = error_ellipse(P)
    w, vec = np.linalg.eigh(P)
    assert (a, b) == pytest.approx((math.sqrt(w[1]), math.sqrt(w[0])))
    major = vec[:, 1]
    assert math.cos(th) * major[1] - math.sin(th) * major[0] == pytest.approx(0.0, abs=1e-12)
    # a pure east-west ellipse is oriented 90 degrees
    assert error_ellipse(np.diag([1.0, 9.0]))[2] == pytest.approx(math.pi / 2)


def test_prob_inside_2m_circle_and_line_limits_and_simulation():
    assert prob_inside_2m(np.eye(2) * 25.0) == pytest.approx(1 - math.exp(-4), abs=1e-10)
    assert prob_inside_2m(np.diag([25.0, 0.0])) == pytest.approx(0.954499736, abs=1e-8)
    P = np.array([[400.0, 120.0], [120.0, 100.0]])
    x = np.random.default_rng(3).multivariate_normal([0, 0], P, 400_000)
    frac = np.mean(np.hypot(x[:, 0], x[:, 1]) <= 2 * math.sqrt(np.trace(P)))
    assert prob_inside_2m(P) == pytest.approx(frac, abs=0.0015)


# ------------------------------------------------------------- honest (Gauss-Markov) covariance


def test_gauss_markov_covariance_equals_brute_force_double_sum():
    rng = np.random.default_rng(1)
    t = np.cumsum(np.r_[0, rng.uniform(0.5, 30, 40)])
    g = rng.normal(size=(41, 2))
    sigma, tau = 0.7, 50.0
    got = gauss_markov_position_covariance_m2(t, g, sigma, tau)
    dt = np.diff(t)
    # Cov of the integrals over the steps, from the exponential autocovariance directly
    fine = [np.linspace(t[i], t[i + 1], 161) for i in range(dt.size)]
    K = np.zeros((dt.size, dt.size))
    for i in range(dt.size):
        for k in range(dt.size):
            R = sigma**2 * np.exp(-np.abs(fine[i][:, None] - fine[k][None, :]) / tau)
            K[i, k] = np.trapezoid(np.trapezoid(R, fine[k], axis=1), fine[i])
    for n in (1, 7, 40):
        G = g[:n]
        np.testing.assert_allclose(got[n], G.T @ K[:n, :n] @ G, rtol=1e-4)


def test_gauss_markov_long_track_blocks_stay_finite_and_match_bias_limit():
    """Spans of many tau use several blocks; tau >> span tends to the bias result."""
    t = np.arange(0.0, 86400.0 + 1, 5.0)
    g = np.tile([0.0, 1.0], (t.size, 1))
    short = gauss_markov_position_covariance_m2(t, g, 1.0, 60.0)
    assert np.all(np.isfinite(short))
    # long span, short tau: random walk, variance -> 2 sigma^2 tau T
    assert short[-1, 1, 1] == pytest.approx(2 * 60.0 * 86400.0, rel=0.01)
    nearly_bias = gauss_markov_position_covariance_m2(t, g, 1.0, 1e12)
    bias = gauss_markov_position_covariance_m2(t, g, 1.0, math.inf)
    assert bias[-1, 1, 1] == pytest.approx(86400.0**2)
    np.testing.assert_allclose(nearly_bias[-1], bias[-1], rtol=1e-6, atol=1e-6)


def test_tau_zero_is_the_paper_b23_form():
    lat = 40 * D
    t = np.array([0.0, 10.0, 25.0, 30.0])
    course = np.array([0.3, 1.2, 2.0, 2.0])
    v = np.array([5.0, 6.0, 4.0, 4.0])
    cfg = DeadReckoningConfig(
        compass_bias_deg=ErrorSource(0.0),
        compass_noise_deg=ErrorSource(1.0, 0.0),
        log_scale=ErrorSource(0.0),
        log_bias_kn=ErrorSource(0.0),
        log_noise_kn=ErrorSource(0.3, 0.0),
    )
    honest = honest_covariance_m2(t, v, course, error_processes(cfg, "ground"))
    paper = covariance_b23_rad2(t, lat, v, course, 0.3 * 1852 / 3600, 1.0 * D, np.zeros((2, 2)))
    np.testing.assert_allclose(honest, covariance_m2_from_rad2(paper, lat), rtol=1e-10, atol=1e-12)


def _winding_track(hz: float, hours: float = 2.0):
    t = np.arange(0.0, hours * 3600 + 1e-9, 1.0 / hz)
    course = (40 * D + 1.2 * np.sin(t / 900.0)) % (2 * math.pi)
    speed = 6.0 + 0.5 * np.cos(t / 700.0)
    return t, course, speed


def test_covariance_independent_of_logging_rate():
    """0.1 Hz, 1 Hz and 10 Hz logs of one voyage give the same 2M within 1 %."""
    radii = []
    for hz in (0.1, 1.0, 10.0):
        t, c, v = _winding_track(hz)
        tr = dead_reckon(t, c, v, lat0_rad=0.9, lon0_rad=0.1, reset_s="never")
        radii.append(tr.radius_2m_m[-1])
        sel = np.searchsorted(t, 1800.0)
        radii.append(tr.radius_2m_m[sel])
    r = np.array(radii).reshape(3, 2)
    np.testing.assert_allclose(r, np.broadcast_to(r[2], r.shape), rtol=0.01)


def test_paper_form_shrinks_with_logging_rate_where_honest_does_not():
    """The reason for the honest form: (B23) at 10 Hz gives a circle ~sqrt(100) smaller than at 0.1 Hz."""
    out = []
    for hz in (0.1, 10.0):
        t, c, v = _winding_track(hz, hours=1.0)
        P = covariance_b23_rad2(t, 0.9, v, c, 0.1, 1 * D, np.zeros((2, 2)))
        out.append(mean_error_m(P[-1], 0.9))
    assert out[0] / out[1] == pytest.approx(10.0, rel=0.05)


def test_straight_course_bias_gives_cross_track_sigma_v_t_sigma_c():
    cfg = DeadReckoningConfig(
        compass_bias_deg=ErrorSource(1.0),
        compass_noise_deg=ErrorSource(0.0),
        log_scale=ErrorSource(0.0),
        log_bias_kn=ErrorSource(0.0),
        log_noise_kn=ErrorSource(0.0),
        fix_sigma_m=0.0,
    )
    t = np.arange(0.0, 3601.0, 1.0)
    tr = dead_reckon(
        t,
        np.zeros(t.size),
        np.full(t.size, 5.0),
        errors=cfg,
        lat0_rad=0.5,
        lon0_rad=0.0,
        mode="ground",
    )
    assert tr.semi_major_m[-1] == pytest.approx(5.0 * 3600 * D, rel=1e-9)  # V T sigma_C
    assert tr.semi_minor_m[-1] == pytest.approx(0.0, abs=1e-6)
    assert tr.orientation_rad[-1] == pytest.approx(math.pi / 2)  # across a northerly track


# ---------------------------------------------------------------- dead_reckon: legs and gaps


def _fixes(t_fix, lat, lon):
    return (t_fix, np.full(t_fix.size, lat), np.full(t_fix.size, lon), np.full(t_fix.size, 7.0))


def test_restarts_every_hour_from_fixes_with_fix_covariance():
    t = np.arange(0.0, 3 * 3600 + 1, 1.0)
    tf = np.arange(0.0, 3 * 3600 + 1, 60.0)
    tr = dead_reckon(
        t, np.full(t.size, 1.0), np.full(t.size, 5.0), fixes=_fixes(tf, 0.8, 0.2), reset_s="1h"
    )
    np.testing.assert_allclose(tr.leg_start_s, [0.0, 3600.0, 7200.0, 10800.0])
    assert tr.leg_start_reason == ("start", "reset", "reset", "reset")
    k = 3600
    np.testing.assert_allclose(tr.P_m2[k], 49.0 * np.eye(2))
    assert tr.lat_rad[k] == 0.8 and tr.since_fix_s[k] == 0.0
    assert tr.since_fix_s[k - 1] == 3599.0
    assert tr.radius_2m_m[k - 1] > 10 * tr.radius_2m_m[k]
    # epochs every 10 min
    np.testing.assert_allclose(tr.time_s[tr.epoch_index], np.arange(0, 10801, 600.0))


def test_reset_never_and_watch():
    t = np.arange(0.0, 9 * 3600 + 1, 10.0)
    tf = np.arange(0.0, 9 * 3600 + 1, 60.0)
    h, v = np.full(t.size, 1.0), np.full(t.size, 5.0)
    assert dead_reckon(t, h, v, fixes=_fixes(tf, 0.8, 0.2), reset_s="never").n_legs == 1
    tr = dead_reckon(t, h, v, fixes=_fixes(tf, 0.8, 0.2), reset_s="watch")
    np.testing.assert_allclose(tr.leg_start_s, [0.0, WATCH_S, 2 * WATCH_S])


def test_fix_between_samples_is_advanced_to_the_next_sample():
    t = np.arange(0.0, 200.0, 10.0)
    tf = np.array([95.0])
    tr = dead_reckon(
        t,
        np.zeros(t.size),
        np.full(t.size, 2.0),
        lat0_rad=0.0,
        lon0_rad=0.0,
        fixes=(tf, np.array([0.5]), np.array([0.0]), np.array([3.0])),
        reset_s=50.0,
    )
    k = 10  # t = 100
    assert tr.leg[k] == 1
    assert (tr.lat_rad[k] - 0.5) / k_phi(0.5) == pytest.approx(10.0, rel=1e-6)  # 5 s at 2 m/s


def test_short_gap_bridged_and_reported():
    t = np.arange(0.0, 600.0, 1.0)
    h = np.full(t.size, 0.5)
    h[100:120] = np.nan  # 21 s between valid samples 99 and 120
    tr = dead_reckon(t, h, np.full(t.size, 4.0), lat0_rad=0.3, lon0_rad=0.0, max_gap_s=30.0)
    assert tr.n_legs == 1 and tr.n_breaks == 0
    assert len(tr.gaps) == 1 and tr.gaps[0].bridged and tr.gaps[0].duration_s == 21.0
    assert tr.n_invalid_samples == 20
    full = dead_reckon(t, np.full(t.size, 0.5), np.full(t.size, 4.0), lat0_rad=0.3, lon0_rad=0.0)
    np.testing.assert_allclose(tr.lat_rad, full.lat_rad, rtol=0, atol=1e-15)


def test_long_gap_breaks_track_until_next_fix():
    t = np.arange(0.0, 2000.0, 1.0)
    v = np.full(t.size, 4.0)
    v[500:700] = np.nan
    tf = np.array([650.0, 900.0, 1500.0])
    fx = (tf, np.full(3, 0.31), np.full(3, 0.01), np.full(3, 5.0))
    tr = dead_reckon(
        t,
        np.zeros(t.size),
        v,
        lat0_rad=0.3,
        lon0_rad=0.0,
        fixes=fx,
        reset_s="never",
        max_gap_s=30.0,
    )
    assert tr.n_breaks == 1 and not tr.gaps[0].bridged
    assert np.isfinite(tr.lat_rad[499]) and np.all(np.isnan(tr.lat_rad[500:900]))
    assert tr.leg_start_reason == ("start", "after-gap")
    assert tr.leg_start_s[1] == 900.0 and tr.lat_rad[900] == pytest.approx(0.31)


def test_break_without_fixes_leaves_rest_unknown():
    t = np.arange(0.0, 300.0)
    h = np.zeros(t.size)
    h[100:200] = np.nan
    tr = dead_reckon(t, h, np.full(t.size, 1.0), lat0_rad=0.0, lon0_rad=0.0, max_gap_s=10)
    assert np.all(np.isnan(tr.lat_rad[100:])) and tr.n_breaks == 1


def test_no_heading_at_all_raises_instead_of_steering_north():
    t = np.arange(0.0, 10.0)
    with pytest.raises(InsufficientDataError, match=r"no heading.*not assume north"):
        dead_reckon(t, np.full(t.size, np.nan), np.ones(t.size), lat0_rad=0.0, lon0_rad=0.0)


def test_no_start_position_raises():
    t = np.arange(0.0, 10.0)
    with pytest.raises(InsufficientDataError, match="start position"):
        dead_reckon(t, np.zeros(t.size), np.ones(t.size))


def test_water_mode_adds_current_and_transverse_log_leeway():
    t = np.arange(0.0, 101.0)
    tr = dead_reckon(
        t,
        np.zeros(t.size),
        np.full(t.size, 3.0),
        transverse_mps=np.full(t.size, 4.0),
        current_ne_mps=[0.0, -4.0],
        lat0_rad=0.0,
        lon0_rad=0.0,
    )
    # (B1) V = 5, (B5) alpha = atan2(4, 3); east component 5 sin(alpha) = 4 cancels the current
    assert tr.vn_mps[0] == pytest.approx(3.0) and tr.ve_mps[0] == pytest.approx(0.0, abs=1e-12)
    assert {p.name for p in error_processes(DeadReckoningConfig(), "ground")}.isdisjoint(
        {"current_kn", "leeway_deg"}
    )


@pytest.mark.parametrize(
    "text,want",
    [
        ("1h", 3600.0),
        ("30min", 1800.0),
        ("90s", 90.0),
        ("watch", 4 * 3600.0),
        ("never", math.inf),
        (120, 120.0),
    ],
)
def test_parse_reset(text, want):
    assert parse_reset_s(text) == want


@pytest.mark.parametrize("text", ["hourly", "-1h", "0h", "1 fortnight"])
def test_parse_reset_rejects(text):
    with pytest.raises(ConfigError, match="reset"):
        parse_reset_s(text)


def test_negative_sigma_in_config_is_a_config_error():
    cfg = DeadReckoningConfig(log_noise_kn=ErrorSource(-0.1, 10.0))
    with pytest.raises(ConfigError, match="log_noise_kn"):
        error_processes(cfg)


def test_union_time_base_holds_each_channel_independently():
    """10 Hz compass and 1 Hz log on one union time base (NaN where a channel has no
    sample): each value is held until its next sample, nothing is reported as a gap."""
    t = np.arange(0.0, 600.0, 0.1)
    h = 0.4 + 0.3 * np.sin(t / 60.0)
    v_full = 5.0 + np.floor(t) * 0.001  # the log's value changes once a second
    v = np.where(np.isclose(t % 1.0, 0.0) | np.isclose(t % 1.0, 1.0), v_full, np.nan)
    tr = dead_reckon(t, h, v, lat0_rad=0.2, lon0_rad=0.3)
    ref = dead_reckon(t, h, v_full, lat0_rad=0.2, lon0_rad=0.3)
    assert tr.gaps == () and tr.n_legs == 1
    np.testing.assert_allclose(tr.lat_rad, ref.lat_rad, rtol=0, atol=1e-13)
    np.testing.assert_allclose(tr.P_m2, ref.P_m2, rtol=1e-12)


def test_gap_names_its_channel():
    t = np.arange(0.0, 100.0)
    v = np.ones(t.size)
    v[40:45] = np.nan
    tr = dead_reckon(t, np.zeros(t.size), v, lat0_rad=0.0, lon0_rad=0.0)
    assert [(g.channel, g.bridged) for g in tr.gaps] == [("speed", True)]


def test_real_log_without_heading_says_so(real_dir):
    """signalk-server/plaka.log: VHW speed but every HDT/HDM heading field is empty."""
    path = real_dir / "signalk-server" / "plaka.log"
    if not path.exists():
        pytest.skip("plaka.log not present")
    heading, speed = [], []
    for line in path.read_text(errors="replace").splitlines()[:20000]:
        f = line.split("*")[0].split(",")
        if f[0] in ("$IIHDT", "$IIHDM"):
            heading.append(float(f[1]) * D if f[1] else np.nan)
        elif f[0] == "$IIVHW":
            speed.append(float(f[5]) * 1852 / 3600 if f[5] else np.nan)
    n = min(len(heading), len(speed))
    assert n > 100 and np.isfinite(speed[:n]).any()
    with pytest.raises(InsufficientDataError, match="no heading"):
        dead_reckon(
            np.arange(float(n)),
            np.array(heading[:n]),
            np.array(speed[:n]),
            lat0_rad=0.6,
            lon0_rad=0.4,
        )


def test_true_heading_from_mixed_gyro_and_magnetic_samples():
    cfg = DeadReckoningConfig(variation_deg=2.0, deviation_table={"0": 1.0, "180": -1.0})
    h = np.array([10.0, 10.0, 10.0, 90.0]) * D
    th = true_heading_rad(
        h,
        ["T", "M", "M", "M"],
        deviation_rad=[np.nan, 0.5 * D, np.nan, np.nan],
        variation_rad=[np.nan, 3.0 * D, np.nan, np.nan],
        errors=cfg,
    )
    want = np.array([10.0, 10 + 3 + 0.5, 10 + 2 + (1 - 2 * 10 / 180), 90 + 2 + 0.0]) * D
    np.testing.assert_allclose(th.heading_rad, want, atol=1e-12)
    assert (th.n_magnetic, th.n_variation_from_sentence, th.n_variation_from_config) == (3, 1, 2)
    assert th.deviation_source == "mixed"


def test_true_heading_magnetic_without_variation_raises():
    with pytest.raises(InsufficientDataError, match="variation_deg"):
        true_heading_rad(np.array([0.3]), "M")


def _variation_counts(th):
    """(from sentence, placeholder, from config, missing): a partition of the magnetic samples."""
    counts = (
        th.n_variation_from_sentence,
        th.n_variation_placeholder,
        th.n_variation_from_config,
        th.n_variation_missing,
    )
    assert sum(counts) == th.n_magnetic
    return counts


def test_true_heading_configured_variation_replaces_a_zero_placeholder():
    """HDG ...,0.0,E: with variation_deg set, a 0.0 field is a placeholder and the
    configured 4 deg is applied; a non-zero field is kept; no field is filled."""
    th = true_heading_rad(
        np.array([10.0, 20.0, 30.0, 40.0]) * D,
        "M",
        deviation_rad=np.zeros(4),
        variation_rad=[0.0, 3.0 * D, np.nan, 0.0],
        errors=DeadReckoningConfig(variation_deg=4.0),
    )
    np.testing.assert_allclose(th.heading_rad, np.array([14.0, 23.0, 34.0, 44.0]) * D, atol=1e-12)
    assert _variation_counts(th) == (1, 2, 1, 0)


def test_true_heading_without_configured_variation_uses_a_zero_as_sent():
    th = true_heading_rad(
        np.array([10.0, 20.0]) * D, "M", np.zeros(2), [0.0, 3.0 * D], errors=DeadReckoningConfig()
    )
    np.testing.assert_allclose(th.heading_rad, np.array([10.0, 23.0]) * D, atol=1e-12)
    assert _variation_counts(th) == (1, 1, 0, 0)


def test_true_heading_missing_variation_zero_takes_0_and_counts_it():
    """No variation sent and none configured: "raise" (the default) refuses, "zero"
    takes 0 there and says how many samples."""
    h = np.array([10.0, 20.0, 30.0]) * D
    var = [np.nan, 2.0 * D, 0.0]
    with pytest.raises(InsufficientDataError, match=r"^1 magnetic heading samples have no"):
        true_heading_rad(h, "M", np.zeros(3), var)
    with pytest.raises(InsufficientDataError, match="variation_deg"):
        true_heading_rad(h, "M", np.zeros(3), var, missing_variation="raise")
    th = true_heading_rad(h, "M", np.zeros(3), var, missing_variation="zero")
    np.testing.assert_allclose(th.heading_rad, np.array([10.0, 22.0, 30.0]) * D, atol=1e-12)
    assert _variation_counts(th) == (1, 1, 0, 1)
    # a configured variation fills the gap in either mode: nothing is missing
    cfg = DeadReckoningConfig(variation_deg=-1.5)
    th = true_heading_rad(h, "M", np.zeros(3), var, errors=cfg, missing_variation="zero")
    np.testing.assert_allclose(th.heading_rad, np.array([8.5, 22.0, 28.5]) * D, atol=1e-12)
    assert _variation_counts(th) == (1, 1, 1, 0)


def test_true_heading_reference_per_sample_in_any_container():
    """The reference per sample as a list, an object array with None/NaN, a pandas
    Categorical or Series: 'M' or 'm' is magnetic, anything else (missing too) is not."""
    pd = pytest.importorskip("pandas")
    h = np.array([10.0, 20.0, 30.0, 40.0, 50.0]) * D
    refs = ["M", "T", None, "m", "T"]
    want = np.array([13.0, 20.0, 30.0, 43.0, 50.0]) * D
    cfg = DeadReckoningConfig(variation_deg=3.0)
    for ref in (
        refs,
        np.array(refs, dtype=object),
        np.array(["M", "T", np.nan, "m", "T"], dtype=object),
        pd.Categorical(refs),
        pd.Series(refs, dtype="category"),
        pd.array(refs, dtype="string"),
    ):
        th = true_heading_rad(h, ref, np.zeros(5), errors=cfg)
        np.testing.assert_allclose(th.heading_rad, want, atol=1e-12)
        assert (th.n_magnetic, th.n_variation_from_config) == (2, 2)
    assert true_heading_rad(h, "t", errors=cfg).n_magnetic == 0


# ---------------------------------------------------------------- properties (hypothesis)


@settings(max_examples=40, deadline=None)
@given(
    lat_deg=st.floats(-75, 75),
    lon_deg=st.floats(-180, 180),
    course_deg=st.floats(0, 360),
    speed=st.floats(0.5, 15.0),
)
def test_out_and_back_returns_to_the_start(lat_deg, lon_deg, course_deg, speed):
    """A rhumb line retraced on the reciprocal course ends where it began (< 1 mm)."""
    t = np.arange(0.0, 2 * 1800.0 + 1, 10.0)
    c = np.where(t < 1800.0, course_deg * D, course_deg * D + math.pi)
    vn, ve = velocity_ground_ne_mps(speed, c)
    lat, lon = integrate_ne(t, vn, ve, lat_deg * D, lon_deg * D)
    assert distance_m(lat[-1], lon[-1], lat_deg * D, lon_deg * D) < 1e-3


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), tau=st.sampled_from([0.0, 5.0, 60.0, 900.0, math.inf]))
def test_gauss_markov_covariance_is_symmetric_positive_semidefinite(seed, tau):
    rng = np.random.default_rng(seed)
    t = np.cumsum(np.r_[0.0, rng.uniform(0.1, 20.0, 200)])
    g = rng.normal(size=(t.size, 2)) * rng.uniform(0, 5)
    P = gauss_markov_position_covariance_m2(t, g, 0.3, tau)
    w = np.linalg.eigvalsh(P)
    assert np.all(w >= -1e-9 * max(1.0, float(np.abs(w).max())))
    np.testing.assert_array_equal(P[:, 0, 1], P[:, 1, 0])


def test_covariance_on_a_coarser_grid_matches_the_exact_propagation():
    """10 Hz data, correlated processes propagated on a 1 s grid: within 0.5 % of the
    per-sample propagation after the first 10 s (before, within 0.05 m^2: linear
    interpolation of a quadratic start), and exact for a bias at the grid points."""
    t, c, v = _winding_track(10.0, hours=1.0)
    procs = error_processes(DeadReckoningConfig(current_kn=ErrorSource(0.3, 3600.0)))
    exact = honest_covariance_m2(t, v, c, procs)
    coarse = honest_covariance_m2(t, v, c, procs, step_s=1.0)
    tr_exact = np.trace(exact, axis1=1, axis2=2)[1:]
    tr_coarse = np.trace(coarse, axis1=1, axis2=2)[1:]
    np.testing.assert_allclose(tr_coarse[100:], tr_exact[100:], rtol=0.005)
    np.testing.assert_allclose(tr_coarse, tr_exact, rtol=0, atol=0.05)
    bias = [p for p in procs if p.name == "compass_bias_deg"]
    grid = np.arange(0, t.size, 10)
    np.testing.assert_allclose(
        honest_covariance_m2(t, v, c, bias, step_s=1.0)[grid],
        honest_covariance_m2(t, v, c, bias)[grid],
        rtol=1e-9,
    )
