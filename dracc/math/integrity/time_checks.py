"""time: the logger's clock and the receivers' own times of fix, judged over the night.

Five checks, each a :class:`Check` of the family ``time``:

``backstep``, ``loop`` (one each per voyage: the logger's property; :mod:`.clock_steps`)
    the logger's times going back (:attr:`dracc.frames.TimeEvents.steps`) by more than
    ``backstep_min_s``, a short run of records out of order passed over; the steps of one
    logger at once are one event with its sources listed: a ``loop`` where the records
    after the step repeat, values and all, those recorded at those times before it (a
    replayed recording), a ``backstep`` where fresh values arrive at times already
    recorded (the clock set back).  Rules on recorded times: false-alarm probability 0.
``leap_second`` (per source with its own time of fix beside a receive time)
    ``a = time of fix - receive time``, the time of fix *ahead* of the logger clock, which
    no delay makes.  Spells of at least ``spell_min_s`` where the running median (5
    records) of ``a`` is ``clock_ahead_min_s`` or more -- never less than the resolution
    of the logger's stamps: whole-second stamps cut a receipt at 12:00:00.3 to 12:00:00,
    so a fix of 12:00:00.0 shows ``a`` up to 1 s short of a whole second -- fail, named by
    the whole number of seconds nearest (18 s: GPS time written without the UTC offset; 1
    or 2 s: a stale leap-second count).  A spell that begins where the logger clock was
    set back (a ``backstep`` event of about its size) is that event, not a second
    finding.  Two sources whose times of fix at the same receive times differ by a steady
    whole number of seconds of at least :data:`CROSS_MIN_S` (more than the latencies of
    two receivers can differ by) fail on the source ahead, where neither already fails
    against the logger clock.  A time of fix *behind* the logger clock is latency's
    (:mod:`.latency`).  Rule: probability 0.
``week_rollover`` (one per voyage)
    dates 1024 GPS weeks early, repaired by the ingest (:func:`dracc.ingest.timebase.fix_dates`,
    its decision note per file): a ``fail`` saying where and how many, with the
    receivers that send dates in that file.  Rule: probability 0.
``clock_drift`` (per source with its own time of fix beside a receive time)
    the slope of ``receive time - time of fix`` over the night: Theil-Sen over the medians
    of up to :data:`DRIFT_BINS` equal stretches of time, its σ from the residuals about
    the line (robust, widened by their lag-1 autocorrelation).  Fails where the slope is
    significant (two-sided z-test at ``false_alarm``) *and* moves the offset by more than
    ``clock_drift_max_s`` over the source's span.  Stated rate: ``false_alarm``.
``no_clock`` (per source of a log without a clock, ``not_checked``)
    its times are only the order of its records: none of the above is made for it.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dracc.core import distributions as dist
from dracc.core.config import IntegrityConfig
from dracc.core.timefmt import iso_utc
from dracc.core.units import NS_PER_S
from dracc.frames import MISSING_NS, Voyage
from dracc.math.integrity.clock_steps import (
    GROUP_NS,
    WEEK_ROLLOVER_NS,
    WEEK_ROLLOVER_TOL_NS,
    StepEvent,
    step_checks,
    step_events,
)
from dracc.math.integrity.helpers import (
    MAX_EVIDENCE,
    NO_CLOCK,
    by_source,
    present_keys,
    robust_sigma,
    role_of,
    runs,
    statistic,
    threshold,
)
from dracc.math.integrity.results import Check

__all__ = ["OffsetSeries", "offset_series", "time_checks"]

#: the running median of the clock offset (records) before a spell is judged
SMOOTH = 5
#: two receivers' times of fix at the same receive times this far apart, steadily, in
#: whole seconds, are a leap-second count apart (their latencies differ by less: a
#: receiver, a relay and a logger queue make up to about 2 s behind, never ahead)
CROSS_MIN_S = 2.5
#: ... whole: within this of a whole number of seconds; steady: this share of the pairs
CROSS_WHOLE_S = 0.2
CROSS_STEADY = 0.9
#: receive times of two sources this close are 'the same receive time'
CROSS_MATCH_NS = NS_PER_S // 2
#: the drift is fitted on the medians of up to this many equal stretches of time
DRIFT_BINS = 100
DRIFT_MIN_BINS = 10  #: ... and needs at least this many stretches with records
#: a change of the offset between two stretches beyond this (and 10 sigma) is a step, not drift
JUMP_MIN_S = 0.5
GPS_UTC_S = 18  #: GPS time - UTC since 2017-01-01
#: a receiver's latency shortens the lead of its time of fix by up to about this much (and
#: a logger clock a little behind lengthens it by up to 1 - this)
LATENCY_ALLOWANCE_S = 0.6
_ROLLOVER = re.compile(r"^(?P<file>.*?): (?P<n>\d+) dates corrected for the GPS week rollover")
_ROLLOVER_SOURCE = re.compile(r"the first at message \d+ \((?P<key>[^,]+),")
_STAMP_QUANTA_NS = (NS_PER_S, NS_PER_S // 10, NS_PER_S // 100, NS_PER_S // 1000)


def time_checks(voyage: Voyage, cfg: IntegrityConfig, start_ns: int, end_ns: int) -> list[Check]:
    """Every time check of ``voyage`` over the night [start_ns, end_ns]."""
    win = {"start_ns": int(start_ns), "end_ns": int(end_ns)}
    checks = no_clock_checks(voyage)
    clocked = present_keys(voyage) - voyage.clockless
    if not clocked:
        return checks
    events, displaced = step_events(voyage, cfg)
    series = offset_series(voyage)
    drift = [clock_drift_check(voyage, cfg, s) for s in series.values()]
    drifting = {str(c.source) for c in drift if c.status == "fail"}
    ends: list[tuple[str, int, float]] = []
    leap = leap_second_checks(voyage, cfg, series, events, drifting, ends)
    # a receiver's own time stepping back where its lead ended is that lead, said once
    events = [replace(e, kind="leap_second") if _leap_end(e, ends) else e for e in events]
    checks += step_checks(events, displaced, cfg, win)
    checks.append(week_rollover_check(voyage, win, events, series))
    return checks + leap + drift


def _leap_end(e: StepEvent, ends: list[tuple[str, int, float]]) -> bool:
    """A back-step event of the sources whose time of fix was ahead of the logger clock,
    where that lead ended and by about as much."""
    srcs = {v.source for v in e.verdicts}
    return e.kind == "backstep" and any(
        all(src == k for k in srcs)
        and abs(e.from_ns - end_ns) <= GROUP_NS
        and abs(e.back_s - ahead) <= max(2.0, 0.1 * ahead)
        for src, end_ns, ahead in ends
    )


# ----------------------------------------------------------------------- no clock


def no_clock_checks(voyage: Voyage) -> list[Check]:
    """One ``not_checked`` entry per source of a log without a clock."""
    rule = "the logger's clock and the receivers' times of fix (back-steps, offsets, drift)"
    return [
        Check(
            "time",
            "no_clock",
            key,
            role_of(voyage, key),
            "not_checked",
            statistic("clock", None, ""),
            threshold(None, "", rule),
            {},
            0.0,
            f"{key}: {NO_CLOCK}; no back-step, leap-second, rollover or drift check, and no "
            "latency, cadence or availability figure",
            why_not=NO_CLOCK,
        )
        for key in sorted(voyage.clockless & present_keys(voyage))
    ]


# ---------------------------------------------------------------------- week rollover


def week_rollover_check(
    voyage: Voyage,
    win: dict[str, int],
    events: Sequence[StepEvent] = (),
    series: dict[str, OffsetSeries] | None = None,
) -> Check:
    """``week_rollover``: dates 1024 weeks early -- repaired by the ingest (its decision
    note per file: the RMC/ZDA dates of an NMEA log, before 2000 or behind their receive
    times, with a note on the first; the stamps of an MCAP log's messages behind their
    log times, naming the first message and its source), or not: a source's own times
    1024 weeks behind the logger clock (receive stamps of that day), or stepping back
    1024 weeks."""
    ev: list[dict[str, Any]] = []
    decisions = voyage.time_events.decisions
    for d in decisions:
        m = _ROLLOVER.match(d)
        if m is None:
            continue
        name = m.group("file")
        named = _ROLLOVER_SOURCE.search(d)
        senders = sorted(
            k
            for k, s in voyage.sources.items()
            if any(Path(f).name == name for f in s.files)
            and (
                any(x in s.sentences for x in ("RMC", "ZDA"))
                or (named is not None and k == named.group("key"))
            )
        )
        head = f"{name}: GPS week rollover: "  # the NMEA time base's note on the first
        first = next((x.removeprefix(head) for x in decisions if x.startswith(head)), None)
        ev.append(
            {
                "file": name,
                "records": int(m.group("n")),
                "senders": senders,
                "note": d,
                "first": first,
            }
        )
    repaired = sum(e["records"] for e in ev)
    unrepaired: list[dict[str, Any]] = []
    for key, s in sorted((series or {}).items()):
        behind = np.abs((s.recv_ns - s.time_ns) - WEEK_ROLLOVER_NS) <= WEEK_ROLLOVER_TOL_NS
        if behind.any():
            i = np.flatnonzero(behind)
            unrepaired.append(
                {
                    "source": key,
                    "records": int(len(i)),
                    "first_line": int(s.line[i[0]]),
                    "start": iso_utc(unit="ms", time_ns=s.time_ns[i[0]]),
                    "end": iso_utc(unit="ms", time_ns=s.time_ns[i[-1]]),
                    "behind_logger_clock": "1024 weeks",
                }
            )
    seen = {u["source"] for u in unrepaired}
    for e in events:
        if e.kind == "week_rollover" and not {v.source for v in e.verdicts} <= seen:
            unrepaired.append({**e.evidence(), "records": None})
    parts = [
        f"{e['file']} ({e['records']}, sent by {', '.join(e['senders']) or 'an unknown source'})"
        for e in ev
    ]
    msg = "no date 1024 weeks early"
    if ev:
        msg = (
            f"GPS week rollover: {repaired} date(s) 1024 weeks early found and repaired (+1024 "
            f"weeks) in {'; '.join(parts)}: the receiver's week number has rolled over, its "
            "dates are wrong until it is updated"
        )
    if unrepaired:
        u = unrepaired[0]
        who = u.get("source") or ", ".join(u.get("sources", []))
        msg = (msg + "; " if ev else "GPS week rollover: ") + (
            f"{who}'s own times are 1024 weeks early (first at line "
            f"{u.get('first_line', u.get('line'))}, {u.get('start', u.get('to'))}), not "
            "repaired: its records stand 19.6 years early"
        )
    return Check(
        "time",
        "week_rollover",
        None,
        None,
        "fail" if ev or unrepaired else "pass",
        statistic(
            "rollover_dates",
            float(repaired + sum(u["records"] or 0 for u in unrepaired)),
            "records",
        ),
        threshold(0.0, "records", "dates 1024 GPS weeks (19.6 years) early"),
        dict(win),
        0.0,
        msg,
        tuple([*ev, *unrepaired][:MAX_EVIDENCE]),
        detail={"repaired": repaired, "unrepaired_sources": len(unrepaired)},
    )


# ------------------------------------------------------------ the receivers' clocks


@dataclass(frozen=True)
class OffsetSeries:
    """One source's times of fix beside their receive times, in time order."""

    source: str
    time_ns: np.ndarray
    recv_ns: np.ndarray
    line: np.ndarray

    @property
    def ahead_s(self) -> np.ndarray:
        """time of fix - receive time (s): the time of fix ahead of the logger clock."""
        out: np.ndarray = (self.time_ns - self.recv_ns) / NS_PER_S
        return out

    @property
    def stamp_s(self) -> float:
        """The resolution of the logger's stamps: the coarsest of 1 s .. 1 ms every one is
        a multiple of (0 where finer)."""
        for q in _STAMP_QUANTA_NS:
            if not np.any(self.recv_ns % q):
                return q / NS_PER_S
        return 0.0


