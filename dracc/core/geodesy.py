"""WGS-84 ellipsoid, radii of curvature (B18, B19) and the one home for angle wrapping.

All functions are pure, take and return numpy arrays (or scalars) and broadcast.
Glossary: ``phi`` latitude, ``lam`` longitude (radians); ``R_M`` meridional radius
of curvature, ``R_N`` prime-vertical radius of curvature (metres).
"""

from __future__ import annotations

from typing import Any, overload

import numpy as np
from numpy.typing import NDArray

from dracc.core.arrays import ArrayLike, FloatArray

A_M = 6378137.0  #: WGS-84 semi-major axis a
F = 1.0 / 298.257223563  #: WGS-84 flattening f
E2 = F * (2.0 - F)  #: first eccentricity squared e^2 = f(2 - f)

TWO_PI = 2.0 * np.pi


@overload
def radius_meridian_m(lat_rad: float) -> float: ...
@overload
def radius_meridian_m(lat_rad: ArrayLike) -> FloatArray: ...
def radius_meridian_m(lat_rad: ArrayLike) -> Any:
    """Meridional radius of curvature R_M = a(1 - e^2) / (1 - e^2 sin^2 phi)^(3/2)."""
    s2 = np.sin(lat_rad) ** 2
    return A_M * (1.0 - E2) / (1.0 - E2 * s2) ** 1.5


@overload
def radius_prime_vertical_m(lat_rad: float) -> float: ...
@overload
def radius_prime_vertical_m(lat_rad: ArrayLike) -> FloatArray: ...
def radius_prime_vertical_m(lat_rad: ArrayLike) -> Any:
    """Prime-vertical radius of curvature R_N = a / (1 - e^2 sin^2 phi)^(1/2)."""
    s2 = np.sin(lat_rad) ** 2
    return A_M / np.sqrt(1.0 - E2 * s2)


@overload
def k_phi(lat_rad: float) -> float: ...
@overload
def k_phi(lat_rad: ArrayLike) -> FloatArray: ...
def k_phi(lat_rad: ArrayLike) -> Any:
    """k_phi = 1/R_M, radians of latitude per metre north (B18)."""
    return 1.0 / radius_meridian_m(lat_rad)


@overload
def k_lambda(lat_rad: float) -> float: ...
@overload
def k_lambda(lat_rad: ArrayLike) -> FloatArray: ...
def k_lambda(lat_rad: ArrayLike) -> Any:
    """k_lambda = 1/(R_N cos phi), radians of longitude per metre east (B19)."""
    return 1.0 / (radius_prime_vertical_m(lat_rad) * np.cos(lat_rad))


@overload
def wrap_pi(angle_rad: float) -> float: ...
@overload
def wrap_pi(angle_rad: ArrayLike) -> FloatArray: ...
def wrap_pi(angle_rad: ArrayLike) -> Any:
    """Wrap an angle into (-pi, pi]."""
    a = np.mod(np.asarray(angle_rad, dtype=float) + np.pi, TWO_PI) - np.pi
    # np.mod maps +pi to -pi; move it to the closed end of (-pi, pi].
    a = np.where(a == -np.pi, np.pi, a)
    return a if a.ndim else float(a)


@overload
def wrap_2pi(angle_rad: float) -> float: ...
@overload
def wrap_2pi(angle_rad: ArrayLike) -> FloatArray: ...
def wrap_2pi(angle_rad: ArrayLike) -> Any:
    """Wrap an angle into [0, 2*pi)."""
    a = np.mod(np.asarray(angle_rad, dtype=float), TWO_PI)
    a = np.where(a >= TWO_PI, 0.0, a)  # mod of tiny negatives can round up to 2*pi
    return a if a.ndim else float(a)


@overload
def angdiff(a_rad: float, b_rad: float) -> float: ...
@overload
def angdiff(a_rad: ArrayLike, b_rad: ArrayLike) -> FloatArray: ...
def angdiff(a_rad: ArrayLike, b_rad: ArrayLike) -> Any:
    """The difference a - b on the circle, in (-pi, pi]. The one place angles are subtracted."""
    return wrap_pi(np.asarray(a_rad, dtype=float) - np.asarray(b_rad, dtype=float))


