"""Sensor calibration from a reference: simulated voyages with known errors.

The simulator here is independent of dracc's estimators: true water track, a current
(constant plus a slow Gauss-Markov wander), sensor errors as Gauss-Markov sequences,
GNSS positions with white noise.  Positions are integrated with dracc.integrate_ne
(tested against GeographicLib in test_deadreckoning).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import lfilter

from dracc.core.errors import InsufficientDataError
from dracc.core.geodesy import add_offset_ne, angdiff
from dracc.core.units import DEG_RAD as D
from dracc.core.units import KN_MPS as KN
from dracc.math.calibration import (
    block_means,
    calibrate_from_track,
    compass_error_from_heading,
    deviation_from_heading,
)
from dracc.math.deadreckoning import deviation_curve_rad, integrate_ne


def _gm(rng, n, sigma, tau_s, dt_s=1.0):
    a = math.exp(-dt_s / tau_s)
    x = rng.normal(0.0, sigma * math.sqrt(1 - a * a), n)
    x[0] = rng.normal(0.0, sigma)
    return lfilter([1.0], [1.0, -a], x)


def _voyage(
    seed,
    *,
    hours=24.0,
    speed_range=(4.0, 7.0),
    wander_kn=0.1,
    single_course=None,
    constant_speed=None,
):
    """True water course/speed at 1 Hz (20-40 min legs, 2 min turns), current and GNSS."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, hours * 3600, 1.0)
    n = t.size
    edges = np.cumsum(rng.uniform(1200, 2400, int(hours * 4)))
    legs = np.searchsorted(edges, t)
    course = np.unwrap(rng.uniform(0, 2 * math.pi, edges.size + 1))[legs]
    course = np.convolve(np.pad(course, 60, mode="edge"), np.ones(121) / 121, "valid")
    if single_course is not None:
        course = np.full(n, single_course)
    speed = rng.uniform(*speed_range, edges.size + 1)[legs]
    if constant_speed is not None:
        speed = np.full(n, constant_speed)
    cur_n = 0.5 * KN * math.cos(60 * D) + _gm(rng, n, wander_kn * KN, 6 * 3600)
    cur_e = 0.5 * KN * math.sin(60 * D) + _gm(rng, n, wander_kn * KN, 6 * 3600)
    lat, lon = integrate_ne(
        t, speed * np.cos(course) + cur_n, speed * np.sin(course) + cur_e, 57.0 * D, 11.0 * D
    )
    glat, glon = add_offset_ne(lat, lon, rng.normal(0, 5.0, n), rng.normal(0, 5.0, n))
    return rng, t, course % (2 * math.pi), speed, glat, glon


def test_block_means_hand_values():
    t = np.array([0.0, 1.0, 2.0, 10.0, 11.0, 25.0])
    bt, m, c = block_means(t, np.array([1.0, 2.0, 3.0, 10.0, 20.0, 99.0]), 10.0)
    np.testing.assert_allclose(bt, [1.0, 10.5])
    np.testing.assert_allclose(m, [2.0, 15.0])  # the lone sample at 25 s is not a block
    np.testing.assert_array_equal(c, [3, 2])


def test_gyro_error_against_reference_heading_constant_across_north():
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 6 * 3600, 1.0)
    ref = np.mod(359.9 * D + 0.3 * D * np.sin(t / 500), 2 * math.pi)  # around north
    compass = np.mod(ref + 0.3 * D + _gm(rng, t.size, 0.2 * D, 120.0), 2 * math.pi)
    est = compass_error_from_heading(t, compass, ref)
    assert est.error_rad == pytest.approx(0.3 * D, abs=max(3 * est.sigma_rad, 1e-9))
    assert abs(est.error_rad - 0.3 * D) < 0.05 * D
    assert 0.005 * D < est.sigma_rad < 0.05 * D
    assert not est.varying and est.window_error_rad.size == 6


def test_gyro_error_slowly_varying_is_detected_and_followed():
    rng = np.random.default_rng(6)
    t = np.arange(0.0, 24 * 3600, 1.0)
    drift = (0.1 + 0.6 * t / t[-1]) * D  # 0.1 deg -> 0.7 deg over the day
    ref = np.mod(t * 1e-3, 2 * math.pi)
    compass = ref + drift + _gm(rng, t.size, 0.2 * D, 120.0)
    est = compass_error_from_heading(t, compass, ref, window_s=3 * 3600)
    assert est.varying and est.p_constant < 1e-6
    mid = est.window_start_s + 1.5 * 3600
    truth = (0.1 + 0.6 * mid / t[-1]) * D
    assert np.all(np.abs(est.window_error_rad - truth) < 4 * est.window_sigma_rad + 0.01 * D)


