"""Sensor calibration from a reference (GNSS or the INS mean), with uncertainties.

Beyond the papers (issue 3, "Sensor calibration from the reference").  Pure numpy/scipy
over arrays; no I/O.

Sign conventions (the same throughout dracc)
    compass error    eps = compass heading - true heading (the correction pz = -eps, B3)
    deviation        delta = true magnetic heading - compass heading, so that
                     KDd = KK + d + delta (B2); curve delta(K) = A + B sin K + C cos K
                     + D sin 2K + E cos 2K with K the compass heading
    log              V_log = (1 + s) V_true + b: scale error s (fraction), offset b (m/s)

Three estimators:

:func:`compass_error_from_heading`
    against a reference *heading* (INS mean, GNSS dual-antenna): differences on the
    circle, averaged in blocks (blocks longer than the error's correlation time are
    treated as independent), a constant with its standard error, per-window values and a
    chi-square test of constancy ("slowly varying where the data support it").
:func:`deviation_from_heading`
    the magnetic deviation coefficients A-E against a reference heading by linear least
    squares over block means, with the covariance from the residuals.
:func:`calibrate_from_track`
    against reference *positions* only (GNSS, INS mean): the heading error (constant, or a
    deviation curve), the log scale and offset, and the current, by nonlinear least
    squares over segments.  Model, for a segment j of length T_j:
        (p(t_j + T_j) - p(t_j)) / T_j = mean over the segment of
            (V_log - b) / (1 + s) * [cos(H - eps(H)), sin(H - eps(H))]  +  c(t_j mid)
    with the reference displacement p in metres north/east, H the logged heading and
    c(t) the current, piecewise linear in time between knots every ``current_knot_s``;
    eps is a constant, -delta(K) with the deviation curve A-E, or (slowly varying gyro
    error) piecewise linear in time between knots every ``heading_knot_s``.
    Current and log scale are separable only where the ship steers different headings
    within the current's time scale (a 3 % scale error on a northerly course looks
    exactly like a 0.3 kn northerly current); speed changes separate scale from offset.
    What the data cannot separate is judged from the fit itself and named with why in
    ``not_determinable`` (issue 29): a parameter in a near-null direction of the
    normal matrix (``ILL_CONDITIONED``: the current on one course), an offset that would
    inflate the scale's variance more than ``VIF_MAX``-fold (one speed), or a parameter
    whose sigma against its estimate cannot tell the log's water track from none
    (``DETERMINABLE_Z``; a ship at rest).  An offset the fit cannot separate from the scale is dropped (the scale then
    absorbs it).  Heading errors are wrapped to (-pi, pi].  Uncertainties are
    f s^2 (J^T J)^-1 with s^2 the residual variance per segment and f = (1+rho)/(1-rho)
    the AR(1) inflation for the lag-1 correlation rho of consecutive segments' residuals
    (current wander and slow sensor noise make them correlated).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import cast

import numpy as np

from dracc.core import distributions as dist
from dracc.core.arrays import ArrayLike, BoolArray, FloatArray, IntArray
from dracc.core.errors import InsufficientDataError
from dracc.core.geodesy import angdiff, offset_ne_m, wrap_pi
from dracc.core.numbers import counted
from dracc.core.units import KN_MPS
from dracc.math.identifiability import (
    DETERMINABLE_Z,
    VIF_MAX,
    inseparable,
    normal_inverse,
    variance_inflation,
)

__all__ = [
    "CompassErrorEstimate",
    "DeviationEstimate",
    "TrackCalibration",
    "block_means",
    "calibrate_from_track",
    "compass_error_from_heading",
    "deviation_from_heading",
]


@dataclass(frozen=True)
class LeastSquaresSolution:
    x: FloatArray
    fun: FloatArray  #: residuals at x
    jac: FloatArray  #: Jacobian at x
    n_iter: int


def levenberg_marquardt(
    resid: Callable[[FloatArray], FloatArray],
    jac: Callable[[FloatArray], FloatArray],
    x0: ArrayLike,
    ftol: float = 1e-10,
    xtol: float = 1e-10,
    max_iter: int = 200,
) -> LeastSquaresSolution:
    """min ||resid(x)||^2 by Levenberg-Marquardt with Marquardt's scaling.

    Each step solves (J'J + lam diag(J'J)) dx = -J' r (Marquardt 1963; the damping scaled
    by the Jacobian's column norms, as MINPACK's x_scale="jac"); a step that lowers the cost
    is taken and lam shrinks tenfold, otherwise lam grows tenfold.  Stops when the cost
    falls by less than ``ftol`` relative or the step is below ``xtol`` relative to x.
    The calibration models are nearly linear, so it ends in a few Gauss-Newton steps.
    """
    x = np.asarray(x0, dtype=float).copy()
    r = resid(x)
    J = jac(x)
    cost = float(r @ r)
    lam = 1e-3
    it = 0
    for it in range(1, max_iter + 1):
        A = J.T @ J
        g = J.T @ r
        d = np.diag(A).copy()
        d[d <= 0] = max(float(d.max(initial=0.0)), 1.0) * 1e-12  # a column without effect
        while True:
            try:
                dx = np.linalg.solve(A + lam * np.diag(d), -g)
            except np.linalg.LinAlgError:
                dx = np.linalg.lstsq(A + lam * np.diag(d), -g, rcond=None)[0]
            x_new = x + dx
            r_new = resid(x_new)
            cost_new = float(r_new @ r_new)
            if np.isfinite(cost_new) and cost_new <= cost:
                break
            lam *= 10.0
            if lam > 1e16:  # no step lowers the cost: x is the minimum to rounding
                return LeastSquaresSolution(x, r, J, it)
        small_step = float(np.linalg.norm(dx)) <= xtol * (xtol + float(np.linalg.norm(x)))
        small_gain = cost - cost_new <= ftol * cost
        x, r, cost = x_new, r_new, cost_new
        J = jac(x)
        lam = max(lam / 10.0, 1e-12)
        if small_step or small_gain:
            break
    return LeastSquaresSolution(x, r, J, it)


def _block_ids(time_s: ArrayLike, block_s: float) -> IntArray:
    t = np.asarray(time_s, float)
    return cast(IntArray, np.floor((t - t[0]) / block_s).astype(np.int64))


def block_means(
    time_s: ArrayLike, values: ArrayLike, block_s: float, *, min_samples: int = 2
) -> tuple[FloatArray, FloatArray, IntArray]:
    """Means of ``values`` (n,) or (n, k) over consecutive blocks of ``block_s`` seconds.

    Returns (block_time_s, means, counts) for blocks with at least ``min_samples``
    finite samples; block_time_s is the mean sample time of the block.
    """
    t = np.asarray(time_s, float)
    v = np.asarray(values, float)
    v2 = v.reshape(v.shape[0], -1)
    ok = np.isfinite(t) & np.all(np.isfinite(v2), axis=1)
    t, v2 = t[ok], v2[ok]
    if t.size == 0:
        return np.zeros(0), np.zeros((0,) + v.shape[1:]), np.zeros(0, dtype=np.int64)
    ids = _block_ids(t, block_s)
    _uniq, start, counts = np.unique(ids, return_index=True, return_counts=True)
    sums = np.add.reduceat(v2, start, axis=0)
    tsum = np.add.reduceat(t, start)
    keep = counts >= min_samples
    means = (sums[keep] / counts[keep, None]).reshape((-1,) + v.shape[1:])
    return tsum[keep] / counts[keep], means, counts[keep]


# --------------------------------------------------------------------------------------
# Compass error against a reference heading
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CompassErrorEstimate:
    """Compass error eps = compass - reference, constant and per window.

    ``sigma_rad`` is the standard error of the constant from the scatter of block means.
    ``varying`` is True when the per-window values differ more than their standard
    errors allow (chi-square, p < alpha); then ``window_error_rad`` is the estimate to use.
    """

    error_rad: float
    sigma_rad: float
    n_samples: int
    n_blocks: int
    block_s: float
    window_start_s: FloatArray
    window_error_rad: FloatArray
    window_sigma_rad: FloatArray
    chi2_constant: float
    p_constant: float
    varying: bool


def compass_error_from_heading(
    time_s: ArrayLike,
    compass_rad: ArrayLike,
    reference_rad: ArrayLike,
    *,
    block_s: float = 600.0,
    window_s: float = 3600.0,
    alpha: float = 0.01,
) -> CompassErrorEstimate:
    """Estimate the compass error against a reference heading (INS mean, GNSS heading).

    eps_i = angdiff(compass_i, reference_i); block means over ``block_s`` (longer than the
    compass noise correlation time: default 10 min for tau ~ 2 min) are the independent
    observations.  Constant: mean of block means, standard error s_b / sqrt(n_b).  Per
    window of ``window_s``: mean of its blocks, standard error s_w / sqrt(n_in_window)
    with s_w the pooled within-window scatter; chi2 = sum ((w_j - eps)/sigma_j)^2 on
    (windows - 1) degrees of freedom tests constancy.
    """
    t = np.asarray(time_s, float)
    d = angdiff(compass_rad, reference_rad)
    ok = np.isfinite(d) & np.isfinite(t)
    if ok.sum() < 2:
        raise InsufficientDataError(
            "compass calibration needs compass and reference headings at the same times; "
            f"found {int(ok.sum())} usable pairs"
        )
    bt, bm, _ = block_means(t[ok], d[ok], block_s)
    if bm.size < 3:
        raise InsufficientDataError(
            f"compass calibration needs at least 3 blocks of {block_s:g} s with data; found {bm.size}"
        )
    eps = float(np.mean(bm))
    sigma = float(np.std(bm, ddof=1) / math.sqrt(bm.size))
    wid = np.floor((bt - bt[0] + 0.5 * block_s) / window_s).astype(np.int64)
    uniq, inv, counts = np.unique(wid, return_inverse=True, return_counts=True)
    w_mean = np.bincount(inv, weights=bm) / counts
    resid = bm - w_mean[inv]
    dof = bm.size - uniq.size
    if dof > 0 and uniq.size > 1:
        s_within = math.sqrt(float(np.sum(resid**2)) / dof)
        w_sigma = s_within / np.sqrt(counts)
        with np.errstate(divide="ignore"):
            chi2 = float(np.sum(((w_mean - eps) / w_sigma) ** 2))
        p = float(dist.chi2_sf(chi2, uniq.size - 1))
    else:
        w_sigma = np.full(uniq.size, np.nan)
        chi2, p = float("nan"), float("nan")
    return CompassErrorEstimate(
        error_rad=eps,
        sigma_rad=sigma,
        n_samples=int(ok.sum()),
        n_blocks=int(bm.size),
        block_s=block_s,
        window_start_s=t[ok][0] + uniq * window_s,
        window_error_rad=w_mean,
        window_sigma_rad=w_sigma,
        chi2_constant=chi2,
        p_constant=p,
        varying=bool(np.isfinite(p) and p < alpha),
    )


# --------------------------------------------------------------------------------------
# Magnetic deviation curve against a reference heading
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DeviationEstimate:
    """Deviation curve coefficients (A, B, C, D, E) in radians with their covariance."""

    coefficients_rad: FloatArray  #: (5,) A, B, C, D, E
    covariance_rad2: FloatArray  #: (5, 5)
    sigma_rad: FloatArray  #: (5,) standard errors
    residual_rms_rad: float  #: of the block means about the curve
    n_blocks: int
    heading_coverage_rad: float  #: largest heading gap left uncovered (2 pi minus it is covered)


def _curve_basis(k_rad: ArrayLike) -> FloatArray:
    k = np.asarray(k_rad, float)
    return np.stack([np.ones_like(k), np.sin(k), np.cos(k), np.sin(2 * k), np.cos(2 * k)], -1)


def deviation_from_heading(
    time_s: ArrayLike,
    compass_rad: ArrayLike,
    reference_true_rad: ArrayLike,
    variation_rad: ArrayLike,
    *,
    block_s: float = 120.0,
) -> DeviationEstimate:
    """Fit delta(K) = A + B sin K + C cos K + D sin 2K + E cos 2K against a reference.

    Observed deviation delta_i = angdiff(reference_true_i, compass_i + d_i) (B2 with
    z = 0: compare headings, not courses).  The model is linear in A-E, so block means of
    delta and of the basis functions of the compass heading K keep it exact; ordinary
    least squares over blocks, covariance s^2 (X^T X)^-1 with s^2 the residual variance
    (blocks of ``block_s`` treated as independent).  Raises InsufficientDataError when
    the headings steered do not determine the five coefficients (a swing needs headings
    all round the compass).
    """
    t = np.asarray(time_s, float)
    k = np.asarray(compass_rad, float)
    delta = angdiff(reference_true_rad, k + np.asarray(variation_rad, float))
    cols = np.column_stack([delta, _curve_basis(k)])
    _bt, bm, _ = block_means(t, cols, block_s)
    if bm.shape[0] < 6:
        raise InsufficientDataError(
            f"deviation fit needs at least 6 blocks of {block_s:g} s with compass, reference "
            f"and variation; found {bm.shape[0]}"
        )
    y, X = bm[:, 0], bm[:, 1:]
    hk = np.sort(np.mod(k[np.isfinite(k)], 2 * np.pi))
    gaps = np.diff(np.r_[hk, hk[0] + 2 * np.pi])
    largest_gap = float(gaps.max())
    cond = np.linalg.cond(X)
    if not np.isfinite(cond) or cond > 1e6:
        raise InsufficientDataError(
            "deviation fit: the compass headings steered do not determine A-E "
            f"(largest heading gap {math.degrees(largest_gap):.0f} deg); swing the ship "
            "through all headings"
        )
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    res = y - X @ coef
    dof = y.size - 5
    s2 = float(res @ res) / dof
    cov = s2 * np.linalg.inv(X.T @ X)
    return DeviationEstimate(
        coefficients_rad=cast(FloatArray, coef),  # lstsq is typed floating[Any]
        covariance_rad2=cov,
        sigma_rad=np.sqrt(np.diag(cov)),
        residual_rms_rad=math.sqrt(float(np.mean(res**2))),
        n_blocks=int(y.size),
        heading_coverage_rad=largest_gap,
    )


# --------------------------------------------------------------------------------------
# Heading error, log scale/offset and current against reference positions
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TrackCalibration:
    """Result of :func:`calibrate_from_track`; every estimate with its standard error.

    ``heading_error_rad`` is the constant compass error eps (heading_model='constant'),
    the deviation-curve coefficients A-E with the sign of delta = -eps
    (heading_model='deviation'), or eps at the knots ``heading_knot_s``, linear in time
    between them (heading_model='varying': a slowly varying gyro error, with
    ``heading_constant_p`` the chi-square p-value of "constant after all").
    """

    heading_model: str
    heading_error_rad: FloatArray  #: (1,) eps; (5,) A-E of delta; or eps at heading_knot_s
    heading_error_sigma_rad: FloatArray
    heading_knot_s: FloatArray  #: knot times of the 'varying' model (empty otherwise)
    heading_constant_p: float  #: 'varying': chi-square p-value that eps is constant (NaN otherwise)
    log_scale: float  #: s in V_log = (1 + s) V_true + b
    log_scale_sigma: float
    log_offset_mps: float  #: b (0 and sigma NaN when not fitted)
    log_offset_sigma_mps: float
    current_knot_s: FloatArray  #: (m,) knot times of the piecewise-linear current
    current_ne_mps: FloatArray  #: (m, 2) current north/east at the knots
    current_sigma_ne_mps: FloatArray  #: (m, 2)
    covariance: FloatArray  #: of all parameters, in the order heading, s, [b], currents
    residual_rms_mps: float  #: segment velocity residuals (per axis)
    residual_lag1_correlation: float  #: rho used to inflate the covariance by (1+rho)/(1-rho)
    n_segments: int
    segment_s: float
    #: the quantities the data cannot determine, and why: keys "compass_error",
    #: "log_scale", "log_offset" (see :func:`calibrate_from_track`); their figures are
    #: the fit's but mean nothing
    not_determinable: Mapping[str, str] = field(default_factory=dict)


def _segment_reference_velocity(
    ref_t: ArrayLike,
    ref_lat: ArrayLike,
    ref_lon: ArrayLike,
    edges_s: FloatArray,
    max_ref_gap_s: float,
) -> tuple[FloatArray, BoolArray]:
    """Mean reference velocity (north, east) over each segment from its end positions."""
    rt = np.asarray(ref_t, float)
    ok = np.isfinite(rt) & np.isfinite(ref_lat) & np.isfinite(ref_lon)
    rt = rt[ok]
    order = np.argsort(rt, kind="stable")
    rt = rt[order]
    rla = np.asarray(ref_lat, float)[ok][order]
    rlo = np.unwrap(np.asarray(ref_lon, float)[ok][order])
    hi = np.clip(np.searchsorted(rt, edges_s), 1, max(rt.size - 1, 1))
    lo = hi - 1
    good = (
        (rt.size >= 2)
        & (rt[lo] <= edges_s)
        & (rt[hi] >= edges_s)
        & (rt[hi] - rt[lo] <= max_ref_gap_s)
    )
    lat_e = np.interp(edges_s, rt, rla)
    lon_e = wrap_pi(np.interp(edges_s, rt, rlo))
    dn, de = offset_ne_m(lat_e[1:], lon_e[1:], lat_e[:-1], lon_e[:-1])
    dur = np.diff(edges_s)
    vel = np.column_stack([dn / dur, de / dur])
    return vel, good[:-1] & good[1:]


def _start(
    hs: FloatArray,
    vs: FloatArray,
    wn: FloatArray,
    si: IntArray,
    B: FloatArray,
    u: FloatArray,
    Hd: FloatArray,
    n_b: int,
) -> FloatArray:
    """A starting point from the linear form of the model without offset: the reference
    velocity is ``a W + b W_perp + c`` with W the log's water track, a = cos(eps)/(1+s),
    b = sin(eps)/(1+s); so a compass error of any size (a compass 178 deg off) starts
    near its value, not at 0, where a reversed water track fits a negative gain."""
    m, nk = B.shape
    wn_n = np.bincount(si, weights=wn * vs * np.cos(hs), minlength=m)
    wn_e = np.bincount(si, weights=wn * vs * np.sin(hs), minlength=m)
    X = np.zeros((2 * m, 2 + 2 * nk))
    X[0::2, 0], X[1::2, 0] = wn_n, wn_e
    X[0::2, 1], X[1::2, 1] = wn_e, -wn_n
    X[0::2, 2 : 2 + nk], X[1::2, 2 + nk :] = B, B
    coef = np.linalg.lstsq(X, u.ravel(), rcond=None)[0]
    gain = math.hypot(coef[0], coef[1])
    eps = math.atan2(coef[1], coef[0]) if gain > 0 else 0.0
    n_h = Hd.shape[1]
    theta = np.zeros(n_h + 1 + n_b + 2 * nk)
    # eps = Hd @ theta: every knot at eps (constant, varying), or A = -eps (deviation)
    theta[:n_h] = np.linalg.lstsq(Hd, np.full(Hd.shape[0], eps), rcond=None)[0]
    theta[n_h] = 1.0 / gain - 1.0 if gain > 0 else 0.0
    theta[n_h + 1 + n_b :] = coef[2:]
    return theta


def _times(vif: float) -> str:
    if not math.isfinite(vif):
        return "without bound"
    return "over a thousand-fold" if vif >= 1000 else f"{vif:.0f}-fold"


@dataclass(frozen=True)
class _Water:
    """The water track the fit saw: segment-mean speeds and courses (for the whys)."""

    mean_mps: float
    span_kn: float  #: 5-95 % of the segment-mean speeds
    heading_span_deg: float  #: the widest spread of courses within one current interval

    @classmethod
    def of(
        cls, vs: FloatArray, hs: FloatArray, wn: FloatArray, si: IntArray, m: int, k_lo: IntArray
    ) -> _Water:
        v = np.bincount(si, weights=wn * vs, minlength=m)
        c = np.bincount(si, weights=wn * np.cos(hs), minlength=m)
        sn = np.bincount(si, weights=wn * np.sin(hs), minlength=m)
        course = np.mod(np.arctan2(sn, c), 2 * np.pi)
        spans = []
        for k in np.unique(k_lo):
            a = np.sort(course[k_lo == k])
            gaps = np.diff(np.r_[a, a[0] + 2 * np.pi])
            spans.append(2 * np.pi - float(gaps.max()))
        return cls(
            mean_mps=float(np.mean(v)),
            span_kn=float(np.ptp(np.percentile(v, [5, 95]))) / KN_MPS,
            heading_span_deg=math.degrees(max(spans)),
        )


def _not_determinable(
    A: FloatArray,
    names: list[str],
    x: FloatArray,
    sig: FloatArray,
    water: _Water,
    *,
    moving: bool,
) -> dict[str, str]:
    """Which of the compass error and the log scale the fit does not determine, and why:
    judged from the fit itself (the near-null directions of its normal matrix, the sigma
    against the estimate), the water track's figures only said."""
    out: dict[str, str] = {}
    h = [k for k, nm in enumerate(names) if nm == "heading"]
    i_s = names.index("log scale")
    still = (
        f"the ship did not move through the water ({water.mean_mps / KN_MPS:.1f} kn on "
        "average, within the noise of the reference's velocity)"
    )
    sig_h = float(np.max(sig[h]))
    culprits = inseparable(A, names)
    if not moving and not sig_h < 1 / DETERMINABLE_Z:
        out["compass_error"] = f"compass error not observable: {still}"
    elif "heading" in culprits:
        out["compass_error"] = (
            "compass error and current cannot be separated: the courses steered within "
            f"one current interval span {water.heading_span_deg:.0f} deg at most (a turn "
            "tells a heading error from a cross-track current)"
        )
    elif not sig_h < 1 / DETERMINABLE_Z:
        out["compass_error"] = (
            f"compass error not observable: +-{math.degrees(sig_h):.0f} deg (1 sigma) "
            "tells the log's water track from none at all less than 95 % of the time"
        )
    gain = 1.0 + x[i_s]
    if not moving and not (gain > 0 and sig[i_s] < gain / DETERMINABLE_Z):
        out["log_scale"] = f"log scale not determinable: {still}"
    elif "log scale" in culprits:
        out["log_scale"] = (
            "log scale and current cannot be separated: the courses steered within one "
            f"current interval span {water.heading_span_deg:.0f} deg at most and the speed "
            f"through the water {water.span_kn:.1f} kn"
        )
    elif not (gain > 0 and sig[i_s] < gain / DETERMINABLE_Z):
        out["log_scale"] = (
            f"log scale not determinable: {100 * x[i_s]:+.0f} +- {100 * sig[i_s]:.0f} %: "
            "the log's speed does not show in the reference's motion (its gain 1/(1+s) "
            "is not 1.96 sigma from 0)"
        )
    if "log_scale" in out and "log offset" in names:  # b is read through (V - b)/(1 + s)
        out["log_offset"] = f"log offset not determinable beside the scale: {out['log_scale']}"
    elif "log offset" in culprits:
        out["log_offset"] = (
            "log offset and current cannot be separated: the speed through the water spans "
            f"{water.span_kn:.1f} kn"
        )
    return out


