"""What the audit reads from one analysis: :class:`NightFacts`.

:func:`facts_from_analysis` is the one place that reads the typed
:class:`~dracc.pipeline.results.Analysis` for the audit and the fleet: the period, the
input counts, the sources by role, the INS statistics per unit and channel, the DR
verdict, the calibration and the integrity checks.  Figures that are not finite become
None, as in the analysis JSON document.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from dracc.core.errors import InsufficientDataError
from dracc.core.numbers import finite_or_none
from dracc.core.timefmt import iso_utc, parse_utc
from dracc.core.vocabulary import CHANNELS
from dracc.pipeline.audit.measures import night_measures
from dracc.pipeline.state import ChannelRow

if TYPE_CHECKING:
    from dracc.math.deviation import DeviationResult
    from dracc.math.integrity import Check
    from dracc.pipeline.results import Analysis, CalibrationSection, DRSection, Estimate


@dataclass(frozen=True)
class NightFacts:
    """What the audit reads from one analysis."""

    period_start_utc: str | None
    period_end_utc: str | None
    inputs: tuple[str, ...]
    lines: int | None
    rejected: int | None
    rejected_rate: float | None  #: fraction
    sources: dict[str, str]  #: role -> source key
    channels: tuple[ChannelRow, ...]
    dr_containment_2m: float | None
    dr_n_scored: int | None
    compass_error_deg: float | None
    compass_error_sigma_deg: float | None
    log_scale: float | None  #: fraction of speed
    log_scale_sigma: float | None
    missing: tuple[str, ...]
    #: the analysis' DR verdict word: 'consistent', 'conservative', 'inconsistent',
    #: 'undetermined', or None (no DR section, or no verdict)
    dr_verdict: str | None = None
    dr_verdict_text: str | None = None  #: the verdict sentence as the analysis wrote it
    dr_consistent: bool | None = None  #: True consistent/conservative, False inconsistent
    dr_nees: float | None = None  #: NEES statistic (chi-square over the scored legs)
    dr_nees_lower: float | None = None
    dr_nees_upper: float | None = None
    dr_dominant_source: str | None = None  #: what the 2M is mostly made of where it fails
    dr_dominant_key: str | None = None  #: the [dead_reckoning] key that sets its prior
    dr_reference_source: str | None = None  #: the source of the DR's reference fixes
    #: the scored legs ({"start", "end"} UTC) a jump of the reference touched where the DR
    #: was called inconsistent, and the verdict word of its test without them
    dr_jump_legs: tuple[dict[str, str | None], ...] = ()
    dr_verdict_without_jump_legs: str | None = None
    duration_s: float | None = None  #: the period the logs cover
    ignored: Mapping[str, int] = field(default_factory=dict)  #: valid unused input, by type
    #: the analysis' integrity checks (:class:`dracc.math.integrity.Check`)
    integrity_checks: tuple[Check, ...] = ()
    integrity_false_alarm: float | None = None  #: per-night bound of its statistical checks
    #: the fleet ranking's measures (:func:`dracc.pipeline.audit.measures.night_measures`)
    measures: Mapping[str, Any] = field(default_factory=dict)
    #: calibrated quantities the data could not determine, and why (issue 29)
    calibration_not_determinable: Mapping[str, str] = field(default_factory=dict)
    #: why the analysis has no calibration at all (its Missing entry), None where it has one
    calibration_why_not: str | None = None


#: reject reasons of older analyses that were valid input dracc does not use
VALID_UNUSED = ("unsupported", "comment")

#: the words a DR verdict sentence starts with
DR_VERDICTS = ("consistent", "conservative", "inconsistent", "undetermined")


def dr_verdict_word(text: object) -> str | None:
    """The verdict word of a DR verdict sentence ("inconsistent (circle too small): …" ->
    'inconsistent'); None for anything else."""
    if not isinstance(text, str):
        return None
    head = text.split(":", 1)[0].strip().lower()
    for word in DR_VERDICTS:  # "inconsistent" is not read as "consistent": whole first word
        if head == word or head.startswith((word + " ", word + "(")):
            return word
    return None


def _bool(x: object) -> bool | None:
    return x if isinstance(x, bool) else None


def _text(x: object) -> str | None:
    return x if isinstance(x, str) and x.strip() else None


def _estimate(e: Estimate | None) -> tuple[float | None, float | None]:
    """(value, sigma) of an estimate; (None, None) without one."""
    if e is None:
        return None, None
    return finite_or_none(e.value), finite_or_none(e.sigma)


def _sources_by_role(a: Analysis) -> dict[str, str]:
    """role -> the keys of the sources in that role, comma-separated, in source order."""
    keys: dict[str, list[str]] = {}
    for s in a.sources:
        for role in s.roles:
            keys.setdefault(str(role), []).append(str(s.key))
    return {role: ",".join(k) for role, k in keys.items()}


def channel_rows(dev: DeviationResult | None) -> tuple[ChannelRow, ...]:
    """The whole-log statistics per unit (sorted) and channel (the paper's order)."""
    if dev is None:
        return ()
    rows = []
    for unit, per in sorted(dev.whole.units.items()):
        for ch in CHANNELS:
            st = per.channels.get(ch)
            if st is None:
                continue
            rows.append(
                ChannelRow(
                    unit=str(unit),
                    channel=ch,
                    n=int(st.n or 0),
                    m_u=finite_or_none(st.m_u),
                    m_y=finite_or_none(st.m_y),
                    kurtosis=finite_or_none(st.kurtosis),
                    limit_error=finite_or_none(st.limit),
                )
            )
    return tuple(rows)


def _dr_facts(dr: DRSection | None) -> dict[str, Any]:
    """The NightFacts fields of the dead-reckoning section."""
    if dr is None:
        return {"dr_containment_2m": None, "dr_n_scored": None}
    verdict_text = _text(dr.verdict)
    return {
        "dr_containment_2m": finite_or_none(dr.containment_2m),
        "dr_n_scored": int(dr.n_scored),
        "dr_verdict": dr_verdict_word(verdict_text),
        "dr_verdict_text": verdict_text,
        "dr_consistent": _bool(dr.consistent),
        "dr_nees": finite_or_none(dr.nees_statistic),
        "dr_nees_lower": finite_or_none(dr.nees_lower),
        "dr_nees_upper": finite_or_none(dr.nees_upper),
        "dr_dominant_source": _text(dr.dominant_source),
        "dr_dominant_key": _text(dr.dominant_key),
        "dr_reference_source": _text(dr.fix_source_key),
        "dr_jump_legs": tuple(
            {"start": iso_utc(leg.start_ns), "end": iso_utc(leg.end_ns)}
            for leg in dr.legs
            if leg.index in dr.reference_jump_legs
        ),
        "dr_verdict_without_jump_legs": dr.verdict_without_jump_legs,
    }


def facts_from_analysis(a: Analysis) -> NightFacts:
    """Read the figures the audit checks from an analysis."""
    inputs = a.inputs
    lines = sum(int(i.lines or 0) for i in inputs) if inputs else None
    # damaged lines only: analyses made before 'ignored' counted valid unused
    # sentences as the reasons 'unsupported' and 'comment'
    rejected = (
        sum(
            sum(int(n) for r, n in (i.rejected or {}).items() if r not in VALID_UNUSED)
            for i in inputs
        )
        if inputs
        else None
    )
    ignored: dict[str, int] = {}
    for i in inputs:
        for k, n in {
            **(i.ignored or {}),
            **{r: n for r, n in (i.rejected or {}).items() if r in VALID_UNUSED},
        }.items():
            ignored[str(k)] = ignored.get(str(k), 0) + int(n)
    cal = a.calibration
    ce, ce_s = _estimate(cal.compass_error_deg if cal is not None else None)
    ls, ls_s = _estimate(cal.log_scale if cal is not None else None)
    integ = a.integrity
    return NightFacts(
        period_start_utc=iso_utc(a.start_ns),
        period_end_utc=iso_utc(a.end_ns),
        inputs=tuple(str(i.path) for i in inputs),
        lines=lines,
        rejected=rejected,
        rejected_rate=(rejected / lines) if lines and rejected is not None else None,
        sources=_sources_by_role(a),
        channels=channel_rows(a.deviation),
        compass_error_deg=ce,
        compass_error_sigma_deg=ce_s,
        log_scale=ls,
        log_scale_sigma=ls_s,
        missing=tuple(str(m) for m in a.missing),
        duration_s=finite_or_none(a.duration_s),
        ignored=ignored,
        integrity_checks=tuple(integ.checks) if integ is not None else (),
        integrity_false_alarm=(
            finite_or_none(integ.false_alarm_per_night) if integ is not None else None
        ),
        measures=night_measures(a),
        calibration_not_determinable=_not_determinable(cal),
        calibration_why_not=None if cal is not None else _calibration_why_not(a),
        **_dr_facts(a.dead_reckoning),
    )


def _not_determinable(cal: CalibrationSection | None) -> dict[str, str]:
    """The calibration's quantities it could not determine, with why; one it gives no
    finite estimate of is among them (said so), never left to read as 'not estimated'."""
    if cal is None:
        return {}
    out = dict(cal.not_determinable)
    for key, e in (("compass_error_deg", cal.compass_error_deg), ("log_scale", cal.log_scale)):
        if e is None or finite_or_none(e.value) is None:
            got = "no estimate" if e is None else f"an estimate of {e.value}"
            out.setdefault(key, f"the calibration gives {got} and no reason")
    return out


def _calibration_why_not(a: Analysis) -> str | None:
    """Why the analysis has no calibration where its fit ran and failed (the fit's own
    reason, from the Missing list); None where the dead reckoning it rests on did not run."""
    from dracc.pipeline.calibration_stage import NOT_COMPUTED

    return next((str(m) for m in a.missing if str(m).startswith(NOT_COMPUTED)), None)


def night_of(facts: NightFacts) -> str:
    """The night a log belongs to when no --date is given: the UTC date of the period's middle."""
    if not facts.period_start_utc or not facts.period_end_utc:
        raise InsufficientDataError("the logs carry no dated records; give the night with --date")
    t0 = parse_utc(facts.period_start_utc)
    t1 = parse_utc(facts.period_end_utc)
    return (t0 + (t1 - t0) / 2).date().isoformat()
