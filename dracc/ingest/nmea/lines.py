"""Lines in a buffer of NMEA text: where lines start and end (LF, CR LF, CR CR LF or a
lone CR) and which hold non-printable bytes, where a buffer is cut into chunks of whole
lines, and where the readable tail of a line too long starts."""

from __future__ import annotations

import numpy as np


def ranges_any(pos: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """True where the sorted positions ``pos`` have an element in [a, b)."""
    return np.searchsorted(pos, b) > np.searchsorted(pos, a)


class Marked:
    """Where the bytes of one class (here: binary ones) lie in a buffer: their sorted
    positions when they are few, else a boolean mask (one byte per byte, where positions
    would take eight); :meth:`any` tells which ranges [a, b) hold one."""

    def __init__(self, pos: np.ndarray | None = None, mask: np.ndarray | None = None):
        self.pos, self.mask = pos, mask  # mask: one False more than the buffer

    def any(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        if self.pos is not None:
            return ranges_any(self.pos, a, b)
        out = np.zeros(len(a), dtype=bool)
        ne = np.flatnonzero(b > a)
        if len(ne):
            idx = np.empty(2 * len(ne), dtype=np.int64)
            idx[0::2], idx[1::2] = a[ne], b[ne]
            out[ne] = np.logical_or.reduceat(self.mask, idx)[0::2]  # type: ignore[arg-type]
        return out


def line_bounds(buf: np.ndarray, bufp: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool, Marked]:
    """Lines of a buffer: (start, content end, ends with a line end, binary bytes).

    A line ends at LF, CR LF, CR CR LF (CR LF through a text-mode conversion: one line
    end, not an empty line) or a lone CR (old Mac loggers, serial capture tools); the
    content excludes its line end.  ``bufp`` is ``buf`` with zero bytes after it.  One
    pass finds the bytes outside printable ASCII, ``(b - 32) mod 256 > 94``; where they
    are most of the buffer (a run of NUL bytes) no position array per byte is made."""
    n = len(buf)
    m = (buf - np.uint8(32)) > 94
    if np.count_nonzero(m) * 8 <= n:  # text: positions (one line end or so per line)
        ctl = np.flatnonzero(m)
        del m
        cb = buf[ctl]
        isterm = (cb == 10) | (cb == 13)
        term = ctl[isterm]
        bad = Marked(pos=ctl[~isterm & (cb != 9)])
        del ctl, cb, isterm
    else:  # mostly control bytes: line ends by position, binary bytes by mask if dense
        tm = (buf == 10) | (buf == 13)
        term = np.flatnonzero(tm)
        m &= ~tm
        m &= buf != 9
        del tm
        if np.count_nonzero(m) * 8 <= n:
            bad = Marked(pos=np.flatnonzero(m))
        else:
            bad = Marked(mask=np.concatenate((m, np.zeros(1, dtype=bool))))
        del m
    start, end, ends = line_spans(buf, bufp, term)
    return start, end, ends, bad


def line_spans(
    buf: np.ndarray, bufp: np.ndarray, term: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, bool]:
    """(start, content end, ends with a line end) of the lines of a buffer, cut as
    :func:`line_bounds` cuts them; ``term``: the positions of its CR and LF bytes (found
    here where None)."""
    n = len(buf)
    if term is None:
        term = np.flatnonzero((buf == 10) | (buf == 13))
    # a CR followed by LF or by CR LF belongs to the line end at that LF
    tb = buf[term]
    nx1 = bufp[term + 1]
    within = (tb == 13) & ((nx1 == 10) | ((nx1 == 13) & (bufp[term + 2] == 10)))
    last = term[~within]  # the last byte of each line end
    del term, tb, nx1, within
    c1 = (buf[last] == 10) & (bufp[last - 1] == 13)  # bufp[-1], bufp[-2]: zero padding
    c2 = c1 & (bufp[last - 2] == 13)
    first = last - c1 - c2  # the first byte of each line end: the end of the content
    ends = bool(len(last)) and int(last[-1]) == n - 1
    line_end = first if ends else np.concatenate((first, [n]))
    line_start = np.concatenate(([0], last[:-1] + 1)) if ends else np.concatenate(([0], last + 1))
    return line_start.astype(np.int64, copy=False), line_end.astype(np.int64, copy=False), ends


def tail_start(tail: bytes) -> int:
    """Where the tail of a line too long is read from: its last sentence start ('$' or
    '!'), with the TAG block right before it (``\\...\\``, at most 128 bytes), so that
    one sentence is read and not a run of junk; ``len(tail)`` if it has none, or if the
    TAG block before it is longer (damaged: the sentence's source and time are unknown).
    As the kernel's tail_start."""
    j = max(tail.rfind(b"$"), tail.rfind(b"!"))
    if j < 0:
        return len(tail)
    if j > 0 and tail[j - 1] == 92:  # '\\': the end of a TAG block: with it, or not at all
        k = tail.rfind(b"\\", max(0, j - 1 - 128), j - 1)
        return k if k >= 0 else len(tail)  # a TAG block that long is damaged: source unknown
    return j


def chunk_cuts(data: bytes, size: int, max_lines: int) -> list[tuple[int, int]]:
    """[a, b) byte ranges of at most about ``size`` bytes and ``max_lines`` lines, each
    ending after a line end (or at the end of ``data``)."""
    n = len(data)
    out, a = [], 0
    while True:
        b = min(a + size, n)
        k = data.count(b"\n", a, b) + data.count(b"\r", a, b)  # at least the lines in [a, b)
        if k > max_lines:
            b = a + max(1, (b - a) * max_lines // k)
        e = _end_of_line_at(data, b) if b < n else None
        if e is None or e >= n:
            out.append((a, n))
            return out
        out.append((a, e))
        a = e


def _end_of_line_at(data: bytes, pos: int) -> int | None:
    """The offset after the first line end that starts at or after ``pos`` in ``data``."""
    i, j = data.find(b"\n", pos), data.find(b"\r", pos)
    q = i if j < 0 else j if i < 0 else min(i, j)
    if q < 0:
        return None
    return q + line_end_length(data[q : q + 3])


def line_end_length(b: bytes) -> int:
    """Bytes of the line end at the start of ``b`` (LF, CR LF, CR CR LF, a lone CR)."""
    if b[:1] == b"\r":
        return 2 if b[1:2] == b"\n" else 3 if b[1:3] == b"\r\n" else 1
    return 1
