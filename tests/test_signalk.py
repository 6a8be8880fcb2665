"""Signal K server data logs (``<ms>;<type>;<payload>``) and bare Signal K delta JSON.

The logs are built here from real lines (NMEA 0183 from signalk-server/plaka.log, NMEA
2000 canboat plain from signalk-server/aava-n2k.data) and deltas written by hand with
known SI values; none of the shared signalk-server files is in the multiplexed form.
NMEA 2000 values are checked against canboat's decoder (the ``nmea2000`` package).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import real_path

from dracc.core.config import IngestConfig
from dracc.core.errors import IngestError
from dracc.frames import MISSING_NS
from dracc.ingest.nmea import read_nmea
from dracc.ingest.signalk import looks_like_signalk, read_signalk
from dracc.ingest.signalk_delta import looks_like_signalk_delta, read_signalk_delta

KN = 1852.0 / 3600.0
T0_MS = 1408129200000  #: 2014-08-15T19:00:00Z, the day of aava-n2k.data
A_LINES = (2, 5, 9, 15)  #: the NMEA 2000 lines of the log below


def _ms(line: int) -> int:
    return T0_MS + 100 * line


def _real_lines(*parts: str) -> list[str]:
    return real_path(*parts).read_text().splitlines()


def _mux_log(tmp_path):
    plaka = _real_lines("signalk-server", "plaka.log")
    aava = _real_lines("signalk-server", "aava-n2k.data")[:200]
    heading = [ln for ln in aava if ",127250," in ln][:3]
    stw = next(ln for ln in aava if ",128259,115," in ln)
    vhw, vtg, gll = plaka[0].strip(), plaka[2].strip(), plaka[10].strip()
    assert vhw.startswith("$IIVHW") and vtg.startswith("$IIVTG") and gll.startswith("$GPGLL")
    own = (
        '{"context":"vessels.self","updates":[{"$source":"test.gnss",'
        '"timestamp":"2014-08-15T19:00:01.000Z","values":['
        '{"path":"navigation.position","value":{"latitude":60.0845,"longitude":23.539,'
        '"altitude":2.5}},{"path":"navigation.gnss.methodQuality","value":"DGNSS fix"},'
        '{"path":"navigation.gnss.horizontalDilution","value":0.8},'
        '{"path":"navigation.courseOverGroundTrue","value":3.9},'
        '{"path":"navigation.speedOverGround","value":3.0},'
        '{"path":"navigation.speedThroughWater","value":3.1},'
        '{"path":"navigation.log","value":1852000},{"path":"navigation.trip.log","value":1852.0},'
        '{"path":"navigation.rateOfTurn","value":-0.01},'
        '{"path":"environment.wind.speedApparent","value":5.0}]}]}'
    )
    ais = (
        '{"context":"vessels.urn:mrn:imo:mmsi:244000000","updates":[{"source":{"label":'
        '"nmea0183","type":"NMEA0183","talker":"AI","sentence":"VDM"},"$source":"nmea0183.AI",'
        '"timestamp":"2014-08-15T19:00:01.000Z","values":[{"path":"navigation.position",'
        '"value":{"latitude":60.2,"longitude":23.7}}]}]}'
    )
    rows = [
        f"N;{vhw}",
        f"A;{heading[0]}",
        'I;{"updates":[{"$source":"test.compass","timestamp":"2014-08-15T19:00:00.500Z",'
        '"values":[{"path":"navigation.headingMagnetic","value":1.2},'
        '{"path":"navigation.magneticVariation","value":0.05}]}]}',
        f"N;{vtg}",
        f"A;{heading[1]}",
        f"I;{own}",
        f"I;{ais}",
        f"N;{gll}",
        f"A;{heading[2]}",
        'I;{"updates": [',
        "X;something dracc does not read",
        None,
        'I;{"updates":[{"source":{"label":"can0","src":"17"},'
        '"values":[{"path":"navigation.headingTrue","value":0.5}]}]}',
        'I;{"updates":[{"$source":"x","values":[{"path":"navigation.headingTrue","value":"N"}]}]}',
        f"A;{stw}",
    ]
    text = "\n".join("" if r is None else f"{_ms(i)};{r}" for i, r in enumerate(rows, 1))
    p = tmp_path / "skserver-raw_2014-08-15T19.log"
    p.write_text(text + "\n")
    return p, heading, stw


def _not_a(df):
    return df[~df["line"].isin(A_LINES)].reset_index(drop=True)


def test_mux_log_gives_each_value_once_with_its_line_and_source(tmp_path):
    p, _, _ = _mux_log(tmp_path)
    assert looks_like_signalk(p.read_bytes())
    r = read_signalk(p, IngestConfig())
    assert r.format == "signalk" and r.lines == 15
    f = {k: _not_a(v) for k, v in r.frames.items()}
    water = f["water"]
    assert list(water["line"]) == [1, 6] and list(water["source"]) == ["II", "test.gnss"]
    assert water["stw_mps"].tolist() == pytest.approx([6.11 * KN, 3.1])
    assert water["time_ns"].iloc[0] == _ms(1) * 10**6  # VHW has no time: its receive time
    ground = f["ground"]
    assert list(ground["line"]) == [4, 6]
    assert ground["cog_rad"].tolist() == pytest.approx([math.radians(224.44), 3.9])
    assert ground["sog_mps"].tolist() == pytest.approx([5.81 * KN, 3.0])
    pos = f["position"].sort_values("line")
    assert list(pos["line"]) == [6, 8]  # the AIS target (line 7) is not the own vessel
    lat = [math.radians(60.0845), math.radians(60 + 5.071 / 60)]
    lon = [math.radians(23.539), math.radians(23 + 32.346 / 60)]
    assert pos["lat_rad"].tolist() == pytest.approx(lat, abs=1e-12)
    assert pos["lon_rad"].tolist() == pytest.approx(lon, abs=1e-12)
    own = pos.iloc[0]
    assert own["source"] == "test.gnss" and own["quality"] == 2 and own["hdop"] == 0.8
    assert own["alt_m"] == 2.5
    assert own["time_ns"] == T0_MS * 10**6 + 10**9 and own["recv_ns"] == _ms(6) * 10**6
    assert pos.iloc[1]["source"] == "GP" and pos.iloc[1]["recv_ns"] == _ms(8) * 10**6
    h = f["heading"].sort_values("line")
    assert list(h["line"]) == [3, 13]
    assert list(h["reference"]) == ["M", "T"] and list(h["source"]) == ["test.compass", "can0.17"]
    assert h["heading_rad"].tolist() == pytest.approx([1.2, 0.5])
    assert h["variation_rad"].iloc[0] == pytest.approx(0.05) and np.isnan(
        h["variation_rad"].iloc[1]
    )
    assert h["time_ns"].iloc[0] == T0_MS * 10**6 + 5 * 10**8
    assert h["time_ns"].iloc[1] == _ms(13) * 10**6 and h["recv_ns"].iloc[1] == MISSING_NS
    d = f["distance"]
    assert list(d["line"]) == [6] and d["total_water_m"].iloc[0] == 1852000.0
    assert d["trip_water_m"].iloc[0] == 1852.0
    assert list(f["rot"]["line"]) == [6] and f["rot"]["rot_radps"].iloc[0] == -0.01
    assert r.rejects.counts["bad_json"] == 1 and r.rejects.examples["bad_json"][0][1] == 10
    assert r.rejects.counts["bad_value"] == 1 and r.rejects.examples["bad_value"][0][1] == 14
    assert r.rejects.examples["bad_json"][0][0] == str(p)
    assert r.ignored["signalk X"] == 1 and r.ignored_examples["signalk X"][0][1] == 11
    assert r.ignored["blank"] == 1 and r.ignored["signalk other vessel"] == 1
    assert r.ignored["signalk environment.wind"] == 1
    for kind, df in r.frames.items():
        assert np.all(np.diff(df["time_ns"].to_numpy()) >= 0), kind


def test_mux_log_nmea2000_lines_equal_canboat(tmp_path):
    pytest.importorskip("dracc.ingest.n2k.reader")
    from nmea2000.decoder import NMEA2000Decoder

    p, heading, stw = _mux_log(tmp_path)
    r = read_signalk(p, IngestConfig())
    peer = NMEA2000Decoder()

    def field(line, fid):
        msg = peer.decode(line)
        return next(x.value for x in msg.fields if x.id == fid)

    h = r.frames["heading"]
    h = h[h["line"].isin(A_LINES)].sort_values("line")
    assert list(h["line"]) == [2, 5, 9] and h["source"].nunique() == 1
    want = [field(ln, "heading") for ln in heading]
    assert h["heading_rad"].tolist() == pytest.approx(want, abs=1e-4)
    assert h["variation_rad"].tolist() == pytest.approx([field(heading[0], "variation")] * 3)
    assert list(h["recv_ns"]) == [_ms(n) * 10**6 for n in (2, 5, 9)]  # the log's receive time
    w = r.frames["water"]
    w = w[w["line"] == 15]
    assert len(w) == 1 and w["stw_mps"].iloc[0] == pytest.approx(
        field(stw, "speedWaterReferenced"), abs=1e-2
    )
    assert "n2k_unread" not in r.rejects.counts


def test_nmea_lines_read_as_in_a_plain_log(tmp_path):
    """The NMEA lines of a log interleaved with deltas give what the same lines alone
    give the NMEA reader, each at its own line number."""
    plaka = [ln.strip() for ln in _real_lines("signalk-server", "plaka.log")[:400]]
    alone = tmp_path / "alone.log"
    alone.write_text("\n".join(f"{T0_MS + 10 * i};N;{s}" for i, s in enumerate(plaka)) + "\n")
    delta = (
        '{"updates":[{"$source":"s","timestamp":"2014-08-15T19:00:00Z",'
        '"values":[{"path":"navigation.rateOfTurn","value":0.001}]}]}'
    )
    rows, where = [], []
    for i, s in enumerate(plaka):
        if i % 3 == 0:
            rows.append(f"{T0_MS + 10 * i};I;{delta}")
        where.append(len(rows) + 1)
        rows.append(f"{T0_MS + 10 * i};N;{s}")
    mixed = tmp_path / "mixed.log"
    mixed.write_text("\n".join(rows) + "\n")
    a, m = read_nmea(alone, IngestConfig()), read_signalk(mixed, IngestConfig())
    assert m.lines == len(rows) and len(m.frames["rot"]) == 134
    assert m.ignored == a.ignored and m.rejects.counts == a.rejects.counts
    for kind in ("position", "heading", "ground", "water"):
        x, y = a.frames[kind], m.frames[kind]
        assert len(x) == len(y), kind
        assert (y["line"].to_numpy() == np.asarray(where)[x["line"].to_numpy() - 1]).all()
        for c in x.columns:
            if c != "line":
                assert x[c].astype(object).equals(y[c].astype(object)), (kind, c)


def test_bare_delta_file_declares_its_own_vessel(tmp_path):
    lines = [
        '{"name":"signalk-server","version":"2.8.0","self":"vessels.urn:mrn:signalk:uuid:a1",'
        '"roles":["master","main"],"timestamp":"2024-05-01T12:00:00.000Z"}',
        '{"context":"vessels.urn:mrn:signalk:uuid:a1","updates":[{"$source":"n2k.3",'
        '"source":{"label":"n2k","src":"3","pgn":127250},"timestamp":"2024-05-01T12:00:01Z",'
        '"values":[{"path":"navigation.headingTrue","value":1.0}]}]}',
        '{"context":"vessels.urn:mrn:imo:mmsi:230000001","updates":[{"$source":"n2k.9",'
        '"timestamp":"2024-05-01T12:00:01Z","values":[{"path":"navigation.headingTrue",'
        '"value":2.0}]}]}',
        '{"updates":[{"meta":[{"path":"navigation.headingTrue","value":{"units":"rad"}}]}]}',
        "not json at all",
        "[1, 2]",
        '{"updates":[{"timestamp":"2024-05-01T12:00:02Z","values":[{"path":'
        '"navigation.speedOverGround","value":null}]}]}',
    ]
    p = tmp_path / "delta.log"
    p.write_text("\n".join(lines) + "\n")
    head = p.read_bytes()
    assert looks_like_signalk_delta(head) and not looks_like_signalk(head)
    r = read_signalk_delta(p, IngestConfig())
    assert r.format == "signalk-delta" and r.lines == 7
    h = r.frames["heading"]
    assert list(h["line"]) == [2] and h["heading_rad"].iloc[0] == 1.0
    assert h["source"].iloc[0] == "n2k.3" and h["sentence"].iloc[0] == "PGN127250"
    assert h["time_ns"].iloc[0] == 1714564801 * 10**9
    assert r.ignored["signalk other vessel"] == 1 and r.ignored["signalk hello"] == 1
    assert r.ignored["signalk meta"] == 1 and r.ignored["signalk null"] == 1
    assert dict(r.rejects.counts) == {"bad_json": 1, "not_delta": 1}
    assert r.rejects.examples["bad_json"][0][1] == 5
    with pytest.raises(IngestError, match=r"delta.log:5: rejected \(bad_json"):
        read_signalk_delta(p, IngestConfig(strict=True))


def test_no_shared_signalk_server_file_is_multiplexed():
    folder = real_path("signalk-server")
    for f in sorted(folder.iterdir()):
        head = f.read_bytes()[:65536]
        assert not looks_like_signalk(head), f.name
        assert not looks_like_signalk_delta(head), f.name


def test_damaged_mux_lines_are_counted_never_raised(tmp_path):
    p, _, _ = _mux_log(tmp_path)
    data = bytearray(p.read_bytes())
    rng = np.random.default_rng(3)
    for _ in range(60):
        data[rng.integers(len(data))] = rng.integers(256)
    data += b"1408129209999;I;" + b"{" * 5000 + b"\n12;N;x\n1408129209999;A;garbage\n"
    q = tmp_path / "damaged.log"
    q.write_bytes(bytes(data))
    r = read_signalk(q, IngestConfig())
    assert r.lines == bytes(data).count(b"\n")
    assert r.rejects.total > 0
    with pytest.raises(IngestError, match="rejected"):
        read_signalk(q, IngestConfig(strict=True))


def test_line_preserving_copy_matches_a_line_by_line_copy():
    from dracc.ingest.demux import line_bounds, line_copy

    raw = b"12;N;$A\r\n\r\nxx;yy\n;;\r\n123456;I;{}\nlast;no;lf"
    buf = np.frombuffer(raw, dtype=np.uint8)
    start, end, nxt = line_bounds(buf)
    lines = raw.split(b"\n")
    assert len(start) == len(lines) == 6
    keep = np.array([True, True, False, True, True, True])
    skip = np.array([5, 0, 0, 1, 9, 3])
    got = line_copy(buf, start, end, nxt, keep, skip).tobytes()
    want = b"".join(
        (ln.rstrip(b"\r")[k:] if kp else b"") + b"\n"
        for ln, kp, k in zip(lines, keep, skip, strict=True)
    )
    assert got == want == b"$A\n\n\n;\n{}\nt;no;lf\n"