def offset_series(voyage: Voyage) -> dict[str, OffsetSeries]:
    """Per source with a clock: its records with their own time of fix and a receive time,
    from its positions where it has them (a fix's own time; the other kinds repeat it),
    else from the first kind that has them."""
    out: dict[str, OffsetSeries] = {}
    for kind in ("position", *(k for k in voyage.frames if k != "position")):
        df = voyage.frames.get(kind)
        if df is None or len(df) == 0 or "recv_ns" not in df:
            continue
        has = df["recv_ns"].to_numpy(np.int64) != MISSING_NS
        if not has.any():
            continue
        for key, g in by_source(df[has]):
            if key in voyage.clockless or key in out:
                continue
            t = g["time_ns"].to_numpy(np.int64)
            r = g["recv_ns"].to_numpy(np.int64)
            o = np.argsort(t, kind="stable")
            out[key] = OffsetSeries(key, t[o], r[o], g["line"].to_numpy(np.int64)[o])
    return out


def _smoothed(x: np.ndarray) -> np.ndarray:
    if len(x) < SMOOTH:
        return x
    out: np.ndarray = (
        pd.Series(x).rolling(SMOOTH, center=True, min_periods=1).median().to_numpy(float)
    )
    return out


def _explained(t0_ns: int, ahead_s: float, events: list[StepEvent]) -> StepEvent | None:
    """The back-step event a spell of the time of fix ahead of the logger clock starts
    at (the logger clock set back: its stamps behind the receivers' times of fix)."""
    for e in events:
        if (
            e.kind == "backstep"
            and abs(t0_ns - e.from_ns) <= GROUP_NS
            and abs(ahead_s - e.back_s) <= max(10.0, 0.1 * e.back_s)
        ):
            return e
    return None


