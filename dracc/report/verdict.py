"""The verdict of one voyage's analysis: what a navigator reads first, as plain texts.

:func:`verdict` reads an :class:`~dracc.pipeline.results.Analysis` and says, each with
a level and the reasons behind it:

- whether the dead reckoning is honest: the reference inside the 2M circle as often as
  the model states (B31; issue 31), the summed NEES inside its chi-square bounds, the RMS
  of error/M (B30) near 1;
- which INS unit and channel stands out, by one rule said with it (:attr:`WorstUnit.label`):
  with an a priori RMS configured, the unit furthest over its own a priori RMS (or, every
  unit within it, the one closest to it); with limits given instead, the same against the
  limits; with neither, the unit with the largest m_y against the median of the units in
  its channel; and whether any is out of its limits;
- which integrity checks failed;
- sensor faults: found, "none found" (the checks ran and found nothing) or "not
  checked" (and why not), kept apart;
- what could not be computed.

Levels are :data:`OK`, :data:`ATTENTION`, :data:`FAIL` and :data:`NOT_CHECKED`, each
with a text label (:data:`LABELS`) so that no renderer has to rely on colour.  The
function is pure and renderer-free: texts are plain (not escaped, no markup); the
terminal and the HTML report only style them.  A statistical artefact (a negative
three-cornered-hat variance) is named as such in the reasons and never makes a failure.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from dracc.core.numbers import counted
from dracc.core.vocabulary import CHANNEL_KEYS, CHANNEL_UNITS, CHANNELS, as_heading, dr_name
from dracc.math.deviation import DeviationResult
from dracc.math.integrity import IntegrityResult
from dracc.math.integrity.causes import failed_with_consequences
from dracc.math.integrity.results import Check
from dracc.pipeline.results import Analysis, DRHonesty, DRSection
from dracc.report import fmt, fmt_pct
from dracc.report.rows import channel_digits

__all__ = [
    "ATTENTION",
    "FAIL",
    "FAULTS_FOUND",
    "FAULTS_NONE_FOUND",
    "FAULTS_NOT_CHECKED",
    "LABELS",
    "NOT_CHECKED",
    "OK",
    "Finding",
    "Verdict",
    "WorstUnit",
    "integrity_count",
    "verdict",
    "worst_unit",
]

OK, ATTENTION, FAIL, NOT_CHECKED = "ok", "attention", "fail", "not-checked"
#: the text label of each level (shown beside any colour)
LABELS = {OK: "OK", ATTENTION: "ATTENTION", FAIL: "FAIL", NOT_CHECKED: "NOT CHECKED"}
#: how serious a level is, for the overall verdict (not checked is not a pass)
_RANK = {OK: 0, NOT_CHECKED: 1, ATTENTION: 2, FAIL: 3}

#: the three states of the sensor-fault search
FAULTS_FOUND, FAULTS_NONE_FOUND, FAULTS_NOT_CHECKED = "found", "none found", "not checked"

#: roles whose sources carry a heading (checked for a stuck heading)
_HEADING_ROLES = ("compass", "ins1", "ins2", "ins3")


@dataclass(frozen=True)
class Finding:
    """One part of the verdict: its level, one headline sentence and the reasons."""

    topic: str  #: 'dead reckoning', 'INS accuracy', 'integrity', 'sensor faults', 'missing'
    level: str  #: OK, ATTENTION, FAIL or NOT_CHECKED
    headline: str
    reasons: tuple[str, ...] = ()

    @property
    def label(self) -> str:
        return LABELS[self.level]


@dataclass(frozen=True)
class WorstUnit:
    """The worst INS unit and channel and the yardstick it was judged against."""

    unit: str
    channel: str  #: 'lat', 'lon' or 'course'
    channel_unit: str  #: 'm' or 'deg'
    m_y: float  #: its estimated RMS error (K5b)
    #: 'a priori' (m_y / a priori RMS), 'limit' (K8 limiting error / the limit given),
    #: 'other units' (m_y / the median m_y of the units in the channel) or 'only unit'
    basis: str
    yardstick: float  #: the a priori RMS, the limit, or the units' median m_y (NaN: none)
    ratio: float  #: m_y (or the limiting error) over the yardstick
    out_of_limits: bool  #: ratio > 1 against an a priori RMS or a limit

    @property
    def detail(self) -> str:
        """e.g. 'm_y 1122.0 m, 1.81 x the median of the units (620.1 m)'."""
        d = channel_digits(self.channel)
        u = self.channel_unit
        head = f"m_y {fmt(self.m_y, d)} {u}"
        if self.basis == "a priori":
            return f"{head}, {fmt(self.ratio, 2)} x its a priori RMS {fmt(self.yardstick, d)} {u}"
        if self.basis == "limit":
            return (
                f"{head}, limiting error {fmt(self.ratio * self.yardstick, d)} {u} = "
                f"{fmt(self.ratio, 2)} x its limit {fmt(self.yardstick, d)} {u}"
            )
        if self.basis == "other units":
            return (
                f"{head}, {fmt(self.ratio, 2)} x the median of the units "
                f"({fmt(self.yardstick, d)} {u})"
            )
        return f"{head} (the only unit: nothing to compare it with)"

    @property
    def text(self) -> str:
        """e.g. 'ins2 lon: m_y 1122.0 m, 1.81 x the median of the units (620.1 m)'."""
        return f"{self.unit} {self.channel}: {self.detail}"

    @property
    def label(self) -> str:
        """The rule that chose it, as every report names it: 'INS unit furthest over its a
        priori RMS', '... closest to its a priori RMS' (every unit within its own, so no bad
        unit is implied), the same of a limit, 'INS unit with the largest m_y against the
        others' (nothing configured), 'the only INS unit'."""
        if self.basis in ("a priori", "limit"):
            what = "a priori RMS" if self.basis == "a priori" else "limit"
            where = "furthest over" if self.out_of_limits else "closest to"
            return f"INS unit {where} its {what}"
        if self.basis == "other units":
            return "INS unit with the largest m_y against the others"
        return "the only INS unit"

    def to_dict(self) -> dict[str, object]:
        """The JSON form (``worst_ins_unit`` of the analysis document)."""
        return {
            "ins_unit": self.unit,
            "channel": self.channel,
            "measure_unit": self.channel_unit,
            "rule": self.label,
            "basis": self.basis,
            "m_y": self.m_y if math.isfinite(self.m_y) else None,
            "yardstick": self.yardstick if math.isfinite(self.yardstick) else None,
            "ratio": self.ratio if math.isfinite(self.ratio) else None,
            "out_of_limits": self.out_of_limits,
        }


