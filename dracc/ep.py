"""Estimated position over the ground, with a DR error model learned causally from the fixes.

Source: the dead-reckoning paper (seeds/000, B7-B12: the water track plus the current
(Vp, Kp)), the aided dead-reckoning paper (seeds/003: a Gauss-Markov medium estimated
from intermittent fixes and blended into the DR); METHODS sections 2, 3 and 7.

The ship's velocity over the ground is the DR velocity through the water ``v_w`` (B7-B10
without the current) plus what the DR does not know::

    v_g = v_w + cbar + c'(t) + eps J_eps(t) + s J_s(t) + n(t)

    cbar        a persistent current (north, east), m/s
    c'(t)       its variation: first-order Gauss-Markov (sigma_c, tau_c) per axis
    eps         heading error (compass error + leeway), rad: J_eps = d v_w / dC = (-v_E, v_N)
    s           log scale error (fraction):              J_s   = v_w     = ( v_N, v_E)
    n(t)        white velocity noise of spectral density q_n (m^2/s) per axis: the log's,
                compass's and leeway's short-correlated noise

A Kalman filter with the state ``x = [p_N, p_E, cbar_N, cbar_E, c'_N, c'_E, eps, s]``,
``p`` the integral of ``v_g - v_w`` (the error of the water track, metres), observes
``y = reference position - water track`` at steps of ``step_s``.  Its exact
discretisation over a step of dt (phi = exp(-dt/tau_c))::

    p+    = p + dt cbar + tau_c (1 - phi) c' + G eps_s     G = int J dt over the step
    c'+   = phi c'
    Q: the integrated Gauss-Markov current (dracc.current._current_noise) + q_n dt on p

The hyper-parameters ``(sigma_c, tau_c, q_n)`` and a widening of the sensor priors are not
known; the filter runs for every point of a grid of them at once (a leading axis), and
each point's cumulative log-likelihood of the innovations up to a time weighs it there
(Bayesian model averaging, i.e. maximum likelihood when the data are many).  Everything
a leg uses comes from the fixes *before* its start fix (causal): the posterior of
``(cbar, c', eps, s)`` at the start, the weights at the start.

The estimated position of a leg started at a fix at t_s is the fix plus the water track
plus the predicted correction ``mu(h) = h cbar + tau_c (1 - phi(h)) c' + G(h) [eps, s]``,
``h = t - t_s``; its covariance, per grid point m,
``A P_s A^T + Q_current(h) + q_n h I + sigma_fix^2 I`` with ``A = [h I, tau_c(1-phi) I, G(h)]``,
and over the grid the moment-matched mixture ``sum w_m (Sigma_m + mu_m mu_m^T) - mu mu^T``.
So the circle grows with the time since the estimate (the current's uncertainty and its
change), not only with the distance run, and it widens where the grid points disagree.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .current import _current_noise, transition
from .deadreckoning import DRTrack, error_ellipse
from .geodesy import add_offset_ne, interp_position, offset_ne_m
from .units import KN_MPS

__all__ = [
    "ErrorPrior",
    "EstimatedPosition",
    "estimate_position",
    "Hyperparameters",
    "LearnedModel",
    "LegForecast",
    "FilterHistory",
    "hyperparameter_grid",
    "learn_error_model",
    "forecast_legs",
    "sensitivities",
]

#: state layout
P_, CBAR, CVAR, EPS, SCALE = slice(0, 2), slice(2, 4), slice(4, 6), 6, 7
N_STATE = 8
#: a step whose water track broke: the water-track error p is re-anchored by the next fix
_REANCHOR_M2 = 1e14
#: an innovation that even the widest grid point finds this improbable (NIS, 2 dof) is an
#: outlier (a GNSS jump) and is not used
OUTLIER_NIS = 60.0


@dataclass(frozen=True)
class ErrorPrior:
    """What is assumed before anything is learned (1-sigma, SI units)."""

    current_sigma_mps: float  #: persistent current, per axis (a knot or so: honest about not knowing)
    heading_sigma_rad: float  #: compass error + leeway (IMO gyro limit with sec phi, as 95 %)
    scale_sigma: float  #: log scale error (IMO 2 % or 0.2 kn, as 95 %)
    fix_sigma_m: float  #: the reference fixes, per axis


@dataclass(frozen=True)
class Hyperparameters:
    """The grid of models the filter weighs, each (M,)."""

    current_sigma_mps: np.ndarray  #: sigma_c of the current's variation c'
    current_tau_s: np.ndarray  #: tau_c
    noise_psd_m2ps: np.ndarray  #: q_n
    prior_widening: np.ndarray  #: factor on the heading and scale priors

    @property
    def size(self) -> int:
        return int(self.current_sigma_mps.size)


def hyperparameter_grid() -> Hyperparameters:
    """The default grid: current variation 0.05-1.5 kn over 0.5-8 h, white velocity noise
    of 0.3-30 m^2/s (0.1 kn over 5 min is 1.6 m^2/s), sensor priors as given or 4x wider."""
    sig = np.array([0.05, 0.15, 0.5, 1.5]) * KN_MPS
    tau = np.array([0.5, 2.0, 8.0]) * 3600.0
    q = np.array([0.3, 3.0, 30.0])
    wide = np.array([1.0, 4.0])
    g = np.meshgrid(sig, tau, q, wide, indexing="ij")
    return Hyperparameters(*(a.ravel() for a in g))


def sensitivities(vn_w_mps, ve_w_mps):
    """(n, 2, 2): d v / d[eps, s] per sample, columns J_eps = (-v_E, v_N), J_s = (v_N, v_E)."""
    vn = np.asarray(vn_w_mps, float)
    ve = np.asarray(ve_w_mps, float)
    return np.stack([np.stack([-ve, vn], -1), np.stack([vn, ve], -1)], -1)


@dataclass(frozen=True)
class FilterHistory:
    """The filter at its steps (after each update), mixed over the grid: for the current plot."""

    time_s: np.ndarray  #: (K,)
    current_ne_mps: np.ndarray  #: (K, 2): cbar + c'
    current_sigma_mps: np.ndarray  #: (K,): sqrt of half the trace of its covariance
    heading_error_rad: np.ndarray  #: (K,) eps: add to the DR course
    scale_error: np.ndarray  #: (K,) s: V_true = (1 + s) V_log
    updated: np.ndarray  #: (K,) bool: a fix was used at this step


@dataclass(frozen=True)
class LearnedModel:
    """The filter's posterior at each leg start (causal) and at the end of the data."""

    hyper: Hyperparameters
    prior: ErrorPrior
    step_s: float
    start_s: np.ndarray  #: (L,) leg start times
    weights: np.ndarray  #: (L, M) grid weights at each start
    x: np.ndarray  #: (L, M, 8) posterior mean at each start
    P: np.ndarray  #: (L, M, 8, 8) posterior covariance at each start
    learned_s: np.ndarray  #: (L,) span of reference data the start's posterior has seen
    n_updates: np.ndarray  #: (L,) fixes used before each start
    final_weights: np.ndarray  #: (M,)
    final_x: np.ndarray  #: (M, 8)
    final_P: np.ndarray  #: (M, 8, 8)
    n_outliers: int  #: fixes left out as outliers
    history: FilterHistory


