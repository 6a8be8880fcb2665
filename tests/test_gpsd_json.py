"""gpsd JSON (gpspipe -w) and gpsfake .chk files: gpsd as the peer of dracc's NMEA reader.

gpsd's regression expectations (``<log>.chk``) hold the JSON gpsd made of ``<log>``:
what dracc reads from the JSON must be what dracc's NMEA reader reads from the
sentences, to the JSON's printed precision (9 decimals of degrees, 3 of m/s, 4 of
degrees of track).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import real_path

from dracc.core.config import IngestConfig
from dracc.ingest.gpsd_json import looks_like_gpsd_json, read_gpsd_json
from dracc.ingest.nmea import read_nmea

D = 180.0 / math.pi
KN = 1852.0 / 3600.0


def _gpsd(frame):
    return frame[frame["source"] == "gpsd"]


def _angle_deg(a, b):
    return np.abs((np.asarray(a) - b + 180.0) % 360.0 - 180.0)


def test_bundg_zeus_tpv_positions_equal_the_nmea_reader():
    log = real_path("gpsd", "bundg_zeus_9.log")
    chk = log.with_name(log.name + ".chk")
    assert looks_like_gpsd_json(chk.read_bytes()[:65536])
    assert not looks_like_gpsd_json(log.read_bytes()[:65536])
    g = read_gpsd_json(chk, IngestConfig())
    n = read_nmea(log, IngestConfig())
    pos, npos = _gpsd(g.frames["position"]), n.frames["position"]
    assert len(pos) == 147  # one record per epoch with a time (1468 TPVs, 3 without time)
    assert g.ignored["gpsd TPV repeat"] + len(pos) + g.ignored["gpsd TPV without time"] == 1468
    with_alt = 0
    for t, la, lo, alt in zip(
        pos["time_ns"], pos["lat_rad"], pos["lon_rad"], pos["alt_m"], strict=True
    ):
        m = npos[npos["time_ns"] == t]
        assert len(m), t  # every TPV time is the time of a fix sentence
        err = np.hypot((m["lat_rad"] - la) * D, (m["lon_rad"] - lo) * D).min()
        assert err < 5.1e-10  # 9 printed decimals of degrees
        if np.isfinite(alt):  # gpsd's altMSL is GGA's altitude field
            with_alt += 1
            assert np.nanmin(np.abs(m["alt_m"] - alt)) < 1e-4
    assert with_alt > 50
    assert (pos["quality"] == 1).all()  # mode 3, no status: a plain fix


def test_bundg_zeus_tpv_tracks_and_speeds():
    """Where the epoch's TPVs carry the RMC/VTG values, they equal what the NMEA reader
    reads; gpsd closes some epochs before the RMC comes and then reports a track from the
    heading (HDG plus variation) and a speed from successive fixes, which are not the
    log's (about one epoch in five here)."""
    log = real_path("gpsd", "bundg_zeus_9.log")
    g = read_gpsd_json(log.with_name(log.name + ".chk"), IngestConfig())
    n = read_nmea(log, IngestConfig())
    gr, ngr = _gpsd(g.frames["ground"]), n.frames["ground"]
    same = compared = 0
    for t, c, s in zip(gr["time_ns"], gr["cog_rad"], gr["sog_mps"], strict=True):
        m = ngr[ngr["time_ns"] == t]
        if not len(m) or not np.isfinite(c):
            continue
        compared += 1
        ok = (_angle_deg(m["cog_rad"] * D, c * D) < 1e-4) & (np.abs(m["sog_mps"] - s) < 6e-4)
        same += bool(ok.any())
    assert compared > 120 and same >= 0.75 * compared


@pytest.mark.parametrize(
    "name", ["hemi.log", "st-teseo-liv4f.log", "ais-nmea.log", "skytraq-PX1172RH_DS.log"]
)
def test_tpv_equal_the_nmea_reader_record_for_record(name):
    log = real_path("gpsd", name)
    g = read_gpsd_json(log.with_name(name + ".chk"), IngestConfig())
    n = read_nmea(log, IngestConfig())
    pos, gr = _gpsd(g.frames["position"]), _gpsd(g.frames["ground"])
    assert len(pos)
    for t, la, lo in zip(pos["time_ns"], pos["lat_rad"], pos["lon_rad"], strict=True):
        m = n.frames["position"][n.frames["position"]["time_ns"] == t]
        assert np.hypot((m["lat_rad"] - la) * D, (m["lon_rad"] - lo) * D).min() < 5.1e-10
    for t, c, s in zip(gr["time_ns"], gr["cog_rad"], gr["sog_mps"], strict=True):
        m = n.frames["ground"][n.frames["ground"]["time_ns"] == t]
        if np.isfinite(c):
            assert _angle_deg(m["cog_rad"] * D, c * D).min() < 1e-4
        assert np.abs(m["sog_mps"] - s).min() < 6e-4


