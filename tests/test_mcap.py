"""MCAP voyage logs: round trips, real files, independent encoders, damaged and cut files."""

from __future__ import annotations

import json
import math
import struct

import numpy as np
import pandas as pd
import pytest
from test_csv import assert_same_frames, voyage_frames

from dracc.core.config import IngestConfig
from dracc.core.errors import IngestError
from dracc.ingest.mcap import read_mcap, topic_role, topic_source
from dracc.sim.mcap_out import NAVSATFIX, write_mcap

CFG = IngestConfig()
ROLES = {"INS2": "ins2", "GYRO": "compass", "LOG": "log"}


def _expected(fr, encoding):
    """What each encoding carries: NavSatFix has no HDOP, and its status maps quality.
    Every message dracc writes is timed by its own stamp, logged at that time: its
    receive time (the log time) is its time."""
    fr = {k: f.assign(recv_ns=f["time_ns"]) for k, f in fr.items()}
    if encoding == "ros2":
        fr = dict(fr)
        p = fr["position"].copy()
        p["hdop"] = np.nan
        fr["position"] = p
    if encoding in ("protobuf",):
        fr = dict(fr)
        p = fr["position"].copy()
        p["hdop"] = np.nan
        p["quality"] = np.int8(1)
        fr["position"] = p
    return fr


@pytest.mark.parametrize("encoding", ["json", "ros2", "protobuf"])
@pytest.mark.parametrize("compression,indexed", [("zstd", True), ("lz4", True), (None, False)])
def test_round_trip_same_frames(tmp_path, encoding, compression, indexed):
    fr = voyage_frames()
    p = write_mcap(
        fr,
        ROLES,
        tmp_path / "v.mcap",
        encoding=encoding,
        compression=compression,
        chunk_size=3000,
        indexed=indexed,
    )
    r = read_mcap(p, CFG)
    assert r.rejects.total == 0, dict(r.rejects.counts)
    assert r.lines == sum(len(f) for f in fr.values())
    assert_same_frames(_expected(fr, encoding), r.frames)


def test_round_trip_raw_nmea(tmp_path):
    pytest.importorskip("dracc.sim.nmea_out")
    fr = voyage_frames()
    fr = {k: fr[k] for k in ("position", "heading", "water")}
    p = write_mcap(fr, ROLES, tmp_path / "n.mcap", encoding="nmea")
    r = read_mcap(p, CFG)
    assert r.format == "mcap"
    # every position/heading/water record comes back from its sentence
    for kind in fr:
        got = r.frames[kind]
        assert len(got) == len(fr[kind]), kind
        # sentence time fields hold hundredths of a second
        dt = np.sort(got["time_ns"].to_numpy()) - np.sort(fr[kind]["time_ns"].to_numpy())
        assert np.abs(dt).max() <= 10_000_000, kind
    pos = r.frames["position"].sort_values("time_ns")
    want = fr["position"].sort_values("time_ns")
    # GGA carries 1e-4 arc-minute resolution or better
    np.testing.assert_allclose(pos["lat_rad"].to_numpy(), want["lat_rad"].to_numpy(), atol=2e-8)
    assert set(r.frames["heading"]["source"].astype(str)) == {"GYRO"}


def test_raw_nmea_parsed_in_chunks_equals_one_parse(tmp_path, monkeypatch):
    """Raw NMEA in MCAP is parsed a chunk of sentences at a time (memory bounded by the
    chunk, not the file): chunks of 7 sentences give the frames, rejects, time events
    and message numbers of one parse over everything."""
    pytest.importorskip("dracc.sim.nmea_out")
    import dracc.ingest.mcap.assembly as mcap_assembly

    fr = voyage_frames()
    fr = {k: fr[k] for k in ("position", "heading", "water")}
    p = write_mcap(fr, ROLES, tmp_path / "n.mcap", encoding="nmea")
    whole = read_mcap(p, CFG)
    monkeypatch.setattr(mcap_assembly, "_NMEA_CHUNK", 7)
    chunked = read_mcap(p, CFG)
    assert chunked.lines == whole.lines and chunked.records == whole.records
    for kind, f in whole.frames.items():
        pd.testing.assert_frame_equal(chunked.frames[kind], f, check_categorical=False)
    assert dict(chunked.rejects.counts) == dict(whole.rejects.counts)
    te_w, te_c = whole.time_events, chunked.time_events
    assert (te_c.duplicates, te_c.backsteps, te_c.gaps) == (
        te_w.duplicates,
        te_w.backsteps,
        te_w.gaps,
    )


