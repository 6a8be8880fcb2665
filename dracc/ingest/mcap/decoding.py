"""Per-channel decoding of MCAP messages: the schemas and channels a file declares, the
decoder each channel gets from its encoding (:data:`DECODERS`, all of one signature,
:data:`~dracc.ingest.mcap.channels.Decoder`), and the checks every batch of messages
passes first (log time in range, a declared channel)."""

from __future__ import annotations

import numpy as np

from dracc.core.config import IngestConfig
from dracc.frames import Rejects
from dracc.ingest.csv_quantities import add_rejects
from dracc.ingest.mcap.assembly import FrameAssembly
from dracc.ingest.mcap.cdr import CdrError
from dracc.ingest.mcap.channels import (
    _NMEA_START,
    DecodeContext,
    Decoder,
    _Channel,
    _Schema,
    topic_source,
)
from dracc.ingest.mcap.json_messages import decode_json
from dracc.ingest.mcap.protobuf_messages import decode_protobuf, setup_protobuf
from dracc.ingest.mcap.ros2_messages import decode_ros2, setup_ros2


def decode_text(
    ctx: DecodeContext,
    ch: _Channel,
    buf: bytes,
    starts: np.ndarray,
    ends: np.ndarray,
    times: np.ndarray,
    nums: np.ndarray,
) -> None:
    """The :data:`~dracc.ingest.mcap.channels.Decoder` of schemaless channels of raw NMEA
    text (each message timed by its log time)."""
    for s, e, t, k in zip(
        starts.tolist(), ends.tolist(), times.tolist(), nums.tolist(), strict=False
    ):
        ctx.frames.nmea_text(ch, buf[s:e], t, k, t)


#: channel mode -> its decoder
DECODERS: dict[str, Decoder] = {
    "cdr": decode_ros2,
    "json": decode_json,
    "protobuf": decode_protobuf,
    "text": decode_text,
}


class ChannelDecoding:
    """The channels of one file and their decoding (a
    :class:`~dracc.ingest.mcap.container.MessageSink`, and the
    :class:`~dracc.ingest.mcap.channels.DecodeContext` of the decoders); the decoded
    columns go to ``frames``."""

    def __init__(self, file: str, cfg: IngestConfig, rejects: Rejects) -> None:
        self.file = file
        self.cfg = cfg
        self.declared = dict(getattr(cfg, "quantities", {}) or {})
        self.rejects = rejects
        self.schemas: dict[int, _Schema] = {}
        self.channels: dict[int, _Channel] = {}
        self.frames = FrameAssembly(file, cfg, rejects, self.channels)
        self.orphans = 0  #: messages on channels never declared
        self.bad_stamps = 0  #: message stamps out of range (log time used instead)
        self.queued = 0  #: JSON messages of all channels waiting to be parsed

    def add_schema(self, sid: int, name: str, encoding: str, data: bytes) -> None:
        self.schemas[sid] = _Schema(sid, name, encoding, data)

    def add_channel(self, cid: int, topic: str, encoding: str, schema_id: int) -> None:
        """A channel record (the summary repeats them: the first one counts)."""
        if cid not in self.channels:
            sch = self.schemas.get(schema_id) if schema_id else None
            key = topic if topic in self.cfg.sources else topic_source(topic)
            self.channels[cid] = _Channel(cid, topic, encoding, sch, key)

    def decode(
        self,
        cid: int,
        buf: bytes,
        starts: np.ndarray,
        ends: np.ndarray,
        times: np.ndarray,
        nums: np.ndarray,
    ) -> None:
        """Decode messages ``buf[starts[i]:ends[i]]`` of channel ``cid``."""
        times = np.asarray(times)
        if times.dtype == np.uint64:  # MCAP log times are uint64; beyond int64 is damage
            over = times > np.uint64(np.iinfo(np.int64).max)
            if over.any():
                add_rejects(
                    self.rejects,
                    "log time out of range (after year 2262)",
                    self.file,
                    nums[over],
                    [f"channel {cid}"] * 5,
                )
                starts, ends, times, nums = starts[~over], ends[~over], times[~over], nums[~over]
                if len(starts) == 0:
                    return
            times = times.astype(np.int64)
        ch = self.channels.get(cid)
        if ch is None:
            self.orphans += len(starts)
            return
        ch.messages += len(starts)
        if ch.mode == "pending":
            self._setup(ch, buf, int(starts[0]), int(ends[0]))
        if ch.mode == "skip":
            return
        decoder = DECODERS.get(ch.mode)
        try:
            if decoder is not None:
                decoder(self, ch, buf, starts, ends, times, nums)
        except (CdrError, ValueError, TypeError, KeyError) as err:
            ch.bad += len(starts)
            add_rejects(
                self.rejects,
                f"message does not decode ({ch.type_name})",
                self.file,
                nums,
                [f"{ch.topic}: {err}"] * 5,
            )

    def _setup(self, ch: _Channel, buf: bytes, s: int, e: int) -> None:
        """Choose the channel's mode (its decoder) from its encoding, schema and first
        message, or ``skip`` with the reason."""
        enc = ch.encoding
        sch = ch.schema
        if enc == "cdr":
            setup_ros2(ch, self.declared)
        elif enc == "json":
            ch.mode = "json"
        elif enc == "protobuf":
            setup_protobuf(ch)
        elif sch is None and bytes(buf[s : s + 1]) in _NMEA_START:
            ch.mode = "text"
        else:
            ch.mode = "skip"
            ch.why = (
                f"message encoding {enc!r} not supported" if enc else "schemaless, not NMEA text"
            )
