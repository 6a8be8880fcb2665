"""Seed 000 (B15): the acceleration-aided speed between log readings, against hand
calculations and a simulated voyage with known truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dracc.core.geodesy import k_lambda, k_phi
from dracc.math.deadreckoning import (
    aided_speed_between_readings_mps,
    aided_speed_mps,
    integrate_ne,
    log_frame_rate_mps2,
)


def test_b15_by_hand():
    # Vx = Vx(log) + ax dt: 5.0 m/s + 0.02 m/s^2 * 10 s = 5.2 m/s (B15)
    assert aided_speed_mps(5.0, 0.02, 10.0) == pytest.approx(5.2, abs=1e-15)
    # both components at once, broadcasting one dt; a decelerating transverse drift
    v = aided_speed_mps([5.0, 0.3], [0.02, -0.01], 2.5)
    np.testing.assert_allclose(v, [5.05, 0.275], atol=1e-15)
    assert math.isnan(aided_speed_mps(5.0, math.nan, 1.0))


def test_between_readings_by_hand():
    t = np.arange(6.0)
    a = np.array([0.1, 0.2, np.nan, 0.3, 0.3, 0.0])
    log_t, log_v = np.array([0.5, 3.5]), np.array([4.0, 6.0])
    v = aided_speed_between_readings_mps(t, a, log_t, log_v)
    # t=0: before the first reading; t=1: 4 + 0.1*0.5; t=2: + 0.2*1; t=3: the NaN of
    # [2, 3] is held over the interval; t=4: 6 + 0.3*0.5; t=5: + 0.3*1
    expected = [np.nan, 4.05, 4.25, np.nan, 6.15, 6.45]
    np.testing.assert_allclose(v, expected, atol=1e-12, equal_nan=True)
    bridged = aided_speed_between_readings_mps(t, a, log_t, log_v, max_bridge_s=1.0)
    np.testing.assert_allclose(
        bridged, [np.nan, 4.05, np.nan, np.nan, 6.15, np.nan], atol=1e-12, equal_nan=True
    )
    # a reading on a sample is the log's own speed; a NaN reading is skipped
    v2 = aided_speed_between_readings_mps(t, a, [4.0, 4.5], [7.0, np.nan])
    np.testing.assert_allclose(v2, [np.nan] * 4 + [7.0, 7.3], atol=1e-12, equal_nan=True)
    with pytest.raises(ValueError, match="strictly increasing"):
        aided_speed_between_readings_mps(t, a, [2.0, 1.0], [1.0, 1.0])


def test_transport_term_of_a_turning_ship():
    # constant velocity over ground (no acceleration, accelerometers read 0) seen from a
    # hull turning at r: the log's components change as dVx/dt = r Vy, dVy/dt = -r Vx
    r, vn, ve = 0.02, 4.0, 1.5
    t = np.linspace(0.0, 30.0, 3001)
    psi = 0.3 + r * t
    vx = vn * np.cos(psi) + ve * np.sin(psi)  # forward
    vy = -vn * np.sin(psi) + ve * np.cos(psi)  # starboard
    dvx, dvy = log_frame_rate_mps2(0.0, 0.0, vx, vy, r)
    np.testing.assert_allclose(dvx[1:-1], np.gradient(vx, t)[1:-1], atol=1e-6)
    np.testing.assert_allclose(dvy[1:-1], np.gradient(vy, t)[1:-1], atol=1e-6)
    # a steady turn ahead at 6 m/s: the lateral accelerometer reads the centripetal V r,
    # and the transverse log speed does not change
    dvx, dvy = log_frame_rate_mps2(0.0, 6.0 * r, 6.0, 0.0, r)
    assert (float(dvx), float(dvy)) == pytest.approx((0.0, 0.0), abs=1e-15)


PERIOD_S, V0, DV = 600.0, 6.0, 2.0  # speed 6 +- 2 m/s over 10 minutes
OMEGA = 2.0 * math.pi / PERIOD_S


def _speed(t):
    return V0 + DV * np.sin(OMEGA * t)


def _distance(t):  # integral of _speed from 0
    return V0 * t + DV / OMEGA * (1.0 - np.cos(OMEGA * t))


def _along_track_error_m(lat, lon, lat_true, lon_true, course):
    north = (lat - lat_true) / k_phi(lat_true)
    east = (lon - lon_true) / k_lambda(lat_true)
    return north * math.cos(course) + east * math.sin(course)


@pytest.mark.parametrize("bias_mps2", [0.0, 0.005])
def test_simulated_voyage_with_known_truth(bias_mps2):
    # one hour on 040 deg at 54 N, accelerometer at 10 Hz, log reading every 10 s
    dt, log_dt, course = 0.1, 10.0, math.radians(40.0)
    t = np.arange(0.0, 3600.0 + dt / 2, dt)
    lat0, lon0 = math.radians(54.0), math.radians(10.0)
    step = np.diff(_distance(t)) / dt  # the exact mean speed over each step: the truth
    v_true = np.append(step, step[-1])
    lat_t, lon_t = integrate_ne(t, v_true * math.cos(course), v_true * math.sin(course), lat0, lon0)
    accel = DV * OMEGA * np.cos(OMEGA * t) + bias_mps2
    log_t = np.arange(0.0, 3600.0 + 1e-9, log_dt)
    log_v = _speed(log_t)

    held = log_v[np.searchsorted(log_t, t, side="right") - 1]  # the DR today: held reading
    aided = aided_speed_between_readings_mps(t, accel, log_t, log_v)  # (B15)
    assert np.all(np.isfinite(aided))
    errs = {}
    for name, v in (("held", held), ("aided", aided)):
        lat, lon = integrate_ne(t, v * math.cos(course), v * math.sin(course), lat0, lon0)
        errs[name] = _along_track_error_m(lat, lon, lat_t, lon_t, course)

    # holding a reading for log_dt lags by (1/2) a log_dt^2 per interval: at the readings
    # the error is -(1/2) log_dt (V(t) - V(0)), within the curvature term
    # (1/6) log_dt^2 |a(t) - a(0)| <= 0.7 m; largest (1/2) 10 s * 2 m/s = 10 m
    at = np.searchsorted(t, log_t[1:] - 1e-9)
    hand = -0.5 * log_dt * (_speed(t[at]) - V0)
    np.testing.assert_allclose(errs["held"][at], hand, atol=0.75)
    assert np.max(np.abs(errs["held"])) == pytest.approx(10.0, abs=0.75)
    if bias_mps2 == 0.0:
        # aided: only the 10 Hz hold remains, (1/2) dt DV = 0.1 m at most
        assert np.max(np.abs(errs["aided"])) < 0.15
    else:
        # an accelerometer bias b gains (1/2) b log_dt^2 every interval, (1/2) b log_dt T
        # over T (the 10 Hz hold takes dt off: (1/2) b (log_dt - dt) T exactly), 89.1 m
        # after the hour, against the held DR's bounded 10 m
        drift = 0.5 * bias_mps2 * (log_dt - dt) * t[at]
        np.testing.assert_allclose(errs["aided"][at], drift, atol=0.15)
        assert errs["aided"][-1] == pytest.approx(89.1, abs=0.15)