def _mix_mean(w, x):
    return np.einsum("...m,...mi->...i", w, x)


def learn_error_model(time_s, vn_w_mps, ve_w_mps, step_ok, ref_time_s, ref_lat_rad, ref_lon_rad,
                      leg_start_s, prior: ErrorPrior, *, hyper: Hyperparameters | None = None,
                      step_s: float = 300.0, ref_max_gap_s: float = 5.0) -> LearnedModel:
    """Run the filter over the voyage on every grid point; keep its posterior at each leg start.

    time_s (n,) the DR grid; vn_w_mps, ve_w_mps (n,) the velocity through the water (NaN
    where the DR has none); step_ok (n-1,) steps the water track runs over; the reference
    (GNSS or INS mean) positions; leg_start_s (L,) the DR's leg start times (samples of
    time_s).  The filter steps every ``step_s`` and at each leg start.
    """
    hp = hyper if hyper is not None else hyperparameter_grid()
    t = np.asarray(time_s, float)
    n = t.size
    vn = np.nan_to_num(np.asarray(vn_w_mps, float))
    ve = np.nan_to_num(np.asarray(ve_w_mps, float))
    good = np.asarray(step_ok, bool) & np.isfinite(np.asarray(vn_w_mps, float)[:-1]) \
        & np.isfinite(np.asarray(ve_w_mps, float)[:-1])
    dt = np.diff(t)
    # water track W (metres) and int J dt, from the velocity held over each step (B20)
    W = np.zeros((n, 2))
    W[1:, 0] = np.cumsum(np.where(good, vn[:-1], 0.0) * dt)
    W[1:, 1] = np.cumsum(np.where(good, ve[:-1], 0.0) * dt)
    J = sensitivities(vn[:-1], ve[:-1]) * np.where(good, dt, 0.0)[:, None, None]
    JI = np.concatenate([np.zeros((1, 2, 2)), np.cumsum(J, axis=0)])
    bad_before = np.concatenate([[0], np.cumsum(~good)])  # broken steps before sample k

    starts = np.asarray(leg_start_s, float)
    grid = np.arange(t[0], t[-1] + 1e-9, step_s)
    tf = np.unique(np.concatenate([grid, starts, [t[-1]]]))
    kf = np.clip(np.searchsorted(t, tf, side="left"), 0, n - 1)
    tf = t[kf]
    tf, first = np.unique(tf, return_index=True)
    kf = kf[first]
    rlat, rlon = interp_position(np.asarray(ref_time_s, float), ref_lat_rad, ref_lon_rad, tf,
                                 ref_max_gap_s)
    has_ref = np.isfinite(rlat) & np.isfinite(rlon)
    # observation y = reference - water track, chained over small steps (local metres)
    y = np.full((tf.size, 2), np.nan)
    iv = np.flatnonzero(has_ref)
    if iv.size:
        dn, de = offset_ne_m(rlat[iv[1:]], rlon[iv[1:]], rlat[iv[:-1]], rlon[iv[:-1]])
        d = np.column_stack([dn, de]) - (W[kf[iv[1:]]] - W[kf[iv[:-1]]])
        y[iv] = np.concatenate([np.zeros((1, 2)), np.cumsum(d, axis=0)])

    M = hp.size
    R = prior.fix_sigma_m ** 2
    x = np.zeros((M, N_STATE))
    P = np.zeros((M, N_STATE, N_STATE))
    P[:, 0, 0] = P[:, 1, 1] = _REANCHOR_M2
    P[:, 2, 2] = P[:, 3, 3] = prior.current_sigma_mps ** 2
    P[:, 4, 4] = P[:, 5, 5] = hp.current_sigma_mps ** 2
    P[:, 6, 6] = (prior.heading_sigma_rad * hp.prior_widening) ** 2
    P[:, 7, 7] = (prior.scale_sigma * hp.prior_widening) ** 2
    loglik = np.zeros(M)
    tau = hp.current_tau_s

    start_idx = np.searchsorted(tf, starts)
    want = np.zeros(tf.size, bool)
    want[start_idx[start_idx < tf.size]] = True
    snaps: dict[int, tuple] = {}
    first_ref_t = math.nan
    n_upd = 0
    n_out = 0
    K_ = tf.size
    h_x = np.zeros((K_, M, N_STATE))
    h_Pc = np.zeros((K_, M, 2, 2))
    h_ll = np.zeros((K_, M))
    h_upd = np.zeros(K_, bool)
    d_all = np.diff(tf)
    G_all = JI[kf[1:]] - JI[kf[:-1]]
    broke = bad_before[kf[1:]] > bad_before[kf[:-1]]
    cache: dict[float, tuple] = {}
    F = np.zeros((M, N_STATE, N_STATE))
    F[:, range(N_STATE), range(N_STATE)] = 1.0
    eye2 = np.eye(2)
    for i in range(K_):
        if i > 0:
            d = float(d_all[i - 1])
            if d not in cache:
                f_pc, phi = transition(d, tau)
                q_pp, q_pc, q_cc = _current_noise(d, _Tau(tau, hp.current_sigma_mps))
                Q = np.zeros((M, N_STATE, N_STATE))
                Q[:, 0, 0] = Q[:, 1, 1] = q_pp + hp.noise_psd_m2ps * d
                Q[:, 0, 4] = Q[:, 4, 0] = Q[:, 1, 5] = Q[:, 5, 1] = q_pc
                Q[:, 4, 4] = Q[:, 5, 5] = q_cc
                cache[d] = (f_pc, phi, Q)
            f_pc, phi, Q = cache[d]
            F[:, 0:2, 2:4] = d * eye2
            F[:, 0, 4] = F[:, 1, 5] = f_pc
            F[:, 4, 4] = F[:, 5, 5] = phi
            F[:, 0:2, 6:8] = G_all[i - 1]
            x = np.matmul(F, x[:, :, None])[:, :, 0]
            P = F @ P @ F.transpose(0, 2, 1) + Q
            if broke[i - 1]:
                P[:, 0, 0] += _REANCHOR_M2
                P[:, 1, 1] += _REANCHOR_M2
        if has_ref[i]:
            nu = y[i] - x[:, 0:2]
            S = P[:, 0:2, 0:2] + R * eye2
            det = S[:, 0, 0] * S[:, 1, 1] - S[:, 0, 1] ** 2
            Si = np.empty_like(S)
            Si[:, 0, 0] = S[:, 1, 1] / det
            Si[:, 1, 1] = S[:, 0, 0] / det
            Si[:, 0, 1] = Si[:, 1, 0] = -S[:, 0, 1] / det
            nis = (Si[:, 0, 0] * nu[:, 0] ** 2 + 2 * Si[:, 0, 1] * nu[:, 0] * nu[:, 1]
                   + Si[:, 1, 1] * nu[:, 1] ** 2)
            reanchor = P[0, 0, 0] > 0.5 * _REANCHOR_M2
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
        h_x[i] = x
        h_Pc[i] = P[:, 2:4, 2:4] + P[:, 4:6, 4:6] + P[:, 2:4, 4:6] + P[:, 4:6, 2:4]
        h_ll[i] = loglik
        if want[i]:
            span = tf[i] - first_ref_t if math.isfinite(first_ref_t) else 0.0
            snaps[i] = (_weights(loglik), x.copy(), P.copy(), span, n_upd)
    # the history, mixed over the grid
    w_all = _weights(h_ll)  # (K, M)
    c_mix = h_x[:, :, 2:4] + h_x[:, :, 4:6]
    h_cur = np.einsum("km,kmi->ki", w_all, c_mix)
    spread = np.sum((c_mix - h_cur[:, None, :]) ** 2, axis=2)
    h_sig = np.sqrt(0.5 * np.einsum("km,km->k", w_all,
                                    np.trace(h_Pc, axis1=2, axis2=3) + spread))
    h_eps = np.einsum("km,km->k", w_all, h_x[:, :, EPS])
    h_s = np.einsum("km,km->k", w_all, h_x[:, :, SCALE])
    L = starts.size
    weights = np.zeros((L, M))
    xs = np.zeros((L, M, N_STATE))
    Ps = np.zeros((L, M, N_STATE, N_STATE))
    learned = np.zeros(L)
    nu_before = np.zeros(L, np.int64)
    for j, i in enumerate(start_idx):
        w, xx, PP, span, nn = snaps[int(min(i, tf.size - 1))]
        weights[j], xs[j], Ps[j], learned[j], nu_before[j] = w, xx, PP, span, nn
    hist = FilterHistory(time_s=tf, current_ne_mps=h_cur, current_sigma_mps=h_sig,
                         heading_error_rad=h_eps, scale_error=h_s, updated=h_upd)
    return LearnedModel(hyper=hp, prior=prior, step_s=float(step_s), start_s=starts,
                        weights=weights, x=xs, P=Ps, learned_s=learned, n_updates=nu_before,
                        final_weights=_weights(loglik), final_x=x, final_P=P, n_outliers=n_out,
                        history=hist)


