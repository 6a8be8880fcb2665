"""``dracc analyze LOG...``: the main job — dead reckoning, INS deviations, current, reports.

The command parses options into the configuration, calls :func:`dracc.pipeline.analysis.analyse`
once, and hands the result to the renderers: a short summary on stdout (unless the JSON
goes there), ``--json`` (file or ``-``), ``--html`` (one offline file) and ``--out``
(CSV and Parquet tables).  Every file is written atomically.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

import typer

from dracc.cli.app import (
    QUICK_EXIT,
    ConfigOption,
    LogsArgument,
    app,
    check_date,
    err,
    option_values,
    out,
    paths_exist,
    progress,
)
from dracc.core import atomic
from dracc.core.config import load_config, validate
from dracc.core.durations import parse_duration_s, parse_reset_s
from dracc.core.errors import ConfigError, DraccError
from dracc.core.vocabulary import ROLES
from dracc.ingest.sources import keys_must_match


def parse_roles(items: list[str]) -> dict[str, str]:
    """['INS2=ins2', 'II=compass'] -> {'INS2': 'ins2', 'II': 'compass'}."""
    out_: dict[str, str] = {}
    for item in items:
        key, sep, role = item.partition("=")
        key, role = key.strip(), role.strip().lower()
        if not sep or not key:
            raise ConfigError(f"--role {item!r}: expected KEY=ROLE, e.g. --role INS2=ins2")
        if role not in ROLES:
            raise ConfigError(f"--role {item!r}: role must be one of {', '.join(ROLES)}")
        out_[key] = role
    return out_


def build_config(
    config: Path | None,
    *,
    interval: str | None = None,
    window: str | None = None,
    dr_reset: str | None = None,
    probability: float | None = None,
    roles: list[str] | None = None,
    date: str | None = None,
    strict: bool = False,
    ignore_checksum: bool = False,
    epoch_interval: str | None = None,
    variation_deg: float | None = None,
    fix_role: str | None = None,
):
    """The configuration file with the command-line options applied on top.

    An error of the file is a ConfigError (exit 4); a bad option value, or one the
    validated file's settings cannot take, an OptionError (exit 2)."""
    cfg = load_config(config)  # validated: what fails below comes from the options
    with option_values():
        return _apply_options(
            cfg,
            interval=interval,
            window=window,
            dr_reset=dr_reset,
            probability=probability,
            roles=roles,
            date=date,
            strict=strict,
            ignore_checksum=ignore_checksum,
            epoch_interval=epoch_interval,
            variation_deg=variation_deg,
            fix_role=fix_role,
        )


def _apply_options(
    cfg,
    *,
    interval,
    window,
    dr_reset,
    probability,
    roles,
    date,
    strict,
    ignore_checksum,
    epoch_interval,
    variation_deg,
    fix_role,
):
    ing = cfg.ingest
    sources = {**ing.sources, **parse_roles(roles or [])}
    date = check_date(date)
    ing = replace(
        ing,
        sources=sources,
        strict=ing.strict or strict,
        ignore_checksum=ing.ignore_checksum or ignore_checksum,
        date=date if date is not None else ing.date,
    )
    dev = cfg.deviation
    if interval is not None:
        dev = replace(dev, interval_s=parse_duration_s(interval, "--interval"))
    if window is not None:
        dev = replace(dev, window_s=parse_duration_s(window, "--window"))
    if probability is not None:
        if not 0.5 <= probability < 1.0:
            raise ConfigError(f"--probability {probability}: must be in [0.5, 1)")
        dev = replace(dev, probability=probability)
    dr = cfg.dead_reckoning
    if dr_reset is not None:
        try:
            if dr_reset.strip().lower() != "auto":
                parse_reset_s(dr_reset)
        except ConfigError as e:
            raise ConfigError(
                f"--dr-reset {dr_reset!r}: expected auto, 1h, 4h, 30min, watch or never"
            ) from e
        dr = replace(dr, reset=dr_reset)
    if epoch_interval is not None:
        dr = replace(dr, epoch_interval_s=parse_duration_s(epoch_interval, "--epoch-interval"))
    if variation_deg is not None:
        if not -180.0 <= variation_deg <= 180.0:
            raise ConfigError(f"--variation {variation_deg}: must be within ±180 degrees (east +)")
        dr = replace(dr, variation_deg=variation_deg)
    if fix_role is not None:
        if fix_role not in ("gnss", "ins_mean"):
            raise ConfigError(f"--fix-role {fix_role!r}: must be gnss or ins_mean")
        dr = replace(dr, fix_role=fix_role)
    return validate(replace(cfg, ingest=ing, deviation=dev, dead_reckoning=dr))


