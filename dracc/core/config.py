"""Configuration: a TOML file read as data (never executed) into frozen dataclasses.

Every section is optional; defaults are documented in the README and in
``docs/dracc.example.toml``.  Unknown keys are an error (a typo must not be
silently ignored), and so is a value of the wrong type or out of range: every key
of every section is checked when the file is read (:func:`validate`), against the type
its dataclass field is annotated with (a TOML boolean for ``bool``, a number for
``float``, an integer for ``int`` ...) and the range in ``_RULES``, and a wrong one is a
ConfigError (exit 4) naming ``[section] key``.  Angles and speeds are given in the units
navigators use (degrees, knots) with the unit in the key name, and converted here.
"""

from __future__ import annotations

import datetime as _dt
import functools
import json
import math
import re
import sys
import types
import typing
from collections.abc import Callable, Collection
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, TypeGuard, cast

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from dracc.core.bounds import (
    DAY_S,
    FACTOR,
    FINITE,
    HALF_TO_ONE,
    MAX_CONFIG_BYTES,
    MAX_ITEMS,
    NON_NEGATIVE,
    RESET_S,
    SIGMA_M,
    SIGMAS,
    SPEED_KN,
    STEP_S,
    TAU_S,
    UP_TO_A_DAY,
    UP_TO_A_YEAR,
    YEAR_S,
    ZERO_TO_A_DAY,
    Range,
    within,
)
from dracc.core.durations import parse_reset_s
from dracc.core.errors import ConfigError
from dracc.core.quantities import QUANTITIES
from dracc.core.reference_config import (
    BerthConfig,
    ReferenceConfig,
    check_abeam,
    check_alongside,
    check_berth,
    check_pier,
    check_utc,
    one_or_many,
    toml_datetime,
)
from dracc.core.source_config import source_latencies
from dracc.core.vocabulary import CHANNEL_KEYS, INS_ROLES, ROLES


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
    #: a compressed log decompressing to more than this many times its size (and more than
    #: 256 MiB) stops the read: a decompression bomb (dracc.ingest.compressed)
    max_inflate_ratio: float = 200.0
    #: the disk a temporary copy of a compressed log (a format read from a file: MCAP,
    #: CSV, Signal K ...) or of standard input may take
    temp_cap_mb: int = 4096


@dataclass(frozen=True)
class DeadReckoningConfig:
    learn: bool = (
        True  #: learn the errors and the current from the reference, causally (dracc.math.ep)
    )
    #: restart from a fix: "auto" (1 h on logs of 8 h or more, shorter on short logs), a
    #: duration ("1h", "4h", "30min"), "watch" (4 h) or "never"
    reset: str = "auto"
    fix_role: str = "gnss"  #: where restart fixes come from: "gnss", "ins_mean"
    max_gap_s: float = (
        30.0  #: bridge heading/speed gaps up to this long; longer ones break the track
    )
    epoch_interval_s: float | None = (
        None  #: spacing of reported DR epochs (None: 10 min, shorter for short resets)
    )
    variation_deg: float | None = None  #: magnetic variation (east +) where the log has none
    deviation_table: dict[str, float] = field(
        default_factory=dict
    )  #: heading_deg -> deviation_deg (east +)
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
    max_interp_gap_s: float = (
        120.0  #: a unit with no reading this close to an instant is missing there
    )
    factor_lat: float = 1.32  #: (K5b) second approximation
    factor_lon: float = 1.49  #: empirical, Table 1
    factor_course: float = 1.49
    probability: float = 0.95  #: for limiting errors (K8)
    #: a priori RMS per unit and channel, e.g. {"ins1": {"lat_m": 300, "lon_m": 400, "course_deg": 0.1}}
    apriori: dict[str, dict[str, float]] = field(default_factory=dict)
    first_approximation: bool = False  #: (K5a) use sqrt(3/2) = 1.2247 for every channel instead
    confidence: float = 0.95  #: of the upper bound K_hm of an RMS (K8)
    correlation_time_s: float = (
        18000.0  #: INS error correlation time (paper: 4-6 h) -> N_eff, blocks
    )
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
    """Sensor-fault detection (dracc.math.faults); faults are always reported, excluded only if asked."""

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
    """Integrity checks of every source (dracc.math.integrity): the ``[integrity]`` table."""

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
    #: a time of fix ahead of the logger clock by this much (at least the resolution of the
    #: logger's stamps) for ``spell_min_s`` is a clock offset no delay makes (time/leap_second)
    clock_ahead_min_s: float = 0.5
    #: a receiver's time of fix drifting against the logger clock matters when the offset
    #: changes by more than this over the night (time/clock_drift)
    clock_drift_max_s: float = 1.0
    #: the logger's times going back by more than this is a clock step (time/backstep, loop)
    backstep_min_s: float = 1.0


