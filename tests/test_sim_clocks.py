"""The simulator's clocks (issue 30, item 4): per source a sample phase and a latency to
the logger (``SimParams.phases_s``, ``latency_s``, :func:`dracc.sim.params.random_clocks`),
their truth (``SimVoyage.clocks``), the time faults (leap, rollover, loop, clockstep), the
writers and ``dracc simulate``'s options -- each read back by dracc's own ingest.

Canonical-frame semantics (dracc/frames.py): a record with its own time of fix (GGA, RMC,
ZDA) has ``time_ns`` = the time of fix and ``recv_ns`` = the receive time; a record without
one (HDT, THS, HDG, ROT, VHW, VBW, VLW, VTG) has ``time_ns`` = its receive time.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dracc.core.config import IngestConfig
from dracc.core.errors import ConfigError, DraccError
from dracc.frames import KINDS, MISSING_NS
from dracc.ingest import read_logs
from dracc.sim import SimFault, SimParams, parse_fault, random_clocks, resolve_faults, simulate
from dracc.sim.faults import OWN_TIME_SENTENCES, ROLLOVER_DAYS, TIME_FAULT_KINDS, fault_table
from dracc.sim.model import simulate_segments
from dracc.sim.nmea_out import write_nmea
from dracc.sim.output import merge_clocks, with_clocks, write_log
from dracc.sim.readings import q_angle_rad, q_latlon_rad
from dracc.sim.truth import start_ns

S = 1_000_000_000
T0 = start_ns("2026-03-01T00:00:00Z")
#: a short voyage, 10 Hz compasses (a 10 Hz truth: phases to 0.1 s), the rest at 1 Hz
BASE = {"duration_s": 600.0, "seed": 2, "compass": "both", "compass_hz": 10.0}
CLOCKS = {
    "phases_s": (("INS2", 0.3), ("GYRO", 0.5), ("LOG", 0.9)),
    "latency_s": (("INS2", 0.25), ("GNSS", 0.1), ("GYRO", 1.2), ("MAG", 0.04)),
}


def own(df: pd.DataFrame) -> np.ndarray:
    return df["sentence"].astype(str).isin(OWN_TIME_SENTENCES).to_numpy(bool)


def of(df: pd.DataFrame, source: str) -> pd.DataFrame:
    return df[(df["source"].astype(str) == source).to_numpy(bool)].reset_index(drop=True)


def received(df: pd.DataFrame) -> np.ndarray:
    r, t = df["recv_ns"].to_numpy(np.int64), df["time_ns"].to_numpy(np.int64)
    return np.where(r != MISSING_NS, r, t)


def every_record(v) -> pd.DataFrame:
    """Every record of every frame (line, source, sentence, times), in line order."""
    cols = ["line", "source", "sentence", "time_ns", "recv_ns"]
    parts = [v.frames[k][cols].astype({"source": str, "sentence": str}) for k in KINDS]
    df = pd.concat(parts, ignore_index=True)
    return df.sort_values("line", kind="stable").reset_index(drop=True)


def read_back(path: Path):
    got = read_logs([path], IngestConfig())
    assert got.rejects.total == 0
    return got


def assert_read_back_exactly(v, got) -> None:
    """dracc's ingest of the TAG form with c: in ms returns the simulator's frames: every
    value and time, line by line; a record with a time of fix the simulator gave no
    receive time gets the TAG c: (its time of fix) as ``recv_ns``."""
    for kind in KINDS:
        want = v.frames[kind].sort_values("line", kind="stable").reset_index(drop=True)
        have = got.frames[kind].sort_values("line", kind="stable").reset_index(drop=True)
        assert len(have) == len(want), kind
        for c in want.columns:
            w, h = want[c], have[c]
            if c == "recv_ns":
                w, h = w.to_numpy(), h.to_numpy()
                ms = want["time_ns"].to_numpy() // 1_000_000 * 1_000_000
                assert ((h == w) | ((w == MISSING_NS) & (h == ms))).all(), kind
            elif c in ("source", "talker", "sentence", "reference"):
                assert (h.astype(str).to_numpy() == w.astype(str).to_numpy()).all(), (kind, c)
            else:
                np.testing.assert_allclose(
                    h.to_numpy(float), w.to_numpy(float), rtol=0, atol=1e-12, err_msg=f"{kind}.{c}"
                )


# ---------------------------------------------------------------- defaults unchanged

#: the columns frames had before the clocks (a column added later is not hashed)
HASHED = {
    "position": ["lat_rad", "lon_rad", "alt_m", "quality", "hdop"],
    "heading": ["heading_rad", "reference", "deviation_rad", "variation_rad", "heading_quality"],
    "ground": ["cog_rad", "sog_mps"],
    "water": ["stw_mps", "stw_transverse_mps", "sog_long_mps", "sog_transverse_mps"],
    "distance": ["total_water_m", "trip_water_m"],
    "rot": ["rot_radps"],
}


def frame_hash(frames) -> str:
    h = hashlib.sha256()
    for kind in KINDS:
        df = frames[kind]
        h.update(kind.encode())
        h.update(str(len(df)).encode())
        for c in ["time_ns", "source", "talker", "sentence", "line", "recv_ns", *HASHED[kind]]:
            a = df[c]
            if isinstance(a.dtype, pd.CategoricalDtype) or a.dtype == object:
                h.update("\x1f".join(a.astype(str).tolist()).encode())
            else:
                h.update(np.ascontiguousarray(a.to_numpy()).tobytes())
    return h.hexdigest()[:16]


def file_hash(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


DEFAULT_CASES = {
    "plain": SimParams(duration_s=900.0, seed=5, compass="both", compass_hz=2.0),
    "faults": SimParams(
        duration_s=1800.0,
        seed=7,
        compass="both",
        compass_hz=1.0,
        faults=(
            SimFault("latency", "GNSS", 300.0, 600.0, 3.0),
            SimFault("dropout", "INS3", 200.0, 100.0),
            SimFault("freeze", "MAG", 500.0, 100.0),
            SimFault("invalid", "INS1", 700.0, 100.0),
            SimFault("latency", "INS2", 100.0, 300.0, 1.5),
            SimFault("jump", "GNSS", 1000.0, 60.0, 500.0, 30.0),
        ),
    ),
}
#: computed with the code before the clocks (commit bfa1f27's simulator)
BEFORE = {
    "plain": "a7e48e0c847661c5",
    "plain-tag-s": "2b2f9c39c433d92a",
    "plain-tag-ms": "f3e376c320c4da98",
    "plain-prefix-s": "81c62d413b88f300",
    "plain-bare-s": "6a6910f452e8af44",
    "plain-csv-long": "caf8cc9d79d8847c",
    "plain-csv-wide": "1c88ea426545d697",
    "faults": "685270d84ab022a4",
    "faults-tag-s": "5f24ba56a622994e",
    "faults-tag-ms": "362c6ee1b77ad950",
    "faults-prefix-s": "62e4f843a5862235",
    "faults-bare-s": "ca14c7caf56a05c9",
    "faults-csv-long": "996f10886322fd43",
    "faults-csv-wide": "f55355bff27a64ba",
    "segments": ["f06ae44c73df7282", "018dc06fbf811794", "c7b128334e740d1d"],
}


def test_defaults_give_the_frames_and_logs_of_before(tmp_path):
    from dracc.sim.csv_out import write_csv

    for name, p in DEFAULT_CASES.items():
        v = simulate(p)
        assert frame_hash(v.frames) == BEFORE[name], name
        for form, tt in (("tag", "s"), ("tag", "ms"), ("prefix", "s"), ("bare", "s")):
            f = tmp_path / f"{name}-{form}-{tt}.nmea"
            write_nmea(v, f, form=form, tag_time=tt)
            assert file_hash(f) == BEFORE[f"{name}-{form}-{tt}"], f.name
            write_nmea(v.frames, f, form=form, tag_time=tt, roles=v.roles)  # frames: time order
            assert file_hash(f) == BEFORE[f"{name}-{form}-{tt}"], f.name
        for form in ("long", "wide"):
            f = tmp_path / f"{name}-{form}.csv"
            write_csv(v.frames, f, form=form, date_shifts=v.date_shifts)
            assert file_hash(f) == BEFORE[f"{name}-csv-{form}"], f.name
        assert v.date_shifts == ()
    segs = simulate_segments(DEFAULT_CASES["faults"], segment_s=600.0)
    assert [frame_hash(s.frames) for s in segs] == BEFORE["segments"]


def test_clocks_change_only_the_sampling():
    """Truth and errors do not depend on the clocks (no random draw moves); without clocks
    the truth of every source is phase 0, latency 0."""
    a = simulate(SimParams(**BASE))
    b = simulate(SimParams(**BASE, **CLOCKS))
    pd.testing.assert_frame_equal(a.truth, b.truth)
    pd.testing.assert_frame_equal(a.errors, b.errors)
    assert set(a.clocks) == {"GYRO", "MAG", "LOG", "INS1", "INS2", "INS3", "GNSS"}
    for src, c in a.clocks.items():
        assert c["phase_s"] == c["latency_s"] == 0.0
        if src in ("LOG", "INS1", "INS2", "INS3"):
            assert c["offset_s"] == c["offset_whole_s_stamps"] == 0.0  # 1 Hz on the second
    assert a.clocks["MAG"]["offset_whole_s_stamps"] == pytest.approx(-0.45, abs=1e-3)


# ---------------------------------------------------------------- phases and latencies


def test_phases_take_exact_truth_values_at_shifted_instants():
    p = SimParams(
        duration_s=120.0,
        seed=4,
        compass_hz=10.0,
        phases_s=(("INS2", 0.3), ("GYRO", 0.7), ("GNSS", 0.9)),
    )
    v = simulate(p)
    truth, err = v.truth, v.errors
    t = truth["time_ns"].to_numpy(np.int64)
    ins2 = of(v.frames["position"], "INS2")
    k = np.searchsorted(t, ins2["time_ns"].to_numpy(np.int64))
    np.testing.assert_array_equal(k[:4], [3, 13, 23, 33])  # 1 Hz at 0.3 s of a 10 Hz truth
    assert (np.diff(k) == 10).all() and k[-1] == 1193
    hd = of(v.frames["heading"], "INS2")
    np.testing.assert_array_equal(hd["time_ns"], ins2["time_ns"])  # no latency: same instants
    psi = truth["heading_rad"].to_numpy()
    want = q_angle_rad(psi[k] + err["ins2_heading_rad"].to_numpy()[k])
    np.testing.assert_array_equal(hd["heading_rad"].to_numpy(), want)
    # the gyro: HDT every 0.1 s (its phase within 0.1 s is 0), THS and ROT at 0.7 s
    gyro = of(v.frames["heading"], "GYRO")
    ths = gyro[gyro["sentence"] == "THS"]
    kt = np.searchsorted(t, ths["time_ns"].to_numpy(np.int64))
    assert kt[0] == 7 and (np.diff(kt) == 10).all()
    want = q_angle_rad(psi[kt] + err["gyro_err_rad"].to_numpy()[kt])
    np.testing.assert_array_equal(ths["heading_rad"].to_numpy(), want)
    assert (gyro["sentence"] == "HDT").sum() == len(t)
    # a noiseless GNSS reads the truth at its instants, 0.9 s past the second
    exact = simulate(SimParams.noiseless(duration_s=120.0, compass_hz=10.0, phases_s=p.phases_s))
    g = of(exact.frames["position"], "GNSS")
    kg = np.searchsorted(t, g["time_ns"].to_numpy(np.int64))
    assert kg[0] == 9
    lat = exact.truth["lat_rad"].to_numpy()
    np.testing.assert_array_equal(g["lat_rad"].to_numpy(), q_latlon_rad(lat[kg]))
    assert v.clocks["INS2"]["phase_s"] == 0.3 and v.clocks["GNSS"]["phase_s"] == 0.9
    assert v.clocks["GYRO"]["phase_s"] == 0.7


def test_phases_continue_over_segments():
    p = SimParams(duration_s=1200.0, seed=1, compass_hz=10.0, phases_s=(("INS1", 0.4),))
    whole = of(simulate(replace(p, ins_hz=0.5)).frames["position"], "INS1")["time_ns"]
    parts = simulate_segments(replace(p, ins_hz=0.5), segment_s=301.0)
    seg = pd.concat([of(v.frames["position"], "INS1")["time_ns"] for v in parts])
    np.testing.assert_array_equal(seg.to_numpy(), whole.to_numpy())  # 2 s grid at 0.4 s
    assert ((whole.to_numpy() - T0) % (2 * S) == 0.4 * S).all()


def test_latencies_land_in_time_or_receive_time():
    a = simulate(SimParams(**BASE, phases_s=CLOCKS["phases_s"]))
    b = simulate(SimParams(**BASE, **CLOCKS))
    lags = dict(CLOCKS["latency_s"])
    for kind in KINDS:
        for src in ("GYRO", "MAG", "LOG", "INS1", "INS2", "INS3", "GNSS"):
            x, y = of(a.frames[kind], src), of(b.frames[kind], src)
            assert len(x) == len(y)
            if not len(x):
                continue
            lag = int(round(lags.get(src, 0.0) * 1e3)) * 1_000_000
            o = own(x)
            np.testing.assert_array_equal(y["time_ns"][o], x["time_ns"][o])  # time of fix
            np.testing.assert_array_equal(y["time_ns"][~o], x["time_ns"][~o] + lag)  # receipt
            r = y["recv_ns"].to_numpy()
            if src in lags:
                np.testing.assert_array_equal(r[o], x["time_ns"][o] + lag)
                assert (r[~o] == MISSING_NS).all()
            else:
                assert (r == MISSING_NS).all()
            for c in x.columns.difference(["time_ns", "recv_ns", "line"]):  # values kept
                pd.testing.assert_series_equal(x[c], y[c])
    # lines in the order the logger receives them
    rec = every_record(b)
    assert (np.diff(received(rec)) >= 0).all()
    assert (np.diff(received(every_record(a))) >= 0).all()
    assert not (rec["line"].to_numpy() == every_record(a)["line"].to_numpy()).all()


def test_clock_truth():
    v = simulate(SimParams(**BASE, **CLOCKS))
    c = v.clocks
    assert c["INS2"] == {
        "phase_s": 0.3,
        "latency_s": 0.25,
        "offset_s": 0.25,
        "offset_whole_s_stamps": pytest.approx(-0.3),  # floor(k + 0.55) - (k + 0.3)
        "records": 2.0 * 600,  # HDT and VTG at 0.3 .. 599.3 s
    }
    assert c["GYRO"]["offset_s"] == 1.2 and c["LOG"]["offset_whole_s_stamps"] == pytest.approx(-0.9)
    # HDT at 10 Hz: floor(t + 1.2) - t is 1, 0.9 .. 0.3, 1.2, 1.1 (mean 0.75); THS, ROT 0.5
    hdt, aux = 6001, 2 * 600
    want = (0.75 * 6000 + 1.0 + 0.5 * aux) / (hdt + aux)
    assert c["GYRO"]["offset_whole_s_stamps"] == pytest.approx(want)
    assert c["MAG"]["offset_whole_s_stamps"] == pytest.approx(-0.45, abs=1e-3)
    assert c["MAG"]["latency_s"] == 0.04
    assert math.isnan(c["GNSS"]["offset_s"]) and c["GNSS"]["records"] == 0.0
    assert c["GNSS"]["latency_s"] == 0.1
    # the truth is the records': time_ns minus the true instant of each record without a fix
    for src in ("GYRO", "LOG", "INS2"):
        lag = int(c[src]["latency_s"] * 1e3) * 1_000_000
        t = np.concatenate(
            [of(f, src)["time_ns"].to_numpy()[~own(of(f, src))] for f in v.frames.values()]
        )
        inst = t - lag
        assert len(t) == c[src]["records"]
        whole = (t // S * S - inst).mean() / 1e9
        assert whole == pytest.approx(c[src]["offset_whole_s_stamps"], abs=1e-12)
    # segments: the weighted means
    parts = [v.clocks for v in simulate_segments(SimParams(**BASE, **CLOCKS), segment_s=250.0)]
    total = {}
    for part in parts:
        total = merge_clocks(total, part)
    for src, x in total.items():
        assert x["records"] == sum(p[src]["records"] for p in parts)
        if src != "GNSS":
            assert x["offset_s"] == c[src]["offset_s"]
            assert x["offset_whole_s_stamps"] == pytest.approx(c[src]["offset_whole_s_stamps"])


def test_a_clock_the_voyage_cannot_have():
    for kw in (
        {"phases_s": (("INS2", 1.0),)},  # a whole period
        {"phases_s": (("INS2", -0.1),)},
        {"phases_s": (("GYRO", 0.1),)},  # compass magnetic: no gyro
        {"latency_s": (("INS1", -1.0),)},
        {"latency_s": (("INS1", float("nan")),)},
        {"latency_s": (("INS1", 1.0), ("INS1", 2.0))},
        {"latency_s": (("ALL", 1.0),)},
    ):
        with pytest.raises(ConfigError):
            simulate(SimParams(duration_s=60.0, compass="magnetic", **kw))


def test_random_clocks():
    p = SimParams(**BASE)
    a, b = random_clocks(p, 9), random_clocks(p, 9)
    assert a == b and a != random_clocks(p, 10)
    assert a.duration_s == p.duration_s and a.faults == p.faults
    assert [s for s, _ in a.phases_s] == ["GYRO", "MAG", "LOG", "INS1", "INS2", "INS3", "GNSS"]
    for (src, ph), (_, lat) in zip(a.phases_s, a.latency_s, strict=True):
        assert 0.0 <= ph < (0.1 if src == "MAG" else 1.0)  # MAG: its 10 Hz period
        assert round(ph * 10, 9) == int(round(ph * 10))  # on the 10 Hz truth grid
        assert 0.0 <= lat <= (0.5 if src == "GNSS" else 2.0) and round(lat, 3) == lat
    q = random_clocks(SimParams(duration_s=60.0, compass_hz=10.0, ins_hz=0.5), 3, latency_max_s=5)
    ph = dict(q.phases_s)
    assert all(round(x * 10, 9) == int(round(x * 10)) for x in ph.values())  # on the grid
    assert 0 <= ph["INS1"] < 2.0 and 0 <= ph["GYRO"] < 1.0 and "MAG" not in ph
    draws = [random_clocks(SimParams(duration_s=60.0, ins_hz=0.5), s) for s in range(40)]
    assert max(dict(d.phases_s)["INS1"] for d in draws) >= 1.0  # the whole 2 s period
    assert max(dict(d.latency_s)["INS3"] for d in draws) > 1.5
    assert max(dict(d.latency_s)["GNSS"] for d in draws) <= 0.5
    g = np.random.default_rng(1)
    assert random_clocks(p, g).phases_s  # a generator works too
    with pytest.raises(ConfigError):
        random_clocks(p, 1, latency_max_s=-1.0)


# ---------------------------------------------------------------- written and read back


@pytest.fixture(scope="module")
def clocked():
    return simulate(SimParams(**BASE, **CLOCKS))


def test_ms_tag_log_reads_back_to_the_frames(clocked, tmp_path):
    p = tmp_path / "c.nmea"
    write_nmea(clocked, p, form="tag", tag_time="ms")
    got = read_back(p)
    assert_read_back_exactly(clocked, got)
    # and the prefix form carries the same receive times
    p = tmp_path / "p.nmea"
    write_nmea(clocked, p, form="prefix")
    pos = read_logs([p], IngestConfig()).frames["position"]
    gnss = pos[pos["source"] == "GP"]
    lag = (gnss["recv_ns"] - gnss["time_ns"]).to_numpy()
    assert (lag == 100_000_000).all()


def test_offset_whole_s_stamps_is_what_parsing_whole_second_stamps_gives(tmp_path):
    """For each source, the mean of (parsed time - true instant) over its records without a
    time of fix, parsed from TAG c: in whole seconds, is ``offset_whole_s_stamps``; with
    c: in ms it is the latency."""
    for seed in (3, 4):
        v = simulate(random_clocks(SimParams(**{**BASE, "seed": seed}), seed))
        inst = every_record(v)
        lag = inst["source"].map({s: c["latency_s"] for s, c in v.clocks.items()})
        inst["instant"] = np.where(
            own(inst),
            inst["time_ns"],
            inst["time_ns"] - np.rint(lag * 1e3).astype(np.int64) * 10**6,
        )
        for tt, key in (("s", "offset_whole_s_stamps"), ("ms", "offset_s")):
            p = tmp_path / f"w{seed}{tt}.nmea"
            write_nmea(v, p, form="tag", tag_time=tt)
            got = read_back(p)
            rec = pd.concat([got.frames[k][["line", "time_ns", "sentence"]] for k in KINDS])
            rec = rec.drop_duplicates("line").set_index("line")
            m = inst.set_index("line").join(rec.add_suffix("_parsed"))
            m = m[~own(m)]
            assert (m["sentence"] == m["sentence_parsed"]).all()
            for src, grp in m.groupby("source"):
                parsed = ((grp["time_ns_parsed"] - grp["instant"]) / 1e9).mean()
                assert parsed == pytest.approx(v.clocks[src][key], abs=1e-9), (seed, tt, src)
            assert set(m["source"]) == set(v.clocks) - {"GNSS"}


# ---------------------------------------------------------------- time faults


def run(*faults: SimFault, **kw):
    return simulate(SimParams(**{**BASE, **kw}, faults=tuple(faults)))


def test_parse_resolve_and_describe_the_time_faults():
    got = resolve_faults([SimFault(k) for k in TIME_FAULT_KINDS], 4 * 3600.0, seed=5)
    by = {f.kind: f for f in got}
    assert by["leap"].source == "GNSS" and by["leap"].size == 18.0
    assert by["leap"].duration_s == 3600.0
    assert by["rollover"].source == "GNSS" and by["rollover"].size is None
    assert math.isinf(by["rollover"].duration_s)
    assert by["loop"].source == "ALL" and by["loop"].size == 1320.0
    assert by["loop"].duration_s == 0.0
    assert by["clockstep"].source == "ALL" and by["clockstep"].size == -1320.0
    assert resolve_faults(got, 4 * 3600.0, seed=5) == got
    for f in got:
        assert 0.2 * 4 * 3600 <= f.start_s <= 0.5 * 4 * 3600
        again = resolve_faults([parse_fault(f.describe())], 4 * 3600.0, seed=5)[0]
        assert again == f, f.describe()
    assert by["loop"].describe() == f"loop:ALL@{by['loop'].start_s:g}s=1320s"
    assert parse_fault("clockstep:INS2@1h+10min=-22min") == SimFault(
        "clockstep", "INS2", 3600.0, 600.0, -1320.0
    )
    assert parse_fault("LEAP=17s").size == 17.0 and parse_fault("loop:all@2h=1h").size == 3600.0
    table = fault_table(got, T0, 4 * 3600.0, {"GNSS": "gnss"})
    row = {r["kind"]: r for r in table}
    assert row["loop"]["start_utc"] == row["loop"]["end_utc"] and row["loop"]["role"] is None
    assert row["loop"]["duration_s"] == 0.0 and row["loop"]["size_unit"] == "s"
    assert row["leap"]["role"] == "gnss" and row["rollover"]["size"] is None
    for bad in (
        "leap:INS1",  # GNSS only
        "rollover=3s",  # no size
        "loop+10min",  # no duration
        "leap=-18s",  # not signed
        "loop=-1min",
        "clockstep=x",
        "clockstep:BOGUS",
    ):
        with pytest.raises(ConfigError):
            resolve_faults([parse_fault(bad)], 3600.0, 0)
    # the sensor faults' draws are unchanged by the new kinds
    assert (
        resolve_faults([SimFault("jump")], 3600.0, 3)
        == resolve_faults([SimFault("jump"), SimFault("loop")], 3600.0, 3)[:1]
    )


def test_leap(tmp_path):
    f = SimFault("leap", "GNSS", 100.0, 200.0, 18.0)
    a, b = run(latency_s=(("GNSS", 0.2),)), run(f, latency_s=(("GNSS", 0.2),))
    lo, hi = T0 + 100 * S, T0 + 300 * S
    for kind in ("position", "ground"):
        x, y = of(a.frames[kind], "GNSS"), of(b.frames[kind], "GNSS")
        t = x["time_ns"].to_numpy()
        w = (t >= lo) & (t < hi)
        np.testing.assert_array_equal(y["time_ns"], np.where(w, t + 18 * S, t))
        np.testing.assert_array_equal(y["recv_ns"], x["recv_ns"])  # the logger's clock: true
        np.testing.assert_array_equal(y.iloc[:, 6:], x.iloc[:, 6:])  # values of the instant
    for kind in KINDS:  # other sources untouched
        x, y = a.frames[kind], b.frames[kind]
        pd.testing.assert_frame_equal(x[x["source"] != "GNSS"], y[y["source"] != "GNSS"])
    zt = a.zda["time_ns"].to_numpy()
    np.testing.assert_array_equal(
        b.zda["time_ns"], np.where((zt >= lo) & (zt < hi), zt + 18 * S, zt)
    )
    # without a latency the GNSS still keeps its receive time
    c = of(run(f).frames["position"], "GNSS")
    w = (c["recv_ns"] != MISSING_NS).to_numpy()
    assert w.sum() == 2 * 200 and ((c["recv_ns"] - c["time_ns"])[w] == -18 * S).all()
    # written and read back: GNSS receive minus time of fix = latency - size
    p = tmp_path / "leap.nmea"
    write_nmea(b, p, form="tag", tag_time="ms")
    got = read_back(p)
    assert_read_back_exactly(b, got)
    g = of(got.frames["position"], "GNSS")
    lag = (g["recv_ns"] - g["time_ns"]).to_numpy() / 1e9
    w = ((g["recv_ns"] >= lo) & (g["recv_ns"] < hi)).to_numpy()
    assert lag[w] == pytest.approx(0.2 - 18.0) and lag[~w] == pytest.approx(0.2)
    line = next(ln for ln in p.read_bytes().split(b"\r\n") if b"$GPGGA,000200.00" in ln)
    assert b",c:1772323302200*" in line  # GPS time 00:02:00 received at 00:01:42.2 UTC


def test_rollover(tmp_path):
    """The GNSS's dates 1024 weeks early in the log, its TAG c: the true time; dracc's
    ingest repairs the dates (1999 -> 2019) and counts them as implausible."""
    kw = {"start_utc": "2019-05-01T00:00:00Z", "latency_s": (("GNSS", 0.3),)}
    a, b = run(**kw), run(SimFault("rollover", start_s=200.0), **kw)
    assert b.params.faults[0].source == "GNSS" and math.isinf(b.params.faults[0].duration_s)
    for kind in KINDS:  # a perfect parser of the TAG form: the same frames
        pd.testing.assert_frame_equal(a.frames[kind], b.frames[kind])
    t0 = start_ns("2019-05-01T00:00:00Z")
    assert b.date_shifts == (("GNSS", t0 + 200 * S, None, ROLLOVER_DAYS),)
    early = 400 - 1  # RMC and ZDA from 200 s to the end (600 s, its last sample included)
    for form in ("tag", "prefix", "bare"):
        p = tmp_path / f"r-{form}.nmea"
        write_nmea(b, p, form=form, tag_time="ms")
        text = p.read_bytes()
        assert text.count(b",1999,00,00*") == early + 2  # ZDA 1999-09-15
        assert text.count(b",150999,,,A*") == early + 2  # RMC ddmmyy
        assert b"$GPZDA,000319.00,01,05,2019" in text
        got = read_logs([p], IngestConfig())
        assert got.time_events.implausible_dates == 2 * (early + 2)
        g = of(got.frames["position"], "GNSS" if form == "tag" else "GP")
        want = of(b.frames["position"], "GNSS")["time_ns"].to_numpy()
        np.testing.assert_array_equal(np.sort(g["time_ns"].to_numpy()), want)
    zda = next(
        ln for ln in (tmp_path / "r-tag.nmea").read_bytes().split(b"\r\n") if b"ZDA,000500" in ln
    )
    assert zda.startswith(b"\\s:GNSS,c:1556669100300*") and b",15,09,1999," in zda
    # MCAP: the NMEA encoding writes the early dates, the others stamp the fixes 1024 weeks
    # early, their log time the true receive time: both repaired on reading
    pytest.importorskip("mcap")
    for fmt in ("mcap-nmea", "mcap-json"):
        p = tmp_path / f"r.{fmt}.mcap"
        write_log(b, p, fmt)
        got = read_back(p)
        g = of(got.frames["position"], "GNSS")
        if fmt == "mcap-nmea":
            assert got.time_events.implausible_dates == 2 * (early + 2)
            np.testing.assert_array_equal(np.sort(g["time_ns"].to_numpy()), want)
        else:  # every GNSS record stamped early (position, ground ...) repaired
            late = (g["recv_ns"] - g["time_ns"]).to_numpy() - 300_000_000
            assert sorted(set(late)) == [0]
            np.testing.assert_array_equal(np.sort(g["time_ns"].to_numpy()), want)
            assert got.time_events.implausible_dates >= early + 2
    # CSV: one time per record, the GNSS's own: early
    p = tmp_path / "r.csv"
    write_log(b, p, "csv-long")
    assert "1999-09-15T00:05:00.000000000Z,GNSS" in p.read_text()


def test_loop(tmp_path):
    """The records received in the 120 s before 300 s written again at 300 s: the TAG
    times go back; dracc reads the log back to the frames, line by line."""
    a, b = (
        run(latency_s=CLOCKS["latency_s"]),
        run(SimFault("loop", start_s=300.0, size=120.0), latency_s=CLOCKS["latency_s"]),
    )
    ra, rb = every_record(a), every_record(b)
    lo = T0 + 300 * S
    copied = ra[(received(ra) >= lo - 120 * S) & (received(ra) < lo)]
    assert len(rb) == len(ra) + len(copied) and len(copied) > 120 * 15
    at = int(ra["line"][received(ra) >= lo].min())
    cols = ["source", "sentence", "time_ns", "recv_ns"]
    # the log: up to 300 s, the replay, then on as before
    head, rest = rb[rb["line"] < at], rb[rb["line"] >= at]
    pd.testing.assert_frame_equal(head[cols], ra[ra["line"] < at][cols])
    replay = rest.iloc[: len(copied)].reset_index(drop=True)
    pd.testing.assert_frame_equal(replay[cols], copied[cols].reset_index(drop=True))
    tail = rest.iloc[len(copied) :].reset_index(drop=True)
    pd.testing.assert_frame_equal(tail[cols], ra[ra["line"] >= at][cols].reset_index(drop=True))
    lines = np.union1d(rb["line"], b.zda["line"])
    assert (np.diff(lines) == 1).all() and lines[0] == 1
    # values of a copy are those of its original
    for kind in KINDS:
        df = b.frames[kind]
        key = ["source", "sentence", "time_ns", "recv_ns"]
        dup = df[df.duplicated(key, keep=False)]
        assert dup.drop(columns="line").drop_duplicates().shape[0] * 2 == len(dup), kind
    # a loop of one source replays that source only
    one = run(SimFault("loop", "INS2", 300.0, size=60.0))
    n = {s: len(g) for s, g in every_record(one).groupby("source")}
    m = {s: len(g) for s, g in every_record(run()).groupby("source")}
    assert n["INS2"] == m["INS2"] + 3 * 60 and all(n[s] == m[s] for s in m if s != "INS2")
    # written (all three forms) and read back
    p = tmp_path / "loop.nmea"
    write_nmea(b, p, form="tag", tag_time="ms")
    got = read_back(p)
    assert_read_back_exactly(b, got)
    assert got.time_events.backsteps > 0
    c = np.array([int(x) for x in re.findall(rb",c:(\d+)\*", p.read_bytes())])
    back = np.flatnonzero(np.diff(c) < 0)
    assert len(back) == 1 and c[back[0] + 1] - c[back[0]] == pytest.approx(-120_000, abs=1300)
    for form in ("prefix", "bare"):
        q = tmp_path / f"loop-{form}.nmea"
        write_nmea(b, q, form=form)
        assert len(q.read_bytes().split(b"\r\n")) == len(p.read_bytes().split(b"\r\n"))


def test_clockstep(tmp_path):
    f = SimFault("clockstep", "ALL", 200.0, 100.0, -60.0)
    a, b = run(latency_s=(("INS2", 0.25),)), run(f, latency_s=(("INS2", 0.25),))
    lo, hi = T0 + 200 * S, T0 + 300 * S
    for kind in KINDS:
        x, y = a.frames[kind], b.frames[kind]
        r = received(x)
        w = (r >= lo) & (r < hi)
        o = own(x)
        np.testing.assert_array_equal(
            y["time_ns"], np.where(w & ~o, x["time_ns"] - 60 * S, x["time_ns"])
        )
        np.testing.assert_array_equal(y["recv_ns"], np.where(w & o, r - 60 * S, x["recv_ns"]))
        np.testing.assert_array_equal(y["line"], x["line"])
    # written: the stamps step back at 200 s and forward at 300 s; fixes keep their time
    p = tmp_path / "step.nmea"
    write_nmea(b, p, form="tag", tag_time="ms")
    got = read_back(p)
    assert_read_back_exactly(b, got)
    g = of(got.frames["position"], "GNSS")
    lag = (g["recv_ns"] - g["time_ns"]).to_numpy()
    t = g["time_ns"].to_numpy()
    w = (t >= lo) & (t < hi)
    assert (lag[w] == -60 * S).all() and (lag[~w] == 0).all()
    c = np.array([int(x) for x in re.findall(rb",c:(\d+)\*", p.read_bytes())])
    d = np.diff(c)
    big = sorted(d[np.abs(d) > 5000].tolist())
    assert len(big) == 2 and big == pytest.approx([-60_000, 60_000], abs=1000)
    # one source's clock only
    one = run(SimFault("clockstep", "LOG", 200.0, 100.0, 30.0))
    for kind in KINDS:
        x, y = a.frames[kind], one.frames[kind]
        keep = (x["source"] != "LOG").to_numpy()
        np.testing.assert_array_equal(y["time_ns"][keep], run().frames[kind]["time_ns"][keep])


def test_mcap_writes_receive_times_and_the_logger_order(tmp_path):
    pytest.importorskip("mcap")
    from mcap.reader import make_reader

    v = run(
        SimFault("loop", start_s=400.0, size=60.0),
        SimFault("clockstep", start_s=100.0, duration_s=50.0, size=-20.0),
        SimFault("leap", start_s=450.0, duration_s=100.0),
        **CLOCKS,
    )
    for fmt in ("mcap-json", "mcap-ros2", "mcap-nmea"):
        p = tmp_path / f"v.{fmt}.mcap"
        write_log(v, p, fmt)
        with open(p, "rb") as fh:
            msgs = list(make_reader(fh).iter_messages(log_time_order=False))
        log_t = np.array([m[2].log_time for m in msgs])
        assert all(m[2].publish_time == m[2].log_time for m in msgs)
        back = np.diff(log_t)
        assert back.min() < -50 * S and (back < -10 * S).sum() == 2  # the loop, the step
        got = read_back(p)
        if fmt == "mcap-nmea":
            assert got.time_events.backsteps > 0
        g = of(got.frames["position"], "GNSS")
        lag = np.unique((g["recv_ns"] - g["time_ns"]).to_numpy())
        assert {100_000_000, 100_000_000 - 18 * S, 100_000_000 - 20 * S} <= set(lag.tolist())
        assert sum(len(f) for f in got.frames.values()) == sum(len(f) for f in v.frames.values())
    # json: log time = receive time of every record, stamps = time_ns
    p = tmp_path / "v.mcap-json.mcap"
    with open(p, "rb") as fh:
        msgs = list(make_reader(fh).iter_messages(log_time_order=False))
    ins2 = [m for m in msgs if m[1].topic == "/INS2/fix"]
    stamps = [json.loads(m[2].data)["timestamp"] for m in ins2]
    t = np.array([s["sec"] * S + s["nsec"] for s in stamps])
    lt = np.array([m[2].log_time for m in ins2])
    assert set((lt - t).tolist()) == {250_000_000, 250_000_000 - 20 * S}  # the clock step
    hd = [m for m in msgs if m[1].topic == "/GYRO/heading"]
    ts = np.array([json.loads(m[2].data)["timestamp"]["sec"] * S for m in hd[:5]])
    assert ((ts - T0) % S == 0).all()  # stamped on receipt: 0.5 s phase + 1.2 s latency = 1.7


# ---------------------------------------------------------------- the command


def _run(*args):
    from dracc.cli import simulate_cmd  # noqa: F401
    from dracc.cli.app import app

    try:
        app(args=[str(a) for a in args], prog_name="dracc", standalone_mode=False)
        return 0
    except DraccError as e:
        return int(e.exit_code)


def test_cli_clocks_and_time_faults(tmp_path):
    out = tmp_path / "v"
    code = _run(
        "simulate",
        "--hours",
        "0.5",
        "--seed",
        "4",
        "--segment-hours",
        "0.1",
        "--clocks",
        "random",
        "--latency-max",
        "1.5",
        "--phase",
        "INS2=0.3",
        "--latency",
        "gnss=0.1",
        "--fault",
        "loop@20min=6min",
        "--fault",
        "clockstep@10min+2min=-30s",
        "--fault",
        "leap:GNSS@5min+5min",
        "--fault",
        "rollover@25min",
        "--out",
        out,
    )
    assert code == 0
    info = json.loads((out / "params.json").read_text())
    clocks = info["clocks"]
    assert set(clocks) == {"GYRO", "LOG", "INS1", "INS2", "INS3", "GNSS"}
    assert clocks["INS2"]["phase_s"] == 0.3 and clocks["GNSS"]["latency_s"] == 0.1
    assert clocks["GNSS"]["offset_s"] is None and clocks["GNSS"]["records"] == 0
    assert all(0 <= c["latency_s"] <= 1.5 for c in clocks.values())
    assert clocks["INS1"]["offset_s"] == clocks["INS1"]["latency_s"]
    want = with_clocks(
        SimParams(seed=4), "random", 1.5, ["INS2=0.3"], ["gnss=0.1"]
    )  # the same draws as the command's
    assert dict(map(tuple, info["params"]["latency_s"])) == dict(want.latency_s)
    assert [f["kind"] for f in info["faults"]] == ["loop", "clockstep", "leap", "rollover"]
    # the log: receive order through the segments, back only at the step and the loop
    text = (out / "voyage.nmea").read_bytes()
    c = np.array([int(x) for x in re.findall(rb",c:(\d+)\*", text)])
    assert len(str(c[0])) == 13  # ms: the compass writes at 10 Hz
    d = np.diff(c)
    back = c[1:][d < 0] - T0 // 10**6
    assert len(back) == 2 and abs(back[0] - 570_000) < 2000 and abs(back[1] - 840_000) < 2000
    assert b",1999,00,00*" not in text and b",16,07,2006,00,00*" in text  # 2026 - 1024 weeks
    got = read_back(out / "voyage.nmea")
    assert got.time_events.backsteps > 0
    # whole seconds: offset_whole_s_stamps as parsed, from params.json
    out2 = tmp_path / "w"
    assert (
        _run(
            "simulate",
            "--hours",
            "0.1",
            "--compass-hz",
            "1",
            "--clocks",
            "random",
            "--segment-hours",
            "0.05",
            "--out",
            out2,
        )
        == 0
    )
    info = json.loads((out2 / "params.json").read_text())
    assert info["tag_time"] == "s"
    lines = (out2 / "voyage.nmea").read_bytes()
    c = np.array([int(x) for x in re.findall(rb",c:(\d+)\*", lines)])
    assert (np.diff(c) >= 0).all()
    for bad in (
        ["--clocks", "sometimes"],
        ["--phase", "INS2"],
        ["--phase", "MAG=0.1"],
        ["--latency", "INS1=-1"],
        ["--latency-max", "-1", "--clocks", "random"],
        ["--fault", "loop+1min"],
    ):
        assert _run("simulate", "--hours", "0.1", "--out", tmp_path / "bad", *bad) == 2
    assert not (tmp_path / "bad").exists()
