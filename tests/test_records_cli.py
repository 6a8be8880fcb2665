"""``dracc records LOG --out FILE.parquet|FILE.csv|-``: every decoded record as one table.

Checked against what the log itself says (each row's fields parsed again from its raw
line, here, by a few lines of plain Python) and against the canonical frames converted by
hand (deg = rad * 180 / pi, kn = m/s * 3600 / 1852, nmi = m / 1852); the Parquet read back
with DuckDB, the CSV with pandas."""

from __future__ import annotations

import math
import os
from collections import Counter
from pathlib import Path

import duckdb
import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from conftest import real_path

from dracc.cli.main import main
from dracc.core.config import Config
from dracc.core.errors import ExitCode
from dracc.frames import MISSING_NS
from dracc.ingest import read_logs

SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"
LOGS = {
    "sample": lambda: SAMPLES / "voyage_tag.nmea",
    "bundg": lambda: real_path("gpsd", "bundg_zeus_9.log"),
}
DEG, KN, NMI = 180.0 / math.pi, 3600.0 / 1852.0, 1.0 / 1852.0
#: frame kind -> (frame column, table column, factor)
BY_HAND = {
    "position": [("lat_rad", "lat_deg", DEG), ("lon_rad", "lon_deg", DEG), ("alt_m", "alt_m", 1)]
    + [("hdop", "hdop", 1), ("quality", "fix_quality", 1)],
    "heading": [("heading_rad", "heading_deg", DEG), ("variation_rad", "variation_deg", DEG)]
    + [("deviation_rad", "deviation_deg", DEG), ("heading_quality", "heading_quality", 1)],
    "ground": [("cog_rad", "cog_deg", DEG), ("sog_mps", "sog_kn", KN)],
    "water": [("stw_mps", "stw_kn", KN), ("stw_transverse_mps", "stw_transverse_kn", KN)]
    + [("sog_long_mps", "sog_long_kn", KN), ("sog_transverse_mps", "sog_transverse_kn", KN)],
    "distance": [
        ("total_water_m", "total_water_nmi", NMI),
        ("trip_water_m", "trip_water_nmi", NMI),
    ],
    "rot": [("rot_radps", "rot_degpmin", DEG * 60)],
}


@pytest.fixture(scope="module", params=sorted(LOGS))
def log(request, tmp_path_factory):
    """A log, its records as Parquet (read back with DuckDB) and CSV, and its frames."""
    path = LOGS[request.param]()
    out = tmp_path_factory.mktemp(request.param)
    for name in ("r.parquet", "r.csv"):
        assert main(["records", str(path), "--out", str(out / name)]) == ExitCode.OK
    table = _duckdb(f"SELECT * FROM '{out / 'r.parquet'}'").to_arrow_table().to_pandas()
    csv = pd.read_csv(out / "r.csv", keep_default_na=False, na_values=[""])
    voyage = read_logs([path], Config().ingest)
    return {"path": path, "out": out, "table": table, "csv": csv, "voyage": voyage}


def _duckdb(query: str) -> duckdb.DuckDBPyRelation:
    con = duckdb.connect()
    con.execute("SET TimeZone = 'UTC'")
    return con.sql(query)


def _ns(times: pd.Series) -> np.ndarray:
    """int64 ns since the epoch of a column of times (NaT: MISSING_NS)."""
    return pd.DatetimeIndex(times).as_unit("ns").asi8


def _raw(path: Path) -> dict[int, list[str]]:
    """Line number -> the fields of the sentence on it (checksum valid), from the text."""
    out = {}
    for n, text in enumerate(path.read_text(encoding="ascii", errors="replace").splitlines(), 1):
        start = text.find("$")
        body, _, check = text[start + 1 :].partition("*")
        if start < 0 or len(check) < 2:
            continue
        xor = 0
        for ch in body:
            xor ^= ord(ch)
        if f"{xor:02X}" == check[:2].upper():
            out[n] = body.split(",")
    return out


def _num(field: str) -> float:
    return float(field) if field else math.nan


def _angle(value: str, hemisphere: str) -> float:
    """ddmm.mmm / dddmm.mmm with its hemisphere -> signed degrees."""
    if not value:
        return math.nan
    head, _, _ = value.partition(".")
    deg = float(value[: len(head) - 2]) + float(value[len(head) - 2 :]) / 60
    return -deg if hemisphere in "SW" else deg


