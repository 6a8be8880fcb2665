"""``dracc simulate``: a voyage with known truth, written as a log plus truth, errors and params."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
import pandas as pd
import typer

from .. import __version__
from ..atomic import atomic_path, write_text
from ..errors import ConfigError, DraccError
from .app import app, err

FORMATS = ("nmea", "csv-long", "csv-wide", "mcap-json", "mcap-ros2", "mcap-protobuf",
           "mcap-nmea")
EXT = {"nmea": "nmea", "csv-long": "csv", "csv-wide": "csv", "mcap-json": "mcap",
       "mcap-ros2": "mcap", "mcap-protobuf": "mcap", "mcap-nmea": "mcap"}


def write_log(voyage, path: Path, fmt: str, form: str = "tag", tag_time: str = "s") -> None:
    """Write the voyage's log in ``fmt`` (one of :data:`FORMATS`) to ``path``."""
    if fmt == "nmea":
        from ..sim.nmea_out import write_nmea

        write_nmea(voyage, path, form=form, tag_time=tag_time)
    elif fmt.startswith("csv-"):
        try:
            from ..sim.csv_out import write_csv
        except ImportError as e:
            raise DraccError(f"CSV output is not available in this build ({e})") from e
        write_csv(voyage.frames, path, form=fmt[4:])
    elif fmt.startswith("mcap-"):
        try:
            from ..sim.mcap_out import write_mcap
        except ImportError as e:
            raise DraccError(f"MCAP output is not available in this build ({e})") from e
        write_mcap(voyage.frames, voyage.roles, path, encoding=fmt[5:])
    else:
        raise ConfigError(f"--format must be one of {', '.join(FORMATS)}, got {fmt!r}")


def write_table(df: pd.DataFrame, path: Path) -> None:
    """A truth or error table as CSV: time_utc (ISO, ns) first, floats to 12 significant digits."""
    out = df.copy()
    out.insert(0, "time_utc", np.char.add(np.datetime_as_string(
        df["time_ns"].to_numpy().astype("datetime64[ns]"), unit="ns"), "Z"))
    with atomic_path(path) as tmp:
        out.to_csv(tmp, index=False, float_format="%.12g", lineterminator="\n")


def _decimate(df: pd.DataFrame, truth_hz: float, base_hz: float) -> pd.DataFrame:
    if truth_hz <= 0 or truth_hz >= base_hz:
        return df
    step = base_hz / truth_hz
    if abs(step - round(step)) > 1e-9:
        raise ConfigError(f"--truth-hz {truth_hz} does not divide the truth rate {base_hz} Hz")
    return df.iloc[:: int(round(step))]


