"""Hostile and damaged CSV and MCAP (issue 15): memory bounded by caps, not by content.

Each case has a regression test named after it:

1. a long CSV field or row (``test_csv_long_field_memory_is_bounded``,
   ``test_csv_line_over_4mb_keeps_the_other_rows``): rows over ``max_line_bytes`` are
   counted (``too_long``) and left out, text never becomes a fixed-width numpy array;
2. MCAP decompression bombs (``test_mcap_zstd_bomb_is_rejected_with_bounded_memory``,
   ``test_mcap_lz4_bomb_is_rejected``, ...): a chunk inflating beyond its declared size
   or ``max_chunk_bytes`` is rejected (``chunk_too_large``), the rest read;
3. MCAP chunk CRCs (``test_mcap_chunk_crc_mismatch_drops_that_chunk_only``): a chunk whose
   ``uncompressed_crc`` does not match is rejected whole (``chunk_crc``);
4. MCAP topic names with control characters are kept as data
   (``test_mcap_topic_with_control_characters_is_kept_as_data``).

Peak memory is measured on a real ``dracc analyze`` process (``RUSAGE_CHILDREN`` of a
wrapper whose only child it is), under an address-space cap so that a regression fails
with a MemoryError instead of exhausting the shared machine.
"""

from __future__ import annotations

import json
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dracc.core.config import IngestConfig
from dracc.core.errors import IngestError
from dracc.ingest.csv import read_csv
from dracc.ingest.mcap import read_mcap
from dracc.sim.mcap_out import write_mcap

SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"
CFG = IngestConfig()
RSS_LIMIT_MIB = 300  #: `dracc analyze` of the samples peaks at about 180-190 MiB
AS_CAP = 1536 << 20  #: address-space cap of the measured process (analyze runs in 1 GiB)

_WRAP = """
import resource, subprocess, sys
cap = int(sys.argv[1])
def limit():
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
r = subprocess.run(sys.argv[2:], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, preexec_fn=limit)
sys.stderr.write(r.stderr.decode("utf-8", "replace"))
print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, r.returncode)
"""


