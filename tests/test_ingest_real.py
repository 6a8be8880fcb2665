"""Every real NMEA text log in ../shared/data/real ingests without a traceback and gives a
sensible account; gpsd's decoded TPV records are reproduced."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import REAL, REAL_MISSING

from dracc.core.config import IngestConfig
from dracc.core.errors import IngestError
from dracc.ingest import detect_format, read_logs
from dracc.ingest.inspect import inspect_logs
from dracc.ingest.nmea import REASONS, read_nmea

SKIP_SUFFIXES = {".chk", ".mcap", ".json", ".md"}
#: the NMEA 2000 captures (tests/test_n2k_*.py read them; here they are only not NMEA text)
N2K_FILES = ("signalk-server/aava-n2k.data",)
N2K_DIRS = ("canboat/",)


def _is_n2k(rel: str) -> bool:
    return rel in N2K_FILES or rel.startswith(N2K_DIRS)


NMEA_FILES = (
    sorted(
        rel
        for p in REAL.rglob("*")
        if p.is_file()
        and p.suffix not in SKIP_SUFFIXES
        and not _is_n2k(rel := p.relative_to(REAL).as_posix())
    )
    if REAL.is_dir()
    else [pytest.param(None, marks=pytest.mark.skip(reason=REAL_MISSING))]
)
D = 180.0 / math.pi


@pytest.mark.parametrize("rel", NMEA_FILES)
def test_real_file_ingests_with_a_sensible_account(real_dir, rel):
    path = real_dir / rel
    assert detect_format(path) == "nmea"
    voyage = read_logs([path], IngestConfig())
    n_lines = len(_lines(path.read_bytes()))
    assert voyage.lines == n_lines
    assert set(voyage.rejects.counts) <= set(REASONS)
    n_records = sum(len(f) for f in voyage.frames.values())
    assert n_records == sum(s.records for s in voyage.sources.values())
    for kind, df in voyage.frames.items():
        assert np.all(np.diff(df["time_ns"].to_numpy()) >= 0), kind  # merged in time order
        if len(df):
            assert df["time_ns"].min() > 946684800 * 10**9  # after 2000-01-01: every time resolved
    rep = inspect_logs([path], IngestConfig())
    json.dumps(rep)
    assert rep["lines"] == n_lines and rep["rejected"] == dict(voyage.rejects.counts)
    for key, s in rep["sources"].items():
        assert s["records"] > 0 and s["first_utc"] <= s["last_utc"], key
    # every line is accounted for: used, rejected by a reason, or ignored (valid, unused)
    assert n_records > 0 or voyage.rejects.total > 0 or sum(voyage.ignored.values()) > 0


def _tpv(chk: Path) -> list[tuple[dict, str]]:
    """TPV records with the type of the sentence gpsd echoed just before each."""
    out, last = [], ""
    for line in chk.read_text(errors="replace").splitlines():
        if line.startswith('{"class":"TPV"'):
            out.append((json.loads(line), last))
        elif line[:1] in "$!" and len(line) > 6:
            last = line[3:6]
    return out


GPSD = [
    "ais-nmea.log",
    "bundg_zeus_9.log",
    "firefly-II.log",
    "gpsdf.log",
    "hemi.log",
    "isync.log",
    "nmea-fuzzy-cases.log",
    "skytraq-PX1172RH_DS.log",
    "st-teseo-liv4f.log",
    "triton400.log",
]


@pytest.mark.parametrize("name", GPSD)
def test_gpsd_tpv_times_positions_courses_speeds(real_dir, name):
    """gpsd's TPV (time, lat, lon, and track/speed where a sentence reported a track) is
    reproduced record for record.  Times are compared in full: every one of these logs
    carries RMC or ZDA dates.  Track and speed are compared where gpsd reports them right
    after an RMC or VTG; elsewhere gpsd derives them (speed from successive positions,
    track from HDG plus variation), which is not what the log says."""
    log = real_dir / "gpsd" / name
    r = read_nmea(log, IngestConfig())
    pos, gr = r.frames["position"], r.frames["ground"]
    tpv = _tpv(log.with_name(name + ".chk"))
    fixes = [t for t, _ in tpv if "lat" in t and "time" in t]
    assert fixes
    for f in fixes:
        t = pd.Timestamp(f["time"]).value
        m = pos[pos["time_ns"] == t]
        assert len(m), f["time"]
        err = np.hypot(m["lat_rad"] * D - f["lat"], m["lon_rad"] * D - f["lon"]).min()
        assert err < 1e-7, (f["time"], err)
    moving = [
        t
        for t, last in tpv
        if "track" in t and "speed" in t and "time" in t and last in ("RMC", "VTG")
    ]
    for f in moving:
        g = gr[gr["time_ns"] == pd.Timestamp(f["time"]).value]
        assert len(g), f["time"]
        assert np.abs(g["sog_mps"] - f["speed"]).min() < 1e-3
        assert np.abs((g["cog_rad"] * D - f["track"] + 180) % 360 - 180).min() < 1e-6


def test_hakefjord_two_receivers_one_talker(real_dir):
    v = read_logs([real_dir / "VDRplayer" / "Hakefjord.txt"], IngestConfig())
    assert {"GP/3dp", "GP/5dp", "II"} <= set(v.sources)
    assert v.sources["II"].roles == ["compass", "log"]
    assert v.sources["GP/5dp"].sentences["RMC"] > 300 and "GGA" not in v.sources["GP/5dp"].sentences
    assert v.sources["GP/3dp"].sentences["GGA"] > 600
    # two receivers behind one talker: one chosen by evidence (the finer 5-decimal one), the
    # other kept as a witness, never both interleaved
    assert v.role_sources("gnss") == ["GP/5dp"]
    assert any("gnss: GP/5dp chosen by evidence" in d for d in v.time_events.decisions)


def test_spliced_addresses_rejected(real_dir):
    r = read_nmea(real_dir / "anemomind/Irene/2013/training/NMEA0001.TXT", IngestConfig())
    assert (
        r.rejects.counts["implausible_talker"] == 45
    )  # 19 GPHDG + 19 GIHDG + 3 GPVLW + 2 GIVHW + ...
    assert len(r.frames["heading"]) == 4274  # every IIHDG kept


def test_wrong_checksum_logger(real_dir):
    path = real_dir / "anemomind/Irene/2013/Flensburg2013/entrainement_31.7/NMEA0023.TXT"
    r = read_nmea(path, IngestConfig())
    assert r.rejects.counts["checksum"] == 37550 and r.records == 0
    r = read_nmea(path, IngestConfig(ignore_checksum=True))
    assert r.records > 20000 and r.rejects.counts["checksum"] == 0
    with pytest.raises(IngestError, match=r"NMEA0023.TXT:10: rejected \(checksum"):
        read_nmea(path, IngestConfig(strict=True))


def test_binary_garbage_counted_rest_kept(real_dir):
    r = read_nmea(real_dir / "anemomind/Irene/2008/regate_21_mai_08/IreneLog.txt", IngestConfig())
    assert r.rejects.counts["binary"] >= 1 and len(r.frames["heading"]) > 5000


def test_openrvdas_prefix_times(real_dir):
    r = read_nmea(real_dir / "openrvdas/NBP1406_gyr1-2014-08-01", IngestConfig())
    h = r.frames["heading"]
    assert len(h) == 5000 and h["time_ns"].iloc[0] == pd.Timestamp("2014-08-01T00:00:00.183Z").value
    assert h["time_ns"].iloc[-1] == pd.Timestamp("2014-08-01T00:16:40.076Z").value


def test_merge_two_files_by_time(real_dir):
    v = read_logs(
        [
            real_dir / "openrvdas/NBP1406_seap-2014-08-01",
            real_dir / "openrvdas/NBP1406_gyr1-2014-08-01",
        ],
        IngestConfig(),
    )
    h = v.frames["heading"]
    # the Seapath's own $PSXN,23 headings are a source of their own (no talker)
    assert set(h["source"].astype(str)) == {"GP", "HE", "PSXN"}
    assert np.all(np.diff(h["time_ns"]) >= 0)
    assert [i["records"] for i in v.inputs] == [715 + 714 + 714 + 714, 5000]


@pytest.mark.parametrize(
    "content, match",
    [
        (None, "no such file"),
        ("dir", "is a directory"),
        (b"", "empty file"),
        (b"\xff\xd8\xff\xe0\x00\x10JFIF", "JPEG"),
    ],
)
def test_unreadable_inputs_are_clear_errors(tmp_path, content, match):
    p = tmp_path / "x.log"
    if content == "dir":
        p.mkdir()
    elif content is not None:
        p.write_bytes(content)
    with pytest.raises(IngestError, match=match):
        read_logs([p], IngestConfig())


def test_random_binary_is_named_once_not_a_traceback(tmp_path):
    """Issue 29: random bytes are one IngestError saying what they are (were read as
    NMEA text, every line rejected)."""
    p = tmp_path / "noise.bin"
    p.write_bytes(np.random.default_rng(1).integers(0, 256, 200_000, dtype=np.uint8).tobytes())
    with pytest.raises(IngestError, match="binary file with no NMEA sentence"):
        read_logs([p], IngestConfig())


# ------------------------------------------------ rejected = damaged; ignored = valid, unused
ALL_FILES = (
    sorted(
        p.relative_to(REAL).as_posix()
        for p in REAL.rglob("*")
        if p.is_file() and p.suffix not in {".chk", ".json", ".md"}
    )
    if REAL.is_dir()
    else [pytest.param(None, marks=pytest.mark.skip(reason=REAL_MISSING))]
)


#: a line ends at CR CR LF, CR LF, LF or a lone CR (docs/ingest.md)
_LINE_END = re.compile(rb"\r\r\n|\r\n|\n|\r")


def _lines(data: bytes) -> list[bytes]:
    """The lines of a text log, counted independently of the reader."""
    lines = _LINE_END.split(data)
    if lines and lines[-1] == b"":
        lines.pop()
    return lines


def _outcomes(data: bytes) -> int:
    """What the reader must account for, counted independently of it: one per sentence
    (a '$'/'!' not followed by another: '$$GPGGA' is one), one per line without a
    sentence (comments, blank, noise)."""
    n = 0
    for ln in _lines(data):
        starts = (
            0
            if ln.startswith(b"#")
            else sum(
                1
                for i, c in enumerate(ln)
                if c in b"$!" and not (i + 1 < len(ln) and ln[i + 1] in b"$!")
            )
        )
        n += max(starts, 1)
    return n


@pytest.mark.parametrize("rel", ALL_FILES)
def test_real_file_rejects_only_damage_and_accounts_for_every_line(real_dir, rel):
    """Valid lines dracc does not use are ignored by type, never rejected ('unsupported' and
    'comment' are no reject reasons); used + rejected + ignored = every sentence and every
    line without one (NMEA text), every message (MCAP files without navigation data)."""
    from dracc.ingest.nmea import StreamState, iter_nmea_blocks

    path = real_dir / rel
    v = read_logs([path], IngestConfig())
    assert not {"unsupported", "comment"} & set(v.rejects.counts)
    assert v.inputs[0]["ignored"] == dict(v.ignored)
    assert v.inputs[0]["rejected"] == dict(v.rejects.counts)
    assert all(isinstance(k, str) and k and n > 0 for k, n in v.ignored.items())
    if detect_format(path) == "mcap":
        if v.inputs[0]["records"] == 0:
            assert sum(v.ignored.values()) + v.rejects.total == v.lines
        return
    if _is_n2k(rel):  # NMEA 2000: every message used, rejected or ignored by PGN
        assert detect_format(path) == "n2k"
        assert v.inputs[0]["records"] + sum(v.ignored.values()) > 0
        return
    st = StreamState(str(path))
    for _ in iter_nmea_blocks(path, IngestConfig(), st, workers=1):
        pass
    assert st.ignored == v.ignored and st.rejects.counts == v.rejects.counts
    used = sum(st.sentences.values()) - st.rejects.counts["no_date"]  # decoded, dated
    assert used + v.rejects.total + sum(v.ignored.values()) == _outcomes(path.read_bytes())


def test_bundg_zeus_rejects_nothing_and_ignores_2519_lines_by_type(real_dir):
    """gpsd's B&G Zeus log: once 10 'comment' and 2509 'unsupported' rejects; every one is
    valid, so none is rejected now, and the 2519 are ignored by type."""
    v = read_logs([real_dir / "gpsd" / "bundg_zeus_9.log"], IngestConfig())
    assert v.rejects.total == 0
    assert sum(v.ignored.values()) == 2519
    assert v.ignored == {
        "comment": 10,
        "GSA": 144,
        "RMB": 147,
        "APB": 147,
        "GLC": 146,
        "BOD": 149,
        "MWD": 150,
        "XTE": 149,
        "AAM": 147,
        "XDR": 148,
        "DBT": 148,
        "DPT": 149,
        "GSV": 436,
        "MWV": 300,
        "MTW": 149,
    }
