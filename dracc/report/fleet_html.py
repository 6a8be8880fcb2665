"""The ``dracc fleet`` page: the ranked list first, then the logs per vessel, the latest
night's figures per vessel, unit and channel, the findings and integrity counts per vessel
and night, DR containment and trend plots.

Renders a :class:`~dracc.pipeline.fleet.FleetResult`; nothing is estimated here.  The page is one
self-contained file (:mod:`dracc.report.page`); matplotlib loads only when a plot is drawn.
The cell formatters and :func:`latest` are shared by the page and the terminal table
(:func:`dracc.report.terminal.print_fleet`).  The trend plot's date axis is fitted to the
days plotted (:func:`dracc.report.audit_html.date_axis`); the table's headers name their
columns of :data:`dracc.core.vocabulary.TABLE_COLUMNS`.
"""

from __future__ import annotations

import html
import json
import math

import pandas as pd

from dracc.core.vocabulary import CHANNELS
from dracc.pipeline.fleet import FleetResult
from dracc.pipeline.fleet.findings import CONSEQUENCES_SEP, INTEGRITY_COLUMNS
from dracc.report.audit_html import column_header, m_y_history_plot
from dracc.report.page import PAGE_END, img_tag, page_head

_DPI = 85


def fmt_num(x, digits: int = 1) -> str:
    """``x`` to ``digits`` decimals with a thousands separator; '-' if missing or not finite."""
    if x is None or pd.isna(x) or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return f"{x:,.{digits}f}"


def fmt_num_unit(x, digits: int, unit: str) -> str:
    """A number with its unit, or '-'."""
    text = fmt_num(x, digits)
    return text if text == "-" else text + unit


def cell_text(x) -> str:
    """Text for a table cell; '-' for missing."""
    return "-" if x is None or pd.isna(x) else str(x)


def latest(table: pd.DataFrame) -> pd.DataFrame:
    """Per vessel, INS unit and channel: the latest log's row (its night in ``day``), with
    the vessel's log count and the nights they span in this run (``logs``, ``first_day``,
    ``last_day``: the vessel's, not the row's)."""
    ok = table[table["status"] == "ok"]
    if ok.empty:
        return ok
    # logs without INS statistics keep one row (unit and channel empty) for DR and calibration
    last = ok.groupby(["vessel", "ins_unit", "channel"], sort=True, dropna=False).tail(1).copy()
    span = ok.groupby("vessel").agg(
        first_day=("day", "min"), last_day=("day", "max"), logs=("log", "nunique")
    )
    return last.join(span, on="vessel").sort_values(
        ["vessel", "ins_unit", "channel"], na_position="last"
    )


def trend_plot(trends: pd.DataFrame, vessel: str) -> bytes | None:
    """Per channel: the day's pooled m_y per INS unit and the a priori (dashed); PNG bytes."""
    t = trends[trends["vessel"] == vessel]
    if t.empty:
        return None
    lines = {
        c: [
            (unit, pd.to_datetime(g["day"].astype(str)), g["m_y"], g["apriori_after"])
            for unit, g in t[t["channel"] == c].groupby("ins_unit")
        ]
        for c in CHANNELS
        if (t["channel"] == c).any()
    }
    return m_y_history_plot(
        lines, f"{vessel}: daily RMS error from deviations (pooled m_y) and a priori", 2.2, dpi=_DPI
    )


def containment_plot(table: pd.DataFrame) -> bytes | None:
    """DR containment in 2M per vessel and log (the 2 drms promise ~95 %); PNG bytes."""
    import matplotlib  # loaded only when a page is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from dracc.report.plots import png_bytes

    d = table[table["dr_containment_2m"].notna()].drop_duplicates(["vessel", "log"])
    if d.empty:
        return None
    fig, ax = plt.subplots(figsize=(8, 0.4 * d["vessel"].nunique() + 1.5))
    vessels = sorted(d["vessel"].unique())
    for i, v in enumerate(vessels):
        c = d.loc[d["vessel"] == v, "dr_containment_2m"] * 100
        ax.plot(c, [i] * len(c), "o", alpha=0.7)
    ax.axvline(95.4, ls="--", color="grey", lw=1)
    ax.set_yticks(range(len(vessels)), vessels)
    ax.set_xlabel("reference inside 2M (% of DR epochs), per log")
    ax.set_title("Dead-reckoning consistency")
    ax.grid(alpha=0.3)
    return png_bytes(fig, dpi=_DPI)


#: rows of the ranked list shown beyond the discoveries (the next strongest)
_NEXT_ROWS = 10

