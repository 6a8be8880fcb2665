"""Seeded sensor faults of ``dracc simulate`` (dracc.sim.faults): spec parsing, defaults,
each kind changing exactly the named source in the named window, reproducibility, and the
written logs read back with dracc's ingest showing the fault."""

from __future__ import annotations

import json
import math
import re
from dataclasses import replace
from functools import reduce
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dracc.core.config import IngestConfig
from dracc.core.errors import ConfigError, DraccError
from dracc.core.geodesy import angdiff, offset_ne_m
from dracc.core.units import KN_MPS
from dracc.frames import KINDS, MISSING_NS
from dracc.ingest import read_logs
from dracc.sim import SimFault, SimParams, parse_fault, resolve_faults, simulate
from dracc.sim.faults import (
    ALL_SOURCES,
    DEFAULT_DURATION_S,
    DEFAULT_SOURCE,
    FAULT_KINDS,
    fault_table,
)
from dracc.sim.model import simulate_segments
from dracc.sim.nmea_out import frames_to_lines, write_nmea
from dracc.sim.readings import SOURCES
from dracc.sim.truth import start_ns

#: a short voyage, every sensor at 1 Hz, both compasses (so MAG exists)
BASE = {"duration_s": 3600.0, "seed": 11, "compass": "both", "compass_hz": 1.0, "aux_hz": 1.0}
S = 1_000_000_000


@pytest.fixture(scope="module")
def base():
    return simulate(SimParams(**BASE))


def run(*faults: SimFault, **kw):
    return simulate(SimParams(**{**BASE, **kw}, faults=tuple(faults)))


def rows(v, kind: str, source: str) -> pd.DataFrame:
    f = v.frames[kind]
    return f[(f["source"] == source).to_numpy(bool)].reset_index(drop=True)


def window(v, i: int = 0) -> tuple[int, int | None]:
    return v.params.faults[i].window_ns(start_ns(v.params.start_utc))


def inside(t, lo, hi) -> np.ndarray:
    t = np.asarray(t, np.int64)
    return (t >= lo) & (t < hi) if hi is not None else t >= lo


def same(x: pd.DataFrame, y: pd.DataFrame, drop=(), what: str = "") -> None:
    """Frames equal column by column, bit for bit (NaN equal to NaN; string columns by
    value, whatever their categories; fast: no per-element Python)."""
    assert list(x.columns) == list(y.columns) and len(x) == len(y), what
    for c in x.columns:
        if c in drop:
            continue
        a, b = x[c], y[c]
        if isinstance(a.dtype, pd.CategoricalDtype) or a.dtype == object:
            assert (a.astype(str).to_numpy() == b.astype(str).to_numpy()).all(), (what, c)
        else:
            a, b = a.to_numpy(), b.to_numpy()
            assert a.dtype == b.dtype, (what, c)
            assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), (what, c)


def assert_others_unchanged(a, b, source: str, ignore_line: bool = False) -> None:
    """Every frame row of every source except ``source`` identical in a and b (the truth
    too)."""
    pd.testing.assert_frame_equal(a.truth, b.truth)
    for kind in KINDS:
        for src in ALL_SOURCES:
            if src == source:
                continue
            same(
                rows(a, kind, src),
                rows(b, kind, src),
                ("line",) if ignore_line else (),
                f"{kind} {src}",
            )


def assert_errors_unchanged_except(a, b, cols=(), lo=None, hi=None) -> None:
    for c in a.errors.columns:
        x, y = a.errors[c].to_numpy(), b.errors[c].to_numpy()
        if c in cols:
            out = ~inside(a.errors["time_ns"], lo, hi)
            np.testing.assert_array_equal(x[out], y[out], err_msg=c)
        else:
            np.testing.assert_array_equal(x, y, err_msg=c)


def xor(s: bytes) -> int:
    return reduce(lambda a, b: a ^ b, s, 0)


# ---------------------------------------------------------------- spec parsing


def test_parse_the_documented_examples():
    assert parse_fault("jump:GNSS@2h=670m") == SimFault("jump", "GNSS", 7200.0, None, 670.0)
    assert parse_fault("freeze:INS2@1.5h+40min") == SimFault("freeze", "INS2", 5400.0, 2400.0)
    assert parse_fault("dropout:INS3+25min") == SimFault("dropout", "INS3", None, 1500.0)
    assert parse_fault("drift:INS1=1kn") == SimFault("drift", "INS1", size=KN_MPS)
    assert parse_fault("latency:GNSS=3s") == SimFault("latency", "GNSS", size=3.0)
    assert parse_fault("invalid:GNSS+10min") == SimFault("invalid", "GNSS", None, 600.0)
    assert parse_fault("freeze") == SimFault("freeze")


