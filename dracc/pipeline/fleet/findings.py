"""Each night's findings and integrity results, as the fleet's ``findings`` and
``integrity`` tables.

A night of the fleet carries what its audit says, whichever way it came in:

- a raw log: :func:`dracc.pipeline.audit.findings.evaluate` on the log's analysis under
  the ``[audit]`` settings (the checks the audit makes of one night: the integrity
  checks that failed, the required sources, the DR against the fixes, compass and log
  against their limits, damaged input), and the counts of the analysis' integrity checks;
- an audit document (``dracc.audit/1``): its ``findings`` and ``not_checked``, and its
  ``integrity`` counts (from its embedded analysis for a document written before it had
  them; none for a brief one);
- an audit database: the findings it stored (no counts, no checks not made).

The limiting errors judged over the accuracy window are in a document's or database's
findings only: a raw log is one night, and the window needs several.

``findings`` has one row per finding (``status='fail'``; the failed checks it caused in
``consequences``, ``name: message`` each, separated by `` | ``) and per check that could not be made (``status='not_checked'``, the
reason as its ``message``); ``integrity`` one row per log (a night of a document) with
the integrity checks made (``checks_made = checks_passed + checks_failed``) and not made
(``checks_not_checked``), NULL where the input does not say.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import pandas as pd

from dracc.pipeline.fleet.tables import DATE_DTYPE, night_of_summary
from dracc.pipeline.fleet.tasks import LogTask

if TYPE_CHECKING:
    from dracc.math.integrity import IntegrityResult

#: columns of findings.parquet/.csv, in order
FINDING_COLUMNS = (
    "vessel",
    "log",
    "night",
    "status",
    "check",
    "name",
    "source",
    "role",
    "message",
    "window_start_utc",
    "window_end_utc",
    "consequences",
)
#: columns of integrity.parquet/.csv, in order
INTEGRITY_COLUMNS = (
    "vessel",
    "log",
    "night",
    "checks_made",
    "checks_passed",
    "checks_failed",
    "checks_not_checked",
)
#: the counts of :func:`integrity_counts`, as the integrity table names them
COUNT_KEYS = INTEGRITY_COLUMNS[3:]


def _counts(made: int, failed: int, not_checked: int) -> dict[str, int]:
    return {
        "checks_made": made,
        "checks_passed": made - failed,
        "checks_failed": failed,
        "checks_not_checked": not_checked,
    }


def integrity_counts(ig: IntegrityResult) -> dict[str, int]:
    """The night's integrity checks made (passed + failed), passed, failed, not checked:
    the counts every report states (:attr:`IntegrityResult.made`, ``.failed``,
    ``.not_checked``)."""
    return _counts(len(ig.made), len(ig.failed), len(ig.not_checked))


def document_counts(checks: Iterable[Mapping]) -> dict[str, int]:
    """The same counts from an analysis document's checks (``integrity.checks`` of
    ``dracc.analysis/1``), each with its ``status``: pass, fail or not_checked."""
    status = [str(c.get("status")) for c in checks]
    skipped = status.count("not_checked")
    return _counts(len(status) - skipped, status.count("fail"), skipped)


def _text(x: Any) -> str | None:
    return x if isinstance(x, str) and x.strip() else None


#: between the failed checks a finding caused, in its ``consequences`` cell
CONSEQUENCES_SEP = " | "


def _consequence(c: Mapping) -> str:
    """'name: message' of a finding listed under its cause (the audit document names it
    ``name``; a stored finding ``kind``; the message names the source)."""
    name = _text(c.get("name")) or _text(c.get("kind")) or "?"
    return f"{name}: {c.get('message') or ''}"


def night_findings(
    findings: Iterable[Mapping], not_checked: Iterable[Mapping] = ()
) -> list[dict[str, Any]]:
    """One night's findings (dicts as the audit document, the audit database or
    ``dataclasses.asdict`` of a :class:`~dracc.pipeline.audit.findings.Finding` give them)
    and checks not made (``{check, name, source, role, why}``) as rows of the findings table
    (without vessel, log and night)."""
    rows = []
    for f in findings:
        window = f.get("window") or {}
        rows.append(
            {
                "status": "fail",
                "check": _text(f.get("check")),
                "name": _text(f.get("kind")) or _text(f.get("name")),
                # the source key; an audit-level finding names its subject (DR, compass)
                "source": _text(f.get("source")) or _text(f.get("subject")),
                "role": _text(f.get("role")),
                "message": str(f.get("message") or ""),
                "window_start_utc": window.get("start_utc"),
                "window_end_utc": window.get("end_utc"),
                "consequences": CONSEQUENCES_SEP.join(
                    _consequence(c) for c in f.get("consequences") or ()
                )
                or None,
            }
        )
    for n in not_checked:
        rows.append(
            {
                "status": "not_checked",
                "check": _text(n.get("check")),
                "name": _text(n.get("name")),
                "source": _text(n.get("source")),
                "role": _text(n.get("role")),
                "message": str(n.get("why") or ""),
                "window_start_utc": None,
                "window_end_utc": None,
                "consequences": None,
            }
        )
    return rows


def _key(t: LogTask, s: Mapping) -> dict[str, Any]:
    return {"vessel": t.vessel, "log": t.log, "night": night_of_summary(s)}


def findings_table(tasks: Sequence[LogTask], summaries: Mapping[str, Mapping]) -> pd.DataFrame:
    """Every night's findings and checks not made (:data:`FINDING_COLUMNS`), by vessel,
    night, log, then failed before not checked, in the order the audit gives them."""
    rows = [
        {**_key(t, s), **f}
        for t in tasks
        if (s := summaries.get(t.path)) is not None
        for f in s.get("findings") or ()
    ]
    df = pd.DataFrame(rows, columns=list(FINDING_COLUMNS))
    for c in ("window_start_utc", "window_end_utc"):
        df[c] = pd.to_datetime(df[c], utc=True, format="ISO8601").astype("datetime64[ns, UTC]")
    df["night"] = _dates(df["night"])
    for c in FINDING_COLUMNS:
        if c not in ("night", "window_start_utc", "window_end_utc"):
            df[c] = df[c].astype("string")
    order = df["status"].map({"fail": 0}).fillna(1)
    return (
        df.assign(_order=order)
        .sort_values(["vessel", "night", "log", "_order"], kind="mergesort", na_position="last")
        .drop(columns="_order")
        .reset_index(drop=True)
    )


def integrity_table(tasks: Sequence[LogTask], summaries: Mapping[str, Mapping]) -> pd.DataFrame:
    """One row per log or night read (:data:`INTEGRITY_COLUMNS`), by vessel, night, log."""
    rows = [
        {**_key(t, s), **(s.get("integrity") or {})}
        for t in tasks
        if (s := summaries.get(t.path)) is not None
    ]
    df = pd.DataFrame(rows, columns=list(INTEGRITY_COLUMNS))
    df["night"] = _dates(df["night"])
    for c in ("vessel", "log"):
        df[c] = df[c].astype("string")
    for c in COUNT_KEYS:
        df[c] = pd.to_numeric(df[c], errors="coerce").astype("Int64")
    return df.sort_values(
        ["vessel", "night", "log"], kind="mergesort", na_position="last"
    ).reset_index(drop=True)


def _dates(texts: pd.Series) -> pd.Series:
    """ISO dates (or None) as the tables' date column (pyarrow ``date32``)."""
    return pd.Series(
        pd.to_datetime(texts, format="%Y-%m-%d", errors="coerce").dt.date, index=texts.index
    ).astype(DATE_DTYPE)
