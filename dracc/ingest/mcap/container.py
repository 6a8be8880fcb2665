"""The walk through an MCAP file's records (https://mcap.dev/spec), front to back.

One record at a time, with the record parsers of the official ``mcap`` package; the
summary and the indexes are not needed, so indexed and non-indexed files read alike.
Every chunk is decompressed by dracc itself, bounded (:mod:`dracc.ingest.mcap.inflate`):
a complete chunk (at most ``[ingest] max_chunk_bytes``) is decompressed whole and its
CRC checked before its messages are handed on (located through its message index, or
walked in windows of about 8 MiB); a chunk cut off by the end of the file is streamed
and walked in windows.  Damage (a cut, a bad opcode, a bomb, a CRC mismatch) is noted
and counted here; the messages are handed, grouped by channel, to a
:class:`MessageSink` (the channel decoding).
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Iterable
from io import BytesIO
from pathlib import Path
from typing import BinaryIO, Protocol

import numpy as np

from dracc.core.config import IngestConfig
from dracc.core.errors import IngestError
from dracc.frames import Rejects
from dracc.ingest.mcap.inflate import _drain, _guard, _inflate, _TooLarge
from dracc.ingest.mcap.records import (
    _MSG_HEAD,
    _OP_CHANNEL,
    _OP_CHUNK,
    _OP_DATA_END,
    _OP_FOOTER,
    _OP_MESSAGE,
    _OP_NAMES,
    _OP_SCHEMA,
    _REC_HEAD,
    MAGIC,
    _past_zeros,
    crc_of,
    indexed_messages,
    message_indexes,
)

_WINDOW = 8 << 20  #: uncompressed chunk bytes walked at a time
_TOPLEVEL_FLUSH = 20000  #: messages outside chunks gathered before they are handed on
_CHUNK_NOTES = 10  #: rejected chunks noted one by one (all are counted in the rejects)


class MessageSink(Protocol):
    """Where the walk hands what it reads: schemas, channels, and messages of one channel
    as ``buf[starts[i]:ends[i]]`` with their log times and message numbers."""

    def add_schema(self, sid: int, name: str, encoding: str, data: bytes) -> None: ...

    def add_channel(self, cid: int, topic: str, encoding: str, schema_id: int) -> None: ...

    def decode(
        self,
        cid: int,
        buf: bytes,
        starts: np.ndarray,
        ends: np.ndarray,
        times: np.ndarray,
        nums: np.ndarray,
    ) -> None: ...


class ContainerWalk:
    """Reads the records of one MCAP file (:meth:`run`), handing them to ``sink``; notes
    and counts the damage in ``notes`` and ``rejects``; ``msg_no`` messages met."""

    def __init__(
        self, path: Path, cfg: IngestConfig, rejects: Rejects, notes: list[str], sink: MessageSink
    ) -> None:
        self.path = path
        self.file = str(path)
        self.cfg = cfg
        self.rejects = rejects
        self.notes = notes
        self.sink = sink
        self.msg_no = 0
        self.top_msgs: list[tuple[int, int, bytes, int]] = []
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

    def _check_data_crc(self, fh: BinaryIO, pos: int, ln: int) -> None:
        """The DataEnd record's ``data_section_crc`` (0: not computed): the CRC32 of every
        byte before it.  A mismatch is noted; it is counted (``data_section_crc``) when no
        chunk's own CRC explained it (the damage is outside the chunks' records: a record
        outside chunks, a message index, a chunk's header)."""
        if ln < 4:
            return
        (want,) = struct.unpack("<I", fh.read(4))
        if not want:
            return
        got = crc_of(fh, 0, pos)
        if got == want:
            return
        why = f"data section CRC32 {got:08x}, the DataEnd record at byte {pos} says {want:08x}"
        if not self.chunks_rejected.get("chunk_crc"):
            self.rejects.add("data_section_crc", self.file, 0, why)
        self.notes.append(
            f"{self.file}: {why}: the file was altered or damaged (what could be read is kept)"
        )

    def _check_summary_crc(self, fh: BinaryIO, pos: int, ln: int) -> None:
        """The Footer's ``summary_crc`` (0: not computed): the CRC32 from the summary's
        start to the Footer's ``summary_offset_start`` field.  A mismatch is counted
        (``summary_crc``) and noted: the channels and schemas read from the summary may
        be damaged."""
        if ln < 20:
            return
        start, _offsets, want = struct.unpack("<QQI", fh.read(20))
        if not want or not start or not 8 <= start <= pos:
            return
        got = crc_of(fh, start, pos + 9 + 16)
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
                self.sink.add_schema(s.id, s.name, s.encoding, s.data)
            elif op == _OP_CHANNEL:
                c = Channel.read(ReadDataStream(BytesIO(body)))
                self.sink.add_channel(c.id, c.topic, c.message_encoding, c.schema_id)
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
            self.sink.decode(cid, buf, starts[ix], ends[ix], times, nums)

    # ---------------------------------------------------------------- chunks
    def _chunk(self, fh: BinaryIO, body_at: int, ln: int, size: int) -> None:
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
            bodies = message_indexes(fh, body_at + ln, size, cap)
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

    def _chunk_trouble(self, where: str, box: list[BaseException], usize: int, kept: str) -> None:
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

    def _walk_pieces(self, pieces: Iterable[bytes]) -> bytes:
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
        with numpy instead of a walk (:func:`indexed_messages`); any record it does not
        cover is walked (schemas and channels; a message there means the index is
        incomplete).  Returns False (and the caller walks the chunk) when the index is
        not usable.
        """
        found = indexed_messages(data, bodies)
        if found is None:
            return False
        cid, off, end, log_time = found
        n = len(data)
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
            assert log_time is not None  # indexed_messages gives it where there are messages
            for c in np.unique(cid).tolist():
                m = cid == c
                self.sink.decode(c, data, off[m] + 31, end[m], log_time[m], nums[m])
        return True

    def _walk(self, buf: bytes) -> bytes:
        """Decode the complete records at the start of ``buf``; return the incomplete rest."""
        n = len(buf)
        pos = 0
        #: channel -> (starts, ends, log times, message numbers) of its messages
        per: dict[int, tuple[list[int], list[int], list[int], list[int]]] = {}
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
            self.sink.decode(
                cid,
                buf,
                np.asarray(s, np.int64),
                np.asarray(e, np.int64),
                np.asarray(t, np.uint64),
                np.asarray(k, np.int64),
            )
        return buf[pos:]