def test_topics_give_source_keys_and_roles():
    assert topic_source("/ins2/fix") == "ins2"
    assert topic_source("/ins2/heading") == "ins2"
    assert topic_source("/gyro/heading") == "gyro"
    assert topic_source("/log/water") == "log"
    assert topic_source("rise/v0/ais/nmea0183") == "rise/v0/ais/nmea0183"
    assert topic_source("/fix") == "fix"
    assert [topic_role(k) for k in ("ins2", "gyro", "log", "gps", "camera")] == [
        "ins2",
        "compass",
        "log",
        "gnss",
        None,
    ]


# ----------------------------------------------------------------- independent encoders
def _ros2_writer(path, schema_name, schema_text, topic, msgs):
    from mcap_ros2.writer import Writer

    with open(path, "wb") as fh:
        w = Writer(fh)
        sch = w.register_msgdef(schema_name, schema_text)
        for t, m in msgs:
            w.write_message(topic, sch, m, log_time=t, publish_time=t)
        w.finish()


def test_navsatfix_from_the_stock_ros2_encoder(tmp_path):
    """Messages encoded by mcap-ros2-support (not by dracc), frame_id lengths varying so
    that both the grouped and the one-by-one decoding run."""
    msgs = []
    for i in range(30):
        stamp = {"sec": 1_700_000_000 + i, "nanosec": 250_000_000}
        msgs.append(
            (
                1_800_000_000_000_000_000 + i,
                {
                    "header": {
                        "stamp": stamp if i != 5 else {"sec": 0, "nanosec": 0},
                        "frame_id": "gps" + "x" * (i % 3),
                    },
                    "status": {"status": [-1, 0, 1, 2][i % 4], "service": 1},
                    "latitude": 54.0 + i * 1e-4,
                    "longitude": -18.5,
                    "altitude": 10.0 + i,
                    "position_covariance": [0.0] * 9,
                    "position_covariance_type": 0,
                },
            )
        )
    p = tmp_path / "fix.mcap"
    _ros2_writer(p, "sensor_msgs/msg/NavSatFix", NAVSATFIX, "/gps/fix", msgs)
    r = read_mcap(p, CFG)
    f = r.frames["position"].sort_values("line")
    assert len(f) == 30 and set(f["source"].astype(str)) == {"gps"}
    np.testing.assert_allclose(
        np.degrees(f["lat_rad"].to_numpy()), 54.0 + np.arange(30) * 1e-4, rtol=1e-15
    )
    np.testing.assert_allclose(np.degrees(f["lon_rad"].to_numpy()), -18.5)
    np.testing.assert_allclose(f["alt_m"].to_numpy(), 10.0 + np.arange(30))
    assert f["quality"].tolist() == [[0, 1, 2, 4][i % 4] for i in range(30)]
    t = f["time_ns"].to_numpy()
    assert t[0] == 1_700_000_000_250_000_000  # header stamp, not the log time
    assert t[5] == 1_800_000_000_000_000_005  # zero stamp: log time


QUAT_STAMPED = (
    "std_msgs/Header header\ngeometry_msgs/Quaternion quaternion\n"
    + "=" * 80
    + "\nMSG: geometry_msgs/Quaternion\nfloat64 x\nfloat64 y\nfloat64 z\nfloat64 w\n"
    + "=" * 80
    + "\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
)


def test_heading_from_an_enu_quaternion(tmp_path):
    """REP 103: ENU yaw 0 faces east (heading 90 deg), yaw 90 deg north (0), yaw -90 deg south (180),
    yaw 150 deg -> heading 300 deg; hand values."""
    yaws_deg = [0.0, 90.0, -90.0, 150.0]
    msgs = [
        (
            1_700_000_000_000_000_000 + i,
            {
                "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "imu"},
                "quaternion": {
                    "x": 0.0,
                    "y": 0.0,
                    "z": math.sin(math.radians(y) / 2),
                    "w": math.cos(math.radians(y) / 2),
                },
            },
        )
        for i, y in enumerate(yaws_deg)
    ]
    p = tmp_path / "q.mcap"
    _ros2_writer(p, "geometry_msgs/msg/QuaternionStamped", QUAT_STAMPED, "/gyro/heading", msgs)
    r = read_mcap(p, CFG)
    h = r.frames["heading"].sort_values("line")
    np.testing.assert_allclose(
        np.degrees(h["heading_rad"].to_numpy()), [90.0, 0.0, 180.0, 300.0], atol=1e-9
    )
    assert set(h["source"].astype(str)) == {"gyro"}


def _json_file(path, topic, payloads, schema_name="foxglove.LocationFix", encoding="json"):
    from mcap.writer import Writer

    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        sid = (
            w.register_schema(name=schema_name, encoding="jsonschema", data=b"{}")
            if schema_name
            else 0
        )
        cid = w.register_channel(topic=topic, message_encoding=encoding, schema_id=sid)
        for i, p in enumerate(payloads):
            w.add_message(
                cid,
                log_time=1_700_000_000_000_000_000 + i * 10**9,
                data=p,
                publish_time=1_700_000_000_000_000_000 + i * 10**9,
            )
        w.finish()


