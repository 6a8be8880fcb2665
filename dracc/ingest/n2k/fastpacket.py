"""NMEA 2000 fast-packet reassembly, vectorised, and which PGNs are fast packets.

A fast-packet message longer than one CAN frame is sent as up to 32 frames of 8 bytes:
byte 0 of each holds a 3-bit sequence counter (high bits, the same in every frame of one
message) and a 5-bit frame index; frame 0 then gives the total length (byte 1) and 6
payload bytes, each later frame 7 more. Frames of one message come from one source with
one PGN, so messages are reassembled per (PGN, source, sequence counter).

The common case -- frames of a message consecutive within their (PGN, source) stream
and in order -- is found for all messages at once with numpy. What is left (frames
delivered out of order, as YDWG gateways do, or interleaved retransmissions) goes
through a small per-frame state machine that keeps, like canboat's analyzer, one slot
per (PGN, source, sequence counter) and completes a message when every frame its length
needs has arrived; frames of messages that never complete are counted as
``fast_packet_incomplete``.

Unlike canboat's analyzer, a frame held longer than :data:`STALE_NS` before the next
frame of its slot arrives is stale: the burst it belonged to lost frames, and the
3-bit counter has come round again.  canboat glues such leftovers to the next burst of
the same counter (4 wrong 130824 messages in ``susteranna2020.raw``, stale by 0.78 to
1.57 s); dracc counts them as incomplete.  A burst takes a few milliseconds on the bus.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dracc.ingest.n2k.messages import (
    TIME_UTC,
    Messages,
    add_reject,
    concat_messages,
    empty_messages,
    make_messages,
)
from dracc.ingest.n2k.textscan import ramp

#: the standard's fast-packet PGNs below the proprietary fast range (NMEA 2000 Appendix
#: B PGN list; checked against canboat's database in tests/test_n2k_formats.py)
FAST_PGNS = frozenset(
    {
        126208, 126464, 126983, 126984, 126985, 126986, 126987, 126988, 126996, 126998,
        127233, 127237, 127489, 127490, 127491, 127494, 127495, 127496, 127497, 127498,
        127503, 127504, 127506, 127507, 127509, 127510, 127511, 127512, 127513, 127514,
        128275, 128520, 128538, 129029, 129038, 129039, 129040, 129041, 129044, 129045,
        129284, 129285, 129301, 129302, 129538, 129540, 129541, 129542, 129545, 129547,
        129549, 129551, 129556, 129792, 129793, 129794, 129795, 129796, 129797, 129798,
        129799, 129800, 129801, 129802, 129803, 129804, 129805, 129806, 129807, 129808,
        129809, 129810, 129811, 129812, 129813, 129814, 129815, 129816, 130052, 130053,
        130054, 130060, 130061, 130064, 130065, 130066, 130067, 130068, 130069, 130070,
        130071, 130072, 130073, 130074, 130320, 130321, 130322, 130323, 130324, 130329,
        130330, 130561, 130562, 130563, 130564, 130565, 130566, 130567, 130568, 130569,
        130570, 130571, 130572, 130573, 130574, 130575, 130577, 130578, 130580, 130581,
        130583, 130584, 130586,
    }
)  # fmt: skip
#: proprietary fast-packet PGNs: the addressed one (0x1EF00) and the range 0x1FF00-0x1FFFF
PROPRIETARY_FAST = 126720
PROPRIETARY_FAST_RANGE = (130816, 131071)
#: the longest fast-packet payload: 6 bytes in frame 0 and 7 in each of 31 more
MAX_FAST_LENGTH = 223
#: frames of one message further apart than this are not one message (ISO 11783-3's
#: receive timeout T1, 750 ms; a 32-frame burst takes some 20 ms at 250 kbit/s)
STALE_NS = 750_000_000

_FAST_ARRAY = np.array(sorted(FAST_PGNS), dtype=np.int64)


def is_fast_pgn(pgn: int) -> bool:
    """Whether messages of ``pgn`` are sent as fast packets."""
    lo, hi = PROPRIETARY_FAST_RANGE
    return pgn in FAST_PGNS or pgn == PROPRIETARY_FAST or lo <= pgn <= hi


def fast_mask(pgn: np.ndarray) -> np.ndarray:
    """:func:`is_fast_pgn` of every element of ``pgn``."""
    pgn = np.asarray(pgn, dtype=np.int64)
    lo, hi = PROPRIETARY_FAST_RANGE
    out = np.isin(pgn, _FAST_ARRAY)
    out |= (pgn == PROPRIETARY_FAST) | ((pgn >= lo) & (pgn <= hi))
    return out


@dataclass
class Frames:
    """Single CAN frames (at most 8 data bytes), in file order."""

    time_ns: np.ndarray  #: int64
    line: np.ndarray  #: int64
    prio: np.ndarray  #: uint8
    pgn: np.ndarray  #: int64
    src: np.ndarray  #: uint8
    dst: np.ndarray  #: uint8
    data: np.ndarray  #: uint8 (n, 8), 0xff past ``dlen``
    dlen: np.ndarray  #: int64 data bytes of each frame
    pos: np.ndarray  #: int64 order key of each frame in the file


def reassemble(fr: Frames, time_kind: str = TIME_UTC) -> tuple[Messages, np.ndarray]:
    """The complete messages of fast-packet frames ``fr`` and the order key of each (the
    key of the frame completing it; time, priority and destination are that frame's,
    ``line`` the first frame's, as canboat's analyzer reports them)."""
    n = len(fr.pgn)
    if n == 0:
        return empty_messages(time_kind), np.zeros(0, dtype=np.int64)
    key = fr.pgn * 256 + fr.src.astype(np.int64)
    order = np.argsort((key << 36) | fr.pos)  # by (PGN, source), then file order
    k = key[order]
    b0 = fr.data[order, 0].astype(np.int64)
    idx = b0 & 0x1F
    seq = b0 >> 5
    ar = np.arange(n, dtype=np.int64)
    group_start = np.ones(n, dtype=bool)
    group_start[1:] = k[1:] != k[:-1]
    gfirst = np.maximum.accumulate(np.where(group_start, ar, 0))
    s = np.maximum.accumulate(np.where(idx == 0, ar, -1))
    valid = s >= gfirst
    s_c = np.where(valid, s, 0)
    ok = valid & (ar - s_c == idx) & (seq == seq[s_c])
    csum = np.concatenate(([0], np.cumsum(ok)))
    starts = np.flatnonzero(idx == 0)
    size = np.minimum(fr.data[order[starts], 1].astype(np.int64), MAX_FAST_LENGTH)
    nfr = 1 + size // 7
    last = starts + nfr - 1
    inside = last < n
    last_c = np.minimum(last, n - 1)
    complete = inside & (csum[last_c + 1] - csum[starts] == nfr) & (s_c[last_c] == starts)
    span = fr.time_ns[order[last_c]] - fr.time_ns[order[starts]]
    complete &= span <= STALE_NS  # frames a second apart are two broken bursts
    starts, size, nfr, last = starts[complete], size[complete], nfr[complete], last[complete]
    edge = np.zeros(n + 1, dtype=np.int64)
    edge[starts] += 1
    edge[starts + nfr] -= 1
    used = np.cumsum(edge[:n]) > 0
    # payload: byte 1.. of every frame one after another, less frame 0's length byte
    flat7 = fr.data[order, 1:].reshape(-1)
    gather = np.repeat(7 * starts + 1, size) + ramp(size)
    rows_first, rows_last = order[starts], order[last]
    vec = make_messages(
        fr.time_ns[rows_last],
        fr.line[rows_first],
        fr.prio[rows_last],
        fr.pgn[rows_first],
        fr.src[rows_first],
        fr.dst[rows_last],
        size,
        flat7[gather],
        time_kind,
    )
    vec_pos = fr.pos[rows_last]
    rest = order[~used]
    if len(rest) == 0:
        return vec, vec_pos
    # a complete burst clears its slot: stale frames of the same (PGN, source, sequence)
    # from before it never join frames after it
    resets = rows_first[np.isin(key[rows_first], key[rest])]
    slow, slow_pos, dropped = _reassemble_slow(fr, np.sort(rest), time_kind, np.sort(resets))
    msgs = concat_messages([vec, slow])
    msgs.time_kind = time_kind
    pos = np.concatenate([vec_pos, slow_pos])
    add_reject(
        msgs,
        "fast_packet_incomplete",
        len(dropped),
        [(int(fr.line[i]), _frame_text(fr, i)) for i in dropped[:5]],
    )
    return msgs, pos


def _frame_text(fr: Frames, i: int) -> str:
    data = " ".join(f"{b:02X}" for b in fr.data[i, : fr.dlen[i]])
    return f"pgn {int(fr.pgn[i])} src {int(fr.src[i])}: {data}"


def _reassemble_slow(
    fr: Frames, rows: np.ndarray, time_kind: str, resets: np.ndarray | None = None
) -> tuple[Messages, np.ndarray, list[int]]:
    """Frames ``rows`` (file order) through canboat's slot logic, one at a time; at the
    frames ``resets`` (first frames of messages completed elsewhere) the slot of their
    (PGN, source, sequence) is emptied."""
    slots: dict[tuple[int, int, int], dict[str, object]] = {}
    out: list[tuple[int, int, int]] = []  # (first row, last row, size) of each message
    bodies: list[bytes] = []
    dropped: list[int] = []
    pgn, src, data, when = fr.pgn.tolist(), fr.src.tolist(), fr.data, fr.time_ns.tolist()
    events = [(r, False) for r in rows.tolist()]
    if resets is not None and len(resets):
        events += [(r, True) for r in resets.tolist()]
        events.sort()
    for r, is_reset in events:
        b0 = int(data[r, 0])
        frame, seq = b0 & 0x1F, b0 >> 5
        key = (pgn[r], src[r], seq)
        slot = slots.get(key)
        if is_reset:
            if slot is not None:
                dropped.extend(slot["parts"].values())  # type: ignore[attr-defined]
                del slots[key]
            continue
        if slot is None:
            slot = {"parts": {}, "size": -1, "mask": 0, "t": when[r]}
            slots[key] = slot
        parts: dict[int, int] = slot["parts"]  # type: ignore[assignment]
        if frame in parts or when[r] - int(slot["t"]) > STALE_NS:  # type: ignore[call-overload]
            dropped.extend(parts.values())
            parts.clear()
        slot["t"] = when[r]
        if frame == 0:
            size = min(int(data[r, 1]), MAX_FAST_LENGTH)
            mask = (1 << (1 + size // 7)) - 1
            have = 1
            for f in parts:
                have |= 1 << f
            if parts and mask != 1 and have & mask == mask:
                dropped.extend(parts.values())
                parts.clear()
            slot["size"], slot["mask"] = size, mask
        parts[frame] = r
        mask = int(slot["mask"])  # type: ignore[call-overload]
        got = 0
        for f in parts:
            got |= 1 << f
        if mask and got == mask:
            size = int(slot["size"])  # type: ignore[call-overload]
            body = bytearray()
            for f in sorted(parts):
                row = parts[f]
                body += bytes(data[row, 2:8] if f == 0 else data[row, 1:8])
            out.append((parts[0], r, size))
            bodies.append(bytes(body[:size]))
            del slots[key]
    for slot in slots.values():
        dropped.extend(slot["parts"].values())  # type: ignore[attr-defined]
    if not out:
        return empty_messages(time_kind), np.zeros(0, dtype=np.int64), sorted(dropped)
    first = np.array([o[0] for o in out], dtype=np.int64)
    lastr = np.array([o[1] for o in out], dtype=np.int64)
    size_a = np.array([o[2] for o in out], dtype=np.int64)
    payload = np.frombuffer(b"".join(bodies), dtype=np.uint8)
    msgs = make_messages(
        fr.time_ns[lastr],
        fr.line[first],
        fr.prio[lastr],
        fr.pgn[first],
        fr.src[first],
        fr.dst[lastr],
        size_a,
        payload,
        time_kind,
    )
    return msgs, fr.pos[lastr], sorted(dropped)


def rows_to_messages(
    time_ns: np.ndarray,
    line: np.ndarray,
    prio: np.ndarray,
    pgn: np.ndarray,
    src: np.ndarray,
    dst: np.ndarray,
    length: np.ndarray,
    payload: np.ndarray,
    time_kind: str,
    reassemble_fast: bool = True,
) -> Messages:
    """Messages of rows in file order whose payloads lie one after another in
    ``payload``: rows of fast-packet PGNs with at most 8 bytes are frames, reassembled
    (when ``reassemble_fast``); all others are whole messages."""
    msgs = make_messages(time_ns, line, prio, pgn, src, dst, length, payload, time_kind)
    if not reassemble_fast or len(msgs) == 0:
        return msgs
    is_frame = (msgs.length <= 8) & fast_mask(msgs.pgn)
    if not is_frame.any():
        return msgs
    rows = np.flatnonzero(is_frame)
    ln = msgs.length[rows]
    k = np.arange(8, dtype=np.int64)
    at = msgs.start[rows][:, None] + k
    data = msgs.payload.take(at, mode="clip") if len(msgs.payload) else np.zeros(at.shape, np.uint8)
    data[k >= ln[:, None]] = 0xFF
    fr = Frames(
        msgs.time_ns[rows],
        msgs.line[rows],
        msgs.prio[rows],
        msgs.pgn[rows],
        msgs.src[rows],
        msgs.dst[rows],
        data,
        ln,
        rows,
    )
    whole = np.flatnonzero(~is_frame)
    fast, fast_pos = reassemble(fr, time_kind)
    both = concat_messages([msgs.select(whole), fast])
    # file order of the completing rows (each row completes at most one message)
    at_row = np.full(len(msgs), -1, dtype=np.int64)
    at_row[whole] = np.arange(len(whole))
    at_row[fast_pos] = np.arange(len(whole), len(whole) + len(fast_pos))
    out = both.select(at_row[at_row >= 0])
    out.time_kind = time_kind
    return out
