"""The aided-DR estimated position (seeds/003) in the exports, the HTML page and the terminal.

One ``dracc analyze`` of the 3 h sample with an observation file (a bearing) and the
``--fix-interval`` study writes every report; each is read back with an independent reader
(gpxpy, fastkml and shapely, the official mcap reader, the standard library's HTML parser)
and compared with the JSON's ``estimated_position``.  The ellipse polygons are checked
against GeographicLib: their geodesic area against pi (2a)(2b) of the inscribed 72-gon,
their vertices' distances from the EP between the 2-sigma semi-axes.
"""

from __future__ import annotations

import base64
import datetime as dt
import json
import math
import types
from html.parser import HTMLParser

import fastkml
import gpxpy
import numpy as np
import pytest
from conftest import SAMPLES
from geographiclib.geodesic import Geodesic
from shapely.geometry import Point, Polygon

from dracc.core.errors import ExitCode
from dracc.core.vocabulary import FIX_UPDATED_EP
from dracc.report import terminal

SAMPLE = SAMPLES / "voyage_tag.nmea"
NS = "https://dracc.example/gpx/1"
KML_FOLDER = FIX_UPDATED_EP
WGS84 = Geodesic.WGS84

pytestmark = pytest.mark.skipif(not SAMPLE.exists(), reason="sample_logs not generated")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """The analysis with a bearing and the fix-interval study, every report written."""
    from dracc.cli.main import main
    from dracc.pipeline import analysis

    out = tmp_path_factory.mktemp("ep_exports")
    obs = out / "obs.toml"
    obs.write_text(
        '[[bearing]]\ntime = "2026-03-01T07:00:05Z"\nlat = 54.7\nlon = 18.9\nbearing_deg = 40.0\n'
    )
    files = {k: out / f"r.{k}" for k in ("json", "gpx", "kml", "geojson", "mcap", "html")}
    caught = {}
    real = analysis.analyse

    def keep(*args, **kwargs):
        caught["a"] = real(*args, **kwargs)
        return caught["a"]

    args = ["analyze", str(SAMPLE), "--observations", str(obs), "--fix-interval", "5min,600,1h"]
    for k, p in files.items():
        args += [f"--{k}", str(p)]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(analysis, "analyse", keep)
        assert main(args) == ExitCode.OK
    doc = json.loads(files["json"].read_text(encoding="utf-8"))
    ep = doc["estimated_position"]
    assert ep is not None and ep["n_lop_updates"] == 1 and len(ep["epochs"]) > 50
    return types.SimpleNamespace(files=files, ep=ep, analysis=caught["a"])


def _utc_ns(text: str) -> int:
    t = dt.datetime.fromisoformat(text.replace("Z", "+00:00"))
    return int(round(t.timestamp() * 1e9))


def _stretch_count(epochs) -> int:
    """Stretches of DR: each begins at its start fix (no time since an update, no update)."""
    return sum(
        1 for k, e in enumerate(epochs) if k == 0 or (e["since_update_s"] == 0 and not e["update"])
    )


def test_gpx_holds_the_ep_track_at_the_json_epochs(run):
    with open(run.files["gpx"], encoding="utf-8") as fh:
        gpx = gpxpy.parse(fh)
    (trk,) = [t for t in gpx.tracks if t.type == "aided_ep"]
    assert [t.type for t in gpx.tracks][-1] == "reference"  # the reference stays on top
    assert len(trk.segments) == _stretch_count(run.ep["epochs"])
    pts = [p for s in trk.segments for p in s.points]
    want = run.ep["epochs"]
    assert len(pts) == len(want)
    assert [int(round(p.time.timestamp() * 1e9)) for p in pts] == [
        _utc_ns(e["time_utc"]) for e in want
    ]
    assert np.allclose([p.latitude for p in pts], [e["lat_deg"] for e in want], atol=1e-8, rtol=0)
    assert np.allclose([p.longitude for p in pts], [e["lon_deg"] for e in want], atol=1e-8, rtol=0)
    for p, e in zip(pts, want, strict=True):
        ext = {x.tag.split("}")[1]: x for x in p.extensions}
        unc = {c.tag.split("}")[1]: float(c.text) for c in ext["uncertainty"]}
        assert unc["radius_2m_m"] == pytest.approx(e["radius_2m_m"], abs=1e-6)
        assert unc["semi_major_m"] == pytest.approx(e["ellipse"]["semi_major_m"], abs=1e-6)
        assert unc["since_update_s"] == pytest.approx(e["since_update_s"], abs=1e-6)
        assert (ext["update"].text if "update" in ext else "") == e["update"]
    assert any(e["update"] == "bearing 1" for e in want)
    # the bounds hold every point of every track
    assert gpx.bounds is not None
    lat = [p.latitude for p in pts]
    assert gpx.bounds.min_latitude <= min(lat) and max(lat) <= gpx.bounds.max_latitude