def test_json_location_fix_pretty_printed_and_a_bad_message(tmp_path):
    objs = [
        json.dumps(
            {
                "timestamp": {"sec": 1_700_000_100 + i, "nsec": 5},
                "frame_id": "f",
                "latitude": 10.5 + i,
                "longitude": 20.25,
                "altitude": None,
                "position_covariance_type": 0,
            },
            indent=2,
        ).encode()
        for i in range(5)
    ]
    objs.insert(2, b'{"latitude": "north", "longitude": 1}')
    p = tmp_path / "j.mcap"
    _json_file(p, "/gnss/fix", objs)
    r = read_mcap(p, CFG)
    f = r.frames["position"]
    assert len(f) == 5
    assert r.rejects.counts["bad JSON message"] == 1
    assert r.rejects.examples["bad JSON message"][0][1] == 3  # the third message
    np.testing.assert_allclose(np.degrees(f["lat_rad"].to_numpy()), [10.5, 11.5, 12.5, 13.5, 14.5])
    assert f["time_ns"].iloc[0] == 1_700_000_100_000_000_005
    assert f["alt_m"].isna().all()


def test_plain_json_objects_units_from_keys(tmp_path):
    objs = [
        json.dumps(
            {"time_ns": 1_700_000_000_123_456_789 + i, "stw_kn": 10.0, "sog_long_mps": 5.0}
        ).encode()
        for i in range(3)
    ]
    p = tmp_path / "w.mcap"
    _json_file(p, "/log/water", objs, schema_name="dracc.WaterSpeed")
    r = read_mcap(p, CFG)
    w = r.frames["water"]
    np.testing.assert_allclose(w["stw_mps"].to_numpy(), 10 * 1852 / 3600)
    np.testing.assert_allclose(w["sog_long_mps"].to_numpy(), 5.0)
    assert w["time_ns"].tolist() == [1_700_000_000_123_456_789 + i for i in range(3)]  # exact ns


def test_json_sentence_and_text_channels_go_to_the_nmea_parser(tmp_path):
    s = "$GNGGA,092542.00,4846.4008666,N,00854.7249096,E,4,12,0.47,419.166,M,47.535,M,0.0,0000*66"
    p = tmp_path / "s.mcap"
    _json_file(p, "/gnss/nmea", [json.dumps({"sentence": s}).encode()], schema_name="nmea_sentence")
    r = read_mcap(p, CFG)
    assert len(r.frames["position"]) == 1 and r.frames["position"]["source"].iloc[0] == "gnss"
    p2 = tmp_path / "t.mcap"
    _json_file(p2, "/gnss/nmea", [s.encode() + b"\r\n"], schema_name=None, encoding="nmea0183")
    r2 = read_mcap(p2, CFG)
    assert math.degrees(r2.frames["position"]["lat_rad"].iloc[0]) == pytest.approx(
        48 + 46.4008666 / 60
    )


# ----------------------------------------------------------------- real files
def test_real_keelson_raw_nmea_in_protobuf(real_dir):
    r = read_mcap(real_dir / "keelson" / "4a625f9" / "test.mcap", CFG)
    assert r.lines == 2172
    assert any("nmea0183" in n and "raw NMEA" in n for n in r.notes)
    # the 1451 NMEA messages reach the NMEA parser (AIS and VSI: valid sentences it does not
    # use, so ignored by type, not rejected); the 721 JSON messages: ignored by schema
    assert r.rejects.total == 0
    assert r.ignored == {
        "VDM": 703,
        "VDO": 41,
        "VSI": 707,
        "keelson.primitives.TimestampedBytes": 721,
    }
    assert sum(r.ignored.values()) == r.lines
    assert any("not used" in n and "JSON" in n for n in r.notes)


def test_real_keelson_empty_file_says_so(real_dir):
    r = read_mcap(real_dir / "keelson" / "6389403" / "test.mcap", CFG)
    assert r.records == 0 and r.lines == 0
    assert any("no channels" in n and "nothing to read" in n for n in r.notes)


@pytest.mark.parametrize(
    "name,channels",
    [
        ("talker.mcap", ["/rosout", "/parameter_events", "/topic"]),
        ("cdr_test_0.mcap", ["/test_topic", "/array_topic"]),
        ("wrong_rmw_test_0.mcap", ["/test_topic", "/array_topic"]),
        ("test_bag_for_seek_0.mcap", ["topic1"]),
        ("rewriter_b_0.mcap", ["c_strings", "a_empty"]),
        ("only_topics.mcap", ["/rosout", "/parameter_events", "/events/write_split"]),
    ],
)
def test_real_rosbag2_files_report_channels_and_no_navigation_data(real_dir, name, channels):
    r = read_mcap(real_dir / "rosbag2" / name, CFG)
    assert r.records == 0 and r.rejects.total == 0
    assert sum(r.ignored.values()) == r.lines > 0  # every message: valid, of a type not used
    text = "\n".join(r.notes)
    for c in channels:
        assert f"channel {c} [" in text
    assert "no navigation data" in text
    if name == "wrong_rmw_test_0.mcap":
        assert "'wrong_format' not supported" in text