def _expected(f: list[str]) -> dict[str, float]:
    """What the table must hold for a sentence, read from its fields by hand."""
    kind = f[0][2:]
    if kind == "GGA":
        return {"lat_deg": _angle(f[2], f[3]), "lon_deg": _angle(f[4], f[5])} | {
            "fix_quality": _num(f[6]),
            "hdop": _num(f[8]),
            "alt_m": _num(f[9]),
        }
    if kind == "RMC":
        return {"lat_deg": _angle(f[3], f[4]), "lon_deg": _angle(f[5], f[6])} | {
            "sog_kn": _num(f[7]),
            "cog_deg": _num(f[8]),
            "fix_quality": 1.0 if f[2] == "A" else 0.0,
        }
    if kind == "GLL":
        return {"lat_deg": _angle(f[1], f[2]), "lon_deg": _angle(f[3], f[4])}
    if kind == "VTG":
        return {"cog_deg": _num(f[1]), "sog_kn": _num(f[5])}
    if kind in ("HDT", "THS"):
        return {"heading_deg": _num(f[1])}
    if kind == "HDG":
        sign = -1 if f[5] == "W" else 1
        return {"heading_deg": _num(f[1]), "variation_deg": sign * _num(f[4])}
    if kind == "VHW":
        return {"stw_kn": _num(f[5])}
    if kind == "VBW":
        return {"stw_kn": _num(f[1]), "stw_transverse_kn": _num(f[2])} | {
            "sog_long_kn": _num(f[4]),
            "sog_transverse_kn": _num(f[5]),
        }
    if kind == "VLW":
        return {"total_water_nmi": _num(f[1]), "trip_water_nmi": _num(f[3])}
    if kind == "ROT":
        return {"rot_degpmin": _num(f[1])}
    raise AssertionError(f"no hand reading for {kind}")


def test_every_row_holds_what_its_line_says(log):
    table, raw = log["table"], _raw(log["path"])
    assert len(table) > 1000
    checked = Counter()
    for row in table.itertuples(index=False):
        fields = raw[row.line]
        assert fields[0][2:] == row.sentence and fields[0][:2] == row.talker
        for column, value in _expected(fields).items():
            got = getattr(row, column)
            got = math.nan if got is None or got is pd.NA else float(got)
            assert got == pytest.approx(value, rel=1e-12, abs=1e-12, nan_ok=True), (row, column)
        checked[row.sentence] += 1
    # every valid sentence of a type dracc decodes is one row, no more
    in_text = Counter(f[0][2:] for f in raw.values() if f[0][2:] in checked)
    assert checked == in_text


def test_counts_per_sentence_are_the_frames_counts(log):
    got = dict(
        _duckdb(
            f"SELECT sentence, count(*) FROM '{log['out'] / 'r.parquet'}' GROUP BY sentence"
        ).fetchall()
    )
    frames = log["voyage"].frames
    want: dict[str, int] = {}
    for kind, df in frames.items():
        for sentence, n in Counter(df["sentence"].astype(str)).items():
            # an RMC is one record: the position row and the ground row of the same line
            assert want.setdefault(sentence, n) == n, (kind, sentence)
    assert got == want
    assert len(log["table"]) == sum(len(f) for f in frames.values()) - len(
        frames["ground"].query("sentence == 'RMC'")
    )


def test_values_are_the_frames_converted_by_hand(log):
    table = log["table"].set_index("line")
    assert table.index.is_unique  # one sentence per line in these logs
    for kind, columns in BY_HAND.items():
        df = log["voyage"].frames[kind]
        rows = table.loc[df["line"].to_numpy()]
        assert (rows["sentence"].to_numpy() == df["sentence"].astype(str).to_numpy()).all()
        assert (rows["source"].to_numpy() == df["source"].astype(str).to_numpy()).all()
        np.testing.assert_array_equal(_ns(rows["time_utc"]), df["time_ns"].to_numpy())
        np.testing.assert_array_equal(_ns(rows["recv_utc"]), df["recv_ns"].to_numpy())
        for frame_col, col, factor in columns:
            want = df[frame_col].to_numpy(dtype=float) * factor
            got = rows[col].to_numpy(dtype=float, na_value=np.nan)
            np.testing.assert_allclose(got, want, rtol=1e-13, atol=0, equal_nan=True)
        if kind == "heading":
            ref = df["reference"].astype(object).where(df["reference"].notna(), None)
            assert list(rows["heading_ref"]) == list(ref)


