"""Estimated position over the ground, with a DR error model learned causally from the fixes.

Source: the dead-reckoning paper (seeds/000, B7-B12: the water track plus the current
(Vp, Kp)), the aided dead-reckoning paper (seeds/003: Gauss-Markov errors of the medium
and the sensors estimated from intermittent fixes and blended into the DR); METHODS
sections 2, 3 and 7.

The ship's velocity over the ground is the DR velocity through the water ``v_w`` (B7-B10
without the current) plus what the DR does not know::

    v_g = v_w + cbar + c(t) + n(t) + eps J_eps(t) + s J_s(t)

    cbar    a persistent current (north, east), m/s
    c(t)    the current's variation: first-order Gauss-Markov (sigma_c, tau_c) per axis
    n(t)    short-term velocity noise (log, compass, leeway): Gauss-Markov (sigma_n, tau_n)
    eps     heading error (compass error + leeway), rad: J_eps = d v_w / dC = (-v_E, v_N)
    s       log scale error (fraction):              J_s   = v_w     = ( v_N, v_E)

A Kalman filter with the state ``x = [p, cbar, c, n, eps, s]`` (p: the integral of
``v_g - v_w``, the error of the water track in metres north/east; 10 states) observes
``y = reference position - water track`` every ``step_s``.  Exact discretisation over a
step dt, for each Gauss-Markov process g = c, n (phi = exp(-dt/tau))::

    p+ = p + dt cbar + tau_c (1 - phi_c) c + tau_n (1 - phi_n) n + G [eps, s],  G = int J dt
    g+ = phi g,  Q: the integrated Gauss-Markov process (dracc.math.current.gauss_markov_noise)

The hyper-parameters ``(sigma_c, tau_c, sigma_n, tau_n)``, the fixes' noise and a widening
of the sensor priors are not known: the filter runs for every point of a grid of them at
once (a leading axis), and each point's cumulative log-likelihood of the innovations up to
a time weighs it there (Bayesian model averaging, i.e. maximum likelihood once the data
are many).  A point whose log-likelihood falls PRUNE_LOGLIK below the best is dropped
from the run (its weight is below e^-25 and does not come back).  Everything a leg uses
comes from the fixes *before* its start fix (causal): the posterior at the start, the
weights at the start.

The estimated position of a leg started at a fix at t_s is the fix plus the water track
plus the predicted correction, with h = t - t_s and A(h) = [h I, tau_c (1 - phi_c(h)) I,
tau_n (1 - phi_n(h)) I, G(h)] acting on the posterior of ``(cbar, c, n, eps, s)``::

    mu(h)    = A(h) x_s
    Sigma(h) = A P_s A^T + Q_c(h) + Q_n(h) + sigma_fix^2 I       (per grid point)

and over the grid the moment-matched mixture ``sum w (Sigma + mu mu^T) - mu_bar mu_bar^T``.
So the circle grows with the time since the estimate (the current's uncertainty and its
change), not only with the distance run, and widens where the grid points disagree.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from dracc.core.arrays import ArrayLike, BoolArray, FloatArray, IntArray, unique_sorted
from dracc.core.geodesy import add_offset_ne, interp_position, offset_ne_m, wrap_pi
from dracc.core.units import KN_MPS
from dracc.math.current import gauss_markov_noise, transition
from dracc.math.deadreckoning import DRTrack, covered_span_s
from dracc.math.ellipse import error_ellipse

__all__ = [
    "ErrorPrior",
    "EstimatedPosition",
    "FilterHistory",
    "Hyperparameters",
    "LearnedModel",
    "LegForecast",
    "estimate_position",
    "forecast_legs",
    "heading_prior_rad",
    "hyperparameter_grid",
    "learn_error_model",
    "sensitivities",
]

#: state layout: p (0, 1), cbar (2, 3), c (4, 5), n (6, 7), eps (8), s (9), delta (10)
N_STATE = 11
EPS, SCALE, DELTA = 8, 9, 10
#: the heading-dependent error delta decorrelates over this change of course (rad)
TURN_DECORRELATION_RAD = 1.0
#: the sensor priors (IMO limits) are widened by this factor: real logs are often worse
PRIOR_WIDENING = 3.0
#: a step whose water track broke: the water-track error p is re-anchored by the next fix
_REANCHOR_M2 = 1e14
#: an innovation that even the widest grid point finds this improbable (NIS, 2 dof) is an
#: outlier (a GNSS jump) and is not used
OUTLIER_NIS = 60.0
#: grid points this far below the best log-likelihood leave the run
PRUNE_LOGLIK = 25.0


@dataclass(frozen=True)
class ErrorPrior:
    """What is assumed before anything is learned (1-sigma, SI units)."""

    current_sigma_mps: (
        float  #: persistent current, per axis (a knot or so: honest about not knowing)
    )
    heading_sigma_rad: float  #: compass error + leeway (IMO gyro limit with sec phi, as 95 %)
    scale_sigma: float  #: log scale error (IMO 2 % or 0.2 kn, as 95 %)
    fix_sigma_m: float  #: the reference fixes, per axis (the grid spans 0.3-3 times this)


@dataclass(frozen=True)
class Hyperparameters:
    """The grid of models the filter weighs, each (M,)."""

    current_sigma_mps: FloatArray  #: sigma_c of the current's variation c
    current_tau_s: FloatArray  #: tau_c
    noise_sigma_mps: FloatArray  #: sigma_n of the short-term velocity noise n
    noise_tau_s: FloatArray  #: tau_n
    turn_sigma_rad: FloatArray  #: sigma of the heading-dependent error delta
    fix_sigma_m: FloatArray  #: the reference fixes' noise, per axis

    @property
    def size(self) -> int:
        return int(self.current_sigma_mps.size)

    def take(self, idx: NDArray[Any]) -> Hyperparameters:
        return Hyperparameters(*(getattr(self, f)[idx] for f in self.__dataclass_fields__))

    @property
    def noise_psd_m2ps(self) -> FloatArray:
        """The short-term noise as white noise at horizons beyond tau_n: 2 sigma_n^2 tau_n."""
        return 2.0 * self.noise_sigma_mps**2 * self.noise_tau_s


def hyperparameter_grid(fix_sigma_m: float = 10.0) -> Hyperparameters:
    """The default grid: the current's variation 0.05-1.5 kn over 0.5-8 h; short-term
    noise 0.03-0.3 kn over 1 or 10 min (a log's 0.1 kn over 5 min lies between); a
    heading-dependent error (residual deviation, leeway that changes side with the tack) of
    0 or 1.5 deg; fix noise 0.1, 0.3, 1 or 3 times ``fix_sigma_m``."""
    axes = (
        np.array([0.05, 0.15, 0.5, 1.5]) * KN_MPS,
        np.array([0.5, 2.0, 8.0]) * 3600.0,
        np.array([0.03, 0.1, 0.3]) * KN_MPS,
        np.array([60.0, 600.0]),
        np.array([0.0, 1.5]) * math.pi / 180.0,
        np.array([0.1, 0.3, 1.0, 3.0]) * fix_sigma_m,
    )
    return Hyperparameters(*(a.ravel() for a in np.meshgrid(*axes, indexing="ij")))


#: the sensitivities J are taken from the water velocity averaged over this window
SENSITIVITY_WINDOW_S = 900.0


def _smooth_velocity(
    time_s: ArrayLike, vn: FloatArray, ve: FloatArray, window_s: float = SENSITIVITY_WINDOW_S
) -> tuple[FloatArray, FloatArray]:
    """The water velocity averaged over ``window_s`` (centred, in time).

    The sensitivities must not carry the log's and compass's own noise: J_s = v_w with the
    log noise in it correlates with the very error it is regressed on (the noise is in the
    water track too), and the scale estimate runs away along a straight leg (errors in
    variables).  Averaged over 15 min the noise (correlated over minutes) is mostly gone
    while turns and speed changes stay."""
    t = np.asarray(time_s, float)
    if t.size < 3:
        return vn, ve
    # time as covered by samples: a silence (a step over a minute) counts as none
    dt = np.diff(t)
    dt = np.where(dt <= 60.0, dt, 0.0)
    u = np.concatenate([[0.0], np.cumsum(dt)])
    out = []
    for v in (vn, ve):
        area = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
        lo = np.interp(u - 0.5 * window_s, u, area)
        hi = np.interp(u + 0.5 * window_s, u, area)
        span = np.minimum(u + 0.5 * window_s, u[-1]) - np.maximum(u - 0.5 * window_s, u[0])
        out.append(np.where(span > 0, (hi - lo) / np.where(span > 0, span, 1.0), v))
    return out[0], out[1]


def _sensitivity_steps(t: FloatArray, vn: FloatArray, ve: FloatArray, dt: FloatArray) -> FloatArray:
    """(n-1, 2, 2): J dt over each step, J from the smoothed water velocity held over it."""
    return sensitivities(*_smooth_velocity(t, vn, ve))[:-1] * dt[:, None, None]


def sensitivities(vn_w_mps: ArrayLike, ve_w_mps: ArrayLike) -> FloatArray:
    """(n, 2, 2): d v / d[eps, s] per sample, columns J_eps = (-v_E, v_N), J_s = (v_N, v_E)."""
    vn = np.asarray(vn_w_mps, float)
    ve = np.asarray(ve_w_mps, float)
    return np.stack([np.stack([-ve, vn], -1), np.stack([vn, ve], -1)], -1)


@dataclass(frozen=True)
class FilterHistory:
    """The filter at its steps (after each update), mixed over the grid: for the current plot."""

    time_s: FloatArray  #: (K,)
    current_ne_mps: FloatArray  #: (K, 2): cbar + c
    current_sigma_mps: FloatArray  #: (K,): sqrt of half the trace of its covariance
    heading_error_rad: FloatArray  #: (K,) eps: add to the DR course
    scale_error: FloatArray  #: (K,) s: V_true = (1 + s) V_log
    updated: BoolArray  #: (K,) bool: a fix was used at this step
    #: (K,) the fix's innovation against the DR with its covariance, chi^2_2 for the most
    #: favourable grid model (NaN where no fix or while re-anchoring); a fix above
    #: OUTLIER_NIS is an outlier, left out
    nis: FloatArray | None = None
    #: (K,) the smallest innovation (m, along the worst axis) the outlier gate can see:
    #: sqrt(OUTLIER_NIS * largest eigenvalue of S) of the most favourable model
    gate_m: FloatArray | None = None


@dataclass(frozen=True)
class LearnedModel:
    """The filter's posterior at each leg start (causal) and at the end of the data.

    Grid points left out of the run have weight 0 (and x, P of zero)."""

    hyper: Hyperparameters
    prior: ErrorPrior
    step_s: float
    start_s: FloatArray  #: (L,) leg start times
    weights: FloatArray  #: (L, M) grid weights at each start
    x: FloatArray  #: (L, M, 10) posterior mean at each start
    P: FloatArray  #: (L, M, 10, 10) posterior covariance at each start
    learned_s: FloatArray  #: (L,) span of reference data the start's posterior has seen
    n_updates: IntArray  #: (L,) fixes used before each start
    final_weights: FloatArray  #: (M,)
    final_x: FloatArray  #: (M, 10)
    final_P: FloatArray  #: (M, 10, 10)
    n_outliers: int  #: fixes left out as outliers
    history: FilterHistory


def _weights(loglik: FloatArray) -> FloatArray:
    """Grid weights from cumulative log-likelihoods (..., M), uniform prior over the grid."""
    w = np.exp(loglik - loglik.max(axis=-1, keepdims=True))
    return cast(FloatArray, w / w.sum(axis=-1, keepdims=True))  # np.exp is typed Any


#: F entries ((f_pc, phi) of the current and of the noise) and Q over one step
_StepMatrices = tuple[list[tuple[FloatArray, FloatArray]], FloatArray]


def _step_matrices(d: float, hp: Hyperparameters) -> _StepMatrices:
    """F entries and Q (M, 11, 11) over a step d for the two Gauss-Markov processes."""
    M = hp.size
    Q = np.zeros((M, N_STATE, N_STATE))
    f = []
    for (sig, tau), j in (
        ((hp.current_sigma_mps, hp.current_tau_s), 4),
        ((hp.noise_sigma_mps, hp.noise_tau_s), 6),
    ):
        f_pc, phi = transition(d, tau)
        q_pp, q_pc, q_cc = gauss_markov_noise(d, sig, tau)
        Q[:, 0, 0] += q_pp
        Q[:, 1, 1] += q_pp
        Q[:, 0, j] = Q[:, j, 0] = Q[:, 1, j + 1] = Q[:, j + 1, 1] = q_pc
        Q[:, j, j] = Q[:, j + 1, j + 1] = q_cc
        f.append((f_pc, phi))
    return f, Q


def learn_error_model(
    time_s: ArrayLike,
    vn_w_mps: ArrayLike,
    ve_w_mps: ArrayLike,
    step_ok: ArrayLike,
    ref_time_s: ArrayLike,
    ref_lat_rad: ArrayLike,
    ref_lon_rad: ArrayLike,
    leg_start_s: ArrayLike,
    prior: ErrorPrior,
    *,
    hyper: Hyperparameters | None = None,
    step_s: float = 300.0,
    ref_max_gap_s: float = 5.0,
) -> LearnedModel:
    """Run the filter over the voyage on every grid point; keep its posterior at each leg start.

    time_s (n,) the DR grid; vn_w_mps, ve_w_mps (n,) the velocity through the water (NaN
    where the DR has none); step_ok (n-1,) steps the water track runs over; the reference
    (GNSS or INS mean) positions; leg_start_s (L,) the DR's leg start times (samples of
    time_s).  The filter steps every ``step_s`` and at each leg start.
    """
    hp_all = hyper if hyper is not None else hyperparameter_grid(prior.fix_sigma_m)
    t = np.asarray(time_s, float)
    n = t.size
    vn = np.nan_to_num(np.asarray(vn_w_mps, float))
    ve = np.nan_to_num(np.asarray(ve_w_mps, float))
    good = (
        np.asarray(step_ok, bool)
        & np.isfinite(np.asarray(vn_w_mps, float)[:-1])
        & np.isfinite(np.asarray(ve_w_mps, float)[:-1])
    )
    # water track W (metres) and int J dt, from the velocity held over each step (B20)
    dt_good = np.where(good, np.diff(t), 0.0)
    W = _prefix_sum(np.column_stack([vn[:-1], ve[:-1]]) * dt_good[:, None])
    JI = _prefix_sum(_sensitivity_steps(t, vn, ve, dt_good))
    bad_before = _prefix_sum(~good)  # broken steps before sample k

    starts = np.asarray(leg_start_s, float)
    # filter steps: the first sample of every step_s from the first leg's start (nothing is
    # learned before it: no fix), each leg start and the last sample; silences get no steps
    t_first = starts[0] if starts.size else t[0]
    after = np.flatnonzero(t >= t_first)
    bins = np.floor((t[after] - t_first) / step_s)
    firsts = after[np.r_[True, bins[1:] != bins[:-1]]] if after.size else after
    kf = unique_sorted(np.concatenate([firsts, np.searchsorted(t, starts), [n - 1]]).clip(0, n - 1))
    tf = t[kf]
    rlat, rlon = interp_position(
        np.asarray(ref_time_s, float), ref_lat_rad, ref_lon_rad, tf, ref_max_gap_s
    )
    has_ref = np.isfinite(rlat) & np.isfinite(rlon)
    # observation y = reference - water track, chained over small steps (local metres)
    y = np.full((tf.size, 2), np.nan)
    iv = np.flatnonzero(has_ref)
    if iv.size:
        dn, de = offset_ne_m(rlat[iv[1:]], rlon[iv[1:]], rlat[iv[:-1]], rlon[iv[:-1]])
        d = np.column_stack([dn, de]) - (W[kf[iv[1:]]] - W[kf[iv[:-1]]])
        y[iv] = np.concatenate([np.zeros((1, 2)), np.cumsum(d, axis=0)])

    M_all = hp_all.size
    active = np.arange(M_all)
    hp = hp_all
    x = np.zeros((M_all, N_STATE))
    P = np.zeros((M_all, N_STATE, N_STATE))
    P[:, 0, 0] = P[:, 1, 1] = _REANCHOR_M2
    P[:, 2, 2] = P[:, 3, 3] = prior.current_sigma_mps**2
    P[:, 4, 4] = P[:, 5, 5] = hp.current_sigma_mps**2
    P[:, 6, 6] = P[:, 7, 7] = hp.noise_sigma_mps**2
    P[:, EPS, EPS] = (prior.heading_sigma_rad * PRIOR_WIDENING) ** 2
    P[:, SCALE, SCALE] = (prior.scale_sigma * PRIOR_WIDENING) ** 2
    P[:, DELTA, DELTA] = hp.turn_sigma_rad**2
    loglik = np.zeros(M_all)

    start_idx = np.searchsorted(tf, starts)
    want = np.zeros(tf.size, bool)
    want[start_idx[start_idx < tf.size]] = True
    snaps: dict[int, tuple[NDArray[Any], FloatArray, FloatArray, FloatArray, float, int]] = {}
    first_ref_t = math.nan
    n_upd = 0
    n_out = 0
    K_ = tf.size
    h_cur = np.zeros((K_, 2))
    h_sig = np.zeros(K_)
    h_eps = np.zeros(K_)
    h_s = np.zeros(K_)
    h_upd = np.zeros(K_, bool)
    h_nis = np.full(K_, np.nan)
    h_gate = np.full(K_, np.nan)
    d_all = np.diff(tf)
    G_all = JI[kf[1:]] - JI[kf[:-1]]
    # course change between consecutive filter steps (mean water course over each step)
    dW = W[kf[1:]] - W[kf[:-1]]
    course = np.arctan2(dW[:, 1], dW[:, 0])
    turn = np.abs(np.angle(np.exp(1j * np.diff(course, prepend=course[:1]))))
    turn = np.where(np.hypot(dW[:, 0], dW[:, 1]) > 1.0, turn, 0.0)
    rho_turn = np.exp(-turn / TURN_DECORRELATION_RAD)
    broke = bad_before[kf[1:]] > bad_before[kf[:-1]]
    cache: dict[float, _StepMatrices] = {}
    eye2 = np.eye(2)

    def new_F() -> FloatArray:
        F = np.zeros((active.size, N_STATE, N_STATE))
        F[:, range(N_STATE), range(N_STATE)] = 1.0
        return F

    F = new_F()
    for i in range(K_):
        if i > 0:
            d = float(d_all[i - 1])
            if d not in cache:
                cache[d] = _step_matrices(d, hp)
            ((fc, phic), (fn, phin)), Q = cache[d]
            F[:, 0:2, 2:4] = d * eye2
            F[:, 0, 4] = F[:, 1, 5] = fc
            F[:, 4, 4] = F[:, 5, 5] = phic
            F[:, 0, 6] = F[:, 1, 7] = fn
            F[:, 6, 6] = F[:, 7, 7] = phin
            F[:, 0:2, 8:10] = G_all[i - 1]
            F[:, 0:2, DELTA] = G_all[i - 1][:, 0]
            F[:, DELTA, DELTA] = rho_turn[i - 1]
            x = np.matmul(F, x[:, :, None])[:, :, 0]
            P = F @ P @ F.transpose(0, 2, 1) + Q
            P[:, DELTA, DELTA] += hp.turn_sigma_rad**2 * (1.0 - rho_turn[i - 1] ** 2)
            if broke[i - 1]:
                P[:, 0, 0] += _REANCHOR_M2
                P[:, 1, 1] += _REANCHOR_M2
        if has_ref[i]:
            nu = y[i] - x[:, 0:2]
            S = P[:, 0:2, 0:2] + (hp.fix_sigma_m**2)[:, None, None] * eye2
            det = S[:, 0, 0] * S[:, 1, 1] - S[:, 0, 1] ** 2
            Si = np.empty_like(S)
            Si[:, 0, 0] = S[:, 1, 1] / det
            Si[:, 1, 1] = S[:, 0, 0] / det
            Si[:, 0, 1] = Si[:, 1, 0] = -S[:, 0, 1] / det
            nis = (
                Si[:, 0, 0] * nu[:, 0] ** 2
                + 2 * Si[:, 0, 1] * nu[:, 0] * nu[:, 1]
                + Si[:, 1, 1] * nu[:, 1] ** 2
            )
            reanchor = P[0, 0, 0] > 0.5 * _REANCHOR_M2
            if not reanchor:
                best = int(np.argmin(nis))
                h_nis[i] = nis[best]
                tr, dt_ = S[best, 0, 0] + S[best, 1, 1], det[best]
                h_gate[i] = math.sqrt(
                    OUTLIER_NIS * 0.5 * (tr + math.sqrt(max(tr * tr - 4 * dt_, 0.0)))
                )
            if not reanchor and nis.min() > OUTLIER_NIS:
                n_out += 1
            else:
                Kg = P[:, :, 0:2] @ Si
                x = x + np.matmul(Kg, nu[:, :, None])[:, :, 0]
                P = P - Kg @ P[:, 0:2, :]
                P = 0.5 * (P + P.transpose(0, 2, 1))
                if not reanchor:
                    loglik = loglik - 0.5 * (nis + np.log(det)) - math.log(2 * math.pi)
                if not math.isfinite(first_ref_t):
                    first_ref_t = tf[i]
                n_upd += 1
                h_upd[i] = True
        w = _weights(loglik)
        c_mix = x[:, 2:4] + x[:, 4:6]
        h_cur[i] = w @ c_mix
        cov_c = P[:, 2:4, 2:4] + P[:, 4:6, 4:6] + P[:, 2:4, 4:6] + P[:, 4:6, 2:4]
        spread = np.sum((c_mix - h_cur[i]) ** 2, axis=1)
        h_sig[i] = math.sqrt(max(0.5 * float(w @ (cov_c[:, 0, 0] + cov_c[:, 1, 1] + spread)), 0.0))
        h_eps[i] = float(w @ x[:, EPS])
        h_s[i] = float(w @ x[:, SCALE])
        if want[i]:
            span = tf[i] - first_ref_t if math.isfinite(first_ref_t) else 0.0
            snaps[i] = (active.copy(), w, x.copy(), P.copy(), span, n_upd)
        keep = loglik >= loglik.max() - PRUNE_LOGLIK
        if not keep.all():
            active, x, P, loglik = active[keep], x[keep], P[keep], loglik[keep]
            hp = hp_all.take(active)
            cache = {
                k: ([(a[keep], b[keep]) for a, b in f], Q[keep]) for k, (f, Q) in cache.items()
            }
            F = new_F()
    L = starts.size
    weights = np.zeros((L, M_all))
    xs = np.zeros((L, M_all, N_STATE))
    Ps = np.zeros((L, M_all, N_STATE, N_STATE))
    learned = np.zeros(L)
    nu_before = np.zeros(L, np.int64)
    for j, i in enumerate(start_idx):
        act, w, xx, PP, span, nn = snaps[int(min(i, tf.size - 1))]
        weights[j, act], xs[j, act], Ps[j, act] = w, xx, PP
        learned[j], nu_before[j] = span, nn
    fw = np.zeros(M_all)
    fx = np.zeros((M_all, N_STATE))
    fP = np.zeros((M_all, N_STATE, N_STATE))
    fw[active], fx[active], fP[active] = _weights(loglik), x, P
    hist = FilterHistory(
        time_s=tf,
        current_ne_mps=h_cur,
        current_sigma_mps=h_sig,
        heading_error_rad=h_eps,
        scale_error=h_s,
        updated=h_upd,
        nis=h_nis,
        gate_m=h_gate,
    )
    return LearnedModel(
        hyper=hp_all,
        prior=prior,
        step_s=float(step_s),
        start_s=starts,
        weights=weights,
        x=xs,
        P=Ps,
        learned_s=learned,
        n_updates=nu_before,
        final_weights=fw,
        final_x=fx,
        final_P=fP,
        n_outliers=n_out,
        history=hist,
    )


def _prefix_sum(a: NDArray[Any]) -> FloatArray:
    """Cumulative sums along axis 0 with a leading zero: sums over [i, k) are S[k] - S[i]."""
    return np.concatenate([np.zeros((1,) + a.shape[1:]), np.cumsum(a, axis=0)])


def _significant(w: FloatArray, mass: float = 1.0 - 1e-4) -> NDArray[np.intp]:
    """Indices of the largest weights that together hold ``mass`` of the total."""
    order = np.argsort(w)[::-1]
    n = int(np.searchsorted(np.cumsum(w[order]), mass * w.sum())) + 1
    return np.sort(order[:n])


@dataclass(frozen=True)
class LegForecast:
    """The EP's correction to the water track and its covariance, per DR sample."""

    offset_ne_m: FloatArray  #: (n, 2) mu: add to the water track
    P_m2: FloatArray  #: (n, 2, 2) covariance of the EP error, metres north/east
    inflation: FloatArray  #: (L, 3) the factor on each leg's covariance, in thirds of its horizon
    leg_nees: (
        FloatArray  #: (L, 3) mean NEES/2 of each leg against the reference, per third (raw model)
    )
    components_m2: dict[
        str, FloatArray
    ]  #: name -> (n,) trace contribution (fix, current, current change, heading, log scale, noise)


