"""Each source's clock (dracc.math.clock, dracc.pipeline.clock_stage) against known truth:
synthetic series with a known lag, stamps with a known spread, and simulated voyages whose
sources are stamped late by known latencies."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from test_pipeline import voyage_from_sim

from dracc.core.config import Config, config_from_dict
from dracc.core.errors import ConfigError
from dracc.frames import own_time
from dracc.math.clock import (
    combine,
    rate_lag,
    spread_shared_stamps,
    stamp_resolution_s,
    time_of_fix_offset,
)
from dracc.pipeline.clock_stage import learn_clocks
from dracc.sim import SimParams, simulate

NS = 1_000_000_000


def _yawing_heading(t_s: np.ndarray, period_s: float, amp_deg: float) -> np.ndarray:
    """A ship's heading: a slow course with a 60 deg turn, a yaw (radians)."""
    turn = np.clip((t_s - 1800.0) / 120.0, 0.0, 1.0) * math.radians(60.0)
    return 1.0 + turn + math.radians(amp_deg) * np.sin(2 * np.pi * t_s / period_s)


@pytest.mark.parametrize("seed", range(6))
def test_rate_lag_finds_a_known_lag_with_a_sigma_that_covers(seed):
    rng = np.random.default_rng(seed)
    lag, period, amp = rng.uniform(-1.5, 1.5), rng.uniform(9.0, 20.0), rng.uniform(0.3, 1.0)
    step = 0.25
    t = np.arange(0.0, 3600.0, step)
    x = _yawing_heading(t - lag, period, amp) + math.radians(0.3)
    x += rng.normal(0, math.radians(0.02), len(t))  # white noise on the lagging one
    ref = _yawing_heading(t, period, amp) + rng.normal(0, math.radians(0.01), len(t))
    est = rate_lag(x, ref, step, angle=True, highpass_s=61.0)
    assert est.windows >= 5
    assert abs(est.lag_s - lag) < max(4 * est.sigma_s, 0.01), (est, lag)
    assert est.sigma_s < 0.05


def test_rate_lag_without_motion_is_not_usable():
    t = np.arange(0.0, 3600.0, 1.0)
    flat = np.full(len(t), 1.0) + np.random.default_rng(1).normal(0, 1e-4, len(t))
    est = rate_lag(flat, flat.copy(), 1.0, angle=True, min_rate=math.radians(0.02))
    assert not est.usable