def test_parse_units_and_case():
    assert parse_fault("jump@90=1.2km").start_s == 90.0  # bare number: seconds
    assert parse_fault("jump@90=1.2km").size == pytest.approx(1200.0)
    assert parse_fault("jump=5").size == 5.0  # bare: metres
    assert parse_fault("drift=0.5m/s").size == 0.5
    assert parse_fault("drift=2").size == pytest.approx(2 * KN_MPS)  # bare: knots
    assert parse_fault("latency=250ms").size == pytest.approx(0.25)
    assert parse_fault("latency=7").size == 7.0
    assert parse_fault("FREEZE:ins2@30min+90s") == SimFault("freeze", "INS2", 1800.0, 90.0)
    assert parse_fault(" dropout:gnss@1.5h+0.25h ").duration_s == 900.0
    assert math.isinf(parse_fault("drift:INS3@1h+end=1kn").duration_s)


@pytest.mark.parametrize(
    "spec, words",
    [
        ("jmp:GNSS", ["jmp", "unknown kind", "jump, freeze, dropout, drift, latency, invalid"]),
        ("jump:INS4", ["INS4", "unknown source", "INS1"]),
        ("jump:GNSS@2hours", ["START", "2hours", "s, min, h"]),
        ("jump:GNSS@2m", ["START", "s, min, h"]),  # m is metres, not minutes
        ("jump:GNSS=670ft", ["SIZE", "670ft", "m, km"]),
        ("drift:INS1=1knot", ["SIZE", "kn, m/s"]),
        ("freeze:INS2=5m", ["freeze takes no =SIZE"]),
        ("latency:GNSS+x", ["DURATION"]),
        ("jump:GNSS=670m@2h", ["SIZE"]),  # the parts in the wrong order
        ("", ["expected KIND[:SOURCE][@START][+DURATION][=SIZE]"]),
    ],
)
def test_parse_errors_name_the_spec_and_what_is_expected(spec, words):
    with pytest.raises(ConfigError) as e:
        parse_fault(spec)
    msg = str(e.value)
    assert repr(spec) in msg
    for w in words:
        assert w in msg


# ---------------------------------------------------------------- resolution


def test_resolve_fills_the_defaults():
    got = resolve_faults([SimFault(k) for k in FAULT_KINDS], 4 * 3600.0, seed=5)
    for f in got:
        assert f.source == DEFAULT_SOURCE[f.kind]
        assert 0.2 * 4 * 3600 <= f.start_s <= 0.5 * 4 * 3600 and f.start_s == round(f.start_s)
        want = DEFAULT_DURATION_S[f.kind]
        assert f.duration_s == (want if f.start_s + want < 4 * 3600 else math.inf)
    by = {f.kind: f for f in got}
    assert by["jump"].size == 670.0 and by["drift"].size == pytest.approx(KN_MPS)
    assert by["latency"].size == 3.0 and math.isinf(by["drift"].duration_s)
    assert by["freeze"].size is by["dropout"].size is by["invalid"].size is None
    assert 0 <= by["jump"].direction_deg < 360 and 0 <= by["drift"].direction_deg < 360
    assert by["latency"].direction_deg is None
    # idempotent, and given values are kept
    assert resolve_faults(got, 4 * 3600.0, seed=5) == got
    f = resolve_faults([SimFault("jump", "INS1", 100.0, 50.0, 10.0, 90.0)], 3600.0, seed=5)[0]
    assert f == SimFault("jump", "INS1", 100.0, 50.0, 10.0, 90.0)
    # a window beyond the end runs to the end
    assert math.isinf(resolve_faults([SimFault("freeze", start_s=3000.0)], 3600.0, 0)[0].duration_s)


def test_resolve_draws_are_seeded_and_independent():
    one = resolve_faults([SimFault("jump")], 3600.0, seed=1)
    assert one == resolve_faults([SimFault("jump")], 3600.0, seed=1)
    assert one != resolve_faults([SimFault("jump")], 3600.0, seed=2)
    # adding or reordering faults changes no other fault's draws
    more = resolve_faults([SimFault("freeze"), SimFault("latency"), SimFault("jump")], 3600.0, 1)
    assert more[2] == one[0]
    # a second fault of the same kind and source gets its own draws
    two = resolve_faults([SimFault("jump"), SimFault("jump")], 3600.0, seed=1)
    assert two[0] == one[0] and two[1].start_s != two[0].start_s


