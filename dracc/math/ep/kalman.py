"""The Kalman filter over the fixes, run on every point of the model grid at once.

learn_error_model steps the 11-state filter (predict with the exact Gauss-Markov
discretisation, update on each fix with the NIS outlier gate), weighs the grid points by
their cumulative log-likelihood of the innovations, prunes the hopeless ones and keeps the
posterior at each leg start (LearnedModel) and the mixed state at each step
(FilterHistory).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from dracc.core.arrays import ArrayLike, BoolArray, FloatArray, IntArray, unique_sorted
from dracc.core.geodesy import interp_position, offset_ne_m
from dracc.math.current import gauss_markov_noise, transition
from dracc.math.ep.error_model import (
    DELTA,
    EPS,
    N_STATE,
    OUTLIER_NIS,
    PRIOR_WIDENING,
    PRUNE_LOGLIK,
    SCALE,
    TURN_DECORRELATION_RAD,
    ErrorPrior,
    Hyperparameters,
    hyperparameter_grid,
)
from dracc.math.ep.sensitivity import prefix_sum, sensitivity_steps

#: a step whose water track broke: the water-track error p is re-anchored by the next fix
_REANCHOR_M2 = 1e14


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
    W = prefix_sum(np.column_stack([vn[:-1], ve[:-1]]) * dt_good[:, None])
    JI = prefix_sum(sensitivity_steps(t, vn, ve, dt_good))
    bad_before = prefix_sum(~good)  # broken steps before sample k

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
