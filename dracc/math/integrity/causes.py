"""One cause, one finding: which failed check is a consequence of another.

A GNSS position held 670 m off for ten minutes fails its ``jump`` check, and with it the
``contradiction`` check (the receiver flagged those fixes valid) and ``dr_2m`` (the fixes
fell outside the DR's 2M); the DR's circles, scored against the displaced fixes, are
called too small.  These are one cause and its consequences.  :func:`cause_of` says,
for each failed check, which other failed check caused it, from the checks' own
evidence -- their source and the times their evidence names -- never their messages.

A cause is a plausibility fault of one source (``jump``, ``frozen``, ``stuck``,
``out_of_range``).  A consequence is attached to the first cause of the *same source*
(the DR: of its reference) that explains *every* event of its evidence:

- validity / ``contradiction``: each event names the fault (``what``: jump, frozen) and
  its time, inside that fault's span;
- plausibility / ``dr_2m`` (fixes outside the DR and its 2M): each run of such fixes
  (successive ones less than :data:`RUN_GAP_S` apart: the filter settling after one
  disturbance) starts inside a span of the source's jump or frozen run;
- consistency (``velocity``, ``heading``, ``speed``, the witnesses) and ``latency``:
  each failing run overlaps a span of a jump, frozen, stuck or out-of-range run of the
  source, within the data the run's statistic reads (``velocity``: two Schuler periods
  back, :data:`~dracc.math.integrity.consistency.SCHULER_PERIOD_S`);
- consistency / ``dr_inconsistent`` (the DR's circles too small; an audit finding): the
  legs a jump of its reference touched overlap the jump's span, and the DR passes its
  test without those legs (``verdict_without_them``: consistent or conservative).

A fault's span is what its evidence says: a frozen or stuck run from start to end; a
jump is a displaced fix, and two consecutive jumps whose innovations cancel (out by
``d``, back by ``-d``) bracket the time the source was displaced.  Spans are widened by
:data:`TOLERANCE_S` either side.  A consequence is never a cause, so no chain forms;
a check that fits no cause stands alone as its own cause.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from itertools import pairwise
from typing import Any, TypeVar

from dracc.core.timefmt import parse_utc
from dracc.math.integrity.consistency import SCHULER_PERIOD_S
from dracc.math.integrity.results import Check, IntegrityResult

__all__ = [
    "CAUSES",
    "RUN_GAP_S",
    "TOLERANCE_S",
    "Trace",
    "cause_of",
    "check_trace",
    "event_span",
    "failed_with_consequences",
    "group",
    "jump_spans",
    "overlaps",
    "trace",
]

#: the plausibility faults that are causes
CAUSES = ("jump", "frozen", "stuck", "out_of_range")
#: (check, name) of a consequence -> the faults of the same source that can cause it
_CAUSED_BY: dict[tuple[str, str], tuple[str, ...]] = {
    ("validity", "contradiction"): ("jump", "frozen"),
    ("plausibility", "dr_2m"): ("jump", "frozen"),
    ("consistency", "velocity"): CAUSES,
    ("consistency", "heading"): CAUSES,
    ("consistency", "speed"): CAUSES,
    ("consistency", "compass_witness"): CAUSES,
    ("consistency", "log_witness"): CAUSES,
    ("latency", "latency"): ("frozen",),
    ("consistency", "dr_inconsistent"): ("jump",),
}
#: s either side of a span: the records about a fault's first and last evidence (a
#: minute of a 1 Hz source, one DR epoch)
TOLERANCE_S = 60.0
#: s between two fixes outside the DR's 2M that belong to one run: the estimated
#: position's filter settling after one disturbance (its fix epochs are 12-36 s apart)
RUN_GAP_S = 120.0
#: how far back of its failing run a statistic reads data (s)
_REACH_S = {("consistency", "velocity"): 2.0 * SCHULER_PERIOD_S}
#: two jumps are out and back when their innovations' sum is within this of the larger
_CANCEL_FRACTION = 0.25

Span = tuple[float, float]


@dataclass(frozen=True)
class Trace:
    """What a failed check's evidence says about where and when: its events' spans in
    Unix seconds (a fault: the spans it covers; a consequence: one span per event) and,
    per event, the fault it names (``contradiction`` only, else None)."""

    check: str
    name: str
    source: str | None
    spans_s: tuple[Span, ...]
    names: tuple[str | None, ...] = ()
    explained: bool = True  #: dr_inconsistent: the DR passes without the touched legs
    anchored: bool = False  #: each span needs only its start inside the cause (a run)


def _unix_s(text: object) -> float | None:
    if not isinstance(text, str) or not text:
        return None
    try:
        return parse_utc(text).timestamp()
    except ValueError:
        return None


def event_span(e: Mapping[str, Any]) -> Span | None:
    """(start, end) in Unix s of one evidence event: start/end, from/to, or one time;
    None without a time."""
    a = _unix_s(e.get("start", e.get("from")))
    b = _unix_s(e.get("end", e.get("to")))
    if a is not None and b is not None:
        return (a, b)
    t = _unix_s(e.get("time"))
    return None if t is None else (t, t)


def _cancel(a: Mapping[str, Any], b: Mapping[str, Any]) -> bool:
    """Two jumps out and back: their innovation vectors (north, east) cancel."""
    try:
        an, ae = float(a["innovation_north_m"]), float(a["innovation_east_m"])
        bn, be = float(b["innovation_north_m"]), float(b["innovation_east_m"])
    except (KeyError, TypeError, ValueError):
        return False
    big = max(math.hypot(an, ae), math.hypot(bn, be))
    return big > 0 and math.hypot(an + bn, ae + be) <= _CANCEL_FRACTION * big


def _jump_spans(evidence: Sequence[Mapping[str, Any]]) -> list[Span]:
    """Each jump's time, and from a jump to the jump back where the two cancel."""
    events = [(e, s) for e in evidence if (s := event_span(e)) is not None]
    spans = [s for _, s in events]
    for (e0, s0), (e1, s1) in pairwise(events):
        if _cancel(e0, e1):
            spans.append((s0[0], s1[1]))
    return spans


