"""Damaged containers and files that are not logs, through the CLI (``inspect``, ``analyze``):
a clear one-line error (exit 3) or a partial result saying what was recovered; never a
traceback, never the internal-error exit code."""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REAL, real_path

from dracc.core.config import IngestConfig
from dracc.core.errors import ExitCode
from dracc.ingest import read_file

REPO = Path(__file__).resolve().parents[1]
SAMPLES = REPO / "sample_logs"


def _one_line_error(code: int, err: str, *needles: str) -> None:
    assert code == ExitCode.INPUT, err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    for n in needles:
        assert n in lines[0], lines[0]


def _inspect(run_cli, path: Path) -> tuple[int, dict | None, str]:
    code, out, err = run_cli("inspect", "--json", "-", path)
    assert "Traceback" not in err and code != ExitCode.INTERNAL, err
    return code, (json.loads(out) if code == ExitCode.OK else None), err


# ---------------------------------------------------------------- not a log at all


@pytest.mark.parametrize("cmd", ["inspect", "analyze"])
def test_empty_file(run_cli, tmp_path, cmd):
    p = tmp_path / "empty.nmea"
    p.write_bytes(b"")
    code, _, err = run_cli(cmd, p)
    _one_line_error(code, err, "empty file", str(p))


@pytest.mark.parametrize("cmd", ["inspect", "analyze"])
def test_jpeg(run_cli, tmp_path, cmd):
    p = tmp_path / "photo.nmea"  # the name does not matter, the bytes do
    p.write_bytes(b"\xff\xd8\xff\xe0\x00\x10JFIF\x00\x01\x01" + bytes(range(256)) * 40)
    code, _, err = run_cli(cmd, p)
    _one_line_error(code, err, "not a log file", "JPEG")


@pytest.mark.parametrize(
    "magic,what",
    [
        (b"PK\x03\x04", "ZIP"),
        (b"\x1f\x8b\x08", "gzip"),
        (b"%PDF-1.4", "PDF"),
        (b"\x89PNG\r\n\x1a\n", "PNG"),
    ],
)
def test_other_known_non_logs(run_cli, tmp_path, magic, what):
    p = tmp_path / "x.log"
    p.write_bytes(magic + b"\x00" * 100)
    code, _, err = run_cli("analyze", p)
    _one_line_error(code, err, what)


def test_directory(run_cli, tmp_path):
    code, _, err = run_cli("analyze", tmp_path)
    _one_line_error(code, err, "is a directory")


def test_missing_file(run_cli, tmp_path):
    code, _, err = run_cli("analyze", tmp_path / "nope.nmea")
    _one_line_error(code, err, "no such file")


@pytest.mark.parametrize("dev", ["/dev/null", "/dev/zero"])
def test_device(run_cli, dev):
    """Regression: /dev/zero was read as an NMEA log of 0 lines (exit 0, empty report)."""
    if not Path(dev).exists():
        pytest.skip(f"{dev} not present")
    code, _, err = run_cli("inspect", dev)
    _one_line_error(code, err, "is a device")


