"""Logs of raw 29-bit CAN frames: Linux candump (three forms) and Yacht Devices RAW.

``(1745600961.335462) can0 11FC1063#003DFFFF02000100`` (``candump -l``), ``can0
09F20101   [8]  60 1A ...`` (candump's screen form, maybe after a ``(time)``),
``<0x18eeff01> [8] 05 a0 ...`` (older candump) and ``00:29:58.617 R 0DFF180D A2 8C ...``
(YDWG-02 / YDEN-02 RAW: time of day; ``R`` received and ``T`` transmitted frames are
both kept, as canboat's analyzer keeps them: both were on the bus). The CAN id gives
priority, PGN (PDU1: PF < 240 carries the destination in PS; PDU2: PS is part of the
PGN and the message is broadcast) and source. ``candump -l`` and YDWG's fixed layouts
are read vectorised; other lines one at a time.  A candump whose lines carry no
``(time)`` (``candump can0``) has no clock: its messages are ``TIME_NONE``, timed by
their order (a line without a time among timed ones takes the time before it).
"""

from __future__ import annotations

import numpy as np

from dracc.ingest.n2k.fastpacket import rows_to_messages
from dracc.ingest.n2k.messages import (
    TIME_NONE,
    TIME_OF_DAY,
    TIME_RELATIVE,
    TIME_UTC,
    Messages,
    add_reject,
    fill_forward,
)
from dracc.ingest.n2k.textscan import (
    HEX_VALUE,
    Lines,
    first_at_or_after,
    parse_hex,
    parse_seconds,
    parse_time_of_day,
    ramp,
)

#: candump times from this many seconds on are Unix times (2001-09-09), below relative
UNIX_TIME_FROM_S = 1_000_000_000
#: times from this many seconds on (the year 2286) are not believed
MAX_TIME_S = 10_000_000_000


