"""Durations as people write them: "1h", "30min", "90s", "1d", plain seconds ("3600").

One grammar for every option and configuration key that takes a duration;
``[dead_reckoning] reset`` adds the words "watch" (4 h) and "never".
"""

from __future__ import annotations

import math
import re

from dracc.core.errors import ConfigError

WATCH_S = 4 * 3600.0  #: one watch
_DURATION = re.compile(r"^\s*([0-9]*\.?[0-9]+)\s*(s|sec|min|m|h|hr|d)?\s*$", re.IGNORECASE)
_UNIT_S = {"s": 1.0, "sec": 1.0, "min": 60.0, "m": 60.0, "h": 3600.0, "hr": 3600.0, "d": 86400.0}


def parse_duration_s(
    text: str | float, what: str, example: str = "1h, 2h, 90min, 30s or 3600"
) -> float:
    """Seconds (> 0, finite) from "1h", "90min", "30s", "1d", "3600" or a number.

    ``what`` names the option or key in the message of the :class:`ConfigError` raised
    for anything else.
    """
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        value = float(text)
    else:
        m = _DURATION.match(str(text))
        if not m:
            raise ConfigError(f"{what} {text!r}: expected a duration such as {example}")
        unit = m.group(2).lower() if m.group(2) else "s"
        value = float(m.group(1)) * _UNIT_S[unit]
    if not value > 0 or not math.isfinite(value):
        raise ConfigError(f"{what} {text!r}: must be positive")
    return value


def parse_reset_s(text: str | float) -> float:
    """Restart interval of the dead reckoning in seconds: a duration, "watch" (4 h) or
    "never" (inf); the grammar of ``[dead_reckoning] reset`` besides "auto"."""
    word = str(text).strip().lower()
    if word == "never":
        return math.inf
    if word == "watch":
        return WATCH_S
    return parse_duration_s(
        text, "[dead_reckoning] reset =", example='"1h", "30min", "90s", or "watch" or "never"'
    )
