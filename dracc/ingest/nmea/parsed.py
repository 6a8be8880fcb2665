"""The result of parsing a block of lines (:class:`ParsedBlock`), the block of one line too
long to parse, and the joining of the blocks of consecutive pieces of a buffer."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from dracc.ingest.nmea.sentences import IGNORED_EXAMPLES


@dataclass
class ParsedBlock:
    """What a worker returns for one block (line numbers relative to the block, 1-based)."""

    n_lines: int
    n_blank: int
    #: kind -> columns incl. 'line', 'seq', 'talker', 'sentence', 'tag_source', 'dec', 'tod_ns', 'date_days', 'ext_ns'
    kinds: dict[str, dict[str, np.ndarray]]
    #: the ZDA records (time only): seq, tod_ns, date_days, ext_ns, line
    clock: dict[str, np.ndarray]
    reject_counts: Counter[str]
    reject_examples: dict[str, list[tuple[int, str]]]
    first_fatal: tuple[int, str, str] | None  #: (line, reason, text) of the first fatal rejection
    stats: Counter[str] = field(default_factory=Counter)
    #: names for the 'tag_source' codes (TAG s: / given source keys; '' = none)
    source_names: list[str] = field(default_factory=list)
    #: valid sentences and lines dracc does not use, by type (GSV, VDM, PGRME, comment)
    ignored: Counter[str] = field(default_factory=Counter)
    #: type -> the first few (line, text) of each ignored type
    ignored_examples: dict[str, list[tuple[int, str]]] = field(default_factory=dict)
    #: sentence starts in the block (the range of ``seq``)
    n_seg: int = 0
    #: side tables (seq, line, talker, sentence, tag_source and their columns) of what is
    #: not a record but qualifies records: ``psxn_quality`` (``$PSXN,20`` head-qual),
    #: ``ais_second`` (the UTC second of an own-ship AIS report), see
    #: :mod:`~dracc.ingest.nmea.ins_ais`; applied by :mod:`~dracc.ingest.nmea.assemble`
    aux: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    #: the lines with a TAG line-group parameter ``g:`` (see
    #: :func:`~dracc.ingest.nmea.groups.scan_groups`; empty without), joined by the reader
    groups: dict[str, np.ndarray] = field(default_factory=dict)


def too_long_block(text: bytes) -> ParsedBlock:
    """The block of one line too long to parse (``text``: its first bytes)."""
    tx = text[:120].decode("ascii", "replace")
    return ParsedBlock(
        1, 0, {}, {}, Counter(too_long=1), {"too_long": [(1, tx)]}, (1, "too_long", tx)
    )


def concat_parsed(
    parts: list[tuple[ParsedBlock, dict[str, int]]],
) -> tuple[ParsedBlock, dict[str, int]]:
    """Blocks of consecutive pieces of a buffer as the block of the whole buffer: line
    numbers and ``seq`` offset, TAG source codes in order of first appearance over all
    lines (from each piece's first lines of its sources, see :func:`parse_core`),
    examples the first ones in stream order."""
    if len(parts) == 1:
        return parts[0]
    firsts: dict[str, int] = {}
    n_lines = 0
    for pb, fs in parts:
        for nm, i in fs.items():
            if nm not in firsts:
                firsts[nm] = i + n_lines
        n_lines += pb.n_lines
    names = {nm: k for k, nm in enumerate(sorted(firsts, key=firsts.__getitem__))}
    n_lines = n_seg = n_blank = 0
    kinds: dict[str, dict[str, list[np.ndarray]]] = {}
    aux: dict[str, dict[str, list[np.ndarray]]] = {}
    clock: dict[str, list[np.ndarray]] = {}
    counts: Counter[str] = Counter()
    examples: dict[str, list[tuple[int, str]]] = {}
    fatal: list[tuple[int, str, str]] = []
    stats: Counter[str] = Counter()
    ignored: Counter[str] = Counter()
    ign_examples: dict[str, list[tuple[int, str]]] = {}
    for pb, _ in parts:
        lut = np.array([names[str(x)] for x in pb.source_names] or [0], dtype=np.int32)
        groups = [(kinds.setdefault(k, {}), cols) for k, cols in pb.kinds.items()]
        groups += [(aux.setdefault(k, {}), cols) for k, cols in pb.aux.items()]
        if pb.clock:
            groups.append((clock, pb.clock))
        for d, cols in groups:
            for c, v in cols.items():
                if c == "line":
                    v = v + n_lines
                elif c == "seq":
                    v = v + n_seg
                elif c == "tag_source":
                    v = lut[v]
                d.setdefault(c, []).append(v)
        counts.update(pb.reject_counts)
        for r, ex in pb.reject_examples.items():
            examples.setdefault(r, []).extend((ln + n_lines, tx) for ln, tx in ex)
        if pb.first_fatal is not None:
            fatal_line, fatal_reason, fatal_text = pb.first_fatal
            fatal.append((fatal_line + n_lines, fatal_reason, fatal_text))
        stats.update(pb.stats)
        ignored.update(pb.ignored)
        for k, ex in pb.ignored_examples.items():
            ign_examples.setdefault(k, []).extend((ln + n_lines, tx) for ln, tx in ex)
        n_lines += pb.n_lines
        n_seg += pb.n_seg
        n_blank += pb.n_blank
    cat = {k: {c: np.concatenate(v) for c, v in d.items()} for k, d in kinds.items()}
    clock_np = {c: np.concatenate(v) for c, v in clock.items()}
    aux_np = {k: {c: np.concatenate(v) for c, v in d.items()} for k, d in aux.items()}
    pb = ParsedBlock(
        n_lines,
        n_blank,
        cat,
        clock_np,
        counts,
        {r: ex[:5] for r, ex in examples.items()},
        min(fatal) if fatal else None,
        stats,
        list(names) if n_seg else [],
        ignored,
        {k: ex[:IGNORED_EXAMPLES] for k, ex in ign_examples.items()},
        n_seg,
        aux_np,
    )
    return pb, firsts


def first_examples(
    examples: dict[str, list[tuple[int, str]]], k: int
) -> dict[str, list[tuple[int, str]]]:
    """The first ``k`` examples of each reason or type in stream order (by line; on one
    line in the order they were found): the same whatever pieces a buffer was cut into."""
    return {r: sorted(ex, key=lambda e: e[0])[:k] for r, ex in examples.items()}
