"""The audit pages: one audited night (:func:`audit_page`) and ``dracc audit history``.

:func:`audit_page` renders the audit document of one night (``dracc.audit/1``) with the
analysis report's sections below; :func:`history_html` renders the history document built
by :func:`dracc.report.audit_json.history_document` (schema ``dracc.audit.history/1``), per
vessel a plot of the nights and their tables.  Nothing is computed here.  The page is one
self-contained file (:mod:`dracc.report.page`); matplotlib loads only when a plot is drawn.
The history plot (:func:`m_y_history_plot`, shared with the fleet page) fits its date
axis to the nights plotted (:func:`date_axis`); the tables' headers name their columns
of :data:`dracc.core.vocabulary.TABLE_COLUMNS` (:func:`column_header`).
"""

from __future__ import annotations

import html
import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from dracc.core.numbers import counted, none_to_nan
from dracc.core.vocabulary import CHANNEL_UNITS, CHANNELS, TABLE_COLUMNS
from dracc.report.page import PAGE_END, consequences_html, img_tag, page_head

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from dracc.pipeline.audit import AuditOutcome
    from dracc.report.verdict import Finding as VerdictPart

_DPI = 90


def fmt_value(x, digits: int = 1, unit: str = "") -> str:
    """``x`` to ``digits`` decimals with a thousands separator and ``unit``; '-' if missing."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return f"{x:,.{digits}f}{(' ' + unit) if unit else ''}"


def measure_digits(measure: str) -> int:
    """Decimals for a channel's measure: 3 for degrees, 1 for metres."""
    return 3 if measure == "deg" else 1


def column_header(label: str, column: str) -> str:
    """A ``<th>`` showing ``label`` for the table column ``column`` of
    :data:`dracc.core.vocabulary.TABLE_COLUMNS`: its name in ``data-column`` (the same
    name as in the CSV and Parquet tables), its meaning as the tooltip."""
    meaning = TABLE_COLUMNS[column][1]
    return (
        f"<th data-column='{html.escape(column)}' title='{html.escape(meaning)}'>"
        f"{html.escape(label)}</th>"
    )


def date_axis(ax: Axes, times) -> None:
    """A date x axis fitted to ``times`` (the nights or days plotted): limits from the
    first to the last with a pad of 5 % of the span and at least half a day each side (one
    night is a day wide, not matplotlib's default four years), a tick on whole days at
    most about eight of them for spans up to 60 days (labelled ``YYYY-MM-DD``), the
    automatic locator with concise labels beyond."""
    import matplotlib.dates as mdates
    import pandas as pd

    t = pd.DatetimeIndex(pd.to_datetime(list(times))).dropna()
    if t.empty:
        return
    if t.tz is not None:
        t = t.tz_convert("UTC").tz_localize(None)
    lo, hi = t.min(), t.max()
    span = hi - lo
    pad = max(span * 0.05, pd.Timedelta(hours=12))
    ax.set_xlim(lo - pad, hi + pad)
    days = span / pd.Timedelta(days=1)
    if days <= 60:
        ax.xaxis.set_major_locator(mdates.DayLocator(interval=max(1, math.ceil((days + 1) / 8))))
        ax.xaxis.set_major_formatter(mdates.DateFormatter("%Y-%m-%d"))
    else:
        locator = mdates.AutoDateLocator()
        ax.xaxis.set_major_locator(locator)
        ax.xaxis.set_major_formatter(mdates.ConciseDateFormatter(locator))


