"""Datums (seeds/004 §2): chart positions on ED50, NAD27, ... brought to WGS-84 before fusion.

References: PROJ's own choice of transformation (pyproj ``Transformer.from_crs``), the
EPSG dataset's published parameters applied by hand (geocentric Helmert, checked on the
EPSG Guidance Note 7-2 worked example), GeographicLib for the synthetic observations.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from geographiclib.geodesic import Geodesic
from pyproj import Transformer
from pyproj.transformer import AreaOfInterest

from dracc.core.errors import ConfigError
from dracc.ingest.datums import resolve_datum, to_wgs84
from dracc.pipeline.fix import run_fix, run_fix_datums
from dracc.report.fix_report import JSON_SCHEMA

WGS84_ELL = (6378137.0, 1 / 298.257223563)
INTL_1924 = (6378388.0, 1 / 297.0)  # ED50's ellipsoid
CLARKE_1866 = (6378206.4, 1 - 6356583.8 / 6378206.4)  # NAD27's, a and b


def geocentric(lat_deg, lon_deg, h_m, ell):
    a, f = ell
    e2 = f * (2 - f)
    la, lo = math.radians(lat_deg), math.radians(lon_deg)
    n = a / math.sqrt(1 - e2 * math.sin(la) ** 2)
    return np.array(
        [
            (n + h_m) * math.cos(la) * math.cos(lo),
            (n + h_m) * math.cos(la) * math.sin(lo),
            (n * (1 - e2) + h_m) * math.sin(la),
        ]
    )


def geodetic(xyz, ell):
    """ECEF -> (lat, lon) degrees by fixed-point iteration on the latitude (to 1e-12 rad)."""
    a, f = ell
    e2 = f * (2 - f)
    x, y, z = xyz
    p = math.hypot(x, y)
    la = math.atan2(z, p * (1 - e2))
    for _ in range(20):
        n = a / math.sqrt(1 - e2 * math.sin(la) ** 2)
        h = p / math.cos(la) - n
        la = math.atan2(z, p * (1 - e2 * n / (n + h)))
    return math.degrees(la), math.degrees(math.atan2(y, x))


def helmert(lat_deg, lon_deg, src, dst, t_m, r_arcsec=(0.0, 0.0, 0.0), ds_ppm=0.0):
    """EPSG method 9606 (position vector, small angles) or 9603 (translations only), h = 0."""
    rx, ry, rz = (math.radians(r / 3600.0) for r in r_arcsec)
    rot = np.array([[1, -rz, ry], [rz, 1, -rx], [-ry, rx, 1]])
    xyz = np.asarray(t_m) + (1 + ds_ppm * 1e-6) * rot @ geocentric(lat_deg, lon_deg, 0.0, src)
    return geodetic(xyz, dst)


def geo_m(lat1, lon1, lat2, lon2):
    return Geodesic.WGS84.Inverse(lat1, lon1, lat2, lon2)["s12"]


def test_hand_geocentric_formulas_reproduce_the_epsg_guidance_note_example():
    """GN 7-2 (method 1031/9603): WGS 84 53°48'33.82"N 2°07'46.38"E h 73 m is geocentric
    X 3771793.97, Y 140253.34, Z 5124304.35 m; +(84.87, 96.49, 116.95) m gives the ED50
    geocentric 3771878.84, 140349.83, 5124421.30 m."""
    lat = 53 + 48 / 60 + 33.82 / 3600
    lon = 2 + 7 / 60 + 46.38 / 3600
    xyz = geocentric(lat, lon, 73.0, WGS84_ELL)
    assert xyz == pytest.approx([3771793.97, 140253.34, 5124304.35], abs=0.01)
    ed50 = xyz + np.array([84.87, 96.49, 116.95])
    assert ed50 == pytest.approx([3771878.84, 140349.83, 5124421.30], abs=0.01)
    back = geodetic(geocentric(*geodetic(ed50, INTL_1924), 0.0, INTL_1924), INTL_1924)
    assert back == pytest.approx(geodetic(ed50, INTL_1924), abs=1e-10)


def test_ed50_north_sea_by_the_published_epsg_1311_parameters():
    """ED50 to WGS 84 (18), EPSG:1311 (UKOOA, North Sea offshore, ±1 m): tx -89.5,
    ty -93.8, tz -123.1 m, rz -0.156", +1.2 ppm (position vector): a shift of ~120 m."""
    lat, lon = 55.5, 3.0
    pos = to_wgs84([lat], [lon], "ED50")
    t = pos.transformation
    assert t.operation_code == "EPSG:1311" and t.accuracy_m == 1.0 and t.grid_free
    assert t.crs == "EPSG:4230" and not t.fallback
    want = helmert(lat, lon, INTL_1924, WGS84_ELL, (-89.5, -93.8, -123.1), (0, 0, -0.156), 1.2)
    assert geo_m(pos.lat_deg[0], pos.lon_deg[0], *want) < 0.001
    shift = geo_m(lat, lon, *want)
    assert 100.0 < shift < 140.0  # "about 100 m" in Europe
    assert pos.shift_m[0] == pytest.approx(shift, abs=0.001)


