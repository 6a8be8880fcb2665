"""Compact columns for the frames an MCAP log gives: constant categoricals, the smallest
integer codes for labels, and :class:`_KindStore`, which keeps the records of one kind in
sorted runs in their own memory mappings and merges them into the output frame step by
step (the working memory does not grow with the file)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from dracc.ingest.memory import mapped_columns


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
        self.how: dict[str, tuple[str, Any]] = {}
        self.labels: dict[str, dict[Any, int]] = {}  #: label column -> {label: code}
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
        in_store: np.ndarray = lut[codes].astype(_code_dtype(len(known)))
        return in_store

    def frame(self) -> pd.DataFrame:
        """The merged frame (see the class doc); the runs are released on the way."""
        out: dict[str, Any] = {}
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


def _strings(codes: np.ndarray, labels: list[Any], dtype: Any) -> object:
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
