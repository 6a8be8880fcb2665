"""Each source's clock, learned from the data: the offset between the time a record is
stamped with and the instant it describes, its σ, and the drift of a source's own clock.

Sign: ``offset_s > 0`` means the data are stamped *after* the instant they describe (a
sensor's latency, a logger that stamps on receipt).  A record stamped ``s`` describes the
instant ``s - offset_s``.  For a source faster than its stamps the offset is against the
times reconstructed inside the stamp (its latency); the stamps' own offset is
``offset_s - spread_mean_s``.

Three measurements, each a pure function over arrays:

- **Own time of fix** (:func:`time_of_fix_offset`): a source writing its own time of fix
  beside a receive stamp (GGA under a TAG block) shows ``recv - fix`` directly; its other
  records, received the same way, share that offset.  The slope of ``recv - fix`` over the
  night is the drift of the logger clock against the source's, in ppm.
- **Rate cross-regression** (:func:`rate_lag`): two series of one quantity (two headings; a
  heading and the GNSS course; the log and the GNSS speed) differ by slowly varying errors
  plus the timing skew times the rate of change:  ``x(s) - r(s) = c(t) - Δ·ṙ(s)`` with
  ``Δ = offset_x - offset_r`` (first-order Taylor: ``x(s) = q(s - offset_x)``).  Per window
  the slowly varying part is a line in time (plus, against the course over ground, the
  current's drift angle ``a·sin ψ + b·cos ψ``); Δ is the least-squares slope on ``-ṙ``,
  its σ from the residuals with their lag-1 autocorrelation (effective sample size), and
  the windows are combined by inverse variance, σ widened by √(χ²/dof) when they disagree.
- **Shared stamps** (:func:`spread_shared_stamps`): a source faster than its stamps (a
  10 Hz gyro behind whole-second TAG ``c:`` stamps) has runs of records with one stamp;
  received at a steady cadence inside the stamp interval ``[s, s + q)``, record ``j`` of ``m``
  is placed at ``s + (j + ½)·q/m`` (the mean of where it can be).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dracc.core.arrays import FloatArray, IntArray
from dracc.core.units import NS_PER_S

__all__ = [
    "LagEstimate",
    "SourceClock",
    "combine",
    "hermite",
    "rate_lag",
    "slopes",
    "spread_shared_stamps",
    "time_of_fix_offset",
]

#: how each offset was measured (the ``method`` of ``sources[KEY].clock``)
METHODS = (
    "time_of_fix",  # the source's own time of fix beside its receive stamp
    "own_time",  # every record carries its own time of fix, no receive stamp: used as is
    "heading_rate",  # its heading against an anchored heading, in turns and yaw
    "course_rate",  # its heading against the GNSS course over ground, in turns
    "speed_rate",  # the log against the GNSS speed over ground, in speed changes
    "configured",  # [sources.KEY] latency_s
    "not_determinable",  # nothing to measure it against, or too little motion
    "no_clock",  # a log without a clock: its times are only the order of its records
)


@dataclass(frozen=True)
class LagEstimate:
    """A timing skew Δ (seconds) with its σ from ``windows`` windows of motion."""

    lag_s: float
    sigma_s: float
    windows: int

    @property
    def usable(self) -> bool:
        return self.windows > 0 and math.isfinite(self.sigma_s)


@dataclass(frozen=True)
class SourceClock:
    """One source's clock against the time base of the analysis (GNSS time of fix)."""

    offset_s: float  #: stamped this long after the instant described (NaN: not known)
    offset_sigma_s: float  #: 1σ of ``offset_s`` (NaN where not known; 0 where configured)
    drift_ppm: float | None  #: the logger clock against the source's own, where measurable
    method: str  #: one of :data:`METHODS`
    basis: str | None = None  #: what it was measured against (a source key, 'GNSS course')
    samples: int = 0  #: records or windows the estimate rests on
    spread: int = 0  #: records placed inside a shared stamp by the source's cadence
    #: how far those records moved on average (s): their stamps' offset is
    #: ``offset_s - spread_mean_s``
    spread_mean_s: float = 0.0
    stamp_s: float | None = None  #: the resolution of the stamps its records carry

    @property
    def known(self) -> bool:
        return math.isfinite(self.offset_s)


