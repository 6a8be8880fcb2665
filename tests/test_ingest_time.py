"""Time base: civil dates, nearest-day anchoring, midnight rollovers, dates back-filled,
no date at all, GPS week rollover, duplicates, back-steps and gaps."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest
from conftest import real_path
from hypothesis import given
from hypothesis import strategies as st

from dracc.core.config import IngestConfig
from dracc.ingest.nmea import read_nmea
from dracc.ingest.timebase import (
    ASSUMED_DATE,
    ASSUMED_DATE_NOTE,
    EventCounter,
    days_from_civil,
    fix_dates,
    nearest_day,
    valid_civil,
)


def nmea(body: str) -> str:
    x = 0
    for b in body.encode():
        x ^= b
    return f"${body}*{x:02X}"


def ns(iso: str) -> int:
    t = dt.datetime.fromisoformat(iso.replace("Z", "+00:00"))
    return int(t.timestamp()) * 10**9 + t.microsecond * 1000


@given(st.dates(min_value=dt.date(1600, 1, 1), max_value=dt.date(2400, 12, 31)))
def test_days_from_civil_matches_datetime(d):
    assert days_from_civil(d.year, d.month, d.day) == (d - dt.date(1970, 1, 1)).days
    assert valid_civil(d.year, d.month, d.day)


def test_valid_civil_rejects_impossible_dates():
    assert (
        not valid_civil(2023, 2, 29) and valid_civil(2024, 2, 29) and not valid_civil(1900, 2, 29)
    )
    assert (
        not valid_civil(2023, 13, 1)
        and not valid_civil(2023, 4, 31)
        and not valid_civil(2023, 1, 0)
    )


def test_nearest_day_both_ways():
    ref = np.array(
        [ns("2023-11-15T00:00:00.500Z"), ns("2023-11-14T23:59:59.000Z"), ns("2023-11-14T12:00:00Z")]
    )
    tod = np.array([86399_800_000_000, 1_000_000_000, 43_200_000_000_000])
    got = nearest_day(tod, ref)
    assert list(got) == [
        ns("2023-11-14T23:59:59.800Z"),
        ns("2023-11-15T00:00:01Z"),
        ns("2023-11-14T12:00:00Z"),
    ]


def test_gps_week_rollover_corrected_and_counted():
    good = days_from_civil(2019, 4, 7)
    rolled = good - 1024 * 7  # 1999-08-22: what a pre-2019 receiver reports after the rollover
    far = days_from_civil(1980, 1, 6)
    fixed, n_fix, n_bad = fix_dates(
        np.array([good, rolled, far, -1]), latest_days=days_from_civil(2026, 1, 1)
    )
    assert list(fixed) == [good, good, -1, -1] and n_fix == 1 and n_bad == 1


def _write(tmp_path, lines, name="t.nmea"):
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def gga(hhmmss: str) -> str:
    return nmea(f"GPGGA,{hhmmss},5436.0,N,01847.0,E,1,08,1.0,5.0,M,,M,,")


def test_midnight_without_date_on_the_assumed_date_or_the_date_option(tmp_path):
    p = _write(tmp_path, [gga("235958"), gga("235959"), gga("000000"), gga("000001")])
    r = read_nmea(p, IngestConfig())
    # no date anywhere: read on the assumed date, with a plain warning, nothing rejected
    assert r.rejects.total == 0 and len(r.frames["position"]) == 4
    assert r.frames["position"]["time_ns"].tolist() == [
        ns(f"{ASSUMED_DATE}T23:59:58Z"),
        ns(f"{ASSUMED_DATE}T23:59:59Z"),
        ns("2000-01-02T00:00:00Z"),
        ns("2000-01-02T00:00:01Z"),
    ]
    assert ASSUMED_DATE_NOTE in r.time_events.decisions and "--date" in ASSUMED_DATE_NOTE
    r = read_nmea(p, IngestConfig(date="2019-03-09"))
    t = r.frames["position"]["time_ns"].tolist()
    assert t == [
        ns("2019-03-09T23:59:58Z"),
        ns("2019-03-09T23:59:59Z"),
        ns("2019-03-10T00:00:00Z"),
        ns("2019-03-10T00:00:01Z"),
    ]
    assert r.time_events.rollovers == 1
    assert ASSUMED_DATE_NOTE not in r.time_events.decisions


@pytest.mark.parametrize(
    ("parts", "records"),
    [
        (("gpsd", "sounder.log"), 122),
        (("gpsbabel", "adddate.nmea"), 500),
        (("signalk-server", "plaka.log"), 43500),
    ],
)
def test_real_dateless_logs_read_on_the_assumed_date(parts, records):
    """The dateless logs of issue 17: each read whole without --date, on the assumed
    date, and told so; the durations are the log's own."""
    r = read_nmea(real_path(*parts), IngestConfig())
    assert r.rejects.counts.get("no_date", 0) == 0
    assert ASSUMED_DATE_NOTE in r.time_events.decisions
    t = np.concatenate([f["time_ns"].to_numpy() for f in r.frames.values() if len(f)])
    day0 = ns(f"{ASSUMED_DATE}T00:00:00Z")
    assert day0 <= t.min() and t.max() < day0 + 2 * 86_400 * 10**9
    assert r.records >= records
    dated = read_nmea(real_path(*parts), IngestConfig(date="2021-06-01"))
    td = np.concatenate([f["time_ns"].to_numpy() for f in dated.frames.values() if len(f)])
    assert len(td) == len(t) and np.array_equal(
        np.sort(td) - np.sort(t), np.full(len(t), td.min() - t.min())
    )


