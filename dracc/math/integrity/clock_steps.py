"""time / ``backstep``, ``loop``: the logger's times going back (:mod:`.time_checks`).

Input: :attr:`dracc.frames.TimeEvents.steps`, every back-step of a source's own times in
stream order, as the ingest records it (:class:`~dracc.frames.ClockStep`: the file, the
line after the step, the source and sentence, the time before and after it).

- A step back of ``backstep_min_s`` or less (interleaved sentences, a jittering stamp) is
  no finding.
- Nor is a short run of records out of order: a clock going back covers the stretch it
  goes back over twice, about equally (the records before the step later than where it
  lands, the records after it up to where it left); a few records early or late cover it
  on one side only, by a run less than half the other side's (:func:`judge_step`,
  'displaced').
- The steps of one file within :data:`GROUP_NS` of each other and of about the same
  depth, each stream (a source's sentence type) at most once, are one event: a looped
  logger steps every source at once, one finding with the sources listed.
- An event is a ``loop`` (a replayed recording) where the records after the step repeat
  those recorded at the same times before it -- the k-th record of a time after the step
  against the k-th of that time before it, every value equal -- for at least
  :data:`LOOP_EQUAL` of those compared; a ``backstep`` (the clock set back) where fresh
  values arrive at times already recorded.  Values that never change over the stretch
  (a ship at rest, a constant reading) cannot tell a replay: a ``backstep``, said so.

Rules on recorded times: false-alarm probability 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dracc.core.config import IntegrityConfig
from dracc.core.timefmt import iso_utc
from dracc.core.units import NS_PER_S
from dracc.frames import KIND_COLUMNS, ClockStep, Voyage
from dracc.math.integrity.helpers import MAX_EVIDENCE, present_keys, statistic, threshold
from dracc.math.integrity.results import Check

__all__ = [
    "GROUP_NS",
    "WEEK_ROLLOVER_NS",
    "WEEK_ROLLOVER_TOL_NS",
    "StepEvent",
    "StepVerdict",
    "judge_step",
    "step_checks",
    "step_events",
]

#: back-steps of one file this close in time (and in depth) are one event of the logger
GROUP_NS = 60 * NS_PER_S
#: share of the repeated records with equal values that makes a replayed recording
LOOP_EQUAL = 0.9
#: records after a step compared with those before it, at most
LOOP_COMPARE = 5000
#: a GPS week-number rollover: dates (times) 1024 weeks early
WEEK_ROLLOVER_NS = 1024 * 7 * 86400 * NS_PER_S
#: a step or an offset this close to 1024 weeks is a rollover (time/week_rollover)
WEEK_ROLLOVER_TOL_NS = 86400 * NS_PER_S


@dataclass(frozen=True)
class StepVerdict:
    """One back-step judged against the frames."""

    step: ClockStep
    source: str  #: the source key in the frames (renamed where two files share a key)
    back_s: float
    repeated: int = 0  #: records after the step at a time recorded before it
    equal: int = 0  #: ... of which with the same values
    constant: bool = False  #: the values compared never change (a replay cannot be told)

    @property
    def replay(self) -> bool:
        return self.repeated >= 2 and not self.constant and self.equal >= LOOP_EQUAL * self.repeated


@dataclass(frozen=True)
class StepEvent:
    """Back-steps of one logger at once: one finding."""

    kind: str  #: 'loop', 'backstep', or the check whose finding it is ('week_rollover', 'leap_second')
    verdicts: tuple[StepVerdict, ...]

    @property
    def first(self) -> StepVerdict:
        return min(self.verdicts, key=lambda v: (v.step.line, v.step.to_ns))

    @property
    def back_s(self) -> float:
        return float(np.median([v.back_s for v in self.verdicts]))

    @property
    def from_ns(self) -> int:
        return min(v.step.from_ns for v in self.verdicts)

    def evidence(self) -> dict[str, Any]:
        f = self.first
        rep = sum(v.repeated for v in self.verdicts)
        eq = sum(v.equal for v in self.verdicts)
        return {
            "kind": self.kind,
            "file": Path(f.step.file).name,
            "line": int(f.step.line),
            "from": iso_utc(unit="ms", time_ns=f.step.from_ns),
            "to": iso_utc(unit="ms", time_ns=f.step.to_ns),
            "back_s": round(self.back_s, 3),
            "sources": sorted({v.source for v in self.verdicts}),
            "lines": {v.source: int(v.step.line) for v in self.verdicts},
            "repeated_records": int(rep),
            "equal_values": int(eq),
            **({"values_constant": True} if any(v.constant for v in self.verdicts) else {}),
        }


def _step_source(voyage: Voyage, step: ClockStep, present: set[str]) -> str | None:
    """The key of the step's source in the frames (``id:key`` where two files kept it apart)."""
    if step.source in present:
        return step.source
    name = Path(step.file).name
    for key in sorted(present):
        info = voyage.sources.get(key)
        if key.endswith(":" + step.source) and (
            info is None or any(Path(f).name == name for f in info.files)
        ):
            return key
    return None


