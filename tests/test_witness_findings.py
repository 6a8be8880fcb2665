"""A finding needs a witness (issue 29, item 2): frozen, stuck, jump, latency and the
clockless log.  Each defect seen on real logs is a named test here, with the injected
fault on a simulated voyage that the check must still find (the checks keep their power).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
from conftest import real_path

from dracc.core.config import Config, IngestConfig, IntegrityConfig
from dracc.core.geodesy import add_offset_ne
from dracc.core.resolution import HEADING_QUANTA_RAD, quantum
from dracc.core.units import DEG_RAD, NS_PER_S
from dracc.frames import KINDS, MISSING_NS, Rejects, SourceInfo, TimeEvents, Voyage, empty_frame
from dracc.ingest import read_logs
from dracc.math.integrity import check_night
from dracc.sim import SimParams, simulate
from dracc.sim.faults import parse_fault
from dracc.sim.params import GM

MIN = 60 * NS_PER_S


def _voyage(sv, drop: tuple[str, ...] = ()) -> Voyage:
    """The simulated frames as a perfect reader returns them (copies), roles from the
    simulator, without the sources ``drop``."""
    frames = {}
    for k in KINDS:
        df = sv.frames.get(k, empty_frame(k)).copy()
        frames[k] = df[~df["source"].isin(drop).to_numpy()].reset_index(drop=True)
    sources = {k: SourceInfo(k, roles=[r]) for k, r in sv.roles.items() if k not in drop}
    return Voyage(frames, sources, Rejects(), TimeEvents(), [])


def _check(result, name: str, source: str):
    return next(c for c in result.checks if c.name == name and c.source == source)


def _hold(df: pd.DataFrame, source: str, cols: tuple[str, ...], a_ns: int, b_ns: int) -> None:
    """``source`` repeats its first reading in [a, b] bit for bit there (in place)."""
    t = df["time_ns"].to_numpy(np.int64)
    i = np.flatnonzero((df["source"].to_numpy() == source) & (t >= a_ns) & (t <= b_ns))
    for c in cols:
        df.loc[i, c] = df.loc[i[0], c]


def _held_gnss_voyage(speed_kn: float, drop: tuple[str, ...] = ()) -> Voyage:
    """One hour; the GNSS holds its fix in blocks of 15 min (a receiver's static mode)
    and says SOG 0.0 itself; every other source as simulated."""
    sv = simulate(
        SimParams(
            duration_s=3600.0,
            seed=5,
            compass_hz=1.0,
            aux_hz=0.0,
            speed_kn=speed_kn,
            current_drift_kn=0.0,
            current_noise_kn=GM(0.0, 1800.0),  # moored: no drift
        )
    )
    v = _voyage(sv, drop)
    pos = v.frames["position"]
    t0 = int(pos["time_ns"].min())
    for k in range(4):
        _hold(pos, "GNSS", ("lat_rad", "lon_rad"), t0 + k * 15 * MIN, t0 + (k + 1) * 15 * MIN - 1)
    gnd = v.frames["ground"]
    gnd.loc[(gnd["source"] == "GNSS").to_numpy(), "sog_mps"] = 0.0
    return v


# ------------------------------------------------------------------ frozen / stuck


def test_moored_boat_is_at_rest_not_frozen():
    """A moored boat whose GNSS holds its fix (SOG 0.0) was 'position frozen 15 min' x3
    and a 'contradiction': the INS and the log show it at rest, so it passes, saying so."""
    r = check_night(_held_gnss_voyage(0.0))
    frozen = _check(r, "frozen", "GNSS")
    assert frozen.status == "pass", frozen.message
    assert "at rest: SOG" in frozen.message and "heading spread" in frozen.message
    assert {e["verdict"] for e in frozen.evidence} == {"at_rest"}
    assert not [c for c in r.failed if c.name in ("frozen", "stuck", "contradiction", "jump")]
    # no other source at all: nothing can be concluded, and the check says why
    alone = check_night(_held_gnss_voyage(0.0, drop=("INS1", "INS2", "INS3", "LOG", "GYRO")))
    c = _check(alone, "frozen", "GNSS")
    assert c.status == "not_checked" and "no other source" in c.why_not
    assert not alone.failed
    # the real at-dock log: no frozen, stuck or contradiction finding
    dock = read_logs([real_path("signalk-server", "gofree-merrimac.log")], IngestConfig())
    failed = check_night(dock, IntegrityConfig()).failed
    assert not [c for c in failed if c.name in ("frozen", "stuck", "contradiction")], failed


def test_moored_boat_heading_not_stuck_while_witnesses_wander():
    """A moored boat's gyro repeating its heading was 'heading stuck': at rest (the INS
    SOG says so) the INS headings' 1.3 deg of yaw is no swing that proves it dead.  The
    same gyro held while the boat swings 20 deg at its mooring is stuck."""
    v = _held_gnss_voyage(0.0)
    hd = v.frames["heading"]
    t0 = int(hd["time_ns"].min())
    a, b = t0 + 20 * MIN, t0 + 40 * MIN
    _hold(hd, "GYRO", ("heading_rad",), a, b)
    c = _check(check_night(v), "stuck", "GYRO")
    assert c.status == "pass" and "at rest: SOG" in c.message, c.message
    t = hd["time_ns"].to_numpy(np.int64)
    ins = hd["source"].isin(["INS1", "INS2", "INS3"]).to_numpy() & (t >= a) & (t <= b)
    hd.loc[ins, "heading_rad"] += 20.0 * DEG_RAD * (t[ins] - a) / (b - a)  # the swing
    c = _check(check_night(v), "stuck", "GYRO")
    assert c.status == "fail", c.message


def _instrument_bus(speed_kn: float) -> Voyage:
    """GNSS, compass (whole degrees) and log all under one talker, 'II', as an NKE or B&G
    bus logs them; the fix held in blocks of 15 min, its SOG 0.0."""
    v = _held_gnss_voyage(speed_kn, drop=("INS1", "INS2", "INS3"))
    frames = {}
    for k, df in v.frames.items():
        df = df.copy()
        df["source"] = "II"
        frames[k] = df
    frames["water"]["stw_mps"] *= speed_kn > 0
    h = frames["heading"]
    h["heading_rad"] = np.round(h["heading_rad"] / DEG_RAD) * DEG_RAD
    return replace(v, frames=frames, sources={"II": SourceInfo("II", roles=["compass", "log"])})


def test_moored_instrument_bus_is_at_rest_not_frozen_stuck_or_contradicted():
    """One talker for everything (an instrument bus) moored, SOG 0.0 and STW 0.0: was
    frozen, stuck and a contradiction.  The log is another instrument under the same key:
    at rest; the heading has no other witness: never stuck.  Under way at 12 kn the log
    witnesses the held fix."""
    r = check_night(_instrument_bus(0.0))
    assert not r.failed, [c.message for c in r.failed]
    frozen = _check(r, "frozen", "II")
    assert frozen.status == "pass" and "at rest: log speed 0.0 kn (II)" in frozen.message
    assert _check(r, "stuck", "II").status in ("pass", "not_checked")
    moving = check_night(_instrument_bus(12.0))
    assert _check(moving, "frozen", "II").status == "fail"


def test_held_gnss_fix_under_way_is_still_frozen():
    """The same held fix at 12 kn: the INS witness the motion, frozen fails (and the
    source flagged the frozen fixes valid: a contradiction)."""
    r = check_night(_held_gnss_voyage(12.0))
    frozen = _check(r, "frozen", "GNSS")
    assert frozen.status == "fail" and "while SOG 1" in frozen.message, frozen.message
    assert _check(r, "contradiction", "GNSS").status == "fail"


def _straight_voyage(yaw_amp_deg: float, legs=None):
    return simulate(
        SimParams(
            duration_s=2 * 3600.0,
            seed=9,
            compass_hz=1.0,
            aux_hz=0.0,
            yaw_amp_deg=yaw_amp_deg,
            legs=legs or ((0.0, 75.0),),
        )
    )


def _with_ais_heading(v: Voyage, hold: tuple[int, int]) -> Voyage:
    """An 'AIS' heading source: the gyro in whole degrees, held over ``hold``."""
    hd = v.frames["heading"]
    ais = hd[(hd["source"] == "GYRO").to_numpy()].copy()
    ais["heading_rad"] = np.round(ais["heading_rad"].to_numpy() / DEG_RAD) * DEG_RAD
    ais["source"] = "AIS"
    ais = ais.reset_index(drop=True)
    _hold(ais, "AIS", ("heading_rad",), *hold)
    frames = dict(v.frames)
    frames["heading"] = pd.concat([hd, ais], ignore_index=True).sort_values(
        "time_ns", kind="stable", ignore_index=True
    )
    frames["heading"]["source"] = frames["heading"]["source"].astype("category")
    return replace(v, frames=frames, sources={**v.sources, "AIS": SourceInfo("AIS", roles=[])})


def test_ais_integer_heading_not_stuck_while_gyro_turns_under_its_resolution():
    """An AIS heading in whole degrees repeats while the gyro and the INS yaw 0.9 deg on
    a straight leg: not stuck (three of its 1 deg steps would be).  The same AIS heading
    held through a 40 deg turn is stuck; the gyro held through the 0.9 deg yaw is stuck
    (its own resolution is far finer)."""
    sv = _straight_voyage(0.45)
    v = _voyage(sv)
    t0 = int(v.frames["heading"]["time_ns"].min())
    hold = (t0 + 30 * MIN, t0 + 50 * MIN)
    va = _with_ais_heading(v, hold)
    ais = va.frames["heading"][(va.frames["heading"]["source"] == "AIS").to_numpy()]
    assert quantum(ais["heading_rad"].to_numpy(), HEADING_QUANTA_RAD) == pytest.approx(DEG_RAD)
    r = check_night(va)
    c = _check(r, "stuck", "AIS")
    assert c.status == "pass", c.message
    assert "steady" in c.message and "within 3 deg" in c.message
    # power: a turn well beyond its resolution, or the fine gyro held through the yaw
    turning = _voyage(_straight_voyage(0.45, legs=((0.0, 75.0), (40 * 60.0, 115.0))))
    r = check_night(_with_ais_heading(turning, hold))
    assert _check(r, "stuck", "AIS").status == "fail"
    _hold(v.frames["heading"], "GYRO", ("heading_rad",), *hold)
    r = check_night(v)
    gyro = _check(r, "stuck", "GYRO")
    assert gyro.status == "fail", gyro.message


# ------------------------------------------------------------------------ jumps

IRENE = ("anemomind", "Irene", "2008", "regate_21_mai_08", "IreneLog.txt")


@pytest.fixture(scope="module")
def irene() -> Voyage:
    return read_logs([real_path(*IRENE)], IngestConfig())


def _displace(v: Voyage, at_ns: int, north_m: float) -> Voyage:
    """A copy of ``v`` whose position records at ``at_ns`` are ``north_m`` north."""
    pos = v.frames["position"].copy()
    i = np.flatnonzero(pos["time_ns"].to_numpy(np.int64) == at_ns)
    lat, lon = add_offset_ne(pos.loc[i, "lat_rad"], pos.loc[i, "lon_rad"], north_m, 0.0)
    pos.loc[i, "lat_rad"], pos.loc[i, "lon_rad"] = lat, lon
    return replace(v, frames={**v.frames, "position": pos})


def test_irene_gaps_no_jump(irene):
    """Ordinary motion at 5.8-7.3 kn across 6-18 s gaps in the compass and log was 3
    'jumps' (and a contradiction x3): the step across a hole is predicted from the held
    heading and speed, and what the ship can do over the unseen time is allowed.  A
    displaced fix is still found, on a regular step and on the 18 s gap step."""
    r = check_night(irene, IntegrityConfig())
    jump = _check(r, "jump", "II")
    assert jump.status == "pass", jump.message
    assert not [c for c in r.failed if c.name == "contradiction"]
    gap_step = int(pd.Timestamp("2008-05-21T17:53:38Z").value)
    regular = int(pd.Timestamp("2008-05-21T17:00:00Z").value)
    for at, size in ((regular, 60.0), (gap_step, 200.0)):
        c = _check(check_night(_displace(irene, at, size), IntegrityConfig()), "jump", "II")
        assert c.status == "fail", (at, c.message)
        assert any(
            e["time"].startswith(pd.Timestamp(at).strftime("%Y-%m-%dT%H:%M:%S")) for e in c.evidence
        )


# --------------------------------------------------------------- latency, clocks


def _sim_night(*specs: str):
    return simulate(
        SimParams(
            duration_s=2 * 3600.0,
            seed=4,
            compass_hz=1.0,
            aux_hz=0.0,
            faults=tuple(parse_fault(s) for s in specs),
        )
    )


def test_clockless_log_no_latency_finding(tmp_path):
    """A candump without a clock was 'data 25 s old': the sources of a log whose times
    are only the order of its records get no latency or drop-out finding, a not_checked
    saying why; the same night with a clock still fails both."""
    sv = _sim_night("latency:GNSS@30min+30min=25s", "dropout:GNSS@1h+10min")
    clocked = check_night(_voyage(sv))
    assert _check(clocked, "latency", "GNSS").status == "fail"
    assert _check(clocked, "dropout", "GNSS").status == "fail"
    v = replace(_voyage(sv), clockless=frozenset(sv.roles))
    r = check_night(v)
    for name in ("latency", "dropout"):
        c = _check(r, name, "GNSS")
        assert c.status == "not_checked" and c.why_not.startswith("no clock"), c
    assert not [c for c in r.failed if c.check in ("latency", "availability")]
    summary = next(s for s in r.sources if s.source == "GNSS")
    assert summary.latency_s is None and summary.availability is None
    # the audit of the log read back: no latency or availability finding or measure,
    # 'no clock' among what could not be checked
    from dracc.pipeline.analysis import analyse_voyage
    from dracc.pipeline.audit.facts import facts_from_analysis
    from dracc.pipeline.audit.findings import evaluate
    from dracc.pipeline.audit.limits import AuditConfig
    from dracc.sim.output import write_log

    write_log(sv, tmp_path / "night.nmea", "nmea", tag_time="ms")
    read = read_logs([tmp_path / "night.nmea"], IngestConfig())
    read = replace(read, clockless=frozenset(read.sources))
    facts = facts_from_analysis(analyse_voyage(read, Config()))
    found, skipped = evaluate(facts, AuditConfig())
    assert not [f for f in found if f.check == "latency" or f.kind == "dropout"], found
    assert any(s["name"] == "latency" and "no clock" in s["why"] for s in skipped), skipped
    rows = facts.measures["rows"]
    assert not [m for m in rows if m["quantity"] in ("latency", "availability")], rows
    # a real candump without times (canboat's candumpSample2, read as clockless)
    from conftest import REPO

    dump = read_logs([REPO / "tests" / "data" / "n2k" / "candumpSample2.txt"], IngestConfig())
    assert dump.clockless
    r = check_night(dump, IntegrityConfig())
    timed = [c for c in r.checks if c.check in ("latency", "availability")]
    assert timed and all(c.status == "not_checked" and "no clock" in c.why_not for c in timed)


def test_negative_latency_worded_as_clock_lead():
    """A clock offset of -2.17 s was worded 'data 2.17 s old': a time of fix ahead of
    the logger clock is said to be ahead (a clock offset), never old; a positive latency
    is a time of fix behind the logger clock."""
    sv = _sim_night("latency:GNSS@30min+30min=3s")
    r = check_night(_voyage(sv))
    late = _check(r, "latency", "GNSS")
    assert late.status == "fail"
    assert "time of fix is 3.00 s behind the logger clock" in late.message, late.message
    v = _voyage(sv)
    pos = v.frames["position"]
    recv = pos["recv_ns"].to_numpy(np.int64)
    has = recv != MISSING_NS
    pos.loc[has, "recv_ns"] = pos.loc[has, "time_ns"] - int(2.17 * NS_PER_S)
    r = check_night(v)
    # ahead of the logger clock is the time checks' finding (time/leap_second), said once
    early = _check(r, "leap_second", "GNSS")
    assert early.status == "fail"
    assert "2.17 s ahead of the logger clock" in early.message, early.message
    assert " old" not in early.message
    lat = _check(r, "latency", "GNSS")
    assert lat.status == "pass" and "judged by time/leap_second" in lat.message, lat.message


def test_integrity_frozen_uses_the_users_faults_thresholds():
    """[faults] moving_min_kn reaches the integrity checks: a fix held at 12 kn is frozen
    by default; where the user says only 20 kn proves motion, no witness shows it."""
    from dracc.core.config import FaultsConfig

    v = _held_gnss_voyage(12.0)
    assert _check(check_night(v), "frozen", "GNSS").status == "fail"
    r = check_night(v, faults_cfg=FaultsConfig(moving_min_kn=20.0))
    assert _check(r, "frozen", "GNSS").status != "fail"
