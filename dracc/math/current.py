"""Estimated position (EP) and current: a Kalman filter with a Gauss-Markov current.

Source: the aided dead-reckoning paper (seeds/003, Gebre-Egziabher, Powell & Enge):
heading + speed dead reckoning whose dominant error is the motion of the medium,
modelled as a first-order Gauss-Markov process and estimated from intermittent fixes
(full fixes or single lines of position); METHODS §3.

State (per run): the position (held as WGS-84 ``lat_rad, lon_rad``; its error and
covariance in metres north/east) and the current ``c = (c_N, c_E)`` in m/s, the
velocity of the water over the ground.  Continuous model::

    d(p)/dt = v_w + c + n_v          v_w = V (cos C, sin C): DR velocity through the water
    d(c)/dt = -c / tau + w           E[w w^T] = 2 sigma_c^2 / tau, per axis

with C the course through the water (heading + gyro correction + leeway, (B3)-(B5))
and V the speed through the water.  Its exact discretisation over dt, phi = exp(-dt/tau)::

    p+ = p + v_w dt + tau (1 - phi) c          (position from the integrated current)
    c+ = phi c
    Q_cc = sigma_c^2 (1 - phi^2)
    Q_pc = sigma_c^2 tau (1 - phi)^2
    Q_pp = 2 sigma_c^2 tau [dt - 2 tau (1 - phi) + tau (1 - phi^2) / 2]

The water-velocity errors n_v (log and compass noise, each (sigma, tau) Gauss-Markov)
enter as white noise of the equivalent power spectral density 2 sigma^2 tau, along
track for the log and across track (V sigma_C) for the compass, rotated to north/east
as in (B26)-(B28) (corrected (B28)); the covariance growth therefore does not depend on
the logging rate.

Every (sigma, tau) form that ``[dead_reckoning]`` accepts is a valid model here:

* ``tau = inf`` (a bias, e.g. ``current_kn = 0.42``): the current is a random constant,
  ``phi = 1``, ``F_pc = dt``, no driving noise (``Q = 0``, the limit of the formulas above
  as tau -> inf); its uncertainty is the prior ``sigma^2`` at the start, which the fixes
  shrink.  A constant log or compass error (``log_noise_kn`` / ``compass_noise_deg``
  with ``tau = inf``) is, over a leg, a constant velocity error the filter cannot tell
  from current: it adds no white noise, and its variance (``sigma^2`` along track,
  ``(V sigma_C)^2`` across, at the first epoch's course and speed) is added to the
  prior of the current, which absorbs it.
* ``tau = 0`` (white noise): a value independent from one second to the next
  (``WHITE_NOISE_STEP_S``; the DR's (B23) form takes it per logged step, but the filter
  runs on its own grid and needs a rate that does not depend on it), i.e. white noise of
  power spectral density ``sigma^2 * 1 s``: ``Q_pp = sigma^2 (1 s) dt``, the same growth
  as a Gauss-Markov process with tau = 0.5 s.  A white current has nothing
  to carry over: ``phi = 0``, ``F_pc = 0``, ``Q_pc = 0``, ``Q_cc = sigma^2`` (its value at an
  instant, unrelated to the position), so its estimate stays at the prior mean.  White
  log or compass noise enters the position the same way (PSD ``sigma^2 * 1 s`` instead
  of ``2 sigma^2 tau``).

Updates: every observation of :mod:`dracc.math.fusion` (``PositionFix``, ``RangeLOP``,
``BearingLOP``, ``LineLOP``, ``PierLine``, ``NadirCircle``) linearised at the predicted
position, ``H = [g, 0]``; extended Kalman update in Joseph form.  A single line of
position has a 1x4 ``H``, so the position covariance shrinks only across the line.

Set is the direction the water flows TOWARDS, ``set = atan2(c_E, c_N)`` in [0, 2pi);
drift is ``|c|``.

All functions broadcast over a leading axis of independent runs (Monte Carlo).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast, overload

import numpy as np
from numpy.typing import NDArray

from dracc.core.arrays import ArrayLike, FloatArray, FloatOrArray
from dracc.core.errors import InsufficientDataError
from dracc.core.geodesy import add_offset_ne, k_lambda, k_phi, offset_ne_m, wrap_2pi, wrap_pi
from dracc.core.units import DEG_RAD, KN_MPS
from dracc.math.ellipse import Ellipse, error_ellipse
from dracc.math.fusion import Observation, PositionFix

if TYPE_CHECKING:
    from dracc.core.config import DeadReckoningConfig

#: tau = 0 (white noise) means a value independent from one WHITE_NOISE_STEP_S to the next
WHITE_NOISE_STEP_S = 1.0


def _psd(sigma: float, tau_s: float) -> float:
    """Power spectral density of a (sigma, tau) process seen as white noise at long
    horizons: 2 sigma^2 tau; sigma^2 WHITE_NOISE_STEP_S for tau = 0; 0 for a bias (tau = inf,
    which is not white noise at all: see the module doc)."""
    tau = float(tau_s)
    if math.isinf(tau):
        return 0.0
    if tau == 0.0:
        return sigma**2 * WHITE_NOISE_STEP_S
    return 2.0 * sigma**2 * tau


@dataclass(frozen=True)
class CurrentModel:
    """Error model of the filter (sigmas 1-sigma, >= 0; tau in seconds, 0 <= tau <= inf:
    ``inf`` a bias, ``0`` white noise independent per second; see the module doc).

    ``current_*``: the Gauss-Markov current, per axis.  ``speed_*``: the speed log's
    noise; ``heading_*``: the compass noise (course through the water).
    ``initial_current_sigma_mps``: prior of the current at the start (default: the
    stationary ``current_sigma_mps``).
    """

    current_sigma_mps: float = 0.3 * KN_MPS
    current_tau_s: float = 3600.0
    speed_sigma_mps: float = 0.1 * KN_MPS
    speed_tau_s: float = 300.0
    heading_sigma_rad: float = 0.2 * DEG_RAD
    heading_tau_s: float = 120.0
    initial_current_sigma_mps: float | None = None

    def __post_init__(self) -> None:
        for name in ("current_tau_s", "speed_tau_s", "heading_tau_s"):
            v = getattr(self, name)
            if not v >= 0:  # also NaN; inf is a bias, 0 white noise
                raise InsufficientDataError(
                    f"CurrentModel.{name} must be >= 0 (inf: a bias, 0: white noise), got {v!r}"
                )
        for name in ("current_sigma_mps", "speed_sigma_mps", "heading_sigma_rad"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0:
                raise InsufficientDataError(
                    f"CurrentModel.{name} must be finite and >= 0, got {v!r}"
                )
        s0 = self.initial_current_sigma_mps
        if s0 is not None and (not np.isfinite(s0) or s0 < 0):
            raise InsufficientDataError(
                f"CurrentModel.initial_current_sigma_mps must be finite and >= 0, got {s0!r}"
            )

    @property
    def current0_sigma_mps(self) -> float:
        s = self.initial_current_sigma_mps
        return self.current_sigma_mps if s is None else s

    def water_bias_cov(self, course_rad: ArrayLike, speed_mps: ArrayLike) -> FloatArray:
        """(..., 2, 2) north/east covariance (m^2/s^2) of the log and compass errors that
        are biases (tau = inf): sigma^2 along track, (V sigma_C)^2 across; zero otherwise."""
        course = np.nan_to_num(np.asarray(course_rad, float))  # a lone last epoch may lack them
        speed = np.nan_to_num(np.asarray(speed_mps, float))
        along = self.speed_sigma_mps**2 if math.isinf(self.speed_tau_s) else 0.0
        across = (
            (speed * self.heading_sigma_rad) ** 2
            if math.isinf(self.heading_tau_s)
            else np.zeros(speed.shape)
        )
        c, s = np.cos(course), np.sin(course)
        out = np.empty(np.broadcast_shapes(np.shape(c), np.shape(across)) + (2, 2))
        out[..., 0, 0] = along * c**2 + across * s**2
        out[..., 1, 1] = along * s**2 + across * c**2
        out[..., 0, 1] = out[..., 1, 0] = (along - across) * s * c
        return out

    @classmethod
    def from_config(cls, cfg: DeadReckoningConfig) -> CurrentModel:
        """From a :class:`dracc.core.config.DeadReckoningConfig`: its ``current_kn``,
        ``log_noise_kn`` and ``compass_noise_deg`` error sources, in any of their forms
        (a number or ``tau_s = "inf"``: a bias; ``tau_s = 0``: white noise)."""
        return cls(
            current_sigma_mps=cfg.current_kn.sigma * KN_MPS,
            current_tau_s=cfg.current_kn.tau_s,
            speed_sigma_mps=cfg.log_noise_kn.sigma * KN_MPS,
            speed_tau_s=cfg.log_noise_kn.tau_s,
            heading_sigma_rad=cfg.compass_noise_deg.sigma * DEG_RAD,
            heading_tau_s=cfg.compass_noise_deg.tau_s,
        )


# ------------------------------------------------------------------------ kernels


def _regular(tau: ArrayLike) -> bool:
    """Every tau finite and > 0 (the closed forms apply as written)."""
    t = np.asarray(tau, float)
    return bool(np.all(np.isfinite(t) & (t > 0)))


@overload
def transition(dt_s: float, tau_s: float) -> tuple[FloatOrArray, FloatOrArray]: ...
@overload
def transition(dt_s: ArrayLike, tau_s: float | NDArray[Any]) -> tuple[FloatArray, FloatArray]: ...
def transition(dt_s: ArrayLike, tau_s: float | NDArray[Any]) -> tuple[Any, Any]:
    """Exact discretisation of the integrated Gauss-Markov current: (F_pc, phi).

    F = [[I, F_pc I], [0, phi I]], F_pc = tau (1 - exp(-dt/tau)), phi = exp(-dt/tau).
    ``tau_s`` may be an array; tau = inf (a random constant): F_pc = dt, phi = 1;
    tau = 0 (white): F_pc = 0, phi = 0 for dt > 0 (1 at dt = 0).
    """
    if _regular(tau_s):
        x = np.asarray(dt_s, float) / tau_s
        return -tau_s * np.expm1(-x), np.exp(-x)
    dt = np.asarray(dt_s, float)
    tau = np.asarray(tau_s, float)
    inf, white = np.isinf(tau), tau == 0.0
    safe = np.where(inf | white, 1.0, tau)
    x = dt / safe
    f_pc = np.where(inf, dt, np.where(white, 0.0, -safe * np.expm1(-x)))
    phi = np.where(inf, 1.0, np.where(white, np.where(dt > 0, 0.0, 1.0), np.exp(-x)))
    return f_pc, phi


def _current_noise(
    dt_s: ArrayLike, model: CurrentModel
) -> tuple[FloatOrArray, FloatOrArray, FloatOrArray]:
    """(q_pp, q_pc, q_cc) of the integrated Gauss-Markov current over dt (module doc)."""
    return gauss_markov_noise(dt_s, model.current_sigma_mps, model.current_tau_s)


@overload
def gauss_markov_noise(
    dt_s: float, sigma: float, tau_s: float
) -> tuple[FloatOrArray, FloatOrArray, FloatOrArray]: ...
@overload
def gauss_markov_noise(
    dt_s: ArrayLike, sigma: ArrayLike, tau_s: float | NDArray[Any]
) -> tuple[FloatArray, FloatArray, FloatArray]: ...
def gauss_markov_noise(
    dt_s: ArrayLike, sigma: ArrayLike, tau_s: float | NDArray[Any]
) -> tuple[Any, Any, Any]:
    """(q_pp, q_pc, q_cc): the driving noise over dt of a first-order Gauss-Markov process
    (sigma, tau) and of its integral (module doc), arrays broadcast.

    tau = inf: no driving noise (0, 0, 0); tau = 0: white, independent per
    WHITE_NOISE_STEP_S: (sigma^2 WHITE_NOISE_STEP_S dt, 0, sigma^2 for dt > 0).
    """
    if not _regular(tau_s):
        return _gauss_markov_noise_special(dt_s, sigma, tau_s)
    dt = np.asarray(dt_s, float)
    tau, s2 = tau_s, np.asarray(sigma, float) ** 2
    x = dt / tau
    one_m_phi = -np.expm1(-x)  # 1 - phi, exact for small dt
    one_m_phi2 = -np.expm1(-2.0 * x)  # 1 - phi^2
    q_cc = s2 * one_m_phi2
    q_pc = s2 * tau * one_m_phi**2
    # x - 2(1 - phi) + (1 - phi^2)/2, by its series x^3/3 - x^4/4 + 7x^5/60 where it cancels
    bracket = np.where(
        x < 1e-3,
        x**3 / 3.0 - x**4 / 4.0 + 7.0 * x**5 / 60.0,
        x - 2.0 * one_m_phi + 0.5 * one_m_phi2,
    )
    q_pp = 2.0 * s2 * tau**2 * bracket
    return q_pp, q_pc, q_cc


def _gauss_markov_noise_special(
    dt_s: ArrayLike, sigma: ArrayLike, tau_s: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """gauss_markov_noise where some tau is inf or 0 (the regular ones by the closed form)."""
    dt = np.asarray(dt_s, float)
    tau = np.asarray(tau_s, float)
    s2 = np.asarray(sigma, float) ** 2
    inf, white = np.isinf(tau), tau == 0.0
    safe = np.where(inf | white, 1.0, tau)
    q_pp, q_pc, q_cc = gauss_markov_noise(dt, np.sqrt(s2), safe)
    zero = np.zeros(np.broadcast_shapes(q_pp.shape, white.shape))
    q_pp = np.where(inf, zero, np.where(white, s2 * WHITE_NOISE_STEP_S * dt + zero, q_pp))
    q_pc = np.where(inf | white, zero, q_pc)
    q_cc = np.where(inf, zero, np.where(white, np.where(dt > 0, s2, 0.0) + zero, q_cc))
    return q_pp, q_pc, q_cc


def _water_noise(
    dt_s: ArrayLike, course_rad: ArrayLike, speed_mps: ArrayLike, model: CurrentModel
) -> tuple[FloatOrArray, FloatOrArray, FloatOrArray]:
    """(v_nn, v_ee, v_ne): position noise from the water velocity over dt, white noise of
    PSD 2 sigma^2 tau along track (log) and across track (V sigma_C, compass); sigma^2 * 1 s
    for tau = 0, none for a bias (tau = inf: absorbed by the current, module doc)."""
    dt = np.asarray(dt_s, float)
    psd_along = _psd(model.speed_sigma_mps, model.speed_tau_s)
    if _regular(model.heading_tau_s):
        psd_across = (
            2.0
            * (np.asarray(speed_mps, float) * model.heading_sigma_rad) ** 2
            * model.heading_tau_s
        )
    else:
        psd_across = np.asarray(speed_mps, float) ** 2 * _psd(
            model.heading_sigma_rad, model.heading_tau_s
        )
    c, s = np.cos(course_rad), np.sin(course_rad)
    v_nn = (psd_along * c**2 + psd_across * s**2) * dt  # (B26) in metres, PSD form
    v_ee = (psd_along * s**2 + psd_across * c**2) * dt  # (B27)
    v_ne = (psd_along - psd_across) * s * c * dt  # (B28), corrected: common factor
    return v_nn, v_ee, v_ne


def process_noise(
    dt_s: ArrayLike, course_rad: ArrayLike, speed_mps: ArrayLike, model: CurrentModel
) -> FloatArray:
    """Q (..., 4, 4) over dt for state (p_N, p_E, c_N, c_E) (metres, m/s); see module doc."""
    q_pp, q_pc, q_cc = _current_noise(dt_s, model)
    v_nn, v_ee, v_ne = _water_noise(dt_s, course_rad, speed_mps, model)
    shape = np.broadcast_shapes(np.shape(q_pp), np.shape(v_nn))
    q = np.zeros(shape + (4, 4))
    q[..., 0, 0] = q_pp + v_nn
    q[..., 1, 1] = q_pp + v_ee
    q[..., 0, 1] = q[..., 1, 0] = v_ne
    q[..., 2, 2] = q[..., 3, 3] = q_cc
    q[..., 0, 2] = q[..., 2, 0] = q[..., 1, 3] = q[..., 3, 1] = q_pc
    return q


def _transition_matrix(dt_s: ArrayLike, tau_s: float) -> FloatArray:
    f_pc, phi = transition(dt_s, tau_s)
    f = np.zeros(np.shape(f_pc) + (4, 4))
    f[..., 0, 0] = f[..., 1, 1] = 1.0
    f[..., 0, 2] = f[..., 1, 3] = f_pc
    f[..., 2, 2] = f[..., 3, 3] = phi
    return f


@dataclass
class _State:
    lat: FloatArray  # (R,)
    lon: FloatArray  # (R,)
    c: FloatArray  # (R, 2)
    p: FloatArray  # (R, 4, 4)


def _propagate(
    st: _State,
    t_from: float,
    targets: ArrayLike,
    t_s: FloatArray,
    course: FloatArray,
    speed: FloatArray,
    model: CurrentModel,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Predict from t_from to each of ``targets`` (m,), ascending, >= t_from, no update between.

    Vectorised over the segment: with s = target - t_from, F(s) and the current part of Q
    are exact for the whole span (the discretisation is a semigroup); the water-velocity
    noise leaves F unchanged, so its contribution is a cumulative sum.  The velocity of
    epoch k is held over [t_k, t_k+1) ((B20)-(B22)).  Positions: (B16)-(B22) with k_phi,
    k_lambda at each step's mid latitude.  Returns (lat, lon, c, P) at the targets,
    shapes (R, m), (R, m), (R, m, 2), (R, m, 4, 4), and leaves ``st`` at the last target.
    """
    targets = np.asarray(targets, float)
    pts = np.concatenate([[t_from], targets])
    dts = np.diff(pts)  # (m,)
    k = np.clip(np.searchsorted(t_s, pts[:-1], side="right") - 1, 0, t_s.size - 1)
    crs, spd = course[:, k], speed[:, k]  # (R, m)
    f_pc, phi = transition(targets - t_from, model.current_tau_s)  # (m,)
    step_pc = np.diff(np.concatenate([[0.0], f_pc]))  # increments of tau (1 - phi(s))
    d_n = spd * np.cos(crs) * dts + step_pc * st.c[:, :1]  # (B7), (B20): water + current
    d_e = spd * np.sin(crs) * dts + step_pc * st.c[:, 1:]  # (B8), corrected (B10), (B21)
    lat0 = st.lat[:, None]
    lat = lat0 + np.cumsum(d_n, axis=1) * k_phi(lat0)
    for _ in range(2):  # mid-latitude k_phi, refined twice (B16, B18)
        prev = np.concatenate([lat0, lat[:, :-1]], axis=1)
        lat = lat0 + np.cumsum(d_n * k_phi(0.5 * (prev + lat)), axis=1)
    prev = np.concatenate([lat0, lat[:, :-1]], axis=1)
    lon = wrap_pi(
        st.lon[:, None] + np.cumsum(d_e * k_lambda(0.5 * (prev + lat)), axis=1)
    )  # (B17, B19)
    c = phi[None, :, None] * st.c[:, None, :]
    f = _transition_matrix(targets - t_from, model.current_tau_s)  # (m, 4, 4)
    p = f @ st.p[:, None] @ np.swapaxes(f, -1, -2)  # (R, m, 4, 4)
    q_pp, q_pc, q_cc = _current_noise(targets - t_from, model)
    p[..., 0, 0] += q_pp
    p[..., 1, 1] += q_pp
    p[..., 2, 2] += q_cc
    p[..., 3, 3] += q_cc
    for i, j in ((0, 2), (2, 0), (1, 3), (3, 1)):
        p[..., i, j] += q_pc
    v_nn, v_ee, v_ne = (np.cumsum(v, axis=1) for v in _water_noise(dts, crs, spd, model))
    p[..., 0, 0] += v_nn
    p[..., 1, 1] += v_ee
    p[..., 0, 1] += v_ne
    p[..., 1, 0] += v_ne
    if targets.size:
        st.lat, st.lon, st.c, st.p = (
            lat[:, -1].copy(),
            lon[:, -1].copy(),
            c[:, -1].copy(),
            p[:, -1].copy(),
        )
    return lat, lon, c, p


