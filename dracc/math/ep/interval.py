"""The fix-interval study (seeds/003, Figure 5) on the *learned* error model.

:func:`dracc.math.ep.aided.interval_study` runs the 4-state filter of seeds/003 with a
configured :class:`dracc.math.current.CurrentModel`.  Where dracc learned the DR error
model from the voyage (``[dead_reckoning] learn = true``, :mod:`dracc.math.ep.kalman`) the
study runs on that model instead: the learned filter's own state and dynamics, with the
fixes thinned to each interval.

State (per grid point, the layout of :mod:`dracc.math.ep.error_model`)::

    x = [p (2), cbar (2), c (2), n (2), eps, s, delta]

p the error of the water track since the study's start fix (metres north/east), cbar the
persistent current, c its Gauss-Markov variation (sigma_c, tau_c), n the short-term noise
(sigma_n, tau_n), eps the heading error, s the log scale error, delta the heading-dependent
error (decorrelating over TURN_DECORRELATION_RAD of turn).  Over a step d (the exact
discretisation of the package doc)::

    p+ = p + d cbar + tau_c (1 - phi_c) c + tau_n (1 - phi_n) n + G [eps, s] + G_eps delta

with G = int J dt of the smoothed water velocity (:mod:`dracc.math.ep.sensitivity`).

What is learned and what is not
    the grid points that hold 1 - 1e-4 of the final weight, with those weights
    (``sigma_c, tau_c, sigma_n, tau_n``, the heading-dependent error and the fixes' noise
    of each); the heading and log-scale corrections eps, s (each point's final posterior
    mean and covariance: applied to the water track and kept in the covariance, then
    updated by the study's fixes).  Not learned: the current, cbar and c, which the
    study's filter estimates from its own fixes from the prior the learning started from
    (``ErrorPrior.current_sigma_mps``; c stationary), as the seeds/003 filter does.  The
    hyper-parameters and corrections are learned from the whole voyage (a handful of
    numbers from all its fixes); the fixes the study scores are among those.

Each grid point runs its own filter; the prediction of a fix is the weighted mixture of
their Gaussian predictions (fixed weights), moment-matched: mean mu = sum w mu_m, S = sum
w (S_m + (mu_m - mu)(mu_m - mu)^T), S_m = P_m,pp + sigma_fix,m^2 I.  Per update: 2M just
before it, 2 sqrt(trace P) of the mixed position covariance ((B30)/(B31)); the NIS of the
fix against S; and the probability the mixture gives that ellipse (NIS <= chi^2_2(0.95)):
0.95 for one model, different when the grid points disagree (:func:`prob_in_ellipse`).  A
fix that even the most favourable point puts above OUTLIER_NIS is scored (outside) and not
used, as the learning does.

Covariance matching.  The grid is weighed by the likelihood of one filter step (300 s or
less); over longer intervals its growth of the error can be wrong (on the random voyages
of tests/test_fix_interval_montecarlo.py it picks a short-lived current variation and
predicts too much growth over 30-60 min), as :mod:`dracc.math.ep.forecast` finds over a
leg.  So the prediction's covariance is scaled by a factor lambda learned from the study's
earlier updates (of every run of that interval, strictly earlier in time: causal): NIS/2
is lambda Exp(1) for a prediction lambda times too small; 1/lambda ~ Gamma(alpha, beta)
from MATCH_PRIOR; the prediction uses the posterior mean of lambda, and the model's own
probability of the fix inside averages over its posterior (a Student-t-like predictive).

The probability stated.  Matching the mean of the NIS sets the ellipse's size, not its
coverage: the probability the scaled Gaussian puts in it holds only where the NIS has the
chi-square's shape.  Over 30-60 min it has not (on the random voyages the first update of
a run, predicted from the current's prior, has NIS well above the later ones, and the
later ones are less dispersed than chi-square, as of an innovation with a persistent
bias), so the model's probability (about 0.94) under-states what the ellipse holds (about
0.97-0.98 at 60 min).  What is stated for an update is therefore the coverage the study
has achieved so far, causally: the fraction of the earlier updates (of every run of that
interval, strictly earlier in time) that fell inside their own scaled ellipse (each
scored with its own causal factor, as this one will be), shrunk to the model's own
probability worth STATE_PRIOR updates (the Beta-binomial posterior mean; the model's value
where nothing is seen yet):  p = (k0 p_model + n_inside) / (k0 + n).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dracc.core import distributions as dist
from dracc.core.arrays import ArrayLike, FloatArray, unique_sorted
from dracc.core.geodesy import offset_ne_m
from dracc.math.current import gauss_markov_noise, transition
from dracc.math.ep.aided import NIS_95_2DOF, thinned_fixes
from dracc.math.ep.error_model import (
    DELTA,
    EPS,
    N_STATE,
    OUTLIER_NIS,
    SCALE,
    TURN_DECORRELATION_RAD,
    Hyperparameters,
)
from dracc.math.ep.kalman import LearnedModel
from dracc.math.ep.sensitivity import prefix_sum, sensitivity_steps

#: the grid points kept: the largest weights holding this share of the total
SIGNIFICANT_MASS = 1.0 - 1e-4

#: runs of the study start every this many seconds (one per interval when it is longer):
#: at a long interval several runs, so the factor and the containment have more updates
START_SPACING_S = 900.0
#: covariance matching: the prior (alpha0, beta0) of 1/lambda ~ Gamma (mean lambda 1, worth
#: about one update: weakly informative), and the quantiles of its posterior the
#: probability is taken over
MATCH_PRIOR = (2.0, 1.0)
MATCH_QUANTILES = 8
#: the probability stated: the model's own worth this many updates beside the coverage
#: achieved by the earlier ones (as MATCH_PRIOR, about one update)
STATE_PRIOR = 1.0

_GL_X, _GL_W = np.polynomial.legendre.leggauss(64)


@dataclass(frozen=True)
class StudyModel:
    """The learned model as the study runs it: the significant grid points, each (m,)."""

    weights: FloatArray  #: (m,) summing to 1
    hyper: Hyperparameters  #: (m,)
    sensor_x: FloatArray  #: (m, 2) eps (rad), s: the learned corrections
    sensor_P: FloatArray  #: (m, 2, 2) their covariance
    current_sigma_mps: float  #: prior of the persistent current, per axis
    step_s: float  #: the filter's step (as learned)

    @classmethod
    def from_learned(cls, model: LearnedModel) -> StudyModel:
        """The points holding SIGNIFICANT_MASS of ``model.final_weights``."""
        w = model.final_weights
        order = np.argsort(w)[::-1]
        n = int(np.searchsorted(np.cumsum(w[order]), SIGNIFICANT_MASS * w.sum())) + 1
        keep = np.sort(order[:n])
        wk = w[keep] / w[keep].sum()
        sel = [EPS, SCALE]
        return cls(
            weights=wk,
            hyper=model.hyper.take(keep),
            sensor_x=model.final_x[keep][:, sel],
            sensor_P=model.final_P[keep][:, sel][:, :, sel],
            current_sigma_mps=model.prior.current_sigma_mps,
            step_s=model.step_s,
        )


def prob_in_ellipse(
    mean: ArrayLike, cov: ArrayLike, shape: ArrayLike, chi2: ArrayLike = NIS_95_2DOF
) -> FloatArray:
    """P(z^T shape^-1 z <= chi2) for z ~ N(mean, cov); mean (..., 2), cov, shape (..., 2, 2),
    chi2 (...) broadcast with them.

    Whitened by ``shape`` the region is the disc of radius sqrt(chi2); in the principal
    axes of the whitened covariance, 64-point Gauss-Legendre over the first axis (u1 = r
    sin theta) of its density times the normal probability of the chord along the second
    (as :func:`dracc.math.deadreckoning.prob_inside_2m`, with a mean)."""
    L = np.linalg.cholesky(np.asarray(shape, float))
    a = np.linalg.solve(L, np.asarray(mean, float)[..., None])[..., 0]
    Li = np.linalg.inv(L)
    C = Li @ np.asarray(cov, float) @ np.swapaxes(Li, -1, -2)
    lam, V = np.linalg.eigh(C)
    b = np.einsum("...ji,...j->...i", V, a)  # V^T a
    s1, s2 = np.sqrt(lam[..., 1:2]), np.sqrt(lam[..., 0:1])  # larger first
    b1, b2 = b[..., 1:2], b[..., 0:1]
    r = np.sqrt(np.asarray(chi2, float))[..., None]
    theta = 0.5 * np.pi * _GL_X
    u1 = r * np.sin(theta)
    half = r * np.cos(theta)  # half the chord at u1
    inner = dist.norm_cdf((half - b2) / s2) - dist.norm_cdf((-half - b2) / s2)
    dens = dist.norm_pdf((u1 - b1) / s1) / s1
    out: FloatArray = np.sum(_GL_W * dens * inner * half, axis=-1) * 0.5 * np.pi
    return out


@dataclass(frozen=True)
class StudyRun:
    """One run of the study (one interval, one start): per update, in time order, the
    mixed prediction before it, unscaled (covariance matching comes after, over runs)."""

    t_s: FloatArray  #: (k,) the update times
    trace_m2: FloatArray  #: (k,) trace of the mixed position covariance just before
    nis: FloatArray  #: (k,) the fix's NIS against the mixed innovation covariance
    dev_m: FloatArray  #: (k, m, 2) each grid point's predicted fix minus the mixture's
    S_m2: FloatArray  #: (k, m, 2, 2) each grid point's innovation covariance
    S_mix_m2: FloatArray  #: (k, 2, 2) the mixture's (moment-matched)


def _gm_step(hp: Hyperparameters, d: float) -> tuple[FloatArray, FloatArray]:
    """F, Q (m, 11, 11) over a step d of the parts that do not depend on the track: the
    persistent current, the current's variation and the short-term noise."""
    m = hp.size
    F = np.zeros((m, N_STATE, N_STATE))
    F[:, range(N_STATE), range(N_STATE)] = 1.0
    Q = np.zeros((m, N_STATE, N_STATE))
    F[:, 0, 2] = F[:, 1, 3] = d
    for (sig, tau), j in (
        ((hp.current_sigma_mps, hp.current_tau_s), 4),
        ((hp.noise_sigma_mps, hp.noise_tau_s), 6),
    ):
        f_pc, phi = transition(d, tau)
        q_pp, q_pc, q_cc = gauss_markov_noise(d, sig, tau)
        F[:, 0, j] = F[:, 1, j + 1] = f_pc
        F[:, j, j] = F[:, j + 1, j + 1] = phi
        Q[:, 0, 0] += q_pp
        Q[:, 1, 1] += q_pp
        Q[:, 0, j] = Q[:, j, 0] = Q[:, 1, j + 1] = Q[:, j + 1, 1] = q_pc
        Q[:, j, j] = Q[:, j + 1, j + 1] = q_cc
    return F, Q


