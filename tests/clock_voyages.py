"""Voyages whose sources have clocks (issue 30): random sample phases and latencies, whole-
second TAG stamps, speed changes at the turns; each analysed as the NMEA log a logger
writes and as the MCAP of exact times, against the truth.

Shared by ``tests/test_clock_montecarlo.py`` (a few voyages) and
``benchmarks/bench_clock.py`` (thirty and more, printed).
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dracc.core.config import Config
from dracc.core.geodesy import angdiff, offset_ne_m
from dracc.core.units import DEG_RAD
from dracc.pipeline.analysis import analyse
from dracc.sim import GM, SimParams, random_clocks, simulate
from dracc.sim.mcap_out import write_mcap
from dracc.sim.nmea_out import write_nmea

CHANNELS = ("lat", "lon", "course")


def clock_voyage(seed: int, hours: float = 12.0, noiseless: bool = False) -> SimParams:
    """One voyage drawn over realistic ranges: 1-10 Hz compass (gyro, magnetic or both),
    1 Hz INS, log and GNSS; a new course and speed every 1.5-3 h (speed 8-16 kn,
    changed at 0.005-0.02 m/s^2); every source at a random phase with a latency of 0-2 s."""
    r = np.random.default_rng(104_729 + seed)
    legs, speeds, t = [], [], r.uniform(1800.0, 3600.0)
    while t < hours * 3600.0 - 1800.0:
        legs.append((t, r.uniform(0.0, 360.0)))
        speeds.append((t, r.uniform(8.0, 16.0)))
        t += r.uniform(1.5, 3.0) * 3600.0
    base = SimParams.noiseless if noiseless else SimParams
    p = base(
        duration_s=hours * 3600.0,
        seed=seed,
        start_utc="2026-03-01T00:00:00Z",
        start_lat_deg=r.uniform(-60.0, 60.0),
        start_lon_deg=r.uniform(-170.0, 170.0),
        speed_kn=r.uniform(8.0, 16.0),
        speed_changes=tuple(speeds),
        accel_mps2=r.uniform(0.005, 0.02),
        legs=tuple(legs),
        initial_heading_deg=r.uniform(0.0, 360.0),
        compass=str(r.choice(["gyro", "magnetic", "both"])),
        compass_hz=float(r.choice([1.0, 5.0, 10.0])),
        aux_hz=0.0,
        **({} if noiseless else {"current_noise_kn": GM(r.uniform(0.05, 0.3), 6 * 3600.0)}),
    )
    return random_clocks(p, seed, latency_max_s=2.0)


@dataclass(frozen=True)
class ClockRun:
    """One voyage analysed as whole-second NMEA and as exact-time MCAP, with its truth."""

    params: SimParams
    #: source -> (learned offset_s, its sigma, method, true offset of the whole-second log)
    offsets: dict[str, tuple[float, float, str, float]]
    #: unit -> channel -> (m_u of the NMEA analysis, m_u of the MCAP analysis, RMS of the
    #: NMEA analysis's deviation samples, RMS of the true deviations at those instants)
    m_u: dict[str, dict[str, tuple[float, float, float, float]]]
    ep_max_error_m: float  #: the learned DR's largest distance from the truth at its epochs
    #: the same from the MCAP of exact times (what the clocks cannot be blamed for)
    ep_exact_max_error_m: float = math.nan


def _m_u(result, unit: str, channel: str) -> float:
    return float(result.whole.units[unit].channels[channel].m_u)


def _true_deviations(sv, times_ns: np.ndarray) -> dict[str, dict[str, np.ndarray]]:
    """The true deviations at the sampling instants: each unit's true error at its own
    sample instants, interpolated to the instants as a perfectly timed analysis would,
    minus the mean over the units (m, m, deg)."""
    err, t = sv.errors, sv.truth["time_ns"].to_numpy()
    per: dict[str, dict[str, np.ndarray]] = {}
    phase = {k: c["phase_s"] for k, c in sv.clocks.items()}
    for j in (1, 2, 3):
        idx = _sample_indices(sv, phase.get(f"INS{j}", 0.0))
        ts = t[idx]
        per[f"ins{j}"] = {
            "lat": np.interp(times_ns, ts, err[f"ins{j}_north_m"].to_numpy()[idx]),
            "lon": np.interp(times_ns, ts, err[f"ins{j}_east_m"].to_numpy()[idx]),
            "course": np.interp(times_ns, ts, err[f"ins{j}_heading_rad"].to_numpy()[idx]) / DEG_RAD,
        }
    out: dict[str, dict[str, np.ndarray]] = {u: {} for u in per}
    for ch in CHANNELS:
        mean = np.mean([per[u][ch] for u in per], axis=0)
        for u in per:
            out[u][ch] = per[u][ch] - mean
    return out


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.nanmean(np.asarray(x, float) ** 2)))


def _sample_indices(sv, phase_s: float) -> np.ndarray:
    base = sv.params.base_hz()
    step = int(round(base / sv.params.ins_hz))
    first = int(round(phase_s * base)) % step
    return np.arange(first, len(sv.truth), step)


def _ep_max_error(sv, a) -> float:
    dr = a.dead_reckoning
    if dr is None:
        return math.nan
    e = dr.epochs
    t = sv.truth["time_ns"].to_numpy()
    i = np.clip(np.searchsorted(t, e.time_ns), 0, len(t) - 1)
    dn, de = offset_ne_m(
        e.lat_rad, e.lon_rad, sv.truth["lat_rad"].to_numpy()[i], sv.truth["lon_rad"].to_numpy()[i]
    )
    return float(np.max(np.hypot(dn, de)))


def run_voyage(seed: int, hours: float = 12.0, noiseless: bool = False) -> ClockRun:
    p = clock_voyage(seed, hours, noiseless)
    sv = simulate(p)
    exact = simulate(replace(p, latency_s=()))
    with tempfile.TemporaryDirectory() as tmp:
        nmea, mcap = Path(tmp) / "voyage.nmea", Path(tmp) / "voyage.mcap"
        write_nmea(sv, nmea, tag_time="s")
        write_mcap(exact.frames, exact.roles, mcap)
        a_nmea = analyse([nmea], Config())
        a_mcap = analyse([mcap], Config())
    offsets = {}
    for s in a_nmea.sources:
        c, truth = s.clock, sv.clocks.get(s.key, {}).get("offset_whole_s_stamps")
        if c is not None and truth is not None and math.isfinite(truth):
            # against the times reconstructed inside shared stamps, as dracc reports it
            offsets[s.key] = (c.offset_s, c.offset_sigma_s, c.method, truth + c.spread_mean_s)
    m_u: dict[str, dict[str, tuple[float, float, float, float]]] = {}
    d_n, d_m = a_nmea.deviation, a_mcap.deviation
    if d_n is not None and d_m is not None:
        true = _true_deviations(exact, d_n.time_ns)
        for u in ("ins1", "ins2", "ins3"):
            m_u[u] = {
                ch: (
                    _m_u(d_n, u, ch),
                    _m_u(d_m, u, ch),
                    _rms(d_n.samples[u][ch]),
                    _rms(np.where(np.isfinite(d_n.samples[u][ch]), true[u][ch], np.nan)),
                )
                for ch in CHANNELS
            }
    return ClockRun(p, offsets, m_u, _ep_max_error(sv, a_nmea), _ep_max_error(exact, a_mcap))


def wrap_deg(x: float) -> float:
    return float(angdiff(x * DEG_RAD, 0.0) / DEG_RAD)
