"""Differential tests: the compiled scanning kernel (``dracc.ingest._nmeascan``) against
the numpy path of ``dracc.ingest.nmea``, which stays the reference and the fallback.

Both engines must give the same :class:`~dracc.ingest.nmea.ParsedBlock` (every column
with its dtype, bit for bit; ``seq``; rejects with reasons, counts and examples; the
first fatal line; statistics; TAG source names in the same order) on the real logs, the
sample logs, simulated logs in every form, fuzzed logs (the mutators of
``tests/test_fuzz.py``), hand-made edge cases and random bytes; and the same frames,
rejects, time events and notes through :func:`~dracc.ingest.nmea.read_nmea` and the
block streamer.  Some values are also checked against hand calculations, and the kernel
is checked to decode the clean lines itself (not hand them all to numpy).
"""

from __future__ import annotations

import math
import random
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dracc.core.config import IngestConfig
from dracc.ingest import nmea
from dracc.ingest.nmea import ParsedBlock, engine_c, parse_buffer, read_nmea

_nmeascan = pytest.importorskip("dracc.ingest._nmeascan", reason="compiled kernel not built")

from test_fuzz import load_corpus, mutate  # noqa: E402  (tests/ is on sys.path)

REPO = Path(__file__).resolve().parents[1]
SAMPLES = REPO / "sample_logs"
FIELDS = (
    "n_lines",
    "n_blank",
    "kinds",
    "clock",
    "reject_counts",
    "reject_examples",
    "first_fatal",
    "stats",
    "source_names",
    "ignored",
    "ignored_examples",
    "n_seg",
    "aux",
)
MAX_BYTES = 1_500_000  #: the first bytes of each real log (the test stays fast)