def test_fifo_is_refused_not_waited_on(tmp_path):
    """Regression: a FIFO blocked the open() forever.  A real process with a bounded wait."""
    fifo = tmp_path / "pipe.nmea"
    os.mkfifo(fifo)
    r = subprocess.run(
        [sys.executable, "-m", "dracc", "analyze", str(fifo)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    _one_line_error(r.returncode, r.stderr, "FIFO")


def test_binary_noise_is_named_once_not_counted_per_line(run_cli, tmp_path):
    """Random bytes with no magic and no NMEA sentence: one refusal saying so, exit 3
    (issue 29: it was read as text, every line rejected, thousands of not_nmea)."""
    rng = random.Random(5)
    p = tmp_path / "noise.nmea"
    p.write_bytes(bytes(rng.randrange(256) for _ in range(20000)))
    for cmd in ("analyze", "inspect"):
        code, _, err = run_cli(cmd, p)
        _one_line_error(code, err, "binary file", "no NMEA sentence", str(p))


# ---------------------------------------------------------------- damaged MCAP


@pytest.fixture(scope="module")
def mcap_full() -> tuple[bytes, int]:
    data = (SAMPLES / "voyage.mcap").read_bytes()
    return data, read_file(SAMPLES / "voyage.mcap", IngestConfig()).records


@pytest.mark.parametrize("seed", range(6))
def test_mcap_cut_at_random_offsets(run_cli, tmp_path, mcap_full, seed):
    data, full = mcap_full
    rng = random.Random(seed)
    cut = rng.randrange(8, len(data))
    p = tmp_path / "cut.mcap"
    p.write_bytes(data[:cut])
    code, doc, err = _inspect(run_cli, p)
    if code == ExitCode.OK:
        got = doc["inputs"][0]["records"]
        assert got <= full
        assert any("cut short" in n or "file ends at byte" in n for n in doc["notes"]), doc["notes"]
    else:
        _one_line_error(code, err)


def test_mcap_cut_keeps_what_was_complete(tmp_path, mcap_full):
    """Cut after the data section: every message is still there (the summary is lost)."""
    data, full = mcap_full
    p = tmp_path / "cut.mcap"
    p.write_bytes(data[:-100])
    r = read_file(p, IngestConfig())
    assert r.records == full
    assert any("every complete message before it was read" in n for n in r.notes)


def test_mcap_magic_only(run_cli, tmp_path):
    p = tmp_path / "magic.mcap"
    p.write_bytes(b"\x89MCAP0\r\n")
    code, _out, err = run_cli("analyze", p)
    _one_line_error(code, err, "no usable record")


@pytest.mark.parametrize("seed", range(6))
def test_mcap_corrupted_bytes(run_cli, tmp_path, mcap_full, seed):
    """Overwrite a run of bytes inside the data: a partial result with the loss named, or
    a one-line error."""
    data, full = mcap_full
    rng = random.Random(100 + seed)
    b = bytearray(data)
    at = rng.randrange(40, len(b) - 200)
    n = rng.randrange(1, 400)
    b[at : at + n] = bytes(rng.randrange(256) for _ in range(n))
    p = tmp_path / "bad.mcap"
    p.write_bytes(bytes(b))
    code, doc, err = _inspect(run_cli, p)
    if code == ExitCode.OK:
        got = doc["inputs"][0]["records"]
        lost = full - got
        if lost > 0:  # what was not read is said, as a note or as counted rejects
            assert doc["notes"] or sum(doc["rejected"].values()), doc
    else:
        _one_line_error(code, err)


@pytest.mark.parametrize("name", ["keelson/4a625f9/test.mcap", "rosbag2/talker.mcap"])
def test_real_mcap_cut_in_half(run_cli, tmp_path, name):
    src = real_path(name)
    data = src.read_bytes()
    p = tmp_path / "half.mcap"
    p.write_bytes(data[: len(data) // 2])
    code, _doc, err = _inspect(run_cli, p)
    if code != ExitCode.OK:
        _one_line_error(code, err)


# ---------------------------------------------------------------- damaged CSV


@pytest.mark.parametrize("name", ["voyage_long.csv", "voyage_wide.csv"])
@pytest.mark.parametrize("seed", range(3))
def test_csv_cut_at_random_offsets(run_cli, tmp_path, name, seed):
    data = (SAMPLES / name).read_bytes()
    full = read_file(SAMPLES / name, IngestConfig()).records
    cut = random.Random(seed).randrange(len(data) // 10, len(data))
    p = tmp_path / name
    p.write_bytes(data[:cut])
    code, doc, err = _inspect(run_cli, p)
    assert code == ExitCode.OK, err
    got = doc["inputs"][0]["records"]
    assert 0 < got <= full
    # the last row, cut mid-way, is counted as rejected when it lost fields
    lines = data[:cut].count(b"\n") + (0 if data[:cut].endswith(b"\n") else 1)
    assert doc["lines"] <= lines


def test_csv_corrupted_rows_are_counted_not_fatal(run_cli, tmp_path):
    """Regression: a row with invalid UTF-8 printed an ignored UnicodeDecodeError traceback
    (pyarrow) and failed the whole file; now only those rows are rejected."""
    lines = (SAMPLES / "voyage_wide.csv").read_bytes().split(b"\n")
    full = read_file(SAMPLES / "voyage_wide.csv", IngestConfig()).records
    lines[10] = lines[10][:30] + b"\xff\xfe" + lines[10][30:]  # invalid UTF-8 in a cell
    lines[20] = lines[20] + b",7\xfe"  # one field too many, and invalid UTF-8
    lines[30] = b"\x00\x00\x00garbage,,,"
    p = tmp_path / "bad.csv"
    p.write_bytes(b"\n".join(lines))
    code, doc, err = _inspect(run_cli, p)
    assert code == ExitCode.OK, err
    assert "UnicodeDecodeError" not in err and "Exception ignored" not in err
    assert doc["inputs"][0]["records"] == full - 3
    rej = doc["rejected"]
    assert sum(rej.values()) == 3, rej
    assert any("wrong number of fields" in k for k in rej)


def test_csv_header_only(run_cli, tmp_path):
    p = tmp_path / "head.csv"
    p.write_text("time_utc,source,quantity,value\n")
    code, _, err = run_cli("analyze", p)
    _one_line_error(code, err)


def test_csv_invalid_utf8_subprocess_has_no_traceback(tmp_path):
    """The noise was printed by the interpreter (sys.unraisablehook): check a real process."""
    lines = (SAMPLES / "voyage_long.csv").read_bytes().split(b"\n")[:400]
    lines[50] = lines[50] + b",\xff\xfe\xfd"
    p = tmp_path / "u.csv"
    p.write_bytes(b"\n".join(lines))
    r = subprocess.run(
        [sys.executable, "-m", "dracc", "inspect", str(p)], capture_output=True, timeout=120
    )
    assert r.returncode == 0, r.stderr
    assert b"Traceback" not in r.stderr and b"Exception ignored" not in r.stderr


# ---------------------------------------------------------------- damaged NMEA text


def test_nmea_cut_mid_line_and_real_damaged_logs(run_cli, tmp_path):
    data = (SAMPLES / "voyage_tag.nmea").read_bytes()
    p = tmp_path / "cut.nmea"
    p.write_bytes(data[: len(data) // 2 + 17])
    code, doc, _ = _inspect(run_cli, p)
    assert code == ExitCode.OK
    assert doc["rejected"].get("truncated", 0) + doc["rejected"].get("checksum", 0) >= 1
    for name in (
        "gpsd/holux-gm-210.log",
        "gpsd/triton400.log",
        "anemomind/Irene/2008/regate_21_mai_08/IreneLog.txt",
    ):
        src = REAL / name
        if src.exists():
            code, doc, err = _inspect(run_cli, src)
            assert code in (ExitCode.OK, ExitCode.INPUT), err
