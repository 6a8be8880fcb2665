"""$PASHR, $PSXN and own-ship !AIVDO (dracc.ingest.nmea.ins_ais): values against the
sentences' documented examples and hand calculations, the Seapath log of a real ship,
own-ship AIS against the same unit's RMC fixes (two real logs), pyais's decoder, and the
compiled kernel against the numpy path on these lines."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import REAL
from geographiclib.geodesic import Geodesic

from dracc.core.config import IngestConfig
from dracc.ingest.nmea import iter_nmea_blocks, parse_buffer, read_nmea
from dracc.ingest.nmea.state import StreamState

D = math.pi / 180.0
KN = 1852.0 / 3600.0
SEAP = REAL / "openrvdas" / "NBP1406_seap-2014-08-01"
MERRIMAC = REAL / "signalk-server" / "nais400-merrimac.log"
HAKEFJORD = REAL / "VDRplayer" / "Hakefjord.txt"


def cs(body: str) -> str:
    x = 0
    for b in body.encode():
        x ^= b
    return f"{x:02X}"


def nmea(body: str, start: str = "$") -> str:
    return f"{start}{body}*{cs(body)}"


def tag(params: str, sentence: str) -> str:
    return f"\\{params}*{cs(params)}\\{sentence}"


ZDA = nmea("GPZDA,163000.00,14,11,2023,00,00")  # 2023-11-14
DAY = 1_699_920_000 * 10**9  # 2023-11-14T00:00Z in ns


def read(tmp_path: Path, lines: list[str], **cfg):
    p = tmp_path / "log.nmea"
    p.write_text("\n".join(lines) + "\n")
    return read_nmea(p, IngestConfig(**cfg))


def both_engines(data: bytes) -> None:
    """The kernel (handing these lines to numpy) and the numpy path give one block."""
    from test_nmeascan import assert_same_block

    assert_same_block(parse_buffer(data, engine="c"), parse_buffer(data, engine="numpy"))


# ----------------------------------------------------------------------------- $PASHR
NOVATEL = "$PASHR,163029.000,158.09,T,-0.30,+0.31,+0.01,0.029,0.029,0.059,1,1*3B"


def test_pashr_novatel_example(tmp_path):
    """The example line of NovAtel's PASHR log (its checksum as printed there): a true
    heading with its own time of day (16:30:29 on the ZDA's date), aligned INS with a
    GNSS fix -> heading_quality 0; the source is the address (no talker)."""
    r = read(tmp_path, [ZDA, NOVATEL])
    assert r.rejects.total == 0
    h = r.frames["heading"].iloc[0]
    assert h.heading_rad == pytest.approx(158.09 * D, abs=1e-12)
    assert h.reference == "T" and h.sentence == "PASHR" and h.source == "PASHR"
    assert h.talker == "" and h.heading_quality == 0.0
    assert h.time_ns == DAY + (16 * 3600 + 30 * 60 + 29) * 10**9


@pytest.mark.parametrize(
    "tail, quality",
    [
        ("", math.nan),  # the short form: no accuracy fields, no flags
        (",0.029,0.029,0.059,1", math.nan),  # NovAtel before 7.03: no INS status field
        (",0.029,0.029,0.059,1,0", 2.0),  # INS not aligned (GPS only / pre-alignment)
        (",0.029,0.029,0.059,1,2", 1.0),  # Trimble: degraded solution
        (",0.029,0.029,0.059,4,3", 0.0),  # Trimble: aligned, RTK fixed
        (",0.029,0.029,0.059,0,1", 1.0),  # aligned but no GNSS fix: coasting
        (",0.029,0.029,0.059,1,9", math.nan),  # an undocumented code: says nothing
    ],
)
def test_pashr_quality_from_its_flags(tmp_path, tail, quality):
    r = read(tmp_path, [ZDA, nmea("PASHR,163029.000,158.09,T,-0.30,+0.31,+0.01" + tail)])
    assert r.rejects.total == 0
    q = r.frames["heading"].heading_quality.iloc[0]
    assert (math.isnan(q) and math.isnan(quality)) or q == quality


def test_pashr_with_a_tag_time_gets_a_receive_time(tmp_path):
    c = 1_699_979_429_250  # 16:30:29.25 on 2023-11-14, ms
    r = read(tmp_path, [ZDA, tag(f"s:ins1,c:{c}", NOVATEL)])
    h = r.frames["heading"].iloc[0]
    assert h.source == "ins1" and h.time_ns == DAY + 59429 * 10**9
    assert h.recv_ns == c * 10**6


def test_pashr_other_forms_ignored_damage_rejected(tmp_path):
    r = read(
        tmp_path,
        [
            ZDA,
            nmea("PASHR,ATT,88536.0000,345.9640,0.0390,-0.9052,0.0024,0.0144,0"),  # Ashtech
            nmea("PASHR,163029.000,158.09,M,-0.30,+0.31,+0.01"),  # no magnetic form
            nmea("PASHR,163029.000,158.09,T,-0.30"),  # cut short
            nmea("PASHR,163029.000,400.00,T,-0.30,+0.31,+0.01"),
        ],
    )
    assert r.ignored["PASHR"] == 1
    assert r.rejects.counts == {"malformed_field": 2, "field_count": 1}
    assert len(r.frames["heading"]) == 0


# ------------------------------------------------------------------------------ $PSXN
def test_psxn_quality_of_the_latest_20_applies_per_source(tmp_path):
    """``,23`` headings take the head-qual of the latest ``,20`` of their own source;
    none before the first; an invalid (2) heading stays a record; ``,22`` is ignored."""
    lines = [
        ZDA,
        nmea("PSXN,23,1.28,1.93,104.68,-0.24"),  # no ,20 yet
        nmea("PSXN,20,1,0,2,0"),  # heading invalid
        nmea("PSXN,23,1.28,1.93,104.70,-0.24"),
        tag("s:sp2", nmea("PSXN,20,0,0,1,0")),  # another Seapath: reduced
        nmea("PSXN,22,0.12,0.03"),
        nmea("PSXN,23,1.28,1.93,104.72,-0.24"),  # still the first unit's 2
        tag("s:sp2", nmea("PSXN,23,1.28,1.93,210.00,-0.24")),
        nmea("PSXN,20,0,0,0,0"),
        nmea("PSXN,23,1.28,1.93,104.74,-0.24"),
    ]
    r = read(tmp_path, lines)
    assert r.rejects.total == 0 and r.ignored["PSXN"] == 1
    h = r.frames["heading"].sort_values("line")
    assert h.source.tolist() == ["PSXN", "PSXN", "PSXN", "sp2", "PSXN"]
    assert h.heading_rad.to_numpy() == pytest.approx(
        np.array([104.68, 104.70, 104.72, 210.00, 104.74]) * D, abs=1e-12
    )
    q = h.heading_quality.to_numpy()
    assert math.isnan(q[0]) and q[1:].tolist() == [2.0, 2.0, 1.0, 0.0]
    assert (h.reference == "T").all() and (h.sentence == "PSXN").all()
    both_engines("\n".join(lines).encode())


def test_psxn_quality_carries_over_blocks_and_engines(tmp_path, monkeypatch):
    """The quality of a ``,20`` applies to the ``,23`` after it in the next block too,
    and the same with either engine and with two workers."""
    from dracc.ingest.nmea import engine_c

    body = []
    for i in range(300):
        if i % 50 == 0:
            body.append(nmea(f"PSXN,20,0,0,{(i // 50) % 3},0"))
        body.append(nmea(f"PSXN,23,1.28,1.93,{100 + i * 0.01:.2f},-0.24"))
    p = tmp_path / "log.nmea"
    p.write_text(ZDA + "\n" + "\n".join(body) + "\n")
    want = np.repeat([0.0, 1.0, 2.0, 0.0, 1.0, 2.0], 50)
    for engine in ("c", "numpy"):
        monkeypatch.setattr(engine_c, "ENGINE", engine)
        for kw in (
            {"workers": 1},
            {"workers": 1, "block_bytes": 700},
            {"workers": 2, "block_bytes": 3000},
        ):
            st = StreamState(str(p))
            blocks = list(iter_nmea_blocks(p, IngestConfig(), st, **kw))
            q = np.concatenate([b.frames["heading"].heading_quality.to_numpy() for b in blocks])
            assert len(blocks) > 1 or kw == {"workers": 1}
            assert np.array_equal(q, want), (engine, kw)


@pytest.mark.skipif(not SEAP.exists(), reason="real Seapath log not found")
def test_psxn_real_seapath_log():
    """N. B. Palmer's Seapath: every ``,23`` a true heading as written (read here with
    str.split), each quality the head-qual of the ``,20`` before it; ``,22`` ignored."""
    r = read_nmea(SEAP, IngestConfig())
    text = SEAP.read_text().splitlines()
    want_h, want_q, q = [], [], math.nan
    for ln in text:
        body = ln.split("$", 1)[-1].split("*")[0].split(",")
        if body[0] == "PSXN" and body[1] == "20":
            q = float(body[4])
        elif body[0] == "PSXN" and body[1] == "23":
            want_h.append(float(body[4]))
            want_q.append(q)
    h = r.frames["heading"]
    h = h[h.sentence == "PSXN"].sort_values("line")
    assert len(h) == len(want_h) == 714
    assert h.heading_rad.to_numpy() == pytest.approx(np.array(want_h) * D, abs=1e-12)
    assert np.array_equal(h.heading_quality.to_numpy(), np.array(want_q), equal_nan=True)
    assert r.ignored["PSXN"] == 714  # the ,22 (gyro calibration) lines
    # the same unit's HDT, written just before: the same heading (to its 0.01 deg)
    import pandas as pd

    hdt = r.frames["heading"]
    hdt = hdt[hdt.sentence == "HDT"].sort_values("time_ns")
    m = pd.merge_asof(
        h.sort_values("time_ns"), hdt, on="time_ns", direction="backward", tolerance=500_000_000
    ).dropna(subset=["heading_rad_y"])
    assert len(m) > 700
    assert np.abs(m.heading_rad_x - m.heading_rad_y).max() < 0.0051 * D


# ----------------------------------------------------------------------------- !AIVDO
def armour(fields: list[tuple[int, int]]) -> str:
    """A payload from (width, value) fields, packed by hand: bits, then 6-bit characters
    (value + 48, plus 8 above 39)."""
    bits = "".join(format(v & ((1 << w) - 1), f"0{w}b") for w, v in fields)
    bits += "0" * (-len(bits) % 6)
    out = ""
    for i in range(0, len(bits), 6):
        v = int(bits[i : i + 6], 2)
        out += chr(v + 48 if v < 40 else v + 56)
    return out


def type1(lon_min: float, lat_min: float, sog: int, cog: int, hdg: int, sec: int, acc: int = 1):
    f = [(6, 1), (2, 0), (30, 244_660_000), (4, 0), (8, 0), (10, sog), (1, acc)]
    f += [(28, round(lon_min * 10000)), (27, round(lat_min * 10000)), (12, cog), (9, hdg)]
    f += [(6, sec), (2, 0), (3, 0), (1, 0), (19, 0)]
    return armour(f)


def vdo(payload: str, count: str = "1,1,,A") -> str:
    return nmea(f"AIVDO,{count},{payload},0", "!")


def test_vdo_type1_hand_encoded(tmp_path):
    """A class A report packed by hand: position (1/10000 min, west/south negative),
    SOG 1/10 kn, COG 1/10 deg, heading; the time moved to its UTC second."""
    lon, lat = -(70 * 60 + 30.5), -(33 * 60 + 12.25)  # 70 30.5 W, 33 12.25 S
    c = 1_699_979_431_600  # 16:30:31.6 on the logger's clock
    r = read(tmp_path, [ZDA, tag(f"c:{c}", vdo(type1(lon, lat, 123, 2805, 279, 29)))])
    assert r.rejects.total == 0
    p, g, h = (r.frames[k].iloc[0] for k in ("position", "ground", "heading"))
    assert p.lat_rad == pytest.approx(-(33 + 12.25 / 60) * D, abs=1e-12)
    assert p.lon_rad == pytest.approx(-(70 + 30.5 / 60) * D, abs=1e-12)
    assert p.quality == 1 and p.source == "AI" and p.talker == "AI" and p.sentence == "VDO"
    assert g.sog_mps == pytest.approx(12.3 * KN) and g.cog_rad == pytest.approx(280.5 * D)
    assert h.heading_rad == pytest.approx(279 * D) and h.reference == "T"
    t = DAY + (16 * 3600 + 30 * 60 + 29) * 10**9  # second 29, 2.6 s before the tag time
    assert p.time_ns == g.time_ns == h.time_ns == t


def test_vdo_not_available_values_give_no_record(tmp_path):
    na = type1(181 * 60, 91 * 60, 1023, 3600, 511, 60)
    pos_only = type1(600.0, 3000.0, 1023, 3600, 511, 63)  # positioning system inoperative
    sog_only = type1(181 * 60, 91 * 60, 50, 3600, 511, 62)
    r = read(tmp_path, [ZDA, vdo(na), vdo(pos_only), vdo(sog_only)])
    assert r.rejects.total == 0 and r.ignored["VDO"] == 1  # nothing available
    assert len(r.frames["position"]) == 1 and r.frames["position"].quality.iloc[0] == 0
    g = r.frames["ground"]
    assert len(g) == 1 and g.sog_mps.iloc[0] == pytest.approx(5.0 * KN)
    assert math.isnan(g.cog_rad.iloc[0]) and len(r.frames["heading"]) == 0


def test_vdo_damage_rejected_multisentence_ignored(tmp_path):
    good = type1(600.0, 3000.0, 50, 900, 90, 10)
    r = read(
        tmp_path,
        [
            ZDA,
            vdo(good[:20]),  # payload too short for a type 1
            vdo(good[:5] + "~" + good[6:]),  # '~' is outside the six-bit alphabet
            vdo(type1(600.0, 95 * 60, 50, 900, 90, 10)),  # latitude 95 deg
            vdo(type1(600.0, 3000.0, 50, 3700, 90, 10)),  # COG 370 deg
            vdo(good, "2,1,3,A"),  # first of two sentences
            vdo(armour([(6, 5), (2, 0), (30, 1)] + [(8, 0)] * 52), "1,1,,A"),  # type 5
            nmea("AIVDM,1,1,,B," + good + ",0", "!"),  # another ship: not own ship
        ],
    )
    assert r.rejects.counts == {"malformed_field": 4}
    assert r.ignored["VDO"] == 2 and r.ignored["VDM"] == 1
    assert sum(len(df) for df in r.frames.values()) == 0


def test_vdo_without_any_date_is_one_no_date_line(tmp_path):
    r = read(tmp_path, [vdo(type1(600.0, 3000.0, 50, 900, 90, 10))])
    assert r.rejects.counts == {"no_date": 1}


@pytest.mark.skipif(not MERRIMAC.exists(), reason="real AIS log not found")
@pytest.mark.parametrize("path", [MERRIMAC, HAKEFJORD], ids=lambda p: p.name)
def test_vdo_positions_lie_on_the_same_units_rmc(path):
    """The own-ship reports of a transponder that is also the log's GPS (NAIS-400 on
    Merrimac, moored; the 5-decimal RMC receiver of Hakefjord, 5 kn): at the same UTC
    seconds the VDO and RMC positions agree within 0.5 m (WGS-84 geodesic,
    geographiclib); a second off would be metres off under way."""
    r = read_nmea(path, IngestConfig())
    p = r.frames["position"]
    v = p[p.sentence == "VDO"]
    g = Geodesic.WGS84

    def distances(shift_ns: int, src: str) -> np.ndarray:
        q = p[(p.source == src) & (p.sentence == "RMC")].drop_duplicates("time_ns")
        m = v.assign(time_ns=v.time_ns + shift_ns).merge(q, on="time_ns", suffixes=("", "_r"))
        cols = zip(m.lat_rad, m.lon_rad, m.lat_rad_r, m.lon_rad_r, strict=True)
        return np.array([g.Inverse(*np.degrees([a, b, c, e]))["s12"] for a, b, c, e in cols])

    srcs = sorted(set(p.source[p.sentence == "RMC"]))
    d = {s: distances(0, s) for s in srcs}
    best = min((s for s in srcs if len(d[s]) >= 6), key=lambda s: np.median(d[s]))
    assert d[best].max() < 0.5, np.percentile(d[best], [50, 99, 100])
    assert len(d[best]) >= (300 if path == HAKEFJORD else 6)
    if path == HAKEFJORD:  # under way: one second off is metres off
        assert np.median(distances(10**9, best)) > 1.5


@pytest.mark.skipif(not HAKEFJORD.exists(), reason="real log not found")
def test_vdo_values_against_pyais():
    pyais = pytest.importorskip("pyais")
    lines = HAKEFJORD.read_bytes().splitlines()
    r = read_nmea(HAKEFJORD, IngestConfig())
    fr = {
        k: r.frames[k][r.frames[k].sentence == "VDO"].set_index("line")
        for k in ("position", "ground")
    }
    n = 0
    for ln in fr["position"].index[:60]:
        m = pyais.decode(lines[ln - 1].decode())
        assert m.msg_type == 18
        pos, gr = fr["position"].loc[ln], fr["ground"].loc[ln]
        assert pos.lat_rad == pytest.approx(m.lat * D, abs=6e-7 * D)  # pyais: 6 decimals
        assert pos.lon_rad == pytest.approx(m.lon * D, abs=6e-7 * D)
        assert gr.sog_mps == pytest.approx(m.speed * KN, abs=1e-9)
        assert gr.cog_rad == pytest.approx(m.course * D, abs=1e-9)
        assert m.heading == 511 and (pos.time_ns // 10**9) % 60 == m.second
        n += 1
    assert n == 60


def test_vdo_type1_and_19_against_pyais_encoder(tmp_path):
    pyais = pytest.importorskip("pyais")
    a = {
        "type": 1,
        "mmsi": 244660000,
        "lat": -33.204,
        "lon": -70.5083,
        "speed": 12.3,
        "course": 280.5,
        "heading": 279,
        "second": 29,
        "accuracy": 1,
    }
    b = {
        "type": 19,
        "mmsi": 244660001,
        "lat": 57.98495,
        "lon": 11.739057,
        "speed": 5.2,
        "course": 28.2,
        "heading": 30,
        "second": 11,
        "shipname": "HAKE",
    }
    lines = [ZDA] + [pyais.encode_dict(x, talker_id="AI", sentence_type="VDO")[0] for x in (a, b)]
    r = read(tmp_path, lines)
    assert r.rejects.total == 0
    for i, x in enumerate((a, b)):
        m = pyais.decode(lines[i + 1])  # what the armour holds (lat/lon to 1/10000 min)
        p, g, h = (
            r.frames[k].sort_values("line").iloc[i] for k in ("position", "ground", "heading")
        )
        assert p.lat_rad == pytest.approx(x["lat"] * D, abs=2e-6 * D)  # 1/10000 min
        assert p.lon_rad == pytest.approx(x["lon"] * D, abs=2e-6 * D)
        assert p.lat_rad == pytest.approx(m.lat * D, abs=6e-7 * D)
        assert g.sog_mps == pytest.approx(x["speed"] * KN) and g.cog_rad == pytest.approx(
            x["course"] * D
        )
        assert h.heading_rad == pytest.approx(x["heading"] * D)
        assert (p.time_ns // 10**9) % 60 == x["second"]
    both_engines("\n".join(lines).encode())
