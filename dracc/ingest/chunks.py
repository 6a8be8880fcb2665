"""A file of lines read in chunks of bounded size, for the readers that take a line at a
time (Signal K, gpsd JSON): memory stays flat as logs grow.

:func:`iter_line_chunks` cuts a file after a line end (LF; a CR before it is not part
of the line, as :func:`dracc.ingest.demux.line_bounds` reads lines), about
``CHUNK_BYTES`` at a time.  A line longer than the chunk is held whole up to
``max_line_bytes`` plus ``LINE_SLACK`` (a prefix such as a Signal K log's
``<ms>;<letter>;``); a longer line is *cut*: a chunk of that line alone holding only its
first bytes, its true length kept, so a reader rejects it as ``too_long`` (it is
longer than any reader takes) and its bytes are never held.  :class:`LineCopy` writes a
line-preserving copy (:mod:`dracc.ingest.demux`) chunk by chunk, a cut line streamed
from the file.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np

from dracc.ingest.demux import line_bounds, line_copy

CHUNK_BYTES = 32 * 1024 * 1024  #: bytes read at a time (a chunk ends after a line end)
LINE_SLACK = 64  #: bytes beyond ``max_line_bytes`` a line may have and still be held whole
_SCAN_BYTES = 1 << 20  #: bytes read at a time along a cut line


@dataclass
class Chunk:
    """Whole lines of a file: ``data`` (also as ``buf``, uint8) from file offset
    ``offset``, the lines' (start, end, next) in ``data``, ``line0`` lines before them.
    A cut line (``cut`` not None) is a chunk of one line whose ``data`` is its first
    bytes; ``nxt[0]`` is its true length with its line end and ``cut`` is (file offset
    of its content's end, file offset of the next line)."""

    data: bytes | bytearray
    buf: np.ndarray
    start: np.ndarray
    end: np.ndarray
    nxt: np.ndarray
    line0: int
    offset: int
    cut: tuple[int, int] | None = None

    @property
    def nbytes(self) -> int:
        """Bytes of the file this chunk stands for."""
        return int(self.nxt[-1]) if len(self.nxt) else 0

    def numbers(self, idx: np.ndarray) -> np.ndarray:
        """The 1-based line numbers in the file of the chunk's lines ``idx``."""
        return idx + 1 + self.line0


def iter_line_chunks(
    path: str | Path,
    max_line_bytes: int,
    chunk_bytes: int | None = None,
    stop: int | None = None,
) -> Iterator[Chunk]:
    """The chunks of ``path`` (its first ``stop`` bytes, ``stop`` a line start) in order;
    ``chunk_bytes`` None: ``CHUNK_BYTES`` (read at call time, so tests may shrink it)."""
    size_chunk = max(1, chunk_bytes if chunk_bytes is not None else CHUNK_BYTES)
    limit = max_line_bytes + LINE_SLACK + 2  # content, CR and LF of the longest line held
    fd = os.open(path, os.O_RDONLY)
    try:
        size = os.fstat(fd).st_size if stop is None else stop
        off = line0 = 0
        while off < size:
            data = _whole_lines(fd, off, size, size_chunk, limit)
            if data is None:
                ch = _cut_line(fd, off, size, limit, line0)
            else:
                buf = np.frombuffer(data, dtype=np.uint8)
                start, end, nxt = line_bounds(buf)
                ch = Chunk(data, buf, start, end, nxt, line0, off)
            yield ch
            off += ch.nbytes
            line0 += len(ch.start)
    finally:
        os.close(fd)


def _whole_lines(fd: int, off: int, size: int, chunk: int, limit: int) -> bytearray | None:
    """The bytes from ``off`` to the last line end within ``chunk`` bytes (to the end of
    the file where it is nearer); a first line longer: up to its end when within
    ``limit`` bytes; None when it is longer still."""
    data = bytearray(min(chunk, size - off))  # read into, cut in place: never copied
    del data[os.preadv(fd, [data], off) :]
    if off + len(data) >= size:
        return data
    k = data.rfind(b"\n")
    if k >= 0:
        del data[k + 1 :]
        return data
    if len(data) < limit:
        data += os.pread(fd, min(limit, size - off) - len(data), off + len(data))
        k = data.find(b"\n")
        if k >= 0:
            del data[k + 1 :]
            return data
        if off + len(data) >= size:
            return data
    return None


def _cut_line(fd: int, off: int, size: int, limit: int, line0: int) -> Chunk:
    """The chunk of a line at ``off`` longer than ``limit``: its first ``limit - 1``
    bytes (more than any reader takes), its end found by reading on, never held."""
    head = os.pread(fd, limit - 1, off)
    at, last, nxt = off + len(head), head[-1:], size
    content_end = -1
    while at < size:
        piece = os.pread(fd, min(_SCAN_BYTES, size - at), at)
        if not piece:
            break
        k = piece.find(b"\n")
        if k >= 0:
            before = piece[k - 1 : k] if k else last
            content_end = at + k - (before == b"\r")
            nxt = at + k + 1
            break
        last = piece[-1:]
        at += len(piece)
    if content_end < 0:  # the last line, no line end: a CR at its end is not content
        content_end = size - (last == b"\r")
    buf = np.frombuffer(head, dtype=np.uint8)
    one = np.zeros(1, dtype=np.int64)
    return Chunk(head, buf, one, one + len(head), one + (nxt - off), line0, off, (content_end, nxt))


class LineCopy:
    """A line-preserving copy of a file (:func:`dracc.ingest.demux.line_copy`) written
    chunk by chunk to ``path``."""

    def __init__(self, source: str | Path, path: Path) -> None:
        self.source = Path(source)
        self.path = path
        self._fh: BinaryIO = path.open("wb")

    def pad(self, lines: int) -> None:
        """``lines`` blank lines (the lines before the first one copied)."""
        for a in range(0, lines, _SCAN_BYTES):
            self._fh.write(b"\n" * min(_SCAN_BYTES, lines - a))

    def add(self, ch: Chunk, keep: np.ndarray, skip: np.ndarray | int = 0) -> None:
        """The lines of ``ch``: from ``start + skip`` to their end where ``keep``, blank
        otherwise; a cut line kept is streamed from the file."""
        if ch.cut is None:
            self._fh.write(line_copy(ch.buf, ch.start, ch.end, ch.nxt, keep, skip).data)
            return
        if bool(keep[0]):
            sk = int(skip[0]) if isinstance(skip, np.ndarray) else skip
            at, stop = ch.offset + sk, ch.cut[0]
            with self.source.open("rb") as src:
                src.seek(at)
                while at < stop:
                    piece = src.read(min(_SCAN_BYTES, stop - at))
                    if not piece:
                        break
                    self._fh.write(piece)
                    at += len(piece)
        self._fh.write(b"\n")

    def close(self) -> Path:
        """Close the copy (again: nothing); its path."""
        self._fh.close()
        return self.path
