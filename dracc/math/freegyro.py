"""The free-gyro positioning and directional system and its errors (seeds/002, Jeong).

Pure numpy, radians, seconds.  Equation numbers are the paper's; docs/free-gyro.md names
every one and every departure.  Glossary (the paper's symbols):

``u``        gyro vector g^i, the spin-axis unit vector in the inertial frame (x towards
             Greenwich at t = 0, z towards the north pole)
``L``        lambda + omega_e t, the longitude in the inertial frame
``theta``    nadir angle of a gyro vector (1); ``alpha`` its azimuth from north (2), (5)
``psi``      ship's heading (4); ``zeta`` azimuth of the gyro vector from the ship's head (5)
``C_g_b``    gyro -> body frame (8); ``C_b_n`` body -> navigation (NED) frame
``xi``       gyro-frame attitude error (8), (19); ``gamma`` body-frame attitude error (20), (21)
``omega_L``  motion rate of the spin axis in the navigation frame, C_b^n C_g^b omega_ig^g (22)
``omega_N``  spin motion rate in the NED frame used for the heading (27)-(28)

Misprints corrected (METHODS §7 and docs/free-gyro.md): the third component of
delta omega_in^n below (21) has the wrong sign; (29) lacks the minus sign of (4); (37)
squares the cofactors (dimensionally unsound; reported as printed beside the trace form);
(34) assumes one sigma for both rows Z although Var Z = sin^2(theta) sigma_theta^2.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np

from dracc.core.arrays import ArrayLike, FloatArray
from dracc.core.errors import GeometryError
from dracc.core.geodesy import radius_meridian_m, radius_prime_vertical_m, wrap_2pi
from dracc.math.fusion import OMEGA_E_RADPS

# ------------------------------------------------------------ (1)-(7): the system


def _inertial_frame(lat_rad: ArrayLike, lon_rad: ArrayLike, t_s: ArrayLike) -> FloatArray:
    """(3, 3, ...) rows: the local vertical n (up), north and east in the inertial frame."""
    lat = np.asarray(lat_rad, float)
    big_l = np.asarray(lon_rad, float) + OMEGA_E_RADPS * np.asarray(t_s, float)
    cl, sl, cp, sp = np.cos(big_l), np.sin(big_l), np.cos(lat), np.sin(lat)
    up = np.stack([cp * cl, cp * sl, sp * np.ones_like(cl)])
    north = np.stack([-sp * cl, -sp * sl, cp * np.ones_like(cl)])
    east = np.stack([-sl, cl, np.zeros_like(cl)])
    return np.stack([up, north, east])


def cos_nadir(u: ArrayLike, lat_rad: ArrayLike, lon_rad: ArrayLike, t_s: ArrayLike) -> FloatArray:
    """(1): cos(theta) = -u_x cos(phi) cos(L) - u_y cos(phi) sin(L) - u_z sin(phi).

    ``u`` (..., 3); the rest broadcast against its leading axes.
    """
    up = _inertial_frame(lat_rad, lon_rad, t_s)[0]
    return cast(FloatArray, -np.einsum("...i,i...->...", np.asarray(u, float), up))  # (1)


def nadir_rad(u: ArrayLike, lat_rad: ArrayLike, lon_rad: ArrayLike, t_s: ArrayLike) -> FloatArray:
    """The nadir angle theta of (1), in [0, pi]."""
    return cast(FloatArray, np.arccos(np.clip(cos_nadir(u, lat_rad, lon_rad, t_s), -1.0, 1.0)))


def gyro_azimuth_rad(
    u: ArrayLike, lat_rad: ArrayLike, lon_rad: ArrayLike, t_s: ArrayLike
) -> FloatArray:
    """(2): tan(alpha) = E_D / N_D, the azimuth of the gyro vector from north, [0, 2 pi).

    N_D = -u_x sin(phi) cos(L) - u_y sin(phi) sin(L) + u_z cos(phi) and
    E_D = -u_x sin(L) + u_y cos(L) are u's north and east components; the quadrant is
    taken from their signs (atan2; the paper writes tan).
    """
    frame = _inertial_frame(lat_rad, lon_rad, t_s)
    uu = np.asarray(u, float)
    n_d = np.einsum("...i,i...->...", uu, frame[1])  # (2) N_D
    e_d = np.einsum("...i,i...->...", uu, frame[2])  # (2) E_D
    return cast(FloatArray, wrap_2pi(np.arctan2(e_d, n_d)))


def spin_rates_radps(lat_rad: ArrayLike, heading_rad: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """(3): omega_Nx = omega_e cos(phi) cos(psi), omega_Ny = -omega_e cos(phi) sin(psi)."""
    h = OMEGA_E_RADPS * np.cos(np.asarray(lat_rad, float))
    psi = np.asarray(heading_rad, float)
    return h * np.cos(psi), -h * np.sin(psi)  # (3)


def heading_from_spin_rates_rad(omega_nx_radps: ArrayLike, omega_ny_radps: ArrayLike) -> FloatArray:
    """(4): psi = -atan(omega_Ny / omega_Nx), the quadrant from both signs, [0, 2 pi)."""
    return wrap_2pi(-np.arctan2(omega_ny_radps, omega_nx_radps))  # (4)


def azimuth_from_heading_rad(heading_rad: ArrayLike, zeta_rad: ArrayLike) -> FloatArray:
    """(5): alpha = psi + zeta, [0, 2 pi)."""
    return cast(FloatArray, wrap_2pi(np.asarray(heading_rad, float) + np.asarray(zeta_rad, float)))


def tilt_rate_radps(lat_rad: ArrayLike, alpha_rad: ArrayLike) -> FloatArray:
    """(6): omega_H = -omega_e cos(phi) sin(alpha); (7) integrates it to the nadir angle."""
    lat, alpha = np.asarray(lat_rad, float), np.asarray(alpha_rad, float)
    return cast(FloatArray, -OMEGA_E_RADPS * np.cos(lat) * np.sin(alpha))  # (6)


# ------------------------------------------------------- (8)-(21): attitude errors


def skew(v: ArrayLike) -> FloatArray:
    """The skew-symmetric matrix of v: Xi of xi (8), Gamma of gamma (21); skew(a) b = a x b."""
    x, y, z = np.asarray(v, float)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def _frame_error_rate(
    err: ArrayLike, omega: ArrayLike, dcm: ArrayLike, d_inner: ArrayLike, d_own: ArrayLike
) -> FloatArray:
    """The common form of (19) and (20): e' = -omega x e - C d_inner + d_own."""
    w, e = np.asarray(omega, float), np.asarray(err, float)
    d_in, d_ow = np.asarray(d_inner, float), np.asarray(d_own, float)
    return cast(FloatArray, -np.cross(w, e) - np.asarray(dcm, float) @ d_in + d_ow)


