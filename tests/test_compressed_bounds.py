"""Issue 33, compressed input: decompressed as it is read, bounded, no copy left behind.

1. A 9 KB bzip2 of zeros was inflated to a 12 GB temporary copy (on a tmpfs: RAM): an
   NMEA text log is now decompressed as it is read (no copy at all), and a log that
   decompresses to more than ``[ingest] max_inflate_ratio`` times its size (at least
   256 MiB) stops with one line, exit 3: a bomb is counted, never held.
2. The formats read from a file (MCAP, CSV ...) get a copy of at most ``[ingest]
   temp_cap_mb``, past it one line.
3. A run killed by SIGKILL left its partial copy for good: copies live in a folder named
   with the run's process id, and the next run removes those whose process is gone.
"""

from __future__ import annotations

import bz2
import gzip
import lzma
import os
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np
import pytest
import zstandard
from conftest import SAMPLES

from dracc.core.config import IngestConfig
from dracc.core.errors import IngestError
from dracc.ingest import compressed, read_file, read_logs
from dracc.ingest.compressed import INPUT_PREFIX, Packed
from dracc.ingest.inspect import inspect_logs

COMPRESS = {
    "gzip": gzip.compress,
    "xz": lambda b: lzma.compress(b, preset=0),
    "bzip2": bz2.compress,
    "zstd": lambda b: zstandard.ZstdCompressor().compress(b),
}
ZEROS = bytes(4 << 20)


