"""``dracc fleet``: batch reports over many vessels' logs, in parallel, resumable."""

from __future__ import annotations

import base64
import html
import io
import math
from pathlib import Path

import pandas as pd
import typer
from rich.table import Table

from .. import atomic
from ..config import load_config
from ..errors import ConfigError, ExitCode
from ..fleet import FleetResult, count_logs, discover, fleet_config, inside, run_fleet, write_tables
from .app import ConfigOption, app, err, out, progress


def _f(x, digits: int = 1) -> str:
    if x is None or pd.isna(x) or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return f"{x:,.{digits}f}"


def _fu(x, digits: int, unit: str) -> str:
    """A number with its unit, or '-'."""
    text = _f(x, digits)
    return text if text == "-" else text + unit


def _s(x) -> str:
    """Text for a table cell; '-' for missing."""
    return "-" if x is None or pd.isna(x) else str(x)


def latest(table: pd.DataFrame) -> pd.DataFrame:
    """Per vessel, unit and channel: the latest log's row, with the vessel's log count and period."""
    ok = table[table["status"] == "ok"]
    if ok.empty:
        return ok
    # logs without INS statistics keep one row (unit and channel empty) for DR and calibration
    last = ok.groupby(["vessel", "unit", "channel"], sort=True, dropna=False).tail(1).copy()
    span = ok.groupby("vessel").agg(first_day=("day", "min"), last_day=("day", "max"),
                                    logs=("log", "nunique"))
    return last.join(span, on="vessel").sort_values(["vessel", "unit", "channel"], na_position="last")


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=85, bbox_inches="tight")
    return base64.b64encode(buf.getvalue()).decode("ascii")


def trend_plot(trends: pd.DataFrame, vessel: str) -> str | None:
    """Per channel: the day's pooled m_y per unit and the a priori (dashed), base64 PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = trends[trends["vessel"] == vessel]
    if t.empty:
        return None
    channels = [c for c in ("lat", "lon", "course") if (t["channel"] == c).any()]
    fig, axes = plt.subplots(len(channels), 1, figsize=(8, 2.2 * len(channels)), sharex=True,
                             squeeze=False)
    for ax, ch in zip(axes[:, 0], channels, strict=True):
        for unit, g in t[t["channel"] == ch].groupby("unit"):
            days = pd.to_datetime(g["day"].astype(str))
            line, = ax.plot(days, g["m_y"], "o-", label=f"{unit} m_y")
            ax.step(days, g["apriori_after"], "--", where="post", color=line.get_color(), alpha=0.7,
                    label=f"{unit} a priori")
        ax.set_ylabel(f"{ch} ({'deg' if ch == 'course' else 'm'})")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, ncol=3)
    axes[0, 0].set_title(f"{vessel}: daily RMS error from deviations (pooled m_y) and a priori")
    fig.autofmt_xdate()
    png = _png(fig)
    plt.close(fig)
    return png


def containment_plot(table: pd.DataFrame) -> str | None:
    """DR containment in 2M per vessel and log (the 2 drms promise ~95 %), base64 PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

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
    png = _png(fig)
    plt.close(fig)
    return png


def fleet_html(res: FleetResult) -> str:
    """One self-contained page (offline): fleet table of latest figures, plots, failures."""
    e = html.escape
    parts = ["<!doctype html><html><head><meta charset='utf-8'><title>dracc fleet report</title>",
             "<style>body{font-family:sans-serif;margin:1.5em}table{border-collapse:collapse}"
             "td,th{border:1px solid #bbb;padding:2px 6px;text-align:right}"
             "td:nth-child(-n+3),th:nth-child(-n+3){text-align:left}.bad{color:#b00}</style>"
             "</head><body><h1>dracc fleet report</h1>",
             f"<p>{count_logs(res.table)} logs of {res.table['vessel'].nunique()} vessels; "
             f"{res.analysed} analysed in this run, {res.cached} from the cache, "
             f"{len(res.failures)} failed.</p>"]
    lt = latest(res.table)
    if not lt.empty:
        parts.append("<h2>Latest figures per vessel, unit and channel</h2><table><tr>"
                     + "".join(f"<th>{h}</th>" for h in (
                         "vessel", "unit", "channel", "days", "logs", "m_y", "kurtosis",
                         "limiting error", "a priori", "verdict", "DR in 2M", "compass error",
                         "log scale")) + "</tr>")
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
                f"<td>{_fu(r['compass_error_deg'], 2, '°')}</td><td>{_fu(r['log_scale_pct'], 2, ' %')}</td></tr>")
        parts.append("</table>")
    png = containment_plot(res.table)
    if png:
        parts.append(f"<h2>Dead reckoning</h2><img alt='DR containment per vessel' "
                     f"src='data:image/png;base64,{png}'>")
    for v in sorted(res.trends["vessel"].dropna().unique()):
        png = trend_plot(res.trends, v)
        if png:
            parts.append(f"<h2>{e(str(v))}</h2><img alt='trend of {e(str(v))}' "
                         f"src='data:image/png;base64,{png}'>")
    if res.failures:
        parts.append("<h2 class='bad'>Failures</h2><ul>")
        parts += [f"<li>{e(f['vessel'])} / {e(f['log'])}: {e(f['error'])}</li>" for f in res.failures]
        parts.append("</ul>")
    parts.append("</body></html>\n")
    return "\n".join(parts)