def _stream(voyage: Voyage, source: str, sentence: str) -> tuple[str, pd.DataFrame] | None:
    """(kind, the rows of one source and sentence, in stream order) -- the stream a step
    was seen in (``sentence`` may be a kind where the reader names none)."""
    for kind, df in voyage.frames.items():
        if len(df) == 0:
            continue
        rows = df["source"] == source
        if sentence != kind:
            rows &= df["sentence"] == sentence
        if rows.any():
            return kind, df[rows.to_numpy(bool)].sort_values("line", kind="stable")
    return None


def _values(kind: str, df: pd.DataFrame) -> np.ndarray:
    """The kind's measured values as one float matrix (NaN where empty)."""
    cols = [c for c, t in KIND_COLUMNS[kind].items() if t == "float64" and c in df]
    return df[cols].to_numpy(float) if cols else np.zeros((len(df), 0))


def judge_step(
    voyage: Voyage,
    step: ClockStep,
    source: str,
    cache: dict[tuple[str, str], tuple[str, pd.DataFrame] | None] | None = None,
    tol_ns: int = NS_PER_S,
) -> StepVerdict | str:
    """The step against its stream: a :class:`StepVerdict`, or 'displaced' where a few
    records were out of order (the stretch the step goes back over is covered on one side
    of it only, by a run less than half the other side's)."""
    back_s = (step.from_ns - step.to_ns) / NS_PER_S
    cache = {} if cache is None else cache
    if (source, step.sentence) not in cache:
        cache[(source, step.sentence)] = _stream(voyage, source, step.sentence)
    found = cache[(source, step.sentence)]
    if found is None:
        return StepVerdict(step, source, back_s)
    kind, df = found
    t = df["time_ns"].to_numpy(np.int64)
    line = df["line"].to_numpy(np.int64)
    # the record after the step by its line (the clock stage may have moved the times of
    # stamped records by the source's offset since the ingest saw them: the stream's own
    # times before and after the step are used from here on)
    at = np.flatnonzero(line == step.line)
    if len(at) == 0 or at[0] == 0:
        return StepVerdict(step, source, back_s)
    j = int(at[np.argmin(np.abs(t[at] - step.to_ns))])
    to_ns, from_ns = int(t[j]), int(t[j - 1])
    # the run of records before the step later than where it lands, and the run after it
    # up to where it left: a clock going back covers that stretch twice, about equally; a
    # few records out of order (early, or late) are a short run on one side only (each
    # within the stretch of the stream between its back-steps; a run the log's start or
    # end cuts short is no evidence of that)
    lands = np.flatnonzero(np.diff(t) < -tol_ns) + 1
    lo = int(lands[lands < j][-1]) if (lands < j).any() else 0
    hi = int(lands[lands > j][0]) if (lands > j).any() else len(t)
    early = np.flatnonzero(t[lo:j] <= to_ns)
    m = j - lo - (int(early[-1]) + 1 if len(early) else 0)
    late = np.flatnonzero(t[j:hi] > from_ns)
    n = int(late[0]) if len(late) else hi - j
    cut_m = lo == 0 and len(early) == 0  # the log starts inside the stretch
    cut_n = hi == len(t) and len(late) == 0  # the log ends inside it (a live window)
    short = (m < n and not cut_m and 2 * m <= n) or (n < m and not cut_n and 2 * n <= m)
    if short or (min(m, n) < 2 and not (cut_m or cut_n)):  # two records swapped: no step
        return "displaced"
    # the stretch before the step against the one after it, record by record: the k-th
    # record at a time after the step with the k-th at that time before it
    idx = np.arange(len(t))
    before = idx[lo:j][(t[lo:j] >= to_ns) & (t[lo:j] <= from_ns)]
    after = idx[j : min(hi, j + LOOP_COMPARE)]
    after = after[t[after] <= from_ns]
    if len(before) == 0 or len(after) == 0:
        return StepVerdict(step, source, back_s)
    pb = pd.DataFrame({"t": t[before], "b": before})
    pa = pd.DataFrame({"t": t[after], "a": after})
    pb["k"] = pb.groupby("t").cumcount()
    pa["k"] = pa.groupby("t").cumcount()
    pairs = pa.merge(pb, on=["t", "k"])
    if len(pairs) == 0:
        return StepVerdict(step, source, back_s)
    vals = _values(kind, df)
    va, vb = vals[pairs["a"].to_numpy()], vals[pairs["b"].to_numpy()]
    eq = np.all((va == vb) | (np.isnan(va) & np.isnan(vb)), axis=1)
    ref = vals[before]
    constant = bool(len(ref) < 2 or np.all((ref == ref[0]) | (np.isnan(ref) & np.isnan(ref[0]))))
    return StepVerdict(step, source, back_s, len(pairs), int(eq.sum()), constant)


