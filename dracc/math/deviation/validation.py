"""``check_config``: the ``[deviation]`` values the method of METHODS section 4 can use
(types, ranges, the a priori table); a ConfigError names the key otherwise."""

from __future__ import annotations

from dracc.core.config import DeviationConfig, validate_section

__all__ = ["check_config"]


def check_config(cfg: DeviationConfig) -> None:
    """Raise ConfigError naming the key for values the method cannot use: the schema of
    the ``[deviation]`` section, its types and ranges, as a configuration file is checked
    (:func:`dracc.core.config.validate_section`; the ranges: :mod:`dracc.core.bounds`)."""
    validate_section(cfg, "deviation")
