"""``dracc audit``: the nightly shipboard audit, and ``dracc audit history``.

``dracc audit LOG…|DIR`` (same as ``dracc audit run …``) analyses the last day's logs,
checks them against the ``[audit]`` limits, records the night in the SQLite state and
exits 0 (all checks passed), 1 (findings), 2 (bad option value), 3 (no logs for the night,
or no usable logs) or 4 (config error).
"""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.table import Table
from typer.core import TyperGroup

from dracc.cli.app import ConfigOption, app, check_choice, check_date, check_pattern, out, progress
from dracc.core import atomic
from dracc.core.config import load_config
from dracc.core.errors import ConfigError, ExitCode, StateError
from dracc.core.safetext import printable
from dracc.core.vocabulary import CHANNEL_KEYS, CHANNELS
from dracc.pipeline.audit import UNITS, AuditOutcome, audit_config, run_audit
from dracc.pipeline.state import StateStore
from dracc.report.audit_html import fmt_value as _f
from dracc.report.audit_html import history_html
from dracc.report.audit_html import measure_digits as _digits


class _DefaultRun(TyperGroup):
    """``dracc audit ARGS`` runs ``dracc audit run ARGS`` unless ARGS start with a subcommand."""

    def parse_args(self, ctx, args):
        if args and args[0] not in self.commands and args[0] not in ("-h", "--help"):
            args = ["run", *args]
        return super().parse_args(ctx, args)


audit_app = typer.Typer(
    cls=_DefaultRun,
    no_args_is_help=True,
    help="Nightly audit on board: analyse the last day's logs, check the limits, keep the "
    "state in SQLite (dracc audit LOG…|DIR), and show the trend (dracc audit history). "
    "Exit codes: 0 all checks passed, 1 findings, 2 bad option value, 3 no logs for the "
    "night or no usable logs, 4 configuration error.",
)
app.add_typer(audit_app, name="audit")


# --------------------------------------------------------------------- the summary


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


# --------------------------------------------------------------------------- run


def _check_date(value: str | None) -> str | None:
    """--date must be YYYY-MM-DD (a usage error, exit 2, otherwise)."""
    return check_date(value, "--date")


@audit_app.command("run")
def audit_run(
    logs: list[Path] = typer.Argument(..., help="Log files, or folders holding the night's logs."),
    date: str | None = typer.Option(
        None,
        "--date",
        callback=_check_date,
        help="The night to audit, YYYY-MM-DD (files "
        "in folders must carry it in their name). Default for "
        "folders: yesterday (UTC).",
    ),
    pattern: str | None = typer.Option(
        None,
        "--pattern",
        help="Glob for the log files inside "
        "folders, e.g. '*.nmea' or '**/*.nmea' ([audit] pattern).",
    ),
    vessel: str | None = typer.Option(
        None,
        "--vessel",
        help="Vessel name in the state ([audit] vessel, else [vessel] name, else 'default').",
    ),
    db: Path | None = typer.Option(None, "--db", help="SQLite state file ([audit] db)."),
    config: Path | None = ConfigOption,
    json_out: Path | None = typer.Option(
        None,
        "--json",
        help="Write the audit document "
        "(schema dracc.audit/1: verdict, findings, not "
        "checked, and the analysis it rests on).",
    ),
    html_out: Path | None = typer.Option(
        None,
        "--html",
        help="Write the audit page: the verdict and findings first, then the analysis report.",
    ),
    summary_out: Path | None = typer.Option(
        None, "--summary", help="Write the plain-text summary to this file instead of stdout."
    ),
) -> int:
    """Audit one night: analyse, check the limits, record the night; exit 0/1/2/3/4.

    Same as 'dracc audit LOG…'.  Auditing the same night again with the same logs records
    it once; with changed logs the night is replaced.
    """
    pattern = check_pattern(pattern, "--pattern")
    cfg = load_config(config)
    with progress("audit: analysing", total=100.0) as advance:
        last = [0.0]

        def report(stage: str, fraction: float) -> None:
            step = max(0.0, 100.0 * fraction - last[0])
            last[0] += step
            advance(step)

        outcome, analysis = run_audit(
            logs, cfg, db=db, vessel=vessel, night=date, pattern=pattern, progress=report
        )
    from dracc.report import audit_json

    analysis_doc = None
    if analysis is not None:
        from dracc.report import json_report

        analysis_doc = json_report.to_dict(analysis)
    if json_out is not None:
        audit_json.write_json(outcome, analysis_doc, json_out)
    if html_out is not None:
        from dracc.report import html as html_report
        from dracc.report.audit_html import night_html

        body, css = html_report.render_sections(analysis) if analysis is not None else ("", "")
        atomic.write_text(
            html_out, night_html(audit_json.to_dict(outcome, analysis_doc), body, css)
        )
    text = format_summary(outcome, cfg.deviation.probability)
    if summary_out is not None:  # mailed: a log's control characters shown, not sent
        atomic.write_text(summary_out, printable(text, keep="\n"))
    else:
        out.print(text, end="", markup=False, highlight=False)
    return int(outcome.exit_code)


