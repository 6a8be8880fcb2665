"""Actisense binary logs: EBL files (NGT-1 / W2K-1 recordings, read as canboat's
actisense-serial reads a ``.ebl`` file) and the bare NGT-1 byte stream (what an NGT-1,
or a Yacht Devices YDNU-02 in its NGT-1 mode, sends over USB: a ``.dle`` capture).

Both are byte streams of BST messages ``DLE STX <command> <len> <data...> <checksum>
DLE ETX``: inside a frame a literal DLE is doubled, and the bytes from the command to
the checksum sum to 0 mod 256.  Command 0x93 is a received NMEA 2000 message: priority,
PGN (3 bytes little-endian), destination, source, the gateway's 4-byte millisecond
timer, data length, data. 0x94 is a message sent by the logger (priority, PGN,
destination, length, data; source 0). 0xA0 is the gateway's own status; canboat reports
it as PGN 0x40000 + its first byte (Actisense's pseudo-PGNs), and so do we.

An EBL file adds the logger's own records ``ESC SOH <command> <data> ESC LF`` (command
0x03: an 8-byte little-endian Windows FILETIME, 100 ns since 1601-01-01 UTC, the PC's
time of the messages that follow; 0x01 a version), and ESC is a second escape byte
inside both kinds of record (``ESC ESC`` a literal ESC).  In the bare stream ESC is an
ordinary byte: reading it as an escape there (as dracc once did) broke every frame whose
data held a 0x1B, and the frames after it, 11 % of a real YDNU-02 capture.

Times.  A received message's time is its gateway timer (ms; unwrapped where the 32-bit
counter wraps; a restart of the gateway, a drop of more than a minute, begins a new run).
In an EBL file the timer is put on UTC by the FILETIME records: the PC stamps a record
after the gateway received it, so ``FILETIME - timer`` is the offset plus a latency of
milliseconds to a second, and the offset is the least of it (the lower envelope, over
windows of ten minutes, interpolated between them, per run).  Without FILETIME records
the times are relative (runs follow one another).  Messages without a timer (0x94, 0xA0)
take the FILETIME where there is one, else the timer time of the message before them.
A file with neither timers nor FILETIMEs has no clock (``TIME_NONE``).

Damage.  A frame cut short (by the next frame's start, a stray escape, the end of the
file), a run of bytes outside any frame, a wrong checksum or a malformed message is one
reject each, its example naming its byte offset; the next frame is still found.  A
message's ``line`` is its record number (1-based, EBL headers and damaged frames
counted).
"""

from __future__ import annotations

import re
from collections.abc import Iterator

import numpy as np

from dracc.ingest.n2k.fastpacket import rows_to_messages
from dracc.ingest.n2k.messages import (
    TIME_NONE,
    TIME_RELATIVE,
    TIME_UTC,
    Messages,
    add_reject,
    fill_forward,
)

DLE, STX, ETX, ESC, SOH, LF = 0x10, 0x02, 0x03, 0x1B, 0x01, 0x0A
N2K_RECEIVED, N2K_SENT, NGT_MESSAGE = 0x93, 0x94, 0xA0
EBL_TIMESTAMP, EBL_VERSION = 0x03, 0x01
#: Actisense's pseudo-PGNs for the NGT's own messages
ACTISENSE_BEM = 0x40000
#: 100 ns ticks from 1601-01-01 to 1970-01-01
FILETIME_UNIX_OFFSET = 116_444_736_000_000_000
#: FILETIME of 2200-01-01, past any real log
FILETIME_2200 = FILETIME_UNIX_OFFSET + 7_258_118_400 * 10_000_000
MAX_N2K_LENGTH = 223
#: a drop of the gateway timer by more than this (ms) that is no 32-bit wrap: a restart
TIMER_RESTART_MS = 60_000
#: the window (ms of gateway time) of each lower-envelope offset to the FILETIMEs
ENVELOPE_WINDOW_MS = 600_000
_WRAP = 1 << 32
_ESCAPES_EBL = re.compile(rb"[\x10\x1b]")
_ESCAPES_NGT = re.compile(rb"\x10")


