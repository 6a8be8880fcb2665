"""MCAP voyage logs into canonical frames: streamed, channel-wise decoding, damage recovered.

Reading
    The file is read front to back as a stream of MCAP records (spec:
    https://mcap.dev/spec), one record at a time, with the record parsers, opcodes and
    compression of the official ``mcap`` package; the summary and the indexes are not
    needed, so indexed and non-indexed files read alike.  dracc decompresses every chunk
    itself (zstd, lz4, none; the ``mcap`` package's own decompression is not bounded):
    its compressed bytes are read in 1 MiB pieces and at most 1 MiB comes out at a time,
    never more than the chunk's declared size (:func:`_inflate`).  A complete chunk (at
    most ``[ingest] max_chunk_bytes``) is decompressed whole and its CRC checked before
    its messages are decoded (through its message index, or walked in windows of about
    8 MiB); a chunk cut off by the end of the file is streamed and walked in windows.
Memory
    Besides the frames it returns, the reader holds a window, the decoded columns of at
    most 100 000 records (all channels) and JSON texts of at most 50 000 messages; frame
    pieces go into sorted runs in their own memory mappings (:class:`_KindStore`) that
    are merged step by step into the output columns at the end, each run unmapped when
    used up; the C heap and pyarrow's pool are trimmed every 200 000 records.  So the
    working memory does not grow with the file (``benchmarks/bench_mcap.py``).  Raw NMEA
    text is parsed 100 000 sentences at a time (:class:`dracc.ingest.nmea.SentenceStream`,
    one time base through all chunks), its frames going into the stores like the others.
Decoding
    Messages are grouped by channel within each window and decoded together:
    ROS 2 CDR onto numpy structured arrays (:mod:`dracc.ingest.mcap_cdr`), JSON with one
    pyarrow parse per channel and window, protobuf with the classes generated from the
    FileDescriptorSet embedded in the schema (``mcap-protobuf-support``).
Message types understood (field -> quantity; see ``docs/mcap-csv.md``)
    - ``sensor_msgs/msg/NavSatFix`` (CDR) and ``foxglove.LocationFix`` (JSON, protobuf):
      latitude/longitude in degrees, altitude in metres; NavSatFix ``status.status``
      -1/0/1/2 -> fix quality 0/1/2/4.
    - ``geometry_msgs/msg/QuaternionStamped``, ``sensor_msgs/msg/Imu`` (CDR): true
      heading from the ENU orientation (REP 103): ``heading = pi/2 - yaw``,
      ``yaw = atan2(2(wz + xy), 1 - 2(y^2 + z^2))``.
    - any message (CDR, JSON, protobuf) whose fields are quantity names with units
      (``heading_deg``, ``stw_kn``, ``sog_mps`` ...; :mod:`dracc.ingest.csv_quantities`),
      e.g. the documented ``dracc_msgs/msg/*`` and ``dracc.*`` types dracc writes.
    - raw NMEA 0183: ``nmea_msgs/msg/Sentence`` (CDR), ``std_msgs/msg/String`` holding
      sentences, JSON ``{"sentence": ...}``, protobuf messages with a bytes/string field
      holding sentences (keelson ``TimestampedBytes``), and schema-less text channels;
      these go through :func:`dracc.ingest.nmea.parse_sentences`.
Times
    The message's own stamp where it has one (``header.stamp``, ``timestamp``,
    ``time_ns``) and it is not zero, else the MCAP log time; both int64 ns UTC.  A record
    timed by its own stamp has the log time as ``recv_ns`` (its receive time; none where
    the log time is implausible, e.g. 0); one timed by its log time has ``MISSING_NS``.
    Raw sentences are anchored to the message's stamp (else its log time) and have the
    log time as ``recv_ns`` where they carry a time of fix (the NMEA rule).
Source keys
    The topic without its leading '/' and without a trailing standard leaf (``fix``,
    ``position``, ``heading``, ``velocity``, ``water``, ``distance``, ``rot``, ``nmea``,
    ``sentence``): ``/ins2/fix`` and ``/ins2/heading`` are both source ``ins2``.
    :func:`topic_role` suggests a role from the key (``ins2`` -> ins2, ``gyro`` ->
    compass, ``log`` -> log, ``gps``/``gnss`` -> gnss).  A topic named verbatim in
    ``[ingest.sources]`` is its own source key (``"/nav/a/fix" = "ins1"``).
Damage
    A file that ends early yields every complete message before the cut, and a note
    says at which byte it ended; a damaged chunk keeps its messages before the damage;
    a chunk that inflates beyond its declared size or declares more than
    ``max_chunk_bytes`` (a decompression bomb: ``chunk_too_large``), or whose records do
    not match its CRC (``chunk_crc``), is counted and none of its messages read, the rest
    of the file is; a record outside chunks over the cap is ``record_too_large``; the data
    section and summary CRCs are checked where the writer computed them
    (``data_section_crc``, ``summary_crc``); names from the file (topics, schema names)
    are kept as data, control characters included;
    unusable channels (unknown encoding, no navigation fields) are listed in the notes
    with their message counts, and their messages (valid input dracc does not use) are
    counted in ``FileResult.ignored`` by schema name, never rejected; so are raw
    sentences of types dracc does not read, by sentence type (``GSV``, ``VDM``).  A valid file without navigation data returns empty
    frames and a note saying so (the caller raises InsufficientDataError when no input
    at all holds data); a file that is not MCAP raises IngestError.
"""

from __future__ import annotations

import json
import math
import re
import struct
import zlib
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path

import numpy as np
import pandas as pd

from dracc.core.config import IngestConfig
from dracc.core.errors import IngestError
from dracc.frames import MISSING_NS, FileResult, Rejects
from dracc.ingest.csv_quantities import (
    REF_QUANTITIES,
    add_rejects,
    build_frames,
    check_declared,
    lookup,
)
from dracc.ingest.mcap_cdr import (
    CdrError,
    compile_schema,
    decode_channel,
    scalar_paths,
    string_paths,
)
from dracc.ingest.memory import mapped_columns, trim_heap
from dracc.ingest.references import ASCII_CODES, ros_constants
from dracc.ingest.timebase import drop_implausible_ext

MAGIC = b"\x89MCAP0\r\n"
_PIECE = 1 << 20
_WINDOW = 8 << 20
_TOPLEVEL_FLUSH = 20000
_CHUNK_NOTES = 10  #: rejected chunks noted one by one (all are counted in the rejects)
_JSON_BATCH = 50000  #: JSON messages of one channel parsed together
_JSON_QUEUED = (
    50000  #: JSON messages of all channels waiting to be parsed (the largest queue goes first)
)
_TRIM_RECORDS = 200_000  #: records moved into the stores between two trims of the C heap
_NMEA_CHUNK = 100_000  #: raw NMEA sentences gathered before they are parsed
_PIECE_RECORDS = (
    50_000  #: decoded records of a channel kept as columns before becoming a frame piece
)
_PENDING_RECORDS = (
    100_000  #: decoded records of all channels kept as columns (the largest one goes first)
)

_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 1, 2, 3, 4, 5, 6
_OP_DATA_END = 0x0F
_OP_NAMES = {
    1: "Header",
    2: "Footer",
    3: "Schema",
    4: "Channel",
    5: "Message",
    6: "Chunk",
    7: "MessageIndex",
    8: "ChunkIndex",
    9: "Attachment",
    10: "AttachmentIndex",
    11: "Statistics",
    12: "Metadata",
    13: "MetadataIndex",
    14: "SummaryOffset",
    15: "DataEnd",
}
_MSG_HEAD = struct.Struct("<HIQQ")
_REC_HEAD = struct.Struct("<BQ")

LEAVES = ("fix", "position", "heading", "velocity", "water", "distance", "rot", "nmea", "sentence")
_NMEA_START = (b"$", b"!", b"\\")


def topic_source(topic: str) -> str:
    """Source key of a topic: no leading '/', no trailing standard leaf (see module doc)."""
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
    #: decoded parts: (time_ns, line, {quantity: values})
    parts: list = field(default_factory=list)
    state: dict = field(default_factory=dict)

    @property
    def type_name(self) -> str:
        return self.schema.name if self.schema else self.encoding or "schemaless"


