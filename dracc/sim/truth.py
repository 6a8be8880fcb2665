"""The true voyage of the simulator: start time, legs steered, heading with yaw, leeway,
current, the track over the WGS-84 ellipsoid and the magnetic compass course
(:func:`true_track`).

Symbols of the dead-reckoning paper (METHODS.md §2): ``psi`` true heading, ``alpha``
leeway (starboard +), ``KK`` magnetic compass course with ``psi = KK + delta(KK) + d``
(B2), ``V`` speed through the water (``Vx = V cos alpha``, ``Vy = V sin alpha``, B1, B5),
``Vp, Kp`` current drift and set (B7-B12, B10 corrected).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from datetime import datetime, timezone
from typing import Any

import numpy as np
import pandas as pd

from dracc.core.errors import ConfigError
from dracc.core.geodesy import angdiff, k_lambda, k_phi, wrap_2pi, wrap_pi
from dracc.core.units import DEG_RAD, KN_MPS
from dracc.sim.params import SimParams
from dracc.sim.processes import GmDraw, component_rng


def start_ns(start_utc: str | datetime) -> int:
    """Start time as int64 UTC ns; naive datetimes and ISO strings without zone are UTC."""
    try:
        ts = pd.Timestamp(start_utc)
    except (ValueError, TypeError) as e:
        raise ConfigError(f"start time {start_utc!r} is not an ISO 8601 time") from e
    if ts.tzinfo is None:
        ts = ts.tz_localize(timezone.utc)
    return int(ts.tz_convert(timezone.utc).value)


def _generated_legs(p: SimParams) -> tuple[tuple[float, float], ...]:
    rng = component_rng(p.seed, 1)
    legs = [(0.0, p.initial_heading_deg)]
    t, h = 0.0, p.initial_heading_deg
    while True:
        t += rng.uniform(2 * 3600.0, 4 * 3600.0)
        if t >= p.duration_s:
            break
        h = (h + rng.choice([-1, 1]) * rng.uniform(30.0, 120.0)) % 360.0
        legs.append((t, h))
    return tuple(legs)


def generated_legs(params: SimParams) -> tuple[tuple[float, float], ...]:
    """The legs :func:`simulate` steers when ``params.legs`` is None (drawn from the seed)."""
    return params.legs if params.legs is not None else _generated_legs(params)


def _heading_profile(
    t_s: np.ndarray, legs: Iterable[tuple[float, float]], initial_deg: float, rate_rad_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Steered heading (rad) and its rate: each leg turns the shorter way at ``rate``."""
    psi = np.empty_like(t_s)
    rot = np.zeros_like(t_s)
    legs = sorted((float(a), float(b)) for a, b in legs)
    if not legs or legs[0][0] > t_s[0]:
        legs = [(float(t_s[0]), initial_deg)] + legs
    h_start = legs[0][1] * DEG_RAD
    for i, (t0, c_deg) in enumerate(legs):
        t1 = legs[i + 1][0] if i + 1 < len(legs) else np.inf
        sel = (t_s >= t0) & (t_s < t1)
        if i == 0:
            sel |= t_s < t0
            h_start = c_deg * DEG_RAD
        delta = float(angdiff(c_deg * DEG_RAD, h_start))
        turn_s = abs(delta) / rate_rad_s if rate_rad_s > 0 else 0.0
        el = np.clip(t_s[sel] - t0, 0.0, None)
        psi[sel] = h_start + np.sign(delta) * rate_rad_s * np.minimum(el, turn_s)
        rot[sel] = np.where(el < turn_s, np.sign(delta) * rate_rad_s, 0.0)
        if np.isfinite(t1):
            el1 = t1 - t0
            h_start = h_start + np.sign(delta) * rate_rad_s * min(el1, turn_s)
    return psi, rot


