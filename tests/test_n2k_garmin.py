"""Garmin chartplotter NMEA 2000 CSV logs, both forms (dracc.ingest.n2k.garmin), read as
canboat's analyzer reads them (its GARMIN_CSV1 / GARMIN_CSV2).

Defect: such a log was refused with "no column names a quantity" (read as a CSV table).
The logs are parts of canboat's ``samples/sample3_GPSMAP4008_NMEA2000_6_21_2015_16_7_59.csv``
(form 1, first 400 rows) and ``samples/sample3_GPSMAP820_NMEA2000_6_21_2015_16_11_8.n2klog.csv``
(form 2, rows 311-690), the reference ``analyzer -json`` of each (tests/data/n2k/README.md).
On the whole samples dracc reads 3355 and 2238 messages, as canboat does.
"""

from __future__ import annotations

from datetime import datetime

import numpy as np

from dracc.core.config import IngestConfig
from dracc.ingest import detect_format, read_file
from dracc.ingest.n2k.formats import parse_n2k, sniff_n2k
from dracc.ingest.n2k.messages import TIME_RELATIVE, TIME_UTC
from dracc.ingest.n2k.reader import n2k_result
from tests.n2k_reference import DATA, check_fields, check_messages, load

CSV1 = DATA / "garmin-gpsmap4008-head.csv"
CSV2 = DATA / "garmin-gpsmap820-part.csv"


def _ms(stamp: str) -> int:
    return round(datetime.fromisoformat(stamp.replace("Z", "+00:00")).timestamp() * 1000)


def test_garmin_csv_was_refused_and_is_now_nmea_2000():
    for path, fmt in ((CSV1, "n2k-garmin-csv1"), (CSV2, "n2k-garmin-csv2")):
        assert detect_format(path) == "n2k"
        res = read_file(path, IngestConfig())
        assert res.format == fmt and res.records > 0 and res.rejects.total == 0
        assert res.ignored["csv header"] == 1 and not res.clockless


def test_garmin_csv1_equals_canboat():
    raw = CSV1.read_bytes()
    assert sniff_n2k(raw) == "n2k-garmin-csv1"
    msgs = parse_n2k(raw, "n2k-garmin-csv1")
    ref = load("garmin-gpsmap4008-head.canboat.json")
    check_messages(msgs, ref)
    # the plotter's ms counter, which canboat prints as a time on 1970-01-01
    assert msgs.time_kind == TIME_RELATIVE
    assert (msgs.time_ns // 1_000_000).tolist() == [_ms(r[4]["timestamp"]) for r in ref]
    res = n2k_result(msgs, str(CSV1), "n2k-garmin-csv1", IngestConfig())
    compared = check_fields(msgs, res.frames, ref)
    assert compared == {127250: 100, 129025: 116, 129026: 46, 129029: 12}  # values
    # put on UTC by the GPS's own times of fix: 129029 (row 130) received when it says
    first = res.frames["position"]
    own = first[first["sentence"].astype(str) == "PGN129029"]
    assert abs(int(own["recv_ns"].iloc[0]) - int(own["time_ns"].iloc[0])) < 5e8


def test_garmin_csv2_equals_canboat_and_keeps_the_counter():
    raw = CSV2.read_bytes()
    assert sniff_n2k(raw) == "n2k-garmin-csv2"
    msgs = parse_n2k(raw, "n2k-garmin-csv2")
    ref = load("garmin-gpsmap820-part.canboat.json")
    check_messages(msgs, ref)
    assert msgs.time_kind == TIME_UTC
    ticks = [int(line.split(",")[1].split("_")[-1]) for line in raw.decode().splitlines()[1:]]
    assert np.diff(msgs.time_ns // 1_000_000).tolist() == np.diff(ticks).tolist()
    # canboat: the clock's second and the counter's ms; the clock stood still for 10 s
    # (rows 335-664 of the sample, lines 25-354 here, all say 16:11:24), the counter did
    # not: canboat's times there fall behind by up to 10 s, dracc's follow the counter
    late_s = (np.array([_ms(r[4]["timestamp"]) for r in ref]) - msgs.time_ns // 1_000_000) / 1e3
    running = (msgs.line < 25) | (msgs.line > 354)
    assert np.abs(late_s[running]).max() < 1.0
    assert late_s[~running].min() < -9.0
    assert any("stopped or was set" in n for n in msgs.notes)
    res = n2k_result(msgs, str(CSV2), "n2k-garmin-csv2", IngestConfig())
    assert check_fields(msgs, res.frames, ref) == {127250: 115}


def test_garmin_rows_that_are_not_rows_are_rejected_with_their_line(tmp_path):
    head, good = CSV1.read_text().splitlines()[:2]
    size = good.replace(",8,0x", ",9,0x")  # Size 9, 8 bytes
    path = tmp_path / "g.csv"
    path.write_text("\n".join([head, good, size, "7,abc,127250", good, "", good + "Z"]) + "\n")
    msgs = parse_n2k(path.read_bytes(), "n2k-garmin-csv1")
    assert len(msgs) == 2 and msgs.line.tolist() == [2, 5]
    assert msgs.rejects == {"garmin_csv_size": 1, "garmin_csv_line": 2, "ignored_csv_header": 1}
    assert [ln for ln, _ in msgs.examples["garmin_csv_line"]] == [4, 7]
