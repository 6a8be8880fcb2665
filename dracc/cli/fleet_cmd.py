"""``dracc fleet``: batch reports over many vessels' logs, in parallel, resumable."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import typer
from rich.table import Table
from rich.text import Text

from dracc.cli.app import ConfigOption, app, check_pattern, err, out, progress
from dracc.core.config import load_config
from dracc.core.errors import ConfigError, ExitCode, Interrupted, OptionError
from dracc.core.safetext import printable
from dracc.pipeline.fleet import FleetResult, discover, fleet_config, run_fleet, write_tables
from dracc.report.fleet_html import cell_text as _s
from dracc.report.fleet_html import fleet_html, latest
from dracc.report.fleet_html import fmt_num as _f
from dracc.report.fleet_html import fmt_num_unit as _fu


def print_table(res: FleetResult) -> None:
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
        d = 3 if _s(r["measure"]) == "deg" else 0
        c = r["dr_containment_2m"]
        unit = "-" if pd.isna(r["unit"]) else f"{r['unit']} {r['channel']}"
        measure = "" if pd.isna(r["measure"]) else r["measure"]
        # Text, not str: a vessel folder named '[red]x' is not markup; control
        # characters from names are shown escaped, never sent to the terminal
        t.add_row(
            *(
                Text(printable(x))
                for x in (
                    _s(r["vessel"]),
                    unit,
                    _fu(r["m_y"], d, measure),
                    _f(r["kurtosis"], 1),
                    _f(r["limit"], d),
                    _f(r["apriori_after"], d),
                    _s(r["apriori_verdict"]),
                    "-" if pd.isna(c) else f"{100 * c:.0f}%",
                    _fu(r["compass_error_deg"], 2, "°"),
                    _fu(r["log_scale_pct"], 1, "%"),
                )
            )
        )
    out.print(t)


def check_scheduler(address: str | None, where: str, error: type[Exception]) -> None:
    """A Dask scheduler address must name a port (tcp://host:8786, host:8786): Dask says
    ValueError otherwise, deep inside the client.  Not checked without Dask (the batch then
    says what is missing)."""
    if not address:
        return
    try:
        from distributed.comm.addressing import parse_address, parse_host_port
        from distributed.comm.registry import get_backend
    except ImportError:
        return
    try:
        scheme, loc = parse_address(address)
        get_backend(scheme)  # an unknown scheme
        if scheme in ("tcp", "tls", "ws", "wss"):
            parse_host_port(loc)
    except ValueError as e:
        raise error(
            f"{where} {address!r}: {e}; expected an address such as tcp://host:8786"
        ) from None


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
    config: Path | None = ConfigOption,
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
            raise Interrupted(
                f"interrupted; the new fleet outputs were already complete in {target}"
            ) from None
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
        print_table(res)
        for f in res.failures:
            err.print(Text(printable(f"failed: {f['vessel']}/{f['log']}: {f['error']}")))
        err.print(
            Text(
                printable(
                    f"fleet: {len(tasks)} logs, {res.analysed} analysed, {res.cached} "
                    f"from the cache, {len(res.failures)} failed; tables and fleet.html "
                    f"in {target}"
                )
            )
        )
    except KeyboardInterrupt:
        raise Interrupted(
            f"interrupted; the new fleet outputs were already complete in {target}"
        ) from None
    return int(ExitCode.INPUT if res.failures else ExitCode.OK)
