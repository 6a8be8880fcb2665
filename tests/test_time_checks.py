"""The time checks (dracc.math.integrity.time_checks): the logger's clock and the
receivers' own times of fix.

Logs are written here line by line (IEC 61162-450 TAG blocks ``\\s:SRC,c:STAMP*hh\\``,
checksums by hand), independent of dracc's writers: a GNSS (GGA, RMC) and a gyro (HDT)
at 1 Hz, the GNSS's time of fix ``leap_s`` ahead of the truth and received ``latency_s``
after it.  The back-steps of a log are what the ingest records
(``TimeEvents.steps``); where the ingest at hand records none, the same
:class:`~dracc.frames.ClockStep` objects are built here from the frames in line order.
"""

from __future__ import annotations

import datetime as dt
import math
from dataclasses import replace
from functools import reduce
from pathlib import Path

import numpy as np
import pytest
from conftest import REAL, REPO, SAMPLES, real_path

from dracc.core.config import Config, IngestConfig, IntegrityConfig
from dracc.frames import (
    ClockStep,
    Rejects,
    SourceInfo,
    TimeEvents,
    Voyage,
    empty_frame,
    make_frame,
    own_time,
)
from dracc.ingest import read_logs
from dracc.math.integrity import check_night
from dracc.math.integrity.time_checks import drift_fit, whole_seconds

START_S = 1_780_000_000.0  # 2026-05-28T20:26:40Z
CFG = Config()


# ------------------------------------------------------------------ writing logs


def _cs(body: str) -> str:
    return f"{reduce(lambda a, c: a ^ ord(c), body, 0):02X}"


def _line(body: str, source: str | None = None, c_s: float = 0.0, whole: bool = False) -> str:
    """``$BODY*hh``, under ``\\s:SOURCE,c:STAMP*hh\\`` where a source is given (the stamp
    in milliseconds, or in whole seconds cut down as a logger of whole seconds does)."""
    s = f"${body}*{_cs(body)}"
    if source is None:
        return s
    stamp = str(int(math.floor(c_s))) if whole else str(int(round(c_s * 1000)))
    tag = f"s:{source},c:{stamp}"
    return f"\\{tag}*{_cs(tag)}\\{s}"


def _hms(t_s: float) -> str:
    s = t_s % 86400
    return f"{int(s // 3600):02d}{int(s % 3600 // 60):02d}{s % 60:05.2f}"


def _dmy(t_s: float, days_early: int = 0) -> str:
    d = dt.datetime.fromtimestamp(t_s, dt.timezone.utc) - dt.timedelta(days=days_early)
    return d.strftime("%d%m%y")


def _latlon(lat: float, lon: float) -> str:
    la, lo = abs(lat), abs(lon)
    return (
        f"{int(la):02d}{(la - int(la)) * 60:09.6f},{'N' if lat >= 0 else 'S'},"
        f"{int(lo):03d}{(lo - int(lo)) * 60:09.6f},{'E' if lon >= 0 else 'W'}"
    )


