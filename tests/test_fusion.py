"""Fix fusion (seeds/004 W1-W4, seeds/002 (1), (35)-(38)): hand solutions, GeographicLib,
Monte Carlo scatter."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dracc.core.errors import DraccError, GeometryError
from dracc.core.geodesy import add_offset_ne, offset_ne_m, range_azimuth
from dracc.math.ellipse import error_ellipse
from dracc.math.fusion import (
    OMEGA_E_RADPS,
    BearingLOP,
    LineLOP,
    NadirCircle,
    PierLine,
    PositionFix,
    RangeLOP,
    alongside_reference,
    fuse_fix,
    stack_rows,
)

LAT0, LON0 = np.deg2rad(54.52), np.deg2rad(18.55)  # Gdynia roads
D = np.deg2rad


def _direct(lat, lon, az_rad, s_m):
    """Point at geodesic distance s and azimuth az (GeographicLib), radians."""
    geo = pytest.importorskip("geographiclib.geodesic").Geodesic.WGS84
    r = geo.Direct(np.rad2deg(lat), np.rad2deg(lon), np.rad2deg(az_rad), s_m)
    return D(r["lat2"]), D(r["lon2"])


def _local(n_m, e_m):
    lat, lon = add_offset_ne(LAT0, LON0, n_m, e_m)
    return float(lat), float(lon)


# ------------------------------------------------------------------ geodesy


@pytest.mark.parametrize(
    "s_m, tol_m, tol_rad", [(150.0, 1e-6, 1e-9), (2e4, 1e-4, 1e-8), (1e5, 1e-2, 2e-7)]
)
def test_range_azimuth_against_geographiclib(s_m, tol_m, tol_rad):
    geo = pytest.importorskip("geographiclib.geodesic").Geodesic.WGS84
    rng = np.random.default_rng(7)
    lat1 = rng.uniform(-75, 75, 50)
    lon1 = rng.uniform(-180, 180, 50)
    az = rng.uniform(0, 360, 50)
    out = [geo.Direct(a, b, c, s_m) for a, b, c in zip(lat1, lon1, az, strict=True)]
    lat2 = D(np.array([o["lat2"] for o in out]))
    lon2 = D(np.array([o["lon2"] for o in out]))
    dist, azi = range_azimuth(D(lat1), D(lon1), lat2, lon2)
    assert np.max(np.abs(dist - s_m)) < tol_m
    assert np.max(np.abs(np.angle(np.exp(1j * (azi - D(az)))))) < tol_rad
    # and the back azimuth (at point 2) for bearings observed at the mark
    back = np.array([o["azi2"] for o in out])
    _, azi21 = range_azimuth(lat2, lon2, D(lat1), D(lon1))
    assert np.max(np.abs(np.angle(np.exp(1j * (azi21 - D(back + 180.0)))))) < tol_rad


def test_error_ellipse_matches_eigen_decomposition():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(200, 2, 2))
    p = a @ np.swapaxes(a, -1, -2) + 0.01 * np.eye(2)
    ell = error_ellipse(p)
    w, v = np.linalg.eigh(p)
    assert np.allclose(ell.semi_major_m, np.sqrt(w[:, 1]))
    assert np.allclose(ell.semi_minor_m, np.sqrt(w[:, 0]))
    major = v[:, :, 1]  # (north, east) of the major axis
    az = np.mod(np.arctan2(major[:, 1], major[:, 0]), np.pi)
    assert np.allclose(np.angle(np.exp(2j * (az - ell.orientation_rad))), 0.0, atol=1e-9)
    # by hand: variance 9 m^2 east, 1 m^2 north -> major axis 3 m towards east (pi/2)
    e = error_ellipse(np.diag([1.0, 9.0]))
    assert (e.semi_major_m, e.semi_minor_m, e.orientation_rad) == pytest.approx(
        (3.0, 1.0, np.pi / 2)
    )


# ------------------------------------------------------------ LS / WLS by hand


def _line(az_deg, right_m, sigma_m, offset_m):
    """A line at azimuth az through the point right_m to the right of the origin
    (geodesic end points 500 m either side, GeographicLib)."""
    lat, lon = _direct(LAT0, LON0, D(az_deg + 90.0), right_m) if right_m else (LAT0, LON0)
    a = _direct(lat, lon, D(az_deg + 180.0), 500.0)
    b = _direct(lat, lon, D(az_deg), 500.0)
    return LineLOP(*a, *b, sigma_m, offset_m=offset_m)


def _two_lines(sigma1=5.0, sigma2=5.0):
    """Line 1 runs north through the origin, the ship 30 m to its right (east): E = 30.
    Line 2 runs at 045 through the origin, ship 10 m to its right: -N/sqrt2 + E/sqrt2 = 10."""
    return [_line(0.0, 0.0, sigma1, 30.0), _line(45.0, 0.0, sigma2, 10.0)]


@pytest.mark.parametrize("weighted", [False, True])
def test_two_lines_hand_solved(weighted):
    sol = fuse_fix(_two_lines(), *_local(300.0, -200.0), weighted=weighted)
    n, e = offset_ne_m(sol.lat_rad, sol.lon_rad, LAT0, LON0)
    # hand: E = 30, N = E - 10 sqrt2 = 15.858
    assert (float(n), float(e)) == pytest.approx((30.0 - 10.0 * np.sqrt(2.0), 30.0), abs=2e-3)
    # G = [[0, 1], [-1/sqrt2, 1/sqrt2]]; G^T G = [[.5, -.5], [-.5, 1.5]]; its inverse [[3, 1], [1, 1]]
    # (tolerance: the lines' azimuths at the ship differ from those at the origin by the
    # meridian convergence over 30 m, ~7e-6 rad)
    assert np.allclose(sol.cofactor, [[3.0, 1.0], [1.0, 1.0]], atol=1e-4)
    assert np.allclose(sol.cov_m2, 25.0 * np.array([[3.0, 1.0], [1.0, 1.0]]), atol=25e-4)  # (W3)
    assert sol.dop == pytest.approx(2.0, abs=1e-4)  # sqrt(3 + 1)
    assert sol.redundancy == 0 and sol.chi2 == pytest.approx(0.0, abs=1e-8)


def test_ls_and_wls_differ_when_weights_differ():
    lines = _two_lines(2.0, 2.0)
    # a third line running east through N = +5 m (ship 5 m north => left of A->B going east)
    obs = [*lines, _line(90.0, -5.0, 20.0, -1.0)]
    ls = fuse_fix(obs, LAT0, LON0, weighted=False)
    wls = fuse_fix(obs, LAT0, LON0, weighted=True)
    g = np.array([[0.0, 1.0], [-1 / np.sqrt(2), 1 / np.sqrt(2)], [1.0, 0.0]])
    z = np.array([30.0, 10.0, 5.0 + 1.0])  # metres, in the frame of the origin
    w = np.diag([1 / 4, 1 / 4, 1 / 400])
    x_ls = np.linalg.solve(g.T @ g, g.T @ z)  # (W1)
    x_wls = np.linalg.solve(g.T @ w @ g, g.T @ w @ z)  # (W4)
    for sol, x in ((ls, x_ls), (wls, x_wls)):
        n, e = offset_ne_m(sol.lat_rad, sol.lon_rad, LAT0, LON0)
        assert (float(n), float(e)) == pytest.approx(tuple(x), abs=2e-3)
    assert np.allclose(wls.cov_m2, np.linalg.inv(g.T @ w @ g), rtol=1e-4)  # (W3)
    assert wls.redundancy == 1 and wls.chi2 > 0
    assert np.trace(ls.cov_m2) > np.trace(wls.cov_m2)  # WLS is the better estimator


def test_two_ranges_closed_form_intersection():
    """Marks 4 km apart on a geodesic baseline; plane-triangle closed form and geodesic truth."""
    geo = pytest.importorskip("geographiclib.geodesic").Geodesic.WGS84
    m1 = _local(0.0, 0.0)
    m2 = _direct(*m1, D(90.0), 4000.0)
    truth = _direct(*m1, D(30.0), 3000.0)
    r1 = geo.Inverse(*np.rad2deg(m1), *np.rad2deg(truth))["s12"]
    r2 = geo.Inverse(*np.rad2deg(m2), *np.rad2deg(truth))["s12"]
    obs = [RangeLOP(*m1, r1, 5.0), RangeLOP(*m2, r2, 5.0)]
    sol = fuse_fix(obs, *_local(2000.0, 2000.0))  # the northern solution
    assert np.hypot(*offset_ne_m(sol.lat_rad, sol.lon_rad, *truth)) < 1e-3
    # closed form: the angle at m1 between the baseline and the ship (law of cosines)
    d = 4000.0
    angle = np.arccos((d**2 + r1**2 - r2**2) / (2 * d * r1))
    inv = geo.Inverse(*np.rad2deg(m1), *np.rad2deg((sol.lat_rad, sol.lon_rad)))
    assert D(90.0 - inv["azi1"]) == pytest.approx(angle, abs=1e-6)  # spherical excess ~1e-7
    assert inv["s12"] == pytest.approx(r1, abs=1e-3)
    sol_s = fuse_fix(obs, *_local(-2000.0, 2000.0))  # the mirror solution, south of the baseline
    inv_s = geo.Inverse(*np.rad2deg(m1), *np.rad2deg((sol_s.lat_rad, sol_s.lon_rad)))
    assert D(inv_s["azi1"] - 90.0) == pytest.approx(angle, abs=1e-6)


# --------------------------------------------------------------- Monte Carlo


def _scene():
    ship = _local(1200.0, -800.0)
    marks = [
        _local(6000.0, 1000.0),
        _local(-2000.0, 5000.0),
        _local(-4000.0, -6000.0),
        _local(3000.0, -7000.0),
    ]
    return ship, marks


def test_wls_covariance_matches_monte_carlo_scatter():
    geo = pytest.importorskip("geographiclib.geodesic").Geodesic.WGS84
    ship, marks = _scene()
    rng = np.random.default_rng(11)
    sig_r = [8.0, 15.0, 30.0]
    sig_b = D(0.5)
    inv = [geo.Inverse(*np.rad2deg(ship), *np.rad2deg(m)) for m in marks]
    runs = 4000
    obs = [
        RangeLOP(*m, inv[j]["s12"] + rng.normal(0, sig_r[j], runs), sig_r[j])
        for j, m in enumerate(marks[:3])
    ]
    obs.append(BearingLOP(*marks[3], D(inv[3]["azi1"]) + rng.normal(0, sig_b, runs), sig_b))
    sol = fuse_fix(obs, *ship)  # one batch of 4000 independent fixes
    est = np.stack(offset_ne_m(sol.lat_rad, sol.lon_rad, *ship), axis=-1)
    scatter = np.cov(est.T)
    p = sol.cov_m2.mean(axis=0)
    # elementwise within the sampling error of a covariance from 4000 samples (~2.2 %)
    assert np.allclose(scatter, p, rtol=0.08, atol=0.08 * np.sqrt(p[0, 0] * p[1, 1]))
    assert np.abs(est.mean(axis=0)).max() < 4 * np.sqrt(np.diag(p).max() / runs)
    # the batch equals one-at-a-time solutions
    one = fuse_fix(
        [
            type(o)(
                *(
                    getattr(o, f)[7] if np.ndim(getattr(o, f)) else getattr(o, f)
                    for f in o.__dataclass_fields__
                )
            )
            for o in obs
        ],
        *ship,
    )
    assert (one.lat_rad, one.lon_rad) == pytest.approx((sol.lat_rad[7], sol.lon_rad[7]), abs=1e-12)
    assert np.allclose(one.cov_m2, sol.cov_m2[7])


def test_dop_trace_form_gives_rms_over_sigma():
    """(38): rms = DOP sigma holds with DOP = sqrt(q_nn + q_ee), not with the squared (37)."""
    geo = pytest.importorskip("geographiclib.geodesic").Geodesic.WGS84
    ship, marks = _scene()
    sigma = 10.0
    rng = np.random.default_rng(5)
    ranges = np.array([geo.Inverse(*np.rad2deg(ship), *np.rad2deg(m))["s12"] for m in marks])
    runs = 4000
    obs = [
        RangeLOP(*m, r + rng.normal(0, sigma, runs), sigma)
        for m, r in zip(marks, ranges, strict=True)
    ]
    sol = fuse_fix(obs, *ship, weighted=False)
    n, e = offset_ne_m(sol.lat_rad, sol.lon_rad, *ship)
    rms = np.sqrt(np.mean(n**2 + e**2))
    dop = float(np.mean(sol.dop))
    assert np.ptp(sol.dop) < 1e-3  # geometry only: nearly the same for every run
    assert rms / sigma == pytest.approx(dop, rel=0.04)  # (38)
    q = sol.cofactor[0]
    paper_37 = np.sqrt(q[0, 0] ** 2 + q[1, 1] ** 2)
    assert abs(paper_37 - rms / sigma) > 0.2  # the squared form does not satisfy (38)
    assert np.allclose(sol.drms_m, sol.dop * sigma, rtol=1e-9)  # equal sigmas: drms = DOP sigma


def test_chi_square_of_redundant_fits_has_its_degrees_of_freedom():
    geo = pytest.importorskip("geographiclib.geodesic").Geodesic.WGS84
    ship, marks = _scene()
    rng = np.random.default_rng(9)
    ranges = np.array([geo.Inverse(*np.rad2deg(ship), *np.rad2deg(m))["s12"] for m in marks])
    runs = 2000
    sol = fuse_fix(
        [
            RangeLOP(*m, r + rng.normal(0, 5.0, runs), 5.0)
            for m, r in zip(marks, ranges, strict=True)
        ],
        *ship,
    )
    assert sol.redundancy == 2
    assert np.mean(sol.chi2) == pytest.approx(2.0, abs=0.15)  # sd of the mean 0.045
    assert np.mean(sol.variance_factor) == pytest.approx(1.0, abs=0.075)


# ---------------------------------------------------------- rows and gradients


@pytest.mark.parametrize(
    "obs",
    [
        RangeLOP(*_local(3000.0, 4000.0), 5000.0, 5.0),
        BearingLOP(*_local(3000.0, 4000.0), 0.9, 0.01, "ship"),
        BearingLOP(*_local(3000.0, 4000.0), 4.0, 0.01, "mark"),
        NadirCircle(D(20.0), D(-40.0), D(60.0), 1e-4),
        LineLOP(*_local(0.0, 0.0), *_local(1000.0, 300.0), 3.0, 7.0),
    ],
    ids=["range", "bearing-ship", "bearing-mark", "nadir", "line"],
)
def test_gradients_match_finite_differences(obs):
    lat, lon = _local(150.0, -120.0)
    rows = obs.linearise(lat, lon)
    h = 0.5
    for axis in range(2):
        dn, de = (h, 0.0) if axis == 0 else (0.0, h)
        up = obs.linearise(*add_offset_ne(lat, lon, dn, de)).residual
        dw = obs.linearise(*add_offset_ne(lat, lon, -dn, -de)).residual
        # residual = u - f(x): d(residual)/dx = -g
        assert -(up - dw)[0] / (2 * h) == pytest.approx(rows.g[0, axis], rel=1e-5, abs=1e-12)


def test_position_fix_rows_and_batch():
    fix = PositionFix(LAT0, LON0, [[25.0, 5.0], [5.0, 16.0]])
    lats = np.full(3, LAT0)
    rows = stack_rows([fix, RangeLOP(*_local(1000.0, 0.0), 1000.0, 5.0)], lats, np.full(3, LON0))
    assert rows.g.shape == (3, 3, 2) and rows.cov.shape == (3, 3, 3)
    assert np.allclose(rows.cov[0, :2, :2], [[25.0, 5.0], [5.0, 16.0]])
    assert rows.kinds == ("fix_north", "fix_east", "range")


# ---------------------------------------------------------------- pier line


@pytest.mark.parametrize(
    "heading_deg, side, expected_east_m",
    [
        (0.0, "starboard", -9.0),  # pier to starboard, ship heading up the pier: ship west of it
        (180.0, "starboard", 9.0),  # heading down the pier, starboard to it: ship east
        (0.0, "port", 13.0),  # port side-to: ref point 11 + 2 m east of the pier line
        (180.0, "port", -13.0),
    ],
)
def test_pier_line_shift_by_hand(heading_deg, side, expected_east_m):
    """Pier A->B runs north; half breadth 10 m, fenders 1 m, reference point 2 m to starboard."""
    a, b = _local(-100.0, 0.0), _local(100.0, 0.0)
    pier = PierLine(
        *a,
        *b,
        D(heading_deg),
        side,
        half_breadth_m=10.0,
        sigma_m=0.5,
        ref_transverse_m=2.0,
        gap_m=1.0,
    )
    assert pier.offset_m == pytest.approx(
        expected_east_m, abs=1e-9
    )  # right of A->B (east) positive
    mark = _local(20.0, 0.0)
    sol = alongside_reference(pier, abeam_mark=mark, abeam_sigma_m=1.0)
    truth = (
        _direct(*mark, D(90.0), expected_east_m)
        if expected_east_m > 0
        else _direct(*mark, D(270.0), -expected_east_m)
    )
    assert np.hypot(*offset_ne_m(sol.lat_rad, sol.lon_rad, *truth)) < 0.01
    # across the pier the ellipse is the pier's 0.5 m, along it the mark's 1 m
    assert sol.ellipse.semi_major_m == pytest.approx(1.0, rel=1e-4)
    assert sol.ellipse.semi_minor_m == pytest.approx(0.5, rel=1e-4)
    assert np.angle(np.exp(2j * sol.ellipse.orientation_rad)) == pytest.approx(
        0.0, abs=1e-4
    )  # along: north


def test_alongside_reference_with_ins_fixes():
    a, b = _local(0.0, -100.0), _local(0.0, 100.0)  # pier running east, ship north of it
    pier = PierLine(*a, *b, D(90.0), "starboard", half_breadth_m=8.0, sigma_m=0.3)
    # starboard side-to heading east: starboard points south, so the ship lies north; offset = -8 (left)
    assert pier.offset_m == pytest.approx(-8.0)
    ins_mean = PositionFix(*_local(20.0, 35.0), np.diag([40.0**2, 40.0**2]))
    sol = alongside_reference(pier, fixes=[ins_mean])
    n, e = offset_ne_m(sol.lat_rad, sol.lon_rad, LAT0, LON0)
    assert float(n) == pytest.approx(8.0, abs=0.01)  # across: the pier
    assert float(e) == pytest.approx(35.0, abs=0.01)  # along: the INS
    assert np.sqrt(sol.cov_m2[0, 0]) < 0.3 and np.sqrt(sol.cov_m2[1, 1]) == pytest.approx(
        40.0, rel=1e-6
    )


def test_pier_line_errors():
    a, b = _local(-100.0, 0.0), _local(100.0, 0.0)
    with pytest.raises(GeometryError, match="not along the pier"):
        PierLine(*a, *b, D(40.0), "port", half_breadth_m=10.0, sigma_m=0.5)
    with pytest.raises(GeometryError, match="side"):
        PierLine(*a, *b, D(0.0), "aft", half_breadth_m=10.0, sigma_m=0.5)
    pier = PierLine(*a, *b, D(0.0), "port", half_breadth_m=10.0, sigma_m=0.5)
    with pytest.raises(GeometryError, match="alone"):
        alongside_reference(pier)


# -------------------------------------------------------------- nadir circle


def test_nadir_circle_from_gyro_vector_is_equation_1():
    rng = np.random.default_rng(2)
    u = rng.normal(size=3)
    u /= np.linalg.norm(u)
    t_s = 5000.0
    circle = NadirCircle.from_gyro_vector(u, t_s, 1.0, 1e-4)
    lat, lon = D(35.0), D(129.0)
    w = OMEGA_E_RADPS * t_s
    eq1 = (
        -u[0] * np.cos(lat) * np.cos(lon + w)
        - u[1] * np.cos(lat) * np.sin(lon + w)
        - u[2] * np.sin(lat)
    )  # (1)
    assert circle.cos_nadir(lat, lon) == pytest.approx(eq1, abs=1e-12)
    with pytest.raises(GeometryError, match="unit vector"):
        NadirCircle.from_gyro_vector(2 * u, t_s, 1.0, 1e-4)


def test_three_nadir_circles_fix_the_position():
    lat, lon = D(35.1), D(129.05)
    subs = [(D(80.0), D(10.0)), (D(-5.0), D(60.0)), (D(10.0), D(-150.0))]
    circles = []
    for s_lat, s_lon in subs:
        c = NadirCircle(s_lat, s_lon, 0.0, 2e-5)
        circles.append(NadirCircle(s_lat, s_lon, float(np.arccos(c.cos_nadir(lat, lon))), 2e-5))
    sol = fuse_fix(circles, D(35.0), D(129.0))
    assert np.hypot(*offset_ne_m(sol.lat_rad, sol.lon_rad, lat, lon)) < 1e-3
    assert sol.kinds == ("nadir", "nadir", "nadir")
    # 2e-5 rad of nadir angle is ~130 m on the Earth: the drms is of that order times DOP
    assert 50.0 < sol.drms_m < 2000.0


# ---------------------------------------------------------------- geometry


def test_single_lop_and_parallel_lines_cannot_fix():
    lines = _two_lines()
    with pytest.raises(GeometryError, match="do not fix"):
        fuse_fix(lines[:1], LAT0, LON0)
    a, b = _local(50.0, -500.0), _local(50.0, 500.0)
    parallel = LineLOP(*_local(0.0, -500.0), *_local(0.0, 500.0), 5.0)
    with pytest.raises(GeometryError, match="do not fix"):
        fuse_fix([parallel, LineLOP(*a, *b, 5.0)], LAT0, LON0)
    with pytest.raises(GeometryError, match="no observations"):
        fuse_fix([], LAT0, LON0)
    assert issubclass(GeometryError, DraccError)


def test_bad_observations_are_refused():
    with pytest.raises(GeometryError, match="sigma"):
        RangeLOP(LAT0, LON0, 100.0, 0.0)
    with pytest.raises(GeometryError, match="positive definite"):
        PositionFix(LAT0, LON0, [[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(GeometryError, match="observed_at"):
        BearingLOP(LAT0, LON0, 1.0, 0.01, "bridge")
    with pytest.raises(GeometryError, match="less than 1 m"):
        LineLOP(LAT0, LON0, LAT0, LON0, 1.0)


# ---------------------------------------------------------------- properties


@settings(max_examples=60, deadline=None)
@given(
    lat=st.floats(-80, 80),
    lon=st.floats(-180, 180),
    az=st.floats(0, 360),
    s=st.floats(10.0, 50_000.0),
)
def test_range_is_symmetric_and_back_azimuth_is_opposite(lat, lon, az, s):
    lat2, lon2 = _direct(D(lat), D(lon), D(az), s)
    d12, a12 = range_azimuth(D(lat), D(lon), lat2, lon2)
    d21, _ = range_azimuth(lat2, lon2, D(lat), D(lon))
    assert d12 == pytest.approx(d21, abs=1e-6) and d12 == pytest.approx(s, abs=1e-3)
    assert np.angle(np.exp(1j * (a12 - D(az)))) == pytest.approx(0.0, abs=1e-7)


@settings(max_examples=60, deadline=None)
@given(
    n=st.floats(-5000, 5000),
    e=st.floats(-5000, 5000),
    sn=st.floats(0.5, 50),
    se=st.floats(0.5, 50),
    rho=st.floats(-0.9, 0.9),
)
def test_a_fix_alone_is_returned_with_its_covariance(n, e, sn, se, rho):
    cov = np.array([[sn**2, rho * sn * se], [rho * sn * se, se**2]])
    fix = PositionFix(*_local(n, e), cov)
    sol = fuse_fix([fix], LAT0, LON0)
    assert np.hypot(*offset_ne_m(sol.lat_rad, sol.lon_rad, fix.lat_rad, fix.lon_rad)) < 1e-4
    assert np.allclose(sol.cov_m2, cov, rtol=1e-9)
    ell = sol.ellipse
    assert ell.semi_major_m**2 + ell.semi_minor_m**2 == pytest.approx(sn**2 + se**2, rel=1e-9)
    assert ell.semi_major_m * ell.semi_minor_m == pytest.approx(
        np.sqrt(np.linalg.det(cov)), rel=1e-6
    )
