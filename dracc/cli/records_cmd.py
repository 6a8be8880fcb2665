"""``dracc records LOG... --out FILE.parquet|FILE.csv|-``: every decoded record as one table,
built by :mod:`dracc.pipeline.records`, written by :mod:`dracc.report.records_out`."""

from __future__ import annotations

import typer

from dracc.cli.analyze_cmd import build_config
from dracc.cli.app import QUICK_EXIT, app, err, paths_exist, progress
from dracc.cli.options import ConfigFile, IgnoreChecksum, LogDate, LogFiles, Roles, Strict
from dracc.cli.options import parse_roles as roles_of


@app.command("records")
def records(
    logs: LogFiles,
    out: str = typer.Option(..., "--out", "-o", help="FILE.parquet, FILE.csv or - (CSV, stdout)."),
    kinds: str | None = typer.Option(None, help="Only some: position,heading,ground,water,..."),
    config: ConfigFile = None,
    role: Roles = None,
    date: LogDate = None,
    strict: Strict = False,
    no_check: IgnoreChecksum = False,
) -> None:
    """Every decoded record of the logs as one table (Parquet or CSV), in time order."""
    from dracc.ingest import read_logs
    from dracc.ingest.sources import keys_must_match
    from dracc.pipeline.records import check_kinds, records_table
    from dracc.report.records_out import output_form, write_records
    from dracc.report.write import writing

    cfg = build_config(config, roles=role, date=date, strict=strict, ignore_checksum=no_check)
    output_form(out), check_kinds(kinds), paths_exist(logs)  # usage errors before reading
    total = sum(p.stat().st_size for p in logs if p.is_file())
    with progress("records", total) as advance, keys_must_match(roles_of(role or [])):
        voyage = read_logs(logs, cfg.ingest, advance)  # a --role KEY matching nothing: error
    with writing(out):
        err.print(write_records(records_table(voyage, check_kinds(kinds)), out), markup=False)
    QUICK_EXIT["on"] = True