#: covariance matching over earlier legs: prior weight (in legs) of an inflation of 1, the
#: forgetting factor per leg, the cap on one leg's mean NEES/2, and the factor's bounds
INFLATION_PRIOR_LEGS = 3.0
INFLATION_FORGET = 0.95
INFLATION_LEG_CAP = 25.0
INFLATION_BOUNDS = (0.25, 25.0)
#: the factor is learned in this many equal parts of the reset interval
INFLATION_BINS = 3


def _horizon_span(model: LearnedModel) -> float:
    starts = model.start_s
    return float(np.median(np.diff(starts))) if starts.size > 1 else 3600.0


def _horizon_bin(h: FloatArray, model: LearnedModel) -> NDArray[np.int_]:
    bins: NDArray[np.int_] = np.clip(
        (np.asarray(h) / _horizon_span(model) * INFLATION_BINS).astype(int), 0, INFLATION_BINS - 1
    )
    return bins


def _inflation_at(h: FloatArray, factors: FloatArray, model: LearnedModel) -> FloatArray:
    """The factor at horizons h: linear between the parts' centres, constant beyond."""
    span = _horizon_span(model)
    centres = (np.arange(INFLATION_BINS) + 0.5) * span / INFLATION_BINS
    return np.interp(h, centres, factors)