def m_y_history_figure(
    lines: Mapping[str, Sequence[tuple[str, Any, Any, Any]]],
    title: str,
    row_height_in: float,
) -> Figure:
    """One panel per channel: each INS unit's m_y (points and line) and its a priori
    (dashed steps, same colour) over nights or days, on a shared :func:`date_axis`.
    ``lines``: channel -> [(ins_unit, dates, m_y, a priori)], NaN where missing."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(
        len(lines), 1, figsize=(8, row_height_in * len(lines)), sharex=True, squeeze=False
    )
    every = []
    for ax, (ch, rows) in zip(axes[:, 0], lines.items(), strict=True):
        for unit, t, m_y, apriori in rows:
            (line,) = ax.plot(t, m_y, "o-", label=f"{unit} m_y")
            ax.step(
                t,
                apriori,
                "--",
                where="post",
                color=line.get_color(),
                alpha=0.7,
                label=f"{unit} a priori",
            )
            every.extend(list(t))
        ax.set_ylabel(f"{ch} ({CHANNEL_UNITS.get(ch, '')})")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, ncol=3)
    date_axis(axes[-1, 0], every)
    axes[-1, 0].set_xlabel("UTC date")
    axes[0, 0].set_title(title)
    fig.autofmt_xdate()
    return fig


def m_y_history_plot(
    lines: Mapping[str, Sequence[tuple[str, Any, Any, Any]]],
    title: str,
    row_height_in: float,
    dpi: int = _DPI,
) -> bytes:
    """:func:`m_y_history_figure` as PNG bytes."""
    from dracc.report.plots import png_bytes  # matplotlib loaded only when a page is drawn

    return png_bytes(m_y_history_figure(lines, title, row_height_in), dpi=dpi)


def history_lines(doc: dict, vessel: str) -> dict[str, list[tuple[str, Any, Any, Any]]]:
    """The history document's series of ``vessel`` as plot lines: channel ->
    [(ins_unit, nights as dates, m_y, a priori after)]."""
    import pandas as pd

    series = [s for s in doc["series"] if s["vessel"] == vessel]
    return {
        c: [
            (
                s["unit"],
                pd.to_datetime([n["night"] for n in s["nights"]]),
                none_to_nan(n["m_y"] for n in s["nights"]),
                none_to_nan(n["apriori_after"] for n in s["nights"]),
            )
            for s in series
            if s["channel"] == c
        ]
        for c in CHANNELS
        if any(s["channel"] == c for s in series)
    }


def history_plot(doc: dict, vessel: str) -> bytes | None:
    """m_y per INS unit and the a priori (dashed steps) per channel over nights; PNG bytes."""
    lines = history_lines(doc, vessel)
    if not lines:
        return None
    return m_y_history_plot(
        lines, f"{vessel}: RMS error from deviations (m_y) and a priori, per night", 2.4, dpi=_DPI
    )


def history_html(doc: dict) -> str:
    """One self-contained page (no network): per vessel a plot and the table of nights.
    Column headers name their column of the tables' vocabulary (:func:`column_header`)."""
    e = html.escape
    _f = fmt_value
    h = column_header
    parts = [page_head("dracc audit history", "td:first-child,th:first-child{text-align:left}")]
    vessels = sorted({s["vessel"] for s in doc["series"]} | {n["vessel"] for n in doc["nights"]})
    if not vessels:
        parts.append("<p>No nights recorded yet.</p>")
    for v in vessels:
        parts.append(f"<h2>{e(v)}</h2>")
        png = history_plot(doc, v)
        if png:
            parts.append(img_tag(png, f"m_y and a priori per night for {e(v)}"))
        parts.append(
            "<table class='history'><tr>"
            + h("INS unit", "ins_unit")
            + h("channel", "channel")
            + h("night", "night")
            + h("n", "n")
            + h("m_y", "m_y")
            + h("limit", "limit")
            + h("a priori", "apriori_after")
            + h("verdict", "apriori_verdict")
            + "</tr>"
        )
        for s in (s for s in doc["series"] if s["vessel"] == v):
            d = measure_digits(s["measure"])
            for n in s["nights"]:
                parts.append(
                    f"<tr><td>{e(s['unit'])}</td><td>{e(s['channel'])}</td>"
                    f"<td>{e(n['night'])}</td><td>{n['n']}</td>"
                    f"<td>{_f(n['m_y'], d, s['measure'])}</td>"
                    f"<td>{_f(n['limit_error'], d, s['measure'])}</td>"
                    f"<td>{_f(n['apriori_after'], d, s['measure'])}</td>"
                    f"<td>{e(n['verdict'] or '-')}</td></tr>"
                )
        parts.append(
            "</table><h3>Nights</h3><table class='nights'><tr>"
            + h("night", "night")
            + h("DR in 2M", "dr_containment_2m")
            + h("compass error", "compass_error_deg")
            + h("log scale", "log_scale_pct")
            + h("findings", "findings")
            + "</tr>"
        )
        for n in (n for n in doc["nights"] if n["vessel"] == v):
            c = n["dr_containment_2m"]
            ls = n["log_scale"]
            parts.append(
                f"<tr><td>{e(n['night'])}</td><td>{'-' if c is None else f'{100 * c:.1f} %'}"
                f"</td><td>{_f(n['compass_error_deg'], 2, 'deg')}</td>"
                f"<td>{'-' if ls is None else f'{100 * ls:+.2f} %'}</td>"
                f"<td>{e('; '.join(f['message'] for f in n['findings'])) or 'none'}</td></tr>"
            )
        parts.append("</table>")
    parts.append(PAGE_END)
    return "\n".join(parts)