def _track(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Heading (deg), latitude, longitude of a ship at 6 m/s weaving about 040."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=float)
    hdg = 40 + 20 * np.sin(t / 300.0 + seed)
    k = 180 / math.pi / 6371000
    lat = 57.0 + np.cumsum(6 * np.cos(np.radians(hdg))) * k
    lon = 11.0 + np.cumsum(6 * np.sin(np.radians(hdg))) * k / math.cos(math.radians(57))
    return (
        hdg + rng.normal(0, 0.1, n),
        lat + rng.normal(0, 2e-6, n),
        lon + rng.normal(0, 3e-6, n),
    )


def night(
    minutes: float = 5.0,
    leap_s: float = 0.0,
    latency_s: float | np.ndarray = 0.1,
    whole: bool = False,
    seed: int = 0,
    start_s: float = START_S,
    gyro: str | None = "GYRO",
    second_gnss: str | None = None,
    logger_s: float = 0.0,
) -> list[str]:
    """The lines of a GNSS (and a gyro, and a second GNSS writing UTC) at 1 Hz; the
    logger clock ``logger_s`` ahead of the truth."""
    n = int(minutes * 60)
    hdg, lat, lon = _track(n, seed)
    late = np.broadcast_to(np.asarray(latency_s, float), (n,))
    out = []
    for i in range(n):
        t = start_s + i
        recv, tof, where = t + late[i] + logger_s, t + leap_s, _latlon(lat[i], lon[i])
        if gyro:
            out.append(_line(f"HEHDT,{hdg[i] % 360:.1f},T", gyro, t + 0.05 + logger_s, whole))
        out.append(
            _line(f"GPGGA,{_hms(tof)},{where},1,10,0.9,12.0,M,40.0,M,,", "GNSS", recv, whole)
        )
        rmc = f"GPRMC,{_hms(tof)},A,{where},11.7,{hdg[i] % 360:.1f},{_dmy(tof)},,,A"
        out.append(_line(rmc, "GNSS", recv, whole))
        if second_gnss:
            gga = f"GNGGA,{_hms(t)},{where},1,10,0.9,12.0,M,40.0,M,,"
            out.append(_line(gga, second_gnss, t + 0.2 + logger_s, whole))
    return out


def restamped(lines: list[str], shift_s: float) -> list[str]:
    """The lines with their TAG ``c:`` moved by ``shift_s`` (the sentences unchanged)."""
    out = []
    for ln in lines:
        tag, rest = ln[1:].split("\\", 1)
        src = tag.split(",")[0][2:]
        c_ms = int(tag.split(",")[1].split("*")[0][2:])
        out.append(_line(rest[1 : rest.index("*")], src, c_ms / 1000 + shift_s))
    return out


def steps_from_lines(voyage: Voyage, path: Path, tol_ns: int = 1_000_000_000) -> list[ClockStep]:
    """The back-steps of each stream (one source's sentence type) in line order, as the
    ingest records them: the line after the step, the time before and after it; only
    records with a time of their own (a time of fix, a receive stamp: every record of a
    log of TAG blocks) are compared."""
    out, seen = [], set()
    stamped = path.read_bytes()[:1] == b"\\"
    for df in voyage.frames.values():
        if len(df) == 0:
            continue
        df = df if stamped else df[own_time(df)]
        for (src, sent), g in df.groupby(["source", "sentence"], observed=True):
            if (src, sent) in seen:
                continue
            seen.add((src, sent))
            g = g.sort_values("line", kind="stable")
            t, ln = g["time_ns"].to_numpy(np.int64), g["line"].to_numpy(np.int64)
            for j in np.flatnonzero(np.diff(t) < -tol_ns):
                out.append(ClockStep(str(path), int(ln[j + 1]), str(src), str(sent), int(t[j]), int(t[j + 1])))  # fmt: skip
    return sorted(out, key=lambda s: s.line)


def read(path: Path, lines: list[str] | None = None) -> Voyage:
    """``lines`` written to ``path`` and read back, its back-steps as the ingest records
    them (built from the frames where this ingest records none)."""
    if lines is not None:
        path.write_text("\n".join(lines) + "\n")
    v = read_logs([path], IngestConfig())
    if v.time_events.steps or not v.time_events.backsteps:
        return v
    return replace(v, time_events=replace(v.time_events, steps=steps_from_lines(v, path)))


def time_of(v: Voyage, cfg: IntegrityConfig | None = None) -> dict[tuple[str, str | None], object]:
    r = check_night(v, cfg or IntegrityConfig())
    assert r is not None
    return {(c.name, c.source): c for c in r.checks if c.check in ("time", "latency")}


def failed(checks: dict) -> set[tuple[str, str | None]]:
    return {k for k, c in checks.items() if c.status == "fail"}


# --------------------------------------------------------------------- leap second


@pytest.mark.parametrize("leap_s", range(1, 19))
def test_leap_offsets_found_and_named_by_their_seconds(tmp_path, leap_s):
    """A time of fix 1..18 s ahead of the truth, received 0-0.5 s after the truth (each
    record its own latency, and a steady 0.5 s): found, named by its whole seconds; the
    latency check (a time of fix behind the logger clock) does not fail for it too."""
    rng = np.random.default_rng(leap_s)
    for latency in (rng.uniform(0.0, 0.5, 300), 0.5, 0.0):
        c = time_of(read(tmp_path / "leap.nmea", night(leap_s=leap_s, latency_s=latency)))
        assert failed(c) == {("leap_second", "GNSS")}, (leap_s, latency, failed(c))
        leap = c[("leap_second", "GNSS")]
        assert leap.evidence[0]["whole_s"] == leap_s, leap.evidence
        assert f"{leap_s} whole second(s)" in leap.message, leap.message
        assert "ahead of the logger clock" in leap.message
        if leap_s == 18:
            assert "GPS time written without the 18 s UTC offset" in leap.message
        assert c[("latency", "GNSS")].status == "pass"


@pytest.mark.parametrize("latency_s", [0.0, 0.3, 0.7, 0.99])
def test_whole_second_stamps_are_no_clock_offset(tmp_path, latency_s):
    """A logger of whole seconds cuts the receipt of a 12:00:00.0 fix at 12:00:00.3 to
    12:00:00: receive minus time of fix is 0.0 exactly, never a finding; a real lead of
    1 or 18 s behind the same stamps is."""
    healthy = time_of(read(tmp_path / "w.nmea", night(latency_s=latency_s, whole=True)))
    assert failed(healthy) == set(), {k: healthy[k].message for k in failed(healthy)}
    assert healthy[("leap_second", "GNSS")].threshold["value"] == 1.0  # the stamps' second
    for k in (1, 18):
        c = time_of(read(tmp_path / "w.nmea", night(leap_s=k, latency_s=latency_s, whole=True)))
        assert failed(c) == {("leap_second", "GNSS")}, (k, failed(c))
        assert c[("leap_second", "GNSS")].evidence[0]["whole_s"] == k


def test_whole_seconds_allow_for_latency():
    assert [whole_seconds(x) for x in (0.5, 0.75, 1.0, 1.02, 17.5, 17.9, 18.0, 18.3)] == [
        1,
        1,
        1,
        1,
        18,
        18,
        18,
        18,
    ]


def test_two_receivers_a_whole_number_of_seconds_apart(tmp_path):
    """The logger's clock keeps GPS time (taken from a receiver writing it): that receiver
    is on time, the one writing UTC 18 s behind -- latency says so; the time check names
    the cause, the two 18 whole seconds apart at the same receive times."""
    lines = night(minutes=5, leap_s=18, second_gnss="GNSS2", logger_s=18.0)
    c = time_of(read(tmp_path / "two.nmea", lines))
    assert failed(c) == {("leap_second", "GNSS"), ("latency", "GNSS2")}, failed(c)
    leap = c[("leap_second", "GNSS")]
    assert "ahead of GNSS2's at the same receive times" in leap.message, leap.message
    assert leap.evidence[0]["whole_s"] == 18 and leap.evidence[0]["against"] == "GNSS2"
    healthy = time_of(read(tmp_path / "two.nmea", night(minutes=5, second_gnss="GNSS2")))
    assert failed(healthy) == set()


# -------------------------------------------------------------------- week rollover


def test_week_rollover_found_and_said_repaired(tmp_path):
    """A receiver whose week number rolled over sends dates 1024 weeks early (a 2019 fix
    dated 1999): the ingest repairs them; the time check says so, where and how many."""
    start = dt.datetime(2019, 6, 1, 10, tzinfo=dt.timezone.utc).timestamp()
    hdg, lat, lon = _track(120, 3)
    lines = []
    for i in range(120):
        t = start + i
        where = _latlon(lat[i], lon[i])
        lines.append(_line(f"GPGGA,{_hms(t)},{where},1,10,0.9,12.0,M,40.0,M,,"))
        date = _dmy(t, days_early=1024 * 7)
        lines.append(_line(f"GPRMC,{_hms(t)},A,{where},11.7,{hdg[i] % 360:.1f},{date},,,A"))
    v = read(tmp_path / "rollover.nmea", lines)
    assert v.time_events.implausible_dates == 120
    c = time_of(v)
    assert failed(c) == {("week_rollover", None)}, failed(c)
    roll = c[("week_rollover", None)]
    assert roll.evidence[0]["file"] == "rollover.nmea" and roll.evidence[0]["records"] == 120
    assert roll.evidence[0]["senders"] == ["GP"]
    assert (
        "found and repaired" in roll.message and "rollover.nmea (120, sent by GP)" in roll.message
    )
    assert roll.statistic["value"] == 120
    # repaired: the fixes are on their real day
    t0 = int(v.frames["position"]["time_ns"].min())
    assert dt.datetime.fromtimestamp(t0 / 1e9, dt.timezone.utc).date() == dt.date(2019, 6, 1)


# -------------------------------------------------------------- back-steps and loops


def test_a_looped_logger_is_a_loop(tmp_path):
    """A logger replaying a 22 min recording, its stamps with it, four times over: three
    steps back of 22 min, each one event of every source, called a loop."""
    v = read(tmp_path / "loop.nmea", night(minutes=22) * 4)
    c = time_of(v)
    assert failed(c) == {("loop", None)}, failed(c)
    loop = c[("loop", None)]
    assert loop.detail["events"] == 3 and len(loop.evidence) == 3
    for e in loop.evidence:
        assert e["kind"] == "loop" and e["sources"] == ["GNSS", "GYRO"]
        assert abs(e["back_s"] - 22 * 60) < 2 and e["equal_values"] == e["repeated_records"] > 0
        assert e["file"] == "loop.nmea" and e["line"] > 0
    assert "replayed a recording (a loop)" in loop.message and "22.0 min" in loop.message
    assert c[("backstep", None)].status == "pass"


def test_a_recording_replayed_under_live_stamps_is_a_loop(tmp_path):
    """The sentences of a recording played again while the logger stamps them live: the
    GNSS's times of fix go back and repeat their values."""
    first = night(minutes=15, seed=3)
    c = time_of(read(tmp_path / "replay.nmea", first + restamped(first, 900.0)))
    loop = c[("loop", None)]
    assert loop.status == "fail" and loop.evidence[0]["sources"] == ["GNSS"], loop.message
    assert c[("backstep", None)].status == "pass"


def test_a_clock_set_back_is_a_backstep(tmp_path):
    """The logger clock set back 10 min at minute 12: the stamps of the gyro go back with
    fresh headings at times already recorded; the GNSS's times of fix go on, ahead of the
    stamps from then on -- that lead is the back-step, not a second finding."""
    a = night(minutes=12, seed=1)
    b = restamped(night(minutes=10, seed=2, start_s=START_S + 720), -600.0)
    c = time_of(read(tmp_path / "setback.nmea", a + b))
    assert failed(c) == {("backstep", None)}, failed(c)
    back = c[("backstep", None)]
    e = back.evidence[0]
    assert e["kind"] == "backstep" and e["sources"] == ["GYRO"]
    assert 595 <= e["back_s"] <= 601 and e["equal_values"] < 0.1 * e["repeated_records"]
    assert "clock was set back" in back.message and "10.0 min" in back.message
    assert c[("loop", None)].status == "pass"
    leap = c[("leap_second", "GNSS")]
    assert leap.status == "pass" and leap.detail["explained_spells"] == 1
    assert leap.evidence[0]["explained_by"] == "time/backstep"


def test_steps_within_the_tolerance_and_out_of_order_records_are_no_finding(tmp_path):
    """Interleaved sentences a second apart, and one record out of order (the stream goes
    on where it was), are not clock steps."""
    lines = night(minutes=5)
    # the GGA of second 100 written after second 103's lines: one late record
    i = next(k for k, ln in enumerate(lines) if "GPGGA," + _hms(START_S + 100) in ln)
    moved = lines[:i] + lines[i + 1 : i + 10] + [lines[i]] + lines[i + 10 :]
    v = read(tmp_path / "order.nmea", moved)
    c = time_of(v)
    assert failed(c) == set()
    assert c[("backstep", None)].detail["displaced_records"] >= 1
    assert "out-of-order record" in c[("backstep", None)].message
    # a step back of exactly the tolerance (1 s) given by hand: no finding
    v2 = read(tmp_path / "plain.nmea", night(minutes=5))
    t = int(v2.frames["heading"]["time_ns"].iloc[50])
    one = ClockStep("plain.nmea", 200, "GYRO", "HDT", t, t - 1_000_000_000)
    v2 = replace(v2, time_events=replace(v2.time_events, steps=[one]))
    assert failed(time_of(v2)) == set()


def test_a_real_recording_looped_four_times_is_one_loop_finding(tmp_path):
    """The reviewer's case: a 22 min yacht recording (VDRplayer's Hakefjord, bare NMEA
    from three position sources) played four times: three back-steps of 21.9 min, each
    one event of every stepping source, every record after a step equal to the one before
    it at that time."""
    log = tmp_path / "hakefjord-x4.txt"
    log.write_bytes(real_path("VDRplayer", "Hakefjord.txt").read_bytes() * 4)
    c = time_of(read(log))
    assert failed(c) == {("loop", None)}, failed(c)
    ev = c[("loop", None)].evidence
    assert len(ev) == 3 and [e["line"] for e in ev] == [25722, 51443, 77164]
    for e in ev:
        assert e["sources"] == ["GP/3dp", "GP/5dp", "II"] and abs(e["back_s"] - 1316) < 2
        assert e["equal_values"] == e["repeated_records"] > 4000
    once = time_of(read(real_path("VDRplayer", "Hakefjord.txt")))
    assert failed(once) == set()


def _frames_voyage(replayed: bool) -> Voyage:
    """Frames built by hand: a heading source at 1 Hz for 10 min whose stream then steps
    back 5 min, the records after the step repeating (``replayed``) those recorded at
    those times before, or fresh."""
    rng = np.random.default_rng(9)
    t = int(START_S * 1e9) + np.arange(600, dtype=np.int64) * 1_000_000_000
    h = rng.uniform(0, 2 * np.pi, 600)
    after = h[300:] if replayed else rng.uniform(0, 2 * np.pi, 300)
    times, vals = np.concatenate([t, t[300:]]), np.concatenate([h, after])
    head = make_frame(
        "heading",
        {
            "time_ns": times,
            "source": np.full(900, "GYRO", dtype=object),
            "sentence": np.full(900, "HDT", dtype=object),
            "line": np.arange(1, 901, dtype=np.int64),
            "heading_rad": vals,
        },
    )
    order = np.argsort(times, kind="stable")  # frames are in time order
    frames = {k: empty_frame(k) for k in ("position", "ground", "water", "distance", "rot")}
    frames["heading"] = head.iloc[order].reset_index(drop=True)
    step = ClockStep("bench.log", 601, "GYRO", "HDT", int(t[-1]), int(t[300]))
    te = TimeEvents(backsteps=1, steps=[step])
    return Voyage(frames, {"GYRO": SourceInfo("GYRO", ["compass"])}, Rejects(), te, [])


@pytest.mark.parametrize("replayed", [True, False])
def test_clock_steps_judged_on_frames_built_by_hand(replayed):
    c = time_of(_frames_voyage(replayed))
    name = "loop" if replayed else "backstep"
    assert failed(c) == {(name, None)}, failed(c)
    e = c[(name, None)].evidence[0]
    assert e["sources"] == ["GYRO"] and e["line"] == 601 and e["repeated_records"] > 250


# ----------------------------------------------------------------------- clock drift


@pytest.mark.parametrize(
    "ppm,fails", [(0.0, False), (50.0, False), (200.0, True), (-200.0, True), (-50.0, False)]
)
def test_clock_drift_found_when_significant_and_large(tmp_path, ppm, fails):
    """The logger clock gaining (losing) on the receiver's time of fix by ``ppm`` over 2 h,
    with 0.3-0.5 s latency: 200 ppm moves the offset 1.44 s (> 1 s), a finding; 50 ppm
    0.36 s, none.  A drift that takes the time of fix ahead of the logger clock is the
    drift's finding, not a leap second's."""
    rng = np.random.default_rng(int(abs(ppm)) + 1)
    t = np.arange(7200)
    late = 0.3 + rng.uniform(0, 0.2, t.size) + ppm * 1e-6 * t
    c = time_of(read(tmp_path / "drift.nmea", night(minutes=120, latency_s=late, gyro=None)))
    drift = c[("clock_drift", "GNSS")]
    assert (drift.status == "fail") == fails, drift.message
    assert drift.detail["drift_ppm"] == pytest.approx(ppm, abs=5), drift.detail
    assert c[("leap_second", "GNSS")].status == "pass"
    assert drift.false_alarm == IntegrityConfig().false_alarm
    if fails:
        assert "ppm: the offset changed 1.4" in drift.message, drift.message
        gains = "gains on" if ppm > 0 else "loses on"
        assert f"the logger clock {gains} the receiver's time of fix" in drift.message


def test_drift_fit_passes_over_a_step_of_the_offset():
    """A clock set back (a step of the offset) is no drift."""
    t = (np.arange(3600) * 1e9).astype(np.int64)
    d = np.where(np.arange(3600) < 1800, 0.2, -599.8) + np.random.default_rng(1).normal(
        0, 0.01, 3600
    )
    slope, sigma, _ = drift_fit(t, d)
    assert abs(slope) < 5e-6 and sigma < 5e-6


# ------------------------------------------------------------------------- no clock


def test_a_clockless_log_is_named_and_gets_no_time_finding():
    """A candump without times (canboat's candumpSample2): one ``no_clock`` entry per
    source, ``not checked`` with why, and no other time check."""
    dump = read_logs([REPO / "tests" / "data" / "n2k" / "candumpSample2.txt"], IngestConfig())
    assert dump.clockless
    r = check_night(dump, IntegrityConfig())
    assert r is not None
    times = [c for c in r.checks if c.check == "time"]
    present = {str(k) for df in dump.frames.values() if len(df) for k in df["source"].unique()}
    assert {c.source for c in times} == present == set(dump.clockless) & present
    for c in times:
        assert c.name == "no_clock" and c.status == "not_checked", c
        assert "no clock" in c.why_not and c.source in c.message


# ------------------------------------------------- the simulator's time faults


@pytest.mark.parametrize(
    "fault,fmt,found",
    [
        ("leap:GNSS@20min+30min=18s", "nmea", {("leap_second", "GNSS")}),
        ("leap:GNSS@20min+30min=2s", "mcap-json", {("leap_second", "GNSS")}),
        ("loop:ALL@50min=22min", "nmea", {("loop", None)}),
        ("clockstep:ALL@20min+20min=-10min", "nmea", {("backstep", None)}),
        ("rollover:GNSS@30min", "mcap-json", {("week_rollover", None)}),
    ],
)
def test_the_simulators_time_faults_are_found(tmp_path, fault, fmt, found):
    """``dracc simulate``'s own writers (independent of the lines written here): each
    time fault is its one time finding; a lead that ends steps the receiver's time back
    (that lead, not a clock set back); a rollover's step back is the rollover's."""
    import subprocess
    import sys

    cmd = [sys.executable, "-m", "dracc", "simulate", "--out", str(tmp_path), "--hours", "1.2"]
    subprocess.run([*cmd, "--seed", "5", "--format", fmt, "--fault", fault], check=True)
    v = read(next(tmp_path.glob("voyage.*")))
    c = time_of(v)
    assert {k for k in failed(c) if c[k].check == "time"} == found, failed(c)
    if "leap" in fault:
        leap = c[("leap_second", "GNSS")]
        assert leap.evidence[0]["whole_s"] == int(fault.split("=")[1][:-1]), leap.evidence
    if "rollover" in fault:  # the MCAP stamps repaired by the ingest: latency as it is
        assert c[("latency", "GNSS")].status == "pass"
        assert c[("week_rollover", None)].detail["repaired"] > 0


# ------------------------------------------------------- what the reports carry


def test_audit_and_analysis_carry_the_time_checks(tmp_path, run_cli):
    """``dracc analyze --json`` lists the time checks with the others; ``dracc audit``
    makes the failed one a finding (exit 1) in its summary, JSON and page."""
    import json

    log = tmp_path / "2026-05-28" / "loop.nmea"
    log.parent.mkdir()
    log.write_text("\n".join(night(minutes=22) * 2) + "\n")
    if not read_logs([log], IngestConfig()).time_events.steps:
        pytest.skip("the ingest records no back-steps yet")
    code, out, _ = run_cli("analyze", log, "--json", "-")
    assert code == 0
    checks = json.loads(out)["integrity"]["checks"]
    names = {(c["check"], c["name"], c["status"]) for c in checks if c["check"] == "time"}
    assert ("time", "loop", "fail") in names and ("time", "backstep", "pass") in names
    html = tmp_path / "audit.html"
    doc = tmp_path / "audit.json"
    summary = tmp_path / "summary.txt"
    code, out, _ = run_cli(
        "audit", log, "--db", tmp_path / "a.sqlite", "--summary", summary, "--json", doc,
        "--html", html,
    )  # fmt: skip
    assert code == 1, out
    lines = [ln for ln in summary.read_text().splitlines() if ln.startswith("  - [time]")]
    assert len(lines) == 1 and "replayed a recording (a loop)" in lines[0], lines
    found = [f for f in json.loads(doc.read_text())["findings"] if f["check"] == "time"]
    assert [f["kind"] for f in found] == ["loop"], found
    assert "replayed a recording" in html.read_text()
    assert "<th>time</th>" in html.read_text()


def test_watch_raises_the_loop_from_its_window(tmp_path):
    """``dracc watch`` analyses its window with the same checks: a logger looping while it
    is watched raises one ``time/loop`` finding (its first analysis after the step sees
    only the start of the replay: still a loop, not a few records out of order)."""
    from test_watch_analysis import _replay

    log = tmp_path / "live.nmea"
    log.write_text("\n".join(night(minutes=22) * 3) + "\n")
    if not read_logs([log], IngestConfig()).time_events.steps:
        pytest.skip("the ingest records no back-steps yet")
    _, events, analyser = _replay(log, window_s=3600.0, per=2000)
    assert analyser.runs >= 5 and analyser.error is None
    raised = [e for e in events if e["event"] == "raised"]
    assert [(e["check"], e["name"], e["source"]) for e in raised] == [("time", "loop", None)]
    assert "replayed a recording" in raised[0]["message"]


# ---------------------------------------------------------------------- real logs

#: the real logs with a time finding, and what it is (everything else: none)
REAL_FINDINGS = {
    # simulated own ship in a real AIS capture: GPRMC dated 1994 (1024 weeks early)
    "OpenCPN/stupan.se-10112-tcp.log": {("week_rollover", None)},
    "OpenCPN/stupan.se-10112-tcp.log.input": {("week_rollover", None)},
    # canboat/ikonvert.log: the iKonvert's timer runs ~3900 ppm fast against the GNSS's
    # PGN 129029 times of fix (-0.55 s to +0.44 s in 315 s); the N2K reader now rescales
    # a relative timer against its anchors, so nothing drifts and nothing is found
}


def _logs() -> list[Path]:
    real = [
        p
        for p in sorted(REAL.rglob("*"))
        if p.is_file() and not p.name.endswith((".chk", ".md", ".json"))
    ]
    samples = [
        p
        for p in sorted(SAMPLES.rglob("*"))
        if p.suffix in (".nmea", ".mcap", ".csv") and p.name not in ("truth.csv", "errors.csv")
    ]
    return real + samples


def test_real_logs_and_samples_have_no_time_finding_but_the_named(real_dir):
    """Every real log and sample log: the time checks pass (or could not be made), but
    for the named logs and what they truly carry."""
    from dracc.core.errors import DraccError

    seen = {}
    for p in _logs():
        try:
            v = read_logs([p], IngestConfig())
        except DraccError:
            continue
        r = check_night(v, IntegrityConfig())
        if r is None:
            continue
        name = str(p.relative_to(REAL)) if p.is_relative_to(REAL) else p.name
        got = {(c.name, c.source) for c in r.checks if c.check == "time" and c.status == "fail"}
        seen[name] = got
        assert got == REAL_FINDINGS.get(name, set()), (name, [c.message for c in r.failed])
    assert set(REAL_FINDINGS) <= set(seen)
    ikonvert = read_logs([real_path("canboat", "ikonvert.log")], IngestConfig())
    assert any("ppm fast" in d for d in ikonvert.time_events.decisions)
    c = next(c for c in check_night(ikonvert, IntegrityConfig()).checks if c.name == "clock_drift")
    assert c.status == "pass" and abs(c.detail["drift_ppm"]) < 1000, c.detail
