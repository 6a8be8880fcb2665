"""The sensor error processes of the simulator: Gauss-Markov noise, the INS error model,
and every true error series of a voyage (:func:`sensor_errors`).

Error processes are first-order Gauss-Markov (exact discretisation
``x[k+1] = a x[k] + sigma sqrt(1 - a^2) w[k]``, ``a = exp(-dt/tau)``, started stationary),
``tau = inf`` a bias drawn once, ``tau = 0`` white noise.  INS errors add a Schuler
oscillation (period ``2 pi sqrt(R/g)`` = 84.4 min), a 24 h oscillation and a linear drift.
Errors are *measured minus true*.  Each component draws from its own random stream
(:func:`component_rng`), so adding one never changes the others.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy.signal import lfilter

from dracc.core.errors import ConfigError
from dracc.core.units import DEG_RAD, KN_MPS
from dracc.sim.params import InsErrorParams, SimParams

SCHULER_PERIOD_S = 84.4 * 60.0  #: Schuler period 2 pi sqrt(R/g) = 84.4 min
DAY_PERIOD_S = 86400.0  #: the 24 h INS oscillation (earth rate)

#: draws a named Gauss-Markov process: (key, sigma, tau_s, rng) -> samples; :func:`simulate`
#: passes one that continues each process from the previous segment's last value
GmDraw = Callable[[str, float, float, np.random.Generator], np.ndarray]


def component_rng(seed: int, component: int, segment: int = 0) -> np.random.Generator:
    """An independent stream per component (and segment), so adding one never changes the
    others."""
    key = [int(seed) & 0xFFFFFFFF, component] + ([segment] if segment else [])
    return np.random.default_rng(key)


def gauss_markov(
    n: int,
    dt_s: float,
    sigma: float,
    tau_s: float,
    rng: np.random.Generator,
    runs: int | None = None,
    x0: float | None = None,
) -> np.ndarray:
    """First-order Gauss-Markov samples, started stationary (variance sigma^2 throughout).

    ``x[0] = sigma w0``, ``x[k+1] = a x[k] + sigma sqrt(1 - a^2) w[k+1]``,
    ``a = exp(-dt/tau)`` (exact discretisation of ``dx = -x/tau dt + sigma sqrt(2/tau) dW``).
    ``tau = inf``: a constant ``sigma w0``; ``tau = 0``: white noise.  Shape ``(n,)`` or
    ``(runs, n)`` (Monte Carlo runs vectorised along axis 0).  ``x0``: continue a process
    whose value at the first sample is ``x0`` (a voyage simulated in segments).
    """
    shape = (n,) if runs is None else (runs, n)
    if sigma == 0.0 or n == 0:
        return np.zeros(shape)
    if tau_s < 0 or math.isnan(tau_s):
        raise ConfigError(f"correlation time tau_s must be >= 0 or inf, got {tau_s}")
    w = rng.standard_normal(shape)
    if x0 is not None and tau_s > 0:
        w[..., 0] = x0 / sigma
    if math.isinf(tau_s):
        return np.broadcast_to(sigma * w[..., :1], shape).copy()
    if tau_s == 0.0:
        return sigma * w
    a = math.exp(-dt_s / tau_s)
    q = math.sqrt(1.0 - a * a)
    drive = q * w
    drive[..., 0] = w[..., 0]  # stationary start: x[0] = w0, then the recursion
    return sigma * lfilter([1.0], [1.0, -a], drive, axis=-1)


def ins_errors(
    p: InsErrorParams,
    t_s: np.ndarray,
    dt_s: float,
    rng: np.random.Generator,
    phases: np.ndarray | None = None,
    gm: GmDraw | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One INS unit's errors (north_m, east_m, heading_rad, vn_mps, ve_mps) at times ``t_s``.

    The velocity errors are the time derivative of the smooth part of the position error
    (oscillations, drift, the GM's mean reversion), as an INS's velocity and position
    errors are tied.
    """
    n = len(t_s)
    ph = rng.uniform(0.0, 2 * np.pi, 6) if phases is None else phases
    if gm is None:

        def gm(key: str, sigma: float, tau_s: float, r: np.random.Generator) -> np.ndarray:
            return gauss_markov(n, dt_s, sigma, tau_s, r)

    ws = 2 * np.pi / SCHULER_PERIOD_S
    wd = 2 * np.pi / DAY_PERIOD_S
    gm_n = gm("north", p.gm_m.sigma, p.gm_m.tau_s, rng)
    gm_e = gm("east", p.gm_m.sigma, p.gm_m.tau_s, rng)
    smooth_n = (
        p.schuler_n_m * np.sin(ws * t_s + ph[0])
        + p.day_n_m * np.sin(wd * t_s + ph[1])
        + p.drift_n_mps * t_s
        + gm_n
    )
    smooth_e = (
        p.schuler_e_m * np.sin(ws * t_s + ph[2])
        + p.day_e_m * np.sin(wd * t_s + ph[3])
        + p.drift_e_mps * t_s
        + gm_e
    )
    north = smooth_n + p.white_m * rng.standard_normal(n)
    east = smooth_e + p.white_m * rng.standard_normal(n)
    hb = gm("heading", p.heading_gm_deg.sigma, p.heading_gm_deg.tau_s, rng)
    heading = DEG_RAD * (
        p.heading_bias_deg
        + p.heading_schuler_deg * np.sin(ws * t_s + ph[4])
        + p.heading_day_deg * np.sin(wd * t_s + ph[5])
        + hb
        + p.heading_white_deg * rng.standard_normal(n)
    )
    # d/dt of the oscillations and the drift, and the mean-reverting part -x/tau of the GM
    # (its white driving term is not a velocity an INS would show)
    gm_rate = 0.0 if not np.isfinite(p.gm_m.tau_s) or p.gm_m.tau_s == 0 else 1.0 / p.gm_m.tau_s
    vn = (
        p.schuler_n_m * ws * np.cos(ws * t_s + ph[0])
        + p.day_n_m * wd * np.cos(wd * t_s + ph[1])
        + p.drift_n_mps
        - gm_rate * gm_n
    )
    ve = (
        p.schuler_e_m * ws * np.cos(ws * t_s + ph[2])
        + p.day_e_m * wd * np.cos(wd * t_s + ph[3])
        + p.drift_e_mps
        - gm_rate * gm_e
    )
    return north, east, heading, vn, ve


