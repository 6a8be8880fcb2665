"""The error ellipse of a north/east covariance: the one implementation dracc uses.

A covariance that is not positive semi-definite is reported, never repaired: its
semi-minor axis is NaN (a square root of a negative eigenvalue), so a report shows
"-" and a test sees the fault.  Only rounding — an eigenvalue a hair below zero,
within 1e-9 of the larger one — is read as the zero it is.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from dracc.core.arrays import ArrayLike, FloatArray


class Ellipse(NamedTuple):
    """1-sigma error ellipse (metres; broadcasts over leading axes).

    ``orientation_rad`` is the azimuth of the semi-major axis from north towards east,
    in [0, pi).  Unpacks as ``(semi_major_m, semi_minor_m, orientation_rad)``.
    """

    semi_major_m: FloatArray
    semi_minor_m: FloatArray
    orientation_rad: FloatArray


def error_ellipse(cov_m2: ArrayLike) -> Ellipse:
    """Semi-axes and orientation of P (..., 2, 2) in m^2, P = [[a, b], [b, c]] in
    (north, east): lambda = (a + c)/2 +- sqrt(((a - c)/2)^2 + b^2) (closed-form
    eigenvalues of a symmetric 2x2 matrix), azimuth = atan2(2b, a - c)/2."""
    p = np.asarray(cov_m2, dtype=float)
    a, b, c = p[..., 0, 0], p[..., 0, 1], p[..., 1, 1]
    mean = 0.5 * (a + c)
    half_diff = np.hypot(0.5 * (a - c), b)
    lam1 = mean + half_diff
    lam2 = mean - half_diff
    # rounding can leave a singular P a hair below zero; a truly indefinite P stays NaN
    lam2 = np.where((lam2 < 0) & (lam2 > -1e-9 * lam1), 0.0, lam2)
    orientation = np.mod(0.5 * np.arctan2(2.0 * b, a - c), np.pi)
    with np.errstate(invalid="ignore"):
        return Ellipse(np.sqrt(lam1), np.sqrt(lam2), orientation)
