"""A file as blocks of whole lines: where its blocks are cut (:func:`block_ranges`,
reading ahead for line ends with ``os.pread``, a line too long a block of its own) and
the parse of one block (:func:`parse_range`); a stream (a decompressed log) cut the same
way as it is read (:func:`stream_pieces`, :func:`parse_piece`)."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
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


@dataclass
class Piece:
    """Whole lines read from a stream (``data``), or one line too long (``long``: its
    first bytes, the last ``max_line_bytes`` of its content, its line end), ``nbytes``
    of the stream it stands for; ``at_eof``: the last piece."""

    data: bytes
    nbytes: int
    at_eof: bool
    long: tuple[bytes, bytes, bytes] | None = None


def stream_pieces(
    read: Callable[[int], bytes], first_bytes: int, block_bytes: int, max_line_bytes: int
) -> Iterator[Piece]:
    """A stream (``read(n)``: up to ``n`` bytes, ``b""`` at its end) cut as
    :func:`block_ranges` cuts a file: pieces of whole lines, the first about
    ``first_bytes``, the others about ``block_bytes``, each ending after a line end (the
    bytes after it wait for the next piece); a line longer than a piece is a piece of
    its own, flagged ``long`` and read to its end without being held.  Memory: one
    piece, whatever the stream holds."""
    carry, size = b"", first_bytes
    while True:
        want = max(size, max_line_bytes + 4)
        size = block_bytes
        data = carry + _fill(read, want - len(carry))
        if len(data) < want:  # the end of the stream
            if data:
                yield Piece(data, len(data), True)
            return
        cut = _last_line_end(data)
        if cut:
            yield Piece(data[:cut], cut, False)
            carry = data[cut:]
            continue
        piece, carry = _long_line(data, read, max_line_bytes)
        yield piece
        if piece.at_eof:
            return


def _fill(read: Callable[[int], bytes], n: int) -> bytes:
    """Up to ``n`` bytes of the stream: fewer only at its end."""
    parts, got = [], 0
    while got < n:
        b = read(n - got)
        if not b:
            break
        parts.append(b)
        got += len(b)
    return parts[0] if len(parts) == 1 else b"".join(parts)


def _last_line_end(data: bytes) -> int:
    """The offset after the last line end of ``data`` whose kind its next bytes tell
    (LF, CR LF, CR CR LF, a lone CR: as :func:`_next_line_end`), 0 for none."""
    n = len(data)
    k = max(data.rfind(b"\n", 0, n - 2), data.rfind(b"\r", 0, n - 2))
    return 0 if k < 0 else k + line_end_length(data[k : k + 3])


def _long_line(
    data: bytes, read: Callable[[int], bytes], max_line_bytes: int
) -> tuple[Piece, bytes]:
    """The piece of a line longer than ``data`` (which it starts), read on to its line
    end keeping only its first and last bytes; and the bytes after it."""
    head, tail, buf, nbytes = data[:120], b"", data, 0
    while True:
        i, j = buf.find(b"\n"), buf.find(b"\r")
        q = i if j < 0 else j if i < 0 else min(i, j)
        if q >= 0 and q + 3 > len(buf):  # a line end to tell: its next bytes
            more = _fill(read, 3)
            if more:
                buf += more
                continue
        if q < 0:
            tail = (tail + buf)[-max_line_bytes:]
            nbytes += len(buf)
            buf = read(_SCAN_BYTES)
            if buf:
                continue
            return Piece(b"", nbytes, True, (head, tail, b"")), b""
        le = line_end_length(buf[q : q + 3])
        rest = buf[q + le :] or _fill(read, 1)
        piece = Piece(
            b"",
            nbytes + q + le,
            not rest,
            (head, (tail + buf[:q])[-max_line_bytes:], buf[q : q + le]),
        )
        return piece, rest


def parse_piece(piece: Piece, ignore_checksum: bool, max_line_bytes: int) -> ParsedBlock:
    """Parse one piece of :func:`stream_pieces` (as :func:`parse_range` parses a block)."""
    if piece.long is not None:
        head, tail, line_end = piece.long
        return long_line_block(head, tail, line_end, ignore_checksum, piece.at_eof, max_line_bytes)[
            0
        ]
    return parse_buffer(
        piece.data,
        ignore_checksum=ignore_checksum,
        at_eof=piece.at_eof,
        max_line_bytes=max_line_bytes,
    )