# ----------------------------------------------------------------- damage
def test_not_mcap_and_empty_files_are_clear_errors(tmp_path):
    (tmp_path / "e.mcap").write_bytes(b"")
    with pytest.raises(IngestError, match="empty file"):
        read_mcap(tmp_path / "e.mcap", CFG)
    (tmp_path / "x.mcap").write_bytes(b"$GPGGA,...\r\n")
    with pytest.raises(IngestError, match="not an MCAP file"):
        read_mcap(tmp_path / "x.mcap", CFG)


def _message_ends(data: bytes) -> list[int]:
    """File offsets where each message record ends, walking top-level and (uncompressed)
    chunk records independently of the reader."""
    ends = []
    pos = 8
    while pos + 9 <= len(data):
        op, ln = struct.unpack_from("<BQ", data, pos)
        if op == 5:
            ends.append(pos + 9 + ln)
        elif op == 6:
            clen = struct.unpack_from("<I", data, pos + 9 + 28)[0]
            assert data[pos + 9 + 32 : pos + 9 + 32 + clen] == b""  # uncompressed
            rstart = pos + 9 + 32 + clen + 8
            (rlen,) = struct.unpack_from("<Q", data, rstart - 8)
            q = rstart
            while q < rstart + rlen:
                op2, ln2 = struct.unpack_from("<BQ", data, q)
                if op2 == 5:
                    ends.append(q + 9 + ln2)
                q += 9 + ln2
        elif op in (2, 15):
            break
        pos += 9 + ln
    return ends


def _derived_fixture(tmp_path, real_dir, **kw):
    """Positions from real GGA/RMC sentences (nmea_navsat_driver/nmea.log) written as ROS 2
    NavSatFix: a derived fixture."""
    from dracc.ingest.nmea import parse_sentences

    lines = (real_dir / "nmea_navsat_driver" / "nmea.log").read_bytes().splitlines()[:120]
    t = 1_587_374_742_000_000_000 + np.arange(len(lines), dtype=np.int64) * 250_000_000
    res = parse_sentences(lines, t, ["GNSS"] * len(lines), "nmea.log", CFG)
    fr = {"position": res.frames["position"]}
    assert len(fr["position"]) == 120
    return write_mcap(fr, {"GNSS": "gnss"}, tmp_path / "derived.mcap", **kw), fr


@pytest.mark.parametrize("chunked", [True, False])
def test_cut_files_recover_every_complete_message(tmp_path, real_dir, chunked):
    p, _fr = _derived_fixture(
        tmp_path, real_dir, encoding="ros2", compression=None, chunk_size=2500
    )
    if not chunked:  # rewrite unchunked, from the first file's messages
        from mcap.reader import make_reader
        from mcap.writer import CompressionType, Writer

        q = tmp_path / "unchunked.mcap"
        with open(p, "rb") as src, open(q, "wb") as dst:
            rd = make_reader(src)
            w = Writer(dst, use_chunking=False, compression=CompressionType.NONE)
            w.start()
            ids = {}
            for sch, ch, m in rd.iter_messages():
                if ch.id not in ids:
                    sid = w.register_schema(sch.name, sch.encoding, sch.data)
                    ids[ch.id] = w.register_channel(ch.topic, ch.message_encoding, sid)
                w.add_message(ids[ch.id], m.log_time, m.data, m.publish_time)
            w.finish()
        p = q
    data = p.read_bytes()
    ends = np.asarray(_message_ends(data))
    assert len(ends) == 120
    whole = read_mcap(p, CFG).frames["position"]
    cut = tmp_path / "cut.mcap"
    cuts = np.concatenate([np.linspace(9, len(data) - 1, 41).astype(int), ends[::4] - 1, ends[::4]])
    for k in np.unique(cuts).tolist():
        cut.write_bytes(data[:k])
        r = read_mcap(cut, CFG)  # never raises
        n_complete = int((ends <= k).sum())
        got = r.frames.get("position")
        n_got = 0 if got is None else len(got)
        assert n_got == n_complete, (k, n_got, n_complete)
        if n_got:
            np.testing.assert_array_equal(
                got["lat_rad"].to_numpy(), whole["lat_rad"].to_numpy()[:n_got]
            )
        if k < len(data) - 8:
            assert any("ends at byte" in n or "cut" in n for n in r.notes), (k, r.notes)


