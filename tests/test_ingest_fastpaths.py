"""The ingest's fast paths agree with the general paths they shortcut.

* ``tagblock.parse_tag_rows`` (TAG blocks as rows of a byte matrix) against
  ``tagblock.parse_tags`` (buffer-wide tables of stars, commas and colons), on
  hand-made and random TAG blocks, well-formed and damaged;
* ``parse_prefixes`` on long TAG blocks (the general path) and short ones (the matrix
  path) mixed in one buffer;
* ``tagblock.parse_numbers``: Arrow's cast (the common case) against numpy's
  ``astype`` with row-wise validation (the general path);
* ``ingest.summarize_frames`` (counts on categorical codes) against
  ``sources.summarize`` (sorting strings), on real and sample logs.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hs

from dracc.core.config import IngestConfig
from dracc.ingest import read_file, summarize_frames, tagblock
from dracc.ingest.sources import summarize
from dracc.ingest.tagblock import (
    TAG_ROW_BYTES,
    gather_rows,
    parse_numbers,
    parse_prefixes,
    parse_tag_rows,
    parse_tags,
    tag_checksum,
)
from dracc.ingest.timebase import MISSING_NS


def _tag(body: str) -> bytes:
    return b"\\" + body.encode() + b"*%02X\\" % tag_checksum(body.encode())


def _both(tags: list[bytes]):
    """Run both TAG parsers on ``tags``, each followed by a sentence, in one buffer."""
    line = b"$GPZDA,000000.00,01,03,2026,00,00*62"
    data = b"".join(t + line + b"\n" for t in tags)
    buf = np.frombuffer(data + bytes(64), dtype=np.uint8)
    cum_xor = np.bitwise_xor.accumulate(buf)
    starts, ends, pos = [], [], 0
    for t in tags:
        starts.append(pos)
        ends.append(pos + len(t))
        pos += len(t) + len(line) + 1
    s, e = np.array(starts), np.array(ends)
    general = parse_tags(
        buf,
        s,
        e,
        cum_xor,
        np.flatnonzero(buf == 42),
        np.flatnonzero(buf == 44),
        np.flatnonzero(buf == 58),
    )
    w = int((e - s).max())
    mat = gather_rows(buf, s, w)
    mat = np.where(np.arange(w) < (e - s)[:, None], mat, 0).astype(np.uint8)
    rows = parse_tag_rows(buf, mat, s, e - s, cum_xor)
    return general, rows


def _assert_same(general, rows):
    for a, b in zip(general, rows, strict=True):
        assert a.tolist() == b.tolist()


def test_hand_made_tags_agree_and_read_right():
    tags = [
        _tag("s:INS2,c:1700000000"),
        _tag("c:1700000000250,s:GYRO"),
        _tag("s:A"),
        _tag("c:1700000000"),
        _tag("g:1-2-3,s:LOG,c:1700000001"),
        b"\\s:INS2,c:1700000000*00\\",  # wrong checksum
        b"\\s:INS2,c:1700000000\\",  # no checksum
        _tag("s:X,c:17000x0000"),  # unreadable time
        _tag("xs:Y,c:5"),  # 'xs' is not the key 's'
        b"\\s:B,c:1700000000*7\\",  # one hex digit
        _tag("s:,c:1700000000"),
        _tag("c:,s:Q"),
    ]  # empty values
    general, rows = _both(tags)
    _assert_same(general, rows)
    ok, bad_cs, ext, source = rows
    assert ok.tolist() == [True, True, True, True, True, True, False, False, True, True, True, True]
    assert bad_cs.tolist()[5] and not bad_cs[0]
    assert ext[0] == 1_700_000_000 * 10**9  # seconds
    assert ext[1] == 1_700_000_000_250 * 10**6  # milliseconds
    assert ext[2] == MISSING_NS
    assert source.tolist()[:5] == ["INS2", "GYRO", "A", "", "LOG"]
    assert source[8] == ""
    assert source[10] == "" and ext[10] == 1_700_000_000 * 10**9
    assert source[11] == "Q" and ext[11] == MISSING_NS


_ALPHABET = "sc:,*\\0123456789ABCDEFabxg-."


@settings(max_examples=200, deadline=None)
@given(
    hs.lists(hs.text(alphabet=_ALPHABET, min_size=0, max_size=40), min_size=1, max_size=12),
    hs.lists(hs.booleans(), min_size=12, max_size=12),
)
def test_random_tags_agree(bodies, good):
    """Random bodies, with a right checksum or with the raw text closed by a backslash."""
    tags = [
        (_tag(b) if g else b"\\" + b.encode() + b"\\") for b, g in zip(bodies, good, strict=False)
    ]
    tags = [t for t in tags if b"$" not in t and b"\n" not in t]
    general, rows = _both(tags)
    _assert_same(general, rows)


def test_parse_prefixes_mixes_short_and_long_tags():
    long_tag = _tag("s:LONG," + "x:" + "9" * (TAG_ROW_BYTES + 10) + ",c:1700000002")
    tags = [_tag("s:A,c:1700000000"), _tag("s:A,c:1700000000"), long_tag, _tag("s:B,c:1700000001")]
    line = b"$HEHDT,60.3,T*1A"
    data = b"".join(t + line + b"\n" for t in tags)
    buf = np.frombuffer(data + bytes(64), dtype=np.uint8)
    starts = np.array([0] + [i + 1 for i in np.flatnonzero(buf[: len(data)] == 10)[:-1]])
    ends = starts + np.array([len(t) for t in tags])
    pr = parse_prefixes(buf, starts, ends, np.bitwise_xor.accumulate(buf))
    assert pr.source.tolist() == ["A", "A", "LONG", "B"]
    assert (pr.ext_ns // 10**9).tolist() == [1700000000, 1700000000, 1700000002, 1700000001]
    assert not pr.bad_tag.any() and not pr.bad_tag_checksum.any()


# --------------------------------------------------------------- source summaries
REAL = Path("/work/shared/data/real")
SAMPLES = Path(__file__).resolve().parent.parent / "sample_logs"


def _summaries_equal(a: dict, b: dict) -> None:
    assert list(a) == list(b)  # sources in the same order
    for k in a:
        assert a[k] == b[k]
        assert list(a[k].sentences.items()) == list(b[k].sentences.items())  # insertion order too
        assert list(a[k].talkers.items()) == list(b[k].talkers.items())


@pytest.mark.parametrize(
    "path",
    [
        REAL / "VDRplayer" / "Hakefjord.txt",
        SAMPLES / "voyage_tag.nmea",
        SAMPLES / "voyage_prefix.nmea",
        SAMPLES / "voyage.mcap",
    ],
)
def test_summarize_frames_equals_summarize(path):
    if not path.exists():
        pytest.skip(f"{path} not present")
    r = read_file(path, IngestConfig())
    fast = summarize_frames(r.frames, r.path)
    _summaries_equal(summarize(r.frames, r.path), fast)
    assert sum(s.records for s in fast.values()) == sum(len(df) for df in r.frames.values())


def test_summarize_frames_accumulates_and_falls_back():
    """Two files into one summary; a frame with plain string columns (general path)."""
    r = read_file(SAMPLES / "voyage_tag.nmea", IngestConfig())
    plain = {
        k: df.astype({"source": object, "talker": object, "sentence": object})
        for k, df in r.frames.items()
    }
    a = summarize(r.frames, "one")
    summarize(plain, "two", into=a)
    b = summarize_frames(r.frames, "one")
    summarize_frames(plain, "two", into=b)
    _summaries_equal(a, b)
    assert all(s.files == {"one", "two"} for s in b.values())


# ------------------------------------------------------------------------- numbers
def _numbers(fields: list[bytes], decimals: bool = True):
    data = b",".join(fields) + b","
    buf = np.frombuffer(data + bytes(64), dtype=np.uint8)
    ends = np.cumsum([len(f) + 1 for f in fields]) - 1
    starts = ends - np.array([len(f) for f in fields])
    return parse_numbers(buf, starts, ends, 20, decimals)


@settings(max_examples=300, deadline=None)
@given(
    hs.lists(hs.text(alphabet="0123456789.+-", min_size=0, max_size=22), min_size=1, max_size=8),
    hs.booleans(),
)
def test_numbers_arrow_path_equals_general_path(fields, decimals):
    """Arrow's cast (fast path) and numpy's astype with row-wise validation (general
    path) give the same values, decimals and invalid flags, bit for bit."""
    raw = [f.encode() for f in fields]
    fast = _numbers(raw, decimals)
    saved = tagblock._numbers_arrow
    tagblock._numbers_arrow = lambda *a: None
    try:
        general = _numbers(raw, decimals)
    finally:
        tagblock._numbers_arrow = saved
    assert fast[0].tobytes() == general[0].tobytes()  # NaN and -0.0 included
    assert fast[1].tolist() == general[1].tolist()
    assert fast[2].tolist() == general[2].tolist()


def test_numbers_fast_path_values():
    val, dec, invalid = _numbers([b"5741.2345", b"-0.5", b"+12", b"", b"7.", b"1.2.3"])
    assert val[:3].tolist() == [5741.2345, -0.5, 12.0] and np.isnan(val[3]) and val[4] == 7.0
    assert dec.tolist() == [4, 1, -1, -1, 0, -1]
    assert invalid.tolist() == [False, False, False, False, False, True] and np.isnan(val[5])


_VALID = hs.from_regex(r"[+-]?[0-9]{0,12}(\.[0-9]{0,9})?", fullmatch=True)


@settings(max_examples=300, deadline=None)
@given(hs.lists(_VALID, min_size=1, max_size=8), hs.booleans())
def test_numbers_arrow_path_on_numbers(fields, decimals):
    """Mostly well-formed numbers: the fast path is taken and agrees with the general one."""
    test_numbers_arrow_path_equals_general_path.hypothesis.inner_test(fields, decimals)