@dataclass(frozen=True)
class Config:
    ingest: IngestConfig = IngestConfig()
    dead_reckoning: DeadReckoningConfig = DeadReckoningConfig()
    deviation: DeviationConfig = DeviationConfig()
    faults: FaultsConfig = FaultsConfig()
    integrity: IntegrityConfig = IntegrityConfig()
    reference: ReferenceConfig = field(default_factory=ReferenceConfig)
    #: further sections (audit, fleet, report, vessel, sources) as plain tables, validated by their
    #: owners (dracc.pipeline.audit.audit_config, dracc.pipeline.fleet.fleet_config); here only: each is a table
    extra: dict[str, Any] = field(default_factory=dict)


_KNOWN_EXTRA = {"audit", "fleet", "report", "vessel", "sources"}
_SECTIONS: dict[str, type] = {
    "ingest": IngestConfig,
    "dead_reckoning": DeadReckoningConfig,
    "deviation": DeviationConfig,
    "faults": FaultsConfig,
    "integrity": IntegrityConfig,
    "reference": ReferenceConfig,
}


def _build(cls: type[Any], table: object, where: str) -> Any:
    """Dataclass ``cls`` from a TOML table, rejecting unknown keys; the values are checked
    and converted by :func:`validate` (the one place that knows the schema)."""
    if not isinstance(table, dict):
        raise ConfigError(f"[{where}] must be a table, got {_kind(table)}")
    _no_unknown(table, [f.name for f in fields(cls)], where)
    return cls(**table)


def _no_unknown(table: dict[Any, Any], known: Collection[str], where: str) -> None:
    unknown = set(table) - set(known)
    if unknown:
        raise ConfigError(
            f"[{where}] unknown key(s): {', '.join(sorted(map(str, unknown)))}; "
            f"known: {', '.join(sorted(known))}"
        )


# --------------------------------------------------------------------------------------
# The schema: each field's type comes from its annotation, its range from _RULES
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Rule:
    """What a field accepts beyond its annotated type.

    ``range``: bounds of the number (of each element of an array, each value of a table);
    ``check(value, section, key) -> value``: a rule on the typed value (names, forms);
    ``before(value) -> value``: a conversion of the raw TOML value before the type check."""

    range: Range | None = None
    check: Callable[[Any, str, str], Any] | None = None
    before: Callable[[Any], Any] | None = None


_TYPE_ONLY = _Rule()


def _key(k: object) -> str:
    """A key as TOML writes it: bare where it can be, else quoted."""
    k = str(k)
    return (
        k if re.fullmatch(r"[A-Za-z0-9_-]+(\[[0-9]+\])?", k) else json.dumps(k, ensure_ascii=False)
    )


def _show(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _kind(value: object) -> str:
    """The TOML name of a value's type, for 'got ...'."""
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int):
        return "an integer"
    if isinstance(value, float):
        return "a float"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, (list, tuple)):
        return "an array"
    if isinstance(value, dict):
        return "a table"
    if isinstance(value, _dt.datetime):
        return "a date-time"
    if isinstance(value, _dt.date):
        return "a date"
    if isinstance(value, _dt.time):
        return "a time"
    return type(value).__name__


