"""Vectorised scanning of text logs: lines, fields, decimal and hex numbers, timestamps.

Everything works on a whole file at once: the bytes as one ``uint8`` array and, per
line or field, start and end offsets into it. Numbers are read from a fixed-width
block of bytes per field (a strided view of the buffer, no per-byte index arrays),
digit column by digit column, so no Python runs per line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_HEX = np.full(256, -1, dtype=np.int16)
for _i, _c in enumerate(b"0123456789abcdef"):
    _HEX[_c] = _i
for _i, _c in enumerate(b"ABCDEF"):
    _HEX[_c] = 10 + _i
HEX_VALUE = _HEX  #: byte -> hex digit value, -1 for a non-hex byte

#: zero bytes before and after the text in every ``Lines.buf``, so fixed-width windows
#: at a line's start or end never leave the buffer
PAD = 64


@dataclass
class Lines:
    """The lines of a text buffer that carry data (not blank, not ``#`` comments)."""

    buf: np.ndarray  #: uint8, the whole text between ``PAD`` zero bytes each side
    start: np.ndarray  #: int64 offset of each line's first byte
    end: np.ndarray  #: int64 offset past each line's last byte (before its line end)
    number: np.ndarray  #: int64 1-based line number in the file

    def text(self, i: int) -> str:
        """Line ``i`` as text (for reject examples)."""
        return bytes(self.buf[self.start[i] : self.end[i]]).decode("latin-1")

    def select(self, mask: np.ndarray) -> Lines:
        return Lines(self.buf, self.start[mask], self.end[mask], self.number[mask])


def split_lines(data: bytes, first_line: int = 1) -> Lines:
    """The data lines of ``data`` (LF, CR LF or CR line ends; blank and ``#`` lines are
    skipped but counted in line numbers)."""
    buf = np.frombuffer(data, dtype=np.uint8)
    if len(buf) == 0:
        z = np.zeros(0, dtype=np.int64)
        return Lines(_padded(buf), z, z, z)
    if b"\r" in data:
        cr = buf == 13
        lf = buf == 10
        lf_after_cr = np.zeros(len(buf), dtype=bool)
        lf_after_cr[1:] = lf[1:] & cr[:-1]
        ends = np.flatnonzero(cr | (lf & ~lf_after_cr))
        step = np.ones(len(ends), dtype=np.int64)
        nxt = ends + 1
        inside = nxt < len(buf)
        step[inside] += lf[nxt[inside]]
        starts_next = ends + step
    else:
        ends = np.flatnonzero(buf == 10)
        starts_next = ends + 1
    ends = ends.astype(np.int64)
    starts = np.concatenate(([0], starts_next)).astype(np.int64)
    if starts[-1] < len(buf):
        ends = np.concatenate((ends, [len(buf)]))
    else:
        starts = starts[:-1]
    number = np.arange(first_line, first_line + len(starts), dtype=np.int64)
    keep = ends > starts
    keep[keep] = buf[starts[keep]] != ord("#")
    return Lines(_padded(buf), starts[keep] + PAD, ends[keep] + PAD, number[keep])


def _padded(core: np.ndarray) -> np.ndarray:
    buf = np.zeros(len(core) + 2 * PAD, dtype=np.uint8)
    buf[PAD : PAD + len(core)] = core
    return buf


def join_lines(lines: list[bytes], numbers: np.ndarray) -> Lines:
    """Lines given one by one (their own line numbers), as one buffer."""
    clean = [ln.rstrip(b"\r\n") for ln in lines]
    lens = np.array([len(c) for c in clean], dtype=np.int64)
    starts = np.zeros(len(clean), dtype=np.int64)
    if len(clean) > 1:
        np.cumsum(lens[:-1] + 1, out=starts[1:])
    buf = _padded(np.frombuffer(b"\n".join(clean), dtype=np.uint8))
    starts += PAD
    out = Lines(buf, starts, starts + lens, np.asarray(numbers, dtype=np.int64))
    keep = lens > 0
    keep[keep] = buf[starts[keep]] != ord("#")
    return out.select(keep)


def block(buf: np.ndarray, at: np.ndarray, width: int) -> np.ndarray:
    """``buf[at[i] : at[i] + width]`` of every ``i`` as rows of a (n, width) array
    (``at`` clipped into the buffer)."""
    if len(buf) < width:
        buf = np.concatenate([buf, np.zeros(width - len(buf), dtype=np.uint8)])
    win = np.lib.stride_tricks.sliding_window_view(buf, width)
    return win[np.clip(at, 0, len(buf) - width)]


def pack_lines(buf: np.ndarray, a: np.ndarray, e: np.ndarray) -> tuple[bytes, np.ndarray]:
    """The bytes ``buf[a[i]:e[i]]`` of each line ``i``, each followed by LF, as one
    buffer; and where each starts in it."""
    n = e - a
    offs = np.zeros(len(n), dtype=np.int64)
    if len(n) > 1:
        np.cumsum(n[:-1] + 1, out=offs[1:])
    out = np.full(int(n.sum()) + len(n), 10, dtype=np.uint8)
    out[np.repeat(offs, n) + ramp(n)] = buf[np.repeat(a, n) + ramp(n)]
    return out.tobytes(), offs


def ramp(counts: np.ndarray) -> np.ndarray:
    """0, 1, ..., c-1 for every c in ``counts``, one after another."""
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64)
    ends = np.cumsum(counts)
    return np.arange(total, dtype=np.int64) - np.repeat(ends - counts, counts)