@dataclass(frozen=True)
class _Tau:
    """The two fields of dracc.current.CurrentModel that _current_noise reads."""

    current_tau_s: np.ndarray
    current_sigma_mps: np.ndarray


def _weights(loglik):
    """Grid weights from cumulative log-likelihoods (..., M), uniform prior over the grid."""
    w = np.exp(loglik - loglik.max(axis=-1, keepdims=True))
    return w / w.sum(axis=-1, keepdims=True)


def _significant(w, mass: float = 1.0 - 1e-6):
    """Indices of the largest weights that together hold ``mass`` of the total."""
    order = np.argsort(w)[::-1]
    n = int(np.searchsorted(np.cumsum(w[order]), mass * w.sum())) + 1
    return np.sort(order[:n])


@dataclass(frozen=True)
class LegForecast:
    """The EP's correction to the water track and its covariance, per DR sample."""

    offset_ne_m: np.ndarray  #: (n, 2) mu: add to the water track
    P_m2: np.ndarray  #: (n, 2, 2) covariance of the EP error, metres north/east
    components_m2: dict  #: name -> (n,) trace contribution (fix, current, current change, heading, scale, noise)


def forecast_legs(time_s, vn_w_mps, ve_w_mps, leg_of, model: LearnedModel, *,
                  horizon_step_s: float = 60.0) -> LegForecast:
    """The EP correction and covariance at every sample of every leg (see module docstring)."""
    t = np.asarray(time_s, float)
    n = t.size
    vn = np.nan_to_num(np.asarray(vn_w_mps, float))
    ve = np.nan_to_num(np.asarray(ve_w_mps, float))
    dt = np.diff(t)
    J = sensitivities(vn[:-1], ve[:-1]) * dt[:, None, None]
    JI = np.concatenate([np.zeros((1, 2, 2)), np.cumsum(J, axis=0)])
    leg_of = np.asarray(leg_of)
    off = np.full((n, 2), np.nan)
    Pout = np.full((n, 2, 2), np.nan)
    names = ("fix", "current", "current change", "heading", "log scale", "noise")
    comp = {k: np.full(n, np.nan) for k in names}
    hp = model.hyper
    tau = hp.current_tau_s
    R = model.prior.fix_sigma_m ** 2
    for leg in range(model.start_s.size):
        sel = np.flatnonzero(leg_of == leg)
        if sel.size == 0:
            continue
        k0 = sel[0]
        t0 = t[k0]
        th = np.unique(np.concatenate([np.arange(0.0, t[sel[-1]] - t0, horizon_step_s),
                                       [t[sel[-1]] - t0]]))
        kh = np.clip(np.searchsorted(t, t0 + th), 0, n - 1)
        G = JI[kh] - JI[k0]  # (H, 2, 2)
        w = model.weights[leg]
        keep = _significant(w)
        w = w[keep] / w[keep].sum()
        tau_k = tau[keep]
        f_pc, _ = transition(th[:, None], tau_k[None, :])  # (H, m)
        H, m = th.size, keep.size
        A = np.zeros((H, m, 2, 6))
        A[:, :, 0, 0] = A[:, :, 1, 1] = th[:, None]
        A[:, :, 0, 2] = A[:, :, 1, 3] = f_pc
        A[:, :, :, 4:6] = G[:, None]
        xs = model.x[leg][keep, 2:]  # (m, 6)
        Ps = model.P[leg][keep, 2:, 2:]  # (m, 6, 6)
        mu = np.matmul(A, xs[None, :, :, None])[..., 0]  # (H, m, 2)
        AP = np.matmul(A, Ps[None])  # (H, m, 2, 6)
        S = np.matmul(AP, A.transpose(0, 1, 3, 2))
        q_pp, _, _ = _current_noise(th[:, None], _Tau(tau_k[None, :],
                                                      hp.current_sigma_mps[keep][None, :]))
        noise = hp.noise_psd_m2ps[keep][None, :] * th[:, None]
        S[..., 0, 0] += q_pp + noise + R
        S[..., 1, 1] += q_pp + noise + R
        mu_mix = np.einsum("m,hmi->hi", w, mu)
        dev = mu - mu_mix[:, None, :]
        S_mix = np.einsum("m,hmij->hij", w, S + dev[..., :, None] * dev[..., None, :])

        # contributions to the trace, for naming what dominates a miss
        def part(block):
            Ab = A[..., block]
            return np.einsum("m,hmij,mjk,hmik->h", w, Ab, Ps[:, block, block], Ab)

        contrib = {
            "fix": np.full(H, 2 * R),
            "current": part(slice(0, 4)) + np.einsum("m,hmi->h", w, dev**2),
            "current change": 2 * q_pp @ w,
            "heading": part(slice(4, 5)),
            "log scale": part(slice(5, 6)),
            "noise": 2 * noise @ w,
        }
        ts = t[sel] - t0
        for j in range(2):
            off[sel, j] = np.interp(ts, th, mu_mix[:, j])
            for k in range(2):
                Pout[sel, j, k] = np.interp(ts, th, S_mix[:, j, k])
        for k, v in contrib.items():
            comp[k][sel] = np.interp(ts, th, v)
    return LegForecast(offset_ne_m=off, P_m2=Pout, components_m2=comp)