def test_kml_ellipses_are_valid_polygons_around_the_ep(run):
    kml = fastkml.KML.parse(run.files["kml"])
    folders = {f.name: f for f in kml.features[0].features}
    assert list(folders).index(KML_FOLDER) < list(folders).index("Tracks")  # reference on top
    track, *ellipses = folders[KML_FOLDER].features
    assert sum(len(t.whens) for t in track.kml_geometry.tracks) == len(run.ep["epochs"])
    want = [e for e in run.ep["epochs"] if e["ellipse"]["semi_minor_m"]]
    assert len(ellipses) == len(want) > 50
    for pm, e in zip(ellipses, want, strict=True):
        assert pm.times.begin.dt == dt.datetime.fromisoformat(e["time_utc"].replace("Z", "+00:00"))
        ring = [(c[0], c[1]) for c in pm.kml_geometry.geometry.exterior.coords]
        poly = Polygon(ring)
        assert poly.is_valid and poly.exterior.is_ccw
        assert poly.contains(Point(e["lon_deg"], e["lat_deg"]))
        a, b = 2.0 * e["ellipse"]["semi_major_m"], 2.0 * e["ellipse"]["semi_minor_m"]
        geo = WGS84.Polygon()
        for lon, lat in ring[:-1]:
            geo.AddPoint(lat, lon)
        _, _, area = geo.Compute(False, True)
        n = len(ring) - 1  # the inscribed n-gon of the ellipse: pi a b sin(2 pi / n) n / (2 pi)
        assert area == pytest.approx(
            math.pi * a * b * n / (2 * math.pi) * math.sin(2 * math.pi / n), rel=2e-3
        )
        dist = [WGS84.Inverse(e["lat_deg"], e["lon_deg"], la, lo)["s12"] for lo, la in ring[:-1]]
        assert min(dist) >= b * (1 - 1e-4) and max(dist) <= a * (1 + 1e-4)


def test_geojson_ep_track_is_one_line_per_stretch(run):
    geo = json.loads(run.files["geojson"].read_text(encoding="utf-8"))
    lines = [f for f in geo["features"] if f["properties"].get("track") == "aided_ep"]
    assert len(lines) == _stretch_count(run.ep["epochs"])
    pts = [c for f in lines for c in f["geometry"]["coordinates"]]
    assert len(pts) == len(run.ep["epochs"])


def test_mcap_ep_topic_reads_back_as_the_json_epochs(run):
    from mcap.reader import make_reader

    topics: dict[str, list] = {}
    with open(run.files["mcap"], "rb") as fh:
        for schema, channel, msg in make_reader(fh).iter_messages():
            topics.setdefault(channel.topic, []).append((schema.name, msg))
    want = run.ep["epochs"]
    fixes = topics["/dracc/aided_ep"]
    assert {s for s, _ in fixes} == {"foxglove.LocationFix"} and len(fixes) == len(want)
    for (_, m), e in zip(fixes, want, strict=True):
        o = json.loads(m.data)
        assert m.log_time == _utc_ns(e["time_utc"])
        assert (o["latitude"], o["longitude"]) == pytest.approx(
            (e["lat_deg"], e["lon_deg"]), abs=1e-12
        )
        c = np.array(o["position_covariance"]).reshape(3, 3)
        assert o["position_covariance_type"] == 3
        # 2M = 2 sqrt(trace P) (B30, B31); the eigenvalues are the squared 1-sigma semi-axes
        assert 2.0 * math.sqrt(np.trace(c)) == pytest.approx(e["radius_2m_m"], rel=1e-9)
        ev = np.linalg.eigvalsh(c[:2, :2])
        ell = e["ellipse"]
        assert np.sqrt(ev) == pytest.approx([ell["semi_minor_m"], ell["semi_major_m"]], rel=1e-6)
    errs = [json.loads(m.data) for _, m in topics["/dracc/aided_ep_error"]]
    assert [x["update"] for x in errs] == [e["update"] for e in want]
    polys = topics["/dracc/aided_ep_2m"]
    assert {s for s, _ in polys} == {"foxglove.GeoJSON"} and len(polys) == len(want)
    shapes = json.loads(json.loads(polys[-1][1].data)["geojson"])["features"]
    assert [f["properties"]["shape"] for f in shapes] == ["circle", "ellipse"]


