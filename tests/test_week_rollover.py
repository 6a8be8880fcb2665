"""A GNSS week-number rollover found wherever it hides (issue 30): a receiver dating its
fixes 1024 weeks (7168 days) early.

* NMEA under a TAG ``c:`` or a logger prefix: the time base places a time of fix on the
  day of the external time (rule 1); an RMC/ZDA date 1024·k weeks behind it is a
  rollover whatever its year (a 2026 voyage dated 2006), counted and noted, the times
  kept.
* MCAP: a message stamp 1024·k weeks behind its log time is repaired (+1024·k weeks),
  counted and noted with the first message.
* A bare log dated 2006 all through is used as it reads (nothing tells it from a real
  2006 log).

Each simulated voyage (``dracc.sim``'s ``rollover`` fault, the default 2026 start) gives
exactly one ``time/week_rollover`` finding through :func:`dracc.pipeline.analysis.analyse`
and no drop-out; a healthy one none; the real logs none but the one that has it.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from conftest import REAL

from dracc.core.config import Config, IngestConfig
from dracc.core.timefmt import iso_utc
from dracc.frames import MISSING_NS
from dracc.ingest import read_logs
from dracc.ingest.timebase import (
    DAY_NS,
    GPS_WEEK_ROLLOVER_DAYS,
    WEEK_ROLLOVER_NS,
    TimeBase,
    rollover_weeks,
)
from dracc.pipeline.analysis import analyse
from dracc.sim import SimFault, SimParams, simulate
from dracc.sim.nmea_out import write_nmea
from dracc.sim.output import write_log
from dracc.sim.truth import start_ns

S = 1_000_000_000
T0 = start_ns("2026-03-01T00:00:00Z")
START_S = 300.0  #: the rollover's start
PARAMS = {"duration_s": 1200.0, "seed": 3, "latency_s": (("GNSS", 0.3),)}


def voyage(rollover: bool = True):
    faults = (SimFault("rollover", start_s=START_S),) if rollover else ()
    return simulate(SimParams(**PARAMS, faults=faults))


def write(v, path: Path) -> Path:
    form = path.suffix.lstrip(".")
    if form in ("tag", "prefix", "bare"):
        write_nmea(v, path, form=form, tag_time="ms")
    else:
        write_log(v, path, "mcap-json")
    return path


def failed(a) -> list[tuple[str, str, str | None]]:
    """The failed time and availability checks of an analysis, each as often as it failed."""
    assert a.integrity is not None
    return sorted(
        (c.check, c.name, c.source)
        for c in a.integrity.checks
        if c.status == "fail" and c.check in ("time", "availability")
    )


def gnss(frames, name: str = "GNSS"):
    df = frames["position"]
    return df[(df["source"].astype(str) == name).to_numpy(bool)]


# ------------------------------------------------------------------ the time base alone


def test_rollover_weeks_within_a_day():
    w, d = WEEK_ROLLOVER_NS, DAY_NS
    behind = np.array([0, w, w - d, w + d, w + d + 1, 2 * w + 5 * S, 3 * w, -w, w // 2, 12 * S])
    np.testing.assert_array_equal(rollover_weeks(behind), [0, 1, 1, 1, 0, 2, 0, 0, 0, 0])


def test_time_base_counts_dates_behind_their_receive_times():
    """RMC/ZDA dates 1024 and 2048 weeks behind their receive times are rollovers (a fix
    at 23:59:59.8 received at 00:00:00.5 too); other dates, a date a few days off, or a
    date with no receive time beside it are not; the times keep the receive times' day."""
    day = int(T0 // DAY_NS)  # 2026-03-01
    tod = np.array([10.0, 20.0, 86_399.8, 30.0, 40.0, 50.0, 60.0]) * S
    tod = np.rint(tod).astype(np.int64)
    w = GPS_WEEK_ROLLOVER_DAYS
    date = np.array([day, day - w, day - 1 - w, day - 2 * w, day - 3, day - w, -1])
    ext = day * DAY_NS + tod + S // 2
    ext[2] = day * DAY_NS + S // 2  # the fix of 23:59:59.8 received just after midnight
    ext[5] = MISSING_NS  # no receive time: the date (2006) used as it reads
    tb = TimeBase()
    (t,) = tb.feed(tod, date.astype(np.int64), ext)
    assert tb.week_rollovers == 3 and tb.implausible == 0
    assert t[2] == (day - 1) * DAY_NS + tod[2]  # placed on the day before the receive time
    assert t[1] == day * DAY_NS + 20 * S and t[3] == day * DAY_NS + 30 * S
    assert t[4] == day * DAY_NS + 40 * S  # three days off: no rollover (nor any repair)
    note = [d for d in tb.decisions if d.startswith("GPS week rollover:")]
    assert note == [
        "GPS week rollover: RMC/ZDA dates 1024 weeks behind their receive times, the first "
        f"received {iso_utc(int(ext[1]))}: the day taken from the receive times"
    ]


def test_a_bare_log_of_2006_dates_is_used_as_it_reads(tmp_path):
    """Without an external time a 2006 date is a date of 2006: nothing tells a rollover
    from a real log of that year (the time base does not guess)."""
    v = simulate(SimParams(**{**PARAMS, "duration_s": 120.0}, start_utc="2006-07-16T00:00:00Z"))
    got = read_logs([write(v, tmp_path / "v.bare")], IngestConfig())
    assert got.time_events.implausible_dates == 0
    assert not any("rollover" in d for d in got.time_events.decisions)
    t = gnss(got.frames, "GP")["time_ns"].to_numpy()
    assert iso_utc(int(t.min())).startswith("2006-07-16")


# ------------------------------------------------------------- the simulated voyages


@pytest.mark.parametrize("form", ["tag", "prefix", "mcap"])
def test_a_rollover_is_repaired_counted_and_found_once(tmp_path, form):
    """The ``rollover`` fault of a 2026 voyage (dates of 2006 from 300 s on) written as
    NMEA under TAG ``c:``, NMEA with a logger prefix and MCAP (JSON): the ingest counts
    (and in MCAP repairs) it, names the file and the first record; the analysis raises
    one ``time/week_rollover`` and no drop-out; the GNSS's times are those of the healthy
    voyage."""
    if form == "mcap":
        pytest.importorskip("mcap")
    v, ok = voyage(), voyage(rollover=False)
    p = write(v, tmp_path / f"voyage.{form}")
    got = read_logs([p], IngestConfig())
    healthy = read_logs([write(ok, tmp_path / f"healthy.{form}")], IngestConfig())
    key = "GP" if form == "prefix" else "GNSS"
    g, h = gnss(got.frames, key), gnss(healthy.frames, key)
    np.testing.assert_array_equal(g["time_ns"].to_numpy(), h["time_ns"].to_numpy())
    np.testing.assert_array_equal(g["recv_ns"].to_numpy(), h["recv_ns"].to_numpy())
    late = (g["recv_ns"] - g["time_ns"]).to_numpy()
    assert (late == 300_000_000).all()  # the GNSS's latency, nothing 1024 weeks
    te = got.time_events
    rolled = [d for d in te.decisions if re.match(rf"{p.name}: \d+ dates corrected", d)]
    assert len(rolled) == 1, te.decisions
    n = int(rolled[0].split(": ")[1].split()[0])
    assert te.implausible_dates == n and healthy.time_events.implausible_dates == 0
    first_recv = T0 + int(START_S * S) + 300_000_000  # the first fix of the rollover
    if form == "mcap":
        # every GNSS record (position, ground, ...) from 300 s on, stamped 1024 weeks early
        after = sum(
            int(((df["source"].astype(str) == "GNSS") & (df["time_ns"] >= T0 + 300 * S)).sum())
            for df in got.frames.values()
        )
        assert n == after > 0
        first = re.search(
            r"message stamps 1024 weeks behind their log times, the first at message (\d+) "
            r"\(GNSS, stamped (\S+), logged (\S+)\)",
            rolled[0],
        )
        assert first is not None, rolled[0]
        assert first.group(2) == iso_utc(first_recv - 300_000_000 - GPS_WEEK_ROLLOVER_DAYS * DAY_NS)
        assert first.group(3) == iso_utc(first_recv)
        from mcap.reader import make_reader

        with p.open("rb") as f:  # message numbers count the file's messages, from 1
            msgs = enumerate(make_reader(f).iter_messages(log_time_order=False), 1)
            _, ch, m = next(x for i, x in msgs if i == int(first.group(1)))
        assert ch.topic.startswith("/GNSS/") and m.log_time == first_recv
    else:
        text = p.read_bytes().split(b"\r\n")
        early = [i for i, ln in enumerate(text, 1) if re.search(rb",(16,07,2006|160706),", ln)]
        assert n == len(early) > 0  # every RMC and ZDA of 2006, once
        note = f"{p.name}: GPS week rollover: RMC/ZDA dates 1024 weeks behind their receive times"
        said = [d for d in te.decisions if d.startswith(note)]
        assert said == [
            f"{note}, the first received {iso_utc(first_recv)}: the day taken from the receive times"
        ]
        stamp = (
            rb"c:%d" % (first_recv // 1_000_000)
            if form == "tag"
            else iso_utc(first_recv)[11:19].encode()
        )
        assert stamp in text[early[0] - 1]
    # the analysis: one time/week_rollover finding, no drop-out; none for the healthy log
    a = analyse([p], Config())
    assert failed(a) == [("time", "week_rollover", None)]
    c = next(c for c in a.integrity.checks if c.name == "week_rollover")
    assert c.statistic["value"] == n and c.detail == {"repaired": n, "unrepaired_sources": 0}
    assert c.evidence[0]["file"] == p.name and c.evidence[0]["senders"] == [key]
    assert f"in {p.name} ({n}, sent by {key})" in c.message
    if form != "mcap":
        assert c.evidence[0]["first"].endswith(
            f"the first received {iso_utc(first_recv)}: the day taken from the receive times"
        )
    b = analyse([tmp_path / f"healthy.{form}"], Config())
    assert failed(b) == []
    c = next(c for c in b.integrity.checks if c.name == "week_rollover")
    assert c.status == "pass" and c.message == "no date 1024 weeks early"


# ------------------------------------------------------------------------ real logs


def test_real_logs_gain_no_rollover(real_dir):
    """Of the real logs only stupan.se's AIS capture (36 RMC dates of 1994, no external
    time: repaired before 2000 as before) has a rollover; no other log gains a count, a
    note or a ``time/week_rollover`` finding."""
    from dracc.core.errors import DraccError
    from dracc.math.integrity import check_night

    want = {"OpenCPN/stupan.se-10112-tcp.log", "OpenCPN/stupan.se-10112-tcp.log.input"}
    seen: dict[str, int] = {}
    for p in sorted(REAL.rglob("*")):
        if not p.is_file() or p.name.endswith((".chk", ".md", ".json")):
            continue
        try:
            v = read_logs([p], IngestConfig())
        except DraccError:
            continue
        name = str(p.relative_to(REAL))
        notes = [d for d in v.time_events.decisions if "week rollover" in d]
        r = check_night(v)
        roll = [c for c in (r.checks if r else []) if c.name == "week_rollover"]
        if name in want:
            assert v.time_events.implausible_dates == 36, name
            assert notes == [
                f"{p.name}: 36 dates corrected for the GPS week rollover (+1024 weeks)"
            ]
            assert [c.status for c in roll] == ["fail"], name
        else:
            assert not notes and all(c.status != "fail" for c in roll), (name, notes)
        seen[name] = v.time_events.implausible_dates
    assert want <= set(seen) and len(seen) > 40
