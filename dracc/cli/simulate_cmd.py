"""``dracc simulate``: a voyage with known truth, written as a log plus truth, errors and params.

The files are made by :func:`dracc.sim.output.simulate_to_folder` (imported when the
command runs: the simulator loads scipy).
"""

from __future__ import annotations

from pathlib import Path

import typer

from dracc.cli.app import app, err
from dracc.cli.options import options_only


@app.command("simulate")
@options_only  # no configuration file: a ConfigError here is a bad option value (exit 2)
def simulate_cmd(
    out_dir: Path = typer.Option(..., "--out", "-o", help="Output folder (created if missing)."),
    hours: float = typer.Option(4.0, "--hours", help="Duration of the voyage in hours."),
    seed: int = typer.Option(0, "--seed", help="Random seed: the same seed gives the same files."),
    start: str = typer.Option("2026-03-01T00:00:00Z", "--start", help="Start time, ISO 8601 UTC."),
    fmt: str = typer.Option(
        "nmea",
        "--format",
        help="Log format: nmea, csv-long, csv-wide, mcap-json, mcap-ros2, mcap-protobuf, mcap-nmea.",
    ),
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
    ins_unit_scales: str = typer.Option(
        "1,1,1",
        "--ins-unit-scales",
        help="Multiply the error amplitudes of INS1,INS2,INS3 (after --ins-error-scale), "
        "e.g. 1,3,1 for an INS2 three times worse.",
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
        "invalid:GNSS+10min; time faults leap:GNSS=18s, rollover:GNSS, "
        "loop:ALL@2h=22min, clockstep:ALL@2h+1h=-22min (docs/simulate.md).",
    ),
    clocks: str = typer.Option(
        "none",
        "--clocks",
        help="Sources' clocks: none (every source samples the same grid, no delay) or "
        "random (a phase and a latency per source from --seed).",
    ),
    latency_max: float = typer.Option(
        2.0, "--latency-max", help="--clocks random: latency at most this, s (GNSS 0.5 s)."
    ),
    phase: list[str] = typer.Option(
        [], "--phase", metavar="SRC=S", help="A source's sample phase in s (repeatable)."
    ),
    latency: list[str] = typer.Option(
        [],
        "--latency",
        metavar="SRC=S",
        help="A source's delay from sampling to the logger in s (repeatable).",
    ),
) -> None:
    """Simulate a voyage with known truth; write its log, truth.csv, errors.csv, params.json.

    The log is OUT/<name>.nmea (or .csv, .mcap); truth.csv and errors.csv hold the true
    track and every true sensor error (measured - true) at --truth-hz; params.json the
    parameters, the source roles, each INS unit's true error RMS, the seeded faults and
    each source's clock.
    """
    options = dict(locals())  # every option, by its name, as simulate_to_folder takes it
    from dracc.sim.output import simulate_to_folder

    written = simulate_to_folder(**options)
    size = written.log_path.stat().st_size
    faults_txt = (
        f"; faults: {', '.join(f.describe() for f in written.faults)}" if written.faults else ""
    )
    err.print(
        f"simulated {hours:g} h and wrote {written.log_path} ({size / 1e6:.1f} MB), truth.csv, "
        f"errors.csv, params.json in {written.seconds:.1f} s{faults_txt}",
        highlight=False,
        markup=False,
        emoji=False,
    )