def stamp_resolution_s(time_ns: IntArray) -> float | None:
    """The coarsest of 1 s, 0.1 s, 0.01 s, 1 ms that every stamp is a multiple of
    (None: finer, or no stamp)."""
    if len(time_ns) == 0:
        return None
    for q_s in (1.0, 0.1, 0.01, 0.001):
        if not np.any(time_ns % int(q_s * NS_PER_S)):
            return q_s
    return None


def spread_shared_stamps(time_ns: IntArray, value: FloatArray) -> tuple[IntArray, int]:
    """Records of one stream (stream order, non-decreasing) that share a stamp, placed
    inside the stamp interval by their order; returns (times, records moved).

    Only a stream whose typical run of equal stamps is two or more (a source faster than
    its stamps) is spread, and only where the records of a run are different samples
    (``value`` changes inside at least 1 % of the runs: a steady heading repeats, a
    turning one does not): two records of one fix with one stamp (a CSV row's position
    twice) never change inside a run and stay together."""
    t = np.asarray(time_ns, np.int64)
    if len(t) < 3:
        return t, 0
    starts = np.flatnonzero(np.r_[True, t[1:] != t[:-1]])
    sizes = np.diff(np.r_[starts, len(t)])
    if len(starts) < 2 or np.median(sizes) < 2:
        return t, 0
    v = np.asarray(value, float)
    changes = (t[1:] == t[:-1]) & (v[1:] != v[:-1])  # a new value under the same stamp
    runs_changing = np.unique(np.searchsorted(starts, np.flatnonzero(changes) + 1, "right"))
    if len(runs_changing) < 0.01 * np.sum(sizes > 1):
        return t, 0
    q_ns = float(np.median(np.diff(t[starts])))
    j = np.arange(len(t)) - np.repeat(starts, sizes)
    m = np.repeat(sizes, sizes)
    out = t + np.rint((j + 0.5) / m * q_ns).astype(np.int64)
    return out, int(sizes[sizes > 1].sum())


def time_of_fix_offset(recv_ns: IntArray, fix_ns: IntArray) -> tuple[float, float, float | None]:
    """(offset_s, sigma_s, drift_ppm) from receive stamps and the source's own times of
    fix: the median of ``recv - fix``; σ the standard error of a median of the spread
    about it (1.2533·1.4826·MAD/√n, with the stamp quantisation as a floor); the drift the
    least-squares slope of ``recv - fix`` against time (None under an hour)."""
    d_s = (np.asarray(recv_ns, np.int64) - np.asarray(fix_ns, np.int64)) / NS_PER_S
    if len(d_s) == 0:
        return math.nan, math.nan, None
    med = float(np.median(d_s))
    mad = float(np.median(np.abs(d_s - med)))
    sigma = 1.2533 * max(1.4826 * mad, 1e-3) / math.sqrt(len(d_s))
    t_s = (np.asarray(fix_ns, np.int64) - int(fix_ns[0])) / NS_PER_S
    drift = None
    if t_s[-1] - t_s[0] >= 3600.0 and len(d_s) >= 10:
        drift = float(np.polyfit(t_s, d_s, 1)[0]) * 1e6
    return med, sigma, drift


def _effective_factor(resid: FloatArray) -> FloatArray:
    """√(n / n_eff) per window from the lag-1 autocorrelation ρ of the residuals:
    n_eff = n (1 - ρ) / (1 + ρ)."""
    r0 = np.sum(resid * resid, axis=1)
    r1 = np.sum(resid[:, 1:] * resid[:, :-1], axis=1)
    rho = np.clip(np.divide(r1, r0, out=np.zeros_like(r0), where=r0 > 0), 0.0, 0.98)
    factor: FloatArray = np.sqrt((1.0 + rho) / (1.0 - rho))
    return factor