def whole_seconds(ahead_s: float) -> int:
    """The whole seconds a time of fix ``ahead_s`` ahead of the logger clock is off by: a
    receiver k s ahead is seen k s less its latency (0 to :data:`LATENCY_ALLOWANCE_S`, never
    negative) ahead, so the lead is rounded up from there: k = floor(ahead + allowance)."""
    return int(math.floor(ahead_s + LATENCY_ALLOWANCE_S))


def _whole_words(k: int) -> str:
    if k == GPS_UTC_S:
        return f"GPS time written without the {GPS_UTC_S} s UTC offset"
    if 0 < k < GPS_UTC_S:
        return "a stale or wrong leap-second count (or the logger clock that far behind)"
    return "a clock offset between the receiver and the logger"


def leap_second_checks(
    voyage: Voyage,
    cfg: IntegrityConfig,
    series: dict[str, OffsetSeries],
    events: list[StepEvent],
    drifting: set[str] | frozenset[str] = frozenset(),
    ends: list[tuple[str, int, float]] | None = None,
) -> list[Check]:
    """``leap_second``: per source, spells of its time of fix ahead of the logger clock
    (those at a back-step of the logger's clock, or of a source whose clock drifts, are
    that finding's); then the sources' times of fix against each other at the same
    receive times.  ``ends`` gets (source, end, lead in s) of each spell found."""
    spell_ns = int(cfg.spell_min_s * NS_PER_S)
    checks: dict[str, Check] = {}
    for key, s in sorted(series.items()):
        gate = max(cfg.clock_ahead_min_s, s.stamp_s)
        a = _smoothed(s.ahead_s)
        rule = (
            f"time of fix ahead of the logger clock by {gate:g} s or more (running median of "
            f"{SMOOTH}; at least the stamps' resolution) for {cfg.spell_min_s:g} s or more"
        )
        spells, explained = [], []
        for i, j in runs(a >= gate):
            if s.time_ns[j - 1] - s.time_ns[i] < spell_ns:
                continue
            ahead = float(np.median(s.ahead_s[i:j]))
            item = {
                "start": iso_utc(unit="ms", time_ns=s.time_ns[i]),
                "end": iso_utc(unit="ms", time_ns=s.time_ns[j - 1]),
                "duration_s": float((s.time_ns[j - 1] - s.time_ns[i]) / NS_PER_S),
                "records": int(j - i),
                "first_line": int(s.line[i]),
                "ahead_s": round(ahead, 3),
                "whole_s": whole_seconds(ahead),
            }
            e = _explained(int(s.time_ns[i]), ahead, events)
            if e is not None:
                explained.append({**item, "explained_by": f"time/{e.kind}"})
            elif key in drifting:
                explained.append({**item, "explained_by": "time/clock_drift"})
            else:
                spells.append(item)
                if ends is not None:
                    ends.append((key, int(s.time_ns[j - 1]), ahead))
        worst = max(spells, key=lambda x: x["ahead_s"], default=None)
        p50 = float(np.median(s.ahead_s))
        if worst is not None:
            k = worst["whole_s"]
            msg = (
                f"{key}: the time of fix is {worst['ahead_s']:.2f} s ahead of the logger clock "
                f"for {worst['duration_s']:.0f} s from {worst['start']} (line "
                f"{worst['first_line']}): {k} whole second(s) -- {_whole_words(k)}; no "
                "delay makes data arrive before its time of fix"
            )
        else:
            rel = "ahead of" if p50 > 0 else "behind"
            msg = (
                f"{key}: the time of fix is never {gate:g} s or more ahead of the logger clock "
                f"for {cfg.spell_min_s:g} s (median {abs(p50):.2f} s {rel} it)"
            )
            if explained:
                msg += (
                    f"; {len(explained)} spell(s) ahead, the finding of "
                    f"{explained[0]['explained_by']}"
                )
        checks[key] = Check(
            "time",
            "leap_second",
            key,
            role_of(voyage, key),
            "fail" if spells else "pass",
            statistic("clock_ahead_s", float(worst["ahead_s"] if worst else np.max(a)), "s"),
            threshold(gate, "s", rule),
            {"start_ns": int(s.time_ns[0]), "end_ns": int(s.time_ns[-1])},
            0.0,
            msg,
            tuple([*spells, *explained][:MAX_EVIDENCE]),
            detail={
                "ahead_p50_s": p50,
                "stamp_s": s.stamp_s,
                "spells": len(spells),
                "explained_spells": len(explained),
            },
        )
    for (a_key, b_key), item in _cross_offsets(series, cfg).items():
        c = checks[a_key]
        if c.status == "fail" or checks[b_key].status == "fail":
            continue
        k = item["whole_s"]
        checks[a_key] = replace(
            c,
            status="fail",
            message=(
                f"{a_key}: its time of fix is {item['ahead_s']:.2f} s ahead of {b_key}'s at the "
                f"same receive times ({item['pairs']} records over {item['duration_s']:.0f} s, "
                f"steady): {k} whole seconds -- {_whole_words(k)}; which of the two is right "
                "the logger clock cannot tell"
                + (
                    f" (it keeps {a_key}'s time: {b_key} is {item['against_latency_s']:.2f} s "
                    "behind it, which latency reports)"
                    if item["against_latency_s"] > cfg.latency_max_s
                    else ""
                )
            ),
            evidence=(item,),
            statistic=statistic("clock_ahead_s", item["ahead_s"], "s"),
        )
    return [checks[k] for k in sorted(checks)]