def parse_ebl(data: bytes) -> Messages:
    """Messages of an Actisense EBL file (reject reasons ``ebl_*`` and ``checksum``)."""
    return _parse(data, ebl=True)


def parse_ngt1(data: bytes) -> Messages:
    """Messages of a bare NGT-1 byte stream (reject reasons ``ngt1_*`` and ``checksum``)."""
    return _parse(data, ebl=False)


def _parse(data: bytes, ebl: bool) -> Messages:
    tag = "ebl" if ebl else "ngt1"
    cols: list[list[int]] = [[] for _ in range(7)]  # record prio pgn src dst timer pc_ms
    bodies: list[bytes] = []
    bad: dict[str, list[tuple[int, str]]] = {}
    pc_ms = -1
    for record, (kind, offset, body) in enumerate(frames(data, ebl), start=1):
        if kind == "header":
            why, stamp = _header(body)
            pc_ms = stamp if stamp >= 0 else pc_ms
        elif kind == "bad":
            why = f"{tag}_framing"
        else:
            why, got = _message(body, tag)
            if got is not None:
                prio, pgn, src, dst, payload = got
                timer = int.from_bytes(body[8:12], "little") if body[0] == N2K_RECEIVED else -1
                for col, v in zip(cols, (record, prio, pgn, src, dst, timer, pc_ms), strict=True):
                    col.append(v)
                bodies.append(payload)
        if why:
            bad.setdefault(why, []).append((record, f"byte {offset}: {body[:32].hex(' ')}"))
    line, prio_a, pgn_a, src_a, dst_a, timer_a, pc_a = (np.array(c, dtype=np.int64) for c in cols)
    t, kind_of_time = message_times(timer_a, pc_a)
    msgs = rows_to_messages(
        t,
        line,
        prio_a,
        pgn_a,
        src_a,
        dst_a,
        np.array([len(b) for b in bodies], dtype=np.int64),
        np.frombuffer(b"".join(bodies), dtype=np.uint8),
        kind_of_time,
        reassemble_fast=False,
    )
    for reason, ex in bad.items():
        add_reject(msgs, reason, len(ex), ex)
    timed = timer_a >= 0
    runs = int(unwrap_timer(timer_a[timed])[1].max(initial=0)) if timed.any() else 0
    if runs:
        msgs.notes.append(
            f"the gateway's millisecond timer restarted {runs} times (the gateway restarted): "
            "each run of its times follows the one before, the gap between them unknown"
            + (" (put on UTC by the FILETIMEs of each run)" if kind_of_time == TIME_UTC else "")
        )
    return msgs


def _header(body: bytes) -> tuple[str, int]:
    """(reject reason or "", Unix ms of a FILETIME record or -1) of an EBL header."""
    if body and body[0] == EBL_TIMESTAMP:
        ft = int.from_bytes(body[1:9], "little")
        if len(body) != 9 or not FILETIME_UNIX_OFFSET <= ft < FILETIME_2200:
            return "ebl_timestamp", -1
        return "", (ft - FILETIME_UNIX_OFFSET) // 10_000  # whole ms, as canboat
    if not body or body[0] != EBL_VERSION:
        return "ebl_unknown_record", -1
    return "", -1


def _message(body: bytes, tag: str) -> tuple[str, tuple[int, int, int, int, bytes] | None]:
    """(reject reason or "", its message or None) of an unescaped BST frame; other BST
    traffic (commands, replies) carries no bus message: ``ignored_bst_command``."""
    if len(body) < 3 or sum(body) & 0xFF:
        return "checksum", None
    command, n = body[0], body[1]
    if command not in (N2K_RECEIVED, N2K_SENT, NGT_MESSAGE):
        return "ignored_bst_command", None  # valid, but no bus message: counted as ignored
    got = _bst(command, body[2 : 2 + n])
    return ("", got) if got is not None else (f"{tag}_message", None)


