"""Geodesy against GeographicLib and hand values; angle wrapping properties."""

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from dracc.core import geodesy as g

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
    _n, e = g.offset_ne_m(0.0, math.radians(-179.999), 0.0, math.radians(179.999))
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
    assert g.angdiff(g.circmean(np.radians([350.0, 10.0, np.nan])), 0.0) == pytest.approx(
        0.0, abs=1e-12
    )
    assert np.isnan(g.circmean(np.radians([0.0, 180.0])))
    assert 0.0 <= g.circmean(np.radians([359.0, 358.0])) < 2 * math.pi


def test_interp_position_hand_values_gaps_and_exact_hits():
    # samples at 0, 10, 20, 100 s; gaps up to 15 s bridged
    t = np.array([0.0, 10.0, 20.0, 100.0])
    lat = np.array([0.10, 0.20, 0.40, 0.50])
    lon = np.array([1.00, 1.10, 1.30, 1.40])
    tq = np.array([-1.0, 0.0, 2.5, 10.0, 15.0, 50.0, 100.0, 101.0])
    la, lo = g.interp_position(t, lat, lon, tq, 15.0)
    # by hand: 2.5 s is a quarter of 0..10; 15 s half of 10..20; 50 s inside the 80 s gap
    want_lat = [np.nan, 0.10, 0.125, 0.20, 0.30, np.nan, 0.50, np.nan]
    want_lon = [np.nan, 1.00, 1.025, 1.10, 1.20, np.nan, 1.40, np.nan]
    np.testing.assert_allclose(la, want_lat, rtol=0, atol=1e-15)
    np.testing.assert_allclose(lo, want_lon, rtol=0, atol=1e-15)
    # an exact hit is kept even when both of its gaps are too long; the gap bound is inclusive
    la, _ = g.interp_position(t, lat, lon, np.array([100.0, 60.0]), 5.0)
    assert la[0] == 0.50 and np.isnan(la[1])
    la, _ = g.interp_position(t, lat, lon, np.array([5.0]), 10.0)
    assert la[0] == pytest.approx(0.15, abs=1e-15)


def test_interp_position_antimeridian_short_way():
    # 179.9 E -> 179.9 W in 10 s: the midpoint is on the antimeridian, not at 0
    lon = np.radians([179.9, -179.9])
    _la, lo = g.interp_position(np.array([0.0, 10.0]), np.zeros(2), lon, np.array([5.0, 7.5]), 60.0)
    assert abs(g.angdiff(lo[0], np.pi)) < 1e-12
    assert lo[1] == pytest.approx(np.radians(-179.95), abs=1e-12)
    assert np.all(lo <= np.pi) and np.all(lo > -np.pi)


def test_interp_position_drops_nonfinite_and_sorts():
    t = np.array([20.0, np.nan, 0.0, 10.0, 5.0])
    lat = np.array([0.4, 0.9, 0.0, 0.2, np.nan])
    lon = np.zeros(5)
    la, _ = g.interp_position(t, lat, lon, np.array([5.0, 15.0]), 10.0)
    # the NaN sample at 5 s is left out: 5 s interpolates 0..10
    np.testing.assert_allclose(la, [0.1, 0.3], atol=1e-15)
    la, lo = g.interp_position(np.zeros(0), np.zeros(0), np.zeros(0), np.array([1.0, 2.0]), 10.0)
    assert la.shape == (2,) and np.all(np.isnan(la)) and np.all(np.isnan(lo))


def test_interp_position_ns_matches_seconds():
    # int64 ns far from 0 (a 2026 epoch) give what float seconds from that epoch give
    t0 = 1_790_000_000_000_000_000
    t_s = np.array([0.0, 1.0, 2.0, 9.0])
    lat = np.array([0.1, 0.2, 0.3, 0.4])
    lon = np.array([3.1, -3.1, -3.0, -2.9])
    tq_s = np.array([0.25, 1.5, 2.0, 5.0, 9.0])
    la_s, lo_s = g.interp_position(t_s, lat, lon, tq_s, 2.0)
    t_ns = t0 + (t_s * 1e9).astype(np.int64)
    tq_ns = t0 + (tq_s * 1e9).astype(np.int64)
    la_n, lo_n = g.interp_position(t_ns, lat, lon, tq_ns, 2.0e9)
    np.testing.assert_array_equal(np.isnan(la_n), [False, False, False, True, False])
    np.testing.assert_allclose(la_n, la_s, atol=1e-15)
    np.testing.assert_allclose(lo_n, lo_s, atol=1e-15)
    # 0.25 s of 0..1 s from 3.1 to -3.1 rad the short way (2 pi - 6.2 rad apart)
    assert lo_n[0] == pytest.approx(g.wrap_pi(3.1 + 0.25 * (2 * np.pi - 6.2)), abs=1e-12)
