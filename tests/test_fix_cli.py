"""``dracc fix``: the coordinate parser, fixes checked against GeographicLib, the berthed
reference by hand, the JSON schema, LS vs WLS, the verdict, errors and the TOML form."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from dracc.core.errors import ExitCode
from dracc.ingest.observations import parse_coordinate_deg, parse_distance_m
from dracc.math.fix import standardised_residuals
from dracc.report.fix_report import JSON_SCHEMA, format_dm

geographiclib = pytest.importorskip("geographiclib.geodesic")
GEOD = geographiclib.Geodesic.WGS84
DOCS = Path(__file__).resolve().parents[1] / "docs" / "fix.md"


def fix_json(run_cli, *args):
    code, out, err = run_cli("fix", *args, "--json", "-")
    assert code == ExitCode.OK, err
    return json.loads(out)


def geo_distance_m(lat1, lon1, lat2, lon2) -> float:
    return GEOD.Inverse(lat1, lon1, lat2, lon2)["s12"]


def direct(lat, lon, azi_deg, s_m):
    g = GEOD.Direct(lat, lon, azi_deg, s_m)
    return g["lat2"], g["lon2"], g["azi2"]


# ------------------------------------------------------------------- the parser


@pytest.mark.parametrize(
    "text, axis, expected",
    [
        ("54.6", "lat", 54.6),
        ("-18.8", "lon", -18.8),
        ("+7", "lon", 7.0),
        ("54 36.5N", "lat", 54 + 36.5 / 60),
        ("018 48.2E", "lon", 18 + 48.2 / 60),
        ("54°36.5'N", "lat", 54 + 36.5 / 60),
        ("54°36'30\"N", "lat", 54 + 36.5 / 60),
        ("N54 36.5", "lat", 54 + 36.5 / 60),
        ("12 30S", "lat", -12.5),
        ("12 30 s", "lat", -12.5),
        ("005 15.0W", "lon", -5.25),
        ("0 30.0S", "lat", -0.5),
        ("179 59.9W", "lon", -(179 + 59.9 / 60)),
        ("54.6N", "lat", 54.6),
        ("90S", "lat", -90.0),
        ("  054° 36.5′ N ", "lat", 54 + 36.5 / 60),
    ],
)
def test_coordinate_parser_hand_values(text, axis, expected):
    assert parse_coordinate_deg(text, axis) == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize(
    "text, axis, reason",
    [
        ("54 36.5E", "lat", "longitude hemisphere"),
        ("018 48.2N", "lon", "latitude hemisphere"),
        ("-54 36.5N", "lat", "not both"),
        ("54 61N", "lat", "below 60"),
        ("54 30 60N", "lat", "below 60"),
        ("90 0.1N", "lat", "outside"),
        ("181E", "lon", "outside"),
        ("54.5 30N", "lat", "whole"),
        ("54 30.5 10N", "lat", "whole"),
        ("abc", "lat", "not a coordinate"),
        ("", "lat", "not a coordinate"),
        ("54 36.5NE", "lat", "not a coordinate"),
        ("nan", "lat", "not a coordinate"),
    ],
)
def test_coordinate_parser_refuses(text, axis, reason):
    with pytest.raises(ValueError, match=reason):
        parse_coordinate_deg(text, axis)


@pytest.mark.parametrize(
    "text, unit_required, metres",
    [
        ("2.4nmi", True, 2.4 * 1852),
        ("2.4nm", True, 2.4 * 1852),
        ("2.4 NM", True, 2.4 * 1852),
        ("4cbl", True, 4 * 185.2),
        ("450m", True, 450.0),
        ("1.2km", True, 1200.0),
        ("12", False, 12.0),
        (".5nmi", True, 926.0),
    ],
)
def test_distance_parser(text, unit_required, metres):
    assert parse_distance_m(text, unit_required=unit_required) == pytest.approx(metres, rel=1e-15)


@pytest.mark.parametrize("text", ["2.4", "-1nmi", "2.4mi", "nmi", "1e3m"])
def test_distance_parser_refuses(text):
    with pytest.raises(ValueError):
        parse_distance_m(text, unit_required=True)


@pytest.mark.parametrize(
    "deg, axis, text",
    [
        (54 + 36.5 / 60, "lat", "54°36.500'N"),
        (-(5 + 15 / 60), "lon", "005°15.000'W"),
        (54.99999999, "lat", "55°00.000'N"),
        (0.0, "lon", "000°00.000'E"),
    ],
)
def test_format_dm(deg, axis, text):
    assert format_dm(deg, axis) == text
    assert parse_coordinate_deg(text, axis) == pytest.approx(deg, abs=1e-5 / 60)


# --------------------------------------------------------- fixes against GeographicLib

SHIP = (54.6123456, 18.7654321)


def test_two_range_fix_matches_geographiclib(run_cli):
    marks = [(54.63, 18.73), (54.59, 18.71)]
    ranges = [geo_distance_m(*m, *SHIP) for m in marks]
    args = []
    for (lat, lon), r in zip(marks, ranges, strict=True):
        args += ["--range", f"{lat},{lon},{r:.4f}m,5"]
    j = fix_json(run_cli, *args, "--prior", "54.62,18.78")
    assert geo_distance_m(j["lat_deg"], j["lon_deg"], *SHIP) < 0.02  # centimetres
    assert j["redundancy"] == 0 and j["chi2"] == pytest.approx(0.0, abs=1e-6)
    # the same fix given in nautical miles (numbers rounded to 1e-7 nmi = 0.2 mm)
    args_nmi = [
        a if not a.endswith(",5") else a.replace(f"{r:.4f}m", f"{r / 1852:.7f}nmi")
        for a, r in zip(args, [None, ranges[0], None, ranges[1]], strict=True)
    ]
    j2 = fix_json(run_cli, *args_nmi, "--prior", "54 37.2N,18 46.8E")
    assert geo_distance_m(j2["lat_deg"], j2["lon_deg"], *SHIP) < 0.02


def test_two_ranges_without_prior_are_ambiguous_and_name_both_positions(run_cli):
    marks = [(54.63, 18.73), (54.59, 18.71)]
    args = []
    for lat, lon in marks:
        args += ["--range", f"{lat},{lon},{geo_distance_m(lat, lon, *SHIP):.4f}m,5"]
    code, out, err = run_cli("fix", *args)
    assert code == ExitCode.INPUT and out == ""
    assert len(err.strip().splitlines()) == 1 and "--prior" in err and "2 positions" in err
    found = re.findall(r"(\d+)°(\d+\.\d+)'([NS]) (\d+)°(\d+\.\d+)'([EW])", err)
    cands = [(int(a) + float(b) / 60, int(c) + float(d) / 60) for a, b, _, c, d, _ in found]
    assert len(cands) == 2
    assert min(geo_distance_m(*c, *SHIP) for c in cands) < 2.0  # one is the ship (to 0.001')


@pytest.mark.parametrize("at", ["ship", "mark"])
def test_bearing_and_range_fix_matches_geographiclib(run_cli, at):
    mark = (54.58, 18.69)
    azi_mark_to_ship, dist = 57.3, 4321.0
    lat, lon, azi2 = direct(*mark, azi_mark_to_ship, dist)
    if at == "ship":
        brg = (azi2 + 180.0) % 360.0  # bearing of the mark taken from the ship
        opt = "--bearing"
    else:
        brg, opt = azi_mark_to_ship, "--bearing-from-mark"
    j = fix_json(
        run_cli,
        opt,
        f"{mark[0]},{mark[1]},{brg:.9f},0.5",
        "--range",
        f"{mark[0]},{mark[1]},{dist}m,10",
    )
    assert geo_distance_m(j["lat_deg"], j["lon_deg"], lat, lon) < 0.02
    # the ellipse of a range and a bearing from one mark: axes along and across the line
    across = dist * math.radians(0.5)
    assert j["ellipse"]["semi_major_m"] == pytest.approx(across, rel=1e-3)
    assert j["ellipse"]["semi_minor_m"] == pytest.approx(10.0, rel=1e-3)
    assert j["ellipse"]["orientation_deg"] == pytest.approx((azi_mark_to_ship + 90) % 180, abs=0.05)
    assert j["two_drms_m"] == pytest.approx(2 * math.hypot(across, 10.0), rel=1e-3)


@pytest.mark.parametrize(
    "heading, side, west_m",
    [
        ("000", "starboard", 11.0),  # heading north, pier to starboard (east): ship west of it
        ("180", "port", 11.0),  # heading south, pier to port (east): ship west
        ("180", "starboard", -11.0),  # heading south, pier to starboard (west): ship east
    ],
)
def test_pier_line_and_abeam_mark_berthed_reference_by_hand(run_cli, heading, side, west_m):
    """Pier A->B along a meridian; the reference point on the centreline; half-breadth 10 m,
    fenders 1 m: the reference point lies 11 m off the pier line, abeam of the mark."""
    a = (54.5, 18.6)
    b = direct(*a, 0.0, 300.0)[:2]
    mark = direct(*a, 0.0, 120.0)[:2]
    expected = direct(*mark, 270.0 if west_m > 0 else 90.0, abs(west_m))[:2]
    a_b = f"{a[0]},{a[1]},{b[0]:.10f},{b[1]:.10f}"
    j = fix_json(
        run_cli,
        "--pier",
        f"{a_b},{heading},{side},10,0.3,1",
        "--abeam",
        f"{mark[0]:.10f},{mark[1]:.10f},2",
    )
    assert geo_distance_m(j["lat_deg"], j["lon_deg"], *expected) < 0.01
    e = j["ellipse"]  # 0.3 m across the pier (east-west), 2 m along it (north)
    assert e["semi_major_m"] == pytest.approx(2.0, rel=1e-3)
    assert e["semi_minor_m"] == pytest.approx(0.3, rel=1e-3)
    assert min(e["orientation_deg"], 180 - e["orientation_deg"]) < 0.01
    assert j["prior"]["source"] == "mean of the marks"


def test_pier_with_reference_point_to_starboard_and_a_fix(run_cli):
    """Reference point 2 m to starboard, heading 000, starboard side-to: 9 m west of the
    pier (docs/current-fusion.md's table); along the pier a GNSS fix decides."""
    a = (54.5, 18.6)
    b = direct(*a, 0.0, 300.0)[:2]
    gnss = direct(*direct(*a, 0.0, 150.0)[:2], 270.0, 9.0)[:2]
    a_b = f"{a[0]},{a[1]},{b[0]:.10f},{b[1]:.10f}"
    j = fix_json(
        run_cli,
        "--pier",
        f"{a_b},0,starboard,10,0.3,1,2",
        "--fix",
        f"{gnss[0]:.10f},{gnss[1]:.10f},5",
    )
    assert geo_distance_m(j["lat_deg"], j["lon_deg"], *gnss) < 0.01


# --------------------------------------------------------------- JSON, LS/WLS, verdict


def _schema_keys(schema) -> set[str]:
    keys = set()
    if isinstance(schema, dict):
        for k, v in schema.get("properties", {}).items():
            keys.add(k)
            keys |= _schema_keys(v)
        if "items" in schema:
            keys |= _schema_keys(schema["items"])
    return keys


def test_json_validates_and_every_key_is_documented(run_cli):
    jsonschema = pytest.importorskip("jsonschema")
    j = fix_json(
        run_cli,
        "--fix",
        "54 36.0N,018 45.0E,15",
        "--range",
        "54.58,18.69,2.1nmi",
        "--bearing",
        "54.58,18.69,200",
        "--line",
        "54.6,18.7,54.62,18.8,8,-3",
    )
    jsonschema.validate(j, JSON_SCHEMA)
    assert j["schema"] == "dracc.fix/1" and j["method"] == "WLS" and j["weighted"] is True
    assert [r["row"] for r in j["residuals"]] == ["north", "east", "range", "bearing", "line"]
    assert j["residuals"][3]["unit"] == "deg" and j["residuals"][3]["sigma_default"] is True
    assert j["redundancy"] == 3 and j["chi2_bound_95"] == pytest.approx(7.8147, abs=1e-4)
    text = DOCS.read_text(encoding="utf-8")
    missing = [k for k in _schema_keys(JSON_SCHEMA) if f"`{k}`" not in text]
    assert not missing, f"keys not documented in docs/fix.md: {missing}"


def test_json_is_strict_json_without_nan(run_cli):
    code, out, _ = run_cli(
        "fix",
        "--range",
        "54.63,18.73,3000m",
        "--range",
        "54.59,18.71,3500m",
        "--prior",
        "54.62,18.78",
        "--json",
        "-",
    )
    assert code == 0
    j = json.loads(out, parse_constant=lambda c: pytest.fail(f"non-JSON constant {c}"))
    assert j["chi2_bound_95"] is None and j["consistent"] is None
    assert all(r["w"] is None for r in j["residuals"])


def test_json_to_a_file_keeps_the_tables(run_cli, tmp_path):
    """``--json PATH`` writes the document (the same as ``--json -`` prints) and the
    tables still go to stdout; a bare ``--json`` is a usage error (it takes a PATH)."""
    args = ["--range", "54.63,18.73,3000m", "--range", "54.59,18.71,3500m"]
    args += ["--prior", "54.62,18.78"]
    path = tmp_path / "fix.json"
    code, out, err = run_cli("fix", *args, "--json", path)
    assert code == ExitCode.OK, err
    assert "residuals" in out and "verdict:" in out and f"wrote {path}" in err
    assert json.loads(path.read_text(encoding="utf-8")) == fix_json(run_cli, *args)
    code, _, _ = run_cli("fix", *args, "--json")
    assert code == ExitCode.USAGE


def _three_ranges(sigmas):
    marks = [(54.63, 18.73), (54.59, 18.71), (54.60, 18.80)]
    blunders = [0.0, 0.0, 40.0]
    args = []
    for (lat, lon), s, d in zip(marks, sigmas, blunders, strict=True):
        args += ["--range", f"{lat},{lon},{geo_distance_m(lat, lon, *SHIP) + d:.4f}m,{s}"]
    return args


def test_ls_and_wls_differ_with_unequal_sigmas(run_cli):
    args = _three_ranges([2, 2, 50])
    wls = fix_json(run_cli, *args)
    ls = fix_json(run_cli, *args, "--ls")
    assert ls["method"] == "LS" and not ls["weighted"]
    # WLS all but ignores the 50 m range: it lands near the ship; LS does not
    assert geo_distance_m(wls["lat_deg"], wls["lon_deg"], *SHIP) < 2.0
    assert geo_distance_m(ls["lat_deg"], ls["lon_deg"], *SHIP) > 5.0
    # the WLS covariance (W3) is the smaller: LS is not the best linear unbiased estimate
    assert wls["drms_m"] < ls["drms_m"]
    # equal sigmas: the two coincide
    eq = _three_ranges([5, 5, 5])
    a, b = fix_json(run_cli, *eq), fix_json(run_cli, *eq, "--ls")
    assert geo_distance_m(a["lat_deg"], a["lon_deg"], b["lat_deg"], b["lon_deg"]) < 1e-3


def test_verdict_names_the_blunder(run_cli):
    marks = [(54.63, 18.73), (54.59, 18.71), (54.60, 18.80), (54.64, 18.79)]
    args = []
    for i, (lat, lon) in enumerate(marks):
        blunder = 150.0 if i == 2 else 0.0
        args += ["--range", f"{lat},{lon},{geo_distance_m(lat, lon, *SHIP) + blunder:.3f}m,10"]
    code, out, _ = run_cli("fix", *args)
    assert code == 0 and "an observation disagrees: range 3" in out
    good = [a for i, a in enumerate(args) if i not in (4, 5)]
    code, out, _ = run_cli("fix", *good)
    assert code == 0 and "residuals consistent with the sigmas" in out
    for word in ("position", "error ellipse", "2drms", "DOP", "chi-square", "range 1"):
        assert word in out


def test_standardised_residuals_are_unit_normal_by_simulation():
    """Baarda's w: v / sqrt(C_v,ii) has unit variance when the sigmas are right (WLS and LS)."""
    rng = np.random.default_rng(3)
    az = np.radians([10.0, 80.0, 150.0, 200.0, 300.0])
    psi = np.stack([np.cos(az), np.sin(az)], axis=1)
    sig = np.array([1.0, 2.0, 4.0, 1.0, 3.0])
    r_m2 = np.diag(sig**2)
    runs = 4000
    noise = rng.normal(size=(runs, 5)) * sig
    for weighted in (True, False):
        w_mat = np.diag(1 / sig**2) if weighted else np.eye(5)
        h = psi @ np.linalg.solve(psi.T @ w_mat @ psi, psi.T @ w_mat)
        v = noise @ (np.eye(5) - h).T  # post-fit residuals of each run
        w = np.array([standardised_residuals(psi, r_m2, vi, weighted) for vi in v])
        np.testing.assert_allclose(w.std(axis=0), 1.0, atol=0.05)


# --------------------------------------------------------------------------- errors


A_B = "54.5,18.6,54.503,18.6"


@pytest.mark.parametrize(
    "args, code, words",
    [
        (["--range", "54.6,18.8,2.4"], ExitCode.USAGE, ["--range", "2.4", "unit"]),
        (["--fix", "95,18"], ExitCode.USAGE, ["--fix", "95", "outside"]),
        (["--fix", "54 36.5E,18"], ExitCode.USAGE, ["--fix", "LAT", "hemisphere"]),
        (["--fix", "54.6"], ExitCode.USAGE, ["--fix", "LAT,LON[,SIGMA_M]"]),
        (["--fix", "54.6,18.8,0"], ExitCode.USAGE, ["SIGMA_M", "> 0"]),
        (["--bearing", "54.6,18.8,400"], ExitCode.USAGE, ["--bearing", "400"]),
        (["--pier", f"{A_B},0,aft,10"], ExitCode.USAGE, ["--pier", "aft"]),
        (["--abeam", "54.5,18.6"], ExitCode.USAGE, ["--abeam", "exactly one pier"]),
        (["--nadir", "40,10,30,0.1", "--nadir", "45,30,35,0.1"], ExitCode.USAGE, ["--prior"]),
        (["--prior", "54.6"], ExitCode.USAGE, ["--prior", "LAT,LON"]),
        ([], ExitCode.USAGE, ["no observations"]),
        (["--range", "54.6,18.8,2nmi"], ExitCode.INPUT, ["do not fix both"]),
        (
            ["--line", "54.5,18.6,54.6,18.6", "--line", "54.5,18.6,54.6,18.6,5,20"],
            ExitCode.INPUT,
            ["do not fix both"],
        ),
        # two transits along meridians 650 m apart: great circles meeting at the pole
        (
            ["--line", "54.5,18.6,54.6,18.6", "--line", "54.5,18.61,54.6,18.61"],
            ExitCode.INPUT,
            ["nearly parallel", "DOP"],
        ),
        (
            [
                "--line",
                "54.5,18.6,54.6,18.6",
                "--line",
                "54.5,18.61,54.6,18.61",
                "--prior",
                "54.5,18.6",
            ],
            ExitCode.INPUT,
            ["nearly parallel"],
        ),
        (
            ["--pier", f"{A_B},45,port,10", "--fix", "54.5,18.6"],
            ExitCode.INPUT,
            ["--pier", "not along the pier"],
        ),
    ],
)
def test_errors_are_one_line_with_documented_exit_code(run_cli, args, code, words):
    got, out, err = run_cli("fix", *args)
    assert got == code, err
    assert out == "" and err.startswith("error:") and len(err.strip().splitlines()) == 1
    assert "Traceback" not in err
    for w in words:
        assert w in err


def test_the_first_error_in_solving_order_is_reported(run_cli):
    """Observations are checked one by one in solving order: a pier the library refuses
    (exit 3) is reported before a bad value of a later abeam mark (exit 2)."""
    got, _, err = run_cli(
        "fix", "--pier", f"{A_B},45,port,10", "--abeam", "54.5011,18.6,-2", "--fix", "54.5,18.6"
    )
    assert got == ExitCode.INPUT and "not along the pier" in err
    got, _, err = run_cli("fix", "--pier", f"{A_B},0,port,10", "--abeam", "54.5011,18.6,-2")
    assert got == ExitCode.USAGE and "--abeam" in err and "SIGMA_M" in err


def test_file_errors(run_cli, tmp_path):
    got, _, err = run_cli("fix", "--file", tmp_path / "missing.toml")
    assert got == ExitCode.INPUT and "no such file" in err
    cases = {
        "broken.toml": ("[[range]\nlat = 1", "not valid TOML"),
        "key.toml": ("[[range]]\nlat = 54.6\nlon = 18.8\ndsit_m = 5\n", "unknown key 'dsit_m'"),
        "table.toml": ("[[ranges]]\nlat = 54.6\n", "unknown table 'ranges'"),
        "missing.toml2": ("[[range]]\nlat = 54.6\nlon = 18.8\n", "missing key"),
        "value.toml": ("[[fix]]\nlat = '54 36.5X'\nlon = 18.8\n", "[[fix]] #1"),
        "unit.toml": ("[[range]]\nlat = 54.6\nlon = 18.8\ndist = 2.4\n", "give a unit"),
    }
    for name, (text, words) in cases.items():
        p = tmp_path / name
        p.write_text(text, encoding="utf-8")
        got, _out, err = run_cli("fix", "--file", p)
        assert got == ExitCode.CONFIG, (name, err)
        assert words in err and str(p) in err and len(err.strip().splitlines()) == 1


# ----------------------------------------------------------------- the TOML form


OPTIONS = [
    "--fix",
    "54 36.0N,018 45.0E,15",
    "--range",
    "54.58,18.69,2.1nmi,20",
    "--bearing",
    "54.62,18.70,300.5,0.7",
    "--bearing-from-mark",
    "54.6,18.8,255,1.5",
    "--line",
    "54.6,18.7,54.62,18.8,8,-3",
]

TOML = """
[prior]
lat = "54 36.5N"
lon = 18.75

[[fix]]
lat = "54 36.0N"
lon = "018 45.0E"
sigma_m = 15

[[range]]
lat = 54.58
lon = 18.69
dist_nmi = 2.1
sigma_m = 20

[[bearing]]
lat = 54.62
lon = 18.70
bearing_deg = 300.5
sigma_deg = 0.7

[[bearing]]
lat = 54.6
lon = 18.8
bearing_deg = 255
sigma_deg = 1.5
observed_at = "mark"

[[line]]
lat1 = 54.6
lon1 = 18.7
lat2 = 54.62
lon2 = 18.8
sigma_m = 8
offset_m = -3
"""


def test_toml_file_gives_the_same_result_as_the_options(run_cli, tmp_path):
    path = tmp_path / "obs.toml"
    path.write_text(TOML, encoding="utf-8")
    by_options = fix_json(run_cli, *OPTIONS, "--prior", "54 36.5N,18.75")
    by_file = fix_json(run_cli, "--file", path)
    mixed_path = tmp_path / "half.toml"
    mixed_path.write_text(TOML.split("[[bearing]]")[0], encoding="utf-8")  # prior, fix, range
    mixed = fix_json(run_cli, "--file", mixed_path, *OPTIONS[4:])
    for other in (by_file, mixed):
        assert other["lat_deg"] == pytest.approx(by_options["lat_deg"], abs=1e-12)
        assert other["lon_deg"] == pytest.approx(by_options["lon_deg"], abs=1e-12)
        np.testing.assert_allclose(other["cov_m2"], by_options["cov_m2"], rtol=1e-9)
        assert other["chi2"] == pytest.approx(by_options["chi2"], rel=1e-9)
        assert [r["residual"] for r in other["residuals"]] == pytest.approx(
            [r["residual"] for r in by_options["residuals"]], rel=1e-6, abs=1e-9
        )
    assert by_file["prior"]["source"] == "given"


def test_nadir_circles_fix_with_a_prior(run_cli):
    """Three nadir circles (seeds/002 (1)) about sub-points, radii from the ship's true
    position: the fix returns the ship (the circles are exact on WGS-84)."""
    from dracc.math.fusion import NadirCircle

    ship = np.radians([35.0, 129.0])
    args = []
    for sub in ([60.0, 100.0], [10.0, 140.0], [40.0, 170.0]):
        c = NadirCircle(*np.radians(sub), 0.0, 1.0)
        theta = math.degrees(math.acos(c.cos_nadir(*ship)))
        args += ["--nadir", f"{sub[0]},{sub[1]},{theta:.10f},0.01"]
    j = fix_json(run_cli, *args, "--prior", "35.3,128.6")
    assert geo_distance_m(j["lat_deg"], j["lon_deg"], *np.degrees(ship)) < 1.0
    assert [r["unit"] for r in j["residuals"]] == ["deg"] * 3


def test_real_log_two_receivers_fused_as_fixes(run_cli, real_dir):
    """Hakefjord.txt (VDRplayer): two GPS receivers on one yacht.  Their literal RMC/GGA
    fields go in as navigator text ('57 59.10253N'); the fused fix must be the inverse-
    variance weighted mean (by hand on the geodesic) with chi2 = s^2 / (s1^2 + s2^2)."""
    path = real_dir / "VDRplayer" / "Hakefjord.txt"
    if not path.is_file():
        pytest.skip(f"{path} not found")
    lines = path.read_text(encoding="ascii", errors="replace").splitlines()
    rmc = next(x for x in lines if x.startswith("$GPRMC,092215.00,")).split(",")
    ggas = [x.split(",") for x in lines if x.startswith(("$GPGGA,092214,", "$GPGGA,092216,"))]

    def text(field, hemi, width):  # NMEA ddmm.mmmm -> '57 59.10253N'
        return f"{field[:width]} {field[width:]}{hemi}"

    def deg(field, hemi, width):
        return parse_coordinate_deg(text(field, hemi, width), "lat" if width == 2 else "lon")

    fine = (deg(rmc[3], rmc[4], 2), deg(rmc[5], rmc[6], 3))
    assert fine == pytest.approx((57 + 59.10253 / 60, 11 + 44.34844 / 60), abs=1e-12)
    # the Garmin GGA at 09:22:14 and :16, averaged to 09:22:15 (a straight track over 2 s)
    garmin = tuple(np.mean([[deg(g[2], g[3], 2), deg(g[4], g[5], 3)] for g in ggas], axis=0))
    s1, s2 = 3.0, 10.0
    j = fix_json(
        run_cli,
        "--fix",
        f"{text(rmc[3], rmc[4], 2)},{text(rmc[5], rmc[6], 3)},{s1}",
        "--fix",
        f"{garmin[0]:.10f},{garmin[1]:.10f},{s2}",
    )
    inv = GEOD.Inverse(*fine, *garmin)
    s = inv["s12"]
    assert 1.0 < s < 20.0  # the receivers agree to metres (README: median 4 m)
    expected = direct(*fine, inv["azi1"], s * s1**2 / (s1**2 + s2**2))[:2]
    assert geo_distance_m(j["lat_deg"], j["lon_deg"], *expected) < 0.01
    assert j["chi2"] == pytest.approx(s**2 / (s1**2 + s2**2), rel=1e-4)
    assert j["redundancy"] == 2 and j["consistent"] is True
    assert j["drms_m"] == pytest.approx(math.sqrt(2 * s1**2 * s2**2 / (s1**2 + s2**2)), rel=1e-9)
