"""The cells of a CSV voyage log, shared by its long, wide and raw readers: the time and
raw-sentence column names, the cell parsers (times, numbers, NaN spelled out), blank rows,
and the order of the frames read.

Text cells are Python strings in object arrays: nothing here builds a fixed-width
``<U..`` array (see :mod:`dracc.ingest.csv`).
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import pandas as pd

from dracc.core.errors import IngestError
from dracc.frames import Rejects
from dracc.ingest.csv_quantities import add_rejects

#: a block of CSV rows: column name -> object array of its cells
Columns = dict[str, Any]

TIME_COLUMNS = (
    "time_utc",
    "time_ns",
    "received_at",
    "timestamp",
    "time",
    "datetime",
    "date_time",
    "utc",
    "log_time",
)
RAW_COLUMNS = ("raw_data", "raw", "nmea", "raw_sentence", "sentence_raw")


#: time columns as instruments' exports name them, compared without case, blanks or
#: punctuation, the zone word ``utc``/``gmt`` left out: ``DATE/TIME(UTC)``, ``Time (UTC)``,
#: ``UTC Time``, ``Date Time``.  A name that says ``local`` is never one (not UTC).
_LOOSE_TIME = {"datetime", "time", "timestamp", "dateandtime", "timeanddate", "timeofday"}


def column_name(name: str) -> str:
    """A header name as dracc matches it: without blanks (and quotes) around it, as
    instruments write ``Lat. , Long.``."""
    return name.strip().strip('"').strip()


def find_column(cols: list[str], names: tuple[str, ...]) -> str | None:
    """The first of ``names`` among the columns ``cols`` (any case, blanks around a name
    ignored), as spelled there."""
    low = {column_name(c).lower(): c for c in cols}
    for n in names:
        if n in low:
            return low[n]
    if names is TIME_COLUMNS:
        for c in cols:
            if "local" not in c.lower() and _loose(c) in _LOOSE_TIME:
                return c
    return None


def date_column(cols: list[str], tcol: str) -> str | None:
    """The date column beside a time-of-day column (``Date`` and ``Time (UTC)``, as
    instrument tables give them), or None where the time column holds whole times."""
    if _loose(tcol) not in ("time", "timeofday"):
        return None
    return next((c for c in cols if c != tcol and _loose(c) == "date"), None)


def _loose(name: str) -> str:
    key = re.sub(r"[^a-z]", "", name.lower())
    return re.sub(r"^(utc|gmt)|(utc|gmt)$", "", key)


def required_column(cols: list[str], names: tuple[str, ...]) -> str:
    """:func:`find_column` for a column the form requires (the header check found it)."""
    found = find_column(cols, names)
    if found is None:
        raise IngestError(f"no {names[0]!r} column in the header")
    return found


def parse_times(text: np.ndarray, column: str) -> tuple[np.ndarray, np.ndarray]:
    """(time_ns int64, ok bool) from a column of strings; see "Times" in
    :mod:`dracc.ingest.csv`."""
    s = pd.Series(text, dtype=object)
    n = len(s)
    out = np.zeros(n, dtype=np.int64)
    if column.lower() == "time_ns":
        num = pd.to_numeric(s, errors="coerce")
        ok = num.notna().to_numpy()
        out[ok] = s[ok].astype(np.int64).to_numpy()
        return out, ok
    num = pd.to_numeric(s, errors="coerce").to_numpy(dtype=np.float64)
    isnum = ~np.isnan(num)
    if isnum.any():
        mag = np.abs(num[isnum])
        scale = np.where(mag < 1e11, 1e9, np.where(mag < 1e14, 1e6, np.where(mag < 1e17, 1e3, 1.0)))
        out[isnum] = np.round(num[isnum] * scale).astype(np.int64)
    rest = ~isnum
    ok = isnum.copy()
    if rest.any():
        dt = pd.to_datetime(s[rest], utc=True, format="ISO8601", errors="coerce")
        good = dt.notna().to_numpy()
        vals = (
            dt[good].dt.as_unit("ns").astype("int64").to_numpy()
            if good.any()
            else np.zeros(0, np.int64)
        )
        idx = np.flatnonzero(rest)
        out[idx[good]] = vals
        ok[idx[good]] = True
    return out, ok


def drop_blank_rows(
    data: Columns, lines: np.ndarray, rejects: Rejects, file: str
) -> tuple[Columns, np.ndarray]:
    """The rows of a block without its blank rows (counted as ``blank line``)."""
    blank = np.ones(len(lines), dtype=bool)
    for v in data.values():
        blank &= v == ""
    if blank.any():
        add_rejects(rejects, "blank line", file, lines[blank], [""] * 5)
        keep = ~blank
        data = {k: v[keep] for k, v in data.items()}
        lines = lines[keep]
    return data, lines


def row_times(
    data: Columns, lines: np.ndarray, tcol: str, rejects: Rejects, file: str
) -> tuple[np.ndarray, np.ndarray]:
    """The times of a block's rows (:func:`parse_times`), bad ones counted as ``bad time``."""
    t_ns, ok = parse_times(data[tcol], tcol)
    if not ok.all():
        bad = ~ok
        add_rejects(rejects, "bad time", file, lines[bad], [str(x) for x in data[tcol][bad][:5]])
    return t_ns, ok


def spells_nan(text: np.ndarray, where: np.ndarray) -> np.ndarray:
    """True where ``text`` (an object array of strings) spells NaN in any case, looked at
    only where ``where``: string by string, never as a fixed-width array (``astype(str)``,
    ``np.char``), which would be the number of rows times the longest value in size."""
    out = np.zeros(len(text), dtype=bool)
    idx = np.flatnonzero(where)
    if len(idx):
        out[idx] = np.fromiter(
            (isinstance(x, str) and len(x) == 3 and x.lower() == "nan" for x in text[idx].tolist()),
            dtype=bool,
            count=len(idx),
        )
    return out


def cell_numbers(
    text: np.ndarray, lines: np.ndarray, name: str, rejects: Rejects, file: str
) -> np.ndarray:
    """Floats from strings: '' is absent (NaN); anything else non-numeric is counted."""
    v = pd.to_numeric(pd.Series(text, dtype=object), errors="coerce").to_numpy(dtype=np.float64)
    maybe = np.isnan(v) & (text != "")
    bad = maybe & ~spells_nan(text, maybe)
    if bad.any():
        add_rejects(
            rejects, "value not a number", file, lines[bad], [f"{name}={x}" for x in text[bad][:5]]
        )
    return v


def sorted_frames(frames: dict[str, pd.DataFrame]) -> dict[str, pd.DataFrame]:
    """Each frame in time order (ties in file order)."""
    return {
        k: f.sort_values(["time_ns", "line"], kind="stable").reset_index(drop=True)
        for k, f in frames.items()
    }
