"""The paper's statistics (K1)-(K8) over deviations from the mean of three INS.

Pure functions over numpy arrays, no I/O.  Equation labels ``(Kn)`` refer to the
INS-deviation paper (Boykov, Mikhalskiy, Ivantsov; ``seeds/001``) as restated in
``METHODS.md`` section 4.

Glossary
--------
``y``      readings of the units at the sampling instants, shape (J, n) (J units)
``u``      deviations from the mean of the units, same shape (K1a)
``m_u``    RMS of the deviations with the (n - 1.45) denominator (K3b)
``m_y``    RMS error estimate ``k * m_u`` (K5a, K5b)
``E``      *excess* kurtosis (normal = 0) of the deviations (K6)
``R, r``   latitude/longitude covariance and correlation of the deviations (K7)
``K_PIE``  conversion from RMS to the limiting error at probability P for a symmetric
           distribution of excess kurtosis E (K8)
``K_hm``   upper confidence factor of an RMS estimated from few independent samples (K8)

Missing values are NaN and are ignored by every statistic (``n`` counts the valid
ones); nothing is filled.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dracc.core import distributions as dist
from dracc.core.geodesy import angdiff, circmean, k_lambda, k_phi

#: (K3b) the paper's Student-corrected number of deviations is n - 1.45
N_CORRECTION = 1.45
#: (K5a) first approximation, independent equal errors of three units: sqrt(1/(1 - 1/3))
K_FIRST_APPROX_THREE = math.sqrt(3.0 / 2.0)
#: two units: u = (y1 - y2)/2 has variance sigma^2/2 for equal independent errors
K_FIRST_APPROX_TWO = math.sqrt(2.0)
#: (K5b) the paper's second approximation (latitude), and its empirical longitude/course factor
K_SECOND_APPROX = 1.32
K_EMPIRICAL_LON = 1.49
#: lowest excess kurtosis of any distribution (the symmetric two-point law)
KURTOSIS_MIN = -2.0

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


# ----------------------------------------------------------------- deviations (K1)


def deviations_linear(y: ArrayLike) -> FloatArray:
    """Deviations from the mean of the units for a linear channel.

    ``y`` has shape (J, ...) with the units along axis 0; instants where any unit is
    NaN give NaN deviations for every unit (the mean of three needs all three).

    y*_i = (1/J) sum_j y_ji                                  (K1b)
    u_ji = y_ji - y*_i                                       (K1a)
    """
    y = np.asarray(y, dtype=float)
    mean: FloatArray = np.mean(y, axis=0)  # (K1b); NaN propagates: incomplete instants stay NaN
    return y - mean  # (K1a)


def deviations_position_m(
    lat_rad: ArrayLike, lon_rad: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """North and east deviations in metres of each unit's position from the mean position.

    ``lat_rad``, ``lon_rad``: shape (J, n).  The mean latitude is the arithmetic mean;
    the mean longitude is taken through :func:`angdiff` relative to the first unit, so
    the antimeridian does no harm.  Radians become metres with the radii of curvature at
    the mean latitude:

    phi*_i = (1/J) sum_j phi_ji,  lam*_i likewise on the circle   (K1b)
    u_north_ji = (phi_ji - phi*_i) / k_phi(phi*_i)                (K1a), (B18)
    u_east_ji  = (lam_ji - lam*_i) / k_lambda(phi*_i)             (K1a), (B19)

    Returns (north_m, east_m, lat_mean_rad); NaN where any unit is missing.
    """
    lat = np.asarray(lat_rad, dtype=float)
    lon = np.asarray(lon_rad, dtype=float)
    lat_mean = np.mean(lat, axis=0)  # (K1b)
    dlon = angdiff(lon, lon[0])
    lon_mean = lon[0] + np.mean(dlon, axis=0)  # (K1b) on the circle
    north_m = (lat - lat_mean) / k_phi(lat_mean)  # (K1a), (B18)
    east_m = angdiff(lon, lon_mean) / k_lambda(lat_mean)  # (K1a), (B19)
    return north_m, east_m, lat_mean


def deviations_course_rad(heading_rad: ArrayLike) -> FloatArray:
    """Course deviations on the circle  (K1a, K1b).

    ``heading_rad``: shape (J, n).  The headings are unwrapped around their circular
    mean c_i (:func:`circmean`), and (K1b) is applied to the unwrapped values:

    y*_i = c_i + (1/J) sum_j angdiff(y_ji, c_i)                 (K1b) on the circle
    u_ji = angdiff(y_ji, y*_i)                                  (K1a)

    so 359 deg and 1 deg average to 0 deg, and the deviations sum to zero exactly as in
    the paper (the circular mean itself differs from (K1b) by O(spread^3), which would
    break sum_j u_ji = 0).  An instant with any unit missing gives NaN for all.
    """
    h = np.asarray(heading_rad, dtype=float)
    complete = ~np.any(np.isnan(h), axis=0)
    c = np.where(complete, circmean(h, axis=0), np.nan)
    mean = c + np.mean(angdiff(h, c), axis=0)  # (K1b) on the circle
    return np.where(complete, angdiff(h, mean), np.nan)  # (K1a)


# ------------------------------------------------------------------- (K3b)-(K7)


def count_valid(u: ArrayLike, axis: int = -1) -> Any:
    """Number of non-NaN values along ``axis``."""
    return np.sum(~np.isnan(np.asarray(u, dtype=float)), axis=axis)


def rms_k3b(u: ArrayLike, axis: int = -1) -> FloatArray:
    """RMS with the paper's denominator: m = sqrt( sum u^2 / (n - 1.45) )   (K3b).

    NaNs ignored; NaN where n < 2 (the denominator must stay positive).
    """
    u = np.asarray(u, dtype=float)
    n = count_valid(u, axis)
    s2 = np.nansum(u * u, axis=axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        m = np.sqrt(s2 / (n - N_CORRECTION))  # (K3b)
    return np.where(n >= 2, m, np.nan)


def rms_plain(x: ArrayLike, axis: int = -1) -> FloatArray:
    """Plain RMS sqrt( sum x^2 / n ), NaNs ignored; NaN where n = 0."""
    x = np.asarray(x, dtype=float)
    n = count_valid(x, axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, np.sqrt(np.nansum(x * x, axis=axis) / n), np.nan)


def excess_kurtosis_k6(u: ArrayLike, axis: int = -1) -> FloatArray:
    """Excess kurtosis of deviations, with the (K3b) RMS in the denominator  (K6).

    E = (1/n) sum u^4 / m_u^4 - 3,   m_u^2 = sum u^2 / (n - 1.45)

    0 for a normal law; it can fall slightly below -2 for small n because of the
    (n - 1.45) denominator.  NaN where n < 4.
    """
    u = np.asarray(u, dtype=float)
    n = count_valid(u, axis)
    m = rms_k3b(u, axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        e = np.nansum(u**4, axis=axis) / n / m**4 - 3.0  # (K6)
    return np.where(n >= 4, e, np.nan)


def lat_lon_covariance(
    u_lat: ArrayLike, u_lon: ArrayLike, axis: int = -1
) -> tuple[FloatArray, FloatArray]:
    """Covariance and correlation of latitude and longitude deviations  (K7).

    R = (1/n) sum u_lat,i u_lon,i                                   (K7a)
    r = R / (m_lat m_lon)                                           (K7b), corrected:
        with m_lat, m_lon the RMS over the same n, i.e. m^2 = (1/n) sum u^2

    The paper takes m from (K3b), with n - 1.45: then perfectly correlated channels give
    r = (n - 1.45)/n (0.71 at n = 5, 0.94 at n = 24), not 1.  dracc uses the same
    normalisation in R and in m, so that |r| <= 1; the paper's literal value is
    r * (n - 1.45)/n.  Only instants where both channels are valid count.  Returns
    (R, r); NaN where n < 2 or an RMS is zero.
    """
    a = np.asarray(u_lat, dtype=float)
    b = np.asarray(u_lon, dtype=float)
    both = ~(np.isnan(a) | np.isnan(b))
    a = np.where(both, a, 0.0)
    b = np.where(both, b, 0.0)
    n = np.sum(both, axis=axis)
    with np.errstate(invalid="ignore", divide="ignore"):
        cov = np.sum(a * b, axis=axis) / n  # (K7a)
        r = cov / np.sqrt(np.sum(a * a, axis=axis) / n * np.sum(b * b, axis=axis) / n)  # (K7b)
    return np.where(n >= 2, cov, np.nan), np.where(n >= 2, r, np.nan)


# --------------------------------------------------------------------------- (K8)


def k_pie(probability: ArrayLike, kurtosis: ArrayLike) -> FloatArray | float:
    """K_PIE(P, E): two-sided quantile at probability P of a unit-variance symmetric law
    with excess kurtosis E  (K8).

    The paper ties the conversion to the law's kurtosis but names no family; dracc uses
    one continuous family spanning every possible kurtosis:

    - E > 0: Student's t with nu = 4 + 6/E degrees of freedom (excess kurtosis 6/(nu-4)),
      scaled to unit variance by sqrt((nu-2)/nu);
    - E = 0: the normal law (K_PIE(0.95, 0) = 1.95996);
    - -2 < E < 0: the symmetric beta law on [-1, 1], X = 2B - 1 with B ~ Beta(a, a),
      a = (-6/E - 3)/2 (excess kurtosis -6/(2a + 3)), scaled by sqrt(2a + 1).  a = 1 is the
      uniform law (E = -1.2, K_PIE(0.95) = 0.95 sqrt 3), a -> 0 the two-point law (K -> 1).

    Both branches tend to the normal law as E -> 0.  E <= -2 is no distribution's
    kurtosis: NaN is returned (the caller reports it).  Broadcasts.
    """
    p = np.asarray(probability, dtype=float)
    e = np.asarray(kurtosis, dtype=float)
    p, e = np.broadcast_arrays(p, e)
    q = (1.0 + p) / 2.0  # two-sided: P(|X| <= K) = P
    out = np.full(e.shape, np.nan)
    pos = e > 0
    zero = e == 0
    neg = (e < 0) & (e > KURTOSIS_MIN)
    if np.any(pos):
        nu = 4.0 + 6.0 / e[pos]
        out[pos] = dist.t_ppf(q[pos], nu) * np.sqrt((nu - 2.0) / nu)
    if np.any(zero):
        out[zero] = dist.norm_ppf(q[zero])
    if np.any(neg):
        a = (-6.0 / e[neg] - 3.0) / 2.0
        out[neg] = (2.0 * dist.beta_ppf(q[neg], a, a) - 1.0) * np.sqrt(2.0 * a + 1.0)
    return out if out.ndim else float(out)


def effective_samples(n: ArrayLike, interval_s: float, correlation_time_s: float) -> FloatArray:
    """Effective number of independent samples among n taken every ``interval_s``.

    INS errors are correlated over 4-6 h (the paper's conclusions), so samples closer
    than the correlation time are not independent:  N_eff = min(n, n * dt / tau).
    The paper's eight days at 1 h with tau = 4.8 h give N_eff = 40, its figure.
    """
    n = np.asarray(n, dtype=float)
    if correlation_time_s <= 0:
        return n
    n_eff: FloatArray = np.minimum(n, n * interval_s / correlation_time_s)
    return n_eff


def k_hm(confidence: float, n_eff: ArrayLike) -> FloatArray | float:
    """K_hm: upper confidence factor of an RMS estimated from N_eff independent samples (K8).

    With m^2 ~ sigma^2 chi^2(N_eff) / N_eff, the one-sided upper bound of sigma at
    ``confidence`` is  sigma <= m sqrt( N_eff / chi2_{1-confidence}(N_eff) ),  so
    K_hm = sqrt( N_eff / chi2.ppf(1 - confidence, N_eff) ).
    N_eff need not be an integer; NaN where N_eff <= 0.
    """
    nu = np.asarray(n_eff, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(
            nu > 0, np.sqrt(nu / dist.chi2_ppf(1.0 - confidence, np.where(nu > 0, nu, 1.0))), np.nan
        )
    return out if out.ndim else float(out)


def limiting_error(
    m_y: ArrayLike, probability: ArrayLike, kurtosis: ArrayLike, confidence: float, n_eff: ArrayLike
) -> tuple[FloatArray | float, FloatArray | float, FloatArray | float]:
    """Limiting error y^(P) = K_PIE(P, E) * K_hm * m_y   (K8).

    Returns (limit, k_pie, k_hm), each NaN where its input does not allow it.
    """
    kp = k_pie(probability, kurtosis)
    kh = k_hm(confidence, n_eff)
    return kp * kh * np.asarray(m_y, dtype=float), kp, kh  # (K8)


# ------------------------------------- beside the fixed factors: (3a)-(5b) and K_FD


def r_deviation_mean_k4(m_u: ArrayLike, m_y_star: ArrayLike) -> FloatArray:
    """Correlation of a unit's deviation u with the mean of three y*, as the paper takes it  (4):

    r_{u,y*} = m_o6^2 / (m_u m_y*),   m_o6^2 ~ (1/3) m_y*^2   ->   r = m_y* / (3 m_u)

    (the paper's m_o6 is the RMS of the part common to u and y*, "taking into account
    (1, b)").  Note: for three independent equal errors the true correlation is 0
    (cov(x_1 - x*, x*) = sigma^2/3 - sigma^2/3), which is why (5a) is exact then.
    """
    m_u = np.asarray(m_u, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.asarray(m_y_star, dtype=float) / (3.0 * m_u)  # (4)


def m_y_k3a(
    m_u: ArrayLike, r: ArrayLike, cross: float = 2.0, mean_share: float = 1.0 / 3.0
) -> FloatArray | float:
    """RMS error m_y solving (3a) for a given correlation r:

    m_y^2 = m_u^2 + m_y*^2 + cross * r * m_u * m_y*                 (3, a), cross = 2 as printed
    m_y*^2 = mean_share * m_y^2 = (1/3) m_y^2                       (the relation of (5, a))

    a quadratic in m_y:  (1 - s) m_y^2 - cross r sqrt(s) m_u m_y - m_u^2 = 0  (s = mean_share),
    m_y = m_u [cross r sqrt(s) + sqrt(cross^2 r^2 s + 4 (1 - s))] / (2 (1 - s)).
    r = 0 gives (5a), m_y = sqrt(3/2) m_u.  ``cross = 1`` is the reading in which the paper's
    own arithmetic enters the cross term once.  Broadcasts.
    """
    m_u = np.asarray(m_u, dtype=float)
    r = np.asarray(r, dtype=float)
    s = float(mean_share)
    b = cross * r * math.sqrt(s)
    k = (b + np.sqrt(b * b + 4.0 * (1.0 - s))) / (2.0 * (1.0 - s))  # (3, a) solved
    out = k * m_u
    return out if out.ndim else float(out)


def k_second_approximation(
    r: ArrayLike | None = None, cross: float = 2.0, iterations: int = 1
) -> FloatArray | float:
    """Factor k = m_y / m_u of the paper's second approximation (5b), from its text:

    "determine the correlation coefficient r plugging the obtained values [of (5a)] in (4)
    and make the second approximation for m_y with respect to (3, a)" (seeds/001).

    With ``r`` None: start from (5a), k_0 = sqrt(3/2); each iteration takes r from (4) at
    the current k (m_y* = k m_u / sqrt 3, so r = k / (3 sqrt 3)) and solves (3a)
    (:func:`m_y_k3a`).  One iteration is the paper's second approximation:

    - cross = 2, (3a) as printed: r = sqrt(2)/6 = 0.2357, k = (sqrt 2 + sqrt 74)/(4 sqrt 3) = 1.4458;
    - cross = 1: k = (sqrt 6 + sqrt 870)/24 = 1.3311.
    Iterated to the fixed point, k^2 = 9/(6 - cross): 1.5 (cross 2), sqrt(9/5) = 1.342 (cross 1).

    The paper states k = sqrt(1/0.57) = 1.32 (0.57 = 0.67 - 0.10), which none of these
    readings of its formulas gives (METHODS section 7: 1.32 cannot be recomputed from
    the text); dracc's default factor stays the stated 1.32 (:data:`K_SECOND_APPROX`).
    With a given ``r`` (e.g. measured against a reference) the factor is (3a) solved
    once for that r.
    """
    if r is not None:
        return m_y_k3a(1.0, r, cross)
    k: FloatArray | float = K_FIRST_APPROX_THREE  # (5, a)
    for _ in range(int(iterations)):
        r_k = float(r_deviation_mean_k4(1.0, k / math.sqrt(3.0)))  # (4) at the current k
        k = m_y_k3a(1.0, r_k, cross)  # (3, a)
    return k


def m_y_second_approximation(
    m_u: ArrayLike, r: ArrayLike | None = None, cross: float = 2.0, iterations: int = 1
) -> FloatArray | float:
    """m_y = k m_u with k from :func:`k_second_approximation` (3a), (4), (5b).  Broadcasts."""
    out = k_second_approximation(r, cross, iterations) * np.asarray(m_u, dtype=float)
    return out if np.ndim(out) else float(out)


def k_fd(
    probability: float, n1: ArrayLike, n2: ArrayLike | None = None, squared: bool = False
) -> FloatArray | float:
    """Fisher factor K_FD: upper confidence bound at ``probability`` of the ratio of two
    RMS estimated from n1 and n2 independent samples, relative to the true ratio
    (seeds/001, analysis of Table 1: "the upper confidence bound for the RMS ratio is
    assigned by Fisher distribution").

    (m_1/sigma_1)^2 / (m_2/sigma_2)^2 ~ F(n1, n2), so  K_FD = sqrt(F_P(n1, n2))  for the
    ratio of RMS (``squared`` True: F_P(n1, n2) itself, for the ratio of variances).
    n2 defaults to n1 (Table 1: errors and deviations over the same instants).

    The paper: P = 0.99, N = 40 (eight days hourly, correlation interval 4-6 h), and it
    states K_FD = 1.69, k_it = 1.32 * 1.69 = 2.23.  By the formula, sqrt(F_0.99(40, 40))
    = sqrt(2.114) = 1.454 (k_it = 1.92); F_0.99(40, 40) = 2.114 for variances.  The
    stated 1.69 is F_0.95(40, 40) = 1.693, the variance ratio at P = 0.95 (METHODS
    section 7: not recomputable from the text as stated).  Either way k* = 1.49 lies
    below the bound, the paper's conclusion.  NaN where a count is <= 0.
    """
    n1 = np.asarray(n1, dtype=float)
    n2 = n1 if n2 is None else np.asarray(n2, dtype=float)
    ok = (n1 > 0) & (n2 > 0)
    f = np.where(ok, dist.f_ppf(probability, np.where(ok, n1, 1.0), np.where(ok, n2, 1.0)), np.nan)
    out = f if squared else np.sqrt(f)
    return out if out.ndim else float(out)


def k_upper_fisher(
    k: float,
    n: ArrayLike,
    interval_s: float,
    correlation_time_s: float,
    probability: float = 0.99,
    squared: bool = False,
) -> tuple[FloatArray | float, FloatArray | float, FloatArray | float]:
    """Upper confidence bound of the factor, k_it = k * K_FD(P; N, N), with N the number
    of independent samples among n taken every ``interval_s``: N = n dt / tau
    (:func:`effective_samples`, tau the INS error correlation time, 4-6 h).

    Returns (k_it, K_FD, N).  The paper: n = 192 (8 days hourly), tau = 4.8 h: N = 40
    (tau 4 h: 48; 6 h: 32).  A k* above k_it contradicts the factor k at P.
    """
    n_eff = effective_samples(n, interval_s, correlation_time_s)
    kf = k_fd(probability, n_eff, squared=squared)
    return k * kf, kf, float(n_eff) if np.ndim(n_eff) == 0 else n_eff


# ------------------------------------------------------------ windows and averages


def weighted_rms(rms: ArrayLike, n: ArrayLike) -> float:
    """Weighted average of (K3b) RMS values over windows (the last row of the paper's Table 1):

    m_w = sqrt( sum_d (n_d - 1.45) m_d^2 / sum_d (n_d - 1.45) )

    The paper does not state its weights; dracc weighs each day by the denominator of its
    (K3b) RMS, so m_w pools the days' sums of squares over their pooled (n - 1.45) (days
    of equal n get equal weights).  Windows with n < 2 or NaN RMS are skipped.
    """
    m = np.asarray(rms, dtype=float)
    w = np.asarray(n, dtype=float) - N_CORRECTION
    ok = ~np.isnan(m) & (w > 0)
    if not np.any(ok):
        return math.nan
    return float(np.sqrt(np.sum(w[ok] * m[ok] ** 2) / np.sum(w[ok])))


def window_index(time_ns: ArrayLike, window_s: float, origin_ns: int) -> IntArray:
    """Index of the window [origin + k W, origin + (k+1) W) holding each instant."""
    w_ns = int(round(window_s * 1e9))
    index: IntArray = (np.asarray(time_ns, dtype=np.int64) - np.int64(origin_ns)) // w_ns
    return index
