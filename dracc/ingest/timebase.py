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
4. A date earlier than 2000-01-01 that becomes plausible when 1024 GPS weeks are added
   is a GPS week-number rollover: corrected, counted (``implausible_dates``) and
   noted.  Other dates outside 2000-01-01 .. today+1 are counted and noted, not used.

Civil-date arithmetic: Howard Hinnant's ``days_from_civil`` (proleptic Gregorian,
http://howardhinnant.github.io/date_algorithms.html), vectorised.
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from dracc.core.arrays import ArrayLike
from dracc.frames import MISSING_NS as MISSING_NS  # the "no time" marker (re-exported)
from dracc.frames import TimeEvents

DAY_NS = 86_400 * 1_000_000_000
HALF_DAY_NS = DAY_NS // 2
GPS_WEEK_ROLLOVER_DAYS = 1024 * 7
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
        date_days, nfix, nbad = fix_dates(date_days)
        self.week_rollovers += nfix
        self.implausible += nbad
        ext_ns, nbad = drop_implausible_ext(ext_ns)
        self.implausible += nbad
        has_ext = ext_ns != MISSING_NS
        has_tod = tod_ns >= 0
        seq = has_tod & ~has_ext
        tods = tod_ns[seq]
        # rule 2: running day index over the time-of-day sequence
        prev = np.concatenate(
            (
                [
                    self.last_tod_ns
                    if self.last_tod_ns is not None
                    else (tods[0] if len(tods) else 0)
                ],
                tods[:-1],
            )
        )
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


def _codes(values: ArrayLike | pd.Series) -> tuple[np.ndarray, list[Any]]:
    """(codes, names) of a categorical or any array of labels."""
    if isinstance(values, pd.Series) and isinstance(values.dtype, pd.CategoricalDtype):
        values = values.array
    if isinstance(values, pd.Categorical):
        return values.codes.astype(np.int64), list(values.categories)
    codes, names = pd.factorize(np.asarray(values, dtype=object))
    return codes.astype(np.int64), list(names)


@dataclass
class EventCounter:
    """Counts duplicates, back-steps and gaps per (source, kind) over blocks in order.

    Only records with their own time (time of fix or external time) are compared;
    a duplicate is a time equal to the previous one of the same source and kind, a
    back-step a decrease by more than ``tolerance_s``, a gap an increase by more than
    ``gap_s``.
    """

    gap_s: float = 60.0
    tolerance_s: float = 1.0
    last: dict[tuple[str, str], int] = field(default_factory=dict)
    per_source: dict[str, dict[str, Any]] = field(
        default_factory=dict
    )  #: source -> {"duplicates","backsteps","gaps","max_gap_s"}
    examples: list[tuple[str, int, str]] = field(default_factory=list)

    def add(
        self,
        kind: str,
        source: np.ndarray,
        time_ns: np.ndarray,
        own: np.ndarray,
        line: np.ndarray,
        file: str,
        sentence: np.ndarray | None = None,
    ) -> None:
        """Arrays aligned with ``time_ns`` in stream order; streams are told apart by
        (source, sentence type) so the GGA, GLL and RMC of one fix are not duplicates."""
        if len(time_ns) == 0:
            return
        sc, sn = _codes(np.full(len(time_ns), kind, dtype=object) if sentence is None else sentence)
        kc, kn = _codes(source)
        combo = kc.astype(np.int64) * (len(sn) + 1) + sc
        # the rows of each (source, sentence) stream, in stream order: one stable sort
        counts = np.bincount(combo)
        ucombo = np.flatnonzero(counts)
        # small keys as int16: numpy's stable sort is then a radix sort (the same order)
        order = np.argsort(
            combo.astype(np.int16) if len(counts) <= 1 << 15 else combo, kind="stable"
        )
        bounds = np.concatenate(([0], np.cumsum(counts[ucombo])))
        gap_ns = int(self.gap_s * 1e9)
        tol_ns = int(self.tolerance_s * 1e9)
        for i, uc in enumerate(ucombo.tolist()):
            key, stype = str(kn[uc // (len(sn) + 1)]), str(sn[uc % (len(sn) + 1)])
            rows = order[bounds[i] : bounds[i + 1]]
            sel = rows[own[rows]]
            t = time_ns[sel]
            if len(t) == 0:
                continue
            ln = line[sel]
            prev = self.last.get((key, stype))
            tt = np.concatenate(([prev], t)) if prev is not None else t
            d = np.diff(tt)
            st = self.per_source.setdefault(
                key, {"duplicates": 0, "backsteps": 0, "gaps": 0, "max_gap_s": 0.0}
            )
            dup = d == 0
            back = d < -tol_ns
            gap = d > gap_ns
            st["duplicates"] += int(dup.sum())
            st["backsteps"] += int(back.sum())
            st["gaps"] += int(gap.sum())
            if len(d):
                st["max_gap_s"] = max(st["max_gap_s"], float(d.max()) / 1e9)
            lines_d = ln if prev is not None else ln[1:]
            for what, mask in (("back-step", back), ("gap", gap), ("duplicate", dup)):
                room = max(0, 3 - sum(e[2].startswith(what) for e in self.examples))
                for j in np.flatnonzero(mask)[:room]:
                    self.examples.append(
                        (file, int(lines_d[j]), f"{what} {d[j] / 1e9:+.3f} s in {key} {stype}")
                    )
            self.last[(key, stype)] = int(t[-1])

    def totals(self) -> dict[str, int]:
        out = {"duplicates": 0, "backsteps": 0, "gaps": 0}
        for st in self.per_source.values():
            for k in out:
                out[k] += st[k]
        return out

    def time_events(self, decisions: list[str] | None = None) -> TimeEvents:
        """The totals and first examples as a file's :class:`~dracc.frames.TimeEvents`."""
        tot = self.totals()
        return TimeEvents(
            duplicates=tot["duplicates"],
            backsteps=tot["backsteps"],
            gaps=tot["gaps"],
            decisions=list(decisions or []),
            examples=list(self.examples),
        )
