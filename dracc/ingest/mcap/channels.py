"""MCAP channels: their schemas, source keys and roles from topics, which fields are
quantities, message times from stamps, the notes on what each channel gave, and the one
signature every message decoder has (:data:`Decoder`)."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Collection, Iterable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from dracc.frames import MISSING_NS, Rejects
from dracc.ingest.csv_quantities import lookup

LEAVES = ("fix", "position", "heading", "velocity", "water", "distance", "rot", "nmea", "sentence")
_NMEA_START = (b"$", b"!", b"\\")


def topic_source(topic: str) -> str:
    """Source key of a topic: no leading '/', no trailing standard leaf (see the package doc)."""
    parts = [p for p in topic.strip("/").split("/") if p]
    if len(parts) > 1 and parts[-1] in LEAVES:
        parts = parts[:-1]
    return "/".join(parts) if parts else topic


def topic_role(key: str) -> str | None:
    """The role a source key's first component names, or None (ambiguous or silent)."""
    head = key.split("/")[0].lower()
    if head in ("ins1", "ins2", "ins3"):
        return head
    if head in ("gyro", "compass"):
        return "compass"
    if head in ("log", "speedlog"):
        return "log"
    if head in ("gps", "gnss"):
        return "gnss"
    return None


@dataclass
class _Schema:
    id: int
    name: str
    encoding: str
    data: bytes


@dataclass
class _Channel:
    """One channel: how its messages decode, and what it yielded."""

    id: int
    topic: str
    encoding: str
    schema: _Schema | None
    key: str
    mode: str = "pending"  #: json, cdr, protobuf, text, skip
    why: str = ""
    messages: int = 0
    bad: int = 0
    #: decoded parts: (time_ns, line, {quantity: values}, recv_ns)
    parts: list[tuple[np.ndarray, np.ndarray, dict[str, np.ndarray], np.ndarray]] = field(
        default_factory=list
    )
    state: dict[str, Any] = field(default_factory=dict)

    @property
    def type_name(self) -> str:
        return self.schema.name if self.schema else self.encoding or "schemaless"


class FrameSink(Protocol):
    """Where decoders put what they decoded (:class:`dracc.ingest.mcap.assembly.FrameAssembly`)."""

    def add_part(
        self,
        ch: _Channel,
        t: np.ndarray,
        nums: np.ndarray,
        qs: dict[str, np.ndarray],
        recv: np.ndarray,
    ) -> None: ...

    def nmea_text(self, ch: _Channel, text: bytes, t: int, k: int, log_time: int) -> None: ...


class DecodeContext(Protocol):
    """What a decoder is given besides its channel's messages
    (:class:`dracc.ingest.mcap.decoding.ChannelDecoding`)."""

    file: str
    declared: dict[str, str]
    rejects: Rejects
    channels: dict[int, _Channel]
    bad_stamps: int  #: message stamps out of range (log time used instead)
    queued: int  #: JSON messages of all channels waiting to be parsed

    @property
    def frames(self) -> FrameSink: ...


#: A message decoder: ``(ctx, channel, buf, starts, ends, times, nums)`` decodes the
#: messages ``buf[starts[i]:ends[i]]`` of one channel (log times ``times`` as int64 ns,
#: message numbers ``nums``) and hands their columns to ``ctx.frames``.
Decoder = Callable[
    [DecodeContext, _Channel, bytes, np.ndarray, np.ndarray, np.ndarray, np.ndarray], None
]


def quantities_of(names: Collection[str], declared: dict[str, str]) -> dict[str, str]:
    """Field name -> quantity name (unit in the name) for the fields dracc reads:
    foxglove's latitude/longitude/altitude, and names with a unit suffix or declared in
    ``[ingest.quantities]``.  One rule for JSON objects and protobuf descriptors."""
    fields: dict[str, str] = {}
    if "latitude" in names and "longitude" in names:
        fields.update({"latitude": "lat_deg", "longitude": "lon_deg"})
        if "altitude" in names:
            fields["altitude"] = "alt_m"
    for name in names:
        q = lookup(name, declared)
        if q is not None:
            fields[name] = q.name
    return fields


def message_times(
    ctx: DecodeContext, sec: np.ndarray, nsec: np.ndarray, log_time: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(time, recv): stamp times where the message has a stamp (not zero), else the log
    time; a stamp outside int64 nanoseconds or with nanoseconds outside [0, 1e9) is
    counted (``ctx.bad_stamps``) and the log time used.  ``recv`` is the log time where
    the stamp was used (the receive time of a record timed by its own stamp), MISSING_NS
    elsewhere."""
    have = ~np.isnan(sec) & ~np.isnan(nsec) & ((sec != 0) | (nsec != 0))
    ok = (np.abs(sec) < 9.2e9) & (nsec >= 0) & (nsec < 1e9)
    ctx.bad_stamps += int((have & ~ok).sum())
    have &= ok
    t = np.asarray(log_time, dtype=np.int64).copy()
    recv = np.where(have, t, MISSING_NS)
    if have.any():
        t[have] = sec[have].astype(np.int64) * 1_000_000_000 + nsec[have].astype(np.int64)
    return t, recv


def channel_notes(channels: Iterable[_Channel]) -> list[str]:
    """One note per channel (what it gave, or why it was not used); with more than 40,
    the unused ones are summarised by reason."""
    notes: list[str] = []
    unused: Counter[str] = Counter()
    for ch in channels:
        what = (
            f"{ch.topic} [{ch.type_name}, {ch.encoding or 'no encoding'}]: {ch.messages} message(s)"
        )
        if ch.mode == "skip" or ch.mode == "pending":
            why = ch.why or "no messages"
            unused[why] += 1
            notes.append(f"channel {what}: not used ({why})")
        elif ch.state.get("nmea"):
            notes.append(f"channel {what}: raw NMEA, source {ch.key!r}")
        elif ch.state.get("records"):
            notes.append(f"channel {what}: {ch.state['records']} record(s), source {ch.key!r}")
        else:
            notes.append(f"channel {what}: no navigation records")
    if len(notes) > 40:  # hundreds of channels (e.g. one per AIS target): summarise the unused
        used = [n for n in notes if "not used" not in n]
        notes = used + [
            f"{k} further channel(s) not used ({why})" for why, k in unused.most_common()
        ]
    return notes