@dataclass(frozen=True)
class UpdateRecord:
    """One measurement update: time, row kinds, normalised innovation squared (NIS,
    chi-square with ``dof`` degrees of freedom when consistent), and the position
    covariance (..., 2, 2; m^2) just before and just after."""

    t_s: float
    kinds: tuple[str, ...]
    nis: FloatArray
    dof: int
    cov_before_m2: FloatArray
    cov_after_m2: FloatArray


def _update(st: _State, obs: Observation, t_s: float) -> UpdateRecord:
    rows = obs.linearise(st.lat, st.lon)
    runs = st.lat.shape[0]
    g = np.broadcast_to(rows.g, (runs,) + rows.g.shape[-2:])
    r = np.broadcast_to(rows.residual, (runs,) + rows.residual.shape[-1:])
    rr = np.broadcast_to(rows.cov, (runs,) + rows.cov.shape[-2:])
    k_rows = r.shape[-1]
    h = np.zeros((runs, k_rows, 4))
    h[..., :2] = g  # H = [g, 0]: fixes and LOPs see the position only
    before = st.p[:, :2, :2].copy()
    pht = st.p @ np.swapaxes(h, -1, -2)
    s = h @ pht + rr  # innovation covariance
    s_inv = np.linalg.inv(s)
    gain = pht @ s_inv
    dx = np.einsum("rij,rj->ri", gain, r)
    nis = np.einsum("ri,rij,rj->r", r, s_inv, r)
    i_kh = np.eye(4) - gain @ h
    p = i_kh @ st.p @ np.swapaxes(i_kh, -1, -2) + gain @ rr @ np.swapaxes(gain, -1, -2)  # Joseph
    st.p = 0.5 * (p + np.swapaxes(p, -1, -2))
    st.lat, st.lon = add_offset_ne(st.lat, st.lon, dx[:, 0], dx[:, 1])
    st.c = st.c + dx[:, 2:]
    return UpdateRecord(float(t_s), rows.kinds, nis, k_rows, before, st.p[:, :2, :2].copy())


