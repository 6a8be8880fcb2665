"""Voyage simulator with known truth: :func:`simulate` and :func:`simulate_segments`.

Pure numpy; no I/O.  :func:`simulate` turns a :class:`SimParams` into a :class:`SimVoyage`
holding the truth, every true error series, and the canonical frames
(:mod:`dracc.frames`) that a perfect parser of the written log returns.  Its parts:
:mod:`dracc.sim.params` (the parameters), :mod:`dracc.sim.truth` (the true track),
:mod:`dracc.sim.processes` (the sensor error processes), :mod:`dracc.sim.readings` (what
each sensor writes, to the written precision) and :mod:`dracc.sim.faults`.

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
Error processes: :mod:`dracc.sim.processes`; written precision: :mod:`dracc.sim.readings`.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pandas as pd

from dracc.core.errors import ConfigError
from dracc.core.units import DEG_RAD
from dracc.sim.faults import (
    SimFault,
    apply_error_faults,
    apply_frame_faults,
    date_shifts,
    resolve_faults,
)
from dracc.sim.params import SimParams
from dracc.sim.processes import (
    gauss_markov,
    sensor_errors,
)
from dracc.sim.readings import (
    sensor_readings,
    unit_rms_from_frames,
)
from dracc.sim.truth import (
    generated_legs,
    start_ns,
    true_track,
)

__all__ = ["MAX_SAMPLES", "SimVoyage", "simulate", "simulate_segments"]

MAX_SAMPLES = 3e6  #: truth samples in one simulate() call (~1.7 kB each at peak)


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
    state: dict[str, Any] = field(default_factory=dict)
    #: source key -> its clock truth: ``phase_s``, ``latency_s``, ``offset_s``,
    #: ``offset_whole_s_stamps``, ``records`` (:func:`dracc.sim.readings.clock_truth`)
    clocks: dict[str, dict[str, float]] = field(default_factory=dict)
    #: ``(source, lo_ns, hi_ns, days)``: dates the writers put ``days`` early (a rollover;
    #: :func:`dracc.sim.faults.date_shifts`)
    date_shifts: tuple[tuple[str, int, int | None, int], ...] = ()


def _check(p: SimParams) -> float:
    if not p.duration_s > 0:
        raise ConfigError(f"duration must be positive, got {p.duration_s} s")
    if not p.accel_mps2 > 0 or any(not v > 0 for _, v in p.speed_changes):
        raise ConfigError("speed changes need a positive acceleration and positive speeds")
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
    p.clock_steps()  # raises on a phase or latency the voyage cannot have
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

    ``params.phases_s`` and ``latency_s`` (the sources' clocks) choose the samples each
    source takes and the times of its records (:mod:`dracc.sim.readings`); ``clocks`` holds
    their truth.  They change neither the truth nor the errors.
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
    state_out: dict[str, Any] = {}
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

    legs = generated_legs(p)
    p = replace(p, legs=tuple((float(a), float(b)) for a, b in legs))  # explicit in the result
    if faults:
        p = replace(p, faults=faults)
    track = true_track(p, legs, t_s, time_ns, dt, gm, seg, state_in.get("water_distance_m", 0.0))
    state_out["water_distance_m"] = float(track["water_distance_m"][-1])
    truth = pd.DataFrame(track)

    errors, rot_noise = sensor_errors(p, track, t_s, dt, gm, seg)
    if faults:  # jumps and drifts are position errors: frames and errors.csv agree
        errors = apply_error_faults(faults, errors, time_ns, t_s, v0_ns)
    err = pd.DataFrame(errors)

    r = sensor_readings(p, track, errors, rot_noise, base_hz, state_in.get("trip_m", 0.0))
    state_out["trip_m"] = r.trip_m
    frames, zda, unit_rms = r.frames, r.zda, r.unit_rms
    lat, lon, psi = track["lat_rad"], track["lon_rad"], track["heading_rad"]
    if faults:
        frames, zda, err, fstate = apply_frame_faults(
            faults, frames, zda, err, truth, v0_ns, state_in
        )
        state_out.update(fstate)
        if "voyage_s" in state_in:
            state_out["voyage_s"] = voyage_s
        unit_rms = unit_rms_from_frames(frames, time_ns, lat, lon, psi, p.clock_steps()[1])
    state_out.update(
        lat_rad=float(lat[-1]), lon_rad=float(lon[-1]), t0_s=float(t_s[-1]), segment=seg
    )
    if p.skip_first:
        truth = truth.iloc[1:].reset_index(drop=True)
        err = err.iloc[1:].reset_index(drop=True)
    return SimVoyage(
        truth=truth,
        frames=frames,
        roles=r.roles,
        errors=err,
        unit_rms=unit_rms,
        params=p,
        zda=zda,
        state=state_out,
        clocks=r.clocks,
        date_shifts=date_shifts(faults, v0_ns),
    )


def _segment_len(t0: float, segment_s: float, faults: tuple[SimFault, ...], p: SimParams) -> float:
    """The length of the segment from ``t0``: ``segment_s``, longer (to the truth's grid)
    where its end would cut a loop's replay (a loop needs its replayed records in its
    segment); at most to the voyage's end."""
    margin = 10.0 + max((v for _, v in p.latency_s), default=0.0)
    loops = [(f.start_s, f.size) for f in faults if f.kind == "loop"]
    end_s, moved = t0 + segment_s, False
    for _ in range(len(loops) + 1):
        cut = [
            a
            for a, b in loops
            if a is not None and b is not None and a - b - margin < end_s < a + margin
        ]
        if not cut:
            break
        end_s = math.ceil((cut[0] + margin) * p.base_hz()) / p.base_hz()
        moved = True
    return min(end_s - t0 if moved else segment_s, p.duration_s - t0)


def simulate_segments(params: SimParams, segment_s: float = 6 * 3600.0) -> Iterator[SimVoyage]:
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
        seg_len = _segment_len(t0, segment_s, params.faults, params)
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
