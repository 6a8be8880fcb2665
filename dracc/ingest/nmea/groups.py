"""IEC 61162-450 line groups: TAG ``g:<i>-<n>-<id>`` (§7.3), sentence ``i`` of ``n`` of
group ``id``, joined to their group's first line.

A group's sentences are one message of one source at one time (§7.3, line grouping: a
source sends related sentences, e.g. a GSV triple, the fragments of an ``!AIVDM``, a
``$..TXT`` text, a fix's GGA, RMC and HDT, as one group); usually only its first line
(``i == 1``) carries ``s:`` and ``c:``.  The rule dracc reads a group by:

* **source**: a line ``i > 1`` without ``s:`` takes the ``s:`` of its group's first line;
  a line with its own ``s:`` keeps it.
* **time**: every line of a group takes the ``c:`` of its group's first line where that
  line has one; a line keeps its own ``c:`` only where the first line has none.  dracc
  keeps one external time per line, the ``c:``: it is the time of a sentence without a
  time of its own and the receive time (``recv_ns``, the latency) of one with its own
  (:func:`~dracc.ingest.nmea.assemble._recv_ns`); it holds no separate receive time that
  could keep a second value.  The group being one message at one time, its time is the
  first line's.  This is what matters for ``dracc watch`` recordings
  (:func:`dracc.ingest.live.record.tag_line`): the recorder adds its receive time ``c:``
  to every line without one, so a recorded continuation line has a ``c:`` (the moment its
  datagram arrived) but no ``s:``; read by this rule the recording gives the same source
  and time as the stream it recorded.
* **the first line**: the nearest earlier line of the same id with ``i == 1`` and the
  same ``n``, at most :data:`GROUP_WINDOW_LINES` lines before, of which no line ``>= i``
  has been seen (ids are reused cyclically: a line ``i`` seen again is a new group).  The
  first line's TAG block must be readable (its sentence need not be: its ``s:`` and
  ``c:`` are the group's).
* **incomplete**: a line ``i > 1`` without such a first line keeps what it has (its own
  ``s:``/``c:``, else its talker as source key) and is counted ``tag_group_incomplete``
  (a note: line group incomplete).  An unreadable ``g:`` value (``g:3-2-7``, ``g:1-x``)
  is read as if there were none, counted ``tag_group_bad``.

Lines with ``g:`` are rare: a buffer without a byte ``g`` costs one ``memchr``, one
with some (AIS payloads) a numpy pass for ``\\g:`` and ``,g:`` (:func:`scan_groups`); only
where there are such, the lines holding them are found and their TAG blocks read,
vectorised (:func:`~dracc.ingest.tagblock.parse_groups`); the joining
(:func:`resolve_groups`) loops over the group lines.
The table of a block's group lines travels with its :class:`ParsedBlock` (``groups``);
the reader joins them in stream order (:func:`join_line_groups`), across blocks, with a
:class:`GroupCarry` of the groups still open.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from dracc.frames import MISSING_NS
from dracc.ingest.nmea.lines import line_bounds
from dracc.ingest.nmea.parsed import ParsedBlock
from dracc.ingest.tagblock import parse_groups, parse_prefixes

#: a line of a group is looked for at most this many lines after its group's first line
GROUP_WINDOW_LINES = 300


def scan_groups(data: bytes, ignore_checksum: bool = False) -> tuple[dict[str, np.ndarray], int]:
    """The lines of ``data`` whose TAG block has a readable ``g:`` and the number of
    those with an unreadable one: ({line (1-based, the parser's numbering), index, total,
    group (the id), source (``s:``, '' none), ext_ns (``c:``, ``MISSING_NS`` none)}, bad).

    A line counts where its prefix (the text before its first ``$``/``!``) is a TAG
    block :func:`~dracc.ingest.tagblock.parse_prefixes` reads as the parser does (with
    a wrong checksum only under ``ignore_checksum``); ``{}`` where there is none."""
    if data.find(b"g") < 0:  # memchr: the common case costs next to nothing
        return {}, 0
    raw = np.frombuffer(data, dtype=np.uint8)
    g = np.flatnonzero(raw[1:-1] == 103) + 1  # a 'g' with a byte before and after it
    g = g[(raw[g + 1] == 58) & ((raw[g - 1] == 92) | (raw[g - 1] == 44))]  # '\\g:' ',g:'
    if not len(g):
        return {}, 0
    bufp = np.frombuffer(data + bytes(64), dtype=np.uint8)
    line_start, line_end, _, _ = line_bounds(bufp[: len(data)], bufp)
    lines = np.unique(np.searchsorted(line_start, g, side="right") - 1)
    lines = lines[bufp[line_start[lines]] == 92]  # a TAG block at the line's start
    ls = line_start[lines]
    starts = np.flatnonzero((bufp == 36) | (bufp == 33))  # only where a 'g:' is there
    k = np.searchsorted(starts, ls)
    pe = starts[np.minimum(k, max(len(starts) - 1, 0))] if len(starts) else ls
    has = (k < len(starts)) & (pe < line_end[lines])  # a sentence after the TAG block
    lines, ls, pe = lines[has], ls[has], pe[has]
    if not len(lines):
        return {}, 0
    # the TAG blocks end to end in a small buffer (its own cumulative XOR)
    ln = pe - ls
    off = np.zeros(len(ls) + 1, dtype=np.int64)
    np.cumsum(ln, out=off[1:])
    mb = np.concatenate(
        (bufp[np.repeat(ls - off[:-1], ln) + np.arange(int(off[-1]))], np.zeros(64, np.uint8))
    )
    ts, te = off[:-1], off[1:]
    pr = parse_prefixes(mb, ts, te, np.bitwise_xor.accumulate(mb))
    ok = ~pr.bad_tag & (~pr.bad_tag_checksum | ignore_checksum)
    found, good, idx, total, gid = parse_groups(mb, ts, te)
    bad = int(np.count_nonzero(ok & found & ~good))
    sel = ok & good
    if not sel.any():
        return {}, bad
    table = {
        "line": lines[sel] + 1,
        "index": idx[sel],
        "total": total[sel],
        "group": gid[sel],
        "source": np.asarray(pr.source, dtype=object)[sel],
        "ext_ns": pr.ext_ns[sel].astype(np.int64),
    }
    return table, bad


def attach_groups(pb: ParsedBlock, data: bytes, ignore_checksum: bool) -> ParsedBlock:
    """``pb`` (the parse of ``data``) with its table of group lines (:func:`scan_groups`)
    and its unreadable ``g:`` values counted in its stats (``tag_group_bad``)."""
    table, bad = scan_groups(data, ignore_checksum)
    pb.groups = table
    if bad:
        pb.stats["tag_group_bad"] += bad
    return pb


@dataclass
class _Open:
    """A group whose first line was seen: its stream line, n, the last index seen, its
    first line's source and time."""

    line: int
    total: int
    last: int
    source: str
    ext_ns: int


@dataclass
class GroupCarry:
    """The groups still open at the end of the blocks joined so far, by id."""

    open: dict[int, _Open] = field(default_factory=dict)


def resolve_groups(
    table: dict[str, np.ndarray], carry: GroupCarry, line0: int, stats: Counter[str]
) -> dict[str, np.ndarray]:
    """The source and time of each group line of one block (``table`` from
    :func:`scan_groups`, the block's first line the stream's ``line0``), by the rule of
    the module docstring: {line (in the block), source, ext_ns} of the lines joined to
    their first line (a first line is itself: its own), in stream order.  Counts
    ``tag_group_joined`` (lines i > 1 joined) and ``tag_group_incomplete`` in ``stats``."""
    out_line, out_src, out_ext = [], [], []
    for ln, i, n, gid, src, ext in zip(
        table["line"].tolist(),
        table["index"].tolist(),
        table["total"].tolist(),
        table["group"].tolist(),
        table["source"].tolist(),
        table["ext_ns"].tolist(),
        strict=True,
    ):
        at = line0 + ln - 1
        if i == 1:
            if n > 1:
                carry.open[gid] = _Open(at, n, 1, src, ext)
            else:
                carry.open.pop(gid, None)
            continue
        g = carry.open.get(gid)
        if g is None or g.total != n or i <= g.last or at - g.line > GROUP_WINDOW_LINES:
            stats["tag_group_incomplete"] += 1
            if g is not None:  # a stale or different group of a reused id
                del carry.open[gid]
            continue
        g.last = i
        if i == n:
            del carry.open[gid]
        stats["tag_group_joined"] += 1
        out_line.append(ln)
        out_src.append(src or g.source)
        out_ext.append(g.ext_ns if g.ext_ns != MISSING_NS else ext)
    return {
        "line": np.array(out_line, dtype=np.int64),
        "source": np.array(out_src, dtype=object),
        "ext_ns": np.array(out_ext, dtype=np.int64),
    }


def join_line_groups(pb: ParsedBlock, carry: GroupCarry, line0: int, stats: Counter[str]) -> None:
    """Give the records of ``pb``'s group lines (every table: kinds, clock, side tables)
    their group's source and time (:func:`resolve_groups`); ``pb`` is changed, its
    ``source_names`` extended by names it did not have.  Nothing to do without ``g:``."""
    if not pb.groups:
        return
    res = resolve_groups(pb.groups, carry, line0, stats)
    if not len(res["line"]):
        return
    names = pb.source_names
    code_of = {nm: k for k, nm in enumerate(names)}
    codes = np.empty(len(res["line"]), dtype=np.int32)
    for k, nm in enumerate(res["source"].tolist()):
        if nm not in code_of:
            code_of[nm] = len(names)
            names.append(nm)
        codes[k] = code_of[nm]
    order = np.argsort(res["line"], kind="stable")
    lines, codes, ext = res["line"][order], codes[order], res["ext_ns"][order]
    tables = list(pb.kinds.values()) + list(pb.aux.values()) + ([pb.clock] if pb.clock else [])
    for t in tables:
        if not len(t.get("line", ())):
            continue
        rows = np.flatnonzero(np.isin(t["line"], lines))
        if not len(rows):
            continue
        j = np.searchsorted(lines, t["line"][rows])
        src = np.array(t["tag_source"], dtype=np.int32, copy=True)  # may be read-only
        src[rows] = codes[j]
        e = np.array(t["ext_ns"], dtype=np.int64, copy=True)
        e[rows] = ext[j]
        t["tag_source"], t["ext_ns"] = src, e