@dataclass(frozen=True)
class Verdict:
    """The whole verdict: the overall level and headline, and one finding per part."""

    level: str
    headline: str
    dead_reckoning: Finding
    ins: Finding
    worst: WorstUnit | None
    integrity: Finding
    faults: Finding
    faults_state: str  #: FAULTS_FOUND, FAULTS_NONE_FOUND or FAULTS_NOT_CHECKED
    missing: Finding

    @property
    def label(self) -> str:
        return LABELS[self.level]

    @property
    def findings(self) -> tuple[Finding, ...]:
        """The parts in reading order."""
        return (self.dead_reckoning, self.ins, self.integrity, self.faults, self.missing)


# ------------------------------------------------------------------ dead reckoning


def _missing_about(a: Analysis, *words: str) -> str | None:
    """The first 'missing' sentence naming one of ``words`` (case-insensitive)."""
    for m in a.missing:
        low = m.lower()
        if any(w in low for w in words):
            return m
    return None


def _nees_reason(dr: DRSection) -> tuple[str, bool | None]:
    """('NEES ... within/above/below the chi^2 bounds', above the upper bound?)."""
    s, lo, hi = dr.nees_statistic, dr.nees_lower, dr.nees_upper
    if not all(math.isfinite(v) for v in (s, lo, hi)):
        return "NEES not computed (no leg scored against the reference)", None
    where = "above" if s > hi else ("below" if s < lo else "within")
    return (
        f"NEES {fmt(s, 1)} over {counted(len(dr.leg_checks), 'scored leg')}: {where} the χ² bounds "
        f"{fmt(lo, 1)}-{fmt(hi, 1)}",
        s > hi,
    )