def test_cut_compressed_files_never_raise_and_keep_whole_chunks(tmp_path, real_dir):
    p, _ = _derived_fixture(
        tmp_path, real_dir, encoding="json", compression="zstd", chunk_size=3000
    )
    data = p.read_bytes()
    cut = tmp_path / "cut.mcap"
    prev = 0
    for k in np.unique(np.linspace(1, len(data), 60).astype(int)).tolist():
        cut.write_bytes(data[:k])
        try:
            r = read_mcap(cut, CFG)
        except IngestError as err:  # only a cut inside the 8-byte magic is "not MCAP"
            assert k < 8, (k, err)
            continue
        n = r.records
        assert n >= prev, k  # a longer prefix never yields fewer records
        prev = n
    assert prev == 120


def test_garbage_after_valid_records_is_reported(tmp_path, real_dir):
    p, _ = _derived_fixture(tmp_path, real_dir, encoding="ros2", compression="lz4", chunk_size=4000)
    data = bytearray(p.read_bytes())
    ends = []
    pos = 8
    while True:  # find the second chunk and overwrite its opcode
        op, ln = struct.unpack_from("<BQ", data, pos)
        if op == 6:
            ends.append(pos)
            if len(ends) == 2:
                break
        pos += 9 + ln
    data[ends[1]] = 0x00
    q = tmp_path / "bad.mcap"
    q.write_bytes(bytes(data))
    r = read_mcap(q, CFG)
    assert 0 < r.records < 120
    assert any("invalid record opcode 0x00" in n for n in r.notes)


def test_non_indexed_copy_reads_like_the_indexed_file(tmp_path, real_dir):
    p, fr = _derived_fixture(
        tmp_path, real_dir, encoding="ros2", compression="zstd", chunk_size=3000
    )
    q = tmp_path / "noindex.mcap"
    write_mcap(fr, {}, q, encoding="ros2", compression="zstd", chunk_size=3000, indexed=False)
    a, b = read_mcap(p, CFG), read_mcap(q, CFG)
    assert_same_frames(a.frames, b.frames, rtol=0)


# ----------------------------------------------------------------- one voyage, every container
def test_one_simulated_voyage_reads_the_same_from_every_container(tmp_path):
    """The simulator's voyage written as NMEA, CSV (long, wide) and MCAP (JSON, ROS 2,
    protobuf, raw NMEA) and read through ``read_logs``: the same records per source and
    kind, the same roles, the same values (to the resolution of NMEA sentence fields)."""
    from dracc.ingest import read_logs
    from dracc.sim.csv_out import write_csv
    from dracc.sim.model import simulate
    from dracc.sim.nmea_out import write_nmea
    from dracc.sim.params import SimParams

    v = simulate(SimParams(duration_s=300, compass_hz=1))
    paths = {"nmea": tmp_path / "v.nmea"}
    write_nmea(v, paths["nmea"])
    for form in ("long", "wide"):
        paths[f"csv-{form}"] = write_csv(v.frames, tmp_path / f"v_{form}.csv", form)
    for enc in ("json", "ros2", "protobuf", "nmea"):
        paths[f"mcap-{enc}"] = write_mcap(
            v.frames, v.roles, tmp_path / f"v_{enc}.mcap", encoding=enc
        )
    coarse = {
        "lat_rad": 1e-8,
        "lon_rad": 1e-8,
        "heading_rad": 2e-5,
        "cog_rad": 2e-4,
        "sog_mps": 3e-3,
        "stw_mps": 3e-3,
    }
    for name, p in paths.items():
        voy = read_logs([p], CFG)
        assert voy.rejects.total == 0, (name, dict(voy.rejects.counts))
        assert {k: s.role for k, s in voy.sources.items()} == dict(v.roles.items()), name
        exact = name in ("csv-long", "csv-wide", "mcap-json", "mcap-ros2", "mcap-protobuf")
        for kind, want in v.frames.items():
            got = voy.frames[kind]
            assert len(got) == len(want), (name, kind)
            for src, w in want.groupby(want["source"].astype(str), observed=True):
                g = got[got["source"].astype(str) == src]
                assert len(g) == len(w), (name, kind, src)
                cols = (
                    [c for c in w.columns if w[c].dtype.kind == "f"]
                    if exact
                    else [c for c in coarse if c in w.columns]
                )
                for c in cols:
                    a, b = np.sort(w[c].to_numpy()), np.sort(g[c].to_numpy())
                    if exact and name == "mcap-ros2" and c == "hdop":
                        continue  # NavSatFix carries no HDOP
                    if exact and name == "mcap-protobuf" and c == "hdop":
                        continue  # foxglove.LocationFix carries no HDOP
                    np.testing.assert_allclose(
                        b,
                        a,
                        rtol=1e-12 if exact else 0,
                        atol=1e-12 if exact else coarse[c],
                        equal_nan=True,
                        err_msg=f"{name} {kind} {src} {c}",
                    )