def print_table(res: FleetResult) -> None:
    """The latest figures per vessel, unit and channel, compact enough for 80 columns."""
    lt = latest(res.table)
    t = Table(title="fleet: latest log per vessel, unit and channel", padding=(0, 1))
    for col in ("vessel", "unit", "m_y", "kurt", "limit", "a priori", "verdict", "DR 2M",
                "compass", "log"):
        left = col in ("vessel", "unit", "verdict")
        t.add_column(col, justify="left" if left else "right", no_wrap=col in ("vessel", "unit"),
                     overflow="fold")
    for _, r in lt.iterrows():
        d = 3 if _s(r["measure"]) == "deg" else 0
        c = r["dr_containment_2m"]
        unit = "-" if pd.isna(r["unit"]) else f"{r['unit']} {r['channel']}"
        measure = "" if pd.isna(r["measure"]) else r["measure"]
        t.add_row(_s(r["vessel"]), unit, _fu(r["m_y"], d, measure),
                  _f(r["kurtosis"], 1), _f(r["limit"], d), _f(r["apriori_after"], d),
                  _s(r["apriori_verdict"]), "-" if pd.isna(c) else f"{100 * c:.0f}%",
                  _fu(r["compass_error_deg"], 2, "°"), _fu(r["log_scale_pct"], 1, "%"))
    out.print(t)


@app.command("fleet")
def fleet_cmd(
    inputs: list[str] = typer.Argument(..., help="Vessel folders (one per vessel) or log files / "
                                       "globs (the vessel is the parent folder's name)."),
    workers: int | None = typer.Option(None, "--workers", "-j", min=1, help="Local worker "
                                          "processes ([fleet] workers; default: CPU count)."),
    scheduler: str | None = typer.Option(None, "--scheduler", help="Run on an existing Dask "
                                            "scheduler, e.g. tcp://host:8786 ([fleet] scheduler)."),
    out_dir: Path | None = typer.Option(None, "--out", "-o", help="Output folder ([fleet] out; "
                                           "default ./fleet-report)."),
    force: bool = typer.Option(False, "--force", help="Analyse every log again (ignore the cache)."),
    pattern: str | None = typer.Option(None, "--pattern", help="Glob for log files inside vessel "
                                          "folders ([fleet] pattern; default '**/*')."),
    config: Path | None = ConfigOption,
) -> int:
    """Analyse many vessels' logs in parallel: fleet table (Parquet, CSV), trends, HTML page.

    A re-run skips logs already analysed (same bytes, same settings) unless --force; a log
    that fails is listed and the batch goes on (exit 3 when any failed, else 0).
    """
    cfg = load_config(config)
    fc = fleet_config(cfg)
    if scheduler and workers:
        raise ConfigError("--workers is for the local pool; with --scheduler the Dask workers run the logs")
    target = Path(out_dir or fc.out or "fleet-report")
    tasks = discover(inputs, pattern or fc.pattern)
    with progress(f"fleet: {len(tasks)} logs", total=len(tasks)) as advance:
        res = run_fleet(tasks, cfg, target, workers=workers or fc.workers,
                        scheduler=scheduler or fc.scheduler, force=force,
                        connect_timeout_s=fc.connect_timeout_s, progress=advance)
    write_tables(res, target)
    atomic.write_text(inside(target, "fleet.html"), fleet_html(res))
    print_table(res)
    for f in res.failures:
        err.print(f"failed: {f['vessel']}/{f['log']}: {f['error']}", markup=False, highlight=False)
    err.print(f"fleet: {len(tasks)} logs, {res.analysed} analysed, {res.cached} from the cache, "
              f"{len(res.failures)} failed; tables and fleet.html in {target}",
              markup=False, highlight=False)
    return int(ExitCode.INPUT if res.failures else ExitCode.OK)