def _analyze(path: Path, tmp_path: Path) -> tuple[int, int, dict, str]:
    """(peak RSS in MiB, exit code, the analysis JSON, stderr) of ``dracc analyze PATH``."""
    out = tmp_path / f"{path.stem}.json"
    r = subprocess.run(
        [
            sys.executable,
            "-c",
            _WRAP,
            str(AS_CAP),
            sys.executable,
            "-m",
            "dracc",
            "analyze",
            str(path),
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    kib, code = (int(x) for x in r.stdout.split()[-2:])
    doc = json.loads(out.read_text()) if out.exists() else {}
    return kib // 1024, code, doc, r.stderr


# ===================================================================== CSV
def _raw_csv(path: Path) -> Path:
    """A logger's CSV of raw sentences (``received_at,protocol,source,raw_data``) from the
    sample voyage: a derived fixture."""
    from dracc.sim.nmea_out import frames_to_lines

    frames = read_mcap(SAMPLES / "voyage.mcap", CFG).frames
    t, src, lines = frames_to_lines(frames)
    stamps = pd.to_datetime(np.asarray(t), utc=True).strftime("%Y-%m-%dT%H:%M:%S.%fZ")
    rows = ["received_at,protocol,source,raw_data"]
    rows += [f'{s},NMEA0183,{k},"{b.decode()}"' for s, k, b in zip(stamps, src, lines, strict=True)]
    path.write_text("\n".join(rows) + "\n")
    return path


def _csv_lines(form: str, tmp_path: Path) -> list[bytes]:
    if form == "raw":
        return _raw_csv(tmp_path / "clean_raw.csv").read_bytes().split(b"\n")
    return (SAMPLES / f"voyage_{form}.csv").read_bytes().split(b"\n")


def _with_cell(line: bytes, col: int, value: bytes) -> bytes:
    parts = line.split(b",")
    parts[col] = value
    return b",".join(parts)


@pytest.mark.parametrize("form", ["long", "wide", "raw"])
def test_csv_long_field_memory_is_bounded(tmp_path, form):
    """Regression: one long value made numpy build fixed-width ``<U{longest}`` arrays of
    every row of a block (a 16 kB value in the long sample: 3.8 GB peak RSS, exit 5 from
    MemoryError beyond); a 10 MB row failed the whole file.  Now the 10 MB row is counted
    (too_long) and left out, the 60 kB one (under max_line_bytes) is read as text and
    rejected by its content, and ``dracc analyze`` stays near its usual ~190 MiB."""
    lines = _csv_lines(form, tmp_path)
    col = {"long": 3, "wide": 2, "raw": 1}[form]  # value / lat_deg / protocol
    k = len(lines) // 3
    lines[k] = _with_cell(lines[k], col, b"9" * 10_000_000)
    lines[2 * k] = _with_cell(lines[2 * k], col, b"7" * 60_000)
    p = tmp_path / f"long_field_{form}.csv"
    p.write_bytes(b"\n".join(lines))
    full = read_csv(
        SAMPLES / f"voyage_{form}.csv" if form != "raw" else tmp_path / "clean_raw.csv", CFG
    ).records
    rss, code, doc, err = _analyze(p, tmp_path)
    assert code == 0, err
    assert rss < RSS_LIMIT_MIB, f"peak RSS {rss} MiB"
    assert doc["rejected"].get("too_long") == 1, doc["rejected"]
    assert doc["reject_examples"]["too_long"][0]["line"] == k + 1
    got = doc["inputs"][0]["records"]
    assert full - 2 <= got <= full  # the two rows' records (or quantities) and nothing else


@pytest.mark.parametrize("form", ["long", "wide", "raw"])
def test_csv_line_over_4mb_keeps_the_other_rows(tmp_path, form):
    """Regression: a row longer than pyarrow's 4 MiB block failed the whole file ("straddling
    object straddles two block boundaries").  A 5 MB junk line inserted into a file: it is
    counted (too_long, with its line), every other row gives the record it gave before,
    numbered by its own line (the lines after it one further on)."""
    lines = _csv_lines(form, tmp_path)
    src = tmp_path / f"clean_{form}.csv"
    src.write_bytes(b"\n".join(lines))
    k = len(lines) // 2  # 0-based index of the inserted line: file line k + 1
    bad = lines[:k] + [b"2026-03-01T07:30:00Z," + b"x" * 5_000_000] + lines[k:]
    p = tmp_path / f"over_4mb_{form}.csv"
    p.write_bytes(b"\n".join(bad))
    clean, got = read_csv(src, CFG), read_csv(p, CFG)
    assert dict(got.rejects.counts) == {**clean.rejects.counts, "too_long": 1}
    assert got.rejects.examples["too_long"][0][1] == k + 1
    assert any("max_line_bytes" in n for n in got.notes)
    assert got.lines == clean.lines and got.records == clean.records
    for kind, f in clean.frames.items():
        g = got.frames[kind]
        want = f.copy()
        want["line"] = np.where(want["line"] > k, want["line"] + 1, want["line"])
        pd.testing.assert_frame_equal(g, want, check_categorical=False)


def test_csv_too_long_rows_with_other_bad_rows_keep_their_line_numbers(tmp_path):
    """Rows left out before pyarrow sees the file shift pyarrow's own row numbers: the
    rows after them, and pyarrow's wrong-field-count rows, keep their file lines.  Line
    ends LF, CR LF and a lone CR; a too-long last row without a line end."""
    rows = [
        b"time_utc,source,quantity,value",  # 1
        b"2024-05-01T00:00:00Z,LOG,stw_kn,10",  # 2
        b"2024-05-01T00:00:00Z,LOG,stw_kn," + b"1" * 300,  # 3 too long
        b"2024-05-01T00:00:01Z,LOG,stw_kn",  # 4 too few fields
        b"2024-05-01T00:00:02Z,LOG,stw_kn,12",  # 5
        b"x" * 500,  # 6 too long
        b"2024-05-01T00:00:03Z,LOG,stw_kn,13",  # 7
        b"2024-05-01T00:00:04Z,LOG,stw_kn,14",  # 8
        b"2024-05-01T00:00:05Z,LOG," + b"q" * 400,
    ]  # 9 too long, no line end
    ends = [b"\n", b"\r\n", b"\r", b"\n", b"\r\n", b"\n", b"\r", b"\n"]
    p = tmp_path / "mixed.csv"
    p.write_bytes(b"".join(r + e for r, e in zip(rows, ends + [b""], strict=True)))
    r = read_csv(p, IngestConfig(max_line_bytes=200))
    assert r.rejects.counts["too_long"] == 3
    assert [e[1] for e in r.rejects.examples["too_long"]] == [3, 6, 9]
    assert [e[1] for e in r.rejects.examples["wrong number of fields (3, header has 4)"]] == [4]
    w = r.frames["water"]
    assert w["line"].tolist() == [2, 5, 7, 8]
    np.testing.assert_allclose(w["stw_mps"].to_numpy() * 3600 / 1852, [10, 12, 13, 14])
    with pytest.raises(IngestError, match="too_long"):
        read_csv(p, IngestConfig(max_line_bytes=200, strict=True))
    with pytest.raises(IngestError, match="header line"):
        read_csv(p, IngestConfig(max_line_bytes=20))


def test_csv_block_boundaries_do_not_change_the_scan(tmp_path, monkeypatch):
    """The scan for long rows reads 4 MiB blocks; with blocks of 7 bytes (a CR LF and
    every row split across blocks) it finds the same rows."""
    import dracc.ingest.csv as csv_mod

    rows = [b"time_utc,source,quantity,value"] + [
        b"2024-05-01T00:00:%02dZ,LOG,stw_kn,%s" % (i, b"1" * (250 if i % 4 == 1 else 2))
        for i in range(20)
    ]
    p = tmp_path / "crlf.csv"
    p.write_bytes(b"\r\n".join(rows) + b"\r\n")
    cfg = IngestConfig(max_line_bytes=200)
    whole = csv_mod._scan(p, 200)
    monkeypatch.setattr(csv_mod, "_BLOCK_BYTES", 7)
    small = csv_mod._scan(p, 200)
    assert small.long_rows == whole.long_rows and small.longest == whole.longest
    assert [x[0] for x in whole.long_rows] == [i + 2 for i in range(20) if i % 4 == 1]
    assert all(x[4].startswith(b"2024-05-01T00:00:") for x in small.long_rows)
    r = read_csv(p, cfg)
    assert r.rejects.counts["too_long"] == 5 and len(r.frames["water"]) == 15


# ===================================================================== MCAP crafting
def _records(data: bytes):
    """(opcode, offset, length) of every top-level record up to the footer."""
    pos, out = 8, []
    while pos + 9 <= len(data):
        op, ln = struct.unpack_from("<BQ", data, pos)
        out.append((op, pos, ln))
        if op == 2:
            break
        pos += 9 + ln
    return out


def _chunk_fields(data: bytes, pos: int) -> dict:
    b = pos + 9
    start, end, usize, crc, clen = struct.unpack_from("<QQQII", data, b)
    comp = data[b + 32 : b + 32 + clen].decode()
    (rlen,) = struct.unpack_from("<Q", data, b + 32 + clen)
    rat = b + 32 + clen + 8
    return {
        "start": start,
        "end": end,
        "usize": usize,
        "crc": crc,
        "comp": comp,
        "records": data[rat : rat + rlen],
        "records_at": rat,
    }


def _chunk_messages(data: bytes, pos: int) -> int:
    """Message records in a chunk, counted independently of the reader."""
    import lz4.frame
    import zstandard

    f = _chunk_fields(data, pos)
    raw = {
        "zstd": lambda b: zstandard.ZstdDecompressor().decompress(b, max_output_size=f["usize"]),
        "lz4": lz4.frame.decompress,
        "": bytes,
    }[f["comp"]](f["records"])
    n, q = 0, 0
    while q + 9 <= len(raw):
        op, ln = struct.unpack_from("<BQ", raw, q)
        n += op == 5
        q += 9 + ln
    return n


def _replace_chunk(
    data: bytes,
    pos: int,
    records: bytes,
    comp: str,
    usize: int | None = None,
    crc: int | None = None,
) -> bytes:
    """The file with the chunk at ``pos`` holding ``records`` (already compressed with
    ``comp``); its declared size and CRC as given (default: the old ones).  The record
    lengths, the footer's offsets and the summary CRC are fixed up, so that the chunk is
    the only damage."""
    f = _chunk_fields(data, pos)
    cs = comp.encode()
    body = (
        struct.pack(
            "<QQQI",
            f["start"],
            f["end"],
            f["usize"] if usize is None else usize,
            f["crc"] if crc is None else crc,
        )
        + struct.pack("<I", len(cs))
        + cs
        + struct.pack("<Q", len(records))
        + records
    )
    (old_len,) = struct.unpack_from("<Q", data, pos + 1)
    out = bytearray(
        data[:pos] + struct.pack("<BQ", 6, len(body)) + body + data[pos + 9 + old_len :]
    )
    delta = len(body) - old_len
    op, fpos, _ = _records(bytes(out))[-1]
    assert op == 2
    s0, s1, scrc = struct.unpack_from("<QQI", out, fpos + 9)
    if s0:
        s0, s1 = s0 + delta, (s1 + delta if s1 else 0)
        struct.pack_into("<QQ", out, fpos + 9, s0, s1)
        if scrc:
            struct.pack_into("<I", out, fpos + 25, zlib.crc32(bytes(out[s0 : fpos + 25])))
    return bytes(out)


def _zstd_bomb(n: int) -> bytes:
    """A zstd frame of ``n`` zero bytes that does not say its size (streamed)."""
    import zstandard

    cobj = zstandard.ZstdCompressor(level=3, write_content_size=False).compressobj()
    zero = bytes(1 << 20)
    parts = [cobj.compress(zero) for _ in range(n >> 20)]
    return b"".join(parts) + cobj.flush()


def _lz4_bomb(n: int) -> bytes:
    import lz4.frame

    c = lz4.frame.LZ4FrameCompressor()
    zero = bytes(1 << 20)
    return c.begin() + b"".join(c.compress(zero) for _ in range(n >> 20)) + c.flush()


@pytest.fixture(scope="module")
def chunked_voyage(tmp_path_factory) -> tuple[Path, dict]:
    """The sample voyage written again in small zstd chunks (about 30 of them)."""
    d = tmp_path_factory.mktemp("voyage")
    frames = read_mcap(SAMPLES / "voyage.mcap", CFG).frames
    p = write_mcap(
        frames, {}, d / "chunked.mcap", encoding="json", chunk_size=64 << 10, compression="zstd"
    )
    return p, frames


def _chunks(data: bytes) -> list[int]:
    return [pos for op, pos, _ in _records(data) if op == 6]


def _by_time(frames: dict, kind: str) -> pd.DataFrame:
    return frames[kind].sort_values(["time_ns", "source"], kind="stable").reset_index(drop=True)


# ===================================================================== MCAP bombs
def test_mcap_zstd_bomb_is_rejected_with_bounded_memory(tmp_path, chunked_voyage):
    """Regression: a chunk declaring ~64 kB whose zstd data (300 MB of zeros in 10 kB,
    without a size in its frame header) inflates to 300 MB: ``decompressobj`` returned it
    all at once (a 98 kB bomb of 3 GB peaked at 3.3 GB RSS).  Now the decompression stops
    just past the declared size, the chunk is rejected (chunk_too_large, where it is) and
    every other chunk's messages are read."""
    p, _ = chunked_voyage
    data = p.read_bytes()
    chunks = _chunks(data)
    victim = chunks[3]
    lost = _chunk_messages(data, victim)
    bomb = _zstd_bomb(300 << 20)
    assert len(bomb) < 20_000
    q = tmp_path / "zstd_bomb.mcap"
    q.write_bytes(_replace_chunk(data, victim, bomb, "zstd"))
    full = read_mcap(p, CFG).records
    rss, code, doc, err = _analyze(q, tmp_path)
    assert code == 0, err
    assert rss < RSS_LIMIT_MIB, f"peak RSS {rss} MiB"
    assert doc["rejected"] == {"chunk_too_large": 1}, doc["rejected"]
    text = doc["reject_examples"]["chunk_too_large"][0]["text"]
    assert f"Chunk 4 at byte {victim}" in text and "inflates" in text
    assert doc["inputs"][0]["records"] == full - lost
    r = read_mcap(q, CFG)  # the notes say it too (bounded: this process stays small as well)
    assert any("rejected (chunk_too_large)" in n and f"byte {victim}" in n for n in r.notes)


@pytest.mark.parametrize("where", ["complete", "cut"])
def test_mcap_lz4_bomb_is_rejected(tmp_path, chunked_voyage, where):
    """The same with an lz4 frame (300 MB of zeros in 1.2 MB; ``lz4.frame.decompress`` had
    no bound at all), in a complete chunk and in a chunk cut off by the end of the file
    (streamed): rejected, memory bounded (the read's own peak), the other chunks read."""
    import resource

    p, _frames = chunked_voyage
    data = p.read_bytes()
    chunks = _chunks(data)
    victim = chunks[-1] if where == "cut" else chunks[5]
    new = _replace_chunk(data, victim, _lz4_bomb(300 << 20), "lz4")
    if where == "cut":
        new = new[: victim + 9 + 200_000]  # the file ends inside the bomb's compressed data
    q = tmp_path / f"lz4_bomb_{where}.mcap"
    q.write_bytes(new)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    r = read_mcap(q, CFG)
    grew = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) // 1024
    assert grew < 100, f"peak RSS grew by {grew} MiB"
    assert r.rejects.counts == {"chunk_too_large": 1}
    full = read_mcap(p, CFG).records
    assert r.records == full - _chunk_messages(data, victim)


def test_mcap_chunk_declaring_more_than_max_chunk_bytes_is_rejected(tmp_path, chunked_voyage):
    """A chunk whose declared size is over ``[ingest] max_chunk_bytes`` is not decompressed
    at all: each is counted, and a file of such chunks reads as 'no navigation data'."""
    p, _ = chunked_voyage
    n = len(_chunks(p.read_bytes()))
    r = read_mcap(p, IngestConfig(max_chunk_bytes=1000))
    assert r.rejects.counts == {"chunk_too_large": n} and r.records == 0
    assert "max_chunk_bytes = 1,000" in r.rejects.examples["chunk_too_large"][0][2]
    assert sum("rejected (chunk_too_large)" in x for x in r.notes) == 10  # the first ten noted


def test_mcap_record_outside_chunks_larger_than_the_cap_is_not_read(tmp_path):
    """A message record outside chunks longer than ``max_chunk_bytes`` is counted
    (record_too_large) without being read; the smaller ones are read."""
    from mcap.writer import CompressionType, Writer

    p = tmp_path / "unchunked.mcap"
    with p.open("wb") as fh:
        w = Writer(fh, use_chunking=False, compression=CompressionType.NONE)
        w.start()
        ch = w.register_channel("/gps/fix", "json", 0)
        for i, pad in enumerate([0, 0, 50_000, 0]):
            msg = {"latitude": 54.0 + i / 100, "longitude": 18.0, "pad": "x" * pad}
            w.add_message(ch, 1_700_000_000_000_000_000 + i, json.dumps(msg).encode(), 0)
        w.finish()
    r = read_mcap(p, IngestConfig(max_chunk_bytes=10_000))
    assert r.rejects.counts == {"record_too_large": 1}
    assert r.rejects.examples["record_too_large"][0][1] == 3  # the third message
    assert len(r.frames["position"]) == 3


# ===================================================================== MCAP CRCs
@pytest.mark.parametrize("compression", [None, "zstd"])
def test_mcap_chunk_crc_mismatch_drops_that_chunk_only(tmp_path, compression):
    """Regression: chunk CRCs were never verified, so a flipped byte in a message was read
    as a valid value.  One byte of a latitude flipped inside the third chunk (left
    uncompressed, or recompressed with the old CRC kept): that chunk is rejected whole
    (chunk_crc: which of its messages are damaged cannot be told) and the others' messages
    are read, with their values."""
    import zstandard

    frames = read_mcap(SAMPLES / "voyage.mcap", CFG).frames
    frames = {"position": frames["position"]}
    p = write_mcap(
        frames,
        {},
        tmp_path / "v.mcap",
        encoding="json",
        chunk_size=16 << 10,
        compression=compression,
    )
    data = p.read_bytes()
    victim = _chunks(data)[2]
    f = _chunk_fields(data, victim)
    raw = zstandard.ZstdDecompressor().decompress(f["records"]) if compression else f["records"]
    at = raw.index(b'"latitude":') + len(b'"latitude":') + 3  # a digit of the first latitude
    bad = bytearray(raw)
    bad[at] = ord("1") if bad[at] != ord("1") else ord("2")
    bad = bytes(bad)
    if compression:
        new = _replace_chunk(data, victim, zstandard.ZstdCompressor().compress(bad), "zstd")
    else:
        new = data[: f["records_at"] + at] + bad[at : at + 1] + data[f["records_at"] + at + 1 :]
    q = tmp_path / "flipped.mcap"
    q.write_bytes(new)
    r = read_mcap(q, CFG)
    assert r.rejects.counts == {"chunk_crc": 1}, dict(r.rejects.counts)
    assert f"Chunk 3 at byte {victim}" in r.rejects.examples["chunk_crc"][0][2]
    assert any("rejected (chunk_crc)" in n for n in r.notes)
    lost = _chunk_messages(data, victim)
    assert lost > 0
    clean = read_mcap(p, CFG)
    want = _by_time(clean.frames, "position")
    got = _by_time(r.frames, "position")
    assert len(got) == len(want) - lost
    # the records kept are clean ones, with their values: the damaged latitude is not among them
    from collections import Counter

    def triples(f):
        return Counter(
            zip(
                f["time_ns"].tolist(),
                f["source"].astype(str).tolist(),
                f["lat_rad"].tolist(),
                strict=True,
            )
        )

    assert not triples(got) - triples(want)


def test_mcap_zero_crc_is_not_checked(tmp_path):
    """``uncompressed_crc`` 0 means 'not computed': the chunk is read."""
    frames = {"position": read_mcap(SAMPLES / "voyage.mcap", CFG).frames["position"]}
    p = write_mcap(
        frames, {}, tmp_path / "v.mcap", encoding="json", chunk_size=16 << 10, compression=None
    )
    data = p.read_bytes()
    victim = _chunks(data)[1]
    f = _chunk_fields(data, victim)
    q = tmp_path / "nocrc.mcap"
    q.write_bytes(_replace_chunk(data, victim, f["records"], "", crc=0))
    r = read_mcap(q, CFG)
    assert r.rejects.total == 0 and r.records == read_mcap(p, CFG).records


def test_mcap_zero_bytes_inside_a_chunk_are_walked_over(tmp_path):
    """A run of zero bytes in a chunk (empty records of opcode 0; a chunk of zeros with a
    right CRC cost seconds per 64 MiB walked record by record) is stepped over at once,
    exactly where the record-by-record walk would go on: every message is still read
    (the message index no longer fits, so the chunk is walked)."""
    frames = {"position": read_mcap(SAMPLES / "voyage.mcap", CFG).frames["position"]}
    p = write_mcap(
        frames, {}, tmp_path / "v.mcap", encoding="json", chunk_size=16 << 10, compression=None
    )
    data = p.read_bytes()
    victim = _chunks(data)[1]
    raw = _chunk_fields(data, victim)["records"]
    (first,) = struct.unpack_from("<Q", raw, 1)
    k = 9 + first
    padded = raw[:k] + bytes(9 * 50_000) + raw[k:]
    q = tmp_path / "zeros.mcap"
    q.write_bytes(
        _replace_chunk(data, victim, padded, "", usize=len(padded), crc=zlib.crc32(padded))
    )
    r = read_mcap(q, CFG)
    assert r.rejects.total == 0, dict(r.rejects.counts)
    assert r.records == read_mcap(p, CFG).records


def test_mcap_data_and_summary_crcs_are_verified(tmp_path):
    """The DataEnd record's data-section CRC and the Footer's summary CRC (where the writer
    computed them): a byte changed outside any chunk's records (a chunk's start time, a
    summary record) is counted (data_section_crc, summary_crc); every message is read."""
    from mcap.writer import CompressionType, Writer

    p = tmp_path / "crcs.mcap"
    with p.open("wb") as fh:
        w = Writer(fh, chunk_size=2000, compression=CompressionType.ZSTD, enable_data_crcs=True)
        w.start()
        ch = w.register_channel("/gps/fix", "json", 0)
        for i in range(200):
            msg = {"latitude": 54.0 + i / 1000, "longitude": 18.0}
            w.add_message(ch, 1_700_000_000_000_000_000 + i * 10**9, json.dumps(msg).encode(), 0)
        w.finish()
    data = p.read_bytes()
    assert read_mcap(p, CFG).rejects.total == 0
    recs = _records(data)
    chunk = next(pos for op, pos, _ in recs if op == 6)
    b = bytearray(data)
    b[chunk + 9] ^= 0x01  # the first chunk's message_start_time: not covered by its own CRC
    q = tmp_path / "data_crc.mcap"
    q.write_bytes(bytes(b))
    r = read_mcap(q, CFG)
    assert r.rejects.counts == {"data_section_crc": 1} and r.records == 200
    stats = next(pos for op, pos, _ in recs if op == 11)  # the Statistics record in the summary
    b = bytearray(data)
    b[stats + 9] ^= 0x01
    q.write_bytes(bytes(b))
    r = read_mcap(q, CFG)
    assert r.rejects.counts == {"summary_crc": 1} and r.records == 200


# ===================================================================== MCAP topic names
def test_mcap_topic_with_control_characters_is_kept_as_data(tmp_path):
    """A topic holding an ANSI escape and an OSC sequence (terminal title) is stored as it
    is: the source key and the notes carry the same characters, not mangled and not
    interpreted (escaping them is the renderers' job)."""
    from mcap.writer import CompressionType, Writer

    topic = "/\x1b[31mINS2\x1b]0;pwned\x07/fix"
    p = tmp_path / "esc.mcap"
    with p.open("wb") as fh:
        w = Writer(fh, compression=CompressionType.ZSTD)
        w.start()
        ch = w.register_channel(topic, "json", 0)
        for i in range(5):
            w.add_message(
                ch,
                1_700_000_000_000_000_000 + i * 10**9,
                json.dumps({"latitude": 54.0, "longitude": 18.0 + i / 100}).encode(),
                0,
            )
        w.finish()
    r = read_mcap(p, CFG)
    key = "\x1b[31mINS2\x1b]0;pwned\x07"
    assert set(r.frames["position"]["source"].astype(str)) == {key}
    assert any(topic in n and repr(key) in n for n in r.notes)
