"""Writing the records table of ``dracc records`` (:mod:`dracc.pipeline.records`).

``--out FILE.parquet``: Parquet written with pyarrow, one row group per chunk of the
table; ``time_utc`` and ``recv_utc`` are ``timestamp[ns, tz=UTC]``, the text columns
strings, ``fix_quality`` int8, a missing value NULL.  ``--out FILE.csv``: CSV with a
header, times ISO 8601 with ``Z`` (as many fractional digits as the log's times need),
a missing value an empty cell, numbers to 15 significant digits (a degree converted
from radians shows as the log wrote it, ``12.95``, not ``12.949999999999998``; Parquet
keeps the exact doubles), a text that a spreadsheet would run as a formula quoted with
a leading ``'``.  ``--out -``: the CSV on standard output (Parquet is a file format
with its index at the end: it is not written to standard output).

Files are written atomically (:func:`dracc.core.atomic.atomic_path`): an interrupted or
failed write leaves no partial file and an earlier file as it was.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from typing import Literal

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq
from numpy.typing import NDArray

from dracc.core import atomic
from dracc.core.errors import OptionError
from dracc.core.safetext import csv_cell
from dracc.pipeline.records import CHUNK_ROWS, COLUMNS, TEXT_COLUMNS, Records

STDOUT = "-"
_Unit = Literal["s", "ms", "us", "ns"]
#: fractional digits of a second -> the datetime unit that shows them
_UNITS: dict[int, _Unit] = {0: "s", 3: "ms", 6: "us", 9: "ns"}
#: what ``--out`` may end in, and the form it writes
FORMS = {".parquet": "parquet", ".csv": "csv"}
_TIMES = ("time_utc", "recv_utc")
#: significant digits of a CSV number (of the largest value of its column in a chunk)
CSV_DIGITS = 15


def _type(name: str) -> pa.DataType:
    if name in _TIMES:
        return pa.timestamp("ns", tz="UTC")
    if name in TEXT_COLUMNS:
        return pa.string()
    return {"line": pa.int64(), "fix_quality": pa.int8()}.get(name, pa.float64())


#: the Parquet schema: :data:`dracc.pipeline.records.COLUMNS`, in order
SCHEMA = pa.schema([pa.field(name, _type(name)) for name in COLUMNS])


def output_form(target: str) -> str:
    """``'parquet'`` or ``'csv'`` for ``--out target`` (``-``: CSV on standard output);
    anything else is an :class:`OptionError` (exit 2) naming the forms."""
    if target == STDOUT:
        return "csv"
    form = FORMS.get(Path(target).suffix.lower())
    if form is None:
        raise OptionError(
            f"--out {target!r}: expected FILE.parquet, FILE.csv, or - for CSV on "
            "standard output (Parquet is not written to standard output)"
        )
    return form


def write_records(records: Records, target: str, rows: int = CHUNK_ROWS) -> str:
    """Write ``records`` to ``target`` (its form from :func:`output_form`), ``rows`` rows
    at a time; returns the line that says what was written."""
    form = output_form(target)
    if target == STDOUT:
        _csv(records, _stdout, rows)
        sys.stdout.flush()
        return f"wrote {records.rows} records to standard output"
    with atomic.atomic_path(target) as tmp:
        if form == "parquet":
            with pq.ParquetWriter(tmp, SCHEMA) as writer:
                for chunk in records.chunks(rows):
                    writer.write_table(arrow_table(chunk), row_group_size=rows)
        else:
            with open(tmp, "wb") as fh:
                _csv(records, fh.write, rows)
    return f"wrote {records.rows} records to {target}"


def arrow_table(chunk: pd.DataFrame) -> pa.Table:
    """A chunk of the records table as an Arrow table of :data:`SCHEMA` (NaN as NULL)."""
    return pa.Table.from_pandas(chunk, preserve_index=False).cast(SCHEMA)


def _stdout(data: bytes) -> None:
    buffer = getattr(sys.stdout, "buffer", None)
    if buffer is None:  # standard output replaced by a text-only stream
        sys.stdout.write(data.decode("utf-8"))
    else:
        buffer.write(data)


def _csv(records: Records, write: Callable[[bytes], object], rows: int) -> None:
    for k, chunk in enumerate(records.chunks(rows)):
        sink = pa.BufferOutputStream()
        options = pa_csv.WriteOptions(include_header=k == 0)
        pa_csv.write_csv(csv_table(chunk, records.time_digits), sink, options)
        write(sink.getvalue().to_pybytes())


def csv_table(chunk: pd.DataFrame, time_digits: int = 9) -> pa.Table:
    """A chunk of the records table as the Arrow table its CSV is written from: times as
    ISO 8601 text with ``time_digits`` fractional digits and ``Z``, numbers rounded to
    :data:`CSV_DIGITS` significant digits, formula-like texts quoted."""
    unit = _UNITS.get(time_digits, "ns")
    columns = []
    for name in COLUMNS:
        col = chunk[name]
        if name in _TIMES:
            columns.append(_iso(col.dt.tz_convert("UTC").dt.tz_localize(None).to_numpy(), unit))
        elif name in TEXT_COLUMNS:
            columns.append(pa.array(_safe_text(col), type=pa.dictionary(pa.int32(), pa.string())))
        elif col.dtype == np.float64:
            columns.append(pa.array(_rounded(col.to_numpy()), from_pandas=True))
        else:
            columns.append(pa.array(col, from_pandas=True))
    return pa.Table.from_arrays(columns, names=list(COLUMNS))


def _iso(t: NDArray[np.datetime64], unit: _Unit) -> pa.DictionaryArray:
    """ISO 8601 texts of the datetimes ``t`` (NULL for NaT), each distinct time formatted
    once (a day's log holds some 30 records per second)."""
    distinct, at = np.unique(t, return_inverse=True)
    text = np.char.add(np.datetime_as_string(distinct, unit=unit), "Z")
    return pa.DictionaryArray.from_arrays(pa.array(at.ravel(), mask=np.isnat(t)), text)


def _safe_text(col: pd.Series) -> pd.Series:
    """A categorical text column with every formula-like label quoted (:func:`csv_cell`)."""
    labels = [csv_cell(str(c)) for c in col.cat.categories]
    if len(set(labels)) == len(labels):
        return col.cat.rename_categories(labels)
    return col.astype(object).map(csv_cell, na_action="ignore").astype("category")


def _rounded(x: np.ndarray) -> np.ndarray:
    """``x`` rounded to :data:`CSV_DIGITS` significant digits of its largest value."""
    finite = np.abs(x[np.isfinite(x)])
    if not finite.size or not finite.max():
        return x
    decimals = CSV_DIGITS - 1 - int(np.floor(np.log10(finite.max())))
    return np.round(x, min(max(decimals, 0), 17))
