"""``dracc simulate``: a voyage with known truth, written as a log plus truth, errors and params."""

from __future__ import annotations

import json
import math
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import typer

from dracc import __version__
from dracc.cli.app import app, err, options_only
from dracc.core.atomic import atomic_path, write_text
from dracc.core.errors import ConfigError, DraccError

FORMATS = ("nmea", "csv-long", "csv-wide", "mcap-json", "mcap-ros2", "mcap-protobuf", "mcap-nmea")
EXT = {
    "nmea": "nmea",
    "csv-long": "csv",
    "csv-wide": "csv",
    "mcap-json": "mcap",
    "mcap-ros2": "mcap",
    "mcap-protobuf": "mcap",
    "mcap-nmea": "mcap",
}


def write_log(voyage, path: Path, fmt: str, form: str = "tag", tag_time: str = "s") -> None:
    """Write the voyage's log in ``fmt`` (one of :data:`FORMATS`) to ``path``."""
    if fmt == "nmea":
        from dracc.sim.nmea_out import write_nmea

        write_nmea(voyage, path, form=form, tag_time=tag_time)
    elif fmt.startswith("csv-"):
        try:
            from dracc.sim.csv_out import write_csv
        except ImportError as e:
            raise DraccError(f"CSV output is not available in this build ({e})") from e
        write_csv(voyage.frames, path, form=fmt[4:])
    elif fmt.startswith("mcap-"):
        try:
            from dracc.sim.mcap_out import write_mcap
        except ImportError as e:
            raise DraccError(f"MCAP output is not available in this build ({e})") from e
        write_mcap(voyage.frames, voyage.roles, path, encoding=fmt[5:])
    else:
        raise ConfigError(f"--format must be one of {', '.join(FORMATS)}, got {fmt!r}")


def write_table(df: pd.DataFrame, fh, header: bool = True) -> None:
    """A truth or error table as CSV into an open text file: time_utc (ISO, ns) first,
    floats to 12 significant digits."""
    out = df.copy()
    out.insert(
        0,
        "time_utc",
        np.char.add(
            np.datetime_as_string(df["time_ns"].to_numpy().astype("datetime64[ns]"), unit="ns"), "Z"
        ),
    )
    out.to_csv(fh, index=False, header=header, float_format="%.12g", lineterminator="\n")


def decimate(df: pd.DataFrame, truth_hz: float, base_hz: float, start_ns: int) -> pd.DataFrame:
    """Rows at ``start + k / truth_hz`` (all rows for ``truth_hz <= 0`` or faster than the data)."""
    if truth_hz <= 0 or truth_hz >= base_hz:
        return df
    step = base_hz / truth_hz
    if abs(step - round(step)) > 1e-9:
        raise ConfigError(f"--truth-hz {truth_hz} does not divide the truth rate {base_hz} Hz")
    step_ns = int(round(1e9 / truth_hz))
    return df[(df["time_ns"].to_numpy() - start_ns) % step_ns == 0]