def _same(a, b, path: str) -> None:
    if isinstance(a, Counter):
        assert Counter(a) == Counter(b), path  # zero counts equal missing ones
    elif isinstance(a, dict):
        assert set(a) == set(b), (path, set(a) ^ set(b))
        for k in a:
            _same(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape, (path, a.dtype, b.dtype, a.shape, b.shape)
        if a.dtype.kind == "f":  # NaN where NaN, else bit for bit (-0.0 is not 0.0)
            assert np.array_equal(np.isnan(a), np.isnan(b)), path
            ok = ~np.isnan(a)
            assert np.array_equal(a[ok].view(np.int64), b[ok].view(np.int64)), path
        else:
            assert np.array_equal(a, b), (path, np.flatnonzero(a != b)[:5])
    else:
        assert a == b, (path, a, b)


def assert_same_block(c: ParsedBlock, n: ParsedBlock) -> None:
    for f in FIELDS:
        _same(getattr(c, f), getattr(n, f), f)


def both(data: bytes, **kw) -> tuple[ParsedBlock, ParsedBlock]:
    c = parse_buffer(data, engine="c", **kw)
    n = parse_buffer(data, engine="numpy", **kw)
    assert_same_block(c, n)
    return c, n


def _text_logs() -> list[Path]:
    from conftest import REAL

    out = sorted(
        p for p in SAMPLES.rglob("*") if p.is_file() and p.suffix in (".nmea", ".txt", ".log")
    )
    if REAL.is_dir():
        out += sorted(
            p
            for p in REAL.rglob("*")
            if p.is_file() and p.suffix not in (".mcap", ".json", ".md", ".csv", ".parquet")
        )
    return out


# --------------------------------------------------------------------- real and sample logs
@pytest.mark.parametrize("path", _text_logs(), ids=lambda p: p.name)
def test_real_and_sample_logs(path):
    data = path.read_bytes()[:MAX_BYTES]
    for kw in ({}, {"ignore_checksum": True}, {"at_eof": False}):
        both(data, **kw)
    # a block cut anywhere (a final line without its newline)
    both(data[: len(data) * 2 // 3], at_eof=True)


def test_real_logs_exist_and_kernel_decodes_most_lines():
    """The differential test above is not vacuous: the real logs are there, and on a
    clean real log the kernel decodes the lines itself."""
    logs = _text_logs()
    assert len(logs) >= 20
    hake = [p for p in logs if p.name == "Hakefjord.txt"]
    if hake:
        data = hake[0].read_bytes()[:MAX_BYTES]
        r = engine_c.scan_c(data)
        n = parse_buffer(data, engine="numpy")
        seqs = [k["seq"] for k in n.kinds.values()] + ([n.clock["seq"]] if n.clock else [])
        used = np.unique(np.concatenate(seqs))
        assert len(r["sentence"]) > 0.7 * len(used)  # of the sentences numpy reads


# ---------------------------------------------------------------------------- simulated
@pytest.fixture(scope="module")
def voyage():
    from dracc.sim import SimParams, simulate

    return simulate(
        SimParams(
            duration_s=300.0,
            compass="both",
            compass_hz=2.0,
            seed=3,
            start_utc="2025-12-31T23:58:30Z",
            start_lat_deg=-33.9,
            start_lon_deg=-0.01,
            legs=((0.0, 265.0),),
        )
    )


@pytest.mark.parametrize(
    "form,tag_time", [("tag", "s"), ("tag", "ms"), ("prefix", "s"), ("bare", "s")]
)
def test_simulated_forms(voyage, tmp_path, form, tag_time):
    from dracc.sim.nmea_out import write_nmea

    p = tmp_path / "v.nmea"
    write_nmea(voyage, p, form=form, tag_time=tag_time)
    data = p.read_bytes()
    c, _ = both(data)
    r = engine_c.scan_c(data)
    if form in ("tag", "bare"):  # every line clean: the kernel reads them all
        assert len(r["fb_line"]) == 0
        assert len(r["sentence"]) == c.n_lines
    else:  # ISO prefixes: left to the numpy path
        assert len(r["fb_line"]) == r["n_lines"]


def test_kernel_values_against_hand_calculation():
    """Values decoded by the kernel itself (no fallback) against hand calculations."""
    lines = [
        b"$GPGGA,123519.25,4807.038,N,01131.000,W,1,08,0.9,545.4,M,46.9,M,,",
        b"$HEHDT,359.5,T",
        b"$GPRMC,235959.999,A,3352.2000,S,00000.6000,W,12.5,360.0,290224,,,A",
        b"$VWVHW,,T,,M,,N,36.0,K",
        b"$IIROT,-12.0,A",
        b"$GPZDA,000001.5,01,03,1999,,",
    ]
    data = b"".join(b"%s*%02X\r\n" % (s, _xor(s[1:])) for s in lines)
    c, _ = both(data)
    r = engine_c.scan_c(data)
    assert len(r["fb_line"]) == 0
    deg = math.pi / 180
    pos = c.kinds["position"]
    assert pos["lat_rad"][0] == pytest.approx((48 + 7.038 / 60) * deg, rel=1e-15)
    assert pos["lon_rad"][0] == pytest.approx(-(11 + 31 / 60) * deg, rel=1e-15)
    assert pos["tod_ns"][0] == (12 * 3600 + 35 * 60 + 19) * 10**9 + 250_000_000
    assert pos["dec"][0] == 3 and pos["quality"][0] == 1 and pos["alt_m"][0] == 545.4
    assert pos["lat_rad"][1] == pytest.approx(-(33 + 52.2 / 60) * deg, rel=1e-15)
    assert pos["tod_ns"][1] == 86399_999_000_000
    assert pos["date_days"][1] == 19782  # 2024-02-29: 54 years of days since 1970 + leap
    gr = c.kinds["ground"]
    assert (
        gr["sog_mps"][0] == pytest.approx(12.5 * 1852 / 3600, rel=1e-15) and gr["cog_rad"][0] == 0.0
    )
    assert gr["tod_ns"][0] == 86399_999_000_000
    assert c.kinds["heading"]["heading_rad"][0] == pytest.approx(359.5 * deg, rel=1e-15)
    assert c.kinds["water"]["stw_mps"][0] == pytest.approx(10.0, rel=1e-15)  # 36 km/h
    assert c.kinds["rot"]["rot_radps"][0] == pytest.approx(-12 * deg / 60, rel=1e-15)
    assert c.clock["date_days"][0] == 10651 and c.clock["tod_ns"][0] == 1_500_000_000  # 1999-03-01


def _xor(b: bytes) -> int:
    x = 0
    for v in b:
        x ^= v
    return x


def _sentence(body: bytes, cs: bool = True) -> bytes:
    return b"$" + body + (b"*%02X" % _xor(body) if cs else b"")


def _tag(body: bytes) -> bytes:
    return b"\\" + body + b"*%02X\\" % _xor(body)


# ------------------------------------------------------------------------- edge cases
GOOD = _sentence(b"GPGGA,000001,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,")
EDGE = [
    b"",
    b"\n",
    b"\r\n",
    b"\r",
    b"#comment\n",
    GOOD,
    GOOD + b"\n" + GOOD,
    GOOD.replace(b"$", b"$$"),
    GOOD.replace(b"$", b"!$"),
    GOOD + b"$",
    GOOD + GOOD,
    GOOD.replace(b"4807", b"48\x0007"),
    b"\x00" * 100 + b"\n" + GOOD,
    GOOD[:-1] + b"a",
    GOOD.lower(),
    GOOD[:-2] + b"5",
    GOOD[:-3],
    GOOD + b" ",
    GOOD.replace(b"\n", b"") + b"\r\r\n",
    b"$GPGGA" + b",1" * 100000 + b"*00",
    b"x" * 300000 + GOOD,
    GOOD + b"\t",
    _sentence(b"GPHDG,10,1,E,2,W"),
    _sentence(b"HCHDG,10,1,E,2,W"),
    _sentence(b"HCHDG,10,1,X,2,W"),
    _sentence(b"PGRMZ,1,2,3"),
    _sentence(b"P"),
    _sentence(b"GPXYZ,1,2"),
    _sentence(b"GPHDT"),
    _sentence(b"GPHDT,"),
    _sentence(b"gpHDT,1,T"),
    _sentence(b"G1HDT,1,T"),
    _sentence(b"GPH1T,1,T"),
    _sentence(b"HEHDT,1,T,,,,,,,,,,,,,,,,,,,,,,,,"),
    _sentence(b"HEHDT,1.5.5,T"),
    _sentence(b"HEHDT,+5,T"),
    _sentence(b"HEHDT,5.,T"),
    _sentence(b"HEHDT,.5,T"),
    _sentence(b"HEHDT,-0,T"),
    _sentence(b"HEHDT,-,T"),
    _sentence(b"HEHDT,.,T"),
    _sentence(b"HEHDT,360,T"),
    _sentence(b"HEHDT,360.0001,T"),
    _sentence(b"HEHDT,1,TT"),
    _sentence(b"HEHDT,1234567890123456.5,T"),
    _sentence(b"HEHDT,0.1234567890123456789,T"),
    _sentence(b"HEHDT,000000000000000000001,T"),
    _sentence(b"HEHDT, 1,T"),
    _sentence(b"HETHS,10.5,V"),
    _sentence(b"HETHS,10.5,A"),
    _sentence(b"TIROT,5,V"),
    _sentence(b"GPGGA,,,,,,,,,,,,,,"),
    _sentence(b"GPGGA,240000,,,,,200,,,,,,,"),
    _sentence(b"GPGGA,235960,,,,,-129,,,,,,,"),
    _sentence(b"GPGGA,235959.9999995,,,,,1.9,,,,,,,"),
    _sentence(b"GPGGA,1,9000.0001,N,18000.0,E,,,,,,,,"),
    _sentence(b"GPGGA,1,4860.0,N,1,E,,,,,,,,"),
    _sentence(b"GPGGA,1,4807,S,1,X,,,,,,,,"),
    _sentence(b"GPGGA,1,-4807,N,1,E,,,,,,,,"),
    _sentence(b"GPGLL,4807.0,N,01131.0,E,120000,A,N"),
    _sentence(b"GPGLL,4807.0,N,01131.0,E,,V"),
    _sentence(b"GPGLL,4807.0,N,01131.0,E,120000,,"),
    _sentence(b"GPRMC,1,A,1,N,1,E,1,1,290223,,,A"),
    _sentence(b"GPRMC,1,A,1,N,1,E,1,1,010180,,,A"),
    _sentence(b"GPRMC,1,A,1,N,1,E,1,1,01018.5,,,A"),
    _sentence(b"GPRMC,1,A,1,N,1,E,1,1,99999999999999,,,A"),
    _sentence(b"GPRMC,1,A,1,N,1,E,1,1,-10100,,,A"),
    _sentence(b"GPRMC,1,A,1,N,1,E,,,,,,AB"),
    _sentence(b"GNGNS,1,1,N,1,E,AAN,10,1,2,,,"),
    _sentence(b"GNGNS,1,1,N,1,E,,10,1,2,,,"),
    _sentence(b"GNGNS,1,1,N,1,E,XYZ,10,1,2,,,"),
    _sentence(b"GPVTG,1,T,,M,2,N,,K"),
    _sentence(b"GPVTG,1,T,,M,,N,7.2,K"),
    _sentence(b"VWVBW,1,2,V,3,4,A"),
    _sentence(b"VWVBW,1,2,A,3,4,V"),
    _sentence(b"VWVLW,1.5,N,2.5,N"),
    _sentence(b"GPVLW,1.5,N,2.5,N"),
    _sentence(b"GPZDA,120000,31,12,2024,,"),
    _sentence(b"GPZDA,120000,31,11,2024,,"),
    _sentence(b"GPZDA,120000,1,1,1e3,,"),
    _sentence(b"GPZDA,120000,1,1,1000000000000000,,"),
    _sentence(b"GPZDA,120000,1,1,-4713,,"),
    _sentence(b"GPZDA,120000,1.7,1.2,2024.9,,"),
    _sentence(b"HEHDT,1,T", cs=False),
    _sentence(b"HEHDT,1,T", cs=False) + GOOD,
    b"!AIVDM,1,1,,A,13aEOK?P00PD2wVMdLDRhgvL289?,0*26",
    _tag(b"s:GP1,c:1700000000") + GOOD,
    _tag(b"c:1700000000250,s:X") + GOOD,
    _tag(b"s:GP1,c:-5") + GOOD,
    _tag(b"s:GP1,c:1e5") + GOOD,
    _tag(b"s:GP1,c:") + GOOD,
    _tag(b"s:GP1,c:99999999999999999999") + GOOD,
    _tag(b"s:GP1,c:9200000000") + GOOD,
    _tag(b"s:GP1,c:1700000000.1234567") + GOOD,
    _tag(b"s:,c:1") + GOOD,
    _tag(b"x:1") + GOOD,
    _tag(b"s:" + b"A" * 64) + GOOD,
    _tag(b"s:" + b"A" * 65) + GOOD,
    _tag(b"s:" + b"B" * 200) + GOOD,
    _tag(b"s:A,s:B,c:1,c:2") + GOOD,
    _tag(b"ss:A,xc:1") + GOOD,
    _tag(b"s:A:B,c:1") + GOOD,
    _tag(b"s:GP1")[:-2] + b"0\\" + GOOD,
    _tag(b"s:GP1")[:-1] + GOOD,
    b"\\s:A*5\\" + GOOD,
    _tag(b"s:GP1") + b" " + GOOD,
    _tag(b"s:GP$1") + GOOD,
    _tag(b"s:G\x01") + GOOD,
    b"\\" + GOOD,
    b"2024-01-01T00:00:00Z " + GOOD,
    b"1700000000.5 " + GOOD,
    b"1507112745025;A;" + GOOD,
    b"foo " + GOOD,
    # line ends: a lone CR, CR CR LF, LF CR, runs of CR (each engine splits them alike)
    GOOD + b"\r" + GOOD,
    GOOD + b"\r\r" + GOOD,
    GOOD + b"\r\r\n" + GOOD,
    GOOD + b"\n\r" + GOOD,
    b"\r" * 10,
    b"\r\r\r\n",
    GOOD + b"\r\r\r\n\r\n",
    b"\r" + GOOD + b"\r",
    b"#c\r" + GOOD,
    # lines longer than max_line_bytes: too_long, and the tail's last sentence read
    b"A" * 65536,
    b"A" * 65537,
    b"\x00" * 70000 + GOOD,
    b"\x00" * 70000 + _tag(b"s:GP1,c:1700000000") + GOOD,
    b"$GPGGA," * 10000 + GOOD,
    b"$GPGGA," * 10000,
    GOOD + b"x" * 70000,
    b"\\" * 70000 + GOOD,
    b"\x00" * 70000 + b"$$" + GOOD[1:],
    b"\x00" * 70000 + b"\\" + GOOD,
    # INS and own-ship AIS sentences: the kernel hands their lines to the numpy path
    _sentence(b"PASHR,163029.000,158.09,T,-0.30,+0.31,+0.01,0.029,0.029,0.059,1,1"),
    _sentence(b"PASHR,163029.000,158.09,T,-0.30,+0.31,+0.01"),
    _sentence(b"PASHR,ATT,88536.0000,345.9640,0.0390,-0.9052,0.0024,0.0144,0"),
    _sentence(b"PASHR,163029.000,158.09,M,-0.30,+0.31,+0.01"),
    _sentence(b"PSXN,20,1,0,2,0") + b"\n" + _sentence(b"PSXN,23,1.28,1.93,104.68,-0.24"),
    _sentence(b"PSXN,23,1.28,1.93,104.68,-0.24") + b"\n" + _sentence(b"PSXN,22,0.1,0.2"),
    _sentence(b"PSXN,20,1,0,7,0") + GOOD,
    _tag(b"s:SP1") + _sentence(b"PSXN,20,0,0,1,0") + b"\n" + _sentence(b"PSXN,23,1,2,3,4"),
    b"!AIVDO,1,1,,,B3`hBQh0086=Ui7VpAsQ3wsUoP06,0*41",
    b"!AIVDO,1,1,,,B3`hBQh0086=Ui7VpAsQ3wsUoP06,0*41" + GOOD,
    b"!" + _sentence(b"AIVDO,1,1,,,B3`hBQh0086=Ui7VpAsQ3wsUoP0,0")[1:],  # too short
    b"!"
    + _sentence(b"AIVDO,2,1,1,A,55?MbV02;H;s<HtKR20EHE:0@T4@Dn2222222216L961O5Gf0NSQEp6,0")[1:],
    _tag(b"s:AIS,c:1700000000") + b"!AIVDO,1,1,,,B3uBrjP0=0=Kjm8BoS`AcwUUwP06,0*75",
]


@pytest.mark.parametrize("i", range(len(EDGE)))
def test_edge_cases(i):
    line = EDGE[i]
    for data in (
        line,
        line + b"\r\n",
        GOOD + b"\n" + line + b"\n" + GOOD + b"\n",
        _tag(b"s:Z") + GOOD + b"\n" + line,
    ):
        for kw in ({}, {"ignore_checksum": True}, {"at_eof": False}):
            both(data, **kw)


def test_many_tag_sources_overflow_the_kernel_table():
    """More distinct TAG sources than the kernel's table: the rest go to numpy, and the
    source codes still follow first appearance."""
    data = b"".join(
        _tag(b"s:S%d,c:%d" % (i % 300, 1700000000 + i)) + GOOD + b"\n" for i in range(900)
    )
    c, _ = both(data)
    assert len(c.source_names) == 300


def test_scan_checks_its_output_buffers():
    data = GOOD + b"\n"
    r = engine_c.scan_c(data)
    assert r["n_lines"] == 1 and len(r["sentence"]) == 1
    assert _nmeascan.sizes(data) == (2, 1) and _nmeascan.sizes(b"a\rb\r\nc\r\r\n") == (5, 0)
    a = [np.empty(1, np.uint8)] * 16
    with pytest.raises(ValueError, match="needs"):
        _nmeascan.scan(data, 1, 1, 100, *a)
    with pytest.raises(ValueError, match="cap_lines"):
        _nmeascan.scan(data, 0, 1, 100, *a)
    with pytest.raises(TypeError):
        _nmeascan.scan("text", 1, 1, 100, *a)


# ------------------------------------------------------------------------------- fuzzing
@pytest.fixture(scope="module")
def corpus():
    c = load_corpus(max_lines=3000)
    if not c:
        pytest.skip("no fuzz corpus")
    return c


@pytest.mark.parametrize("seed", range(6))
def test_fuzzed_logs(corpus, seed):
    rng = random.Random(1000 + seed)
    for _ in range(25):
        lines, _timed = rng.choice(corpus)
        k = rng.randrange(max(1, len(lines) - 200))
        m = mutate(lines[k : k + 200], rng, rng.randint(1, 40))
        for kw in ({}, {"ignore_checksum": True}, {"at_eof": False}):
            both(m.data, **kw)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(max_size=400))
def test_random_bytes(data):
    both(data)


TOKENS = [
    b"$",
    b"!",
    b"\\",
    b"*",
    b",",
    b"\r",
    b"\n",
    b"\x00",
    b"GPGGA",
    b"HEHDT",
    b"GPRMC",
    b"GPZDA",
    b"s:A",
    b"c:17",
    b"1",
    b"4807.038",
    b"N",
    b"E",
    b"-",
    b".",
    b"*4F",
    b"*00",
    b"A",
    b"V",
    b"T",
    GOOD,
    _tag(b"s:GP1,c:1700000000"),
]


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.sampled_from(TOKENS), max_size=60))
def test_nmea_like_token_soup(tokens):
    both(b"".join(tokens))