def gyro_attitude_error_rate(
    xi: ArrayLike,
    omega_ib_b: ArrayLike,
    c_g_b: ArrayLike,
    d_omega_ig_g: ArrayLike,
    d_omega_ib_b: ArrayLike,
) -> FloatArray:
    """(19): xi' = -omega_ib^b x xi - C_g^b d omega_ig^g + d omega_ib^b (from (15)-(18))."""
    return _frame_error_rate(xi, omega_ib_b, c_g_b, d_omega_ig_g, d_omega_ib_b)  # (19)


def body_attitude_error_rate(
    gamma: ArrayLike,
    omega_in_n: ArrayLike,
    c_b_n: ArrayLike,
    d_omega_ib_b: ArrayLike,
    d_omega_in_n: ArrayLike,
) -> FloatArray:
    """(20): gamma' = -omega_in^n x gamma - C_b^n d omega_ib^b + d omega_in^n."""
    return _frame_error_rate(gamma, omega_in_n, c_b_n, d_omega_ib_b, d_omega_in_n)  # (20)


def nav_rate_error_radps(
    lat_rad: float,
    lon_rate_radps: float,
    d_lat_rad: float,
    d_lat_rate_radps: float,
    d_lon_rate_radps: float,
) -> FloatArray:
    """The error of omega_in^n = [(lam' + w) cos phi, -phi', -(lam' + w) sin phi] (below (21)).

    Corrected: the paper prints the third component as ``+ d lam' sin phi``; perturbing
    -(lam' + w) sin phi gives ``- d lam' sin phi - (lam' + w) cos phi d phi``.
    """
    s, c, rate = np.sin(lat_rad), np.cos(lat_rad), lon_rate_radps + OMEGA_E_RADPS
    return np.array(
        [
            d_lon_rate_radps * c - rate * d_lat_rad * s,
            -d_lat_rate_radps,
            -d_lon_rate_radps * s - rate * d_lat_rad * c,  # sign corrected
        ]
    )


