"""Every decoded record of a voyage as one table: what ``dracc records`` writes.

One row per record -- a sentence, a CSV row of one source, an MCAP or NMEA 2000 message --
holding every field it carried: an RMC is one row with its position, course and speed
(the canonical frames hold it twice, a ``position`` and a ``ground`` row, which are
joined again here by source, sentence, line and time).  Rows are in time order; records
of the same time in the order of their line in the log, then of their kind
(:data:`dracc.frames.KINDS`), then as the frames hold them (stable).

The units are those in the column names (degrees, knots, nautical miles, degrees per
minute: the user's units, converted at this edge from the frames' radians and SI);
:data:`COLUMNS` lists every column with its meaning.  A field a record does not carry is
missing (NaN, or NULL in Parquet), never zero.

The table is built chunk by chunk (:meth:`Records.chunks`): a day of logs is millions of
records, and only the ordering (a few integers per record) is held for the whole of it;
each chunk's columns are gathered from the frames with numpy.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from dracc.core.errors import InsufficientDataError, OptionError
from dracc.core.units import KN_MPS, NMI_M
from dracc.frames import KINDS, MISSING_NS, REFERENCE_DTYPE, Voyage

#: the table's columns, in order: name -> what it holds (the contract of ``dracc records``)
COLUMNS: dict[str, str] = {
    "time_utc": "the record's time, UTC (its time of fix where it has one)",
    "recv_utc": "its receive time (TAG c:, logger prefix, MCAP log time) where distinct",
    "source": "the source key (TAG s:, talker, MCAP topic, CSV source)",
    "role": "the role(s) of the source, '+'-joined (compass+log); '' where none",
    "talker": "the NMEA talker ID; '' where none",
    "sentence": "GGA, HDT, ..., PGN127250 (NMEA 2000), the MCAP message or 'csv'",
    "file": "the log file the source's records come from; '' where several files",
    "line": "1-based line or message number in its file",
    "lat_deg": "latitude, degrees north",
    "lon_deg": "longitude, degrees east",
    "alt_m": "altitude, metres",
    "fix_quality": "the position's quality (GGA fix quality; 1 valid, 0 invalid)",
    "hdop": "horizontal dilution of precision",
    "heading_deg": "heading, degrees",
    "heading_ref": "T true, M magnetic; missing where unknown",
    "deviation_deg": "magnetic deviation, degrees east",
    "variation_deg": "magnetic variation, degrees east",
    "heading_quality": "the unit's heading quality (0 normal, 1 reduced, 2 invalid)",
    "cog_deg": "course over ground, degrees true",
    "sog_kn": "speed over ground, knots",
    "stw_kn": "speed through the water (longitudinal), knots",
    "stw_transverse_kn": "transverse speed through the water, knots, starboard +",
    "sog_long_kn": "longitudinal ground speed (VBW), knots",
    "sog_transverse_kn": "transverse ground speed (VBW), knots, starboard +",
    "total_water_nmi": "total distance through the water, nautical miles",
    "trip_water_nmi": "trip distance through the water, nautical miles",
    "rot_degpmin": "rate of turn, degrees per minute, starboard +",
}
#: the text columns (categoricals in a chunk)
TEXT_COLUMNS = ("source", "role", "talker", "sentence", "file", "heading_ref")

_RAD_DEG = 180.0 / np.pi
#: value column -> (kind, frame column, factor from the frame's unit)
_VALUES: dict[str, tuple[str, str, float]] = {
    "lat_deg": ("position", "lat_rad", _RAD_DEG),
    "lon_deg": ("position", "lon_rad", _RAD_DEG),
    "alt_m": ("position", "alt_m", 1.0),
    "hdop": ("position", "hdop", 1.0),
    "heading_deg": ("heading", "heading_rad", _RAD_DEG),
    "deviation_deg": ("heading", "deviation_rad", _RAD_DEG),
    "variation_deg": ("heading", "variation_rad", _RAD_DEG),
    "heading_quality": ("heading", "heading_quality", 1.0),
    "cog_deg": ("ground", "cog_rad", _RAD_DEG),
    "sog_kn": ("ground", "sog_mps", 1.0 / KN_MPS),
    "stw_kn": ("water", "stw_mps", 1.0 / KN_MPS),
    "stw_transverse_kn": ("water", "stw_transverse_mps", 1.0 / KN_MPS),
    "sog_long_kn": ("water", "sog_long_mps", 1.0 / KN_MPS),
    "sog_transverse_kn": ("water", "sog_transverse_mps", 1.0 / KN_MPS),
    "total_water_nmi": ("distance", "total_water_m", 1.0 / NMI_M),
    "trip_water_nmi": ("distance", "trip_water_m", 1.0 / NMI_M),
    "rot_degpmin": ("rot", "rot_radps", _RAD_DEG * 60.0),
}
#: rows per chunk (and per Parquet row group)
CHUNK_ROWS = 262_144


def check_kinds(text: str | None) -> tuple[str, ...]:
    """``--kinds position,heading`` -> ('position', 'heading'); None: every kind.  A name
    that is not a kind is an :class:`OptionError` (exit 2) naming the kinds."""
    if text is None:
        return KINDS
    names = [k.strip().lower() for k in text.split(",") if k.strip()]
    wrong = [k for k in names if k not in KINDS]
    if wrong or not names:
        raise OptionError(f"--kinds {text!r}: expected a comma list of {', '.join(KINDS)}")
    return tuple(k for k in KINDS if k in names)


class _Text:
    """One text column's labels across the kinds' frames, each frame's codes mapped into them."""

    def __init__(self) -> None:
        self.labels: list[str] = []
        self._index: dict[str, int] = {}

    def code(self, label: str) -> int:
        if label not in self._index:
            self._index[label] = len(self.labels)
            self.labels.append(label)
        return self._index[label]

    def mapped(self, col: pd.Series) -> tuple[np.ndarray, np.ndarray]:
        """(the column's own codes, their map into :attr:`labels`, -1 (missing) to '')."""
        cat = col if isinstance(col.dtype, pd.CategoricalDtype) else col.astype("category")
        to = [self.code(str(c)) for c in cat.cat.categories] + [self.code("")]
        return cat.cat.codes.to_numpy(), np.asarray(to, dtype=np.int64)

    def column(self, codes: np.ndarray) -> pd.Categorical:
        return pd.Categorical.from_codes(codes, categories=self.labels, validate=False)


