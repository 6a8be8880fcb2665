"""The paper's position covariance (B23-B31): P_V, its propagation (B23), M and 2M.

(B23) treats the errors as independent per step, which averages correlated errors away
at high data rates (METHODS section 2); :mod:`dracc.math.deadreckoning.error_processes`
holds the rate-independent ("honest") form.  2M and how often it holds the error live
in :mod:`dracc.math.uncertainty`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from dracc.core.arrays import FloatArray
from dracc.core.geodesy import k_lambda, k_phi

__all__ = [
    "covariance_b23_rad2",
    "covariance_m2_from_rad2",
    "mean_error_m",
    "sigma_course_rad",
    "speed_covariance_rad2",
]


def sigma_course_rad(
    sigma_kz_rad: ArrayLike, sigma_pz_rad: ArrayLike = 0.0, sigma_z_rad: ArrayLike = 0.0
) -> FloatArray:
    """sigma_C = sqrt(sigma_KZ^2 + sigma_pz^2 + sigma_z^2) (B29)."""
    sigma_c: FloatArray = np.sqrt(
        np.square(sigma_kz_rad) + np.square(sigma_pz_rad) + np.square(sigma_z_rad)  # (B29)
    )
    return sigma_c


def speed_covariance_rad2(
    lat_rad: ArrayLike,
    speed_mps: ArrayLike,
    course_rad: ArrayLike,
    sigma_v_mps: ArrayLike,
    sigma_c_rad: ArrayLike,
) -> FloatArray:
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


def covariance_b23_rad2(
    time_s: ArrayLike,
    lat_rad: ArrayLike,
    speed_mps: ArrayLike,
    course_rad: ArrayLike,
    sigma_v_mps: ArrayLike,
    sigma_c_rad: ArrayLike,
    P0_rad2: ArrayLike,
) -> FloatArray:
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


def covariance_m2_from_rad2(P_rad2: ArrayLike, lat_rad: ArrayLike) -> FloatArray:
    """P in metres north/east from P in (phi, lambda): divide by k_phi, k_lambda (B30's scaling)."""
    s = np.stack([1.0 / k_phi(lat_rad), 1.0 / k_lambda(lat_rad)], -1)
    return np.asarray(P_rad2) * s[..., :, None] * s[..., None, :]


def mean_error_m(P_rad2: ArrayLike, lat_rad: ArrayLike) -> FloatArray:
    """M = sqrt((sigma_phi/k_phi)^2 + (sigma_lambda/k_lambda)^2) (B30); 2M is (B31)."""
    P = np.asarray(P_rad2, float)
    return np.sqrt(
        P[..., 0, 0] / k_phi(lat_rad) ** 2 + P[..., 1, 1] / k_lambda(lat_rad) ** 2
    )  # (B30)