@overload
def circmean(
    angles_rad: ArrayLike, axis: None = None, weights: ArrayLike | None = None
) -> float: ...
@overload
def circmean(
    angles_rad: ArrayLike, axis: int | tuple[int, ...], weights: ArrayLike | None = None
) -> FloatArray: ...
def circmean(
    angles_rad: ArrayLike,
    axis: int | tuple[int, ...] | None = None,
    weights: ArrayLike | None = None,
) -> Any:
    """Mean direction on the circle, in [0, 2*pi); NaN where the resultant is zero or all NaN.

    NaNs are ignored (the mean of the valid angles along ``axis``).
    """
    a = np.asarray(angles_rad, dtype=float)
    w = np.ones_like(a) if weights is None else np.broadcast_to(np.asarray(weights, float), a.shape)
    valid = ~np.isnan(a)
    s = np.sum(np.where(valid, w * np.sin(np.where(valid, a, 0.0)), 0.0), axis=axis)
    c = np.sum(np.where(valid, w * np.cos(np.where(valid, a, 0.0)), 0.0), axis=axis)
    total = np.sum(np.where(valid, np.abs(w), 0.0), axis=axis)
    # A resultant that vanishes to rounding (e.g. 0 and 180 degrees) has no direction.
    with np.errstate(invalid="ignore"):
        m = np.where(np.hypot(s, c) <= 1e-12 * total, np.nan, np.arctan2(s, c))
    return wrap_2pi(m)


@overload
def offset_ne_m(
    lat_rad: float, lon_rad: float, lat0_rad: float, lon0_rad: float
) -> tuple[float, float]: ...
@overload
def offset_ne_m(
    lat_rad: ArrayLike, lon_rad: ArrayLike, lat0_rad: ArrayLike, lon0_rad: ArrayLike
) -> tuple[FloatArray, FloatArray]: ...
def offset_ne_m(
    lat_rad: ArrayLike, lon_rad: ArrayLike, lat0_rad: ArrayLike, lon0_rad: ArrayLike
) -> Any:
    """North and east offsets in metres of (lat, lon) from (lat0, lon0).

    Local linearisation with the radii of curvature at the mid latitude (B18, B19
    inverted): accurate to < 1e-5 relative for offsets of tens of kilometres.
    Longitude differences go through :func:`angdiff` (antimeridian safe).
    """
    lat_mid = 0.5 * (np.asarray(lat_rad, float) + np.asarray(lat0_rad, float))
    north_m = (np.asarray(lat_rad, float) - lat0_rad) / k_phi(lat_mid)
    east_m = angdiff(lon_rad, lon0_rad) / k_lambda(lat_mid)
    return north_m, east_m


@overload
def add_offset_ne(
    lat0_rad: float, lon0_rad: float, north_m: float, east_m: float
) -> tuple[float, float]: ...
@overload
def add_offset_ne(
    lat0_rad: ArrayLike,
    lon0_rad: ArrayLike,
    north_m: float | NDArray[Any],
    east_m: float | NDArray[Any],
) -> tuple[FloatArray, FloatArray]: ...
def add_offset_ne(
    lat0_rad: ArrayLike,
    lon0_rad: ArrayLike,
    north_m: float | NDArray[Any],
    east_m: float | NDArray[Any],
) -> Any:
    """Position reached from (lat0, lon0) by a small north/east offset in metres (inverse of :func:`offset_ne_m`)."""
    lat0 = np.asarray(lat0_rad, float)
    # One fixed-point step on the mid latitude is enough for offsets of tens of km.
    lat1 = lat0 + north_m * k_phi(lat0)
    lat_mid = 0.5 * (lat0 + lat1)
    lat1 = lat0 + north_m * k_phi(lat_mid)
    lat_mid = 0.5 * (lat0 + lat1)
    lon1 = wrap_pi(np.asarray(lon0_rad, float) + east_m * k_lambda(lat_mid))
    return lat1, lon1


@overload
def distance_m(lat1_rad: float, lon1_rad: float, lat2_rad: float, lon2_rad: float) -> float: ...
@overload
def distance_m(
    lat1_rad: ArrayLike, lon1_rad: ArrayLike, lat2_rad: ArrayLike, lon2_rad: ArrayLike
) -> FloatArray: ...
def distance_m(
    lat1_rad: ArrayLike, lon1_rad: ArrayLike, lat2_rad: ArrayLike, lon2_rad: ArrayLike
) -> Any:
    """Distance in metres between nearby points (local-tangent approximation, see offset_ne_m)."""
    n, e = offset_ne_m(lat2_rad, lon2_rad, lat1_rad, lon1_rad)
    return np.hypot(n, e)