class _Reader:
    def __init__(self, path: Path, cfg: IngestConfig):
        self.path = path
        self.file = str(path)
        self.cfg = cfg
        self.declared = dict(getattr(cfg, "quantities", {}) or {})
        self.schemas: dict[int, _Schema] = {}
        self.channels: dict[int, _Channel] = {}
        self.rejects = Rejects()
        self.notes: list[str] = []
        self.msg_no = 0
        # raw NMEA text: one chunk of sentences (text, time, source, message number) at a
        # time, parsed by ``nmea`` (a SentenceStream) when full, its frames into the stores
        self.nmea_lines: list[bytes] = []
        self.nmea_time: list[int] = []
        self.nmea_recv: list[int] = []  #: the MCAP log time of each sentence (its receive time)
        self.nmea_src: list[str] = []
        self.nmea_no: list[int] = []
        self.nmea = None
        self.orphans = 0
        self.top_msgs: list[tuple[int, int, bytes, int]] = []
        self.bad_stamps = 0  #: message stamps out of range (log time used instead)
        self.stores: dict[str, _KindStore] = {}  #: kind -> its records so far, in sorted runs
        self.pending = 0  #: decoded records of all channels not yet in the stores
        self.queued = 0  #: JSON messages of all channels waiting to be parsed
        self.untrimmed = 0  #: records moved into the stores since the C heap was last trimmed
        self.chunk_no = 0  #: chunks met so far (numbered from 1 in notes and rejects)
        self.chunks_rejected: dict[
            str, int
        ] = {}  #: reason -> chunks none of whose messages was read

    # ---------------------------------------------------------------- records
    def run(self) -> None:
        p = self.path
        try:
            size = p.stat().st_size
            fh = p.open("rb")
        except OSError as err:
            raise IngestError(f"{self.file}: cannot read: {err}") from err
        with fh:
            head = fh.read(8)
            if size == 0:
                raise IngestError(f"{self.file}: empty file (0 bytes), not an MCAP log")
            if head != MAGIC:
                raise IngestError(f"{self.file}: not an MCAP file (no MCAP magic at byte 0)")
            pos = 8
            ended = False
            while True:
                if pos + 9 > size:
                    if pos < size:
                        self.notes.append(
                            f"{self.file}: file ends at byte {size} inside a record "
                            f"header at byte {pos} (recording cut short); every "
                            f"complete message before it was read"
                        )
                    else:
                        self.notes.append(
                            f"{self.file}: file ends at byte {size} without a footer "
                            f"(recording cut short); every message before it was read"
                        )
                    break
                fh.seek(pos)
                op, ln = _REC_HEAD.unpack(fh.read(9))
                body_at = pos + 9
                if op == 0 or (op > 0x0F and op < 0x80):
                    self.notes.append(
                        f"{self.file}: damaged at byte {pos}: invalid record opcode "
                        f"0x{op:02x}; reading stopped, messages before it kept"
                    )
                    break
                cut = body_at + ln > size
                if cut and op != _OP_CHUNK:
                    self.notes.append(
                        f"{self.file}: file ends at byte {size} inside a "
                        f"{_OP_NAMES.get(op, 'record')} record starting at byte {pos} "
                        f"(needs {ln} bytes); every complete message before it was read"
                    )
                    break
                if op == _OP_CHUNK:
                    self._chunk(fh, body_at, ln, size)
                    if cut:
                        self.notes.append(
                            f"{self.file}: file ends at byte {size} inside a Chunk record "
                            f"starting at byte {pos} (it would end at byte "
                            f"{body_at + ln}); the complete messages in it before the "
                            f"cut were read"
                        )
                        break
                elif op in (_OP_SCHEMA, _OP_CHANNEL) or (op == _OP_MESSAGE and not ended):
                    # the summary repeats schemas and channels, and may hold channels without messages
                    if ln > self.cfg.max_chunk_bytes:
                        self._record_too_large(op, pos, ln)
                    else:
                        self._small_record(op, fh.read(ln), pos)
                elif op == _OP_DATA_END:
                    ended = True
                    self._check_data_crc(fh, pos, ln)
                elif op == _OP_FOOTER:
                    ended = True
                    self._check_summary_crc(fh, pos, ln)
                    break
                pos = body_at + ln
            self._flush_top()
        if not ended and not any("ends" in n or "damaged" in n for n in self.notes):
            self.notes.append(f"{self.file}: no data-end record")

    def _record_too_large(self, op: int, pos: int, ln: int) -> None:
        """A schema, channel or message record outside chunks longer than
        ``max_chunk_bytes``: not read, counted (``record_too_large``)."""
        if op == _OP_MESSAGE:
            self.msg_no += 1
        self.rejects.add(
            "record_too_large",
            self.file,
            self.msg_no if op == _OP_MESSAGE else 0,
            f"{_OP_NAMES[op]} record at byte {pos}: {ln:,} bytes, over [ingest] max_chunk_bytes "
            f"= {int(self.cfg.max_chunk_bytes):,}",
        )
        self.notes.append(
            f"{self.file}: {_OP_NAMES[op]} record at byte {pos} of {ln:,} bytes not read "
            f"(record_too_large)"
        )

    def _crc_of(self, fh, start: int, end: int) -> int:
        """CRC32 of the file's bytes ``start`` to ``end``, read ``_PIECE`` at a time."""
        crc = 0
        fh.seek(start)
        left = end - start
        while left > 0:
            b = fh.read(min(_PIECE, left))
            if not b:
                break
            crc = zlib.crc32(b, crc)
            left -= len(b)
        return crc

    def _check_data_crc(self, fh, pos: int, ln: int) -> None:
        """The DataEnd record's ``data_section_crc`` (0: not computed): the CRC32 of every
        byte before it.  A mismatch is noted; it is counted (``data_section_crc``) when no
        chunk's own CRC explained it (the damage is outside the chunks' records: a record
        outside chunks, a message index, a chunk's header)."""
        if ln < 4:
            return
        (want,) = struct.unpack("<I", fh.read(4))
        if not want:
            return
        got = self._crc_of(fh, 0, pos)
        if got == want:
            return
        why = f"data section CRC32 {got:08x}, the DataEnd record at byte {pos} says {want:08x}"
        if not self.chunks_rejected.get("chunk_crc"):
            self.rejects.add("data_section_crc", self.file, 0, why)
        self.notes.append(
            f"{self.file}: {why}: the file was altered or damaged (what could be read is kept)"
        )

    def _check_summary_crc(self, fh, pos: int, ln: int) -> None:
        """The Footer's ``summary_crc`` (0: not computed): the CRC32 from the summary's
        start to the Footer's ``summary_offset_start`` field.  A mismatch is counted
        (``summary_crc``) and noted: the channels and schemas read from the summary may
        be damaged."""
        if ln < 20:
            return
        start, _offsets, want = struct.unpack("<QQI", fh.read(20))
        if not want or not start or not 8 <= start <= pos:
            return
        got = self._crc_of(fh, start, pos + 9 + 16)
        if got != want:
            why = f"summary section CRC32 {got:08x}, the Footer at byte {pos} says {want:08x}"
            self.rejects.add("summary_crc", self.file, 0, why)
            self.notes.append(f"{self.file}: {why}: its schemas and channels may be damaged")

    def _small_record(self, op: int, body: bytes, pos: int) -> None:
        from mcap.data_stream import ReadDataStream
        from mcap.exceptions import McapError
        from mcap.records import Channel, Schema

        try:
            if op == _OP_SCHEMA:
                s = Schema.read(ReadDataStream(BytesIO(body)))
                self.schemas[s.id] = _Schema(s.id, s.name, s.encoding, s.data)
            elif op == _OP_CHANNEL:
                c = Channel.read(ReadDataStream(BytesIO(body)))
                if c.id not in self.channels:
                    sch = self.schemas.get(c.schema_id) if c.schema_id else None
                    key = c.topic if c.topic in self.cfg.sources else topic_source(c.topic)
                    self.channels[c.id] = _Channel(c.id, c.topic, c.message_encoding, sch, key)
            else:
                cid, _seq, log_time, _pub = _MSG_HEAD.unpack_from(body, 0)
                self.msg_no += 1
                self.top_msgs.append((cid, log_time, body[22:], self.msg_no))
                if len(self.top_msgs) >= _TOPLEVEL_FLUSH:
                    self._flush_top()
        except (McapError, struct.error, UnicodeDecodeError, ValueError) as err:
            self.notes.append(
                f"{self.file}: damaged {_OP_NAMES[op]} record at byte {pos} skipped ({err})"
            )

    def _flush_top(self) -> None:
        if not self.top_msgs:
            return
        msgs, self.top_msgs = self.top_msgs, []
        buf = b"".join(m[2] for m in msgs)
        lens = np.fromiter((len(m[2]) for m in msgs), dtype=np.int64, count=len(msgs))
        ends = np.cumsum(lens)
        starts = ends - lens
        groups: dict[int, list[int]] = {}
        for i, m in enumerate(msgs):
            groups.setdefault(m[0], []).append(i)
        for cid, idx in groups.items():
            ix = np.asarray(idx)
            times = np.fromiter((msgs[i][1] for i in idx), dtype=np.uint64, count=len(idx))
            nums = np.fromiter((msgs[i][3] for i in idx), dtype=np.int64, count=len(idx))
            self._decode(cid, buf, starts[ix], ends[ix], times, nums)

    def _chunk(self, fh, body_at: int, ln: int, size: int) -> None:
        """One chunk: checked against its declared size, ``[ingest] max_chunk_bytes`` and
        its CRC, then decoded through its message index or walked in windows.

        Decompression is bounded (:func:`_inflate`): a chunk that inflates beyond its
        declared ``uncompressed_size`` (a decompression bomb), or declares more than the
        cap, is rejected (``chunk_too_large``) after at most its declared size and one
        piece have come out.  A complete chunk is decompressed whole (at most its declared
        size) and its ``uncompressed_crc`` verified (0: not computed) before any of its
        messages is decoded: on a mismatch none of them is read (``chunk_crc``; which of
        them are damaged cannot be told).  A chunk cut off by the end of the file cannot
        be checked: it is streamed and its complete records before the cut are read."""
        self.chunk_no += 1
        where = f"Chunk {self.chunk_no} at byte {body_at - 9}"
        avail = min(ln, size - body_at)
        head = fh.read(min(avail, 4096))
        try:
            (_s, _e, usize, want_crc, clen) = struct.unpack_from("<QQQII", head, 0)
            comp = head[32 : 32 + clen].decode("ascii")
            (rlen,) = struct.unpack_from("<Q", head, 32 + clen)
        except (struct.error, UnicodeDecodeError):
            self.notes.append(f"{self.file}: {where} cut or damaged in its header; skipped")
            return
        data_at = body_at + 32 + clen + 8
        if 32 + clen + 8 + rlen != ln:
            self.notes.append(
                f"{self.file}: {where} damaged (its lengths disagree: "
                f"{32 + clen + 8 + rlen} vs {ln}); skipped"
            )
            return
        cap = int(self.cfg.max_chunk_bytes)
        if usize > cap:
            self._reject_chunk(
                "chunk_too_large",
                where,
                f"declares {usize:,} bytes uncompressed, over [ingest] max_chunk_bytes = {cap:,}",
            )
            return
        if comp not in ("zstd", "lz4", ""):
            self.notes.append(
                f"{self.file}: {where}: unsupported compression {comp!r}; its messages skipped"
            )
            return
        box: list[BaseException] = []
        if body_at + ln > size:  # cut off by the end of the file: streamed, no CRC to check
            rest = self._walk_pieces(
                _guard(_inflate(fh, data_at, size - data_at, comp, usize), box)
            )
            self._chunk_trouble(where, box, usize, "its complete messages before that kept")
            if rest:
                self.notes.append(
                    f"{self.file}: {where}: {len(rest)} bytes of an incomplete record at "
                    f"its end not read"
                )
            return
        parts: list[bytes] = []
        crc = got = 0
        for out in _guard(_inflate(fh, data_at, rlen, comp, usize), box):
            parts.append(out)
            crc = zlib.crc32(out, crc)
            got += len(out)
        if box and isinstance(box[0], _TooLarge):
            self._chunk_trouble(where, box, usize, "none of its messages read")
            return
        if not box and want_crc and crc != want_crc:
            self._reject_chunk(
                "chunk_crc",
                where,
                f"the CRC32 of its {got:,} uncompressed bytes is "
                f"{crc:08x}, its record says {want_crc:08x}",
            )
            return
        if box:  # damaged compressed data: what came out before the damage
            self._chunk_trouble(
                where, box, usize, "its messages before the damage kept (CRC not checked)"
            )
        elif got != usize:
            self.notes.append(
                f"{self.file}: {where}: holds {got:,} bytes uncompressed, its record declares "
                f"{usize:,}{'' if want_crc else ' (no CRC to check)'}"
            )
        if not box and got == usize:
            bodies = self._message_indexes(fh, body_at + ln, size)
            if bodies:
                data = b"".join(parts)
                parts.clear()
                if self._indexed_chunk(data, bodies):
                    return
                parts = [data]
                del data
        rest = self._walk_pieces(_drain(parts))
        if rest:
            self.notes.append(
                f"{self.file}: {where}: {len(rest)} bytes of an incomplete record at its end "
                f"not read"
            )

    def _reject_chunk(
        self, reason: str, where: str, why: str, kept: str = "none of its messages read"
    ) -> None:
        """Count a rejected chunk (reason ``chunk_too_large`` or ``chunk_crc``); the first
        ones are also noted (all are counted in the rejects, with the first examples)."""
        self.rejects.add(reason, self.file, 0, f"{where}: {why}")
        self.chunks_rejected[reason] = self.chunks_rejected.get(reason, 0) + 1
        if sum(self.chunks_rejected.values()) <= _CHUNK_NOTES:
            self.notes.append(
                f"{self.file}: {where} rejected ({reason}): {why}; {kept}, the rest of the "
                f"file read"
            )

    def _chunk_trouble(self, where: str, box: list, usize: int, kept: str) -> None:
        if not box:
            return
        err = box[0]
        if isinstance(err, _TooLarge):
            self._reject_chunk(
                "chunk_too_large",
                where,
                f"declares {usize:,} bytes uncompressed but inflates "
                f"to more (stopped after {err.n:,} bytes)",
                kept,
            )
        else:
            self.notes.append(
                f"{self.file}: {where}: compressed data damaged ({type(err).__name__}: "
                f"{err}); {kept}"
            )

    def _message_indexes(self, fh, pos: int, size: int) -> list[bytes]:
        """The bodies of the MessageIndex records right after a chunk (each at most
        ``max_chunk_bytes``)."""
        bodies = []
        cap = int(self.cfg.max_chunk_bytes)
        while pos + 9 <= size:
            fh.seek(pos)
            op, n = _REC_HEAD.unpack(fh.read(9))
            if op != 7 or pos + 9 + n > size or n > cap:
                break
            bodies.append(fh.read(n))
            pos += 9 + n
        return bodies

    def _walk_pieces(self, pieces) -> bytes:
        """Decode the records of a chunk given as pieces of its uncompressed bytes, in
        windows of about ``_WINDOW``; return the incomplete rest."""
        pend: list[bytes] = []
        plen = 0
        for out in pieces:
            pend.append(out)
            plen += len(out)
            if plen >= _WINDOW:
                rest = self._walk(b"".join(pend))
                pend = [rest] if rest else []
                plen = len(rest)
        return self._walk(b"".join(pend)) if pend else b""

    def _indexed_chunk(self, data: bytes, bodies: list[bytes]) -> bool:
        """Decode a complete chunk through the MessageIndex records that follow it.

        The index gives every message's offset per channel, so the records are located
        with numpy instead of a walk; the index is checked against the data (opcode,
        channel id, lengths) and any record it does not cover is walked (schemas and
        channels; a message there means the index is incomplete).  Returns False (and the
        caller walks the chunk) when the index is not usable.
        """
        try:
            cids, offs = [], []
            for b in bodies:
                (cid, blen) = struct.unpack_from("<HI", b, 0)
                pairs = np.frombuffer(b, dtype="<u8", count=blen // 8, offset=6).reshape(-1, 2)
                offs.append(pairs[:, 1].astype(np.int64))
                cids.append(np.full(len(pairs), cid, dtype=np.int64))
        except (struct.error, ValueError):
            return False
        off = np.concatenate(offs)
        cid = np.concatenate(cids)
        order = np.argsort(off, kind="stable")
        off, cid = off[order], cid[order]
        n = len(data)
        if len(off) and (off[0] < 0 or off[-1] + 31 > n):
            return False
        u8 = np.frombuffer(data, dtype=np.uint8)
        if len(off):
            if not (u8[off] == _OP_MESSAGE).all():
                return False
            length = u8[off[:, None] + 1 + np.arange(8)].copy().view("<u8").ravel().astype(np.int64)
            ch_in = u8[off[:, None] + 9 + np.arange(2)].copy().view("<u2").ravel().astype(np.int64)
            end = off + 9 + length
            if (
                (ch_in != cid).any()
                or (length < 22).any()
                or (end > n).any()
                or (end[:-1] > off[1:]).any()
            ):
                return False
            log_time = u8[off[:, None] + 15 + np.arange(8)].copy().view("<u8").ravel()
        else:
            end = off
        # records the index does not cover: schemas and channels (walked), never messages
        gap_from = np.concatenate(([0], end))
        gap_to = np.concatenate((off, [n]))
        for a, b in zip(
            gap_from[gap_from < gap_to].tolist(), gap_to[gap_from < gap_to].tolist(), strict=True
        ):
            p = a
            while p + 9 <= b:
                op, rl = _REC_HEAD.unpack_from(data, p)
                if op == 0 and rl == 0:
                    p = _past_zeros(data, p, b)
                    continue
                if p + 9 + rl > b or op == _OP_MESSAGE:
                    return False
                if op in (_OP_SCHEMA, _OP_CHANNEL):
                    self._small_record(op, data[p + 9 : p + 9 + rl], p)
                p += 9 + rl
            if p != b:
                return False
        nums = self.msg_no + 1 + np.arange(len(off), dtype=np.int64)
        self.msg_no += len(off)
        if len(off):
            for c in np.unique(cid).tolist():
                m = cid == c
                self._decode(c, data, off[m] + 31, end[m], log_time[m], nums[m])
        return True

    def _walk(self, buf: bytes) -> bytes:
        """Decode the complete records at the start of ``buf``; return the incomplete rest."""
        n = len(buf)
        pos = 0
        per: dict[int, tuple[list, list, list, list]] = {}
        unpack_rec = _REC_HEAD.unpack_from
        unpack_msg = _MSG_HEAD.unpack_from
        no = self.msg_no
        while pos + 9 <= n:
            op, ln = unpack_rec(buf, pos)
            if (
                op == 0 and ln == 0
            ):  # a run of zero bytes (empty records of opcode 0): skipped at once
                pos = _past_zeros(buf, pos, n)
                continue
            end = pos + 9 + ln
            if end > n:
                break
            if op == _OP_MESSAGE:
                cid, _seq, log_time, _pub = unpack_msg(buf, pos + 9)
                lst = per.get(cid)
                if lst is None:
                    lst = per[cid] = ([], [], [], [])
                no += 1
                lst[0].append(pos + 31)
                lst[1].append(end)
                lst[2].append(log_time)
                lst[3].append(no)
            elif op in (_OP_SCHEMA, _OP_CHANNEL):
                self._small_record(op, buf[pos + 9 : end], pos)
            pos = end
        self.msg_no = no
        for cid, (s, e, t, k) in per.items():
            self._decode(
                cid,
                buf,
                np.asarray(s, np.int64),
                np.asarray(e, np.int64),
                np.asarray(t, np.uint64),
                np.asarray(k, np.int64),
            )
        return buf[pos:]

    # ---------------------------------------------------------------- decoding
    def _decode(self, cid: int, buf: bytes, starts, ends, times, nums) -> None:
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
        try:
            if ch.mode == "cdr":
                self._cdr(ch, buf, starts, ends, times, nums)
            elif ch.mode == "json":
                self._json_queue(ch, _join_lines(buf, starts, ends), len(starts), times, nums)
            elif ch.mode == "protobuf":
                self._protobuf(ch, buf, starts, ends, times, nums)
            elif ch.mode == "text":
                for s, e, t, k in zip(
                    starts.tolist(), ends.tolist(), times.tolist(), nums.tolist(), strict=False
                ):
                    self._nmea_text(ch, buf[s:e], t, k, t)
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
        enc = ch.encoding
        sch = ch.schema
        if enc == "cdr":
            if sch is None or sch.encoding != "ros2msg":
                ch.mode, ch.why = "skip", "CDR without a ros2msg schema"
                return
            try:
                fields = compile_schema(sch.name, sch.data.decode("utf-8"))
            except (
                CdrError,
                UnicodeDecodeError,
                Exception,
            ) as err:  # the IDL parser raises its own
                ch.mode, ch.why = "skip", f"schema not understood ({type(err).__name__}: {err})"
                return
            self._setup_cdr(ch, fields, buf, s, e)
        elif enc == "json":
            ch.mode = "json"
        elif enc == "protobuf":
            if sch is None or sch.encoding != "protobuf":
                ch.mode, ch.why = "skip", "protobuf without a schema"
                return
            from mcap.records import Schema
            from mcap_protobuf.decoder import DecoderFactory

            try:
                fn = DecoderFactory().decoder_for(
                    "protobuf",
                    Schema(id=sch.id, name=sch.name, encoding=sch.encoding, data=sch.data),
                )
            except Exception as err:  # protobuf raises several types on bad descriptors
                ch.mode, ch.why = (
                    "skip",
                    f"protobuf schema not usable ({type(err).__name__}: {err})",
                )
                return
            ch.state["decode"] = fn
            ch.mode = "protobuf"
        elif sch is None and bytes(buf[s : s + 1]) in _NMEA_START:
            ch.mode = "text"
        else:
            ch.mode = "skip"
            ch.why = (
                f"message encoding {enc!r} not supported" if enc else "schemaless, not NMEA text"
            )

    def _setup_cdr(self, ch: _Channel, fields, buf: bytes, s: int, e: int) -> None:
        paths = scalar_paths(fields)
        strs = string_paths(fields)
        short = ch.schema.name.split("/")[-1]
        want: dict[str, str] = {}  # path -> quantity name (or a special)
        if "latitude" in paths and "longitude" in paths:
            want.update({"latitude": "lat_deg", "longitude": "lon_deg"})
            if "altitude" in paths:
                want["altitude"] = "alt_m"
            if "status.status" in paths:
                want["status.status"] = "_navsat_status"
        for prefix in ("orientation", "quaternion"):
            if all(f"{prefix}.{c}" in paths for c in "xyzw") and short in (
                "Imu",
                "QuaternionStamped",
            ):
                for c in "xyzw":
                    want[f"{prefix}.{c}"] = f"_q{c}"
        for p in paths:
            if "." not in p:
                q = lookup(p, self.declared)
                if q is not None:
                    want[p] = q.name
        if "reference" in paths:
            want["reference"] = "_reference_code"
            # the definition's own constants (compass_msgs/Azimuth: REFERENCE_MAGNETIC=0,
            # REFERENCE_GEOGRAPHIC=1, REFERENCE_UTM=2) win over dracc's ASCII codes 84/77
            ch.state["ref_codes"] = ros_constants(ch.schema.data.decode("utf-8", "replace"))
        text_path = None
        if short == "Sentence" and "sentence" in strs:
            text_path = "sentence"
        elif short == "String" and "data" in strs:
            text_path = "data"
        if text_path:
            ch.state["text_path"] = text_path
        elif not any(
            not v.startswith("_") or v.startswith(("_q", "_navsat")) for v in want.values()
        ):
            ch.mode, ch.why = "skip", "no navigation fields"
            return
        if "header.stamp.sec" in paths and "header.stamp.nanosec" in paths:
            want["header.stamp.sec"] = "_sec"
            want["header.stamp.nanosec"] = "_nsec"
        ch.state["fields"] = fields
        ch.state["want"] = want
        ch.mode = "cdr"

    def _stamp(
        self, sec: np.ndarray, nsec: np.ndarray, log_time: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(time, recv): stamp times where the message has a stamp (not zero), else the log
        time; a stamp outside int64 nanoseconds or with nanoseconds outside [0, 1e9) is
        counted and the log time used.  ``recv`` is the log time where the stamp was used
        (the receive time of a record timed by its own stamp), MISSING_NS elsewhere."""
        have = ~np.isnan(sec) & ~np.isnan(nsec) & ((sec != 0) | (nsec != 0))
        ok = (np.abs(sec) < 9.2e9) & (nsec >= 0) & (nsec < 1e9)
        self.bad_stamps += int((have & ~ok).sum())
        have &= ok
        t = np.asarray(log_time, dtype=np.int64).copy()
        recv = np.where(have, t, MISSING_NS)
        if have.any():
            t[have] = sec[have].astype(np.int64) * 1_000_000_000 + nsec[have].astype(np.int64)
        return t, recv

    def _cdr(self, ch: _Channel, buf, starts, ends, times, nums) -> None:
        fields = ch.state["fields"]
        want = ch.state["want"]
        tp = ch.state.get("text_path")
        vals, strs, ok = decode_channel(fields, buf, starts, ends, list(want), [tp] if tp else [])
        if not ok.all():
            ch.bad += int((~ok).sum())
            add_rejects(
                self.rejects,
                f"message does not match its schema ({ch.type_name})",
                self.file,
                nums[~ok],
                [ch.topic] * 5,
            )
        if "header.stamp.sec" in want:
            t, recv = self._stamp(vals["header.stamp.sec"], vals["header.stamp.nanosec"], times)
        else:
            t = np.asarray(times, dtype=np.int64)
            recv = np.full(len(t), MISSING_NS, dtype=np.int64)
        if tp:
            if "nmea" not in ch.state:
                first = next((strs[tp][i] for i in np.flatnonzero(ok) if strs[tp][i]), "")
                if first[:1] not in ("$", "!", "\\"):
                    ch.mode, ch.why = "skip", f"text that is not NMEA ({first[:30]!r})"
                    return
            for i in np.flatnonzero(ok):
                text = strs[tp][i]
                if text is not None:
                    self._nmea_text(
                        ch, text.encode("utf-8", "replace"), int(t[i]), int(nums[i]), int(times[i])
                    )
            return
        out: dict[str, np.ndarray] = {}
        for path, q in want.items():
            v = np.where(ok, vals[path], np.nan)
            if q == "_navsat_status":
                # NavSatStatus -1 no fix, 0 fix, 1 SBAS, 2 GBAS -> GGA-style quality 0, 1, 2, 4
                out["quality"] = np.select(
                    [v == -1, v == 0, v == 1, v == 2], [0.0, 1.0, 2.0, 4.0], np.nan
                )
            elif q == "_reference_code":
                codes = ch.state.get("ref_codes") or {}
                if codes:  # declared constants: a declared code dracc cannot use is not understood
                    ref = np.array(
                        [
                            None if c != c else (codes.get(int(c)) or f"code {int(c)}")
                            for c in v.tolist()
                        ],
                        dtype=object,
                    )
                else:  # dracc's uint8 reference: 84 'T', 77 'M', 0 not given
                    ref = np.array(
                        [
                            None
                            if (c != c or c == 0)
                            else ASCII_CODES.get(int(c), f"code {int(c)}")
                            for c in v.tolist()
                        ],
                        dtype=object,
                    )
                out["reference"] = ref
            elif not q.startswith("_"):
                out[q] = v
        if "_qw" in want.values():
            inv = {q: p for p, q in want.items()}
            x, y, z, w = (np.where(ok, vals[inv[f"_q{c}"]], np.nan) for c in "xyzw")
            yaw_rad = np.arctan2(
                2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)
            )  # ENU yaw (REP 103)
            out["heading_rad"] = np.mod(math.pi / 2 - yaw_rad, 2 * math.pi)  # from north, clockwise
        keep = ok
        self._add_part(ch, t[keep], nums[keep], {k: v[keep] for k, v in out.items()}, recv[keep])

    def _json_queue(self, ch: _Channel, joined: bytes, n: int, times, nums) -> None:
        """Collect a channel's JSON payloads (one per line, see :func:`_join_lines`); parse
        them in batches, since each parse has a fixed cost."""
        q = ch.state.setdefault("queue", [[], 0, [], []])
        q[0].append(joined)
        q[1] += n
        q[2].append(np.asarray(times, np.int64))
        q[3].append(np.asarray(nums, np.int64))
        self.queued += n
        if q[1] >= _JSON_BATCH:
            self._json_flush(ch)
        elif self.queued >= _JSON_QUEUED:
            self._json_flush(
                max(self.channels.values(), key=lambda c: c.state.get("queue", [0, 0])[1])
            )

    def _json_flush(self, ch: _Channel) -> None:
        q = ch.state.pop("queue", None)
        if q:
            self.queued -= q[1]
        if not q or not q[1] or ch.mode == "skip":
            return
        self._json(ch, b"".join(q[0]), np.concatenate(q[2]), np.concatenate(q[3]))

    def _json(self, ch: _Channel, joined: bytes, times, nums) -> None:
        """Decode newline-separated JSON messages of one channel into quantity columns."""
        payloads = None
        if "plan" not in ch.state:
            try:
                first = json.loads(joined[: joined.find(b"\n")])
            except ValueError:
                first = None
            plan = self._json_plan(first)
            if plan is None:
                ch.mode = "skip"
                keys = (
                    ", ".join(list(first)[:8]) if isinstance(first, dict) else type(first).__name__
                )
                ch.why = "JSON without navigation fields (no quantity names, no latitude/longitude)"
                ch.state["keys"] = keys
                return
            ch.state["plan"] = plan
        plan = ch.state["plan"]
        n = len(times)
        if plan["nmea"]:
            payloads = joined.split(b"\n")[:-1]
            for p, t, k in zip(payloads, times.tolist(), nums.tolist(), strict=False):
                try:
                    obj = json.loads(p)
                    self._nmea_text(ch, str(obj["sentence"]).encode("utf-8", "replace"), t, k, t)
                except (ValueError, KeyError, TypeError):
                    ch.bad += 1
                    add_rejects(
                        self.rejects, "bad JSON message", self.file, np.array([k]), [ch.topic]
                    )
            return
        cols = _json_columns(joined, n, plan)
        if cols is None:  # pyarrow could not: message by message, counting the bad ones
            payloads = joined.split(b"\n")[:-1]
            cols = _json_columns_slow(payloads, plan)
        good = cols.pop("_ok")
        if not good.all():
            payloads = payloads or joined.split(b"\n")[:-1]
            ch.bad += int((~good).sum())
            add_rejects(
                self.rejects,
                "bad JSON message",
                self.file,
                nums[~good],
                [
                    bytes(payloads[i][:100]).decode("utf-8", "replace")
                    for i in np.flatnonzero(~good)[:5]
                ],
            )
        sec, nsec = cols.pop("_sec", None), cols.pop("_nsec", None)
        tns = cols.pop("_time_ns", None)
        t = np.asarray(times, dtype=np.int64)
        recv = np.full(len(t), MISSING_NS, dtype=np.int64)
        if sec is not None:
            t, recv = self._stamp(sec, nsec, t)
        elif tns is not None:  # the record's own time (dracc's JSON messages)
            have = tns >= 0
            recv = np.where(have, t, MISSING_NS)
            t = t.copy()
            t[have] = tns[have]
        self._add_part(ch, t[good], nums[good], {k: v[good] for k, v in cols.items()}, recv[good])

    def _quantities_of(self, names) -> dict[str, str]:
        """Field name -> quantity name (unit in the name) for the fields dracc reads:
        foxglove's latitude/longitude/altitude, and names with a unit suffix or declared in
        ``[ingest.quantities]``.  One rule for JSON objects and protobuf descriptors."""
        fields: dict[str, str] = {}
        if "latitude" in names and "longitude" in names:
            fields.update({"latitude": "lat_deg", "longitude": "lon_deg"})
            if "altitude" in names:
                fields["altitude"] = "alt_m"
        for name in names:
            q = lookup(name, self.declared)
            if q is not None:
                fields[name] = q.name
        return fields

    def _json_plan(self, obj) -> dict | None:
        if not isinstance(obj, dict):
            return None
        if isinstance(obj.get("sentence"), str):
            return {"nmea": True}
        fields = self._quantities_of(obj)
        if not fields:
            return None
        stamp = None
        ts = obj.get("timestamp")
        hd = obj.get("header")
        if isinstance(ts, dict) and "sec" in ts:
            stamp = ("timestamp", "sec", "nsec")
        elif isinstance(hd, dict) and isinstance(hd.get("stamp"), dict):
            stamp = ("header.stamp", "sec", "nanosec")
        return {"nmea": False, "fields": fields, "stamp": stamp, "time_ns": "time_ns" in obj}

    def _protobuf(self, ch: _Channel, buf, starts, ends, times, nums) -> None:
        decode = ch.state["decode"]
        msgs = []
        good = np.ones(len(starts), dtype=bool)
        for i, (s, e) in enumerate(zip(starts.tolist(), ends.tolist(), strict=False)):
            try:
                msgs.append(decode(buf[s:e]))
            except Exception:  # protobuf's DecodeError and friends
                msgs.append(None)
                good[i] = False
        if not good.all():
            ch.bad += int((~good).sum())
            add_rejects(
                self.rejects,
                f"message does not decode ({ch.type_name})",
                self.file,
                nums[~good],
                [ch.topic] * 5,
            )
        live = [m for m in msgs if m is not None]
        if not live:
            return
        if "pplan" not in ch.state:
            ch.state["pplan"] = self._proto_plan(ch, live[0])
        plan = ch.state["pplan"]
        if plan is None:
            return
        t = np.asarray(times, dtype=np.int64).copy()
        recv = np.full(len(t), MISSING_NS, dtype=np.int64)
        if plan["stamp"]:
            for i, m in enumerate(msgs):
                if m is not None and m.HasField(plan["stamp"]):
                    ts = getattr(m, plan["stamp"])
                    if ts.seconds or ts.nanos:
                        v = ts.seconds * 1_000_000_000 + ts.nanos
                        if abs(v) < 2**63:
                            recv[i] = t[i]  # the log time of a message timed by its stamp
                            t[i] = v
                        else:
                            self.bad_stamps += 1
        if plan["bytes"]:
            fld = plan["bytes"]
            payloads, tt, kk, ll = [], [], [], []
            log_times = np.asarray(times, dtype=np.int64)
            for i, m in enumerate(msgs):
                if m is None:
                    continue
                v = getattr(m, fld)
                v = v.encode("utf-8") if isinstance(v, str) else bytes(v)
                payloads.append(v)
                tt.append(t[i])
                kk.append(nums[i])
                ll.append(log_times[i])
            if not payloads:
                return
            if payloads[0][:1] in _NMEA_START:
                for p, ti, k, lt in zip(payloads, tt, kk, ll, strict=False):
                    self._nmea_text(ch, p, int(ti), int(k), int(lt))
            else:
                sub_t = np.asarray(tt, np.int64)
                lens = np.fromiter((len(x) for x in payloads), dtype=np.int64, count=len(payloads))
                e = np.cumsum(lens)
                self._json_queue(
                    ch,
                    _join_lines(b"".join(payloads), e - lens, e),
                    len(payloads),
                    sub_t,
                    np.asarray(kk, np.int64),
                )
            return
        out = {
            q: np.array(
                [getattr(m, f) if m is not None else np.nan for m in msgs], dtype=np.float64
            )
            for f, q in plan["fields"].items()
            if q not in REF_QUANTITIES
        }
        for f, q in plan["fields"].items():
            if q in REF_QUANTITIES:  # text or boolean, normalised by build_frames
                out[q] = np.array(
                    [getattr(m, f) if m is not None else None for m in msgs], dtype=object
                )
        self._add_part(ch, t[good], nums[good], {k: v[good] for k, v in out.items()}, recv[good])

    def _proto_plan(self, ch: _Channel, msg) -> dict | None:
        desc = msg.DESCRIPTOR
        names = {f.name: f for f in desc.fields}
        stamp = None
        ts = names.get("timestamp")
        if (
            ts is not None
            and ts.message_type is not None
            and ts.message_type.full_name == "google.protobuf.Timestamp"
        ):
            stamp = "timestamp"
        fields = self._quantities_of(names)
        if fields:
            return {"stamp": stamp, "fields": fields, "bytes": None}
        # a wrapper of raw text (keelson TimestampedBytes: timestamp + value)
        from google.protobuf.descriptor import FieldDescriptor

        texts = [
            f.name
            for f in desc.fields
            if f.type in (FieldDescriptor.TYPE_BYTES, FieldDescriptor.TYPE_STRING)
            and not _repeated(f)
        ]
        if len(texts) == 1:
            ch.state["plan_note"] = f"text in field {texts[0]!r}"
            return {"stamp": stamp, "fields": {}, "bytes": texts[0]}
        ch.mode, ch.why = "skip", "protobuf message without navigation fields"
        return None

    def _nmea_text(self, ch: _Channel, text: bytes, t: int, k: int, log_time: int) -> None:
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
            self._nmea_flush()

    def _nmea_flush(self) -> None:
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
        self._nmea_store(released)

    def _nmea_store(self, released: list) -> None:
        for frames in released:
            for kind, f in frames.items():
                if len(f):
                    self.stores.setdefault(kind, _KindStore()).add(f)

    # ---------------------------------------------------------------- result
    def _add_part(self, ch: _Channel, t, nums, qs: dict, recv) -> None:
        """Keep decoded columns of a channel (``recv``: the receive time of records timed
        by their own stamp, MISSING_NS elsewhere); turn them into compact frame pieces once
        enough have gathered, so the pending columns stay bounded."""
        ch.parts.append((t, nums, qs, recv))
        ch.state["pending"] = ch.state.get("pending", 0) + len(t)
        self.pending += len(t)
        if ch.state["pending"] >= _PIECE_RECORDS:
            self._to_pieces(ch)
        elif self.pending >= _PENDING_RECORDS:
            self._to_pieces(max(self.channels.values(), key=lambda c: c.state.get("pending", 0)))

    def _to_pieces(self, ch: _Channel) -> None:
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

    def result(self) -> FileResult:
        trim_heap()
        for ch in self.channels.values():
            self._json_flush(ch)
            self._to_pieces(ch)
        trim_heap()
        res = FileResult(
            path=self.file,
            format="mcap",
            frames={},
            lines=self.msg_no,
            rejects=self.rejects,
            notes=[],
        )
        self._nmea_flush()
        if self.nmea is not None:
            self._nmea_store(self.nmea.finish())
            nres = self.nmea.result([])
            res.rejects.merge(nres.rejects)
            res.ignored.update(nres.ignored)  # raw sentences dracc does not use: GSV, VDM ...
            res.ignored_examples.update(nres.ignored_examples)
            res.time_events = nres.time_events
            res.notes.extend(nres.notes)
        for kind in list(self.stores):
            store = self.stores.pop(kind)
            if store.total:
                res.frames[kind] = store.frame()
            del store
        trim_heap()
        res.notes[:0] = self.notes + self._channel_notes()
        for ch in self.channels.values():  # valid messages on channels dracc does not decode
            n = ch.messages - ch.bad
            if ch.mode in ("skip", "pending") and n > 0:
                res.ignored[ch.type_name] += n
        if self.bad_stamps:
            res.notes.append(
                f"{self.file}: {self.bad_stamps} message stamp(s) out of range; their log "
                f"time was used"
            )
        if self.orphans:
            add_rejects(
                res.rejects,
                "message on an undeclared channel",
                self.file,
                np.zeros(1, np.int64),
                [f"{self.orphans} messages"],
            )
            res.rejects.counts["message on an undeclared channel"] += self.orphans - 1
        if not res.frames or res.records == 0:
            if not self.channels:
                res.notes.append(
                    f"{self.file}: valid MCAP with no channels and {self.msg_no} messages: "
                    f"nothing to read"
                )
            else:
                res.notes.append(
                    f"{self.file}: no navigation data in {len(self.channels)} channel(s), "
                    f"{self.msg_no} message(s)"
                )
        if self.cfg.strict and res.rejects.total:
            reason, ex = next(iter(res.rejects.examples.items()))
            raise IngestError(f"{ex[0][0]}: message {ex[0][1]}: {reason}: {ex[0][2]!r} (--strict)")
        return res

    def _channel_notes(self) -> list[str]:
        from collections import Counter

        notes = []
        unused: Counter = Counter()
        for ch in self.channels.values():
            what = f"{ch.topic} [{ch.type_name}, {ch.encoding or 'no encoding'}]: {ch.messages} message(s)"
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


_ZEROS = re.compile(b"\\x00+")


def _past_zeros(buf, pos: int, end: int) -> int:
    """Where the walk goes on after the empty 9-byte records (all zero bytes) from ``pos``
    (there is one at least): the same place as walking them one by one, found in C (a
    64 MiB chunk of zeros, whose CRC may well be right, took seconds record by record)."""
    run = _ZEROS.match(buf, pos, end).end() - pos
    return pos + 9 * (run // 9)


class _TooLarge(Exception):
    """A chunk inflating beyond its declared size (``n`` bytes had come out)."""

    def __init__(self, n: int):
        super().__init__(f"inflates beyond {n:,} bytes")
        self.n = n


class _Slice:
    """``n`` bytes of an open file from offset ``at``, read as a stream."""

    def __init__(self, fh, at: int, n: int):
        self.fh, self.pos, self.left = fh, at, max(n, 0)

    def read(self, k: int = -1) -> bytes:
        k = self.left if k is None or k < 0 else min(k, self.left)
        if k <= 0:
            return b""
        self.fh.seek(self.pos)
        b = self.fh.read(k)
        self.pos += len(b)
        self.left = 0 if not b else self.left - len(b)
        return b


def _inflate(fh, at: int, n: int, comp: str, limit: int):
    """Yield the uncompressed bytes of the ``n`` compressed bytes at file offset ``at``,
    at most ``_PIECE`` at a time; raise :class:`_TooLarge` as soon as more than ``limit``
    bytes have come out.  The memory is bounded whatever the data says: zstd through a
    stream reader asked for ``_PIECE`` bytes at a time (``ZstdDecompressor.decompress``
    sizes its output by the frame header, not by ``max_output_size``, and a decompressobj
    returns all it can: 98 kB of zstd gave 3 GB at once), lz4 frames with ``max_length``.
    Damaged data raises the library's own error."""
    src = _Slice(fh, at, n)
    if comp == "zstd":
        import zstandard

        reader = zstandard.ZstdDecompressor().stream_reader(
            src, read_size=_PIECE, read_across_frames=True, closefd=False
        )
        pieces = iter(lambda: reader.read(_PIECE), b"")
    elif comp == "lz4":
        pieces = _lz4_pieces(src)
    else:
        pieces = iter(lambda: src.read(_PIECE), b"")
    total = 0
    for out in pieces:
        total += len(out)
        if total > limit:
            raise _TooLarge(total)
        yield out


def _lz4_pieces(src: _Slice):
    """lz4 frames (one or several in a row) decompressed ``_PIECE`` bytes at a time."""
    import lz4.frame

    dec = lz4.frame.LZ4FrameDecompressor()
    while True:
        data = src.read(_PIECE)
        if not data:
            return
        while True:
            out = dec.decompress(data, max_length=_PIECE)
            data = b""
            if out:
                yield out
            if dec.eof:  # a frame ended: the next one may follow in the same input
                data = dec.unused_data or b""
                dec = lz4.frame.LZ4FrameDecompressor()
                if data:
                    continue
                break
            if dec.needs_input or not out:  # (no output and no frame end: more input needed)
                break


def _guard(pieces, box: list):
    """The pieces until the first error, which is put in ``box`` (decompression errors
    are the libraries' own types; a bomb is :class:`_TooLarge`)."""
    try:
        yield from pieces
    except Exception as err:  # zstd/lz4 raise their own error types on damaged data
        box.append(err)


def _drain(parts: list):
    """The items of ``parts`` in order, each let go of once handed out."""
    parts.reverse()
    while parts:
        yield parts.pop()


def _const_cat(value: str, n: int) -> pd.Categorical:
    """A categorical column holding one value n times (1 byte a row); the dtype is
    cached (building a categories index costs more than the column)."""
    dt = _CONST_DTYPES.get(value)
    if dt is None:
        if len(_CONST_DTYPES) > 4096:
            _CONST_DTYPES.clear()
        dt = _CONST_DTYPES[value] = pd.CategoricalDtype(pd.Index([value]))
    return pd.Categorical.from_codes(np.zeros(n, dtype=np.int8), dtype=dt, validate=False)


_CONST_DTYPES: dict[str, pd.CategoricalDtype] = {}


def _code_dtype(ncat: int) -> np.dtype:
    """The integer type pandas gives the codes of ``ncat`` categories (the smallest)."""
    for t in (np.int8, np.int16, np.int32):
        if ncat < np.iinfo(t).max:
            return np.dtype(t)
    return np.dtype(np.int64)


@dataclass
class _Run:
    """Records of one kind sorted by (time_ns, line), as columns (labels as codes)."""

    cols: dict[str, np.ndarray]
    n: int
    pos: int = 0  #: records already merged into the output

    def key(self, i: int) -> tuple[int, int]:
        return int(self.cols["time_ns"][i]), int(self.cols["line"][i])

    def count_upto(self, key: tuple[int, int]) -> int:
        """How many of the records from ``pos`` on have (time_ns, line) <= ``key``."""
        t = self.cols["time_ns"][self.pos : self.n]
        lo = int(np.searchsorted(t, key[0], side="left"))
        hi = int(np.searchsorted(t, key[0], side="right"))
        return lo + int(
            np.searchsorted(self.cols["line"][self.pos + lo : self.pos + hi], key[1], side="right")
        )


class _KindStore:
    """The records of one kind, gathered piece by piece in compact sorted runs and
    merged into the frame at the end.

    Each piece (a canonical frame of a few ten thousand records) is ordered by
    (time_ns, line) (a stable sort of the piece alone) and copied into a run whose
    columns live in one memory mapping of its own (:func:`mapped_columns`); string columns
    are kept as the smallest integer codes into one label list per column.  The runs
    together are the size of the frame.  :meth:`frame` merges them into the output
    columns, allocated once at their final size, a step of at most about ``step``
    records at a time, releasing each run as soon as it is used up: the memory above
    the frame is a few runs and one step, whatever the length of the voyage.  The
    order is that of a stable sort of all pieces in the order they were added by
    (time_ns, line).
    """

    def __init__(self, step: int = 1 << 16):
        self.step = step
        self.names: list[str] = []
        #: column -> ('num', None), ('cat', dtype of its categories) or ('str', its dtype), from the first piece
        self.how: dict[str, tuple] = {}
        self.labels: dict[str, dict] = {}  #: label column -> {label: code}
        self.runs: list[_Run] = []
        self.total = 0

    def add(self, df: pd.DataFrame) -> None:
        """Add a canonical frame (any order; its columns as in the first frame added)."""
        n = len(df)
        if n == 0:
            return
        if not self.names:
            self.names = list(df.columns)
            for c in self.names:
                dt = df[c].dtype
                if isinstance(dt, pd.CategoricalDtype):
                    self.how[c] = ("cat", dt.categories.dtype)
                elif pd.api.types.is_string_dtype(dt):  # object or str
                    self.how[c] = ("str", dt)
                else:
                    self.how[c] = ("num", None)
                if self.how[c][0] != "num":
                    self.labels[c] = {}
        t = df["time_ns"].to_numpy(dtype=np.int64)
        ln = df["line"].to_numpy(dtype=np.int64)
        order = None
        if n > 1 and not ((t[1:] > t[:-1]) | ((t[1:] == t[:-1]) & (ln[1:] >= ln[:-1]))).all():
            order = np.lexsort((ln, t))  # stable: equal keys keep the piece's order
        vals = {}
        for c in self.names:
            v = self._codes(c, df[c]) if c in self.labels else df[c].to_numpy()
            vals[c] = v if order is None else v[order]
        cols = dict(
            zip(self.names, mapped_columns(n, [v.dtype for v in vals.values()]), strict=True)
        )
        for c, v in vals.items():
            cols[c][:] = v
        del vals
        self.runs.append(_Run(cols, n))
        self.total += n

    def _codes(self, c: str, col: pd.Series) -> np.ndarray:
        """A label column as codes into this store's labels for ``c`` (-1: missing)."""
        if isinstance(col.dtype, pd.CategoricalDtype):
            codes, uniq = col.array.codes, col.dtype.categories
        else:
            codes, uniq = pd.factorize(col, use_na_sentinel=True)
        known = self.labels[c]
        lut = np.empty(len(uniq) + 1, dtype=np.int64)
        for i, u in enumerate(uniq.tolist()):
            lut[i] = known.setdefault(u, len(known))
        lut[-1] = -1  # code -1 indexes the last entry
        return lut[codes].astype(_code_dtype(len(known)))

    def frame(self) -> pd.DataFrame:
        """The merged frame (see the class doc); the runs are released on the way."""
        out = {}
        for c in self.names:
            dt = (
                np.result_type(*[r.cols[c].dtype for r in self.runs])
                if self.how[c][0] == "num"
                else _code_dtype(len(self.labels[c]))
            )
            out[c] = np.empty(self.total, dtype=dt)
        o = 0
        active = self.runs
        self.runs = []
        while active:
            ends = [(r, min(r.pos + self.step, r.n) - 1) for r in active]
            k0 = min(r.key(e) for r, e in ends)
            over = [r for r in active if r.key(r.pos) <= k0]
            if len(over) > 1:  # overlapping runs: a smaller step from each, ~step records in all
                b = max(self.step // len(over), 1)
                k0 = min(r.key(min(r.pos + b, r.n) - 1) for r in over)
            takes = [(r, r.count_upto(k0)) for r in over]
            takes = [(r, m) for r, m in takes if m]
            m_all = sum(m for _, m in takes)
            if len(takes) == 1:
                r, m = takes[0]
                for c in self.names:
                    out[c][o : o + m] = r.cols[c][r.pos : r.pos + m]
            else:
                t = np.concatenate([r.cols["time_ns"][r.pos : r.pos + m] for r, m in takes])
                ln = np.concatenate([r.cols["line"][r.pos : r.pos + m] for r, m in takes])
                order = np.lexsort((ln, t))  # stable: equal keys in the order the runs were added
                for c in self.names:
                    out[c][o : o + m_all] = np.concatenate(
                        [r.cols[c][r.pos : r.pos + m] for r, m in takes]
                    )[order]
            o += m_all
            for r, m in takes:
                r.pos += m
            active = [
                r for r in active if r.pos < r.n
            ]  # used-up runs are dropped: their mappings unmapped
        self.total = 0
        for c in self.names:
            how, dtype = self.how[c]
            if how == "cat":  # categories sorted, whatever order the pieces came in
                labels = list(self.labels[c])
                try:
                    rank = sorted(range(len(labels)), key=labels.__getitem__)
                except TypeError:  # labels of different types: kept in order of appearance
                    rank = list(range(len(labels)))
                if rank != sorted(rank):
                    lut = np.empty(len(labels) + 1, dtype=out[c].dtype)
                    lut[rank] = np.arange(len(labels))
                    lut[-1] = -1
                    out[c] = lut[out[c]]
                cats = pd.CategoricalDtype(pd.Index([labels[i] for i in rank], dtype=dtype))
                out[c] = pd.Categorical.from_codes(out[c], dtype=cats, validate=False)
            elif how == "str":
                out[c] = _strings(out[c], list(self.labels[c]), dtype)
        return pd.DataFrame(out, copy=False)


def _strings(codes: np.ndarray, labels: list, dtype) -> object:
    """A string column of ``dtype`` from codes into ``labels`` (-1: missing), built by
    pyarrow for pandas' arrow strings (no Python object per row)."""
    if isinstance(dtype, pd.StringDtype) and dtype.storage == "pyarrow":
        import pyarrow as pa

        missing = codes < 0
        dic = pa.DictionaryArray.from_arrays(
            pa.array(codes, mask=missing if missing.any() else None),
            pa.array(labels, pa.large_string()),
        )
        arr = dic.cast(pa.large_string())
        if arr.null_count == 0:  # no validity bitmap where nothing is missing (as pandas builds it)
            arr = pa.Array.from_buffers(
                arr.type, len(arr), [None, *arr.buffers()[1:]], offset=arr.offset
            )
        return dtype.construct_array_type()._from_sequence(arr, dtype=dtype)
    vals = np.empty(len(labels) + 1, dtype=object)
    vals[:-1] = labels
    vals[-1] = None
    return vals[codes] if isinstance(dtype, np.dtype) else pd.array(vals[codes], dtype=dtype)


def _repeated(f) -> bool:
    """A repeated protobuf field (protobuf >= 6 has ``is_repeated``; older ones ``label``)."""
    rep = getattr(f, "is_repeated", None)
    if rep is not None:
        return bool(rep)
    return f.label == f.LABEL_REPEATED


def _join_lines(buf: bytes, starts: np.ndarray, ends: np.ndarray) -> bytes:
    """The payloads ``buf[starts[i]:ends[i]]`` as one newline-terminated line each.  A raw
    newline inside a JSON text can only be whitespace (RFC 8259 forbids it inside
    strings), so where there is one it becomes a space."""
    n = len(starts)
    if n == 0:
        return b""
    mv = memoryview(buf)
    parts = [mv[s:e] for s, e in zip(starts.tolist(), ends.tolist(), strict=True)]
    out = b"\n".join(parts) + b"\n"
    if out.count(b"\n") != n:
        out = b"\n".join(bytes(x).replace(b"\n", b" ") for x in parts) + b"\n"
    return out


def _json_columns(joined: bytes, n: int, plan: dict) -> dict[str, np.ndarray] | None:
    """Columns of one channel's JSON messages (one per line) in one pyarrow parse, or None
    if pyarrow cannot (the caller then parses message by message).  The parse allocates
    from the C heap (pyarrow's system pool), which ``trim_heap`` gives back: pyarrow's
    default pool (mimalloc) kept freed parse buffers, 9 MiB more at 24 h than at 6 h
    (``benchmarks/bench_mcap.py``)."""
    import pyarrow as pa
    import pyarrow.json as pj

    fields = [
        pa.field(
            k,
            pa.string()
            if q == "reference"
            else pa.bool_()
            if q in REF_QUANTITIES
            else pa.float64(),
        )
        for k, q in plan["fields"].items()
    ]
    st = plan["stamp"]
    if st:
        inner = pa.struct([pa.field(st[1], pa.float64()), pa.field(st[2], pa.float64())])
        if st[0] == "timestamp":
            fields.append(pa.field("timestamp", inner))
        else:
            fields.append(pa.field("header", pa.struct([pa.field("stamp", inner)])))
    if plan["time_ns"]:
        fields.append(pa.field("time_ns", pa.int64()))
    try:
        table = pj.read_json(
            BytesIO(joined),
            read_options=pj.ReadOptions(
                use_threads=False, block_size=max(len(joined) + 1, 1 << 16)
            ),
            parse_options=pj.ParseOptions(
                explicit_schema=pa.schema(fields), unexpected_field_behavior="ignore"
            ),
            memory_pool=pa.system_memory_pool(),
        )
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
        return None
    if table.num_rows != n:
        return None
    cols: dict[str, np.ndarray] = {"_ok": np.ones(n, dtype=bool)}
    for k, q in plan["fields"].items():
        c = table.column(k)
        if q in REF_QUANTITIES:
            cols[q] = np.asarray(c.to_pylist(), dtype=object)
        else:
            cols[q] = c.to_numpy(zero_copy_only=False).astype(np.float64)
    if st:
        s = table.column(st[0]).combine_chunks(memory_pool=pa.system_memory_pool())
        if st[0] == "header":
            s = s.field("stamp")
        sec = s.field(st[1]).to_numpy(zero_copy_only=False).astype(np.float64)
        nsec = s.field(st[2]).to_numpy(zero_copy_only=False).astype(np.float64)
        cols["_sec"], cols["_nsec"] = sec, nsec
    if plan["time_ns"]:
        c = table.column("time_ns").combine_chunks()
        cols["_time_ns"] = c.fill_null(-1).to_numpy(zero_copy_only=False).astype(np.int64)
    return cols


def _num(v) -> float:
    if v is None:
        return math.nan
    if isinstance(v, bool):
        raise ValueError("boolean where a number is expected")
    return float(v)


def _json_columns_slow(payloads: list[bytes], plan: dict) -> dict[str, np.ndarray]:
    n = len(payloads)
    cols: dict[str, np.ndarray] = {
        q: (np.full(n, None, dtype=object) if q in REF_QUANTITIES else np.full(n, np.nan))
        for q in plan["fields"].values()
    }
    ok = np.ones(n, dtype=bool)
    st = plan["stamp"]
    if st:
        cols["_sec"], cols["_nsec"] = np.full(n, np.nan), np.full(n, np.nan)
    if plan["time_ns"]:
        cols["_time_ns"] = np.full(n, -1, dtype=np.int64)
    for i, p in enumerate(payloads):
        try:
            obj = json.loads(p)
            for k, q in plan["fields"].items():
                v = obj.get(k)
                if q in REF_QUANTITIES:
                    cols[q][i] = v
                else:
                    cols[q][i] = _num(v)
            if st:
                s = (
                    obj.get("timestamp")
                    if st[0] == "timestamp"
                    else (obj.get("header") or {}).get("stamp")
                )
                if s:
                    cols["_sec"][i], cols["_nsec"][i] = _num(s.get(st[1])), _num(s.get(st[2]))
            if plan["time_ns"] and obj.get("time_ns") is not None:
                cols["_time_ns"][i] = int(obj["time_ns"])
        except (ValueError, TypeError, AttributeError):
            ok[i] = False
    cols["_ok"] = ok
    return cols


def read_mcap(path, cfg: IngestConfig) -> FileResult:
    """Read an MCAP log into canonical frames (see the module docstring)."""
    declared = dict(getattr(cfg, "quantities", {}) or {})
    check_declared(declared, str(path))
    r = _Reader(Path(path), cfg)
    r.run()
    return r.result()