def parse_uint(
    buf: np.ndarray, s: np.ndarray, e: np.ndarray, width: int
) -> tuple[np.ndarray, np.ndarray]:
    """Decimal unsigned integers in fields ``[s, e)`` of up to ``width`` digits; the
    values (int64) and whether each field was one."""
    w = e - s
    ok = (w >= 1) & (w <= width)
    dig = block(buf, e - width, width) - np.uint8(48)
    val = np.zeros(len(s), dtype=np.int64)
    for k in range(width):  # column k holds the digit of weight 10**(width-1-k)
        inside = w >= width - k
        d = dig[:, k]
        ok &= (d <= 9) | ~inside
        val = val * 10 + np.where(inside, d, 0)
    return val, ok


def parse_hex(
    buf: np.ndarray, s: np.ndarray, e: np.ndarray, width: int
) -> tuple[np.ndarray, np.ndarray]:
    """Hexadecimal unsigned integers in fields ``[s, e)`` of up to ``width`` digits."""
    w = e - s
    ok = (w >= 1) & (w <= width)
    dig = HEX_VALUE[block(buf, e - width, width)]
    val = np.zeros(len(s), dtype=np.int64)
    for k in range(width):
        inside = w >= width - k
        d = dig[:, k]
        ok &= (d >= 0) | ~inside
        val = (val << 4) + np.where(inside, d, 0)
    return val, ok


def parse_seconds(
    buf: np.ndarray, s: np.ndarray, e: np.ndarray, int_width: int = 12
) -> tuple[np.ndarray, np.ndarray]:
    """Decimal seconds ``123.456`` (fraction optional, up to 9 digits) in fields
    ``[s, e)``, as int64 nanoseconds."""
    n = len(s)
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool)
    found = first_at_or_after(np.flatnonzero(buf == 46), s, e)
    dot = np.where(found >= 0, found, e)
    has_dot = dot < e
    int_end = np.where(has_dot, dot, e)
    whole, ok = parse_uint(buf, s, int_end, int_width)
    frac_ns, fok = parse_fraction(buf, np.where(has_dot, dot + 1, e), e)
    ok &= fok | ~has_dot
    ok &= ~has_dot | (e > dot + 1)
    return whole * 1_000_000_000 + np.where(has_dot, frac_ns, 0), ok


