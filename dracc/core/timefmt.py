"""Time as text: ISO 8601 UTC with a 'Z', the one formatter and parser every layer uses.

Times inside dracc are int64 nanoseconds since the Unix epoch (``time_ns``).
"""

from __future__ import annotations

import datetime as dt
from typing import Any, Literal, cast, overload

import numpy as np
from numpy.typing import NDArray

from dracc.core.units import NS_PER_S

#: the precisions :func:`iso_utc` writes; "auto" is seconds for whole seconds, else ms
UNITS = ("auto", "s", "ms", "us", "ns")


@overload
def iso_utc(time_ns: None, unit: str = "auto") -> None: ...
@overload
def iso_utc(time_ns: int | np.integer, unit: str = "auto") -> str: ...
@overload
def iso_utc(time_ns: NDArray[Any], unit: str = "auto") -> NDArray[np.str_]: ...
def iso_utc(
    time_ns: int | np.integer | NDArray[Any] | None, unit: str = "auto"
) -> str | NDArray[np.str_] | None:
    """'2026-11-21T13:00:00Z' (or '…:00.250Z'): ISO 8601 UTC of int64 Unix nanoseconds.

    A scalar gives a ``str``, an array an array of ``str``, None gives None.  ``unit`` is
    the precision (truncated, never rounded up into the next second); "auto" writes
    milliseconds only where some time has a fraction of a second.
    """
    if time_ns is None:
        return None
    if unit not in UNITS:
        raise ValueError(f"unit must be one of {UNITS}, got {unit!r}")
    t = np.asarray(time_ns, dtype=np.int64)
    if unit == "auto":
        unit = "s" if np.all(t % NS_PER_S == 0) else "ms"
    precision = cast(Literal["s", "ms", "us", "ns"], unit)  # one of UNITS, "auto" resolved
    out = np.datetime_as_string(t.astype("datetime64[ns]"), unit=precision, timezone="UTC")
    return str(out) if out.ndim == 0 else out


def parse_utc(text: str) -> dt.datetime:
    """An ISO 8601 time ('Z', an offset, or none: then UTC) as an aware datetime."""
    t = dt.datetime.fromisoformat(text.strip().replace("Z", "+00:00"))
    return t if t.tzinfo else t.replace(tzinfo=dt.timezone.utc)