def test_times_are_utc_and_rows_in_time_then_line_order(log):
    schema = pq.read_schema(log["out"] / "r.parquet")
    assert str(schema.field("time_utc").type) == "timestamp[ns, tz=UTC]"
    rel = _duckdb(f"SELECT time_utc, recv_utc FROM '{log['out'] / 'r.parquet'}'")
    assert all("TZ" in str(t) or "TIME ZONE" in str(t) for t in rel.types)  # tz-aware
    assert str(log["table"]["time_utc"].dt.tz) == "UTC"
    t = pd.read_parquet(log["out"] / "r.parquet", columns=["time_utc", "line"])
    assert str(t["time_utc"].dt.tz) == "UTC"
    key = list(zip(_ns(t["time_utc"]), t["line"], strict=True))
    assert key == sorted(key)


def test_roles_and_files_are_the_sources(log):
    table, sources = log["table"], log["voyage"].sources
    for key, info in sources.items():
        rows = table[table["source"] == key]
        assert set(rows["role"]) == {info.role or ""}
        assert set(rows["file"]) == {str(log["path"])}


def test_csv_holds_the_same_values(log):
    pq_table, csv = log["table"], log["csv"]
    assert list(csv.columns) == list(pq_table.columns)
    assert len(csv) == len(pq_table)
    t = pd.to_datetime(csv["time_utc"], format="ISO8601")
    assert str(t.dt.tz) == "UTC" and csv["time_utc"].str.endswith("Z").all()
    assert (_ns(t) == _ns(pq_table["time_utc"])).all()
    for col in ("source", "talker", "sentence", "role", "file", "heading_ref"):
        want = pq_table[col].fillna("").astype(str).to_numpy()
        assert (csv[col].fillna("").astype(str).to_numpy() == want).all(), col
    for col in pq_table.columns[8:]:
        if col == "heading_ref":
            continue
        want = pq_table[col].to_numpy(dtype=float, na_value=np.nan)
        scale = np.nanmax(np.abs(want), initial=0.0)
        np.testing.assert_allclose(
            csv[col].to_numpy(dtype=float), want, rtol=0, atol=1e-13 * scale, equal_nan=True
        )


def test_csv_numbers_read_as_the_log_wrote_them(log):
    # 229.8 degrees went through radians and back: 15 significant digits show it as 229.8
    raw = _raw(log["path"])
    text = (log["out"] / "r.csv").read_text().splitlines()
    header = text[0].replace('"', "").split(",")
    at = header.index("heading_deg")
    lines = header.index("line")
    shown = 0
    for row in text[1:400]:
        cells = row.split(",")
        fields = raw[int(cells[lines])]
        if fields[0][2:] in ("HDT", "HDG", "THS"):
            assert cells[at] == str(float(fields[1])).removesuffix(".0"), (row, fields)
            shown += 1
    assert shown > 10


def test_csv_on_stdout_is_the_file(run_cli, log):
    code, out, err = run_cli("records", log["path"], "--out", "-")
    assert code == ExitCode.OK, err
    assert out == (log["out"] / "r.csv").read_text()


def test_kinds_filter(run_cli, tmp_path):
    target = tmp_path / "k.parquet"
    code, _, err = run_cli(
        "records", SAMPLES / "voyage_tag.nmea", "--out", target, "--kinds", "position,heading"
    )
    assert code == ExitCode.OK, err
    t = pd.read_parquet(target)
    assert set(t["sentence"]) == {"GGA", "RMC", "HDT", "HDG", "THS"}
    rmc = t[t["sentence"] == "RMC"]
    assert rmc["lat_deg"].notna().all() and rmc["sog_kn"].isna().all()


def test_mcap_receive_times(run_cli, tmp_path):
    log = SAMPLES / "voyage.mcap"
    target = tmp_path / "m.parquet"
    assert run_cli("records", log, "--out", target)[0] == ExitCode.OK
    t = pd.read_parquet(target).set_index(["sentence", "line"])
    for df in read_logs([log], Config().ingest).frames.values():
        if not len(df):
            continue
        rows = t.loc[list(zip(df["sentence"].astype(str), df["line"], strict=True))]
        assert (df["recv_ns"] != MISSING_NS).all()  # MCAP: every message has its log time
        np.testing.assert_array_equal(_ns(rows["recv_utc"]), df["recv_ns"].to_numpy())