def study_run(
    t_s: FloatArray,
    W: FloatArray,
    JI: FloatArray,
    fix_s: FloatArray,
    fix_lat_rad: FloatArray,
    fix_lon_rad: FloatArray,
    pick: ArrayLike,
    model: StudyModel,
) -> StudyRun:
    """The learned filter from fix ``pick[0]``, updated by the later picks (module doc).

    ``W`` (n, 2): the water track (m) at ``t_s`` from its first sample; ``JI`` (n, 2, 2):
    the integral of the sensitivities there; the velocity is held over each sample's step,
    so both are linear between samples."""
    pick = np.asarray(pick, np.int64)
    hp = model.hyper
    m = hp.size

    def at(arr: FloatArray, tq: FloatArray) -> FloatArray:
        flat = arr.reshape(arr.shape[0], -1)
        return np.stack([np.interp(tq, t_s, flat[:, j]) for j in range(flat.shape[1])], -1).reshape(
            (tq.size,) + arr.shape[1:]
        )

    tfix = fix_s[pick]
    t0, t1 = float(tfix[0]), float(tfix[-1])
    grid = np.arange(t0, t1, model.step_s)
    te = unique_sorted(np.concatenate([grid, tfix]))
    We, Je = at(W, te), at(JI, te)
    is_fix = np.isin(te, tfix)
    fix_of = np.searchsorted(tfix, te)
    # the observation at each fix: y = fix - (start fix + water track), chained fix to fix
    dn, de = offset_ne_m(
        fix_lat_rad[pick[1:]], fix_lon_rad[pick[1:]], fix_lat_rad[pick[:-1]], fix_lon_rad[pick[:-1]]
    )
    Wf = at(W, tfix)
    y = np.concatenate(
        [np.zeros((1, 2)), np.cumsum(np.column_stack([dn, de]) - np.diff(Wf, axis=0), axis=0)]
    )
    dW = np.diff(We, axis=0)
    course = np.arctan2(dW[:, 1], dW[:, 0])
    turn = np.abs(np.angle(np.exp(1j * np.diff(course, prepend=course[:1]))))
    turn = np.where(np.hypot(dW[:, 0], dW[:, 1]) > 1.0, turn, 0.0)
    rho = np.exp(-turn / TURN_DECORRELATION_RAD)

    R = hp.fix_sigma_m**2  # (m,)
    x = np.zeros((m, N_STATE))
    x[:, EPS : SCALE + 1] = model.sensor_x
    P = np.zeros((m, N_STATE, N_STATE))
    P[:, 0, 0] = P[:, 1, 1] = R  # the start fix's noise
    P[:, 2, 2] = P[:, 3, 3] = model.current_sigma_mps**2
    P[:, 4, 4] = P[:, 5, 5] = hp.current_sigma_mps**2
    P[:, 6, 6] = P[:, 7, 7] = hp.noise_sigma_mps**2
    P[:, EPS : SCALE + 1, EPS : SCALE + 1] = model.sensor_P
    P[:, DELTA, DELTA] = hp.turn_sigma_rad**2
    w = model.weights
    eye2 = np.eye(2)
    out: list[list[object]] = [[] for _ in range(6)]
    cache: dict[float, tuple[FloatArray, FloatArray]] = {}
    for i in range(1, te.size):
        d = float(te[i] - te[i - 1])
        if d not in cache:
            cache[d] = _gm_step(hp, d)
        F, Q = cache[d]
        G = Je[i] - Je[i - 1]
        F[:, 0:2, EPS : SCALE + 1] = G  # the heading and log-scale errors over the step
        F[:, 0:2, DELTA] = G[:, 0]  # the heading-dependent error
        F[:, DELTA, DELTA] = rho[i - 1]
        x = np.matmul(F, x[:, :, None])[:, :, 0]
        P = F @ P @ F.transpose(0, 2, 1) + Q
        P[:, DELTA, DELTA] += hp.turn_sigma_rad**2 * (1.0 - rho[i - 1] ** 2)
        if not is_fix[i]:
            continue
        mu = x[:, 0:2]
        Pp = P[:, 0:2, 0:2]
        S = Pp + R[:, None, None] * eye2
        mu_mix = w @ mu
        dev = mu - mu_mix
        outer = dev[:, :, None] * dev[:, None, :]
        P_mix = np.einsum("m,mij->ij", w, Pp + outer)
        S_mix = np.einsum("m,mij->ij", w, S + outer)
        nu = y[fix_of[i]] - mu_mix
        for col, v in zip(
            out,
            (te[i], P_mix[0, 0] + P_mix[1, 1], nu @ np.linalg.solve(S_mix, nu), dev, S, S_mix),
            strict=True,
        ):
            col.append(v)
        nu_m = y[fix_of[i]] - mu
        Si = np.linalg.inv(S)
        nis_m = np.einsum("mi,mij,mj->m", nu_m, Si, nu_m)
        if nis_m.min() > OUTLIER_NIS:
            continue  # a GNSS jump: scored, not used
        K = P[:, :, 0:2] @ Si
        x = x + np.matmul(K, nu_m[:, :, None])[:, :, 0]
        P = P - K @ P[:, 0:2, :]
        P = 0.5 * (P + P.transpose(0, 2, 1))
    if not out[0]:
        return StudyRun(*(np.empty((0,) + sh) for sh in ((), (), (), (m, 2), (m, 2, 2), (2, 2))))
    return StudyRun(*(np.asarray(c, float) for c in out))