# ------------------------------------------ (22)-(29): nadir-angle and heading errors


def spin_rate_error_nav(
    gamma: ArrayLike,
    xi: ArrayLike,
    c_b_n: ArrayLike,
    c_g_b: ArrayLike,
    omega_ig_g: ArrayLike,
    d_omega_ig_g: ArrayLike,
) -> FloatArray:
    """(22): d omega_L = -(Gamma C_b^n + C_b^n Xi) C_g^b omega_ig^g + C_b^n C_g^b d omega_ig^g."""
    cbn, cgb = np.asarray(c_b_n, float), np.asarray(c_g_b, float)
    v = cgb @ np.asarray(omega_ig_g, float)
    return cast(
        FloatArray,
        -(skew(gamma) @ cbn + cbn @ skew(xi)) @ v + cbn @ cgb @ np.asarray(d_omega_ig_g, float),
    )


def horizontal_rate_error(omega_l: ArrayLike, d_omega_l: ArrayLike) -> float:
    """(24): d omega_LH = (w_Lx d w_Lx + w_Ly d w_Ly) / sqrt(w_Lx^2 + w_Ly^2)."""
    w, dw = np.asarray(omega_l, float), np.asarray(d_omega_l, float)
    return float((w[0] * dw[0] + w[1] * dw[1]) / np.hypot(w[0], w[1]))


def tilt_rate_error(
    d_omega_lh: float, omega_lh: float, alpha_rad: float, d_alpha_rad: float
) -> float:
    """(25): d omega_H = -d omega_LH sin(alpha) - omega_LH cos(alpha) d alpha.

    (The paper's stars are multiplication signs lost in print.)  (26) integrates it to
    d theta, as (23) integrates d omega_Lz to d zeta; :func:`nadir_error_budget` does both.
    """
    return float(-d_omega_lh * np.sin(alpha_rad) - omega_lh * np.cos(alpha_rad) * d_alpha_rad)


def body_spin_rate_error(
    xi: ArrayLike,
    gamma: ArrayLike,
    c_g_b: ArrayLike,
    c_b_n: ArrayLike,
    omega_ig_g: ArrayLike,
    omega_en_n: ArrayLike,
    d_omega_ig_g: ArrayLike,
    d_omega_en_n: ArrayLike,
) -> FloatArray:
    """(27): d omega_D = -Xi C_g^b w_ig^g + C_g^b d w_ig^g - C_n^b (Gamma w_en^n + d w_en^n)."""
    cgb, cnb = np.asarray(c_g_b, float), np.asarray(c_b_n, float).T
    return cast(
        FloatArray,
        -skew(xi) @ cgb @ np.asarray(omega_ig_g, float)
        + cgb @ np.asarray(d_omega_ig_g, float)
        - cnb @ (skew(gamma) @ np.asarray(omega_en_n, float) + np.asarray(d_omega_en_n, float)),
    )


def nav_spin_rate_error(
    gamma: ArrayLike, c_b_n: ArrayLike, omega_d: ArrayLike, d_omega_d: ArrayLike
) -> FloatArray:
    """(28): d omega_N = -Gamma C_b^n omega_D + C_b^n d omega_D.

    With d omega_D from (27) this is the paper's (28) term by term (C_b^n C_n^b = I).
    """
    cbn = np.asarray(c_b_n, float)
    return cast(FloatArray, -skew(gamma) @ cbn @ np.asarray(omega_d, float) + cbn @ d_omega_d)


def heading_error_rad(omega_n: ArrayLike, d_omega_n: ArrayLike) -> FloatArray:
    """(29), sign corrected: d psi = -(w_Nx d w_Ny - w_Ny d w_Nx) / (w_Nx^2 sec^2 psi).

    The paper drops the minus sign of (4) (psi = -atan(w_Ny / w_Nx)); with (3),
    w_Nx^2 sec^2 psi = w_Nx^2 + w_Ny^2.  ``omega_n`` and ``d_omega_n`` (..., >= 2).
    """
    w, dw = np.asarray(omega_n, float), np.asarray(d_omega_n, float)
    num = w[..., 0] * dw[..., 1] - w[..., 1] * dw[..., 0]
    return cast(FloatArray, -num / (w[..., 0] ** 2 + w[..., 1] ** 2))  # (29) corrected


# ------------------------------------------------ the linear error model of the rates


