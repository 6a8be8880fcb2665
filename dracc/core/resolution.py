"""The resolution of a source's readings: the step its values are logged with (an AIS
heading's whole degree, a gyro's 0.1°, NMEA 2000's 1e-4 rad, a position's 3 or 5 decimals
of minutes), learned from the values themselves.  One home for the role choice
(:mod:`dracc.ingest.role_evidence`) and the frozen/stuck witnesses
(:mod:`dracc.math.witness`)."""

from __future__ import annotations

import numpy as np

from dracc.core.arrays import FloatArray
from dracc.core.units import DEG_RAD, KN_MPS

__all__ = ["HEADING_QUANTA_RAD", "POSITION_QUANTA_RAD", "SPEED_QUANTA_MPS", "quantum"]

#: the steps headings are logged with: degrees (whole to 1e-4) and radians (NMEA 2000,
#: Signal K), largest first
HEADING_QUANTA_RAD = tuple(
    sorted(
        [d * DEG_RAD for d in (1.0, 0.5, 0.2, 0.1, 0.05, 0.01, 1e-3, 1e-4)]
        + [1e-2, 1e-3, 1e-4, 1e-5, 1e-6],
        reverse=True,
    )
)
#: the steps positions are logged with: minutes of arc (NMEA 0183, 1 to 7 decimals) and
#: degrees (NMEA 2000, Signal K, CSV: 3 to 8 decimals), largest first
POSITION_QUANTA_RAD = tuple(
    sorted(
        [10.0**-k / 60.0 * DEG_RAD for k in range(1, 8)]
        + [10.0**-k * DEG_RAD for k in range(3, 9)],
        reverse=True,
    )
)
#: the steps speeds are logged with: knots (whole to 1e-3) and metres per second (NMEA
#: 2000's 0.01 m/s), largest first
SPEED_QUANTA_MPS = tuple(
    sorted([k * KN_MPS for k in (1.0, 0.5, 0.1, 0.05, 0.01, 1e-3)] + [0.01, 1e-3], reverse=True)
)
#: at most this many distinct values are examined to learn a resolution
_QUANTUM_SAMPLE = 20_000


def quantum(values: FloatArray, candidates: tuple[float, ...], share: float = 0.98) -> float:
    """The resolution of readings ``values``: the largest of ``candidates`` (same unit)
    of which at least ``share`` of the distinct finite values are whole multiples (to
    1e-3 of the step); 0.0 for values on no such grid or fewer than 3 distinct ones."""
    x = np.unique(np.asarray(values, float)[np.isfinite(values)])
    if x.size < 3:
        return 0.0
    if x.size > _QUANTUM_SAMPLE:  # evenly spaced, deterministic
        x = x[np.linspace(0, x.size - 1, _QUANTUM_SAMPLE).astype(np.int64)]
    for q in candidates:
        k = x / q
        if float(np.mean(np.abs(k - np.round(k)) < 1e-3)) >= share:
            return float(q)
    return 0.0
