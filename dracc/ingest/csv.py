"""CSV voyage logs: long form, wide form, and loggers' CSV of raw sentences.

Three forms, told apart by the header (first line; a UTF-8 BOM is skipped; comma-separated,
fields with commas quoted as usual):

long (``csv-long``)
    ``time_utc,source,quantity,value`` -- one value per row; ``quantity`` is a name from
    :mod:`dracc.ingest.csv_quantities` with its unit in the name (``lat_deg``, ``stw_kn``,
    ``sog_mps``, ``reference`` ...).  Rows of one time and source make one record; where a
    quantity repeats at one time and source, its n-th value belongs to the n-th record there.
wide (``csv-wide``)
    ``time_utc,source,<quantity>,<quantity>,...`` -- one row per time and source; every
    column named by a quantity (or declared in ``[ingest] quantities``) is read, others are
    listed in the notes as ignored.  ``source`` is optional (the file stem is used).
raw (``csv-raw``)
    a time column (``received_at``, ``time_utc``, ``timestamp`` ...) and a column of raw
    NMEA 0183 sentences (``raw_data``, ``raw``, ``nmea``, ``raw_sentence``); an optional
    ``source`` column gives the source key; rows whose ``protocol`` names NMEA 2000
    (OpenCPN's data logger: the message as Actisense BST bytes in hex) are decoded by
    :mod:`dracc.ingest.n2k`, timed by their row; sentences dracc does not use are
    ignored by type as in NMEA text.  Sentences go through :func:`dracc.ingest.nmea.parse_sentences`.

Times: a ``time_ns`` column holds integer nanoseconds since the Unix epoch; any other
time column holds ISO 8601 text (a zone-less time is UTC, as the column name says) or
numbers since the Unix epoch whose unit follows from their size (below 1e11 seconds,
below 1e14 milliseconds, below 1e17 microseconds, else nanoseconds: unambiguous for dates
between 1973 and 5138).

The cell parsers are in :mod:`dracc.ingest.csv_cells`, the long form's records in
:mod:`dracc.ingest.csv_long`; this module tells the forms apart, scans and streams the
file, and reads the wide and raw forms.

Reading streams the file in blocks (pyarrow's incremental CSV reader), so memory holds
one block of text plus the compact numeric columns.  Bad rows are counted by reason with
their line numbers (line 1 is the header): wrong number of fields, blank line, bad time,
unknown quantity, value not a number, empty value, implausible value.

Hostile input: memory is bounded by ``[ingest] max_line_bytes``, not by the content.  A
first pass over the file (:func:`_scan`, 4 MiB at a time, which also checks the UTF-8)
finds every row longer than that; those rows are left out of what pyarrow reads and
counted as ``too_long`` with their line numbers (a row of 10 MB used to fail the whole
file: pyarrow cannot parse a row longer than its block).  Text cells stay Python strings
in object arrays end to end: nothing builds a fixed-width ``<U..`` array, whose size
would be the number of rows times the longest value (a 16 kB value in a long-form file
of 30 000 rows took 3.8 GB).
"""

from __future__ import annotations

import codecs
import csv as stdcsv
import functools
import io
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from dracc.core.config import IngestConfig
from dracc.core.errors import ConfigError, IngestError
from dracc.core.quantities import REF_QUANTITIES
from dracc.frames import FileResult, Rejects, concat_blocks
from dracc.ingest.csv_cells import (
    RAW_COLUMNS,
    TIME_COLUMNS,
    Columns,
    cell_numbers,
    column_name,
    date_column,
    drop_blank_rows,
    find_column,
    parse_times,
    required_column,
    row_times,
    sorted_frames,
)
from dracc.ingest.csv_long import FramesAndRows, read_long
from dracc.ingest.csv_quantities import (
    UNITLESS_HINTS,
    add_rejects,
    build_frames,
    check_declared,
    lookup,
    renumber_examples,
)