@pytest.mark.parametrize(
    "fault, compass, words",
    [
        (SimFault("jump", start_s=3600.0), "gyro", ["start 1 h", "outside the voyage", "[0, 1 h)"]),
        (SimFault("jump", start_s=-5.0), "gyro", ["outside the voyage"]),
        (SimFault("jump", size=-1.0), "gyro", ["size -1 m", "SIZE >= 0"]),
        (SimFault("latency", size=-3.0), "gyro", ["SIZE >= 0"]),
        (SimFault("freeze", duration_s=0.0), "gyro", ["DURATION > 0"]),
        (SimFault("freeze", "MAG"), "gyro", ["no source MAG", "INS1, INS2, INS3, GNSS, GYRO"]),
        (SimFault("dropout", "GYRO"), "magnetic", ["no source GYRO"]),
        (SimFault("freeze", "LOG"), "gyro", ["freeze cannot hit source 'LOG'"]),
        (SimFault("jump", "GYRO"), "gyro", ["INS1, INS2, INS3, GNSS"]),
        (SimFault("invalid", size=1.0), "gyro", ["takes no size"]),
        (SimFault("bogus"), "gyro", ["unknown kind"]),
    ],
)
def test_resolve_errors(fault, compass, words):
    with pytest.raises(ConfigError) as e:
        resolve_faults([fault], 3600.0, seed=0, compass=compass, labels=["SPEC"])
    assert "--fault 'SPEC'" in str(e.value)
    for w in words:
        assert w in str(e.value)


def test_sources_match_the_simulator():
    assert set(ALL_SOURCES) == set(SOURCES)


def test_no_fault_is_the_default(base):
    assert SimParams().faults == ()
    assert SimParams(**BASE).to_dict()["faults"] == []
    again = simulate(SimParams(**BASE, faults=()))
    for kind in KINDS:
        same(base.frames[kind], again.frames[kind])
    assert base.unit_rms == again.unit_rms and "voyage_s" not in base.state


# ---------------------------------------------------------------- each kind


def test_jump(base):
    v = run(SimFault("jump", "GNSS", 1200.0, 600.0, 670.0, 30.0))
    lo, hi = window(v)
    assert hi - lo == 600 * S
    assert_others_unchanged(base, v, "GNSS")
    a, b = rows(base, "position", "GNSS"), rows(v, "position", "GNSS")
    w = inside(a["time_ns"], lo, hi)
    assert w.sum() == 2 * 600  # GGA and RMC at 1 Hz
    same(a[~w], b[~w])
    n, e = offset_ne_m(b["lat_rad"][w], b["lon_rad"][w], a["lat_rad"][w], a["lon_rad"][w])
    np.testing.assert_allclose(n, 670 * math.cos(math.radians(30)), atol=0.01)
    np.testing.assert_allclose(e, 670 * math.sin(math.radians(30)), atol=0.01)
    same(rows(base, "ground", "GNSS"), rows(v, "ground", "GNSS"))
    assert_errors_unchanged_except(base, v, ("gnss_north_m", "gnss_east_m"), lo, hi)
    we = inside(v.errors["time_ns"], lo, hi)
    np.testing.assert_allclose(
        v.errors["gnss_north_m"][we] - base.errors["gnss_north_m"][we],
        670 * math.cos(math.radians(30)),
        atol=1e-9,
    )


def test_freeze_position(base):
    v = run(SimFault("freeze", "INS2", 1000.0, 2400.0))
    lo, hi = window(v)
    assert_others_unchanged(base, v, "INS2")
    a, b = rows(base, "position", "INS2"), rows(v, "position", "INS2")
    w = inside(a["time_ns"], lo, hi)
    assert w.sum() == 2400 and len(a) == len(b)  # records keep coming
    same(a[~w], b[~w])
    last = np.flatnonzero(a["time_ns"] < lo)[-1]
    for c in ("lat_rad", "lon_rad"):
        held = b[c].to_numpy()[w]
        assert (held.view(np.int64) == a[c].to_numpy()[last : last + 1].view(np.int64)).all()
    for kind in ("heading", "ground"):  # an INS freeze is its position only
        same(rows(base, kind, "INS2"), rows(v, kind, "INS2"))
    # errors.csv: the frozen reading minus the truth
    assert_errors_unchanged_except(base, v, ("ins2_north_m", "ins2_east_m"), lo, hi)
    we = inside(v.errors["time_ns"], lo, hi)
    n, e = offset_ne_m(
        a["lat_rad"][last], a["lon_rad"][last], v.truth["lat_rad"][we], v.truth["lon_rad"][we]
    )
    np.testing.assert_allclose(v.errors["ins2_north_m"][we], n, atol=1e-6)
    np.testing.assert_allclose(v.errors["ins2_east_m"][we], e, atol=1e-6)
    assert v.unit_rms["ins2"]["lat_m"] > base.unit_rms["ins2"]["lat_m"]
    assert v.unit_rms["ins1"] == base.unit_rms["ins1"]