# ------------------------------------------------------------------------ results


@dataclass(frozen=True)
class CurrentTrack:
    """The EP and the current at each epoch (after any update at that epoch).

    Arrays have shape (n,) — or (runs, n) when the inputs carry a runs axis.
    ``cov`` (..., n, 4, 4): state covariance, (p_N, p_E) in metres, (c_N, c_E) in m/s.
    """

    t_s: FloatArray
    lat_rad: FloatArray
    lon_rad: FloatArray
    current_north_mps: FloatArray
    current_east_mps: FloatArray
    cov: FloatArray
    updates: tuple[UpdateRecord, ...]

    @property
    def position_cov_m2(self) -> FloatArray:
        return self.cov[..., :2, :2]

    @property
    def current_cov_m2ps2(self) -> FloatArray:
        return self.cov[..., 2:, 2:]

    @property
    def set_rad(self) -> FloatArray:
        """Direction the current flows TOWARDS, [0, 2pi): atan2(c_E, c_N)."""
        return wrap_2pi(np.arctan2(self.current_east_mps, self.current_north_mps))

    @property
    def drift_mps(self) -> FloatArray:
        return np.hypot(self.current_north_mps, self.current_east_mps)

    @property
    def drift_kn(self) -> FloatArray:
        return self.drift_mps / KN_MPS

    @property
    def set_deg(self) -> FloatArray:
        return np.rad2deg(self.set_rad)

    @property
    def drift_sigma_mps(self) -> FloatArray:
        """1-sigma of drift: sqrt(u^T P_c u), u the unit vector along the current."""
        u = np.stack([np.cos(self.set_rad), np.sin(self.set_rad)], axis=-1)
        # np.einsum is typed as returning Any
        return cast(
            FloatArray, np.sqrt(np.einsum("...i,...ij,...j->...", u, self.current_cov_m2ps2, u))
        )

    @property
    def set_sigma_rad(self) -> FloatArray:
        """1-sigma of set: sqrt(v^T P_c v) / drift, v across the current (linearised)."""
        v = np.stack([-np.sin(self.set_rad), np.cos(self.set_rad)], axis=-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            return cast(
                FloatArray,
                np.sqrt(np.einsum("...i,...ij,...j->...", v, self.current_cov_m2ps2, v))
                / self.drift_mps,
            )

    @property
    def ellipse(self) -> Ellipse:
        """1-sigma EP error ellipse at each epoch."""
        return error_ellipse(self.position_cov_m2)

    @property
    def two_drms_m(self) -> FloatArray:
        """The 2M circle radius, 2 sqrt(trace P_pos) (B30, B31)."""
        return 2.0 * np.sqrt(self.cov[..., 0, 0] + self.cov[..., 1, 1])


def estimate_current(
    t_s: ArrayLike,
    course_rad: ArrayLike,
    speed_mps: ArrayLike,
    start: PositionFix,
    fixes: Sequence[tuple[float, Observation]] = (),
    model: CurrentModel | None = None,
    *,
    current0_ne_mps: ArrayLike = (0.0, 0.0),
) -> CurrentTrack:
    """Run the filter over DR epochs ``t_s`` (n,) with course and speed through the water.

    ``course_rad`` and ``speed_mps``: (n,) or (runs, n); velocity at epoch k is held
    until epoch k+1 (the (B20)-(B22) step).  ``start``: the position at ``t_s[0]`` with
    its covariance (lat/lon may be (runs,)).  ``fixes``: (t_s, observation) pairs, in
    time order, each within [t_s[0], t_s[-1]]; a fix between epochs is applied at its
    own time.  ``current0_ne_mps``: prior mean of the current (north, east).
    """
    model = CurrentModel() if model is None else model
    t = np.asarray(t_s, float)
    if t.ndim != 1 or t.size < 1:
        raise InsufficientDataError(
            f"estimate_current: t_s must be a non-empty 1-D array, got shape {t.shape}"
        )
    if np.any(np.diff(t) < 0) or not np.all(np.isfinite(t)):
        raise InsufficientDataError(
            "estimate_current: epochs t_s must be finite and non-decreasing"
        )
    course = np.asarray(course_rad, float)
    speed = np.asarray(speed_mps, float)
    lat0 = np.atleast_1d(np.asarray(start.lat_rad, float))
    batched = course.ndim == 2 or speed.ndim == 2 or lat0.size > 1
    runs = max(
        course.shape[0] if course.ndim == 2 else 1,
        speed.shape[0] if speed.ndim == 2 else 1,
        lat0.size,
    )
    course = np.broadcast_to(course, (runs, t.size))
    speed = np.broadcast_to(speed, (runs, t.size))
    bad = ~np.isfinite(course[:, :-1]) | ~np.isfinite(speed[:, :-1])
    if np.any(bad):
        k = int(np.argwhere(bad)[0, 1])
        raise InsufficientDataError(
            f"estimate_current: course or speed missing at epoch {k} (t = {t[k]:.1f} s); bridge gaps first"
        )
    fix_times = [float(tf) for tf, _ in fixes]
    if fix_times and (
        np.any(np.diff(fix_times) < 0) or fix_times[0] < t[0] or fix_times[-1] > t[-1]
    ):
        raise InsufficientDataError(
            f"estimate_current: fix times must be in time order within [{t[0]:.1f}, {t[-1]:.1f}] s, "
            f"got {fix_times[0]:.1f} .. {fix_times[-1]:.1f} s"
        )
    sc2 = model.current0_sigma_mps**2
    p0 = np.zeros((runs, 4, 4))
    p0[:, :2, :2] = start.cov_m2
    p0[:, 2, 2] = p0[:, 3, 3] = sc2
    if math.isinf(model.speed_tau_s) or math.isinf(model.heading_tau_s):
        p0[:, 2:, 2:] += model.water_bias_cov(course[:, 0], speed[:, 0])  # absorbed by the current
    st = _State(
        np.broadcast_to(lat0, (runs,)).copy(),
        np.broadcast_to(np.atleast_1d(np.asarray(start.lon_rad, float)), (runs,)).copy(),
        np.broadcast_to(np.asarray(current0_ne_mps, float), (runs, 2)).copy(),
        p0,
    )
    n = t.size
    lat = np.empty((runs, n))
    lon = np.empty((runs, n))
    cur = np.empty((runs, n, 2))
    cov = np.empty((runs, n, 4, 4))
    updates: list[UpdateRecord] = []
    j = 0
    while j < len(fixes) and fix_times[j] <= t[0]:
        updates.append(_update(st, fixes[j][1], fix_times[j]))
        j += 1
    lat[:, 0], lon[:, 0], cur[:, 0], cov[:, 0] = st.lat, st.lon, st.c, st.p
    now, e = t[0], 1  # state time; next epoch to record
    for tf, obs in zip(fix_times[j:], [f[1] for f in fixes[j:]], strict=True):
        end = max(int(np.searchsorted(t, tf, side="left")), e)  # epochs before the fix: priors
        seg = _propagate(st, now, np.append(t[e:end], tf), t, course, speed, model)
        lat[:, e:end], lon[:, e:end], cur[:, e:end], cov[:, e:end] = (a[:, :-1] for a in seg)
        updates.append(_update(st, obs, tf))
        now, e = tf, end
    seg = _propagate(st, now, t[e:], t, course, speed, model)  # epochs at or after the last fix
    lat[:, e:], lon[:, e:], cur[:, e:], cov[:, e:] = seg
    if not batched:
        lat, lon, cur, cov = lat[0], lon[0], cur[0], cov[0]
        updates = [
            UpdateRecord(u.t_s, u.kinds, u.nis[0], u.dof, u.cov_before_m2[0], u.cov_after_m2[0])
            for u in updates
        ]
    return CurrentTrack(t, lat, lon, cur[..., 0], cur[..., 1], cov, tuple(updates))


@dataclass(frozen=True)
class OpenLoopComparison:
    """The seed's comparison (seeds/003, Figure 6): open-loop DR (no fixes, no current
    estimate) against the blended EP (DR + current filter + fixes), same inputs."""

    open_loop: CurrentTrack
    blended: CurrentTrack


def open_loop_vs_blended(
    t_s: ArrayLike,
    course_rad: ArrayLike,
    speed_mps: ArrayLike,
    start: PositionFix,
    fixes: Sequence[tuple[float, Observation]],
    model: CurrentModel | None = None,
) -> OpenLoopComparison:
    """Both tracks from the same DR inputs: open loop ignores the fixes (its covariance
    grows without bound), blended uses them (bounded)."""
    return OpenLoopComparison(
        estimate_current(t_s, course_rad, speed_mps, start, (), model),
        estimate_current(t_s, course_rad, speed_mps, start, fixes, model),
    )


# --------------------------------------------------------------------- simulation


@dataclass(frozen=True)
class SimulatedVoyage:
    """Truth of a simulated voyage (runs, n) and the DR inputs that go with it."""

    t_s: FloatArray
    lat_rad: FloatArray
    lon_rad: FloatArray
    current_ne_mps: FloatArray  # (runs, n, 2)
    course_rad: FloatArray  # (n,) course through the water, as measured
    speed_mps: FloatArray  # (n,)


def simulate_voyage(
    rng: np.random.Generator,
    t_s: ArrayLike,
    course_rad: ArrayLike,
    speed_mps: ArrayLike,
    start_lat_rad: float,
    start_lon_rad: float,
    model: CurrentModel,
    runs: int,
    *,
    current0_ne_mps: ArrayLike | None = None,
    start_sigma_m: float = 0.0,
) -> SimulatedVoyage:
    """Sample ``runs`` true voyages from exactly the filter's model (seeded).

    Truth state x = (p_N, p_E, c_N, c_E) evolves by x+ = F x + w, w ~ N(0, Q) with the
    F and Q of :func:`transition` and :func:`process_noise` (exact for the continuous
    model); the DR inputs (course, speed) are the given, error-free through-water
    values, the water-velocity noise being inside Q.  ``current0_ne_mps``: a fixed
    initial current (else drawn from N(0, sigma_c0^2)); ``start_sigma_m``: scatter of
    the true start about the nominal one (per axis).
    """
    t = np.asarray(t_s, float)
    n = t.size
    course = np.broadcast_to(np.asarray(course_rad, float), (n,))
    speed = np.broadcast_to(np.asarray(speed_mps, float), (n,))
    if current0_ne_mps is None:
        c = rng.normal(0.0, model.current0_sigma_mps, (runs, 2))
    else:
        c = np.broadcast_to(np.asarray(current0_ne_mps, float), (runs, 2)).copy()
    d0 = rng.normal(0.0, 1.0, (runs, 2)) * start_sigma_m
    lat, lon = add_offset_ne(
        np.full(runs, start_lat_rad), np.full(runs, start_lon_rad), d0[:, 0], d0[:, 1]
    )
    lats, lons = np.empty((runs, n)), np.empty((runs, n))
    curs = np.empty((runs, n, 2))
    lats[:, 0], lons[:, 0], curs[:, 0] = lat, lon, c
    for k in range(n - 1):
        dt = t[k + 1] - t[k]
        f_pc, phi = transition(dt, model.current_tau_s)
        q = process_noise(dt, course[k], speed[k], model)
        w = rng.standard_normal((runs, 4)) @ np.linalg.cholesky(q + 1e-15 * np.eye(4)).T
        d_n = speed[k] * np.cos(course[k]) * dt + f_pc * c[:, 0] + w[:, 0]
        d_e = speed[k] * np.sin(course[k]) * dt + f_pc * c[:, 1] + w[:, 1]
        lat, lon = add_offset_ne(lat, lon, d_n, d_e)
        c = phi * c + w[:, 2:]
        lats[:, k + 1], lons[:, k + 1], curs[:, k + 1] = lat, lon, c
    return SimulatedVoyage(t, lats, lons, curs, np.array(course), np.array(speed))


def nees(track: CurrentTrack, voyage: SimulatedVoyage) -> FloatArray:
    """Normalised estimation error squared (runs, n) of the 4-state against the truth
    (chi-square with 4 degrees of freedom for a consistent filter)."""
    d_n, d_e = offset_ne_m(voyage.lat_rad, voyage.lon_rad, track.lat_rad, track.lon_rad)
    err = np.stack(
        [
            d_n,
            d_e,
            voyage.current_ne_mps[..., 0] - track.current_north_mps,
            voyage.current_ne_mps[..., 1] - track.current_east_mps,
        ],
        axis=-1,
    )
    return cast(
        FloatArray,
        np.einsum("...i,...i->...", err, np.linalg.solve(track.cov, err[..., None])[..., 0]),
    )


__all__ = [
    "CurrentModel",
    "CurrentTrack",
    "OpenLoopComparison",
    "SimulatedVoyage",
    "UpdateRecord",
    "estimate_current",
    "nees",
    "open_loop_vs_blended",
    "process_noise",
    "simulate_voyage",
    "transition",
]