def _bst(command: int, msg: bytes) -> tuple[int, int, int, int, bytes] | None:
    """(prio, pgn, src, dst, data) of one BST message of a message command; None if it
    is too short, too long or shorter than its data length says."""
    if command == N2K_RECEIVED:
        if len(msg) < 11:
            return None
        n = msg[10]
        if n > MAX_N2K_LENGTH or len(msg) < 11 + n:
            return None
        pgn = msg[1] | msg[2] << 8 | msg[3] << 16
        return msg[0] & 7, pgn, msg[5], msg[4], msg[11 : 11 + n]
    if command == N2K_SENT:
        if len(msg) < 6:
            return None
        n = msg[5]
        if n > MAX_N2K_LENGTH or len(msg) < 6 + n:
            return None
        pgn = msg[1] | msg[2] << 8 | msg[3] << 16
        return msg[0] & 7, pgn, 0, msg[4], msg[6 : 6 + n]
    if len(msg) < 12:  # NGT_MESSAGE
        return None
    return 0, ACTISENSE_BEM + msg[0], 0, 0, msg[1:]


def frames(data: bytes, ebl: bool) -> Iterator[tuple[str, int, bytes]]:
    """(kind, byte offset, unescaped bytes) of every record of an Actisense byte stream:
    "message" (DLE STX ... DLE ETX), "header" (EBL only: ESC SOH ... ESC LF) or "bad"
    (a frame cut short, or a run of bytes outside any frame), as canboat's actisense-serial
    frames them.  ``ebl``: ESC is an escape byte and ESC SOH / ESC LF frame headers."""
    escapes = _ESCAPES_EBL if ebl else _ESCAPES_NGT
    n = len(data)
    state = "idle"  # idle | message | header | junk (bytes of a damaged region)
    start = 0
    out = bytearray()
    pos = 0
    while pos < n:
        m = escapes.search(data, pos)
        i = m.start() if m else n
        if state in ("message", "header"):
            out += data[pos:i]
        elif state == "idle" and i > pos:
            state, start = "junk", pos
        if m is None:
            break
        e = data[i]
        if state == "header" and e == DLE:  # only ESC escapes inside a header
            out.append(e)
            pos = i + 1
            continue
        if i + 1 >= n:
            pos = n
            break
        c = data[i + 1]
        pos = i + 2
        if c == STX or (ebl and c == SOH):
            if state in ("message", "header", "junk"):
                yield "bad", start, bytes(out if state != "junk" else data[start:i])
            state, start, out = ("message" if c == STX else "header"), i, bytearray()
        elif c == DLE or (ebl and c == ESC):
            if state in ("message", "header"):
                out.append(c)
            elif state == "idle":
                state, start = "junk", i
        elif state == "message" and c == ETX:
            yield "message", start, bytes(out)
            state = "idle"
        elif state == "header" and ebl and c == LF:
            yield "header", start, bytes(out)
            state = "idle"
        elif state in ("message", "header"):  # a stray escape: the frame is damaged
            state = "junk"
        elif state == "idle":
            state, start = "junk", i
    if state in ("message", "header"):
        yield "bad", start, bytes(out)
    elif state == "junk":
        yield "bad", start, data[start : min(n, start + 32)]


def message_times(timer_ms: np.ndarray, pc_ms: np.ndarray) -> tuple[np.ndarray, str]:
    """ns of every message from its gateway timer (ms, -1 where none) and the last
    FILETIME before it (Unix ms, -1 where none), and the kind of those times (see the
    module docstring)."""
    n = len(timer_ms)
    has_timer = timer_ms >= 0
    has_pc = pc_ms >= 0
    if n == 0:
        return np.zeros(0, dtype=np.int64), TIME_UTC
    if not has_timer.any():
        if not has_pc.any():
            return np.zeros(n, dtype=np.int64), TIME_NONE
        return fill_forward(np.where(has_pc, pc_ms, -1)) * 1_000_000, TIME_UTC
    rows = np.flatnonzero(has_timer)
    dev, run = unwrap_timer(timer_ms[rows])
    out = np.full(n, -1, dtype=np.int64)
    pc = pc_ms[rows]
    if (pc >= 0).any():
        out[rows] = dev + _envelope_offset(dev, run, pc)
        out[~has_timer & has_pc] = pc_ms[~has_timer & has_pc]
        kind = TIME_UTC
    else:
        out[rows] = dev
        kind = TIME_RELATIVE
    return fill_forward(out) * 1_000_000, kind


