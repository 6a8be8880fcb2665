"""NMEA 2000 carried in NMEA 0183-like sentences, one line each (read line by line).

- Digital Yacht iKonvert ``!PDGY,pgn,prio,src,dst,seconds,base64`` -- a whole message,
  time in seconds since the gateway started; ``$PDGY,000000,...`` / ``!PDGY,000000,...``
  lines are the gateway's own status, not messages: counted as ``ignored_pdgy_status``
  (the reader files them as ignored, ``pdgy status``).
- SeaSmart / Chetco ``$PCDIN,pgn,time,src,hex*cs`` -- a whole message; the time is
  read as canboat's analyzer reads it, hexadecimal milliseconds (of an unknown start).
- Shipmodul MiniPlex ``$MXPGN,pgn,attr,hex*cs`` -- one CAN frame: the attribute word
  holds the send flag (bit 15), priority (14-12), data length (11-8) and address (7-0,
  the destination of sent frames, else the source); the data is written last byte
  first. Frames of fast-packet PGNs are reassembled. No time: times are 0 and the log
  has no clock (``TIME_NONE``).

Checksums (``*hh``, XOR of the characters between ``$`` and ``*``) are checked where
present; a wrong one rejects the line as ``checksum``.
"""

from __future__ import annotations

import base64
import binascii

import numpy as np

from dracc.ingest.n2k.fastpacket import rows_to_messages
from dracc.ingest.n2k.messages import TIME_NONE, TIME_RELATIVE, Messages, add_reject
from dracc.ingest.n2k.textscan import Lines

#: gateway times from this many seconds on are not believed
MAX_SECONDS = 10_000_000_000


class _Collect:
    """Messages and rejects gathered line by line."""

    def __init__(self, lines: Lines) -> None:
        self.lines = lines
        self.cols: list[list[int]] = [[] for _ in range(6)]  # time line prio pgn src dst
        self.data: list[bytes] = []
        self.bad: dict[str, list[int]] = {}

    def add(self, i: int, t: int, prio: int, pgn: int, src: int, dst: int, data: bytes) -> None:
        for col, v in zip(
            self.cols, (t, int(self.lines.number[i]), prio, pgn, src, dst), strict=True
        ):
            col.append(v)
        self.data.append(data)

    def reject(self, i: int, reason: str) -> None:
        self.bad.setdefault(reason, []).append(i)

    def messages(self, reassemble: bool, time_kind: str = TIME_RELATIVE) -> Messages:
        t, line, prio, pgn, src, dst = (np.array(c, dtype=np.int64) for c in self.cols)
        msgs = rows_to_messages(
            t,
            line,
            prio,
            pgn,
            src,
            dst,
            np.array([len(d) for d in self.data], dtype=np.int64),
            np.frombuffer(b"".join(self.data), dtype=np.uint8),
            time_kind,
            reassemble_fast=reassemble,
        )
        for reason, rows in self.bad.items():
            ex = [(int(self.lines.number[i]), self.lines.text(i)) for i in rows[:5]]
            add_reject(msgs, reason, len(rows), ex)
        return msgs


def _checked(text: str, tag: str) -> tuple[list[str] | None, str]:
    """The comma fields of the sentence ``tag`` in ``text`` (checksum removed), or None
    and why not."""
    at = text.find(tag)
    if at < 0:
        return None, "not_" + tag[1:].lower()
    body = text[at + 1 :].rstrip()
    star = body.rfind("*")
    if star >= 0:
        want = body[star + 1 : star + 3]
        got = 0
        for ch in body[:star].encode("latin-1"):
            got ^= ch
        try:
            if int(want, 16) != got or len(want) != 2:
                return None, "checksum"
        except ValueError:
            return None, "checksum"
        body = body[:star]
    return body.split(","), ""


def parse_pdgy(lines: Lines) -> Messages:
    """Messages of an iKonvert ``!PDGY`` log."""
    out = _Collect(lines)
    for i in range(len(lines.start)):
        text = lines.text(i).strip()
        parts = text.split(",")
        if len(parts) >= 2 and parts[0] in ("!PDGY", "$PDGY") and parts[1] == "000000":
            out.reject(i, "ignored_pdgy_status")
            continue
        if len(parts) != 7 or parts[0] != "!PDGY":
            out.reject(i, "pdgy_line")
            continue
        try:
            pgn, prio, src, dst = (int(p) for p in parts[1:5])
            secs = float(parts[5])
            if not 0 <= secs < MAX_SECONDS:
                raise ValueError(secs)
            t = round(secs * 1e9)
            data = base64.b64decode(parts[6].encode("ascii"), validate=True)
        except (ValueError, binascii.Error, UnicodeEncodeError):
            out.reject(i, "pdgy_field")
            continue
        if not (0 <= prio <= 7 and 0 <= src <= 255 and 0 <= dst <= 255 and 0 <= pgn < 1 << 19):
            out.reject(i, "pdgy_field")
            continue
        out.add(i, t, prio, pgn, src, dst, data)
    return out.messages(reassemble=False)


def parse_pcdin(lines: Lines) -> Messages:
    """Messages of ``$PCDIN`` sentences (lines without one count as ``not_pcdin``)."""
    out = _Collect(lines)
    for i in range(len(lines.start)):
        parts, why = _checked(lines.text(i), "$PCDIN")
        if parts is None:
            out.reject(i, why)
            continue
        try:
            if len(parts) != 5 or len(parts[1]) != 6 or len(parts[2]) > 8 or len(parts[4]) % 2:
                raise ValueError(parts)
            pgn, tms, src = int(parts[1], 16), int(parts[2], 16), int(parts[3], 16)
            data = bytes.fromhex(parts[4])
        except ValueError:
            out.reject(i, "pcdin_field")
            continue
        if src > 255:
            out.reject(i, "pcdin_field")
            continue
        out.add(i, tms * 1_000_000, 0, pgn, src, 255, data)
    return out.messages(reassemble=False)


def parse_mxpgn(lines: Lines) -> Messages:
    """Messages of ``$MXPGN`` sentences (frames of fast PGNs reassembled)."""
    out = _Collect(lines)
    for i in range(len(lines.start)):
        parts, why = _checked(lines.text(i), "$MXPGN")
        if parts is None:
            out.reject(i, why)
            continue
        try:
            if len(parts) != 4 or len(parts[1]) > 6 or len(parts[2]) != 4 or len(parts[3]) % 2:
                raise ValueError(parts)
            pgn, attr = int(parts[1], 16), int(parts[2], 16)
            data = bytes.fromhex(parts[3])[::-1]
        except ValueError:
            out.reject(i, "mxpgn_field")
            continue
        send, prio, dlc, addr = attr >> 15, (attr >> 12) & 7, (attr >> 8) & 15, attr & 0xFF
        if dlc != len(data) or dlc > 8:
            out.reject(i, "mxpgn_field")
            continue
        src, dst = (0, addr) if send else (addr, 255)
        out.add(i, 0, prio, pgn, src, dst, data)
    return out.messages(reassemble=True, time_kind=TIME_NONE)