def _cross_offsets(
    series: dict[str, OffsetSeries], cfg: IntegrityConfig
) -> dict[tuple[str, str], dict[str, Any]]:
    """(source ahead, source behind) -> the evidence, for pairs whose times of fix at the
    same receive times differ by a steady whole number of seconds of CROSS_MIN_S or more."""
    out: dict[tuple[str, str], dict[str, Any]] = {}
    keys = sorted(series)
    for i, ka in enumerate(keys):
        for kb in keys[i + 1 :]:
            a, b = series[ka], series[kb]
            ob = np.argsort(b.recv_ns, kind="stable")
            rb = b.recv_ns[ob]
            at = np.searchsorted(rb, a.recv_ns)
            lo = np.clip(at - 1, 0, len(rb) - 1)
            hi = np.clip(at, 0, len(rb) - 1)
            j = np.where(np.abs(rb[lo] - a.recv_ns) <= np.abs(rb[hi] - a.recv_ns), lo, hi)
            ok = np.abs(rb[j] - a.recv_ns) <= CROSS_MATCH_NS
            if ok.sum() < 2:
                continue
            # a's time of fix minus b's, each against its own receive time
            diff = (a.ahead_s[ok] - b.ahead_s[ob][j[ok]]).astype(float)
            med = float(np.median(diff))
            k = int(math.floor(abs(med) + 0.5))
            span = float((a.time_ns[ok][-1] - a.time_ns[ok][0]) / NS_PER_S)
            steady = float(np.mean(np.abs(diff - med) <= CROSS_WHOLE_S))
            if (
                abs(med) < CROSS_MIN_S
                or abs(abs(med) - k) > CROSS_WHOLE_S
                or steady < CROSS_STEADY
                or span < cfg.spell_min_s
            ):
                continue
            ahead, behind = (ka, kb) if med > 0 else (kb, ka)
            out[(ahead, behind)] = {
                "against": behind,
                "against_latency_s": round(-float(np.median(series[behind].ahead_s)), 3),
                "ahead_s": round(abs(med), 3),
                "whole_s": k,
                "pairs": int(ok.sum()),
                "steady_share": round(steady, 3),
                "duration_s": span,
                "start": iso_utc(unit="ms", time_ns=a.time_ns[ok][0]),
                "first_line": int(a.line[ok][0]),
            }
    return out


