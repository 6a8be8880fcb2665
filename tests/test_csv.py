"""CSV voyage logs: long/wide/raw forms, units from names, bad rows by reason and line."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from dracc.core.config import IngestConfig
from dracc.core.errors import ConfigError, IngestError
from dracc.core.quantities import QUANTITIES
from dracc.frames import make_frame
from dracc.ingest.csv import looks_like_csv, parse_times, read_csv
from dracc.sim.csv_out import write_csv

T0 = 1_700_000_000_000_000_000


def voyage_frames(n: int = 40, seed: int = 1) -> dict[str, pd.DataFrame]:
    """Canonical frames of every kind with awkward values (0, near 2*pi, NaN, negatives)."""
    rng = np.random.default_rng(seed)
    t = T0 + np.arange(n, dtype=np.int64) * 1_000_000_000 + 123_456_789

    def common(src, sen):
        return {
            "time_ns": t,
            "source": np.full(n, src, object),
            "sentence": np.full(n, sen, object),
            "line": np.arange(1, n + 1),
        }

    hd = rng.uniform(0, 2 * math.pi, n)
    hd[:2] = [0.0, 2 * math.pi - 1e-12]
    alt = rng.normal(20, 3, n)
    alt[3] = np.nan
    return {
        "position": make_frame(
            "position",
            {
                **common("INS2", "GGA"),
                "lat_rad": rng.uniform(-1.5, 1.5, n),
                "lon_rad": rng.uniform(-3.1, 3.1, n),
                "alt_m": alt,
                "quality": rng.choice([0, 1, 2, 4], n),
                "hdop": rng.uniform(0.5, 3, n),
            },
        ),
        "heading": make_frame(
            "heading",
            {
                **common("GYRO", "HDT"),
                "heading_rad": hd,
                "reference": np.where(np.arange(n) % 2, "T", "M").astype(object),
                "deviation_rad": rng.normal(0, 0.02, n),
                "variation_rad": np.full(n, 0.05),
            },
        ),
        "ground": make_frame(
            "ground",
            {
                **common("INS2", "VTG"),
                "cog_rad": rng.uniform(0, 6.28, n),
                "sog_mps": rng.uniform(0, 9, n),
            },
        ),
        "water": make_frame(
            "water",
            {
                **common("LOG", "VBW"),
                "stw_mps": rng.uniform(-1, 9, n),
                "stw_transverse_mps": rng.normal(0, 0.2, n),
                "sog_long_mps": rng.uniform(0, 9, n),
                "sog_transverse_mps": np.nan * np.ones(n),
            },
        ),
        "distance": make_frame(
            "distance",
            {
                **common("LOG", "VLW"),
                "total_water_m": 1e6 + np.arange(n) * 5.0,
                "trip_water_m": np.arange(n) * 5.0,
            },
        ),
        "rot": make_frame("rot", {**common("GYRO", "ROT"), "rot_radps": rng.normal(0, 0.01, n)}),
    }


def assert_same_frames(
    a: dict[str, pd.DataFrame],
    b: dict[str, pd.DataFrame],
    rtol: float = 1e-13,
    skip: tuple[str, ...] = (),
) -> None:
    for kind, fa in a.items():
        fb = b[kind]
        assert len(fa) == len(fb), kind
        fa = fa.sort_values(["time_ns", "source"], kind="stable").reset_index(drop=True)
        fb = fb.sort_values(["time_ns", "source"], kind="stable").reset_index(drop=True)
        np.testing.assert_array_equal(fa["time_ns"].to_numpy(), fb["time_ns"].to_numpy())
        np.testing.assert_array_equal(
            fa["source"].astype(str).to_numpy(), fb["source"].astype(str).to_numpy()
        )
        for c in fa.columns:
            if c in skip or c in ("time_ns", "source", "talker", "sentence", "line"):
                continue
            if fa[c].dtype.kind == "f":
                np.testing.assert_allclose(
                    fb[c].to_numpy(),
                    fa[c].to_numpy(),
                    rtol=rtol,
                    atol=1e-15,
                    equal_nan=True,
                    err_msg=f"{kind}.{c}",
                )
            else:
                np.testing.assert_array_equal(
                    fb[c].astype(str).to_numpy(),
                    fa[c].astype(str).to_numpy(),
                    err_msg=f"{kind}.{c}",
                )


@pytest.mark.parametrize("form", ["long", "wide"])
def test_round_trip_same_frames(tmp_path, form):
    fr = voyage_frames()
    p = write_csv(fr, tmp_path / f"v_{form}.csv", form=form)
    r = read_csv(p, IngestConfig())
    assert r.format == f"csv-{form}"
    assert r.rejects.total == 0, dict(r.rejects.counts)
    assert_same_frames(fr, r.frames)


def test_units_from_names_knots_never_read_as_mps(tmp_path):
    p = tmp_path / "u.csv"
    p.write_text(
        "time_utc,source,quantity,value\n"
        "2024-05-01T00:00:00Z,LOG,stw_kn,10\n"
        "2024-05-01T00:00:01Z,LOG,stw_mps,10\n"
        "2024-05-01T00:00:02Z,LOG,stw_kmh,36\n"
        "2024-05-01T00:00:00Z,LOG,total_water_nmi,2.5\n"
        "2024-05-01T00:00:00Z,GYRO,rot_degpmin,30\n"
        "2024-05-01T00:00:00Z,GYRO,heading_deg,360\n"
        "2024-05-01T00:00:01Z,GYRO,heading_rad,1.5\n"
    )
    r = read_csv(p, IngestConfig())
    w = r.frames["water"]["stw_mps"].to_numpy()
    np.testing.assert_allclose(
        w, [10 * 1852 / 3600, 10.0, 10.0], rtol=1e-15
    )  # 10 kn = 5.1444 m/s by hand
    assert r.frames["distance"]["total_water_m"].iloc[0] == pytest.approx(2.5 * 1852.0)
    assert r.frames["rot"]["rot_radps"].iloc[0] == pytest.approx(30 / 60 * math.pi / 180)
    np.testing.assert_allclose(
        r.frames["heading"]["heading_rad"].to_numpy(), [0.0, 1.5]
    )  # 360 deg -> 0
    assert r.frames["heading"]["reference"].tolist() == ["T", "T"]


def test_quantity_table_factors():
    assert QUANTITIES["sog_kn"].factor == 1852 / 3600
    assert QUANTITIES["lat_deg"].factor == math.pi / 180
    assert QUANTITIES["stw_mps"].factor == 1.0
    assert QUANTITIES["trip_water_nmi"].column == "trip_water_m"


def test_bad_rows_counted_by_reason_with_line_numbers(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text(
        "time_utc,source,quantity,value\n"  # 1
        "2024-05-01T00:00:00Z,INS1,lat_deg,54.5\n"  # 2
        "2024-05-01T00:00:00Z,INS1,lon_deg,18.5\n"  # 3
        "\n"  # 4 blank
        "2024-05-01T00:00:01Z,INS1,lat_deg\n"  # 5 too few fields
        "yesterday,INS1,lat_deg,54.6\n"  # 6 bad time
        "2024-05-01T00:00:01Z,INS1,speed,3\n"  # 7 unknown quantity
        "2024-05-01T00:00:01Z,LOG,stw_kn,fast\n"  # 8 not a number
        "2024-05-01T00:00:02Z,INS1,lat_deg,95\n"  # 9 out of range -> with 10 a bad position
        "2024-05-01T00:00:02Z,INS1,lon_deg,18.6\n"  # 10
        "2024-05-01T00:00:03Z,LOG,stw_kn,\n"  # 11 empty value
        "2024-05-01T00:00:03Z,LOG,stw_kn,5\n"
    )  # 12
    r = read_csv(p, IngestConfig())
    c = r.rejects.counts
    ex = {k: [e[1] for e in v] for k, v in r.rejects.examples.items()}
    assert c["blank line"] == 1 and ex["blank line"] == [4]
    assert ex["wrong number of fields (3, header has 4)"] == [5]
    assert ex["bad time"] == [6]
    assert ex["unknown quantity"] == [7]
    assert ex["value not a number"] == [8]
    assert ex["lat_rad out of range"] == [9]
    assert ex["empty value"] == [11]
    assert r.rejects.total == 7
    assert len(r.frames["position"]) == 1 and r.frames["position"]["line"].tolist() == [2]
    assert r.frames["water"]["line"].tolist() == [12]
    with pytest.raises(IngestError, match="strict"):
        read_csv(p, IngestConfig(strict=True))


def test_wide_form_declared_units_and_ignored_columns(tmp_path):
    p = tmp_path / "w.csv"
    p.write_text(
        "time_utc,Speed (kn),heading_deg,speed,comment\n"
        "2024-05-01T00:00:00,10,90,1,a\n"
        "2024-05-01T00:00:01,12,,1,b\n"
    )
    cfg = IngestConfig(quantities={"Speed (kn)": "stw_kn"})
    r = read_csv(p, cfg)
    assert r.frames["water"]["stw_mps"].tolist() == pytest.approx(
        [10 * 1852 / 3600, 12 * 1852 / 3600]
    )
    assert r.frames["water"]["source"].astype(str).tolist() == [
        "w",
        "w",
    ]  # file stem without a source column
    assert len(r.frames["heading"]) == 1
    assert any("'speed' ignored" in n and "unit" in n for n in r.notes)
    assert any("'comment' ignored" in n for n in r.notes)
    with pytest.raises(ConfigError, match="not a quantity"):
        read_csv(p, IngestConfig(quantities={"Speed (kn)": "stw_knots"}))


def test_time_forms():
    t, ok = parse_times(
        np.array(
            [
                "2024-05-01T00:00:00.5Z",
                "2024-05-01 00:00:00.5",
                "1714521600.5",
                "1714521600500",
                "2024-05-01T02:00:00.5+02:00",
                "soon",
                "",
            ],
            dtype=object,
        ),
        "time_utc",
    )
    ref = 1714521600_500_000_000
    assert ok.tolist() == [True] * 5 + [False, False]
    assert t[:5].tolist() == [ref] * 5
    t, ok = parse_times(np.array(["1714521600500000001"], dtype=object), "time_ns")
    assert t[0] == 1714521600500000001 and ok.all()


def test_detection():
    assert looks_like_csv(b"time_utc,source,quantity,value\n2024-...")
    assert looks_like_csv(b"\xef\xbb\xbfreceived_at,protocol,msg_type,source,raw_data\r\n")
    assert looks_like_csv(b"time_utc,lat_deg,lon_deg\n")
    assert not looks_like_csv(b"$GPGGA,092542.00,4846.4008666,N,00854.7249096,E,4,12*66\r\n")
    assert not looks_like_csv(b"\\s:INS2,c:1700000000*5B\\$INHDT,12.0,T*2A\n")
    assert not looks_like_csv(b"hello world\n")
    assert not looks_like_csv(b"a,b,c\n1,2,3\n")


def test_not_a_csv_header_is_a_clear_error(tmp_path):
    p = tmp_path / "x.csv"
    p.write_text("a,b,c\n1,2,3\n")
    with pytest.raises(IngestError, match=r"x.csv:1: not a dracc CSV header"):
        read_csv(p, IngestConfig())


# real sentences from ros-drivers/nmea_navsat_driver test/logs/nmea.log (BSD-3-Clause),
# placed in a logger CSV: a derived fixture
REAL_LINES = [
    "$GNRMC,092542.00,A,4846.4008666,N,00854.7249096,E,0.011,,200420,,,R,V*01",
    "$GNGGA,092542.00,4846.4008666,N,00854.7249096,E,4,12,0.47,419.166,M,47.535,M,0.0,0000*66",
    "$GNRMC,092542.50,A,4846.4008639,N,00854.7249134,E,0.017,,200420,,,R,V*01",
]


def test_raw_logger_csv_goes_through_the_nmea_parser(tmp_path, real_dir):
    lines = (real_dir / "nmea_navsat_driver" / "nmea.log").read_text().splitlines()
    assert lines[:3] == REAL_LINES
    p = tmp_path / "logger.csv"
    rows = ["received_at,protocol,msg_type,source,raw_data"]
    for i, s in enumerate(lines[:20]):
        rows.append(
            f'2020-04-20T09:25:{42 + i // 4:02d}.{(i % 4) * 25:02d}Z,NMEA0183,{s[3:6]},GNSS,"{s}"'
        )
    # an NMEA 2000 row as OpenCPN's data logger writes it: the Actisense BST 0x93 bytes
    # (prio, PGN LE, dst, src, timer, length, data) of a real 127250 (canboat/scx20.raw
    # line 5), and a row that is no such message
    heading = bytes.fromhex("ff4a3bff7f7af8fc")
    bst = bytes([0x93, 13 + 8, 2, 0x12, 0xF1, 0x01, 255, 1, 0, 0, 0, 0, 8]) + heading
    rows.append(f'2020-04-20T09:25:59Z,NMEA2000,127250,N2K,"{bst.hex(" ")} 00"')
    rows.append('2020-04-20T09:25:59.5Z,NMEA2000,129025,N2K,"0x1234"')
    p.write_text("\n".join(rows) + "\n")
    r = read_csv(p, IngestConfig())
    assert r.format == "csv-raw"
    assert r.rejects.counts == {"bst_message": 1} and "NMEA 2000" not in r.ignored
    hd = r.frames["heading"]
    assert hd["sentence"].astype(str).tolist() == ["PGN127250"] and hd["line"].tolist() == [22]
    # canboat's analyzer on that line: "Heading": 87.0 (printed to 0.1 deg), "Reference": "True"
    assert math.degrees(hd["heading_rad"].iloc[0]) == pytest.approx(87.0, abs=0.05)
    assert hd["reference"].iloc[0] == "T"
    assert hd["time_ns"].iloc[0] == pd.Timestamp("2020-04-20T09:25:59Z").value
    pos = r.frames["position"]
    assert len(pos) == 20  # 10 RMC + 10 GGA
    assert set(pos["source"].astype(str)) == {"GNSS"}
    gga = pos[pos["sentence"].astype(str) == "GGA"].iloc[0]
    assert gga["line"] == 3  # second data row of the CSV
    assert math.degrees(gga["lat_rad"]) == pytest.approx(48 + 46.4008666 / 60, abs=1e-12)
    assert math.degrees(gga["lon_rad"]) == pytest.approx(8 + 54.7249096 / 60, abs=1e-12)
    assert gga["quality"] == 4
    # the logger's receive time (09:25:42.25) is the GGA's receive time; its fix 09:25:42.00
    assert gga["recv_ns"] == pd.Timestamp("2020-04-20T09:25:42.25Z").value
    assert gga["recv_ns"] - gga["time_ns"] == 250_000_000


def test_raw_csv_rejects_name_csv_lines(tmp_path):
    p = tmp_path / "logger.csv"
    p.write_text(
        "received_at,raw_data\n"
        '2020-04-20T09:25:42Z,"$GNGGA,092542.00,4846.4008666,N,00854.7249096,E,4,12,0.47,419.166,M,47.535,M,0.0,0000*66"\n'
        '2020-04-20T09:25:43Z,"$GNGGA,092543.00,4846.4008666,N,00854.7249096,E,4,12,0.47,419.166,M,47.535,M,0.0,0000*00"\n'
    )
    r = read_csv(p, IngestConfig())
    assert len(r.frames["position"]) == 1
    ((reason, ex),) = r.rejects.examples.items()
    assert r.rejects.counts[reason] == 1 and ex[0][1] == 3  # the bad checksum is on CSV line 3


@pytest.mark.parametrize("form", ["long", "wide"])
def test_small_blocks_and_unsorted_rows_give_the_same_frames(tmp_path, monkeypatch, form):
    """The long form makes a time's rows into records once a later time is seen, block by
    block; a file not sorted by time is read again whole.  Blocks of 2 kB (a record's rows
    split over blocks), and the same rows shuffled, give the frames of one big block."""
    import dracc.ingest.csv as csv_mod

    fr = voyage_frames(n=400)
    p = write_csv(fr, tmp_path / f"v_{form}.csv", form=form)
    whole = read_csv(p, IngestConfig())
    monkeypatch.setattr(csv_mod, "_BLOCK_BYTES", 2048)
    small = read_csv(p, IngestConfig())
    head, *body = p.read_text(encoding="utf-8").splitlines(keepends=True)
    rng = np.random.default_rng(4)
    shuffled = tmp_path / f"shuffled_{form}.csv"
    shuffled.write_text(
        head + "".join(body[i] for i in rng.permutation(len(body))), encoding="utf-8"
    )
    import dracc.ingest.csv_long as csv_long

    passes = []
    real_pass = csv_long.read_long_pass

    def counted(*args, streaming):
        passes.append(streaming)
        return real_pass(*args, streaming=streaming)

    monkeypatch.setattr(csv_long, "read_long_pass", counted)
    mixed = read_csv(shuffled, IngestConfig())
    if form == "long":
        assert passes == [True, False]  # the unsorted rows were noticed and the file read again
    assert small.lines == whole.lines == mixed.lines
    for kind, f in whole.frames.items():
        pd.testing.assert_frame_equal(small.frames[kind], f, check_categorical=False)
        # shuffled: the same records, their lines where the rows went
        cols = [c for c in f.columns if c != "line"]
        pd.testing.assert_frame_equal(
            mixed.frames[kind][cols]
            .sort_values(["time_ns", "source"], kind="stable")
            .reset_index(drop=True),
            f[cols].sort_values(["time_ns", "source"], kind="stable").reset_index(drop=True),
            check_categorical=False,
        )
    assert dict(small.rejects.counts) == dict(whole.rejects.counts) == dict(mixed.rejects.counts)
