"""``dracc fleet``: batch reports over many vessels' logs, in parallel, resumable; and
``dracc fleet query "SQL"``: DuckDB over the tables a run wrote.

``dracc fleet INPUT…`` is ``dracc fleet run INPUT…``.  The work is :mod:`dracc.pipeline.fleet`
(discover, run, publish the tables; :mod:`~dracc.pipeline.fleet.query` for SQL); the page is
:mod:`dracc.report.fleet_html`, the terminal table :func:`dracc.report.terminal.print_fleet`.
"""

from __future__ import annotations

import sys
from pathlib import Path

import typer
from typer.core import TyperGroup

from dracc.cli.app import QUICK_EXIT, app, err, out, progress
from dracc.cli.options import ConfigFile, check_choice, check_pattern
from dracc.core import atomic
from dracc.core.config import load_config
from dracc.core.errors import ConfigError, ExitCode, Interrupted, OptionError
from dracc.pipeline.fleet import check_scheduler, discover, fleet_config, run_fleet
from dracc.report.fleet_html import fleet_html
from dracc.report.fleet_tables import (
    counts_text,
    csv_text,
    input_lines,
    json_lines,
    result_text,
    write_tables,
)
from dracc.report.terminal import print_fleet
from dracc.report.textout import Layout, layout, print_lines, wrap
from dracc.report.write import writing


class _DefaultRun(TyperGroup):
    """``dracc fleet ARGS`` runs ``dracc fleet run ARGS`` unless ARGS start with a subcommand."""

    def parse_args(self, ctx, args):
        if args and args[0] not in self.commands and args[0] not in ("-h", "--help"):
            args = ["run", *args]
        return super().parse_args(ctx, args)


fleet_app = typer.Typer(
    cls=_DefaultRun,
    no_args_is_help=True,
    help="Many vessels: analyse their logs in parallel into fleet tables, trends, a ranking "
    "and a page (dracc fleet INPUT… --out DIR, same as dracc fleet run), then query the "
    'tables with SQL (dracc fleet query "SQL" --out DIR).  A vessel folder named run or '
    "query is given as ./run or ./query.",
)
app.add_typer(fleet_app, name="fleet")
OutDir = typer.Option(
    None, "--out", "-o", help="Output folder ([fleet] out; default ./fleet-report)."
)