@dataclass(frozen=True)
class FreeGyro:
    """One free gyro's nominal state over the integration interval (held constant).

    ``c_g_b`` (3, 3) gyro -> body; ``omega_ig_g_radps`` (3,) the spin motion rate in the
    gyro frame; ``alpha_rad`` the azimuth of its gyro vector from north (5).
    """

    c_g_b: FloatArray
    omega_ig_g_radps: FloatArray
    alpha_rad: float


@dataclass(frozen=True)
class Platform:
    """The ship's nominal rates and attitude: ``c_b_n`` body -> NED, ``omega_ib_b_radps``
    the body rate sensed, ``omega_in_n_radps`` and ``omega_en_n_radps`` (below (21))."""

    c_b_n: FloatArray
    omega_ib_b_radps: FloatArray
    omega_in_n_radps: FloatArray
    omega_en_n_radps: FloatArray


@dataclass(frozen=True)
class RateSensorErrors:
    """Sigmas of the rate-sensor errors, the same on each axis.

    Biases (rad/s, constant over the interval), white noise as angle random walk
    (rad/sqrt(s), the square root of the rate noise's power spectral density), and the
    initial attitude errors xi, gamma (rad per axis) from the alignment.
    """

    spin_bias_radps: float = 0.0
    spin_noise_rad_rts: float = 0.0
    body_bias_radps: float = 0.0
    body_noise_rad_rts: float = 0.0
    attitude0_rad: float = 0.0


def _state_rate(
    x: FloatArray, w: FloatArray, gyros: tuple[FreeGyro, ...], p: Platform
) -> tuple[FloatArray, FloatArray]:
    """(x', d psi per gyro) of the linear error model: x = [gamma, (xi, d zeta, d theta) per
    gyro], w = [d omega_ib^b, d omega_ig^g per gyro]; (19)-(29) with d omega_in^n = d
    omega_en^n = 0 (the position-rate errors' feedback is left out over the interval)."""
    zero = np.zeros(3)
    gamma, d_wib = x[:3], w[:3]
    out = [body_attitude_error_rate(gamma, p.omega_in_n_radps, p.c_b_n, d_wib, zero)]  # (20)
    d_psi = []
    for k, g in enumerate(gyros):
        xi, d_zeta = x[3 + 5 * k : 6 + 5 * k], x[6 + 5 * k]
        d_wig = w[3 + 3 * k : 6 + 3 * k]
        out.append(gyro_attitude_error_rate(xi, p.omega_ib_b_radps, g.c_g_b, d_wig, d_wib))  # (19)
        omega_l = p.c_b_n @ g.c_g_b @ g.omega_ig_g_radps
        d_wl = spin_rate_error_nav(gamma, xi, p.c_b_n, g.c_g_b, g.omega_ig_g_radps, d_wig)  # (22)
        omega_d = g.c_g_b @ g.omega_ig_g_radps - p.c_b_n.T @ p.omega_en_n_radps
        d_wd = body_spin_rate_error(
            xi, gamma, g.c_g_b, p.c_b_n, g.omega_ig_g_radps, p.omega_en_n_radps, d_wig, zero
        )  # (27)
        d_wn = nav_spin_rate_error(gamma, p.c_b_n, omega_d, d_wd)  # (28)
        omega_n = p.c_b_n @ omega_d
        dpsi = float(heading_error_rad(omega_n, d_wn))  # (29)
        d_alpha = d_zeta + dpsi  # (23)
        d_wlh = horizontal_rate_error(omega_l, d_wl)  # (24)
        d_wh = tilt_rate_error(d_wlh, float(np.hypot(*omega_l[:2])), g.alpha_rad, d_alpha)  # (25)
        out.append(np.array([d_wl[2], d_wh]))  # (23) d zeta', (26) d theta'
        d_psi.append(dpsi)
    return np.concatenate(out), np.array(d_psi)


def expm(a: ArrayLike) -> FloatArray:
    """Matrix exponential by scaling and squaring of a 24-term Taylor series (small matrices)."""
    a = np.asarray(a, float)
    norm = float(np.max(np.sum(np.abs(a), axis=1)))
    squarings = max(0, int(np.ceil(np.log2(norm / 0.25)))) if norm > 0.25 else 0
    b = a / 2.0**squarings
    term, result = np.eye(len(a)), np.eye(len(a))
    for k in range(1, 25):
        term = term @ b / k
        result = result + term
    for _ in range(squarings):
        result = result @ result
    return result