def sensor_errors(
    p: SimParams,
    track: dict[str, np.ndarray],
    t_s: np.ndarray,
    dt: float,
    gm: GmDraw,
    segment: int,
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Every true error series (measured - true) at the samples of ``track`` (the columns
    of :func:`dracc.sim.truth.true_track`), and the white noise of the ROT sentence.

    Keys: time_ns, gyro_err_rad, mag_err_rad (on KK), log_scale, log_bias_mps,
    log_noise_long_mps, log_noise_transverse_mps, log_ground_noise_long_mps,
    log_ground_noise_transverse_mps, leeway_rad, current_n_mps, current_e_mps, insJ_north_m,
    insJ_east_m, insJ_heading_rad, insJ_vn_mps, insJ_ve_mps (J = 1..3), gnss_north_m,
    gnss_east_m, gnss_vn_mps, gnss_ve_mps.
    """
    n = len(t_s)
    seg = segment
    errors: dict[str, np.ndarray] = {"time_ns": track["time_ns"]}
    r = component_rng(p.seed, 3, seg)
    errors["gyro_err_rad"] = DEG_RAD * (
        p.gyro_offset_deg
        + gm("gyro_bias", p.gyro_bias_deg.sigma, p.gyro_bias_deg.tau_s, r)
        + gm("gyro_noise", p.gyro_noise_deg.sigma, p.gyro_noise_deg.tau_s, r)
        + p.gyro_white_deg * r.standard_normal(n)
    )
    rot_noise = p.rot_white_dpm * DEG_RAD / 60.0 * r.standard_normal(n)
    r = component_rng(p.seed, 4, seg)
    errors["mag_err_rad"] = DEG_RAD * (
        gm("mag_noise", p.mag_noise_deg.sigma, p.mag_noise_deg.tau_s, r)
        + p.mag_white_deg * r.standard_normal(n)
    )
    r = component_rng(p.seed, 5, seg)
    errors["log_scale"] = np.full(n, float(p.log_scale))
    errors["log_bias_mps"] = np.full(n, p.log_bias_kn * KN_MPS)
    for name in (
        "log_noise_long_mps",
        "log_noise_transverse_mps",
        "log_ground_noise_long_mps",
        "log_ground_noise_transverse_mps",
    ):
        errors[name] = KN_MPS * (
            gm(name, p.log_noise_kn.sigma, p.log_noise_kn.tau_s, r)
            + p.log_white_kn * r.standard_normal(n)
        )
    errors["leeway_rad"] = track["leeway_rad"]
    errors["current_n_mps"] = track["current_n_mps"]
    errors["current_e_mps"] = track["current_e_mps"]
    for j, unit in enumerate(p.ins, start=1):
        r = component_rng(p.seed, 10 + j, seg)
        phases = component_rng(p.seed, 30 + j).uniform(0.0, 2 * np.pi, 6)  # shared by segments

        def ins_gm(
            key: str, sigma: float, tau_s: float, rr: np.random.Generator, j: int = j
        ) -> np.ndarray:
            return gm(f"ins{j}_{key}", sigma, tau_s, rr)

        en, ee, eh, evn, eve = ins_errors(unit, t_s, dt, r, phases=phases, gm=ins_gm)
        wv = p.ins_velocity_white_kn * KN_MPS
        errors[f"ins{j}_north_m"] = en
        errors[f"ins{j}_east_m"] = ee
        errors[f"ins{j}_heading_rad"] = eh
        errors[f"ins{j}_vn_mps"] = evn + wv * r.standard_normal(n)
        errors[f"ins{j}_ve_mps"] = eve + wv * r.standard_normal(n)
    r = component_rng(p.seed, 20, seg)
    errors["gnss_north_m"] = gm(
        "gnss_north", p.gnss_noise_m.sigma, p.gnss_noise_m.tau_s, r
    ) + p.gnss_white_m * r.standard_normal(n)
    errors["gnss_east_m"] = gm(
        "gnss_east", p.gnss_noise_m.sigma, p.gnss_noise_m.tau_s, r
    ) + p.gnss_white_m * r.standard_normal(n)
    errors["gnss_vn_mps"] = p.gnss_speed_white_kn * KN_MPS * r.standard_normal(n)
    errors["gnss_ve_mps"] = p.gnss_speed_white_kn * KN_MPS * r.standard_normal(n)
    return errors, rot_noise
