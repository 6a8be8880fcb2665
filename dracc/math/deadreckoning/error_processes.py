"""The "honest" covariance: DR position error from Gauss-Markov sensor-error processes.

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

Holds the configured sources as :class:`ErrorProcess` (:func:`error_processes`), the
covariance of one process (:func:`gauss_markov_position_covariance_m2`) and of them all
(:func:`honest_covariance_m2`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from dracc.core.arrays import FloatArray, IntArray, unique_sorted
from dracc.core.config import DeadReckoningConfig, ErrorSource
from dracc.core.errors import ConfigError
from dracc.core.units import DEG_RAD, KN_MPS

__all__ = [
    "ErrorProcess",
    "error_processes",
    "gauss_markov_position_covariance_m2",
    "honest_covariance_m2",
]


# --------------------------------------------------------------------------------------
# One process: the closed-form covariance
# --------------------------------------------------------------------------------------


def _linear_recurrence(a: FloatArray, b: FloatArray, tau_s: float, dt: FloatArray) -> FloatArray:
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


def _gm_cov3(t: FloatArray, gn: ArrayLike, ge: ArrayLike, sigma: float, tau_s: float) -> FloatArray:
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


def _cov3_to_22(c3: FloatArray) -> FloatArray:
    """[P_NN, P_NE, P_EE] (..., 3) as the symmetric matrices (..., 2, 2)."""
    out = np.empty(c3.shape[:-1] + (2, 2))
    out[..., 0, 0] = c3[..., 0]
    out[..., 0, 1] = c3[..., 1]
    out[..., 1, 0] = c3[..., 1]
    out[..., 1, 1] = c3[..., 2]
    return out


def gauss_markov_position_covariance_m2(
    time_s: ArrayLike, g_mps: ArrayLike, sigma: float, tau_s: float
) -> FloatArray:
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


# --------------------------------------------------------------------------------------
# The configured sources
# --------------------------------------------------------------------------------------


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


def _sensitivity_mps(
    acts_on: str, speed_mps: ArrayLike, course_rad: ArrayLike
) -> tuple[FloatArray | float, FloatArray | float]:
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


# --------------------------------------------------------------------------------------
# All processes: the honest covariance, on a coarser grid where the data are dense
# --------------------------------------------------------------------------------------


class _CoarseGrid(NamedTuple):
    """The samples correlated processes are propagated on, and the logged steps."""

    samples: IntArray  #: samples at or after each multiple of step_s from t_0, plus the last
    time_s: FloatArray  #: their times
    dt: FloatArray  #: (n-1,) the logged steps


def _coarse_grid(t: FloatArray, step_s: float) -> IntArray:
    """Indices of the samples at or after each multiple of ``step_s`` from t_0, plus the last."""
    marks = np.arange(t[0], t[-1], step_s)
    idx: IntArray = unique_sorted(np.r_[np.searchsorted(t, marks, side="left"), t.size - 1])
    return idx


def _process_cov3(
    t: FloatArray,
    grid: _CoarseGrid | None,
    gn: ArrayLike,
    ge: ArrayLike,
    sigma: float,
    tau_s: float,
) -> FloatArray:
    """(n, 3) [P_NN, P_NE, P_EE] of one process, on ``grid`` when given and tau > 0."""
    if grid is None or tau_s == 0.0:
        return _gm_cov3(t, gn, ge, sigma, tau_s)
    n = t.size
    # time-weighted mean of g over each grid step, from prefix sums of g dt
    gcols = []
    for g_in in (gn, ge):
        g = np.broadcast_to(np.asarray(g_in, float), (n,))
        G = np.r_[0.0, np.cumsum(g[:-1] * grid.dt)][grid.samples]
        gcols.append(np.r_[np.diff(G) / np.diff(grid.time_s), 0.0])
    c3c = _gm_cov3(grid.time_s, gcols[0], gcols[1], sigma, tau_s)
    return np.column_stack([np.interp(t, grid.time_s, c3c[:, j]) for j in range(3)])


def _same_current_on_both_axes(processes: Sequence[ErrorProcess]) -> bool:
    """True when the north and east currents are one (sigma, tau) pair."""
    pair = [q for q in processes if q.acts_on in ("current_n", "current_e")]
    return len(pair) == 2 and pair[0].sigma == pair[1].sigma and pair[0].tau_s == pair[1].tau_s


def honest_covariance_m2(
    time_s: ArrayLike,
    speed_mps: ArrayLike,
    course_rad: ArrayLike,
    processes: Sequence[ErrorProcess],
    P0_m2: ArrayLike | None = None,
    *,
    step_s: float | None = None,
) -> FloatArray:
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
    grid = None
    if step_s is not None and n > 2 and (t[-1] - t[0]) / (n - 1) < 0.5 * step_s:
        coarse = _coarse_grid(t, step_s)
        grid = _CoarseGrid(coarse, t[coarse], np.diff(t))

    done_current = False
    for p in processes:
        if p.acts_on in ("current_n", "current_e"):
            # north and east currents with one (sigma, tau): one scalar run, on the diagonal
            if done_current:
                continue
            if _same_current_on_both_axes(processes):
                c3 = _process_cov3(t, grid, 1.0, 0.0, p.sigma, p.tau_s)
                acc[:, 0] += c3[:, 0]
                acc[:, 2] += c3[:, 0]
                done_current = True
                continue
        gn, ge = _sensitivity_mps(p.acts_on, speed_mps, course_rad)
        acc[:] += _process_cov3(t, grid, gn, ge, p.sigma, p.tau_s)
    return _cov3_to_22(acc)