def interp_position(
    t: ArrayLike, lat_rad: ArrayLike, lon_rad: ArrayLike, t_query: ArrayLike, max_gap: float
) -> tuple[FloatArray, FloatArray]:
    """Position at ``t_query`` by linear interpolation in time, NaN outside and across gaps.

    ``t`` (n,) and ``t_query`` (k,) share one time unit: float seconds, or int64
    nanoseconds (then shifted to ``t[0]`` before the float interpolation, exact for spans
    under 2**53 ns, 104 days); ``max_gap`` is in that unit too.  Samples with a non-finite
    time or coordinate are left out and the rest sorted by time (stable).  A query time
    gets a position when it equals a sample time, or lies between two neighbouring samples
    at most ``max_gap`` apart; NaN otherwise (before the first sample, after the last,
    inside a longer gap).  Latitude is linear in time; longitude is unwrapped
    (``np.unwrap``) before the interpolation and wrapped back into (-pi, pi], so a leg
    across the antimeridian interpolates the short way.  Returns ``(lat_rad, lon_rad)``,
    each shaped like ``t_query``.
    """
    times = np.asarray(t)
    if not np.issubdtype(times.dtype, np.integer):
        times = times.astype(float)
    query = np.asarray(t_query)
    lat = np.asarray(lat_rad, float)
    lon = np.asarray(lon_rad, float)
    ok = np.isfinite(times) & np.isfinite(lat) & np.isfinite(lon)
    times, lat, lon = times[ok], lat[ok], lon[ok]
    order = np.argsort(times, kind="stable")
    times, lat, lon = times[order], lat[order], np.unwrap(lon[order])
    out_lat = np.full(query.shape, np.nan)
    out_lon = np.full(query.shape, np.nan)
    if times.size == 0:
        return out_lat, out_lon
    hi = np.clip(np.searchsorted(times, query, side="left"), 0, times.size - 1)
    lo = np.clip(hi - 1, 0, times.size - 1)
    exact = times[hi] == query
    bracket = (times[lo] <= query) & (times[hi] >= query) & (times[hi] - times[lo] <= max_gap)
    use = exact | bracket
    if np.issubdtype(times.dtype, np.integer):
        x, xq = (times - times[0]).astype(float), (query[use] - times[0]).astype(float)
    else:
        x, xq = times, query[use]
    out_lat[use] = np.interp(xq, x, lat)
    out_lon[use] = wrap_pi(np.interp(xq, x, lon))
    return out_lat, out_lon


def ecef_m(lat_rad: ArrayLike, lon_rad: ArrayLike) -> FloatArray:
    """ECEF coordinates (..., 3) in metres of points on the WGS-84 ellipsoid (height 0)."""
    lat = np.asarray(lat_rad, float)
    lon = np.asarray(lon_rad, float)
    n_m = radius_prime_vertical_m(lat)
    return np.stack(
        [
            n_m * np.cos(lat) * np.cos(lon),
            n_m * np.cos(lat) * np.sin(lon),
            n_m * (1 - E2) * np.sin(lat),
        ],
        axis=-1,
    )


@overload
def range_azimuth(
    lat1_rad: float, lon1_rad: float, lat2_rad: float, lon2_rad: float
) -> tuple[float, float]: ...
@overload
def range_azimuth(
    lat1_rad: ArrayLike, lon1_rad: ArrayLike, lat2_rad: ArrayLike, lon2_rad: ArrayLike
) -> tuple[FloatArray, FloatArray]: ...
def range_azimuth(
    lat1_rad: ArrayLike, lon1_rad: ArrayLike, lat2_rad: ArrayLike, lon2_rad: ArrayLike
) -> Any:
    """Distance (m) and azimuth at point 1 towards point 2 (rad, [0, 2pi)); broadcasts.

    Azimuth: the chord X2 - X1 (ECEF) projected on the horizon of point 1 (the normal
    section azimuth).  Distance: s = 2 R asin(c / 2R), c the chord, R = sqrt(R_M R_N)
    at the mid latitude (the Gaussian mean radius).
    """
    lat1 = np.asarray(lat1_rad, float)
    lon1 = np.asarray(lon1_rad, float)
    d = ecef_m(lat2_rad, lon2_rad) - ecef_m(lat1, lon1)
    sl, cl = np.sin(lon1), np.cos(lon1)
    sp, cp = np.sin(lat1), np.cos(lat1)
    east = -sl * d[..., 0] + cl * d[..., 1]
    north = -sp * cl * d[..., 0] - sp * sl * d[..., 1] + cp * d[..., 2]
    chord = np.linalg.norm(d, axis=-1)
    lat_mid = 0.5 * (lat1 + np.asarray(lat2_rad, float))
    r_m = np.sqrt(radius_meridian_m(lat_mid) * radius_prime_vertical_m(lat_mid))
    dist = 2.0 * r_m * np.arcsin(np.minimum(chord / (2.0 * r_m), 1.0))
    return dist, wrap_2pi(np.arctan2(east, north))
