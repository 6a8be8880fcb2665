"""``check_config``: the ``[deviation]`` values the method of METHODS section 4 can use
(types, ranges, the a priori table); a ConfigError names the key otherwise."""

from __future__ import annotations

import math
from dataclasses import fields

from dracc.core.config import DeviationConfig
from dracc.core.errors import ConfigError
from dracc.core.vocabulary import CHANNEL_KEYS, INS_ROLES

__all__ = ["check_config"]


def check_config(cfg: DeviationConfig) -> None:
    """Raise ConfigError naming the key for values the method cannot use."""
    for f in fields(DeviationConfig):
        value, default = getattr(cfg, f.name), getattr(DeviationConfig(), f.name)
        if isinstance(default, bool):
            ok = isinstance(value, bool)
        elif isinstance(default, int):
            ok = isinstance(value, int) and not isinstance(value, bool)
        elif isinstance(default, float):
            ok = (
                isinstance(value, (int, float))
                and not isinstance(value, bool)
                and math.isfinite(value)
            )
        else:
            continue
        if not ok:
            raise ConfigError(
                f"[deviation] {f.name} = {value!r}: must be "
                f"{type(default).__name__ if not isinstance(default, float) else 'a finite number'}"
            )
    if cfg.interval_s <= 0 or cfg.window_s <= 0:
        raise ConfigError("[deviation] interval_s and window_s must be positive")
    if cfg.velocity_min_gap_s < 0:
        raise ConfigError(
            f"[deviation] velocity_min_gap_s must be >= 0, got {cfg.velocity_min_gap_s}"
        )
    if cfg.max_interp_gap_s < 0:
        raise ConfigError(f"[deviation] max_interp_gap_s must be >= 0, got {cfg.max_interp_gap_s}")
    for name in ("confidence", "hat_confidence"):
        v = getattr(cfg, name)
        if not 0.5 <= v < 1.0:
            raise ConfigError(f"[deviation] {name} must be in [0.5, 1), got {v}")
    if cfg.correlation_time_s < 0:
        raise ConfigError(
            f"[deviation] correlation_time_s must be >= 0, got {cfg.correlation_time_s}"
        )
    if any(w <= 0 for w in cfg.kurtosis_windows_s):
        raise ConfigError("[deviation] kurtosis_windows_s must all be positive")
    if cfg.hat_draws < 100:
        raise ConfigError(f"[deviation] hat_draws must be >= 100, got {cfg.hat_draws}")
    keys = set(CHANNEL_KEYS.values())
    for unit, table in cfg.apriori.items():
        if unit not in INS_ROLES:
            raise ConfigError(
                f"[deviation.apriori] {unit!r}: unit must be one of {', '.join(INS_ROLES)}"
            )
        if not isinstance(table, dict):
            raise ConfigError(
                f"[deviation.apriori] {unit} must be a table of {', '.join(sorted(keys))}"
            )
        for key, value in table.items():
            if key not in keys:
                raise ConfigError(
                    f"[deviation.apriori.{unit}] unknown key {key!r}; known: "
                    f"{', '.join(sorted(keys))}"
                )
            if not isinstance(value, (int, float)) or not value > 0:
                raise ConfigError(
                    f"[deviation.apriori.{unit}] {key} = {value!r}: must be a positive number"
                )
