"""``dracc analyze --gpx --kml --geojson --mcap``: the exports of the 24 h voyage, read by
the tools' own parsers (gpxpy, fastkml, shapely) and checked against the analysis's JSON
and tables (one run of the CLI for the module), geodesic areas by geographiclib."""

from __future__ import annotations

import datetime as dt
import importlib.util
import json
import math
import sys
import types
import xml.etree.ElementTree as ET
from itertools import pairwise
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dracc.core.errors import ExitCode

gpxpy = pytest.importorskip("gpxpy")
fastkml = pytest.importorskip("fastkml")
shapely_geometry = pytest.importorskip("shapely.geometry")
geodesic = pytest.importorskip("geographiclib.geodesic")

SAMPLES = Path(__file__).resolve().parents[1] / "sample_logs"
SAMPLE_DAY = SAMPLES / "day" / "voyage_day.mcap"
SAMPLE = SAMPLES / "voyage_tag.nmea"
WGS84 = geodesic.Geodesic.WGS84
NS = "https://dracc.example/gpx/1"
GPX = "{http://www.topografix.com/GPX/1/1}"
HAVE_MCAP_EXPORT = importlib.util.find_spec("dracc.report.mcap_export") is not None

pytestmark = pytest.mark.skipif(not SAMPLE_DAY.exists(), reason="sample_logs not generated")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One ``dracc analyze`` of the day with every report; the Analysis object kept too."""
    from dracc.cli.main import main
    from dracc.pipeline import analysis

    out = tmp_path_factory.mktemp("exports")
    files = {k: out / f"day.{k}" for k in ("json", "gpx", "kml", "geojson", "mcap")}
    caught = {}
    real = analysis.analyse

    def keep(*args, **kwargs):
        caught["a"] = real(*args, **kwargs)
        return caught["a"]

    args = ["analyze", str(SAMPLE_DAY), "--out", str(out / "tables")]
    for k in ("json", "gpx", "kml", "geojson") + (("mcap",) if HAVE_MCAP_EXPORT else ()):
        args += [f"--{k}", str(files[k])]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(analysis, "analyse", keep)
        code = main(args)
    assert code == ExitCode.OK
    doc = json.loads(files["json"].read_text(encoding="utf-8"))
    track = pd.read_parquet(out / "tables" / "dr_track.parquet")
    return types.SimpleNamespace(
        dir=out, files=files, doc=doc, dr=doc["dead_reckoning"], track=track, analysis=caught["a"]
    )


def _utc(text: str) -> dt.datetime:
    return dt.datetime.fromisoformat(text.replace("Z", "+00:00"))


def _expected_rows(track: pd.DataFrame, leg: int) -> pd.DataFrame:
    """The documented thinning: each whole 10 s since the leg's first row, and its last."""
    rows = track[track.leg == leg].reset_index(drop=True)
    since = (rows.time_utc - rows.time_utc.iloc[0]).dt.total_seconds()
    step = np.floor(since / 10.0)
    keep = np.r_[True, np.diff(step) > 0]
    keep[-1] = True
    return rows[keep]


# ------------------------------------------------------------------------- GPX


@pytest.fixture(scope="module")
def gpx(run):
    with open(run.files["gpx"], encoding="utf-8") as fh:
        return gpxpy.parse(fh)


def _ext(point) -> dict[str, float]:
    (box,) = [e for e in point.extensions if e.tag == f"{{{NS}}}uncertainty"]
    return {c.tag.split("}")[1]: float(c.text) for c in box}


