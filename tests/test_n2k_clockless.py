"""NMEA 2000 logs without a clock are named as such (``FileResult.clockless``), timed by
the order of their records, and no other log is.

Defect: a ``candump can0`` log (no ``(time)`` on its lines) was given invented times,
every message at one instant, and the audit then found "data 25 s old" latency between
a 129029's own time of fix and that invented receive time.
"""

from __future__ import annotations

import numpy as np
import pytest

from dracc.core.config import IngestConfig
from dracc.ingest import read_logs
from dracc.ingest.n2k import read_n2k
from dracc.ingest.n2k.formats import parse_n2k, parse_n2k_lines
from dracc.ingest.n2k.messages import TIME_NONE, TIME_UTC
from dracc.ingest.n2k.reader import NO_CLOCK_NOTE, n2k_result
from tests.conftest import real_path
from tests.n2k_reference import DATA, check_fields, check_messages, load

CANDUMP = DATA / "candumpSample2.txt"


def test_candump_without_times_is_clockless():
    msgs = parse_n2k(CANDUMP.read_bytes(), "n2k-candump")
    assert msgs.time_kind == TIME_NONE
    ref = load("candumpSample2.canboat.json")
    check_messages(msgs, ref)  # 267 messages, as canboat's candump2analyzer | analyzer
    res = read_n2k(CANDUMP, IngestConfig())
    assert res.clockless
    assert NO_CLOCK_NOTE in res.notes
    compared = check_fields(msgs, res.frames, ref)
    assert compared == {127250: 46, 127251: 46, 129025: 92, 129026: 46, 129029: 10}


def test_clockless_times_keep_the_record_order():
    res = read_n2k(CANDUMP, IngestConfig())
    for kind, df in res.frames.items():
        if not len(df) or kind == "position":
            continue
        order = np.argsort(df["time_ns"].to_numpy(), kind="stable")
        assert np.all(np.diff(df["line"].to_numpy()[order]) > 0), kind
        assert len(np.unique(df["time_ns"])) == len(df), kind  # never one instant
    # a 129029 keeps its own time of fix; its receive time is only the record's order
    pos = res.frames["position"]
    own = pos[pos["sentence"].astype(str) == "PGN129029"]
    assert len(own) == 5 and np.all(own["recv_ns"] > 0)


def test_voyage_names_the_clockless_sources():
    voyage = read_logs([CANDUMP], IngestConfig())
    assert voyage.clockless and voyage.clockless == set(voyage.sources)


@pytest.mark.parametrize(
    "where",
    [
        ("canboat", "candump-fast-cr.txt"),  # relative times from zero: a clock, unset
        ("canboat", "actisense-522.candump.log"),
        ("canboat", "actisense-523.rx.ebl"),
        ("canboat", "merrimac-ydwg-2020.raw"),  # time of day only
        ("canboat", "scx20.raw"),
    ],
    ids=lambda w: w[1],
)
def test_logs_with_a_clock_are_not_clockless(where):
    res = read_n2k(real_path(*where), IngestConfig())
    assert not res.clockless
    assert NO_CLOCK_NOTE not in res.notes


def test_ngt1_stream_with_its_timer_is_not_clockless():
    assert not read_n2k(DATA / "ydnu02-ev1-head.dle", IngestConfig()).clockless


def test_times_before_2000_are_clockless(tmp_path):
    """canboat plain lines stamped 1970 by a logger without a clock (the case
    ``taken as relative``): clockless too."""
    lines = [
        f"1970-01-01T00:00:{s:06.3f}Z,2,127250,1,255,8,00,10,27,00,00,00,00,fd" for s in range(5)
    ]
    path = tmp_path / "noclock.raw"
    path.write_text("\n".join(lines) + "\n")
    res = read_n2k(path, IngestConfig())
    assert res.clockless
    assert any("taken as relative" in n for n in res.notes) and NO_CLOCK_NOTE in res.notes
    assert np.diff(res.frames["heading"]["time_ns"]).tolist() == [10**9] * 4


def test_times_that_never_advance_are_clockless(tmp_path):
    path = tmp_path / "zero.log"
    path.write_text("(0.000000) can0 09F11201#FF3412FF7FFF7FFD\n" * 4)
    res = read_n2k(path, IngestConfig())
    assert res.clockless and NO_CLOCK_NOTE in res.notes
    assert np.diff(res.frames["heading"]["time_ns"]).tolist() == [10**6] * 3


def test_mxpgn_alone_is_clockless_but_not_inside_a_timed_log(tmp_path):
    sentence = "$MXPGN,01F112,2801,FD7FFF7FFF12342A"
    body = sentence[1:]
    cs = 0
    for ch in body.encode():
        cs ^= ch
    line = f"{sentence}*{cs:02X}"
    path = tmp_path / "mx.log"
    path.write_text((line + "\r\n") * 3)
    res = read_n2k(path, IngestConfig())
    assert res.format == "n2k-mxpgn" and res.clockless
    # inside an NMEA 0183 log the sentences take the log's times (embedded_n2k)
    msgs = parse_n2k_lines([line.encode()] * 3, np.array([1, 2, 3]), "n2k-mxpgn")
    msgs.time_ns = np.array([1, 2, 3], dtype=np.int64) * 10**9 + 1_700_000_000 * 10**9
    msgs.time_kind = TIME_UTC
    assert not n2k_result(msgs, "x", "n2k-mxpgn", IngestConfig(), lines=0).clockless


def test_older_candump_banner_is_ignored_not_rejected(tmp_path):
    """candumpSample1.txt (canboat's samples) begins ``interface = can0, family = 29, ...``:
    candump's own banner, a valid line without a frame; then ``<0x18eeff01> [8] ...``
    frames without times."""
    path = tmp_path / "old.txt"
    lines = ["interface = can0, family = 29, type = 3, proto = 1"]
    lines += ["<0x09f11201> [8] ff 34 12 ff 7f ff 7f fd "] * 3
    path.write_text("\n".join(lines) + "\n")
    res = read_n2k(path, IngestConfig())
    assert res.rejects.total == 0 and res.ignored["candump banner"] == 1
    assert res.clockless and len(res.frames["heading"]) == 3
