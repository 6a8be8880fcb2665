"""NMEA 2000 messages as columns: what every N2K log format gives, before decoding.

A log of any form (canboat plain/fast, candump, Yacht Devices raw, iKonvert ``!PDGY``,
Actisense EBL, ``$PCDIN``/``$MXPGN``, Signal K ``A`` lines) becomes one
:class:`Messages`: a row per NMEA 2000 message, fast packets already reassembled, its
payload bytes in one flat ``uint8`` array (``payload[start[i] : start[i] + length[i]]``).
Decoders gather fixed byte offsets from it for all messages of a PGN at once.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: what ``Messages.time_ns`` counts from
TIME_UTC = "utc"  #: ns since the Unix epoch (dated times, candump -l, EBL)
TIME_OF_DAY = "time_of_day"  #: ns since midnight of an unknown day (YDWG raw)
#: ns since an unknown start (iKonvert, PCDIN, candump and EBL without absolute times)
TIME_RELATIVE = "relative"
#: no clock at all (a candump without times, ``$MXPGN``): the times are 0, the order of
#: the messages is all there is
TIME_NONE = "none"


@dataclass
class Messages:
    """NMEA 2000 messages in file order, one row each (fast packets reassembled)."""

    time_ns: np.ndarray  #: int64, see ``time_kind``
    #: int64, 1-based line (EBL: record) of the message's first frame; time, priority and
    #: destination of a reassembled message are its last frame's (canboat does the same)
    line: np.ndarray
    prio: np.ndarray  #: uint8, 0..7
    pgn: np.ndarray  #: int64
    src: np.ndarray  #: uint8, source address 0..253
    dst: np.ndarray  #: uint8, destination address (255 broadcast)
    start: np.ndarray  #: int64 offsets into ``payload``
    length: np.ndarray  #: int64 payload bytes of each message
    payload: np.ndarray  #: uint8, all payloads one after another
    time_kind: str = TIME_UTC
    #: reason -> count of frames or lines that did not become a message
    rejects: dict[str, int] = field(default_factory=dict)
    #: reason -> first few (line, text) examples of them
    examples: dict[str, list[tuple[int, str]]] = field(default_factory=dict)
    #: what the parser decided about the log (its clock, its time base), for the notes
    notes: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.pgn)

    def select(self, mask: np.ndarray) -> Messages:
        """The messages where ``mask`` is true, or rows ``mask`` if it is an index array
        (the payload array is shared)."""
        return Messages(
            time_ns=self.time_ns[mask],
            line=self.line[mask],
            prio=self.prio[mask],
            pgn=self.pgn[mask],
            src=self.src[mask],
            dst=self.dst[mask],
            start=self.start[mask],
            length=self.length[mask],
            payload=self.payload,
            time_kind=self.time_kind,
            rejects=dict(self.rejects),
            examples={k: list(v) for k, v in self.examples.items()},
            notes=list(self.notes),
        )

    def byte(self, offset: int) -> np.ndarray:
        """Byte ``offset`` of every payload as int64; -1 where a payload is shorter."""
        ok = self.length > offset
        out = np.full(len(self), -1, dtype=np.int64)
        out[ok] = self.payload[self.start[ok] + offset]
        return out


#: examples kept per reject reason
MAX_EXAMPLES = 5


def add_reject(
    msgs: Messages, reason: str, count: int, examples: list[tuple[int, str]] | None = None
) -> None:
    """Count ``count`` frames or lines of ``msgs``'s input as rejected for ``reason``."""
    if count <= 0:
        return
    msgs.rejects[reason] = msgs.rejects.get(reason, 0) + int(count)
    have = msgs.examples.setdefault(reason, [])
    for line, text in examples or []:
        if len(have) >= MAX_EXAMPLES:
            break
        have.append((int(line), text[:120]))


def make_messages(
    time_ns: np.ndarray,
    line: np.ndarray,
    prio: np.ndarray,
    pgn: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    length: np.ndarray,
    payload: np.ndarray,
    time_kind: str = TIME_UTC,
) -> Messages:
    """Messages from columns whose payloads lie one after another in ``payload``."""
    length = np.asarray(length, dtype=np.int64)
    start = np.zeros(len(length), dtype=np.int64)
    if len(length) > 1:
        np.cumsum(length[:-1], out=start[1:])
    return Messages(
        time_ns=np.asarray(time_ns, dtype=np.int64),
        line=np.asarray(line, dtype=np.int64),
        prio=np.asarray(prio, dtype=np.uint8),
        pgn=np.asarray(pgn, dtype=np.int64),
        src=np.asarray(src, dtype=np.uint8),
        dst=np.asarray(dst, dtype=np.uint8),
        start=start,
        length=length,
        payload=np.asarray(payload, dtype=np.uint8),
        time_kind=time_kind,
    )


def empty_messages(time_kind: str = TIME_UTC) -> Messages:
    """No messages."""
    i64 = np.zeros(0, dtype=np.int64)
    u8 = np.zeros(0, dtype=np.uint8)
    return Messages(i64, i64, u8, i64, u8, u8, i64, i64, u8, time_kind=time_kind)


def concat_messages(parts: list[Messages]) -> Messages:
    """Messages of several parts one after another (payload offsets shifted)."""
    if not parts:
        return empty_messages()
    shift = np.cumsum([0] + [len(p.payload) for p in parts[:-1]])
    rejects: dict[str, int] = {}
    examples: dict[str, list[tuple[int, str]]] = {}
    for p in parts:
        for k, v in p.rejects.items():
            rejects[k] = rejects.get(k, 0) + v
        for k, ex in p.examples.items():
            examples.setdefault(k, []).extend(ex[: max(0, MAX_EXAMPLES - len(examples.get(k, [])))])
    kinds = {p.time_kind for p in parts if len(p)}
    return Messages(
        time_ns=np.concatenate([p.time_ns for p in parts]),
        line=np.concatenate([p.line for p in parts]),
        prio=np.concatenate([p.prio for p in parts]),
        pgn=np.concatenate([p.pgn for p in parts]),
        src=np.concatenate([p.src for p in parts]),
        dst=np.concatenate([p.dst for p in parts]),
        start=np.concatenate([p.start + s for p, s in zip(parts, shift, strict=True)]),
        length=np.concatenate([p.length for p in parts]),
        payload=np.concatenate([p.payload for p in parts]),
        time_kind=kinds.pop() if len(kinds) == 1 else parts[0].time_kind,
        rejects=rejects,
        examples=examples,
        notes=[n for p in parts for n in p.notes],
    )


def fill_forward(t: np.ndarray) -> np.ndarray:
    """``t`` (int64) with every negative value replaced by the value before it (the first
    ones by the first value there is); all zeros where there is none."""
    t = np.asarray(t, dtype=np.int64)
    have = t >= 0
    if have.all() or not have.any():
        return np.where(have, t, 0)
    idx = np.where(have, np.arange(len(t)), 0)
    np.maximum.accumulate(idx, out=idx)
    first = int(np.flatnonzero(have)[0])
    idx[:first] = first
    return t[idx]
