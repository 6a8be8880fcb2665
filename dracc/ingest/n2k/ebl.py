"""Actisense EBL binary logs (NGT-1 / W2K-1 recordings), read as canboat's
actisense-serial reads a ``.ebl`` file.

The file is a byte stream of two kinds of records:

- ``ESC SOH <command> <data> ESC LF`` -- the logger's own records: command 0x03 is an
  8-byte little-endian Windows FILETIME (100 ns since 1601-01-01 UTC), the time of the
  messages that follow; 0x01 a version.
- ``DLE STX <command> <len> <data...> <checksum> DLE ETX`` -- Actisense BST messages
  (inside them DLE and ESC are doubled); the bytes sum to 0 mod 256 with the checksum.
  Command 0x93 is a received NMEA 2000 message: priority, PGN (3 bytes little-endian),
  destination, source, the NGT's 4-byte millisecond timer, data length, data. 0x94 is a
  message sent by the logger (priority, PGN, destination, length, data; source 0).
  0xA0 is the NGT's own status; canboat reports it as PGN 0x40000 + its first byte
  (Actisense's pseudo-PGNs), and so do we.

A message's time is the last FILETIME record before it (UTC), as canboat gives it;
messages before the first are at time 0 and the file's times then are relative.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from dracc.ingest.n2k.fastpacket import rows_to_messages
from dracc.ingest.n2k.messages import TIME_RELATIVE, TIME_UTC, Messages, add_reject

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


def parse_ebl(data: bytes) -> Messages:
    """Messages of an Actisense EBL file; ``line`` is the 1-based record number."""
    cols: list[list[int]] = [[] for _ in range(6)]  # time record prio pgn src dst
    bodies: list[bytes] = []
    bad: dict[str, list[tuple[int, str]]] = {}
    stamp = -1
    record = 0
    for kind, body in _records(data):
        record += 1
        if kind == "header":
            if body and body[0] == EBL_TIMESTAMP:
                if len(body) != 9:
                    bad.setdefault("ebl_timestamp", []).append((record, body.hex(" ")))
                    continue
                ft = int.from_bytes(body[1:9], "little")
                if not FILETIME_UNIX_OFFSET <= ft < FILETIME_2200:
                    bad.setdefault("ebl_timestamp", []).append((record, body.hex(" ")))
                    continue
                stamp = (ft - FILETIME_UNIX_OFFSET) // 10_000 * 1_000_000  # whole ms, as canboat
            elif not body or body[0] != EBL_VERSION:
                bad.setdefault("ebl_unknown_record", []).append((record, body.hex(" ")))
            continue
        if kind == "bad":
            bad.setdefault("ebl_framing", []).append((record, body[:40].hex(" ")))
            continue
        if len(body) < 3 or sum(body) & 0xFF:
            bad.setdefault("checksum", []).append((record, body[:40].hex(" ")))
            continue
        command, n = body[0], body[1]
        msg = body[2 : 2 + n]
        if command not in (N2K_RECEIVED, N2K_SENT, NGT_MESSAGE):
            continue  # other BST traffic (commands, replies) carries no bus message
        got = _bst(command, msg)
        if got is None:
            bad.setdefault("ebl_message", []).append((record, body[:40].hex(" ")))
            continue
        prio, pgn, src, dst, payload = got
        for col, v in zip(cols, (max(stamp, 0), record, prio, pgn, src, dst), strict=True):
            col.append(v)
        bodies.append(payload)
    t, line, prio_a, pgn_a, src_a, dst_a = (np.array(c, dtype=np.int64) for c in cols)
    msgs = rows_to_messages(
        t,
        line,
        prio_a,
        pgn_a,
        src_a,
        dst_a,
        np.array([len(b) for b in bodies], dtype=np.int64),
        np.frombuffer(b"".join(bodies), dtype=np.uint8),
        TIME_UTC if stamp >= 0 else TIME_RELATIVE,
        reassemble_fast=False,
    )
    for reason, ex in bad.items():
        add_reject(msgs, reason, len(ex), ex)
    return msgs


def _bst(command: int, msg: bytes) -> tuple[int, int, int, int, bytes] | None:
    """(prio, pgn, src, dst, data) of one BST message of a message command; None if it
    is too short or too long."""
    if command == N2K_RECEIVED:
        if len(msg) < 11:
            return None
        n = msg[10]
        if n > MAX_N2K_LENGTH:
            return None
        pgn = msg[1] | msg[2] << 8 | msg[3] << 16
        return msg[0] & 7, pgn, msg[5], msg[4], msg[11 : 11 + n]
    if command == N2K_SENT:
        if len(msg) < 6:
            return None
        n = msg[5]
        if n > MAX_N2K_LENGTH:
            return None
        pgn = msg[1] | msg[2] << 8 | msg[3] << 16
        return msg[0] & 7, pgn, 0, msg[4], msg[6 : 6 + n]
    if len(msg) < 12:  # NGT_MESSAGE
        return None
    return 0, ACTISENSE_BEM + msg[0], 0, 0, msg[1:]


def _records(data: bytes) -> Iterator[tuple[str, bytes]]:
    """(kind, bytes) of every record: "header" (ESC SOH ... ESC LF, unescaped), "message"
    (DLE STX ... DLE ETX, unescaped) or "bad" (a broken escape)."""
    i, n = 0, len(data)
    while i < n:
        c = data[i]
        if c == ESC and i + 1 < n and data[i + 1] == SOH:
            end_tag, kind = LF, "header"
        elif c == DLE and i + 1 < n and data[i + 1] == STX:
            end_tag, kind = ETX, "message"
        else:
            i += 1
            continue
        i += 2
        out = bytearray()
        escapes = (ESC,) if kind == "header" else (DLE, ESC)
        while i < n:
            c = data[i]
            i += 1
            if c not in escapes:
                out.append(c)
                continue
            if i >= n:
                break
            d = data[i]
            i += 1
            if d == end_tag:
                break
            if d in escapes:
                out.append(d)
                continue
            kind = "bad"  # a new record begins (SOH, STX) or a stray escape
            i -= 2 if d in (SOH, STX) else 0
            break
        else:
            kind = "bad"
        yield kind, bytes(out)


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