@app.command("simulate")
@options_only  # no configuration file: a ConfigError here is a bad option value (exit 2)
def simulate_cmd(
    out_dir: Path = typer.Option(..., "--out", "-o", help="Output folder (created if missing)."),
    hours: float = typer.Option(4.0, "--hours", help="Duration of the voyage in hours."),
    seed: int = typer.Option(0, "--seed", help="Random seed: the same seed gives the same files."),
    start: str = typer.Option("2026-03-01T00:00:00Z", "--start", help="Start time, ISO 8601 UTC."),
    fmt: str = typer.Option("nmea", "--format", help="Log format: " + ", ".join(FORMATS) + "."),
    form: str = typer.Option("tag", "--form", help="NMEA line form: tag, prefix or bare."),
    tag_time: str = typer.Option(
        "auto",
        "--tag-time",
        help="TAG block c: time unit: s, ms, or auto (ms when a sensor "
        "writes faster than 1 Hz, else s).",
    ),
    compass: str = typer.Option(
        "gyro", "--compass", help="Compass fitted: gyro, magnetic or both."
    ),
    compass_hz: float = typer.Option(10.0, "--compass-hz", help="Compass heading rate (Hz)."),
    log_hz: float = typer.Option(1.0, "--log-hz", help="Speed log rate (Hz)."),
    ins_hz: float = typer.Option(1.0, "--ins-hz", help="INS output rate (Hz)."),
    gnss_hz: float = typer.Option(1.0, "--gnss-hz", help="GNSS output rate (Hz)."),
    aux_hz: float = typer.Option(1.0, "--aux-hz", help="Gyro THS and ROT rate (Hz; 0: none)."),
    lat_deg: float = typer.Option(54.60, "--lat", help="Start latitude, degrees (north +)."),
    lon_deg: float = typer.Option(18.80, "--lon", help="Start longitude, degrees (east +)."),
    speed_kn: float = typer.Option(12.0, "--speed-kn", help="Speed through the water, knots."),
    legs: str = typer.Option(
        "",
        "--legs",
        help="Headings steered: 'T_S:DEG,T_S:DEG,...' (seconds from the "
        "start, degrees true); default: generated from the seed.",
    ),
    ins_talkers: str = typer.Option(
        "IN,IN,IN",
        "--ins-talkers",
        help="Talker IDs of INS1-3, e.g. II,IN,IR (tells them apart "
        "in prefix and bare forms, which carry no TAG source).",
    ),
    ins_error_scale: float = typer.Option(
        1.0, "--ins-error-scale", help="Multiply every INS error amplitude."
    ),
    gyro_error_deg: float = typer.Option(
        0.3, "--gyro-error-deg", help="Gyro compass constant error, degrees (reads high +)."
    ),
    log_scale_pct: float = typer.Option(2.0, "--log-scale-pct", help="Speed log scale error, %."),
    log_bias_kn: float = typer.Option(0.05, "--log-bias-kn", help="Speed log bias, knots."),
    current_kn: float = typer.Option(0.5, "--current-kn", help="Mean current drift, knots."),
    current_set_deg: float = typer.Option(
        120.0, "--current-set-deg", help="Mean current set (towards), degrees true."
    ),
    variation_deg: float = typer.Option(
        5.0, "--variation-deg", help="Magnetic variation, degrees (east +)."
    ),
    noiseless: bool = typer.Option(
        False,
        "--noiseless",
        help="No sensor errors, current, leeway or yaw (the options "
        "above then only set the voyage, not its errors).",
    ),
    truth_hz: float = typer.Option(
        1.0, "--truth-hz", help="Rate of truth.csv and errors.csv (0: every sample)."
    ),
    name: str = typer.Option("voyage", "--name", help="Stem of the log file name."),
    segment_hours: float = typer.Option(
        6.0,
        "--segment-hours",
        help="NMEA: simulate and write in segments of this "
        "length, so memory does not grow with --hours.",
    ),
    fault: list[str] = typer.Option(
        [],
        "--fault",
        metavar="KIND[:SOURCE][@START][+DURATION][=SIZE]",
        help="Seed a sensor fault (repeatable): KIND jump, freeze, "
        "dropout, drift, latency or invalid, e.g. "
        "jump:GNSS@2h=670m, freeze:INS2@1.5h+40min, "
        "dropout:INS3+25min, drift:INS1=1kn, latency:GNSS=3s, "
        "invalid:GNSS+10min (docs/simulate.md).",
    ),
) -> None:
    """Simulate a voyage with known truth; write its log, truth.csv, errors.csv, params.json.

    The log is OUT/<name>.nmea (or .csv, .mcap); truth.csv and errors.csv hold the true
    track and every true sensor error (measured - true) at --truth-hz; params.json the
    parameters, the source roles, each INS unit's true error RMS and the seeded faults.
    """
    from dracc.sim.faults import fault_table, parse_fault, resolve_faults
    from dracc.sim.model import SimParams, generated_legs, simulate, simulate_segments, start_ns

    if fmt not in FORMATS:
        raise ConfigError(f"--format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    if not (hours > 0 and math.isfinite(hours)):
        raise ConfigError(f"--hours must be positive, got {hours}")
    common = dict(
        legs=parse_legs(legs),
        ins_talkers=tuple(ins_talkers.split(",")),
        duration_s=hours * 3600.0,
        seed=seed,
        start_utc=start,
        start_lat_deg=lat_deg,
        start_lon_deg=lon_deg,
        speed_kn=speed_kn,
        compass=compass,
        compass_hz=compass_hz,
        log_hz=log_hz,
        ins_hz=ins_hz,
        gnss_hz=gnss_hz,
        aux_hz=aux_hz,
        variation_deg=variation_deg,
        current_set_deg=current_set_deg,
    )
    if noiseless:
        params = SimParams.noiseless(**common)
    else:
        params = SimParams(
            **common,
            gyro_offset_deg=gyro_error_deg,
            log_scale=log_scale_pct / 100.0,
            log_bias_kn=log_bias_kn,
            current_drift_kn=current_kn,
        ).with_ins_error_scale(ins_error_scale)
    if not segment_hours > 0:
        raise ConfigError(f"--segment-hours must be positive, got {segment_hours}")
    if form not in ("tag", "prefix", "bare") or tag_time not in ("s", "ms", "auto"):
        raise ConfigError(
            f"--form must be tag, prefix or bare and --tag-time s, ms or auto, "
            f"got {form!r}, {tag_time!r}"
        )
    if tag_time == "auto":
        # whole seconds would give every sub-second sentence its neighbour's time
        tag_time = "ms" if max(compass_hz, log_hz, ins_hz, gnss_hz, aux_hz) > 1.0 else "s"
    params = replace(params, legs=generated_legs(params))
    specs = list(fault or [])
    params = replace(
        params,
        faults=resolve_faults(
            [parse_fault(f) for f in specs],
            params.duration_s,
            params.seed,
            params.compass,
            labels=specs,
        ),
    )
    base_hz = max(compass_hz, log_hz, ins_hz, gnss_hz, aux_hz)
    t0_ns = start_ns(params.start_utc)
    log_path = out_dir / f"{name}.{EXT[fmt]}"
    t0 = time.perf_counter()
    records: Counter = Counter()
    sq = {u: {"lat_m": 0.0, "lon_m": 0.0, "course_deg": 0.0} for u in ("ins1", "ins2", "ins3")}
    count = dict.fromkeys(sq, 0)
    roles: dict = {}
    with (
        atomic_path(out_dir / "truth.csv") as tt,
        atomic_path(out_dir / "errors.csv") as te,
        open(tt, "w", encoding="utf-8") as ft,
        open(te, "w", encoding="utf-8") as fe,
    ):
        if fmt == "nmea":
            from dracc.sim.nmea_out import iter_blocks

            with atomic_path(log_path) as tl, open(tl, "wb") as fl:
                for i, v in enumerate(simulate_segments(params, segment_hours * 3600.0)):
                    for _, _, blob in iter_blocks(v.frames, v.roles, form=form, tag_time=tag_time):
                        fl.write(blob)
                    _tables_and_tallies(v, i, ft, fe, truth_hz, base_hz, t0_ns, records, sq, count)
                    roles = v.roles
        else:
            v = simulate(params)
            write_log(v, log_path, fmt)
            _tables_and_tallies(v, 0, ft, fe, truth_hz, base_hz, t0_ns, records, sq, count)
            roles = v.roles
    t1 = time.perf_counter()
    unit_rms = {
        u: {ch: math.sqrt(s / count[u]) if count[u] else float("nan") for ch, s in sq[u].items()}
        for u in sq
    }
    info = {
        "dracc_version": __version__,
        "format": fmt,
        "form": form if fmt == "nmea" else None,
        "tag_time": tag_time if fmt == "nmea" and form == "tag" else None,
        "files": {"log": log_path.name, "truth": "truth.csv", "errors": "errors.csv"},
        "roles": roles,
        "unit_rms": unit_rms,
        "records": dict(records),
        "faults": fault_table(params.faults, t0_ns, params.duration_s, roles),
        "params": params_dict(params),
    }
    write_text(out_dir / "params.json", json.dumps(info, indent=2) + "\n")
    size = log_path.stat().st_size
    faults_txt = (
        f"; faults: {', '.join(f.describe() for f in params.faults)}" if params.faults else ""
    )
    err.print(
        f"simulated {hours:g} h and wrote {log_path} ({size / 1e6:.1f} MB), truth.csv, "
        f"errors.csv, params.json in {t1 - t0:.1f} s{faults_txt}",
        highlight=False,
        markup=False,
        emoji=False,
    )


def _tables_and_tallies(v, i, ft, fe, truth_hz, base_hz, t0_ns, records, sq, count) -> None:
    """Append one segment's truth and errors; add up its records and INS squared errors."""
    write_table(decimate(v.truth, truth_hz, base_hz, t0_ns), ft, header=i == 0)
    write_table(decimate(v.errors, truth_hz, base_hz, t0_ns), fe, header=i == 0)
    for kind, f in v.frames.items():
        records[kind] += len(f)
    pos = v.frames["position"]
    for u in sq:
        n = int((pos["source"] == u.upper()).sum())
        if n == 0:  # a short last segment may hold no INS sample
            continue
        count[u] += n
        for ch, rms in v.unit_rms[u].items():
            sq[u][ch] += n * rms**2


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