@pytest.mark.parametrize("source, err_col", [("GYRO", "gyro_err_rad"), ("MAG", "mag_err_rad")])
def test_freeze_compass(base, source, err_col):
    v = run(SimFault("freeze", source, 600.0, 300.0))
    lo, hi = window(v)
    assert_others_unchanged(base, v, source)
    a, b = rows(base, "heading", source), rows(v, "heading", source)
    w = inside(a["time_ns"], lo, hi)
    same(a[~w], b[~w])
    assert w.sum() == 300 * (2 if source == "GYRO" else 1)  # gyro: HDT and THS
    assert b["heading_rad"][w].nunique() == 1
    assert b["heading_rad"][w].iloc[0] == a["heading_rad"][a["time_ns"] < lo].iloc[-1]
    if source == "MAG":
        assert b["deviation_rad"][w].nunique() == 1
    same(rows(base, "rot", source), rows(v, "rot", source))
    assert_errors_unchanged_except(base, v, (err_col,), lo, hi)
    we = inside(v.errors["time_ns"], lo, hi)
    true = v.truth["heading_rad" if source == "GYRO" else "compass_course_rad"][we]
    np.testing.assert_allclose(
        v.errors[err_col][we], angdiff(b["heading_rad"][w].iloc[0], true), atol=1e-12
    )


def test_dropout(base):
    v = run(SimFault("dropout", "GNSS", 1000.0, 1500.0))
    lo, hi = window(v)
    assert_others_unchanged(base, v, "GNSS", ignore_line=True)
    for kind in ("position", "ground"):
        a, b = rows(base, kind, "GNSS"), rows(v, kind, "GNSS")
        w = inside(a["time_ns"], lo, hi)
        assert w.sum() > 0 and not inside(b["time_ns"], lo, hi).any()
        same(a[~w].reset_index(drop=True), b, ("line",))
    assert not inside(v.zda["time_ns"], lo, hi).any() and len(v.zda) == len(base.zda) - 1500
    # line numbers are those of the written log: consecutive again
    lines = np.concatenate([f["line"].to_numpy() for f in v.frames.values()] + [v.zda["line"]])
    u = np.unique(lines)
    assert (u == np.arange(1, len(u) + 1)).all()
    _, _, written = frames_to_lines(v.frames, v.roles)
    assert len(written) == len(u)
    assert_errors_unchanged_except(base, v)  # the sensor's error process goes on


def test_drift(base):
    v = run(SimFault("drift", "INS1", 1800.0, size=KN_MPS, direction_deg=200.0))
    lo, hi = window(v)
    assert hi is None  # to the end, including the last sample
    assert_others_unchanged(base, v, "INS1")
    a, b = rows(base, "position", "INS1"), rows(v, "position", "INS1")
    w = inside(a["time_ns"], lo, hi)
    assert w[-1] and w.sum() == 1801
    same(a[~w], b[~w])
    n, e = offset_ne_m(b["lat_rad"][w], b["lon_rad"][w], a["lat_rad"][w], a["lon_rad"][w])
    ramp = KN_MPS * (a["time_ns"][w].to_numpy() - lo) / S
    np.testing.assert_allclose(n, ramp * math.cos(math.radians(200)), rtol=1e-3, atol=0.01)
    np.testing.assert_allclose(e, ramp * math.sin(math.radians(200)), rtol=1e-3, atol=0.01)
    assert np.hypot(n, e).max() == pytest.approx(KN_MPS * 1800, rel=1e-3)  # 926 m at the end
    for kind in ("heading", "ground"):
        same(rows(base, kind, "INS1"), rows(v, kind, "INS1"))
    assert_errors_unchanged_except(base, v, ("ins1_north_m", "ins1_east_m"), lo, hi)
    # a drift of given duration: back to normal after it
    v2 = run(SimFault("drift", "INS1", 1800.0, 600.0, KN_MPS, 200.0))
    lo2, hi2 = window(v2)
    b2 = rows(v2, "position", "INS1")
    w2 = inside(a["time_ns"], lo2, hi2)
    same(a[~w2], b2[~w2])
    assert (b2["lat_rad"][w2] != a["lat_rad"][w2]).sum() > 590


