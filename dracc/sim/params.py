"""The parameters of a simulated voyage: :class:`SimParams`, the INS error model
:class:`InsErrorParams` (three realistic units in :data:`DEFAULT_INS`) and the Gauss-Markov
process description :class:`GM`.

Degrees and knots at this edge only; :func:`dracc.sim.model.simulate` turns the parameters
into SI.  Errors are *measured minus true* (see :mod:`dracc.sim.model`).

Clocks: ``phases_s`` and ``latency_s`` give a source its sample phase and its delay to the
logger (:meth:`SimParams.clock_steps`); :func:`random_clocks` draws both from a seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from datetime import datetime
from typing import Any, cast

import numpy as np

from dracc.core.errors import ConfigError
from dracc.sim.faults import ALL_SOURCES, SimFault

RNG_CLOCKS = 70  #: random stream of :func:`random_clocks` (see dracc.sim.processes.component_rng)
GNSS_LATENCY_MAX_S = 0.5  #: a GNSS receiver's fixes reach the logger within half a second


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
        kw: dict[str, Any] = {}
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
    **cast(
        dict[str, Any],
        {
            f.name: (GM(0.0, math.inf) if f.type in ("GM", GM) else 0.0)
            for f in fields(InsErrorParams)
        },
    )
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
    #: speed changes ``((time_s, speed_kn), ...)``: the speed through the water set from
    #: ``time_s`` on, reached at ``accel_mps2`` (empty: ``speed_kn`` throughout)
    speed_changes: tuple[tuple[float, float], ...] = ()
    accel_mps2: float = 0.01
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
    #: (source key, seconds): the sample phase within the source's period; the source
    #: samples at grid + phase, on the truth's grid (``round(phase * base rate)`` samples)
    phases_s: tuple[tuple[str, float], ...] = ()
    #: (source key, seconds): the delay from sampling to the logger (to the millisecond);
    #: records without a time of fix are timed by it, the others get it as ``recv_ns``
    latency_s: tuple[tuple[str, float], ...] = ()
    # segments of a long voyage (see dracc.sim.model.simulate_segments)
    t0_s: float = 0.0  #: time of this segment's first sample from the voyage start
    segment: int = 0  #: segment number (its own random streams; phases are shared)
    skip_first: bool = False  #: drop the first sample (the previous segment's last one)
    #: values of every Gauss-Markov process and the VLW trip at the first sample
    state: dict[str, Any] | None = field(default=None, compare=False)

    @classmethod
    def noiseless(cls, **overrides: Any) -> SimParams:
        """Exact-truth voyage: no sensor error, no current, no leeway, no yaw; every
        sentence reads the truth (to its written precision).  ``overrides`` apply last."""
        zero = GM(0.0, math.inf)
        base: dict[str, Any] = {
            "gyro_offset_deg": 0.0,
            "gyro_bias_deg": zero,
            "gyro_noise_deg": zero,
            "gyro_white_deg": 0.0,
            "rot_white_dpm": 0.0,
            "mag_noise_deg": zero,
            "mag_white_deg": 0.0,
            "log_scale": 0.0,
            "log_bias_kn": 0.0,
            "log_noise_kn": zero,
            "log_white_kn": 0.0,
            "leeway_deg": 0.0,
            "leeway_noise_deg": zero,
            "current_drift_kn": 0.0,
            "current_noise_kn": zero,
            "yaw_amp_deg": 0.0,
            "ins": (NO_INS_ERROR,) * 3,
            "ins_velocity_white_kn": 0.0,
            "gnss_noise_m": zero,
            "gnss_white_m": 0.0,
            "gnss_speed_white_kn": 0.0,
        }
        base.update(overrides)
        return cls(**base)

    def with_ins_error_scale(self, k: float) -> SimParams:
        """The same voyage with every INS error amplitude multiplied by ``k``."""
        scaled = tuple(u.scaled(k) for u in self.ins)
        return replace(
            self, ins=cast("tuple[InsErrorParams, InsErrorParams, InsErrorParams]", scaled)
        )

    def with_ins_unit_scales(self, k: tuple[float, float, float]) -> SimParams:
        """The same voyage with INS1..INS3's error amplitudes multiplied by ``k[0..2]``."""
        scaled = tuple(u.scaled(f) for u, f in zip(self.ins, k, strict=True))
        return replace(
            self, ins=cast("tuple[InsErrorParams, InsErrorParams, InsErrorParams]", scaled)
        )

    def base_hz(self) -> float:
        """The truth's rate: the fastest sensor rate."""
        return float(max(self.compass_hz, self.log_hz, self.ins_hz, self.gnss_hz, self.aux_hz))

    def source_rates_hz(self) -> dict[str, tuple[float, ...]]:
        """Each fitted source key -> the rates of its sentences (Hz)."""
        gyro: tuple[float, ...] = (
            (self.compass_hz, self.aux_hz) if self.aux_hz > 0 else (self.compass_hz,)
        )
        rates: dict[str, tuple[float, ...]] = {
            "GYRO": gyro,
            "MAG": (self.compass_hz,),
            "LOG": (self.log_hz,),
        }
        rates.update({f"INS{j}": (self.ins_hz,) for j in (1, 2, 3)})
        rates["GNSS"] = (self.gnss_hz,)
        if self.compass == "gyro":
            del rates["MAG"]
        elif self.compass == "magnetic":
            del rates["GYRO"]
        return rates

    def clock_steps(self) -> tuple[dict[str, int], dict[str, int]]:
        """(source -> phase in truth samples, source -> latency in ns) of the sources named
        in ``phases_s`` and ``latency_s``; the latency rounded to the millisecond.  Raises
        :class:`ConfigError` for a source the voyage does not have, a source named twice, a
        phase outside ``[0, period)`` of the source's slowest sentence or a latency < 0."""
        rates, base = self.source_rates_hz(), self.base_hz()
        steps: dict[str, int] = {}
        lat: dict[str, int] = {}
        for what, pairs, out in (("phase", self.phases_s, steps), ("latency", self.latency_s, lat)):
            for src, value in pairs:
                if src not in rates:
                    raise ConfigError(
                        f"{what} {src}={value}: the voyage has no source {src!r}; "
                        f"expected one of {', '.join(rates)}"
                    )
                if src in out:
                    raise ConfigError(f"{what} of {src} given twice")
                period = 1.0 / min(rates[src])
                v = float(value)
                hi = period if what == "phase" else math.inf
                if not (math.isfinite(v) and 0.0 <= v < hi):
                    raise ConfigError(
                        f"{what} {src}={value}: expected seconds in [0, {hi:g})"
                        if what == "phase"
                        else f"latency {src}={value}: expected finite seconds >= 0"
                    )
                out[src] = (
                    int(round(v * base)) if what == "phase" else int(round(v * 1e3)) * 1_000_000
                )
        return steps, lat

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (GM as {"sigma", "tau_s"}, inf as the string "inf")."""

        def conv(v: Any) -> Any:
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


def random_clocks(
    params: SimParams, rng: np.random.Generator | int, latency_max_s: float = 2.0
) -> SimParams:
    """``params`` with a random clock per fitted source: a phase drawn uniformly from the
    truth's grid within the period of the source's slowest sentence, a latency uniform in
    ``[0, latency_max_s]`` (GNSS: ``[0, min(0.5, latency_max_s)]``), to the millisecond.
    ``rng``: a generator, or a seed (its own stream: the voyage's other draws are kept)."""
    if not (math.isfinite(latency_max_s) and latency_max_s >= 0):
        raise ConfigError(f"latency maximum {latency_max_s} s: expected finite seconds >= 0")
    if not isinstance(rng, np.random.Generator):
        rng = np.random.default_rng([int(rng) & 0xFFFFFFFF, RNG_CLOCKS])
    rates, base = params.source_rates_hz(), params.base_hz()
    phases, lats = [], []
    for src in ALL_SOURCES:  # every key draws, fitted or not: stable streams
        u_phase, u_lat = rng.uniform(0.0, 1.0, 2)
        if src not in rates:
            continue
        n = max(int(round(base / min(rates[src]))), 1)
        phases.append((src, round(int(u_phase * n) / base, 9)))
        top = min(GNSS_LATENCY_MAX_S, latency_max_s) if src == "GNSS" else latency_max_s
        lats.append((src, round(float(u_lat) * top, 3)))
    return replace(params, phases_s=tuple(phases), latency_s=tuple(lats))