@dataclass
class _Kind:
    """Where one kind's frame rows go in the table."""

    kind: str
    frame: pd.DataFrame
    order: np.ndarray  #: frame rows, sorted by their table row
    dest: np.ndarray  #: the table row of each, ascending
    #: source, sentence, talker: (the frame's codes, their map into the table's labels)
    text: dict[str, tuple[np.ndarray, np.ndarray]]


@dataclass
class Records:
    """The records table of a voyage, to be read in chunks (:meth:`chunks`)."""

    rows: int  #: records (table rows)
    #: fractional digits of a second (0, 3, 6 or 9) that write every time exactly
    time_digits: int
    _kinds: list[_Kind]
    _source: _Text
    _talker: _Text
    _sentence: _Text
    _role: np.ndarray  #: source code -> role code
    _roles: _Text
    _file: np.ndarray  #: source code -> file code
    _files: _Text

    def chunks(self, rows: int = CHUNK_ROWS) -> Iterator[pd.DataFrame]:
        """The table, ``rows`` rows at a time, every chunk with the columns of
        :data:`COLUMNS` and the same categories in its text columns."""
        for start in range(0, self.rows, rows):
            yield self._chunk(start, min(start + rows, self.rows))

    def frame(self) -> pd.DataFrame:
        """The whole table as one DataFrame (for a library user; the writers take chunks)."""
        parts = list(self.chunks())
        return pd.concat(parts, ignore_index=True) if len(parts) > 1 else parts[0]

    def _chunk(self, a: int, b: int) -> pd.DataFrame:
        n = b - a
        time = np.zeros(n, dtype=np.int64)
        recv = np.full(n, MISSING_NS, dtype=np.int64)
        line = np.zeros(n, dtype=np.int64)
        src, talk, sent = (np.zeros(n, dtype=np.int64) for _ in range(3))
        values = {c: np.full(n, np.nan) for c in _VALUES}
        quality = np.zeros(n, dtype=np.int8)
        has_quality = np.zeros(n, dtype=bool)
        ref = np.full(n, -1, dtype=np.int8)
        for k in self._kinds:
            lo, hi = np.searchsorted(k.dest, [a, b])
            rows, at = k.order[lo:hi], k.dest[lo:hi] - a
            f = k.frame
            time[at] = f["time_ns"].to_numpy()[rows]
            line[at] = f["line"].to_numpy()[rows]
            for name, into in (("source", src), ("sentence", sent), ("talker", talk)):
                codes, to = k.text[name]
                into[at] = to[codes[rows]]
            r = f["recv_ns"].to_numpy()[rows]
            recv[at[r != MISSING_NS]] = r[r != MISSING_NS]
            for name, (kind, col, factor) in _VALUES.items():
                if kind == k.kind:
                    values[name][at] = f[col].to_numpy(dtype=np.float64)[rows] * factor
            if k.kind == "position":
                quality[at] = f["quality"].to_numpy()[rows]
                has_quality[at] = True
            elif k.kind == "heading":
                ref[at] = f["reference"].cat.codes.to_numpy()[rows]
        cols: dict[str, object] = {
            "time_utc": pd.to_datetime(time, unit="ns", utc=True),
            "recv_utc": pd.to_datetime(recv.view("M8[ns]"), utc=True),  # MISSING_NS is NaT
            "source": self._source.column(src),
            "role": self._roles.column(self._role[src]),
            "talker": self._talker.column(talk),
            "sentence": self._sentence.column(sent),
            "file": self._files.column(self._file[src]),
            "line": line,
        }
        for name in COLUMNS:
            if name in values:
                cols[name] = values[name]
        cols["fix_quality"] = pd.arrays.IntegerArray(quality, ~has_quality)
        cols["heading_ref"] = pd.Categorical.from_codes(ref, dtype=REFERENCE_DTYPE)
        return pd.DataFrame({c: cols[c] for c in COLUMNS})