__all__ = ["RAW_COLUMNS", "TIME_COLUMNS", "looks_like_csv", "parse_times", "read_csv"]

_BLOCK_BYTES = 4 << 20


def header_delimiter(head: bytes) -> str:
    """The delimiter of a table whose first bytes are ``head``: a tab where its first line
    has more tabs than commas (instruments' tab-separated exports), else a comma."""
    first = head.split(b"\n", 1)[0]
    return "\t" if first.count(b"\t") > first.count(b",") else ","


def raw_header(head: bytes, delimiter: str = ",") -> list[str] | None:
    """The names of the first line of ``head`` as written (blanks kept, quotes as a CSV
    parser reads them), or None where it is no table header."""
    if head.startswith(b"\xef\xbb\xbf"):
        head = head[3:]
    first = head.split(b"\n", 1)[0].rstrip(b"\r")
    try:
        text = first.decode("utf-8")
    except UnicodeDecodeError:
        return None
    if not text or text[0] in "$!\\" or delimiter not in text:
        return None
    return next(stdcsv.reader([text], delimiter=delimiter), None)


def _split_header(head: bytes, delimiter: str = ",") -> list[str] | None:
    """The header names as dracc matches them: blanks around each name left out
    (``Lat. , Long.`` names ``Lat.`` and ``Long.``)."""
    raw = raw_header(head, delimiter)
    return None if raw is None else [column_name(c) for c in raw]


def looks_like_csv(head: bytes) -> bool:
    """True when the first line of ``head`` is a header dracc reads: a time column and
    either ``quantity,value``, a raw-sentence column, or at least one other column;
    comma- or tab-separated (:func:`header_delimiter`)."""
    cols = _split_header(head, header_delimiter(head))
    if not cols or len(cols) < 2:
        return False
    return find_column(cols, TIME_COLUMNS) is not None


def _form(cols: list[str]) -> str:
    low = {c.lower() for c in cols}
    if {"quantity", "value"} <= low:
        return "csv-long"
    if find_column(cols, RAW_COLUMNS) is not None:
        return "csv-raw"
    return "csv-wide"


def _line_numbers(k0: int, n: int, invalid_lines: list[int]) -> np.ndarray:
    """File line numbers of valid data rows k0..k0+n-1, given the skipped rows' lines.

    Valid row k (0-based) is on line ``k + 2 + j``, j the number of skipped rows before
    it; skipped row i (sorted) has ``L_i - 2 - i`` valid rows before it.
    """
    k = np.arange(k0, k0 + n, dtype=np.int64)
    if not invalid_lines:
        return k + 2
    inv = np.sort(np.asarray(invalid_lines, dtype=np.int64))
    before = inv - 2 - np.arange(len(inv))
    return k + 2 + np.searchsorted(before, k, side="right")


@dataclass
class _Scan:
    """What the first pass over a CSV found: its codec and the rows too long to read."""

    encoding: str = "utf8"
    delimiter: str = ","  #: a comma, or a tab (:func:`header_delimiter`)
    names: list[str] = field(default_factory=list)  #: the header's names as written
    #: rows longer than the limit: (file line number, byte offset, end offset incl. the line
    #: end, length without the line end, their first bytes)
    long_rows: list[tuple[int, int, int, int, bytes]] = field(default_factory=list)
    longest: int = 0  #: the longest row that is read (bytes)

    @property
    def drops(self) -> list[tuple[int, int]]:
        return [(a, b) for _, a, b, _, _ in self.long_rows]

    @property
    def lines(self) -> list[int]:
        return [ln for ln, *_ in self.long_rows]


_HEAD = 40  #: bytes of a too-long row kept as its example