def _dead_reckoning(a: Analysis) -> Finding:
    topic = "dead reckoning"
    dr = a.dead_reckoning
    if dr is None:
        why = _missing_about(a, "dead reckoning", "dead-reckoning", "heading", "speed", " dr")
        return Finding(topic, NOT_CHECKED, "DR not computed", (why or "no dead-reckoning section",))
    if dr.consistent is None:
        return Finding(
            topic,
            NOT_CHECKED,
            "DR honesty not checked: nothing to compare the 2M circle with",
            (dr.verdict,),
        )
    track = as_heading(dr_name(dr.scored_out_of_sample))  # the track the 2M is drawn around
    reasons = [
        f"reference inside 2M at {containment_text(dr)}",
        _nees_reason(dr)[0],
        f"RMS error/M {fmt(dr.error_over_m_rms, 2)} (1 expected)",
    ]
    if dr.consistent is False and dr.verdict_without_jump_legs in ("consistent", "conservative"):
        # the cause is the reference's jump (an integrity finding), not the DR's model
        n = len(dr.reference_jump_legs)
        return Finding(
            topic,
            ATTENTION,
            f"scored against a reference that jumped: {dr.verdict_without_jump_legs} without "
            f"the {counted(n, 'leg')} the jump touched",
            (*reasons, f"the reference {dr.fix_source_key} jumped: see integrity"),
        )
    if dr.consistent is False:
        if dr.dominant_source:
            key = f" ([dead_reckoning] {dr.dominant_key})" if dr.dominant_key else ""
            reasons.append(f"the 2M is mostly made of {dr.dominant_source}{key}")
        return Finding(
            topic, FAIL, f"{track} not honest: its 2M is too small for its errors", tuple(reasons)
        )
    if dr.verdict.startswith("conservative"):
        return Finding(
            topic,
            ATTENTION,
            f"{track} honest but conservative: its 2M is much larger than its errors",
            tuple(reasons),
        )
    return Finding(
        topic,
        OK,
        f"{track} honest: the reference stays inside its 2M as often as it should",
        tuple(reasons),
    )


# ---------------------------------------------------------------------- INS units


def _limit_for(
    limits: Mapping[str, Mapping[str, float]] | None, unit: str, channel: str
) -> float | None:
    """The limit of ``unit``'s ``channel`` in the [audit] limits shape (unit or 'all')."""
    if not limits:
        return None
    key = CHANNEL_KEYS[channel]
    for name in (unit, "all"):
        v = limits.get(name, {}).get(key)
        if v is not None:
            return float(v)
    return None


def _candidates(
    d: DeviationResult, limits: Mapping[str, Mapping[str, float]] | None
) -> list[WorstUnit]:
    """Every unit and channel judged against the best yardstick any channel has."""
    stats = [
        (name, ch, c)
        for name, u in d.whole.units.items()
        for ch in CHANNELS
        if (c := u.channels.get(ch)) is not None and math.isfinite(c.m_y)
    ]
    out: list[WorstUnit] = []
    for name, ch, c in stats:
        if c.apriori is not None and c.apriori > 0:
            out.append(
                WorstUnit(
                    name, ch, CHANNEL_UNITS[ch], c.m_y, "a priori", c.apriori,
                    c.m_y / c.apriori, c.m_y > c.apriori,
                )
            )  # fmt: skip
    if out:
        return out
    for name, ch, c in stats:
        lim = _limit_for(limits, name, ch)
        if lim is not None and lim > 0 and math.isfinite(c.limit):
            r = c.limit / lim
            out.append(WorstUnit(name, ch, CHANNEL_UNITS[ch], c.m_y, "limit", lim, r, r > 1))
    if out:
        return out
    for name, ch, c in stats:
        peers = [s.m_y for _, ch2, s in stats if ch2 == ch]
        if len(peers) < 2:
            out.append(WorstUnit(name, ch, CHANNEL_UNITS[ch], c.m_y, "only unit", math.nan,
                                 math.nan, False))  # fmt: skip
            continue
        med = statistics.median(peers)
        r = c.m_y / med if med > 0 else math.nan
        out.append(WorstUnit(name, ch, CHANNEL_UNITS[ch], c.m_y, "other units", med, r, False))
    return out


