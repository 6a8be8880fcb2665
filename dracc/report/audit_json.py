"""The audit document, schema ``dracc.audit/1`` (``audit.schema.json`` beside this file).

What one night's audit found, in the terms of the integrity standards (IMO MSC.252(83)
5.1.2, 5.3-5.4): the verdict, the findings with their check, source, role, clause,
statistic, threshold, window and evidence, the checks that could not be made and why,
the accuracy window, and the analysis document (``dracc.analysis/1``) it rests on.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import asdict
from pathlib import Path

from dracc import __version__
from dracc.core import atomic
from dracc.core.numbers import jsonable
from dracc.pipeline.audit import AuditOutcome, Finding

SCHEMA = "dracc.audit/1"
SCHEMA_PATH = Path(__file__).with_name("audit.schema.json")


def load_schema() -> dict:
    return json.loads(SCHEMA_PATH.read_text(encoding="utf-8"))


def finding_dict(f: Finding) -> dict:
    """One finding with the contract keys first (check, source, role, clause, statistic,
    threshold, window, evidence, message)."""
    d = asdict(f)
    head = {
        k: d.pop(k)
        for k in (
            "check",
            "source",
            "role",
            "clause",
            "statistic",
            "threshold",
            "window",
            "evidence",
            "message",
        )
    }
    head["kind"] = d.pop("kind")
    head["subject"] = d.pop("subject")
    head["false_alarm"] = d.pop("false_alarm")
    return jsonable(head)


def to_dict(o: AuditOutcome, analysis: Mapping | None) -> dict:
    """The audit document of one night."""
    r = o.record
    channels = [
        {
            "unit": c.unit,
            "channel": c.channel,
            "measure": c.measure,
            "n": c.n,
            "m_u": c.m_u,
            "m_y": c.m_y,
            "kurtosis": c.kurtosis,
            "limit_error": c.limit_error,
            "apriori_before": c.apriori_before,
            "apriori_after": c.apriori_after,
            "verdict": c.verdict,
        }
        for c in r.channels
    ]
    doc = {
        "schema": SCHEMA,
        "dracc_version": __version__,
        "vessel": r.vessel,
        "night": r.night,
        "verdict": o.verdict,
        "exit_code": int(o.exit_code),
        "state": o.status,
        "audited_utc": r.audited_utc,
        "logs": {
            "files": list(r.inputs),
            "lines": r.lines,
            "rejected": r.rejected,
            "rejected_rate": r.rejected_rate,
            "ignored": dict(o.ignored),
            "period": {"start_utc": r.period_start_utc, "end_utc": r.period_end_utc},
        },
        "sources": dict(r.sources),
        "findings": [finding_dict(f) for f in o.findings],
        "not_checked": [dict(n) for n in o.not_checked],
        "false_alarm_per_night": o.false_alarm_per_night,
        "accuracy": dict(o.accuracy),
        "ins": channels,
        "apriori_events": [
            {
                "unit": e.unit,
                "channel": e.channel,
                "value": e.value,
                "previous": e.previous,
                "reason": e.reason,
            }
            for e in o.apriori_events
        ],
        "dead_reckoning": {
            "verdict": r.dr_verdict,
            "verdict_text": r.dr_verdict_text,
            "containment_2m": r.dr_containment_2m,
            "nees": r.dr_nees,
        },
        "calibration": {
            "compass_error_deg": r.compass_error_deg,
            "compass_error_sigma_deg": r.compass_error_sigma_deg,
            "log_scale": r.log_scale,
            "log_scale_sigma": r.log_scale_sigma,
        },
        "missing": list(r.missing),
        "analysis": analysis,
    }
    return jsonable(doc)


def write_json(o: AuditOutcome, analysis: Mapping | None, path: str | Path) -> None:
    """Write the audit document atomically."""
    atomic.write_text(
        path, json.dumps(to_dict(o, analysis), indent=1, allow_nan=False, ensure_ascii=False) + "\n"
    )
