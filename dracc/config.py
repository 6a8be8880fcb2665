"""Configuration: a TOML file read as data (never executed) into frozen dataclasses.

Every section is optional; defaults are documented in the README and in
``docs/dracc.example.toml``.  Unknown keys are an error (a typo must not be
silently ignored).  Angles and speeds are given in the units navigators use
(degrees, knots) with the unit in the key name, and converted here.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field, fields, is_dataclass, replace
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from .errors import ConfigError
from .ingest.frames import ROLES


@dataclass(frozen=True)
class ErrorSource:
    """One sensor error process: first-order Gauss-Markov with standard deviation
    ``sigma`` (in the unit named by the field that holds it) and correlation time
    ``tau_s``; ``tau_s = inf`` is a bias (constant over the voyage), ``tau_s = 0`` white noise."""

    sigma: float
    tau_s: float = math.inf


@dataclass(frozen=True)
class IngestConfig:
    strict: bool = False  #: fail on the first rejected line
    ignore_checksum: bool = False  #: accept lines whose checksum is wrong (counted still)
    date: str | None = None  #: YYYY-MM-DD for logs that carry no date at all
    gap_s: float = 60.0  #: a time gap longer than this (per source and kind) is reported
    backstep_tolerance_s: float = 1.0  #: backward steps up to this are jitter, not events
    #: source key -> role, e.g. {"INS2": "ins2", "HE": "compass"}
    sources: dict[str, str] = field(default_factory=dict)
    #: CSV column / JSON field name -> quantity with unit (e.g. {"Speed (kn)": "stw_kn"}), for
    #: logs whose names do not carry the unit; see dracc.ingest.csv_quantities
    quantities: dict[str, str] = field(default_factory=dict)
    #: a line (NMEA sentence, CSV row) longer than this is cut and counted (reason
    #: 'too_long'): a damaged file costs memory bounded by this, not by its content
    max_line_bytes: int = 65536
    #: an MCAP chunk or record that inflates beyond this (or beyond its declared size) is
    #: rejected and counted, the rest of the file read (a decompression bomb)
    max_chunk_bytes: int = 64 * 1024 * 1024
    #: the peak memory dracc aims to stay under on damaged input (documented, benchmarked)
    memory_cap_mb: int = 512


@dataclass(frozen=True)
class DeadReckoningConfig:
    learn: bool = True  #: learn the errors and the current from the reference, causally (dracc.ep)
    #: restart from a fix: "auto" (1 h on logs of 8 h or more, shorter on short logs), a
    #: duration ("1h", "4h", "30min"), "watch" (4 h) or "never"
    reset: str = "auto"
    fix_role: str = "gnss"  #: where restart fixes come from: "gnss", "ins_mean"
    max_gap_s: float = 30.0  #: bridge heading/speed gaps up to this long; longer ones break the track
    epoch_interval_s: float | None = None  #: spacing of reported DR epochs (None: 10 min, shorter for short resets)
    variation_deg: float | None = None  #: magnetic variation (east +) where the log has none
    deviation_table: dict[str, float] = field(default_factory=dict)  #: heading_deg -> deviation_deg (east +)
    # Error sources (METHODS §2, §6).  Defaults from IMO performance standards,
    # treating the standards' limits as 95 % bounds (sigma = limit / 1.96).
    compass_bias_deg: ErrorSource = ErrorSource(0.75 / 1.96, math.inf)
    compass_noise_deg: ErrorSource = ErrorSource(0.2, 120.0)
    log_scale: ErrorSource = ErrorSource(0.02 / 1.96, math.inf)  #: fraction of speed
    log_bias_kn: ErrorSource = ErrorSource(0.2 / 1.96, math.inf)
    log_noise_kn: ErrorSource = ErrorSource(0.1, 300.0)
    #: per axis: a persistent current of the order of a knot (the prior of the learned EP)
    current_kn: ErrorSource = ErrorSource(0.7, 6 * 3600.0)
    leeway_deg: ErrorSource = ErrorSource(0.5, 1800.0)
    fix_sigma_m: float = 10.0  #: 1-sigma per axis of a restart fix when the source gives none


@dataclass(frozen=True)
class DeviationConfig:
    interval_s: float = 3600.0  #: sampling interval (K: 1 h, 2 h allowed)
    offset_s: float = 0.0  #: sampling instants at offset + k*interval from 00:00 UTC
    window_s: float = 86400.0  #: statistics windows (per day by default)
    kurtosis_windows_s: tuple[float, ...] = (86400.0, 172800.0, 259200.0)
    max_interp_gap_s: float = 120.0  #: a unit with no reading this close to an instant is missing there
    factor_lat: float = 1.32  #: (K5b) second approximation
    factor_lon: float = 1.49  #: empirical, Table 1
    factor_course: float = 1.49
    probability: float = 0.95  #: for limiting errors (K8)
    #: a priori RMS per unit and channel, e.g. {"ins1": {"lat_m": 300, "lon_m": 400, "course_deg": 0.1}}
    apriori: dict[str, dict[str, float]] = field(default_factory=dict)
    first_approximation: bool = False  #: (K5a) use sqrt(3/2) = 1.2247 for every channel instead
    confidence: float = 0.95  #: of the upper bound K_hm of an RMS (K8)
    correlation_time_s: float = 18000.0  #: INS error correlation time (paper: 4-6 h) -> N_eff, blocks
    min_kurtosis_samples: int = 12  #: a kurtosis window with fewer samples gives no upper bound
    kurtosis_tol: float = 0.05  #: kurtosis marks of Table 1: '=' within this
    hat_confidence: float = 0.90  #: three-cornered-hat bootstrap interval
    hat_draws: int = 1000  #: bootstrap draws
    seed: int = 0  #: bootstrap seed (reproducible reports)
    #: a unit whose nearer reading is further than this from an instant follows its own
    #: ground velocity (VTG/RMC) between its readings (the sag of the turn) instead of a line
    velocity_min_gap_s: float = 0.1


@dataclass(frozen=True)
class FaultsConfig:
    """Sensor-fault detection (dracc.faults); faults are always reported, excluded only if asked."""

    exclude: bool = False  #: keep flagged records out of the statistics (raw figures still shown)
    max_speed_kn: float = 60.0  #: a position step implying more than this is a jump ...
    jump_min_m: float = 500.0  #: ... when it is also longer than this
    frozen_min_s: float = 1800.0  #: a position repeated exactly for this long is frozen
    stuck_min_s: float = 600.0  #: a heading repeated exactly for this long is stuck
    min_records: int = 10  #: a frozen or stuck run needs at least this many records
    moving_min_kn: float = 1.0  #: other sources showing this speed prove the ship moved
    turn_min_deg: float = 5.0  #: other headings spanning this much prove the ship turned
    max_rot_deg_per_min: float = 600.0  #: a rate of turn beyond this is out of range


@dataclass(frozen=True)
class IntegrityConfig:
    """Integrity checks of every source (dracc.integrity): the ``[integrity]`` table."""

    #: false-alarm probability of each statistical check, per source and night
    false_alarm: float = 1e-3
    latency_max_s: float = 1.0  #: |receive time - time of fix| beyond this is late ...
    spell_min_s: float = 30.0  #: ... for this long (also: invalid-flag spells)
    dropout_cadences: float = 10.0  #: a gap of this many of the source's own intervals ...
    dropout_min_s: float = 60.0  #: ... and at least this long is a drop-out
    frozen_min_s: float = 120.0  #: bit-identical positions (or heading) this long while moving
    #: a position step within this is not a jump (IMO A.1046(27): 10 m, 95 %, for a receiver)
    jump_floor_m: float = 10.0
    consistency_interval_s: float = 10.0  #: instants at which sources are compared
    consistency_max_gap_s: float = 5.0  #: a source is interpolated across gaps up to this
    #: the heading consistency gate is never below this (a gyro's settle-point error is
    #: allowed 0.75 deg sec(lat) by IMO A.424(XI); 1 deg covers it to 41 deg latitude)
    heading_gate_min_deg: float = 1.0
    #: the INS/GNSS velocity consistency gate: 3 x the 0.2 kn of IMO A.824(19)
    velocity_gate_kn: float = 0.6


@dataclass(frozen=True)
class Config:
    ingest: IngestConfig = IngestConfig()
    dead_reckoning: DeadReckoningConfig = DeadReckoningConfig()
    deviation: DeviationConfig = DeviationConfig()
    faults: FaultsConfig = FaultsConfig()
    integrity: IntegrityConfig = IntegrityConfig()
    #: further sections (audit, fleet, report) as plain tables, validated by their owners
    extra: dict[str, Any] = field(default_factory=dict)


_KNOWN_EXTRA = {"audit", "fleet", "report", "vessel"}


def _build(cls, table: dict, where: str):
    """Build dataclass ``cls`` from a TOML table, rejecting unknown keys."""
    if not isinstance(table, dict):
        raise ConfigError(f"[{where}] must be a table, got {type(table).__name__}")
    known = {f.name: f for f in fields(cls)}
    unknown = set(table) - set(known)
    if unknown:
        raise ConfigError(f"[{where}] unknown key(s): {', '.join(sorted(unknown))}; known: {', '.join(sorted(known))}")
    kwargs = {}
    for name, value in table.items():
        default = getattr(cls(), name) if _has_defaults(cls) else None
        if isinstance(default, ErrorSource):
            kwargs[name] = _error_source(value, f"{where}.{name}")
        elif isinstance(default, tuple):
            kwargs[name] = tuple(float(v) for v in value)
        elif is_dataclass(default):
            kwargs[name] = _build(type(default), value, f"{where}.{name}")
        else:
            kwargs[name] = value
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as err:
        raise ConfigError(f"[{where}] {err}") from err


def _has_defaults(cls) -> bool:
    try:
        cls()
        return True
    except TypeError:
        return False


def _error_source(value, where: str) -> ErrorSource:
    if isinstance(value, (int, float)):
        return ErrorSource(float(value), math.inf)
    if isinstance(value, dict) and set(value) <= {"sigma", "tau_s"} and "sigma" in value:
        tau = value.get("tau_s", "inf")
        tau_s = math.inf if tau in ("inf", "infinity", None) else float(tau)
        return ErrorSource(float(value["sigma"]), tau_s)
    raise ConfigError(f"[{where}] must be a number (a bias) or {{sigma = …, tau_s = … | \"inf\"}}")


def validate(cfg: Config) -> Config:
    """Check cross-field rules; raise ConfigError naming the offending key."""
    for key, role in cfg.ingest.sources.items():
        if role not in ROLES:
            raise ConfigError(f"[ingest.sources] {key!r} = {role!r}: role must be one of {', '.join(ROLES)}")
    d = cfg.deviation
    if d.interval_s <= 0 or d.window_s <= 0:
        raise ConfigError("[deviation] interval_s and window_s must be positive")
    if not 0.5 <= d.probability < 1.0:
        raise ConfigError(f"[deviation] probability must be in [0.5, 1), got {d.probability}")
    for f in ("factor_lat", "factor_lon", "factor_course"):
        if getattr(d, f) <= 0:
            raise ConfigError(f"[deviation] {f} must be positive")
    for f in fields(IntegrityConfig):
        v = getattr(cfg.integrity, f.name)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise ConfigError(f"[integrity] {f.name} must be a positive number, got {v!r}")
    if not cfg.integrity.false_alarm < 0.5:
        raise ConfigError(f"[integrity] false_alarm is a probability below 0.5, got "
                          f"{cfg.integrity.false_alarm}")
    return cfg


def load_config(path: str | Path | None = None) -> Config:
    """Read a TOML config file (or return the defaults when ``path`` is None)."""
    if path is None:
        return Config()
    p = Path(path)
    try:
        with p.open("rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError as err:
        raise ConfigError(f"config file not found: {p}") from err
    except IsADirectoryError as err:
        raise ConfigError(f"config path is a directory: {p}") from err
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{p}: invalid TOML: {err}") from err
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(f"{p}: cannot read config: {err}") from err
    return config_from_dict(data, str(p))


def config_from_dict(data: dict, where: str = "config") -> Config:
    """Build a validated Config from a parsed TOML document."""
    sections = {"ingest": IngestConfig, "dead_reckoning": DeadReckoningConfig, "deviation": DeviationConfig,
                "faults": FaultsConfig, "integrity": IntegrityConfig}
    unknown = set(data) - set(sections) - _KNOWN_EXTRA
    if unknown:
        raise ConfigError(f"{where}: unknown section(s): {', '.join(sorted(unknown))}")
    kwargs: dict[str, Any] = {name: _build(cls, data[name], name) for name, cls in sections.items() if name in data}
    kwargs["extra"] = {k: v for k, v in data.items() if k in _KNOWN_EXTRA}
    return validate(Config(**kwargs))


def with_overrides(cfg: Config, section: str, **values) -> Config:
    """A copy of ``cfg`` with some keys of one section replaced (CLI options); None values are skipped."""
    values = {k: v for k, v in values.items() if v is not None}
    if not values:
        return cfg
    return validate(replace(cfg, **{section: replace(getattr(cfg, section), **values)}))