def _fail(section: str, key: str, value: object, what: str) -> ConfigError:
    return ConfigError(f"[{section}] {_key(key)} = {_show(value)}: {what}")


def _wrong(section: str, key: str, value: object, expected: str) -> ConfigError:
    return _fail(section, key, value, f"expected {expected}, got {_kind(value)}")


def _is_number(value: object) -> TypeGuard[int | float]:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _number(value: object, section: str, key: str, rng: Range | None) -> float:
    if not _is_number(value):
        raise _wrong(section, key, value, "a number")
    v = float(value)
    if not math.isfinite(v):
        raise _fail(section, key, value, "must be a finite number")
    if rng is not None and not rng.holds(v):
        raise _fail(section, key, value, f"must be {rng.text}")
    return v


def _integer(value: object, section: str, key: str, rng: Range | None) -> int:
    if isinstance(value, float) and math.isfinite(value) and value.is_integer():
        value = int(value)  # 1e3 is an integer; 1.5 is not
    if isinstance(value, bool) or not isinstance(value, int):
        raise _wrong(section, key, value, "an integer")
    if rng is not None and not rng.holds(value):
        raise _fail(section, key, value, f"must be {rng.text}")
    return value


def _tau(value: object, section: str, key: str) -> float:
    if isinstance(value, str) and value.strip().lower() in ("inf", "infinity"):
        return math.inf
    if not _is_number(value):
        raise _wrong(section, key, value, 'a correlation time in seconds (>= 0) or "inf"')
    v = float(value)
    if v == math.inf:
        return v
    if not TAU_S.holds(v):  # NaN too
        raise _fail(section, key, value, f'must be {TAU_S.text} (0: white noise, "inf": a bias)')
    return v


_SOURCE_FORM = 'a number (a bias) or a table {sigma = ..., tau_s = ... | "inf"}'


def _error_source(value: object, section: str, key: str, rng: Range | None = None) -> ErrorSource:
    """An ErrorSource from a number (a bias), a table {sigma, tau_s} or an ErrorSource;
    ``rng``: the sigma's range."""
    inner = f"{section}.{_key(key)}"
    rng = rng or NON_NEGATIVE
    if _is_number(value):
        return ErrorSource(_number(value, section, key, rng), math.inf)
    if isinstance(value, ErrorSource):
        sigma, tau = value.sigma, value.tau_s
    elif isinstance(value, dict):
        _no_unknown(value, ("sigma", "tau_s"), inner)
        if "sigma" not in value:
            raise ConfigError(f"[{inner}] sigma is missing: expected {_SOURCE_FORM}")
        sigma, tau = value["sigma"], value.get("tau_s", math.inf)
    else:
        raise _wrong(section, key, value, _SOURCE_FORM)
    return ErrorSource(_number(sigma, inner, "sigma", rng), _tau(tau, inner, "tau_s"))


def _describe(tp: Any) -> str:
    if tp is bool:
        return "true or false"
    if tp is int:
        return "an integer"
    if tp is float:
        return "a number"
    if tp is BerthConfig:
        return "a berth table"
    if tp is str:
        return "a string"
    origin = typing.get_origin(tp)
    if origin is dict:
        return "a table"
    if origin is tuple:
        return f"an array of {_describe(typing.get_args(tp)[0])[2:]}s"
    return cast(str, tp.__name__)