def heading_prior_rad(compass_bias_rad: float, leeway_rad: float, lat_rad: float,
                      gyro: bool) -> float:
    """Prior of the heading error: the compass bias (gyro: x sec phi, METHODS section 6)
    combined with the leeway."""
    sec = 1.0 / max(math.cos(lat_rad), 0.1) if gyro else 1.0
    return math.hypot(compass_bias_rad * sec, leeway_rad)


#: a leg is scored out of sample when its start's posterior has seen at least this span of
#: reference data (and MIN_LEARNED_UPDATES fixes)
MIN_LEARNED_S = 1800.0
MIN_LEARNED_UPDATES = 3


@dataclass(frozen=True)
class EstimatedPosition:
    """The EP track (a DRTrack with the current and corrections applied) and how it was learned."""

    track: DRTrack  #: positions, P, 2M of the estimated position
    water: DRTrack  #: the water track (no current, no corrections), as dead_reckon gave it
    model: LearnedModel
    forecast: LegForecast
    learned_leg: np.ndarray  #: (L,) bool: the leg's model was learned from earlier fixes


def step_ok_of(track: DRTrack) -> np.ndarray:
    """(n-1,) steps along which the water track runs continuously (resets included, breaks not)."""
    leg = track.leg
    on = (leg[:-1] >= 0) & (leg[1:] >= 0)
    new_leg = leg[1:] != leg[:-1]
    reasons = np.asarray(track.leg_start_reason + ("",), dtype=object)
    after_gap = new_leg & (reasons[np.where(leg[1:] >= 0, leg[1:], -1)] == "after-gap")
    return on & ~after_gap