def forecast_legs(
    time_s: ArrayLike,
    vn_w_mps: ArrayLike,
    ve_w_mps: ArrayLike,
    leg_of: ArrayLike,
    model: LearnedModel,
    *,
    ref_offset_ne_m: ArrayLike | None = None,
    horizon_step_s: float = 60.0,
) -> LegForecast:
    """The EP correction and covariance at every sample of every leg (see module docstring).

    ``ref_offset_ne_m`` (n, 2): the reference minus the water track at each sample (NaN
    where there is none).  With it, each leg's covariance is multiplied by a factor
    learned from the legs that ended before it started (covariance matching): the mean
    over those legs of their mean NEES/2 against the reference, shrunk towards 1 by
    INFLATION_PRIOR_LEGS legs and forgetting older legs by INFLATION_FORGET per leg.  It
    corrects what the one-step likelihood of the grid cannot see, how fast the error
    really grows over a leg.
    """
    t = np.asarray(time_s, float)
    n = t.size
    vn = np.nan_to_num(np.asarray(vn_w_mps, float))
    ve = np.nan_to_num(np.asarray(ve_w_mps, float))
    J = _sensitivity_steps(t, vn, ve, np.diff(t))
    JI = _prefix_sum(J)
    leg_of = np.asarray(leg_of)
    course = np.arctan2(ve, vn)  # for the heading-dependent error
    J_eps = J[:, :, 0]
    off = np.full((n, 2), np.nan)
    Pout = np.full((n, 2, 2), np.nan)
    names = ("fix", "current", "current change", "heading", "log scale", "noise")
    comp = {k: np.full(n, np.nan) for k in names}
    n_legs = model.start_s.size
    nb = INFLATION_BINS
    inflation = np.ones((n_legs, nb))
    leg_nees = np.full((n_legs, nb), np.nan)
    leg_end = model.start_s.astype(float).copy()  # a leg without samples ends at its start
    acc_num = np.full(nb, INFLATION_PRIOR_LEGS)
    acc_den = np.full(nb, INFLATION_PRIOR_LEGS)
    folded = 0
    for leg in range(n_legs):
        sel = np.flatnonzero(leg_of == leg)
        # the legs that ended before this one started (legs run in time order): fold them in
        while folded < leg and leg_end[folded] <= model.start_s[leg]:
            has = np.isfinite(leg_nees[folded])
            acc_num[has] = (
                INFLATION_PRIOR_LEGS
                + INFLATION_FORGET * (acc_num[has] - INFLATION_PRIOR_LEGS)
                + np.minimum(leg_nees[folded][has], INFLATION_LEG_CAP)
            )
            acc_den[has] = (
                INFLATION_PRIOR_LEGS
                + INFLATION_FORGET * (acc_den[has] - INFLATION_PRIOR_LEGS)
                + 1.0
            )
            folded += 1
        # the factor has an inverse-gamma posterior (shape acc_den: one per leg, whose mean
        # NEES/2 is Exp(1) when the model is right; scale acc_num); the position's
        # predictive is then Student-t with the variance acc_num / (acc_den - 1)
        inflation[leg] = np.clip(acc_num / (acc_den - 1.0), *INFLATION_BOUNDS)
        if sel.size == 0:
            continue
        k0, k1 = sel[0], sel[-1]
        t0 = t[k0]
        leg_end[leg] = t[k1]
        step = min(horizon_step_s, max((t[sel[-1]] - t0) / 20.0, 1.0))
        th = unique_sorted(
            np.concatenate([np.arange(0.0, t[sel[-1]] - t0, step), [t[sel[-1]] - t0]])
        )
        kh = np.clip(np.searchsorted(t, t0 + th), 0, n - 1)
        G = JI[kh] - JI[k0]  # (H, 2, 2)
        keep = _significant(model.weights[leg])
        w = model.weights[leg][keep]
        w = w / w.sum()
        hp = model.hyper.take(keep)
        fc, _ = transition(th[:, None], hp.current_tau_s[None, :])  # (H, m)
        fn, _ = transition(th[:, None], hp.noise_tau_s[None, :])
        H, m = th.size, keep.size
        # the heading-dependent error: its value at the start counts as far as the course
        # stays near the start course (Gr), a new one takes over as it turns away (Gn)
        rho = np.exp(-np.abs(wrap_pi(course[k0:k1] - course[k0])) / TURN_DECORRELATION_RAD)
        Gr = _prefix_sum(J_eps[k0:k1] * rho[:, None])[kh - k0]
        Gn = _prefix_sum(J_eps[k0:k1] * np.sqrt(1.0 - rho**2)[:, None])[kh - k0]
        A = np.zeros((H, m, 2, 9))
        A[:, :, 0, 0] = A[:, :, 1, 1] = th[:, None]
        A[:, :, 0, 2] = A[:, :, 1, 3] = fc
        A[:, :, 0, 4] = A[:, :, 1, 5] = fn
        A[:, :, :, 6:8] = G[:, None]
        A[:, :, :, 8] = Gr[:, None]
        xs = model.x[leg][keep, 2:]  # (m, 9)
        Ps = model.P[leg][keep, 2:, 2:]  # (m, 9, 9)
        mu = np.matmul(A, xs[None, :, :, None])[..., 0]  # (H, m, 2)
        AP = np.matmul(A, Ps[None])  # (H, m, 2, 9)
        S = np.matmul(AP, A.transpose(0, 1, 3, 2))
        qc, _, _ = gauss_markov_noise(
            th[:, None], hp.current_sigma_mps[None, :], hp.current_tau_s[None, :]
        )
        qn, _, _ = gauss_markov_noise(
            th[:, None], hp.noise_sigma_mps[None, :], hp.noise_tau_s[None, :]
        )
        R = hp.fix_sigma_m**2
        S[..., 0, 0] += qc + qn + R
        S[..., 1, 1] += qc + qn + R
        turn_new = (hp.turn_sigma_rad**2)[None, :, None, None] * (Gn[:, :, None] * Gn[:, None, :])[
            :, None
        ]
        S += turn_new
        mu_mix = np.einsum("m,hmi->hi", w, mu)
        dev = mu - mu_mix[:, None, :]
        S_mix = np.einsum("m,hmij->hij", w, S + dev[..., :, None] * dev[..., None, :])
        # the trace split by state: tr(A P A^T) = sum_j sum_i (A P)_ij A_ij, grouped by
        # column j (cross-covariances shared between their two columns); for naming what
        # dominates a miss
        by_col = np.einsum("hmj,m->hj", np.sum(AP * A, axis=2), w)  # (H, 9)
        contrib = {
            "fix": np.full(H, 2 * float(R @ w)),
            "current": by_col[:, 0:4].sum(axis=1) + np.einsum("m,hmi->h", w, dev**2),
            "current change": 2 * qc @ w,
            "heading": by_col[:, 6] + by_col[:, 8] + np.trace(turn_new, axis1=2, axis2=3) @ w,
            "log scale": by_col[:, 7],
            "noise": 2 * qn @ w + by_col[:, 4:6].sum(axis=1),
        }
        ts = t[sel] - t0
        if ref_offset_ne_m is not None:
            yr = np.asarray(ref_offset_ne_m)[kh]
            ok = np.isfinite(yr).all(axis=1) & (th > 0)
            if ok.any():
                e = mu_mix[ok] - yr[ok]
                Sk = S_mix[ok]
                det = Sk[:, 0, 0] * Sk[:, 1, 1] - Sk[:, 0, 1] ** 2
                nees = (
                    Sk[:, 1, 1] * e[:, 0] ** 2
                    - 2 * Sk[:, 0, 1] * e[:, 0] * e[:, 1]
                    + Sk[:, 0, 0] * e[:, 1] ** 2
                ) / det
                b = _horizon_bin(th[ok], model)
                for q in range(nb):
                    if np.any(b == q):
                        leg_nees[leg, q] = float(np.mean(nees[b == q])) / 2.0
        lam = _inflation_at(th, inflation[leg], model)
        S_mix = S_mix * lam[:, None, None]
        for j in range(2):
            off[sel, j] = np.interp(ts, th, mu_mix[:, j])
            for k in range(2):
                Pout[sel, j, k] = np.interp(ts, th, S_mix[:, j, k])
        for name, v in contrib.items():
            comp[name][sel] = np.interp(ts, th, v * lam)
    return LegForecast(
        offset_ne_m=off, P_m2=Pout, components_m2=comp, inflation=inflation, leg_nees=leg_nees
    )