def test_latency(base):
    v = run(SimFault("latency", "INS3", 1000.0, 600.0, 3.0))
    lo, hi = window(v)
    assert_others_unchanged(base, v, "INS3")
    for kind in ("position", "heading", "ground"):
        a, b = rows(base, kind, "INS3"), rows(v, kind, "INS3")
        same(a, b, ("recv_ns",))
        # the records received in the window: received 3 s after their time of fix
        got = b["recv_ns"].to_numpy() != MISSING_NS
        np.testing.assert_array_equal(got, inside(b["time_ns"] + 3 * S, lo, hi))
        assert got.sum() == 600
        assert ((b["recv_ns"][got] - b["time_ns"][got]) == 3 * S).all()
        assert (a["recv_ns"] == MISSING_NS).all()
    assert_errors_unchanged_except(base, v)


def test_invalid(base):
    v = run(SimFault("invalid", "INS1", 1200.0, 600.0))
    lo, hi = window(v)
    assert_others_unchanged(base, v, "INS1")
    a, b = rows(base, "position", "INS1"), rows(v, "position", "INS1")
    w = inside(a["time_ns"], lo, hi)
    assert (b["quality"][w] == 0).all() and (b["quality"][~w] == 1).all() and w.sum() == 600
    same(a, b, ("quality",))
    assert_errors_unchanged_except(base, v)
    # written: GGA fix quality 0 and VTG mode N in the window, A elsewhere
    t, src, lines = frames_to_lines(v.frames, v.roles)
    ins1 = src == "INS1"
    win = inside(t, lo, hi)
    for typ, pat_bad, pat_ok in (("GGA", rb",E,0,", rb",E,1,"), ("VTG", rb",K,N\*", rb",K,A\*")):
        sel = [
            ln
            for ln, s, k in zip(lines, ins1, win, strict=True)
            if s and ln[3:6] == typ.encode() and k
        ]
        out = [
            ln
            for ln, s, k in zip(lines, ins1, win, strict=True)
            if s and ln[3:6] == typ.encode() and not k
        ]
        assert len(sel) == 600 and all(re.search(pat_bad, ln) for ln in sel)
        assert all(re.search(pat_ok, ln) for ln in out)
    # GNSS invalid: RMC status V and mode N
    g = run(SimFault("invalid", "GNSS", 1200.0, 10.0))
    _, _gsrc, glines = frames_to_lines(g.frames, g.roles)
    rmc = [ln for ln in glines if ln.startswith(b"$GPRMC")]
    assert sum(ln.split(b",")[2] == b"V" and ln[-4:-3] == b"N" for ln in rmc) == 10
    assert sum(ln.split(b",")[2] == b"A" for ln in rmc) == 3601 - 10


def test_reproducible_and_composable(base):
    faults = (
        SimFault("jump"),
        SimFault("freeze"),
        SimFault("dropout"),
        SimFault("drift"),
        SimFault("latency"),
        SimFault("invalid"),
    )
    a, b = run(*faults), run(*faults)
    for kind in KINDS:
        same(a.frames[kind], b.frames[kind])
    pd.testing.assert_frame_equal(a.errors, b.errors)
    assert a.params.faults == b.params.faults
    # every fault resolved as when given alone; the truth (other draws) is the same
    for i, f in enumerate(faults):
        assert run(f).params.faults[0] == a.params.faults[i]
    pd.testing.assert_frame_equal(a.truth, base.truth)
    # LOG and the compasses untouched by this set
    for src in ("LOG", "GYRO", "MAG"):
        for kind in KINDS:
            x, y = rows(base, kind, src), rows(a, kind, src)
            same(x, y, ("line",), f"{kind} {src}")