def _scan(path: Path, max_line: int) -> _Scan:
    """One pass over the file, a block at a time: is it valid UTF-8 (else a codec that
    decodes bad bytes to U+FFFD; see below), and which rows are longer than ``max_line``
    bytes.  A row ends at ``\\n``, ``\\r\\n`` or a lone ``\\r`` (as pyarrow reads it).

    pyarrow cannot hand a row with invalid UTF-8 to the invalid-row handler (it prints an
    ignored UnicodeDecodeError and fails the whole file); decoded with replacement, such
    a row is read and its bad cells are counted like any other unreadable value.
    """
    out = _Scan()
    dec = codecs.getincrementaldecoder("utf-8")()
    utf8 = True
    line = 1  #: number of the row being scanned
    start = 0  #: its byte offset
    head = b""  #: its first bytes
    at = 0  #: file offset of ``buf``
    carry = b""
    with path.open("rb") as fh:
        while True:
            block = fh.read(_BLOCK_BYTES)
            eof = not block
            buf = carry + block
            carry = b""
            if not eof and buf.endswith(b"\r"):  # a CR LF may straddle the blocks
                buf, carry = buf[:-1], b"\r"
            if utf8:
                try:
                    dec.decode(block, final=eof)
                except UnicodeDecodeError:
                    utf8 = False
            if not buf:
                if eof:
                    break
                continue
            b = np.frombuffer(buf, dtype=np.uint8)
            nxt = np.empty_like(b)
            nxt[:-1] = b[1:]
            nxt[-1] = 0
            ends = np.flatnonzero((b == 10) | ((b == 13) & (nxt != 10)))  # offsets in buf
            if len(ends):
                starts = np.empty(len(ends), dtype=np.int64)
                starts[0] = start - at
                starts[1:] = ends[:-1] + 1
                crlf = (b[np.maximum(ends - 1, 0)] == 13) & (b[ends] == 10) & (ends > starts)
                lens = ends - starts - crlf.astype(np.int64)  # without the line end
                over = np.flatnonzero(lens > max_line)
                ok = np.ones(len(lens), dtype=bool)
                ok[over] = False
                if ok.any():
                    out.longest = max(out.longest, int(lens[ok].max()))
                if start < at:  # the row that began in an earlier block ends here
                    head += bytes(buf[: max(min(_HEAD - len(head), int(ends[0])), 0)])
                for i in over.tolist():
                    a = int(starts[i]) + at
                    first = head if i == 0 and a < at else bytes(buf[a - at : a - at + _HEAD])
                    out.long_rows.append((line + i, a, int(ends[i]) + at + 1, int(lens[i]), first))
                line += len(ends)
                start = int(ends[-1]) + 1 + at
                head = bytes(buf[start - at : start - at + _HEAD])
            elif start >= at:
                head = bytes(buf[start - at : start - at + _HEAD])
            elif len(head) < _HEAD:
                head += bytes(buf[: _HEAD - len(head)])
            at += len(buf)
            if eof:
                break
        if start < at:  # a last row without a line end
            n = at - start
            if n > max_line:
                out.long_rows.append((line, start, at, n, head))
            else:
                out.longest = max(out.longest, n)
    if not utf8:
        out.encoding = _REPLACE_CODEC
    return out


class _Without(io.RawIOBase):
    """A file read without some byte ranges (sorted, disjoint): the rows too long to read."""

    def __init__(self, path: Path, drops: list[tuple[int, int]]):
        self.fh = path.open("rb")
        self.drops = drops
        self.i = 0
        self.pos = 0

    def readable(self) -> bool:
        return True

    def readinto(self, b) -> int:
        while self.i < len(self.drops) and self.pos >= self.drops[self.i][0]:
            self.pos = max(self.pos, self.drops[self.i][1])
            self.i += 1
            self.fh.seek(self.pos)
        n = len(b)
        if self.i < len(self.drops):
            n = min(n, self.drops[self.i][0] - self.pos)
        got = self.fh.readinto(memoryview(b)[:n])
        self.pos += got
        return got

    def close(self) -> None:
        self.fh.close()
        super().close()


