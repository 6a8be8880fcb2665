"""The numpy engine: a buffer of whole lines parsed in pieces of bounded working memory
(:func:`parse_numpy`), its lines too long split off and read only at their tail
(:func:`long_line_block`); each piece goes through the vectorised core
(:func:`dracc.ingest.nmea.numpy_core.parse_core`)."""

from __future__ import annotations

from collections import Counter

import numpy as np

from dracc.ingest.nmea.lines import chunk_cuts, line_bounds, tail_start
from dracc.ingest.nmea.numpy_core import parse_core
from dracc.ingest.nmea.parsed import ParsedBlock, concat_parsed, too_long_block
from dracc.ingest.nmea.sentences import MAX_LINE_BYTES

#: the numpy path works on pieces of at most this many bytes and lines ...
NUMPY_CHUNK_BYTES = 2 * 1024 * 1024
NUMPY_CHUNK_LINES = 1 << 18
#: ... and of at most this estimated working memory: ``8`` bytes per byte, ``200`` per
#: sentence start and ``80`` per line (measured on dense junk: '$,' repeated, 2-byte lines)
PIECE_BUDGET = 96 * 1024 * 1024
_W_BYTE, _W_START, _W_LINE = 8, 200, 80


def long_line_block(
    head: bytes,
    tail: bytes,
    line_end: bytes,
    ignore_checksum: bool,
    at_eof: bool,
    max_line_bytes: int,
    ext_ns: np.ndarray | None = None,
    ext_src: np.ndarray | None = None,
) -> tuple[ParsedBlock, dict[str, int]]:
    """The block of one line longer than ``max_line_bytes``: one ``too_long`` reject (its
    example the line's first bytes, ``head``), and the line's ``tail`` (its last
    ``max_line_bytes`` bytes) read from its last sentence start (:func:`tail_start`), so
    that a sentence written right after a run of NUL bytes (a logger restarted after a
    crash) is not lost; ``line_end``: the line's own line end (none at the end of a file)."""
    k = tail_start(tail)
    if k == len(tail):
        return too_long_block(head), {"": 0}
    pb, src = _parse_chunk(
        tail[k:] + line_end,
        ignore_checksum,
        at_eof,
        ext_ns,
        ext_src,
        0,
        max_line_bytes,
        split=False,
    )[0]
    tx = head[:120].decode("ascii", "replace")
    pb.reject_counts["too_long"] += 1
    pb.reject_examples["too_long"] = [(1, tx)]
    pb.first_fatal = min(x for x in (pb.first_fatal, (1, "too_long", tx)) if x is not None)
    return pb, src


def parse_numpy(
    data: bytes,
    ignore_checksum: bool = False,
    at_eof: bool = True,
    ext_line_ns: np.ndarray | None = None,
    ext_line_source: np.ndarray | None = None,
    max_line_bytes: int = MAX_LINE_BYTES,
) -> tuple[ParsedBlock, dict[str, int]]:
    """Parse a buffer of whole lines (the vectorised numpy core).

    ``ext_line_ns``/``ext_line_source`` give a receive time / source key per line (for
    :func:`parse_sentences`); otherwise they come from TAG blocks and prefixes.  Returns
    the block and the first line (0-based) of each source key over all lines ('' for
    lines without one), the order of ``source_names``.

    Memory is bounded by the piece, not by the content: the buffer is parsed in pieces
    of at most :data:`NUMPY_CHUNK_BYTES` and :data:`NUMPY_CHUNK_LINES`, and within
    :data:`PIECE_BUDGET` (estimated), cut at line ends, and merged
    (:func:`concat_parsed`); a line longer than ``max_line_bytes`` is one ``too_long``
    reject and only its tail is read (:func:`long_line_block`).
    """
    data = data if isinstance(data, bytes) else bytes(data)
    if not data:
        return ParsedBlock(0, 0, {}, {}, Counter(), {}, None), {}
    parts: list[tuple[ParsedBlock, dict[str, int]]] = []
    line0 = 0
    cuts = chunk_cuts(data, NUMPY_CHUNK_BYTES, NUMPY_CHUNK_LINES)
    for a, b in cuts:
        chunk = data if len(cuts) == 1 else data[a:b]
        for part in _parse_chunk(
            chunk,
            ignore_checksum,
            at_eof and b == len(data),
            ext_line_ns,
            ext_line_source,
            line0,
            max_line_bytes,
        ):
            parts.append(part)
            line0 += part[0].n_lines
    return concat_parsed(parts)


