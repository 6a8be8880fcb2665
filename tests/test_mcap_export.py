"""The MCAP export for Foxglove (dracc.report.mcap_export) on the shipped 24 h voyage.

Read back with the official ``mcap`` reader; the ``foxglove.LocationFix`` and
``foxglove.GeoJSON`` messages validated against the published JSON schemas (transcribed in
tests/data/foxglove_schemas.json, source cited there) and parsed into the official protobuf
classes of ``foxglove-schemas-protobuf`` (unknown fields refused); the polygons checked
with shapely and their vertices' distances with geographiclib; the inputs against the raw
log read with the mcap reader; the layout in docs/foxglove against the channels.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from dracc.core import atomic
from dracc.pipeline.analysis import analyse
from dracc.report.mcap_export import mcap_streams, write_mcap_export

mcap_reader = pytest.importorskip("mcap.reader")
jsonschema = pytest.importorskip("jsonschema")
shapely_geometry = pytest.importorskip("shapely.geometry")
geodesic = pytest.importorskip("geographiclib.geodesic")
location_fix_pb2 = pytest.importorskip("foxglove_schemas_protobuf.LocationFix_pb2")
geojson_pb2 = pytest.importorskip("foxglove_schemas_protobuf.GeoJSON_pb2")
json_format = pytest.importorskip("google.protobuf.json_format")

ROOT = Path(__file__).resolve().parents[1]
VOYAGE = ROOT / "sample_logs" / "day" / "voyage_day.mcap"
LAYOUT = ROOT / "docs" / "foxglove" / "dracc-layout.json"
SCHEMAS = json.loads((Path(__file__).parent / "data" / "foxglove_schemas.json").read_text())
WGS84 = geodesic.Geodesic.WGS84


def _read(path: Path) -> dict:
    """Everything the official reader gives: summary, channels, messages in file order."""
    out: dict = {"messages": []}
    with open(path, "rb") as fh:
        r = mcap_reader.make_reader(fh)
        out["summary"] = r.get_summary()
        out["header"] = r.get_header()
        for schema, channel, msg in r.iter_messages(log_time_order=False):
            out["messages"].append((schema, channel, msg))
        out["metadata"] = {m.name: m.metadata for m in r.iter_metadata()}
    by_topic: dict[str, list] = {}
    for _schema, channel, msg in out["messages"]:
        by_topic.setdefault(channel.topic, []).append((msg, json.loads(msg.data)))
    out["topics"] = by_topic
    out["schema_of"] = {
        c.topic: out["summary"].schemas[c.schema_id] for c in out["summary"].channels.values()
    }
    return out


@pytest.fixture(scope="module")
def analysis():
    return analyse([VOYAGE])


@pytest.fixture(scope="module")
def export(analysis, tmp_path_factory):
    path = tmp_path_factory.mktemp("mcap") / "voyage.mcap"
    write_mcap_export(analysis, path)
    return _read(path)


def _fixes(export, schema_name="foxglove.LocationFix"):
    return {t: m for t, m in export["topics"].items() if export["schema_of"][t].name == schema_name}


def _ns(obj) -> int:
    return obj["timestamp"]["sec"] * 1_000_000_000 + obj["timestamp"]["nsec"]


# ------------------------------------------------------------------ the container


def test_official_reader_reads_every_message(export):
    s = export["summary"]
    assert s.statistics.message_count == len(export["messages"]) > 50_000
    assert s.statistics.channel_count == len(export["topics"])
    assert {c.compression for c in s.chunk_indexes} == {"zstd"}
    assert {c.message_encoding for c in s.channels.values()} == {"json"}
    assert {sc.encoding for sc in s.schemas.values()} == {"jsonschema"}
    for topic in (
        "/dracc/ep",
        "/dracc/dr",
        "/dracc/dr_2m",
        "/dracc/dr_error",
        "/dracc/reference",
        "/dracc/current",
        "/input/gnss/fix",
        "/input/compass/heading",
    ):
        assert export["topics"].get(topic), topic
    for u in ("ins1", "ins2", "ins3"):
        assert export["topics"][f"/dracc/deviation/{u}"]
        assert export["topics"][f"/input/{u}/fix"] and export["topics"][f"/input/{u}/heading"]
    assert export["metadata"]["dracc.export"]["dr_step_s"] == "10"


def test_log_times_are_the_record_times_in_order(export, analysis):
    log = np.array([m.log_time for _, _, m in export["messages"]], np.int64)
    assert np.all(np.diff(log) >= 0)  # file order is log-time order
    assert all(m.publish_time == m.log_time for _, _, m in export["messages"])
    assert log[0] >= analysis.start_ns and log[-1] <= analysis.end_ns
    for topic, msgs in export["topics"].items():
        if topic in ("/dracc/dr_2m", "/dracc/aided_ep_2m"):
            continue  # foxglove.GeoJSON has no timestamp: its time is in the properties
        assert all(m.log_time == _ns(o) for m, o in msgs), topic
        seq = [m.sequence for m, _ in msgs]
        assert seq == list(range(len(seq))), topic


# ------------------------------------------------------------------ the schemas


def _without_descriptions(x):
    if isinstance(x, dict):
        return {k: _without_descriptions(v) for k, v in x.items() if k != "description"}
    if isinstance(x, list):
        return [_without_descriptions(v) for v in x]
    return x


@pytest.mark.parametrize("name", ["foxglove.LocationFix", "foxglove.GeoJSON"])
def test_embedded_schemas_are_the_published_ones(export, name):
    embedded = [sc for sc in export["summary"].schemas.values() if sc.name == name]
    assert len(embedded) == 1
    assert _without_descriptions(json.loads(embedded[0].data)) == SCHEMAS[name]


def test_location_fixes_validate_against_foxglove(export):
    validator = jsonschema.Draft202012Validator(SCHEMAS["foxglove.LocationFix"])
    fixes = _fixes(export)
    assert set(fixes) >= {"/dracc/ep", "/dracc/dr", "/dracc/reference", "/input/gnss/fix"}
    for topic, msgs in fixes.items():
        for k, (_, obj) in enumerate(msgs):
            if topic.startswith("/input/") and k % 10:
                continue  # every tenth input fix; every fix of dracc's own channels
            if k % 10 == 0:  # jsonschema: 0.1 ms a message
                validator.validate(obj)
            # the official protobuf definition: every field known, each of its type
            body = {k2: v for k2, v in obj.items() if k2 != "timestamp"}
            pb = json_format.ParseDict(body, location_fix_pb2.LocationFix())
            pb.timestamp.seconds, pb.timestamp.nanos = (
                obj["timestamp"]["sec"],
                obj["timestamp"]["nsec"],
            )
            assert pb.latitude == obj["latitude"] and len(pb.position_covariance) == 9
            assert -90 <= obj["latitude"] <= 90 and -180 <= obj["longitude"] <= 180
    kinds = {t: {o["position_covariance_type"] for _, o in m} for t, m in fixes.items()}
    assert kinds["/dracc/ep"] == {location_fix_pb2.LocationFix.KNOWN}
    assert kinds["/dracc/dr"] == {location_fix_pb2.LocationFix.UNKNOWN}  # no covariance of its own
    assert kinds["/dracc/reference"] == {location_fix_pb2.LocationFix.DIAGONAL_KNOWN}


def test_geojson_messages_are_foxglove_geojson(export):
    validator = jsonschema.Draft202012Validator(SCHEMAS["foxglove.GeoJSON"])
    for _, obj in export["topics"]["/dracc/dr_2m"]:
        validator.validate(obj)
        json_format.ParseDict(obj, geojson_pb2.GeoJSON())


# ------------------------------------------------------------- against the analysis


def test_ep_covariance_is_the_analysis_covariance(export, analysis):
    tr = analysis.dead_reckoning.track
    msgs = [o for _, o in export["topics"]["/dracc/ep"]]
    t = np.array([_ns(o) for o in msgs], np.int64)
    i = np.searchsorted(tr.time_ns, t)
    assert np.array_equal(tr.time_ns[i], t)
    lat = np.array([o["latitude"] for o in msgs])
    lon = np.array([o["longitude"] for o in msgs])
    assert np.allclose(lat, np.degrees(tr.lat_rad[i]), rtol=0, atol=1e-12)
    assert np.allclose(lon, np.degrees(tr.lon_rad[i]), rtol=0, atol=1e-12)
    P = np.array([o["position_covariance"] for o in msgs]).reshape(-1, 3, 3)
    assert np.array_equal(P, np.swapaxes(P, 1, 2))
    assert not P[:, 2, :].any() and not P[:, :, 2].any()  # the vertical is not estimated
    en = P[:, :2, :2]  # (east, north)
    # independent of the writer's formula: 2M = 2 sqrt(tr P) (B31), and the eigen-ellipse
    scale = tr.radius_2m_m[i] ** 2
    assert np.allclose(4.0 * np.trace(en, axis1=1, axis2=2), scale, rtol=1e-9, atol=1e-9)
    w, v = np.linalg.eigh(en)
    assert np.allclose(w[:, 1], tr.semi_major_m[i] ** 2, rtol=1e-9, atol=1e-9 * scale.max())
    assert np.allclose(w[:, 0], tr.semi_minor_m[i] ** 2, rtol=1e-9, atol=1e-9 * scale.max())
    az = np.mod(np.arctan2(v[:, 0, 1], v[:, 1, 1]), np.pi)  # major axis: east over north
    elongated = w[:, 1] > 1.001 * w[:, 0]
    d = np.angle(np.exp(2j * (az - tr.orientation_rad[i])))[elongated] / 2
    assert elongated.sum() > 1000 and np.abs(d).max() < 1e-6


def test_ep_rows_cover_each_epoch_and_leg(export, analysis):
    dr = analysis.dead_reckoning
    t = {_ns(o) for _, o in export["topics"]["/dracc/ep"]}
    assert set(dr.epochs.time_ns.tolist()) <= t
    assert {leg.start_ns for leg in dr.legs} <= t and {leg.end_ns for leg in dr.legs} <= t
    steps = np.diff(sorted(t))
    assert steps.max() <= 10_000_000_000  # one every 10 s of each leg at least
    assert len(t) < dr.track.time_ns.size / 9
    water = {_ns(o): o for _, o in export["topics"]["/dracc/dr"]}
    i = np.searchsorted(dr.track.time_ns, sorted(water))
    lat = np.array([water[k]["latitude"] for k in sorted(water)])
    assert np.allclose(lat, np.degrees(dr.track.water_lat_rad[i]), rtol=0, atol=1e-12)


def test_2m_polygons_are_valid_circles_and_ellipses(export, analysis):
    dr = analysis.dead_reckoning
    ep = dr.epochs
    msgs = export["topics"]["/dracc/dr_2m"]
    assert [m.log_time for m, _ in msgs] == ep.time_ns.tolist()
    inside = []
    for k, (_m, obj) in enumerate(msgs):
        doc = json.loads(obj["geojson"])
        assert doc["type"] == "FeatureCollection"
        shapes = {f["properties"]["shape"]: f for f in doc["features"]}
        assert set(shapes) == {"circle", "ellipse"}
        for f in doc["features"]:
            poly = shapely_geometry.shape(f["geometry"])
            assert poly.is_valid and poly.exterior.is_ccw and poly.exterior.is_closed
            assert f["properties"]["time_utc"].endswith("Z") and "color" in f["properties"]["style"]
        inside.append(shapes["circle"]["properties"]["inside"])
        if k % 4:
            continue
        # the circle's vertices lie 2M from the EP on the ellipsoid (geographiclib)
        lat0, lon0 = math.degrees(ep.lat_rad[k]), math.degrees(ep.lon_rad[k])
        r = float(ep.radius_2m_m[k])
        ring = shapes["circle"]["geometry"]["coordinates"][0]
        dist = [WGS84.Inverse(lat0, lon0, la, lo)["s12"] for lo, la in ring]
        assert np.allclose(dist, r, rtol=1e-4)
        # the ellipse: semi-axes 2 sigma, the farthest vertex along the major axis
        ring = shapes["ellipse"]["geometry"]["coordinates"][0]
        inv = [WGS84.Inverse(lat0, lon0, la, lo) for lo, la in ring]
        far = max(inv, key=lambda g: g["s12"])
        assert far["s12"] == pytest.approx(2 * ep.semi_major_m[k], rel=1e-4)
        near = min(g["s12"] for g in inv)
        assert near == pytest.approx(2 * ep.semi_minor_m[k], rel=2e-3)  # 72 vertices
        if ep.semi_major_m[k] > 1.05 * ep.semi_minor_m[k]:  # a circle has no orientation
            az = math.radians(far["azi1"]) % math.pi
            assert abs(math.remainder(az - ep.orientation_rad[k], math.pi)) < 0.05
    # the flags count as the analysis's consistency check does
    scored = [x for x in inside if x is not None]
    assert len(scored) == dr.n_scored
    assert np.mean(scored) == pytest.approx(dr.containment_2m, abs=1e-12)


def test_reference_deviation_and_current(export, analysis):
    dr = analysis.dead_reckoning
    ref = [o for _, o in export["topics"]["/dracc/reference"]]
    s2 = dr.reference_sigma_m**2
    assert ref[0]["position_covariance"] == [s2, 0, 0, 0, s2, 0, 0, 0, 0]
    gnss = [o for _, o in export["topics"]["/input/gnss/fix"]]
    assert [(o["latitude"], o["longitude"]) for o in ref] == [
        (o["latitude"], o["longitude"]) for o in gnss
    ]
    d = analysis.deviation
    for u in d.units:
        msgs = [o for _, o in export["topics"][f"/dracc/deviation/{u}"]]
        assert [_ns(o) for o in msgs] == d.time_ns.tolist()
        assert np.allclose([o["lat_m"] for o in msgs], d.samples[u]["lat"], rtol=0, atol=1e-12)
        assert np.allclose([o["course_deg"] for o in msgs], d.samples[u]["course"], atol=1e-12)
    c = analysis.current
    cur = [o for _, o in export["topics"]["/dracc/current"]]
    assert [_ns(o) for o in cur] == c.time_ns.tolist()
    kn = 3600.0 / 1852.0  # knots per m/s, by hand
    assert np.allclose([o["drift_kn"] for o in cur], c.drift_mps * kn, rtol=1e-12)
    for o in cur:
        assert math.hypot(o["north_kn"], o["east_kn"]) == pytest.approx(o["drift_kn"], rel=1e-9)
        towards = math.degrees(math.atan2(o["east_kn"], o["north_kn"])) % 360
        assert abs(math.remainder(towards - o["set_deg"], 360)) < 1e-6
    # the voyage figure is the persistent current: the filtered steps scatter about it
    assert np.median([o["drift_kn"] for o in cur]) == pytest.approx(c.drift_kn.value, rel=0.5)


def test_inputs_are_the_logged_records(export):
    """Positions and headings against the raw log, read with the official reader."""
    raw: dict[str, dict[int, dict]] = {}
    with open(VOYAGE, "rb") as fh:
        for _, channel, msg in mcap_reader.make_reader(fh).iter_messages(
            topics=["/GNSS/fix", "/GYRO/heading", "/INS2/heading"]
        ):
            obj = json.loads(msg.data)
            raw.setdefault(channel.topic, {})[_ns(obj)] = obj
    for ours, theirs, key in (
        ("/input/gnss/fix", "/GNSS/fix", "latitude"),
        ("/input/compass/heading", "/GYRO/heading", "heading_deg"),
        ("/input/ins2/heading", "/INS2/heading", "heading_deg"),
    ):
        msgs = [o for _, o in export["topics"][ours]]
        assert msgs
        for o in msgs:
            r = raw[theirs][_ns(o)]
            assert o[key] == pytest.approx(r[key], abs=1e-9), (ours, _ns(o))
    assert {o["reference"] for _, o in export["topics"]["/input/compass/heading"]} == {"true"}
    t = [_ns(o) for _, o in export["topics"]["/input/compass/heading"]]
    assert np.diff(t).min() >= 10_000_000_000 - 1  # thinned to one per 10 s


def test_without_a_learned_model_the_dr_carries_the_covariance(analysis):
    """learn = false: the DR is the one track; /dracc/dr gets its covariance, no /dracc/ep."""
    dr = dataclasses.replace(analysis.dead_reckoning, learned=None)
    streams = {s.topic: s for s in mcap_streams(dataclasses.replace(analysis, dead_reckoning=dr))}
    assert "/dracc/ep" not in streams and "/dracc/dr_2m" in streams
    first = json.loads(streams["/dracc/dr"].messages[1])
    assert first["position_covariance_type"] == location_fix_pb2.LocationFix.KNOWN
    i = int(np.searchsorted(dr.track.time_ns, _ns(first)))
    assert first["latitude"] == pytest.approx(math.degrees(dr.track.lat_rad[i]), abs=1e-12)


# -------------------------------------------------------------------- the layout


def test_layout_names_only_channels_the_mcap_has(export):
    layout = json.loads(LAYOUT.read_text())
    panels = layout["configById"]
    topics = set(export["topics"])
    maps = [c for k, c in panels.items() if k.startswith("map!")]
    plots = [c for k, c in panels.items() if k.startswith("Plot!")]
    assert len(maps) == 1 and plots
    m = maps[0]
    named = set(m["topicColors"]) | set(m["disabledTopics"]) | {m["followTopic"]}
    assert named <= topics, named - topics
    kinds = {export["schema_of"][t].name for t in named}
    assert kinds == {"foxglove.LocationFix", "foxglove.GeoJSON"}
    assert {"/dracc/ep", "/dracc/dr", "/dracc/dr_2m", "/dracc/reference"} <= set(m["topicColors"])
    assert m["followTopic"] not in m["disabledTopics"]
    fields = set()
    for p in plots:
        for path in p["paths"]:
            topic, _, name = path["value"].partition(".")
            assert topic in topics, path["value"]
            schema = json.loads(export["schema_of"][topic].data)
            assert name in schema["properties"], path["value"]
            fields.add((topic.rsplit("/", 1)[-1], name))
    assert {("ins1", "lat_m"), ("current", "drift_kn"), ("dr_error", "radius_2m_m")} <= fields

    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(node["second"])

    assert sorted(leaves(layout["layout"])) == sorted(panels)


# --------------------------------------------------------------------- atomicity


def test_written_atomically_with_the_other_reports(analysis, tmp_path):
    path = tmp_path / "voyage.mcap"
    path.write_bytes(b"old")
    with pytest.raises(RuntimeError), atomic.together():
        write_mcap_export(analysis, path)
        raise RuntimeError("interrupted after the MCAP, before the next report")
    assert path.read_bytes() == b"old" and sorted(p.name for p in tmp_path.iterdir()) == [
        "voyage.mcap"
    ]
    with atomic.together():
        write_mcap_export(analysis, path)
        assert path.read_bytes() == b"old"  # renamed at the end of the block
    assert path.read_bytes()[:8] == b"\x89MCAP0\r\n"