_REPLACE_CODEC = "dracc-utf8-replace"
codecs.register(
    lambda name: (
        codecs.CodecInfo(
            name=_REPLACE_CODEC,
            encode=codecs.utf_8_encode,
            decode=codecs.utf_8_decode,
            incrementaldecoder=functools.partial(
                codecs.getincrementaldecoder("utf-8"), errors="replace"
            ),
            incrementalencoder=codecs.getincrementalencoder("utf-8"),
        )
        if name.replace("_", "-") == _REPLACE_CODEC
        else None
    )
)


def _iter_blocks(
    path: Path, cols: list[str], rejects: Rejects, file: str, scan: _Scan
) -> Iterator[tuple[Columns, np.ndarray]]:
    """Yield (dict column -> object array, line numbers) per block of the CSV, the rows
    ``scan`` found too long left out (counted by the caller)."""
    import pyarrow as pa
    import pyarrow.csv as pcsv

    invalid: list[int] = list(scan.lines)  #: file lines of rows not in the batches
    # pyarrow numbers the rows of what it reads: its row s is file line s + (dropped rows
    # before it); dropped row i (sorted) has d_i - i rows of pyarrow's before it, itself included
    dropped = np.asarray(scan.lines, dtype=np.int64) - np.arange(len(scan.lines))

    def on_invalid(row) -> str:
        line = int(row.number) if row.number is not None else -1
        if line > 0 and len(dropped):
            line += int(np.searchsorted(dropped, line, side="right"))
        invalid.append(line)
        reason = f"wrong number of fields ({row.actual_columns}, header has {row.expected_columns})"
        rejects.add(reason, file, line, row.text or "")
        return "skip"

    source = io.BufferedReader(_Without(path, scan.drops), 1 << 20) if scan.drops else str(path)
    try:
        reader = pcsv.open_csv(
            source,
            # a row must fit in one block (pyarrow): the longest row read sets the least size
            read_options=pcsv.ReadOptions(
                block_size=max(_BLOCK_BYTES, 2 * scan.longest + 64),
                use_threads=False,
                encoding=scan.encoding,
            ),
            parse_options=pcsv.ParseOptions(
                delimiter=scan.delimiter,
                invalid_row_handler=on_invalid,
                ignore_empty_lines=False,
                newlines_in_values=False,
            ),
            convert_options=pcsv.ConvertOptions(
                # by the names as written (``Lat. `` with its blank): every cell a string
                column_types={c: pa.string() for c in [*cols, *scan.names]},
                strings_can_be_null=False,
                quoted_strings_can_be_null=False,
            ),
            memory_pool=pa.system_memory_pool(),  # freed blocks go back to the C heap (see mcap)
        )
    except (pa.ArrowInvalid, OSError) as err:
        if not isinstance(source, str):
            source.close()
        raise IngestError(f"{file}: cannot read as CSV: {err}") from err
    k0 = 0
    try:
        for batch in reader:
            n = batch.num_rows
            if n == 0:
                continue
            lines = _line_numbers(k0, n, invalid)
            k0 += n
            # the columns by position, named as dracc matches them (blanks around a
            # name left out: pyarrow keeps them, and ``Lat. `` is the column ``Lat.``)
            names = batch.schema.names
            keys = cols if len(cols) == len(names) else [column_name(c) for c in names]
            data = {
                key: batch.column(i).to_numpy(zero_copy_only=False).astype(object)
                for i, key in enumerate(keys)
            }
            yield data, lines
    except pa.ArrowInvalid as err:
        raise IngestError(f"{file}: CSV damaged after line {k0 + 1 + len(invalid)}: {err}") from err
    finally:
        if not isinstance(source, str):
            source.close()


