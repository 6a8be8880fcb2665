"""``dracc analyze LOG...``: the main job — dead reckoning, INS deviations, current, reports.

The command merges its options into the configuration (:func:`build_config`), calls
:func:`dracc.pipeline.analysis.analyse` once, and hands the result to
:func:`dracc.report.write.write_reports`: a short summary on stdout (unless the JSON goes
there), ``--json`` (file or ``-``), ``--html`` (one offline file), ``--out`` (CSV and
Parquet tables) and the exports ``--gpx``, ``--kml``, ``--geojson`` and ``--mcap``.  Every
file is written atomically, and all of them appear together.
"""

from __future__ import annotations

import gc
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import typer

from dracc.cli.app import QUICK_EXIT, app, err, out, paths_exist, staged_progress
from dracc.cli.options import (
    ConfigFile,
    GeoJsonOut,
    GpxOut,
    HtmlOut,
    IgnoreChecksum,
    JsonOut,
    KmlOut,
    LogDate,
    LogFiles,
    McapOut,
    Roles,
    Strict,
    build_config,
    option_values,
    parse_roles,
)
from dracc.core.durations import parse_duration_s
from dracc.ingest.sources import keys_must_match
from dracc.ingest.timed_observations import read_timed_observations
from dracc.pipeline.results import EPOptions

__all__ = ["analyze", "build_config"]  # build_config: records_cmd's too (dracc.cli.options)

#: the analysis's stages and their shares of the progress bar (reading is most of the time)
STAGES = {
    "reading logs": 78.0,
    "sensor faults": 2.0,
    "dead reckoning": 8.0,
    "current": 4.0,
    "deviation statistics": 4.0,
    "calibration": 4.0,
}


@app.command("analyze")
def analyze(
    logs: LogFiles,
    config: ConfigFile = None,
    out_dir: Path | None = typer.Option(
        None,
        "--out",
        "-o",
        help="Write CSV and Parquet tables "
        "(DR track, DR epochs, deviation samples, per-unit statistics) here.",
    ),
    json_path: JsonOut = None,
    html_path: HtmlOut = None,
    gpx_path: GpxOut = None,
    kml_path: KmlOut = None,
    geojson_path: GeoJsonOut = None,
    mcap_path: McapOut = None,
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
    role: Roles = None,
    date: LogDate = None,
    strict: Strict = False,
    ignore_checksum: IgnoreChecksum = False,
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
    observations: Path | None = typer.Option(
        None,
        "--observations",
        help="TOML file of timed fixes, ranges, bearings and lines: "
        "each updates the fix-updated EP.",
    ),
    fix_interval: str | None = typer.Option(
        None,
        "--fix-interval",
        help="Update-interval study of the fix-updated EP: "
        "GNSS fix intervals, e.g. 300,600,1200,1800,3600 (or 5min,1h).",
    ),
) -> None:
    """Analyse a voyage: DR with honest 2M circles, INS deviations from the mean, current; reports."""
    from dracc.pipeline.analysis import analyse
    from dracc.report.write import write_reports

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
        with (
            staged_progress("analyze", STAGES) as on_progress,
            keys_must_match(parse_roles(role or [])),  # a --role key matching nothing: error
        ):
            result = analyse(
                logs,
                cfg,
                progress=on_progress,
                total_bytes=total,
                ep=_ep(observations, fix_interval),
            )
        for line in write_reports(
            result,
            out,
            json_path,
            html_path,
            out_dir,
            gpx_path=gpx_path,
            kml_path=kml_path,
            geojson_path=geojson_path,
            mcap_path=mcap_path,
        ):
            err.print(line, highlight=False, markup=False)
    QUICK_EXIT["on"] = True


def _ep(observations: Path | None, fix_interval: str | None) -> EPOptions:
    """The observation file read and the ``--fix-interval`` values parsed (seconds)."""
    with option_values():
        parts = [p for p in (fix_interval or "").split(",") if p.strip()]
        iv = tuple(parse_duration_s(p.strip(), "--fix-interval") for p in parts)
    return EPOptions(read_timed_observations(observations) if observations else (), iv)


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