def _typed(value: object, tp: Any, section: str, key: str, rng: Range | None) -> Any:
    """``value`` checked against the annotation ``tp`` (and numbers against ``rng``), converted
    to it: an int where a float belongs becomes a float, an array a tuple."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        (inner,) = [a for a in args if a is not type(None)]
        return _typed(value, inner, section, key, rng)
    if tp is bool:
        if not isinstance(value, bool):
            raise _wrong(section, key, value, "true or false")
        return value
    if tp is float:
        return _number(value, section, key, rng)
    if tp is int:
        return _integer(value, section, key, rng)
    if tp is str:
        if not isinstance(value, str):
            raise _wrong(section, key, value, "a string")
        return value
    if tp is ErrorSource:
        return _error_source(value, section, key, rng)
    if tp is BerthConfig:
        return _berth(value, section, key)
    if (
        origin in (tuple, dict)
        and isinstance(value, (list, tuple, dict))
        and len(value) > MAX_ITEMS
    ):
        raise _fail(section, key, f"<{len(value):,} items>", f"at most {MAX_ITEMS:,} items")
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise _wrong(section, key, value, _describe(tp))
        return tuple(_typed(v, args[0], section, f"{key}[{i}]", rng) for i, v in enumerate(value))
    if origin is dict:
        if not isinstance(value, dict):
            raise _wrong(section, key, value, _describe(tp))
        inner = f"{section}.{_key(key)}"
        return {k: _typed(v, args[1], inner, k, rng) for k, v in value.items()}
    raise TypeError(f"no schema for {tp!r}")  # pragma: no cover - a new annotation


# -------------------------------------------------------------- rules on names and forms


def _toml_date(value: object) -> object:
    """A TOML date (``date = 2026-03-01``, unquoted) is the date its text names."""
    if isinstance(value, _dt.date) and not isinstance(value, _dt.datetime):
        return value.isoformat()
    return value


def _check_date(value: str | None, section: str, key: str) -> str | None:
    if value is None:
        return None
    try:
        if not re.fullmatch(r"\d{4}-\d{2}-\d{2}", value.strip()):
            raise ValueError
        return _dt.date.fromisoformat(value.strip()).isoformat()
    except ValueError:
        raise _fail(section, key, value, 'expected a date "YYYY-MM-DD"') from None


def _check_roles(table: dict[str, str], section: str, key: str) -> dict[str, str]:
    for src, role in table.items():
        if role not in ROLES:
            raise ConfigError(
                f"[{section}.{key}] {src!r} = {role!r}: role must be one of {', '.join(ROLES)}"
            )
    return table


def _check_quantities(table: dict[str, str], section: str, key: str) -> dict[str, str]:
    for col, q in table.items():
        if q not in QUANTITIES:
            raise ConfigError(
                f"[{section}.{key}] {_key(col)} = {q!r}: not a quantity name; "
                f"known: {', '.join(sorted(QUANTITIES))}"
            )
    return table


def _check_reset(value: str, section: str, key: str) -> str:
    if value.strip().lower() != "auto":
        try:
            reset_s = parse_reset_s(value)
        except ConfigError:
            raise _fail(
                section,
                key,
                value,
                'expected "auto", "watch", "never" or a positive '
                'duration such as "1h", "4h", "30min", "90s"',
            ) from None
        if math.isfinite(reset_s) and not RESET_S.holds(reset_s):  # a leg every 10 ms: 8.6 M a day
            raise _fail(section, key, value, f'must be a duration {RESET_S.text}, or "never"')
    return value


def _one_of(*choices: str) -> Callable[[Any, str, str], Any]:
    def check(value: Any, section: str, key: str) -> Any:
        if value not in choices:
            raise _fail(section, key, value, f"expected one of {', '.join(map(repr, choices))}")
        return value

    return check


def _check_deviation_table(table: dict[str, float], section: str, key: str) -> dict[str, float]:
    """Headings (the keys) are numbers of degrees in [0, 360], each heading once (0 and 360
    are one heading); deviations (degrees, east +) within +-180 (the range checks them)."""
    where = f"{section}.{key}"
    seen: dict[float, tuple[str, float]] = {}
    for heading, dev in table.items():
        try:
            h = float(heading)
        except ValueError:
            h = math.nan
        if not 0.0 <= h <= 360.0:
            raise ConfigError(
                f"[{where}] {_key(heading)} = {_show(dev)}: the key is a compass "
                "heading in degrees, a number in [0, 360]"
            )
        h %= 360.0
        if h in seen and seen[h][1] != dev:
            raise ConfigError(
                f"[{where}] heading {_key(heading)} given twice with different "
                f"deviations (as {_key(seen[h][0])}; 0 and 360 are the same heading)"
            )
        seen[h] = (heading, dev)
    return table


#: the channels of an a priori RMS
_APRIORI_KEYS = tuple(sorted(CHANNEL_KEYS.values()))


def _check_apriori(
    table: dict[str, dict[str, float]], section: str, key: str
) -> dict[str, dict[str, float]]:
    for unit, values in table.items():
        if unit not in INS_ROLES:
            raise ConfigError(
                f"[{section}.{key}] {_key(unit)} = {_show(values)}: unit must be one "
                f"of {', '.join(INS_ROLES)}"
            )
        _no_unknown(values, _APRIORI_KEYS, f"{section}.{key}.{_key(unit)}")
    return table


def _berth(value: object, section: str, key: str) -> BerthConfig:
    """One berth of ``[reference] alongside``: its keys and values checked as a section's
    are (:func:`_section`), then its own rules (:func:`check_berth`).  A berth already
    built (a validated configuration validated again, as every command's options are
    merged) is checked as the table of its fields: one path, so :func:`validate` is
    idempotent."""
    where = f"{section}.{_key(key)}"
    if isinstance(value, BerthConfig):
        value = {f.name: getattr(value, f.name) for f in fields(BerthConfig)}
    if not isinstance(value, dict):
        raise _wrong(
            section, key, value, "a table {pier = [...], side = ..., half_breadth_m = ...}"
        )
    _no_unknown(value, [f.name for f in fields(BerthConfig)], where)
    for name in ("pier", "side", "half_breadth_m"):
        if name not in value:
            raise ConfigError(
                f"[{where}] {name} is missing: a berth needs pier = [LAT1, LON1, LAT2, LON2], "
                'side = "port" or "starboard" and half_breadth_m'
            )
    return check_berth(_section(BerthConfig(**value), where), where)


#: every field of every section: its range and rules beyond its annotated type (a test
#: checks that no field is missing here)
_RULES: dict[type, dict[str, _Rule]] = {
    IngestConfig: {
        "strict": _TYPE_ONLY,
        "ignore_checksum": _TYPE_ONLY,
        "date": _Rule(check=_check_date, before=_toml_date),
        "gap_s": _Rule(UP_TO_A_DAY),
        "backstep_tolerance_s": _Rule(ZERO_TO_A_DAY),
        "sources": _Rule(check=_check_roles),
        "quantities": _Rule(check=_check_quantities),
        "max_line_bytes": _Rule(within(64, 2**30, "bytes")),
        "max_chunk_bytes": _Rule(within(1024, 2**34, "bytes")),
        "memory_cap_mb": _Rule(within(16, 2**20, "MB")),
        "max_inflate_ratio": _Rule(within(2, 1e6)),
        "temp_cap_mb": _Rule(within(1, 2**24, "MB")),
    },
    DeadReckoningConfig: {
        "learn": _TYPE_ONLY,
        "reset": _Rule(check=_check_reset),
        "fix_role": _Rule(check=_one_of("gnss", "ins_mean")),
        "max_gap_s": _Rule(UP_TO_A_DAY),
        "epoch_interval_s": _Rule(STEP_S),
        "variation_deg": _Rule(Range("within +-180 degrees (east +)", -180.0, 180.0)),
        "deviation_table": _Rule(
            Range("a deviation within +-180 degrees (east +)", -180.0, 180.0),
            check=_check_deviation_table,
        ),
        **{name: _Rule(rng) for name, rng in SIGMAS.items()},
        "fix_sigma_m": _Rule(SIGMA_M),
    },
    DeviationConfig: {
        "interval_s": _Rule(within(1.0, DAY_S, "seconds")),
        "offset_s": _Rule(within(-DAY_S, DAY_S, "seconds")),
        "window_s": _Rule(within(60.0, YEAR_S, "seconds")),
        "kurtosis_windows_s": _Rule(within(60.0, YEAR_S, "seconds")),
        "max_interp_gap_s": _Rule(ZERO_TO_A_DAY),
        "factor_lat": _Rule(FACTOR),
        "factor_lon": _Rule(FACTOR),
        "factor_course": _Rule(FACTOR),
        "probability": _Rule(HALF_TO_ONE),
        "apriori": _Rule(within(0.0, 1e6, lo_open=True), check=_check_apriori),
        "first_approximation": _TYPE_ONLY,
        "confidence": _Rule(HALF_TO_ONE),
        "correlation_time_s": _Rule(within(0.0, YEAR_S, "seconds")),
        "min_kurtosis_samples": _Rule(within(1, 1e6)),
        "kurtosis_tol": _Rule(within(0.0, 10.0)),
        "hat_confidence": _Rule(HALF_TO_ONE),
        "hat_draws": _Rule(within(100, 100_000)),
        "seed": _Rule(within(0, 2**32 - 1)),
        "velocity_min_gap_s": _Rule(ZERO_TO_A_DAY),
    },
    FaultsConfig: {
        "exclude": _TYPE_ONLY,
        "max_speed_kn": _Rule(within(0.0, 1000.0, "kn", lo_open=True)),
        "jump_min_m": _Rule(within(0.0, 1e7, "m", lo_open=True)),
        "frozen_min_s": _Rule(UP_TO_A_YEAR),
        "stuck_min_s": _Rule(UP_TO_A_YEAR),
        "moving_min_kn": _Rule(SPEED_KN),
        "turn_min_deg": _Rule(within(0.0, 360.0, "degrees", lo_open=True)),
        "max_rot_deg_per_min": _Rule(within(0.0, 1e5, "degrees a minute", lo_open=True)),
        "min_records": _Rule(within(1, 1e9)),
    },
    IntegrityConfig: {
        "false_alarm": _Rule(Range("a probability in (0, 0.5)", 0.0, 0.5, True, True)),
        **{
            name: _Rule(UP_TO_A_DAY)
            for name in (
                "latency_max_s",
                "spell_min_s",
                "dropout_min_s",
                "frozen_min_s",
                "consistency_max_gap_s",
                "clock_ahead_min_s",
                "clock_drift_max_s",
                "backstep_min_s",
            )
        },
        "dropout_cadences": _Rule(within(0.0, 1e6, lo_open=True)),
        "jump_floor_m": _Rule(within(0.0, 1e6, "m", lo_open=True)),
        "consistency_interval_s": _Rule(STEP_S),
        "heading_gate_min_deg": _Rule(within(0.0, 180.0, "degrees", lo_open=True)),
        "velocity_gate_kn": _Rule(SPEED_KN),
    },
    BerthConfig: {
        "pier": _Rule(FINITE, check=check_pier),
        "side": _Rule(check=_one_of("port", "starboard")),
        "half_breadth_m": _Rule(within(0.0, 100.0, "m", lo_open=True)),
        "heading_deg": _Rule(Range("in [0, 360] degrees", 0.0, 360.0)),
        "sigma_m": _Rule(SIGMA_M),
        "gap_m": _Rule(within(0.0, 1000.0, "m")),
        "ref_stbd_m": _Rule(within(-100.0, 100.0, "m")),
        "abeam": _Rule(FINITE, check=check_abeam),
        "abeam_sigma_m": _Rule(SIGMA_M),
        "start_utc": _Rule(check=check_utc, before=toml_datetime),
        "end_utc": _Rule(check=check_utc, before=toml_datetime),
        "tolerance_m": _Rule(within(0.0, 1e6, "m", lo_open=True)),
        "max_speed_kn": _Rule(SPEED_KN),
        "datum": _TYPE_ONLY,  # the name is checked by the analysis (pyproj, dracc.ingest.datums)
    },
    ReferenceConfig: {"alongside": _Rule(check=check_alongside, before=one_or_many)},
}


@functools.cache
def _hints(cls: type[Any]) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _section(sec: Any, name: str) -> Any:
    """A section's dataclass with every value checked and converted (see :func:`_typed`)."""
    cls = type(sec)
    # a class is hashable; mypy's Hashable protocol does not see it for type[Any]
    rules, hints = _RULES[cls], _hints(cls)  # type: ignore[arg-type]
    values: dict[str, Any] = {}
    for f in fields(cls):
        rule = rules[f.name]
        value = getattr(sec, f.name)
        if rule.before is not None:
            value = rule.before(value)
        value = _typed(value, hints[f.name], name, f.name, rule.range)
        if rule.check is not None and value is not None:
            value = rule.check(value, name, f.name)
        values[f.name] = value
    return cls(**values)