def deviation_curve_rad(kk_rad: Any, coeffs_rad: tuple[float, ...]) -> np.ndarray:
    """Deviation ``delta = A + B sin KK + C cos KK + D sin 2KK + E cos 2KK`` (east +)."""
    a, b, c, d, e = coeffs_rad
    kk = np.asarray(kk_rad, float)
    return a + b * np.sin(kk) + c * np.cos(kk) + d * np.sin(2 * kk) + e * np.cos(2 * kk)


def compass_course_rad(
    heading_rad: Any, coeffs_rad: tuple[float, ...], variation_rad: float
) -> np.ndarray:
    """The magnetic compass course KK with ``heading = KK + delta(KK) + d`` (B2), by Newton's
    method on ``f(KK) = KK + delta(KK) + d - heading`` (``f' = 1 + delta'``, > 0 for any real
    compass, whose deviation changes by far less than a degree per degree of heading)."""
    _a, b, c, d, e = coeffs_rad
    target = np.asarray(heading_rad, float) - variation_rad
    kk = target - deviation_curve_rad(target, coeffs_rad)
    for _ in range(20):
        f = angdiff(kk + deviation_curve_rad(kk, coeffs_rad), target)
        fp = 1.0 + b * np.cos(kk) - c * np.sin(kk) + 2 * d * np.cos(2 * kk) - 2 * e * np.sin(2 * kk)
        kk = kk - f / fp
        if np.max(np.abs(f), initial=0.0) < 1e-14:
            break
    return wrap_2pi(kk)