def read_csv(
    path: str | Path, cfg: IngestConfig, progress: Callable[[int], object] | None = None
) -> FileResult:
    """Read a CSV voyage log (long, wide or raw form) into canonical frames; ``progress``
    is told the file's size in bytes once it is read (the readers' signature).

    Raises IngestError when the file is missing or its header is not one dracc reads,
    and (``cfg.strict``) on the first rejected row.
    """
    p = Path(path)
    file = str(p)
    given = dict(getattr(cfg, "quantities", {}) or {})
    check_declared(given, file)
    declared = {column_name(k): v for k, v in given.items()}  # matched as header names are
    try:
        with p.open("rb") as fh:
            head = fh.read(65536)
    except OSError as err:
        raise IngestError(f"{file}: cannot read: {err}") from err
    delimiter = header_delimiter(head)
    names = raw_header(head, delimiter)
    cols = None if names is None else [column_name(c) for c in names]
    if not cols or find_column(cols, TIME_COLUMNS) is None:
        first = head.split(b"\n", 1)[0][:80].decode("utf-8", "replace")
        raise IngestError(
            f"{file}:1: not a dracc CSV header (needs a time column such as "
            f"time_utc, and quantity,value or quantity columns): {first!r}"
        )
    if len(set(cols)) != len(cols):
        raise IngestError(f"{file}:1: repeated column name in header")
    if len(head) == 65536 and b"\n" not in head and b"\r" not in head:
        raise IngestError(f"{file}:1: header line longer than 65536 bytes: not a dracc CSV header")
    form = _form(cols)
    rejects = Rejects()
    notes: list[str] = []
    limit = int(cfg.max_line_bytes)
    try:
        scan = _scan(p, limit)
    except OSError as err:
        raise IngestError(f"{file}: cannot read: {err}") from err
    scan.delimiter, scan.names = delimiter, list(names or [])
    if delimiter == "\t":
        notes.append(f"{file}: a tab-separated table, read as CSV with the tab as delimiter")
    if scan.long_rows:
        if scan.long_rows[0][0] == 1:
            raise IngestError(
                f"{file}:1: header line of {scan.long_rows[0][3]} bytes, longer than "
                f"[ingest] max_line_bytes = {limit}"
            )
        for ln, _a, _b, n, row_head in scan.long_rows:
            rejects.add(
                "too_long", file, ln, f"{row_head.decode('utf-8', 'replace')}... ({n} bytes)"
            )
        notes.append(
            f"{file}: {len(scan.long_rows)} row(s) longer than [ingest] max_line_bytes = {limit} "
            f"bytes left out (too_long; the longest {max(r[3] for r in scan.long_rows)} bytes, "
            f"first at line {scan.long_rows[0][0]})"
        )
        if cfg.strict:
            ln, n = scan.long_rows[0][0], scan.long_rows[0][3]
            raise IngestError(
                f"{file}:{ln}: too_long: a row of {n} bytes, over [ingest] max_line_bytes = "
                f"{limit} (--strict)"
            )
    if form == "csv-long":
        frames, rows = read_long(
            lambda r: _iter_blocks(p, cols, r, file, scan), p.stem, cols, declared, rejects, file
        )
    elif form == "csv-wide":
        frames, rows = _read_wide(p, cols, declared, rejects, notes, file, scan)
    else:
        raw = _read_raw(p, cols, cfg, rejects, notes, file, scan)
        if progress is not None:
            progress(p.stat().st_size)
        return raw
    if cfg.strict and rejects.total:
        reason, ex = next(iter(rejects.examples.items()))
        f, line, text = ex[0]
        raise IngestError(f"{f}:{line}: {reason}: {text!r} (--strict)")
    if not frames:
        notes.append(f"{file}: no navigation records ({rows} rows read)")
    if progress is not None:
        progress(p.stat().st_size)
    return FileResult(
        path=file, format=form, frames=frames, lines=rows, rejects=rejects, notes=notes
    )