# ----------------------------------------------------------------------- history


def _open_existing(db: Path | None, config: Path | None) -> StateStore:
    cfg = load_config(config)
    acfg = audit_config(cfg)
    path = db or (Path(acfg.db) if acfg.db else None)
    if path is None:
        raise ConfigError('no audit database: give --db PATH or [audit] db = "PATH"')
    if not Path(path).is_file():
        raise StateError(f"{path}: no audit database here (run 'dracc audit' first)")
    return StateStore(path, busy_timeout_s=acfg.busy_timeout_s)


def history_document(store: StateStore, vessel=None, unit=None, channel=None) -> dict:
    """The trend as a JSON-ready dict (schema ``dracc.audit.history/1``)."""
    series: dict[tuple, dict] = {}
    for h in store.history(vessel, unit, channel):
        key = (h["vessel"], h["unit"], h["channel"])
        s = series.setdefault(
            key,
            {
                "vessel": key[0],
                "unit": key[1],
                "channel": key[2],
                "measure": h["measure"],
                "nights": [],
            },
        )
        s["nights"].append(
            {
                k: h[k]
                for k in (
                    "night",
                    "n",
                    "m_u",
                    "m_y",
                    "kurtosis",
                    "limit_error",
                    "apriori_before",
                    "apriori_after",
                    "verdict",
                )
            }
        )
    nights = [
        {
            "vessel": r.vessel,
            "night": r.night,
            "audited_utc": r.audited_utc,
            "content_sha256": r.content_sha256,
            "dr_containment_2m": r.dr_containment_2m,
            "dr_verdict": r.dr_verdict,
            "dr_consistent": r.dr_consistent,
            "dr_nees": r.dr_nees,
            "compass_error_deg": r.compass_error_deg,
            "log_scale": r.log_scale,
            "rejected_rate": r.rejected_rate,
            "findings": list(r.findings),
        }
        for v in ([vessel] if vessel else store.vessels())
        for r in store.nights(v)
    ]
    events = [
        {
            "vessel": e.vessel,
            "unit": e.unit,
            "channel": e.channel,
            "night": e.night,
            "value": e.value,
            "previous": e.previous,
            "reason": e.reason,
            "evidence": e.evidence,
        }
        for e in store.apriori_events(vessel)
        if (unit is None or e.unit == unit) and (channel is None or e.channel == channel)
    ]
    return {
        "schema": "dracc.audit.history/1",
        "series": list(series.values()),
        "nights": nights,
        "apriori_events": events,
    }


@audit_app.command("history")
def audit_history(
    db: Path | None = typer.Option(None, "--db", help="SQLite state file ([audit] db)."),
    vessel: str | None = typer.Option(None, "--vessel", help="Only this vessel."),
    unit: str | None = typer.Option(None, "--unit", help="Only this unit (ins1, ins2, ins3)."),
    channel: str | None = typer.Option(
        None, "--channel", help="Only this channel (lat, lon, course)."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print the history as JSON on stdout."),
    html_out: Path | None = typer.Option(None, "--html", help="Write an HTML page with plots."),
    config: Path | None = ConfigOption,
) -> int:
    """The trend per vessel, unit and channel: m_y, limiting error, a priori and verdict per night."""
    check_choice(unit, UNITS, "--unit")
    check_choice(channel, CHANNELS, "--channel")
    with _open_existing(db, config) as store:
        check_choice(
            vessel, store.vessels(), "--vessel", "no vessel is recorded in this database yet"
        )
        doc = history_document(store, vessel, unit, channel)
    if html_out is not None:
        atomic.write_text(html_out, history_html(doc))
    if as_json:
        out.print(json.dumps(doc, indent=1, ensure_ascii=False), markup=False, highlight=False)
        return int(ExitCode.OK)
    if not doc["series"]:
        out.print("no nights recorded for this selection", markup=False, highlight=False)
        return int(ExitCode.OK)
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
        out.print(t)
    return int(ExitCode.OK)