# ------------------------------------------------------------------ whole files, streamed
def _read(path: Path, engine: str, monkeypatch, **cfg):
    monkeypatch.setattr(engine_c, "ENGINE", engine)
    return read_nmea(path, IngestConfig(**cfg), workers=1)


def _assert_same_result(a, b):
    for kind in a.frames:
        pd.testing.assert_frame_equal(a.frames[kind], b.frames[kind], check_exact=True)
    assert a.lines == b.lines
    assert a.rejects.counts == b.rejects.counts and a.rejects.examples == b.rejects.examples
    assert a.time_events == b.time_events
    assert a.notes == b.notes


def _real(*parts: str) -> Path:
    from conftest import REAL

    p = REAL.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"{p} not found")
    return p


@pytest.mark.parametrize(
    "parts",
    [
        ("VDRplayer", "Hakefjord.txt"),
        ("gpsd", "nmea-fuzzy-cases.log"),
        ("libais", "tagblock.nmea"),
        ("signalk-server", "plaka.log"),
    ],
)
def test_read_nmea_real_equal(parts, monkeypatch):
    p = _real(*parts)
    for cfg in ({}, {"ignore_checksum": True}):
        _assert_same_result(
            _read(p, "c", monkeypatch, **cfg), _read(p, "numpy", monkeypatch, **cfg)
        )