_QUANTITY_TEXT = {
    "lat_m_y": "latitude RMS error",
    "lon_m_y": "longitude RMS error",
    "course_m_y": "course RMS error",
    "log_scale": "log scale error",
    "compass_error": "compass error",
    "dr_consistency": "DR inside 2M",
    "latency": "latency p95",
    "availability": "availability",
}


def _p(x) -> str:
    if x is None or pd.isna(x):
        return "-"
    return f"{x:.2g}" if x >= 1e-4 else f"{x:.1e}"


def _value(x, unit: str) -> str:
    digits = 3 if unit == "deg" else (2 if unit in ("%", "s") else 0)
    return fmt_num_unit(x, digits, f" {unit}" if unit != "%" else " %")


def ranking_section(ranking: pd.DataFrame) -> list[str]:
    """The ranked list (discoveries, then the next strongest rows), each row linked to
    its evidence: the nights and values, the peers, the change point."""
    if ranking is None or ranking.empty:
        return ["<h2>Ranking</h2><p>Nothing to rank: no nightly measures.</p>"]
    e = html.escape
    found = ranking[ranking["discovery"].fillna(False).astype(bool)]
    shown = ranking.head(len(found) + _NEXT_ROWS)
    parts = [
        "<h2>Ranking: which unit on which ship is worse than its peers or got worse</h2>",
        f"<p>{len(found)} of {len(ranking)} units and quantities stand out at a false "
        "discovery rate of 5 % (q &lt; 0.05, Benjamini-Hochberg over the fleet); the "
        f"next {min(_NEXT_ROWS, len(ranking) - len(found))} rows follow for context. "
        "p combines the comparison with peers and the unit's own change point "
        "(Bonferroni over the two).  The value is the unit's figure pooled over its last "
        "nights (up to the ranking's peer_nights; how many: its evidence); each night's "
        "own figure is under its evidence (for an INS unit, the same number as the RMS "
        "error of that night in the tables below).</p><table><tr>"
        + "".join(
            f"<th>{h}</th>"
            for h in (
                "rank",
                "vessel",
                "unit",
                "quantity",
                "value, last nights pooled",
                "peers' median",
                "score",
                "p",
                "q",
                "since",
                "evidence",
            )
        )
        + "</tr>",
    ]
    for _, r in shown.iterrows():
        unit = cell_text(r["measure_unit"])
        cls = " class='bad'" if bool(r["discovery"]) else ""
        parts.append(
            f"<tr{cls}><td>{r['rank']}</td><td>{e(cell_text(r['vessel']))}</td>"
            f"<td>{e(cell_text(r['ins_unit']))}</td>"
            f"<td>{e(_QUANTITY_TEXT.get(str(r['quantity']), str(r['quantity'])))}</td>"
            f"<td>{e(_value(r['value'], unit))}</td><td>{e(_value(r['peer_median'], unit))}</td>"
            f"<td>{fmt_num(r['score'], 1)}</td><td>{_p(r['p_value'])}</td>"
            f"<td>{_p(r['q_value'])}</td><td>{e(cell_text(r['since']))}</td>"
            f"<td><a href='#ev-{r['rank']}'>nights</a></td></tr>"
        )
    parts.append("</table><h3>Evidence</h3>")
    for _, r in shown.iterrows():
        ev = json.loads(str(r["evidence"]))
        unit = cell_text(r["measure_unit"])
        peer, change = ev.get("peer") or {}, ev.get("change") or {}
        nights = "".join(
            f"<tr><td>{e(str(n['night']))}</td><td>{e(_value(n['value'], unit))}</td></tr>"
            for n in ev.get("nights", [])
        )
        parts.append(
            f"<details id='ev-{r['rank']}'{' open' if bool(r['discovery']) else ''}><summary>"
            f"#{r['rank']} {e(cell_text(r['vessel']))} {e(cell_text(r['ins_unit']))} "
            f"{e(_QUANTITY_TEXT.get(str(r['quantity']), str(r['quantity'])))} "
            f"({e(str(ev.get('method')))})</summary>"
            f"<p>Peers ({e(str(ev.get('peer_group')))}, {peer.get('peers')} units): the last "
            f"{peer.get('window_nights')} nights give {e(_value(peer.get('value'), unit))} "
            f"against the peers' median {e(_value(peer.get('median'), unit))} (mean "
            f"{e(_value(peer.get('mean'), unit))}, the score's centre); z "
            f"{fmt_num(peer.get('z'), 2)}, p {_p(peer.get('p'))}. Own history: the most "
            f"likely change at {e(str(change.get('night') or '-'))}, "
            f"{e(_value(change.get('before'), unit))} before and "
            f"{e(_value(change.get('after'), unit))} after; z {fmt_num(change.get('z'), 2)}, "
            f"p {_p(change.get('p'))} over {change.get('splits')} splits.</p>"
            f"<table><tr><th>night</th><th>the night's value</th></tr>{nights}</table>"
            "</details>"
        )
    return parts


