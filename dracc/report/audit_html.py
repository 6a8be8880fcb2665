"""The audit pages: one audited night (:func:`audit_page`) and ``dracc audit history``.

:func:`audit_page` renders the audit document of one night (``dracc.audit/1``) with the
analysis report's sections below; :func:`history_html` renders the history document built
by :func:`dracc.report.audit_json.history_document` (schema ``dracc.audit.history/1``), per
vessel a plot of the nights and their tables.  Nothing is computed here.  The page is one
self-contained file (:mod:`dracc.report.page`); matplotlib loads only when a plot is drawn.
"""

from __future__ import annotations

import html
import math
from typing import TYPE_CHECKING

from dracc.core.numbers import none_to_nan
from dracc.report.page import PAGE_END, img_tag, page_head

if TYPE_CHECKING:
    from dracc.pipeline.audit import AuditOutcome

_DPI = 90


def fmt_value(x, digits: int = 1, unit: str = "") -> str:
    """``x`` to ``digits`` decimals with a thousands separator and ``unit``; '-' if missing."""
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return f"{x:,.{digits}f}{(' ' + unit) if unit else ''}"


def measure_digits(measure: str) -> int:
    """Decimals for a channel's measure: 3 for degrees, 1 for metres."""
    return 3 if measure == "deg" else 1


def history_plot(doc: dict, vessel: str) -> bytes | None:
    """m_y per unit and the a priori (dashed steps) per channel over nights; PNG bytes."""
    import pandas as pd

    from dracc.report.plots import m_y_apriori_plot  # matplotlib loaded only when a page is drawn

    series = [s for s in doc["series"] if s["vessel"] == vessel]
    if not series:
        return None

    lines = {
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
        for c in ("lat", "lon", "course")
        if any(s["channel"] == c for s in series)
    }
    return m_y_apriori_plot(
        lines, f"{vessel}: RMS error from deviations (m_y) and a priori, per night", 2.4, dpi=_DPI
    )


def history_html(doc: dict) -> str:
    """One self-contained page (no network): per vessel a plot and the table of nights."""
    e = html.escape
    _f = fmt_value
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
            "<table><tr><th>unit</th><th>channel</th><th>night</th><th>n</th><th>m_y</th>"
            "<th>limit</th><th>a priori</th><th>verdict</th></tr>"
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
            "</table><h3>Nights</h3><table><tr><th>night</th><th>DR in 2M</th>"
            "<th>compass error</th><th>log scale</th><th>findings</th></tr>"
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

_VERDICT_TEXT = {
    "ok": "all checks passed",
    "findings": "findings",
    "no data": "no logs for the night",
}


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


def night_html(doc: dict, analysis_body: str = "", analysis_css: str = "") -> str:
    """The audit page of one night (schema ``dracc.audit/1``): the verdict and the findings
    first, then what was not checked, the sources' integrity, the INS table, and the
    analysis report's sections (``analysis_body``) below."""
    e = html.escape
    css = (
        "td:first-child,th:first-child{text-align:left} .verdict{font-size:1.3em;padding:.4em;"
        "border:2px solid #444} .ok{background:#e6f4e6} .findings{background:#fde8e8} "
        ".nodata{background:#fff3d6} td{vertical-align:top}" + analysis_css
    )
    title = f"dracc audit {doc['vessel']} {doc['night']}"
    parts = [page_head(title, css)]
    verdict = doc["verdict"]
    n = len(doc["findings"])
    klass = {"ok": "ok", "findings": "findings"}.get(verdict, "nodata")
    head = (
        _VERDICT_TEXT.get(verdict, verdict)
        if verdict != "findings"
        else f"{n} finding{'s' if n != 1 else ''}"
    )
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
            "<table><tr><th>check</th><th>source</th><th>role</th><th>finding</th>"
            "<th>statistic</th><th>threshold</th><th>window</th><th>evidence</th>"
            "<th>clause</th></tr>"
        )
        for f in doc["findings"]:
            st, th, w = f["statistic"], f["threshold"], f["window"]
            stat = f"{e(str(st.get('name', '')))} {fmt_value(st.get('value'), 3)} {e(str(st.get('unit', '')))}"
            thr = f"{fmt_value(th.get('value'), 3)} {e(str(th.get('unit', '')))}"
            win = " to ".join(str(w[k]) for k in ("start_utc", "end_utc") if w.get(k)) or ", ".join(
                f"{k} {v}" for k, v in w.items()
            )
            parts.append(
                f"<tr><td>{e(f['check'])}</td><td>{e(f['source'] or '-')}</td>"
                f"<td>{e(f['role'] or '-')}</td><td>{e(f['message'])}</td><td>{stat}</td>"
                f"<td title='{e(str(th.get('rule', '')))}'>{thr}</td><td>{e(win)}</td>"
                f"<td>{e(_evidence_text(f['evidence']))}</td><td>{e(f['clause'])}</td></tr>"
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
        f"{e(str(logs['period']['start_utc']))} to {e(str(logs['period']['end_utc']))}.</p>"
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
        kinds = ("validity", "plausibility", "latency", "availability", "consistency")
        parts.append(
            "<section id='sources'><h2>Integrity per source</h2><table><tr><th>source</th>"
            "<th>role</th>"
            + "".join(f"<th>{k}</th>" for k in kinds)
            + "<th>cadence</th><th>available</th><th>latency p50 / p95</th></tr>"
        )
        for src, row in sorted(by_src.items()):
            info = integ.get("sources", {}).get(src, {})
            lat = info.get("latency_s") or {}
            av = info.get("availability")
            parts.append(
                f"<tr><td>{e(src)}</td><td>{e(row['role'] or '-')}</td>"
                + "".join(f"<td>{e(row.get(k, '-'))}</td>" for k in kinds)
                + f"<td>{fmt_value(info.get('cadence_s'), 2, 's')}</td>"
                f"<td>{'-' if av is None else f'{100 * av:.1f} %'}</td>"
                f"<td>{fmt_value(lat.get('p50'), 2)} / {fmt_value(lat.get('p95'), 2, 's')}</td></tr>"
            )
        parts.append("</table></section>")
    if doc["ins"]:
        acc = doc.get("accuracy") or {}
        parts.append(
            "<section id='ins'><h2>INS accuracy and a priori</h2><table><tr><th>unit</th>"
            "<th>channel</th><th>n</th><th>m_y tonight</th><th>a priori</th><th>verdict</th></tr>"
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
            parts.append(
                f"<p>Limiting errors judged over {fmt_value(acc.get('window_h'), 0)} h: "
                f"{fmt_value(acc.get('hours'), 1)} h over {len(acc.get('nights', []))} "
                f"night(s) so far.</p>"
            )
        parts.append("</section>")
    if analysis_body:
        parts.append(f"<section id='analysis'><h2>The analysis</h2>{analysis_body}</section>")
    parts.append(PAGE_END)
    return "\n".join(parts)


def audit_page(o: AuditOutcome, doc: dict | None = None) -> str:
    """The audit page of one night: :func:`night_html` of its audit document (``doc``, or
    :func:`dracc.report.audit_json.to_dict` of ``o``) above the analysis report's sections."""
    from dracc.report import audit_json
    from dracc.report import html as html_report

    body, css = ("", "") if o.analysis is None else html_report.render_sections(o.analysis)
    return night_html(audit_json.to_dict(o) if doc is None else doc, body, css)
