"""The audit's sensor checks: the compass error and the log scale against their limits, and
the required sources (issue 29).

A sensor-error finding compares the limit with the estimate *and* its sigma.  With
``z = Phi^-1(1 - a)`` for the audit's false-alarm probability ``a`` per check and night
(``[audit] false_alarm``, else ``[integrity] false_alarm``), the sensor fails only where
the interval ``estimate -+ z sigma`` lies wholly beyond the limit: a sensor exactly at
the limit fails with probability ``a``, one within it less often.  The finding says the
interval.  An interval that reaches across the limit is inconclusive: no finding, a
``not checked`` entry with the interval.  A quantity the calibration could not determine
(:mod:`dracc.math.calibration`: a ship at rest, one course, one speed) gives no finding
either: a ``not checked`` entry with the calibration's why.

A missing required source names the key to change and what to set it to for this vessel:
the roles its logs have.

The functions return plain data (the keyword arguments of
:func:`dracc.pipeline.audit.findings.make_finding`, and ``not checked`` entries), so
that :func:`~dracc.pipeline.audit.findings.evaluate` builds the findings.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from dracc.core import distributions as dist
from dracc.core.vocabulary import ROLES
from dracc.pipeline.audit.limits import AuditConfig

if TYPE_CHECKING:
    from dracc.pipeline.audit.facts import NightFacts

__all__ = ["missing_source_args", "sensor_checks_made", "sensor_error_checks"]


@dataclass(frozen=True)
class _Quantity:
    """One calibrated quantity the audit checks against a limit."""

    kind: str  #: the finding's kind and the not-checked name
    subject: str
    role: str
    label: str
    unit: str
    key: str  #: its key in the calibration's ``not_determinable``
    rule: str  #: the configuration key of its limit
    absent: str  #: why there is no estimate: no calibration ran (else its own why is said)


_COMPASS = _Quantity(
    "compass_error",
    "compass",
    "compass",
    "compass error",
    "deg",
    "compass_error_deg",
    "[audit] compass_error_max_deg",
    "compass error not estimated: no dead reckoning to calibrate (it needs a heading, a "
    "speed log and a reference; see missing)",
)
_LOG = _Quantity(
    "log_scale",
    "log",
    "log",
    "log scale error",
    "%",
    "log_scale",
    "[audit] log_scale_max_pct",
    "log scale not estimated: no dead reckoning to calibrate (it needs a heading, a "
    "speed log and a reference; see missing)",
)


def _estimates(
    facts: NightFacts, acfg: AuditConfig
) -> tuple[tuple[_Quantity, float | None, float | None, float], ...]:
    """(quantity, estimate, sigma, limit) in the unit of the limit (degrees, percent)."""
    pct = 100.0
    ls, ls_s = facts.log_scale, facts.log_scale_sigma
    return (
        (
            _COMPASS,
            facts.compass_error_deg,
            facts.compass_error_sigma_deg,
            acfg.compass_error_max_deg,
        ),
        (
            _LOG,
            None if ls is None else pct * ls,
            None if ls_s is None else pct * ls_s,
            acfg.log_scale_max_pct,
        ),
    )


def _undetermined(facts: NightFacts) -> Mapping[str, str]:
    return facts.calibration_not_determinable


def sensor_checks_made(facts: NightFacts, acfg: AuditConfig) -> int:
    """How many sensor-error checks the night's figures allowed (each at ``acfg.false_alarm``)."""
    nd = _undetermined(facts)
    return sum(
        1
        for q, v, s, _ in _estimates(facts, acfg)
        if q.key not in nd and v is not None and s is not None and s >= 0
    )


def sensor_error_checks(
    facts: NightFacts, acfg: AuditConfig, window: Mapping[str, Any]
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The compass-error and log-scale checks: (make_finding keyword arguments, not checked)."""
    a = acfg.false_alarm
    z = float(dist.norm_ppf(1.0 - a))
    level = f"{100 * (1 - 2 * a):.4g} %"
    nd = _undetermined(facts)
    found: list[dict[str, Any]] = []
    skipped: list[dict[str, Any]] = []

    def skip(q: _Quantity, why: str) -> None:
        skipped.append(
            {"check": "accuracy", "name": q.kind, "source": None, "role": q.role, "why": why}
        )

    for q, value, sigma, limit in _estimates(facts, acfg):
        if q.key in nd:
            skip(q, f"not determinable from tonight's calibration: {nd[q.key]}")
            continue
        if value is None:
            skip(q, facts.calibration_why_not or q.absent)
            continue
        if sigma is None or not sigma >= 0:
            skip(
                q,
                f"{q.label} {value:+.2f} {q.unit} has no sigma: cannot be compared with the limit",
            )
            continue
        lo, hi = value - z * sigma, value + z * sigma
        interval = f"[{lo:+.2f}, {hi:+.2f}] {q.unit}"
        said = f"{q.label} {value:+.2f} ± {sigma:.2f} {q.unit} (1 sigma)"
        if lo > limit or hi < -limit:
            found.append(
                {
                    "check": "accuracy",
                    "kind": q.kind,
                    "subject": q.subject,
                    "value": value,
                    "limit": limit,
                    "measure": q.unit,
                    "message": (
                        f"{said} exceeds ±{limit:.2f} {q.unit}: its interval {interval} "
                        f"({level}, false alarm {a:g} a night) lies beyond the limit"
                    ),
                    "role": q.role,
                    "rule": q.rule,
                    "window": window,
                    "evidence": (
                        {"estimate": value, "sigma": sigma, "z": z, "interval": [lo, hi]},
                    ),
                    "false_alarm": a,
                }
            )
        elif hi > limit or lo < -limit:
            skip(
                q,
                f"inconclusive: {said}; its interval {interval} ({level}) reaches across "
                f"the limit ±{limit:.2f} {q.unit} ({q.rule}); more hours, turns and speed "
                "changes narrow it",
            )
    return found, skipped


def missing_source_args(
    facts: NightFacts, acfg: AuditConfig, window: Mapping[str, Any]
) -> list[dict[str, Any]]:
    """A finding (make_finding keyword arguments) per required role the logs lack, naming
    ``[audit] required_sources`` and what to set it to for this vessel: the roles it has."""
    has = [r for r in ROLES if r in facts.sources]
    value = json.dumps(has)
    missing = [r for r in acfg.required_sources if r not in facts.sources]
    out = []
    for role in missing:
        if has:
            fix = (
                f"if this vessel has no {role}, set [audit] required_sources = {value} "
                "(the roles its logs have) in the configuration file"
            )
        else:
            fix = "no source in the logs has a role (see 'dracc inspect')"
        out.append(
            {
                "check": "availability",
                "kind": "missing_source",
                "subject": role,
                "value": None,
                "limit": None,
                "measure": "",
                "message": f"required source {role} is missing from the logs; {fix}",
                "role": role,
                "rule": f"[audit] required_sources = {json.dumps(list(acfg.required_sources))}",
                "window": window,
                "evidence": ({"required": list(acfg.required_sources), "present": has},),
                "false_alarm": 0.0,
            }
        )
    return out
