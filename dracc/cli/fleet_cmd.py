"""``dracc fleet``: batch reports over many vessels' logs, in parallel, resumable.

The work is :mod:`dracc.pipeline.fleet` (discover, run, publish the tables); the page is
:mod:`dracc.report.fleet_html`, the terminal table :func:`dracc.report.terminal.print_fleet`.
"""

from __future__ import annotations

from pathlib import Path

import typer

from dracc.cli.app import app, err, out, progress
from dracc.cli.options import ConfigFile, check_pattern
from dracc.core.config import load_config
from dracc.core.errors import ConfigError, ExitCode, Interrupted, OptionError
from dracc.pipeline.fleet import check_scheduler, discover, fleet_config, run_fleet
from dracc.report.fleet_html import fleet_html
from dracc.report.fleet_tables import write_tables
from dracc.report.terminal import print_fleet
from dracc.report.textout import layout, print_lines, wrap


@app.command("fleet")
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
    out_dir: Path | None = typer.Option(
        None, "--out", "-o", help="Output folder ([fleet] out; default ./fleet-report)."
    ),
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

    A re-run skips logs already analysed (same bytes, same settings) unless --force; a log
    that fails is listed and the batch goes on (exit 3 when any failed, else 0).
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
    tasks = discover(inputs, pattern or fc.pattern)
    done = f"interrupted; the new fleet outputs were already complete in {target}"
    published: list[str] = []  # the new set's name, once it is out (see atomic.file_set)
    try:
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
        for f in res.failures:
            print_lines(err, wrap(f"failed: {f['vessel']}/{f['log']}: {f['error']}", width, hang=2))
        said = (
            f"fleet: {len(tasks)} logs, {res.analysed} analysed, {res.cached} from the cache, "
            f"{len(res.failures)} failed; tables and fleet.html in {target}"
        )
        print_lines(err, wrap(said, width, hang=2))
    except KeyboardInterrupt:
        raise Interrupted(done) from None
    return int(ExitCode.INPUT if res.failures else ExitCode.OK)
