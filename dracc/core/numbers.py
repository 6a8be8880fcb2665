"""Numbers at the edges: NaN and infinities where JSON and plots need them.

Inside dracc a missing value is NaN in float arrays; JSON has no NaN, so serialisers
write None (``null``), and plots take None back as NaN.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any


def finite_or_none(x: Any) -> float | None:
    """``float(x)`` when it is a finite number; None for None, NaN, +-inf, booleans and
    anything that is not a number."""
    if x is None or isinstance(x, bool):
        return None
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def jsonable(x: Any) -> Any:
    """``x`` in JSON types: NaN and infinities become None, tuples lists, numpy scalars
    Python numbers, mappings dicts with text keys, anything else its text."""
    if isinstance(x, Mapping):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if x is None or isinstance(x, (bool, int, str)):
        return x
    try:
        v = float(x)
    except (TypeError, ValueError):
        return str(x)
    return v if math.isfinite(v) else None


def none_to_nan(values: Iterable[float | None]) -> list[float]:
    """A JSON series back to floats for plotting: None becomes NaN."""
    return [math.nan if v is None else float(v) for v in values]