def worst_unit(
    a: Analysis, limits: Mapping[str, Mapping[str, float]] | None = None
) -> WorstUnit | None:
    """The INS unit and channel that stands out, by the one rule every report states
    (:attr:`WorstUnit.label`; the module docstring); None without INS statistics."""
    return None if a.deviation is None else _worst(_candidates(a.deviation, limits))


def _worst(cands: list[WorstUnit]) -> WorstUnit | None:
    if not cands:
        return None
    return max(cands, key=lambda w: (w.ratio if math.isfinite(w.ratio) else -math.inf, w.m_y))


def _ins(
    a: Analysis, limits: Mapping[str, Mapping[str, float]] | None
) -> tuple[Finding, WorstUnit | None]:
    topic = "INS accuracy"
    d = a.deviation
    if d is None:
        why = _missing_about(a, "ins")
        return Finding(
            topic, NOT_CHECKED, "INS accuracy not computed", (why or "no INS statistics",)
        ), None
    cands = _candidates(d, limits)
    worst = _worst(cands)
    if worst is None:
        return Finding(
            topic, NOT_CHECKED, "INS accuracy not computed", ("no unit has an RMS error",)
        ), None
    reasons = []
    out = [w for w in cands if w.out_of_limits]
    if worst.basis in ("a priori", "limit"):
        what = "a priori RMS" if worst.basis == "a priori" else "limit"
        if out:
            level = FAIL
            headline = (
                f"{len(out)} of {len(cands)} judged unit channels above their {what}; furthest "
                f"over: {worst.unit} {worst.channel}"
            )
            reasons += [w.text for w in sorted(out, key=lambda w: -w.ratio)]
        else:
            level = OK
            headline = f"every unit within its {what}; closest to it: {worst.unit} {worst.channel}"
            reasons.append(worst.text)
    else:
        level = NOT_CHECKED
        headline = (
            f"largest m_y against the other units: {worst.unit} ({worst.channel}); limits not "
            "checked: no a priori RMS configured"
        )
        reasons.append(worst.text)
        reasons.append(
            "configure [deviation.apriori] to judge each unit against its own RMS (the "
            "deviation estimate is mandatory where none exists)"
        )
    reasons += _ins_notes(d)
    return Finding(topic, level, headline, tuple(reasons)), worst


def _ins_notes(d: DeviationResult) -> list[str]:
    """Artefacts and gaps of the statistics, plainly (never failures)."""
    notes = []
    negative = sorted(
        {name for name, u in d.whole.units.items() for h in u.hat.values() if h.negative}
    )
    if negative:
        notes.append(
            "three-cornered hat: negative variance for "
            + ", ".join(negative)
            + " (a statistical artefact of few samples, not a fault)"
        )
    no_limit = [
        (name, ch)
        for name, u in d.whole.units.items()
        for ch, c in u.channels.items()
        if not math.isfinite(c.limit)
    ]
    if no_limit:
        some = d.whole.units[no_limit[0][0]].channels[no_limit[0][1]]
        why = next((n for n in some.notes if "limiting error" in n), None)
        notes.append(
            f"limiting errors (K8) not computed for {len(no_limit)} unit channels"
            + (f": {why}" if why else "")
        )
    notes += [m.message for m in d.channels.values() if m.message]
    return notes


# ---------------------------------------------------------------- integrity, faults


def _cause(c: Check, under: Sequence[Check]) -> str:
    """A failed check that is a cause, with the checks it caused (one finding per cause)."""
    said = "; ".join(f"{k.check}/{k.name} {k.source or ''}".rstrip() for k in under)
    return f"{c.check}/{c.name}: {c.message}" + (f" (consequences: {said})" if said else "")


