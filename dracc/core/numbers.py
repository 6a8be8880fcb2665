"""Numbers at the edges: NaN and infinities where JSON and plots need them, and a count
said in words.

Inside dracc a missing value is NaN in float arrays; JSON has no NaN, so serialisers
write None (``null``), and plots take None back as NaN.  :func:`counted` says a count
with its noun in the right number ("1 segment", "3 segments") in every message.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np


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
    """``x`` in JSON types: integers (numpy's too) as ``int``, floats as ``float`` with NaN
    and infinities as None, booleans and text as they are, tuples and lists as lists,
    mappings as dicts with text keys, anything else (a path, a date) as its text."""
    if isinstance(x, Mapping):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, (bool, str, np.bool_)) or x is None:
        return bool(x) if isinstance(x, np.bool_) else x
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return finite_or_none(x)
    return str(x)


def none_to_nan(values: Iterable[float | None]) -> list[float]:
    """A JSON series back to floats for plotting: None becomes NaN."""
    return [math.nan if v is None else float(v) for v in values]


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and ``noun`` in the number ``n`` asks for: '1 segment', '0 segments',
    '3 checks'; ``plural`` where adding 's' is wrong ('1 fix', '2 fixes')."""
    word = noun if n == 1 else (plural if plural is not None else noun + "s")
    return f"{n:,} {word}"