def test_compass_calibration_without_overlap_raises():
    with pytest.raises(InsufficientDataError, match="usable pairs"):
        compass_error_from_heading([0.0, 1.0], [0.1, np.nan], [np.nan, 0.2])


def test_deviation_coefficients_recovered_from_a_swing():
    rng = np.random.default_rng(8)
    coef = np.array([0.5, 3.0, -2.0, 0.8, -0.4]) * D
    t = np.arange(0.0, 4 * 3600, 1.0)
    compass = np.mod(t * 2 * math.pi / 1800.0, 2 * math.pi)  # a full circle every 30 min
    variation = 3.0 * D
    true_hdg = compass + variation + deviation_curve_rad(compass, coef)
    ref = true_hdg + _gm(rng, t.size, 0.1 * D, 30.0)
    est = deviation_from_heading(t, compass, ref, variation)
    z = (est.coefficients_rad - coef) / est.sigma_rad
    assert np.all(np.abs(z) < 4), z
    assert np.all(np.abs(est.coefficients_rad - coef) < 0.05 * D)
    assert est.heading_coverage_rad < 1 * D


def test_deviation_fit_refuses_a_single_heading():
    t = np.arange(0.0, 3600.0)
    compass = np.full(t.size, 1.0) + 1e-4 * np.sin(t)
    with pytest.raises(InsufficientDataError, match="swing"):
        deviation_from_heading(t, compass, compass + 0.01, 0.0)


def test_target_24h_gyro_error_and_log_scale_recovered():
    """Issue 3's target: 0.3 deg gyro error, 3 % log scale, 24 h: within 0.1 deg and 0.5 %.

    Current 0.5 kn setting 060 plus a 0.1 kn-per-axis wander (tau 6 h); compass noise
    0.2 deg (tau 120 s), log noise 0.1 kn (tau 300 s), GNSS 5 m white; the log model
    without offset (the simulated log has none).
    """
    for seed in (1, 2):
        rng, t, course, speed, glat, glon = _voyage(seed)
        hdg = course + 0.3 * D + _gm(rng, t.size, 0.2 * D, 120.0)
        spd = 1.03 * speed + _gm(rng, t.size, 0.1 * KN, 300.0)
        cal = calibrate_from_track(t, hdg, spd, t, glat, glon, fit_log_offset=False)
        assert abs(cal.heading_error_rad[0] - 0.3 * D) < 0.1 * D
        assert abs(cal.log_scale - 0.03) < 0.005
        assert abs(cal.heading_error_rad[0] - 0.3 * D) < 4 * cal.heading_error_sigma_rad[0]
        assert abs(cal.log_scale - 0.03) < 4 * cal.log_scale_sigma
        # the current at the knots, within its uncertainty plus the wander
        assert np.all(
            np.abs(cal.current_ne_mps[:, 0] - 0.5 * KN * math.cos(60 * D))
            < 4 * cal.current_sigma_ne_mps[:, 0] + 0.3 * KN
        )


def test_log_scale_and_offset_separated_with_a_wide_speed_range():
    rng, t, course, speed, glat, glon = _voyage(3, speed_range=(1.5, 8.0))
    hdg = course - 0.5 * D + _gm(rng, t.size, 0.2 * D, 120.0)
    spd = 0.97 * speed + 0.15 + _gm(rng, t.size, 0.1 * KN, 300.0)
    cal = calibrate_from_track(t, hdg, spd, t, glat, glon)
    assert abs(cal.log_scale + 0.03) < 4 * cal.log_scale_sigma
    assert abs(cal.log_offset_mps - 0.15) < 4 * cal.log_offset_sigma_mps
    assert cal.log_offset_sigma_mps < 0.05
    assert abs(cal.heading_error_rad[0] + 0.5 * D) < 0.1 * D


def test_magnetic_deviation_curve_from_gnss_track():
    rng, t, course, speed, glat, glon = _voyage(4, hours=24.0)
    coef = np.array([0.4, 2.0, -1.5, 0.6, 0.3]) * D
    variation = 2.5 * D
    # compass heading K such that K + d + delta(K) = course (solve by fixed point)
    k = course - variation
    for _ in range(6):
        k = course - variation - deviation_curve_rad(k, coef)
    compass = k + _gm(rng, t.size, 0.3 * D, 120.0)
    spd = 1.02 * speed + _gm(rng, t.size, 0.1 * KN, 300.0)
    cal = calibrate_from_track(
        t,
        compass + variation,
        spd,
        t,
        glat,
        glon,
        heading_model="deviation",
        fit_log_offset=False,
        variation_rad=variation,
    )
    err = cal.heading_error_rad - coef
    assert np.all(np.abs(err) < 4 * cal.heading_error_sigma_rad + 0.02 * D), err / D
    assert np.all(np.abs(err) < 0.3 * D)
    assert abs(cal.log_scale - 0.02) < 0.005