def heading_prior_rad(
    compass_bias_rad: float, leeway_rad: float, lat_rad: float, gyro: bool
) -> float:
    """Prior of the heading error: the compass bias (gyro: x sec phi, METHODS section 6)
    combined with the leeway."""
    sec = 1.0 / max(math.cos(lat_rad), 0.1) if gyro else 1.0
    return math.hypot(compass_bias_rad * sec, leeway_rad)


#: a leg is scored out of sample when its start's posterior has seen at least this span of
#: reference data (or one reset interval, if shorter) and MIN_LEARNED_UPDATES fixes
MIN_LEARNED_S = 1800.0
MIN_LEARNED_UPDATES = 3


@dataclass(frozen=True)
class EstimatedPosition:
    """The EP track (a DRTrack with the current and corrections applied) and how it was learned."""

    track: DRTrack  #: positions, P, 2M of the estimated position
    water: DRTrack  #: the water track (no current, no corrections), as dead_reckon gave it
    model: LearnedModel
    forecast: LegForecast
    learned_leg: BoolArray  #: (L,) bool: the leg's model was learned from earlier fixes
    reference_sigma_m: float  #: the fixes' noise per axis, as learned over the whole voyage


def step_ok_of(track: DRTrack) -> BoolArray:
    """(n-1,) steps along which the water track runs continuously (resets included, breaks not)."""
    leg = track.leg
    on = (leg[:-1] >= 0) & (leg[1:] >= 0)
    new_leg = leg[1:] != leg[:-1]
    reasons = np.asarray(track.leg_start_reason + ("",), dtype=object)
    after_gap = new_leg & (reasons[np.where(leg[1:] >= 0, leg[1:], -1)] == "after-gap")
    return cast(BoolArray, on & ~after_gap)  # == on an object array is typed Any