@pytest.mark.parametrize(
    "encoding,compression,indexed",
    [("json", "zstd", True), ("ros2", None, False), ("protobuf", "lz4", True)],
)
def test_random_byte_damage_never_raises(tmp_path, encoding, compression, indexed):
    """Regression: corrupt log times (> int64), chunk lengths (MemoryError) and schema
    text once escaped as OverflowError/MemoryError/parser prints."""
    p = write_mcap(
        voyage_frames(30),
        {},
        tmp_path / "v.mcap",
        encoding=encoding,
        compression=compression,
        chunk_size=3000,
        indexed=indexed,
    )
    data = p.read_bytes()
    rng = np.random.default_rng(7)
    q = tmp_path / "d.mcap"
    for _ in range(40):
        d = bytearray(data)
        for i in rng.integers(8, len(d), rng.integers(1, 6)):
            d[i] = rng.integers(0, 256)
        q.write_bytes(bytes(d))
        r = read_mcap(q, CFG)
        assert r.lines <= 180


def test_topic_named_in_config_is_its_own_source_key(tmp_path):
    fr = voyage_frames(5)
    p = write_mcap({"position": fr["position"]}, {}, tmp_path / "v.mcap", encoding="json")
    r = read_mcap(p, IngestConfig(sources={"/INS2/fix": "ins1"}))
    assert set(r.frames["position"]["source"].astype(str)) == {"/INS2/fix"}
    assert set(read_mcap(p, CFG).frames["position"]["source"].astype(str)) == {"INS2"}


# ---------------------------------------------------------------- bounded-memory store
def _random_pieces(rng, n_pieces, sources):
    """Canonical-looking heading pieces with many equal times and equal (time, line) keys."""
    import pandas as pd

    pieces = []
    for _ in range(n_pieces):
        n = int(rng.integers(0, 40))
        t = rng.integers(0, 30, n).astype(np.int64) * 1_000_000_000
        if rng.random() < 0.5:
            t = np.sort(t)  # most pieces arrive sorted, some not
        src = rng.choice(sources, n)
        ref = rng.choice(np.array(["T", "M", None], dtype=object), n)
        pieces.append(
            pd.DataFrame(
                {
                    "time_ns": t,
                    "source": pd.Categorical(src),
                    "line": rng.integers(1, 6, n).astype(np.int64),
                    "heading_rad": rng.uniform(0, 2 * math.pi, n),
                    "quality": rng.integers(0, 5, n).astype(np.int8),
                    "reference": ref,
                }
            )
        )
    return pieces


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("step", [1, 3, 17, 1 << 16])
def test_store_merge_equals_a_stable_sort_of_all_pieces(seed, step):
    """The runs merged step by step give exactly the stable (time_ns, line) sort of the
    pieces concatenated in the order they were added (ties included)."""
    import pandas as pd

    from dracc.ingest.mcap.columns import _KindStore

    rng = np.random.default_rng(seed)
    pieces = _random_pieces(rng, int(rng.integers(1, 12)), np.array(["INS1", "GYRO", "INS2", "A"]))
    store = _KindStore(step=step)
    for p in pieces:
        store.add(p)
    got = store.frame()
    assert store.runs == [] and store.total == 0  # everything released
    allp = pd.concat([p.astype({"source": object}) for p in pieces], ignore_index=True)
    order = np.lexsort((allp["line"].to_numpy(), allp["time_ns"].to_numpy()))
    want = allp.iloc[order].reset_index(drop=True)
    assert len(got) == len(want)
    for c in ("time_ns", "line", "heading_rad", "quality"):
        np.testing.assert_array_equal(got[c].to_numpy(), want[c].to_numpy())
        assert got[c].dtype == pieces[0][c].dtype
    assert list(got["source"].astype(object)) == list(want["source"])
    assert list(got["source"].cat.categories) == sorted(set(want["source"]))  # sorted categories
    assert got["reference"].dtype == pieces[0]["reference"].dtype
    assert [None if pd.isna(x) else x for x in got["reference"]] == [
        None if pd.isna(x) else x for x in want["reference"]
    ]