def test_one_course_cannot_separate_current_from_log_scale():
    """One course at one speed: a 3 % scale error is a 0.3 kn current along the track."""
    _rng, t, course, speed, glat, glon = _voyage(
        5, hours=6.0, single_course=0.7, constant_speed=5.0
    )
    cal = calibrate_from_track(t, course, speed * 1.03, t, glat, glon, fit_log_offset=False)
    nd = cal.not_determinable  # issue 29: named with why, not raised
    assert "log scale and current cannot be separated" in nd["log_scale"]
    assert "compass error and current cannot be separated" in nd["compass_error"]


def test_constant_speed_cannot_separate_log_offset_from_scale():
    _rng, t, course, speed, glat, glon = _voyage(6, hours=6.0, constant_speed=5.0)
    cal = calibrate_from_track(t, course, speed * 1.03, t, glat, glon)
    # the offset is dropped with why; the scale (absorbing it) is the 3 % of the log
    assert (
        "offset cannot be separated: speed through the water spans 0.0 kn"
        in (cal.not_determinable["log_offset"])
    )
    assert set(cal.not_determinable) == {"log_offset"}
    assert abs(cal.log_scale - 0.03) < 4 * cal.log_scale_sigma


def test_heading_errors_are_differences_on_the_circle():
    assert angdiff(0.1 * D, 359.9 * D) == pytest.approx(0.2 * D)


def test_slowly_varying_gyro_error_from_gnss_track():
    """Gyro error drifting 0.1 -> 0.7 deg over 24 h, GNSS positions only: the 'varying'
    model (knots every 6 h) follows it and rejects constancy; a constant 0.3 deg is not
    called varying."""
    rng, t, course, speed, glat, glon = _voyage(2)
    spd = 1.03 * speed + _gm(rng, t.size, 0.1 * KN, 300.0)
    drift = (0.1 + 0.6 * t / t[-1]) * D
    hdg = course + drift + _gm(rng, t.size, 0.2 * D, 120.0)
    cal = calibrate_from_track(
        t, hdg, spd, t, glat, glon, heading_model="varying", fit_log_offset=False
    )
    truth = (0.1 + 0.6 * cal.heading_knot_s / t[-1]) * D
    np.testing.assert_allclose(cal.heading_knot_s, np.arange(0, 25, 6) * 3600.0)
    assert np.all(np.abs(cal.heading_error_rad - truth) < 4 * cal.heading_error_sigma_rad)
    assert cal.heading_constant_p < 0.01
    steady = course + 0.3 * D + _gm(rng, t.size, 0.2 * D, 120.0)
    cal2 = calibrate_from_track(
        t, steady, spd, t, glat, glon, heading_model="varying", fit_log_offset=False
    )
    assert cal2.heading_constant_p > 0.01


def test_too_short_a_log_for_the_track_calibration_says_so():
    _rng, t, course, speed, glat, glon = _voyage(7, hours=0.5)
    with pytest.raises(InsufficientDataError, match="need at least 4"):
        calibrate_from_track(t, course, speed, t, glat, glon)


def test_regression_single_straight_leg_with_yaw_is_not_separable(tmp_path):
    """A simulated 3 h voyage on one course (yaw noise only) fitted a compass error of
    -0.3 +- 31 deg and a log scale of 175 +- 151 %: nearly singular, now reported as such."""
    from dracc.cli.main import main
    from dracc.core.config import Config
    from dracc.pipeline.analysis import analyse

    assert (
        main(
            [
                "simulate",
                "--out",
                str(tmp_path),
                "--hours",
                "3",
                "--seed",
                "105",
                "--name",
                "v",
                "--compass-hz",
                "1",
                "--truth-hz",
                "0.01",
                "--legs",
                "0:60",
            ]
        )
        == 0
    )
    a = analyse([tmp_path / "v.nmea"], Config())
    cal = a.calibration  # issue 29: each quantity NOT DETERMINABLE, with why
    assert cal is not None and cal.compass_error_deg is None and cal.log_scale is None
    assert "cannot be separated" in cal.not_determinable["compass_error_deg"]
    assert "cannot be separated" in cal.not_determinable["log_scale"]