@pytest.mark.parametrize("target", ["x.xlsx", "x", "x.parquet.gz", "/dev/stdout"])
def test_an_unknown_suffix_is_a_usage_error(run_cli, tmp_path, target):
    out = tmp_path / "out"
    code, stdout, err = run_cli("records", SAMPLES / "voyage_tag.nmea", "--out", out / target)
    assert code == ExitCode.USAGE and stdout == ""
    assert ".parquet" in err and ".csv" in err and "standard output" in err
    assert not out.exists()


def test_bad_kinds_and_no_records(run_cli, tmp_path):
    code, _, err = run_cli(
        "records", SAMPLES / "voyage_tag.nmea", "--out", tmp_path / "a.csv", "--kinds", "wind"
    )
    assert code == ExitCode.USAGE and "position, heading" in err
    empty = tmp_path / "gsv.nmea"
    empty.write_text("# a comment\n$GPGSV,1,1,01,07,10,333,39*4F\n")
    code, _, err = run_cli("records", empty, "--out", tmp_path / "a.csv")
    assert code == ExitCode.INPUT and "no usable records" in err
    assert list(tmp_path.iterdir()) == [empty]


def test_csv_cells_are_not_formulas(run_cli, tmp_path):
    log = tmp_path / "f.csv"
    log.write_text(
        "time_utc,source,quantity,value\n"
        "2026-03-01T00:00:00Z,=HYPERLINK(1),heading_deg,10.5\n"
        "2026-03-01T00:00:01Z,=HYPERLINK(1),heading_deg,11.5\n"
    )
    code, out, _ = run_cli("records", log, "--out", "-")
    assert code == ExitCode.OK
    assert list(pd.read_csv(pd.io.common.StringIO(out))["source"]) == ["'=HYPERLINK(1)"] * 2
    parquet = tmp_path / "f.parquet"
    assert run_cli("records", log, "--out", parquet)[0] == ExitCode.OK
    assert set(pd.read_parquet(parquet)["source"]) == {"=HYPERLINK(1)"}  # the data as it is


@pytest.mark.parametrize("name", ["r.parquet", "r.csv"])
def test_a_failed_write_leaves_no_partial_file(run_cli, tmp_path, monkeypatch, name):
    from dracc.pipeline import records

    target = tmp_path / name
    target.write_bytes(b"the earlier table")
    chunks = records.Records.chunks

    def failing(self, rows=records.CHUNK_ROWS):
        for k, chunk in enumerate(chunks(self, 1000)):  # several row groups, then a full disk
            if k == 3:
                raise OSError(28, os.strerror(28), str(target))
            yield chunk

    monkeypatch.setattr(records.Records, "chunks", failing)
    code, _, err = run_cli("records", SAMPLES / "voyage_tag.nmea", "--out", target)
    assert code == ExitCode.OUTPUT and "cannot write" in err and "Traceback" not in err
    assert target.read_bytes() == b"the earlier table"
    assert [p.name for p in tmp_path.iterdir()] == [name]  # no temporary file left


def test_several_files_trace_back_to_their_file_and_line(run_cli, tmp_path):
    ins, rest = tmp_path / "ins.nmea", tmp_path / "rest.nmea"
    lines = (SAMPLES / "voyage_tag.nmea").read_text().splitlines(keepends=True)
    ins.write_text("".join(t for t in lines if t.startswith("\\s:INS")))
    rest.write_text("".join(t for t in lines if not t.startswith("\\s:INS")))
    target = tmp_path / "both.parquet"
    code, _, err = run_cli("records", ins, rest, "--out", target)
    assert code == ExitCode.OK, err
    t = pd.read_parquet(target)
    decoded = [f for f in _raw(SAMPLES / "voyage_tag.nmea").values() if f[0][2:] != "ZDA"]
    assert len(t) == len(decoded)  # every sentence once (a ZDA sets the date, holds no record)
    assert set(t.loc[t["source"].str.startswith("INS"), "file"]) == {str(ins)}
    assert str(rest) in set(t["file"]) and str(ins) not in set(t.loc[t["source"] == "GYRO", "file"])
    raw = {str(ins): _raw(ins), str(rest): _raw(rest)}
    for row in t.sample(300, random_state=1).itertuples():
        assert raw[row.file][row.line][0] == row.talker + row.sentence