def _read_wide(
    p: Path,
    cols: list[str],
    declared: dict[str, str],
    rejects: Rejects,
    notes: list[str],
    file: str,
    scan: _Scan,
) -> FramesAndRows:
    tcol = required_column(cols, TIME_COLUMNS)
    dcol = date_column(cols, tcol)  #: ``Date`` beside ``Time``: each row's time is both
    scol = find_column(cols, ("source",))
    unmatched_keys(declared, cols, file)
    qcols: dict[str, str] = {}
    ignored = []
    for c in cols:
        if c in (tcol, scol, dcol):
            continue
        q = lookup(c, declared)
        if q is None:
            ignored.append(c)
        else:
            qcols[c] = q.name
    for c in ignored:
        hint = (
            (
                " (a quantity without its unit: name the column e.g. sog_kn, or declare it in "
                "[ingest] quantities)"
            )
            if c.lower() in UNITLESS_HINTS
            else ""
        )
        notes.append(f"{file}: column {c!r} ignored: not a quantity name{hint}")
    if not qcols:
        what = "a tab-separated table" if scan.delimiter == "\t" else "a table"
        raise IngestError(
            f"{file}:1: {what} with columns {', '.join(repr(c) for c in cols)}, none of "
            "which names a quantity with its unit (e.g. lat_deg, heading_deg, stw_kn): map "
            'its columns in [ingest.quantities] (e.g. "Lat." = "lat_deg")'
        )
    parts: list[dict[str, pd.DataFrame]] = []
    rows = 0
    for data, lines in _iter_blocks(p, cols, rejects, file, scan):
        rows += len(lines)
        data, lines = drop_blank_rows(data, lines, rejects, file)
        if dcol is not None:
            data[tcol] = data[dcol] + " " + data[tcol]
        t_ns, ok = row_times(data, lines, tcol, rejects, file)
        vals: dict[str, np.ndarray] = {}
        for c, qname in qcols.items():
            text = data[c][ok]
            if qname in REF_QUANTITIES:
                vals[qname] = np.where(text == "", None, text)  # type: ignore[assignment]  # numpy stubs: where(c, None, x) is an array
            else:
                vals[qname] = cell_numbers(text, lines[ok], c, rejects, file)
        src = data[scol][ok] if scol else np.full(int(ok.sum()), p.stem, dtype=object)
        # a row is a record: each block becomes compact frames at once (a float for every
        # column of every row, and a string per row, made memory grow with the file)
        parts.append(build_frames(t_ns[ok], src, lines[ok], "csv", vals, file, rejects))
    return sorted_frames(concat_blocks(parts, every_kind=False)), rows


def unmatched_keys(declared: dict[str, str], cols: list[str], file: str) -> None:
    """ConfigError where a key of ``[ingest.quantities]`` names no column of a wide table:
    its column would be left out without a word (a key ``"Lat"`` for the column ``Lat.``).
    The error names the key, the column it nearly matches, and the columns there are."""
    loose = {re.sub(r"[^a-z0-9]", "", c.lower()): c for c in cols}
    for key in declared:
        if key in cols:
            continue
        near = loose.get(re.sub(r"[^a-z0-9]", "", key.lower()))
        hint = f" (did you mean {near!r}?)" if near else ""
        raise ConfigError(
            f"{file}: [ingest.quantities] {key!r} names no column of this table{hint}; "
            f"its columns are: {', '.join(repr(c) for c in cols)}"
        )


