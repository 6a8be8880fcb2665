"""The nightly checks: :func:`evaluate` turns one night's :class:`NightFacts` into findings.

A :class:`Finding` is one check that failed, in the terms of the integrity standards
(check family, source, role, clause, statistic, threshold, window, evidence); a check
that could not be made is a ``not checked`` entry saying why.  The limiting errors are
judged over several nights (:mod:`dracc.pipeline.audit.accuracy`), not here.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

from dracc.core.numbers import finite_or_none, jsonable
from dracc.core.timefmt import iso_utc
from dracc.math.integrity.causes import Trace, group, trace
from dracc.pipeline.audit.facts import NightFacts
from dracc.pipeline.audit.limits import AuditConfig
from dracc.pipeline.audit.sensor_checks import missing_source_args, sensor_error_checks

if TYPE_CHECKING:
    from dracc.math.integrity import Check


#: the clause each audit-level check cites (the integrity checks carry their own)
AUDIT_CLAUSES = {
    "accuracy": "IMO MSC.252(83) 5.3 accuracy; INS deviations from the mean of three (Boykov, "
    "Mikhalskiy and Ivantsov, K3b-K8): limiting error at the probability, over the accuracy window",
    "input": "IEC 61162-1: sentences that fail their checksum or structure are damaged input",
    "availability": "IMO MSC.252(83) 5.1.2: availability of the required sources",
    "consistency": "IMO MSC.252(83) 5.4: consistency of the DR and its 2M with the position fixes",
}


@dataclass(frozen=True)
class Finding:
    """One check that failed.  ``value`` and ``limit`` in the unit named by ``measure``;
    ``check`` is the family of the audit document (validity | plausibility | latency |
    availability | consistency | accuracy | input)."""

    kind: str  #: e.g. 'jump', 'dropout', 'limit', 'dr_inconsistent', 'rejected_rate', ...
    subject: str  #: e.g. 'ins2 lon', 'DR', 'compass', 'GNSS'
    value: float | None
    limit: float | None
    measure: str
    message: str
    check: str = "accuracy"
    source: str | None = None
    role: str | None = None
    clause: str = ""
    statistic: Mapping[str, Any] = field(default_factory=dict)  #: {"name", "value", "unit"}
    threshold: Mapping[str, Any] = field(default_factory=dict)  #: {"value", "unit", "rule"}
    window: Mapping[str, Any] = field(default_factory=dict)  #: {"start_utc", "end_utc", ...}
    evidence: tuple[Any, ...] = ()
    false_alarm: float | None = None  #: probability per night that a healthy source fails it
    #: the failed checks this one caused (:func:`with_consequences`), listed under it
    consequences: tuple[Finding, ...] = ()


def make_finding(
    check: str,
    kind: str,
    subject: str,
    value: float | None,
    limit: float | None,
    measure: str,
    message: str,
    *,
    source: str | None = None,
    role: str | None = None,
    statistic_name: str = "",
    rule: str = "",
    window: Mapping[str, Any] | None = None,
    evidence: Sequence[Any] = (),
    false_alarm: float | None = None,
) -> Finding:
    """A finding of an audit-level check, citing the clause of its ``check`` family."""
    return Finding(
        kind,
        subject,
        value,
        limit,
        measure,
        message,
        check=check,
        source=source,
        role=role,
        clause=AUDIT_CLAUSES.get(check, ""),
        statistic={"name": statistic_name or kind, "value": value, "unit": measure},
        threshold={"value": limit, "unit": measure, "rule": rule},
        window=dict(window or {}),
        evidence=tuple(evidence),
        false_alarm=false_alarm,
    )


def not_checked(
    check: str, name: str, why: str, source: str | None = None, role: str | None = None
) -> dict[str, Any]:
    """A check that could not be made, and why (an entry of the audit's ``not_checked``)."""
    return {"check": check, "name": name, "source": source, "role": role, "why": why}


def integrity_finding(c: Check) -> Finding:
    """A failed integrity check of the analysis as a finding (its own clause and figures)."""
    st = jsonable(c.statistic or {})
    th = jsonable(c.threshold or {})
    return Finding(
        str(c.name),
        str(c.source or c.role or ""),
        finite_or_none(st.get("value")),
        finite_or_none(th.get("value")),
        str(st.get("unit") or ""),
        str(c.message or ""),
        check=str(c.check),
        source=c.source,
        role=c.role,
        clause=str(c.clause or ""),
        statistic=st,
        threshold=th,
        window={
            "start_utc": iso_utc(c.window.get("start_ns")),
            "end_utc": iso_utc(c.window.get("end_ns")),
        },
        evidence=tuple(jsonable(e) for e in c.evidence),
        false_alarm=finite_or_none(c.false_alarm),
    )


def evaluate(
    facts: NightFacts, acfg: AuditConfig
) -> tuple[tuple[Finding, ...], tuple[dict[str, Any], ...]]:
    """Check one night: (findings, checks that could not be made, each with why).

    The integrity checks of the analysis (validity, plausibility, latency, availability,
    consistency of every source) are read as they failed; the audit adds the required
    sources, the DR against the fixes, the compass and log calibration against their
    limits and the damaged input.  The limiting errors are judged over the accuracy
    window by :func:`dracc.pipeline.audit.accuracy.accuracy_findings`, not one night at a time.
    """
    found: list[Finding] = []
    skipped: list[dict[str, Any]] = []
    window = {"start_utc": facts.period_start_utc, "end_utc": facts.period_end_utc}
    # the required sources, naming the key to change (dracc.pipeline.audit.sensor_checks)
    found += [make_finding(**kw) for kw in missing_source_args(facts, acfg, window)]
    for c in facts.integrity_checks:
        if c.status == "fail":
            found.append(integrity_finding(c))
        elif c.status == "not_checked":
            skipped.append(
                not_checked(
                    str(c.check), str(c.name), str(c.why_not or c.message or ""), c.source, c.role
                )
            )
    below = (
        facts.dr_containment_2m is not None and facts.dr_containment_2m < acfg.dr_containment_min
    )
    if facts.dr_verdict == "inconsistent":
        # the analysis' own verdict (what `dracc analyze` says); one finding for one cause:
        # a containment below the audit's minimum is said in the same finding
        found.append(dr_inconsistent_finding(facts, acfg, below))
    elif facts.dr_containment_2m is None:
        skipped.append(not_checked("consistency", "dr", "no reference position or no DR track"))
    elif below:
        found.append(
            make_finding(
                "consistency",
                "dr_containment",
                "DR",
                facts.dr_containment_2m,
                acfg.dr_containment_min,
                "fraction",
                f"DR: reference inside 2M at {100 * facts.dr_containment_2m:.1f} %"
                f" of epochs < {100 * acfg.dr_containment_min:.1f} %",
                statistic_name="containment_2m",
                rule="[audit] dr_containment_min",
                window=window,
            )
        )
    if facts.dr_verdict == "undetermined":
        skipped.append(not_checked("consistency", "dr", f"DR verdict: {facts.dr_verdict_text}"))
    # compass and log against their limits, with their sigma, from fits that determine them
    sensor_found, sensor_skipped = sensor_error_checks(facts, acfg, window)
    found += [make_finding(**kw) for kw in sensor_found]
    skipped += sensor_skipped
    if facts.rejected_rate is not None and 100 * facts.rejected_rate > acfg.rejected_rate_max_pct:
        found.append(
            make_finding(
                "input",
                "rejected_rate",
                "inputs",
                100 * facts.rejected_rate,
                acfg.rejected_rate_max_pct,
                "%",
                f"{facts.rejected} of {facts.lines} lines damaged "
                f"({100 * facts.rejected_rate:.2f} % > {acfg.rejected_rate_max_pct:.2f} %)",
                rule="[audit] rejected_rate_max_pct: damaged lines (checksum, "
                "truncated, malformed) as % of all lines; valid sentences dracc "
                "does not use are ignored, not rejected",
                window=window,
                false_alarm=0.0,
            )
        )
    return with_consequences(found), tuple(skipped)


def finding_trace(f: Finding) -> Trace:
    """What a finding's evidence says about where and when (:mod:`dracc.math.integrity.causes`)."""
    return trace(f.check, f.kind, f.source, f.evidence)


def with_consequences(found: Sequence[Finding]) -> tuple[Finding, ...]:
    """One finding per cause: each finding another explains (a contradiction, the fixes
    outside the DR's 2M or the DR's verdict under a GNSS jump, a velocity disagreement
    under a frozen unit) listed under its cause (:func:`dracc.math.integrity.causes.cause_of`)."""
    return tuple(
        replace(cause, consequences=cause.consequences + tuple(under))
        for cause, under in group(found, finding_trace)
    )


def dr_inconsistent_finding(facts: NightFacts, acfg: AuditConfig, below: bool) -> Finding:
    """The analysis called the DR inconsistent: its verdict sentence is the message;
    value/limit are the NEES statistic and its upper chi-square bound where given."""
    msg = f"DR: {facts.dr_verdict_text}"
    if facts.dr_dominant_source and facts.dr_dominant_source not in msg:
        key = f" (key [dead_reckoning] {facts.dr_dominant_key})" if facts.dr_dominant_key else ""
        msg += f"; the circle is dominated by {facts.dr_dominant_source}{key}"
    if below and facts.dr_containment_2m is not None:
        msg += (
            f"; {100 * facts.dr_containment_2m:.1f} % inside 2M is below the audit's minimum "
            f"of {100 * acfg.dr_containment_min:.1f} %"
        )
    # the legs a jump of the reference touched, and the test without them: the evidence
    # that attaches this finding to the jump (dracc.math.integrity.causes)
    jumped = (
        {
            "reference_source": facts.dr_reference_source,
            "reference_jump_legs": [dict(leg) for leg in facts.dr_jump_legs],
            "verdict_without_them": facts.dr_verdict_without_jump_legs,
        },
    )
    return make_finding(
        "consistency",
        "dr_inconsistent",
        "DR",
        facts.dr_nees,
        facts.dr_nees_upper,
        "NEES" if facts.dr_nees is not None else "",
        msg,
        statistic_name="nees",
        rule="chi-square bounds of the NEES over the scored legs (alpha 0.01)",
        window={"start_utc": facts.period_start_utc, "end_utc": facts.period_end_utc},
        evidence=jumped if facts.dr_jump_legs else (),
        false_alarm=DR_FALSE_ALARM,
    )


#: the NEES test of dracc.math.deadreckoning.dr_consistency: two-sided at alpha = 0.01
DR_FALSE_ALARM = 0.01