def test_segments_apply_faults_by_absolute_time():
    """Faults across segment boundaries: the same as the unfaulted segmented voyage except
    in the window; a freeze holds one value through every boundary."""
    p = SimParams(duration_s=3600.0, seed=4, compass_hz=1.0)
    faults = (
        SimFault("freeze", "INS2", 500.0, 2000.0),
        SimFault("dropout", "INS3", 800.0, 1000.0),
        SimFault("latency", "GNSS", 1000.0, size=2.0),
    )
    seg = 700.0

    def cat(params):
        vs = list(simulate_segments(params, seg))
        return vs, {k: pd.concat([v.frames[k] for v in vs], ignore_index=True) for k in KINDS}

    _vb, fb = cat(p)
    vf, ff = cat(replace(p, faults=faults))
    assert len(vf) == 6
    t0 = start_ns(p.start_utc)
    res = vf[0].params.faults
    assert res == resolve_faults(faults, 3600.0, 4)  # resolved over the whole voyage
    pos_b, pos_f = fb["position"], ff["position"]
    i2b, i2f = pos_b[pos_b["source"] == "INS2"], pos_f[pos_f["source"] == "INS2"]
    lo, hi = res[0].window_ns(t0)
    w = inside(i2b["time_ns"], lo, hi).astype(bool)
    assert w.sum() == 2000
    assert i2f["lat_rad"][w].nunique() == 1 and i2f["lon_rad"][w].nunique() == 1
    assert i2f["lat_rad"][w].iloc[0] == i2b["lat_rad"][i2b["time_ns"] < lo].iloc[-1]
    np.testing.assert_array_equal(i2f["lat_rad"][~w], i2b["lat_rad"][~w])
    lo, hi = res[1].window_ns(t0)
    for kind in ("position", "heading", "ground"):
        tb = fb[kind]["time_ns"][fb[kind]["source"] == "INS3"].to_numpy()
        tf = ff[kind]["time_ns"][ff[kind]["source"] == "INS3"].to_numpy()
        np.testing.assert_array_equal(tf, tb[~inside(tb, lo, hi)])
        assert np.diff(tf).max() == 1001 * S
    lo, hi = res[2].window_ns(t0)
    g = pos_f[pos_f["source"] == "GNSS"]
    got = g["recv_ns"].to_numpy() != MISSING_NS
    np.testing.assert_array_equal(got, inside(g["time_ns"] + 2 * S, lo, hi))
    for kind in KINDS:  # every other source identical
        for src in ("GYRO", "LOG", "INS1"):
            x = fb[kind][fb[kind]["source"] == src].reset_index(drop=True)
            y = ff[kind][ff[kind]["source"] == src].reset_index(drop=True)
            same(x, y, ("line",), f"{kind} {src}")


# ---------------------------------------------------------------- written logs read back


@pytest.fixture(scope="module")
def faulted():
    return run(
        SimFault("jump", "GNSS", 600.0, 300.0, 670.0, 90.0),
        SimFault("freeze", "INS2", 900.0, 1200.0),
        SimFault("dropout", "INS3", 1200.0, 1500.0),
        SimFault("latency", "GNSS", 1500.0, 900.0, 3.0),
        SimFault("invalid", "INS1", 2400.0, 600.0),
    )


def read_back(path: Path):
    v = read_logs([path], IngestConfig())
    assert v.rejects.total == 0
    return v


def test_nmea_tag_log_read_back_shows_the_faults(faulted, tmp_path):
    p = tmp_path / "f.nmea"
    write_nmea(faulted, p, form="tag", tag_time="s")
    got = read_back(p)
    pos = got.frames["position"]
    t0 = start_ns(faulted.params.start_utc)
    f = {x.kind: x for x in faulted.params.faults}
    # the frozen INS2 positions repeat bit-identically for the freeze's length
    ins2 = pos[pos["source"] == "INS2"]
    lo, hi = f["freeze"].window_ns(t0)
    w = inside(ins2["time_ns"], lo, hi)
    assert ins2["lat_rad"][w].nunique() == 1 and w.sum() == 1200
    runs = (ins2["lat_rad"].diff() == 0).sum()
    assert runs == 1200  # 1200 repeats of the last reading before the start
    # the dropout leaves a gap of about its duration in every INS3 stream
    for kind in ("position", "heading", "ground"):
        t = got.frames[kind]["time_ns"][got.frames[kind]["source"] == "INS3"].to_numpy()
        assert np.diff(t).max() == pytest.approx(1500 * S, abs=1.01 * S)
    assert got.time_events.gaps >= 3
    # the invalid INS1 fixes have quality 0
    ins1 = pos[pos["source"] == "INS1"]
    lo, hi = f["invalid"].window_ns(t0)
    w = inside(ins1["time_ns"], lo, hi)
    assert (ins1["quality"][w] == 0).all() and (ins1["quality"][~w] == 1).all()
    # latency: GNSS received 3 s after the time of fix (c: in whole seconds; 1 Hz fixes)
    g = pos[pos["source"] == "GNSS"]
    lo, hi = f["latency"].window_ns(t0)
    lag = (g["recv_ns"] - g["time_ns"]).to_numpy()
    late = inside(g["time_ns"] + 3 * S, lo, hi)
    assert (lag[late] == 3 * S).all() and late.sum() == 2 * 900
    assert (np.abs(lag[~late]) < S).all()
    # the jump: the GNSS fixes 670 m east in its window, read back as simulated
    lo, hi = f["jump"].window_ns(t0)
    gb = faulted.frames["position"]
    gb = gb[gb["source"] == "GNSS"]
    np.testing.assert_allclose(g["lat_rad"].to_numpy(), gb["lat_rad"].to_numpy(), atol=1e-12)
    np.testing.assert_allclose(g["lon_rad"].to_numpy(), gb["lon_rad"].to_numpy(), atol=1e-12)
    base = run()
    gbase = rows(base, "position", "GNSS")
    n, e = offset_ne_m(
        g["lat_rad"].to_numpy(), g["lon_rad"].to_numpy(), gbase["lat_rad"], gbase["lon_rad"]
    )
    w = inside(g["time_ns"], lo, hi)
    np.testing.assert_allclose(e[w], 670.0, atol=0.01)
    assert np.abs(n[w]).max() < 0.01 and np.abs(e[~w]).max() < 0.01
    # every line still has a valid checksum
    for ln in p.read_bytes().split(b"\r\n")[:-1]:
        body = ln.rsplit(b"\\", 1)[1]
        assert int(body[-2:], 16) == xor(body[1:-3])


