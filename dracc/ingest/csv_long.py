"""The long form of a CSV voyage log (``time_utc,source,quantity,value``, one value per
row): rows become records by (time, source, occurrence), streamed block by block when the
file is sorted by time (:func:`read_long`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np
import pandas as pd

from dracc.core.quantities import QUANTITIES, REF_QUANTITIES
from dracc.frames import Rejects, concat_blocks
from dracc.ingest.csv_cells import (
    TIME_COLUMNS,
    Columns,
    cell_numbers,
    drop_blank_rows,
    find_column,
    required_column,
    row_times,
    sorted_frames,
    spells_nan,
)
from dracc.ingest.csv_quantities import add_rejects, build_frames

#: the blocks of a CSV: rejects -> (column -> object array, file line numbers) per block
Blocks = Callable[[Rejects], Iterator[tuple[Columns, np.ndarray]]]
#: frame kind -> canonical frame, and the number of rows read
FramesAndRows = tuple[dict[str, pd.DataFrame], int]


class Labels:
    """Strings as small integer codes, the same code for the same string in every block
    (one Python string per distinct label, not one per row)."""

    def __init__(self) -> None:
        self.code: dict[str, int] = {}

    def codes(self, text: np.ndarray) -> np.ndarray:
        local, uniq = pd.factorize(text)
        lut = np.array(
            [self.code.setdefault(str(u), len(self.code)) for u in uniq] or [0], dtype=np.int32
        )
        return lut[local]

    def labels(self) -> np.ndarray:
        return np.array(list(self.code), dtype=object)


class Unsorted(Exception):
    """A long-form CSV row whose time was already made into records (the file is not
    sorted by time): the file is read again, all rows at once."""


def read_long(
    blocks: Blocks,
    stem: str,
    cols: list[str],
    declared: dict[str, str],
    rejects: Rejects,
    file: str,
) -> FramesAndRows:
    """One value per row: rows become records by (time, source, occurrence).

    In a file sorted by time, the rows of a time are complete once a later time is seen:
    each block's rows up to its last time become records at once, so the memory holds a
    block and its frames.  A row older than rows already made into records means the file
    is not sorted: it is then read again with every row kept as numbers (time in ns, source
    and quantity as codes, the value, the line: about 40 bytes a row) and the rows of the
    whole file become records together.  Both give the same frames."""
    mine = Rejects()
    try:
        frames, rows = read_long_pass(blocks, stem, cols, declared, mine, file, streaming=True)
    except Unsorted:
        mine = Rejects()  # what the first pass counted is counted again
        frames, rows = read_long_pass(blocks, stem, cols, declared, mine, file, streaming=False)
    rejects.merge(mine)
    return frames, rows


#: rows not yet made into records: (t, source, quantity, value, line, reference text)
Rows = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def _stack(blocks: list[Rows]) -> Rows:
    t, s, q, v, ln, ref = (np.concatenate([b[i] for b in blocks]) for i in range(6))
    return t, s, q, v, ln, ref


def _take(rows: Rows, mask: np.ndarray) -> Rows:
    t, s, q, v, ln, ref = (x[mask] for x in rows)
    return t, s, q, v, ln, ref


def read_long_pass(
    blocks: Blocks,
    stem: str,
    cols: list[str],
    declared: dict[str, str],
    rejects: Rejects,
    file: str,
    streaming: bool,
) -> FramesAndRows:
    """One pass of :func:`read_long`: ``streaming`` makes records block by block (raising
    :class:`Unsorted` at a row older than those), else from all the rows at the end."""
    tcol = required_column(cols, TIME_COLUMNS)
    scol = find_column(cols, ("source",))
    qcol = required_column(cols, ("quantity",))
    vcol = required_column(cols, ("value",))
    sources, quantities = Labels(), Labels()
    #: rows not yet made into records: (t, source, quantity, value, line, reference text)
    held: list[Rows] = []
    parts: list[dict[str, pd.DataFrame]] = []
    done_upto: int | None = None  #: the latest time made into records (streaming)
    rows = 0
    for data, lines in blocks(rejects):
        rows += len(lines)
        data, lines = drop_blank_rows(data, lines, rejects, file)
        t_ns, ok = row_times(data, lines, tcol, rejects, file)
        qname = data[qcol]
        qmapped = quantity_names(qname, declared)
        known = np.isin(qmapped, list(QUANTITIES))
        unk = ok & ~known
        if unk.any():
            add_rejects(
                rejects, "unknown quantity", file, lines[unk], [str(q) for q in qname[unk][:5]]
            )
        val = data[vcol]
        empty = ok & known & (val == "")
        if empty.any():
            add_rejects(
                rejects, "empty value", file, lines[empty], [str(q) for q in qname[empty][:5]]
            )
        keep = ok & known & ~empty
        isref = np.isin(qmapped, list(REF_QUANTITIES))
        num = np.full(len(val), np.nan)
        nr = keep & ~isref
        if nr.any():
            num[nr] = cell_numbers(val[nr], lines[nr], "value", rejects, file)
            maybe = nr & np.isnan(num)
            keep &= ~(maybe & ~spells_nan(val, maybe))
        src = data[scol] if scol else np.full(len(val), stem, dtype=object)
        k = np.flatnonzero(keep)
        if len(k) == 0:
            continue
        ref: np.ndarray = np.where(isref[k], val[k], None)  # type: ignore[assignment]  # numpy stubs: where(c, x, None) is an array
        block = (
            t_ns[k],
            sources.codes(src[k]),
            quantities.codes(qmapped[k]),
            num[k],
            lines[k],
            ref,
        )
        if not streaming:
            held.append(block)
            continue
        if done_upto is not None and block[0].min() <= done_upto:
            raise Unsorted
        rows_now = _stack([*held, block])
        t_last = rows_now[0].max()
        complete = rows_now[0] < t_last
        if complete.any():
            parts.append(
                long_records(*_take(rows_now, complete), sources, quantities, file, rejects)
            )
            done_upto = int(rows_now[0][complete].max())
        held = [_take(rows_now, ~complete)]
    if held and len(held[0][0]):
        rows_now = _stack(held)
        held = []
        parts.append(long_records(*rows_now, sources, quantities, file, rejects))
    return sorted_frames(concat_blocks(parts, every_kind=False)), rows


def quantity_names(qname: np.ndarray, declared: dict[str, str]) -> np.ndarray:
    """The quantity each row names: its cell without blanks around it (`` lat_deg``), or
    what ``[ingest.quantities]`` maps that name to; one look-up per distinct name."""
    codes, uniq = pd.factorize(qname)
    if not len(uniq):
        return qname
    names = [str(u).strip() for u in uniq]
    lut = np.array([declared.get(n, n) for n in names], dtype=object)
    return lut[codes]


def long_records(
    t_ns: np.ndarray,
    sc: np.ndarray,
    qc: np.ndarray,
    num: np.ndarray,
    lines: np.ndarray,
    ref: np.ndarray,
    sources: Labels,
    quantities: Labels,
    file: str,
    rejects: Rejects,
) -> dict[str, pd.DataFrame]:
    """Frames from long-form rows: one record per (time, source, occurrence), the n-th value
    of a quantity at one time and source belonging to the n-th record there (a GGA and an
    RMC fix of one receiver at one time)."""
    occ = occurrence(t_ns, sc, qc)
    order = np.lexsort((occ, sc, t_ns))  # records: runs of equal (time, source, occurrence)
    ts, ss, os_ = t_ns[order], sc[order], occ[order]
    starts = np.r_[True, (ts[1:] != ts[:-1]) | (ss[1:] != ss[:-1]) | (os_[1:] != os_[:-1])]
    rec = np.empty(len(order), dtype=np.int64)
    rec[order] = np.cumsum(starts) - 1
    t_rec, s_codes = ts[starts], ss[starts]
    del ts, ss, os_, order
    nrec = len(t_rec)
    first_line = np.full(nrec, np.iinfo(np.int64).max)
    np.minimum.at(first_line, rec, lines)
    values: dict[str, np.ndarray] = {}
    qlabels = quantities.labels()
    for code in pd.unique(qc):
        m = qc == code
        r = rec[m]  # distinct within a quantity, by construction of the key
        q = str(qlabels[code])
        if q in REF_QUANTITIES:
            arr = np.full(nrec, None, dtype=object)
            arr[r] = ref[m]
        else:
            arr = np.full(nrec, np.nan)
            arr[r] = num[m]
        values[q] = arr
    return build_frames(t_rec, sources.labels()[s_codes], first_line, "csv", values, file, rejects)


def occurrence(t: np.ndarray, s: np.ndarray, q: np.ndarray) -> np.ndarray:
    """For each row, how many rows before it (in file order) have its time, source and
    quantity: 0 for the first value of a quantity at a time and source, 1 for the second."""
    order = np.lexsort((q, s, t))  # stable: file order within equal keys
    ts, ss, qs = t[order], s[order], q[order]
    idx = np.arange(len(order))
    new = np.r_[True, (ts[1:] != ts[:-1]) | (ss[1:] != ss[:-1]) | (qs[1:] != qs[:-1])]
    occ = np.empty(len(order), dtype=np.int32)
    occ[order] = idx - np.maximum.accumulate(np.where(new, idx, 0))
    return occ