def estimate_position(track: DRTrack, ref_time_s, ref_lat_rad, ref_lon_rad, prior: ErrorPrior,
                      *, ref_max_gap_s: float = 5.0, step_s: float | None = None,
                      hyper: Hyperparameters | None = None) -> EstimatedPosition:
    """The estimated position of every leg of a water-track DR, learned causally (module doc).

    ``step_s``: the filter's step; by default 300 s, shorter for logs under 25 h
    (at least 100 steps, at least 60 s).
    """
    t = track.time_s
    span = float(t[-1] - t[0]) if t.size else 0.0
    if step_s is None:
        step_s = float(np.clip(span / 100.0, 60.0, 300.0))
    model = learn_error_model(t, track.vn_mps, track.ve_mps, step_ok_of(track), ref_time_s,
                              ref_lat_rad, ref_lon_rad, track.leg_start_s, prior, hyper=hyper,
                              step_s=step_s, ref_max_gap_s=ref_max_gap_s)
    fc = forecast_legs(t, track.vn_mps, track.ve_mps, track.leg, model)
    on = track.leg >= 0
    lat = np.full(t.size, np.nan)
    lon = np.full(t.size, np.nan)
    lat[on], lon[on] = add_offset_ne(track.lat_rad[on], track.lon_rad[on], fc.offset_ne_m[on, 0],
                                     fc.offset_ne_m[on, 1])
    P = fc.P_m2
    radius = 2.0 * np.sqrt(P[:, 0, 0] + P[:, 1, 1])  # (B30), (B31)
    smaj, smin, orient = error_ellipse(np.nan_to_num(P))
    nan = ~np.isfinite(radius)
    smaj, smin, orient = (np.where(nan, np.nan, a) for a in (smaj, smin, orient))
    ep = replace(track, lat_rad=lat, lon_rad=lon, P_m2=P, radius_2m_m=radius, semi_major_m=smaj,
                 semi_minor_m=smin, orientation_rad=orient)
    learned = (model.learned_s >= MIN_LEARNED_S) & (model.n_updates >= MIN_LEARNED_UPDATES)
    return EstimatedPosition(track=ep, water=track, model=model, forecast=fc, learned_leg=learned)
