"""The ``[audit]`` settings: limits, thresholds, the a priori seeds, the vessel name.

:func:`audit_config` validates the ``[audit]`` table into an :class:`AuditConfig`;
:func:`apriori_seeds` reads the configured a priori RMS (``[deviation.apriori]``);
:func:`settings_sha256` fingerprints the settings that shape an analysis.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path

from dracc.core.config import Config
from dracc.core.errors import ConfigError
from dracc.core.vocabulary import CHANNEL_KEYS, INS_ROLES, ROLES

UNITS = INS_ROLES
KEY_CHANNELS = {v: k for k, v in CHANNEL_KEYS.items()}


@dataclass(frozen=True)
class AuditConfig:
    """The ``[audit]`` table.  Percentages carry ``_pct``; limits use the channel's unit."""

    db: str | None = None  #: SQLite state file; required (here or --db)
    vessel: str | None = None  #: vessel name in the state (else [vessel] name, else "default")
    pattern: str = "*"  #: glob for the log files inside a folder (e.g. "**/*.nmea")
    busy_timeout_s: float = 60.0  #: how long to wait for another audit holding the database
    #: limiting error (K8) per unit and channel; "all" applies to every unit
    limits: Mapping[str, Mapping[str, float]] = field(
        default_factory=lambda: {"all": {"lat_m": 1852.0, "lon_m": 1852.0, "course_deg": 0.75}}
    )
    dr_containment_min: float = 0.90  #: fraction of DR epochs with the reference inside 2M
    compass_error_max_deg: float = 1.0  #: |compass error| estimated against the reference
    log_scale_max_pct: float = 2.0  #: |log scale error|, % of speed (IMO: 2 %)
    rejected_rate_max_pct: float = 1.0  #: rejected lines, % of all lines
    required_sources: tuple[str, ...] = UNITS  #: roles that must be present in the logs
    apriori_raise_is_finding: bool = False  #: a raised a priori value is a finding (exit 1)
    #: the limiting errors are judged over the nights of at least this many hours (seed 001
    #: asks 72 h for a kurtosis that means something): a short night cannot raise a limit
    accuracy_window_h: float = 72.0
    #: false-alarm probability of each sensor-error check a night (compass, log): a finding
    #: needs the estimate beyond its limit by Phi^-1(1 - false_alarm) sigma; not given:
    #: ``[integrity] false_alarm`` (dracc.pipeline.audit.sensor_checks)
    false_alarm: float = 1e-3

    def limit_for(self, unit: str, channel: str) -> float | None:
        key = CHANNEL_KEYS[channel]
        own = self.limits.get(unit, {})
        if key in own:
            return float(own[key])
        value = self.limits.get("all", {}).get(key)
        return None if value is None else float(value)


