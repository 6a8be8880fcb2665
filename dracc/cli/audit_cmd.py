"""``dracc audit``: the nightly shipboard audit, and ``dracc audit history``.

``dracc audit LOG…|DIR`` (same as ``dracc audit run …``) analyses the last day's logs,
checks them against the ``[audit]`` limits, records the night in the SQLite state and
exits 0 (all checks passed), 1 (findings), 2 (bad option value), 3 (no logs for the night,
or no usable logs) or 4 (config error).  The work is :func:`dracc.pipeline.audit.run_audit`;
the reports are :mod:`dracc.report.audit_text`, ``audit_json`` and ``audit_html``.
"""

from __future__ import annotations

from pathlib import Path

import typer
from typer.core import TyperGroup

from dracc.cli import SIGNALLED
from dracc.cli.app import app, out, progress
from dracc.cli.options import (
    ConfigFile,
    JsonOut,
    build_config,
    check_choice,
    check_date,
    check_pattern,
)
from dracc.core import atomic
from dracc.core.errors import ExitCode
from dracc.core.safetext import printable
from dracc.core.vocabulary import CHANNELS
from dracc.pipeline.audit import UNITS, open_state, run_audit
from dracc.report import audit_json
from dracc.report.audit_failed import AuditRequest, reports_on_failure
from dracc.report.audit_html import audit_page, history_html
from dracc.report.audit_text import format_summary, print_history
from dracc.report.output import STDOUT, emit_json


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
    "night or no usable logs, 4 configuration error, 6 a report cannot be written.",
)
app.add_typer(audit_app, name="audit")

DbOption = typer.Option(None, "--db", help="SQLite state file ([audit] db).")


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
        help="The night to audit, YYYY-MM-DD (files in folders must carry it in their "
        "name). Default for folders: yesterday (UTC).",
    ),
    pattern: str | None = typer.Option(
        None,
        "--pattern",
        help="Glob for the log files inside folders, e.g. '*.nmea' or '**/*.nmea' "
        "([audit] pattern).",
    ),
    vessel: str | None = typer.Option(
        None,
        "--vessel",
        help="Vessel name in the state ([audit] vessel, else [vessel] name, else 'default').",
    ),
    db: Path | None = DbOption,
    config: ConfigFile = None,
    json_out: JsonOut = None,
    html_out: Path | None = typer.Option(
        None,
        "--html",
        help="Write the audit page: the verdict and findings first, then the analysis report.",
    ),
    summary_out: Path | None = typer.Option(
        None, "--summary", help="Write the plain-text summary to this file instead of stdout."
    ),
    brief: bool = typer.Option(
        False,
        "--brief",
        help="--json without the analysis (about 10 kB a night: what 'dracc fleet' needs ashore).",
    ),
) -> int:
    """Audit one night: analyse, check the limits, record the night; exit 0/1/2/3/4.

    Same as 'dracc audit LOG…'.  Auditing the same night again with the same logs records
    it once; with changed logs the night is replaced.  --json writes the audit document
    (dracc.audit/1: verdict, findings, not checked, and the analysis it rests on); with
    '--json -' it is printed on stdout instead of the summary.
    """
    request = AuditRequest(logs, date, vessel, config, db, summary_out, json_out, html_out)
    with reports_on_failure(request, signalled=SIGNALLED):  # exit 2-5, 130
        return _run(request, pattern, brief)


def _run(request: AuditRequest, pattern: str | None, brief: bool) -> int:
    pattern = check_pattern(pattern, "--pattern")
    cfg = build_config(request.config)  # as analyze takes it: one validation path
    with progress("audit: analysing", total=100.0) as advance:
        last = [0.0]

        def report(stage: str, fraction: float) -> None:
            step = max(0.0, 100.0 * fraction - last[0])
            last[0] += step
            advance(step)

        outcome = run_audit(
            request.logs,
            cfg,
            db=request.db,
            vessel=request.vessel,
            night=request.date,
            pattern=pattern,
            progress=report,
        )
    json_out, html_out, summary_out = request.json_out, request.html_out, request.summary_out
    doc = audit_json.to_dict(outcome) if (json_out or html_out) else None
    text = format_summary(outcome, cfg.deviation.probability)
    with atomic.together():  # the night's reports appear together, or none of them does
        if json_out is not None:
            emit_json(audit_json.brief(doc) if brief and doc else doc, json_out)
        if html_out is not None:
            atomic.write_text(html_out, audit_page(outcome, doc))
        if summary_out is not None:  # mailed: a log's control characters shown, not sent
            atomic.write_text(summary_out, printable(text, keep="\n"))
    if summary_out is None and json_out != STDOUT:
        out.print(text, end="", markup=False, highlight=False)
    return int(outcome.exit_code)


@audit_app.command("history")
def audit_history(
    db: Path | None = DbOption,
    vessel: str | None = typer.Option(None, "--vessel", help="Only this vessel."),
    unit: str | None = typer.Option(None, "--unit", help="Only this unit (ins1, ins2, ins3)."),
    channel: str | None = typer.Option(
        None, "--channel", help="Only this channel (lat, lon, course)."
    ),
    json_out: JsonOut = None,
    html_out: Path | None = typer.Option(None, "--html", help="Write an HTML page with plots."),
    config: ConfigFile = None,
) -> int:
    """The trend per vessel, unit and channel: m_y, limiting error, a priori and verdict per
    night (--json: the history document, dracc.audit.history/1)."""
    check_choice(unit, UNITS, "--unit")
    check_choice(channel, CHANNELS, "--channel")
    with open_state(build_config(config), db) as store:
        check_choice(
            vessel, store.vessels(), "--vessel", "no vessel is recorded in this database yet"
        )
        doc = audit_json.history_document(store, vessel, unit, channel)
    with atomic.together():
        if html_out is not None:
            atomic.write_text(html_out, history_html(doc))
        if json_out is not None:
            emit_json(doc, json_out)
    if json_out != STDOUT:
        print_history(doc, out)
    return int(ExitCode.OK)
