"""Geodesy against GeographicLib and hand values; angle wrapping properties."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from dracc import geodesy as g

geographiclib = pytest.importorskip("geographiclib.geodesic")
Geodesic = geographiclib.Geodesic.WGS84


@pytest.mark.parametrize("lat_deg", [0.0, 30.0, 45.0, 57.98, 80.0])
def test_k_phi_k_lambda_match_geographiclib_small_steps(lat_deg):
    """(B18), (B19): one metre north/east moves lat/lon by k_phi/k_lambda radians."""
    lat = math.radians(lat_deg)
    for azi, k in ((0.0, g.k_phi(lat)), (90.0, g.k_lambda(lat))):
        r = Geodesic.Direct(lat_deg, 10.0, azi, 1.0)
        moved = math.radians(r["lat2"] - lat_deg) if azi == 0 else math.radians(r["lon2"] - 10.0)
        assert moved == pytest.approx(k * 1.0, rel=1e-6)


def test_radii_hand_values():
    # At the equator R_M = a(1-e^2), R_N = a.
    assert g.radius_meridian_m(0.0) == pytest.approx(6335439.327, abs=1e-3)
    assert g.radius_prime_vertical_m(0.0) == pytest.approx(6378137.0)
    # At the pole both equal a / sqrt(1-e^2).
    assert g.radius_meridian_m(math.pi / 2) == pytest.approx(6399593.626, abs=1e-3)


@pytest.mark.parametrize("north_m,east_m", [(1000, 0), (0, 5000), (-3000, 4000), (20000, -15000)])
def test_offsets_match_geographiclib(north_m, east_m):
    lat0, lon0 = 57.98, 11.73
    lat1, lon1 = g.add_offset_ne(math.radians(lat0), math.radians(lon0), north_m, east_m)
    inv = Geodesic.Inverse(lat0, lon0, math.degrees(lat1), math.degrees(lon1))
    assert inv["s12"] == pytest.approx(math.hypot(north_m, east_m), rel=2e-4)
    n, e = g.offset_ne_m(lat1, lon1, math.radians(lat0), math.radians(lon0))
    assert n == pytest.approx(north_m, abs=1e-3) and e == pytest.approx(east_m, abs=1e-3)


def test_offset_across_antimeridian():
    n, e = g.offset_ne_m(0.0, math.radians(-179.999), 0.0, math.radians(179.999))
    assert e == pytest.approx(2 * 0.001 * math.pi / 180 * 6378137.0, rel=1e-6)


@given(st.floats(-1e4, 1e4, allow_nan=False), st.floats(-1e4, 1e4, allow_nan=False))
def test_angdiff_range_and_consistency(a, b):
    d = g.angdiff(a, b)
    assert -math.pi < d <= math.pi
    assert math.isclose(math.cos(d), math.cos(a - b), abs_tol=1e-6)
    assert math.isclose(math.sin(d), math.sin(a - b), abs_tol=1e-6)


def test_wrap_edges():
    assert g.wrap_pi(math.pi) == math.pi
    assert g.wrap_pi(-math.pi) == math.pi
    assert g.wrap_2pi(-1e-300) == 0.0 or g.wrap_2pi(-1e-300) < 2 * math.pi
    assert g.wrap_2pi(2 * math.pi) == 0.0


def test_circmean_no_359_1_blowup():
    assert g.angdiff(g.circmean(np.radians([359.0, 1.0])), 0.0) == pytest.approx(0.0, abs=1e-12)
    assert g.angdiff(g.circmean(np.radians([350.0, 10.0, np.nan])), 0.0) == pytest.approx(0.0, abs=1e-12)
    assert np.isnan(g.circmean(np.radians([0.0, 180.0])))
    assert 0.0 <= g.circmean(np.radians([359.0, 358.0])) < 2 * math.pi
