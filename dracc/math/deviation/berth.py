"""The berth reference: where the ship lay alongside a known pier (seeds/004, Figure 1).

The pier line A->B, shifted by the vector from the ship's conventional reference point to
her side, is a line of position of that point (:class:`dracc.math.fusion.PierLine`):

    d = (y_ref - y_side) cos(H - alpha)      offset of the shifted line, right of A->B +
    y_side = +-(half_breadth + gap)          starboard +, port -;  y_ref = ref_stbd_m

with H the ship's heading and alpha the pier's azimuth.  Across the pier it fixes the
position; along the pier a mark abeam of the reference point (a line through the mark
perpendicular to the pier) does, or else the mean of the INS units over the period (then
the along-pier component is not independent of the units).  Both are fused by WLS (W3, W4)
in :func:`dracc.math.fusion.alongside_reference`.

When the ship lay there: the configured period, or :func:`alongside_runs`: where the mean
INS position lies within ``tolerance_m`` of the pier segment (beyond half breadth and gap)
and moves slower than ``max_speed_kn``.  Pure numpy; no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dracc.core.geodesy import offset_ne_m, wrap_2pi
from dracc.core.numbers import finite_or_none as _f
from dracc.core.reference_config import BerthConfig
from dracc.core.timefmt import iso_utc
from dracc.core.units import KN_MPS
from dracc.math.fusion import FixSolution, PierLine, alongside_reference

__all__ = [
    "BerthReference",
    "alongside_runs",
    "berth_position",
    "circular_mean_rad",
    "pier_line",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: the abeam line's sigma where the INS mean stands in for an abeam mark (it only places
#: the position along the pier; the fix has no redundancy, so it does not move it)
_INS_MEAN_ALONG_SIGMA_M = 100.0


@dataclass(frozen=True)
class BerthReference:
    """One period alongside and the reference position of the ship's reference point."""

    berth: int  #: index in ``[reference] alongside``
    start_ns: int
    end_ns: int
    period_source: str  #: 'configured' or 'detected'
    lat_rad: float
    lon_rad: float
    sigma_across_m: float  #: across the pier (the pier line's sigma through W3)
    sigma_along_m: float  #: along it (NaN where the INS mean places it)
    heading_rad: float  #: the heading H of the offset d
    heading_source: str  #: 'configured', 'compass' or 'ins'
    along_source: str  #: 'abeam mark' or 'ins mean'
    offset_m: float  #: d, the reference point from the pier line (right of A->B +)
    pier_azimuth_rad: float
    side: str
    half_breadth_m: float
    n_reference: int  #: reference readings given to the check (instants without GNSS)

    def to_dict(self) -> dict[str, Any]:
        return {
            "berth": self.berth,
            "start_utc": iso_utc(self.start_ns),
            "end_utc": iso_utc(self.end_ns),
            "period_source": self.period_source,
            "lat_deg": math.degrees(self.lat_rad),
            "lon_deg": math.degrees(self.lon_rad),
            "sigma_across_m": _f(self.sigma_across_m),
            "sigma_along_m": _f(self.sigma_along_m),
            "heading_deg": math.degrees(self.heading_rad),
            "heading_source": self.heading_source,
            "along_source": self.along_source,
            "offset_m": self.offset_m,
            "pier_azimuth_deg": math.degrees(self.pier_azimuth_rad),
            "side": self.side,
            "half_breadth_m": self.half_breadth_m,
            "n_reference": self.n_reference,
        }


def pier_line(b: BerthConfig, heading_rad: float) -> PierLine:
    """The berth's :class:`PierLine` at heading H (GeometryError if H is not along the pier)."""
    lat1, lon1, lat2, lon2 = (math.radians(v) for v in b.pier)
    return PierLine(
        lat1,
        lon1,
        lat2,
        lon2,
        heading_rad,
        cast(Literal["port", "starboard"], b.side),
        b.half_breadth_m,
        b.sigma_m,
        ref_transverse_m=b.ref_stbd_m,
        gap_m=b.gap_m,
    )