def matched_scale(t_s: FloatArray, nis: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The posterior (alpha, beta) of 1/lambda ~ Gamma(alpha, rate beta) at each update, from
    the updates strictly before it in time (any run): NIS/2 ~ lambda Exp(1) when the
    predicted covariance is lambda times too small; prior MATCH_PRIOR (alpha0, beta0), each
    NIS/2 capped at OUTLIER_NIS/2 (a GNSS jump does not swell the factor)."""
    a0, b0 = MATCH_PRIOR
    order = np.argsort(t_s, kind="stable")
    ts = t_s[order]
    half = np.minimum(nis[order], OUTLIER_NIS) / 2.0
    csum = np.concatenate([[0.0], np.cumsum(half)])
    before = np.searchsorted(ts, ts, side="left")  # updates strictly earlier
    alpha = np.empty(t_s.size)
    beta = np.empty(t_s.size)
    alpha[order] = a0 + before
    beta[order] = b0 + csum[before]
    return alpha, beta


def _scaled(runs: Sequence[StudyRun], w: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(2M before, NIS, probability stated) of the pooled updates, the mixed prediction
    scaled by the causal factor lambda = beta / (alpha - 1) (its posterior mean); the
    model's own probability over the posterior of lambda (MATCH_QUANTILES quantiles of
    1/lambda), the stated one by :func:`stated_containment`."""
    t = np.concatenate([r.t_s for r in runs])
    if t.size == 0:
        return np.empty(0), np.empty(0), np.empty(0)
    nis = np.concatenate([r.nis for r in runs])
    tr = np.concatenate([r.trace_m2 for r in runs])
    dev = np.concatenate([r.dev_m for r in runs])
    S = np.concatenate([r.S_m2 for r in runs])
    S_mix = np.concatenate([r.S_mix_m2 for r in runs])
    alpha, beta = matched_scale(t, nis)
    lam = beta / (alpha - 1.0)
    q = (np.arange(MATCH_QUANTILES) + 0.5) / MATCH_QUANTILES
    inv_lam = dist.chi2_ppf(q[None, :], 2.0 * alpha[:, None]) / (2.0 * beta[:, None])  # (k, Q)
    # the fix inside lam S_mix's ellipse when the truth is 1/inv_lam times the prediction
    chi2 = NIS_95_2DOF * lam[:, None] * inv_lam  # (k, Q)
    p = prob_in_ellipse(
        dev[:, None], S[:, None], S_mix[:, None, None], chi2[:, :, None]
    )  # (k, Q, m)
    p_model = np.einsum("kqm,m->k", p, w) / MATCH_QUANTILES
    return 2.0 * np.sqrt(lam * tr), nis / lam, stated_containment(t, nis / lam, p_model)


def stated_containment(t_s: FloatArray, nis: FloatArray, p_model: FloatArray) -> FloatArray:
    """The probability stated for each update (module doc): the fraction of the updates
    strictly before it in time whose (scaled) NIS fell in the 95 % ellipse, shrunk to the
    model's own probability ``p_model`` worth STATE_PRIOR updates."""
    order = np.argsort(t_s, kind="stable")
    ts = t_s[order]
    hits = np.concatenate([[0.0], np.cumsum(nis[order] <= NIS_95_2DOF)])
    before = np.searchsorted(ts, ts, side="left")  # updates strictly earlier
    out = np.empty(t_s.size)
    out[order] = (STATE_PRIOR * p_model[order] + hits[before]) / (STATE_PRIOR + before)
    return out


def learned_interval_study(
    t_s: ArrayLike,
    vn_mps: ArrayLike,
    ve_mps: ArrayLike,
    fix_s: ArrayLike,
    fix_lat_rad: ArrayLike,
    fix_lon_rad: ArrayLike,
    model: StudyModel,
    intervals_s: Sequence[float],
    *,
    start_spacing_s: float = START_SPACING_S,
) -> list[tuple[FloatArray, FloatArray, FloatArray]]:
    """For each interval: (2M before each update, NIS of each update, the probability
    stated of the fix inside its 95 % ellipse: :func:`stated_containment`), over runs,
    over one stretch of water velocity ``vn_mps``, ``ve_mps`` at ``t_s`` (held over each
    step).

    Runs start at the first fix at or after ``t_s[0] + k interval / phases`` (k = 0 ..
    phases - 1, phases = interval / ``start_spacing_s`` rounded, at least 1), each updated by
    one fix per interval after its start (``thinned_fixes``); the factor of covariance
    matching is learned over the runs' updates in time order."""
    t = np.asarray(t_s, float)
    vn = np.asarray(vn_mps, float)
    ve = np.asarray(ve_mps, float)
    fs = np.asarray(fix_s, float)
    lat = np.asarray(fix_lat_rad, float)
    lon = np.asarray(fix_lon_rad, float)
    dt = np.diff(t)
    W = prefix_sum(np.column_stack([vn[:-1], ve[:-1]]) * dt[:, None])
    JI = prefix_sum(sensitivity_steps(t, vn, ve, dt))
    out = []
    for interval in intervals_s:
        runs = []
        phases = max(1, int(round(float(interval) / start_spacing_s)))
        for k in range(phases):
            pick = thinned_fixes(fs, t[0] + k * float(interval) / phases, t[-1], float(interval))
            if pick.size >= 2:
                runs.append(study_run(t, W, JI, fs, lat, lon, pick, model))
        out.append(_scaled(runs, model.weights))
    return out
