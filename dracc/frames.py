"""Canonical frames: what every reader (NMEA text, CSV, MCAP) produces.

A voyage is a handful of long tables, one per kind of measurement, each a pandas
DataFrame sorted by ``time_ns`` with these columns (and no others needed downstream):

``position``  (GGA, GLL, RMC, GNS; NavSatFix; LocationFix)
    time_ns:int64, source:str, lat_rad, lon_rad, alt_m, quality:int8 (GGA fix
    quality; 1 where only "valid" is known, 0 invalid), hdop
``heading``   (HDT, THS, HDG, HDM)
    time_ns, source, heading_rad, reference ('T' true, 'M' magnetic: a categorical
    of these two, NaN where unknown),
    deviation_rad, variation_rad (east positive; NaN where absent),
    heading_quality (float: the unit's own heading quality where it says one -- 0 normal,
    1 reduced, 2 invalid, as Kongsberg ``$PSXN,20`` -- NaN where it says none)
``ground``    (VTG, RMC: course and speed over ground)
    time_ns, source, cog_rad, sog_mps
``water``     (VHW, VBW: the speed log)
    time_ns, source, stw_mps (longitudinal through water), stw_transverse_mps,
    sog_long_mps, sog_transverse_mps (VBW ground components; starboard positive)
``distance``  (VLW)
    time_ns, source, total_water_m, trip_water_m
``rot``       (ROT)
    time_ns, source, rot_radps

Every table also carries ``talker`` (str: the NMEA talker ID, '' where none),
``sentence`` (str, e.g. 'GGA', or the message type for MCAP/CSV), ``line``
(int64, 1-based line or message number in its file, for tracing a value back to
the input) and ``recv_ns`` (int64: the receive time -- TAG block ``c:``, logger
prefix, MCAP log time -- of a record whose ``time_ns`` is its own time of fix, so
``recv_ns - time_ns`` is its latency; ``MISSING_NS`` where the record has no time of
fix or no receive time). The string columns may be pandas Categoricals (they repeat a few
values millions of times). Missing fields are NaN, never zero.

``source`` is the source key: the TAG block ``s:`` value, the talker ID, an MCAP
topic, a CSV source column, or a file-derived key. Roles (``compass``, ``log``,
``ins1``..``ins3``, ``gnss``) are assigned to source keys afterwards
(:mod:`dracc.ingest.sources`).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

#: the heading reference: two letters as a categorical (a string column of a million
#: rows costs more to filter, sort and concatenate than all the numbers beside it)
REFERENCE_DTYPE = pd.CategoricalDtype(["M", "T"])

COMMON_COLUMNS = {
    "time_ns": "int64",
    "source": "category",
    "talker": "category",
    "sentence": "category",
    "line": "int64",
    "recv_ns": "int64",
}
#: ``recv_ns`` where a record has no receive time distinct from its time of fix
MISSING_NS = np.iinfo(np.int64).min

#: NMEA 0183 sentences that carry their own time of fix (the others are timed by a stamp)
OWN_TIME_SENTENCES = frozenset({"GGA", "GLL", "RMC", "GNS", "ZDA"})


def own_time(df: pd.DataFrame) -> np.ndarray:
    """Rows whose ``time_ns`` is their own time of fix (a receive time beside it, or a
    sentence that carries one); the others are timed by a stamp (TAG ``c:``, a logger
    prefix, an MCAP log time, or the preceding timed record)."""
    mask: np.ndarray = (df["recv_ns"].to_numpy(np.int64) != MISSING_NS) | df["sentence"].isin(
        OWN_TIME_SENTENCES
    ).to_numpy(bool)
    return mask


KIND_COLUMNS: dict[str, dict[str, str]] = {
    "position": {
        "lat_rad": "float64",
        "lon_rad": "float64",
        "alt_m": "float64",
        "quality": "int8",
        "hdop": "float64",
    },
    "heading": {
        "heading_rad": "float64",
        "reference": REFERENCE_DTYPE,
        "deviation_rad": "float64",
        "variation_rad": "float64",
        "heading_quality": "float64",
    },
    "ground": {"cog_rad": "float64", "sog_mps": "float64"},
    "water": {
        "stw_mps": "float64",
        "stw_transverse_mps": "float64",
        "sog_long_mps": "float64",
        "sog_transverse_mps": "float64",
    },
    "distance": {"total_water_m": "float64", "trip_water_m": "float64"},
    "rot": {"rot_radps": "float64"},
}
KINDS = tuple(KIND_COLUMNS)


def empty_frame(kind: str) -> pd.DataFrame:
    """An empty canonical frame of ``kind`` with the right dtypes."""
    cols = {**COMMON_COLUMNS, **KIND_COLUMNS[kind]}
    return pd.DataFrame({c: pd.Series(dtype=t) for c, t in cols.items()})


def make_frame(kind: str, data: dict[str, np.ndarray]) -> pd.DataFrame:
    """Build a canonical frame from column arrays; absent value columns become NaN.

    ``time_ns``, ``source``, ``sentence`` and ``line`` are required; ``talker``
    defaults to '', ``recv_ns`` to ``MISSING_NS``.
    """
    n = len(data["time_ns"])
    cols = {**COMMON_COLUMNS, **KIND_COLUMNS[kind]}
    out = {}
    for c, t in cols.items():
        if c in data:
            v = data[c]
            if t is REFERENCE_DTYPE:
                out[c] = (
                    v
                    if isinstance(v, pd.Categorical) and v.dtype == t
                    else pd.Categorical(np.asarray(v, dtype=object), dtype=t)
                )
            elif t == "category":
                out[c] = (
                    v
                    if isinstance(v, pd.Categorical)
                    else pd.Categorical(np.asarray(v, dtype=object))
                )
            elif t == "object":
                out[c] = np.asarray(v, dtype=object)
            else:
                out[c] = np.asarray(v).astype(t, copy=False)
        elif c == "talker":
            out[c] = pd.Categorical(np.full(n, "", dtype=object))
        elif c == "recv_ns":
            out[c] = np.full(n, MISSING_NS, dtype=np.int64)
        elif t == "float64":
            out[c] = np.full(n, np.nan)
        elif t == "int8":
            out[c] = np.zeros(n, dtype=np.int8)
        elif t is REFERENCE_DTYPE:
            out[c] = pd.Categorical.from_codes(np.full(n, -1, dtype=np.int8), dtype=t)
        elif t == "object":
            out[c] = np.full(n, None, dtype=object)
        else:
            raise KeyError(f"{kind} frame needs column {c!r}")
    return pd.DataFrame(out)


def concat_blocks(
    blocks: list[dict[str, pd.DataFrame]], every_kind: bool = True
) -> dict[str, pd.DataFrame]:
    """One frame per kind from the frames of consecutive blocks (dicts kind -> frame),
    sorted by time (stable: a block's order kept among equal times), the string columns
    categorical.  ``every_kind``: an empty frame for a kind no block has."""
    out = {}
    for kind in KINDS:
        parts = [f[kind] for f in blocks if kind in f and len(f[kind])]
        if not parts:
            if every_kind:
                out[kind] = empty_frame(kind)
            continue
        df = pd.concat(parts, ignore_index=True) if len(parts) > 1 else parts[0]
        for c in ("source", "talker", "sentence"):
            df[c] = df[c].astype("category")
        t = df["time_ns"].to_numpy()
        if (t[1:] < t[:-1]).any():  # a log in time order (nearly all) is not copied again
            df = df.iloc[np.argsort(t, kind="stable")]
        out[kind] = df.reset_index(drop=True)
    return out


@dataclass
class Rejects:
    """Rejected lines, counted by reason, with the first few examples of each."""

    counts: Counter[str] = field(default_factory=Counter)
    #: reason -> list of (file, line number, text excerpt); at most ``max_examples`` each
    examples: dict[str, list[tuple[str, int, str]]] = field(default_factory=dict)
    max_examples: int = 5

    def add(self, reason: str, file: str, line: int, text: str, count: int = 1) -> None:
        self.counts[reason] += count
        ex = self.examples.setdefault(reason, [])
        if len(ex) < self.max_examples:
            ex.append((file, int(line), text[:120]))

    def merge(self, other: Rejects) -> None:
        self.counts.update(other.counts)
        for reason, ex in other.examples.items():
            mine = self.examples.setdefault(reason, [])
            mine.extend(ex[: max(0, self.max_examples - len(mine))])

    @property
    def total(self) -> int:
        return sum(self.counts.values())


@dataclass(frozen=True)
class ClockStep:
    """One jump of a source's clock seen in stream order: a back-step (``to_ns <
    from_ns``: a logger replaying a recording, a clock set back) or a forward jump
    beyond the gap threshold.  Recorded by the time base, judged by the time checks
    (:mod:`dracc.math.integrity.time_checks`)."""

    file: str
    line: int  #: the first record after the step
    source: str
    sentence: str
    from_ns: int  #: the last time before the step
    to_ns: int  #: the first time after it


@dataclass
class TimeEvents:
    """What the time base found and decided; counted, never silently applied."""

    duplicates: int = 0  #: records repeating the previous time of the same source and kind
    backsteps: int = 0  #: times going backwards by more than the tolerance
    gaps: int = 0  #: gaps longer than the configured threshold
    rollovers: int = 0  #: midnight rollovers resolved from time-of-day fields
    implausible_dates: int = 0  #: e.g. GPS week rollover (date ~19.6 years early)
    #: the date a log with no date at all was placed on (YYYY-MM-DD), None if none was
    assumed_date: str | None = None
    decisions: list[str] = field(default_factory=list)  #: human-readable notes
    #: (file, line, what) for the first few of each event
    examples: list[tuple[str, int, str]] = field(default_factory=list)
    #: every back-step of a source's own times, in stream order (at most a few hundred
    #: per file are kept; ``backsteps`` counts them all)
    steps: list[ClockStep] = field(default_factory=list)


@dataclass
class SourceInfo:
    """What one source key contributed."""

    key: str
    #: roles this source serves; one source may serve several in different kinds
    #: (e.g. an instrument bus 'II' giving both the compass heading and the log speed)
    roles: list[str] = field(default_factory=list)
    talkers: Counter[str] = field(default_factory=Counter)
    sentences: Counter[str] = field(default_factory=Counter)
    records: int = 0
    first_ns: int | None = None
    last_ns: int | None = None
    files: set[str] = field(default_factory=set)
    #: several units behind this one key, their positions of one instant far apart
    #: (:mod:`dracc.ingest.interleaved`): what was seen, None for one unit
    interleaved: str | None = None

    @property
    def role(self) -> str | None:
        """The roles joined with '+' (e.g. 'compass+log'), or None if unassigned."""
        return "+".join(self.roles) if self.roles else None


@dataclass
class FileResult:
    """What one reader (NMEA text, CSV, MCAP) returns for one file, times already resolved.

    ``read_logs`` merges several of these (sorting by time), assigns roles and
    builds the :class:`Voyage`.
    """

    path: str
    format: str  #: e.g. "nmea", "csv-long", "csv-wide", "csv-raw", "mcap"
    frames: dict[
        str, pd.DataFrame
    ]  #: kind -> canonical frame (kinds absent from the file may be missing)
    lines: int  #: lines (or messages) read
    rejects: Rejects = field(default_factory=Rejects)
    time_events: TimeEvents = field(default_factory=TimeEvents)
    notes: list[str] = field(default_factory=list)  #: what the reader decided or could not use
    #: valid lines or messages the file holds that dracc does not use, by type (NMEA
    #: sentence type 'GSV', 'VDM', proprietary address 'PGRME', 'comment', 'blank'; MCAP
    #: schema name; CSV 'NMEA 2000'): counted, not rejected
    ignored: Counter[str] = field(default_factory=Counter)
    #: type -> the first few (file, line or message number, text) of each ignored type
    ignored_examples: dict[str, list[tuple[str, int, str]]] = field(default_factory=dict)

    #: the file carries no clock of its own (a candump without times, a logger whose
    #: times start at zero): its times are the order of its records, not time of day, and
    #: no latency, rate or time finding is drawn from them
    clockless: bool = False

    @property
    def records(self) -> int:
        return sum(len(f) for f in self.frames.values())


@dataclass(frozen=True)
class RoleChoice:
    """One role filled by one source, chosen by evidence among several candidates
    (:mod:`dracc.ingest.role_evidence`); the runners-up stay as witnesses."""

    role: str  #: 'compass', 'log' or 'gnss'
    chosen: str  #: the source key that fills the role
    why: str  #: the evidence that decided, in words
    #: (source key, why it was not chosen) for every other candidate: the witnesses
    runners_up: tuple[tuple[str, str], ...] = ()
    #: source key -> the figures weighed (resolution, availability, agreement ...)
    evidence: dict[str, dict[str, Any]] = field(default_factory=dict)

    @property
    def witnesses(self) -> list[str]:
        return [k for k, _ in self.runners_up]


@dataclass
class Voyage:
    """Everything ingested from one or more logs of one voyage."""

    frames: dict[str, pd.DataFrame]  #: kind -> canonical frame (every kind present, maybe empty)
    sources: dict[str, SourceInfo]
    rejects: Rejects
    time_events: TimeEvents
    #: per file: {"path", "format", "lines", "records", "rejected": {reason: n},
    #: "ignored": {type: n}}
    inputs: list[dict[str, Any]]
    lines: int = 0  #: lines (or messages) read in all files
    #: valid lines or messages dracc does not use, by type ('GSV', 'VDM', 'comment', an MCAP
    #: schema name, ...): counted, never rejected (only damaged input is rejected)
    ignored: Counter[str] = field(default_factory=Counter)
    #: roles filled by evidence among several candidates (:class:`RoleChoice`)
    choices: list[RoleChoice] = field(default_factory=list)
    #: source keys read from a file without a clock (:attr:`FileResult.clockless`)
    clockless: frozenset[str] = frozenset()

    def witnesses(self, role: str) -> list[str]:
        """The candidates for ``role`` not chosen, kept as witnesses."""
        return [k for c in self.choices if c.role == role for k in c.witnesses]

    def role_sources(self, role: str) -> list[str]:
        """Source keys assigned to ``role``."""
        return [k for k, s in self.sources.items() if role in s.roles]

    def frame(self, kind: str, role: str | None = None) -> pd.DataFrame:
        """The frame of ``kind``, restricted to the sources of ``role`` if given."""
        df = self.frames[kind]
        if role is None:
            return df
        return df[df["source"].isin(self.role_sources(role))]