def integrate_track(
    lat0_rad: float, lon0_rad: float, vn_mps: np.ndarray, ve_mps: np.ndarray, dt_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Position on the WGS-84 ellipsoid from north/east ground velocity (B16-B22).

    ``phi[k+1] = phi[k] + k_phi(phi_mid) VN_mid dt`` and ``lambda[k+1] = lambda[k] +
    k_lambda(phi_mid) VE_mid dt`` with trapezoidal velocities and the mid-step latitude,
    solved for all steps at once by fixed-point iteration on the latitude profile.
    """
    dn = 0.5 * (vn_mps[1:] + vn_mps[:-1]) * dt_s
    de = 0.5 * (ve_mps[1:] + ve_mps[:-1]) * dt_s
    lat = np.full(len(vn_mps), lat0_rad)
    for _ in range(4):
        mid = 0.5 * (lat[1:] + lat[:-1])
        lat = lat0_rad + np.concatenate(([0.0], np.cumsum(k_phi(mid) * dn)))  # (B16, B20)
    mid = 0.5 * (lat[1:] + lat[:-1])
    lon = lon0_rad + np.concatenate(([0.0], np.cumsum(k_lambda(mid) * de)))  # (B17, B21)
    return lat, wrap_pi(lon)


def speed_profile_mps(
    t_s: np.ndarray,
    v0_mps: float,
    changes: Iterable[tuple[float, float]],
    accel_mps2: float,
) -> np.ndarray:
    """The speed through the water at voyage times ``t_s``: ``v0_mps``, then each change
    ``(time_s, speed_kn)`` approached from the speed of that moment at ``accel_mps2`` (an
    engine order: the speed ramps, it does not jump).  Absolute times: a segment of a
    long voyage gets the same speeds as the whole."""
    v = np.full(len(t_s), v0_mps, dtype=float)
    start = v0_mps
    prev: tuple[float, float, float] | None = None  # (time, start speed, target)
    for t0, speed_kn in sorted(changes):
        if prev is not None:  # the speed at this change: the previous ramp at t0
            start = _ramp(np.array([t0]), *prev, accel_mps2)[0]
        prev = (t0, start, speed_kn * KN_MPS)
        v = np.where(t_s >= t0, _ramp(t_s, *prev, accel_mps2), v)
    return v


def _ramp(t_s: np.ndarray, t0: float, start: float, target: float, accel: float) -> np.ndarray:
    step = accel * np.maximum(t_s - t0, 0.0)
    out: np.ndarray = (
        np.minimum(start + step, target) if target >= start else np.maximum(start - step, target)
    )
    return out


def true_track(
    p: SimParams,
    legs: Iterable[tuple[float, float]],
    t_s: np.ndarray,
    time_ns: np.ndarray,
    dt: float,
    gm: GmDraw,
    segment: int,
    water_distance0_m: float = 0.0,
) -> dict[str, np.ndarray]:
    """The truth's columns at times ``t_s`` (see :func:`dracc.sim.model.simulate`); the
    water distance continues from ``water_distance0_m``."""
    n = len(t_s)
    psi_steer, rot_steer = _heading_profile(
        t_s, legs, p.initial_heading_deg, p.turn_rate_deg_s * DEG_RAD
    )
    wy = 2 * np.pi / p.yaw_period_s if p.yaw_period_s > 0 else 0.0
    yaw_amp = p.yaw_amp_deg * DEG_RAD
    psi = wrap_2pi(psi_steer + yaw_amp * np.sin(wy * t_s))
    rot = rot_steer + yaw_amp * wy * np.cos(wy * t_s)
    rng_env = component_rng(p.seed, 2, segment)
    alpha = p.leeway_deg * DEG_RAD + DEG_RAD * gm(
        "leeway", p.leeway_noise_deg.sigma, p.leeway_noise_deg.tau_s, rng_env
    )
    v_mps = speed_profile_mps(t_s, p.speed_kn * KN_MPS, p.speed_changes, p.accel_mps2)
    vx = v_mps * np.cos(alpha)  # (B5): alpha = atan(Vy/Vx)
    vy = v_mps * np.sin(alpha)
    kdw = psi + alpha  # course through the water (B3, B4 with beta = 0 here)
    set_rad = p.current_set_deg * DEG_RAD
    cn = p.current_drift_kn * KN_MPS * math.cos(set_rad) + KN_MPS * gm(
        "current_n", p.current_noise_kn.sigma, p.current_noise_kn.tau_s, rng_env
    )
    ce = p.current_drift_kn * KN_MPS * math.sin(set_rad) + KN_MPS * gm(
        "current_e", p.current_noise_kn.sigma, p.current_noise_kn.tau_s, rng_env
    )
    vn = v_mps * np.cos(kdw) + cn  # (B7-B9)
    ve = v_mps * np.sin(kdw) + ce  # (B10-B12), corrected: sin Kp
    lat, lon = integrate_track(p.start_lat_deg * DEG_RAD, p.start_lon_deg * DEG_RAD, vn, ve, dt)
    cog = wrap_2pi(np.arctan2(ve, vn))
    sog = np.hypot(vn, ve)
    g_long = vn * np.cos(psi) + ve * np.sin(psi)
    g_trans = -vn * np.sin(psi) + ve * np.cos(psi)
    coeffs = tuple(c * DEG_RAD for c in p.deviation_deg)
    var_rad = p.variation_deg * DEG_RAD
    kk = compass_course_rad(psi, coeffs, var_rad)
    dev_true = deviation_curve_rad(kk, coeffs)
    water_dist = water_distance0_m + np.concatenate(
        ([0.0], np.cumsum(0.5 * (vx[1:] + vx[:-1]) * dt))
    )
    return {
        "time_ns": time_ns,
        "t_s": t_s,
        "lat_rad": lat,
        "lon_rad": lon,
        "heading_rad": psi,
        "rot_radps": rot,
        "leeway_rad": alpha,
        "course_water_rad": wrap_2pi(kdw),
        "stw_mps": v_mps,
        "stw_long_mps": vx,
        "stw_transverse_mps": vy,
        "vn_mps": vn,
        "ve_mps": ve,
        "cog_rad": cog,
        "sog_mps": sog,
        "sog_long_mps": g_long,
        "sog_transverse_mps": g_trans,
        "current_n_mps": cn,
        "current_e_mps": ce,
        "current_set_rad": wrap_2pi(np.arctan2(ce, cn)),
        "current_drift_mps": np.hypot(cn, ce),
        "compass_course_rad": kk,
        "deviation_rad": dev_true,
        "variation_rad": np.full(n, var_rad),
        "water_distance_m": water_dist,
    }