def validate_section(sec: Any, name: str) -> Any:
    """One section (a dataclass built in Python: ``DeviationConfig(...)``) checked and
    converted as :func:`validate` checks it; ``name`` the section's, for the messages."""
    return _section(sec, name)


def validate(cfg: Config) -> Config:
    """Check every key of every section against its type and range (and the few rules on
    names and forms); raise ConfigError naming the key, else return the config with the
    values converted (an integer where a number belongs is a float, an array a tuple)."""
    sections = {name: _section(getattr(cfg, name), name) for name in _SECTIONS}
    if not isinstance(cfg.extra, dict):
        raise ConfigError(f"extra sections must be a table, got {_kind(cfg.extra)}")
    for name, table in cfg.extra.items():
        if not isinstance(table, dict):
            raise ConfigError(f"[{name}] must be a table, got {_kind(table)}")
    source_latencies(cfg.extra.get("sources"))  # [sources.KEY]: checked here, read by its owner
    return replace(cfg, **sections)


def load_config(path: str | Path | None = None) -> Config:
    """Read a TOML config file (or return the defaults when ``path`` is None)."""
    if path is None:
        return Config()
    p = Path(path)
    try:
        with p.open("rb") as fh:
            raw = fh.read(MAX_CONFIG_BYTES + 1)
        if len(raw) > MAX_CONFIG_BYTES:
            raise ConfigError(f"{p}: more than {MAX_CONFIG_BYTES:,} bytes: not a configuration")
        data = tomllib.loads(raw.decode("utf-8"))
    except FileNotFoundError as err:
        raise ConfigError(f"config file not found: {p}") from err
    except IsADirectoryError as err:
        raise ConfigError(f"config path is a directory: {p}") from err
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{p}: invalid TOML: {err}") from err
    except RecursionError as err:  # the parser recurses once per level of nesting
        raise ConfigError(
            f"{p}: invalid TOML: arrays or inline tables nested too deep "
            "(a configuration nests 3 levels)"
        ) from err
    except (OSError, UnicodeDecodeError) as err:
        raise ConfigError(f"{p}: cannot read config: {err}") from err
    return config_from_dict(data, str(p))


def config_from_dict(data: dict[str, Any], where: str = "config") -> Config:
    """Build a validated Config from a parsed TOML document."""
    unknown = set(data) - set(_SECTIONS) - _KNOWN_EXTRA
    if unknown:
        raise ConfigError(
            f"{where}: unknown section(s): {', '.join(sorted(unknown))}; "
            f"known: {', '.join(sorted(set(_SECTIONS) | _KNOWN_EXTRA))}"
        )
    kwargs: dict[str, Any] = {
        name: _build(cls, data[name], name) for name, cls in _SECTIONS.items() if name in data
    }
    kwargs["extra"] = {k: v for k, v in data.items() if k in _KNOWN_EXTRA}
    return validate(Config(**kwargs))


def with_overrides(cfg: Config, section: str, **values: Any) -> Config:
    """A copy of ``cfg`` with some keys of one section replaced (CLI options); None values are skipped."""
    values = {k: v for k, v in values.items() if v is not None}
    if not values:
        return cfg
    return validate(replace(cfg, **{section: replace(getattr(cfg, section), **values)}))
