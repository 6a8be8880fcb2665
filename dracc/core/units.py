"""Unit conversions used at the edges (ingest and reports).

Exact definitions: 1 international nautical mile = 1852 m; 1 knot = 1852/3600 m/s.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, overload

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from dracc.core.arrays import FloatArray

NMI_M = 1852.0  #: metres per nautical mile (exact)
CABLE_M = 185.2  #: metres per cable (0.1 nmi)
KN_MPS = 1852.0 / 3600.0  #: metres per second per knot (exact)
KMH_MPS = 1000.0 / 3600.0  #: metres per second per km/h
DEG_RAD = math.pi / 180.0  #: radians per degree
ARCMIN_RAD = math.pi / (180.0 * 60.0)  #: radians per arc-minute
NS_PER_S = 1_000_000_000


@overload
def kn_to_mps(speed_kn: float) -> float: ...
@overload
def kn_to_mps(speed_kn: NDArray[Any]) -> FloatArray: ...
def kn_to_mps(speed_kn: float | NDArray[Any]) -> float | FloatArray:
    """Knots to metres per second."""
    return speed_kn * KN_MPS


@overload
def mps_to_kn(speed_mps: float) -> float: ...
@overload
def mps_to_kn(speed_mps: NDArray[Any]) -> FloatArray: ...
def mps_to_kn(speed_mps: float | NDArray[Any]) -> float | FloatArray:
    """Metres per second to knots."""
    return speed_mps / KN_MPS