def estimate_position(
    track: DRTrack,
    ref_time_s: ArrayLike,
    ref_lat_rad: ArrayLike,
    ref_lon_rad: ArrayLike,
    prior: ErrorPrior,
    *,
    ref_max_gap_s: float = 5.0,
    step_s: float | None = None,
    hyper: Hyperparameters | None = None,
) -> EstimatedPosition:
    """The estimated position of every leg of a water-track DR, learned causally (module doc).

    ``step_s``: the filter's step; by default 300 s, shorter for logs under 8 h 20 min
    (at least 100 steps, at least 5 s).
    """
    t = track.time_s
    span = covered_span_s(t, 60.0)
    if step_s is None:
        step_s = float(np.clip(span / 100.0, 5.0, 300.0))
    model = learn_error_model(
        t,
        track.vn_mps,
        track.ve_mps,
        step_ok_of(track),
        ref_time_s,
        ref_lat_rad,
        ref_lon_rad,
        track.leg_start_s,
        prior,
        hyper=hyper,
        step_s=step_s,
        ref_max_gap_s=ref_max_gap_s,
    )
    rlat, rlon = interp_position(
        np.asarray(ref_time_s, float), ref_lat_rad, ref_lon_rad, t, ref_max_gap_s
    )
    y_n, y_e = offset_ne_m(rlat, rlon, track.lat_rad, track.lon_rad)
    fc = forecast_legs(
        t, track.vn_mps, track.ve_mps, track.leg, model, ref_offset_ne_m=np.column_stack([y_n, y_e])
    )
    on = track.leg >= 0
    lat = np.full(t.size, np.nan)
    lon = np.full(t.size, np.nan)
    lat[on], lon[on] = add_offset_ne(
        track.lat_rad[on], track.lon_rad[on], fc.offset_ne_m[on, 0], fc.offset_ne_m[on, 1]
    )
    P = fc.P_m2
    radius = 2.0 * np.sqrt(P[:, 0, 0] + P[:, 1, 1])  # (B30), (B31)
    smaj, smin, orient = error_ellipse(np.nan_to_num(P))
    nan = ~np.isfinite(radius)
    smaj, smin, orient = (np.where(nan, np.nan, a) for a in (smaj, smin, orient))
    ep = replace(
        track,
        lat_rad=lat,
        lon_rad=lon,
        P_m2=P,
        radius_2m_m=radius,
        semi_major_m=smaj,
        semi_minor_m=smin,
        orientation_rad=orient,
    )
    need_s = min(MIN_LEARNED_S, track.reset_s)
    learned = (model.learned_s >= need_s) & (model.n_updates >= MIN_LEARNED_UPDATES)
    ref_sigma = math.sqrt(float(model.final_weights @ model.hyper.fix_sigma_m**2))
    return EstimatedPosition(
        track=ep,
        water=track,
        model=model,
        forecast=fc,
        learned_leg=learned,
        reference_sigma_m=ref_sigma,
    )
