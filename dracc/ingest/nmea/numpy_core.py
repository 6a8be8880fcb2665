"""The vectorised core of the numpy engine: one piece of whole lines (none too long)
parsed without a Python loop over lines: sentence starts, checksums, addresses,
rejects, ignored types, TAG blocks and prefixes, then the fields of each sentence type."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pandas as pd

from dracc.frames import KIND_COLUMNS, MISSING_NS
from dracc.ingest.nmea.fields import Fields, decode
from dracc.ingest.nmea.ins_ais import decode_special, ignored_rows
from dracc.ingest.nmea.lines import Marked, ranges_any
from dracc.ingest.nmea.parsed import ParsedBlock, first_examples
from dracc.ingest.nmea.sentences import (
    FIELD_COUNTS,
    GNSS_TALKERS,
    IGNORED_EXAMPLES,
    NO_GNSS,
    NON_FATAL,
    SENTENCES,
    STANDARD,
)
from dracc.ingest.tagblock import FORMS, HEX, parse_prefixes


def parse_core(
    bufp: np.ndarray,
    buf: np.ndarray,
    line_start: np.ndarray,
    line_end: np.ndarray,
    ends_nl: bool,
    bad: Marked,
    st: np.ndarray,
    ignore_checksum: bool,
    at_eof: bool,
    ext_line_ns: np.ndarray | None,
    ext_line_source: np.ndarray | None,
) -> tuple[ParsedBlock, dict[str, int]]:
    """The vectorised parse of a piece without lines too long (see :func:`parse_numpy`):
    ``st`` the positions of its '$' and '!' bytes."""
    n_lines = len(line_end)
    blank = line_end == line_start
    stats: Counter[str] = Counter()
    stats["blank"] = int(blank.sum())
    counts: Counter[str] = Counter()
    examples: dict[str, list[tuple[int, str]]] = {}
    fatal: list[tuple[int, str, str]] = []

    def reject(reason: str, lines_idx: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> None:
        if len(lines_idx) == 0:
            return
        counts[reason] += len(lines_idx)
        ex = examples.setdefault(reason, [])  # the first 5 of each call: sorted at the end
        for j in range(min(5, len(lines_idx))):
            ex.append(
                (
                    int(lines_idx[j]) + 1,
                    bytes(buf[starts[j] : min(ends[j], starts[j] + 120)]).decode(
                        "ascii", "replace"
                    ),
                )
            )
        if reason not in NON_FATAL:
            j = 0
            fatal.append(
                (
                    int(lines_idx[j]) + 1,
                    reason,
                    bytes(buf[starts[j] : min(ends[j], starts[j] + 120)]).decode(
                        "ascii", "replace"
                    ),
                )
            )

    ignored: Counter[str] = Counter()
    ign_examples: dict[str, list[tuple[int, str]]] = {}

    def ignore(
        names: np.ndarray, lines_idx: np.ndarray, starts: np.ndarray, ends: np.ndarray
    ) -> None:
        """Count valid lines/sentences dracc does not use by type: ``names`` an (n, 8)
        uint8 matrix, the type's ASCII name zero-padded.  One sort over the n rows (as
        integers), a loop over the distinct types only."""
        if len(lines_idx) == 0:
            return
        keys = np.ascontiguousarray(names, dtype=np.uint8).view("<u8").ravel()
        u, inv, cnt = np.unique(keys, return_inverse=True, return_counts=True)
        inv = inv.ravel()
        order = np.argsort(inv, kind="stable")  # the rows of each type, in stream order
        g0 = np.cumsum(cnt) - cnt
        for j, key in enumerate(u.tolist()):
            name = int(key).to_bytes(8, "little").rstrip(b"\0").decode("ascii", "replace")
            ignored[name] += int(cnt[j])
            ex = ign_examples.setdefault(name, [])
            for r in order[g0[j] : g0[j] + min(IGNORED_EXAMPLES, int(cnt[j]))].tolist():
                ex.append(
                    (
                        int(lines_idx[r]) + 1,
                        bytes(buf[starts[r] : min(ends[r], starts[r] + 120)]).decode(
                            "ascii", "replace"
                        ),
                    )
                )

    def named(name: str, n: int) -> np.ndarray:
        m = np.zeros((n, 8), dtype=np.uint8)
        m[:, : len(name)] = np.frombuffer(name.encode(), dtype=np.uint8)
        return m

    # sentence starts: '$' or '!' not immediately followed by another start ('$$GPGGA')
    nxt_is = np.zeros(len(st), dtype=bool)
    nxt_is[:-1] = st[1:] == st[:-1] + 1
    stats["doubled_start"] = int(nxt_is.sum())
    st = st[~nxt_is]
    seg_line = np.searchsorted(line_start, st, side="right") - 1
    # drop starts that sit in the line ends or in comment lines
    keep = st < line_end[seg_line]
    comment_line = ~blank & (buf[np.minimum(line_start, len(buf) - 1)] == 35)
    keep &= ~comment_line[seg_line]
    st, seg_line = st[keep], seg_line[keep]
    nseg = len(st)
    seg_end = np.empty(nseg, dtype=np.int64)
    if nseg:
        seg_end[:-1] = np.where(seg_line[:-1] == seg_line[1:], st[1:], line_end[seg_line[:-1]])
        seg_end[-1] = line_end[seg_line[-1]]
    # trailing spaces/tabs after the checksum are ignored
    # lines without sentences
    has_seg = np.zeros(n_lines, dtype=bool)
    has_seg[seg_line] = True
    noseg = np.flatnonzero(~has_seg & ~blank)
    if len(noseg):
        isbin = bad.any(line_start[noseg], line_end[noseg])
        iscom = comment_line[noseg]
        for reason, m in (("binary", isbin & ~iscom), ("not_nmea", ~isbin & ~iscom)):
            sel = noseg[m]
            reject(reason, sel, line_start[sel], line_end[sel])
        sel = noseg[iscom]
        ignore(named("comment", len(sel)), sel, line_start[sel], line_end[sel])
    if nseg == 0:
        return (
            ParsedBlock(
                n_lines,
                int(blank.sum()),
                {},
                {},
                counts,
                first_examples(examples, 5),
                min(fatal) if fatal else None,
                stats,
                ignored=ignored,
                ignored_examples=first_examples(ign_examples, IGNORED_EXAMPLES),
            ),
            {"": 0} if n_lines else {},
        )

    cum_xor = np.bitwise_xor.accumulate(buf)
    commas = np.flatnonzero(buf == 44)
    # prefixes: text before the first sentence of a line
    first_of_line = np.ones(nseg, dtype=bool)
    first_of_line[1:] = seg_line[1:] != seg_line[:-1]
    line_ext = np.full(n_lines, MISSING_NS, dtype=np.int64)
    line_src = np.full(n_lines, "", dtype=object)
    line_bad = np.zeros(n_lines, dtype=bool)
    pre_seg = np.flatnonzero(first_of_line & (st > line_start[seg_line]))
    if len(pre_seg):
        pl = seg_line[pre_seg]
        pr = parse_prefixes(bufp, line_start[pl], st[pre_seg], cum_xor, None, commas)
        line_ext[pl] = pr.ext_ns
        line_src[pl] = pr.source
        badt = pr.bad_tag | (pr.bad_tag_checksum & (not ignore_checksum))
        line_bad[pl[badt]] = True
        stats["tag_checksum_ignored"] += int((pr.bad_tag_checksum & ignore_checksum).sum())
        for code, f in enumerate(FORMS):
            n_form = int(np.count_nonzero(pr.form == code))
            if n_form:
                stats[f"prefix_{f}"] += n_form
    if ext_line_ns is not None:
        line_ext = np.asarray(ext_line_ns, dtype=np.int64)
    if ext_line_source is not None:
        line_src = np.asarray(ext_line_source, dtype=object)
    src_codes, src_names = pd.factorize(line_src)
    src_codes = src_codes.astype(np.int32)
    src_names = [str(x) for x in src_names]
    _, src_first = np.unique(src_codes, return_index=True)  # codes in order of first appearance
    firsts = dict(zip(src_names, src_first.tolist(), strict=True))
    del line_src

    alive = np.ones(nseg, dtype=bool)

    def drop(reason: str, mask: np.ndarray) -> None:
        idx = np.flatnonzero(mask & alive)
        reject(reason, seg_line[idx], st[idx], seg_end[idx])
        alive[idx] = False

    drop("bad_tag", line_bad[seg_line])
    # trim trailing blanks after the checksum
    drop("binary", bad.any(st, seg_end))
    seglen = seg_end - st
    star_ok = (seglen >= 4) & (buf[np.maximum(seg_end - 3, 0)] == 42)
    h1 = HEX[buf[np.maximum(seg_end - 2, 0)]]
    h2 = HEX[buf[np.maximum(seg_end - 1, 0)]]
    has_cs2 = star_ok & (h1 >= 0) & (h2 >= 0)
    # some loggers drop the leading zero of the checksum ('*5' for '*05')
    has_cs1 = ~has_cs2 & (seglen >= 3) & (buf[np.maximum(seg_end - 2, 0)] == 42) & (h2 >= 0)
    has_cs = has_cs2 | has_cs1
    body_end = np.where(has_cs2, seg_end - 3, np.where(has_cs1, seg_end - 2, seg_end))
    h1 = np.where(has_cs1, 0, h1)
    # a '*' elsewhere without two hex digits after it: cut short
    # '*' inside a sentence without a checksum at its end: cut short
    stray_star = np.zeros(nseg, dtype=bool)
    nocs = np.flatnonzero(~has_cs)
    if len(nocs):  # rare: the buffer's stars are only looked up for these
        stars = np.flatnonzero(buf == 42)
        stray_star[nocs] = ranges_any(stars, st[nocs], seg_end[nocs])
    followed = np.zeros(nseg, dtype=bool)
    followed[:-1] = seg_line[1:] == seg_line[:-1]
    eof_cut = np.zeros(nseg, dtype=bool)
    if at_eof and not ends_nl:
        eof_cut[-1] = seg_line[-1] == n_lines - 1
    drop("truncated", ~has_cs & (followed | stray_star | eof_cut))
    x = cum_xor[np.maximum(body_end - 1, 0)] ^ cum_xor[st]  # XOR over (start, body_end)
    given = h1.astype(np.int64) * 16 + h2
    wrong = has_cs & (x.astype(np.int64) != given)
    if ignore_checksum:
        stats["checksum_ignored"] += int((wrong & alive).sum())
    else:
        drop("checksum", wrong)
    stats["no_checksum"] += int((~has_cs & alive).sum())
    stats["one_digit_checksum"] += int((has_cs1 & alive).sum())
    # address
    # the commas of each sentence body: [c_first, c_first + ncomma) in the comma table
    c_first = np.searchsorted(commas, st)
    ncomma = np.searchsorted(commas, body_end) - c_first
    first_comma = np.where(
        ncomma > 0,
        commas[np.minimum(c_first, max(len(commas) - 1, 0))] if len(commas) else 0,
        body_end,
    )
    addr_len = np.where(first_comma < body_end, first_comma - st - 1, body_end - st - 1)
    a5 = st[:, None] + 1 + np.arange(5)
    amat = buf[np.minimum(a5, len(buf) - 1)]
    alnum = ((amat >= 65) & (amat <= 90)) | ((amat >= 48) & (amat <= 57))
    proprietary = amat[:, 0] == 80  # 'P'
    good_addr = (
        (addr_len == 5)
        & alnum.all(axis=1)
        & np.all((amat[:, 2:] >= 65) & (amat[:, 2:] <= 90), axis=1)
    )
    ais = buf[st] == 33

    def drop_ignored(mask: np.ndarray, width: int) -> None:
        """Valid sentences dracc does not use: counted by their first ``width`` address
        characters (from the talker on; 'GSV' for the type: width 3 from index 2)."""
        idx = np.flatnonzero(mask & alive)
        if len(idx) == 0:
            return
        m = np.zeros((len(idx), 8), dtype=np.uint8)
        if width == 3:  # the sentence type
            m[:, :3] = amat[idx, 2:5]
        else:  # a proprietary address, up to its first 5 characters
            m[:, :5] = np.where(np.arange(5) < addr_len[idx, None], amat[idx], 0)
        ignore(m, seg_line[idx], st[idx], seg_end[idx])
        alive[idx] = False

    talker_b = np.ascontiguousarray(amat[:, :2]).view("S2").ravel()
    kinds: dict[str, dict[str, list[np.ndarray]]] = {}
    aux: dict[str, dict[str, list[np.ndarray]]] = {}

    def group(stype: str, rows: np.ndarray) -> tuple[np.ndarray, Fields | None]:
        """The rows of one sentence type with the right field count, and their fields."""
        F = Fields(bufp, commas, c_first[rows], ncomma[rows], body_end[rows])
        lo, hi = FIELD_COUNTS[stype]
        badn = (F.nf < lo) | (F.nf > hi)
        if badn.any():
            drop("field_count", np.isin(np.arange(nseg), rows[badn]))
            rows = rows[~badn]
            if len(rows) == 0:
                return rows, None
            F = Fields(bufp, commas, c_first[rows], ncomma[rows], body_end[rows])
        return rows, F

    def malformed(F: Fields, rows: np.ndarray) -> np.ndarray:
        if F.bad.any():
            drop("malformed_field", np.isin(np.arange(nseg), rows[F.bad]))
        return ~F.bad

    def emit(
        stype: str,
        rows: np.ndarray,
        timing: dict[str, np.ndarray],
        name: str,
        d: dict[str, np.ndarray],
        talker: np.ndarray | None = None,
    ) -> None:
        """Append the rows of one group to a kind (or to a side table, ``aux``)."""
        common = {
            "line": seg_line[rows] + 1,
            "seq": rows,
            "talker": talker_b[rows].view(np.uint16) if talker is None else talker,
            "sentence": np.full(len(rows), SENTENCES.index(stype), dtype=np.int8),
            "tag_source": src_codes[seg_line[rows]],
            "ext_ns": line_ext[seg_line[rows]],
            **timing,
        }
        if name in KIND_COLUMNS:
            for c, t in KIND_COLUMNS[name].items():  # every group carries every column
                if c not in d and t == "float64":
                    d[c] = np.full(len(rows), np.nan)
            tgt = kinds.setdefault(name, {})
        else:
            tgt = aux.setdefault(name, {})
        for c, v in {**common, **d}.items():
            tgt.setdefault(c, []).append(v)

    # INS and own-ship AIS sentences (ins_ais): a proprietary address or '!', before the
    # proprietary and AIS sentences are ignored and the 5-character addresses checked
    prop_rows = np.flatnonzero(alive & proprietary)  # few: the masks are taken on these only
    at4 = np.ascontiguousarray(amat[prop_rows, :4]).view("S4").ravel()
    ai = np.flatnonzero(alive & ais & good_addr)
    specials = {
        "PASHR": prop_rows[
            (addr_len[prop_rows] == 5) & (at4 == b"PASH") & (amat[prop_rows, 4] == 82)
        ],
        "PSXN": prop_rows[(addr_len[prop_rows] == 4) & (at4 == b"PSXN")],
        "VDO": ai[np.ascontiguousarray(amat[ai, 2:]).view("S3").ravel() == b"VDO"],
    }
    for stype, rows in specials.items():
        if len(rows) == 0:
            continue
        F = Fields(bufp, commas, c_first[rows], ncomma[rows], body_end[rows])
        ign = ignored_rows(stype, F)
        drop_ignored(np.isin(np.arange(nseg), rows[ign]), 3 if stype == "VDO" else 5)
        rows, F2 = group(stype, rows[~ign]) if (~ign).any() else (rows[:0], None)
        if F2 is None:
            continue
        out, timing = decode_special(stype, F2)
        ok = malformed(F2, rows)
        used = np.zeros(len(rows), dtype=bool)
        for _, (m, _d) in out.items():
            used |= m
        drop_ignored(np.isin(np.arange(nseg), rows[ok & ~used]), 3 if stype == "VDO" else 5)
        alive[rows] = False
        tk = None if stype == "VDO" else np.zeros(len(rows), dtype=np.uint16)  # no talker
        for name, (m, d) in out.items():
            keep = m & ok
            if keep.any():
                emit(
                    stype,
                    rows[keep],
                    {k: v[keep] for k, v in timing.items()},
                    name,
                    {c: v[keep] for c, v in d.items()},
                    None if tk is None else tk[keep],
                )

    drop_ignored(proprietary & (addr_len >= 2), 5)
    drop_ignored(ais & good_addr, 3)  # AIS: 'VDM', 'VDO' (an unreadable address is damage)
    drop("bad_address", ~good_addr)
    stype_b = np.ascontiguousarray(amat[:, 2:]).view("S3").ravel()
    known_types = np.array([s.encode() for s in STANDARD], dtype="S3")
    is_known = np.isin(stype_b, known_types)
    drop_ignored(~is_known, 3)
    gnss_t = np.isin(talker_b, np.array([t.encode() for t in GNSS_TALKERS], dtype="S2"))
    no_gnss = np.isin(stype_b, np.array([t.encode() for t in NO_GNSS], dtype="S3"))
    drop("implausible_talker", gnss_t & no_gnss)

    for stype in STANDARD:
        rows = np.flatnonzero(alive & (stype_b == stype.encode()))
        if len(rows) == 0:
            continue
        rows, Fg = group(stype, rows)
        if Fg is None:
            continue
        F = Fg
        cols, timing = decode(stype, F)
        okr = malformed(F, rows)
        if not okr.all():
            rows = rows[okr]
            cols = {k: {c: v[okr] for c, v in d.items()} for k, d in cols.items()}
            timing = {k: v[okr] for k, v in timing.items()}
            if len(rows) == 0:
                continue
        if stype == "ZDA":
            emit(stype, rows, timing, "clock", {})
        for kind, d in cols.items():
            emit(stype, rows, timing, kind, d)

    def in_order(parts: dict[str, list[np.ndarray]]) -> dict[str, np.ndarray]:
        cat = {c: np.concatenate(v) for c, v in parts.items()}
        order = np.argsort(cat["seq"], kind="stable")  # back to stream order
        return {c: v[order] for c, v in cat.items()}

    kinds_np = {k: in_order(parts) for k, parts in kinds.items()}
    clock_np = {c: np.concatenate(v) for c, v in aux.pop("clock", {}).items()}
    aux_np = {k: in_order(parts) for k, parts in aux.items()}
    return (
        ParsedBlock(
            n_lines,
            int(blank.sum()),
            kinds_np,
            clock_np,
            counts,
            first_examples(examples, 5),
            min(fatal) if fatal else None,
            stats,
            src_names,
            ignored,
            first_examples(ign_examples, IGNORED_EXAMPLES),
            nseg,
            aux_np,
        ),
        firsts,
    )