def test_date_back_filled_from_trailing_zda(tmp_path):
    p = _write(tmp_path, [gga("235959"), gga("000000"), nmea("GPZDA,000001,10,03,2019,00,00")])
    r = read_nmea(p, IngestConfig(date="2000-01-01"))  # the log's own date wins over --date
    assert r.frames["position"]["time_ns"].tolist() == [
        ns("2019-03-09T23:59:59Z"),
        ns("2019-03-10T00:00:00Z"),
    ]
    assert any("back-filled" in d for d in r.time_events.decisions)


def test_real_backfilldate(real_dir):
    r = read_nmea(real_dir / "gpsbabel" / "backfilldate.nmea", IngestConfig())
    t = r.frames["position"]["time_ns"]
    # the only date is in the trailing ZDA (00:04:19 on 2019-03-09): the track began the day before
    assert (
        len(t) == 500
        and t.iloc[0] == ns("2019-03-08T23:56:00Z")
        and t.iloc[-1] == ns("2019-03-09T00:04:19Z")
    )
    assert r.time_events.rollovers == 1


def test_real_adddate_with_date_option(real_dir):
    r = read_nmea(real_dir / "gpsbabel" / "adddate.nmea", IngestConfig(date="2019-03-09"))
    t = r.frames["position"]["time_ns"]
    assert len(t) == 500 and np.all(np.diff(t) > 0) and t.iloc[-1] == ns("2019-03-10T00:04:19Z")


def test_rmc_dates_and_rollover_with_dates(tmp_path):
    rmc = "GPRMC,{},A,5436.0,N,01847.0,E,1.0,90.0,{},,,A"
    p = _write(
        tmp_path,
        [
            nmea(rmc.format("235959.50", "140324")),
            gga("000000.50"),
            nmea(rmc.format("000001.00", "150324")),
        ],
    )
    r = read_nmea(p, IngestConfig())
    assert r.frames["position"]["time_ns"].tolist() == [
        ns("2024-03-14T23:59:59.500Z"),
        ns("2024-03-15T00:00:00.500Z"),
        ns("2024-03-15T00:00:01Z"),
    ]


def test_sentence_without_time_takes_preceding_fix_time(tmp_path):
    p = _write(
        tmp_path,
        [
            nmea("HEHDT,1.0,T"),
            nmea("GPZDA,120000.00,14,11,2023,00,00"),
            nmea("HEHDT,2.0,T"),
            nmea("GPZDA,120001.00,14,11,2023,00,00"),
            nmea("HEHDT,3.0,T"),
        ],
    )
    r = read_nmea(p, IngestConfig())
    h = r.frames["heading"].sort_values("line")
    noon = ns("2023-11-14T12:00:00Z")
    assert h["time_ns"].tolist() == [noon, noon, noon + 10**9]  # the leading one back-filled
    assert r.time_events.duplicates == 0  # derived times are not duplicates


def test_duplicates_backsteps_gaps_counted(tmp_path):
    lines = [gga(t) for t in ("120000", "120001", "120001", "115950", "120010", "120300")]
    p = _write(tmp_path, lines)
    r = read_nmea(p, IngestConfig(date="2023-11-14", gap_s=60.0, backstep_tolerance_s=1.0))
    te = r.time_events
    assert (te.duplicates, te.backsteps, te.gaps) == (1, 1, 1)
    whats = [e[2] for e in te.examples]
    assert any(w.startswith("back-step -11.000 s") for w in whats) and any(
        w.startswith("gap +170.000 s") for w in whats
    )
    # nothing was dropped or reordered away: all six records are there, sorted by time
    assert len(r.frames["position"]) == 6


def test_gps_week_rollover_in_rmc(tmp_path):
    # a receiver reporting 1999-08-22 for 2019-04-07 (1024 weeks early)
    p = _write(tmp_path, [nmea("GPRMC,120000,A,5436.0,N,01847.0,E,1.0,90.0,220899,,,A")])
    r = read_nmea(p, IngestConfig())
    assert r.frames["position"]["time_ns"].iloc[0] == ns("2019-04-07T12:00:00Z")
    assert r.time_events.implausible_dates == 1
    assert any("week rollover" in d for d in r.time_events.decisions)


def test_event_counter_per_source_and_stream_carry():
    ec = EventCounter(gap_s=10, tolerance_s=0.5)
    t = np.array([0, 1, 1, 30, 2]) * 10**9
    src = np.array(["A", "A", "A", "A", "A"], dtype=object)
    ec.add(
        "heading",
        src[:3],
        t[:3],
        np.ones(3, bool),
        np.arange(1, 4),
        "f",
        np.array(["HDT"] * 3, dtype=object),
    )
    ec.add(
        "heading",
        src[3:],
        t[3:],
        np.ones(2, bool),
        np.arange(4, 6),
        "f",
        np.array(["HDT"] * 2, dtype=object),
    )
    assert ec.per_source["A"]["duplicates"] == 1 and ec.per_source["A"]["gaps"] == 1
    assert ec.per_source["A"]["backsteps"] == 1 and ec.per_source["A"]["max_gap_s"] == 29.0