def test_read_nmea_fuzzed_and_simulated_equal(voyage, corpus, tmp_path, monkeypatch):
    from dracc.sim.nmea_out import write_nmea

    p = tmp_path / "v.nmea"
    write_nmea(voyage, p, form="tag")
    _assert_same_result(_read(p, "c", monkeypatch), _read(p, "numpy", monkeypatch))
    rng = random.Random(7)
    lines = p.read_bytes().split(b"\r\n")[:-1]
    for _ in range(3):
        m = mutate(lines, rng, 60)
        q = tmp_path / "m.nmea"
        q.write_bytes(m.data)
        _assert_same_result(_read(q, "c", monkeypatch), _read(q, "numpy", monkeypatch))


def test_streamed_small_blocks_equal(voyage, tmp_path):
    """Blocks of a few kB (lines cut at block ends, many blocks) through the streamer."""
    from dracc.sim.nmea_out import write_nmea

    p = tmp_path / "v.nmea"
    write_nmea(voyage, p, form="tag")
    data = p.read_bytes()
    lines = data.split(b"\r\n")
    lines[5] = lines[5][:40] + lines[6]  # a lost line end: the first sentence is cut short
    lines[-2] = lines[-2].replace(b",", b";", 2)
    p.write_bytes(b"\r\n".join(lines[:-1]))  # no final newline
    out = {}
    for eng in ("c", "numpy"):
        old = engine_c.ENGINE
        engine_c.ENGINE = eng
        try:
            st_ = nmea.StreamState(str(p))
            blocks = list(
                nmea.iter_nmea_blocks(p, IngestConfig(), st_, block_bytes=4096, workers=1)
            )
        finally:
            engine_c.ENGINE = old
        out[eng] = (blocks, st_)
    (bc, sc), (bn, sn) = out["c"], out["numpy"]
    assert len(bc) == len(bn) > 10
    for x, y in zip(bc, bn, strict=True):
        assert x.frames.keys() == y.frames.keys()
        for k in x.frames:
            pd.testing.assert_frame_equal(x.frames[k], y.frames[k], check_exact=True)
    assert sc.rejects.counts == sn.rejects.counts and sc.rejects.counts["truncated"] >= 1
    assert sc.stats == sn.stats and sc.time_events() == sn.time_events()


def test_without_the_kernel_the_numpy_path_reads(monkeypatch):
    """A machine without a compiler: ``_nmeascan`` missing, ``engine="c"`` falls back."""
    data = (_tag(b"s:GP1,c:1700000000") + GOOD + b"\r\n") * 3 + b"garbage\r\n"
    want = parse_buffer(data, engine="numpy")
    monkeypatch.setattr(engine_c, "_nmeascan", None)
    assert not nmea.engine_available()
    got = parse_buffer(data, engine="c")
    assert_same_block(got, want)
    assert got.reject_counts == Counter({"not_nmea": 1}) and len(got.kinds["position"]["seq"]) == 3
