"""Validation against a reference: the paper's Table 1 and its marks.

Where a reference exists (GNSS, or a berth), each unit's true error is measurable at
the sampling instants, x_ji = y_ji - y_ref,i, and so is the empirical factor

    k* = m_x / m_u,   both RMS by (K3b) over the same instants

which the paper tabulates day by day (Table 1) with two marks:

- ``+`` where k* <= k (using k the limiting error is not understated), ``-`` otherwise,
  with the paper's thresholds: "for latitude channel k* <= k = 1,32 and for longitude
  channel k* <= k' = 1,5" (seeds/001, the notes under Table 1; METHODS section 7).  Its
  longitude factor 1.49 is the weighted k* = 0.226/0.151 = 1.497 of Table 1's last row;
  the mark compares with 1.5 (:func:`table1_mark_k`), so a day at k* = 1.495 is ``+``;
- ``<``, ``>``, ``=`` comparing the kurtosis of the deviations with that of the errors:
  ``<`` where E_dev < E_err (the limiting error from the deviations is understated),
  ``>`` where E_dev > E_err, ``=`` where they agree to ``tol``.

The last row of Table 1 averages over days: see :func:`dracc.math.deviation.stats.weighted_rms`.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dracc.core.geodesy import angdiff, k_lambda, k_phi
from dracc.math.deviation.stats import K_EMPIRICAL_LON

#: the paper's mark threshold k' for its longitude (and course) factor 1.49 (Table 1 notes)
K_MARK_LON = 1.5

FloatArray = NDArray[np.float64]


def position_errors_m(
    lat_rad: ArrayLike, lon_rad: ArrayLike, ref_lat_rad: ArrayLike, ref_lon_rad: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """North and east errors in metres of positions against the reference position.

    x_north = (phi - phi_ref) / k_phi(phi_ref)          (B18)
    x_east  = (lam - lam_ref) / k_lambda(phi_ref)       (B19), difference on the circle
    Broadcasts (units along a leading axis against a reference of shape (n,)).
    """
    ref_lat = np.asarray(ref_lat_rad, dtype=float)
    north: FloatArray = (np.asarray(lat_rad, dtype=float) - ref_lat) / k_phi(ref_lat)  # (B18)
    east: FloatArray = angdiff(lon_rad, ref_lon_rad) / k_lambda(ref_lat)  # (B19)
    return north, east


def course_errors_rad(heading_rad: ArrayLike, ref_heading_rad: ArrayLike) -> FloatArray:
    """Heading errors against the reference heading, on the circle, in (-pi, pi]."""
    errors: FloatArray = angdiff(heading_rad, ref_heading_rad)
    return errors


def table1_mark_k(k: float, channel: str | None = None) -> float:
    """The threshold the Table 1 mark compares k* with, for the factor ``k`` in use.

    The paper's rule (notes under Table 1): latitude k* <= k = 1.32, longitude
    k* <= k' = 1.5.  Its longitude and course factor is 1.49 (the last row's k*, 1.497,
    written 1.49), and the rule's k' for it is 1.5: so where the factor in use is the
    paper's 1.49 the threshold is 1.5, in the longitude and course channels (or any channel
    where ``channel`` is not given, since 1.49 is the paper's factor only there).  Any
    other factor (a configured one, sqrt 2 with two units, 1.32) is its own threshold.
    """
    k = float(k)
    if channel != "lat" and math.isclose(k, K_EMPIRICAL_LON, rel_tol=0.0, abs_tol=1e-12):
        return K_MARK_LON
    return k


def k_star_mark(k_star: float, k: float, channel: str | None = None) -> str:
    """Table 1 mark: '+' where k* <= k', '-' where k* > k', '' where k* is NaN; k' is
    :func:`table1_mark_k` of the factor ``k`` (1.5 for the paper's 1.49)."""
    if np.isnan(k_star):
        return ""
    return "+" if k_star <= table1_mark_k(k, channel) else "-"


def kurtosis_mark(kurtosis_error: float, kurtosis_deviation: float, tol: float = 0.05) -> str:
    """Table 1 mark for the kurtosis of deviations against that of errors:
    '<' where E_dev < E_err - tol, '>' where E_dev > E_err + tol, '=' otherwise,
    '' where either is NaN."""
    if np.isnan(kurtosis_error) or np.isnan(kurtosis_deviation):
        return ""
    if kurtosis_deviation < kurtosis_error - tol:
        return "<"
    if kurtosis_deviation > kurtosis_error + tol:
        return ">"
    return "="