def test_gpx_has_the_tracks_a_segment_per_leg_and_every_point(run, gpx):
    legs = run.dr["legs"]
    tracks = [t for t in gpx.tracks if t.type != "aided_ep"]  # tests/test_ep_exports.py
    assert [t.type for t in tracks] == ["dr", "ep", "reference"]
    assert all(len(t.segments) == len(legs) for t in tracks)
    water, ep, ref = tracks
    for k, leg in enumerate(legs):
        want = _expected_rows(run.track, leg["index"])
        got = ep.segments[k].points
        assert len(got) == len(want) == len(water.segments[k].points)
        times = pd.to_datetime([p.time for p in got], utc=True)
        assert (times == pd.DatetimeIndex(want.time_utc)).all()
        assert got[0].time == _utc(leg["start_utc"]) and got[-1].time == _utc(leg["end_utc"])
        assert np.allclose([p.latitude for p in got], want.lat_deg, atol=1e-7, rtol=0)
        assert np.allclose([p.longitude for p in got], want.lon_deg, atol=1e-7, rtol=0)
        w = water.segments[k].points
        assert np.allclose([p.latitude for p in w], want.water_lat_deg, atol=1e-7, rtol=0)
        assert np.allclose([p.longitude for p in w], want.water_lon_deg, atol=1e-7, rtol=0)
        ext = [_ext(p) for p in got]
        for name in ("radius_2m_m", "semi_major_m", "semi_minor_m", "orientation_deg"):
            assert np.allclose([e[name] for e in ext], want[name], atol=1e-6, rtol=0), name
        # the reference of the leg: its fixes from the leg's start to the next one's
        rt = [p.time for p in ref.segments[k].points]
        nxt = _utc(legs[k + 1]["start_utc"]) if k + 1 < len(legs) else None
        assert all(_utc(leg["start_utc"]) <= t and (nxt is None or t < nxt) for t in rt)
    # the reference: every instant of the log's GNSS fixes once (each is logged twice)
    from mcap.reader import make_reader

    with open(SAMPLE_DAY, "rb") as fh:
        fixes = {m.log_time for _, _, m in make_reader(fh).iter_messages(topics=["/GNSS/fix"])}
    times = [p.time.timestamp() for s in ref.segments for p in s.points]
    assert times == sorted({t / 1e9 for t in fixes})
    # every exported point of the EP is a row of the full-rate table, 26 full legs of 1 h
    assert sum(len(s.points) for s in ep.segments) == 26 * 361 + 1


def test_gpx_waypoints_are_the_misses_and_match_the_containment(run, gpx):
    dr = run.dr
    ep = [e for e in dr["epochs"] if e["since_fix_s"] > 0 and e["ref_error_m"] is not None]
    sig = dr["reference_sigma_m"]
    outside = [e for e in ep if e["ref_error_m"] > math.hypot(e["radius_2m_m"], sig * 8**0.5)]
    assert [w.time for w in gpx.waypoints] == [_utc(e["time_utc"]) for e in outside]
    scored_out = sum(e["scored"] for e in outside)
    assert scored_out == round(dr["n_scored"] * (1 - dr["containment_2m"]))  # 5 of 125
    for w, e in zip(gpx.waypoints, outside, strict=True):
        assert w.type == "2M miss"
        assert (w.latitude, w.longitude) == pytest.approx((e["lat_deg"], e["lon_deg"]), abs=1e-7)
        assert _ext(w)["radius_2m_m"] == pytest.approx(e["radius_2m_m"], abs=1e-6)
        assert _ext(w)["ref_error_m"] == pytest.approx(e["ref_error_m"], abs=1e-6)


#: the GPX 1.1 schema's sequences (gpx.xsd): the child elements each type allows, in order
_ORDER = {
    "gpx": ["metadata", "wpt", "rte", "trk", "extensions"],
    "metadata": ["name", "desc", "author", "copyright", "link", "time", "keywords", "bounds",
                 "extensions"],
    "wpt": ["ele", "time", "magvar", "geoidheight", "name", "cmt", "desc", "src", "link", "sym",
            "type", "fix", "sat", "hdop", "vdop", "pdop", "ageofdgpsdata", "dgpsid",
            "extensions"],
    "trk": ["name", "cmt", "desc", "src", "link", "number", "type", "extensions", "trkseg"],
    "trkseg": ["trkpt", "extensions"],
}  # fmt: skip
_ORDER["trkpt"] = _ORDER["wpt"]
_REPEATS = {"wpt", "rte", "trk", "link", "trkseg", "trkpt"}


def test_gpx_core_elements_follow_the_schema(run):
    """What OpenCPN and chart plotters read: GPX 1.1 elements only, in the schema's order
    and multiplicity, lat/lon in range; dracc's values only inside ``extensions``."""
    root = ET.parse(run.files["gpx"]).getroot()
    assert root.tag == f"{GPX}gpx" and root.get("version") == "1.1" and root.get("creator")

    def check(el: ET.Element) -> None:
        name = el.tag.removeprefix(GPX)
        if name == "extensions":
            assert all(c.tag.startswith(f"{{{NS}}}") for c in el)
            return
        if name in ("wpt", "trkpt"):
            assert -90 <= float(el.get("lat")) <= 90 and -180 <= float(el.get("lon")) < 180
        kids = [c.tag.removeprefix(GPX) for c in el]
        if name in _ORDER:
            pos = [_ORDER[name].index(k) for k in kids]  # ValueError: not allowed here
            assert pos == sorted(pos), (name, kids)
            assert all(kids.count(k) == 1 for k in set(kids) - _REPEATS), (name, kids)
        else:
            assert not kids or name == "bounds", name
        for c in el:
            assert c.tag.startswith(GPX), c.tag
            check(c)

    check(root)


