"""MCAP record layout (https://mcap.dev/spec): magic, opcodes, record and message heads,
and the record-level helpers of the container walk: file CRCs, runs of empty records,
the MessageIndex records after a chunk and the message offsets they give."""

from __future__ import annotations

import re
import struct
import zlib
from typing import BinaryIO

import numpy as np

from dracc.ingest.mcap.inflate import _PIECE

MAGIC = b"\x89MCAP0\r\n"

_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 1, 2, 3, 4, 5, 6
_OP_MESSAGE_INDEX = 7
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

_ZEROS = re.compile(b"\\x00+")


def _past_zeros(buf: bytes, pos: int, end: int) -> int:
    """Where the walk goes on after the empty 9-byte records (all zero bytes) from ``pos``
    (there is one at least): the same place as walking them one by one, found in C (a
    64 MiB chunk of zeros, whose CRC may well be right, took seconds record by record)."""
    m = _ZEROS.match(buf, pos, end)
    assert m is not None  # the caller saw a zero record at ``pos``
    run = m.end() - pos
    return pos + 9 * (run // 9)


def crc_of(fh: BinaryIO, start: int, end: int) -> int:
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


def message_indexes(fh: BinaryIO, pos: int, size: int, cap: int) -> list[bytes]:
    """The bodies of the MessageIndex records at file offset ``pos`` (right after a
    chunk), each at most ``cap`` bytes (``max_chunk_bytes``)."""
    bodies = []
    while pos + 9 <= size:
        fh.seek(pos)
        op, n = _REC_HEAD.unpack(fh.read(9))
        if op != _OP_MESSAGE_INDEX or pos + 9 + n > size or n > cap:
            break
        bodies.append(fh.read(n))
        pos += 9 + n
    return bodies


def indexed_messages(
    data: bytes, bodies: list[bytes]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None] | None:
    """The messages of a complete chunk's records ``data`` located through the bodies of
    its MessageIndex records, with numpy instead of a walk: ``(cid, off, end, log_time)``
    (channel id, record offset and end, log time of each message, in record order), or
    None when the index is not usable (it does not parse, or disagrees with the data:
    opcode, channel id, lengths).  ``log_time`` is None when there are no messages."""
    try:
        cids, offs = [], []
        for b in bodies:
            (cid, blen) = struct.unpack_from("<HI", b, 0)
            pairs = np.frombuffer(b, dtype="<u8", count=blen // 8, offset=6).reshape(-1, 2)
            offs.append(pairs[:, 1].astype(np.int64))
            cids.append(np.full(len(pairs), cid, dtype=np.int64))
    except (struct.error, ValueError):
        return None
    off = np.concatenate(offs)
    cid = np.concatenate(cids)
    order = np.argsort(off, kind="stable")
    off, cid = off[order], cid[order]
    n = len(data)
    if len(off) and (off[0] < 0 or off[-1] + 31 > n):
        return None
    u8 = np.frombuffer(data, dtype=np.uint8)
    log_time = None
    if len(off):
        if not (u8[off] == _OP_MESSAGE).all():
            return None
        length = u8[off[:, None] + 1 + np.arange(8)].copy().view("<u8").ravel().astype(np.int64)
        ch_in = u8[off[:, None] + 9 + np.arange(2)].copy().view("<u2").ravel().astype(np.int64)
        end = off + 9 + length
        if (
            (ch_in != cid).any()
            or (length < 22).any()
            or (end > n).any()
            or (end[:-1] > off[1:]).any()
        ):
            return None
        log_time = u8[off[:, None] + 15 + np.arange(8)].copy().view("<u8").ravel()
    else:
        end = off
    return cid, off, end, log_time