def _integrity(a: Analysis) -> Finding:
    topic = "integrity"
    ig = a.integrity
    if ig is None:
        return Finding(topic, NOT_CHECKED, "integrity checks not run")
    skipped = ig.not_checked
    why: dict[tuple[str, str], list[str]] = {}
    for c in skipped:
        why.setdefault((f"{c.check}/{c.name}", c.why_not or "no reason given"), []).append(
            c.source or "-"
        )
    notes = [
        f"{name} not checked for {', '.join(srcs)}: {reason}"
        for (name, reason), srcs in why.items()
    ]
    failed = ig.failed
    if failed:
        return Finding(
            topic,
            FAIL,
            integrity_count(ig),
            tuple(_cause(c, under) for c, under in failed_with_consequences(ig)) + tuple(notes),
        )
    if not ig.made:
        return Finding(topic, NOT_CHECKED, integrity_count(ig), tuple(notes))
    return Finding(topic, OK, integrity_count(ig), tuple(notes))


def integrity_count(ig: IntegrityResult) -> str:
    """The integrity checks counted, one wording for every report: 'all 42 integrity
    checks passed', 'all 38 integrity checks made passed; 4 not checked', '2 of 38
    integrity checks made failed; 4 not checked' (the not checked never among the made)."""
    made, skipped, failed = len(ig.made), len(ig.not_checked), len(ig.failed)
    if made == 0:
        return "no integrity check could be made" + (f"; {skipped} not checked" if skipped else "")
    checks = "integrity checks made" if skipped else "integrity checks"
    if failed:
        head = f"{failed} of {made} {checks} failed"
    elif made == 1:
        head = f"the one {checks.replace('checks', 'check')} passed"
    else:
        head = f"all {made} {checks} passed"
    return head + (f"; {skipped} not checked" if skipped else "")


def _fault_coverage(a: Analysis) -> tuple[list[str], list[str]]:
    """(the sources searched for position faults, for a stuck heading)."""
    ig = a.integrity
    if ig is not None:
        pos = sorted({str(c.source) for c in ig.checks if c.name in ("frozen", "jump")})
        hdg = sorted({str(c.source) for c in ig.checks if c.name == "stuck"})
        if pos or hdg:
            return pos, hdg
    pos = sorted({t.source for t in a.tracks})
    hdg = sorted(
        s.key for s in a.sources if s.records and any(r in _HEADING_ROLES for r in s.roles)
    )
    return pos, hdg


def _faults(a: Analysis) -> tuple[Finding, str]:
    topic = "sensor faults"
    pos, hdg = _fault_coverage(a)
    gaps = []
    # a repeat no other source could judge (no witness): said, never called a fault
    for c in a.integrity.checks if a.integrity is not None else ():
        if c.name in ("frozen", "stuck") and c.status == "not_checked":
            gaps.append(f"{c.name} {c.source} not judged: {c.why_not or c.message}")
    if not pos:
        gaps.append("jumps and frozen positions not checked: no position source")
    if not hdg:
        gaps.append("stuck headings not checked: no heading source")
    if a.faults:
        kinds = ", ".join(f"{f.kind} {f.source}" for f in a.faults)
        return (
            Finding(
                topic,
                FAIL,
                f"{len(a.faults)} sensor fault(s) found: {kinds}",
                tuple(f.message for f in a.faults) + tuple(gaps),
            ),
            FAULTS_FOUND,
        )
    if not pos and not hdg:
        return (
            Finding(
                topic,
                NOT_CHECKED,
                "sensor faults not checked: the logs hold no position or heading source",
                (*gaps, "only values out of range were looked for"),
            ),
            FAULTS_NOT_CHECKED,
        )
    searched = []
    if pos:
        searched.append(f"jumps and frozen positions in {', '.join(pos)}")
    if hdg:
        searched.append(f"stuck headings in {', '.join(hdg)}")
    return (
        Finding(
            topic,
            OK,
            "none found",
            ("searched for " + "; ".join(searched) + " and for values out of range",) + tuple(gaps),
        ),
        FAULTS_NONE_FOUND,
    )