def calibrate_from_track(
    time_s: ArrayLike,
    heading_rad: ArrayLike,
    speed_mps: ArrayLike,
    ref_time_s: ArrayLike,
    ref_lat_rad: ArrayLike,
    ref_lon_rad: ArrayLike,
    *,
    heading_model: str = "constant",
    fit_log_offset: bool = True,
    segment_s: float = 600.0,
    current_knot_s: float = 2 * 3600.0,
    heading_knot_s: float = 6 * 3600.0,
    max_ref_gap_s: float = 5.0,
    min_coverage: float = 0.9,
    variation_rad: ArrayLike = 0.0,
) -> TrackCalibration:
    """Heading error, log scale and offset, and current from reference positions.

    time_s, heading_rad (true heading from a gyro; for the deviation model the compass
    heading plus variation, with ``variation_rad`` (scalar or (n,)) so that the curve is
    a function of the compass heading K = heading - variation), speed_mps: the log
    samples on one time base, each held until the next (as in dead reckoning).  Segments of ``segment_s`` whose log samples cover at
    least ``min_coverage`` of the segment and whose ends have reference positions are
    used.  The model and its identifiability are in the module docstring.
    """
    if heading_model not in ("constant", "deviation", "varying"):
        raise ValueError(
            f"heading_model must be 'constant', 'deviation' or 'varying', got {heading_model!r}"
        )
    t = np.asarray(time_s, float)
    h = np.asarray(heading_rad, float)
    v = np.asarray(speed_mps, float)
    var = np.broadcast_to(np.asarray(variation_rad, float), t.shape)
    ok = np.isfinite(t) & np.isfinite(h) & np.isfinite(v) & np.isfinite(var)
    t, h, v, var = t[ok], h[ok], v[ok], var[ok]
    if t.size < 2:
        raise InsufficientDataError("log calibration needs heading and speed samples")
    dt = np.diff(t, append=t[-1])  # each sample held until the next
    edges = np.arange(t[0], t[-1] + 1e-9, segment_s)
    if edges.size < 2:
        raise InsufficientDataError(
            f"log calibration needs more than one segment of {segment_s:g} s of log data"
        )
    seg = np.searchsorted(edges, t, side="right") - 1
    inside = seg < edges.size - 1
    cover = np.bincount(seg[inside], weights=dt[inside], minlength=edges.size - 1)
    u_ref, ref_ok = _segment_reference_velocity(
        ref_time_s, ref_lat_rad, ref_lon_rad, edges, max_ref_gap_s
    )
    # a segment is used when the log covers it and no sample holds across its end
    use_seg = ref_ok & (cover >= min_coverage * segment_s)
    sample_use = inside & use_seg[np.clip(seg, 0, edges.size - 2)]
    seg_ids = np.flatnonzero(use_seg)
    m = seg_ids.size
    if m < 4:
        raise InsufficientDataError(
            f"log calibration: only {counted(m, 'segment')} of {segment_s:g} s "
            f"{'has' if m == 1 else 'have'} both log data and reference positions at their "
            "ends (need at least 4)"
        )
    # per-sample arrays restricted to used segments, with a compact segment index
    hs, vs, ws = h[sample_use], v[sample_use], dt[sample_use]
    remap = -np.ones(edges.size - 1, dtype=np.int64)
    remap[seg_ids] = np.arange(m)
    si = remap[seg[sample_use]]
    # time-weighted segment means act through the sample weights w/T
    seg_T = np.bincount(si, weights=ws, minlength=m)
    wn = ws / seg_T[si]
    t_mid = 0.5 * (edges[seg_ids] + edges[seg_ids + 1])
    knots = np.arange(edges[0], edges[-1] + current_knot_s, current_knot_s)
    if knots.size < 2:
        knots = np.array([edges[0], edges[-1]])
    # piecewise-linear current: hat-function weights at each segment's mid time
    pos = np.clip((t_mid - knots[0]) / current_knot_s, 0, knots.size - 1 - 1e-12)
    k_lo = np.floor(pos).astype(np.int64)
    frac = pos - k_lo
    B = np.zeros((m, knots.size))
    B[np.arange(m), k_lo] = 1 - frac
    B[np.arange(m), k_lo + 1] = frac
    used_knots = np.flatnonzero(B.sum(axis=0) > 0)
    B = B[:, used_knots]
    nk = used_knots.size
    # eps = Hd @ theta_heading, per sample
    h_knots = np.zeros(0)
    if heading_model == "deviation":
        Hd = -_curve_basis(hs - var[sample_use])  # eps = -delta(K)
    elif heading_model == "varying":
        ts = t[sample_use]
        h_knots = np.arange(edges[0], edges[-1] + heading_knot_s, heading_knot_s)
        hp = np.clip((ts - h_knots[0]) / heading_knot_s, 0, h_knots.size - 1 - 1e-12)
        h_lo = np.floor(hp).astype(np.int64)
        Hd = np.zeros((ts.size, h_knots.size))
        Hd[np.arange(ts.size), h_lo] = 1 - (hp - h_lo)
        Hd[np.arange(ts.size), h_lo + 1] = hp - h_lo
        keep_h = np.flatnonzero(Hd.sum(axis=0) > 0)
        Hd, h_knots = Hd[:, keep_h], h_knots[keep_h]
    else:
        Hd = np.ones((hs.size, 1))
    n_h: int = Hd.shape[1]
    n_b = 1 if fit_log_offset else 0

    def speed_course(theta: FloatArray) -> tuple[FloatArray, FloatArray, float]:
        """Log speed corrected by scale s and offset b, (vs - b) / (1 + s); course hs - eps."""
        s = theta[n_h]
        b = theta[n_h + 1] if n_b else 0.0
        return (vs - b) / (1.0 + s), hs - Hd @ theta[:n_h], s

    def model(theta: FloatArray) -> FloatArray:
        spd, c, _ = speed_course(theta)
        mn = np.bincount(si, weights=wn * spd * np.cos(c), minlength=m)
        me = np.bincount(si, weights=wn * spd * np.sin(c), minlength=m)
        cur = theta[n_h + 1 + n_b :].reshape(2, nk)
        return np.column_stack([mn + B @ cur[0], me + B @ cur[1]])

    def resid(theta: FloatArray) -> FloatArray:
        return (model(theta) - u_ref[seg_ids]).ravel()

    def jac(theta: FloatArray) -> FloatArray:
        """Analytic Jacobian of ``resid`` (rows: segment j north, j east)."""
        spd, c, s = speed_course(theta)
        cos_c, sin_c = np.cos(c), np.sin(c)
        out = np.zeros((m, 2, n_par))

        def seg_sum(x: FloatArray) -> FloatArray:
            # numpy's stubs type bincount as integer; with weights it is float64
            return cast(FloatArray, np.bincount(si, weights=wn * x, minlength=m))

        # d/d eps of spd [cos c, sin c] = spd [sin c, -cos c]
        for k in range(n_h):  # eps = Hd @ theta
            out[:, 0, k] = seg_sum(Hd[:, k] * spd * sin_c)
            out[:, 1, k] = seg_sum(-Hd[:, k] * spd * cos_c)
        out[:, 0, n_h] = seg_sum(-spd * cos_c) / (1.0 + s)
        out[:, 1, n_h] = seg_sum(-spd * sin_c) / (1.0 + s)
        if n_b:
            out[:, 0, n_h + 1] = seg_sum(-cos_c) / (1.0 + s)
            out[:, 1, n_h + 1] = seg_sum(-sin_c) / (1.0 + s)
        c0 = n_h + 1 + n_b
        out[:, 0, c0 : c0 + nk] = B
        out[:, 1, c0 + nk :] = B
        return out.reshape(2 * m, n_par)

    n_par = n_h + 1 + n_b + 2 * nk
    if 2 * m <= n_par:
        raise InsufficientDataError(
            f"log calibration: {counted(m, 'segment')} cannot determine {n_par} parameters; "
            "use a longer log, shorter segments or a longer current_knot_s"
        )
    sol = levenberg_marquardt(resid, jac, _start(hs, vs, wn, si, B, u_ref[seg_ids], Hd, n_b))
    J = sol.jac
    JtJ = J.T @ J
    if not np.all(np.isfinite(JtJ)):
        raise InsufficientDataError("log calibration: the fit diverged (non-finite Jacobian)")
    names = ["heading"] * n_h + ["log scale"] + ["log offset"] * n_b + ["current"] * (2 * nk)
    speeds = _Water.of(vs, hs, wn, si, m, k_lo)
    vif_offset = variance_inflation(JtJ, names, "log scale", "log offset") if n_b else 1.0
    if vif_offset > VIF_MAX:
        # scale and offset act alike where the speed hardly changes: fit the scale alone
        # (the offset taken as 0: the scale absorbs it) and say why
        cal = calibrate_from_track(
            time_s,
            heading_rad,
            speed_mps,
            ref_time_s,
            ref_lat_rad,
            ref_lon_rad,
            heading_model=heading_model,
            fit_log_offset=False,
            segment_s=segment_s,
            current_knot_s=current_knot_s,
            heading_knot_s=heading_knot_s,
            max_ref_gap_s=max_ref_gap_s,
            min_coverage=min_coverage,
            variation_rad=variation_rad,
        )
        why = (
            "log scale and offset cannot be separated: speed through the water spans "
            f"{speeds.span_kn:.1f} kn (5-95 % of the segments' means), and fitting the "
            f"offset would inflate the scale's variance {_times(vif_offset)} (more than "
            f"{VIF_MAX:g}-fold); the scale absorbs the offset"
        )
        return replace(cal, not_determinable={"log_offset": why, **cal.not_determinable})
    res = sol.fun
    dof = res.size - n_par
    s2 = float(res @ res) / dof
    # residuals of consecutive segments are correlated (current wander, slow sensor
    # noise): inflate by the AR(1) variance factor (1 + rho) / (1 - rho), rho the lag-1
    # autocorrelation of the residuals along consecutive used segments, if positive
    rn = res.reshape(m, 2)
    consecutive = np.diff(seg_ids) == 1
    num = float(np.sum(rn[:-1][consecutive] * rn[1:][consecutive]))
    den = float(np.sum(rn**2))
    rho = min(max(num / den, 0.0), 0.9) if den > 0 and consecutive.any() else 0.0
    inflation = (1 + rho) / (1 - rho)
    with np.errstate(invalid="ignore"):  # an unobservable direction: NaN, reported below
        cov = inflation * s2 * normal_inverse(JtJ)
        sig = np.sqrt(np.diag(cov))
    x = sol.x.copy()
    # the heading error on the circle (the fit is free to wander a turn or more)
    x[: 1 if heading_model == "deviation" else n_h] = wrap_pi(
        x[: 1 if heading_model == "deviation" else n_h]
    )
    residual_rms = math.sqrt(float(np.mean(res**2)))
    unknown = _not_determinable(
        JtJ, names, x, sig, speeds, moving=speeds.mean_mps > DETERMINABLE_Z * residual_rms
    )
    if heading_model == "varying" and n_h > 1 and "compass_error" not in unknown:
        # constancy of the heading error: GLS mean of the knot values and its chi-square
        C = cov[:n_h, :n_h]
        Ci = np.linalg.inv(C)
        one = np.ones(n_h)
        xh = x[:n_h]
        mean_h = float(one @ Ci @ xh / (one @ Ci @ one))
        chi2 = float((xh - mean_h) @ Ci @ (xh - mean_h))
        p_const = float(dist.chi2_sf(chi2, n_h - 1))
    else:
        p_const = float("nan")
    cur = x[n_h + 1 + n_b :].reshape(2, nk).T
    cur_sig = sig[n_h + 1 + n_b :].reshape(2, nk).T
    return TrackCalibration(
        heading_model=heading_model,
        heading_error_rad=x[:n_h].copy(),
        heading_knot_s=h_knots,
        heading_constant_p=p_const,
        heading_error_sigma_rad=sig[:n_h].copy(),
        log_scale=float(x[n_h]),
        log_scale_sigma=float(sig[n_h]),
        log_offset_mps=float(x[n_h + 1]) if n_b else 0.0,
        log_offset_sigma_mps=float(sig[n_h + 1]) if n_b else float("nan"),
        current_knot_s=knots[used_knots],
        current_ne_mps=cur,
        current_sigma_ne_mps=cur_sig,
        covariance=cov,
        residual_rms_mps=residual_rms,
        residual_lag1_correlation=rho,
        n_segments=m,
        segment_s=segment_s,
        not_determinable=unknown,
    )