def _runs(evidence: Sequence[Mapping[str, Any]]) -> tuple[Span, ...]:
    """The events' times as runs: successive times less than RUN_GAP_S apart."""
    times = sorted(s[0] for e in evidence if (s := event_span(e)) is not None)
    runs: list[Span] = []
    for t in times:
        if runs and t - runs[-1][1] <= RUN_GAP_S:
            runs[-1] = (runs[-1][0], t)
        else:
            runs.append((t, t))
    return tuple(runs)


def trace(check: str, name: str, source: str | None, evidence: Sequence[Any] = ()) -> Trace:
    """The :class:`Trace` of a failed check (or an audit finding) from its evidence."""
    ev = [e for e in evidence if isinstance(e, Mapping)]
    if name == "dr_inconsistent":
        # the DR finding's evidence: its reference, the legs a jump of it touched, and
        # the test's verdict without them
        d = ev[0] if ev else {}
        legs = [s for leg in d.get("reference_jump_legs") or () if (s := event_span(leg))]
        return Trace(
            check,
            name,
            d.get("reference_source"),
            tuple(legs),
            explained=d.get("verdict_without_them") in ("consistent", "conservative"),
        )
    if check == "plausibility" and name == "jump":
        return Trace(check, name, source, tuple(_jump_spans(ev)))
    if check == "plausibility" and name == "dr_2m":
        return Trace(check, name, source, _runs(ev), anchored=True)
    spans, names = [], []
    for e in ev:
        s = event_span(e)
        if s is not None:
            spans.append(s)
            names.append(e.get("what") if isinstance(e.get("what"), str) else None)
    return Trace(check, name, source, tuple(spans), tuple(names))


def check_trace(c: Check) -> Trace:
    """The :class:`Trace` of an integrity check."""
    return trace(c.check, c.name, c.source, c.evidence)


def overlaps(event: Span, spans: Sequence[Span], reach_s: float = 0.0) -> bool:
    """Does ``event`` (Unix s), reaching ``reach_s`` back, meet one of ``spans``, within
    :data:`TOLERANCE_S`?"""
    a, b = event[0] - reach_s - TOLERANCE_S, event[1] + TOLERANCE_S
    return any(s0 <= b and s1 >= a for s0, s1 in spans)


def _explains(cause: Trace, c: Trace) -> bool:
    """Does the fault ``cause`` explain every event of the consequence ``c``?"""
    if cause.check != "plausibility" or cause.name not in _CAUSED_BY.get((c.check, c.name), ()):
        return False
    if not c.source or cause.source != c.source or not c.spans_s or not c.explained:
        return False
    reach = _REACH_S.get((c.check, c.name), 0.0)
    names = c.names or (None,) * len(c.spans_s)
    return all(
        (named is None or named == cause.name)
        and overlaps((s[0], s[0]) if c.anchored else s, cause.spans_s, reach)
        for s, named in zip(c.spans_s, names, strict=True)
    )


def cause_of(traces: Sequence[Trace]) -> tuple[int | None, ...]:
    """For each trace, the index of the trace that caused it, or None (a cause itself)."""
    causes = [i for i, t in enumerate(traces) if t.check == "plausibility" and t.name in CAUSES]
    out: list[int | None] = []
    for i, t in enumerate(traces):
        out.append(
            None if i in causes else next((k for k in causes if _explains(traces[k], t)), None)
        )
    return tuple(out)


T = TypeVar("T")


def group(
    items: Sequence[T], trace_of: Callable[[T], Trace]
) -> tuple[tuple[T, tuple[T, ...]], ...]:
    """The causes among ``items`` in their order, each with its consequences (in order)."""
    parent = cause_of([trace_of(x) for x in items])
    return tuple(
        (x, tuple(items[j] for j, p in enumerate(parent) if p == i))
        for i, x in enumerate(items)
        if parent[i] is None
    )


def failed_with_consequences(r: IntegrityResult) -> tuple[tuple[Check, tuple[Check, ...]], ...]:
    """The night's failed checks as causes, each with the failed checks it caused."""
    return group(r.failed, check_trace)


def jump_spans(r: IntegrityResult | None) -> dict[str, tuple[Span, ...]]:
    """Per source, the spans (Unix s) of its failed ``jump`` check: where the DR's legs
    were scored against a displaced reference (:mod:`dracc.pipeline.dr_stage`)."""
    if r is None:
        return {}
    return {
        c.source: check_trace(c).spans_s
        for c in r.failed
        if c.check == "plausibility" and c.name == "jump" and c.source
    }
