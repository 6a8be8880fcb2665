"""Compressed logs (gzip, xz, bzip2, zstd: by content, not by name) and standard input."""

from __future__ import annotations

import bz2
import gzip
import json
import lzma
import subprocess
import sys
import tempfile

import numpy as np
import pytest
import zstandard
from conftest import SAMPLES, real_path

from dracc.core.config import IngestConfig
from dracc.core.errors import IngestError
from dracc.ingest import read_logs

COMPRESS = {
    "gzip": gzip.compress,
    "xz": lzma.compress,
    "bzip2": bz2.compress,
    "zstd": lambda b: zstandard.ZstdCompressor().compress(b),
}
CFG = IngestConfig()


def _positions(voyage):
    df = voyage.frames["position"]
    return df["lat_rad"].to_numpy(), df["lon_rad"].to_numpy(), df["time_ns"].to_numpy()


@pytest.fixture
def private_tmp(tmp_path, monkeypatch):
    """Temporary copies go under tmp_path, so a test can see that none is left."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    return tmp_path


@pytest.mark.parametrize("kind", sorted(COMPRESS))
@pytest.mark.parametrize("name", ["voyage_tag.nmea", "voyage.mcap", "voyage_wide.csv"])
def test_a_compressed_log_reads_as_the_plain_one(private_tmp, kind, name):
    plain = SAMPLES / name
    packed = private_tmp / f"{name}.{kind}"  # the suffix is not what tells the format
    packed.write_bytes(COMPRESS[kind](plain.read_bytes()))
    want, got = read_logs([plain], CFG), read_logs([packed], CFG)
    for a, b in zip(_positions(want), _positions(got), strict=True):
        np.testing.assert_array_equal(a, b)
    assert got.rejects.counts == want.rejects.counts
    assert [i["path"] for i in got.inputs] == [str(packed)]
    said = " ".join(got.time_events.decisions)
    assert f"{kind}-compressed" in said and "dracc-input-" not in said
    assert not list(private_tmp.glob("dracc-input-*")), "the plain copy is removed"


def test_a_truncated_gzip_keeps_what_came_before(private_tmp):
    data = (SAMPLES / "voyage_tag.nmea").read_bytes()
    packed = gzip.compress(data)
    cut = private_tmp / "cut.nmea.gz"
    cut.write_bytes(packed[: len(packed) // 2])
    whole = read_logs([SAMPLES / "voyage_tag.nmea"], CFG)
    got = read_logs([cut], CFG)
    n_whole, n_got = len(_positions(whole)[0]), len(_positions(got)[0])
    assert 0.3 * n_whole < n_got < n_whole
    # the records read are exactly the first ones of the whole log
    np.testing.assert_array_equal(_positions(got)[2], _positions(whole)[2][:n_got])
    said = " ".join(got.time_events.decisions)
    assert "gzip stream ends damaged" in said and "what came before is read" in said
    for examples in got.rejects.examples.values():
        assert all(f == str(cut) for f, _, _ in examples)


def test_an_empty_stream_names_the_log_not_its_copy(private_tmp):
    p = private_tmp / "nothing.nmea.gz"
    p.write_bytes(gzip.compress(b""))
    with pytest.raises(IngestError, match=r"nothing\.nmea\.gz: empty file") as e:
        read_logs([p], CFG)
    assert "dracc-input-" not in str(e.value)


@pytest.mark.parametrize("packed", [False, True])
def test_standard_input(packed):
    data = (SAMPLES / "voyage_tag.nmea").read_bytes()
    run = subprocess.run(
        [sys.executable, "-m", "dracc", "inspect", "-", "--json", "-"],
        input=gzip.compress(data) if packed else data,
        capture_output=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr.decode()
    doc = json.loads(run.stdout)
    assert doc["inputs"][0]["path"] == "-"
    assert doc["lines"] == data.count(b"\n")


@pytest.mark.parametrize("rel", ["VDRplayer/Hakefjord.txt", "gpsd/bundg_zeus_9.log"])
def test_a_real_log_compressed_gives_the_same_records(private_tmp, rel):
    plain = real_path(*rel.split("/"))
    packed = private_tmp / (plain.name + ".gz")
    packed.write_bytes(gzip.compress(plain.read_bytes()))
    cfg = IngestConfig(date="2014-08-01")
    want, got = read_logs([plain], cfg), read_logs([packed], cfg)
    for a, b in zip(_positions(want), _positions(got), strict=True):
        np.testing.assert_array_equal(a, b)
    assert got.rejects.counts == want.rejects.counts
