"""The plain-text audit reports: the night's summary (e-mail or log) and the history tables.

:func:`format_summary` renders an :class:`~dracc.pipeline.audit.AuditOutcome`: the verdict
and the findings first, then what was not checked and the evidence.
:func:`print_history` shows a history document (``dracc.audit.history/1``) as one table per
vessel, unit and channel.  The tables are :mod:`dracc.report.textout`'s: every column at its
natural width in a file or a pipe, the least needed left out on a narrow terminal.
Nothing is computed here.
"""

from __future__ import annotations

from rich.console import Console

from dracc.core.errors import ExitCode
from dracc.core.vocabulary import CHANNEL_KEYS
from dracc.pipeline.audit import AuditOutcome
from dracc.report.audit_html import accuracy_window_text, verdict_head
from dracc.report.audit_html import fmt_value as _f
from dracc.report.audit_html import measure_digits as _digits
from dracc.report.textout import Layout, Page, layout, table, wrap

_STATUS = {
    "recorded": "recorded (a new night)",
    "unchanged": "unchanged: this night was already audited with the same logs and settings; "
    "nothing written",
    "replaced": "replaced: the logs (or settings) changed since this night was last audited; "
    "the stored night was replaced in one transaction",
}


def _own_label(msg: str, names: set[str]) -> int:
    """The length of ``msg``'s leading label ('INS2: ', 'ins2 (INS2): ', 'log (LOG):
    ') when it names only ``names`` (the line's source, role and subject); else 0."""
    head, sep, _ = msg.partition(": ")
    words = head.replace("(", " ").replace(")", " ").replace(",", " ").split()
    named = head in names or (bool(words) and set(words) <= names)
    return len(head) + len(sep) if sep and named else 0


#: a finding's consequence, under it
_UNDER = "      - consequence: "


def _finding_line(f) -> str:
    who = f.source or f.subject
    role = f" ({f.role})" if f.role and f.role != who else ""
    # messages name their source (some as 'role (source)'): said once, before them
    names = {n for n in (who, f.subject, f.role, *(f.source or "").split(",")) if n}
    msg = f.message[_own_label(f.message, names) :]
    if not who and not role:  # a finding of the whole log (a logger's clock stepping back)
        return f"  - [{f.check}] {msg}"
    return f"  - [{f.check}] {who}{role}: {msg}"


def format_summary(
    o: AuditOutcome, probability: float | None = None, width: int | None = None
) -> str:
    """The plain-text summary (e-mail or log): the verdict and the findings first, then
    what was not checked and the evidence.  ``width``: wrap the long lines there, on
    spaces only (:func:`dracc.report.textout.wrap`; a finding's continuation lines under
    its text, the table never); None: one line per fact, however long (for a log that
    is read line by line)."""
    r = o.record
    n = len(o.findings)
    if o.no_data:
        lines = [
            f"dracc audit: {r.vessel}, night {r.night}: NO DATA: {r.missing[0] if r.missing else ''}",
            f"state: {_STATUS[o.status]}; recorded as a night without data",
        ]
        lines.append(f"exit {int(o.exit_code)} (no logs)")
        return _joined(lines, width)
    head = verdict_head(o.verdict, n, len(o.not_checked))
    lines = [f"dracc audit: {r.vessel}, night {r.night}: {head}"]
    if o.findings:
        lines.append("findings:")
        for f in o.findings:  # one per cause, the findings it caused under it
            lines.append(_finding_line(f))
            lines += [_finding_line(c).replace("  - ", _UNDER, 1) for c in f.consequences]
    lines.append(f"state: {_STATUS[o.status]}")
    rate = "-" if r.rejected_rate is None else f"{100 * r.rejected_rate:.2f} %"
    lines.append(
        f"logs: {len(r.inputs)} file(s), {_f(r.lines, 0)} lines, {_f(r.rejected, 0)} "
        f"damaged ({rate}); period {r.period_start_utc or '-'} to {r.period_end_utc or '-'}"
    )
    if o.ignored:
        shown = ", ".join(
            f"{k} {v}" for k, v in sorted(o.ignored.items(), key=lambda kv: -kv[1])[:8]
        )
        lines.append(f"ignored (valid, not used): {sum(o.ignored.values())} ({shown})")
    if r.sources:
        lines.append("sources: " + ", ".join(f"{k}={v}" for k, v in sorted(r.sources.items())))
    if o.false_alarm_per_night is not None:
        lines.append(
            f"false-alarm probability of tonight's statistical checks: at most "
            f"{100 * o.false_alarm_per_night:.2f} %"
        )
    if r.channels:
        p = f" at P = {probability:g}" if probability else ""
        lines.append(
            f"INS tonight (m_y = k m_u; limiting error{p}; the larger of a priori and m_y "
            "becomes the a priori):"
        )
        rows = []
        for c in r.channels:
            d = _digits(c.measure)
            rows.append(
                (
                    c.unit,
                    c.channel,
                    c.n,
                    _f(c.m_y, d, c.measure),
                    _f(c.limit_error, d, c.measure),
                    _f(c.apriori_after, d, c.measure),
                    c.verdict or "-",
                )
            )
        # a file or a mail: every column at its natural width, never squeezed
        lines.append(
            table(
                ("unit", "chan", "n", "m_y", "limit", "a priori", "verdict"),
                rows,
                right=(False, False, True, True, True, True, False),
                indent=2,
            )
        )
    acc = o.accuracy or {}
    if acc.get("channels"):
        lines.append(f"accuracy window: {accuracy_window_text(acc)}")
    established = [e for e in o.apriori_events if e.reason == "established"]
    if established:
        lines.append(
            f"a priori established for {len(established)} unit channel(s) without a "
            "previous value: tonight's m_y (shown in the table)"
        )
    for e in o.apriori_events:
        if e.reason != "raised":
            continue
        measure = CHANNEL_KEYS[e.channel].rsplit("_", 1)[1]
        d = _digits(measure)
        lines.append(
            f"a priori raised: {e.unit} {e.channel} {_f(e.previous, d, measure)} -> "
            f"{_f(e.value, d, measure)} (tonight's m_y is larger)"
        )
    if r.dr_verdict_text:  # the analysis' verdict: the same sentence as `dracc analyze`
        lines.append(f"DR: {r.dr_verdict_text}")
    elif r.dr_containment_2m is not None:
        lines.append(
            f"DR: reference inside 2M at {100 * r.dr_containment_2m:.1f} % of "
            f"{_f(r.dr_n_scored, 0)} epochs"
        )
    cal = []
    if r.compass_error_deg is not None:
        cal.append(
            f"compass error {r.compass_error_deg:+.2f} ± {_f(r.compass_error_sigma_deg, 2)} deg"
        )
    if r.log_scale is not None:
        sig = "-" if r.log_scale_sigma is None else f"{100 * r.log_scale_sigma:.2f}"
        cal.append(f"log scale {100 * r.log_scale:+.2f} ± {sig} %")
    if cal:
        lines.append("calibration: " + "; ".join(cal))
    for nc in o.not_checked:
        who = (
            f" {nc['source']}" if nc.get("source") else (f" {nc['role']}" if nc.get("role") else "")
        )
        lines.append(f"not checked: {nc['check']} {nc['name']}{who}: {nc['why']}")
    for m in r.missing:
        lines.append(f"missing: {m}")
    code = o.exit_code
    lines.append(f"exit {int(code)} ({'findings' if code == ExitCode.FINDINGS else 'ok'})")
    return _joined(lines, width)