# ------------------------------------------------------------------------- KML


@pytest.fixture(scope="module")
def kml(run):
    return fastkml.KML.parse(run.files["kml"]).features[0]


def test_kml_tracks_carry_ordered_times_and_the_reference_comes_last(run, kml, gpx):
    folders = {f.name: f for f in kml.features}
    tracks = folders["Tracks"].features
    gpx_tracks = [t for t in gpx.tracks if t.type != "aided_ep"]  # tests/test_ep_exports.py
    assert [pm.name for pm in tracks] == [t.name for t in gpx_tracks]
    assert tracks[-1].name.startswith("reference")  # drawn above the DR
    for pm, t in zip(tracks, gpx_tracks, strict=True):
        parts = pm.kml_geometry.tracks
        assert len(parts) == len(run.dr["legs"])
        whens = [w.dt for part in parts for w in part.whens]
        assert whens and all(a < b for a, b in pairwise(whens))
        assert whens == [p.time for s in t.segments for p in s.points]
        coords = [(i.coord.x, i.coord.y) for part in parts for i in part.track_items]
        got = [(p.longitude, p.latitude) for s in t.segments for p in s.points]
        assert np.allclose(coords, got, atol=1e-7)


def test_kml_circles_are_timed_polygons_at_the_epochs(run, kml, gpx):
    folders = {f.name: f for f in kml.features}
    circles = folders["2M circles at the reporting epochs"].features
    epochs = run.dr["epochs"]
    assert len(circles) == len(epochs)
    begins = [pm.times.begin.dt for pm in circles]
    assert begins == [_utc(e["time_utc"]) for e in epochs]
    assert all(pm.times.end.dt > pm.times.begin.dt for pm in circles)
    for pm, e in zip(circles, epochs, strict=True):
        poly = shapely_geometry.shape(pm.geometry)
        assert poly.is_valid and poly.exterior.is_ccw
        c = poly.centroid
        assert (c.x, c.y) == pytest.approx((e["lon_deg"], e["lat_deg"]), abs=1e-4)
    misses = folders["2M misses (reference outside 2M)"].features
    assert [pm.times.timestamp.dt for pm in misses] == [w.time for w in gpx.waypoints]


# --------------------------------------------------------------------- GeoJSON


@pytest.fixture(scope="module")
def geo(run):
    def no_nan(name):
        raise AssertionError(f"{name} in GeoJSON")

    return json.loads(run.files["geojson"].read_text(encoding="utf-8"), parse_constant=no_nan)


def _ring_checks(
    geom: dict, centre: tuple[float, float], distances: bool = True
) -> tuple[float, list[float]]:
    """Validity and winding of every ring; geodesic area (m^2) and vertex distances from
    ``centre`` (lat, lon), both on the ellipsoid by geographiclib."""
    shape = shapely_geometry.shape(geom)
    assert shape.is_valid
    polys = [shape] if geom["type"] == "Polygon" else list(shape.geoms)
    area, dists = 0.0, []
    for poly in polys:
        ring = poly.exterior.coords
        assert ring[0] == ring[-1] and poly.exterior.is_ccw and not poly.interiors
        g = WGS84.Polygon()
        for lon, lat in ring[:-1]:
            g.AddPoint(lat, lon)
            if distances and abs(lon) < 180:
                dists.append(WGS84.Inverse(centre[0], centre[1], lat, lon)["s12"])
        _, _, a = g.Compute(False, True)
        area += abs(a)
    return area, dists


def test_geojson_polygons_are_geodesic_circles_and_ellipses(run, geo):
    assert geo["type"] == "FeatureCollection"
    epochs = run.dr["epochs"]
    for shape, scale in (("circle", 1.0), ("ellipse", 2.0)):
        feats = [f for f in geo["features"] if f["properties"].get("shape") == shape]
        assert len(feats) == len(epochs), shape
        for k, (f, e) in enumerate(zip(feats, epochs, strict=True)):
            p = f["properties"]
            assert p["time_utc"] == e["time_utc"] and p["leg"] == e["leg"]
            assert p["radius_2m_m"] == pytest.approx(e["radius_2m_m"], rel=1e-12)
            assert p["semi_major_m"] == pytest.approx(e["ellipse"]["semi_major_m"], rel=1e-12)
            assert p["orientation_deg"] == pytest.approx(e["ellipse"]["orientation_deg"])
            some = k % 4 == 0  # the vertices' distances on a quarter of them (time)
            area, dists = _ring_checks(f["geometry"], (e["lat_deg"], e["lon_deg"]), some)
            a, b = scale * p["semi_major_m"], scale * p["semi_minor_m"]
            if shape == "circle":
                r = p["radius_2m_m"]
                assert area == pytest.approx(math.pi * r * r, rel=0.01)
                assert np.allclose(dists, r, rtol=1e-4)
            else:
                assert area == pytest.approx(math.pi * a * b, rel=0.01)
                if some:
                    assert min(dists) == pytest.approx(b, rel=1e-3)
                    assert max(dists) == pytest.approx(a, rel=1e-3)
            # lon, lat order: the centroid is the EP, not its mirror image
            c = shapely_geometry.shape(f["geometry"]).centroid
            assert (c.x, c.y) == pytest.approx((e["lon_deg"], e["lat_deg"]), abs=1e-4)