def parse_fraction(buf: np.ndarray, s: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Digits of a decimal fraction in ``[s, e)`` (up to 9 read, more ignored) as ns."""
    w = e - s
    ok = w >= 0
    width = min(9, int(w.max()) if len(w) else 0)
    val = np.zeros(len(s), dtype=np.int64)
    if width == 0:
        return val, ok
    dig = block(buf, s, width) - np.uint8(48)
    for k in range(width):
        inside = w > k
        d = dig[:, k]
        ok &= (d <= 9) | ~inside
        val += np.where(inside, d, 0).astype(np.int64) * 10 ** (8 - k)
    return val, ok


def days_from_civil(y: np.ndarray, m: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Days since 1970-01-01 of proleptic Gregorian dates (H. Hinnant's algorithm)."""
    y = y - (m <= 2)
    era = np.floor_divide(y, 400)
    yoe = y - era * 400
    mp = (m + 9) % 12
    doy = (153 * mp + 2) // 5 + d - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    return era * 146097 + doe - 719468


def parse_datetime(buf: np.ndarray, s: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ISO-like UTC times ``YYYY-MM-DDTHH:MM:SS[.fff][Z]`` in fields ``[s, e)`` (the
    date-time separator may also be ``-`` or a space, as older canboat logs write), as
    int64 ns since the epoch."""
    n = len(s)
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool)
    zed = buf.take(e - 1, mode="clip") == ord("Z")
    ee = e - zed
    w = ee - s
    ok = w >= 19
    cols = block(buf, s, 19)
    dig = cols - np.uint8(48)
    for c in (0, 1, 2, 3, 5, 6, 8, 9, 11, 12, 14, 15, 17, 18):
        ok &= dig[:, c] <= 9

    def num(a: int, b: int) -> np.ndarray:
        v = dig[:, a].astype(np.int64)
        for k in range(a + 1, b):
            v = v * 10 + dig[:, k]
        return v

    ok &= (cols[:, 4] == 45) & (cols[:, 7] == 45) & (cols[:, 13] == 58) & (cols[:, 16] == 58)
    sep = cols[:, 10]
    ok &= (sep == ord("T")) | (sep == 45) | (sep == 32)
    year, month, day = num(0, 4), num(5, 7), num(8, 10)
    hour, minute, sec = num(11, 13), num(14, 16), num(17, 19)
    ok &= (month >= 1) & (month <= 12) & (day >= 1) & (day <= 31)
    ok &= (hour <= 23) & (minute <= 59) & (sec <= 60)
    has_frac = w > 19
    ok &= ~has_frac | ((buf.take(s + 19, mode="clip") == 46) & (w > 20))
    frac, fok = parse_fraction(buf, s + 20, np.where(has_frac, ee, s + 20))
    ok &= fok
    days = days_from_civil(year, month, day)
    t = ((days * 24 + hour) * 60 + minute) * 60 + sec
    return t * 1_000_000_000 + np.where(has_frac, frac, 0), ok


def parse_time_of_day(
    buf: np.ndarray, s: np.ndarray, e: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``HH:MM:SS[.fff]`` in fields ``[s, e)`` as int64 ns since midnight."""
    n = len(s)
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool)
    last = len(buf) - 1
    ok = (e - s >= 8) & (buf[np.minimum(s + 2, last)] == 58) & (buf[np.minimum(s + 5, last)] == 58)
    h, k1 = parse_uint(buf, s, s + 2, 2)
    m, k2 = parse_uint(buf, s + 3, s + 5, 2)
    sec, k3 = parse_uint(buf, s + 6, s + 8, 2)
    ok &= k1 & k2 & k3 & (h <= 23) & (m <= 59) & (sec <= 60)
    has_frac = e - s > 8
    ok &= ~has_frac | ((buf[np.minimum(s + 8, last)] == 46) & (e - s > 9))
    frac, fok = parse_fraction(buf, s + 9, np.where(has_frac, e, s + 9))
    ok &= fok
    return ((h * 60 + m) * 60 + sec) * 1_000_000_000 + np.where(has_frac, frac, 0), ok


def first_at_or_after(positions: np.ndarray, s: np.ndarray, e: np.ndarray) -> np.ndarray:
    """For each range ``[s, e)`` the first of sorted ``positions`` inside it, else -1."""
    j = np.searchsorted(positions, s)
    if len(positions) == 0:
        return np.full(len(s), -1, dtype=np.int64)
    p = positions[np.minimum(j, len(positions) - 1)].astype(np.int64)
    return np.where((j < len(positions)) & (p < e), p, -1)
