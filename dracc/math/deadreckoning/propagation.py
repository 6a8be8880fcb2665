"""Velocity over ground (B7-B14) and its integration on the WGS-84 ellipsoid (B16-B22)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from dracc.core.arrays import FloatArray
from dracc.core.geodesy import k_lambda, k_phi, wrap_pi

__all__ = ["integrate_ne", "velocity_ground_ne_mps", "velocity_water_ne_mps"]


def velocity_water_ne_mps(
    speed_water_mps: FloatArray | float,
    course_water_rad: FloatArray | float,
    current_mps: FloatArray | float = 0.0,
    current_set_rad: FloatArray | float = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """Velocity over ground (north, east) from a relative (water) log plus the current.

    VN = Vw cos KDw + Vp cos Kp   (B7, B9, B11)
    VE = Vw sin KDw + Vp sin Kp   (B8, B10 corrected: the paper prints Vp cos Kp, B12)
    ``current_set_rad`` is the direction the current sets towards.
    """
    vn = speed_water_mps * np.cos(course_water_rad) + current_mps * np.cos(current_set_rad)  # (B11)
    # (B10) corrected: the east component of the current is Vp sin Kp, not Vp cos Kp
    ve = speed_water_mps * np.sin(course_water_rad) + current_mps * np.sin(current_set_rad)  # (B12)
    return vn, ve


def velocity_ground_ne_mps(
    speed_ground_mps: FloatArray | float, course_ground_rad: FloatArray | float
) -> tuple[FloatArray, FloatArray]:
    """Velocity over ground from an absolute (ground) log: VN = Vd cos KDd (B13), VE = Vd sin KDd (B14)."""
    return (
        speed_ground_mps * np.cos(course_ground_rad),  # (B13)
        speed_ground_mps * np.sin(course_ground_rad),  # (B14)
    )


def integrate_ne(
    time_s: ArrayLike,
    vn_mps: ArrayLike,
    ve_mps: ArrayLike,
    lat0_rad: ArrayLike,
    lon0_rad: ArrayLike,
    *,
    iterations: int = 2,
) -> tuple[FloatArray, FloatArray]:
    """Dead-reckoned positions from velocities over ground, on the WGS-84 ellipsoid.

    phi_i+1 = phi_i + k_phi V_N dt, lambda_i+1 = lambda_i + k_lambda V_E dt (B16-B22),
    the velocity of sample i held over [t_i, t_i+1] as in (B20, B21).  k_phi and
    k_lambda (B18, B19) are taken at each step's mid-latitude (the second-order form of
    (B20)), found by a fixed-point iteration over the whole track (the cumulative sums
    make it vectorised; after two midpoint passes the latitude error is ~1e-6 m per 500 km).

    time_s: (n,); vn_mps, ve_mps: (..., n) broadcasting over leading axes (e.g. runs);
    lat0_rad, lon0_rad: scalars or (...,).  Returns (lat_rad, lon_rad), shape (..., n),
    longitudes wrapped into (-pi, pi].
    """
    t = np.asarray(time_s, float)
    dt = np.diff(t)
    vn = np.asarray(vn_mps, float)
    ve = np.asarray(ve_mps, float)
    lat0 = np.asarray(lat0_rad, float)[..., None]
    lon0 = np.asarray(lon0_rad, float)[..., None]
    d_north_m = vn[..., :-1] * dt  # V_N dt
    d_east_m = ve[..., :-1] * dt
    zero = np.zeros(np.broadcast_shapes(d_north_m.shape[:-1], lat0.shape[:-1]) + (1,))
    lat = lat0 + np.concatenate([zero, np.cumsum(k_phi(lat0) * d_north_m, axis=-1)], axis=-1)
    for _ in range(iterations):
        lat_mid = 0.5 * (lat[..., :-1] + lat[..., 1:])
        lat = lat0 + np.concatenate(
            [zero, np.cumsum(k_phi(lat_mid) * d_north_m, axis=-1)],
            axis=-1,  # (B16), (B20)
        )
    lat_mid = 0.5 * (lat[..., :-1] + lat[..., 1:])
    lon = lon0 + np.concatenate(
        [zero, np.cumsum(k_lambda(lat_mid) * d_east_m, axis=-1)],
        axis=-1,  # (B17), (B21)
    )
    lon_wrapped: FloatArray = wrap_pi(lon)
    return lat, lon_wrapped
