"""The acceleration-aided speed between log readings (B15).

Source: Banachowicz, Banachowicz & Wolski (seeds/000): "In inertial systems acceleration
components are measured, while average speeds are expressed by these formulas"

    Vx = Vx(log) + ax dt,   Vy = Vy(log) + ay dt                              (B15)

with ax, ay the acceleration components along the ship's axes and dt the time since the
log's speed reading.  With ax held constant, Vx(log) + ax dt is the speed at the end of
the interval; its mean over the interval is Vx(log) + ax dt / 2 (the paper calls (B15) the
"average" speed, which is what it becomes when dt is the short step of a fast
accelerometer).  :func:`aided_speed_between_readings_mps` applies (B15) step by step at
the accelerometer's rate (V_j+1 = V_j + a_j dt_j), restarting at each log reading.

(B15) is written in the ship's axes, which turn with the ship: an accelerometer fixed to
the hull measures the acceleration over ground, whose body components differ from the
rate of change of the log's components by the transport term omega x V.  For a turning
ship (yaw rate r, x forward, y starboard, z down):

    dVx/dt = ax + r Vy,   dVy/dt = ay - r Vx

(:func:`log_frame_rate_mps2`); in a steady turn the lateral accelerometer reads the
centripetal V r and the transverse log speed does not change.  (B15) as printed is the
case r = 0.  The accelerations are kinematic, gravity already removed with the attitude
(an accelerometer reads the specific force: a pitch error of 0.1 deg leaves g sin 0.1 deg =
0.017 m/s^2 in ax).

dracc's frames carry no acceleration (docs/dead-reckoning.md, "Acceleration-aided speed"),
so the DR does not call these functions yet; they are the library form of (B15).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from dracc.core.arrays import FloatArray

__all__ = [
    "aided_speed_between_readings_mps",
    "aided_speed_mps",
    "log_frame_rate_mps2",
]


def aided_speed_mps(
    speed_log_mps: ArrayLike, accel_mps2: ArrayLike, dt_s: ArrayLike
) -> FloatArray | float:
    """The aided speed component V = V(log) + a dt  (B15), for either axis.

    ``speed_log_mps``: the log's reading of the component (m/s); ``accel_mps2``: the
    acceleration along the same axis (m/s^2), held over ``dt_s`` (s), the time since the
    reading.  Broadcasts; NaN in, NaN out.
    """
    v = np.asarray(speed_log_mps, float) + np.asarray(accel_mps2, float) * np.asarray(
        dt_s, float
    )  # (B15)
    return v if v.ndim else float(v)


def log_frame_rate_mps2(
    ax_mps2: ArrayLike,
    ay_mps2: ArrayLike,
    vx_mps: ArrayLike,
    vy_mps: ArrayLike,
    rot_radps: ArrayLike,
) -> tuple[FloatArray, FloatArray]:
    """Rates of change of the log's components from the body accelerations of a turning ship.

    dVx/dt = ax + r Vy,  dVy/dt = ay - r Vx  (dV/dt = a - omega x V in the ship's axes,
    x forward, y starboard, r the yaw rate, positive turning to starboard).  These are the
    accelerations (B15) needs when the ship turns; with r = 0 they are ax, ay.  Broadcasts.
    """
    r = np.asarray(rot_radps, float)
    dvx = np.asarray(ax_mps2, float) + r * np.asarray(vy_mps, float)  # transport term +r Vy
    dvy = np.asarray(ay_mps2, float) - r * np.asarray(vx_mps, float)  # transport term -r Vx
    return dvx, dvy


def aided_speed_between_readings_mps(
    time_s: ArrayLike,
    accel_mps2: ArrayLike,
    log_time_s: ArrayLike,
    log_speed_mps: ArrayLike,
    *,
    max_bridge_s: float = np.inf,
) -> FloatArray:
    """One speed component at the accelerometer's times from sparse log readings and (B15).

    time_s (n,) increasing: the accelerometer's sample times; accel_mps2 (n,) the
    acceleration along the log's axis, each sample held until the next (the last over
    nothing).  log_time_s (m,) increasing, log_speed_mps (m,): the log's readings (NaN
    readings are skipped).  At each time t, with t_k the last valid reading at or before t:

        V(t) = V_log(t_k) + sum_j a_j dt_j   over [t_k, t]                     (B15), stepwise

    the sum being the integral of the held acceleration (exact where the acceleration is
    constant between samples; a reading between two accelerometer samples starts with the
    acceleration held from the earlier one).  NaN before the first reading, before the
    first acceleration sample, more than ``max_bridge_s`` after the last reading (an
    integrated accelerometer drifts: its bias b adds b (t - t_k)), and where an
    acceleration in the interval is NaN.  A reading at t gives V_log itself.
    """
    t = np.asarray(time_s, float)
    a = np.asarray(accel_mps2, float)
    tl = np.asarray(log_time_s, float)
    vl = np.asarray(log_speed_mps, float)
    if t.ndim != 1 or a.shape != t.shape or tl.ndim != 1 or vl.shape != tl.shape:
        raise ValueError(
            "time_s and accel_mps2, and log_time_s and log_speed_mps, must be 1-D pairs of "
            "equal length"
        )
    if np.any(np.diff(t) <= 0) or np.any(np.diff(tl) <= 0):
        raise ValueError("time_s and log_time_s must be strictly increasing")
    ok = np.isfinite(vl) & np.isfinite(tl)
    tl, vl = tl[ok], vl[ok]
    out = np.full(t.shape, np.nan)
    if t.size == 0 or tl.size == 0:
        return out
    dt = np.diff(t)
    bad = ~np.isfinite(a)
    step = np.where(bad[:-1], 0.0, a[:-1]) * dt  # a_j dt_j, (B15) per accelerometer step
    cum = np.concatenate([[0.0], np.cumsum(step)])  # integral of a from t_0 to t_i
    n_bad = np.concatenate([[0], np.cumsum(bad[:-1])])  # NaN accelerations before t_i

    k = np.searchsorted(tl, t, side="right") - 1  # last reading at or before t_i
    has = k >= 0
    kk = np.maximum(k, 0)
    tk = tl[kk]
    j = np.searchsorted(t, tk, side="right") - 1  # accelerometer step holding t_k
    jj = np.clip(j, 0, t.size - 1)
    a_j = np.where(bad[jj], 0.0, a[jj])
    cum_at_tk = cum[jj] + a_j * (tk - t[jj])  # integral of a from t_0 to t_k
    nan_inside = (n_bad - n_bad[jj]) > 0  # a NaN acceleration held over [t_k, t_i]
    usable = has & (j >= 0) & ~nan_inside & (t - tk <= max_bridge_s)
    v = vl[kk] + (cum - cum_at_tk)  # (B15), the held acceleration integrated from t_k
    out[usable] = v[usable]
    return out