def records_table(voyage: Voyage, kinds: Sequence[str] = KINDS) -> Records:
    """The records of ``voyage`` (of the frames ``kinds`` only) as a :class:`Records`
    table.  A voyage with no record of these kinds raises
    :class:`~dracc.core.errors.InsufficientDataError`."""
    parts = [(k, voyage.frames[k]) for k in KINDS if k in kinds and len(voyage.frames[k])]
    if not parts:
        raise InsufficientDataError(
            "no usable records in the logs"
            + ("" if set(kinds) >= set(KINDS) else f" of the kinds {', '.join(kinds)}")
            + "; nothing written"
        )
    source, talker, sentence = _Text(), _Text(), _Text()
    texts = [
        {
            "source": source.mapped(f["source"]),
            "sentence": sentence.mapped(f["sentence"]),
            "talker": talker.mapped(f["talker"]),
        }
        for _, f in parts
    ]
    dest = _table_rows(
        [f["time_ns"].to_numpy() for _, f in parts],
        [to[codes] for codes, to in (t["source"] for t in texts)],
        [to[codes] for codes, to in (t["sentence"] for t in texts)],
        [f["line"].to_numpy() for _, f in parts],
    )
    kinds_at, start = [], 0
    for (name, f), text in zip(parts, texts, strict=True):
        d = dest[start : start + len(f)]
        order = np.argsort(d, kind="stable")
        kinds_at.append(_Kind(name, f, order, d[order], text))
        start += len(f)
    roles, files = _Text(), _Text()
    role_of, file_of = [], []
    for key in source.labels:
        info = voyage.sources.get(key)
        role_of.append(roles.code((info.role or "") if info else ""))
        where = sorted(info.files) if info else []
        file_of.append(files.code(where[0] if len(where) == 1 else ""))
    times = [f[c].to_numpy() for _, f in parts for c in ("time_ns", "recv_ns")]
    return Records(
        rows=int(dest.max()) + 1,
        time_digits=max(_digits(t[t != MISSING_NS]) for t in times),
        _kinds=kinds_at,
        _source=source,
        _talker=talker,
        _sentence=sentence,
        _role=np.asarray(role_of, dtype=np.int64),
        _roles=roles,
        _file=np.asarray(file_of, dtype=np.int64),
        _files=files,
    )


def _table_rows(
    time: list[np.ndarray], src: list[np.ndarray], sent: list[np.ndarray], line: list[np.ndarray]
) -> np.ndarray:
    """The table row of each frame row, the kinds' frames taken one after the other.

    Rows of different kinds with the same time, source, sentence and line are one record
    (an RMC's position and ground rows); rows of one kind that share all four (two
    sentences fused on one line) pair up in frame order.  Records are ordered by time,
    line, then by their first kind and frame row."""
    starts = np.cumsum([0] + [len(x) for x in time[:-1]])
    t, s, se, li = (np.concatenate(x) for x in (time, src, sent, line))
    n = len(t)
    order = np.lexsort((li, se, s, t))  # stable: equal keys stay kind by kind, in frame order
    same = np.ones(n, dtype=bool)  # the row has the key of the row before it
    same[0] = False
    for key in (t, s, se, li):
        k = key[order]
        same[1:] &= k[1:] == k[:-1]
    kind = np.searchsorted(starts, order, side="right")
    same_kind = same.copy()
    same_kind[1:] &= kind[1:] == kind[:-1]
    occ = np.arange(n) - np.flatnonzero(~same_kind)[np.cumsum(~same_kind) - 1]
    per_key = np.maximum.reduceat(occ, np.flatnonzero(~same)) + 1
    record = (np.cumsum(per_key) - per_key)[np.cumsum(~same) - 1] + occ
    m = int(per_key.sum())
    first = np.full(m, n, dtype=np.int64)  # the record's first row: first kind, first row
    np.minimum.at(first, record, order)
    rank = np.lexsort((first, li[first], t[first]))
    place = np.empty(m, dtype=np.int64)
    place[rank] = np.arange(m, dtype=np.int64)
    dest = np.empty(n, dtype=np.int64)
    dest[order] = place[record]
    return dest


def _digits(ns: np.ndarray) -> int:
    """The fewest fractional digits of a second (0, 3, 6, 9) that show every time exactly."""
    for digits, unit in ((0, 10**9), (3, 10**6), (6, 10**3)):
        if not (ns % unit).any():
            return digits
    return 9