def berth_position(
    b: BerthConfig, heading_rad: float, ins_mean: tuple[float, float] | None
) -> tuple[FixSolution, str, float, float]:
    """The reference position alongside (W3, W4): the shifted pier line with the abeam
    mark, else with the INS mean ``(lat_rad, lon_rad)`` along the pier.

    Returns (solution, along_source, sigma_across_m, sigma_along_m).
    """
    pier = pier_line(b, heading_rad)
    if b.abeam is not None:
        mark, sigma, source = (
            (math.radians(b.abeam[0]), math.radians(b.abeam[1])),
            b.abeam_sigma_m,
            "abeam mark",
        )
    elif ins_mean is not None:
        mark, sigma, source = ins_mean, _INS_MEAN_ALONG_SIGMA_M, "ins mean"
    else:
        raise ValueError("berth_position: no abeam mark and no INS mean")
    sol = alongside_reference(pier, abeam_mark=mark, abeam_sigma_m=sigma)
    alpha = pier.line().azimuth_rad
    along = np.array([math.cos(alpha), math.sin(alpha)])
    across = np.array([-math.sin(alpha), math.cos(alpha)])
    s_across = math.sqrt(float(across @ sol.cov_m2 @ across))
    s_along = math.sqrt(float(along @ sol.cov_m2 @ along)) if source == "abeam mark" else math.nan
    return sol, source, s_across, s_along


def circular_mean_rad(angles_rad: ArrayLike) -> float:
    """Mean direction of angles, [0, 2 pi); NaN for none."""
    a = np.asarray(angles_rad, float)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return math.nan
    return float(wrap_2pi(math.atan2(float(np.sin(a).sum()), float(np.cos(a).sum()))))


def alongside_runs(
    b: BerthConfig, time_ns: ArrayLike, lat_rad: ArrayLike, lon_rad: ArrayLike
) -> list[tuple[int, int]]:
    """Periods (first, last instant, ns) where the track (the mean INS position on a regular
    grid, NaN where missing) lies near the pier and is stationary.

    Near: across the pier line within half breadth + gap + ``tolerance_m``, and along it
    within the segment extended by ``tolerance_m`` at both ends.  Stationary: the step to
    the next instant implies less than ``max_speed_kn``.  A period needs two instants.
    """
    t = np.asarray(time_ns, np.int64)
    lat, lon = np.asarray(lat_rad, float), np.asarray(lon_rad, float)
    if t.size < 2:
        return []
    lat1, lon1, lat2, lon2 = (math.radians(v) for v in b.pier)
    bn, be = offset_ne_m(lat2, lon2, lat1, lon1)
    length = math.hypot(bn, be)
    un, ue = bn / length, be / length
    n, e = offset_ne_m(lat, lon, np.full_like(lat, lat1), np.full_like(lon, lon1))
    along, across = n * un + e * ue, -n * ue + e * un
    tol = b.tolerance_m
    near = (
        (np.abs(across) <= b.half_breadth_m + b.gap_m + tol)
        & (along >= -tol)
        & (along <= length + tol)
    )
    dt_s = np.diff(t).astype(float) / 1e9
    step_m = np.hypot(np.diff(n), np.diff(e))
    slow_step = step_m < b.max_speed_kn * KN_MPS * dt_s
    slow = np.zeros(t.size, bool)
    slow[:-1] |= slow_step
    slow[1:] |= slow_step
    ok = near & slow & np.isfinite(n) & np.isfinite(e)
    runs: list[tuple[int, int]] = []
    i = 0
    while i < t.size:
        if not ok[i]:
            i += 1
            continue
        j = i
        while j + 1 < t.size and ok[j + 1]:
            j += 1
        if j > i:
            runs.append((int(t[i]), int(t[j])))
        i = j + 1
    return runs
