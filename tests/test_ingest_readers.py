"""Every reader has one signature, (path, config, progress) -> FileResult, and tells the
progress callback every byte of the file once (the bar of `dracc analyze` ends full)."""

import inspect
from pathlib import Path

import pytest
from conftest import SAMPLES

from dracc.core.config import IngestConfig
from dracc.frames import FileResult
from dracc.ingest import read_file
from dracc.ingest.csv import read_csv
from dracc.ingest.mcap import read_mcap
from dracc.ingest.nmea import read_nmea


@pytest.mark.parametrize("reader", [read_nmea, read_mcap, read_csv])
def test_one_reader_signature(reader):
    params = list(inspect.signature(reader).parameters)
    assert params[:3] == ["path", "cfg", "progress"]


@pytest.mark.parametrize(
    "name",
    ["voyage_tag.nmea", "voyage_prefix.nmea", "voyage.mcap", "voyage_long.csv", "voyage_wide.csv"],
)
def test_progress_counts_every_byte_once(name):
    path = SAMPLES / name
    told: list[int] = []
    result = read_file(path, IngestConfig(), told.append)
    assert isinstance(result, FileResult) and result.lines > 0
    assert sum(told) == Path(path).stat().st_size