def test_nad27_in_the_united_states_grid_free_fallback():
    """NAD27 at 40°N 100°W (Kansas): NADCON (us_noaa_conus.tif) is the best transformation;
    without the grid the EPSG:1175 geocentric translation (-8, 159, 175) m, ±7 m, is used
    and the report says so."""
    lat, lon = 40.0, -100.0
    pos = to_wgs84([lat], [lon], "NAD27")
    t = pos.transformation
    got = (pos.lat_deg[0], pos.lon_deg[0])
    if t.operation_code == "EPSG:1175":  # no NADCON grid installed (dracc's test machine)
        assert t.fallback and "us_noaa_conus.tif" in t.missing_grids and t.grid_free
        assert t.missing_accuracy_m is not None and t.missing_accuracy_m < 7.0
        assert "grid-free fallback" in t.describe()
        want = helmert(lat, lon, CLARKE_1866, WGS84_ELL, (-8.0, 159.0, 175.0))
        assert geo_m(*got, *want) < 0.001
    else:  # the grid is installed: the grid result lies within the Helmert's accuracy
        want = helmert(lat, lon, CLARKE_1866, WGS84_ELL, (-8.0, 159.0, 175.0))
        assert not t.fallback and geo_m(*got, *want) < 7.0 + (t.accuracy_m or 2.0)
    assert 20.0 < pos.shift_m[0] < 60.0


@pytest.mark.parametrize(
    "datum, lat, lon",
    [
        ("ED50", 55.5, 3.0),  # North Sea
        ("ED50", 54.6, 18.8),  # Gulf of Gdańsk
        ("EPSG:4230", 36.2, -6.4),  # Gulf of Cádiz
        ("OSGB36", 50.7, -1.3),  # the Solent
        ("Tokyo", 35.4, 139.7),  # Tokyo Bay
        ("Pulkovo 1942", 59.9, 29.9),  # Gulf of Finland
        ("NAD83", 37.8, -122.4),  # San Francisco Bay
    ],
)
def test_matches_the_transformation_proj_itself_chooses(datum, lat, lon):
    pos = to_wgs84([lat, lat + 0.01], [lon, lon + 0.01], datum)
    ref = Transformer.from_crs(
        resolve_datum(datum),
        "EPSG:4326",
        always_xy=True,
        area_of_interest=AreaOfInterest(lon, lat, lon + 0.01, lat + 0.01),
    )
    for i in range(2):
        x, y = ref.transform(lon + 0.01 * i, lat + 0.01 * i)
        assert geo_m(pos.lat_deg[i], pos.lon_deg[i], y, x) < 0.001
    assert pos.transformation.accuracy_m is not None and pos.transformation.accuracy_m > 0
    assert np.all(pos.shift_m >= 0)


