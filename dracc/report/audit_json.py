"""The audit document, schema ``dracc.audit/1`` (``audit.schema.json`` beside this file).

What one night's audit found, in the terms of the integrity standards (IMO MSC.252(83)
5.1.2, 5.3-5.4): the verdict, the findings with their check, source, role, clause,
statistic, threshold, window and evidence, the checks that could not be made and why,
the accuracy window, and the analysis document (``dracc.analysis/1``) it rests on.

Also the history document of ``dracc audit history`` (schema ``dracc.audit.history/1``):
the trend per vessel, unit and channel, the nights and the a priori events.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from dracc import __version__
from dracc.core.numbers import jsonable
from dracc.pipeline.audit import AuditOutcome, Finding
from dracc.pipeline.results import Analysis
from dracc.pipeline.state import StateStore
from dracc.report.output import emit_json

SCHEMA = "dracc.audit/1"
SCHEMA_PATH = Path(__file__).with_name("audit.schema.json")


def load_schema() -> dict:
    return json.loads(SCHEMA_PATH.read_text(encoding="utf-8"))


def finding_dict(f: Finding) -> dict:
    """One finding with the contract keys first (check, source, role, clause, statistic,
    threshold, window, evidence, message), then the findings it caused (``consequences``)."""
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
    head["consequences"] = [consequence_dict(c) for c in f.consequences]
    return jsonable(head)


def consequence_dict(c: Finding) -> dict:
    """A finding listed under its cause: its check, name, source and message."""
    return {"check": c.check, "name": c.kind, "source": c.source, "message": c.message}


#: the monitoring rule's verdicts in the words of the analysis' a priori column
_RULE_WORDS = {
    "raised": "exceeds",
    "within": "within",
    "established": "no a priori: the deviation estimate is mandatory",
    "no data": "no estimate",
}


def audit_analysis(a: Analysis, ins: Sequence[Mapping[str, Any]]) -> Analysis:
    """``a`` with each unit channel's a priori RMS the one the audit judged it against
    (the monitoring rule's value before tonight, ``apriori_before``; the configured one
    on the first night), so the embedded tables and verdict use the audit's yardstick."""
    from dataclasses import replace

    d = a.deviation
    if d is None or not ins:
        return a
    units = {name: dict(u.channels) for name, u in d.whole.units.items()}
    for c in ins:
        chans = units.get(c["unit"])
        old = None if chans is None else chans.get(c["channel"])
        if chans is None or old is None:
            continue
        before = c["apriori_before"]
        chans[c["channel"]] = replace(
            old,
            apriori=before,
            exceeds_apriori=None if before is None else c["verdict"] == "raised",
            new_apriori=old.m_y if c["apriori_after"] is None else c["apriori_after"],
            verdict=_RULE_WORDS.get(c["verdict"], c["verdict"] or "no estimate"),
        )
    whole = replace(
        d.whole,
        units={n: replace(u, channels=units[n]) for n, u in d.whole.units.items()},
    )
    return replace(a, deviation=replace(d, whole=whole))


def _analysis(a: Analysis, ins: list[dict]) -> dict:
    """The analysis document the night rests on; its worst_ins_unit judged against the
    audit's a priori values, as the audit page's verdict is (one rule, one answer)."""
    from dracc.report import json_report

    return json_report.to_dict(a, judged=audit_analysis(a, ins))


def to_dict(o: AuditOutcome) -> dict:
    """The audit document of one night, with the analysis document it rests on."""
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
        "integrity": _integrity_counts(o),
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
            "n_scored": r.dr_n_scored,
            "consistent": r.dr_consistent,
            "nees": r.dr_nees,
        },
        "calibration": {
            "compass_error_deg": r.compass_error_deg,
            "compass_error_sigma_deg": r.compass_error_sigma_deg,
            "log_scale": r.log_scale,
            "log_scale_sigma": r.log_scale_sigma,
        },
        "missing": list(r.missing),
        "measures": r.measures,
        "analysis": None if o.analysis is None else _analysis(o.analysis, channels),
    }
    return jsonable(doc)


def _integrity_counts(o: AuditOutcome) -> dict | None:
    """The night's integrity checks made, passed, failed and not checked (a brief
    document keeps them: the fleet's integrity table reads them); None without them."""
    from dracc.pipeline.fleet.findings import integrity_counts

    ig = None if o.analysis is None else o.analysis.integrity
    return None if ig is None else integrity_counts(ig)


def brief(doc: dict) -> dict:
    """The audit document without the analysis it rests on (``analysis`` null): the
    night's verdict, findings, INS statistics and ranking measures, about 10 kB, for a
    ship to send ashore (``dracc audit --json F --brief``)."""
    return {**doc, "analysis": None}


def write_json(o: AuditOutcome, target: str | Path, *, without_analysis: bool = False) -> None:
    """Write the audit document to ``target`` (atomically), or on stdout for '-'."""
    doc = to_dict(o)
    emit_json(brief(doc) if without_analysis else doc, target)


# ------------------------------------------------------------------------- history

HISTORY_SCHEMA = "dracc.audit.history/1"

#: the figures of one night in a series of the history
_SERIES_NIGHT_KEYS = (
    "night",
    "n",
    "m_u",
    "m_y",
    "kurtosis",
    "limit_error",
    "apriori_before",
    "apriori_after",
    "verdict",
)


def history_document(
    store: StateStore,
    vessel: str | None = None,
    unit: str | None = None,
    channel: str | None = None,
) -> dict:
    """The trend as a JSON-ready dict (schema ``dracc.audit.history/1``)."""
    series: dict[tuple, dict] = {}
    for h in store.history(vessel, unit, channel):
        key = (h["vessel"], h["unit"], h["channel"])
        s = series.setdefault(
            key,
            {
                "vessel": key[0],
                "unit": key[1],
                "channel": key[2],
                "measure": h["measure"],
                "nights": [],
            },
        )
        s["nights"].append({k: h[k] for k in _SERIES_NIGHT_KEYS})
    nights = [
        {
            "vessel": r.vessel,
            "night": r.night,
            "audited_utc": r.audited_utc,
            "content_sha256": r.content_sha256,
            "dr_containment_2m": r.dr_containment_2m,
            "dr_verdict": r.dr_verdict,
            "dr_consistent": r.dr_consistent,
            "dr_nees": r.dr_nees,
            "compass_error_deg": r.compass_error_deg,
            "log_scale": r.log_scale,
            "rejected_rate": r.rejected_rate,
            "findings": list(r.findings),
        }
        for v in ([vessel] if vessel else store.vessels())
        for r in store.nights(v)
    ]
    events = [
        {
            "vessel": e.vessel,
            "unit": e.unit,
            "channel": e.channel,
            "night": e.night,
            "value": e.value,
            "previous": e.previous,
            "reason": e.reason,
            "evidence": e.evidence,
        }
        for e in store.apriori_events(vessel)
        if (unit is None or e.unit == unit) and (channel is None or e.channel == channel)
    ]
    return {
        "schema": HISTORY_SCHEMA,
        "series": list(series.values()),
        "nights": nights,
        "apriori_events": events,
    }
