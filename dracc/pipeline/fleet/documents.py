"""Edge-first fleet inputs: the nightly audit documents ships send ashore.

A ship's nightly ``dracc audit`` writes a few kB: the audit document (``dracc.audit/1``
JSON, ``--json``) and its state database (SQLite, ``--db``).  :func:`expand_documents`
finds them among the fleet's inputs (by their first bytes, whatever their names) and
turns each night in them into a fleet row, without any raw log: one pseudo-log
``<file>#<night>`` per night, with the summary :func:`dracc.pipeline.fleet.summarise`
would give for the night's logs (the measures the ranking reads are stored verbatim),
so a fleet ranked from documents equals one ranked from the logs.  The vessel is the
one the documents name.  Both come from outside and are checked before use (issue 33):
a document is parsed within bounds of size and nesting and its fields checked
(:mod:`dracc.pipeline.fleet.validate`); a database is opened immutable, its schema and
column types checked, every query bounded in time (:mod:`dracc.pipeline.state_read`).
A document or database that fails is one failed input, its reason said; the rest goes on.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, replace

from dracc.core import jsonbound
from dracc.core.errors import StateError
from dracc.pipeline.fleet import validate
from dracc.pipeline.fleet.findings import COUNT_KEYS, document_counts, night_findings
from dracc.pipeline.fleet.tasks import LogTask
from dracc.pipeline.state import NightRecord
from dracc.pipeline.state_read import read_nights

AUDIT_SCHEMA = "dracc.audit/1"
_SQLITE_MAGIC = b"SQLite format 3\x00"
#: the largest audit document read (a whole one with its analysis is a few hundred kB)
MAX_DOCUMENT_BYTES = 64 << 20
#: how far into a JSON file its "schema" key is looked for (the audit writes it first)
_SNIFF_BYTES = 4096


def sniff(path: str) -> str | None:
    """'audit-json', 'state-db', or None for anything else (a log)."""
    try:
        with open(path, "rb") as f:
            head = f.read(_SNIFF_BYTES)
    except OSError:
        return None
    if head.startswith(_SQLITE_MAGIC):
        return "state-db"
    text = head.lstrip()
    if text.startswith(b"{") and b'"schema"' in text and AUDIT_SCHEMA.encode() in text:
        return "audit-json"
    return None


def _channels(rows) -> list[dict]:
    """The fleet's keys of each unit and channel (a figure absent is None)."""
    keys = ("unit", "channel", "n", "m_u", "m_y", "kurtosis", "limit_error")
    return [{k: c.get(k) for k in keys} for c in rows]


def summary_from_document(doc: dict) -> dict:
    """The fleet summary of one audit document's night."""
    logs = doc.get("logs") or {}
    period = logs.get("period") or {}
    dr = doc.get("dead_reckoning") or {}
    cal = doc.get("calibration") or {}
    return {
        "schema": AUDIT_SCHEMA,
        "night": doc.get("night"),
        "period": {"start_utc": period.get("start_utc"), "end_utc": period.get("end_utc")},
        "lines": logs.get("lines"),
        "rejected": logs.get("rejected"),
        "sources": dict(doc.get("sources") or {}),
        "channels": _channels(doc.get("ins") or []),
        "dr": {
            "containment_2m": dr.get("containment_2m"),
            "n_scored": dr.get("n_scored"),
            "consistent": dr.get("consistent"),
            "verdict": dr.get("verdict"),
            "nees": dr.get("nees"),
        },
        "calibration": {
            k: cal.get(k)
            for k in (
                "compass_error_deg",
                "compass_error_sigma_deg",
                "log_scale",
                "log_scale_sigma",
            )
        },
        "missing": list(doc.get("missing") or []),
        "measures": doc.get("measures") or {},
        "findings": night_findings(doc.get("findings") or [], doc.get("not_checked") or []),
        "integrity": _document_integrity(doc),
    }


def _document_integrity(doc: dict) -> dict | None:
    """The counts of the night's integrity checks: the document's own, else counted from
    the analysis it embeds (a document written before it carried them); None for a
    brief document without them."""
    own = doc.get("integrity")
    if isinstance(own, dict):
        return {k: own.get(k) for k in COUNT_KEYS}
    checks = ((doc.get("analysis") or {}).get("integrity") or {}).get("checks")
    if not isinstance(checks, list):
        return None
    return document_counts(c for c in checks if isinstance(c, dict))


def _dr_and_calibration(r: NightRecord) -> dict:
    """A stored night's DR and calibration figures, as the audit document holds them."""
    return {
        "dr": {
            "containment_2m": r.dr_containment_2m,
            "n_scored": r.dr_n_scored,
            "consistent": r.dr_consistent,
            "verdict": r.dr_verdict,
            "nees": r.dr_nees,
        },
        "calibration": {
            "compass_error_deg": r.compass_error_deg,
            "compass_error_sigma_deg": r.compass_error_sigma_deg,
            "log_scale": r.log_scale,
            "log_scale_sigma": r.log_scale_sigma,
        },
    }