def test_wgs84_is_left_alone_and_names_are_normalised():
    pos = to_wgs84([54.0], [18.0], "wgs 84")
    assert pos.lat_deg[0] == 54.0 and pos.lon_deg[0] == 18.0 and pos.shift_m[0] == 0.0
    assert resolve_datum("pulkovo-1942") == resolve_datum("SK42") == "EPSG:4284"
    assert resolve_datum("epsg:4267") == resolve_datum("nad27") == "EPSG:4267"


@pytest.mark.parametrize(
    "datum, lat, lon, words",
    [
        ("Bessel 1899", 54.0, 18.0, ("unknown datum 'Bessel 1899'", "ED50", "EPSG:4230")),
        ("EPSG:32633", 54.0, 18.0, ("not a geographic 2D CRS", "UTM zone 33N")),
        ("EPSG:99999", 54.0, 18.0, ("not in the EPSG dataset",)),
        ("ED50", 40.0, -100.0, ("no EPSG transformation to WGS 84 covers", "40.0000°N 100.0000°W")),
    ],
)
def test_unknown_datum_or_uncovered_point_is_a_clear_error(datum, lat, lon, words):
    with pytest.raises(ConfigError) as e:
        to_wgs84([lat], [lon], datum)
    assert all(w in str(e.value) for w in words), str(e.value)


# ------------------------------------------------------------------- the fix and the CLI

SHIP = (55.48, 2.95)  # WGS-84 truth
MARKS_ED50 = ((55.50, 3.00), (55.45, 2.90), (55.52, 2.88))  # charted on an ED50 chart


def _observations(marks_wgs84):
    """Exact ranges (m) and true bearings (deg, ship -> mark) from the WGS-84 marks."""
    out = []
    for lat, lon in marks_wgs84:
        g = Geodesic.WGS84.Inverse(*SHIP, lat, lon)
        out.append((lat, lon, g["s12"], g["azi1"] % 360.0))
    return out


def _obs_toml(marks, obs, datum_line):
    lines = [datum_line] if datum_line else []
    for (lat, lon), (_, _, dist, brg) in zip(marks, obs, strict=True):
        lines += [
            "[[range]]",
            f"lat = {lat!r}",
            f"lon = {lon!r}",
            f"dist_m = {dist!r}",
            "sigma_m = 5",
            "[[bearing]]",
            f"lat = {lat!r}",
            f"lon = {lon!r}",
            f"bearing_deg = {brg!r}",
            "sigma_deg = 0.5",
        ]
    return "\n".join(lines) + "\n"


def _marks_wgs84():
    """The marks by pyproj's standard ED50 -> WGS 84 for the area (EPSG:1311)."""
    to84 = Transformer.from_crs(
        "EPSG:4230",
        "EPSG:4326",
        always_xy=True,
        area_of_interest=AreaOfInterest(2.88, 55.45, 3.0, 55.52),
    )
    return [to84.transform(lon, lat)[::-1] for lat, lon in MARKS_ED50]


def test_fix_from_ed50_lops_equals_the_fix_from_pyproj_transformed_inputs(tmp_path):
    marks84 = _marks_wgs84()
    obs = _observations(marks84)
    ed50 = tmp_path / "ed50.toml"
    ed50.write_text(_obs_toml(MARKS_ED50, obs, 'datum = "ED50"'), encoding="utf-8")
    wgs = tmp_path / "wgs.toml"
    wgs.write_text(_obs_toml(marks84, obs, ""), encoding="utf-8")
    rep, datums = run_fix_datums([], ed50, None)
    ref = run_fix([], wgs, None)
    s, r = rep.solution, ref.solution
    lat, lon = math.degrees(s.lat_rad), math.degrees(s.lon_rad)
    assert geo_m(lat, lon, math.degrees(r.lat_rad), math.degrees(r.lon_rad)) < 0.001
    assert geo_m(lat, lon, *SHIP) < 0.05  # exact observations: the truth
    assert float(s.chi2) < 1e-3
    assert [d.label for d in datums] == [
        f"{k} {i}" for k in ("range", "bearing") for i in (1, 2, 3)
    ]
    assert all(d.transformation.operation_code == "EPSG:1311" for d in datums)
    assert all(100.0 < d.shift_m[0] < 140.0 for d in datums)
    # the same ED50 coordinates taken as WGS-84: the systematic error seeds/004 warns of
    naive = tmp_path / "naive.toml"
    naive.write_text(_obs_toml(MARKS_ED50, obs, ""), encoding="utf-8")
    bad = run_fix([], naive, None).solution
    err = geo_m(math.degrees(bad.lat_rad), math.degrees(bad.lon_rad), *SHIP)
    assert 100.0 < err < 140.0


