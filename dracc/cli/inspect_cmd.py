"""``dracc inspect LOG...``: what is in a log — sources, roles, rates, gaps, rejections, time base.

The report is built by :func:`dracc.ingest.inspect.inspect_logs` and shown as tables
(:mod:`dracc.report.inspect_report`) or, with ``--json PATH|-``, written as JSON
(documented in ``docs/ingest.md``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from dracc.cli.app import app, err, out, paths_exist, progress
from dracc.cli.options import (
    ConfigFile,
    IgnoreChecksum,
    JsonOut,
    LogDate,
    LogFiles,
    Strict,
    check_date,
    option_values,
)
from dracc.core.config import IngestConfig, load_config, with_overrides
from dracc.ingest import inspect as log_inspection
from dracc.pipeline.clock_stage import source_clocks
from dracc.report.inspect_report import render_inspection, with_clocks
from dracc.report.output import STDOUT, emit_json
from dracc.report.write import writing


def inspect_logs(
    paths: list[Path], cfg: IngestConfig, show_progress: bool = True
) -> dict[str, Any]:
    """:func:`dracc.ingest.inspect.inspect_logs` with a progress bar on a terminal."""
    total = sum(p.stat().st_size for p in paths if p.is_file())
    with progress("inspect", total if show_progress else None) as advance:
        return log_inspection.inspect_logs(paths, cfg, advance)


@app.command("inspect")
def inspect_cmd(
    logs: LogFiles,
    config: ConfigFile = None,
    json_path: JsonOut = None,
    strict: Strict = False,
    ignore_checksum: IgnoreChecksum = False,
    date: LogDate = None,
) -> None:
    """Show what a log holds: sources and roles, sentence counts, rates, time span and gaps,
    rejected lines by reason with examples, and the time-base decisions."""
    cfg = load_config(config)
    with option_values():
        cfg = with_overrides(
            cfg,
            "ingest",
            strict=strict or None,
            ignore_checksum=ignore_checksum or None,
            date=check_date(date),
        )
    paths_exist(logs)
    rep = inspect_logs(logs, cfg.ingest)
    once = any(str(p) == "-" for p in logs)  # standard input is read once
    clocks = source_clocks(logs, cfg) if rep["sources"] and not once else {}
    rep = with_clocks(rep, clocks)
    if once:
        rep["notes"].append("clocks not learned: standard input can be read only once")
    if json_path == STDOUT:
        emit_json(rep, STDOUT)
        return
    render_inspection(rep, out, clocks)
    if json_path:
        with writing(json_path):
            emit_json(rep, json_path)
        err.print(f"wrote {json_path}", highlight=False, markup=False)
    if not rep["sources"]:
        err.print("warning: no usable records found", highlight=False)
