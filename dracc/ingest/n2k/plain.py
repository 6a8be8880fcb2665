"""canboat's text formats, vectorised: ``time,prio,pgn,src,dst,len,hex bytes...``.

One line per CAN frame (PLAIN), one line per whole message (FAST), or both in one log
(PLAIN_MIX_FAST: fast-packet PGNs sometimes as single 8-byte frames, sometimes whole).
canboat's analyzer reassembles a line of at most 8 bytes of a fast-packet PGN as a frame
in PLAIN and PLAIN_MIX_FAST and takes every line as a whole message in FAST, and so do
we. Times are ``2014-08-15T19:00:00.042Z`` (UTC; older logs write
``2011-11-24-22:42:04.388``) or, failing that in the whole file, plain seconds
(relative).
"""

from __future__ import annotations

import numpy as np

from dracc.ingest.n2k.fastpacket import rows_to_messages
from dracc.ingest.n2k.messages import TIME_RELATIVE, TIME_UTC, Messages, add_reject
from dracc.ingest.n2k.textscan import (
    HEX_VALUE,
    Lines,
    block,
    parse_datetime,
    parse_seconds,
    parse_uint,
    ramp,
)

#: the longest payload a line may carry (ISO transport's limit)
MAX_LENGTH = 1785
#: line length classes read as one block each (the last, ISO transport's limit)
_WIDTHS = (8, 16, 32, 64, 128, 256, MAX_LENGTH)
#: the highest PGN a line may name (canboat's own pseudo-PGNs for gateway data lie above
#: the 18-bit NMEA range, below 0x80000)
MAX_PGN = 0x7FFFF


