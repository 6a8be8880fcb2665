"""Assembling the decoded columns of an MCAP log into canonical frames, in bounded memory.

Decoded columns of a channel wait until ``_PIECE_RECORDS`` of them (or
``_PENDING_RECORDS`` over all channels) have gathered, then become one frame piece per
kind (:func:`dracc.ingest.csv_quantities.build_frames`) that goes into that kind's
:class:`~dracc.ingest.mcap.columns._KindStore`; the C heap is trimmed every
``_TRIM_RECORDS`` records.  Raw NMEA text is gathered ``_NMEA_CHUNK`` sentences at a
time and parsed by one :class:`dracc.ingest.nmea.SentenceStream` (one time base through
all chunks), its frames going into the stores like the others."""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from dracc.core.config import IngestConfig
from dracc.core.timefmt import iso_utc
from dracc.frames import MISSING_NS, Rejects
from dracc.ingest.csv_quantities import build_frames
from dracc.ingest.mcap.channels import _Channel
from dracc.ingest.mcap.columns import _const_cat, _KindStore
from dracc.ingest.memory import trim_heap
from dracc.ingest.timebase import WEEK_ROLLOVER_NS, drop_implausible_ext, rollover_weeks

_TRIM_RECORDS = 200_000  #: records moved into the stores between two trims of the C heap
_NMEA_CHUNK = 100_000  #: raw NMEA sentences gathered before they are parsed
_PIECE_RECORDS = (
    50_000  #: decoded records of a channel kept as columns before becoming a frame piece
)
_PENDING_RECORDS = (
    100_000  #: decoded records of all channels kept as columns (the largest one goes first)
)


