"""NMEA 0183 sentence decoding: one literal real line per type, every field and unit;
line forms; corrupt lines; streaming equals whole-file parsing; round trips."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dracc.core.config import IngestConfig
from dracc.core.errors import IngestError
from dracc.frames import FileResult
from dracc.ingest.nmea import iter_nmea_blocks, parse_sentences, read_nmea

D = math.pi / 180.0
KN = 1852.0 / 3600.0
T0 = 1_700_000_000  # 2023-11-14T22:13:20Z


def cs(body: str) -> str:
    x = 0
    for b in body.encode():
        x ^= b
    return f"{x:02X}"


def nmea(body: str) -> str:
    return f"${body}*{cs(body)}"


def tag(params: str, sentence: str) -> str:
    return f"\\{params}*{cs(params)}\\{sentence}"


def read_text(tmp_path: Path, text: str, **cfg) -> FileResult:
    p = tmp_path / "log.nmea"
    p.write_bytes(text.encode("latin-1") if isinstance(text, str) else text)
    return read_nmea(p, IngestConfig(**cfg))


def one(res, kind: str) -> dict:
    df = res.frames[kind]
    assert len(df) == 1, (kind, len(df), dict(res.rejects.counts))
    return df.iloc[0].to_dict()


def with_date(line: str) -> str:
    """Prefix a line with a ZDA so time-of-day-free sentences have a date to hang on."""
    return nmea("GPZDA,201500.00,14,11,2023,00,00") + "\n" + line + "\n"


# ------------------------------------------------------------------ one real line per type
def test_hdt_real_gyro(tmp_path):
    # openrvdas/NBP1406_gyr1 (RVIB N. B. Palmer gyro), ISO prefix
    r = read_text(tmp_path, "2014-08-01T00:00:00.183000Z $HEHDT,218.53,T*12\n")
    h = one(r, "heading")
    assert h["heading_rad"] == pytest.approx(218.53 * D, abs=1e-12)
    assert (
        h["reference"] == "T" and math.isnan(h["deviation_rad"]) and math.isnan(h["variation_rad"])
    )
    assert h["source"] == "HE" and h["talker"] == "HE" and h["sentence"] == "HDT" and h["line"] == 1
    assert h["time_ns"] == 1406851200_183000000


def test_hdg_real_bundg(tmp_path):
    # gpsd/bundg_zeus_9.log: heading 229.8, no deviation, variation 1.3 E
    r = read_text(tmp_path, with_date("$SDHDG,229.8,,,1.3,E*36"))
    h = one(r, "heading")
    assert h["heading_rad"] == pytest.approx(229.8 * D)
    assert h["reference"] == "M"
    assert math.isnan(h["deviation_rad"])
    assert h["variation_rad"] == pytest.approx(1.3 * D)


def test_hdg_west_and_numeric_talker(tmp_path):
    # signalk-server/n2kd-183-merrimac.log line form, with W made up for the sign
    r = read_text(tmp_path, with_date(nmea("24HDG,182.1,2.5,W,1.0,W")))
    h = one(r, "heading")
    assert h["talker"] == "24" and h["source"] == "24"
    assert h["deviation_rad"] == pytest.approx(-2.5 * D) and h["variation_rad"] == pytest.approx(
        -1.0 * D
    )


def test_hdm_real(tmp_path):
    r = read_text(tmp_path, with_date("$04HDM,186.5,M*2C"))  # n2kd-183-merrimac.log
    h = one(r, "heading")
    assert h["heading_rad"] == pytest.approx(186.5 * D) and h["reference"] == "M"


def test_ths_real_skytraq(tmp_path):
    r = read_text(tmp_path, with_date("$GNTHS,244.28,A*11"))  # gpsd/skytraq-PX1172RH_DS.log
    h = one(r, "heading")
    assert h["heading_rad"] == pytest.approx(244.28 * D) and h["reference"] == "T"
    r = read_text(tmp_path, with_date(nmea("GNTHS,244.28,V")))  # mode V: not valid -> NaN, kept
    assert math.isnan(one(r, "heading")["heading_rad"])


def test_rot_real_pypilot(tmp_path):
    r = read_text(tmp_path, with_date("$APROT,0.013,A*35"))  # gpsd/pypilot.log
    assert one(r, "rot")["rot_radps"] == pytest.approx(0.013 * D / 60.0)
    r = read_text(tmp_path, with_date(nmea("HEROT,-12.5,A")))
    assert one(r, "rot")["rot_radps"] == pytest.approx(-12.5 * math.pi / 180 / 60)


def test_vhw_real_hakefjord(tmp_path):
    r = read_text(
        tmp_path, with_date("$IIVHW,,T,25.0,M,5.9,N,10.9,K*78")
    )  # VDRplayer/Hakefjord.txt
    w = one(r, "water")
    assert w["stw_mps"] == pytest.approx(5.9 * 1852 / 3600)  # knots, not the km/h field
    assert all(
        math.isnan(w[c]) for c in ("stw_transverse_mps", "sog_long_mps", "sog_transverse_mps")
    )
    r = read_text(tmp_path, with_date(nmea("IIVHW,,T,,M,,N,10.8,K")))  # only km/h
    assert one(r, "water")["stw_mps"] == pytest.approx(3.0)


def test_vbw_constructed(tmp_path):
    # no real VBW in the shared data: a standard-layout line (NMEA 0183 v3 VBW)
    r = read_text(tmp_path, with_date(nmea("VWVBW,12.3,-0.4,A,12.7,0.5,A")))
    w = one(r, "water")
    assert w["stw_mps"] == pytest.approx(12.3 * KN) and w["stw_transverse_mps"] == pytest.approx(
        -0.4 * KN
    )
    assert w["sog_long_mps"] == pytest.approx(12.7 * KN) and w[
        "sog_transverse_mps"
    ] == pytest.approx(0.5 * KN)
    r = read_text(tmp_path, with_date(nmea("VWVBW,12.3,-0.4,A,12.7,0.5,V")))  # ground part void
    w = one(r, "water")
    assert w["stw_mps"] == pytest.approx(12.3 * KN) and math.isnan(w["sog_long_mps"])


def test_vlw_real_hakefjord(tmp_path):
    r = read_text(tmp_path, with_date("$IIVLW,2354.92,N,2338.533,N*79"))
    d = one(r, "distance")
    assert d["total_water_m"] == pytest.approx(2354.92 * 1852) and d[
        "trip_water_m"
    ] == pytest.approx(2338.533 * 1852)


def test_gga_real_seapath(tmp_path):
    # openrvdas/NBP1406_seap: 6-decimal minutes, south and west
    line = (
        "2014-08-01T00:00:00.814000Z "
        "$GPGGA,000000.70,2200.112071,S,01756.360200,W,1,10,0.9,1.04,M,,M,,*41\n"
    )
    p = one(read_text(tmp_path, line), "position")
    assert p["lat_rad"] == pytest.approx(-(22 + 0.112071 / 60) * D, abs=1e-13)
    assert p["lon_rad"] == pytest.approx(-(17 + 56.360200 / 60) * D, abs=1e-13)
    assert p["alt_m"] == 1.04 and p["hdop"] == 0.9 and p["quality"] == 1
    assert p["time_ns"] == 1406851200_700000000  # the fix time, on the prefix's date


def test_gga_empty_fields_are_nan(tmp_path):
    r = read_text(tmp_path, with_date("$GPGGA,,,,,,0,,,,M,,M,,*66"))  # gpsd/hemi.log, no fix
    p = one(r, "position")
    assert math.isnan(p["lat_rad"]) and math.isnan(p["lon_rad"]) and math.isnan(p["alt_m"])
    assert p["quality"] == 0


def test_gll_real_sounder(tmp_path):
    r = read_text(tmp_path, "$ECGLL,5119.881,N,00125.169,E,164326,A,D*52\n", date="2012-01-19")
    p = one(r, "position")
    assert p["lat_rad"] == pytest.approx((51 + 19.881 / 60) * D) and p["lon_rad"] == pytest.approx(
        (1 + 25.169 / 60) * D
    )
    assert p["quality"] == 1 and math.isnan(p["alt_m"])
    assert p["time_ns"] == (15358 * 86400 + 16 * 3600 + 43 * 60 + 26) * 10**9  # 2012-01-19


def test_rmc_real_hakefjord(tmp_path):
    r = read_text(
        tmp_path, "$GPRMC,092211.00,A,5759.09700,N,01144.34344,E,5.257,28.27,200715,,,A*58\n"
    )
    p = one(r, "position")
    g = one(r, "ground")
    assert p["lat_rad"] == pytest.approx((57 + 59.097 / 60) * D) and p["lon_rad"] == pytest.approx(
        (11 + 44.34344 / 60) * D
    )
    assert p["quality"] == 1
    assert g["sog_mps"] == pytest.approx(5.257 * KN) and g["cog_rad"] == pytest.approx(28.27 * D)
    assert p["time_ns"] == g["time_ns"] == 1437384131_000000000  # 2015-07-20T09:22:11Z


def test_rmc_void_and_antimeridian(tmp_path):
    r = read_text(
        tmp_path,
        nmea("GPRMC,000001.25,V,0100.5000,S,17959.5000,W,10.0,359.9,010326,3.5,W,A") + "\n",
    )
    p = one(r, "position")
    assert p["quality"] == 0  # kept, flagged invalid
    assert p["lon_rad"] == pytest.approx(-(179 + 59.5 / 60) * D) and p["lat_rad"] == pytest.approx(
        -(1 + 0.5 / 60) * D
    )
    assert p["time_ns"] == (20513 * 86400) * 10**9 + 1_250_000_000  # 2026-03-01T00:00:01.25Z


def test_vtg_real_seapath(tmp_path):
    r = read_text(tmp_path, with_date("$GPVTG,213.66,T,,M,9.4,N,,K,A*1E"))
    g = one(r, "ground")
    assert g["cog_rad"] == pytest.approx(213.66 * D) and g["sog_mps"] == pytest.approx(9.4 * KN)


def test_zda_real_gives_time_only(tmp_path):
    r = read_text(tmp_path, "$GPZDA,000000.70,01,08,2014,,*6F\n$HEHDT,218.53,T*12\n")
    assert sum(len(f) for f in r.frames.values()) == 1  # ZDA makes no record itself
    assert one(r, "heading")["time_ns"] == 1406851200_700000000  # HDT takes the ZDA time


def test_gns_constructed(tmp_path):
    r = read_text(
        tmp_path, with_date(nmea("GPGNS,112257.00,3844.24011,N,00908.43828,W,AN,03,10.5,,,,"))
    )
    p = one(r, "position")
    assert p["lat_rad"] == pytest.approx((38 + 44.24011 / 60) * D) and p[
        "lon_rad"
    ] == pytest.approx(-(9 + 8.43828 / 60) * D)
    assert p["quality"] == 1 and p["hdop"] == 10.5


def test_agrees_with_pynmea2_on_real_lines():
    """An independent parser gives the same angles on the real lines used above."""
    pynmea2 = pytest.importorskip("pynmea2")
    m = pynmea2.parse("$GPGGA,000000.70,2200.112071,S,01756.360200,W,1,10,0.9,1.04,M,,M,,*41")
    r = parse_sentences(
        [b"$GPGGA,000000.70,2200.112071,S,01756.360200,W,1,10,0.9,1.04,M,,M,,*41"],
        np.array([1406851200_800000000]),
        ["seap"],
        "mem",
        IngestConfig(),
    )
    p = r.frames["position"].iloc[0]
    assert p["lat_rad"] / D == pytest.approx(m.latitude, abs=1e-12)
    assert p["lon_rad"] / D == pytest.approx(m.longitude, abs=1e-12)


# ------------------------------------------------------------------------------ line forms
def test_line_forms_mixed_in_one_file(tmp_path):
    gga = nmea("INGGA,235959.50,5436.023081,N,01847.594254,E,4,12,0.8,25.0,M,31.2,M,,")
    hdt = nmea("HEHDT,60.0,T")
    lines = [
        tag(f"s:INS2,c:{T0}", gga),  # TAG, seconds; fix at 23:59:59.5 of the previous day
        tag(f"s:GYRO,c:{T0}250", hdt),  # TAG, milliseconds
        f"2023-11-14T22:13:21.500Z {hdt}",  # ISO 8601 prefix
        f"{T0 + 2}.25 {hdt}",  # Unix seconds
        f"{T0 + 3}000;A;{hdt}",  # Signal K millis;X;
        f"gyr1 2023-11-14T22:13:24Z {hdt}",  # OpenRVDAS-style data id + ISO time
        hdt + nmea("HEHDT,61.0,T"),  # two sentences fused on one line
        "!AIVDM,1,1,,B,13u=gHP3CWPlvs2Q8sHW:5fD0h6a,0*1B",  # '!' sentence (AIS): counted, unused
        "$" + hdt,  # '$$' doubled start
    ]
    r = read_text(tmp_path, "\r\n".join(lines[:4]) + "\n" + "\n".join(lines[4:]) + "\r\n")
    h = r.frames["heading"]
    assert r.rejects.total == 0 and r.ignored == {"VDM": 1}  # AIS: valid, not used: ignored
    by_line = {int(a): b for a, b in zip(h["line"], h["time_ns"], strict=True)}
    assert by_line[2] == T0 * 10**9 + 250_000_000
    assert by_line[3] == (T0 + 1) * 10**9 + 500_000_000
    assert by_line[4] == (T0 + 2) * 10**9 + 250_000_000
    assert by_line[5] == (T0 + 3) * 10**9
    assert by_line[6] == (T0 + 4) * 10**9
    assert (h["line"] == 7).sum() == 2 and sorted(
        h[h["line"] == 7]["heading_rad"] / D
    ) == pytest.approx([60, 61])
    assert set(h["source"].astype(str)) == {"GYRO", "HE"}
    p = one(r, "position")
    assert p["source"] == "INS2" and p["quality"] == 4
    # rule 1: the fix time lands on the day nearest the TAG time (22:13:20 -> same day 23:59:59.5
    # is 1.8 h later, nearer than the previous day)
    assert p["time_ns"] == (T0 // 86400 * 86400 + 86399) * 10**9 + 500_000_000


def test_tag_checksum_validated(tmp_path):
    good = tag(f"s:INS1,c:{T0}", nmea("INHDT,10.0,T"))
    bad = good.replace("s:INS1", "s:INS3")  # same TAG checksum, different body
    r = read_text(tmp_path, good + "\n" + bad + "\n")
    assert len(r.frames["heading"]) == 1 and r.rejects.counts["bad_tag"] == 1
    r = read_text(tmp_path, good + "\n" + bad + "\n", ignore_checksum=True)
    assert len(r.frames["heading"]) == 2


def test_tag_near_midnight_previous_day(tmp_path):
    midnight = (T0 // 86400 + 1) * 86400  # next UTC midnight
    line = tag(
        f"s:GNSS,c:{midnight}", nmea("GPGGA,235959.80,5436.0,N,01847.0,E,1,10,0.8,25.0,M,,M,,")
    )
    p = one(read_text(tmp_path, line + "\n"), "position")
    assert p["time_ns"] == midnight * 10**9 - 200_000_000


# ---------------------------------------------------------------------------- corrupt lines
def test_each_kind_of_corrupt_line_counted_valid_kept(tmp_path):
    good = nmea("HEHDT,10.0,T")
    lines = [
        nmea("GPZDA,201500.00,14,11,2023,00,00"),
        good,
        good[:-2] + ("00" if good[-2:] != "00" else "01"),  # checksum
        "$HEHDT,10.0,T*1"
        + nmea(
            "HEHDT,11.0,T"
        ),  # cut short by the next sentence ('*1' one digit is valid hex: so cut differently)
        "$HEHDT,1\x01.0,T*00",  # binary
        nmea("hehdt,10.0,T"),  # bad address
        nmea("GPVHW,,T,25.0,M,5.9,N,10.9,K"),  # satellite talker on a log sentence
        nmea("HEHDT,10.0"),  # too few fields
        nmea("HEHDT,1O.0,T"),  # letter O in a number
        nmea("HEHDT,400.0,T"),  # out of range
        "foobar",  # not NMEA
        "# a comment",
        nmea("IIMWV,322,R,05.8,N,A"),  # valid, unused
        "",
        good + "\x00",  # binary after checksum
        "$HEHDT,12.0,T",  # no checksum, end of file, no newline
    ]
    r = read_text(tmp_path, "\n".join(lines))
    c = r.rejects.counts
    assert c["checksum"] >= 1 and c["binary"] == 2 and c["bad_address"] == 1
    assert c["implausible_talker"] == 1 and c["field_count"] == 1 and c["malformed_field"] == 2
    assert c["not_nmea"] == 1 and c["truncated"] == 1
    assert "comment" not in c and "unsupported" not in c  # valid lines dracc does not use: ignored
    assert r.ignored == {"comment": 1, "MWV": 1, "blank": 1}
    assert r.ignored_examples["MWV"] == [
        (str(tmp_path / "log.nmea"), 13, nmea("IIMWV,322,R,05.8,N,A"))
    ]
    assert r.ignored_examples["comment"][0][1:] == (12, "# a comment")
    h = r.frames["heading"]
    assert list(h["heading_rad"] / D) == pytest.approx([10.0, 11.0])
    ex = r.rejects.examples["implausible_talker"][0]
    assert ex[1] == 7 and "GPVHW" in ex[2]


def test_strict_fails_on_first_rejected_line(tmp_path):
    p = tmp_path / "x.nmea"
    p.write_text(nmea("IIMWV,322,R,05.8,N,A") + "\n" + nmea("HEHDT,10.0,T")[:-1] + "0\n")
    with pytest.raises(IngestError, match=r"x.nmea:2: rejected \(checksum"):
        read_nmea(p, IngestConfig(strict=True))


def test_ignore_checksum_accepts_and_notes(tmp_path):
    bad = nmea("HEHDT,10.0,T")[:-2] + "00"
    r = read_text(tmp_path, with_date(bad), ignore_checksum=True)
    assert len(r.frames["heading"]) == 1 and r.rejects.total == 0
    assert any("wrong checksums accepted" in n for n in r.notes)


def test_missing_checksum_accepted_and_noted(tmp_path):
    r = read_text(tmp_path, "2014-08-01T00:00:00.316000Z $GPGLL,2200.097,S,01756.346,W\n")
    p = one(r, "position")  # openrvdas gp02 line: GLL without time and without checksum
    assert (
        p["lat_rad"] == pytest.approx(-(22 + 0.097 / 60) * D)
        and p["time_ns"] == 1406851200_316000000
    )
    assert any("without checksum" in n for n in r.notes)


# ----------------------------------------------------------------- streaming and parallelism
def _sim_lines(n_sec: int) -> str:
    out = []
    for k in range(n_sec):
        t = T0 + k
        hh, mm, ss = (t // 3600) % 24, (t // 60) % 60, t % 60
        for u in (1, 2, 3):
            out.append(
                tag(
                    f"s:INS{u},c:{t}",
                    nmea(
                        f"INGGA,{hh:02d}{mm:02d}{ss:02d}.00,54{k % 60:02d}.{u:06d},N,018{k % 60:02d}.5,E,1,,,25.0,M,,M,,"
                    ),
                )
            )
        for j in range(10):
            out.append(tag(f"s:GYRO,c:{t}{j}00", nmea(f"HEHDT,{(k + j) % 360}.5,T")))
        out.append(tag(f"s:LOG,c:{t}", nmea("VWVHW,,T,,M,12.3,N,22.8,K")))
    return "\n".join(out) + "\n"


def test_blocks_and_workers_give_the_same_frames(tmp_path):
    p = tmp_path / "sim.nmea"
    p.write_text(_sim_lines(300))
    whole = read_nmea(p, IngestConfig(), workers=1)
    st_blocks = list(iter_nmea_blocks(p, IngestConfig(), block_bytes=7000, workers=1))
    assert len(st_blocks) > 10
    par = list(iter_nmea_blocks(p, IngestConfig(), block_bytes=20000, workers=2))
    for blocks in (st_blocks, par):
        for kind in ("position", "heading", "water"):
            import pandas as pd

            got = pd.concat([b.frames[kind] for b in blocks if kind in b.frames], ignore_index=True)
            got = got.sort_values(["time_ns", "line"], kind="stable").reset_index(drop=True)
            ref = (
                whole.frames[kind]
                .sort_values(["time_ns", "line"], kind="stable")
                .reset_index(drop=True)
            )
            assert np.array_equal(got["time_ns"].to_numpy(), ref["time_ns"].to_numpy())
            assert np.array_equal(got["line"].to_numpy(), ref["line"].to_numpy())
            assert list(got["source"].astype(str)) == list(ref["source"].astype(str))
    assert len(whole.frames["heading"]) == 3000 and whole.lines == 300 * 14


def test_worker_blocks_come_back_through_files_that_are_removed(tmp_path, monkeypatch):
    """The workers hand parsed blocks over as files (not through the pool's pipe); none is
    left behind, whether the file is read to its end, the reader is abandoned half-way
    or a --strict error stops it."""
    import tempfile

    from dracc.ingest.nmea import reader as mod

    handover = tmp_path / "handover"
    handover.mkdir()
    made = []

    def here(needed_bytes):
        d = tempfile.TemporaryDirectory(prefix="dracc-ingest-", dir=handover)
        made.append(d.name)
        return d

    monkeypatch.setattr(mod, "handover_dir", here)
    p = tmp_path / "sim.nmea"
    p.write_text(_sim_lines(300))
    par = list(iter_nmea_blocks(p, IngestConfig(), block_bytes=20000, workers=2))
    assert sum(len(b.frames["heading"]) for b in par) == 3000
    it = iter_nmea_blocks(p, IngestConfig(), block_bytes=20000, workers=2)
    next(it)
    it.close()  # abandoned after the first block
    bad = tmp_path / "bad.nmea"
    bad.write_text(_sim_lines(150) + "$GPGGA,garbage*00\n" + _sim_lines(150))
    with pytest.raises(IngestError):
        list(iter_nmea_blocks(bad, IngestConfig(strict=True), block_bytes=20000, workers=2))
    assert len(made) == 3
    assert list(handover.iterdir()) == []


def test_without_room_for_the_handover_blocks_come_through_the_pipe(tmp_path, monkeypatch):
    """A container's /dev/shm may hold 64 MB: where neither it nor the temporary directory
    has room for the blocks, or a worker cannot write its file, the block comes through the
    pool's pipe, and the frames are the same."""
    import os as os_mod

    from dracc.ingest import memory
    from dracc.ingest.nmea import ParsedBlock, pool

    p = tmp_path / "sim.nmea"
    p.write_text(_sim_lines(300))
    with_files = list(iter_nmea_blocks(p, IngestConfig(), block_bytes=20000, workers=2))

    class Full:
        f_bavail, f_frsize = 0, 4096

    monkeypatch.setattr(memory.os, "statvfs", lambda path: Full())
    with memory.handover_dir(1) as folder:
        assert folder is None
    piped = list(iter_nmea_blocks(p, IngestConfig(), block_bytes=20000, workers=2))
    assert [b.lines for b in piped] == [b.lines for b in with_files]
    for a, b in zip(piped, with_files, strict=True):
        for kind, f in b.frames.items():
            assert a.frames[kind].equals(f), kind
    # a worker that cannot write its file hands the block back itself
    pb = pool.parse_range_to_file(
        str(tmp_path / "no" / "such" / "folder"), 0, str(p), 0, p.stat().st_size, False, True
    )
    assert isinstance(pb, ParsedBlock) and pool.load_parsed(pb) is pb
    assert not os_mod.path.exists(tmp_path / "no")


def test_a_parsed_block_survives_the_file_handover_unchanged(tmp_path):
    from dracc.ingest.nmea import blocks, pool

    p = tmp_path / "sim.nmea"
    p.write_text(_sim_lines(50))
    direct = blocks.parse_range(str(p), 0, p.stat().st_size, False, True)
    meta, sizes, name = pool.parse_range_to_file(
        str(tmp_path), 0, str(p), 0, p.stat().st_size, False, True
    )
    back = pool.load_parsed((meta, sizes, name))
    assert not Path(name).exists()
    assert back.n_lines == direct.n_lines and back.source_names == direct.source_names
    for kind, cols in direct.kinds.items():
        for c, v in cols.items():
            np.testing.assert_array_equal(back.kinds[kind][c], v)
            assert back.kinds[kind][c].dtype == v.dtype


# --------------------------------------------------------------------------- round trips
@settings(max_examples=60, deadline=None)
@given(
    lat=st.floats(-89.999, 89.999),
    lon=st.floats(-179.999, 179.999),
    sog_kn=st.floats(0, 60),
    cog=st.floats(0, 359.99),
    sec=st.integers(0, 86399),
)
def test_rmc_round_trip(lat, lon, sog_kn, cog, sec):
    def dm(v, w):
        a = abs(v)
        d = int(a)
        m = (a - d) * 60
        if round(m, 6) >= 60:
            d, m = d + 1, 0.0
        return f"{d:0{w}d}{m:09.6f}"

    hh, mm, ss = sec // 3600, sec // 60 % 60, sec % 60
    body = (
        f"GPRMC,{hh:02d}{mm:02d}{ss:02d}.00,A,{dm(lat, 2)},{'N' if lat >= 0 else 'S'},"
        f"{dm(lon, 3)},{'E' if lon >= 0 else 'W'},{sog_kn:.3f},{cog:.2f},141123,,,A"
    )
    r = parse_sentences([nmea(body).encode()], np.array([T0 * 10**9]), [""], "mem", IngestConfig())
    p = r.frames["position"].iloc[0]
    g = r.frames["ground"].iloc[0]
    assert p["lat_rad"] == pytest.approx(lat * D, abs=1e-6 / 60 * D)
    assert p["lon_rad"] == pytest.approx(lon * D, abs=1e-6 / 60 * D)
    assert g["sog_mps"] == pytest.approx(round(sog_kn, 3) * KN, abs=1e-9)
    assert g["cog_rad"] == pytest.approx(round(cog, 2) * D % (2 * math.pi), abs=1e-9)
    # rule 1: the time of day on the UTC day nearest the external (receive) time
    cands = [(T0 // 86400 + k) * 86400 + sec for k in (-1, 0, 1)]
    assert p["time_ns"] == min(cands, key=lambda c: abs(c - T0)) * 10**9


def test_parse_sentences_sources_and_anchor():
    lines = [
        nmea("INGGA,000000.50,5436.0,N,01847.0,E,1,,,25.0,M,,M,,").encode(),
        nmea("HEHDT,1.0,T").encode(),
    ]
    t = np.array([(T0 // 86400) * 86400 * 10**9 - 10**8, T0 * 10**9])  # 23:59:59.9 the day before
    r = parse_sentences(lines, t, ["/ins1/nmea", "/gyro/nmea"], "bag.mcap", IngestConfig())
    p = r.frames["position"].iloc[0]
    assert (
        p["source"] == "/ins1/nmea" and p["time_ns"] == (T0 // 86400) * 86400 * 10**9 + 500_000_000
    )
    assert (
        r.frames["heading"].iloc[0]["source"] == "/gyro/nmea"
        and r.frames["heading"].iloc[0]["time_ns"] == T0 * 10**9
    )


def test_broken_worker_pool_falls_back_to_this_process(tmp_path, monkeypatch):
    import os

    from dracc.ingest.nmea import StreamState
    from dracc.ingest.nmea import blocks as mod

    p = tmp_path / "sim.nmea"
    p.write_text(_sim_lines(100))
    parent = os.getpid()
    real = mod.parse_buffer

    def dying(*args, **kw):
        if os.getpid() != parent:
            os._exit(1)  # a worker killed (e.g. by the OOM killer)
        return real(*args, **kw)

    monkeypatch.setattr(mod, "parse_buffer", dying)  # the forked workers inherit the patch
    st = StreamState(str(p))
    blocks = list(iter_nmea_blocks(p, IngestConfig(), st, block_bytes=20000, workers=2))
    assert sum(len(b.frames["heading"]) for b in blocks) == 1000
    assert any("worker pool failed" in n for n in st.notes())


def _pool_ok_in_child(q):
    from dracc.ingest.nmea.pool import pool_ok

    q.put(pool_ok())


def test_regression_reader_parses_alone_inside_a_daemonic_process():
    """Inside a Dask worker (daemonic) the reader's own pool raised 'daemonic processes are
    not allowed to have children' for logs of 32 MB and more."""
    import multiprocessing

    ctx = multiprocessing.get_context("fork")
    q = ctx.Queue()
    p = ctx.Process(target=_pool_ok_in_child, args=(q,), daemon=True)
    p.start()
    allowed = q.get(timeout=60)
    p.join(timeout=60)
    assert allowed is False


# -------------------------------------------------------------- receive time (recv_ns)
MISSING = np.iinfo(np.int64).min
FIX = "221320.00"  # T0's time of day: 22:13:20


def _by_line(df) -> dict[int, int]:
    """line -> recv_ns - time_ns (the latency), MISSING where there is no receive time."""
    return {
        int(ln): MISSING if r == MISSING else int(r - t)
        for ln, r, t in zip(df["line"], df["recv_ns"], df["time_ns"], strict=True)
    }


@pytest.mark.parametrize("engine", ["c", "numpy"])
@pytest.mark.parametrize("form", ["tag_ms", "tag_s", "iso", "unix", "openrvdas", "signalk"])
def test_recv_ns_is_the_external_time_of_records_with_their_own_fix(
    tmp_path, monkeypatch, form, engine
):
    """A GGA fixed at 22:13:20.00 and received 1.5 s later (2 s for TAG c: in seconds) has
    recv_ns - time_ns = its latency; the RMC's ground row too; an HDT and a VTG (no time
    of fix) have none, nor a fix without an external time."""
    from dracc.ingest.nmea import engine_c as mod

    monkeypatch.setattr(mod, "ENGINE", engine)
    lag = 2.0 if form == "tag_s" else 1.5

    def stamped(sentence: str, src: str) -> str:
        t = T0 + lag
        if form == "tag_ms":
            return tag(f"s:{src},c:{int(t * 1000)}", sentence)
        if form == "tag_s":
            return tag(f"s:{src},c:{int(t)}", sentence)
        iso = pd.Timestamp(t * 10**9, unit="ns", tz="UTC").strftime("%Y-%m-%dT%H:%M:%S.%fZ")
        if form == "iso":
            return f"{iso} {sentence}"
        if form == "openrvdas":
            return f"{src.lower()} {iso} {sentence}"
        if form == "signalk":
            return f"{int(t * 1000)};A;{sentence}"
        return f"{t:.3f} {sentence}"

    lines = [
        nmea("GPZDA,221319.00,14,11,2023,00,00"),  # 1 date only
        stamped(nmea(f"GPGGA,{FIX},5436.0,N,01847.0,E,1,10,0.8,25.0,M,,M,,"), "GNSS"),  # 2
        stamped(nmea(f"GPRMC,{FIX},A,5436.0,N,01847.0,E,5.0,90.0,141123,,,A"), "GNSS"),  # 3
        stamped(nmea("HEHDT,60.0,T"), "GYRO"),  # 4 no fix time
        stamped(nmea("GPVTG,90.0,T,,M,5.0,N,9.3,K,A"), "GNSS"),  # 5 no fix time
        nmea("GPGGA,221321.00,5436.0,N,01847.0,E,1,10,0.8,25.0,M,,M,,"),  # 6 no external time
        stamped(nmea("GPGSV,1,1,01,05,40,083,46"), "GNSS"),  # 7 ignored
    ]
    r = read_text(tmp_path, "\r\n".join(lines) + "\r\n")
    assert r.rejects.total == 0 and r.ignored == {"GSV": 1}
    lat = round(lag * 1e9)
    assert _by_line(r.frames["position"]) == {2: lat, 3: lat, 6: MISSING}
    assert _by_line(r.frames["ground"]) == {3: lat, 5: MISSING}
    assert _by_line(r.frames["heading"]) == {4: MISSING}
    for f in r.frames.values():
        assert f["recv_ns"].dtype == np.int64
    pos = r.frames["position"]
    assert (
        pos.loc[pos["line"] == 2, "time_ns"].iloc[0] == T0 * 10**9
    )  # the fix time, not the receive time


def test_recv_ns_not_from_an_implausible_external_time(tmp_path):
    """A TAG c: before 2000 is not used by the time base: no receive time either."""
    lines = [
        nmea("GPZDA,221319.00,14,11,2023,00,00"),
        tag("s:GNSS,c:946684000", nmea(f"GPGGA,{FIX},5436.0,N,01847.0,E,1,10,0.8,25.0,M,,M,,")),
    ]
    r = read_text(tmp_path, "\n".join(lines) + "\n")
    p = one(r, "position")
    assert p["recv_ns"] == MISSING and p["time_ns"] == T0 * 10**9


def test_recv_ns_through_sentence_stream_with_separate_receive_times():
    """parse_sentences (CSV raw, MCAP): the given time is the receive time; a SentenceStream
    given ``recv_ns`` (MCAP log times beside message stamps) reports those instead, while
    the fix is still anchored to the given time."""
    from dracc.ingest.nmea import SentenceStream

    lines = [
        nmea(f"INGGA,{FIX},5436.0,N,01847.0,E,1,,,25.0,M,,M,,").encode(),
        nmea("HEHDT,1.0,T").encode(),
    ]
    t = np.array([T0 * 10**9 + 700_000_000, T0 * 10**9 + 800_000_000])
    r = parse_sentences(lines, t, ["ins1", "gyro"], "bag.mcap", IngestConfig())
    assert r.frames["position"]["recv_ns"].tolist() == [T0 * 10**9 + 700_000_000]
    assert r.frames["heading"]["recv_ns"].tolist() == [MISSING]
    s = SentenceStream("bag.mcap", IngestConfig())
    frames = s.add(lines, t, ["ins1", "gyro"], numbers=np.array([7, 9]), recv_ns=t + 10**9)
    res = s.result(frames + s.finish())
    p = res.frames["position"].iloc[0]
    assert (
        p["time_ns"] == T0 * 10**9 and p["recv_ns"] == T0 * 10**9 + 1_700_000_000 and p["line"] == 7
    )
    assert res.frames["heading"]["recv_ns"].tolist() == [MISSING]


def test_recv_ns_survives_blocks_and_workers(tmp_path):
    """The receive time is carried by every decoding path: the kernel and the numpy path,
    small blocks, and the worker processes' file hand-over, then the concatenation."""
    p = tmp_path / "sim.nmea"
    p.write_text(_sim_lines(300))
    whole = read_nmea(p, IngestConfig(), workers=1)
    pos = whole.frames["position"]
    assert (pos["recv_ns"] == pos["time_ns"]).all()  # c: is the second of the fix: latency 0
    assert (whole.frames["heading"]["recv_ns"] == MISSING).all()
    for blocks in (
        list(iter_nmea_blocks(p, IngestConfig(), block_bytes=7000, workers=1)),
        list(iter_nmea_blocks(p, IngestConfig(), block_bytes=20000, workers=2)),
    ):
        for kind in ("position", "heading", "water"):
            got = pd.concat([b.frames[kind] for b in blocks if kind in b.frames], ignore_index=True)
            got = got.sort_values(["time_ns", "line"], kind="stable").reset_index(drop=True)
            ref = (
                whole.frames[kind]
                .sort_values(["time_ns", "line"], kind="stable")
                .reset_index(drop=True)
            )
            np.testing.assert_array_equal(got["recv_ns"].to_numpy(), ref["recv_ns"].to_numpy())


# ------------------------------------------------------------- ignored, not rejected
def test_valid_unused_lines_are_ignored_by_type_and_never_fail_strict(tmp_path):
    """Valid sentences dracc does not use, comments and blank lines are not rejected (only
    damaged lines are) and do not make --strict fail: they are counted by type."""
    lines = [
        "# logged by gpsd",
        nmea("GPZDA,201500.00,14,11,2023,00,00"),
        nmea("GPGSV,1,1,01,05,40,083,46"),
        nmea("GPGSV,1,1,01,05,40,083,46"),
        nmea("IIMWV,322,R,05.8,N,A"),
        nmea("SDDBT,8.1,f,2.4,M,1.3,F"),
        nmea("PGRME,15.0,M,45.0,M,25.0,M"),
        nmea("PSRFTXT,Version 2.2"),  # a long proprietary address: its first 5 characters
        "!AIVDM,1,1,,B,13u=gHP3CWPlvs2Q8sHW:5fD0h6a,0*1B",
        # own-ship static data (type 5, two sentences; pyais/ tests' VDM as VDO): not read
        "!"
        + (a := "AIVDO,2,1,1,A,55?MbV02;H;s<HtKR20EHE:0@T4@Dn2222222216L961O5Gf0NSQEp6ClRp8,0")
        + "*"
        + cs(a),
        "!" + (b := "AIVDO,2,2,1,A,88888888880,2") + "*" + cs(b),
        "",
        nmea("HEHDT,10.0,T"),
    ]
    p = tmp_path / "log.nmea"
    p.write_text("\n".join(lines) + "\n")
    r = read_nmea(p, IngestConfig(strict=True))
    assert r.rejects.total == 0 and len(r.frames["heading"]) == 1
    assert r.ignored == {
        "comment": 1,
        "GSV": 2,
        "MWV": 1,
        "DBT": 1,
        "PGRME": 1,
        "PSRFT": 1,
        "VDM": 1,
        "VDO": 2,
        "blank": 1,
    }
    assert [e[1] for e in r.ignored_examples["GSV"]] == [3, 4]
    from dracc.ingest import read_logs

    v = read_logs([p], IngestConfig())
    assert v.ignored == r.ignored and v.inputs[0]["ignored"] == dict(r.ignored)
    assert v.inputs[0]["rejected"] == {} and v.rejects.total == 0


def test_ignored_counts_are_the_same_from_every_engine_and_block_size(tmp_path, monkeypatch):
    from dracc.ingest.nmea import StreamState
    from dracc.ingest.nmea import engine_c as mod

    body = "\n".join(
        [
            "# c",
            nmea("GPGSV,1,1,01,05,40,083,46"),
            nmea("PGRME,15.0,M,45.0,M,25.0,M"),
            "!AIVDM,1,1,,B,13u=gHP3CWPlvs2Q8sHW:5fD0h6a,0*1B",
            "",
            nmea("HEHDT,10.0,T"),
        ]
    )
    p = tmp_path / "log.nmea"
    p.write_text((body + "\n") * 400)
    want = {"comment": 400, "GSV": 400, "PGRME": 400, "VDM": 400, "blank": 400}
    for engine in ("c", "numpy"):
        monkeypatch.setattr(mod, "ENGINE", engine)
        for kw in (
            {"workers": 1},
            {"workers": 1, "block_bytes": 3000},
            {"workers": 2, "block_bytes": 20000},
        ):
            st_ = StreamState(str(p))
            list(iter_nmea_blocks(p, IngestConfig(), st_, **kw))
            assert st_.ignored == want, (engine, kw)
            assert [e[1] for e in st_.ignored_examples["GSV"]] == [2, 8, 14], (engine, kw)


def test_an_rmc_without_any_time_is_one_no_date_line(tmp_path):
    """An RMC gives a position and a ground record; with no time anywhere in the log (no
    time of fix, no receive time) it is one line rejected as no_date, not two."""
    r = read_text(
        tmp_path,
        nmea("GPRMC,,A,5436.0,N,01847.0,E,5.0,90.0,,,,A")
        + "\n"
        + nmea("GPGGA,,5436.0,N,01847.0,E,1,10,0.8,25.0,M,,M,,")
        + "\n",
    )
    assert r.rejects.counts == {"no_date": 2} and r.records == 0
    assert [e[1] for e in r.rejects.examples["no_date"]] == [1, 2]


def test_an_rmc_without_a_date_is_read_on_the_assumed_date(tmp_path):
    """Times of day but no date anywhere: both lines read, on the assumed date."""
    r = read_text(
        tmp_path,
        nmea("GPRMC,221320.00,A,5436.0,N,01847.0,E,5.0,90.0,,,,A")
        + "\n"
        + nmea("GPGGA,221321.00,5436.0,N,01847.0,E,1,10,0.8,25.0,M,,M,,")
        + "\n",
    )
    assert r.rejects.total == 0 and r.records == 3  # RMC: position and ground; GGA
    day0 = 946_684_800 * 10**9  # 2000-01-01T00:00:00Z
    t = r.frames["position"]["time_ns"].tolist()
    assert t == [day0 + 80_000 * 10**9, day0 + 80_001 * 10**9]
    assert r.time_events.assumed_date == "2000-01-01"


def test_recv_ns_stays_with_its_rows_when_files_merge(tmp_path):
    """read_logs sorts the records of several files by time: each keeps its receive time."""
    from dracc.ingest import read_logs

    paths = []
    for name, src, lag_ms, off in (("a.nmea", "GNSS1", 1500, 0), ("b.nmea", "GNSS2", 500, 0.5)):
        lines = [nmea("GPZDA,221319.00,14,11,2023,00,00")]
        for k in range(20):
            t = T0 + k + off
            tod = f"2213{20 + k:02d}.{int(off * 100):02d}"
            lines.append(
                tag(
                    f"s:{src},c:{int(t * 1000) + lag_ms}",
                    nmea(f"GPGGA,{tod},5436.0,N,01847.0,E,1,10,0.8,25.0,M,,M,,"),
                )
            )
            lines.append(tag(f"s:{src},c:{int(t * 1000) + lag_ms}", nmea("HEHDT,10.0,T")))
        p = tmp_path / name
        p.write_text("\n".join(lines) + "\n")
        paths.append(p)
    v = read_logs(paths, IngestConfig())
    pos = v.frames["position"]
    assert len(pos) == 40 and (np.diff(pos["time_ns"]) > 0).all()  # interleaved by time
    lag = (pos["recv_ns"] - pos["time_ns"]).groupby(pos["source"].astype(str)).unique()
    assert {k: list(x) for k, x in lag.items()} == {
        "GNSS1": [1_500_000_000],
        "GNSS2": [500_000_000],
    }
    assert (v.frames["heading"]["recv_ns"] == MISSING).all()


def test_invalid_velocity_flags_leave_the_velocity_empty(tmp_path):
    """VTG mode N and RMC status V carry no valid course and speed: NaN in the ground frame
    (both engines), so no DR uses them and the integrity audit counts them as flagged."""
    from dracc.core.config import IngestConfig
    from dracc.ingest import nmea as nm
    from dracc.ingest.nmea import engine_c

    def s(body: str) -> str:
        cs = 0
        for ch in body.encode():
            cs ^= ch
        return f"${body}*{cs:02X}\n"

    text = "".join(
        [
            s("GPRMC,120000.00,A,5436.000,N,01848.000,E,12.0,045.0,010326,,,A"),
            s("GPRMC,120001.00,V,5436.001,N,01848.001,E,12.0,045.0,010326,,,N"),
            s("GPVTG,045.0,T,,M,12.0,N,22.2,K,A"),
            s("GPVTG,045.0,T,,M,12.0,N,22.2,K,N"),
        ]
    )
    log = tmp_path / "v.nmea"
    log.write_text(text)
    for engine in ("numpy", "c"):
        if engine == "c" and engine_c._nmeascan is None:
            continue
        old = engine_c.ENGINE
        engine_c.ENGINE = engine
        try:
            g = nm.read_nmea(log, IngestConfig()).frames["ground"]
        finally:
            engine_c.ENGINE = old
        sog = g["sog_mps"].to_numpy()
        assert (
            np.isfinite(sog[0]) and np.isnan(sog[1]) and np.isfinite(sog[2]) and np.isnan(sog[3])
        ), engine
