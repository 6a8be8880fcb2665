"""Integrity checks (dracc.math.integrity) on simulated nights with known truth.

Each seeded fault kind of ``dracc simulate`` (jump, freeze, dropout, drift, latency,
invalid) must fail the check made for it on the source it hit, and only there; over 40
clean nights of randomised ships and sensors the rate of nights with any failed check
must stay within the binomial bound of the stated false-alarm probability.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from dracc.core.config import IntegrityConfig
from dracc.core.distributions import binom_cdf
from dracc.frames import KINDS, Rejects, SourceInfo, TimeEvents, Voyage, empty_frame
from dracc.math.integrity import check_night
from dracc.sim import SimParams, simulate
from dracc.sim.faults import parse_fault

HOURS = 3.5


def _params(seed: int, faults=()) -> SimParams:
    """A randomised ship and sensor set (ranges a fleet shows), 1 Hz sensors."""
    rng = np.random.default_rng(1000 + seed)
    p = SimParams(
        duration_s=float(rng.uniform(3.2, 4.0)) * 3600.0,
        seed=seed,
        compass_hz=1.0,
        aux_hz=0.0,
        start_lat_deg=float(rng.uniform(-60, 60)),
        start_lon_deg=float(rng.uniform(-170, 170)),
        speed_kn=float(rng.uniform(6, 18)),
        current_drift_kn=float(rng.uniform(0, 1.5)),
        current_set_deg=float(rng.uniform(0, 360)),
        gyro_offset_deg=float(rng.uniform(-1, 1)),
        faults=tuple(faults),
    )
    return p.with_ins_error_scale(float(rng.uniform(0.5, 1.5)))


def voyage_from_sim(sv) -> Voyage:
    """The simulated frames as a perfect reader returns them, roles from the simulator."""
    frames = {k: sv.frames.get(k, empty_frame(k)) for k in KINDS}
    sources = {k: SourceInfo(k, roles=[r]) for k, r in sv.roles.items()}
    return Voyage(frames, sources, Rejects(), TimeEvents(), [])


def _failed(seed: int, spec: str | None):
    faults = (parse_fault(spec),) if spec else ()
    sv = simulate(_params(seed, faults))
    result = check_night(voyage_from_sim(sv))
    return result, [(c.check, c.name, c.source) for c in result.failed]


@pytest.mark.parametrize(
    "spec, check, name, source",
    [
        ("jump:GNSS@1h=670m", "plausibility", "jump", "GNSS"),
        ("jump:INS1@1.2h+5min=300m", "plausibility", "jump", "INS1"),
        ("freeze:INS2@1h+40min", "plausibility", "frozen", "INS2"),
        ("freeze:GYRO@1h+20min", "plausibility", "stuck", "GYRO"),
        ("dropout:INS3@1h+25min", "availability", "dropout", "INS3"),
        ("drift:INS1@1.5h=1kn", "consistency", "velocity", "INS1"),
        ("drift:GNSS@1.5h=1kn", "consistency", "velocity", "GNSS"),
        ("latency:GNSS@1h+30min=3s", "latency", "latency", "GNSS"),
        ("invalid:GNSS@1h+10min", "validity", "invalid_flag", "GNSS"),
    ],
)
def test_each_seeded_fault_fails_its_check_on_its_source(spec, check, name, source):
    result, failed = _failed(7, spec)
    assert (check, name, source) in failed, failed
    # the fault is not blamed on another source
    assert all(s == source for _, _, s in failed), failed
    c = next(c for c in result.failed if (c.check, c.name, c.source) == (check, name, source))
    assert c.evidence and c.message and c.threshold["rule"] and c.clause


def test_default_fault_specs_are_found():
    """The defaults of every kind (source, start, size drawn from the seed) on one night."""
    for kind, (check, name, source) in {
        "jump": ("plausibility", "jump", "GNSS"),
        "freeze": ("plausibility", "frozen", "INS2"),
        "dropout": ("availability", "dropout", "INS3"),
        "latency": ("latency", "latency", "GNSS"),
        "invalid": ("validity", "invalid_flag", "GNSS"),
    }.items():
        _, failed = _failed(11, kind)
        assert (check, name, source) in failed, (kind, failed)


def test_jump_gate_states_the_smallest_jump_it_could_see():
    result, _ = _failed(3, None)
    jumps = [c for c in result.checks if c.name == "jump"]
    assert jumps and all(c.status == "pass" for c in jumps)
    gnss = next(c for c in jumps if c.source == "GNSS")
    # GNSS white noise of a few metres: a gate of tens of metres, far below 670 m
    assert 1.0 < gnss.detail["min_detectable_m"] < 100.0
    assert "could have seen" not in gnss.message or "jump of" in gnss.message


def test_short_night_lists_velocity_consistency_as_not_checked():
    p = _params(2)
    from dataclasses import replace

    sv = simulate(replace(p, duration_s=2 * 3600.0))
    r = check_night(voyage_from_sim(sv))
    vel = [c for c in r.checks if c.name == "velocity"]
    assert vel and all(c.status == "not_checked" and "Schuler" in c.why_not for c in vel)


N_CLEAN = 40


def test_clean_nights_false_alarm_rate_within_the_stated_bound():
    """Monte Carlo over randomised clean nights: nights with any failed integrity check
    against the stated per-night false-alarm probability (binomial bound, 1 %)."""
    stated, bad = [], []
    for seed in range(N_CLEAN):
        result, failed = _failed(100 + seed, None)
        stated.append(result.false_alarm_per_night)
        if failed:
            bad.append((seed, failed))
    p = float(np.mean(stated))
    assert 0 < p < 0.05
    # the smallest k with P(K >= k | n, p) < 1 %: more failed nights than that refute the claim
    k_max = next(k for k in range(N_CLEAN + 1) if 1.0 - binom_cdf(k - 1, N_CLEAN, p) < 0.01) - 1
    assert len(bad) <= k_max, (len(bad), k_max, bad)
    assert math.isfinite(p)


def test_turns_between_sparse_fixes_are_not_jumps():
    """Regression: the shipped day at sea (GNSS and INS every 60 s) turned between fixes;
    the running median of the fixes' own velocity lagged a turn by minutes and flagged 9
    GNSS 'jumps' of up to 135 m, and two GNSS jumps of 27 m at a change of speed in
    sample_logs/voyage_tag.nmea.  The water track (compass and log) now predicts each
    step: no jump on either, and the injected jumps above are still found."""
    from dracc.core.config import IngestConfig
    from dracc.ingest import read_logs

    samples = Path(__file__).resolve().parents[1] / "sample_logs"
    for log in (samples / "day" / "voyage_day.mcap", samples / "voyage_tag.nmea"):
        voyage = read_logs([log], IngestConfig())
        jumps = [c for c in check_night(voyage, IntegrityConfig()).checks if c.name == "jump"]
        assert jumps and all(c.status == "pass" for c in jumps), [c.message for c in jumps]


def test_comparison_grid_leaves_out_hour_long_silences():
    """A stray record four years early must not make a grid of years (12.6 million
    instants at 10 s, 50 s of CPU in the whole-pipeline fuzz regression); without a long
    silence the grid is exactly the old regular one."""
    from dracc.math.integrity.helpers import covered_instants, shifted_index

    s = 1_000_000_000
    start, end, step = 0, 7200 * s, 10 * s
    t = np.arange(0, 7200 * s, s)
    np.testing.assert_array_equal(
        covered_instants([t], start, end, step), np.arange(start, end, step)
    )
    stray_start = -4 * 365 * 86400 * s
    g = covered_instants([np.concatenate(([stray_start], t))], stray_start, end, step)
    # the stray instant's own grid point and the voyage's 720, in phase with the start
    assert len(g) == 721 and g[0] == stray_start and np.all((g - stray_start) % step == 0)
    idx, ok = shifted_index(g, 600 * s)
    assert not ok[:61].any() and ok[61:].all()  # no t - 10 min across the four years
    np.testing.assert_array_equal(g[idx[ok]], g[ok] - 600 * s)