class _Figures(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.figs: dict[str, list[str]] = {}
        self.srcs: list[str] = []
        self._in: str | None = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "figure":
            self._in = a.get("id")
        if tag in ("img", "script", "link") and (a.get("src") or a.get("href")):
            self.srcs.append(a.get("src") or a.get("href") or "")
            if tag == "img" and self._in:
                self.figs.setdefault(self._in, []).append(a["src"])

    def handle_endtag(self, tag):
        if tag == "figure":
            self._in = None


def test_html_has_the_ep_plot_after_the_track_panels(run):
    text = run.files["html"].read_text(encoding="utf-8")
    p = _Figures()
    p.feed(text)
    (src,) = p.figs["fig-aided-ep"]
    png = base64.b64decode(src.split(",", 1)[1])
    assert src.startswith("data:image/png;base64,") and png[:8] == b"\x89PNG\r\n\x1a\n"
    ids = list(p.figs)
    assert ids.index("fig-aided-ep") == ids.index("fig-track-0") + sum(
        i.startswith("fig-track-") for i in ids
    )
    assert all(s.startswith(("data:", "#")) for s in p.srcs)  # one self-contained page


def test_ep_panel_draws_the_visible_ellipses_and_insets(run):
    from dracc.report import track_plots as tp

    d = tp.aided_ep_panel(run.analysis)
    assert d is not None
    labels = [str(x.get_label()) for x in d.ax.get_lines()]
    assert tp.AIDED_LABEL in labels
    insets = d.fig.axes[1:]
    assert len(insets) == 5  # the five largest 2M of the EP
    r2m = sorted(
        (e["radius_2m_m"] for e in run.ep["epochs"] if e["since_update_s"] > 0), reverse=True
    )
    titles = " ".join(ax.get_title() for ax in insets)
    assert f"2M {r2m[0]:.0f} m" in titles
    import matplotlib.pyplot as plt

    plt.close(d.fig)


@pytest.mark.parametrize(("width", "tty"), [(200, False), (80, True), (44, True)])
def test_terminal_has_the_ep_line_and_the_study_table(run, width, tty):
    text = terminal.render_text(run.analysis, width, tty)
    lines = text.splitlines()
    at = lines.index("Fix-updated EP")
    body = "\n".join(lines[at : at + 12])
    ep = run.ep
    r2m = [e["radius_2m_m"] for e in ep["epochs"]]
    assert f"{ep['n_fix_updates']} GNSS fixes" in body and "1 from the observation file" in body
    assert f"mean {np.mean(r2m):,.0f} m" in " ".join(body.split())
    for r in ep["fix_interval_study"]:
        assert f"{r['mean_2m_before_m']:,.0f} m" in body
        assert f"{100 * r['containment']:.1f} %" in body
    if tty:
        assert max(len(ln) for ln in lines) <= width


def test_two_stretches_make_two_segments_and_no_line_joins_them(run):
    """Two stretches of DR (the section twice, the second a day later): two parts each."""
    from dataclasses import fields, replace

    from dracc.report import exports

    e = run.analysis.estimated_position
    day = np.int64(86_400 * 10**9)
    arrays = {
        f.name: np.concatenate([getattr(e, f.name), getattr(e, f.name)])
        for f in fields(e)
        if isinstance(getattr(e, f.name), np.ndarray)
    }
    arrays["time_ns"] = np.concatenate([e.time_ns, e.time_ns + day])
    two = replace(e, **arrays, update_kind=e.update_kind * 2)
    a = replace(run.analysis, estimated_position=two)
    gpx = gpxpy.parse(exports.gpx_document(a).decode("utf-8"))
    (trk,) = [t for t in gpx.tracks if t.type == "aided_ep"]
    assert [len(s.points) for s in trk.segments] == [len(e.time_ns)] * 2
    geo = exports.geojson_document(a)
    lines = [f for f in geo["features"] if f["properties"].get("track") == "aided_ep"]
    assert [f["properties"]["stretch"] for f in lines] == [0, 1]
    kml = fastkml.KML.from_string(exports.kml_document(a))
    folders = {f.name: f for f in kml.features[0].features}
    assert len(folders[KML_FOLDER].features[0].kml_geometry.tracks) == 2