def parse_plain(lines: Lines, reassemble: bool = True) -> Messages:
    """Messages of canboat PLAIN / PLAIN_MIX_FAST lines (``reassemble``: frames of
    fast-packet PGNs joined) or FAST lines (every line whole)."""
    buf, start, end = lines.buf, lines.start, lines.end
    n = len(start)
    commas = np.flatnonzero(buf == 44)
    if len(commas) == 0:
        commas = np.array([len(buf)], dtype=np.int64)
    c0 = np.searchsorted(commas, start)
    cs = [commas.take(c0 + k, mode="clip").astype(np.int64) for k in range(6)]
    reason = np.zeros(n, dtype=np.int8)  # 0 good, else index into _REASONS
    ok = (cs[4] < end) & (c0 + 4 < len(commas))
    reason[~ok] = 1
    has6 = (cs[5] < end) & (c0 + 5 < len(commas))
    len_end = np.where(has6, cs[5], end)
    prio, k1 = parse_uint(buf, cs[0] + 1, cs[1], 1)
    pgn, k2 = parse_uint(buf, cs[1] + 1, cs[2], 7)
    src, k3 = parse_uint(buf, cs[2] + 1, cs[3], 3)
    dst, k4 = parse_uint(buf, cs[3] + 1, cs[4], 3)
    length, k5 = parse_uint(buf, cs[4] + 1, len_end, 4)
    nums = k1 & k2 & k3 & k4 & k5 & (prio <= 7) & (pgn <= MAX_PGN) & (src <= 255) & (dst <= 255)
    nums &= length <= MAX_LENGTH
    reason[ok & ~nums] = 2
    ok &= nums
    # payload bytes: the common layout "xx,xx,...,xx" read at fixed steps, others by
    # their commas
    ds = cs[5] + 1
    fixed = ok & has6 & (length >= 1) & (end - ds == 3 * length - 1)
    empty = ok & ~has6 & (length == 0)
    other = np.flatnonzero(ok & ~fixed & ~empty)
    # every candidate line's bytes at its place in ``vals`` (line order)
    cand = fixed | (ok & ~fixed & ~empty)
    cand_len = np.where(cand, length, 0)
    at_line = np.zeros(n, dtype=np.int64)
    if n > 1:
        np.cumsum(cand_len[:-1], out=at_line[1:])
    vals = np.zeros(int(cand_len.sum()), dtype=np.uint8)
    row_bad = np.zeros(n, dtype=bool)
    lo_w = 0
    for hi_w in _WIDTHS:  # lines of up to hi_w bytes as one (rows, 3 hi_w) block
        rows = np.flatnonzero(fixed & (length > lo_w) & (length <= hi_w))
        lo_w = hi_w
        if len(rows) == 0:
            continue
        ln = length[rows]
        k = np.arange(hi_w, dtype=np.int64)
        blk = block(buf, ds[rows], 3 * hi_w)
        inside = k < ln[:, None]
        hi = HEX_VALUE[blk[:, 0::3]]
        lo = HEX_VALUE[blk[:, 1::3]]
        sep_ok = (blk[:, 2::3] == 44) | (k >= ln[:, None] - 1)
        row_bad[rows] = ~(((hi >= 0) & (lo >= 0) & sep_ok) | ~inside).all(axis=1)
        got = (hi * 16 + lo).astype(np.uint8)[inside]
        if len(rows) == n:
            vals = got
        else:
            vals[np.repeat(at_line[rows], ln) + ramp(ln)] = got
    if len(other):
        got, good, count_ok = _bytes_by_commas(buf, commas, c0[other], end[other], length[other])
        reason[other[~count_ok]] = 3
        ln = length[other]
        vals[np.repeat(at_line[other], ln) + ramp(ln)] = got
        owner = np.repeat(np.arange(len(other)), ln)
        row_bad[other[np.bincount(owner[~good], minlength=len(other)) > 0]] = True
    reason[row_bad & (reason == 0)] = 4
    ok &= ~row_bad
    # times: UTC where the file writes dates, else relative seconds
    t, tok = parse_datetime(buf, start, cs[0])
    kind = TIME_UTC
    if not (tok & ok).any() and ok.any():
        t, tok = parse_seconds(buf, start, cs[0])
        kind = TIME_RELATIVE
    reason[ok & ~tok] = 5
    ok &= tok
    payload = vals[np.repeat(ok[cand], length[cand])]
    msgs = rows_to_messages(
        t[ok],
        lines.number[ok],
        prio[ok],
        pgn[ok],
        src[ok],
        dst[ok],
        length[ok],
        payload,
        kind,
        reassemble_fast=reassemble,
    )
    _count_rejects(msgs, lines, reason)
    return msgs


def _bytes_by_commas(
    buf: np.ndarray,
    commas: np.ndarray,
    c0: np.ndarray,
    end: np.ndarray,
    length: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(bytes, byte ok, count ok) of lines whose bytes are found by their commas: one or
    two hex digits each, exactly ``length`` of them (count ok per line)."""
    nc = np.searchsorted(commas, end) - c0
    count_ok = nc == 5 + length
    j = ramp(length)
    cidx = np.repeat(c0 + 5, length) + j
    bs = commas.take(cidx, mode="clip").astype(np.int64) + 1
    last = j == np.repeat(length - 1, length)
    be = np.where(last, np.repeat(end, length), commas.take(cidx + 1, mode="clip"))
    w = be - bs
    hi = HEX_VALUE[buf.take(bs, mode="clip")]
    lo = HEX_VALUE[buf.take(bs + 1, mode="clip")]
    val = np.where(w == 2, hi * 16 + lo, hi)
    good = ((w == 2) & (hi >= 0) & (lo >= 0)) | ((w == 1) & (hi >= 0))
    good &= np.repeat(count_ok, length)
    return val.astype(np.uint8), good, count_ok


_REASONS = ("", "plain_fields", "plain_number", "plain_length", "plain_hex", "bad_time")


def _count_rejects(msgs: Messages, lines: Lines, reason: np.ndarray) -> None:
    for code in np.unique(reason[reason > 0]).tolist():
        where = np.flatnonzero(reason == code)
        ex = [(int(lines.number[i]), lines.text(int(i))) for i in where[:5]]
        add_reject(msgs, _REASONS[code], len(where), ex)
