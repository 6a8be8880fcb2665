"""Time events that mean damage (issue 30, item 3): duplicates, shared stamps, back-steps.

A duplicate is damage -- a record repeated, or a time of fix repeated with other values
where the cadence says it should have advanced -- never the samples of a source faster
than its stamps (a 10 Hz gyro behind the whole-second ``c:`` of a TAG logger); every
back-step becomes a :class:`~dracc.frames.ClockStep`; ``dracc inspect`` and ``dracc
analyze`` count them with one code path (:func:`dracc.ingest.timebase.feed_frames`).
The logs are NMEA text written here, with the TAG and checksum helpers of the inspect
tests."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import SAMPLES, real_path
from test_inspect import nmea, tag

from dracc.core.config import IngestConfig
from dracc.ingest import read_logs
from dracc.ingest.inspect import inspect_logs
from dracc.ingest.nmea import StreamState, iter_nmea_blocks, read_nmea
from dracc.ingest.timebase import STEPS_KEPT

T0 = 1_772_323_200  # 2026-03-01T00:00:00Z


def _hms(t: float) -> str:
    s = int(t) % 86400
    return f"{s // 3600:02d}{s // 60 % 60:02d}{s % 60:02d}.{int(round(t % 1 * 100)) % 100:02d}"


def _gyro(t_s: int, heading: float) -> str:
    """A gyro heading behind a whole-second TAG stamp (HDT has no time of its own)."""
    return tag(f"s:GYRO,c:{t_s}", nmea(f"HEHDT,{heading:.1f},T"))


def _gga(t: float, lat_min: float = 36.0, source: str | None = None) -> str:
    body = nmea(f"GPGGA,{_hms(t)},54{lat_min:09.6f},N,01847.000000,E,1,08,1.0,5.0,M,,M,,")
    return tag(f"s:{source},c:{int(t)}", body) if source else body


def _rmc(t: float) -> str:
    return nmea(f"GPRMC,{_hms(t)},A,5436.000000,N,01847.000000,E,12.0,60.0,010326,,,A")


def _write(tmp_path: Path, name: str, lines: list[str]) -> Path:
    p = tmp_path / name
    p.write_text("\r\n".join(lines) + "\r\n")
    return p


def _both(p: Path | list[Path], cfg: IngestConfig | None = None) -> tuple[dict, object]:
    """(inspect's report, analyze's time events) of the same log(s)."""
    paths = p if isinstance(p, list) else [p]
    cfg = cfg or IngestConfig()
    return inspect_logs(paths, cfg), read_logs(paths, cfg).time_events


def _counts(rep: dict, te: object) -> tuple[tuple[int, ...], tuple[int, ...]]:
    tm = rep["time"]
    mine = (tm["duplicates"], tm["backsteps"], tm["gaps"], len(tm["steps"]))
    return mine, (te.duplicates, te.backsteps, te.gaps, len(te.steps))  # type: ignore[attr-defined]


def _gyro_10hz(minutes: float, rng: np.random.Generator, still: bool = False) -> list[str]:
    lines = []
    for k in range(int(minutes * 600)):
        heading = 60.0 if still else 60.0 + 0.5 * np.sin(k / 50) + rng.normal(0, 0.05)
        lines.append(_gyro(T0 + k // 10, heading))
    return lines


def test_a_10_hz_gyro_behind_whole_second_stamps_shares_them(tmp_path):
    p = _write(tmp_path, "gyro.nmea", _gyro_10hz(5, np.random.default_rng(1)))
    rep, te = _both(p)
    mine, theirs = _counts(rep, te)
    assert mine == theirs == (0, 0, 0, 0)
    # 3000 records, 300 stamps: 2700 share the stamp of the record before
    assert rep["sources"]["GYRO"]["shared_stamps"] == 2700
    assert rep["sources"]["GYRO"]["duplicates"] == 0
    assert rep["time"]["shared_stamps"] == 2700
    note = "GYRO HDT: 10 records per 1 s stamp (a 10 Hz source behind whole-second stamps)"
    assert any(note in d for d in rep["time"]["decisions"])
    assert any(note in d for d in te.decisions)  # analyze says it too


def test_a_steady_10_hz_gyro_has_no_duplicates_either(tmp_path):
    # at the berth the heading does not change: records equal in time and value, but a
    # steady reading behind a coarse stamp is not a line written twice
    p = _write(tmp_path, "berth.nmea", _gyro_10hz(2, np.random.default_rng(2), still=True))
    rep, te = _both(p)
    assert _counts(rep, te)[0] == _counts(rep, te)[1] == (0, 0, 0, 0)
    assert rep["sources"]["GYRO"]["shared_stamps"] == 1080


def test_a_line_written_twice_is_one_duplicate(tmp_path):
    rng = np.random.default_rng(3)
    lines = [_gyro(T0 + k, 60 + rng.normal(0, 0.3)) for k in range(300)]
    lines.insert(101, lines[100])  # the logger wrote line 101 twice
    p = _write(tmp_path, "twice.nmea", lines)
    rep, te = _both(p)
    mine, theirs = _counts(rep, te)
    assert mine == theirs == (1, 0, 0, 0)
    assert rep["sources"]["GYRO"]["duplicates"] == 1
    ex = [e for e in rep["time"]["examples"] if e["what"].startswith("duplicate")]
    assert [e["line"] for e in ex] == [102] and "the record again" in ex[0]["what"]


def test_a_gnss_repeating_its_time_of_fix_with_other_values_is_counted(tmp_path):
    lines = [_gga(43200 + k, 36.0 + k * 1e-4) for k in range(120)]
    lines.insert(61, _gga(43260, 36.5))  # the fix of 12:01:00 again, 0.5' further north
    p = _write(tmp_path, "gnss.nmea", lines)
    cfg = IngestConfig(date="2026-03-01")
    rep, te = _both(p, cfg)
    mine, theirs = _counts(rep, te)
    assert mine == theirs == (1, 0, 0, 0)
    ex = [e["what"] for e in rep["time"]["examples"] if e["what"].startswith("duplicate")]
    assert ex == ["duplicate +0.000 s in GP GGA: its time of fix again, other values"]
    assert len(read_nmea(p, cfg).frames["position"]) == 121  # nothing dropped


def test_a_5_hz_gnss_with_whole_second_fix_times_is_no_duplicate(tmp_path):
    # a receiver faster than the resolution of its time of fix: five fixes a second
    lines = [_gga(43200 + k // 5, 36.0 + k * 1e-5) for k in range(500)]
    p = _write(tmp_path, "gnss5.nmea", lines)
    rep, te = _both(p, IngestConfig(date="2026-03-01"))
    assert _counts(rep, te)[0] == _counts(rep, te)[1] == (0, 0, 0, 0)
    assert rep["sources"]["GP"]["shared_stamps"] == 400


def _voyage(seconds: int) -> list[str]:
    """A gyro, a GNSS (GGA, RMC) and a log behind TAG stamps, once a second."""
    lines = []
    for k in range(seconds):
        t = T0 + k
        lines.append(_gyro(t, 60 + 0.01 * k))
        lines.append(tag(f"s:GNSS,c:{t}", _gga(t % 86400, 36 + k * 1e-4)))
        lines.append(tag(f"s:GNSS,c:{t}", _rmc(t % 86400)))
        lines.append(tag(f"s:LOG,c:{t}", nmea("VWVHW,,T,,M,12.0,N,22.2,K")))
    return lines


def test_a_looped_logger_steps_back_once_per_stream_and_replay(tmp_path):
    block = _voyage(22 * 60)  # 22 minutes of recording
    p = _write(tmp_path, "looped.nmea", block * 3)  # replayed twice
    rep, te = _both(p)
    mine, theirs = _counts(rep, te)
    streams = {("GYRO", "HDT"), ("GNSS", "GGA"), ("GNSS", "RMC"), ("LOG", "VHW")}
    assert mine == theirs == (0, 2 * len(streams), 0, 2 * len(streams))
    last, first = (T0 + 22 * 60 - 1) * 10**9, T0 * 10**9
    for replay in (1, 2):
        at = replay * len(block)  # the last line before the replay
        steps = {(s.source, s.sentence): s for s in te.steps if at < s.line <= at + 4}
        assert set(steps) == streams
        for (_, sentence), s in steps.items():
            assert (s.from_ns, s.to_ns) == (last, first)
            offset = {"HDT": 1, "GGA": 2, "RMC": 3, "VHW": 4}[sentence]
            assert s.line == at + offset  # the first record after the step
            assert s.file == str(p)
    js = rep["time"]["steps"][0]
    assert (
        js["from_utc"] == "2026-03-01T00:21:59.000Z" and js["to_utc"] == "2026-03-01T00:00:00.000Z"
    )
    assert js["step_s"] == -1319.0
    # every record kept, the frames in time order
    r = read_nmea(p, IngestConfig())
    assert len(r.frames["heading"]) == 3 * 22 * 60
    assert all(np.all(np.diff(f["time_ns"].to_numpy()) >= 0) for f in r.frames.values())


def test_steps_are_kept_up_to_a_cap_and_counted_all(tmp_path):
    # two clocks under one key, 3 s apart, alternating: a back-step every other record
    lines = [_gyro(T0 + k + (3 if k % 2 else 0), 60.0 + k % 7) for k in range(900)]
    p = _write(tmp_path, "two_clocks.nmea", lines)
    te = read_nmea(p, IngestConfig()).time_events
    assert te.backsteps == 449 and len(te.steps) == STEPS_KEPT


def test_steps_merge_across_files_and_readers(tmp_path):
    a = _write(tmp_path, "a.nmea", _voyage(120) * 2)
    csv = tmp_path / "b.csv"
    rows = ["time_utc,source,heading_deg,reference"]
    for k in list(range(60)) + list(range(30, 90)):  # the CSV steps back once
        rows.append(f"2026-03-01T01:{k // 60:02d}:{k % 60:02d}Z,GYRO2,{60 + k * 0.1:.1f},T")
    csv.write_text("\n".join(rows) + "\n")
    rep, te = _both([a, csv])
    mine, theirs = _counts(rep, te)
    assert mine == theirs == (0, 5, 0, 5)
    s = [s for s in te.steps if s.source == "GYRO2"]
    assert len(s) == 1 and s[0].file == str(csv) and s[0].line == 62
    assert s[0].to_ns - s[0].from_ns == -29 * 10**9  # 01:00:59 -> 01:00:30


def test_counts_do_not_depend_on_the_blocks(tmp_path):
    lines = _gyro_10hz(3, np.random.default_rng(4))
    lines[500:501] = [lines[500], lines[500]]  # one line written twice
    lines += _voyage(60)  # and a step back
    p = _write(tmp_path, "blocks.nmea", lines)
    out = []
    for block_bytes in (None, 4096):
        st = StreamState(str(p))
        for _ in iter_nmea_blocks(p, IngestConfig(), st, block_bytes=block_bytes):
            pass
        te = st.time_events()
        out.append((te.duplicates, te.backsteps, te.shared_stamps, te.per_source))
    assert out[0] == out[1]
    assert out[0][:2] == (0, 1)  # behind a 10 Hz cadence a doubled line is a shared stamp


@pytest.mark.parametrize(
    "name",
    sorted(
        str(p.relative_to(SAMPLES))
        for p in SAMPLES.rglob("*")
        if p.suffix in (".nmea", ".csv", ".mcap") and p.stem not in ("truth", "errors")
    ),
)
def test_inspect_and_analyze_count_alike_on_the_samples(name):
    rep, te = _both(SAMPLES / name)
    mine, theirs = _counts(rep, te)
    assert mine == theirs
    per = rep["sources"].values()
    assert sum(s["duplicates"] for s in per) == te.duplicates
    assert sum(s["backsteps"] for s in per) == te.backsteps
    if name in ("voyage_tag.nmea", "voyage_prefix.nmea", "day/voyage_day.mcap"):
        assert mine == (0, 0, 0, 0)  # healthy simulated logs


def test_the_cli_agrees_on_the_day_sample(run_cli, tmp_path):
    """The reviewer's case: inspect said 3,122 duplicates where analyze said none (the two
    LOG water messages of one instant, VHW and VBW, are a shared stamp)."""
    log = SAMPLES / "day" / "voyage_day.mcap"
    assert run_cli("inspect", log, "--json", tmp_path / "i.json")[0] == 0
    assert run_cli("analyze", log, "--json", tmp_path / "a.json")[0] == 0
    i = json.loads((tmp_path / "i.json").read_text())["time"]
    a = json.loads((tmp_path / "a.json").read_text())["time_events"]
    assert [i[k] for k in ("duplicates", "backsteps", "gaps")] == [0, 0, 0]
    assert [a[k] for k in ("duplicates", "backsteps", "gaps")] == [0, 0, 0]
    assert i["shared_stamps"] == 3122


@pytest.mark.parametrize(
    ("parts", "expected"),
    [
        # (duplicates, backsteps, gaps, steps)
        (("gpsbabel", "nmea+ms.txt"), (0, 3, 0, 3)),  # a receiver's fixes out of order
        (("VDRplayer", "Hakefjord.txt"), (843, 0, 0, 0)),  # IIRMC: the held fix sent again
        (("anemomind", "Irene", "2014", "20140611", "NMEA0048.TXT"), (278, 0, 0, 0)),
        (("gpsd", "bundg_zeus_9.log.chk"), (1, 0, 0, 0)),
        (("canboat", "susteranna2020.raw"), (54, 0, 0, 0)),
        (("openrvdas", "NBP1406_gyr1-2014-08-01"), (0, 0, 0, 0)),
        (("signalk-server", "aava-n2k.data"), (0, 0, 0, 0)),
    ],
)
def test_inspect_and_analyze_count_alike_on_real_logs(parts, expected):
    rep, te = _both(real_path(*parts))
    mine, theirs = _counts(rep, te)
    assert mine == theirs == expected


def test_real_back_steps_are_where_the_receiver_put_them():
    te = read_logs([real_path("gpsbabel", "nmea+ms.txt")], IngestConfig()).time_events
    assert [(s.line, s.sentence, (s.to_ns - s.from_ns) / 1e9) for s in te.steps] == [
        (58, "GGA", -1.5),
        (81, "GGA", -1.25),
        (100, "RMC", -1.5),
    ]