class FrameAssembly:
    """The frames of one file so far: pending columns of the ``channels``, raw NMEA
    sentences not yet parsed, and the stores (kind -> its records, in sorted runs)."""

    def __init__(
        self, file: str, cfg: IngestConfig, rejects: Rejects, channels: dict[int, _Channel]
    ) -> None:
        self.file = file
        self.cfg = cfg
        self.rejects = rejects
        self.channels = channels
        # raw NMEA text: one chunk of sentences (text, time, source, message number) at a
        # time, parsed by ``nmea`` (a SentenceStream) when full, its frames into the stores
        self.nmea_lines: list[bytes] = []
        self.nmea_time: list[int] = []
        self.nmea_recv: list[int] = []  #: the MCAP log time of each sentence (its receive time)
        self.nmea_src: list[str] = []
        self.nmea_no: list[int] = []
        self.nmea: Any = None  #: the SentenceStream, from the first sentence on
        self.stores: dict[str, _KindStore] = {}  #: kind -> its records so far, in sorted runs
        self.pending = 0  #: decoded records of all channels not yet in the stores
        self.untrimmed = 0  #: records moved into the stores since the C heap was last trimmed
        #: records whose own time stood 1024·k GPS weeks behind their log time (repaired),
        #: and the first: (message number, source key, its own time, its log time)
        self.rollovers = 0
        self.first_rollover: tuple[int, str, int, int] | None = None

    # ---------------------------------------------------------------- raw NMEA
    def nmea_text(self, ch: _Channel, text: bytes, t: int, k: int, log_time: int) -> None:
        """Gather the sentences of one message: ``t`` the external time the NMEA time base
        anchors them to (the message's stamp, else its log time), ``log_time`` the MCAP
        log time (their receive time, ``recv_ns``), ``k`` the message number."""
        for line in text.splitlines():
            line = line.strip()
            if not line:
                continue
            self.nmea_lines.append(line)
            self.nmea_time.append(t)
            self.nmea_recv.append(log_time)
            self.nmea_src.append(ch.key)
            self.nmea_no.append(k)
        ch.state["nmea"] = ch.state.get("nmea", 0) + 1
        if len(self.nmea_lines) >= _NMEA_CHUNK:
            self.nmea_flush()

    def nmea_flush(self) -> None:
        """Parse the sentences gathered so far (one chunk) and let go of their text."""
        if not self.nmea_lines:
            return
        if self.nmea is None:
            from dracc.ingest.nmea import SentenceStream

            self.nmea = SentenceStream(self.file, self.cfg)
        released = self.nmea.add(
            self.nmea_lines,
            np.asarray(self.nmea_time, dtype=np.int64),
            self.nmea_src,
            numbers=np.asarray(self.nmea_no, dtype=np.int64),
            recv_ns=np.asarray(self.nmea_recv, dtype=np.int64),
        )
        self.nmea_lines, self.nmea_time, self.nmea_src, self.nmea_no = [], [], [], []
        self.nmea_recv = []
        self.nmea_store(released)

    def nmea_store(self, released: list[dict[str, pd.DataFrame]]) -> None:
        """Put the frames the sentence stream released into the stores."""
        for frames in released:
            for kind, f in frames.items():
                if len(f):
                    self.stores.setdefault(kind, _KindStore()).add(f)

    # ---------------------------------------------------------------- decoded columns
    def add_part(
        self,
        ch: _Channel,
        t: np.ndarray,
        nums: np.ndarray,
        qs: dict[str, np.ndarray],
        recv: np.ndarray,
    ) -> None:
        """Keep decoded columns of a channel (``recv``: the receive time of records timed
        by their own stamp, MISSING_NS elsewhere); turn them into compact frame pieces once
        enough have gathered, so the pending columns stay bounded.  A record's own time
        1024·k GPS weeks behind its log time (a receiver's week-number rollover) is
        repaired: 1024·k weeks added, counted and the first kept (:meth:`rollover_note`)."""
        log = drop_implausible_ext(recv)[0]
        k = rollover_weeks(np.where(log != MISSING_NS, log, t) - t)
        if k.any():
            i = np.flatnonzero(k)
            if self.first_rollover is None:
                j = int(i[0])
                self.first_rollover = (int(nums[j]), ch.key, int(t[j]), int(recv[j]))
            t = t + k * WEEK_ROLLOVER_NS
            self.rollovers += len(i)
        ch.parts.append((t, nums, qs, recv))
        ch.state["pending"] = ch.state.get("pending", 0) + len(t)
        self.pending += len(t)
        if ch.state["pending"] >= _PIECE_RECORDS:
            self.to_pieces(ch)
        elif self.pending >= _PENDING_RECORDS:
            self.to_pieces(max(self.channels.values(), key=lambda c: c.state.get("pending", 0)))

    def rollover_note(self) -> str | None:
        """The decision on the records repaired for a week rollover (None: none were)."""
        if self.first_rollover is None:
            return None
        no, key, own, log = self.first_rollover
        weeks = 1024 * round((log - own) / WEEK_ROLLOVER_NS)
        return (
            f"{self.rollovers} dates corrected for the GPS week rollover (+1024 weeks): "
            f"message stamps {weeks} weeks behind their log times, the first at message {no} "
            f"({key}, stamped {iso_utc(own)}, logged {iso_utc(log)})"
        )

    def to_pieces(self, ch: _Channel) -> None:
        """Turn the channel's pending columns into frame pieces in the stores."""
        if not ch.parts:
            return
        t = np.concatenate([p[0] for p in ch.parts])
        k = np.concatenate([p[1] for p in ch.parts])
        qs = {q: np.concatenate([p[2][q] for p in ch.parts]) for q in ch.parts[0][2]}
        recv, _ = drop_implausible_ext(np.concatenate([p[3] for p in ch.parts]))
        ch.parts = []
        self.pending -= ch.state["pending"]
        ch.state["pending"] = 0
        n = len(t)
        sentence = ch.type_name.split("/")[-1].split(".")[-1]
        frames = build_frames(
            t,
            _const_cat(ch.key, n),
            k,
            _const_cat(sentence, n),
            qs,
            self.file,
            self.rejects,
            talker=_const_cat("", n),
            recv_ns=recv,
        )
        ch.state["records"] = ch.state.get("records", 0) + sum(len(f) for f in frames.values())
        for kind, f in frames.items():
            self.stores.setdefault(kind, _KindStore()).add(f)
        del frames
        self.untrimmed += n
        if self.untrimmed >= _TRIM_RECORDS:
            trim_heap()
            self.untrimmed = 0