def test_geojson_inside_is_the_analysis_containment(run, geo):
    dr = run.dr
    circles = [f["properties"] for f in geo["features"] if f["properties"].get("shape") == "circle"]
    scored = [p for p in circles if p["scored"] and p["inside"] is not None]
    assert len(scored) == dr["n_scored"]
    assert sum(p["inside"] for p in scored) / len(scored) == pytest.approx(dr["containment_2m"])
    for p in circles:  # inside is the reference within the circle drawn, where scored
        if p["ref_error_m"] is None or not p["scored"] or p["since_fix_s"] == 0:
            assert p["inside"] is None
        else:
            assert p["inside"] == (p["ref_error_m"] <= p["radius_2m_m"])


def test_geojson_tracks_are_lon_lat_lines_per_leg(run, geo, gpx):
    lines = [f for f in geo["features"] if f["properties"]["kind"] == "track"]
    for t in gpx.tracks:
        mine = [f for f in lines if f["properties"]["track"] == t.type]
        multi = [s for s in t.segments if len(s.points) >= 2]  # a point is no line
        assert len(mine) == len(multi)
        for f, s in zip(mine, multi, strict=True):
            assert f["geometry"]["type"] == "LineString"
            xy = np.array(f["geometry"]["coordinates"])
            assert np.allclose(xy, [(p.longitude, p.latitude) for p in s.points], atol=1e-7)
            assert f["properties"]["start_utc"] == s.points[0].time.strftime("%Y-%m-%dT%H:%M:%SZ")


def test_circles_across_the_antimeridian_are_cut_in_two():
    from dracc.report.exports import polygon_geometry, ring_deg

    r = 5000.0
    lat, lon = ring_deg(math.radians(-17.0), math.radians(179.99), r, r, 0.0)
    geom = polygon_geometry(lat, lon)
    assert geom["type"] == "MultiPolygon" and len(geom["coordinates"]) == 2
    for part in geom["coordinates"]:
        xs = [x for x, _ in part[0]]
        assert max(xs) <= 180 and min(xs) >= -180
    area, _ = _ring_checks(geom, (-17.0, 179.99))
    assert area == pytest.approx(math.pi * r * r, rel=0.01)
    from dracc.report.exports import _line_geometry

    cut = _line_geometry(np.array([0.0, 0.2]), np.array([179.9, -179.9]))
    assert cut is not None and cut["type"] == "MultiLineString"
    assert cut["coordinates"] == [[[179.9, 0.0], [180.0, 0.1]], [[-180.0, 0.1], [-179.9, 0.2]]]


def test_without_dead_reckoning_the_exports_hold_the_reference_alone(run, tmp_path):
    from dataclasses import replace

    from dracc.report import exports

    a = replace(run.analysis, dead_reckoning=None)
    for fn, ext in ((exports.write_gpx, "gpx"), (exports.write_kml, "kml")):
        fn(a, tmp_path / f"r.{ext}")
    exports.write_geojson(a, tmp_path / "r.geojson")
    g = gpxpy.parse((tmp_path / "r.gpx").read_text(encoding="utf-8"))
    assert [t.type for t in g.tracks] == ["reference"] and not g.waypoints
    assert len(g.tracks[0].segments) == 1 and len(g.tracks[0].segments[0].points) == 1561
    doc = fastkml.KML.parse(tmp_path / "r.kml").features[0]
    assert [f.name for f in doc.features] == ["Tracks"]
    geo = json.loads((tmp_path / "r.geojson").read_text(encoding="utf-8"))
    assert [f["properties"]["track"] for f in geo["features"]] == ["reference"]
    empty = replace(a, tracks=())
    exports.write_geojson(empty, tmp_path / "e.geojson")
    assert json.loads((tmp_path / "e.geojson").read_text(encoding="utf-8"))["features"] == []
    exports.write_gpx(empty, tmp_path / "e.gpx")
    assert not gpxpy.parse((tmp_path / "e.gpx").read_text(encoding="utf-8")).tracks