@fleet_app.command("run")
def fleet_cmd(
    inputs: list[str] = typer.Argument(
        ...,
        help="Vessel folders (one per vessel) or log files / "
        "globs (the vessel is the parent folder's name).",
    ),
    workers: int | None = typer.Option(
        None,
        "--workers",
        "-j",
        min=1,
        help="Local worker processes ([fleet] workers; default: CPU count).",
    ),
    scheduler: str | None = typer.Option(
        None,
        "--scheduler",
        help="Run on an existing Dask scheduler, e.g. tcp://host:8786 ([fleet] scheduler).",
    ),
    out_dir: Path | None = OutDir,
    force: bool = typer.Option(
        False, "--force", help="Analyse every log again (ignore the cache)."
    ),
    pattern: str | None = typer.Option(
        None,
        "--pattern",
        help="Glob for log files inside vessel folders ([fleet] pattern; default '**/*').",
    ),
    config: ConfigFile = None,
) -> int:
    """Analyse many vessels' logs in parallel: fleet table (Parquet, CSV), trends, HTML page.

    Same as 'dracc fleet INPUT…' (a vessel folder named run or query: write ./run,
    ./query).  A re-run skips logs already analysed (same bytes, same settings) unless
    --force; a log that fails is listed and the batch goes on (exit 3 when any failed
    or none was found, else 0); a file that is no log (a README, a photo) is skipped and
    listed, not failed.  The tables are also written Hive-partitioned under DIR/tables/ for SQL.
    """
    if scheduler and workers:
        raise OptionError(
            "--workers is for the local pool; with --scheduler the Dask workers run the logs"
        )
    check_scheduler(scheduler, "--scheduler", OptionError)
    pattern = check_pattern(pattern, "--pattern")
    cfg = load_config(config)
    fc = fleet_config(cfg)
    check_scheduler(fc.scheduler, "[fleet] scheduler", ConfigError)
    target = Path(out_dir or fc.out or "fleet-report")
    done = f"interrupted; the new fleet outputs were already complete in {target}"
    published: list[str] = []  # the new set's name, once it is out (see atomic.file_set)
    try:  # from the first file looked at: an interrupt always says which set is there
        tasks = discover(inputs, pattern or fc.pattern)
        with progress(f"fleet: {len(tasks)} logs", total=len(tasks)) as advance:
            res = run_fleet(
                tasks,
                cfg,
                target,
                workers=workers or fc.workers,
                scheduler=scheduler or fc.scheduler,
                force=force,
                connect_timeout_s=fc.connect_timeout_s,
                progress=advance,
            )
        # every output is rendered and written to a staging folder, then published as one
        write_tables(res, target, extra={"fleet.html": fleet_html(res)}, published=published)
    except KeyboardInterrupt:
        if published:  # the new set went out whole before the interrupt
            raise Interrupted(done) from None
        what = (
            f"the fleet outputs in {target} are still those of the previous run"
            if (target / "fleet.json").exists()
            else f"no fleet outputs in {target} yet"
        )
        raise Interrupted(
            f"interrupted; nothing partial was written: {what}; the logs finished so "
            "far are cached for the next run"
        ) from None
    try:
        print_fleet(res, out)
        lay = layout(err)  # a terminal: wrap on spaces; a pipe or journald: a line each
        width = lay.width if lay.tty else 1 << 30
        for said in input_lines(res):
            print_lines(err, wrap(said, width, hang=2))
        print_lines(
            err, wrap(f"{counts_text(res)}; tables and fleet.html in {target}", width, hang=2)
        )
    except KeyboardInterrupt:
        raise Interrupted(done) from None
    QUICK_EXIT["on"] = True  # the exit follows at once, signals held (cli.quick_exit)
    return int(ExitCode.INPUT if res.failures or not res.logs else ExitCode.OK)


FORMATS = ("table", "csv", "json")


@fleet_app.command("query")
def fleet_query(
    sql: str = typer.Argument(
        ..., help="The query (DuckDB SQL) over fleet, trends, ranking, findings, integrity."
    ),
    out_dir: Path | None = OutDir,
    form: str = typer.Option("table", "--format", help="table, csv or json (JSON lines)."),
    output: Path | None = typer.Option(
        None, "--output", help="Write the result to this file (atomically), not stdout."
    ),
    config: ConfigFile = None,
) -> int:
    """SQL over the tables of a fleet run: views fleet, trends, ranking, findings and
    integrity (DuckDB).

    The views read DIR/tables/ (Hive-partitioned Parquet: vessel=…/night=…) and have the
    columns of fleet.parquet, trends.parquet, ranking.parquet, findings.parquet and
    integrity.parquet.  The query reads these views only: a file, ATTACH, COPY, EXPORT,
    INSTALL, LOAD or SET is refused (exit 2); nothing is written.  Example: dracc fleet
    query "SELECT vessel, avg(m_y) FROM fleet WHERE channel = 'lat' GROUP BY vessel ORDER
    BY 2" --out fleet-report
    """
    from dracc.pipeline.fleet.query import run_query

    check_choice(form, FORMATS, "--format")
    if not sql.strip():
        raise OptionError("the SQL query is empty")
    target = Path(out_dir or fleet_config(load_config(config)).out or "fleet-report")
    df = run_query(target, sql)
    if form == "csv":
        text = csv_text(df) if len(df.columns) else ""
    elif form == "json":
        text = json_lines(df, ascii_only=output is None)
    elif output is not None:  # a file: every column, at its natural width
        text = result_text(df, Layout())
    else:
        text = result_text(df, layout(out)).rstrip("\n")
        print_lines(out, text, bold=[0] if len(df.columns) else [])
        return int(ExitCode.OK)
    with writing(output or "stdout"):
        if output is not None:
            atomic.write_text(output, text)
        elif out.is_terminal:  # a log's control characters shown, not sent
            out.print(text, end="", markup=False, highlight=False)
        else:
            sys.stdout.write(text)
            sys.stdout.flush()
    return int(ExitCode.OK)