def test_spread_places_a_fast_source_inside_its_whole_second_stamps():
    # a 10 Hz source received 0.3 s after it sampled, stamped by a whole-second clock
    instants = np.arange(0, 60 * NS, NS // 10)
    stamps = (instants + 3 * NS // 10) // NS * NS
    values = np.arange(len(stamps), dtype=float)
    placed, moved = spread_shared_stamps(stamps, values)
    assert moved == len(stamps)
    offset = (placed - instants) / NS
    assert np.allclose(offset[10:-10], 0.35, atol=1e-9)  # the receipt delay + half a slot


def test_spread_leaves_two_sentences_of_one_fix_together():
    t = np.repeat(np.arange(0, 30 * NS, NS), 2)  # GGA and RMC of one fix share a stamp
    values = np.repeat(np.arange(30.0), 2)
    placed, moved = spread_shared_stamps(t, values)
    assert moved == 0 and np.array_equal(placed, t)


def test_stamp_resolution():
    assert stamp_resolution_s(np.array([NS, 2 * NS, 5 * NS])) == 1.0
    assert stamp_resolution_s(np.array([NS, NS + 100_000_000])) == 0.1
    assert stamp_resolution_s(np.array([NS + 1_000_000])) == 0.001
    assert stamp_resolution_s(np.array([NS + 1])) is None


def test_time_of_fix_offset_and_drift():
    fix = np.arange(0, 7200 * NS, NS)
    drift_ppm = 20.0
    recv = fix + 250_000_000 + (fix * drift_ppm * 1e-6).astype(np.int64)
    offset, sigma, drift = time_of_fix_offset(recv, fix)
    assert offset == pytest.approx(0.25 + 3600 * drift_ppm * 1e-6, abs=1e-3)
    assert drift == pytest.approx(drift_ppm, rel=1e-3)
    assert sigma < 0.01


def test_combine_widens_sigma_when_windows_disagree():
    agree = combine(np.array([0.5, 0.5, 0.5]), np.array([0.1, 0.1, 0.1]))
    apart = combine(np.array([0.3, 0.5, 0.7]), np.array([0.01, 0.01, 0.01]))
    assert agree.sigma_s == pytest.approx(0.1 / math.sqrt(3))
    assert apart.sigma_s > 0.1  # chi2/dof = 400: sigma x 20


def _stamped_late(sv, latency: dict[str, float]):
    """The simulated voyage with each source's records received ``latency`` s late: the
    records without a time of fix carry the receive time, the others keep theirs."""
    frames = {}
    for kind, df in sv.frames.items():
        if len(df):
            late = np.array([latency.get(str(s), 0.0) for s in df["source"]]) * NS
            own = own_time(df)
            df = df.assign(time_ns=np.where(own, df["time_ns"], df["time_ns"] + late.astype(int)))
            recv = np.where(own, df["time_ns"] + late.astype(int), df["recv_ns"])
            df = df.assign(recv_ns=np.where(late > 0, recv, df["recv_ns"]).astype(np.int64))
            df = df.sort_values("time_ns", kind="stable").reset_index(drop=True)
        frames[kind] = df
    from dataclasses import replace

    return replace(sv, frames=frames)


def test_a_late_compass_and_late_ins_are_learned_and_moved_back():
    latency = {"GYRO": 0.8, "INS1": 0.1, "INS2": 0.45, "INS3": 1.2}
    sv = simulate(SimParams(duration_s=2 * 3600.0, seed=3, compass_hz=5.0, aux_hz=0.0))
    voyage = voyage_from_sim(_stamped_late(sv, latency))
    moved, clocks = learn_clocks(voyage, Config())
    for key in ("INS1", "INS2", "INS3"):
        assert clocks[key].method == "time_of_fix"
        assert clocks[key].offset_s == pytest.approx(latency[key], abs=1e-6)
    gyro = clocks["GYRO"]
    assert gyro.method == "heading_rate"
    assert abs(gyro.offset_s - 0.8) < max(3 * gyro.offset_sigma_s, 0.02)
    assert gyro.offset_sigma_s < 0.05
    # the gyro's records are back at the instants they describe
    hd = moved.frames["heading"]
    g = hd[hd["source"] == "GYRO"]
    orig = sv.frames["heading"]
    orig = orig[orig["source"] == "GYRO"]
    assert np.median(np.abs(g["time_ns"].to_numpy() - orig["time_ns"].to_numpy())) < 0.05 * NS


def test_configured_latency_replaces_the_learned_one():
    sv = simulate(SimParams(duration_s=3600.0, seed=4, compass_hz=1.0, aux_hz=0.0))
    cfg = config_from_dict({"sources": {"GYRO": {"latency_s": 0.4}}})
    _, clocks = learn_clocks(voyage_from_sim(sv), cfg)
    assert clocks["GYRO"].method == "configured"
    assert clocks["GYRO"].offset_s == 0.4
    assert clocks["GYRO"].offset_sigma_s == 0.0


@pytest.mark.parametrize(
    "table",
    [
        {"GYRO": {"latency": 0.4}},
        {"GYRO": {"latency_s": "late"}},
        {"GYRO": {"latency_s": 1e9}},
        {"GYRO": 0.4},
    ],
)
def test_a_bad_sources_table_is_named(table):
    with pytest.raises(ConfigError, match=r"\[sources"):
        config_from_dict({"sources": table})


def test_frames_without_a_clock_get_none():
    sv = simulate(SimParams(duration_s=600.0, seed=1, compass_hz=1.0, aux_hz=0.0))
    voyage = voyage_from_sim(sv)
    from dataclasses import replace

    voyage = replace(voyage, clockless=frozenset(voyage.sources))
    _, clocks = learn_clocks(voyage, Config())
    assert {c.method for c in clocks.values()} == {"no_clock"}
    assert all(isinstance(k, str) for k in clocks)
    assert pd.isna(clocks["GYRO"].offset_s)