def _rms(r: pd.Series, digits: int) -> str:
    """'305.7 m (reference)': the night's RMS error and how it was found; '-' without one."""
    text = fmt_num_unit(r["rms_error"], digits, " " + cell_text(r["measure_unit"]))
    method = r["rms_error_method"]
    return text if text == "-" or pd.isna(method) else f"{text} ({method})"


def latest_section(table: pd.DataFrame) -> list[str]:
    """The latest night of each vessel, INS unit and channel: every figure is that
    night's; the nights each vessel's logs span are a table of their own above it."""
    lt = latest(table)
    if lt.empty:
        return []
    e, _f, _fu, _s = html.escape, fmt_num, fmt_num_unit, cell_text
    span = lt.drop_duplicates("vessel")
    parts = [
        "<h2>Logs per vessel in this run</h2><table><tr>"
        + column_header("vessel", "vessel")
        + column_header("logs", "logs")
        + column_header("first night", "first_night")
        + column_header("last night", "last_night")
        + "</tr>",
        *(
            f"<tr><td>{e(_s(r['vessel']))}</td><td>{r['logs']}</td>"
            f"<td>{e(_s(r['first_day']))}</td><td>{e(_s(r['last_day']))}</td></tr>"
            for _, r in span.iterrows()
        ),
        "</table>",
        "<h2>Latest night per vessel, INS unit and channel</h2>"
        "<p>Each row is the vessel's latest log: every figure is of that log's night. RMS "
        "error is the unit's own figure the ranking reads (against the reference, else "
        "the three-cornered hat, else m_y); m_y is the mean of three's (K5b: one bad unit "
        "raises the other two's), which the a priori rule applies to.</p><table><tr>"
        + "".join(
            column_header(label, column)
            for label, column in (
                ("vessel", "vessel"),
                ("INS unit", "ins_unit"),
                ("channel", "channel"),
                ("night", "day"),
                ("RMS error", "rms_error"),
                ("m_y", "m_y"),
                ("excess kurtosis", "kurtosis_excess"),
                ("limiting error", "limit"),
                ("a priori after (rule on m_y)", "apriori_after"),
                ("verdict", "apriori_verdict"),
                ("DR in 2M", "dr_containment_2m"),
                ("compass error", "compass_error_deg"),
                ("log scale", "log_scale_pct"),
            )
        )
        + "</tr>",
    ]
    for _, r in lt.iterrows():
        d = 3 if _s(r["measure_unit"]) == "deg" else 1
        c = r["dr_containment_2m"]
        parts.append(
            f"<tr><td>{e(_s(r['vessel']))}</td><td>{e(_s(r['ins_unit']))}</td>"
            f"<td>{e(_s(r['channel']))}</td><td>{e(_s(r['day']))}</td>"
            f"<td>{e(_rms(r, d))}</td>"
            f"<td>{e(_fu(r['m_y'], d, ' ' + _s(r['measure_unit'])))}</td>"
            f"<td>{_f(r['kurtosis_excess'], 2)}</td>"
            f"<td>{_f(r['limit'], d)}</td><td>{_f(r['apriori_after'], d)}</td>"
            f"<td>{e(_s(r['apriori_verdict']))}</td>"
            f"<td>{'-' if pd.isna(c) else f'{100 * c:.1f} %'}</td>"
            f"<td>{_fu(r['compass_error_deg'], 2, '°')}</td>"
            f"<td>{_fu(r['log_scale_pct'], 2, ' %')}</td></tr>"
        )
    parts.append("</table>")
    return parts


def _utc(t) -> str:
    return "-" if t is None or pd.isna(t) else f"{t:%Y-%m-%d %H:%M:%S}"