@app.command("analyze")
def analyze(
    logs: list[Path] = LogsArgument,
    config: Path | None = ConfigOption,
    out_dir: Path | None = typer.Option(
        None,
        "--out",
        "-o",
        help="Write CSV and Parquet tables "
        "(DR track, DR epochs, deviation samples, per-unit statistics) here.",
    ),
    json_path: str | None = typer.Option(
        None,
        "--json",
        help="Write the JSON report (schema dracc.analysis/1) to FILE, or '-' for stdout.",
    ),
    html_path: Path | None = typer.Option(
        None, "--html", help="Write one self-contained offline HTML report."
    ),
    interval: str | None = typer.Option(
        None, "--interval", help="INS sampling interval: 1h (default), 2h, 3600 ..."
    ),
    window: str | None = typer.Option(
        None, "--window", help="Statistics window: 24h (default), 2d ..."
    ),
    dr_reset: str | None = typer.Option(
        None,
        "--dr-reset",
        help="Restart the DR from a fix: auto "
        "(default: 1h on logs of 8 h or more, shorter on short logs), "
        "1h, 4h, 30min, watch, never.",
    ),
    probability: float | None = typer.Option(
        None, "--probability", help="Probability of limiting errors (K8), default 0.95."
    ),
    role: list[str] = typer.Option(
        [],
        "--role",
        help="Map a source to a role, KEY=ROLE (repeatable), "
        "e.g. --role INS2=ins2 --role II=compass.",
    ),
    date: str | None = typer.Option(None, "--date", help="YYYY-MM-DD for logs that carry no date."),
    strict: bool = typer.Option(False, "--strict", help="Fail on the first rejected line."),
    ignore_checksum: bool = typer.Option(
        False, "--ignore-checksum", help="Accept lines with wrong checksums (still counted)."
    ),
    epoch_interval: str | None = typer.Option(
        None,
        "--epoch-interval",
        help="Spacing of reported DR epochs: 10min, or a sixth of a shorter reset (default).",
    ),
    variation: float | None = typer.Option(
        None,
        "--variation",
        help="Magnetic variation in degrees, east +, where the compass sends none.",
    ),
    fix_role: str | None = typer.Option(
        None, "--fix-role", help="DR restart fixes from gnss (default) or ins_mean."
    ),
) -> None:
    """Analyse a voyage: DR with honest 2M circles, INS deviations from the mean, current; reports."""
    from dracc.pipeline.analysis import analyse

    paths_exist(logs)
    cfg = build_config(
        config,
        interval=interval,
        window=window,
        dr_reset=dr_reset,
        probability=probability,
        roles=role,
        date=date,
        strict=strict,
        ignore_checksum=ignore_checksum,
        epoch_interval=epoch_interval,
        variation_deg=variation,
        fix_role=fix_role,
    )
    total = sum(p.stat().st_size for p in logs if p.is_file())
    with _gc_spares_loaded_code():
        with progress("analyze", 100.0) as advance:
            state = {"done": 0.0}
            weights = {
                "reading logs": 78.0,
                "sensor faults": 2.0,
                "dead reckoning": 8.0,
                "current": 4.0,
                "deviation statistics": 4.0,
                "calibration": 4.0,
            }
            offsets = {
                "reading logs": 0.0,
                "sensor faults": 78.0,
                "dead reckoning": 80.0,
                "current": 88.0,
                "deviation statistics": 92.0,
                "calibration": 96.0,
            }

            def on_progress(stage: str, fraction: float) -> None:
                target = offsets.get(stage, state["done"]) + weights.get(stage, 0.0) * min(
                    max(fraction, 0.0), 1.0
                )
                if target > state["done"]:
                    advance(target - state["done"])
                    state["done"] = target

            with keys_must_match(parse_roles(role)):  # a --role key that matches nothing: error
                result = analyse(logs, cfg, progress=on_progress, total_bytes=total)
        _write_reports(result, json_path, html_path, out_dir)
    QUICK_EXIT["on"] = True


@contextmanager
def _gc_spares_loaded_code() -> Iterator[None]:
    """Full garbage collections skip the objects that exist now (the loaded modules: some
    hundred thousand objects, walked again by every full collection while a day's log is
    analysed, 0.1 s); they are put back when the analysis ends."""
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


@contextmanager
def _writing(target) -> Iterator[None]:
    """OSError while writing ``target`` -> one line naming it (a closed stdout pipe passes)."""
    try:
        yield
    except BrokenPipeError:
        raise  # stdout closed by the reader (e.g. `| head`): not an error of ours
    except OSError as e:
        detail = f"{e.filename}: {e.strerror}" if e.filename and e.strerror else str(e)
        raise DraccError(f"cannot write {target}: {detail}") from e


def _write_reports(
    result, json_path: str | None, html_path: Path | None, out_dir: Path | None
) -> None:
    """The terminal summary (or the JSON on stdout), then the report files: each written in
    full to a temporary file and all renamed together at the end
    (:func:`dracc.core.atomic.together`), so that an interrupt while the plots are drawn
    leaves every earlier report as it was, not a new JSON beside an old HTML."""
    from dracc.report import html as html_report
    from dracc.report import json_report, tables, terminal

    said = []
    with _writing("the reports"), atomic.together():
        if json_path == "-":
            out.file.write(json_report.dumps(result))
            out.file.flush()
        else:
            terminal.print_summary(result, out)
            if json_path:
                with _writing(json_path):
                    json_report.write_json(result, json_path)
                said.append(f"wrote {json_path}")
        if html_path is not None:
            with _writing(html_path):
                html_report.write_html(result, html_path)
            said.append(f"wrote {html_path}")
        if out_dir is not None:
            with _writing(out_dir):
                written = tables.write_tables(result, out_dir)
            said.append(
                f"wrote {len(written)} tables to {out_dir}"
                if written
                else f"no tables to write to {out_dir} (no DR and no deviation statistics)"
            )
    for line in said:
        err.print(line, highlight=False, markup=False)
