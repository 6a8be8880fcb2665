"""Voyage simulator with known truth: the track, the sensors and their error processes.

Pure numpy; no I/O.  :func:`simulate` turns a :class:`SimParams` into a :class:`SimVoyage`
holding the truth, every true error series, and the canonical frames
(:mod:`dracc.frames`) that a perfect parser of the written log returns.

Glossary (symbols of the dead-reckoning paper, METHODS.md §2)
    ``psi``    true heading KZ + pz of the ship (rad, [0, 2pi))
    ``alpha``  leeway: angle from the heading to the course through the water (starboard +)
    ``KK``     magnetic compass course; ``psi = KK + delta(KK) + d`` (B2 without leeway)
    ``delta``  deviation ``A + B sin KK + C cos KK + D sin 2KK + E cos 2KK`` (east +)
    ``d``      magnetic variation (east +)
    ``V``      speed through the water; ``Vx = V cos alpha``, ``Vy = V sin alpha`` (B1, B5)
    ``Vp, Kp`` current drift and set; ground velocity ``VN = V cos(psi+alpha) + Vp cos Kp``,
               ``VE = V sin(psi+alpha) + Vp sin Kp`` (B7-B12, B10 corrected)

Errors are always *measured minus true*: a gyro error of +0.3 deg reads 0.3 deg high, so the
total gyro correction of (B3) is ``pz = -gyro_err``.  A log scale error ``s`` and bias ``b``
read ``(1 + s) V + b``.  INS and GNSS position errors are metres north and east of the truth.

Error processes are first-order Gauss-Markov (exact discretisation
``x[k+1] = a x[k] + sigma sqrt(1 - a^2) w[k]``, ``a = exp(-dt/tau)``, started stationary),
``tau = inf`` a bias drawn once, ``tau = 0`` white noise.  INS errors add a Schuler
oscillation (period ``2 pi sqrt(R/g)`` = 84.4 min), a 24 h oscillation and a linear drift.

Written precision (what the frames carry, and what the NMEA writer prints):
latitude/longitude minutes 6 decimals (1.9 mm), headings and courses 3 decimals of a degree,
speeds 3 decimals of a knot (and km/h), rate of turn 2 decimals of deg/min, distances
3 decimals of a nautical mile, altitude and HDOP 1 decimal; times to the nanosecond in the
frames (the written log carries them to its form's resolution).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from datetime import datetime, timezone

import numpy as np
import pandas as pd
from pandas.api.types import union_categoricals
from scipy.signal import lfilter

from dracc.core.errors import ConfigError
from dracc.core.geodesy import add_offset_ne, angdiff, k_lambda, k_phi, wrap_2pi, wrap_pi
from dracc.core.units import DEG_RAD, KN_MPS, NMI_M
from dracc.frames import KINDS, empty_frame, make_frame
from dracc.sim.faults import SimFault, apply_error_faults, apply_frame_faults, resolve_faults

MAX_SAMPLES = 3e6  #: truth samples in one simulate() call (~1.7 kB each at peak)
SCHULER_PERIOD_S = 84.4 * 60.0  #: Schuler period 2 pi sqrt(R/g) = 84.4 min
DAY_PERIOD_S = 86400.0  #: the 24 h INS oscillation (earth rate)
KMH_MPS = 1000.0 / 3600.0

# Written precision (see module docstring); shared with nmea_out.
LAT_MICROMIN = 1e6  #: minutes of arc written with 6 decimals
ANGLE_DEC = 3  #: headings/courses in degrees
SPEED_DEC = 3  #: knots and km/h
ROT_DEC = 2  #: deg/min
DIST_DEC = 3  #: nautical miles
ALT_DEC = 1
HDOP_DEC = 1

#: source key -> (role, talker) in emission order within an epoch
SOURCES = {
    "GYRO": ("compass", "HE"),
    "MAG": ("compass", "HC"),
    "LOG": ("log", "VW"),
    "INS1": ("ins1", "IN"),
    "INS2": ("ins2", "IN"),
    "INS3": ("ins3", "IN"),
    "GNSS": ("gnss", "GP"),
}


@dataclass(frozen=True)
class GM:
    """A first-order Gauss-Markov error process: ``sigma`` in the unit of the field holding
    it, correlation time ``tau_s`` (``inf``: a bias drawn once; ``0``: white noise)."""

    sigma: float = 0.0
    tau_s: float = math.inf


@dataclass(frozen=True)
class InsErrorParams:
    """One INS unit's error process.  Position errors in metres north (``_n``) and east
    (``_e``); heading error in degrees.  Each oscillation gets a random phase from the seed.

    north(t) = schuler_n_m sin(2 pi t / 84.4 min + p1) + day_n_m sin(2 pi t / 24 h + p2)
               + drift_n_mps t + GM(gm_m) + white
    (east alike; heading: bias + Schuler + 24 h + GM + white).
    """

    schuler_n_m: float = 150.0
    schuler_e_m: float = 180.0
    day_n_m: float = 250.0
    day_e_m: float = 320.0
    drift_n_mps: float = 0.0015
    drift_e_mps: float = -0.002
    gm_m: GM = GM(30.0, 3600.0)
    white_m: float = 3.0
    heading_bias_deg: float = 0.02
    heading_schuler_deg: float = 0.01
    heading_day_deg: float = 0.04
    heading_gm_deg: GM = GM(0.01, 1800.0)
    heading_white_deg: float = 0.005

    def scaled(self, k: float) -> InsErrorParams:
        """Every error amplitude multiplied by ``k`` (correlation times unchanged)."""
        kw = {}
        for f in fields(self):
            v = getattr(self, f.name)
            kw[f.name] = GM(v.sigma * k, v.tau_s) if isinstance(v, GM) else v * k
        return InsErrorParams(**kw)


#: three realistic, unequal units: INS2 clearly the worst (RMS ~550 m N, ~800 m E over a day)
DEFAULT_INS = (
    InsErrorParams(),
    InsErrorParams(
        schuler_n_m=350.0,
        schuler_e_m=450.0,
        day_n_m=700.0,
        day_e_m=1000.0,
        drift_n_mps=-0.004,
        drift_e_mps=0.005,
        gm_m=GM(60.0, 3600.0),
        white_m=5.0,
        heading_bias_deg=-0.08,
        heading_schuler_deg=0.04,
        heading_day_deg=0.15,
        heading_gm_deg=GM(0.04, 1800.0),
        heading_white_deg=0.01,
    ),
    InsErrorParams(
        schuler_n_m=180.0,
        schuler_e_m=220.0,
        day_n_m=320.0,
        day_e_m=400.0,
        drift_n_mps=-0.002,
        drift_e_mps=0.0025,
        gm_m=GM(40.0, 3600.0),
        white_m=3.0,
        heading_bias_deg=0.03,
        heading_schuler_deg=0.015,
        heading_day_deg=0.06,
        heading_gm_deg=GM(0.015, 1800.0),
        heading_white_deg=0.005,
    ),
)
NO_INS_ERROR = InsErrorParams(
    **{f.name: (GM(0.0, math.inf) if f.type in ("GM", GM) else 0.0) for f in fields(InsErrorParams)}
)


@dataclass(frozen=True)
class SimParams:
    """Everything that defines a simulated voyage.  Degrees and knots at this edge only.

    ``legs``: course changes as ``((time_s, heading_deg), ...)`` (the heading steered from
    ``time_s`` on, reached at ``turn_rate_deg_s``); ``None`` generates one from the seed
    (a new heading every 2-4 h).  Rates in Hz; every rate must divide the fastest one
    (the truth's rate) to a whole number of samples.  ``aux_hz`` is the rate of the gyro's
    THS and ROT sentences (0: none).  ``compass``: which compass is fitted ('both': gyro and
    magnetic; the gyro then holds the role ``compass``).
    """

    duration_s: float = 4 * 3600.0
    seed: int = 0
    start_utc: str | datetime = "2026-03-01T00:00:00Z"
    start_lat_deg: float = 54.60
    start_lon_deg: float = 18.80
    speed_kn: float = 12.0
    legs: tuple[tuple[float, float], ...] | None = None
    initial_heading_deg: float = 60.0
    turn_rate_deg_s: float = 0.5
    yaw_amp_deg: float = 0.5  #: sea-state yaw oscillation of the true heading
    yaw_period_s: float = 15.0
    alt_m: float = 25.0  #: antenna height written in GGA
    # rates
    compass_hz: float = 10.0
    log_hz: float = 1.0
    ins_hz: float = 1.0
    gnss_hz: float = 1.0
    aux_hz: float = 1.0
    compass: str = "gyro"
    # gyro compass (measured - true)
    gyro_offset_deg: float = 0.3  #: constant gyro error (reads high +), known exactly
    gyro_bias_deg: GM = GM(0.0, math.inf)  #: a further random bias, drawn from the seed
    gyro_noise_deg: GM = GM(0.1, 300.0)
    gyro_white_deg: float = 0.02
    rot_white_dpm: float = 0.5  #: white noise of the ROT sentence, deg/min
    # magnetic compass: deviation curve (B2) coefficients A..E in degrees, variation
    deviation_deg: tuple[float, float, float, float, float] = (0.5, 2.0, -1.5, 0.8, 0.3)
    variation_deg: float = 5.0
    mag_noise_deg: GM = GM(0.5, 120.0)
    mag_white_deg: float = 0.1
    hdg_deviation_field: bool = True  #: write the deviation of the curve in HDG (else empty)
    # speed log (measured = (1 + scale) * true + bias + noise)
    log_scale: float = 0.02
    log_bias_kn: float = 0.05
    log_noise_kn: GM = GM(0.1, 300.0)
    log_white_kn: float = 0.02
    log_total_start_nmi: float = 10234.5  #: VLW total distance at the start
    # leeway (starboard +) and current (set towards, drift) plus Gauss-Markov per axis
    leeway_deg: float = 1.0
    leeway_noise_deg: GM = GM(0.3, 600.0)
    current_set_deg: float = 120.0
    current_drift_kn: float = 0.5
    current_noise_kn: GM = GM(0.2, 1800.0)
    # three INS
    ins: tuple[InsErrorParams, InsErrorParams, InsErrorParams] = DEFAULT_INS
    ins_velocity_white_kn: float = 0.02
    #: talker IDs of INS1..INS3; e.g. ("II", "IN", "IR") keeps them apart without TAG blocks
    ins_talkers: tuple[str, str, str] = ("IN", "IN", "IN")
    # GNSS
    gnss_noise_m: GM = GM(1.5, 60.0)
    gnss_white_m: float = 0.3
    gnss_speed_white_kn: float = 0.03
    gnss_hdop: float = 0.8
    #: seeded sensor faults (:mod:`dracc.sim.faults`); unresolved fields take the kind's
    #: defaults, drawn from the seed over the whole voyage
    faults: tuple[SimFault, ...] = ()
    # segments of a long voyage (see dracc.sim.model.simulate_segments)
    t0_s: float = 0.0  #: time of this segment's first sample from the voyage start
    segment: int = 0  #: segment number (its own random streams; phases are shared)
    skip_first: bool = False  #: drop the first sample (the previous segment's last one)
    #: values of every Gauss-Markov process and the VLW trip at the first sample
    state: dict | None = field(default=None, compare=False)

    @classmethod
    def noiseless(cls, **overrides) -> SimParams:
        """Exact-truth voyage: no sensor error, no current, no leeway, no yaw; every
        sentence reads the truth (to its written precision).  ``overrides`` apply last."""
        zero = GM(0.0, math.inf)
        base = dict(
            gyro_offset_deg=0.0,
            gyro_bias_deg=zero,
            gyro_noise_deg=zero,
            gyro_white_deg=0.0,
            rot_white_dpm=0.0,
            mag_noise_deg=zero,
            mag_white_deg=0.0,
            log_scale=0.0,
            log_bias_kn=0.0,
            log_noise_kn=zero,
            log_white_kn=0.0,
            leeway_deg=0.0,
            leeway_noise_deg=zero,
            current_drift_kn=0.0,
            current_noise_kn=zero,
            yaw_amp_deg=0.0,
            ins=(NO_INS_ERROR,) * 3,
            ins_velocity_white_kn=0.0,
            gnss_noise_m=zero,
            gnss_white_m=0.0,
            gnss_speed_white_kn=0.0,
        )
        base.update(overrides)
        return cls(**base)

    def with_ins_error_scale(self, k: float) -> SimParams:
        """The same voyage with every INS error amplitude multiplied by ``k``."""
        return replace(self, ins=tuple(u.scaled(k) for u in self.ins))

    def to_dict(self) -> dict:
        """A JSON-ready dict (GM as {"sigma", "tau_s"}, inf as the string "inf")."""

        def conv(v):
            if isinstance(v, GM):
                return {"sigma": conv(v.sigma), "tau_s": conv(v.tau_s)}
            if isinstance(v, (InsErrorParams, SimFault)):
                return {f.name: conv(getattr(v, f.name)) for f in fields(v)}
            if isinstance(v, (tuple, list)):
                return [conv(x) for x in v]
            if isinstance(v, datetime):
                return v.isoformat()
            if isinstance(v, float) and math.isinf(v):
                return "inf"
            return v

        return {f.name: conv(getattr(self, f.name)) for f in fields(self) if f.name != "state"}


@dataclass(frozen=True)
class SimVoyage:
    """A simulated voyage: truth, sensor errors, and the canonical frames of its log."""

    truth: pd.DataFrame  #: at the fastest sensor rate; see :func:`simulate`
    frames: dict[str, pd.DataFrame]  #: kind -> canonical frame, as a perfect parser returns
    roles: dict[str, str]  #: source key -> role
    errors: pd.DataFrame  #: every true error series, same time base as ``truth``
    #: INS unit ('ins1'..) -> {'lat_m', 'lon_m', 'course_deg'}: RMS of its written errors
    unit_rms: dict[str, dict[str, float]]
    params: SimParams
    #: (time_ns, source) of each GNSS ZDA sentence (no canonical frame holds ZDA)
    zda: pd.DataFrame = field(default_factory=lambda: pd.DataFrame({"time_ns": [], "source": []}))
    #: every Gauss-Markov process's last value, the VLW trip and the last position: what
    #: the next segment continues from
    state: dict = field(default_factory=dict)


# --------------------------------------------------------------------------- processes


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


def deviation_curve_rad(kk_rad, coeffs_rad) -> np.ndarray:
    """Deviation ``delta = A + B sin KK + C cos KK + D sin 2KK + E cos 2KK`` (east +)."""
    a, b, c, d, e = coeffs_rad
    kk = np.asarray(kk_rad, float)
    return a + b * np.sin(kk) + c * np.cos(kk) + d * np.sin(2 * kk) + e * np.cos(2 * kk)


def compass_course_rad(heading_rad, coeffs_rad, variation_rad) -> np.ndarray:
    """The magnetic compass course KK with ``heading = KK + delta(KK) + d`` (B2), by Newton's
    method on ``f(KK) = KK + delta(KK) + d - heading`` (``f' = 1 + delta'``, > 0 for any real
    compass, whose deviation changes by far less than a degree per degree of heading)."""
    a, b, c, d, e = coeffs_rad
    target = np.asarray(heading_rad, float) - variation_rad
    kk = target - deviation_curve_rad(target, coeffs_rad)
    for _ in range(20):
        f = angdiff(kk + deviation_curve_rad(kk, coeffs_rad), target)
        fp = 1.0 + b * np.cos(kk) - c * np.sin(kk) + 2 * d * np.cos(2 * kk) - 2 * e * np.sin(2 * kk)
        kk = kk - f / fp
        if np.max(np.abs(f), initial=0.0) < 1e-14:
            break
    return wrap_2pi(kk)


def integrate_track(
    lat0_rad: float, lon0_rad: float, vn_mps: np.ndarray, ve_mps: np.ndarray, dt_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Position on the WGS-84 ellipsoid from north/east ground velocity (B16-B22).

    ``phi[k+1] = phi[k] + k_phi(phi_mid) VN_mid dt`` and ``lambda[k+1] = lambda[k] +
    k_lambda(phi_mid) VE_mid dt`` with trapezoidal velocities and the mid-step latitude,
    solved for all steps at once by fixed-point iteration on the latitude profile.
    """
    dn = 0.5 * (vn_mps[1:] + vn_mps[:-1]) * dt_s
    de = 0.5 * (ve_mps[1:] + ve_mps[:-1]) * dt_s
    lat = np.full(len(vn_mps), lat0_rad)
    for _ in range(4):
        mid = 0.5 * (lat[1:] + lat[:-1])
        lat = lat0_rad + np.concatenate(([0.0], np.cumsum(k_phi(mid) * dn)))  # (B16, B20)
    mid = 0.5 * (lat[1:] + lat[:-1])
    lon = lon0_rad + np.concatenate(([0.0], np.cumsum(k_lambda(mid) * de)))  # (B17, B21)
    return lat, wrap_pi(lon)


def ins_errors(
    p: InsErrorParams,
    t_s: np.ndarray,
    dt_s: float,
    rng: np.random.Generator,
    phases: np.ndarray | None = None,
    gm=None,
):
    """One INS unit's errors (north_m, east_m, heading_rad, vn_mps, ve_mps) at times ``t_s``.

    The velocity errors are the time derivative of the smooth part of the position error
    (oscillations, drift, the GM's mean reversion), as an INS's velocity and position
    errors are tied.
    """
    n = len(t_s)
    ph = rng.uniform(0.0, 2 * np.pi, 6) if phases is None else phases
    if gm is None:

        def gm(key, sigma, tau_s, r):
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


# --------------------------------------------------------------------------- quantisation


def q_angle_rad(a_rad) -> np.ndarray:
    """An angle in [0, 2pi) as written: degrees to ANGLE_DEC decimals (360.000 -> 0.000)."""
    s = 10.0**ANGLE_DEC
    v = np.rint(np.asarray(wrap_2pi(a_rad), float) / DEG_RAD * s)
    v = np.where(v >= 360 * s, v - 360 * s, v)
    return v / s * DEG_RAD


def q_signed(x, scale: float, dec: int) -> np.ndarray:
    """``x`` (SI) written as ``x / scale`` to ``dec`` decimals, read back in SI."""
    s = 10.0**dec
    return np.rint(np.asarray(x, float) / scale * s) / s * scale


def q_latlon_rad(a_rad) -> np.ndarray:
    """Latitude or longitude as written: degrees and minutes to 6 decimals of a minute."""
    a = np.asarray(a_rad, float)
    micro = np.rint(np.abs(a) / DEG_RAD * 60.0 * LAT_MICROMIN)
    deg = np.floor_divide(micro, 60.0 * LAT_MICROMIN)
    minutes = (micro - deg * 60.0 * LAT_MICROMIN) / LAT_MICROMIN
    return np.sign(a) * (deg + minutes / 60.0) * DEG_RAD


# --------------------------------------------------------------------------- simulate


def _rng(seed: int, component: int, segment: int = 0) -> np.random.Generator:
    """An independent stream per component (and segment), so adding one never changes the
    others."""
    key = [int(seed) & 0xFFFFFFFF, component] + ([segment] if segment else [])
    return np.random.default_rng(key)


def start_ns(start_utc: str | datetime) -> int:
    """Start time as int64 UTC ns; naive datetimes and ISO strings without zone are UTC."""
    try:
        ts = pd.Timestamp(start_utc)
    except (ValueError, TypeError) as e:
        raise ConfigError(f"start time {start_utc!r} is not an ISO 8601 time") from e
    if ts.tzinfo is None:
        ts = ts.tz_localize(timezone.utc)
    return int(ts.tz_convert(timezone.utc).value)


def _generated_legs(p: SimParams) -> tuple[tuple[float, float], ...]:
    rng = _rng(p.seed, 1)
    legs = [(0.0, p.initial_heading_deg)]
    t, h = 0.0, p.initial_heading_deg
    while True:
        t += rng.uniform(2 * 3600.0, 4 * 3600.0)
        if t >= p.duration_s:
            break
        h = (h + rng.choice([-1, 1]) * rng.uniform(30.0, 120.0)) % 360.0
        legs.append((t, h))
    return tuple(legs)


def _heading_profile(t_s: np.ndarray, legs, initial_deg: float, rate_rad_s: float):
    """Steered heading (rad) and its rate: each leg turns the shorter way at ``rate``."""
    psi = np.empty_like(t_s)
    rot = np.zeros_like(t_s)
    legs = sorted((float(a), float(b)) for a, b in legs)
    if not legs or legs[0][0] > t_s[0]:
        legs = [(float(t_s[0]), initial_deg)] + legs
    h_start = legs[0][1] * DEG_RAD
    for i, (t0, c_deg) in enumerate(legs):
        t1 = legs[i + 1][0] if i + 1 < len(legs) else np.inf
        sel = (t_s >= t0) & (t_s < t1)
        if i == 0:
            sel |= t_s < t0
            h_start = c_deg * DEG_RAD
        delta = float(angdiff(c_deg * DEG_RAD, h_start))
        turn_s = abs(delta) / rate_rad_s if rate_rad_s > 0 else 0.0
        el = np.clip(t_s[sel] - t0, 0.0, None)
        psi[sel] = h_start + np.sign(delta) * rate_rad_s * np.minimum(el, turn_s)
        rot[sel] = np.where(el < turn_s, np.sign(delta) * rate_rad_s, 0.0)
        if np.isfinite(t1):
            el1 = t1 - t0
            h_start = h_start + np.sign(delta) * rate_rad_s * min(el1, turn_s)
    return psi, rot


def _check(p: SimParams) -> float:
    if not p.duration_s > 0:
        raise ConfigError(f"duration must be positive, got {p.duration_s} s")
    if p.compass not in ("gyro", "magnetic", "both"):
        raise ConfigError(f"compass must be gyro, magnetic or both, got {p.compass!r}")
    if not -89.0 < p.start_lat_deg < 89.0:
        raise ConfigError(f"start latitude {p.start_lat_deg} deg is outside (-89, 89)")
    if len(p.ins_talkers) != 3 or not all(
        len(t) == 2 and t.isascii() and t.isalnum() and t.isupper() for t in p.ins_talkers
    ):
        raise ConfigError(f"three two-letter INS talker IDs are needed, got {p.ins_talkers!r}")
    if len(p.ins) != 3:
        raise ConfigError(f"three INS error models are needed, got {len(p.ins)}")
    rates = {
        "compass_hz": p.compass_hz,
        "log_hz": p.log_hz,
        "ins_hz": p.ins_hz,
        "gnss_hz": p.gnss_hz,
    }
    for k, v in rates.items():
        if not v > 0:
            raise ConfigError(f"{k} must be positive, got {v}")
    if p.aux_hz < 0:
        raise ConfigError(f"aux_hz must be >= 0, got {p.aux_hz}")
    base = max(*rates.values(), p.aux_hz)
    for k, v in {**rates, "aux_hz": p.aux_hz}.items():
        if v == 0:
            continue
        step = base / v
        if abs(step - round(step)) > 1e-9:
            raise ConfigError(
                f"{k}={v} does not divide the fastest rate {base} Hz into whole steps"
            )
    if base * p.duration_s > MAX_SAMPLES:
        raise ConfigError(
            f"{base} Hz over {p.duration_s:g} s is {base * p.duration_s:.3g} samples "
            f"(about {base * p.duration_s * 1.7e-6:.0f} GB); more than "
            f"{MAX_SAMPLES:.0e} in one piece: use simulate_segments (as "
            f"`dracc simulate` does) or lower the rates"
        )
    return base


def simulate(params: SimParams) -> SimVoyage:
    """Simulate a voyage: truth, sensor readings with known errors, canonical frames.

    ``truth`` columns: time_ns, t_s (from the start), lat_rad, lon_rad, heading_rad (true),
    rot_radps, leeway_rad, course_water_rad, stw_mps (V), stw_long_mps (Vx),
    stw_transverse_mps (Vy), vn_mps, ve_mps (over ground), cog_rad, sog_mps,
    sog_long_mps, sog_transverse_mps, current_n_mps, current_e_mps, current_set_rad,
    current_drift_mps, compass_course_rad (KK), deviation_rad, variation_rad,
    water_distance_m.

    ``errors`` columns (measured - true): gyro_err_rad, mag_err_rad (on KK), log_scale,
    log_bias_mps, log_noise_long_mps, log_noise_transverse_mps, log_ground_noise_long_mps,
    log_ground_noise_transverse_mps, leeway_rad (true leeway: a DR error when ignored),
    current_n_mps, current_e_mps, insJ_north_m, insJ_east_m, insJ_heading_rad, insJ_vn_mps,
    insJ_ve_mps (J = 1..3), gnss_north_m, gnss_east_m, gnss_vn_mps, gnss_ve_mps.

    ``params.faults`` (:mod:`dracc.sim.faults`) are resolved over the voyage (the result's
    ``params.faults`` holds them resolved) and applied to the errors and frames; without
    faults nothing of this runs.
    """
    p = params
    base_hz = _check(p)
    n = int(round(p.duration_s * base_hz)) + 1
    k = np.arange(n, dtype=np.int64)
    dt = 1.0 / base_hz
    t_s = p.t0_s + k * dt
    t0_ns = start_ns(p.start_utc) + int(round(p.t0_s * 1e9))
    time_ns = t0_ns + np.rint(k * (1e9 / base_hz)).astype(np.int64)
    state_in = p.state or {}
    state_out: dict = {}
    seg = int(p.segment)

    def gm(key: str, sigma: float, tau_s: float, rng: np.random.Generator) -> np.ndarray:
        """A GM process continued from the previous segment's last value, if any."""
        x = gauss_markov(n, dt, sigma, tau_s, rng, x0=state_in.get(key))
        state_out[key] = float(x[-1]) if n else state_in.get(key)
        return x

    # faults: resolved over the whole voyage (simulate_segments passes its length on)
    voyage_s = float(state_in.get("voyage_s", p.t0_s + p.duration_s))
    faults = resolve_faults(p.faults, voyage_s, p.seed, p.compass) if p.faults else ()
    v0_ns = start_ns(p.start_utc)  # the voyage's start (t0_ns is this segment's)

    # ---- truth
    legs = p.legs if p.legs is not None else _generated_legs(p)
    p = replace(p, legs=tuple((float(a), float(b)) for a, b in legs))  # explicit in the result
    if faults:
        p = replace(p, faults=faults)
    psi_steer, rot_steer = _heading_profile(
        t_s, legs, p.initial_heading_deg, p.turn_rate_deg_s * DEG_RAD
    )
    wy = 2 * np.pi / p.yaw_period_s if p.yaw_period_s > 0 else 0.0
    yaw_amp = p.yaw_amp_deg * DEG_RAD
    psi = wrap_2pi(psi_steer + yaw_amp * np.sin(wy * t_s))
    rot = rot_steer + yaw_amp * wy * np.cos(wy * t_s)
    rng_env = _rng(p.seed, 2, seg)
    alpha = p.leeway_deg * DEG_RAD + DEG_RAD * gm(
        "leeway", p.leeway_noise_deg.sigma, p.leeway_noise_deg.tau_s, rng_env
    )
    v_mps = np.full(n, p.speed_kn * KN_MPS)
    vx = v_mps * np.cos(alpha)  # (B5): alpha = atan(Vy/Vx)
    vy = v_mps * np.sin(alpha)
    kdw = psi + alpha  # course through the water (B3, B4 with beta = 0 here)
    set_rad = p.current_set_deg * DEG_RAD
    cn = p.current_drift_kn * KN_MPS * math.cos(set_rad) + KN_MPS * gm(
        "current_n", p.current_noise_kn.sigma, p.current_noise_kn.tau_s, rng_env
    )
    ce = p.current_drift_kn * KN_MPS * math.sin(set_rad) + KN_MPS * gm(
        "current_e", p.current_noise_kn.sigma, p.current_noise_kn.tau_s, rng_env
    )
    vn = v_mps * np.cos(kdw) + cn  # (B7-B9)
    ve = v_mps * np.sin(kdw) + ce  # (B10-B12), corrected: sin Kp
    lat, lon = integrate_track(p.start_lat_deg * DEG_RAD, p.start_lon_deg * DEG_RAD, vn, ve, dt)
    cog = wrap_2pi(np.arctan2(ve, vn))
    sog = np.hypot(vn, ve)
    g_long = vn * np.cos(psi) + ve * np.sin(psi)
    g_trans = -vn * np.sin(psi) + ve * np.cos(psi)
    coeffs = tuple(c * DEG_RAD for c in p.deviation_deg)
    var_rad = p.variation_deg * DEG_RAD
    kk = compass_course_rad(psi, coeffs, var_rad)
    dev_true = deviation_curve_rad(kk, coeffs)
    water_dist = state_in.get("water_distance_m", 0.0) + np.concatenate(
        ([0.0], np.cumsum(0.5 * (vx[1:] + vx[:-1]) * dt))
    )
    state_out["water_distance_m"] = float(water_dist[-1])

    truth = pd.DataFrame(
        {
            "time_ns": time_ns,
            "t_s": t_s,
            "lat_rad": lat,
            "lon_rad": lon,
            "heading_rad": psi,
            "rot_radps": rot,
            "leeway_rad": alpha,
            "course_water_rad": wrap_2pi(kdw),
            "stw_mps": v_mps,
            "stw_long_mps": vx,
            "stw_transverse_mps": vy,
            "vn_mps": vn,
            "ve_mps": ve,
            "cog_rad": cog,
            "sog_mps": sog,
            "sog_long_mps": g_long,
            "sog_transverse_mps": g_trans,
            "current_n_mps": cn,
            "current_e_mps": ce,
            "current_set_rad": wrap_2pi(np.arctan2(ce, cn)),
            "current_drift_mps": np.hypot(cn, ce),
            "compass_course_rad": kk,
            "deviation_rad": dev_true,
            "variation_rad": np.full(n, var_rad),
            "water_distance_m": water_dist,
        }
    )

    # ---- sensor errors
    errors: dict[str, np.ndarray] = {"time_ns": time_ns}
    r = _rng(p.seed, 3, seg)
    errors["gyro_err_rad"] = DEG_RAD * (
        p.gyro_offset_deg
        + gm("gyro_bias", p.gyro_bias_deg.sigma, p.gyro_bias_deg.tau_s, r)
        + gm("gyro_noise", p.gyro_noise_deg.sigma, p.gyro_noise_deg.tau_s, r)
        + p.gyro_white_deg * r.standard_normal(n)
    )
    rot_noise = p.rot_white_dpm * DEG_RAD / 60.0 * r.standard_normal(n)
    r = _rng(p.seed, 4, seg)
    errors["mag_err_rad"] = DEG_RAD * (
        gm("mag_noise", p.mag_noise_deg.sigma, p.mag_noise_deg.tau_s, r)
        + p.mag_white_deg * r.standard_normal(n)
    )
    r = _rng(p.seed, 5, seg)
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
    errors["leeway_rad"] = alpha
    errors["current_n_mps"] = cn
    errors["current_e_mps"] = ce
    for j, unit in enumerate(p.ins, start=1):
        r = _rng(p.seed, 10 + j, seg)
        phases = _rng(p.seed, 30 + j).uniform(0.0, 2 * np.pi, 6)  # shared by all segments

        def ins_gm(key, sigma, tau_s, rr, j=j):
            return gm(f"ins{j}_{key}", sigma, tau_s, rr)

        en, ee, eh, evn, eve = ins_errors(unit, t_s, dt, r, phases=phases, gm=ins_gm)
        wv = p.ins_velocity_white_kn * KN_MPS
        errors[f"ins{j}_north_m"] = en
        errors[f"ins{j}_east_m"] = ee
        errors[f"ins{j}_heading_rad"] = eh
        errors[f"ins{j}_vn_mps"] = evn + wv * r.standard_normal(n)
        errors[f"ins{j}_ve_mps"] = eve + wv * r.standard_normal(n)
    r = _rng(p.seed, 20, seg)
    errors["gnss_north_m"] = gm(
        "gnss_north", p.gnss_noise_m.sigma, p.gnss_noise_m.tau_s, r
    ) + p.gnss_white_m * r.standard_normal(n)
    errors["gnss_east_m"] = gm(
        "gnss_east", p.gnss_noise_m.sigma, p.gnss_noise_m.tau_s, r
    ) + p.gnss_white_m * r.standard_normal(n)
    errors["gnss_vn_mps"] = p.gnss_speed_white_kn * KN_MPS * r.standard_normal(n)
    errors["gnss_ve_mps"] = p.gnss_speed_white_kn * KN_MPS * r.standard_normal(n)
    if faults:  # jumps and drifts are position errors: frames and errors.csv agree
        errors = apply_error_faults(faults, errors, time_ns, t_s, v0_ns)
    err = pd.DataFrame(errors)

    # ---- sentences (what each source writes, at which samples)
    def idx(hz: float) -> np.ndarray:
        step = int(round(base_hz / hz))
        return np.arange(step if p.skip_first else 0, n, step, dtype=np.int64)

    ic, il, ii, ig = idx(p.compass_hz), idx(p.log_hz), idx(p.ins_hz), idx(p.gnss_hz)
    ia = idx(p.aux_hz) if p.aux_hz > 0 else np.zeros(0, np.int64)
    # (source, sentence, sample indices) in emission order within an epoch
    plan: list[tuple[str, str, np.ndarray]] = []
    if p.compass in ("gyro", "both"):
        plan += [("GYRO", "HDT", ic), ("GYRO", "THS", ia), ("GYRO", "ROT", ia)]
    if p.compass in ("magnetic", "both"):
        plan += [("MAG", "HDG", ic)]
    plan += [("LOG", "VHW", il), ("LOG", "VBW", il), ("LOG", "VLW", il)]
    for j in (1, 2, 3):
        plan += [(f"INS{j}", "GGA", ii), (f"INS{j}", "HDT", ii), (f"INS{j}", "VTG", ii)]
    plan += [("GNSS", "GGA", ig), ("GNSS", "RMC", ig), ("GNSS", "ZDA", ig)]

    # line numbers: sort every sentence by (sample, order in plan)
    sizes = [len(s[2]) for s in plan]
    all_k = np.concatenate([s[2] for s in plan])
    all_o = np.repeat(np.arange(len(plan)), sizes)
    order = np.lexsort((all_o, all_k))
    line_all = np.empty(len(order), np.int64)
    line_all[order] = np.arange(1, len(order) + 1)
    offs = np.concatenate(([0], np.cumsum(sizes)))
    lines = {(s[0], s[1]): line_all[offs[i] : offs[i + 1]] for i, s in enumerate(plan)}

    parts: dict[str, list[dict]] = {kind: [] for kind in KINDS}
    talkers = {k: v[1] for k, v in SOURCES.items()}
    talkers.update({f"INS{j}": t for j, t in enumerate(p.ins_talkers, start=1)})

    def const(m: int, value: str) -> pd.Categorical:
        return pd.Categorical.from_codes(np.zeros(m, np.int8), categories=[value])

    def rec(kind: str, src: str, sent: str, kidx: np.ndarray, **cols) -> None:
        m = len(kidx)
        d = {
            "time_ns": time_ns[kidx],
            "source": const(m, src),
            "talker": const(m, talkers[src]),
            "sentence": const(m, sent),
            "line": lines[(src, sent)],
        }
        d.update(cols)
        parts[kind].append(d)

    gyro_hdg = psi + errors["gyro_err_rad"]
    if p.compass in ("gyro", "both"):
        rec(
            "heading",
            "GYRO",
            "HDT",
            ic,
            heading_rad=q_angle_rad(gyro_hdg[ic]),
            reference=np.full(len(ic), "T", dtype=object),
        )
        rec(
            "heading",
            "GYRO",
            "THS",
            ia,
            heading_rad=q_angle_rad(gyro_hdg[ia]),
            reference=np.full(len(ia), "T", dtype=object),
        )
        rec(
            "rot",
            "GYRO",
            "ROT",
            ia,
            rot_radps=q_signed(rot[ia] + rot_noise[ia], DEG_RAD / 60.0, ROT_DEC),
        )
    if p.compass in ("magnetic", "both"):
        kk_meas = q_angle_rad(kk[ic] + errors["mag_err_rad"][ic])
        dev_w = (
            q_signed(deviation_curve_rad(kk_meas, coeffs), DEG_RAD, ANGLE_DEC)
            if p.hdg_deviation_field
            else np.full(len(ic), np.nan)
        )
        rec(
            "heading",
            "MAG",
            "HDG",
            ic,
            heading_rad=kk_meas,
            reference=np.full(len(ic), "M", dtype=object),
            deviation_rad=dev_w,
            variation_rad=np.full(len(ic), float(q_signed(var_rad, DEG_RAD, ANGLE_DEC))),
        )
    s1 = 1.0 + p.log_scale
    b = p.log_bias_kn * KN_MPS
    m_long = s1 * vx + b + errors["log_noise_long_mps"]
    m_trans = s1 * vy + errors["log_noise_transverse_mps"]
    m_glong = s1 * g_long + b + errors["log_ground_noise_long_mps"]
    m_gtrans = s1 * g_trans + errors["log_ground_noise_transverse_mps"]
    rec("water", "LOG", "VHW", il, stw_mps=q_signed(m_long[il], KN_MPS, SPEED_DEC))
    rec(
        "water",
        "LOG",
        "VBW",
        il,
        stw_mps=q_signed(m_long[il], KN_MPS, SPEED_DEC),
        stw_transverse_mps=q_signed(m_trans[il], KN_MPS, SPEED_DEC),
        sog_long_mps=q_signed(m_glong[il], KN_MPS, SPEED_DEC),
        sog_transverse_mps=q_signed(m_gtrans[il], KN_MPS, SPEED_DEC),
    )
    trip = state_in.get("trip_m", 0.0) + np.concatenate(
        ([0.0], np.cumsum(0.5 * (m_long[1:] + m_long[:-1]) * dt))
    )
    state_out["trip_m"] = float(trip[-1])
    rec(
        "distance",
        "LOG",
        "VLW",
        il,
        total_water_m=q_signed(p.log_total_start_nmi * NMI_M + trip[il], NMI_M, DIST_DEC),
        trip_water_m=q_signed(trip[il], NMI_M, DIST_DEC),
    )
    unit_rms: dict[str, dict[str, float]] = {}
    for j in (1, 2, 3):
        src = f"INS{j}"
        la, lo = add_offset_ne(
            lat[ii], lon[ii], errors[f"ins{j}_north_m"][ii], errors[f"ins{j}_east_m"][ii]
        )
        qla, qlo = q_latlon_rad(la), q_latlon_rad(lo)
        rec(
            "position",
            src,
            "GGA",
            ii,
            lat_rad=qla,
            lon_rad=qlo,
            alt_m=np.full(len(ii), round(p.alt_m, ALT_DEC)),
            quality=np.ones(len(ii), np.int8),
        )
        qh = q_angle_rad(psi[ii] + errors[f"ins{j}_heading_rad"][ii])
        rec(
            "heading", src, "HDT", ii, heading_rad=qh, reference=np.full(len(ii), "T", dtype=object)
        )
        gvn = vn[ii] + errors[f"ins{j}_vn_mps"][ii]
        gve = ve[ii] + errors[f"ins{j}_ve_mps"][ii]
        rec(
            "ground",
            src,
            "VTG",
            ii,
            cog_rad=q_angle_rad(np.arctan2(gve, gvn)),
            sog_mps=q_signed(np.hypot(gvn, gve), KN_MPS, SPEED_DEC),
        )
        # RMS of the written errors (K: the m_y a reference would measure)
        en_w = (qla - lat[ii]) / k_phi(lat[ii])
        ee_w = angdiff(qlo, lon[ii]) / k_lambda(lat[ii])
        eh_w = angdiff(qh, psi[ii])

        def rms(x: np.ndarray) -> float:
            return float(np.sqrt(np.mean(x**2))) if len(x) else float("nan")  # no sample: NaN

        unit_rms[f"ins{j}"] = {
            "lat_m": rms(en_w),
            "lon_m": rms(ee_w),
            "course_deg": rms(eh_w) / DEG_RAD,
        }
    la, lo = add_offset_ne(lat[ig], lon[ig], errors["gnss_north_m"][ig], errors["gnss_east_m"][ig])
    qla, qlo = q_latlon_rad(la), q_latlon_rad(lo)
    for sent in ("GGA", "RMC"):
        extra = (
            {
                "alt_m": np.full(len(ig), round(p.alt_m, ALT_DEC)),
                "hdop": np.full(len(ig), round(p.gnss_hdop, HDOP_DEC)),
            }
            if sent == "GGA"
            else {}
        )
        rec(
            "position",
            "GNSS",
            sent,
            ig,
            lat_rad=qla,
            lon_rad=qlo,
            quality=np.ones(len(ig), np.int8),
            **extra,
        )
    gvn = vn[ig] + errors["gnss_vn_mps"][ig]
    gve = ve[ig] + errors["gnss_ve_mps"][ig]
    rec(
        "ground",
        "GNSS",
        "RMC",
        ig,
        cog_rad=q_angle_rad(np.arctan2(gve, gvn)),
        sog_mps=q_signed(np.hypot(gvn, gve), KN_MPS, SPEED_DEC),
    )

    frames = {}
    for kind in KINDS:
        if not parts[kind]:
            frames[kind] = empty_frame(kind)
            continue
        names = list(dict.fromkeys(c for d in parts[kind] for c in d))
        cat = {}
        for c in names:
            if c in ("source", "talker", "sentence"):
                cat[c] = union_categoricals([d[c] for d in parts[kind]])
            else:
                # a column one sentence lacks (e.g. HDOP in RMC) is missing there: NaN, never 0
                cat[c] = np.concatenate(
                    [d[c] if c in d else np.full(len(d["time_ns"]), np.nan) for d in parts[kind]]
                )
        o = np.argsort(cat["line"], kind="stable")
        frames[kind] = make_frame(kind, {c: v[o] for c, v in cat.items()})

    # With both compasses fitted the gyro holds the role 'compass'; MAG is left unassigned.
    roles = {s: SOURCES[s][0] for s, _, _ in plan if not (s == "MAG" and p.compass == "both")}
    zda = pd.DataFrame(
        {
            "time_ns": time_ns[ig],
            "source": np.full(len(ig), "GNSS", dtype=object),
            "line": lines[("GNSS", "ZDA")],
        }
    )
    if faults:
        frames, zda, err, fstate = apply_frame_faults(
            faults, frames, zda, err, truth, v0_ns, state_in
        )
        state_out.update(fstate)
        if "voyage_s" in state_in:
            state_out["voyage_s"] = voyage_s
        unit_rms = _unit_rms(frames, time_ns, lat, lon, psi)
    state_out.update(
        lat_rad=float(lat[-1]), lon_rad=float(lon[-1]), t0_s=float(t_s[-1]), segment=seg
    )
    if p.skip_first:
        truth = truth.iloc[1:].reset_index(drop=True)
        err = err.iloc[1:].reset_index(drop=True)
    return SimVoyage(
        truth=truth,
        frames=frames,
        roles=roles,
        errors=err,
        unit_rms=unit_rms,
        params=p,
        zda=zda,
        state=state_out,
    )


def _unit_rms(
    frames: dict[str, pd.DataFrame],
    time_ns: np.ndarray,
    lat: np.ndarray,
    lon: np.ndarray,
    psi: np.ndarray,
) -> dict[str, dict[str, float]]:
    """RMS of each INS unit's written errors, from the frames (as :func:`simulate` computes
    it from the readings; used when faults changed the frames)."""

    def rms(x: np.ndarray) -> float:
        return float(np.sqrt(np.mean(x**2))) if len(x) else float("nan")

    out = {}
    pos, hd = frames["position"], frames["heading"]
    for j in (1, 2, 3):
        f = pos[(pos["source"] == f"INS{j}").to_numpy(bool)]
        k = np.searchsorted(time_ns, f["time_ns"].to_numpy(np.int64))
        en = (f["lat_rad"].to_numpy(float) - lat[k]) / k_phi(lat[k])
        ee = angdiff(f["lon_rad"].to_numpy(float), lon[k]) / k_lambda(lat[k])
        h = hd[(hd["source"] == f"INS{j}").to_numpy(bool)]
        kh = np.searchsorted(time_ns, h["time_ns"].to_numpy(np.int64))
        eh = angdiff(h["heading_rad"].to_numpy(float), psi[kh])
        out[f"ins{j}"] = {"lat_m": rms(en), "lon_m": rms(ee), "course_deg": rms(eh) / DEG_RAD}
    return out


def generated_legs(params: SimParams) -> tuple[tuple[float, float], ...]:
    """The legs :func:`simulate` steers when ``params.legs`` is None (drawn from the seed)."""
    return params.legs if params.legs is not None else _generated_legs(params)


def simulate_segments(params: SimParams, segment_s: float = 6 * 3600.0):
    """Simulate a long voyage in consecutive segments of ``segment_s``, yielding a
    :class:`SimVoyage` per segment, so that memory does not grow with the duration.

    Each segment continues the previous one exactly: the position, every Gauss-Markov
    process (from its last value), the INS oscillations (same phases, absolute time), the
    legs and the VLW distances; only the white noise and the GM driving noise are drawn
    from the segment's own streams.  The first sample of every later segment repeats the
    previous segment's last one and is dropped.  The result therefore differs from one
    :func:`simulate` of the whole voyage only in its random draws, not in its statistics.
    Line numbers in each segment's frames restart at 1.  Faults are resolved over the
    whole voyage and applied by absolute time in every segment they touch.
    """
    if not segment_s > 0:
        raise ConfigError(f"segment length must be positive, got {segment_s} s")
    legs = generated_legs(params)
    total = params.duration_s
    t0, k, state = 0.0, 0, None
    if params.faults:  # resolved over the whole voyage; each segment applies its part
        params = replace(
            params, faults=resolve_faults(params.faults, total, params.seed, params.compass)
        )
        state = {"voyage_s": total}
    while True:
        seg_len = min(segment_s, total - t0)
        p = replace(
            params, legs=legs, duration_s=seg_len, t0_s=t0, segment=k, skip_first=k > 0, state=state
        )
        if state is not None and "lat_rad" in state:
            p = replace(
                p,
                start_lat_deg=state["lat_rad"] / DEG_RAD,
                start_lon_deg=state["lon_rad"] / DEG_RAD,
            )
        v = simulate(p)
        yield v
        state = v.state
        t0 += seg_len
        k += 1
        if t0 >= total - 1e-9:
            break
