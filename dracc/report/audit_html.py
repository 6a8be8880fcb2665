"""The ``dracc audit history`` page: per vessel a plot of the nights and their tables.

Renders the history document built by :func:`dracc.cli.audit_cmd.history_document`
(schema ``dracc.audit.history/1``); nothing is computed here.  The page is one
self-contained file (:mod:`dracc.report.page`); matplotlib loads only when a plot is drawn.
"""

from __future__ import annotations

import html
import math

from .page import PAGE_END, img_tag, page_head

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

    from .plots import m_y_apriori_plot  # matplotlib loaded only when a page is drawn

    series = [s for s in doc["series"] if s["vessel"] == vessel]
    if not series:
        return None

    def nan_for_none(values):
        return [math.nan if v is None else v for v in values]

    lines = {c: [(s["unit"], pd.to_datetime([n["night"] for n in s["nights"]]),
                  nan_for_none(n["m_y"] for n in s["nights"]),
                  nan_for_none(n["apriori_after"] for n in s["nights"]))
                 for s in series if s["channel"] == c]
             for c in ("lat", "lon", "course") if any(s["channel"] == c for s in series)}
    return m_y_apriori_plot(lines, f"{vessel}: RMS error from deviations (m_y) and a priori, per night",
                            2.4, dpi=_DPI)


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
        parts.append("<table><tr><th>unit</th><th>channel</th><th>night</th><th>n</th><th>m_y</th>"
                     "<th>limit</th><th>a priori</th><th>verdict</th></tr>")
        for s in (s for s in doc["series"] if s["vessel"] == v):
            d = measure_digits(s["measure"])
            for n in s["nights"]:
                parts.append(f"<tr><td>{e(s['unit'])}</td><td>{e(s['channel'])}</td>"
                             f"<td>{e(n['night'])}</td><td>{n['n']}</td>"
                             f"<td>{_f(n['m_y'], d, s['measure'])}</td>"
                             f"<td>{_f(n['limit_error'], d, s['measure'])}</td>"
                             f"<td>{_f(n['apriori_after'], d, s['measure'])}</td>"
                             f"<td>{e(n['verdict'] or '-')}</td></tr>")
        parts.append("</table><h3>Nights</h3><table><tr><th>night</th><th>DR in 2M</th>"
                     "<th>compass error</th><th>log scale</th><th>findings</th></tr>")
        for n in (n for n in doc["nights"] if n["vessel"] == v):
            c = n["dr_containment_2m"]
            ls = n["log_scale"]
            parts.append(f"<tr><td>{e(n['night'])}</td><td>{'-' if c is None else f'{100 * c:.1f} %'}"
                         f"</td><td>{_f(n['compass_error_deg'], 2, 'deg')}</td>"
                         f"<td>{'-' if ls is None else f'{100 * ls:+.2f} %'}</td>"
                         f"<td>{e('; '.join(f['message'] for f in n['findings'])) or 'none'}</td></tr>")
        parts.append("</table>")
    parts.append(PAGE_END)
    return "\n".join(parts)