# ------------------------------------------------------------------ one audited night

#: the audit page's tables at any window width: text columns (``t``) wrap, long tokens
#: too; number columns (``n``) stay on one line; the embedded analysis' cells wrap at
#: spaces (its own stylesheet keeps every cell on one line, for the wide report)
WRAP_CSS = (
    " th.t,td.t{text-align:left;white-space:normal;overflow-wrap:anywhere}"
    " th.n,td.n{white-space:nowrap} td.message{min-width:14em}"
    " #analysis td,#analysis th{white-space:normal} #analysis td.l{overflow-wrap:anywhere}"
    " img{max-width:100%;height:auto} body{overflow-wrap:break-word}"
)

#: what each verdict on the audit page judges (shown under the INS table)
RULES_TEXT = (
    "How INS accuracy is judged on this page: the audit judges each unit channel's "
    "limiting error (K8), pooled over [audit] accuracy_window_h, against [audit.limits] "
    "(above it: a finding); the a priori RMS follows the monitoring rule a = max(a priori, "
    "m_y), seeded by [deviation.apriori] and carried over the stored nights: 'raised' when "
    "tonight's m_y is above it (recorded; a finding only with [audit] "
    "apriori_raise_is_finding), 'within' otherwise, 'established' where none was "
    "configured. The analysis below shows these a priori values and this judgement."
)


def verdict_head(verdict: str, findings: int, not_checked: int) -> str:
    """The night's verdict in a few words, one wording for the summary and the page (the
    shape of the analysis' integrity count): 'all checks passed' only when every check
    was made, 'all checks made passed; 1 not checked (listed below)', '8 findings; 3 not
    checked (listed below)', 'no logs for the night'."""
    if verdict == "no data":
        return "no logs for the night"
    if not findings:
        head = "all checks made passed" if not_checked else "all checks passed"
    else:
        head = counted(findings, "finding")
    return head + (f"; {not_checked} not checked (listed below)" if not_checked else "")


def _evidence_text(ev: list) -> str:
    """The first few evidence items as 'key value' pairs."""
    parts = []
    for item in ev[:3]:
        if isinstance(item, dict):
            parts.append(
                ", ".join(
                    f"{k} {fmt_value(v, 2) if isinstance(v, float) else v}"
                    for k, v in item.items()
                    if v is not None and not isinstance(v, dict)
                )
            )
    more = f" (+{len(ev) - 3} more)" if len(ev) > 3 else ""
    return "; ".join(parts) + more