def _parse_chunk(
    data: bytes,
    ignore_checksum: bool,
    at_eof: bool,
    ext_ns: np.ndarray | None,
    ext_src: np.ndarray | None,
    line0: int,
    max_line_bytes: int,
    split: bool = True,
) -> list[tuple[ParsedBlock, dict[str, int]]]:
    """:func:`parse_numpy` of one chunk: its lines too long split off, the rest in pieces
    within :data:`PIECE_BUDGET`; ``line0`` is the chunk's first line in ``ext_ns``/``ext_src``."""
    n = len(data)
    # 64 zero bytes after the data let fields be gathered as fixed-width windows
    bufp = np.frombuffer(data + bytes(64), dtype=np.uint8)
    buf = bufp[:n]
    line_start, line_end, ends_nl, bad = line_bounds(buf, bufp)
    nl = len(line_start)
    st = np.flatnonzero((buf == 36) | (buf == 33))
    long = (line_end - line_start) > max_line_bytes

    def ext(a: int, b: int) -> tuple[np.ndarray | None, np.ndarray | None]:
        return (
            None if ext_ns is None else np.asarray(ext_ns)[line0 + a : line0 + b],
            None if ext_src is None else np.asarray(ext_src, dtype=object)[line0 + a : line0 + b],
        )

    if not split or (
        not long.any() and _W_BYTE * n + _W_START * len(st) + _W_LINE * nl <= PIECE_BUDGET
    ):
        e_ns, e_src = ext(0, nl)
        return [
            parse_core(
                bufp,
                buf,
                line_start,
                line_end,
                ends_nl,
                bad,
                st,
                ignore_checksum,
                at_eof,
                e_ns,
                e_src,
            )
        ]
    w = np.empty(nl + 1, dtype=np.int64)  # estimated working memory before each line
    w[:nl] = (
        _W_BYTE * line_start + _W_START * np.searchsorted(st, line_start) + _W_LINE * np.arange(nl)
    )
    w[nl] = _W_BYTE * n + _W_START * len(st) + _W_LINE * nl
    long_idx = np.flatnonzero(long).tolist()
    spans, a = [], 0
    for b in long_idx + [nl]:
        while a < b:
            j = int(np.searchsorted(w, w[a] + PIECE_BUDGET, side="right")) - 1
            j = min(max(j, a + 1), b)
            spans.append((False, a, j))
            a = j
        if b < nl:
            spans.append((True, b, b + 1))
            a = b + 1
    at = line_start.tolist() + [n]
    ends = {i: int(line_end[i]) for i in long_idx}
    del bufp, buf, line_start, line_end, bad, st, long, w
    out = []
    for is_long, a, b in spans:
        if is_long:
            e = ends[a]
            e_ns, e_src = ext(a, b)
            out.append(
                long_line_block(
                    data[at[a] : at[a] + 120],
                    data[max(at[a], e - max_line_bytes) : e],
                    data[e : at[b]],
                    ignore_checksum,
                    at_eof and b == nl,
                    max_line_bytes,
                    e_ns,
                    e_src,
                )
            )
        else:
            e_ns, e_src = ext(a, b)
            out.extend(
                _parse_chunk(
                    data[at[a] : at[b]],
                    ignore_checksum,
                    at_eof and b == nl,
                    e_ns,
                    e_src,
                    0,
                    max_line_bytes,
                    split=False,
                )
            )
    return out