def test_nmea_prefix_and_bare_forms(faulted, tmp_path):
    t0 = start_ns(faulted.params.start_utc)
    lo, hi = next(x for x in faulted.params.faults if x.kind == "latency").window_ns(t0)
    for form in ("prefix", "bare"):
        p = tmp_path / f"{form}.nmea"
        write_nmea(faulted, p, form=form, roles=faulted.roles)
        got = read_logs([p], IngestConfig(date="2026-03-01") if form == "bare" else IngestConfig())
        pos = got.frames["position"]
        g = pos[pos["source"] == "GP"]  # no TAG source: the talker
        assert len(g) == 7202
        r = g["recv_ns"].to_numpy()
        late = inside(g["time_ns"] + 3 * S, lo, hi)
        if form == "prefix":  # the logger's stamp is the receive time
            assert ((r[late] - g["time_ns"].to_numpy()[late]) == 3 * S).all()
        else:  # bare: no receive time, the latency is invisible
            assert (r == MISSING_NS).all() or (r[late] == g["time_ns"].to_numpy()[late]).all()
    first = (tmp_path / "prefix.nmea").read_bytes().split(b"\r\n")
    late_line = next(ln for ln in first if b"$GPGGA,002500.00" in ln)
    assert late_line.startswith(b"2026-03-01T00:25:03.000Z ")


def test_mcap_log_time_is_the_receive_time(tmp_path):
    pytest.importorskip("mcap")
    from dracc.sim.mcap_out import write_mcap

    v = simulate(
        SimParams(
            duration_s=900.0,
            seed=2,
            compass_hz=1.0,
            faults=(SimFault("latency", "GNSS", 300.0, 300.0, 3.0),),
        )
    )
    lo, hi = window(v)
    for enc in ("json", "nmea"):
        p = tmp_path / f"f-{enc}.mcap"
        write_mcap(v.frames, v.roles, p, encoding=enc)
        got = read_back(p)
        pos = got.frames["position"]
        g = pos[pos["source"] == "GNSS"]
        late = inside(g["time_ns"] + 3 * S, lo, hi)
        assert late.sum() == 600  # GGA and RMC
        lag = (g["recv_ns"] - g["time_ns"]).to_numpy()
        assert (lag[late] == 3 * S).all()
        assert (lag[~late] == 0).all()


# ---------------------------------------------------------------- CLI


def _run(*args):
    from dracc.cli import simulate_cmd  # noqa: F401
    from dracc.cli.app import app

    try:
        app(args=[str(a) for a in args], prog_name="dracc", standalone_mode=False)
        return 0
    except DraccError as e:
        return int(e.exit_code)