def test_hostile_source_names_stay_well_formed_xml(run, tmp_path):
    """A source key from the log (control characters, markup) is text, never markup."""
    from dataclasses import replace

    from dracc.report import exports

    gnss = next(t for t in run.analysis.tracks if t.role == "gnss")
    evil = "GNSS\x1b]0;pwned\x07</name><x>&amp;"
    a = replace(run.analysis, dead_reckoning=None, tracks=(replace(gnss, source=evil),))
    exports.write_gpx(a, tmp_path / "r.gpx")
    exports.write_kml(a, tmp_path / "r.kml")
    g = gpxpy.parse((tmp_path / "r.gpx").read_text(encoding="utf-8"))
    assert g.tracks[0].name == "reference (gnss: GNSS\\x1b]0;pwned\\x07</name><x>&amp;)"
    kml = ET.parse(tmp_path / "r.kml").getroot()
    names = [e.text for e in kml.iter("{http://www.opengis.net/kml/2.2}name")]
    assert g.tracks[0].name in names


# ------------------------------------------------------------ atomic and errors


def test_an_interrupted_export_leaves_the_previous_reports(run, tmp_path, monkeypatch):
    """All reports appear together: a Ctrl-C while the GeoJSON is written (after the JSON,
    GPX and KML went to their temporary files) leaves the earlier set, no part."""
    from rich.console import Console

    from dracc.report import exports
    from dracc.report.write import write_reports

    names = {k: tmp_path / f"r.{k}" for k in ("json", "gpx", "kml", "geojson")}
    for p in names.values():
        p.write_text("previous run\n")
    quiet = Console(file=open(tmp_path / "summary.txt", "w"))  # noqa: SIM115

    def interrupted(a, path):
        raise KeyboardInterrupt

    monkeypatch.setattr(exports, "write_geojson", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_reports(
            run.analysis,
            quiet,
            str(names["json"]),
            None,
            None,
            gpx_path=names["gpx"],
            kml_path=names["kml"],
            geojson_path=names["geojson"],
        )
    assert all(p.read_text() == "previous run\n" for p in names.values())
    assert not list(tmp_path.rglob("*.part"))
    monkeypatch.undo()
    said = write_reports(run.analysis, quiet, None, None, None, geojson_path=names["geojson"])
    assert said == [f"wrote {names['geojson']}"]
    assert names["geojson"].read_bytes() == run.files["geojson"].read_bytes()


@pytest.mark.skipif(not SAMPLE.exists(), reason="sample_logs not generated")
@pytest.mark.parametrize("option", ["--gpx", "--kml", "--geojson"])
def test_an_unwritable_export_is_one_line_naming_it(run_cli, tmp_path, option):
    """As --html: exit 6 and one line naming the path (nothing else written)."""
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    target = blocker / "r.out"
    code, _, err = run_cli("analyze", SAMPLE, "--json", tmp_path / "r.json", option, target)
    assert code == ExitCode.OUTPUT and err.startswith(f"error: cannot write {target}")
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "r.json").exists()


def test_mcap_option_calls_write_mcap_export_inside_the_set(run, tmp_path, monkeypatch):
    """--mcap F: ``dracc.report.mcap_export.write_mcap_export(a, path)``, renamed with the
    others (a stand-in module here, so that the wiring is tested on its own)."""
    from rich.console import Console

    from dracc.core import atomic
    from dracc.report.write import write_reports

    calls = []

    def fake(a, path):
        calls.append((a, Path(path)))
        atomic.write_bytes(path, b"\x89MCAP0\r\n")

    module = types.ModuleType("dracc.report.mcap_export")
    module.write_mcap_export = fake  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "dracc.report.mcap_export", module)
    quiet = Console(file=open(tmp_path / "summary.txt", "w"))  # noqa: SIM115
    said = write_reports(run.analysis, quiet, None, None, None, mcap_path=tmp_path / "d.mcap")
    assert calls == [(run.analysis, tmp_path / "d.mcap")]
    assert said == [f"wrote {tmp_path / 'd.mcap'}"]
    assert (tmp_path / "d.mcap").read_bytes().startswith(b"\x89MCAP")


@pytest.mark.skipif(not HAVE_MCAP_EXPORT, reason="dracc.report.mcap_export not written yet")
def test_mcap_export_of_the_day_is_read_by_the_official_reader(run):
    from mcap.reader import make_reader

    with open(run.files["mcap"], "rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None and summary.statistics.message_count > 0