def _joined(lines: list[str], width: int | None) -> str:
    """The summary's lines as text, each wrapped at ``width`` (a table, several lines in
    one entry, as it is)."""
    if width is not None:
        lines = [
            ln
            if "\n" in ln
            else wrap(
                ln, width, hang=8 if ln.startswith(_UNDER) else 4 if ln.startswith("  - ") else 2
            )
            for ln in lines
        ]
    return "\n".join(lines) + "\n"


#: the history table: name, right-aligned, priority (0: always shown; higher: left out
#: sooner on a narrow terminal, see :mod:`dracc.report.textout`)
_HISTORY_COLUMNS = (
    ("night", False, 0),
    ("n", True, 2),
    ("m_u", True, 1),
    ("m_y", True, 0),
    ("kurtosis", True, 2),
    ("limit", True, 1),
    ("a priori", True, 0),
    ("verdict", False, 0),
)


def history_text(doc: dict, lay: Layout = Layout()) -> str:
    """The history document as text laid out for ``lay``: one table per vessel, unit and
    channel (m_u, m_y, kurtosis, limit, a priori, verdict per night, and a 'no data' row
    for a recorded night without statistics), a blank line between them; a sentence when
    the selection holds no statistics, with the nights recorded."""
    return _history_page(doc, lay).text()


def _no_data_rows(doc: dict, vessel: str, have: set[str]) -> list[tuple[str, ...]]:
    """A row for each recorded night of ``vessel`` not in ``have`` (a series' nights):
    a night without logs (its ``no_logs`` finding), or one whose logs gave this unit and
    channel no statistics.  The a priori is unchanged on such a night (the rule's 'no
    data' step)."""
    rows: list[tuple[str, ...]] = []
    for n in doc["nights"]:
        if n["vessel"] != vessel or n["night"] in have:
            continue
        no_logs = any(f.get("kind") == "no_logs" for f in n["findings"])
        why = "no data: no logs for the night" if no_logs else "no data"
        rows.append((n["night"], "-", "-", "-", "-", "-", "-", why))
    return rows


def _history_page(doc: dict, lay: Layout) -> Page:
    page = Page(lay)
    headers, right, prio = zip(*_HISTORY_COLUMNS, strict=True)
    if not doc["series"]:
        vessels = list(dict.fromkeys(n["vessel"] for n in doc["nights"]))
        what = "INS statistics" if vessels else "nights"
        page.add(f"no {what} recorded for this selection")
        for v in vessels:  # the nights that were recorded, and why they have none
            page.blank()
            page.table(
                headers,
                _no_data_rows(doc, v, set()),
                right=right,
                priorities=prio,
                title=f"{v} (nights)",
            )
        return page
    for k, s in enumerate(doc["series"]):
        d = _digits(s["measure"])
        rows: list[tuple[str, ...]] = [
            (
                n["night"],
                str(n["n"]),
                _f(n["m_u"], d),
                _f(n["m_y"], d),
                _f(n["kurtosis"], 2),
                _f(n["limit_error"], d),
                _f(n["apriori_after"], d),
                n["verdict"] or "-",
            )
            for n in s["nights"]
        ]
        rows += _no_data_rows(doc, s["vessel"], {n["night"] for n in s["nights"]})
        rows.sort(key=lambda row: row[0])  # YYYY-MM-DD: in time order
        if k:
            page.blank()
        title = f"{s['vessel']} {s['unit']} {s['channel']} ({s['measure']})"
        page.table(headers, rows, right=right, priorities=prio, title=title)
    return page


def print_history(doc: dict, console: Console) -> None:
    """:func:`history_text` laid out for ``console`` (:func:`dracc.report.textout.layout`)
    and printed there, the titles and headers bold on a terminal."""
    _history_page(doc, layout(console)).print(console)