def _number(value, where: str, positive: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"[{where}] must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v) or (positive and v <= 0):
        raise ConfigError(f"[{where}] must be a positive number, got {value!r}")
    return v


def _unknown(table: Mapping, known: Iterable[str], where: str) -> None:
    unknown = set(table) - set(known)
    if unknown:
        raise ConfigError(
            f"[{where}] unknown key(s): {', '.join(sorted(map(str, unknown)))}; "
            f"known: {', '.join(sorted(known))}"
        )


def audit_config(cfg: Config) -> AuditConfig:
    """Validate ``cfg.extra['audit']`` into an :class:`AuditConfig` (ConfigError on any doubt)."""
    table = cfg.extra.get("audit", {})
    if not isinstance(table, dict):
        raise ConfigError(f"[audit] must be a table, got {type(table).__name__}")
    default = AuditConfig()
    known = list(asdict(default))
    _unknown(table, known, "audit")
    kw: dict = {"false_alarm": cfg.integrity.false_alarm}
    if "false_alarm" in table:
        v = _number(table["false_alarm"], "audit.false_alarm")
        if not v < 0.5:
            raise ConfigError(f"[audit.false_alarm] is a probability in (0, 0.5), got {v}")
        kw["false_alarm"] = v
    for key in ("db", "vessel", "pattern"):
        if key in table:
            if not isinstance(table[key], str) or not table[key].strip():
                raise ConfigError(f"[audit] {key} must be a non-empty string, got {table[key]!r}")
            kw[key] = table[key]
    if "pattern" in kw and (Path(kw["pattern"]).is_absolute() or Path(kw["pattern"]).drive):
        raise ConfigError(
            f"[audit] pattern must be a glob relative to the log folder "
            f'(e.g. "*.nmea" or "**/*.nmea"), got {kw["pattern"]!r}'
        )
    for key in (
        "busy_timeout_s",
        "compass_error_max_deg",
        "log_scale_max_pct",
        "rejected_rate_max_pct",
        "accuracy_window_h",
    ):
        if key in table:
            kw[key] = _number(table[key], f"audit.{key}")
    if "dr_containment_min" in table:
        v = _number(table["dr_containment_min"], "audit.dr_containment_min")
        if v > 1:
            raise ConfigError(f"[audit.dr_containment_min] is a fraction in (0, 1], got {v}")
        kw["dr_containment_min"] = v
    if "apriori_raise_is_finding" in table:
        if not isinstance(table["apriori_raise_is_finding"], bool):
            raise ConfigError("[audit.apriori_raise_is_finding] must be true or false")
        kw["apriori_raise_is_finding"] = table["apriori_raise_is_finding"]
    if "required_sources" in table:
        req = table["required_sources"]
        if not isinstance(req, list) or any(r not in ROLES for r in req):
            raise ConfigError(
                f"[audit.required_sources] must be a list of roles "
                f"({', '.join(ROLES)}), got {req!r}"
            )
        kw["required_sources"] = tuple(req)
    if "limits" in table:
        lim = table["limits"]
        if not isinstance(lim, dict):
            raise ConfigError(
                '[audit.limits] must be a table: unit or "all" -> { lat_m, lon_m, course_deg }'
            )
        _unknown(lim, ("all",) + UNITS, "audit.limits")
        merged = {k: dict(v) for k, v in default.limits.items()}
        for unit, values in lim.items():
            if not isinstance(values, dict):
                raise ConfigError(
                    f"[audit.limits.{unit}] must be a table {{ lat_m, lon_m, course_deg }}"
                )
            _unknown(values, CHANNEL_KEYS.values(), f"audit.limits.{unit}")
            merged.setdefault(unit, {}).update(
                {k: _number(v, f"audit.limits.{unit}.{k}") for k, v in values.items()}
            )
        kw["limits"] = merged
    return AuditConfig(**kw)


def apriori_seeds(cfg: Config) -> dict[tuple[str, str], float]:
    """The configured a priori RMS per (unit, channel) from ``[deviation.apriori]``."""
    seeds: dict[tuple[str, str], float] = {}
    for unit, values in cfg.deviation.apriori.items():
        if unit not in UNITS or not isinstance(values, dict):
            raise ConfigError(
                f"[deviation.apriori] {unit!r}: expected one of {', '.join(UNITS)} "
                "= { lat_m, lon_m, course_deg }"
            )
        _unknown(values, CHANNEL_KEYS.values(), f"deviation.apriori.{unit}")
        for key, v in values.items():
            seeds[(unit, KEY_CHANNELS[key])] = _number(v, f"deviation.apriori.{unit}.{key}")
    return seeds


def settings_sha256(cfg: Config) -> str:
    """SHA-256 of the settings that shape an analysis (ingest, dead reckoning, deviation)."""
    doc = {
        "ingest": asdict(cfg.ingest),
        "dead_reckoning": asdict(cfg.dead_reckoning),
        "deviation": asdict(cfg.deviation),
    }
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def vessel_name(cfg: Config, acfg: AuditConfig, option: str | None) -> str:
    """--vessel, else [audit] vessel, else [vessel] name, else 'default'."""
    if option:
        return option
    if acfg.vessel:
        return acfg.vessel
    v = cfg.extra.get("vessel", {})
    if not isinstance(v, dict):
        raise ConfigError(f"[vessel] must be a table, got {type(v).__name__}")
    _unknown(v, ("name",), "vessel")
    if "name" in v:
        if not isinstance(v["name"], str) or not v["name"].strip():
            raise ConfigError(f"[vessel] name must be a non-empty string, got {v['name']!r}")
        return v["name"]
    return "default"
