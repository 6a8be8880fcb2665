"""The plain-text audit reports: the night's summary (e-mail or log) and the history tables.

:func:`format_summary` renders an :class:`~dracc.pipeline.audit.AuditOutcome`: the verdict
and the findings first, then what was not checked and the evidence.
:func:`print_history` shows a history document (``dracc.audit.history/1``) as one table per
vessel, unit and channel.  Nothing is computed here.
"""

from __future__ import annotations

from rich.console import Console
from rich.table import Table

from dracc.core.errors import ExitCode
from dracc.core.vocabulary import CHANNEL_KEYS
from dracc.pipeline.audit import AuditOutcome
from dracc.report.audit_html import fmt_value as _f
from dracc.report.audit_html import measure_digits as _digits

_STATUS = {
    "recorded": "recorded (a new night)",
    "unchanged": "unchanged: this night was already audited with the same logs and settings; "
    "nothing written",
    "replaced": "replaced: the logs (or settings) changed since this night was last audited; "
    "the stored night was replaced in one transaction",
}


def _finding_line(f) -> str:
    who = f.source or f.subject
    role = f" ({f.role})" if f.role and f.role != who else ""
    msg = f.message
    for name in dict.fromkeys((who, f.subject)):  # messages name their source: said once
        if name and msg.startswith(f"{name}: "):
            msg = msg[len(name) + 2 :]
            break
    return f"  - [{f.check}] {who}{role}: {msg}"


def format_summary(o: AuditOutcome, probability: float | None = None) -> str:
    """The plain-text summary (e-mail or log): the verdict and the findings first, then
    what was not checked and the evidence."""
    r = o.record
    n = len(o.findings)
    if o.no_data:
        lines = [
            f"dracc audit: {r.vessel}, night {r.night}: NO DATA: {r.missing[0] if r.missing else ''}",
            f"state: {_STATUS[o.status]}; recorded as a night without data",
        ]
        lines.append(f"exit {int(o.exit_code)} (no logs)")
        return "\n".join(lines) + "\n"
    head = "all checks passed" if n == 0 else f"{n} finding{'s' if n > 1 else ''}"
    if o.not_checked:
        k = len(o.not_checked)
        head += f" ({k} check{'s' if k > 1 else ''} could not be made: see 'not checked')"
    lines = [f"dracc audit: {r.vessel}, night {r.night}: {head}"]
    if o.findings:
        lines.append("findings:")
        lines += [_finding_line(f) for f in o.findings]
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
        lines.append(
            f"  {'unit':<5} {'chan':<6} {'n':>4} {'m_y':>12} {'limit':>12} "
            f"{'a priori':>12}  verdict"
        )
        for c in r.channels:
            d = _digits(c.measure)
            lines.append(
                f"  {c.unit:<5} {c.channel:<6} {c.n:>4} {_f(c.m_y, d, c.measure):>12} "
                f"{_f(c.limit_error, d, c.measure):>12} "
                f"{_f(c.apriori_after, d, c.measure):>12}  {c.verdict or '-'}"
            )
    acc = o.accuracy or {}
    if acc.get("channels"):
        lines.append(
            f"accuracy window: {acc['hours']:.1f} h of {acc['window_h']:g} h over "
            f"{len(acc['nights'])} night(s)"
            + ("" if acc.get("complete") else " (limits judged once the window is full)")
        )
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
    return "\n".join(lines) + "\n"


def print_history(doc: dict, console: Console) -> None:
    """One table per vessel, unit and channel: m_u, m_y, kurtosis, limit, a priori, verdict
    per night; a sentence when the selection holds no night."""
    if not doc["series"]:
        console.print("no nights recorded for this selection", markup=False, highlight=False)
        return
    for s in doc["series"]:
        d = _digits(s["measure"])
        t = Table(title=f"{s['vessel']} {s['unit']} {s['channel']} ({s['measure']})")
        for col in ("night", "n", "m_u", "m_y", "kurtosis", "limit", "a priori", "verdict"):
            t.add_column(
                col,
                justify="left" if col in ("night", "verdict") else "right",
                no_wrap=True,
                min_width=10 if col == "night" else None,
            )
        for n in s["nights"]:
            t.add_row(
                n["night"],
                str(n["n"]),
                _f(n["m_u"], d),
                _f(n["m_y"], d),
                _f(n["kurtosis"], 2),
                _f(n["limit_error"], d),
                _f(n["apriori_after"], d),
                n["verdict"] or "-",
            )
        console.print(t)