def test_cli_datum_option_file_datums_text_and_json(run_cli, tmp_path):
    jsonschema = pytest.importorskip("jsonschema")
    marks84 = _marks_wgs84()
    obs = _observations(marks84)
    (lat1, lon1), (lat2, lon2), _ = MARKS_ED50
    # the file: its own datum ED50, one item already on WGS-84 (the third mark)
    path = tmp_path / "obs.toml"
    path.write_text(
        f'datum = "ED50"\n[[range]]\nlat = {lat2!r}\nlon = {lon2!r}\ndist_m = {obs[1][2]!r}\n'
        f"sigma_m = 5\n[[range]]\nlat = {marks84[2][0]!r}\nlon = {marks84[2][1]!r}\n"
        f'dist_m = {obs[2][2]!r}\nsigma_m = 5\ndatum = "WGS84"\n',
        encoding="utf-8",
    )
    code, out, err = run_cli(
        "fix",
        "--datum",
        "ED50",
        "--bearing",
        f"{lat1},{lon1},{obs[0][3]:.9f},0.5",
        "--range",
        f"{lat1},{lon1},{obs[0][2]:.4f}m,5",
        "--file",
        path,
        "--json",
        tmp_path / "fix.json",
    )
    assert code == 0, err
    assert "positions brought to WGS-84 before fusion" in out and "EPSG:1311" in out
    j = json.loads((tmp_path / "fix.json").read_text(encoding="utf-8"))
    jsonschema.validate(j, JSON_SCHEMA)
    assert geo_m(j["lat_deg"], j["lon_deg"], *SHIP) < 0.05
    labels = [d["observation"] for d in j["datums"]]
    assert labels == ["range 1", "range 2", "bearing 1"]  # range 3 was on WGS-84 already
    first = j["datums"][0]
    assert first["datum"] == "ED50" and first["crs"] == "EPSG:4230"
    assert first["points_given_deg"] == [[lat1, lon1]]
    assert geo_m(*first["points_wgs84_deg"][0], *marks84[0]) < 0.001


@pytest.mark.parametrize(
    "args, file_text, code, words",
    [
        (("--datum", "Mars 2000", "--fix", "54,18"), None, 2, ("--datum", "unknown datum")),
        ((), 'datum = "XX"\n[[fix]]\nlat = 54\nlon = 18\n', 4, ("obs.toml: datum", "unknown")),
        ((), "datum = 50\n[[fix]]\nlat = 54\nlon = 18\n", 4, ("must be a text",)),
        (
            (),
            '[[nadir]]\nsublat = 10\nsublon = 20\nnadir_deg = 40\ndatum = "ED50"\n',
            4,
            ("[[nadir]] #1", "not to [[nadir]]"),
        ),
        (("--datum", "ED50", "--fix", "40,-100"), None, 2, ("--fix '40,-100'", "covers")),
    ],
)
def test_cli_datum_errors_are_one_line(run_cli, tmp_path, args, file_text, code, words):
    extra: tuple = ()
    if file_text is not None:
        (tmp_path / "obs.toml").write_text(file_text, encoding="utf-8")
        extra = ("--file", tmp_path / "obs.toml", "--prior", "54,18")
    got, _, err = run_cli("fix", *args, *extra)
    assert got == code, err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert all(w in err for w in words), err
