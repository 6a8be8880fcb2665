"""The ``dracc fleet`` reports: the page (latest figures per vessel, DR containment and
trend plots) and the terminal table of the latest figures (:func:`print_fleet_table`).

Renders a :class:`~dracc.pipeline.fleet.FleetResult`; nothing is estimated here.  The page is one
self-contained file (:mod:`dracc.report.page`); matplotlib loads only when a plot is drawn.
The cell formatters and :func:`latest` are shared by the page and the terminal table.
"""

from __future__ import annotations

import html
import math

import pandas as pd
from rich.console import Console
from rich.table import Table
from rich.text import Text

from dracc.core.safetext import printable
from dracc.pipeline.fleet import FleetResult, count_logs
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
    """Per vessel, unit and channel: the latest log's row, with the vessel's log count and period."""
    ok = table[table["status"] == "ok"]
    if ok.empty:
        return ok
    # logs without INS statistics keep one row (unit and channel empty) for DR and calibration
    last = ok.groupby(["vessel", "unit", "channel"], sort=True, dropna=False).tail(1).copy()
    span = ok.groupby("vessel").agg(
        first_day=("day", "min"), last_day=("day", "max"), logs=("log", "nunique")
    )
    return last.join(span, on="vessel").sort_values(
        ["vessel", "unit", "channel"], na_position="last"
    )


def trend_plot(trends: pd.DataFrame, vessel: str) -> bytes | None:
    """Per channel: the day's pooled m_y per unit and the a priori (dashed); PNG bytes."""
    from dracc.report.plots import m_y_apriori_plot  # matplotlib loaded only when a page is drawn

    t = trends[trends["vessel"] == vessel]
    if t.empty:
        return None
    lines = {
        c: [
            (unit, pd.to_datetime(g["day"].astype(str)), g["m_y"], g["apriori_after"])
            for unit, g in t[t["channel"] == c].groupby("unit")
        ]
        for c in ("lat", "lon", "course")
        if (t["channel"] == c).any()
    }
    return m_y_apriori_plot(
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


def fleet_html(res: FleetResult) -> str:
    """One self-contained page (offline): fleet table of latest figures, plots, failures."""
    e = html.escape
    _f, _fu, _s = fmt_num, fmt_num_unit, cell_text
    parts = [
        page_head(
            "dracc fleet report",
            "td:nth-child(-n+3),th:nth-child(-n+3){text-align:left}.bad{color:#b00}",
        ),
        f"<p>{count_logs(res.table)} logs of {res.table['vessel'].nunique()} vessels; "
        f"{res.analysed} analysed in this run, {res.cached} from the cache, "
        f"{len(res.failures)} failed.</p>",
    ]
    lt = latest(res.table)
    if not lt.empty:
        parts.append(
            "<h2>Latest figures per vessel, unit and channel</h2><table><tr>"
            + "".join(
                f"<th>{h}</th>"
                for h in (
                    "vessel",
                    "unit",
                    "channel",
                    "days",
                    "logs",
                    "m_y",
                    "kurtosis",
                    "limiting error",
                    "a priori",
                    "verdict",
                    "DR in 2M",
                    "compass error",
                    "log scale",
                )
            )
            + "</tr>"
        )
        for _, r in lt.iterrows():
            d = 3 if _s(r["measure"]) == "deg" else 1
            c = r["dr_containment_2m"]
            parts.append(
                f"<tr><td>{e(_s(r['vessel']))}</td><td>{e(_s(r['unit']))}</td>"
                f"<td>{e(_s(r['channel']))}</td><td>{e(_s(r['first_day']))} to "
                f"{e(_s(r['last_day']))}</td><td>{r['logs']}</td>"
                f"<td>{e(_fu(r['m_y'], d, ' ' + _s(r['measure'])))}</td><td>{_f(r['kurtosis'], 2)}</td>"
                f"<td>{_f(r['limit'], d)}</td><td>{_f(r['apriori_after'], d)}</td>"
                f"<td>{e(_s(r['apriori_verdict']))}</td>"
                f"<td>{'-' if pd.isna(c) else f'{100 * c:.1f} %'}</td>"
                f"<td>{_fu(r['compass_error_deg'], 2, '°')}</td><td>{_fu(r['log_scale_pct'], 2, ' %')}</td></tr>"
            )
        parts.append("</table>")
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
    parts.append(PAGE_END)
    return "\n".join(parts)


def print_fleet_table(res: FleetResult, console: Console) -> None:
    """The latest figures per vessel, unit and channel, compact enough for 80 columns."""
    lt = latest(res.table)
    t = Table(title="fleet: latest log per vessel, unit and channel", padding=(0, 1))
    for col in (
        "vessel",
        "unit",
        "m_y",
        "kurt",
        "limit",
        "a priori",
        "verdict",
        "DR 2M",
        "compass",
        "log",
    ):
        left = col in ("vessel", "unit", "verdict")
        t.add_column(
            col,
            justify="left" if left else "right",
            no_wrap=col in ("vessel", "unit"),
            overflow="fold",
        )
    for _, r in lt.iterrows():
        d = 3 if cell_text(r["measure"]) == "deg" else 0
        c = r["dr_containment_2m"]
        unit = "-" if pd.isna(r["unit"]) else f"{r['unit']} {r['channel']}"
        measure = "" if pd.isna(r["measure"]) else r["measure"]
        # Text, not str: a vessel folder named '[red]x' is not markup; control
        # characters from names are shown escaped, never sent to the terminal
        t.add_row(
            *(
                Text(printable(x))
                for x in (
                    cell_text(r["vessel"]),
                    unit,
                    fmt_num_unit(r["m_y"], d, measure),
                    fmt_num(r["kurtosis"], 1),
                    fmt_num(r["limit"], d),
                    fmt_num(r["apriori_after"], d),
                    cell_text(r["apriori_verdict"]),
                    "-" if pd.isna(c) else f"{100 * c:.0f}%",
                    fmt_num_unit(r["compass_error_deg"], 2, "°"),
                    fmt_num_unit(r["log_scale_pct"], 1, "%"),
                )
            )
        )
    console.print(t)
