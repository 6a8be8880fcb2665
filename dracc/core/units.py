"""Unit conversions used at the edges (ingest and reports).

Exact definitions: 1 international nautical mile = 1852 m; 1 knot = 1852/3600 m/s.
"""

from __future__ import annotations

import math

NMI_M = 1852.0  #: metres per nautical mile (exact)
CABLE_M = 185.2  #: metres per cable (0.1 nmi)
KN_MPS = 1852.0 / 3600.0  #: metres per second per knot (exact)
KMH_MPS = 1000.0 / 3600.0  #: metres per second per km/h
DEG_RAD = math.pi / 180.0  #: radians per degree
ARCMIN_RAD = math.pi / (180.0 * 60.0)  #: radians per arc-minute
NS_PER_S = 1_000_000_000


def kn_to_mps(speed_kn):
    """Knots to metres per second."""
    return speed_kn * KN_MPS


def mps_to_kn(speed_mps):
    """Metres per second to knots."""
    return speed_mps / KN_MPS