def accuracy_window_text(acc: Mapping[str, Any]) -> str:
    """The accuracy window in one line, for the summary and the page: '72.0 h of 72 h over
    4 nights (2026-11-17 in part: 0.1 h of its 24.0 h)', '8.0 h of 72 h over 1 night so
    far (limits judged once the window is full)'."""
    text = (
        f"{fmt_value(acc.get('hours'), 1)} h of {acc.get('window_h', 0):g} h over "
        f"{counted(len(acc.get('nights') or ()), 'night')}"
    )
    part = acc.get("partial")
    if part:
        text += f" ({part['night']} in part: {part['hours']:.1f} h of its {part['of_hours']:.1f} h)"
    if not acc.get("complete"):
        text += " so far (limits judged once the window is full)"
    return text


def window_text(w: Mapping[str, Any] | None) -> str:
    """A finding's window or the logs' period: 'start to end' in UTC, 'from start' or
    'until end' where one is known, the accuracy window's nights and hours, or 'no data'
    (never 'None')."""
    w = w or {}
    start, end = w.get("start_utc"), w.get("end_utc")
    if start and end:
        return f"{start} to {end}"
    if start or end:
        return f"from {start}" if start else f"until {end}"
    rest = []
    if w.get("nights"):
        rest.append(", ".join(str(n) for n in w["nights"]))
    if w.get("hours") is not None:
        rest.append(f"{fmt_value(w['hours'], 1)} h")
    rest += [
        f"{k} {v}"
        for k, v in w.items()
        if k not in ("start_utc", "end_utc", "nights", "hours") and v not in (None, "", [])
    ]
    return "; ".join(rest) or "no data"


def _rule_text(ins: Sequence[Mapping[str, Any]]) -> str:
    """The monitoring rule's verdicts tonight, e.g. 'a priori rule max(a priori, m_y):
    within for 8 unit channels; raised for ins2 course (0.123 to 0.140 deg)'."""
    by: dict[str, list[str]] = {}
    for c in ins:
        v = c["verdict"] or "no data"
        d = measure_digits(c["measure"])
        what = f"{c['unit']} {c['channel']}"
        if v == "raised":
            what += (
                f" ({fmt_value(c['apriori_before'], d)} to "
                f"{fmt_value(c['apriori_after'], d, c['measure'])})"
            )
        by.setdefault(v, []).append(what)
    parts = [
        f"{v} for {len(names)} unit channels" if v == "within" else f"{v} for {', '.join(names)}"
        for v, names in by.items()
    ]
    return "a priori rule max(a priori, m_y): " + "; ".join(parts)


def ins_judgement(doc: dict) -> VerdictPart:
    """The INS accuracy part of the page's verdict, from the audit's own judgement (its
    accuracy findings, its accuracy checks not made, the a priori rule's verdicts):
    the embedded analysis shows this instead of its judgement against the configuration."""
    from dracc.report.verdict import FAIL, NOT_CHECKED, OK
    from dracc.report.verdict import Finding as Part

    topic = "INS accuracy"
    if not doc["ins"]:
        return Part(topic, NOT_CHECKED, "INS accuracy not computed: no INS statistics tonight")
    rule = _rule_text(doc["ins"])
    found = [f for f in doc["findings"] if f["check"] == "accuracy"]
    if found:
        return Part(
            topic,
            FAIL,
            f"{len(found)} audit finding{'s' if len(found) != 1 else ''} on accuracy "
            "(see Findings above)",
            tuple(f["message"] for f in found) + (rule,),
        )
    skipped = [n for n in doc["not_checked"] if n["check"] == "accuracy"]
    if skipped:
        return Part(
            topic,
            NOT_CHECKED,
            "limits not checked: " + "; ".join(f"{n['name']}: {n['why']}" for n in skipped),
            (rule,),
        )
    return Part(
        topic,
        OK,
        "every unit's limiting error within its [audit.limits] limit over the accuracy window",
        (rule,),
    )


