"""NMEA 2000 navigation PGN decoding (dracc.ingest.n2k.pgns), NAME source keys (names) and
the N2K result and reader (reader): against canboat's analyzer and the nmea2000 package.

The literal values are canboat analyzer 8.0 ``-json`` output for the real logs (its
printing precision: headings and angles 0.1 deg, lat/lon 1e-7 deg, speeds 0.01 m/s, ROT
1e-6 deg/s); the cross-checks decode every navigation message again with nmea2000
(canboat's database, Python bindings) at full precision.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import real_path

from dracc.core.config import IngestConfig
from dracc.ingest.n2k.messages import TIME_OF_DAY, TIME_RELATIVE, TIME_UTC, Messages
from dracc.ingest.n2k.names import name_fields, name_keys, source_keys
from dracc.ingest.n2k.pgns import decode
from dracc.ingest.n2k.reader import n2k_result
from dracc.ingest.timebase import ASSUMED_DATE_DAYS, ASSUMED_DATE_NOTE, days_from_civil

DEG = math.pi / 180
DAY_NS = 86_400 * 10**9
#: the fast-packet PGNs among the navigation ones: a PLAIN line of at most 8 bytes of
#: these is one frame of a message (not used by the helper below), a longer one whole
FAST = {129029, 128275}


def plain_messages(path: Path) -> tuple[Messages, list[str]]:
    """Messages of the whole-message lines of a canboat PLAIN log (comments and the
    frames of fast packets left out), and the lines themselves."""
    return _plain(str(path))


@functools.lru_cache(maxsize=8)
def _plain(path: str) -> tuple[Messages, list[str]]:
    cols: list[list[int]] = [[] for _ in range(7)]
    payload = bytearray()
    texts = []
    for i, line in enumerate(Path(path).read_text().splitlines(), 1):
        f = line.strip().split(",")
        if line.startswith("#") or len(f) < 7:
            continue
        pgn, n = int(f[2]), int(f[5])
        if n <= 8 and pgn in FAST:
            continue
        t = int(np.datetime64(f[0].rstrip("Z"), "ns").astype(np.int64))
        for c, v in zip(cols, (t, i, int(f[1]), pgn, int(f[3]), int(f[4]), n), strict=True):
            c.append(v)
        payload += bytes(int(x, 16) for x in f[6 : 6 + n])
        texts.append(line.strip())
    return messages(*cols, payload=bytes(payload)), texts


def messages(t, line, prio, pgn, src, dst, length, payload: bytes, kind=TIME_UTC) -> Messages:
    length = np.asarray(length, dtype=np.int64)
    return Messages(
        time_ns=np.asarray(t, dtype=np.int64),
        line=np.asarray(line, dtype=np.int64),
        prio=np.asarray(prio, dtype=np.uint8),
        pgn=np.asarray(pgn, dtype=np.int64),
        src=np.asarray(src, dtype=np.uint8),
        dst=np.asarray(dst, dtype=np.uint8),
        start=np.concatenate(([0], np.cumsum(length)[:-1])).astype(np.int64),
        length=length,
        payload=np.frombuffer(payload, dtype=np.uint8),
        time_kind=kind,
    )


def synth(rows: list[tuple[int, int, str]], t0: int = 1_600_000_000 * 10**9, kind=TIME_UTC):
    """Messages from (pgn, src, hex payload) rows, 0.1 s apart, lines 1..n."""
    pay = [bytes.fromhex(h) for _p, _s, h in rows]
    n = len(rows)
    return messages(
        [t0 + k * 10**8 for k in range(n)],
        range(1, n + 1),
        [2] * n,
        [p for p, _s, _h in rows],
        [s for _p, s, _h in rows],
        [255] * n,
        [len(b) for b in pay],
        b"".join(pay),
        kind,
    )


@functools.lru_cache(maxsize=8)
def _result(path: str):
    m, _ = _plain(path)
    return n2k_result(m, path, "plain", IngestConfig())


def result(*parts: str):
    return _result(str(real_path(*parts)))


def at(res, kind: str, line: int):
    df = res.frames[kind]
    row = df[df["line"] == line]
    assert len(row) == 1, (kind, line)
    return row.iloc[0]


def utc(s: str) -> int:
    return int(np.datetime64(s, "ns").astype(np.int64))


# ------------------------------------------------------------------ canboat's values
def test_aava_values_equal_canboat():
    r = result("signalk-server", "aava-n2k.data")
    p = at(r, "position", 1)  # 129029
    assert p["sentence"] == "PGN129029" and p["talker"] == ""
    assert p["lat_rad"] / DEG == pytest.approx(59.7250108, abs=5e-8)
    assert p["lon_rad"] / DEG == pytest.approx(24.7366770, abs=5e-8)
    assert p["alt_m"] == pytest.approx(2.32, abs=5e-7)
    assert p["hdop"] == pytest.approx(0.80, abs=1e-9)
    assert p["quality"] == 1  # Method "GNSS fix"
    # its own time of fix (Date 2014.08.15, Time 18:59:59.4620); the frame time is recv_ns
    assert p["time_ns"] == utc("2014-08-15T18:59:59.462")
    assert p["recv_ns"] == utc("2014-08-15T19:00:00.042")
    p = at(r, "position", 24)  # 129025
    assert p["sentence"] == "PGN129025" and p["quality"] == -1
    assert p["lat_rad"] / DEG == pytest.approx(59.7249807, abs=5e-8)
    assert p["lon_rad"] / DEG == pytest.approx(24.7366563, abs=5e-8)
    assert p["time_ns"] == utc("2014-08-15T19:00:00.540")
    g = at(r, "ground", 32)  # 129026, COG reference True
    assert g["cog_rad"] / DEG == pytest.approx(196.5, abs=0.05)
    assert g["sog_mps"] == pytest.approx(3.47, abs=5e-3)
    h = at(r, "heading", 74)  # 127250
    assert h["heading_rad"] / DEG == pytest.approx(201.1, abs=0.05)
    assert h["variation_rad"] / DEG == pytest.approx(8.1, abs=0.05)
    assert h["reference"] == "T" and math.isnan(h["deviation_rad"])
    w = at(r, "water", 3)  # 128259 water referenced
    assert w["stw_mps"] == pytest.approx(3.34, abs=5e-3) and math.isnan(w["sog_long_mps"])
    w = at(r, "water", 16)  # 128259 ground referenced only (from the GNSS, src 160)
    assert math.isnan(w["stw_mps"]) and w["sog_long_mps"] == pytest.approx(3.45, abs=5e-3)
    d = at(r, "distance", 11)  # 128275
    assert (d["total_water_m"], d["trip_water_m"]) == (17441025.0, 79951.0)


# canboat analyzer -json: records per navigation PGN
CANBOAT_COUNTS = {
    ("signalk-server", "aava-n2k.data"): {
        129025: 597, 129029: 597, 129026: 596, 127250: 596, 128259: 1798, 128275: 602,
    },
    ("canboat", "scx20.raw"): {129025: 262, 129029: 23, 129026: 106, 127250: 246, 127251: 265},
    ("canboat", "susteranna2020.raw"): {
        129025: 244, 129029: 27, 129026: 172, 127250: 396, 127251: 536, 128259: 129,
        128275: 22,
    },
}  # fmt: skip


@pytest.mark.parametrize("parts", list(CANBOAT_COUNTS))
def test_record_counts_equal_canboat(parts):
    r = result(*parts)
    got = {}
    for df in r.frames.values():
        for s, n in df["sentence"].value_counts().items():
            if n:
                got[int(str(s)[3:])] = int(n)
    assert got == CANBOAT_COUNTS[parts]
    assert r.rejects.total == 0


def test_aava_ignored_counted_by_pgn():
    r = result("signalk-server", "aava-n2k.data")
    assert r.ignored["PGN130306"] == 617  # wind
    assert r.ignored["PGN65370"] == 2538  # Raymarine proprietary
    assert r.ignored["PGN128267"] == 599  # depth
    assert "PGN126992" not in r.ignored and "PGN129029" not in r.ignored
    assert r.ignored_examples["PGN130306"][0][1] > 0
    assert sum(r.ignored.values()) + r.records + 597 == 21595  # + the 126992 time messages


def test_scx20_rot_variation_dops_and_fix_time():
    r = result("canboat", "scx20.raw")
    assert at(r, "rot", 8)["rot_radps"] / DEG == pytest.approx(-0.200942, abs=5e-7)
    h = at(r, "heading", 5)
    assert h["heading_rad"] / DEG == pytest.approx(87.0, abs=0.05)
    assert h["variation_rad"] / DEG == pytest.approx(-11.0, abs=0.05)
    assert h["reference"] == "T"
    p = at(r, "position", 95)  # 129029, Method DGNSS fix, HDOP 0.50, Time 23:33:55.5
    assert p["quality"] == 2 and p["hdop"] == pytest.approx(0.5)
    assert p["lat_rad"] / DEG == pytest.approx(12.5095854, abs=5e-8)
    assert p["lon_rad"] / DEG == pytest.approx(-70.0328156, abs=5e-8)
    assert p["alt_m"] == pytest.approx(-22.287309, abs=5e-7)
    assert p["time_ns"] == utc("2021-01-27T23:33:55.500")
    assert p["recv_ns"] == utc("2021-01-27T23:33:54.437")
    p = at(r, "position", 13)  # 129025 given the HDOP of the 129539 at line 7 (0.50)
    assert p["lat_rad"] / DEG == pytest.approx(12.5095866, abs=5e-8)
    assert p["hdop"] == pytest.approx(0.5)
    g = at(r, "ground", 31)
    assert g["cog_rad"] / DEG == pytest.approx(198.6, abs=0.05)
    assert g["sog_mps"] == pytest.approx(0.26, abs=5e-3)


def test_susteranna_magnetic_references():
    r = result("canboat", "susteranna2020.raw")
    h = at(r, "heading", 28)  # 342.5 magnetic, no variation: the first 127258's (1.5 E)
    assert h["reference"] == "M"
    assert h["heading_rad"] / DEG == pytest.approx(342.5, abs=0.05)
    assert h["variation_rad"] / DEG == pytest.approx(1.5, abs=0.05)
    h = at(r, "heading", 43)  # carries its own variation 1.5
    assert h["variation_rad"] / DEG == pytest.approx(1.5, abs=0.05)
    g = at(r, "ground", 41)  # COG 97.3 referenced to magnetic north: not used; SOG 0.00
    assert math.isnan(g["cog_rad"]) and g["sog_mps"] == 0.0
    assert any("magnetic north not used" in n for n in r.notes)
    assert at(r, "rot", 27)["rot_radps"] / DEG == pytest.approx(-0.003384, abs=5e-7)
    assert at(r, "rot", 36)["rot_radps"] / DEG == pytest.approx(0.037992, abs=5e-7)
    d = at(r, "distance", 307)
    assert (d["total_water_m"], d["trip_water_m"]) == (2307966.0, 1288462.0)
    assert at(r, "water", 107)["stw_mps"] == 0.0
    w = at(r, "water", 72)  # canboat: no fields at all
    assert math.isnan(w["stw_mps"]) and math.isnan(w["sog_long_mps"])
    p = at(r, "position", 424)
    assert p["lat_rad"] / DEG == pytest.approx(53.1750618, abs=5e-8)
    assert p["time_ns"] == utc("2020-08-22T13:52:40.000")
    # two GNSS receivers (addresses 18 and 127) and a heading source are told apart
    assert {"n2k:addr18", "n2k:addr127"} <= set(r.frames["position"]["source"])


# ------------------------------------------------------------ nmea2000 cross-check
#: PGN -> (kind, [(nmea2000 field id, our column, nmea2000 unit -> ours)])
FIELDS = {
    129025: ("position", [("latitude", "lat_rad", DEG), ("longitude", "lon_rad", DEG)]),
    129029: ("position", [("latitude", "lat_rad", DEG), ("longitude", "lon_rad", DEG),
                          ("altitude", "alt_m", 1.0), ("hdop", "hdop", 1.0)]),
    129026: ("ground", [("cog", "cog_rad", 1.0), ("sog", "sog_mps", 1.0)]),
    127250: ("heading", [("heading", "heading_rad", 1.0), ("deviation", "deviation_rad", 1.0),
                         ("variation", "variation_rad", 1.0)]),
    127251: ("rot", [("rate", "rot_radps", 1.0)]),
    128259: ("water", [("speedWaterReferenced", "stw_mps", 1.0),
                       ("speedGroundReferenced", "sog_long_mps", 1.0)]),
    128275: ("distance", [("log", "total_water_m", 1.0), ("tripLog", "trip_water_m", 1.0)]),
}  # fmt: skip


@pytest.mark.parametrize(
    "parts",
    [("signalk-server", "aava-n2k.data"), ("canboat", "scx20.raw"),
     ("canboat", "susteranna2020.raw")],
)  # fmt: skip
def test_every_navigation_message_equals_nmea2000(parts):
    dec_mod = pytest.importorskip("nmea2000.decoder")
    path = real_path(*parts)
    m, texts = plain_messages(path)
    r = result(*parts)
    decoder = dec_mod.NMEA2000Decoder()
    by_line = {k: df.set_index("line") for k, df in r.frames.items()}
    checked = 0
    for text, line, pgn in zip(texts, m.line.tolist(), m.pgn.tolist(), strict=True):
        if pgn not in FIELDS:
            continue
        kind, fields = FIELDS[pgn]
        msg = decoder.decode(text)
        vals = {f.id: f.value for f in msg.fields}
        row = by_line[kind].loc[line]
        for fid, col, scale in fields:
            ours = float(row[col])
            theirs = vals.get(fid)
            if pgn == 127250 and col == "variation_rad" and theirs is None:
                continue  # filled from 127258 (tested above)
            if pgn == 129026 and col == "cog_rad" and vals.get("cogReference") != "True":
                assert math.isnan(ours)
                continue
            if theirs is None:
                assert math.isnan(ours), (line, fid)
            else:
                assert ours == pytest.approx(float(theirs) * scale, rel=1e-12, abs=1e-12), (
                    line,
                    fid,
                )
        if pgn == 129029:
            method = next(f.raw_value for f in msg.fields if f.id == "method")
            assert row["quality"] == method
        if pgn == 127250:
            ref = vals.get("reference")
            assert (row["reference"] if isinstance(row["reference"], str) else None) == (
                {"True": "T", "Magnetic": "M"}.get(ref)
            )
        checked += 1
    assert checked == sum(CANBOAT_COUNTS[parts].values())


def test_not_available_values_are_nan_as_nmea2000():
    dec_mod = pytest.importorskip("nmea2000.decoder")
    rows = [
        (127250, 1, "FFFCFFFD7F0000FF"),  # heading 0xFFFC (valid: rejected, >= 360 deg)
        (127250, 1, "FFFFFFFD7F0010FC"),  # heading n/a, deviation n/a, variation 0.4096
        (128259, 1, "FFFBFFFDFFFFFFFF"),  # STW 0xFFFB = 655.31 (valid: rejected), SOG n/a
        (128259, 1, "00FDFFE803FFFFFF"),  # STW n/a, SOG 10.00
        (129025, 1, "FDFFFF7FFCFFFF7F"),  # lat n/a, lon 0x7FFFFFFC valid (rejected)
        (129025, 1, "FFFFFF7F00000000"),  # lat n/a, lon 0
        (127251, 1, "FFFDFFFF7FFFFFFF"),  # rate n/a
    ]
    m = synth(rows)
    res = n2k_result(m, "x", "plain", IngestConfig())
    d = dec_mod.NMEA2000Decoder()
    for k, (pgn, _s, h) in enumerate(rows):
        body = ",".join(h[i : i + 2] for i in range(0, 16, 2))
        text = f"2020-09-13T12:26:40.000Z,2,{pgn},1,255,8,{body}"
        vals = {f.id: f.value for f in d.decode(text).fields}
        kind, fields = FIELDS[pgn]
        df = res.frames[kind].set_index("line")
        if k + 1 not in df.index:
            continue  # rejected (below)
        for fid, col, scale in fields:
            ours = float(df.loc[k + 1, col])
            if vals[fid] is None:
                assert math.isnan(ours), (k, fid)
            else:
                assert ours == pytest.approx(vals[fid] * scale), (k, fid)
    assert res.rejects.counts == {
        "implausible_heading": 1,
        "implausible_speed": 1,
        "implausible_position": 1,
    }
    assert res.rejects.examples["implausible_position"][0][1] == 5
    assert "PGN129025 src 1: FD FF FF 7F" in res.rejects.examples["implausible_position"][0][2]
    assert len(res.frames["heading"]) == 1 and len(res.frames["rot"]) == 1
    assert math.isnan(res.frames["rot"]["rot_radps"].iloc[0])


def test_short_payload_rejected_and_missing_tail_nan():
    m = synth([(127250, 3, "00"), (127250, 3, "001027"), (129029, 3, "00" * 10)])
    res = n2k_result(m, "x", "plain", IngestConfig())
    assert res.rejects.counts == {"n2k_short_payload": 2}
    h = res.frames["heading"].iloc[0]
    assert h["heading_rad"] == pytest.approx(1.0)  # 0x2710 x 1e-4 rad
    assert math.isnan(h["deviation_rad"]) and math.isnan(h["variation_rad"])
    assert h["reference"] != h["reference"]  # NaN: unknown


# --------------------------------------------------------------------- NAMEs, sources
#: candumpSample3.txt lines 588 and 597 (18EEFFCC#..., 18EEFF00#...), canboat's decode
CLAIMS = [
    ("1FEE72E7359650C0", 1240607, 1851, 5, 6, 150, 40, 0, 4),  # Raymarine autopilot
    ("9DE06FE71C96A0C0", 1040541, 1851, 4, 3, 150, 80, 0, 4),  # Raymarine instrument
]


def test_name_fields_equal_canboat():
    for h, uniq, mfr, lo, up, _f, cls, sysi, ind in CLAIMS:
        name = np.frombuffer(bytes.fromhex(h), dtype="<u8")
        f = {k: int(v[0]) for k, v in name_fields(name).items()}
        assert (f["unique_number"], f["manufacturer_code"]) == (uniq, mfr)
        assert (f["device_instance_lower"], f["device_instance_upper"]) == (lo, up)
        assert (f["device_class"], f["system_instance"], f["industry_group"]) == (cls, sysi, ind)
        assert f["arbitrary_address_capable"] == 1
    key = int(np.frombuffer(bytes.fromhex(CLAIMS[0][0]), "<u8")[0])
    assert name_keys([key]) == {key: "n2k:1851-1240607"}


def test_name_fields_equal_nmea2000_iso_name():
    cb = pytest.importorskip("nmea2000._canboat")
    rng = np.random.default_rng(7)
    for _ in range(200):
        kw = {
            "unique_number": int(rng.integers(0, 1 << 21)),
            "manufacturer_code": int(rng.integers(0, 1 << 11)),
            "device_instance": int(rng.integers(0, 256)),
            "device_function": int(rng.integers(0, 256)),
            "device_class": int(rng.integers(0, 128)),
            "system_instance": int(rng.integers(0, 16)),
            "industry_group": int(rng.integers(0, 8)),
            "arbitrary_address_capable": bool(rng.integers(0, 2)),
        }
        name = cb.iso_name(**kw)
        f = {k: int(v[0]) for k, v in name_fields(np.array([name], dtype=np.uint64)).items()}
        inst = (f.pop("device_instance_upper") << 3) | f.pop("device_instance_lower")
        assert {**f, "device_instance": inst} == {
            **kw,
            "arbitrary_address_capable": int(kw["arbitrary_address_capable"]),
        }


def _name_hex(uniq: int, mfr: int, function: int = 150, instance: int = 0) -> str:
    v = uniq | (mfr << 21) | (instance << 32) | (function << 40) | (40 << 49) | (4 << 60)
    return int(v | (1 << 63)).to_bytes(8, "little").hex()


def test_sources_follow_address_claims():
    a, b = _name_hex(1001, 1851), _name_hex(2002, 135)
    hdg = "00102700000000FD"
    rows = [
        (127250, 5, hdg),  # 1: before any claim at 5: back-filled with A's first claim
        (60928, 5, a),  # 2: A claims 5
        (127250, 5, hdg),  # 3: A
        (127250, 9, hdg),  # 4: address 9 never claimed
        (60928, 7, a),  # 5: A moves to 7
        (127250, 5, hdg),  # 6: 5 is free: unknown device
        (127250, 7, hdg),  # 7: A
        (60928, 5, b),  # 8: B claims 5
        (127250, 5, hdg),  # 9: B
        (60928, 7, a),  # 10: A repeats its claim
        (127250, 7, hdg),  # 11: A
    ]
    m = synth(rows)
    res = n2k_result(m, "x", "plain", IngestConfig())
    src = dict(zip(res.frames["heading"]["line"], res.frames["heading"]["source"], strict=True))
    assert src == {
        1: "n2k:1851-1001",
        3: "n2k:1851-1001",
        4: "n2k:addr9",
        6: "n2k:addr5",
        7: "n2k:1851-1001",
        9: "n2k:135-2002",
        11: "n2k:1851-1001",
    }
    assert any("no address claim" in n and "9" in n for n in res.notes)
    assert any(n.startswith("n2k:1851-1001: NMEA 2000 NAME") for n in res.notes)


def test_name_keys_disambiguate_one_unit_with_several_functions():
    n1 = int.from_bytes(bytes.fromhex(_name_hex(77, 1851, 150, 0)), "little")
    n2 = int.from_bytes(bytes.fromhex(_name_hex(77, 1851, 130, 1)), "little")
    n3 = int.from_bytes(bytes.fromhex(_name_hex(78, 1851)), "little")
    assert name_keys([n1, n2, n3]) == {
        n1: "n2k:1851-77-150-0",
        n2: "n2k:1851-77-130-1",
        n3: "n2k:1851-78",
    }
    codes, keys, _ = source_keys(np.array([3, 3], np.uint8), np.zeros(0, np.int64), np.zeros(0))
    assert [keys[c] for c in codes] == ["n2k:addr3", "n2k:addr3"]


# ------------------------------------------------------------------------------ times
def _with_time(m: Messages, t: np.ndarray, kind: str) -> Messages:
    return Messages(t, m.line, m.prio, m.pgn, m.src, m.dst, m.start, m.length, m.payload, kind)


def test_time_of_day_and_relative_logs_anchored_by_system_time():
    m, _ = plain_messages(real_path("signalk-server", "aava-n2k.data"))
    ref = _result(str(real_path("signalk-server", "aava-n2k.data")))
    local = (m.time_ns + 3 * 3600 * 10**9) % DAY_NS  # a gateway clock on local time of day
    for t, kind in ((local, TIME_OF_DAY), (m.time_ns - m.time_ns[0] + 12345, TIME_RELATIVE)):
        res = n2k_result(_with_time(m, t, kind), "x", "yd", IngestConfig())
        for k in ("heading", "water", "position"):
            got = res.frames[k]["recv_ns" if k == "position" else "time_ns"].to_numpy()
            want = ref.frames[k]["recv_ns" if k == "position" else "time_ns"].to_numpy()
            if k == "position":
                got, want = got[got != want.min()], want[want != want.min()]
            # the offset is the median of (UTC time - frame time): within the spread of
            # the GNSS's message latency (aava: 0.29..0.59 s)
            assert np.abs(got - want).max() < 0.6e9
        assert any("put on UTC by 1194 PGN126992/129029 times" in n for n in res.notes)
        assert res.format == "n2k-yd"


def test_log_without_any_time_uses_cfg_date_else_assumed_date():
    m = synth([(127250, 1, "0010270000000000")] * 3, t0=5 * 10**9, kind=TIME_OF_DAY)
    res = n2k_result(m, "x", "plain", IngestConfig(date="2024-05-06"))
    t = res.frames["heading"]["time_ns"].to_numpy()
    assert t[0] == int(days_from_civil(2024, 5, 6)) * DAY_NS + 5 * 10**9
    res = n2k_result(m, "x", "plain", IngestConfig())
    assert res.frames["heading"]["time_ns"].iloc[0] == ASSUMED_DATE_DAYS * DAY_NS + 5 * 10**9
    assert ASSUMED_DATE_NOTE in res.notes
    rel = synth([(127250, 1, "0010270000000000")] * 3, t0=777 * 10**9, kind=TIME_RELATIVE)
    res = n2k_result(rel, "x", "plain", IngestConfig())
    assert res.frames["heading"]["time_ns"].iloc[0] == ASSUMED_DATE_DAYS * DAY_NS
    assert any("assumed date" in n for n in res.notes)


def test_time_of_day_unwrapped_at_midnight():
    m = synth([(127251, 1, "00000000000000FF")] * 3, t0=DAY_NS - 10**8, kind=TIME_OF_DAY)
    m.time_ns[:] = [DAY_NS - 10**8, 0, 10**8]
    res = n2k_result(m, "x", "plain", IngestConfig(date="2024-05-06"))
    t = res.frames["rot"]["time_ns"].to_numpy()
    assert list(np.diff(t)) == [10**8, 10**8]


def test_clockless_utc_log_is_anchored():
    m, _ = plain_messages(real_path("signalk-server", "aava-n2k.data"))
    res = n2k_result(_with_time(m, m.time_ns - m.time_ns[0], TIME_UTC), "x", "plain",
                     IngestConfig())  # fmt: skip
    assert any("taken as relative" in n for n in res.notes)
    assert abs(int(res.frames["heading"]["time_ns"].iloc[0]) - utc("2014-08-15T19:00:00.892")) < 6e8
    assert res.clockless  # times from zero: no clock, no latency or rate finding from them


# ----------------------------------------------------------------------------- reader
def test_read_n2k_file():
    formats = pytest.importorskip("dracc.ingest.n2k.formats")
    from dracc.ingest.n2k import read_n2k

    path = real_path("signalk-server", "aava-n2k.data")
    assert formats.sniff_n2k(path.read_bytes()[:4096]) is not None
    res = read_n2k(path, IngestConfig())
    ref = _result(str(path))
    assert res.format.startswith("n2k")
    assert res.lines == 21595
    for k in ("position", "heading", "ground", "water", "distance"):
        assert res.frames[k]["time_ns"].tolist() == ref.frames[k]["time_ns"].tolist()
        assert res.frames[k]["line"].tolist() == ref.frames[k]["line"].tolist()


def test_strict_mode_and_bad_date_raise():
    from dracc.core.errors import IngestError

    m = synth([(129025, 1, "00E1F50500000000")])  # lat 10 deg: fine
    assert len(n2k_result(m, "x", "plain", IngestConfig(strict=True)).frames["position"]) == 1
    bad = synth([(129025, 1, "80D99F3800000000")])  # lat 95 deg
    with pytest.raises(IngestError, match="implausible_position"):
        n2k_result(bad, "x", "plain", IngestConfig(strict=True))
    with pytest.raises(IngestError, match="YYYY-MM-DD"):
        n2k_result(m, "x", "plain", IngestConfig(date="2024-13-01"))


def test_decode_of_nothing():
    m = messages([], [], [], [], [], [], [], b"")
    d = decode(m)
    assert d.parts == {} and not d.ignored
    res = n2k_result(m, "x", "plain", IngestConfig())
    assert res.records == 0 and set(res.frames) >= {"position", "heading"}