@dataclass(frozen=True)
class NadirErrorBudget:
    """The nadir-angle errors after ``interval_s`` of integration ((26)).

    ``cov_theta_rad2`` (K, K): all inputs; ``bias_cov_rad2``, ``noise_cov_rad2``,
    ``attitude_cov_rad2`` its parts; ``heading_sigma_rad`` (K,): (29) per gyro at the end
    of the interval from the biases and the initial attitude (white noise has no finite
    instantaneous heading error); ``f``, ``g``: the model x' = F x + G w.
    """

    cov_theta_rad2: FloatArray
    bias_cov_rad2: FloatArray
    noise_cov_rad2: FloatArray
    attitude_cov_rad2: FloatArray
    heading_sigma_rad: FloatArray
    f: FloatArray
    g: FloatArray
    interval_s: float


def error_model_matrices(
    gyros: tuple[FreeGyro, ...], platform: Platform
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """(F, G, H_x, H_w): x' = F x + G w and d psi = H_x x + H_w w, columns of the linear
    map (19)-(29) taken on unit vectors (exact: the map is linear)."""
    n, m = 3 + 5 * len(gyros), 3 + 3 * len(gyros)
    cols_x = [_state_rate(e, np.zeros(m), gyros, platform) for e in np.eye(n)]
    cols_w = [_state_rate(np.zeros(n), e, gyros, platform) for e in np.eye(m)]
    f = np.stack([c[0] for c in cols_x], axis=1)
    g = np.stack([c[0] for c in cols_w], axis=1)
    h_x = np.stack([c[1] for c in cols_x], axis=1)
    h_w = np.stack([c[1] for c in cols_w], axis=1)
    return f, g, h_x, h_w


def nadir_error_budget(
    gyros: tuple[FreeGyro, ...],
    platform: Platform,
    errors: RateSensorErrors,
    interval_s: float,
) -> NadirErrorBudget:
    """Nadir-angle covariance from the rate-sensor errors, (19)-(29) integrated over
    ``interval_s`` ((23), (26)) from d zeta = d theta = 0.

    The biases enter through the exponential of [[F, G], [0, 0]], the white noise through
    Van Loan's exponential of [[-F, G Q G^T], [0, F^T]] (the exact discrete covariance
    of an LTI system), the initial attitude errors through exp(F T).
    """
    if not gyros:
        raise GeometryError("nadir_error_budget: no gyros")
    if not interval_s > 0:
        raise GeometryError(f"nadir_error_budget: interval_s must be > 0, got {interval_s!r}")
    f, g, h_x, h_w = error_model_matrices(gyros, platform)
    n, m = g.shape
    k = len(gyros)
    theta = [3 + 5 * i + 4 for i in range(k)]
    t = float(interval_s)
    # biases: x(T) = B b with B = int_0^T exp(F s) ds G
    aug = np.zeros((n + m, n + m))
    aug[:n, :n], aug[:n, n:] = f, g
    e_aug = expm(aug * t)
    phi, b_map = e_aug[:n, :n], e_aug[:n, n:]
    bias_var = np.r_[
        np.full(3, errors.body_bias_radps**2), np.full(3 * k, errors.spin_bias_radps**2)
    ]
    bias_x = b_map * np.sqrt(bias_var)
    # white noise: Van Loan
    q = np.diag(
        np.r_[
            np.full(3, errors.body_noise_rad_rts**2), np.full(3 * k, errors.spin_noise_rad_rts**2)
        ]
    )
    vl = np.zeros((2 * n, 2 * n))
    vl[:n, :n], vl[:n, n:], vl[n:, n:] = -f, g @ q @ g.T, f.T
    e_vl = expm(vl * t)
    phi_vl = e_vl[n:, n:].T
    q_d = phi_vl @ e_vl[:n, n:]
    q_d = 0.5 * (q_d + q_d.T)
    # initial attitude errors gamma, xi (not d zeta, d theta)
    p0 = np.zeros(n)
    p0[:3] = errors.attitude0_rad**2
    for i in range(k):
        p0[3 + 5 * i : 6 + 5 * i] = errors.attitude0_rad**2
    att_x = phi * np.sqrt(p0)
    sel = np.ix_(theta, theta)
    bias_cov = (bias_x @ bias_x.T)[sel]
    att_cov = (att_x @ att_x.T)[sel]
    noise_cov = q_d[sel]
    psi_b = h_x @ bias_x + h_w * np.sqrt(bias_var)
    psi_a = h_x @ att_x
    heading_var = np.sum(psi_b**2, axis=1) + np.sum(psi_a**2, axis=1)
    return NadirErrorBudget(
        bias_cov + noise_cov + att_cov,
        bias_cov,
        noise_cov,
        att_cov,
        np.sqrt(heading_var),
        f,
        g,
        t,
    )


# ---------------------------------------------- (30)-(36): the position error equations


@dataclass(frozen=True)
class PositionRows:
    """The rows of (31) at a position, one per gyro vector (K of them).

    ``psi`` (K, 2): [Phi, M], d cos(theta) / d(phi, lambda) (per radian); the
    coefficients of Z: ``z_u`` (K, 3) of d u (the vertical n), ``z_theta`` (K,)
    = -sin(theta) of d theta, ``z_t`` (K,) = cos(phi) [u_y cos L - u_x sin L] omega_e of d t.
    """

    psi: FloatArray
    z_u: FloatArray
    z_theta: FloatArray
    z_t: FloatArray
    theta_rad: FloatArray


def position_rows(u: ArrayLike, lat_rad: float, lon_rad: float, t_s: ArrayLike) -> PositionRows:
    """(30)-(31) for gyro vectors ``u`` (K, 3) at times ``t_s`` (K,) or one time."""
    uu = np.atleast_2d(np.asarray(u, float))
    t = np.broadcast_to(np.asarray(t_s, float), uu.shape[:1])
    big_l = lon_rad + OMEGA_E_RADPS * t
    cl, sl, cp, sp = np.cos(big_l), np.sin(big_l), np.cos(lat_rad), np.sin(lat_rad)
    ux, uy, uz = uu[:, 0], uu[:, 1], uu[:, 2]
    phi_row = ux * sp * cl + uy * sp * sl - uz * cp  # (31) Phi
    m_row = ux * cp * sl - uy * cp * cl  # (31) M
    z_u = np.stack([cp * cl, cp * sl, np.full_like(cl, sp)], axis=-1)  # (30) d u terms
    theta = nadir_rad(uu, lat_rad, lon_rad, t)
    z_t = cp * (uy * cl - ux * sl) * OMEGA_E_RADPS  # (30) d t term
    return PositionRows(np.stack([phi_row, m_row], axis=-1), z_u, -np.sin(theta), z_t, theta)


def z_covariance(
    rows: PositionRows, cov_theta_rad2: ArrayLike, sigma_u_rad: ArrayLike, sigma_t_s: float
) -> FloatArray:
    """cov(Delta Z) from the inputs of (30): d theta (K, K covariance), d u a small rotation of
    each gyro vector (sigma per axis, so cov d u = sigma^2 (I - u u^T)), and one clock
    error d t common to all rows (the paper's single t).  Replaces (34)."""
    k = len(rows.z_theta)
    s_u = np.broadcast_to(np.asarray(sigma_u_rad, float), (k,))
    cov = rows.z_theta[:, None] * np.asarray(cov_theta_rad2, float) * rows.z_theta[None, :]
    cos_t = np.cos(rows.theta_rad)
    # n^T (I - u u^T) n = 1 - (u.n)^2 = sin^2(theta): a pointing error acts like a nadir error
    cov = cov + np.diag(s_u**2 * (1.0 - cos_t**2))
    return cast(FloatArray, cov + np.outer(rows.z_t, rows.z_t) * sigma_t_s**2)


def metric_scale(lat_rad: float) -> FloatArray:
    """diag(R_M, R_N cos phi): d(north, east) metres per d(phi, lambda) radians."""
    return np.diag([radius_meridian_m(lat_rad), radius_prime_vertical_m(lat_rad) * np.cos(lat_rad)])


def position_covariance(
    rows: PositionRows, cov_z: ArrayLike, lat_rad: float
) -> tuple[FloatArray, FloatArray]:
    """(cov(Delta x) in rad^2 (phi, lambda), the same north/east in m^2).

    (32)-(33): Delta x = Psi^-1 Delta Z, cov = Psi^-1 cov(Delta Z) Psi^-T for two gyro
    vectors; for more, the generalised least squares (Psi^T C^-1 Psi)^-1, which is (33)
    when Psi is square.
    """
    psi, c = rows.psi, np.asarray(cov_z, float)
    if psi.shape[0] < 2 or np.linalg.matrix_rank(psi, tol=1e-9) < 2:
        raise GeometryError("free-gyro error model: the gyro vectors do not fix both coordinates")
    if psi.shape[0] == 2:
        inv = np.linalg.inv(psi)
        cov_x = inv @ c @ inv.T  # (33)
    else:
        cov_x = np.linalg.inv(psi.T @ np.linalg.solve(c, psi))
    s = metric_scale(lat_rad)
    cov_x = 0.5 * (cov_x + cov_x.T)
    return cov_x, s @ cov_x @ s


# ---------------------------------------------------------------- (35)-(38): DOP


@dataclass(frozen=True)
class DopFigures:
    """Both DOP figures of a free-gyro fix (docs/free-gyro.md).

    ``cofactor_rad2``: Q_x = (Psi^T Psi)^-1 of the paper's rows (35)-(36);
    ``fdop_printed``: (37) as printed, sqrt(q_phiphi^2 + q_lamlam^2) (unit rad^2 per unit
    of Z: dimensionally unsound, reported only to compare with the paper);
    ``dop``: dracc's trace form sqrt(q_nn + q_ee) of the unit rows in metres (METHODS §5);
    ``dop_paper``: the rms of (35) with (34)'s one sigma_s for both rows (sigma_s^2 the
    mean of sin^2(theta) sigma_theta^2), and ``dop_model`` the rms with Var Z_k =
    sin^2(theta_k) sigma_theta^2, both divided by sigma_theta sqrt(R_M R_N); they agree
    when theta_a = theta_b, and ``dop_model`` is ``dop`` to within the flattening.
    """

    cofactor_rad2: FloatArray
    fdop_printed: float
    dop: float
    dop_paper: float
    dop_model: float


def dop_figures(u: ArrayLike, lat_rad: float, lon_rad: float, t_s: ArrayLike) -> DopFigures:
    """The DOP figures of gyro vectors ``u`` (K >= 2, 3) at a position (equal sigma_theta)."""
    rows = position_rows(u, lat_rad, lon_rad, t_s)
    psi = rows.psi
    if psi.shape[0] < 2 or np.linalg.matrix_rank(psi, tol=1e-9) < 2:
        raise GeometryError("free-gyro DOP: the gyro vectors do not fix both coordinates")
    q = np.linalg.inv(psi.T @ psi)  # (35) Q_x
    fdop_printed = float(np.sqrt(q[0, 0] ** 2 + q[1, 1] ** 2))  # (37) as printed
    s = metric_scale(lat_rad)
    psi_m = psi @ np.linalg.inv(s)  # d cos(theta) / d(north, east)
    unit = psi_m / np.linalg.norm(psi_m, axis=1, keepdims=True)
    dop = float(np.sqrt(np.trace(np.linalg.inv(unit.T @ unit))))  # trace form, METHODS §5
    r_g = float(np.sqrt(radius_meridian_m(lat_rad) * radius_prime_vertical_m(lat_rad)))
    sin2 = rows.z_theta**2
    paper = float(np.mean(sin2)) * (s @ q @ s)  # (35) with (34): sigma_s^2 Q_x, sigma_theta = 1
    _, model = position_covariance(rows, np.diag(sin2), lat_rad)
    return DopFigures(
        q,
        fdop_printed,
        dop,
        float(np.sqrt(np.trace(paper))) / r_g,
        float(np.sqrt(np.trace(model))) / r_g,
    )


__all__ = [
    "DopFigures",
    "FreeGyro",
    "NadirErrorBudget",
    "Platform",
    "PositionRows",
    "RateSensorErrors",
    "azimuth_from_heading_rad",
    "body_attitude_error_rate",
    "body_spin_rate_error",
    "cos_nadir",
    "dop_figures",
    "error_model_matrices",
    "expm",
    "gyro_attitude_error_rate",
    "gyro_azimuth_rad",
    "heading_error_rad",
    "heading_from_spin_rates_rad",
    "horizontal_rate_error",
    "metric_scale",
    "nadir_error_budget",
    "nadir_rad",
    "nav_rate_error_radps",
    "nav_spin_rate_error",
    "position_covariance",
    "position_rows",
    "skew",
    "spin_rate_error_nav",
    "spin_rates_radps",
    "tilt_rate_error",
    "tilt_rate_radps",
    "z_covariance",
]