def night_html(doc: dict, analysis_body: str = "", analysis_css: str = "") -> str:
    """The audit page of one night (schema ``dracc.audit/1``): the verdict and the findings
    first, then what was not checked, the sources' integrity, the INS table, and the
    analysis report's sections (``analysis_body``) below."""
    e = html.escape
    css = (
        "td:first-child,th:first-child{text-align:left} .verdict{font-size:1.3em;padding:.4em;"
        "border:2px solid #444} .ok{background:#e6f4e6} .findings{background:#fde8e8} "
        ".nodata{background:#fff3d6} td{vertical-align:top}" + analysis_css + WRAP_CSS
    )
    title = f"dracc audit {doc['vessel']} {doc['night']}"
    parts = [page_head(title, css)]
    verdict = doc["verdict"]
    klass = {"ok": "ok", "findings": "findings"}.get(verdict, "nodata")
    head = verdict_head(verdict, len(doc["findings"]), len(doc["not_checked"]))
    parts.append(
        f"<p id='verdict' class='verdict {klass}'>Verdict: <b>{e(head)}</b> (exit "
        f"{doc['exit_code']}); state {e(doc['state'])}</p>"
    )
    fa = doc.get("false_alarm_per_night")
    if fa is not None:
        parts.append(
            f"<p>False-alarm probability of the statistical checks made: at most "
            f"{100 * fa:.2f} % per night (the others are rules on recorded flags, gaps "
            "and limits).</p>"
        )
    parts.append("<section id='findings'><h2>Findings</h2>")
    if doc["findings"]:
        parts.append(
            "<table class='findings-table'><tr><th class='t'>check</th><th class='t'>source</th>"
            "<th class='t'>role</th><th class='t message'>finding</th><th class='t'>statistic</th>"
            "<th class='n'>threshold</th><th class='t'>window</th><th class='t'>evidence</th>"
            "<th class='t'>clause</th></tr>"
        )
        for f in doc["findings"]:
            st, th, w = f["statistic"], f["threshold"], f["window"]
            stat = f"{e(str(st.get('name', '')))} {fmt_value(st.get('value'), 3)} {e(str(st.get('unit', '')))}"
            thr = f"{fmt_value(th.get('value'), 3)} {e(str(th.get('unit', '')))}"
            parts.append(
                f"<tr><td class='t'>{e(f['check'])}</td><td class='t'>{e(f['source'] or '-')}</td>"
                f"<td class='t'>{e(f['role'] or '-')}</td><td class='t message'>{e(f['message'])}"
                + consequences_html(
                    (str(c.get("check") or ""), str(c.get("message")))
                    for c in f.get("consequences") or ()
                )
                + f"</td><td class='t'>{stat}</td>"
                f"<td class='n' title='{e(str(th.get('rule', '')))}'>{thr}</td>"
                f"<td class='t window'>{e(window_text(w))}</td>"
                f"<td class='t'>{e(_evidence_text(f['evidence']))}</td>"
                f"<td class='t'>{e(f['clause'])}</td></tr>"
            )
        parts.append("</table>")
    else:
        parts.append("<p>None.</p>")
    parts.append("</section><section id='not-checked'><h2>Not checked</h2>")
    if doc["not_checked"]:
        parts.append(
            "<ul>"
            + "".join(
                f"<li>{e(nc['check'])} {e(nc['name'])}{' ' + e(nc['source']) if nc.get('source') else ''}"
                f": {e(nc['why'])}</li>"
                for nc in doc["not_checked"]
            )
            + "</ul>"
        )
    else:
        parts.append("<p>Every check was made.</p>")
    parts.append("</section>")
    logs = doc["logs"]
    ignored = ", ".join(f"{k} {v}" for k, v in sorted(logs.get("ignored", {}).items())) or "none"
    parts.append(
        f"<section id='logs'><h2>Logs</h2><p>{len(logs['files'])} file(s), "
        f"{fmt_value(logs['lines'], 0)} lines, {fmt_value(logs['rejected'], 0)} damaged "
        f"(rejected); valid but unused (ignored): {e(ignored)}. Period "
        f"{e(window_text(logs['period']))}.</p>"
        "</section>"
    )
    integ = (doc.get("analysis") or {}).get("integrity") or {}
    if integ.get("checks"):
        by_src: dict[str, dict] = {}
        for c in integ["checks"]:
            row = by_src.setdefault(c["source"] or c["role"] or "-", {"role": c["role"]})
            row[c["check"]] = (
                row.get(c["check"], "pass")
                if c["status"] == "pass"
                else (
                    "FAIL"
                    if c["status"] == "fail" or row.get(c["check"]) == "FAIL"
                    else "not checked"
                )
            )
        kinds = ("validity", "plausibility", "latency", "availability", "consistency", "time")
        parts.append(
            "<section id='sources'><h2>Integrity per source</h2><table><tr><th class='t'>source</th>"
            "<th class='t'>role</th>"
            + "".join(f"<th>{k}</th>" for k in kinds)
            + "<th>cadence</th><th>available</th><th>latency p50 / p95</th></tr>"
        )
        for src, row in sorted(by_src.items()):
            info = integ.get("sources", {}).get(src, {})
            lat = info.get("latency_s") or {}
            av = info.get("availability")
            parts.append(
                f"<tr><td class='t'>{e(src)}</td><td class='t'>{e(row['role'] or '-')}</td>"
                + "".join(f"<td class='t'>{e(row.get(k, '-'))}</td>" for k in kinds)
                + f"<td>{fmt_value(info.get('cadence_s'), 2, 's')}</td>"
                f"<td>{'-' if av is None else f'{100 * av:.1f} %'}</td>"
                f"<td>{fmt_value(lat.get('p50'), 2)} / {fmt_value(lat.get('p95'), 2, 's')}</td></tr>"
            )
        parts.append("</table></section>")
    if doc["ins"]:
        acc = doc.get("accuracy") or {}
        parts.append(
            "<section id='ins'><h2>INS accuracy and a priori</h2><table><tr>"
            + column_header("INS unit", "ins_unit")
            + column_header("channel", "channel")
            + column_header("n", "n")
            + column_header("m_y tonight", "m_y")
            + column_header("a priori", "apriori_after")
            + column_header("verdict", "apriori_verdict")
            + "</tr>"
        )
        for c in doc["ins"]:
            d = measure_digits(c["measure"])
            parts.append(
                f"<tr><td>{e(c['unit'])}</td><td>{e(c['channel'])}</td><td>{c['n']}</td>"
                f"<td>{fmt_value(c['m_y'], d, c['measure'])}</td>"
                f"<td>{fmt_value(c['apriori_after'], d, c['measure'])}</td>"
                f"<td>{e(c['verdict'] or '-')}</td></tr>"
            )
        parts.append("</table>")
        if acc:
            parts.append(f"<p>Accuracy window: {e(accuracy_window_text(acc))}.</p>")
        parts.append(f"<p class='rules'>{e(RULES_TEXT)}</p></section>")
    if analysis_body:
        parts.append(f"<section id='analysis'><h2>The analysis</h2>{analysis_body}</section>")
    parts.append(PAGE_END)
    return "\n".join(parts)


def audit_page(o: AuditOutcome, doc: dict | None = None) -> str:
    """The audit page of one night: :func:`night_html` of its audit document (``doc``, or
    :func:`dracc.report.audit_json.to_dict` of ``o``) above the analysis report's sections."""
    from dracc.report import audit_json
    from dracc.report import html as html_report

    doc = audit_json.to_dict(o) if doc is None else doc
    body, css = (
        ("", "")
        if o.analysis is None
        else html_report.render_sections(
            audit_json.audit_analysis(o.analysis, doc["ins"]), ins_judgement(doc)
        )
    )
    return night_html(doc, body, css)
