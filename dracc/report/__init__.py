"""Reports: render an :class:`~dracc.pipeline.results.Analysis`; never compute.

``terminal`` (rich summary), ``json_report`` (versioned JSON + schema), ``html`` with
``plots`` (one self-contained offline file), ``tables`` (CSV and Parquet).  This
module holds the few formatting helpers they share.
"""

from __future__ import annotations

import math
from datetime import datetime, timezone
from typing import Any

import numpy as np


def short_utc(time_ns: int | None) -> str:
    """'2026-03-01 12:00Z' for tables; '-' for None."""
    if time_ns is None:
        return "-"
    dt = datetime.fromtimestamp(int(time_ns) // 1_000_000_000, tz=timezone.utc)
    return dt.strftime("%Y-%m-%d %H:%MZ")


def fmt_duration(seconds: float) -> str:
    """'26 h 05 min', '12 min 30 s'; '-' for NaN."""
    if seconds is None or not math.isfinite(seconds):
        return "-"
    s = int(round(seconds))
    h, rem = divmod(s, 3600)
    m, sec = divmod(rem, 60)
    if h:
        return f"{h} h {m:02d} min"
    if m:
        return f"{m} min {sec:02d} s"
    return f"{sec} s"


def fmt(x: Any, digits: int = 1, none: str = "-") -> str:
    """A number with ``digits`` decimals; ``none`` for None/NaN."""
    if x is None:
        return none
    try:
        v = float(x)
    except (TypeError, ValueError):
        return str(x)
    if not math.isfinite(v):
        return none
    return f"{v:,.{digits}f}"


def fmt_signed(x: Any, digits: int = 2) -> str:
    """A correction with its sign ('+0.31', '-0.02'); '-' for None/NaN."""
    text = fmt(x, digits)
    return text if text == "-" or text.startswith("-") else "+" + text


def fmt_pct(x: Any, digits: int = 1) -> str:
    """A fraction as a percentage; '-' for None/NaN."""
    if x is None or not np.isfinite(x):
        return "-"
    return f"{100.0 * float(x):.{digits}f} %"