@pytest.fixture
def private_tmp(tmp_path, monkeypatch):
    """Temporary folders go under tmp_path, so a test sees what is left."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    return tmp_path


HEADS = {
    "nmea": (SAMPLES / "voyage_tag.nmea").read_bytes()[:20000],
    "csv": (SAMPLES / "voyage_long.csv").read_bytes()[:20000],
}


def _bomb(kind: str, head: bytes, members: int) -> bytes:
    """``head`` then ``members`` streams of 4 MiB of zeros, one after another (each
    decompressor reads on across them): a ratio of hundreds to thousands, made in a
    moment."""
    return COMPRESS[kind](head) + COMPRESS[kind](ZEROS) * members


@pytest.mark.parametrize("kind", ["bzip2", "gzip", "xz", "zstd"])
@pytest.mark.parametrize("head", ["nmea", "csv"])
def test_a_bomb_of_zeros_stops_with_one_line(private_tmp, monkeypatch, kind, head):
    """A log whose first lines are NMEA (decompressed as it is read) or CSV (copied),
    then a run of zeros far past its ratio: stopped at its bound, in bounded memory, no
    copy left (the floor lowered to 8 MiB to keep the test small)."""
    monkeypatch.setattr(compressed, "INFLATE_FLOOR", 8 << 20)
    p = private_tmp / f"zeros.{head}.{kind}"
    p.write_bytes(_bomb(kind, HEADS[head], 16))  # 64 MiB of zeros
    cfg = IngestConfig(max_inflate_ratio=20)
    with pytest.raises(IngestError, match=r"zeros\.\w+\.\w+: decompresses to more than 8,388,608 "):
        read_file(p, cfg)
    with pytest.raises(IngestError, match="max_inflate_ratio = 20 "):
        inspect_logs([p], cfg)
    assert not list(private_tmp.glob(f"{INPUT_PREFIX}*"))


def test_a_stream_of_zeros_is_refused_from_its_first_bytes(private_tmp):
    """The issue's 9 KB bzip2 of zeros: told from its first 64 KiB (not a log), nothing
    decompressed beyond them, nothing copied."""
    p = private_tmp / "zeros.bz2"
    p.write_bytes(bz2.compress(ZEROS) * 64)  # 256 MiB of zeros in a few KB
    t0 = time.monotonic()
    with pytest.raises(IngestError, match=r"zeros\.bz2: not a log dracc reads"):
        read_file(p, IngestConfig())
    assert time.monotonic() - t0 < 5 and not list(private_tmp.glob(f"{INPUT_PREFIX}*"))


def test_a_bomb_through_the_cli_is_exit_3_and_one_line(tmp_path):
    """The default bound (256 MiB at least): NMEA lines then 300 MiB of zeros in a bzip2
    of a few KB end with exit 3 and one line on stderr, never a MemoryError or exit 5."""
    p = tmp_path / "zeros.log.bz2"
    p.write_bytes(_bomb("bzip2", HEADS["nmea"], 75))
    assert p.stat().st_size < 30_000
    run = subprocess.run(
        [sys.executable, "-m", "dracc", "inspect", str(p)],
        capture_output=True,
        timeout=300,
        env={**os.environ, "TMPDIR": str(tmp_path)},
    )
    err = run.stderr.decode().strip()
    assert run.returncode == 3, err
    assert len(err.splitlines()) == 1 and "decompresses to more than 268,435,456 bytes" in err
    assert "a decompression bomb" in err


def test_compressed_nmea_is_never_copied(private_tmp, monkeypatch):
    """NMEA text is decompressed as it is read: the copy is never made, and the records
    are those of the plain log."""

    def no_copy(self):
        raise AssertionError("an NMEA log was copied")

    monkeypatch.setattr(Packed, "copy", no_copy)
    plain = SAMPLES / "voyage_tag.nmea"
    for kind, pack in COMPRESS.items():
        p = private_tmp / f"v.nmea.{kind}"
        p.write_bytes(pack(plain.read_bytes()))
        want, got = read_file(plain, IngestConfig()), read_file(p, IngestConfig())
        for k, df in want.frames.items():
            np.testing.assert_array_equal(df["time_ns"], got.frames[k]["time_ns"])
        assert got.lines == want.lines and f"{kind}-compressed" in " ".join(got.notes)
        a, b = inspect_logs([plain], IngestConfig()), inspect_logs([p], IngestConfig())
        assert a["sources"].keys() == b["sources"].keys() and a["accounting"] == b["accounting"]


def test_a_copy_past_temp_cap_mb_is_one_line(private_tmp):
    """A CSV (read from a file) whose copy would pass ``temp_cap_mb`` is refused."""
    p = private_tmp / "long.csv.gz"
    p.write_bytes(gzip.compress((SAMPLES / "voyage_long.csv").read_bytes()))
    with pytest.raises(IngestError, match=r"long\.csv\.gz: its temporary copy would pass "):
        read_logs([p], IngestConfig(temp_cap_mb=1))
    assert len(read_logs([p], IngestConfig(temp_cap_mb=2)).frames["position"]) > 0
    assert not list(private_tmp.glob(f"{INPUT_PREFIX}*"))


def test_a_killed_runs_copy_is_removed_by_the_next_run(tmp_path):
    """SIGKILL while standard input is being saved leaves ``dracc-input-<pid>-...``; the
    next run that reads a compressed log removes it (its process is gone)."""
    env = {**os.environ, "TMPDIR": str(tmp_path)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "dracc", "inspect", "-"],
        stdin=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
    )
    assert proc.stdin is not None
    proc.stdin.write((SAMPLES / "voyage_tag.nmea").read_bytes())
    proc.stdin.flush()
    deadline = time.monotonic() + 120
    saved = []
    while not saved and time.monotonic() < deadline:
        saved = [f for f in tmp_path.glob(f"{INPUT_PREFIX}{proc.pid}-*/stdin") if f.stat().st_size]
        time.sleep(0.1)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=60)
    proc.stdin.close()
    assert saved and saved[0].exists(), "the killed run left its copy"
    p = tmp_path / "v.nmea.gz"
    p.write_bytes(gzip.compress((SAMPLES / "voyage_tag.nmea").read_bytes()))
    run = subprocess.run(
        [sys.executable, "-m", "dracc", "inspect", str(p)],
        capture_output=True,
        env=env,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr.decode()
    assert not saved[0].parent.exists()
    assert not list(tmp_path.glob(f"{INPUT_PREFIX}*"))


@pytest.mark.parametrize("workers", [1, 2])
def test_a_stream_parsed_by_workers_gives_the_files_records(workers):
    """A stream cut in pieces (small, to have many) and parsed here or by two workers
    gives the records of the file read as a file."""
    from dracc.frames import concat_blocks
    from dracc.ingest.nmea import StreamState, iter_nmea_blocks, read_nmea

    p = SAMPLES / "voyage_tag.nmea"
    want = read_nmea(p, IngestConfig(), workers=1)
    st = StreamState(str(p))
    blocks = iter_nmea_blocks(
        p, IngestConfig(), st, block_bytes=70_000, workers=workers, opener=lambda: p.open("rb")
    )
    got = concat_blocks([b.frames for b in blocks])
    assert st.lines == want.lines and st.stats.get("pool_fallback", 0) == 0
    for kind, df in want.frames.items():
        np.testing.assert_array_equal(df["time_ns"], got[kind]["time_ns"])
        np.testing.assert_array_equal(df["line"], got[kind]["line"])
