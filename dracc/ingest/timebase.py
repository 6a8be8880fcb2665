"""Time base: turn time-of-day, date and receive-time fields into int64 UTC nanoseconds.

Rules (documented for users in ``docs/ingest.md``):

1. A record with an **external time** (TAG block ``c:``, logger prefix, MCAP log time)
   and its own **time of fix** (GGA/GLL/RMC/ZDA/GNS) gets the time of fix on the UTC
   day that puts it nearest to the external time (|difference| <= 12 h), so a fix at
   23:59:59.8 stamped 00:00:00.5 by the logger lands on the previous day.
2. A record with a time of fix and no external time is placed by the running day index
   of the file: the time of day is followed in stream order, a drop of more than 12 h
   is a midnight rollover (day index + 1), a rise of more than 12 h a step back over
   midnight (day index - 1; interleaved clocks).  The day index is turned into a date
   by the nearest preceding RMC/ZDA date (``base = date - day_index``), by the first
   following one where none precedes (back-fill), or by ``cfg.date`` for the first
   record where the log carries no date at all.
3. A record without a time field takes its external time, or else the time of the
   preceding timed record of the file (the next one for leading records).  Such
   derived times are not counted as duplicates.
4. A GPS week-number rollover (a receiver dating its fixes 1024·k weeks early, k = 1, 2):
   an RMC/ZDA date that far behind its record's external time (within a day: a midnight
   between them), whatever its year, is counted (``implausible_dates``) and noted with the
   first one's receive time; its time keeps the external time's day (rule 1).  Without an
   external time, a date before 2000-01-01 made plausible by adding 1024 weeks is
   corrected, counted and noted; a later one (2006 for 2026) cannot be told from a real
   log of that year by the date alone, and is used as it reads.  Other dates outside
   2000-01-01 .. today+1 are counted and noted, not used.

Time events (:class:`EventCounter`, one code path for every reader, ``dracc inspect`` and
``dracc analyze`` alike: :func:`feed_frames`).  A *stream* is one source's records of one
sentence type (an NMEA 2000 PGN, an MCAP schema; a CSV file's rows), taken in the order
the log holds them (by line or message number; the records one line gives are one);
only records with a time of their own (a time of fix or a receive stamp: TAG ``c:``,
logger prefix, MCAP log time, CSV time; not a time taken from the record before, rule
3) are compared, each with the one before it in its stream.  Where the time does not
advance, the record is

* a **duplicate** -- damage -- where it repeats the record before in time and values (a
  logger writing a line twice, a bus sending a held fix again), or where its own time of
  fix repeats with other values (its cadence says it should have advanced); but
* a **shared stamp** -- not damage, counted apart -- in a stream that runs faster than
  its stamps (at least :data:`FASTER_THAN_STAMPS` records per distinct time: a 10 Hz gyro
  behind the whole-second ``c:`` of an IEC 61162-450 logger, HDT having no time of its
  own): there a repeated time with other values is a sample, and so is a repeated record
  behind a receive stamp (a steady reading cannot be told from a line written twice);
  only a time of fix sent again with its values stays a duplicate.  Elsewhere too, a
  receive stamp repeated with other values is a shared stamp (a 1 Hz source's jitter
  behind whole-second stamps).

The notes say which streams run faster than their stamps ("GYRO HDT:
10 records per 1 s stamp (a 10 Hz source behind whole-second stamps)").  A **back-step**
is a time lower than the one before by more than the tolerance: counted, and kept
(:data:`STEPS_KEPT` per file) as a :class:`~dracc.frames.ClockStep` (from, to, the line
after it) -- a logger replaying its recording steps back once per stream and replay;
no record is dropped or changed for it (frames are sorted by time).  A **gap** is a rise
by more than the gap threshold.

Civil-date arithmetic: Howard Hinnant's ``days_from_civil`` (proleptic Gregorian,
http://howardhinnant.github.io/date_algorithms.html), vectorised.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pandas as pd

from dracc.core.arrays import ArrayLike
from dracc.core.timefmt import iso_utc
from dracc.frames import MISSING_NS as MISSING_NS  # the "no time" marker (re-exported)
from dracc.frames import ClockStep, FileResult, TimeEvents

DAY_NS = 86_400 * 1_000_000_000
HALF_DAY_NS = DAY_NS // 2
GPS_WEEK_ROLLOVER_DAYS = 1024 * 7
WEEK_ROLLOVER_NS = GPS_WEEK_ROLLOVER_DAYS * DAY_NS
_EPOCH_2000_DAYS = 10957  # 2000-01-01 in days since 1970-01-01
#: the date a log with no date anywhere (and no ``--date``) is placed on: plainly not a
#: real one, so nobody takes it for the day of the voyage
ASSUMED_DATE = "2000-01-01"
ASSUMED_DATE_DAYS = _EPOCH_2000_DAYS
ASSUMED_DATE_NOTE = (
    f"no date in the log and none given: times of day placed on an assumed date, "
    f"{ASSUMED_DATE}; durations, dead reckoning and deviations hold, calendar dates in "
    "the report do not (pass --date YYYY-MM-DD for the real one)"
)


def days_from_civil(year: ArrayLike, month: ArrayLike, day: ArrayLike) -> np.ndarray:
    """Days since 1970-01-01 of a proleptic Gregorian date (arrays broadcast).

    Hinnant's algorithm: era = floor(y'/400) with y' = y - (m <= 2), day of era
    doe = 365*yoe + yoe//4 - yoe//100 + doy, days = era*146097 + doe - 719468.
    """
    y = np.asarray(year, dtype=np.int64) - (np.asarray(month) <= 2)
    m = np.asarray(month, dtype=np.int64)
    d = np.asarray(day, dtype=np.int64)
    era = np.floor_divide(y, 400)
    yoe = y - era * 400
    doy = (153 * (m + np.where(m > 2, -3, 9)) + 2) // 5 + d - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    days: np.ndarray = era * 146097 + doe - 719468
    return days


def valid_civil(year: ArrayLike, month: ArrayLike, day: ArrayLike) -> np.ndarray:
    """True where (year, month, day) is a real calendar date."""
    y = np.asarray(year, dtype=np.int64)
    m = np.asarray(month, dtype=np.int64)
    d = np.asarray(day, dtype=np.int64)
    leap = ((y % 4 == 0) & (y % 100 != 0)) | (y % 400 == 0)
    mdays = np.array([31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31, 31])
    dim = mdays[np.clip(m - 1, 0, 12)] + ((m == 2) & leap)
    valid: np.ndarray = (m >= 1) & (m <= 12) & (d >= 1) & (d <= dim)
    return valid


def today_days() -> int:
    """Today (UTC) in days since the epoch."""
    return (_dt.datetime.now(_dt.timezone.utc).date() - _dt.date(1970, 1, 1)).days


def fix_dates(date_days: np.ndarray, latest_days: int | None = None) -> tuple[np.ndarray, int, int]:
    """Check dates (days since epoch; -1 = none) for plausibility.

    Returns (fixed_days, n_rollover_corrected, n_implausible_unused): a date before
    2000-01-01 that lands in 2000-01-01..today+1 after adding 1024 GPS weeks is
    corrected; other dates outside that range become -1 (unused) and are counted.
    """
    latest = today_days() + 1 if latest_days is None else latest_days
    d = date_days.copy()
    has = d >= 0
    bad = has & ((d < _EPOCH_2000_DAYS) | (d > latest))
    shifted = d + GPS_WEEK_ROLLOVER_DAYS
    fixable = bad & (shifted >= _EPOCH_2000_DAYS) & (shifted <= latest)
    d[fixable] = shifted[fixable]
    unusable = bad & ~fixable
    d[unusable] = -1
    return d, int(fixable.sum()), int(unusable.sum())


def rollover_weeks(behind_ns: np.ndarray) -> np.ndarray:
    """k (1 or 2) where ``behind_ns`` (a receive time minus a record's own time) is 1024·k
    GPS weeks within a day (the latency check's tolerance; a midnight between), else 0."""
    k = np.rint(behind_ns / WEEK_ROLLOVER_NS).astype(np.int64)
    ok = (k >= 1) & (k <= 2) & (np.abs(behind_ns - k * WEEK_ROLLOVER_NS) <= DAY_NS)
    return np.where(ok, k, 0)


def drop_implausible_ext(
    ext_ns: np.ndarray, latest_days: int | None = None
) -> tuple[np.ndarray, int]:
    """Rule 4 for external times (TAG ``c:``, logger prefixes, MCAP log times): a time
    outside 2000-01-01 .. today+1 (a garbled prefix read as a Unix time, a bit flip in a
    year) is not used.  Returns (ext_ns with those set to MISSING_NS, n_unused)."""
    latest = today_days() + 1 if latest_days is None else latest_days
    has = ext_ns != MISSING_NS
    bad = has & ((ext_ns < _EPOCH_2000_DAYS * DAY_NS) | (ext_ns >= (latest + 1) * DAY_NS))
    if not bad.any():
        return ext_ns, 0
    return np.where(bad, MISSING_NS, ext_ns), int(bad.sum())


def nearest_day(tod_ns: np.ndarray, ref_ns: np.ndarray) -> np.ndarray:
    """Time of day placed on the UTC day that puts it nearest to ``ref_ns`` (rule 1)."""
    day0 = np.floor_divide(ref_ns, DAY_NS) * DAY_NS
    t = day0 + tod_ns
    t = np.where(t - ref_ns > HALF_DAY_NS, t - DAY_NS, t)
    placed: np.ndarray = np.where(ref_ns - t > HALF_DAY_NS, t + DAY_NS, t)
    return placed


@dataclass
class TimeBase:
    """Stateful resolver fed with the records of one file in stream order (rule 1-4).

    ``resolve`` returns the times it can give now and ``None`` when the block must
    wait for a later date (back-fill); call ``finish`` at the end of the file.
    """

    cfg_date_days: int | None = None
    day_index: int = 0
    last_tod_ns: int | None = None
    base_days: int | None = None
    last_time_ns: int | None = None
    rollovers: int = 0
    backward_midnight: int = 0
    derived: int = 0
    week_rollovers: int = 0
    implausible: int = 0
    date_changes: int = 0
    #: ``ASSUMED_DATE`` where the log had no date and none was given, else None
    assumed_date: str | None = None
    decisions: list[str] = field(default_factory=list)
    _pending: list[tuple[np.ndarray, ...]] = field(default_factory=list)

    def feed(
        self, tod_ns: np.ndarray, date_days: np.ndarray, ext_ns: np.ndarray
    ) -> list[np.ndarray]:
        """Feed one block (arrays in stream order); return a list of finished
        (block_id, time_ns) pairs in order (possibly empty, possibly several)."""
        ext_ns, nbad = drop_implausible_ext(ext_ns)
        self.implausible += nbad
        has_ext = ext_ns != MISSING_NS
        has_tod = tod_ns >= 0
        # rule 4: a date 1024·k weeks behind its record's external time (which places it)
        dated = np.flatnonzero(has_ext & has_tod & (date_days >= 0))
        k = rollover_weeks(ext_ns[dated] - date_days[dated] * DAY_NS - tod_ns[dated])
        if k.any():
            i, date_days = dated[k > 0], date_days.copy()
            date_days[i] += k[k > 0] * GPS_WEEK_ROLLOVER_DAYS
            self.week_rollovers += len(i)
            if not any(d.startswith("GPS week rollover") for d in self.decisions):
                self.decisions.append(
                    f"GPS week rollover: RMC/ZDA dates {1024 * int(k[k > 0][0])} weeks behind "
                    f"their receive times, the first received {iso_utc(int(ext_ns[i[0]]))}: "
                    "the day taken from the receive times"
                )
        date_days, nfix, nbad = fix_dates(date_days)
        self.week_rollovers += nfix
        self.implausible += nbad
        seq = has_tod & ~has_ext
        tods = tod_ns[seq]
        # rule 2: running day index over the time-of-day sequence
        last = self.last_tod_ns if self.last_tod_ns is not None else (tods[0] if len(tods) else 0)
        prev = np.concatenate(([last], tods[:-1]))
        jump = tods - prev
        step = (jump < -HALF_DAY_NS).astype(np.int64) - (jump > HALF_DAY_NS)
        self.rollovers += int((step > 0).sum())
        self.backward_midnight += int((step < 0).sum())
        dayidx = self.day_index + np.cumsum(step)
        if len(tods):
            self.day_index = int(dayidx[-1])
            self.last_tod_ns = int(tods[-1])
        dates = date_days[seq]
        base_cand = np.where(dates >= 0, dates - dayidx, np.iinfo(np.int64).min)
        self._pending.append((tod_ns, ext_ns, has_ext, has_tod, seq, dayidx, base_cand))
        if self.base_days is None:
            known = np.flatnonzero(base_cand != np.iinfo(np.int64).min)
            if len(known):
                self.base_days = int(base_cand[known[0]])
                if known[0] > 0 or len(self._pending) > 1:
                    self.decisions.append("date back-filled from a later RMC/ZDA date")
            elif seq.any() or len(self._pending) > 1:
                return []
        return self._flush()

    def _flush(self) -> list[np.ndarray]:
        out: list[np.ndarray] = []
        for tod_ns, ext_ns, has_ext, has_tod, seq, dayidx, base_cand in self._pending:
            t = np.full(len(tod_ns), MISSING_NS, dtype=np.int64)
            both = has_ext & has_tod
            t[both] = nearest_day(tod_ns[both], ext_ns[both])  # rule 1
            only_ext = has_ext & ~has_tod
            t[only_ext] = ext_ns[only_ext]
            if seq.any():
                if self.base_days is None:
                    return out  # cannot happen: feed() checked
                sentinel = np.iinfo(np.int64).min
                idx = np.where(base_cand != sentinel, np.arange(len(base_cand)), -1)
                idx = np.maximum.accumulate(idx)
                base = np.where(idx >= 0, base_cand[np.maximum(idx, 0)], self.base_days)
                changed = np.flatnonzero(np.diff(np.concatenate(([self.base_days], base))) != 0)
                self.date_changes += len(changed)
                if len(base):
                    self.base_days = int(base[-1])
                t[seq] = (base + dayidx) * DAY_NS + tod_ns[seq]  # rule 2
            # rule 3: records without any time take the preceding timed record's time
            none = ~has_ext & ~has_tod
            if none.any():
                self.derived += int(none.sum())
                pos = np.where(t != MISSING_NS, np.arange(len(t)), -1)
                pos = np.maximum.accumulate(pos)
                filled = np.where(pos >= 0, t[np.maximum(pos, 0)], MISSING_NS)
                if self.last_time_ns is not None:
                    filled = np.where(pos < 0, self.last_time_ns, filled)
                # leading records with nothing before: the next timed record (back-fill)
                lead = filled == MISSING_NS
                if lead.any():
                    nxt = np.where(t != MISSING_NS, np.arange(len(t)), len(t))
                    nxt = np.minimum.accumulate(nxt[::-1])[::-1]
                    ok = nxt < len(t)
                    filled[lead & ok] = t[nxt[lead & ok]]
                t[none] = filled[none]
            good = t[t != MISSING_NS]
            if len(good):
                self.last_time_ns = int(good[-1])
            out.append(t)
        self._pending = []
        return out

    def finish(self) -> list[np.ndarray]:
        """End of file: resolve what waits, on ``cfg.date`` if the log had no date.

        A log with no date at all (no RMC/ZDA date, no TAG or prefix time) and none given
        is placed on an assumed date, :data:`ASSUMED_DATE` (dead reckoning and
        deviations need only time differences); ``assumed_date`` says so and a decision
        tells the user.  Where some records carry a receive time and the others only a
        time of day, the others are placed on the day of the first receive time.
        """
        if not self._pending:
            return []
        if self.base_days is None:
            first = next((p[5][0] for p in self._pending if len(p[5])), 0)
            ext = next((p[1][p[2]][0] for p in self._pending if p[2].any()), None)
            if self.cfg_date_days is not None:
                self.base_days = int(self.cfg_date_days - first)
                self.decisions.append("no date in the log: date taken from --date / ingest.date")
            elif ext is not None:
                self.base_days = int(int(ext) // DAY_NS - first)
                self.decisions.append(
                    "no date in the log's sentences: times of day placed on the day of "
                    "its first receive time (pass --date YYYY-MM-DD to set it)"
                )
            else:
                self.base_days = int(ASSUMED_DATE_DAYS - first)
                self.assumed_date = ASSUMED_DATE
                self.decisions.append(ASSUMED_DATE_NOTE)
        return self._flush()


#: back-steps kept as :class:`~dracc.frames.ClockStep` per file (``backsteps`` counts all)
STEPS_KEPT = 300
#: a stream with at least this many records per distinct time runs faster than its stamps
FASTER_THAN_STAMPS = 1.5
#: the stamp resolutions told apart (ns) and their names in the notes
_RESOLUTIONS = (
    (1_000_000_000, "whole-second"),
    (100_000_000, "0.1 s"),
    (10_000_000, "0.01 s"),
    (1_000_000, "1 ms"),
)
#: the columns of a frame that are not a record's values
_BOOKKEEPING = frozenset({"time_ns", "recv_ns", "line", "source", "talker", "sentence"})
_EXAMPLES = 3  #: examples kept of each event (back-step, gap, duplicate)
#: the repeats of the time before, by what else was repeated (see :meth:`_Stream.split`)
_REPEATS = ("same_fix", "same_stamp", "other_fix", "other_stamp")


def _codes(values: ArrayLike | pd.Series) -> tuple[np.ndarray, list[Any]]:
    """(codes, names) of a categorical or any array of labels."""
    if isinstance(values, pd.Series) and isinstance(values.dtype, pd.CategoricalDtype):
        values = values.array
    if isinstance(values, pd.Categorical):
        return values.codes.astype(np.int64), list(values.categories)
    codes, names = pd.factorize(np.asarray(values, dtype=object))
    return codes.astype(np.int64), list(names)


@dataclass
class _Stream:
    """The running figures of one stream: one source's records of one sentence type."""

    records: int = 0  #: records compared (those with a time of their own)
    stamps: int = 0  #: records whose time differs from the one before (the first counts)
    #: records repeating the time of the one before, by what else they repeat:
    #: same_fix/other_fix: its own time of fix with the same/other values;
    #: same_stamp/other_stamp: a receive stamp with the same/other values
    repeats: dict[str, int] = field(default_factory=lambda: dict.fromkeys(_REPEATS, 0))
    backsteps: int = 0
    gaps: int = 0
    max_gap_ns: int = 0
    #: the steps forward (not gaps) in ns and their number: the stamps' cadence
    advance_ns: int = 0
    advances: int = 0
    last_ns: int | None = None
    last_sig: int | None = None
    #: index into _RESOLUTIONS of the coarsest resolution all stamps are multiples of
    resolution: int = 0
    #: (file, line) of the first few repeats of each kind
    first: dict[str, list[tuple[str, int]]] = field(default_factory=dict)

    def faster(self) -> bool:
        """At least :data:`FASTER_THAN_STAMPS` records per distinct time: a source faster
        than the resolution of its stamps."""
        return self.records >= FASTER_THAN_STAMPS * max(self.stamps, 1)

    def split(self) -> tuple[int, int, list[str]]:
        """(duplicates, shared stamps, the repeat kinds that are duplicates): the rule
        of the module doc."""
        dup = ["same_fix"] if self.faster() else ["same_fix", "same_stamp", "other_fix"]
        n_dup = sum(self.repeats[k] for k in dup)
        return n_dup, sum(self.repeats.values()) - n_dup, dup

    def shared_note(self, key: str, stype: str) -> str | None:
        """What the records sharing stamps are, where the stream runs faster than its
        stamps (None otherwise)."""
        _, shared, _ = self.split()
        if not shared or not self.faster():
            return None
        per = self.records / max(self.stamps, 1)
        every_s = self.advance_ns / self.advances / 1e9 if self.advances else 0.0
        what = f"{key} {stype}: {round(per, 1):g} records per stamp"
        if self.resolution < len(_RESOLUTIONS):
            res_ns, name = _RESOLUTIONS[self.resolution]
            res_s = res_ns / 1e9
            if 0 < every_s <= 2 * res_s:
                what = (
                    f"{key} {stype}: {round(per, 1):g} records per {res_s:g} s stamp (a "
                    f"{round(per / every_s, 1):g} Hz source behind {name} stamps)"
                )
        if what.endswith("per stamp") and every_s > 0:
            what += f", a stamp every {every_s:.3g} s (several records of one instant)"
        return f"{what}: {shared} records share a stamp, not duplicates"


@dataclass
class CountedTimeEvents(TimeEvents):
    """A file's :class:`~dracc.frames.TimeEvents` with the figures behind them, per source
    (``dracc inspect`` shows them)."""

    #: source -> {duplicates, backsteps, gaps, max_gap_s, shared_stamps}
    per_source: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: records sharing a stamp with the record before (not duplicates: see the module doc)
    shared_stamps: int = 0
    #: the decisions that are notes on the events (the streams faster than their stamps)
    event_notes: list[str] = field(default_factory=list)


@dataclass
class EventCounter:
    """Counts duplicates, shared stamps, back-steps and gaps per stream (one source's
    records of one sentence type) over blocks in stream order; keeps the back-steps as
    :class:`~dracc.frames.ClockStep` (the first :data:`STEPS_KEPT`).

    Only records with their own time (time of fix or receive stamp) are compared, each
    with the record before it in the stream: a time equal to it is a duplicate or a
    shared stamp (the rule of the module doc), a decrease by more than ``tolerance_s`` a
    back-step, an increase by more than ``gap_s`` a gap.  The records of one line (an RMC
    gives a position and a ground record) are one record of its stream.
    """

    gap_s: float = 60.0
    tolerance_s: float = 1.0
    streams: dict[tuple[str, str], _Stream] = field(default_factory=dict)
    #: (file, line, what) of the first back-steps and gaps (duplicates: :meth:`all_examples`)
    examples: list[tuple[str, int, str]] = field(default_factory=list)
    steps: list[ClockStep] = field(default_factory=list)

    def add(
        self,
        kind: str,
        source: ArrayLike | pd.Series,
        time_ns: np.ndarray,
        own: np.ndarray,
        line: np.ndarray,
        file: str,
        sentence: ArrayLike | pd.Series | None = None,
        fix: np.ndarray | None = None,
        signature: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> None:
        """Arrays aligned with ``time_ns``; ``own``: the records with a time of their own;
        ``fix``: those whose time is their own time of fix (default none: receive stamps);
        ``signature(rows)``: the values of records ``rows`` as numbers equal only for equal
        values, summed over the records of a line (default: records of one time are taken
        as the same).  Streams are told apart by (source, sentence type; ``kind`` where no
        sentence is given) and ordered by line."""
        if len(time_ns) == 0:
            return
        kc, kn = _codes(source)
        sc, sn = _codes(np.full(len(time_ns), kind, dtype=object) if sentence is None else sentence)
        self._add(kc, kn, sc, sn, time_ns, own, line, file, fix, signature)

    def _add(
        self,
        kc: np.ndarray,
        kn: list[Any],
        sc: np.ndarray,
        sn: list[Any],
        time_ns: np.ndarray,
        own: np.ndarray,
        line: np.ndarray,
        file: str,
        fix: np.ndarray | None,
        signature: Callable[[np.ndarray], np.ndarray] | None,
    ) -> None:
        """:meth:`add` with the sources and sentences as codes into ``kn`` and ``sn``."""
        sel = np.flatnonzero(np.asarray(own, dtype=bool))
        if len(sel) == 0:
            return
        width = len(sn) + 1
        combo = kc[sel] * width + sc[sel]
        ln = np.asarray(line, dtype=np.int64)[sel]
        # stream order: by line, then by stream (stable; small keys as int16: a radix sort)
        o = np.argsort(ln, kind="stable") if (ln[1:] < ln[:-1]).any() else np.arange(len(ln))
        c = combo[o]
        o = o[np.argsort(c.astype(np.int16) if c.max() < 1 << 15 else c, kind="stable")]
        combo, ln, every = combo[o], ln[o], sel[o]
        # the records of one line are one record of its stream (their values summed)
        one = np.ones(len(every), dtype=bool)
        one[1:] = (combo[1:] != combo[:-1]) | (ln[1:] != ln[:-1])
        run = np.cumsum(one) - 1
        combo, ln, rows = combo[one], ln[one], every[one]
        t = np.asarray(time_ns, dtype=np.int64)[rows]
        fx = np.zeros(len(rows), bool) if fix is None else np.asarray(fix, dtype=bool)[rows]
        start = np.ones(len(rows), dtype=bool)
        start[1:] = combo[1:] != combo[:-1]
        firsts = np.flatnonzero(start)
        lasts = np.append(firsts[1:] - 1, len(rows) - 1)
        keys = [(str(kn[u // width]), str(sn[u % width])) for u in combo[firsts].tolist()]
        streams = [self.streams.setdefault(k, _Stream()) for k in keys]
        carried = [s.last_ns is not None for s in streams]
        has_prev = np.ones(len(rows), dtype=bool)
        has_prev[firsts] = carried
        prev = np.empty(len(rows), dtype=np.int64)
        prev[1:] = t[:-1]
        prev[firsts] = [s.last_ns if s.last_ns is not None else 0 for s in streams]
        d = np.where(has_prev, t - prev, 0)
        eq = has_prev & (d == 0)
        # the values of the repeats and of the records before them (carried from the
        # block before for a stream's first), and of each stream's last for the next block
        same = eq.copy()
        if signature is not None:
            want = np.zeros(len(rows), dtype=bool)
            want[lasts] = True
            want[eq] = True
            want[:-1] |= eq[1:] & ~start[1:]
            h = np.zeros(len(every), dtype=np.uint64)
            need = want[run]
            h[need] = signature(every[need])
            sig = np.add.reduceat(h, np.flatnonzero(one))  # wraps: a sum modulo 2**64
            psig = np.zeros(len(rows), dtype=np.uint64)
            psig[1:] = sig[:-1]
            known = np.ones(len(rows), dtype=bool)
            for i, s in zip(firsts.tolist(), streams, strict=True):
                known[i] = s.last_sig is not None
                psig[i] = s.last_sig if s.last_sig is not None else 0
            same = eq & known & (sig == psig)
        gap_ns = int(self.gap_s * 1e9)
        back = has_prev & (d < -int(self.tolerance_s * 1e9))
        gap = has_prev & (d > gap_ns)
        sid = np.cumsum(start) - 1

        def per(mask: np.ndarray) -> list[int]:
            counts: list[int] = np.bincount(sid[mask], minlength=len(firsts)).tolist()
            return counts

        totals = {
            "records": per(np.ones(len(rows), dtype=bool)),
            "stamps": per(~eq),
            "same_fix": per(same & fx),
            "same_stamp": per(same & ~fx),
            "other_fix": per(eq & ~same & fx),
            "other_stamp": per(eq & ~same & ~fx),
            "backsteps": per(back),
            "gaps": per(gap),
        }
        max_d = np.maximum.reduceat(np.where(has_prev, d, 0), firsts).tolist()
        ahead = has_prev & (d > 0) & ~gap
        advance = np.bincount(sid[ahead], d[ahead] / 1e9, minlength=len(firsts)).tolist()
        totals["advances"] = per(ahead)
        for j, s in enumerate(streams):
            s.records += totals["records"][j]
            s.stamps += totals["stamps"][j]
            for k in _REPEATS:
                s.repeats[k] += totals[k][j]
            s.backsteps += totals["backsteps"][j]
            s.gaps += totals["gaps"][j]
            s.max_gap_ns = max(s.max_gap_ns, int(max_d[j]))
            s.advance_ns += round(advance[j] * 1e9)
            s.advances += totals["advances"][j]
            s.last_ns = int(t[lasts[j]])
            s.last_sig = int(sig[lasts[j]]) if signature is not None else None
        self._resolution(streams, t, sid)
        self._note_repeats(streams, sid, ln, file, same, eq, fx)
        for what, mask in (("back-step", back), ("gap", gap)):
            room = max(0, _EXAMPLES - sum(e[2].startswith(what) for e in self.examples))
            for j in np.flatnonzero(mask)[:room].tolist():
                key, stype = keys[sid[j]]
                self.examples.append(
                    (file, int(ln[j]), f"{what} {d[j] / 1e9:+.3f} s in {key} {stype}")
                )
        for j in np.flatnonzero(back)[: max(0, STEPS_KEPT - len(self.steps))].tolist():
            key, stype = keys[sid[j]]
            self.steps.append(ClockStep(file, int(ln[j]), key, stype, int(prev[j]), int(t[j])))

    @staticmethod
    def _resolution(streams: list[_Stream], t: np.ndarray, sid: np.ndarray) -> None:
        """Each stream's coarsest stamp resolution (:data:`_RESOLUTIONS`) so far."""
        for i, (res_ns, _) in enumerate(_RESOLUTIONS):
            if all(s.resolution > i for s in streams):
                continue
            off = np.bincount(sid[t % res_ns != 0], minlength=len(streams))
            for s, n in zip(streams, off.tolist(), strict=True):
                if s.resolution == i and n:
                    s.resolution = i + 1

    @staticmethod
    def _note_repeats(
        streams: list[_Stream],
        sid: np.ndarray,
        ln: np.ndarray,
        file: str,
        same: np.ndarray,
        eq: np.ndarray,
        fx: np.ndarray,
    ) -> None:
        """The (file, line) of the first few repeats of each kind of each stream."""
        kinds = (
            ("same_fix", same & fx),
            ("same_stamp", same & ~fx),
            ("other_fix", eq & ~same & fx),
        )
        for what, mask in kinds:
            idx = np.flatnonzero(mask)
            if not len(idx):
                continue
            s_of = sid[idx]
            first = np.flatnonzero(np.r_[True, s_of[1:] != s_of[:-1]])
            rank = np.arange(len(idx)) - np.repeat(first, np.diff(np.r_[first, len(idx)]))
            for j in idx[rank < _EXAMPLES].tolist():
                kept = streams[sid[j]].first.setdefault(what, [])
                if len(kept) < _EXAMPLES:
                    kept.append((file, int(ln[j])))

    @property
    def per_source(self) -> dict[str, dict[str, Any]]:
        """source -> {duplicates, backsteps, gaps, max_gap_s, shared_stamps}."""
        out: dict[str, dict[str, Any]] = {}
        for (key, _), s in self.streams.items():
            dup, shared, _ = s.split()
            st = out.setdefault(
                key,
                {"duplicates": 0, "backsteps": 0, "gaps": 0, "max_gap_s": 0.0, "shared_stamps": 0},
            )
            st["duplicates"] += dup
            st["shared_stamps"] += shared
            st["backsteps"] += s.backsteps
            st["gaps"] += s.gaps
            st["max_gap_s"] = max(st["max_gap_s"], s.max_gap_ns / 1e9)
        return out

    def totals(self) -> dict[str, int]:
        out = {"duplicates": 0, "backsteps": 0, "gaps": 0, "shared_stamps": 0}
        for st in self.per_source.values():
            for k in out:
                out[k] += st[k]
        return out

    def all_examples(self) -> list[tuple[str, int, str]]:
        """The first back-steps and gaps, then the first duplicates (in line order)."""
        dups = []
        for (key, stype), s in self.streams.items():
            for what in s.split()[2]:
                why = (
                    "the record again"
                    if what.startswith("same")
                    else "its time of fix again, other values"
                )
                for file, line in s.first.get(what, []):
                    dups.append((file, line, f"duplicate +0.000 s in {key} {stype}: {why}"))
        return self.examples + sorted(dups, key=lambda e: (e[0], e[1]))[:_EXAMPLES]

    def notes(self) -> list[str]:
        """The streams that run faster than their stamps, said once each."""
        out = [s.shared_note(key, stype) for (key, stype), s in self.streams.items()]
        return [n for n in out if n]

    def time_events(self, decisions: list[str] | None = None) -> CountedTimeEvents:
        """The totals, first examples and back-steps as a file's time events
        (``decisions``: the reader's, before the notes on the events)."""
        tot = self.totals()
        notes = self.notes()
        return CountedTimeEvents(
            duplicates=tot["duplicates"],
            backsteps=tot["backsteps"],
            gaps=tot["gaps"],
            decisions=list(decisions or []) + notes,
            examples=self.all_examples(),
            steps=list(self.steps),
            per_source=self.per_source,
            shared_stamps=tot["shared_stamps"],
            event_notes=notes,
        )


def _mix(z: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser: every bit of ``z`` (uint64) moves every bit of the result."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    out: np.ndarray = z ^ (z >> np.uint64(31))
    return out


def _value_hash(df: pd.DataFrame, rows: np.ndarray, seed: int) -> np.ndarray:
    """The value columns of ``df``'s rows ``rows`` as one number each (their 64-bit words,
    floats by their bits, mixed one after the other; ``seed`` tells kinds apart)."""
    h = np.full(len(rows), seed, dtype=np.uint64)
    for c in df.columns:
        if c in _BOOKKEEPING:
            continue
        col = df[c]
        if isinstance(col.dtype, pd.CategoricalDtype):
            v = col.cat.codes.to_numpy()[rows].astype(np.int64).view(np.uint64)
        else:
            a = col.to_numpy()[rows]
            if a.dtype.kind == "f":
                v = a.astype(np.float64, copy=False).view(np.uint64)
            elif a.dtype.kind in "iubmM":
                v = a.astype(np.int64).view(np.uint64)
            else:
                v = pd.util.hash_array(np.asarray(a, dtype=object))
        h = _mix(h ^ v)
    return h


def feed_frames(
    ec: EventCounter,
    frames: dict[str, pd.DataFrame],
    file: str,
    own: dict[str, np.ndarray] | None = None,
    fix: dict[str, np.ndarray] | None = None,
) -> None:
    """Feed the records of ``frames`` (a block of a stream, or a whole file: any order,
    each stream is taken in line order) to ``ec``: the one way every reader counts time
    events.  ``own``: per kind, the records with a time of their own (default all);
    ``fix``: those whose time is their own time of fix (default: those with a receive
    time beside it, ``recv_ns``)."""
    parts = [(k, df) for k, df in frames.items() if len(df)]
    if not parts:
        return
    src_names: dict[str, int] = {}
    sent_names: dict[str, int] = {}
    cols: dict[str, list[np.ndarray]] = {k: [] for k in ("src", "sent", "t", "ln", "own", "fix")}
    for kind, df in parts:
        for name, col, names in (("src", "source", src_names), ("sent", "sentence", sent_names)):
            codes, labels = _codes(df[col])
            lut = np.array([names.setdefault(str(x), len(names)) for x in labels] + [-1])
            cols[name].append(lut[codes])
        cols["t"].append(df["time_ns"].to_numpy(np.int64))
        cols["ln"].append(df["line"].to_numpy(np.int64))
        cols["own"].append(np.ones(len(df), bool) if own is None else own[kind])
        if fix is not None:
            cols["fix"].append(fix[kind])
        elif "recv_ns" in df:
            cols["fix"].append(df["recv_ns"].to_numpy() != MISSING_NS)
        else:
            cols["fix"].append(np.zeros(len(df), bool))
    sizes = np.cumsum([0] + [len(df) for _, df in parts])

    def values(rows: np.ndarray) -> np.ndarray:
        """The values of records ``rows`` (of all the kinds, in order) as numbers."""
        out = np.zeros(len(rows), dtype=np.uint64)
        part = np.searchsorted(sizes, rows, "right") - 1
        for j in range(len(parts)):
            at = np.flatnonzero(part == j)
            if len(at):
                out[at] = _value_hash(parts[j][1], rows[at] - sizes[j], 2 * j + 3)
        return out

    ec._add(
        np.concatenate(cols["src"]),
        list(src_names),
        np.concatenate(cols["sent"]),
        list(sent_names),
        np.concatenate(cols["t"]),
        np.concatenate(cols["own"]),
        np.concatenate(cols["ln"]),
        file,
        np.concatenate(cols["fix"]),
        values,
    )


def count_events(r: FileResult, gap_s: float = 60.0, tolerance_s: float = 1.0) -> EventCounter:
    """Count the time events of a file read whole (``r``'s frames, in line order) into
    ``r.time_events``, replacing any counted before (its decisions, rollovers and dates
    kept); the counter, with the figures per source."""
    ec = EventCounter(gap_s=gap_s, tolerance_s=tolerance_s)
    feed_frames(ec, r.frames, r.path)
    old = r.time_events
    said = set(getattr(old, "event_notes", ()))
    te = ec.time_events([d for d in old.decisions if d not in said])
    te.rollovers, te.implausible_dates = old.rollovers, old.implausible_dates
    te.assumed_date = old.assumed_date
    r.time_events = te
    return ec


def merge_events(into: TimeEvents, e: TimeEvents, rename: dict[str, str] | None = None) -> None:
    """Add the counts, back-steps (their sources renamed by ``rename``) and, between
    :class:`CountedTimeEvents`, the figures per source of ``e`` into ``into``; decisions
    and examples are the caller's."""
    for k in ("duplicates", "backsteps", "gaps", "rollovers", "implausible_dates"):
        setattr(into, k, getattr(into, k) + getattr(e, k))
    into.assumed_date = into.assumed_date or e.assumed_date
    names = rename or {}
    into.steps.extend(
        s if s.source not in names else replace(s, source=names[s.source]) for s in e.steps
    )
    if isinstance(into, CountedTimeEvents) and isinstance(e, CountedTimeEvents):
        into.shared_stamps += e.shared_stamps
        into.event_notes.extend(e.event_notes)
        for key, st in e.per_source.items():
            mine = into.per_source.setdefault(names.get(key, key), dict.fromkeys(st, 0))
            for k, v in st.items():
                mine[k] = max(mine[k], v) if k == "max_gap_s" else mine[k] + v