def findings_section(res: FleetResult) -> list[str]:
    """Per vessel and night: the integrity checks made, passed, failed and not checked;
    the findings, each with the failed checks it caused; the checks that could not be made."""
    ig, fd = res.integrity, res.findings
    if ig.empty and fd.empty:
        return []
    e, _s = html.escape, cell_text
    failed = fd[fd["status"] == "fail"] if not fd.empty else fd
    per_log = failed.groupby(["vessel", "log"]).size() if not failed.empty else pd.Series()
    parts = [
        "<h2>Findings and integrity per vessel and night</h2>"
        "<p>The checks the nightly audit makes, per log (a night of an audit document): "
        "the integrity checks of the analysis (made = passed + failed; '-' where the "
        "input does not say), and the night's findings below: one per cause, with the "
        "failed checks it caused as its consequences (so a night may have fewer findings "
        "than failed checks).</p><table><tr>"
        + "".join(
            column_header(label, column)
            for label, column in (
                ("vessel", "vessel"),
                ("night", "night"),
                ("log", "log"),
                ("checks made", "checks_made"),
                ("passed", "checks_passed"),
                ("failed", "checks_failed"),
                ("not checked", "checks_not_checked"),
                ("findings", "findings"),
            )
        )
        + "</tr>"
    ]
    for _, r in ig.iterrows():
        n = int(per_log.get((r["vessel"], r["log"]), 0))
        counts = "".join(f"<td>{_s(r[c])}</td>" for c in INTEGRITY_COLUMNS[3:])
        bad = " class='bad'"
        parts.append(
            f"<tr{bad if n else ''}><td class='t'>{e(_s(r['vessel']))}</td>"
            f"<td class='t'>{e(_s(r['night']))}</td><td class='t'>{e(_s(r['log']))}</td>"
            f"{counts}<td>{n}</td></tr>"
        )
    parts.append("</table>")
    if not failed.empty:
        parts.append(_findings_table(failed, "Findings", "message"))
    skipped = fd[fd["status"] == "not_checked"] if not fd.empty else fd
    if not skipped.empty:
        parts.append(
            f"<details><summary>{len(skipped)} checks could not be made</summary>"
            + _findings_table(skipped, "", "why")
            + "</details>"
        )
    return parts


def _findings_table(rows: pd.DataFrame, title: str, says: str) -> str:
    """Rows of the findings table: who, which check, the message (or why not), when."""
    e, _s = html.escape, cell_text
    head = (
        (f"<h3>{e(title)}</h3>" if title else "")
        + "<table><tr>"
        + "".join(
            column_header(label, column)
            for label, column in (
                ("vessel", "vessel"),
                ("night", "night"),
                ("source", "source"),
                ("check", "check"),
                ("name", "name"),
                (says, "message"),
                ("from (UTC)", "window_start_utc"),
                ("to (UTC)", "window_end_utc"),
                ("consequences", "consequences"),
            )
        )
        + "</tr>"
    )
    body = "".join(
        "<tr>"
        + "".join(
            f"<td class='t'>{e(_s(r[c]))}</td>"
            for c in ("vessel", "night", "source", "check", "name", "message")
        )
        + f"<td>{_utc(r['window_start_utc'])}</td><td>{_utc(r['window_end_utc'])}</td>"
        + "<td class='t'>"
        + "<br>".join(e(c) for c in _s(r["consequences"]).split(CONSEQUENCES_SEP))
        + "</td></tr>"
        for _, r in rows.iterrows()
    )
    return head + body + "</table>"


def fleet_html(res: FleetResult) -> str:
    """One self-contained page (offline): fleet table of latest figures, plots, failures."""
    e = html.escape
    _f, _fu, _s = fmt_num, fmt_num_unit, cell_text
    parts = [
        page_head(
            "dracc fleet report",
            "td:nth-child(-n+3),th:nth-child(-n+3){text-align:left}.bad{color:#b00}"
            "td{white-space:nowrap}td.t{text-align:left;white-space:normal}",
        ),
        f"<p>{res.logs} logs of {res.table['vessel'].nunique()} vessels; "
        f"{res.analysed} analysed in this run, {res.cached} from the cache, "
        + (f"{res.documents} from audit documents, " if res.documents else "")
        + f"{len(res.failures)} failed"
        + (f"; {len(res.skipped)} files skipped (not a log)" if res.skipped else "")
        + ".</p>",
        *ranking_section(res.ranking),
    ]
    parts += latest_section(res.table)
    parts += findings_section(res)
    png = containment_plot(res.table)
    if png:
        parts.append("<h2>Dead reckoning</h2>" + img_tag(png, "DR containment per vessel"))
    for v in sorted(res.trends["vessel"].dropna().unique()):
        png = trend_plot(res.trends, v)
        if png:
            parts.append(f"<h2>{e(str(v))}</h2>" + img_tag(png, f"trend of {e(str(v))}"))
    if res.failures:
        parts.append("<h2 class='bad'>Failures</h2><ul>")
        parts += [
            f"<li>{e(f['vessel'])} / {e(f['log'])}: {e(f['error'])}</li>" for f in res.failures
        ]
        parts.append("</ul>")
    if res.skipped:
        parts.append("<h2>Skipped: not a log</h2><ul>")
        parts += [f"<li>{e(f['vessel'])} / {e(f['log'])}: {e(f['why'])}</li>" for f in res.skipped]
        parts.append("</ul>")
    parts.append(PAGE_END)
    return "\n".join(parts)
