"""The one error ellipse: an indefinite covariance is reported (NaN), never clamped."""

import numpy as np
import pytest

from dracc.math.ellipse import error_ellipse


def test_indefinite_covariance_is_reported_not_clamped():
    # eigenvalues 4 and -1: no real ellipse; a clamp would give semi-minor 0
    e = error_ellipse(np.array([[1.5, 2.5], [2.5, 1.5]]))
    assert e.semi_major_m == pytest.approx(2.0)
    assert np.isnan(e.semi_minor_m)


def test_singular_covariance_with_rounding_is_a_line():
    # rank one, built so that rounding leaves the small eigenvalue a hair below zero
    v = np.array([0.6, 0.8])
    p = 9.0 * np.outer(v, v)
    smaj, smin, orient = error_ellipse(p)
    assert smaj == pytest.approx(3.0)
    assert smin == 0.0 or smin == pytest.approx(0.0, abs=1e-6)
    assert orient == pytest.approx(np.arctan2(0.8, 0.6))  # azimuth of (north .6, east .8)


def test_broadcasts_and_unpacks():
    p = np.stack([np.diag([4.0, 1.0]), np.diag([1.0, 9.0])])
    smaj, smin, orient = error_ellipse(p)
    assert smaj == pytest.approx([2.0, 3.0])
    assert smin == pytest.approx([1.0, 1.0])
    assert orient == pytest.approx([0.0, np.pi / 2])