def unwrap_timer(timer_ms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gateway timer readings (ms) unwrapped at the 32-bit wrap, and the run number of
    each (a restart begins a new run); a run starts where the one before it ended."""
    t = np.asarray(timer_ms, dtype=np.int64)
    d = np.diff(t, prepend=t[:1])
    wrap = d < -(_WRAP >> 1)
    restart = ~wrap & (d < -TIMER_RESTART_MS)
    run = np.cumsum(restart)
    t = t + np.cumsum(wrap) * _WRAP
    if restart.any():  # each run continues from the end of the one before
        at = np.flatnonzero(restart)
        jump = np.zeros(len(t), dtype=np.int64)
        jump[at] = t[at - 1] - t[at]
        t = t + np.cumsum(jump)
    return t, run


def _envelope_offset(dev: np.ndarray, run: np.ndarray, pc: np.ndarray) -> np.ndarray:
    """Offset (ms) from gateway time ``dev`` to UTC at every row: per run, the least
    ``pc - dev`` of each window of :data:`ENVELOPE_WINDOW_MS`, interpolated between the
    windows' middles (where a run has no FILETIME of its own: the least over the file)."""
    off = np.zeros(len(dev), dtype=np.int64)
    ok = pc >= 0
    fallback = int(np.min((pc - dev)[ok]))
    for r in np.unique(run).tolist():
        sel = run == r
        d, p = dev[sel], pc[sel]
        good = p >= 0
        if not good.any():
            off[sel] = fallback
            continue
        win = (d[good] - d[good].min()) // ENVELOPE_WINDOW_MS
        lo = np.full(int(win.max()) + 1, np.iinfo(np.int64).max, dtype=np.int64)
        np.minimum.at(lo, win, (p - d)[good])
        mid = np.full(len(lo), -1.0)
        for w in np.unique(win).tolist():
            mid[w] = float(np.median(d[good][win == w]))
        have = lo != np.iinfo(np.int64).max
        off[sel] = np.round(np.interp(d, mid[have], lo[have].astype(float))).astype(np.int64)
    return off


def bst_messages(raw: list[bytes], time_ns: np.ndarray, line: np.ndarray) -> Messages:
    """Messages of single Actisense BST messages, each ``<command> <len> <data...>
    [<checksum>]`` with its own time: how OpenCPN's data logger (VDR CSV, protocol
    NMEA2000) writes an NMEA 2000 message in ``raw_data`` (``93 13 02 01 F8 01 ...``).
    One that is not such a message is rejected as ``bst_message``."""
    keep: list[int] = []
    rows: list[tuple[int, int, int, int, bytes]] = []
    bad: list[tuple[int, str]] = []
    for i, msg in enumerate(raw):
        got = None
        if len(msg) >= 2 and msg[0] in (N2K_RECEIVED, N2K_SENT, NGT_MESSAGE):
            got = _bst(msg[0], msg[2 : 2 + msg[1]])
        if got is None:
            bad.append((int(line[i]), msg[:40].hex(" ")))
            continue
        keep.append(i)
        rows.append(got)
    idx = np.asarray(keep, dtype=np.int64)
    data = [r[4] for r in rows]
    msgs = rows_to_messages(
        np.asarray(time_ns, dtype=np.int64)[idx],
        np.asarray(line, dtype=np.int64)[idx],
        np.array([r[0] for r in rows], dtype=np.uint8),
        np.array([r[1] for r in rows], dtype=np.int64),
        np.array([r[2] for r in rows], dtype=np.uint8),
        np.array([r[3] for r in rows], dtype=np.uint8),
        np.array([len(d) for d in data], dtype=np.int64),
        np.frombuffer(b"".join(data), dtype=np.uint8),
        TIME_UTC,
        reassemble_fast=False,
    )
    if bad:
        add_reject(msgs, "bst_message", len(bad), bad[:5])
    return msgs
