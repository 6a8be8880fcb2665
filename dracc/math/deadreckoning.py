"""Dead reckoning on WGS-84 with honest 2M circles (B1-B31), and its consistency against a reference.

Source: Banachowicz, Banachowicz & Wolski, "The accuracy assessment in dead reckoning
navigation" (seeds/000); corrected statements in METHODS.md section 2.

Glossary (paper symbols, used inside the kernels)
    KK     compass course (magnetic compass reading)            ``compass_rad``
    KZ     gyro compass course                                   ``gyro_rad``
    KDd    course made good (over ground / through the water)    ``course_rad``
    d      variation (declination), east positive                ``variation_rad``
    delta  deviation, east positive                              ``deviation_rad``
    pz     total gyro compass correction                         ``correction_rad``
    z      total leeway z = alpha + beta (drift + leeway angle)  ``leeway_rad``
    V      speed (Vw through the water, Vd over the ground)      ``speed_mps``
    Vp, Kp current drift and set (towards)                       ``current_*``
    k_phi, k_lambda  (B18), (B19): radians per metre north / east (dracc.core.geodesy)
    P      position covariance; ``P_m2`` in metres north/east, ``P_rad2`` in (phi, lambda)
    M      mean position error (drms), the "2M circle" radius 2M (B30, B31)

Error model ("honest" covariance)
    Every error source is a first-order Gauss-Markov process e(t) with standard deviation
    sigma and correlation time tau (tau = inf a bias, tau = 0 independent per step), acting
    on the velocity through a sensitivity g(t) (metres per second per unit of e).  The
    velocity error over the step [t_k, t_k+1] is g_k * e(t) (g held, as the velocity is
    held by (B20)), so the position error is a sum of g_k * I_k with I_k the integral of e
    over the step.  For independent processes the position covariance is the sum over
    processes of sum_i sum_l g_i g_l^T Cov(I_i, I_l), where, exactly,
        Var(I_k)      = 2 sigma^2 tau^2 (x - 1 + exp(-x)),  x = dt_k / tau
        Cov(I_i, I_k) = sigma^2 u_i u_k exp(-(t_k - t_i+1)/tau),  i < k,  u = tau (1 - exp(-x)).
    This is the augmented-state Kalman time update (position + error states) solved in
    closed form; it does not depend on the logging rate.  (B23) is the special case of
    errors independent per step (tau = 0): Var(I_k) = sigma^2 dt_k^2, no cross terms.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from dracc.core import distributions as dist
from dracc.core.arrays import unique_sorted
from dracc.core.config import DeadReckoningConfig, ErrorSource
from dracc.core.durations import parse_reset_s
from dracc.core.errors import ConfigError, InsufficientDataError
from dracc.core.geodesy import interp_position, k_lambda, k_phi, offset_ne_m, wrap_2pi, wrap_pi
from dracc.core.units import DEG_RAD, KN_MPS
from dracc.math.ellipse import error_ellipse

__all__ = [
    "DRTrack",
    "Consistency",
    "ErrorProcess",
    "Gap",
    "LegConsistency",
    "course_gyro_rad",
    "course_magnetic_rad",
    "covariance_b23_rad2",
    "covariance_m2_from_rad2",
    "dead_reckon",
    "deviation_curve_rad",
    "deviation_table_rad",
    "dr_consistency",
    "covered_span_s",
    "dr_schedule",
    "error_processes",
    "gauss_markov_position_covariance_m2",
    "honest_covariance_m2",
    "integrate_ne",
    "interp_deviation_rad",
    "leeway_from_log_rad",
    "mean_error_m",
    "prob_inside_2m",
    "sigma_course_rad",
    "speed_covariance_rad2",
    "speed_from_components_mps",
    "total_leeway_rad",
    "TrueHeading",
    "true_heading_rad",
    "velocity_ground_ne_mps",
    "velocity_water_ne_mps",
]


# --------------------------------------------------------------------------------------
# Course made good and speed (B1-B6)
# --------------------------------------------------------------------------------------


def speed_from_components_mps(vx_mps, vy_mps):
    """V = sqrt(Vx^2 + Vy^2) (B1), from the longitudinal and transverse log components."""
    return np.hypot(vx_mps, vy_mps)  # (B1)


def leeway_from_log_rad(vx_mps, vy_mps):
    """Angle of the log's velocity from the ship's head, starboard (transverse > 0) positive.

    Through the water it is the drift angle alpha (B5), over the ground the total
    leeway z (B6).  ``arctan2`` replaces the paper's arctg(Vy/Vx) so that sternway
    (Vx < 0) keeps its direction.
    """
    return np.arctan2(vy_mps, vx_mps)  # (B5), (B6)


def total_leeway_rad(drift_rad, leeway_rad):
    """z = alpha + beta (B4): drift angle plus leeway angle."""
    return np.asarray(drift_rad, float) + np.asarray(leeway_rad, float)  # (B4)


def course_magnetic_rad(compass_rad, variation_rad, deviation_rad, leeway_rad=0.0):
    """Course made good from a magnetic compass, KDd = KK + d + delta + z (B2), in [0, 2 pi)."""
    return wrap_2pi(
        np.asarray(compass_rad, float) + variation_rad + deviation_rad + leeway_rad  # (B2)
    )


def course_gyro_rad(gyro_rad, correction_rad=0.0, leeway_rad=0.0):
    """Course made good from a gyro compass, KDd = KZ + pz + z (B3), in [0, 2 pi)."""
    return wrap_2pi(np.asarray(gyro_rad, float) + correction_rad + leeway_rad)  # (B3)


def deviation_curve_rad(heading_rad, coefficients_rad):
    """Deviation curve delta(K) = A + B sin K + C cos K + D sin 2K + E cos 2K.

    ``coefficients_rad`` = (A, B, C, D, E) in radians; K the compass heading.
    """
    a, b, c, d, e = (float(x) for x in coefficients_rad)
    k = np.asarray(heading_rad, float)
    return a + b * np.sin(k) + c * np.cos(k) + d * np.sin(2 * k) + e * np.cos(2 * k)


def deviation_table_rad(table_deg: Mapping[str, float] | Mapping[float, float]):
    """Parse a deviation table {heading_deg: deviation_deg} (config keys are strings).

    Returns (heading_rad, deviation_rad) sorted by heading in [0, 2 pi).  A key that is
    not a number, a heading outside [0, 360] or a duplicate heading raises ConfigError.
    """
    pts: dict[float, float] = {}
    for key, value in table_deg.items():
        try:
            h_deg = float(key)
            dev_deg = float(value)
        except (TypeError, ValueError) as err:
            raise ConfigError(
                f"[dead_reckoning.deviation_table] {key!r} = {value!r}: heading and "
                "deviation must be numbers in degrees"
            ) from err
        if not (0.0 <= h_deg <= 360.0) or not math.isfinite(dev_deg):
            raise ConfigError(
                f"[dead_reckoning.deviation_table] {key!r} = {value!r}: heading must be in "
                "[0, 360] and the deviation finite"
            )
        h = float(wrap_2pi(h_deg * DEG_RAD))
        if h in pts and pts[h] != dev_deg * DEG_RAD:
            raise ConfigError(
                f"[dead_reckoning.deviation_table] heading {key!r} given twice with "
                "different deviations (0 and 360 are the same heading)"
            )
        pts[h] = dev_deg * DEG_RAD
    if not pts:
        raise ConfigError("[dead_reckoning.deviation_table] is empty")
    h_sorted = np.array(sorted(pts))
    return h_sorted, np.array([pts[h] for h in h_sorted])


def interp_deviation_rad(heading_rad, table_heading_rad, table_deviation_rad):
    """Deviation at ``heading_rad`` by linear interpolation on the circle (periodic in 2 pi)."""
    return np.interp(
        wrap_2pi(heading_rad), table_heading_rad, table_deviation_rad, period=2 * np.pi
    )


@dataclass(frozen=True)
class TrueHeading:
    """True heading per sample and where its corrections came from (for the report)."""

    heading_rad: np.ndarray  #: (n,) in [0, 2 pi); NaN where the input heading is NaN
    n_magnetic: int  #: samples from a magnetic compass ((B2) applied)
    n_variation_from_sentence: int
    n_variation_from_config: int
    deviation_source: str  #: 'sentence', 'curve', 'table', 'none' (0), or 'mixed'


def true_heading_rad(
    heading_rad,
    reference,
    deviation_rad=None,
    variation_rad=None,
    *,
    errors: DeadReckoningConfig | None = None,
    deviation_coefficients_rad=None,
    gyro_correction_rad=0.0,
) -> TrueHeading:
    """True heading from the canonical heading columns, (B2) for magnetic, (B3) for true.

    ``reference`` 'T' (gyro: KZ + pz, B3) or 'M' (magnetic: KK + d + delta, B2), per
    sample or one string.  Deviation delta: the sentence's field where given, else the
    curve A-E (``deviation_coefficients_rad``), else the config's deviation table, else 0
    (the compass error sources then carry it).  Variation d: the sentence's field where
    given, else ``[dead_reckoning] variation_deg``; a magnetic heading with neither
    raises InsufficientDataError (dracc does not assume zero variation).  Leeway is added
    later (dead_reckon's ``transverse_mps``).
    """
    cfg = errors if errors is not None else DeadReckoningConfig()
    h = np.asarray(heading_rad, float)
    n = h.size
    ref = np.broadcast_to(np.asarray(reference, dtype=object), (n,))
    magnetic = np.array([str(r).upper() == "M" for r in ref], dtype=bool) & np.isfinite(h)
    dev_in = (
        np.full(n, np.nan)
        if deviation_rad is None
        else np.broadcast_to(np.asarray(deviation_rad, float), (n,))
    )
    var_in = (
        np.full(n, np.nan)
        if variation_rad is None
        else np.broadcast_to(np.asarray(variation_rad, float), (n,))
    )
    out = np.asarray(course_gyro_rad(h, gyro_correction_rad), float).copy()  # (B3)
    if not magnetic.any():
        return TrueHeading(out, 0, 0, 0, "none")
    var = var_in.copy()
    from_sentence = magnetic & np.isfinite(var_in)
    missing = magnetic & ~np.isfinite(var)
    if missing.any():
        if cfg.variation_deg is None:
            raise InsufficientDataError(
                f"{int(missing.sum())} magnetic heading samples have no variation and "
                "[dead_reckoning] variation_deg is not set; give the local variation "
                "(east positive) in the config"
            )
        var[missing] = cfg.variation_deg * DEG_RAD
    dev = dev_in.copy()
    sources = {"sentence"} if np.any(magnetic & np.isfinite(dev_in)) else set()
    need = magnetic & ~np.isfinite(dev)
    if need.any():
        if deviation_coefficients_rad is not None:
            dev[need] = deviation_curve_rad(h[need], deviation_coefficients_rad)
            sources.add("curve")
        elif cfg.deviation_table:
            th, td = deviation_table_rad(cfg.deviation_table)
            dev[need] = interp_deviation_rad(h[need], th, td)
            sources.add("table")
        else:
            dev[need] = 0.0
            sources.add("none")
    out[magnetic] = course_magnetic_rad(h[magnetic], var[magnetic], dev[magnetic])  # (B2)
    return TrueHeading(
        heading_rad=out,
        n_magnetic=int(magnetic.sum()),
        n_variation_from_sentence=int(from_sentence.sum()),
        n_variation_from_config=int(missing.sum()),
        deviation_source=sources.pop() if len(sources) == 1 else "mixed",
    )


# --------------------------------------------------------------------------------------
# Velocity over ground (B7-B14) and integration on the ellipsoid (B16-B22)
# --------------------------------------------------------------------------------------


def velocity_water_ne_mps(speed_water_mps, course_water_rad, current_mps=0.0, current_set_rad=0.0):
    """Velocity over ground (north, east) from a relative (water) log plus the current.

    VN = Vw cos KDw + Vp cos Kp   (B7, B9, B11)
    VE = Vw sin KDw + Vp sin Kp   (B8, B10 corrected: the paper prints Vp cos Kp, B12)
    ``current_set_rad`` is the direction the current sets towards.
    """
    vn = speed_water_mps * np.cos(course_water_rad) + current_mps * np.cos(current_set_rad)  # (B11)
    # (B10) corrected: the east component of the current is Vp sin Kp, not Vp cos Kp
    ve = speed_water_mps * np.sin(course_water_rad) + current_mps * np.sin(current_set_rad)  # (B12)
    return vn, ve


def velocity_ground_ne_mps(speed_ground_mps, course_ground_rad):
    """Velocity over ground from an absolute (ground) log: VN = Vd cos KDd (B13), VE = Vd sin KDd (B14)."""
    return (
        speed_ground_mps * np.cos(course_ground_rad),  # (B13)
        speed_ground_mps * np.sin(course_ground_rad),  # (B14)
    )


def integrate_ne(time_s, vn_mps, ve_mps, lat0_rad, lon0_rad, *, iterations: int = 2):
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
    return lat, wrap_pi(lon)


# --------------------------------------------------------------------------------------
# The paper's covariance (B23-B31)
# --------------------------------------------------------------------------------------


def sigma_course_rad(sigma_kz_rad, sigma_pz_rad=0.0, sigma_z_rad=0.0):
    """sigma_C = sqrt(sigma_KZ^2 + sigma_pz^2 + sigma_z^2) (B29)."""
    return np.sqrt(
        np.square(sigma_kz_rad) + np.square(sigma_pz_rad) + np.square(sigma_z_rad)  # (B29)
    )


def speed_covariance_rad2(lat_rad, speed_mps, course_rad, sigma_v_mps, sigma_c_rad):
    """Covariance P_V (..., 2, 2) of [V_phi, V_lambda] in (rad/s)^2 (B25-B28).

    sigma^2_Vphi    = k_phi^2 [(sigma_V cos C)^2 + (V sigma_C sin C)^2]      (B26)
    sigma^2_Vlambda = k_lambda^2 [(sigma_V sin C)^2 + (V sigma_C cos C)^2]   (B27)
    sigma_VphiVlam  = 1/2 k_phi k_lambda (sigma_V^2 - V^2 sigma_C^2) sin 2C  (B28, corrected)
    The paper prints (B28) as 1/2 (k_phi^2 sigma_V^2 - k_lambda^2 V^2 sigma_C^2) sin 2C;
    the Jacobian of [k_phi V cos C, k_lambda V sin C] gives the common factor k_phi k_lambda.
    """
    kp = k_phi(lat_rad)
    kl = k_lambda(lat_rad)
    c = np.asarray(course_rad, float)
    v = np.asarray(speed_mps, float)
    s_v = np.asarray(sigma_v_mps, float)
    s_c = np.asarray(sigma_c_rad, float)
    var_phi = kp**2 * ((s_v * np.cos(c)) ** 2 + (v * s_c * np.sin(c)) ** 2)  # (B26)
    var_lam = kl**2 * ((s_v * np.sin(c)) ** 2 + (v * s_c * np.cos(c)) ** 2)  # (B27)
    # (B28), corrected: common factor k_phi*k_lambda
    cov = 0.5 * kp * kl * (s_v**2 - v**2 * s_c**2) * np.sin(2 * c)
    return np.stack([np.stack([var_phi, cov], -1), np.stack([cov, var_lam], -1)], -2)  # (B25)


def covariance_b23_rad2(time_s, lat_rad, speed_mps, course_rad, sigma_v_mps, sigma_c_rad, P0_rad2):
    """The paper's propagation P_i+1 = P_i + dt^2 P_V,i (B23), errors independent per step.

    Inputs are per sample (n,) (sigmas may be scalars); P0_rad2 (2, 2) in rad^2.  Returns
    P (n, 2, 2) in rad^2 of (phi, lambda).  The speed-vector covariance of sample i acts
    over [t_i, t_i+1].  At high data rates this form averages correlated errors away
    (METHODS section 2); see :func:`honest_covariance_m2` for the rate-independent form.
    """
    t = np.asarray(time_s, float)
    n = t.size
    pv = speed_covariance_rad2(
        np.broadcast_to(lat_rad, (n,)),
        np.broadcast_to(speed_mps, (n,)),
        np.broadcast_to(course_rad, (n,)),
        np.broadcast_to(sigma_v_mps, (n,)),
        np.broadcast_to(sigma_c_rad, (n,)),
    )
    dt = np.diff(t)
    incr = dt[:, None, None] ** 2 * pv[:-1]  # (B23)
    out = np.empty((n, 2, 2))
    out[0] = P0_rad2
    out[1:] = np.asarray(P0_rad2, float) + np.cumsum(incr, axis=0)  # (B23)
    return out


def covariance_m2_from_rad2(P_rad2, lat_rad):
    """P in metres north/east from P in (phi, lambda): divide by k_phi, k_lambda (B30's scaling)."""
    s = np.stack([1.0 / k_phi(lat_rad), 1.0 / k_lambda(lat_rad)], -1)
    return np.asarray(P_rad2) * s[..., :, None] * s[..., None, :]


def mean_error_m(P_rad2, lat_rad):
    """M = sqrt((sigma_phi/k_phi)^2 + (sigma_lambda/k_lambda)^2) (B30); 2M is (B31)."""
    P = np.asarray(P_rad2, float)
    return np.sqrt(
        P[..., 0, 0] / k_phi(lat_rad) ** 2 + P[..., 1, 1] / k_lambda(lat_rad) ** 2
    )  # (B30)


_GL_X, _GL_W = np.polynomial.legendre.leggauss(64)


def prob_inside_2m(P_m2):
    """Probability that a zero-mean Gaussian error with covariance P (..., 2, 2) lies inside 2M.

    P(X1^2 + X2^2 <= 4 (s1^2 + s2^2)) over the principal axes; 1 - exp(-4) = 0.9817 for
    a circular distribution, 2 Phi(2) - 1 = 0.9545 for a degenerate (line) one
    (METHODS section 2: "2M covers about 95.4-98.2 %").  64-point Gauss-Legendre over the
    major-axis coordinate x1 = R sin(theta).
    """
    s1, s2, _ = error_ellipse(P_m2)
    s1 = np.asarray(s1)[..., None]
    s2 = np.asarray(s2)[..., None]
    r = 2.0 * np.sqrt(s1**2 + s2**2)
    theta = 0.5 * np.pi * _GL_X
    x1 = r * np.sin(theta)
    rem = r * np.cos(theta)  # sqrt(R^2 - x1^2)
    with np.errstate(divide="ignore", invalid="ignore"):
        inner = np.where(s2 > 0, 2 * dist.norm_cdf(rem / np.where(s2 > 0, s2, 1.0)) - 1, 1.0)
        dens = dist.norm_pdf(x1 / s1) / s1
    val = np.sum(_GL_W * dens * inner * r * np.cos(theta), axis=-1) * 0.5 * np.pi
    return np.where(s1[..., 0] > 0, val, 1.0)


# --------------------------------------------------------------------------------------
# Honest covariance: Gauss-Markov error processes
# --------------------------------------------------------------------------------------


def _linear_recurrence(a, b, tau_s, dt):
    """h_0 = 0, h_k+1 = a_k h_k + b_k, vectorised in blocks (a_k = exp(-dt_k/tau)).

    a: (m,), b: (m, 2).  Returns h (m, 2) with h[k] the value *before* adding b_k
    (i.e. h_k).  Within a block the factors exp(+(t - t_start)/tau) stay below e^40.
    """
    m = a.size
    h = np.empty_like(b)
    if m == 0:
        return h
    cum_t = np.concatenate([[0.0], np.cumsum(dt)])  # t_k - t_0
    span = 40.0 * tau_s
    start = 0
    h_start = np.zeros(b.shape[1])
    while start < m:
        stop = int(np.searchsorted(cum_t, cum_t[start] + span, side="right")) - 1
        stop = min(max(stop, start + 1), m)
        rel = cum_t[start : stop + 1] - cum_t[start]  # t_k - t_s for k = start..stop
        grow = np.exp(rel / tau_s)
        # h_k = exp(-(t_k - t_s)/tau) [h_s + sum_{s<=i<k} b_i exp((t_i+1 - t_s)/tau)]
        acc = np.cumsum(b[start:stop] * grow[1:, None], axis=0)
        inner = np.vstack([h_start[None, :], h_start[None, :] + acc])
        vals = inner / grow[:, None]
        h[start:stop] = vals[:-1]
        h_start = vals[-1]
        start = stop
    return h


def _gm_cov3(t, gn, ge, sigma, tau_s):
    """(n, 3) cumulative [P_NN, P_NE, P_EE] for one process; see the public wrapper."""
    n = t.size
    out = np.zeros((n, 3))
    if n < 2 or sigma == 0.0:
        return out
    dt = np.diff(t)
    gn = np.broadcast_to(gn, (n,))[:-1]
    ge = np.broadcast_to(ge, (n,))[:-1]
    s2 = float(sigma) ** 2
    if math.isinf(tau_s):
        # bias: position error = e * sum g dt, P = sigma^2 G G^T (exact, any dt)
        Gn = np.cumsum(gn * dt)
        Ge = np.cumsum(ge * dt)
        out[1:, 0] = s2 * Gn * Gn
        out[1:, 1] = s2 * Gn * Ge
        out[1:, 2] = s2 * Ge * Ge
        return out
    if tau_s == 0.0:
        var_i = s2 * dt * dt  # (B23): independent per step
        out[1:, 0] = np.cumsum(var_i * gn * gn)
        out[1:, 1] = np.cumsum(var_i * gn * ge)
        out[1:, 2] = np.cumsum(var_i * ge * ge)
        return out
    x = dt / tau_s
    a = np.exp(-x)
    u = -tau_s * np.expm1(-x)  # tau (1 - a), -> dt as tau -> inf
    # Var(I_k) = 2 sigma^2 tau^2 (x - 1 + e^-x), with its series where x is small
    poly = np.where(x < 1e-3, x * x * (0.5 - x / 6 + x * x / 24), x - 1.0 + a)
    var_i = 2.0 * s2 * tau_s**2 * poly
    h = _linear_recurrence(a, np.column_stack([gn * u, ge * u]), tau_s, dt)
    su = s2 * u
    mn = su * h[:, 0]  # m_k = sigma^2 u_k h_k = Cov(p_k, I_k)
    me = su * h[:, 1]
    out[1:, 0] = np.cumsum(2 * gn * mn + var_i * gn * gn)
    out[1:, 1] = np.cumsum(gn * me + mn * ge + var_i * gn * ge)
    out[1:, 2] = np.cumsum(2 * ge * me + var_i * ge * ge)
    return out


def _cov3_to_22(c3):
    out = np.empty(c3.shape[:-1] + (2, 2))
    out[..., 0, 0] = c3[..., 0]
    out[..., 0, 1] = c3[..., 1]
    out[..., 1, 0] = c3[..., 1]
    out[..., 1, 1] = c3[..., 2]
    return out


def gauss_markov_position_covariance_m2(time_s, g_mps, sigma, tau_s):
    """Position covariance (n, 2, 2) in m^2 caused by one Gauss-Markov error process.

    time_s (n,), g_mps (n, 2): velocity error (north, east) per unit of the process on the
    step [t_k, t_k+1]; sigma, tau_s: the process (stationary at t_0; tau = inf a bias,
    tau = 0 independent per step as in (B23)).  The position error is zero at t_0.
    Exact for g held over each step (see the module docstring):
        P_k+1 = P_k + g_k m_k^T + m_k g_k^T + Var(I_k) g_k g_k^T,  m_k = sigma^2 u_k h_k,
        h_k+1 = a_k h_k + u_k g_k,  a_k = exp(-dt_k/tau),  u_k = tau (1 - a_k).
    """
    t = np.asarray(time_s, float)
    g = np.asarray(g_mps, float)
    return _cov3_to_22(_gm_cov3(t, g[:, 0], g[:, 1], sigma, tau_s))


@dataclass(frozen=True)
class ErrorProcess:
    """One configured error source in SI units: sigma in ``unit``, correlation time tau_s."""

    name: str
    sigma: float
    tau_s: float
    unit: str  #: 'rad' (heading), 'fraction' (log scale), 'mps' (log speed, current)
    acts_on: str  #: 'heading', 'scale', 'speed', 'current_n', 'current_e'


def error_processes(cfg: DeadReckoningConfig, mode: str = "water") -> tuple[ErrorProcess, ...]:
    """The configured error sources as SI Gauss-Markov processes.

    Heading: compass bias and noise (deg -> rad); leeway (water mode only: over the
    ground the log measures the track).  Speed: log scale (fraction), bias and noise
    (kn -> m/s).  Current, per axis (water mode only).  A negative sigma or tau raises
    ConfigError naming the key.
    """
    items: list[tuple[str, ErrorSource, float, str, str]] = [
        ("compass_bias_deg", cfg.compass_bias_deg, DEG_RAD, "rad", "heading"),
        ("compass_noise_deg", cfg.compass_noise_deg, DEG_RAD, "rad", "heading"),
        ("log_scale", cfg.log_scale, 1.0, "fraction", "scale"),
        ("log_bias_kn", cfg.log_bias_kn, KN_MPS, "mps", "speed"),
        ("log_noise_kn", cfg.log_noise_kn, KN_MPS, "mps", "speed"),
    ]
    if mode == "water":
        items += [
            ("leeway_deg", cfg.leeway_deg, DEG_RAD, "rad", "heading"),
            ("current_kn", cfg.current_kn, KN_MPS, "mps", "current_n"),
            ("current_kn", cfg.current_kn, KN_MPS, "mps", "current_e"),
        ]
    out = []
    for name, src, factor, unit, acts in items:
        if not (src.sigma >= 0 and src.tau_s >= 0):
            raise ConfigError(
                f"[dead_reckoning.{name}] sigma and tau_s must be >= 0, got "
                f"sigma={src.sigma}, tau_s={src.tau_s}"
            )
        out.append(ErrorProcess(name, float(src.sigma) * factor, float(src.tau_s), unit, acts))
    return tuple(out)


def _sensitivity_mps(acts_on: str, speed_mps, course_rad):
    """(g_north, g_east): velocity error per unit of an error acting on ``acts_on``."""
    v = np.asarray(speed_mps, float)
    if acts_on == "current_n":
        return 1.0, 0.0
    if acts_on == "current_e":
        return 0.0, 1.0
    c = np.asarray(course_rad, float)
    cos_c, sin_c = np.cos(c), np.sin(c)
    if acts_on == "heading":  # d/dC [V cos C, V sin C]
        return -v * sin_c, v * cos_c
    if acts_on == "scale":  # dV = s V
        return v * cos_c, v * sin_c
    if acts_on == "speed":
        return cos_c, sin_c
    raise ValueError(f"unknown error target {acts_on!r}")


def _coarse_grid(t, step_s):
    """Indices of the samples at or after each multiple of ``step_s`` from t_0, plus the last."""
    marks = np.arange(t[0], t[-1], step_s)
    idx = unique_sorted(np.r_[np.searchsorted(t, marks, side="left"), t.size - 1])
    return idx


def honest_covariance_m2(
    time_s, speed_mps, course_rad, processes, P0_m2=None, *, step_s: float | None = None
):
    """Position covariance (n, 2, 2) in m^2 north/east from independent Gauss-Markov sources.

    P_k = P0 + sum over processes of :func:`gauss_markov_position_covariance_m2`; every
    process starts stationary at t_0 (a fix resets the position error, not the sensors).

    ``step_s``: where the data are denser than this, correlated processes (tau > 0) are
    propagated on a grid of about ``step_s`` with the sensitivity g averaged over each
    grid step (sum g dt / step, so biases stay exact) and P interpolated linearly in time
    between grid points (a convex combination, so it stays positive semi-definite).  The
    error is of the order of step_s / tau for the fastest process (well under 1 % for
    step_s = 1 s and tau >= 120 s; see the rate-independence test).  tau = 0 processes
    (independent per logged step, as (B23)) always use the logged steps.
    """
    t = np.asarray(time_s, float)
    n = t.size
    acc = np.zeros((n, 3))
    if P0_m2 is not None:
        p0 = np.asarray(P0_m2, float)
        acc += [p0[0, 0], p0[0, 1], p0[1, 1]]
    coarse = None
    if step_s is not None and n > 2 and (t[-1] - t[0]) / (n - 1) < 0.5 * step_s:
        coarse = _coarse_grid(t, step_s)
        tc = t[coarse]
        dt = np.diff(t)

    def add(gn, ge, sigma, tau_s, diagonal_only=False):
        if coarse is None or tau_s == 0.0:
            c3 = _gm_cov3(t, gn, ge, sigma, tau_s)
        else:
            # time-weighted mean of g over each grid step, from prefix sums of g dt
            gcols = []
            for g in (gn, ge):
                g = np.broadcast_to(np.asarray(g, float), (n,))
                G = np.r_[0.0, np.cumsum(g[:-1] * dt)][coarse]
                gcols.append(np.r_[np.diff(G) / np.diff(tc), 0.0])
            c3c = _gm_cov3(tc, gcols[0], gcols[1], sigma, tau_s)
            c3 = np.column_stack([np.interp(t, tc, c3c[:, j]) for j in range(3)])
        if diagonal_only:  # the same scalar process on both axes (the current)
            acc[:, 0] += c3[:, 0]
            acc[:, 2] += c3[:, 0]
        else:
            acc[:] += c3

    done_current = False
    for p in processes:
        if p.acts_on in ("current_n", "current_e"):
            # north and east currents with one (sigma, tau): one scalar run, on the diagonal
            if done_current:
                continue
            pair = [q for q in processes if q.acts_on in ("current_n", "current_e")]
            if len(pair) == 2 and pair[0].sigma == pair[1].sigma and pair[0].tau_s == pair[1].tau_s:
                add(1.0, 0.0, p.sigma, p.tau_s, diagonal_only=True)
                done_current = True
                continue
        gn, ge = _sensitivity_mps(p.acts_on, speed_mps, course_rad)
        add(gn, ge, p.sigma, p.tau_s)
    return _cov3_to_22(acc)


# --------------------------------------------------------------------------------------
# The dead-reckoning entry point
# --------------------------------------------------------------------------------------

#: where a reset of "auto" stops shrinking: a log of 8 h or more gets hourly legs
_AUTO_RESETS_S = (30.0, 60.0, 120.0, 300.0, 600.0, 900.0, 1200.0, 1800.0, 3600.0)


def dr_schedule(
    cfg: DeadReckoningConfig, span_s: float, reset: str | float | None = None
) -> tuple[float, str, float]:
    """(reset_s, label, epoch_interval_s) for a DR over ``span_s`` seconds.

    ``reset`` overrides ``cfg.reset`` (a duration, "watch", "never" or "auto").

    ``reset = "auto"``: every hour on a log of 8 h or more; on a shorter one the largest of
    30 s, 1, 2, 5, 10, 15, 20, 30 min giving at least 8 legs, so that the consistency test
    has legs to learn from and to score.  ``epoch_interval_s`` unset: 10 min, or a sixth of
    the reset interval where that is shorter (at least 5 s).
    """
    rule = cfg.reset if reset is None else reset
    if str(rule).strip().lower() == "auto":
        fits = [r for r in _AUTO_RESETS_S if r <= span_s / 8.0]
        reset_s = fits[-1] if fits else _AUTO_RESETS_S[0]
        label = f"auto ({_duration_label(reset_s)})"
    else:
        reset_s = parse_reset_s(rule)
        label = str(rule)
    if cfg.epoch_interval_s is not None:
        epoch_s = float(cfg.epoch_interval_s)
    else:
        epoch_s = 600.0 if not math.isfinite(reset_s) else float(np.clip(reset_s / 6.0, 5.0, 600.0))
    return reset_s, label, epoch_s


def covered_span_s(time_s, max_gap_s: float) -> float:
    """The time the samples cover: the sum of the steps no longer than ``max_gap_s`` (a
    stray record years away adds nothing)."""
    dt = np.diff(np.asarray(time_s, float))
    return float(dt[dt <= max_gap_s].sum())


def _duration_label(s: float) -> str:
    return f"{s / 3600:g}h" if s >= 3600 else f"{s / 60:g}min" if s >= 60 else f"{s:g}s"


@dataclass(frozen=True)
class Gap:
    """An interval between two valid samples of one channel longer than twice its usual spacing."""

    start_s: float  #: time of the last valid sample before the gap
    end_s: float  #: time of the next valid sample (inf: none before the end of the data)
    bridged: bool  #: True: held over (<= max_gap_s); False: the track breaks here
    channel: str = "heading"  #: 'heading' or 'speed' (the log, both components)

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s


@dataclass(frozen=True)
class DRTrack:
    """A dead-reckoned track with its honest covariance, per sample.

    Positions are NaN where no leg runs (before the first start, after a break until the
    next fix).  ``P_m2`` is north/east in m^2; ``radius_2m_m`` = 2 sqrt(tr P) (B30, B31);
    the ellipse is 1 sigma.  ``leg`` is -1 where no leg runs.
    """

    time_s: np.ndarray
    lat_rad: np.ndarray
    lon_rad: np.ndarray
    vn_mps: np.ndarray
    ve_mps: np.ndarray
    P_m2: np.ndarray
    radius_2m_m: np.ndarray
    semi_major_m: np.ndarray
    semi_minor_m: np.ndarray
    orientation_rad: np.ndarray
    since_fix_s: np.ndarray
    leg: np.ndarray
    leg_start_s: np.ndarray  #: (n_legs,) start time of each leg
    leg_start_reason: tuple[str, ...]  #: 'start', 'reset', 'after-gap'
    epoch_index: np.ndarray  #: indices of the reported epochs (every epoch_interval_s)
    gaps: tuple[Gap, ...]
    mode: str
    reset_s: float
    n_invalid_samples: int  #: samples without heading or speed (bridged or in breaks)

    @property
    def n_legs(self) -> int:
        return int(self.leg_start_s.size)

    @property
    def n_breaks(self) -> int:
        return sum(not g.bridged for g in self.gaps)


def _as_fixes(fixes, fix_sigma_m):
    if fixes is None:
        return None
    if len(fixes) == 3:
        ft, flat, flon = fixes
        fs = np.full(np.shape(ft), fix_sigma_m)
    else:
        ft, flat, flon, fs = fixes
    ft = np.asarray(ft, float)
    flat = np.asarray(flat, float)
    flon = np.asarray(flon, float)
    fs = np.broadcast_to(np.asarray(fs, float), ft.shape)
    fs = np.where(np.isfinite(fs), fs, fix_sigma_m)
    ok = np.isfinite(ft) & np.isfinite(flat) & np.isfinite(flon)
    order = np.argsort(ft[ok], kind="stable")
    return ft[ok][order], flat[ok][order], flon[ok][order], fs[ok][order]


def _hold_channel(t, ok, max_gap_s, channel):
    """Sample-and-hold for one channel: (index of the value held at each sample, usable
    steps (n-1,), gaps).  Step k (t_k -> t_k+1) is usable when the interval between the
    valid samples around it is at most ``max_gap_s``; intervals longer than twice the
    channel's typical spacing are reported as gaps (bridged or breaking)."""
    n = t.size
    idx = np.arange(n)
    last = np.maximum.accumulate(np.where(ok, idx, -1))
    nxt = np.minimum.accumulate(np.where(ok, idx, n)[::-1])[::-1]
    lv = last[:-1]
    lv_time = np.where(lv >= 0, t[np.maximum(lv, 0)], -np.inf)
    # end of the interval: the next valid sample, or (trailing invalid samples) the step's end
    end_time = np.where(nxt[1:] >= n, t[1:], t[np.minimum(nxt[1:], n - 1)])
    steps_ok = (lv >= 0) & (end_time - lv_time <= max_gap_s)
    vidx = np.flatnonzero(ok)
    tv = t[vidx]
    dtv = np.diff(tv)
    gaps = []
    if dtv.size:
        typical = float(np.median(dtv))
        for j in np.flatnonzero(dtv > 2.0 * typical):
            gaps.append(Gap(float(tv[j]), float(tv[j + 1]), bool(dtv[j] <= max_gap_s), channel))
    if vidx.size and vidx[-1] < n - 1 and t[-1] - tv[-1] > max_gap_s:
        gaps.append(Gap(float(tv[-1]), math.inf, False, channel))
    if vidx.size and vidx[0] > 0:  # nothing to hold before the first value
        gaps.insert(0, Gap(float(t[0]), float(tv[0]), False, channel))
    return np.maximum(last, 0), steps_ok, gaps


def dead_reckon(
    time_s,
    heading_rad,
    speed_mps,
    *,
    errors: DeadReckoningConfig | None = None,
    lat0_rad: float | None = None,
    lon0_rad: float | None = None,
    sigma0_m: float | None = None,
    fixes=None,
    reset_s: float | str | None = None,
    transverse_mps=None,
    current_ne_mps=None,
    mode: str = "water",
    max_gap_s: float | None = None,
    epoch_interval_s: float | None = None,
    covariance_step_s: float | None = 1.0,
    covariance: bool = True,
) -> DRTrack:
    """Dead-reckon a track from heading and speed samples, with the honest 2M circle.

    time_s (n,) increasing seconds from any epoch.  heading_rad (n,): the *true* heading
    (course through the water for ``mode='water'``, course over ground for 'ground'),
    i.e. (B2) or (B3) already applied (see :func:`course_magnetic_rad`,
    :func:`course_gyro_rad`); speed_mps (n,) the log's longitudinal speed.  NaN marks a
    missing value.  ``transverse_mps`` (n,) the log's transverse component (starboard
    +): speed by (B1), leeway/drift angle by (B5)/(B6) added to the heading.
    ``current_ne_mps`` (2,) or (n, 2) a known current added in water mode (B11, B12).

    Start: (lat0_rad, lon0_rad) with 1-sigma ``sigma0_m`` per axis at time_s[0], or the
    first fix.  ``fixes`` = (time_s, lat_rad, lon_rad[, sigma_m]): the track restarts at
    the first fix at or after ``leg start + reset_s`` (or, after a break, at the first fix
    after the data resume), from the fix advanced to the next sample by the held velocity,
    with P0 = sigma_m^2 I.  ``reset_s``: seconds or "1h"/"watch"/"never" (default
    ``errors.reset``).  ``errors`` (default DeadReckoningConfig()) gives the error sources,
    ``max_gap_s`` and ``epoch_interval_s`` unless overridden.

    Heading and speed are held independently, each from its own last valid sample (as
    (B20) holds the velocity), so a union time base of a 10 Hz compass and a 1 Hz log
    with NaN where a channel has no sample is the expected input.  A channel missing for
    at most ``max_gap_s`` (between two of its valid samples) is bridged; a longer gap
    breaks the track (positions NaN until the next fix).  Intervals longer than twice a
    channel's usual spacing are reported in ``gaps``.  Raises InsufficientDataError when
    there is no heading at all, no speed at all, or no start position.

    ``covariance_step_s``: the correlated error processes are propagated on a grid of
    about this step where the data are denser (see :func:`honest_covariance_m2`);
    None propagates at every sample (exact, slower at 10 Hz).  ``covariance=False`` skips
    the configured covariance (P, 2M and the ellipse are NaN): for a caller that forms its
    own, as :func:`dracc.math.ep.estimate_position` does.
    """
    cfg = errors if errors is not None else DeadReckoningConfig()
    if mode not in ("water", "ground"):
        raise ValueError(f"mode must be 'water' or 'ground', got {mode!r}")
    if mode == "ground" and current_ne_mps is not None:
        raise ValueError("a current applies to a water (relative) log only")
    max_gap = float(cfg.max_gap_s if max_gap_s is None else max_gap_s)
    reset, _, auto_epoch = dr_schedule(cfg, covered_span_s(time_s, max_gap), reset_s)
    epoch_dt = float(auto_epoch if epoch_interval_s is None else epoch_interval_s)
    if not max_gap > 0 or not epoch_dt > 0:
        raise ConfigError(
            f"[dead_reckoning] max_gap_s ({max_gap}) and epoch_interval_s ({epoch_dt}) "
            "must be positive"
        )

    t = np.asarray(time_s, float)
    n = t.size
    hdg = np.asarray(heading_rad, float)
    spd = np.asarray(speed_mps, float)
    if hdg.shape != (n,) or spd.shape != (n,):
        raise ValueError("time_s, heading_rad and speed_mps must be 1-D of equal length")
    if n == 0 or not np.any(np.isfinite(hdg)):
        raise InsufficientDataError(
            "dead reckoning needs a heading: the log has no heading values at all "
            "(it will not assume north)"
        )
    if not np.any(np.isfinite(spd)):
        raise InsufficientDataError("dead reckoning needs a speed: the log has no speed values")
    if np.any(np.diff(t) <= 0) or not np.all(np.isfinite(t)):
        raise ValueError("time_s must be finite and strictly increasing")

    vy = None if transverse_mps is None else np.asarray(transverse_mps, float)
    heading_ok = np.isfinite(hdg)
    speed_ok = np.isfinite(spd) if vy is None else np.isfinite(spd) & np.isfinite(vy)
    n_invalid = int(n - np.sum(heading_ok & speed_ok))

    # --- gaps: each channel holds its last valid value up to max_gap_s, breaks beyond ----
    gaps: list[Gap] = []
    step_ok = np.ones(n - 1, dtype=bool)
    held = []
    for channel, ok in (("heading", heading_ok), ("speed", speed_ok)):
        src, ok_steps, ch_gaps = _hold_channel(t, ok, max_gap, channel)
        step_ok &= ok_steps
        held.append(src)
        gaps.extend(ch_gaps)
    gaps.sort(key=lambda g: (g.start_s, g.channel))
    src_h, src_v = held
    if vy is not None:
        # (B1) speed and (B5)/(B6) leeway angle from the log's two components
        speed_f = speed_from_components_mps(spd[src_v], vy[src_v])  # (B1)
        course_f = wrap_2pi(
            hdg[src_h] + leeway_from_log_rad(spd[src_v], vy[src_v])
        )  # (B2)/(B3) + z
    else:
        speed_f = spd[src_v]
        course_f = wrap_2pi(hdg[src_h])
    valid = heading_ok & speed_ok
    next_valid = np.minimum.accumulate(np.where(valid, np.arange(n), n)[::-1])[::-1]

    # --- velocities over ground ---------------------------------------------------------
    if mode == "water":
        if current_ne_mps is not None:
            cur = np.broadcast_to(np.asarray(current_ne_mps, float), (n, 2))
            c_speed = np.hypot(cur[:, 0], cur[:, 1])
            c_set = np.arctan2(cur[:, 1], cur[:, 0])
        else:
            c_speed, c_set = 0.0, 0.0
        vn, ve = velocity_water_ne_mps(speed_f, course_f, c_speed, c_set)  # (B7)-(B12)
    else:
        vn, ve = velocity_ground_ne_mps(speed_f, course_f)  # (B13), (B14)

    # --- legs ---------------------------------------------------------------------------
    fx = _as_fixes(fixes, cfg.fix_sigma_m)
    sigma0 = float(cfg.fix_sigma_m if sigma0_m is None else sigma0_m)
    bad_steps = np.flatnonzero(~step_ok)  # a bad step k breaks between samples k and k+1

    lat = np.full(n, np.nan)
    lon = np.full(n, np.nan)
    P = np.full((n, 2, 2), np.nan)
    since = np.full(n, np.nan)
    leg_of = np.full(n, -1, dtype=np.int64)
    leg_starts: list[float] = []
    reasons: list[str] = []
    processes = error_processes(cfg, mode)

    def fix_start(k_from: int, t_min: float):
        """First fix at time >= t_min whose sample (first t_j >= t_fix) is >= k_from."""
        if fx is None:
            return None
        i = int(np.searchsorted(fx[0], t_min, side="left"))
        while i < fx[0].size:
            j = int(np.searchsorted(t, fx[0][i], side="left"))
            if j >= n:
                return None
            usable = step_ok[j] if j < n - 1 else valid[j]
            if j >= k_from and usable:
                return i, j
            i += 1
        return None

    def start_state(i_fix: int, j: int):
        ft, flat, flon, fs = fx[0][i_fix], fx[1][i_fix], fx[2][i_fix], fx[3][i_fix]
        lead = t[j] - ft  # advance the fix to the sample by the velocity held then
        kv = j - 1 if j > 0 else j
        la, lo = integrate_ne(
            np.array([0.0, lead]), np.full(2, vn[kv]), np.full(2, ve[kv]), flat, flon
        )
        return float(la[-1]), float(lo[-1]), float(fs)

    if lat0_rad is not None and lon0_rad is not None:
        k0 = 0
        s_lat, s_lon, s_sig = float(lat0_rad), float(lon0_rad), sigma0
        reason = "start"
    else:
        first = fix_start(0, -np.inf)
        if first is None:
            raise InsufficientDataError(
                "dead reckoning needs a start position: give lat0/lon0 or fixes within the log's time span"
            )
        k0 = first[1]
        s_lat, s_lon, s_sig = start_state(*first)
        reason = "start"

    k_start: int | None = k0
    while k_start is not None and k_start < n:
        # leg end: first bad step at or after k_start, and the next reset fix
        b = int(np.searchsorted(bad_steps, k_start, side="left"))
        k_break = int(bad_steps[b]) if b < bad_steps.size else n - 1  # last sample of the leg
        k_end = k_break
        nxt = None
        if math.isfinite(reset):
            nxt = fix_start(k_start + 1, t[k_start] + reset)
            if nxt is not None and nxt[1] <= k_break:
                k_end = nxt[1]  # the new leg starts at this sample
            else:
                nxt = None
        leg_id = len(leg_starts)
        leg_starts.append(float(t[k_start]))
        reasons.append(reason)
        sl = slice(k_start, k_end + 1)
        la, lo = integrate_ne(t[sl], vn[sl], ve[sl], s_lat, s_lon)
        if covariance:
            Pl = honest_covariance_m2(
                t[sl],
                speed_f[sl],
                course_f[sl],
                processes,
                P0_m2=s_sig**2 * np.eye(2),
                step_s=covariance_step_s,
            )
        else:
            Pl = np.full((k_end + 1 - k_start, 2, 2), np.nan)
        last = k_end + 1 if nxt is None else k_end  # the reset sample belongs to the new leg
        m = last - k_start
        lat[k_start:last] = la[:m]
        lon[k_start:last] = lo[:m]
        P[k_start:last] = Pl[:m]
        since[k_start:last] = t[k_start:last] - t[k_start]
        leg_of[k_start:last] = leg_id
        if nxt is not None:
            s_lat, s_lon, s_sig = start_state(*nxt)
            k_start, reason = nxt[1], "reset"
            continue
        if k_break >= n - 1:
            break
        # a break: restart at the first fix after the data resume
        resume = int(next_valid[k_break + 1]) if k_break + 1 < n else n
        if resume >= n:
            break
        nxt = fix_start(resume, t[resume])
        if nxt is None:
            break
        s_lat, s_lon, s_sig = start_state(*nxt)
        k_start, reason = nxt[1], "after-gap"

    trace = P[:, 0, 0] + P[:, 1, 1]
    radius = 2.0 * np.sqrt(trace)  # (B30), (B31): 2M = 2 sqrt(tr P), P in metres
    smaj, smin, orient = error_ellipse(np.nan_to_num(P))
    nan = ~np.isfinite(trace)
    smaj, smin, orient = (np.where(nan, np.nan, x) for x in (smaj, smin, orient))

    # epochs: the first sample at or after each multiple of epoch_interval_s
    grid = np.arange(math.ceil(t[0] / epoch_dt) * epoch_dt, t[-1] + 1e-9, epoch_dt)
    ei = np.searchsorted(t, grid, side="left")
    inside = ei < n
    ei, grid = ei[inside], grid[inside]
    ei = unique_sorted(ei[(t[ei] - grid <= max_gap) & np.isfinite(lat[ei])])
    return DRTrack(
        time_s=t,
        lat_rad=lat,
        lon_rad=lon,
        vn_mps=np.where(leg_of >= 0, vn, np.nan),
        ve_mps=np.where(leg_of >= 0, ve, np.nan),
        P_m2=P,
        radius_2m_m=radius,
        semi_major_m=smaj,
        semi_minor_m=smin,
        orientation_rad=orient,
        since_fix_s=since,
        leg=leg_of,
        leg_start_s=np.asarray(leg_starts),
        leg_start_reason=tuple(reasons),
        epoch_index=ei,
        gaps=tuple(gaps),
        mode=mode,
        reset_s=reset,
        n_invalid_samples=n_invalid,
    )


# --------------------------------------------------------------------------------------
# Consistency against a reference
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LegConsistency:
    """Containment of the reference in the 2M circle over the epochs of one DR leg."""

    leg: int
    start_s: float
    n_epochs: int
    n_inside: int
    inside_fraction: float
    rms_error_over_m: float  #: sqrt(mean (d/M)^2); 1 when the covariance is right
    max_error_m: float
    mean_nees: float = math.nan  #: mean over the leg's epochs of d^T P^-1 d (2 expected)
    last_nees: float = math.nan  #: at the leg's last epoch: one chi^2_2 draw per leg
    nees_upper: float = math.nan  #: chi^2_2 quantile 1 - alpha: a leg above it misses


@dataclass(frozen=True)
class Consistency:
    """DR against a reference, per epoch (after a fix, not at it), per leg and overall.

    Per epoch: error d (DR minus reference, metres north/east), 2M, inside (d <= 2M),
    d/M, NEES = d^T P^-1 d (expected 2), and the probability that a correct Gaussian
    error lies inside 2M for that ellipse shape (0.954-0.982).  Verdict: see
    :func:`dr_consistency`.
    """

    time_s: np.ndarray
    leg: np.ndarray
    error_north_m: np.ndarray
    error_east_m: np.ndarray
    error_m: np.ndarray
    radius_2m_m: np.ndarray
    inside: np.ndarray
    error_over_m: np.ndarray
    nees: np.ndarray
    p_inside_expected: np.ndarray
    legs: tuple[LegConsistency, ...]
    n_epochs: int
    n_inside: int
    inside_fraction: float
    expected_inside_fraction: float
    rms_error_over_m: float
    mean_nees: float
    n_legs: int  #: legs with at least one epoch: the independent trials of the tests
    p_value_too_small: float  #: binomial P(K <= k) under the lowest expected containment
    chi2_statistic: float  #: mean over legs of the leg's mean (d/M)^2
    chi2_upper: float  #: inconsistent above this
    chi2_lower: float  #: conservative below this (with every epoch inside)
    alpha: float
    verdict: str  #: 'consistent', 'inconsistent (circle too small)', 'conservative', 'undetermined'
    nees_statistic: float = math.nan  #: sum over legs of the last epoch's NEES ~ chi^2(2 n_legs)
    nees_lower: float = math.nan  #: chi^2_{alpha/2}(2 n_legs)
    nees_upper: float = math.nan  #: chi^2_{1-alpha/2}(2 n_legs)
    reference_sigma_m: float = 0.0  #: the reference's own noise, added to P for the test


def dr_consistency(
    track: DRTrack,
    ref_time_s,
    ref_lat_rad,
    ref_lon_rad,
    *,
    max_ref_gap_s: float = 5.0,
    alpha: float = 0.01,
    ref_sigma_m: float = 0.0,
) -> Consistency:
    """Does the reference (GNSS, INS mean) lie inside the DR's 2M circle as often as it should?

    Epochs are the track's ``epoch_index`` where time since the fix is > 0 (at the fix
    the DR *is* the fix); the reference is interpolated linearly between samples at most
    ``max_ref_gap_s`` apart.

    The binomial reasoning.  For a correct Gaussian error, 2M (2 drms) contains it with
    probability p between 0.954 (degenerate ellipse) and 0.982 (circle), see
    :func:`prob_inside_2m`.  Epochs of one leg share the same sensor-error realisation
    and are strongly correlated, so each leg (not each epoch) is one trial: n = number of
    legs with epochs, k = round(sum of the legs' inside fractions).  The DR is
    "inconsistent (circle too small)" when P(K <= k | n, p_min) < alpha (one-sided
    binomial, p_min the lowest expected containment over the epochs), or when the mean
    over legs of mean (d/M)^2 -- expected 1, as E|d|^2 = tr P = M^2 -- exceeds
    chi2_{1-alpha}(n)/n (the widest case, a line-shaped ellipse: (d/M)^2 ~ chi2_1), or when
    the sum over legs of the NEES at each leg's last epoch (chi^2 with 2 n degrees of
    freedom) exceeds its two-sided 1 - alpha/2 quantile.
    It is "conservative" when every epoch is inside and that mean, or the NEES sum, is
    below its lower quantile (the circle much larger than the errors).  ``ref_sigma_m``:
    the reference's own noise per axis, added to P where DR and reference are compared.  Otherwise "consistent";
    "undetermined" when no epoch has a reference.
    """
    ei = np.asarray(track.epoch_index, dtype=np.int64)
    ei = ei[track.since_fix_s[ei] > 0]
    t_e = track.time_s[ei]
    rlat, rlon = interp_position(
        np.asarray(ref_time_s, float), ref_lat_rad, ref_lon_rad, t_e, max_ref_gap_s
    )
    has = np.isfinite(rlat)
    ei, t_e, rlat, rlon = ei[has], t_e[has], rlat[has], rlon[has]
    dn, de = offset_ne_m(track.lat_rad[ei], track.lon_rad[ei], rlat, rlon)
    d = np.hypot(dn, de)
    P = track.P_m2[ei] + float(ref_sigma_m) ** 2 * np.eye(2)
    m_err = np.sqrt(P[:, 0, 0] + P[:, 1, 1])  # (B30) in metres
    radius = 2.0 * m_err  # (B31)
    inside = d <= radius
    ratio = d / m_err
    det = P[:, 0, 0] * P[:, 1, 1] - P[:, 0, 1] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        nees = (P[:, 1, 1] * dn**2 - 2 * P[:, 0, 1] * dn * de + P[:, 0, 0] * de**2) / det
    p_exp = prob_inside_2m(P) if ei.size else np.zeros(0)
    legs_e = track.leg[ei]

    legs: list[LegConsistency] = []
    nees_leg_hi = float(dist.chi2_ppf(1 - alpha, 2))
    for leg_id in np.unique(legs_e):
        sel = legs_e == leg_id
        k = int(inside[sel].sum())
        legs.append(
            LegConsistency(
                leg=int(leg_id),
                start_s=float(track.leg_start_s[leg_id]),
                n_epochs=int(sel.sum()),
                n_inside=k,
                inside_fraction=k / int(sel.sum()),
                rms_error_over_m=float(np.sqrt(np.mean(ratio[sel] ** 2))),
                max_error_m=float(d[sel].max()),
                mean_nees=float(np.mean(nees[sel])),
                last_nees=float(nees[sel][-1]),
                nees_upper=nees_leg_hi,
            )
        )
    n_legs = len(legs)
    if n_legs == 0:
        nan = float("nan")
        verdict, p_small, q, q_hi, q_lo = "undetermined", nan, nan, nan, nan
        nees_sum, nees_lo, nees_hi = nan, nan, nan
    else:
        nees_sum = float(sum(leg.last_nees for leg in legs))
        nees_lo = float(dist.chi2_ppf(alpha / 2, 2 * n_legs))
        nees_hi = float(dist.chi2_ppf(1 - alpha / 2, 2 * n_legs))
        k_eff = int(round(sum(leg.inside_fraction for leg in legs)))
        p_small = float(dist.binom_cdf(k_eff, n_legs, float(p_exp.min())))
        q = float(np.mean([leg.rms_error_over_m**2 for leg in legs]))
        q_hi = float(dist.chi2_ppf(1 - alpha, n_legs) / n_legs)
        q_lo = float(dist.chi2_ppf(alpha, n_legs) / n_legs)
        if p_small < alpha or q > q_hi or nees_sum > nees_hi:
            verdict = "inconsistent (circle too small)"
        elif bool(inside.all()) and (q < q_lo or nees_sum < nees_lo):
            verdict = "conservative"
        else:
            verdict = "consistent"
    n_ep = int(ei.size)
    return Consistency(
        time_s=t_e,
        leg=legs_e,
        error_north_m=dn,
        error_east_m=de,
        error_m=d,
        radius_2m_m=radius,
        inside=inside,
        error_over_m=ratio,
        nees=nees,
        p_inside_expected=p_exp,
        legs=tuple(legs),
        n_epochs=n_ep,
        n_inside=int(inside.sum()),
        inside_fraction=float(inside.mean()) if n_ep else float("nan"),
        expected_inside_fraction=float(p_exp.mean()) if n_ep else float("nan"),
        rms_error_over_m=float(np.sqrt(np.mean(ratio**2))) if n_ep else float("nan"),
        mean_nees=float(np.mean(nees)) if n_ep else float("nan"),
        n_legs=n_legs,
        p_value_too_small=p_small,
        chi2_statistic=q,
        chi2_upper=q_hi,
        chi2_lower=q_lo,
        alpha=alpha,
        verdict=verdict,
        nees_statistic=nees_sum,
        nees_lower=nees_lo,
        nees_upper=nees_hi,
        reference_sigma_m=float(ref_sigma_m),
    )