def combine(lags: FloatArray, sigmas: FloatArray) -> LagEstimate:
    """Inverse-variance mean of per-window lags; σ widened by √(χ²/dof) when the windows
    disagree beyond their σ (a model that does not hold everywhere)."""
    ok = np.isfinite(lags) & np.isfinite(sigmas) & (sigmas > 0)
    lags, sigmas = lags[ok], sigmas[ok]
    if len(lags) == 0:
        return LagEstimate(math.nan, math.nan, 0)
    # a window far from the median, beyond both its σ and the windows' own spread, is a
    # model failure (a manoeuvre the linear model does not hold through), not data
    med = float(np.median(lags))
    spread = 1.4826 * float(np.median(np.abs(lags - med)))
    keep = np.abs(lags - med) <= 5.0 * np.maximum(sigmas, spread)
    lags, sigmas = lags[keep], sigmas[keep]
    w = 1.0 / sigmas**2
    mean = float(np.sum(w * lags) / np.sum(w))
    sigma = float(1.0 / math.sqrt(np.sum(w)))
    if len(lags) > 1:
        chi2 = float(np.sum(w * (lags - mean) ** 2)) / (len(lags) - 1)
        sigma *= math.sqrt(max(chi2, 1.0))
    return LagEstimate(mean, sigma, int(len(lags)))