# ------------------------------------------------------------------------ clock drift


def drift_fit(
    t_ns: np.ndarray, d_s: np.ndarray, stamp_s: float = 0.0
) -> tuple[float, float, int] | None:
    """(slope s/s, its sigma, stretches) of ``d_s`` against time: Theil-Sen over the
    medians of up to DRIFT_BINS equal stretches of time; None with fewer than
    DRIFT_MIN_BINS stretches holding records.  The residuals' sigma is never taken below
    the stamps' quantisation (``stamp_s``, 1 ms at the least) over root-12."""
    if len(t_ns) < 2 * DRIFT_MIN_BINS:
        return None
    t_s = (t_ns - t_ns[0]) / NS_PER_S
    span = float(t_s[-1])
    if span <= 0:
        return None
    nb = min(DRIFT_BINS, len(t_s) // 3)
    b = np.minimum((t_s / span * nb).astype(np.int64), nb - 1)
    counts = np.bincount(b, minlength=nb)
    used = np.flatnonzero(counts > 0)
    if len(used) < DRIFT_MIN_BINS:
        return None
    df = pd.DataFrame({"b": b, "t": t_s, "d": d_s}).groupby("b").median()
    x, y = df["t"].to_numpy(float), df["d"].to_numpy(float)
    # a step of the offset (a clock set back, a spell of another leap count) is no drift:
    # only pairs of stretches between two such steps are compared
    dy = np.abs(np.diff(y))
    jump = dy > max(JUMP_MIN_S, 10.0 * robust_sigma(np.diff(y)))
    seg = np.concatenate(([0], np.cumsum(jump)))
    i, j = np.triu_indices(len(x), 1)
    good = (x[j] > x[i]) & (seg[i] == seg[j])
    if not good.any():
        return None
    slope = float(np.median((y[j] - y[i])[good] / (x[j] - x[i])[good]))
    # the residuals about the line, each stretch of time about its own level
    lev = pd.Series(y - slope * x).groupby(seg).transform("median").to_numpy(float)
    resid = y - slope * x - lev
    s = max(robust_sigma(resid), max(stamp_s, 1e-3) / math.sqrt(12.0))
    r0 = float(np.sum(resid * resid))
    rho = float(np.clip(np.sum(resid[1:] * resid[:-1]) / r0, 0.0, 0.95)) if r0 > 0 else 0.0
    xm = pd.Series(x).groupby(seg).transform("mean").to_numpy(float)
    sxx = float(np.sum((x - xm) ** 2))
    sigma = s / math.sqrt(sxx) * math.sqrt((1 + rho) / (1 - rho)) if sxx > 0 else math.inf
    return slope, sigma, len(x)


def clock_drift_check(voyage: Voyage, cfg: IntegrityConfig, s: OffsetSeries) -> Check:
    """``clock_drift``: the source's time of fix against the logger clock over the night."""
    key = s.source
    z = float(dist.norm_ppf(1.0 - cfg.false_alarm / 2.0))
    rule = (
        f"the offset (receive time - time of fix) drifting by more than "
        f"{cfg.clock_drift_max_s:g} s over the source's span, the slope significant at "
        f"z = {z:.2f} (two-sided, false alarm {cfg.false_alarm:g})"
    )
    win = {"start_ns": int(s.time_ns[0]), "end_ns": int(s.time_ns[-1])}
    span_s = (s.time_ns[-1] - s.time_ns[0]) / NS_PER_S
    fit = drift_fit(s.time_ns, -s.ahead_s, s.stamp_s)
    if fit is None:
        return Check(
            "time",
            "clock_drift",
            key,
            role_of(voyage, key),
            "not_checked",
            statistic("offset_change_s", None, "s"),
            threshold(cfg.clock_drift_max_s, "s", rule),
            win,
            0.0,
            f"{key}: clock drift not checked: {len(s.time_ns)} records over {span_s:.0f} s",
            why_not=f"too few times of fix beside receive times ({len(s.time_ns)} records, "
            f"{DRIFT_MIN_BINS} stretches of time needed)",
        )
    slope, sigma, bins = fit
    change = abs(slope) * span_s
    zval = abs(slope) / sigma if sigma > 0 else math.inf
    failed = bool(zval > z and change > cfg.clock_drift_max_s)
    ppm, sppm = slope * 1e6, sigma * 1e6
    who = "the logger clock gains on" if slope > 0 else "the logger clock loses on"
    msg = (
        f"{key}: {who} the receiver's time of fix by {abs(ppm):.0f} ± {sppm:.1f} ppm: the "
        f"offset changed {change:.2f} s over {span_s / 3600:.2f} h (z = {zval:.1f})"
    )
    if not failed:
        why = "not significant" if zval <= z else f"within {cfg.clock_drift_max_s:g} s"
        msg = f"{key}: drift {ppm:+.1f} ± {sppm:.1f} ppm, {change:.2f} s over the span ({why})"
    return Check(
        "time",
        "clock_drift",
        key,
        role_of(voyage, key),
        "fail" if failed else "pass",
        statistic("offset_change_s", change, "s"),
        threshold(cfg.clock_drift_max_s, "s", rule),
        win,
        cfg.false_alarm,
        msg,
        (
            {
                "start": iso_utc(unit="ms", time_ns=s.time_ns[0]),
                "end": iso_utc(unit="ms", time_ns=s.time_ns[-1]),
                "first_line": int(s.line[0]),
                "records": int(len(s.time_ns)),
                "drift_ppm": round(ppm, 2),
                "sigma_ppm": round(sppm, 2),
                "z": round(zval, 2),
            },
        )
        if failed
        else (),
        detail={"drift_ppm": ppm, "sigma_ppm": sppm, "z": zval, "stretches": bins},
    )