def test_chunks_join_into_the_table(log):
    from dracc.pipeline.records import records_table

    table = records_table(log["voyage"])
    whole = table.frame()
    pieces = pd.concat(list(table.chunks(777)), ignore_index=True)
    pd.testing.assert_frame_equal(pieces, whole)
    assert len(whole) == table.rows == len(log["table"])


def test_rows_of_one_record_join_and_fused_twins_pair_up():
    from dracc.frames import Rejects, SourceInfo, TimeEvents, Voyage, empty_frame, make_frame
    from dracc.pipeline.records import records_table

    def frame(kind, lines, **values):
        n = len(lines)
        cols = {"time_ns": np.full(n, 10**9), "source": np.array(["GP"] * n, dtype=object)}
        cols |= {"sentence": np.array(["RMC"] * n, dtype=object), "line": np.array(lines)}
        return make_frame(kind, cols | {k: np.asarray(v, dtype=float) for k, v in values.items()})

    frames = {k: empty_frame(k) for k in BY_HAND}
    # line 7 holds two RMC sentences (fused), line 8 one; every one a position and a ground row
    frames["position"] = frame("position", [7, 7, 8], lat_rad=[0.1, 0.2, 0.3])
    frames["ground"] = frame("ground", [7, 7, 8], sog_mps=[1.0, 2.0, 3.0])
    info = {"GP": SourceInfo(key="GP", roles=["gnss"])}
    voyage = Voyage(frames, info, Rejects(), TimeEvents(), [{"path": "x.nmea"}])
    t = records_table(voyage).frame()
    assert list(t["line"]) == [7, 7, 8] and set(t["role"]) == {"gnss"}
    np.testing.assert_allclose(t["lat_deg"], np.array([0.1, 0.2, 0.3]) * DEG)
    np.testing.assert_allclose(t["sog_kn"], np.array([1.0, 2.0, 3.0]) * KN)


def test_nmea2000_records_equal_canboats_decode(tmp_path):
    """signalk-server/aava-n2k.data as a table: the records per PGN and the first record
    of each are canboat's analyzer's (`analyzer -json`, transcribed; it prints lat/lon to
    1e-7 deg, angles to 0.1 deg, speeds in m/s to 0.01, distances in m)."""
    out = tmp_path / "aava.parquet"
    path = real_path("signalk-server", "aava-n2k.data")
    assert main(["records", str(path), "--out", str(out)]) == ExitCode.OK
    t = pq.read_table(out).to_pandas()
    counts = Counter(t["sentence"])
    assert dict(counts) == {
        "PGN129029": 597,
        "PGN129025": 597,
        "PGN129026": 596,
        "PGN127250": 596,
        "PGN128259": 1798,
        "PGN128275": 602,
    }

    def first(pgn: int) -> pd.Series:
        return t[t["sentence"] == f"PGN{pgn}"].sort_values("line").iloc[0]

    fix = first(129029)  # time of fix 18:59:59.4620, frame 19:00:00.042
    assert fix["time_utc"] == pd.Timestamp("2014-08-15T18:59:59.462Z")
    assert fix["recv_utc"] == pd.Timestamp("2014-08-15T19:00:00.042Z")
    assert fix["lat_deg"] == pytest.approx(59.7250108, abs=6e-8)
    assert fix["lon_deg"] == pytest.approx(24.7366770, abs=6e-8)
    assert fix["alt_m"] == pytest.approx(2.32, abs=0.005) and fix["hdop"] == pytest.approx(0.8)
    rapid = first(129025)
    assert rapid["lat_deg"] == pytest.approx(59.7249807, abs=6e-8)
    assert rapid["lon_deg"] == pytest.approx(24.7366563, abs=6e-8)
    cog = first(129026)
    assert cog["cog_deg"] == pytest.approx(196.5, abs=0.05)
    assert cog["sog_kn"] == pytest.approx(3.47 * KN, abs=0.005 * KN)
    hdg = first(127250)
    assert hdg["heading_deg"] == pytest.approx(199.1, abs=0.05) and hdg["heading_ref"] == "T"
    assert hdg["variation_deg"] == pytest.approx(8.1, abs=0.05)
    stw = first(128259)
    assert stw["stw_kn"] == pytest.approx(3.34 * KN, abs=0.005 * KN)
    log = first(128275)
    assert log["total_water_nmi"] == pytest.approx(17441025 / 1852, abs=0.5 / 1852)
    assert log["trip_water_nmi"] == pytest.approx(79951 / 1852, abs=0.5 / 1852)