def _smooth(x: FloatArray, n: int) -> FloatArray:
    """Centred moving average over ``n`` samples (NaN propagates; edges NaN)."""
    if n <= 1:
        return x
    c = np.convolve(x, np.ones(n) / n, mode="same")
    c[: n // 2] = np.nan
    c[len(c) - n // 2 :] = np.nan
    return c


def rate_lag(
    x: FloatArray,
    ref: FloatArray,
    step_s: float,
    *,
    angle: bool,
    window_s: float = 600.0,
    smooth_s: float = 5.0,
    heading_rad: FloatArray | None = None,
    min_rate: float = 0.0,
    highpass_s: float = 0.0,
) -> LagEstimate:
    """The timing skew Δ = offset_x - offset_ref of two series of one quantity on a common
    grid of ``step_s`` (NaN where missing): ``x - ref = c + b·t [+ a sin ψ + a' cos ψ] - Δ·ṙef``
    per window of ``window_s`` (``heading_rad``: the drift-angle terms, for a heading
    against a course), both smoothed over ``smooth_s`` first (a linear filter keeps the
    lag).  Windows whose rate's spread is below ``min_rate`` carry no information and
    are skipped.  ``highpass_s``: a moving average of this length taken off both ``d``
    and the rate first (the yaw's seconds kept, the compass's slow noise gone).
    ``angle``: the series are angles in radians (unwrapped here)."""
    n_s = max(1, int(round(smooth_s / step_s)))
    if angle:
        x, ref = _unwrap_nan(x), _unwrap_nan(ref)
    xs, rs = _smooth(x, n_s), _smooth(ref, n_s)
    d = xs - rs
    if angle:  # the two unwrapped tracks may start a turn apart
        d = np.angle(np.exp(1j * d))
    rate = np.gradient(rs, step_s)
    if highpass_s:  # slow errors away; the lag relation d = -Δ·rate survives a linear filter
        n_h = max(3, int(round(highpass_s / step_s)) | 1)
        d, rate = d - _smooth(d, n_h), rate - _smooth(rate, n_h)
    per = max(8, int(round(window_s / step_s)))
    nw = len(d) // per
    if nw == 0:
        return LagEstimate(math.nan, math.nan, 0)
    shape = (nw, per)
    dw, rw = d[: nw * per].reshape(shape), rate[: nw * per].reshape(shape)
    tw = np.broadcast_to(np.linspace(-1.0, 1.0, per), shape)
    cols = [np.ones(shape), tw, -rw]
    if heading_rad is not None:
        hw = heading_rad[: nw * per].reshape(shape)
        cols[2:2] = [np.sin(hw), np.cos(hw)]
    X = np.stack(cols, axis=2)
    good = np.isfinite(dw) & np.isfinite(X).all(axis=2)
    lags, sigmas = _window_fits(X, dw, good, min_rate)
    return combine(lags, sigmas)


def _window_fits(
    X: FloatArray, d: FloatArray, good: np.ndarray, min_rate: float
) -> tuple[FloatArray, FloatArray]:
    """Per window: least squares of ``d`` on ``X`` (last column the lag's regressor);
    (coefficient of the last column, its σ), NaN for a window without enough data."""
    nw, per, p = X.shape
    X = np.where(good[..., None], X, 0.0)
    d = np.where(good, d, 0.0)
    n = good.sum(axis=1)
    xtx = np.einsum("wni,wnj->wij", X, X)
    xtd = np.einsum("wni,wn->wi", X, d)
    lags = np.full(nw, np.nan)
    sigmas = np.full(nw, np.nan)
    rate = X[:, :, -1]
    spread = np.sqrt(np.maximum(np.sum(rate * rate, axis=1) / np.maximum(n, 1), 0.0))
    ok = (n >= max(3 * p, per // 2)) & (spread > min_rate)
    ok &= np.linalg.cond(np.where(ok[:, None, None], xtx, np.eye(p))) < 1e10
    if not ok.any():
        return lags, sigmas
    inv = np.linalg.inv(xtx[ok])
    beta = np.einsum("wij,wj->wi", inv, xtd[ok])
    resid = (d[ok] - np.einsum("wni,wi->wn", X[ok], beta)) * good[ok]
    dof = np.maximum(n[ok] - p, 1)
    s2 = np.sum(resid * resid, axis=1) / dof
    lags[ok] = beta[:, -1]
    sigmas[ok] = np.sqrt(s2 * inv[:, -1, -1]) * _effective_factor(resid)
    return lags, sigmas


def _unwrap_nan(a: FloatArray) -> FloatArray:
    """np.unwrap over the finite values, NaN kept in place."""
    out = np.array(a, float)
    ok = np.isfinite(out)
    out[ok] = np.unwrap(out[ok])
    return out


def slopes(t: FloatArray, x: FloatArray) -> FloatArray:
    """dx/dt at each node from the Lagrange polynomial through it and two neighbours on
    each side (fourth order: a 15 s yaw sampled at 1 Hz keeps 99.9 % of its rate where a
    central difference keeps 97 %); three points at the ends, two at a lone pair."""
    n = len(t)
    if n < 5:
        return np.gradient(x, t) if n > 1 else np.zeros(n)
    i = np.arange(2, n - 2)
    nodes = [i + k for k in (-2, -1, 1, 2)]
    ti = t[i]
    out = np.gradient(x, t, edge_order=2)
    deriv = np.zeros(len(i))
    for j in nodes:  # weight of x_j: (1/(t_j - t_i)) prod_{m != i,j} (t_i - t_m)/(t_j - t_m)
        w = 1.0 / (t[j] - ti)
        for m in nodes:
            if m is not j:
                w = w * (ti - t[m]) / (t[j] - t[m])
        deriv += w * x[j]
    self_w = sum(1.0 / (ti - t[m]) for m in nodes)
    out[2:-2] = deriv + self_w * x[i]
    return out


def hermite(t: FloatArray, x: FloatArray, at: FloatArray) -> FloatArray:
    """``x(t)`` (``t`` increasing) at the points ``at`` by cubic Hermite interpolation with
    fourth-order slopes (:func:`slopes`); constant beyond the ends."""
    d = slopes(t, x)
    k = np.clip(np.searchsorted(t, at, side="right") - 1, 0, len(t) - 2)
    h = t[k + 1] - t[k]
    u = np.clip((at - t[k]) / h, 0.0, 1.0)
    u2, u3 = u * u, u * u * u
    out: FloatArray = (
        (2 * u3 - 3 * u2 + 1) * x[k]
        + (u3 - 2 * u2 + u) * h * d[k]
        + (-2 * u3 + 3 * u2) * x[k + 1]
        + (u3 - u2) * h * d[k + 1]
    )
    return out