def step_events(voyage: Voyage, cfg: IntegrityConfig) -> tuple[list[StepEvent], int]:
    """The night's clock steps as events of the logger, and the number of out-of-order
    records passed over."""
    present = present_keys(voyage) - voyage.clockless
    verdicts: list[StepVerdict] = []
    displaced = 0
    min_ns = cfg.backstep_min_s * NS_PER_S
    cache: dict[tuple[str, str], tuple[str, pd.DataFrame] | None] = {}
    for step in voyage.time_events.steps:
        if step.from_ns - step.to_ns <= min_ns:
            continue  # not a back-step beyond the tolerance (or a forward jump)
        key = _step_source(voyage, step, present)
        if key is None:
            continue
        back_ns = step.from_ns - step.to_ns
        if abs(back_ns - WEEK_ROLLOVER_NS) <= WEEK_ROLLOVER_TOL_NS:  # a rollover's: no loop
            verdicts.append(StepVerdict(step, key, back_ns / NS_PER_S))
            continue
        v = judge_step(voyage, step, key, cache, int(min_ns))
        if isinstance(v, str):
            displaced += 1
        else:
            verdicts.append(v)
    # one event: the steps of one file close in time and depth, each stream at most once
    # (a recording replayed twice steps every stream twice, far apart in the file)
    groups: list[list[StepVerdict]] = []
    for v in sorted(verdicts, key=lambda v: (v.step.file, v.step.line)):
        g = groups[-1] if groups else None
        if (
            g is not None
            and g[0].step.file == v.step.file
            and abs(v.step.from_ns - g[0].step.from_ns) <= GROUP_NS
            and abs(v.back_s - g[0].back_s) <= max(10.0, 0.1 * g[0].back_s)
            and all((w.source, w.step.sentence) != (v.source, v.step.sentence) for w in g)
        ):
            g.append(v)
        else:
            groups.append([v])
    events = []
    for g in groups:
        rep = sum(v.repeated for v in g)
        eq = sum(v.equal for v in g)
        loop = rep >= 2 and not any(v.constant for v in g) and eq >= LOOP_EQUAL * rep
        kind = "loop" if loop else "backstep"
        if abs(g[0].back_s * NS_PER_S - WEEK_ROLLOVER_NS) <= WEEK_ROLLOVER_TOL_NS:
            kind = "week_rollover"  # the receiver's dates rolled over: not the logger's clock
        events.append(StepEvent(kind, tuple(g)))
    return events, displaced


def step_checks(
    events: list[StepEvent], displaced: int, cfg: IntegrityConfig, win: dict[str, int]
) -> list[Check]:
    """``backstep`` and ``loop``: one each for the voyage."""
    rule = (
        f"the logger's times going back by more than {cfg.backstep_min_s:g} s (a loop: the "
        f"records after the step repeat, with the same values, those recorded at those times "
        f"before it, in {100 * LOOP_EQUAL:.0f} % or more of them)"
    )
    aside = (
        f"; {displaced} out-of-order record(s) passed over (the stream continues where it "
        "was: not a clock step)"
        if displaced
        else ""
    )
    other = [e for e in events if e.kind not in ("backstep", "loop")]
    if other:  # steps another finding explains (a leap-second spell ending, a rollover)
        aside += "; " + ", ".join(
            f"{sum(e.kind == k for e in other)} step(s) back, the finding of time/{k}"
            for k in sorted({e.kind for e in other})
        )
    out = []
    for name, what, how in (
        (
            "backstep",
            "the logger's clock was set back",
            "fresh values at times already recorded",
        ),
        (
            "loop",
            "the logger replayed a recording (a loop)",
            "the records after each step repeat, values and all, those recorded at those "
            "times before",
        ),
    ):
        mine = [e for e in events if e.kind == name]
        ev = tuple(e.evidence() for e in mine[:MAX_EVIDENCE])
        biggest = max((e.back_s for e in mine), default=0.0)
        if mine:
            e0 = ev[0]
            srcs = sorted({s for e in mine for s in e.evidence()["sources"]})
            const = " (values that never change: a replay cannot be told)" * any(
                "values_constant" in e.evidence() for e in mine
            )
            msg = (
                f"{what}: its times went back {len(mine)} time(s), by up to "
                f"{_duration(biggest)}, {how}{const} (first at {e0['file']} line "
                f"{e0['line']}: {e0['from']} -> {e0['to']}, {e0['equal_values']} of "
                f"{e0['repeated_records']} records at times already recorded equal); sources "
                f"{', '.join(srcs)}"
            )
        else:
            msg = f"no {'clock set back' if name == 'backstep' else name} in the logger's times"
            msg += aside
        out.append(
            Check(
                "time",
                name,
                None,
                None,
                "fail" if mine else "pass",
                statistic("largest_step_back_s", biggest, "s"),
                threshold(cfg.backstep_min_s, "s", rule),
                dict(win),
                0.0,
                msg,
                ev,
                detail={"events": len(mine), "displaced_records": displaced},
            )
        )
    return out


def _duration(s: float) -> str:
    if s >= 120:
        return f"{s / 60:.1f} min"
    return f"{s:.1f} s"