def split_can_id(can_id: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Priority, PGN, source and destination of 29-bit CAN ids (ISO 11783 / J1939)."""
    can_id = np.asarray(can_id, dtype=np.int64)
    prio = (can_id >> 26) & 7
    pf = (can_id >> 16) & 0xFF
    ps = (can_id >> 8) & 0xFF
    rdp = (can_id >> 24) & 3
    src = can_id & 0xFF
    pdu1 = pf < 240
    pgn = (rdp << 16) | (pf << 8) | np.where(pdu1, 0, ps)
    dst = np.where(pdu1, ps, 255)
    return prio, pgn, src, dst


class _Rows:
    """Frames collected row by row (the slow path), turned into arrays at the end."""

    def __init__(self) -> None:
        self.idx: list[int] = []
        self.time: list[int] = []
        self.can_id: list[int] = []
        self.data: list[bytes] = []

    def add(self, i: int, t: int, can_id: int, data: bytes) -> None:
        self.idx.append(i)
        self.time.append(t)
        self.can_id.append(can_id)
        self.data.append(data)


def _frames_to_messages(
    lines: Lines,
    idx: np.ndarray,
    time_ns: np.ndarray,
    can_id: np.ndarray,
    dlen: np.ndarray,
    payload: np.ndarray,
    time_kind: str,
) -> Messages:
    """Messages of frames given per line index ``idx`` (any order; payloads in that
    order one after another)."""
    order = np.argsort(idx, kind="stable")
    starts = np.concatenate(([0], np.cumsum(dlen)[:-1])).astype(np.int64) if len(dlen) else dlen
    ln = dlen[order]
    gather = np.repeat(starts[order], ln) + ramp(ln)
    prio, pgn, src, dst = split_can_id(can_id[order])
    return rows_to_messages(
        time_ns[order],
        lines.number[idx[order]],
        prio,
        pgn,
        src,
        dst,
        ln,
        payload[gather],
        time_kind,
    )


def _hex_pairs(
    buf: np.ndarray, first: np.ndarray, count: np.ndarray, step: int
) -> tuple[np.ndarray, np.ndarray]:
    """``count`` hex byte pairs from ``first``, ``step`` bytes apart, per row; the bytes
    one after another and whether each row's were all hex."""
    k = ramp(count)
    at = np.repeat(first, count) + step * k
    hi = HEX_VALUE[buf[at]]
    lo = HEX_VALUE[buf[at + 1]]
    good = (hi >= 0) & (lo >= 0)
    owner = np.repeat(np.arange(len(count)), count)
    row_ok = np.bincount(owner[~good], minlength=len(count)) == 0
    return (hi * 16 + lo).astype(np.uint8), row_ok


def parse_candump(lines: Lines) -> Messages:
    """Messages of a candump log (any of its three forms, even mixed)."""
    buf, start, end = lines.buf, lines.start, lines.end
    n = len(start)
    first = buf[np.minimum(start, max(len(buf) - 1, 0))] if n else np.zeros(0, np.uint8)
    close = first_at_or_after(np.flatnonzero(buf == ord(")")), start, end)
    hashes = first_at_or_after(np.flatnonzero(buf == ord("#")), start, end)
    fast = (first == ord("(")) & (close > 0) & (hashes > close + 9)
    fast &= buf[np.maximum(hashes - 9, 0)] == ord(" ")
    nbytes = end - hashes - 1
    fast &= (nbytes >= 0) & (nbytes <= 16) & (nbytes % 2 == 0)
    rows = np.flatnonzero(fast)
    t, tok = parse_seconds(buf, start[rows] + 1, close[rows])
    can_id, iok = parse_hex(buf, hashes[rows] - 8, hashes[rows], 8)
    count = nbytes[rows] // 2
    data, dok = _hex_pairs(buf, hashes[rows] + 1, count, 2)
    good = tok & iok & dok
    keep_byte = np.repeat(good, count)
    slow_rows = np.concatenate([np.flatnonzero(~fast), rows[~good]])
    slow = _Rows()
    bad: list[int] = []
    for i in np.sort(slow_rows).tolist():
        got = _candump_line(lines.text(i))
        if got is None:
            bad.append(i)
        else:
            slow.add(i, *got)
    idx = np.concatenate([rows[good], np.array(slow.idx, dtype=np.int64)])
    times = np.concatenate([t[good], np.array(slow.time, dtype=np.int64)])
    ids = np.concatenate([can_id[good], np.array(slow.can_id, dtype=np.int64)])
    dlen = np.concatenate([count[good], np.array([len(d) for d in slow.data], dtype=np.int64)])
    payload = np.concatenate([data[keep_byte], np.frombuffer(b"".join(slow.data), dtype=np.uint8)])
    kind = TIME_RELATIVE
    if len(times) and times.max() >= UNIX_TIME_FROM_S * 1_000_000_000:
        kind = TIME_UTC
    untimed = times < 0  # screen-form lines without a (time)
    if untimed.all():
        kind, times = TIME_NONE, np.zeros(len(times), dtype=np.int64)
    elif untimed.any():  # a line without a time takes the time of the line before it
        order = np.argsort(idx, kind="stable")
        times[order] = fill_forward(times[order])
    msgs = _frames_to_messages(lines, idx, times, ids, dlen, payload, kind)
    # candump's own banner (``interface = can0, family = 29, type = 3, proto = 1``) is a
    # valid line that holds no frame: ignored, not rejected
    banner = [i for i in bad if lines.text(i).lstrip().startswith("interface = ")]
    bad = [i for i in bad if i not in banner]
    add_reject(msgs, "candump_line", len(bad), [(int(lines.number[i]), lines.text(i)) for i in bad])
    ex = [(int(lines.number[i]), lines.text(i)) for i in banner[:1]]
    add_reject(msgs, "ignored_candump_banner", len(banner), ex)
    return msgs


def _candump_line(text: str) -> tuple[int, int, bytes] | None:
    """(time ns, -1 where the line has none; CAN id, data) of one candump line of any
    form; None if it is none."""
    tokens = text.replace("#", " # ").split()
    t = -1  # no time on the line
    if tokens and tokens[0].startswith("(") and tokens[0].endswith(")"):
        try:
            secs = float(tokens[0][1:-1])
        except ValueError:
            return None
        if not 0 <= secs < MAX_TIME_S:
            return None
        t = round(secs * 1e9)
        tokens = tokens[1:]
    try:
        if "#" in tokens:  # (time) iface ID#DATA
            k = tokens.index("#")
            if k < 1 or len(tokens[k - 1]) != 8 or k + 2 < len(tokens):
                return None
            data = bytes.fromhex(tokens[k + 1]) if k + 1 < len(tokens) else b""
            if len(data) > 8:
                return None
            return t, int(tokens[k - 1], 16) & 0x1FFFFFFF, data
        k = next(j for j, tok in enumerate(tokens) if tok.startswith("[") and tok.endswith("]"))
        ident = tokens[k - 1].strip("<>")
        if k < 1 or not 8 <= len(ident) <= 10:
            return None
        dlc = int(tokens[k][1:-1])
        body = tokens[k + 1 : k + 1 + dlc]
        if dlc > 8 or len(body) != dlc or any(len(b) != 2 for b in body):
            return None
        return t, int(ident, 16) & 0x1FFFFFFF, bytes.fromhex("".join(body))
    except (ValueError, StopIteration):
        return None


def parse_ydraw(lines: Lines) -> Messages:
    """Messages of a Yacht Devices RAW log (``hh:mm:ss.sss R|T CANID bytes``)."""
    buf, start, end = lines.buf, lines.start, lines.end
    last = max(len(buf) - 1, 0)

    def at(k: int) -> np.ndarray:
        return buf[np.minimum(start + k, last)]

    width = end - start
    count = (width - 23) // 3
    fast = (width >= 23) & ((width - 23) % 3 == 0) & (count <= 8)
    fast &= (at(12) == 32) & ((at(13) == ord("R")) | (at(13) == ord("T"))) & (at(14) == 32)
    rows = np.flatnonzero(fast)
    t, tok = parse_time_of_day(buf, start[rows], start[rows] + 12)
    can_id, iok = parse_hex(buf, start[rows] + 15, start[rows] + 23, 8)
    cnt = count[rows]
    data, dok = _hex_pairs(buf, start[rows] + 24, cnt, 3)
    sep_ok = _spaces_ok(buf, start[rows] + 23, cnt)
    good = tok & iok & dok & sep_ok
    keep_byte = np.repeat(good, cnt)
    slow = _Rows()
    bad: list[int] = []
    for i in np.sort(np.concatenate([np.flatnonzero(~fast), rows[~good]])).tolist():
        got = _ydraw_line(lines.text(i))
        if got is None:
            bad.append(i)
        else:
            slow.add(i, *got)
    idx = np.concatenate([rows[good], np.array(slow.idx, dtype=np.int64)])
    msgs = _frames_to_messages(
        lines,
        idx,
        np.concatenate([t[good], np.array(slow.time, dtype=np.int64)]),
        np.concatenate([can_id[good], np.array(slow.can_id, dtype=np.int64)]),
        np.concatenate([cnt[good], np.array([len(d) for d in slow.data], dtype=np.int64)]),
        np.concatenate([data[keep_byte], np.frombuffer(b"".join(slow.data), dtype=np.uint8)]),
        TIME_OF_DAY,
    )
    add_reject(msgs, "ydraw_line", len(bad), [(int(lines.number[i]), lines.text(i)) for i in bad])
    return msgs


def _spaces_ok(buf: np.ndarray, first: np.ndarray, count: np.ndarray) -> np.ndarray:
    at = np.repeat(first, count) + 3 * ramp(count)
    good = buf[at] == 32
    owner = np.repeat(np.arange(len(count)), count)
    return np.bincount(owner[~good], minlength=len(count)) == 0


def _ydraw_line(text: str) -> tuple[int, int, bytes] | None:
    tokens = text.split()
    if len(tokens) < 3 or tokens[1] not in ("R", "T") or len(tokens) > 11:
        return None
    hms = tokens[0].split(":")
    try:
        if len(hms) != 3 or len(tokens[2]) != 8 or any(len(b) > 2 for b in tokens[3:]):
            return None
        h, m, sec = int(hms[0]), int(hms[1]), float(hms[2])
        if not (0 <= h < 24 and 0 <= m < 60 and 0 <= sec < 61):
            return None
        t = round(((h * 60 + m) * 60 + sec) * 1e9)
        return t, int(tokens[2], 16) & 0x1FFFFFFF, bytes(int(b, 16) for b in tokens[3:])
    except ValueError:
        return None
