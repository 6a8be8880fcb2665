"""``[sources.KEY]``: what the user knows about one source, by its source key.

Today one setting: ``latency_s``, the source's clock offset (seconds its records are
stamped after the instant they describe; see :mod:`dracc.math.clock`), which then
replaces the offset dracc would learn from the data::

    [sources.GYRO]
    latency_s = 0.4
"""

from __future__ import annotations

import math
from typing import Any

from dracc.core.errors import ConfigError

SOURCE_KEYS = ("latency_s",)
#: a latency beyond this is a clock error to be found, not a setting
MAX_LATENCY_S = 3600.0


def source_latencies(table: Any) -> dict[str, float]:
    """``{KEY: latency_s}`` from the ``[sources]`` table, checked (ConfigError naming the
    key otherwise)."""
    if table is None:
        return {}
    if not isinstance(table, dict):
        raise ConfigError(f"[sources] must be a table of [sources.KEY] tables, got {table!r}")
    out = {}
    for key, entry in table.items():
        where = f"[sources.{key}]"
        if not isinstance(entry, dict):
            raise ConfigError(f"{where} must be a table such as latency_s = 0.4, got {entry!r}")
        unknown = set(entry) - set(SOURCE_KEYS)
        if unknown:
            raise ConfigError(
                f"{where} unknown key(s): {', '.join(sorted(map(str, unknown)))}; "
                f"known: {', '.join(SOURCE_KEYS)}"
            )
        if "latency_s" in entry:
            v = entry["latency_s"]
            if (
                isinstance(v, bool)
                or not isinstance(v, (int, float))
                or not math.isfinite(v)
                or abs(v) > MAX_LATENCY_S
            ):
                raise ConfigError(
                    f"{where} latency_s = {v!r}: a number of seconds within "
                    f"+-{MAX_LATENCY_S:g} (positive: stamped after the instant described)"
                )
            out[str(key)] = float(v)
    return out