def test_cli_faults_in_params_json(tmp_path, capsys):
    out = tmp_path / "v"
    code = _run(
        "simulate",
        "--hours",
        "1",
        "--compass-hz",
        "1",
        "--seed",
        "7",
        "--segment-hours",
        "0.25",
        "--out",
        out,
        "--fault",
        "jump:GNSS@20min=670m",
        "--fault",
        "freeze:INS2@15min+40min",
        "--fault",
        "dropout:INS3+25min",
        "--fault",
        "drift:INS1=1kn",
        "--fault",
        "latency:GNSS=3s",
        "--fault",
        "invalid:GNSS+10min",
    )
    assert code == 0
    assert "faults: jump:GNSS@1200s+600s=670m, freeze:INS2@900s+2400s" in capsys.readouterr().err
    info = json.loads((out / "params.json").read_text())
    faults = info["faults"]
    assert [f["kind"] for f in faults] == list(FAULT_KINDS)
    assert set(faults[0]) == {
        "kind",
        "source",
        "role",
        "start_utc",
        "end_utc",
        "start_s",
        "duration_s",
        "size",
        "size_unit",
        "direction_deg",
    }
    assert faults[0] | {"direction_deg": None} == {
        "kind": "jump",
        "source": "GNSS",
        "role": "gnss",
        "start_utc": "2026-03-01T00:20:00.000000000Z",
        "end_utc": "2026-03-01T00:30:00.000000000Z",
        "start_s": 1200.0,
        "duration_s": 600.0,
        "size": 670.0,
        "size_unit": "m",
        "direction_deg": None,
    }
    drift = faults[3]
    assert drift["end_utc"] == "2026-03-01T01:00:00.000000000Z" and drift["size_unit"] == "m/s"
    assert drift["duration_s"] == 3600.0 - drift["start_s"]
    assert drift["size"] == pytest.approx(KN_MPS)
    assert info["params"]["faults"][3]["duration_s"] == "inf"
    want = resolve_faults(
        [
            parse_fault(s)
            for s in (
                "jump:GNSS@20min=670m",
                "freeze:INS2@15min+40min",
                "dropout:INS3+25min",
                "drift:INS1=1kn",
                "latency:GNSS=3s",
                "invalid:GNSS+10min",
            )
        ],
        3600.0,
        7,
    )
    assert faults == fault_table(
        want, start_ns("2026-03-01T00:00:00Z"), 3600.0, {s: SOURCES[s][0] for s in SOURCES}
    )
    # errors.csv holds the truth of the faults: the jump in the GNSS error
    errors = pd.read_csv(out / "errors.csv")
    jumped = np.hypot(errors["gnss_north_m"], errors["gnss_east_m"]) > 600
    assert jumped.sum() == 600
    t = pd.to_datetime(errors["time_utc"][jumped])
    assert t.min() == pd.Timestamp("2026-03-01T00:20:00Z") and t.max() == pd.Timestamp(
        "2026-03-01T00:29:59Z"
    )
    # the log read back: the dropout gap and the frozen run through the segment boundaries
    got = read_back(out / "voyage.nmea")
    pos = got.frames["position"]
    ins3 = pos["time_ns"][pos["source"] == "INS3"].to_numpy()
    assert np.diff(ins3).max() == 1501 * S
    ins2 = pos[pos["source"] == "INS2"]
    assert (ins2["lat_rad"].diff() == 0).sum() == 2400
    assert info["records"]["position"] == len(pos)


def test_cli_rejects_bad_fault_specs(tmp_path, capsys):
    for spec in ("jmp", "jump:GNSS@5h", "jump=-3m", "freeze:MAG", "drift=1knot", "dropout:LOG=1s"):
        assert (
            _run("simulate", "--hours", "1", "--out", tmp_path / "x", "--fault", spec) == 2
        )  # usage
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("fmt", ["csv-long", "mcap-json"])
def test_cli_other_formats(tmp_path, fmt):
    out = tmp_path / fmt
    assert (
        _run(
            "simulate",
            "--hours",
            "0.2",
            "--compass-hz",
            "1",
            "--format",
            fmt,
            "--out",
            out,
            "--fault",
            "freeze:GNSS@5min+2min",
            "--fault",
            "latency:INS1@2min+2min=2s",
        )
        == 0
    )
    got = read_back(next(out.glob("voyage.*")))
    pos = got.frames["position"]
    g = pos[pos["source"] == "GNSS"]
    w = inside(
        g["time_ns"],
        300 * S + start_ns("2026-03-01T00:00:00Z"),
        420 * S + start_ns("2026-03-01T00:00:00Z"),
    )
    assert w.sum() == 240 and g["lat_rad"][w].nunique() == 1 and g["lon_rad"][w].nunique() == 1
    assert g["lat_rad"][w].iloc[0] == g["lat_rad"][g["time_ns"] < g["time_ns"][w].min()].iloc[-1]
    i1 = pos[pos["source"] == "INS1"]
    lag = (i1["recv_ns"] - i1["time_ns"]).to_numpy()
    if fmt == "mcap-json":
        assert (lag == 2 * S).sum() == 120
    else:  # CSV carries one time per record: the latency is invisible
        assert not (lag == 2 * S).any()