@app.command("simulate")
def simulate_cmd(
    out_dir: Path = typer.Option(..., "--out", "-o", help="Output folder (created if missing)."),
    hours: float = typer.Option(4.0, "--hours", help="Duration of the voyage in hours."),
    seed: int = typer.Option(0, "--seed", help="Random seed: the same seed gives the same files."),
    start: str = typer.Option("2026-03-01T00:00:00Z", "--start", help="Start time, ISO 8601 UTC."),
    fmt: str = typer.Option("nmea", "--format", help="Log format: " + ", ".join(FORMATS) + "."),
    form: str = typer.Option("tag", "--form", help="NMEA line form: tag, prefix or bare."),
    tag_time: str = typer.Option("s", "--tag-time", help="TAG block c: time unit: s or ms."),
    compass: str = typer.Option("gyro", "--compass", help="Compass fitted: gyro, magnetic or both."),
    compass_hz: float = typer.Option(10.0, "--compass-hz", help="Compass heading rate (Hz)."),
    log_hz: float = typer.Option(1.0, "--log-hz", help="Speed log rate (Hz)."),
    ins_hz: float = typer.Option(1.0, "--ins-hz", help="INS output rate (Hz)."),
    gnss_hz: float = typer.Option(1.0, "--gnss-hz", help="GNSS output rate (Hz)."),
    aux_hz: float = typer.Option(1.0, "--aux-hz", help="Gyro THS and ROT rate (Hz; 0: none)."),
    lat_deg: float = typer.Option(54.60, "--lat", help="Start latitude, degrees (north +)."),
    lon_deg: float = typer.Option(18.80, "--lon", help="Start longitude, degrees (east +)."),
    speed_kn: float = typer.Option(12.0, "--speed-kn", help="Speed through the water, knots."),
    legs: str = typer.Option("", "--legs",
                             help="Headings steered: 'T_S:DEG,T_S:DEG,...' (seconds from the "
                                  "start, degrees true); default: generated from the seed."),
    ins_talkers: str = typer.Option("IN,IN,IN", "--ins-talkers",
                                    help="Talker IDs of INS1-3, e.g. II,IN,IR (tells them apart "
                                         "in prefix and bare forms, which carry no TAG source)."),
    ins_error_scale: float = typer.Option(1.0, "--ins-error-scale",
                                          help="Multiply every INS error amplitude."),
    gyro_error_deg: float = typer.Option(0.3, "--gyro-error-deg",
                                        help="Gyro compass constant error, degrees (reads high +)."),
    log_scale_pct: float = typer.Option(2.0, "--log-scale-pct", help="Speed log scale error, %."),
    log_bias_kn: float = typer.Option(0.05, "--log-bias-kn", help="Speed log bias, knots."),
    current_kn: float = typer.Option(0.5, "--current-kn", help="Mean current drift, knots."),
    current_set_deg: float = typer.Option(120.0, "--current-set-deg",
                                          help="Mean current set (towards), degrees true."),
    variation_deg: float = typer.Option(5.0, "--variation-deg",
                                        help="Magnetic variation, degrees (east +)."),
    noiseless: bool = typer.Option(False, "--noiseless",
                                   help="No sensor errors, current, leeway or yaw (the options "
                                        "above then only set the voyage, not its errors)."),
    truth_hz: float = typer.Option(1.0, "--truth-hz",
                                   help="Rate of truth.csv and errors.csv (0: every sample)."),
    name: str = typer.Option("voyage", "--name", help="Stem of the log file name."),
) -> None:
    """Simulate a voyage with known truth; write its log, truth.csv, errors.csv, params.json.

    The log is OUT/<name>.nmea (or .csv, .mcap); truth.csv and errors.csv hold the true
    track and every true sensor error (measured - true) at --truth-hz; params.json the
    parameters, the source roles and each INS unit's true error RMS.
    """
    from ..sim.model import SimParams, simulate

    if fmt not in FORMATS:
        raise ConfigError(f"--format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    if not (hours > 0 and math.isfinite(hours)):
        raise ConfigError(f"--hours must be positive, got {hours}")
    common = dict(legs=parse_legs(legs), ins_talkers=tuple(ins_talkers.split(",")), duration_s=hours * 3600.0, seed=seed, start_utc=start, start_lat_deg=lat_deg,
                  start_lon_deg=lon_deg, speed_kn=speed_kn, compass=compass,
                  compass_hz=compass_hz, log_hz=log_hz, ins_hz=ins_hz, gnss_hz=gnss_hz,
                  aux_hz=aux_hz, variation_deg=variation_deg, current_set_deg=current_set_deg)
    if noiseless:
        params = SimParams.noiseless(**common)
    else:
        params = SimParams(**common, gyro_offset_deg=gyro_error_deg,
                           log_scale=log_scale_pct / 100.0, log_bias_kn=log_bias_kn,
                           current_drift_kn=current_kn).with_ins_error_scale(ins_error_scale)
    t0 = time.perf_counter()
    voyage = simulate(params)
    t1 = time.perf_counter()
    log_path = out_dir / f"{name}.{EXT[fmt]}"
    write_log(voyage, log_path, fmt, form=form, tag_time=tag_time)
    t2 = time.perf_counter()
    base_hz = 1e9 / float(np.diff(voyage.truth["time_ns"].to_numpy()[:2])[0]) \
        if len(voyage.truth) > 1 else 1.0
    write_table(_decimate(voyage.truth, truth_hz, base_hz), out_dir / "truth.csv")
    write_table(_decimate(voyage.errors, truth_hz, base_hz), out_dir / "errors.csv")
    info = {
        "dracc_version": __version__,
        "format": fmt, "form": form if fmt == "nmea" else None,
        "tag_time": tag_time if fmt == "nmea" and form == "tag" else None,
        "files": {"log": log_path.name, "truth": "truth.csv", "errors": "errors.csv"},
        "roles": voyage.roles,
        "unit_rms": voyage.unit_rms,
        "records": {k: int(len(f)) for k, f in voyage.frames.items()},
        "params": params_dict(voyage.params),
    }
    write_text(out_dir / "params.json", json.dumps(info, indent=2) + "\n")
    size = log_path.stat().st_size
    err.print(f"simulated {hours:g} h in {t1 - t0:.1f} s, wrote {log_path} "
              f"({size / 1e6:.1f} MB) in {t2 - t1:.1f} s, truth.csv, errors.csv, params.json",
              highlight=False)


def params_dict(p) -> dict:
    """SimParams as JSON-ready data (see :meth:`SimParams.to_dict`)."""
    return p.to_dict()


def parse_legs(text: str) -> tuple[tuple[float, float], ...] | None:
    """``'0:60,3600:150'`` -> ((0.0, 60.0), (3600.0, 150.0)); '' -> None (generated)."""
    if not text.strip():
        return None
    legs = []
    for item in text.split(","):
        try:
            t_s, deg = (float(x) for x in item.split(":"))
        except ValueError as e:
            raise ConfigError(f"--legs: {item!r} is not T_S:DEG (e.g. 3600:150)") from e
        if not (math.isfinite(t_s) and math.isfinite(deg)):
            raise ConfigError(f"--legs: {item!r} is not finite")
        legs.append((t_s, deg))
    return tuple(legs)