def _missing(a: Analysis) -> Finding:
    if not a.missing:
        return Finding("missing", OK, "nothing missing: every section was computed")
    return Finding(
        "missing", NOT_CHECKED, f"{len(a.missing)} part(s) could not be computed", a.missing
    )


# --------------------------------------------------------------------------- verdict


def verdict(a: Analysis, limits: Mapping[str, Mapping[str, float]] | None = None) -> Verdict:
    """The verdict of ``a`` (see the module docstring).

    ``limits``: limiting errors (K8) per unit and channel in the ``[audit] limits`` shape
    (``{"all": {"lat_m": 1852.0, ...}, "ins2": {...}}``); used where no a priori RMS is
    configured.  Without either, the unit that stands out is the one furthest above the
    median of the units in its channel, and the limits are "not checked".
    """
    ins, worst = _ins(a, limits)
    faults, state = _faults(a)
    return _whole(_dead_reckoning(a), ins, worst, _integrity(a), faults, state, _missing(a))


def with_ins(v: Verdict, ins: Finding) -> Verdict:
    """``v`` with its INS accuracy part replaced by ``ins`` (the audit page's own
    judgement), the overall level and headline recomputed from the parts."""
    return _whole(v.dead_reckoning, ins, v.worst, v.integrity, v.faults, v.faults_state, v.missing)


def _whole(
    dr: Finding,
    ins: Finding,
    worst: WorstUnit | None,
    integ: Finding,
    faults: Finding,
    state: str,
    miss: Finding,
) -> Verdict:
    """The overall level (the worst part's) and headline of the parts."""
    parts = (dr, ins, integ, faults, miss)
    level = max((p.level for p in parts), key=_RANK.__getitem__)
    bad = [p.topic for p in parts if p.level == FAIL]
    notice = [p.topic for p in parts if p.level == ATTENTION]
    unchecked = [p.topic for p in parts if p.level == NOT_CHECKED]
    if bad:
        headline = "failed: " + ", ".join(bad)
    elif notice:
        headline = "needs attention: " + ", ".join(notice)
    elif unchecked:
        headline = "nothing failed, but not checked: " + ", ".join(unchecked)
    else:
        headline = "every check passed"
    if worst is not None:
        headline += f"; {worst.label}: {worst.unit} ({worst.channel})"
    return Verdict(level, headline, dr, ins, worst, integ, faults, state, miss)


def scored_legs(dr: DRSection) -> str:
    """'10 legs, 8 of them scored': the legs drawn and the legs the NEES and the verdict
    count (those with epochs scored against the reference), one wording for the two."""
    n, k = len(dr.legs), len(dr.leg_checks)
    return counted(n, "leg") + ("" if k == n else f", {k} of them scored")


def containment_text(dr: DRSection) -> str:
    """'92.5 % of 40 epochs after a fix (stated: 96.8 %)': the reference inside the drawn
    2M against the probability the model states for it (one wording for every report)."""
    return (
        f"{fmt_pct(dr.containment_2m)} of {dr.n_scored} epochs after a fix "
        f"(stated: {fmt_pct(dr.expected_inside)})"
    )


def honesty_text(h: DRHonesty) -> str:
    """The honesty figures in one sentence: the predictive, the inflation, the tail, the
    first leg."""
    infl = (
        f"covariance × {fmt(h.inflation_min, 2)}-{fmt(h.inflation_max, 2)} learned from earlier "
        f"legs, Student-t of shape ≥ {fmt(h.shape_min, 1)}"
        if h.predictive == "student-t"
        else "the configured model, Gaussian"
    )
    return (
        f"{infl}; {h.n_misleading} of {h.n_scored} epochs beyond 2M; {h.n_beyond_99} beyond "
        f"the 99 % radius ({fmt(h.expected_beyond_99, 1)} expected); first scored leg "
        f"{fmt_pct(h.first_leg_inside)} (stated {fmt_pct(h.first_leg_stated)})"
    )