def test_store_codes_widen_past_127_labels():
    """More labels than int8 codes hold: codes widen, every label stays right."""
    import pandas as pd

    from dracc.ingest.mcap.columns import _KindStore

    store = _KindStore(step=50)
    names = [f"S{i:03d}" for i in range(300)]
    for k in range(3):  # the first pieces' runs have int8 codes, later ones int16
        sub = names[k * 100 : (k + 1) * 100]
        store.add(
            pd.DataFrame(
                {
                    "time_ns": np.arange(100, dtype=np.int64)[::-1] * 10 + k,
                    "source": pd.Categorical(sub),
                    "line": np.arange(100, dtype=np.int64),
                }
            )
        )
    got = store.frame()
    assert got["source"].cat.codes.dtype == np.int16
    want = {
        (t, n)
        for k in range(3)
        for t, n in zip(np.arange(100)[::-1] * 10 + k, names[k * 100 : (k + 1) * 100], strict=True)
    }
    assert (
        set(zip(got["time_ns"].tolist(), got["source"].astype(str).tolist(), strict=True)) == want
    )
    assert (np.diff(got["time_ns"].to_numpy()) > 0).all()


def test_mapped_columns_are_separate_writable_and_sized():
    from dracc.ingest.memory import mapped_columns

    a, b, c = mapped_columns(1001, [np.int16, np.float64, np.int8])
    a[:] = np.arange(1001)
    b[:] = -1.5
    c[:] = 7
    assert [x.dtype for x in (a, b, c)] == [np.int16, np.float64, np.int8]
    assert all(len(x) == 1001 and x.flags.writeable and x.ctypes.data % 64 == 0 for x in (a, b, c))
    assert a[1000] == 1000 and (b == -1.5).all() and (c == 7).all()  # no column overlaps another
    assert [len(x) for x in mapped_columns(0, [np.float64, np.int8])] == [0, 0]


@pytest.mark.parametrize("encoding", ["json", "ros2"])
def test_frames_do_not_depend_on_piece_and_queue_sizes(tmp_path, monkeypatch, encoding):
    """Tiny budgets (pieces of 7 records, queues of 5 JSON messages over all channels,
    the C heap trimmed after every piece) give the same frames as the defaults."""
    import pandas as pd

    import dracc.ingest.mcap.assembly as mc_assembly
    import dracc.ingest.mcap.json_messages as mc_json

    fr = voyage_frames(n=300)
    p = write_mcap(fr, ROLES, tmp_path / "v.mcap", encoding=encoding, chunk_size=1 << 12)
    want = read_mcap(p, CFG)
    monkeypatch.setattr(mc_assembly, "_PIECE_RECORDS", 7)
    monkeypatch.setattr(mc_assembly, "_PENDING_RECORDS", 11)
    monkeypatch.setattr(mc_json, "_JSON_BATCH", 5)
    monkeypatch.setattr(mc_json, "_JSON_QUEUED", 5)
    monkeypatch.setattr(mc_assembly, "_TRIM_RECORDS", 1)
    got = read_mcap(p, CFG)
    assert want.frames.keys() == got.frames.keys() and want.notes == got.notes
    for kind, f in want.frames.items():
        pd.testing.assert_frame_equal(f, got.frames[kind])


# ----------------------------------------------------------------- receive time, ignored
MISSING = np.iinfo(np.int64).min
T0_NS = 1_700_000_000_000_000_000  # 2023-11-14T22:13:20Z
GGA_T0 = "$GPGGA,221320.00,5436.0,N,01847.0,E,1,10,0.8,25.0,M,,M,,*"
NMEA_SENTENCE = (
    "std_msgs/Header header\nstring sentence\n"
    + "=" * 80
    + "\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
)


def _cs(sentence: str) -> str:
    x = 0
    for b in sentence[1:-1].encode():
        x ^= b
    return f"{sentence}{x:02X}"


def test_recv_ns_is_the_log_time_of_stamped_messages(tmp_path):
    """NavSatFix timed by its header stamp, logged 1.5 s later: recv_ns is the log time; a
    message with a zero stamp is timed by its log time and has no receive time."""
    msgs = []
    for i in range(4):
        stamp = {"sec": 1_700_000_000 + i, "nanosec": 0} if i != 2 else {"sec": 0, "nanosec": 0}
        msgs.append(
            (
                T0_NS + i * 10**9 + 1_500_000_000,
                {
                    "header": {"stamp": stamp, "frame_id": "gps"},
                    "status": {"status": 0, "service": 1},
                    "latitude": 54.0,
                    "longitude": -18.5,
                    "altitude": 10.0,
                    "position_covariance": [0.0] * 9,
                    "position_covariance_type": 0,
                },
            )
        )
    p = tmp_path / "fix.mcap"
    _ros2_writer(p, "sensor_msgs/msg/NavSatFix", NAVSATFIX, "/gps/fix", msgs)
    f = read_mcap(p, CFG).frames["position"].sort_values("line")
    assert f["time_ns"].tolist() == [T0_NS, T0_NS + 10**9, T0_NS + 3_500_000_000, T0_NS + 3 * 10**9]
    assert f["recv_ns"].tolist() == [
        T0_NS + 1_500_000_000,
        T0_NS + 2_500_000_000,
        MISSING,
        T0_NS + 4_500_000_000,
    ]


