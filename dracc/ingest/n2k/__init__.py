"""NMEA 2000: logs of CAN frames or messages -> canonical frames.

Public API::

    read_n2k(path, cfg, progress=None) -> FileResult
    sniff_n2k(head) -> format name | None   (dracc.ingest.n2k.formats)
    parse_n2k(data, fmt) -> Messages
    n2k_result(messages, file, fmt, cfg, lines=None) -> FileResult   (already parsed)
    decode(messages) -> Decoded          (dracc.ingest.n2k.pgns: the navigation PGNs)
    source_keys(src, claim_row, claim_name) -> (codes, keys, notes)   (device NAMEs)
"""

from __future__ import annotations

from dracc.ingest.n2k.formats import parse_n2k, sniff_n2k
from dracc.ingest.n2k.messages import Messages
from dracc.ingest.n2k.names import source_keys
from dracc.ingest.n2k.pgns import NAV_PGNS, Decoded, decode
from dracc.ingest.n2k.reader import n2k_result, read_n2k

__all__ = [
    "NAV_PGNS",
    "Decoded",
    "Messages",
    "decode",
    "n2k_result",
    "parse_n2k",
    "read_n2k",
    "sniff_n2k",
    "source_keys",
]