def test_att_heading_equals_hdt_and_takes_the_epoch_time():
    """hemi.log's ATT reports carry no time: each takes its epoch's (the TPV before it),
    and its heading is the HDT of that time."""
    log = real_path("gpsd", "hemi.log")
    g = read_gpsd_json(log.with_name("hemi.log.chk"), IngestConfig())
    n = read_nmea(log, IngestConfig())
    h = _gpsd(g.frames["heading"])
    assert len(h) == 4 and (h["reference"] == "T").all()
    for t, v in zip(h["time_ns"], h["heading_rad"], strict=True):
        m = n.frames["heading"][n.frames["heading"]["time_ns"] == t]
        assert np.nanmin(np.abs(m["heading_rad"] - v)) * D < 5.1e-4  # 3 printed decimals


def test_mixed_chk_lines_keep_their_numbers():
    """A .chk file: its sentences read by the NMEA reader, its JSON by gpsd_json; every
    record's line is the line of the file it came from."""
    chk = real_path("gpsd", "bundg_zeus_9.log.chk")
    text = chk.read_bytes().split(b"\n")
    r = read_gpsd_json(chk, IngestConfig())
    assert r.format == "gpsd-json" and r.lines == len(text) - (text[-1] == b"")
    assert r.rejects.total == 0 and "blank" not in r.ignored
    for kind, df in r.frames.items():
        for src, ln, sent in zip(df["source"], df["line"], df["sentence"], strict=True):
            line = text[ln - 1]
            if src == "gpsd":
                assert line.startswith(b'{"class":"' + str(sent).encode()), (kind, ln)
            else:
                assert line.startswith(b"$") and line[3:6] == str(sent).encode(), (kind, ln)
    n = read_nmea(real_path("gpsd", "bundg_zeus_9.log"), IngestConfig())
    # the sentences give what the log gives (gpsd echoes every sentence it used)
    assert len(r.frames["water"]) == len(n.frames["water"]) == 150
    assert np.allclose(
        np.sort(r.frames["water"]["stw_mps"].to_numpy()),
        np.sort(n.frames["water"]["stw_mps"].to_numpy()),
    )