def _read_raw(
    p: Path,
    cols: list[str],
    cfg: IngestConfig,
    rejects: Rejects,
    notes: list[str],
    file: str,
    scan: _Scan,
) -> FileResult:
    from dracc.ingest.nmea import parse_sentences

    tcol = required_column(cols, TIME_COLUMNS)
    rcol = required_column(cols, RAW_COLUMNS)
    scol = find_column(cols, ("source",))
    pcol = find_column(cols, ("protocol",))
    all_lines: list[bytes] = []
    times: list[np.ndarray] = []
    sources: list[np.ndarray] = []
    file_lines: list[np.ndarray] = []
    rows = 0
    n2k_raw: list[str] = []
    n2k_times: list[np.ndarray] = []
    n2k_lines: list[np.ndarray] = []
    for data, lines in _iter_blocks(p, cols, rejects, file, scan):
        rows += len(lines)
        data, lines = drop_blank_rows(data, lines, rejects, file)
        keep = np.ones(len(lines), dtype=bool)
        if pcol:  # valid rows of a protocol dracc does not decode: ignored, not rejected
            n2k = np.fromiter(
                ("2000" in x for x in data[pcol].tolist()), dtype=bool, count=len(lines)
            )
            if n2k.any():  # NMEA 2000 messages: decoded apart (dracc.ingest.n2k)
                t2k, ok2k = parse_times(data[tcol][n2k], tcol)
                n2k_raw.extend(str(x) for x in data[rcol][n2k][ok2k])
                n2k_times.append(t2k[ok2k])
                n2k_lines.append(lines[n2k][ok2k])
                if not ok2k.all():
                    add_rejects(rejects, "bad time", file, lines[n2k][~ok2k], ["NMEA 2000"] * 5)
            keep &= ~n2k
        empty = keep & (data[rcol] == "")
        if empty.any():
            add_rejects(rejects, "empty raw sentence", file, lines[empty], [""] * 5)
        keep &= ~empty
        t_ns, ok = parse_times(data[tcol], tcol)
        bad = keep & ~ok
        if bad.any():
            add_rejects(
                rejects, "bad time", file, lines[bad], [str(x) for x in data[tcol][bad][:5]]
            )
        keep &= ok
        all_lines.extend(s.encode("utf-8", "replace") for s in data[rcol][keep])
        times.append(t_ns[keep])
        sources.append(data[scol][keep] if scol else np.full(int(keep.sum()), "", dtype=object))
        file_lines.append(lines[keep])
    t = np.concatenate(times) if times else np.zeros(0, np.int64)
    src = np.concatenate(sources) if sources else np.zeros(0, object)
    where = np.concatenate(file_lines) if file_lines else np.zeros(0, np.int64)
    res = parse_sentences(all_lines, t, list(src), file, cfg)
    # parse_sentences numbers lines by their position (1-based): map back to CSV lines
    for kind, f in res.frames.items():
        if len(f):
            f = f.copy()
            f["line"] = where[f["line"].to_numpy(dtype=np.int64) - 1]
            res.frames[kind] = f
    renumber_examples(res.rejects, where)
    res.ignored_examples = {
        k: [(f, int(where[ln - 1]) if 1 <= ln <= len(where) else ln, t) for f, ln, t in ex]
        for k, ex in res.ignored_examples.items()
    }
    if n2k_raw:
        res = _with_n2k(res, n2k_raw, n2k_times, n2k_lines, file, cfg)
    res.rejects.merge(rejects)
    res.format = "csv-raw"
    res.lines = rows
    res.notes = notes + res.notes
    return res


def _with_n2k(
    res: FileResult,
    raw: list[str],
    times: list[np.ndarray],
    lines: list[np.ndarray],
    file: str,
    cfg: IngestConfig,
) -> FileResult:
    """``res`` with the NMEA 2000 rows of a raw-sentence CSV decoded and merged in: the
    OpenCPN data logger writes each message as its Actisense BST bytes in hex
    (``93 13 02 01 F8 01 ...``), timed by the row."""
    from dracc.ingest.demux import merge_results
    from dracc.ingest.n2k.ebl import bst_messages
    from dracc.ingest.n2k.reader import n2k_result

    def hex_bytes(text: str) -> bytes:
        try:
            return bytes.fromhex(text.replace("0x", " ").replace(",", " "))
        except ValueError:
            return b""

    msgs = bst_messages([hex_bytes(x) for x in raw], np.concatenate(times), np.concatenate(lines))
    n2k = n2k_result(msgs, file, "csv-raw", cfg, lines=0)
    return merge_results(res.path, res.format, res.lines, [res, n2k], [])
