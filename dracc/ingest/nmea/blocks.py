"""A file as blocks of whole lines: where its blocks are cut (:func:`block_ranges`,
reading ahead for line ends with ``os.pread``, a line too long a block of its own) and
the parse of one block (:func:`parse_range`)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

from dracc.ingest.nmea.engine_c import parse_buffer
from dracc.ingest.nmea.engine_numpy import long_line_block
from dracc.ingest.nmea.lines import line_end_length
from dracc.ingest.nmea.parsed import ParsedBlock
from dracc.ingest.nmea.sentences import MAX_LINE_BYTES


def block_ranges(
    path: Path,
    block_bytes: int,
    first_bytes: int | None = None,
    max_line_bytes: int = MAX_LINE_BYTES,
) -> Iterator[tuple[int, int, bool]]:
    """(offset, length, too long) of blocks of whole lines: the first about ``first_bytes``
    (default ``block_bytes``), the others about ``block_bytes``, each cut after a line end
    (LF, CR LF, CR CR LF or a lone CR).  A line longer than ``max_line_bytes`` across a
    cut is a block of its own, flagged too long: it is found by reading ahead, never held
    (a block never exceeds its size plus ``max_line_bytes``, whatever the file holds)."""
    size = path.stat().st_size
    fd = os.open(path, os.O_RDONLY)
    try:
        off = 0
        while off < size:
            end = off + ((first_bytes or block_bytes) if off == 0 else block_bytes)
            if end >= size:
                yield off, size - off, False
                return
            nxt = _next_line_end(fd, end, min(size, end + max_line_bytes + 3))
            if nxt is not None:
                yield off, nxt - off, False
                off = nxt
                continue
            # the line across the cut is too long: the block ends where it starts
            s = _line_start_before(fd, off, end)
            if s > off:
                yield off, s - off, False
            nxt = _next_line_end(fd, end, size)
            e = size if nxt is None else nxt
            yield s, e - s, True
            off = e
    finally:
        os.close(fd)


_SCAN_BYTES = 1 << 20  #: bytes read at a time when looking for a line end


def _next_line_end(fd: int, pos: int, limit: int) -> int | None:
    """The offset after the first line end starting in [pos, limit), None if there is none."""
    at = pos
    while at < limit:
        chunk = os.pread(fd, min(_SCAN_BYTES, limit - at), at)
        if not chunk:
            return None
        i, j = chunk.find(b"\n"), chunk.find(b"\r")
        q = i if j < 0 else j if i < 0 else min(i, j)
        if q >= 0:
            return at + q + line_end_length(os.pread(fd, 3, at + q))
        at += len(chunk)
    return None


def _line_start_before(fd: int, lo: int, hi: int) -> int:
    """The start of the line holding byte ``hi - 1``: after the last CR or LF in [lo, hi),
    else ``lo`` (the caller knows ``hi`` is neither, so that CR is a line end)."""
    at = hi
    while at > lo:
        a = max(lo, at - _SCAN_BYTES)
        chunk = os.pread(fd, at - a, a)
        k = max(chunk.rfind(b"\n"), chunk.rfind(b"\r"))
        if k >= 0:
            return a + k + 1
        at = a
    return lo


def parse_range(
    path: str,
    off: int,
    length: int,
    ignore_checksum: bool,
    at_eof: bool,
    max_line_bytes: int = MAX_LINE_BYTES,
    too_long: bool = False,
) -> ParsedBlock:
    """Parse one block of a file; a block flagged ``too_long`` (one line, see
    :func:`block_ranges`) is one ``too_long`` reject and only its first bytes are read."""
    with open(path, "rb") as fh:
        fh.seek(off)
        if too_long:
            head = fh.read(min(length, 120))
            a = max(off, off + length - max_line_bytes - 3)
            fh.seek(a)
            tail = fh.read(off + length - a)
            content = tail.rstrip(b"\r\n")  # a line's content holds no CR or LF
            return long_line_block(
                head,
                content[-max_line_bytes:],
                tail[len(content) :],
                ignore_checksum,
                at_eof,
                max_line_bytes,
            )[0]
        data = fh.read(length)
    return parse_buffer(
        data, ignore_checksum=ignore_checksum, at_eof=at_eof, max_line_bytes=max_line_bytes
    )