def summary_from_record(r: NightRecord) -> dict:
    """The fleet summary of one night stored in an audit database."""
    return {
        "schema": "dracc.audit.state",
        "night": r.night,
        "period": {"start_utc": r.period_start_utc, "end_utc": r.period_end_utc},
        "lines": r.lines,
        "rejected": r.rejected,
        "sources": dict(r.sources),
        "channels": _channels(
            [
                {
                    "unit": c.unit,
                    "channel": c.channel,
                    "n": c.n,
                    "m_u": c.m_u,
                    "m_y": c.m_y,
                    "kurtosis": c.kurtosis,
                    "limit_error": c.limit_error,
                }
                for c in r.channels
            ]
        ),
        **_dr_and_calibration(r),
        "missing": list(r.missing),
        "measures": r.measures or {},
        "findings": night_findings(r.findings),  # the database keeps no checks not made
        "integrity": None,  # nor the counts
    }


def _read_document(path: str) -> dict:
    """The audit document at ``path``, parsed within bounds (:data:`MAX_DOCUMENT_BYTES`,
    :data:`dracc.core.jsonbound.MAX_DEPTH` levels) and checked field by field
    (:func:`dracc.pipeline.fleet.validate.check_document`); StateError otherwise."""
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_DOCUMENT_BYTES + 1)
    except OSError as err:
        raise StateError(f"{path}: not a readable audit document: {err}") from None
    if len(data) > MAX_DOCUMENT_BYTES:  # a night's document is kB (brief) to a few MB
        raise StateError(
            f"{path}: more than {MAX_DOCUMENT_BYTES:,} bytes is not a nightly audit document; "
            "not read"
        )
    try:
        doc = jsonbound.loads(data)
    except (ValueError, UnicodeDecodeError) as err:
        raise StateError(f"{path}: not a readable audit document: {err}") from None
    if not isinstance(doc, dict) or doc.get("schema") != AUDIT_SCHEMA:
        raise StateError(f"{path}: not an audit document ({AUDIT_SCHEMA})")
    return doc


def _record_fields(r: NightRecord) -> dict:
    """The fields of a stored night the fleet reads, as :data:`validate.RECORD` names them."""
    return {
        "vessel": r.vessel,
        "night": r.night,
        "period": {"start_utc": r.period_start_utc, "end_utc": r.period_end_utc},
        "inputs": list(r.inputs),
        "sources": r.sources,
        "lines": r.lines,
        "rejected": r.rejected,
        "channels": [asdict(c) for c in r.channels],
        **_dr_and_calibration(r),
        "missing": list(r.missing),
        "measures": r.measures,
        "findings": list(r.findings),
    }


def _nights(task: LogTask, kind: str) -> list[tuple[str, str, dict]]:
    """(vessel, night, summary) of every night with data in one document; StateError for
    a document or database that cannot be read or holds a field the fleet cannot use
    (:mod:`dracc.pipeline.fleet.validate`)."""
    if kind == "audit-json":
        doc = _read_document(task.path)
        if doc.get("verdict") == "no data" or doc.get("status") == "failed":
            return []  # a night without data, or a run that ended without a verdict
        try:
            validate.check_document(doc)
        except validate.Invalid as err:
            raise StateError(f"{task.path}: not a usable audit document: {err}") from None
        return [
            (str(doc.get("vessel") or task.vessel), str(doc["night"]), summary_from_document(doc))
        ]
    out = []
    for r in read_nights(task.path):  # immutable, schema-checked, bounded in time
        if r.period_start_utc is None:
            continue  # a night recorded without logs
        try:
            validate.RECORD(_record_fields(r), "")
        except validate.Invalid as err:
            raise StateError(
                f"{task.path}: night {r.night[:20]!r} of {r.vessel[:40]!r} is not usable: {err}"
            ) from None
        out.append((r.vessel, r.night, summary_from_record(r)))
    return out


def expand_documents(
    tasks: Sequence[LogTask],
) -> tuple[list[LogTask], dict[str, dict], dict[str, str]]:
    """Replace each audit document or database among ``tasks`` by one task per night it
    holds; returns (tasks, summaries of those nights by task path, failures by path).
    A log is passed through unchanged."""
    out: list[LogTask] = []
    summaries: dict[str, dict] = {}
    failures: dict[str, str] = {}
    for t in tasks:
        kind = None if t.error is not None else sniff(t.path)
        if kind is None:
            out.append(t)
            continue
        try:
            nights = _nights(t, kind)
        except StateError as err:
            out.append(t)
            failures[t.path] = str(err)
            continue
        for vessel, night, summary in nights:
            key = f"{t.path}#{vessel}#{night}"
            out.append(replace(t, vessel=vessel, path=key, log=f"{t.log}#{night}"))
            summaries[key] = summary
    return out, summaries, failures