def test_gpspipe_output_classes_device_quality_units(tmp_path):
    lines = [
        '{"class":"VERSION","release":"3.25","rev":"3.25","proto_major":3,"proto_minor":15}',
        '{"class":"DEVICES","devices":[{"class":"DEVICE","path":"/dev/ttyUSB0"}]}',
        '{"class":"WATCH","enable":true,"json":true}',
        '{"class":"TPV","device":"/dev/ttyUSB0","mode":1,"time":"2024-05-01T12:00:00.000Z"}',
        '{"class":"TPV","device":"/dev/ttyUSB0","mode":3,"status":2,"time":"2024-05-01T12:00:01.000Z",'
        '"lat":54.5,"lon":-18.25,"altHAE":60.0,"geoidSep":50.0,"track":90.0,"speed":5.0}',
        '{"class":"SKY","device":"/dev/ttyUSB0","hdop":0.9}',
        '{"class":"ATT","device":"/dev/ttyS1","time":1714564801.5,"heading":10.0,'
        '"mheading":12.0,"rot":30.0}',
        '{"class":"TPV","device":"/dev/ttyUSB0","mode":2,"time":"2024-05-01T12:00:02Z",'
        '"lat":54.6,"lon":-18.2}',
        '{"class":"TPV","device":"/dev/ttyUSB0","mode":',  # cut off (gpsd truncates long reports)
        '{"no":"class"}',
        "",
        '{"class":"AIS","type":1,"mmsi":244000000}',
    ]
    p = tmp_path / "gpspipe.json"
    p.write_text("\n".join(lines) + "\n")
    assert looks_like_gpsd_json(p.read_bytes())
    r = read_gpsd_json(p, IngestConfig())
    assert r.lines == 12
    assert dict(r.rejects.counts) == {"bad_json": 1, "not_gpsd": 1}
    assert r.rejects.examples["bad_json"][0][1] == 9
    assert r.ignored["gpsd VERSION"] == r.ignored["gpsd SKY"] == r.ignored["gpsd AIS"] == 1
    assert r.ignored["gpsd TPV without fix"] == 1 and r.ignored["blank"] == 1
    pos = r.frames["position"]
    assert list(pos["line"]) == [5, 8] and set(pos["source"]) == {"/dev/ttyUSB0"}
    assert list(pos["quality"]) == [2, 1]  # status 2 (DGPS) -> GGA 2; a plain 2D fix -> 1
    assert pos["lat_rad"].iloc[0] == pytest.approx(math.radians(54.5), abs=1e-15)
    assert pos["lon_rad"].iloc[0] == pytest.approx(math.radians(-18.25), abs=1e-15)
    assert pos["alt_m"].iloc[0] == pytest.approx(10.0)  # altHAE - geoidSep
    gr = r.frames["ground"]
    assert gr["cog_rad"].iloc[0] == pytest.approx(math.pi / 2) and gr["sog_mps"].iloc[0] == 5.0
    h = r.frames["heading"].sort_values("reference")
    assert list(h["reference"]) == ["M", "T"] and set(h["source"]) == {"/dev/ttyS1"}
    assert np.allclose(h["heading_rad"], np.radians([12.0, 10.0]))
    assert (h["time_ns"] == 1714564801500000000).all()
    rot = r.frames["rot"]
    assert rot["rot_radps"].iloc[0] == pytest.approx(math.radians(30.0) / 60.0)


def test_garbage_is_counted_never_raised(tmp_path):
    rng = np.random.default_rng(7)
    good = '{"class":"TPV","mode":3,"time":"2024-05-01T12:00:01Z","lat":1.0,"lon":2.0}'
    rows = [good]
    for _ in range(200):
        b = bytearray(good.encode())
        for _ in range(3):
            b[rng.integers(len(b))] = rng.integers(256)
        rows.append(b.decode("latin-1"))
    rows += ['{"class":"TPV","time":[1],"lat":"x","status":[2],"mode":3}', "{", "[]", "null"]
    p = tmp_path / "damaged.json"
    data = "\n".join(rows).encode("latin-1")
    p.write_bytes(data)
    r = read_gpsd_json(p, IngestConfig())
    assert r.lines == len(data.split(b"\n"))  # a damaged byte may be a line end
    assert r.rejects.total > 0 and len(r.frames["position"]) >= 1


def test_a_line_too_long_is_one_reject_and_the_rest_is_read(tmp_path):
    """A 1 MB line (a crashed logger, a runaway report) is rejected unread as too_long,
    in gpsd JSON and in Signal K deltas alike; the lines around it are kept."""
    from dracc.ingest.signalk_delta import read_signalk_delta

    tpv = (
        '{"class":"TPV","device":"/dev/gps","mode":3,"time":"2024-05-01T10:00:0%dZ",'
        '"lat":54.5,"lon":18.5,"track":90.0,"speed":5.0}'
    )
    huge = '{"class":"TPV","junk":"' + "x" * 1_000_000 + '"}'
    p = tmp_path / "gpsd.json"
    p.write_text("\n".join([tpv % 1, huge, tpv % 2]) + "\n")
    r = read_gpsd_json(p, IngestConfig())
    assert r.rejects.counts == {"too_long": 1} and r.rejects.examples["too_long"][0][1] == 2
    assert len(r.frames["position"]) == 2
    delta = (
        '{"context":"vessels.self","updates":[{"$source":"gps","timestamp":'
        '"2024-05-01T10:00:0%dZ","values":[{"path":"navigation.speedOverGround","value":2.5}]}]}'
    )
    p = tmp_path / "delta.log"
    p.write_text("\n".join([delta % 1, '{"x":"' + "y" * 1_000_000 + '"}', delta % 2]) + "\n")
    r = read_signalk_delta(p, IngestConfig())
    assert r.rejects.counts.get("too_long") == 1