def test_recv_ns_of_json_messages_with_their_own_time(tmp_path):
    objs = [
        json.dumps(
            {"timestamp": {"sec": 1_699_999_999, "nsec": 0}, "latitude": 10.5, "longitude": 20.25}
        ).encode()
    ]
    p = tmp_path / "j.mcap"
    _json_file(p, "/gnss/fix", objs)  # logged at T0
    f = read_mcap(p, CFG).frames["position"]
    assert f["time_ns"].tolist() == [T0_NS - 10**9] and f["recv_ns"].tolist() == [T0_NS]
    objs = [
        json.dumps({"time_ns": T0_NS - 250_000_000, "stw_kn": 10.0}).encode(),
        json.dumps({"stw_kn": 11.0}).encode(),
    ]
    p = tmp_path / "w.mcap"
    _json_file(p, "/log/water", objs, schema_name="dracc.WaterSpeed")
    w = read_mcap(p, CFG).frames["water"].sort_values("line")
    assert w["time_ns"].tolist() == [T0_NS - 250_000_000, T0_NS + 10**9]
    assert w["recv_ns"].tolist() == [T0_NS, MISSING]  # the second: timed by its log time


def test_recv_ns_of_raw_nmea_is_the_log_time(tmp_path):
    """Raw sentences: the fix is anchored as before (to the message stamp where there is
    one); the receive time is the MCAP log time.  A sentence without a time of fix has none."""
    p = tmp_path / "s.mcap"
    _json_file(
        p,
        "/gnss/nmea",
        [
            json.dumps({"sentence": _cs(GGA_T0)}).encode(),
            json.dumps({"sentence": _cs("$HEHDT,10.0,T*")}).encode(),
        ],
    )
    r = read_mcap(p, CFG)  # logged at T0 and T0 + 1 s
    pos = r.frames["position"]
    assert pos["time_ns"].tolist() == [T0_NS] and pos["recv_ns"].tolist() == [T0_NS]
    assert r.frames["heading"]["recv_ns"].tolist() == [MISSING]
    msgs = [
        (
            T0_NS + 1_500_000_000,
            {
                "header": {
                    "stamp": {"sec": 1_700_000_001, "nanosec": 200_000_000},
                    "frame_id": "gps",
                },
                "sentence": _cs(GGA_T0),
            },
        )
    ]
    p2 = tmp_path / "cdr.mcap"
    _ros2_writer(p2, "nmea_msgs/msg/Sentence", NMEA_SENTENCE, "/gps/nmea", msgs)
    pos = read_mcap(p2, CFG).frames["position"]
    assert pos["time_ns"].tolist() == [T0_NS] and pos["recv_ns"].tolist() == [T0_NS + 1_500_000_000]


def test_channels_not_decoded_are_ignored_by_schema(tmp_path):
    """Messages on a channel dracc does not decode (JSON without navigation fields, an
    unknown encoding) are valid input: ignored by schema name, not rejected; unused raw
    sentences by sentence type."""
    from mcap.writer import Writer

    p = tmp_path / "m.mcap"
    with open(p, "wb") as fh:
        w = Writer(fh)
        w.start()
        s1 = w.register_schema(name="acme.Camera", encoding="jsonschema", data=b"{}")
        c1 = w.register_channel(topic="/camera", message_encoding="json", schema_id=s1)
        s2 = w.register_schema(name="acme.Blob", encoding="flatbuffer", data=b"")
        c2 = w.register_channel(topic="/blob", message_encoding="flatbuffer", schema_id=s2)
        c3 = w.register_channel(topic="/gps/nmea", message_encoding="nmea0183", schema_id=0)
        for i in range(3):
            t = T0_NS + i * 10**9
            w.add_message(c1, log_time=t, data=json.dumps({"exposure": i}).encode(), publish_time=t)
            w.add_message(c2, log_time=t, data=b"\x00\x01", publish_time=t)
            w.add_message(
                c3, log_time=t, data=_cs("$GPGSV,1,1,01,05,40,083,46*").encode(), publish_time=t
            )
        w.add_message(c3, log_time=T0_NS, data=_cs(GGA_T0).encode(), publish_time=T0_NS)
        w.finish()
    r = read_mcap(p, CFG)
    assert r.rejects.total == 0 and len(r.frames["position"]) == 1
    assert r.ignored == {"acme.Camera": 3, "acme.Blob": 3, "GSV": 3}
    from dracc.ingest import read_logs

    v = read_logs([p], CFG)
    assert v.ignored == r.ignored and v.inputs[0]["ignored"] == dict(r.ignored)
    assert read_mcap(p, IngestConfig(strict=True)).ignored == r.ignored  # never a --strict failure
