"""The aided-DR estimated position (seeds/003, dracc.math.ep.aided) in ``analyze``.

Independent values: Monte Carlo voyages sampled from the filter's own model with known
truth (dracc.math.current.simulate_voyage), bearings from GeographicLib, binomial bounds
on containment rates, chi-square bounds on variances.
"""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from geographiclib.geodesic import Geodesic

from dracc.core.geodesy import add_offset_ne, offset_ne_m
from dracc.math.current import CurrentModel, simulate_voyage
from dracc.math.ep.aided import (
    NIS_95_2DOF,
    TimedUpdate,
    interval_rows,
    interval_study,
    run_aided,
)
from dracc.math.fusion import BearingLOP, PositionFix
from dracc.report.json_report import load_schema

LAT0, LON0 = math.radians(54.0), math.radians(18.0)
P95 = 1.0 - math.exp(-NIS_95_2DOF / 2.0)  # 0.95: chi^2_2 inside the 95 % ellipse


def _binomial_ok(k: int, n: int, p: float = 0.95, z: float = 3.5) -> bool:
    return abs(k / n - p) <= z * math.sqrt(p * (1 - p) / n)


def test_a_bearing_shrinks_the_ellipse_across_its_line_only():
    rng = np.random.default_rng(21)
    model = CurrentModel()
    runs = 400
    t = np.arange(0.0, 3600.0 + 1, 10.0)
    v = simulate_voyage(rng, t, math.pi / 2, 5.0, LAT0, LON0, model, runs, start_sigma_m=10.0)
    k = int(np.searchsorted(t, 1800.0))  # the bearing's epoch
    # a mark 6 km north of the nominal track; true bearings by GeographicLib, noise 0.3 deg
    mark_lat, mark_lon = add_offset_ne(LAT0, LON0, 6000.0, 9000.0)
    geo = Geodesic.WGS84
    true_brg = np.array(
        [
            geo.Inverse(
                math.degrees(v.lat_rad[r, k]),
                math.degrees(v.lon_rad[r, k]),
                math.degrees(mark_lat),
                math.degrees(mark_lon),
            )["azi1"]
            for r in range(runs)
        ]
    )
    sigma = math.radians(0.3)
    brg = np.radians(true_brg) + rng.normal(0.0, sigma, runs)
    start_lat, start_lon = add_offset_ne(
        v.lat_rad[:, 0], v.lon_rad[:, 0], *rng.normal(0.0, 10.0, (2, runs))
    )
    start = PositionFix.from_sigma(start_lat, start_lon, 10.0)
    bearing = BearingLOP(mark_lat, mark_lon, brg, sigma)
    run = run_aided(
        t, v.course_rad, v.speed_mps, start, [TimedUpdate(t[k], bearing, "bearing 1")], model
    )
    (upd,) = run.track.updates
    a = math.radians(float(np.mean(true_brg)))
    along = np.array([math.cos(a), math.sin(a)])  # the line of position runs towards the mark
    across = np.array([-math.sin(a), math.cos(a)])

    def var(P, u):
        return np.einsum("i,...ij,j->...", u, P, u)

    # the filter: across the line the variance falls, along it it stays
    assert np.all(var(upd.cov_after_m2, across) < 0.2 * var(upd.cov_before_m2, across))
    assert np.all(var(upd.cov_after_m2, along) > 0.9 * var(upd.cov_before_m2, along))
    # the truth: the same, and the spread matches the filter's covariance (chi^2, 400 runs)
    d_n, d_e = offset_ne_m(v.lat_rad, v.lon_rad, run.track.lat_rad, run.track.lon_rad)
    err = np.stack([d_n, d_e], -1)
    lo, hi = 1 - 4 * math.sqrt(2 / runs), 1 + 4 * math.sqrt(2 / runs)
    for i in (k - 1, k):
        P = run.track.position_cov_m2[:, i]
        for u in (along, across):
            ratio = np.mean((err[:, i] @ u) ** 2) / np.mean(var(P, u))
            assert lo < ratio < hi, (i, u, ratio)
    before = np.var(err[:, k - 1] @ across)
    after = np.var(err[:, k] @ across)
    assert after < 0.2 * before
    assert np.var(err[:, k] @ along) > 0.8 * np.var(err[:, k - 1] @ along)
    # truth inside the 95 % ellipse at the expected rate, before, at and after the bearing
    for i in (k - 1, k, k + 90, t.size - 1):
        P = run.track.position_cov_m2[:, i]
        nees = np.einsum("ri,rij,rj->r", err[:, i], np.linalg.inv(P), err[:, i])
        assert _binomial_ok(int(np.sum(nees <= NIS_95_2DOF)), runs), i


def test_the_fix_interval_study_reproduces_figure_5():
    rng = np.random.default_rng(5)
    model = CurrentModel()
    runs = 40
    t = np.arange(0.0, 8 * 3600.0 + 1, 10.0)
    v = simulate_voyage(rng, t, math.pi / 2, 5.0, LAT0, LON0, model, runs, start_sigma_m=10.0)
    every = np.arange(0, t.size, 6)  # a GNSS fix every minute, 10 m per axis
    lat, lon = add_offset_ne(
        v.lat_rad[:, every], v.lon_rad[:, every], *rng.normal(0.0, 10.0, (2, runs, every.size))
    )
    intervals = (300.0, 600.0, 1200.0, 1800.0, 3600.0)
    study = interval_study(t, v.course_rad, v.speed_mps, t[every], lat, lon, 10.0, model, intervals)
    rows = interval_rows(intervals, study)
    mean = [r.mean_2m_before_m for r in rows]
    peak = [r.max_2m_before_m for r in rows]
    assert all(b > 1.5 * a for a, b in itertools.pairwise(mean))  # 2M grows with the interval
    assert all(b > a for a, b in itertools.pairwise(peak))
    for r in rows:
        assert r.n_updates == runs * (8 * 3600 // int(r.interval_s) - 1)
        assert _binomial_ok(round(r.containment * r.n_updates), r.n_updates, P95), r
    # independent of the study's bookkeeping: the 2M before the first 600 s update is the
    # prediction of 2 sqrt(trace P) from a 10 m fix over 600 s of the model
    t600 = t[t <= 600.0]
    one = run_aided(
        t600,
        v.course_rad[:61],
        v.speed_mps[:61],
        PositionFix.from_sigma(LAT0, LON0, 10.0),
        [],
        model,
    )
    assert study[1][0][0] == pytest.approx(one.track.two_drms_m[-1], rel=1e-9)


def test_analyze_takes_an_observation_file_and_the_fix_interval_study(tmp_path, run_cli):
    log = Path(__file__).resolve().parents[1] / "sample_logs" / "voyage_tag.nmea"
    obs = tmp_path / "obs.toml"
    obs.write_text(
        '[[bearing]]\ntime = "2026-03-01T07:00:05Z"\nlat = 54.7\nlon = 18.9\nbearing_deg = 40.0\n'
        '[[range]]\ntime = "2026-03-01T12:00:00Z"\nlat = 54.7\nlon = 18.9\ndist_nmi = 3.0\n'
    )
    out = tmp_path / "a.json"
    code, _, stderr = run_cli(
        "analyze",
        log,
        "--observations",
        str(obs),
        "--fix-interval",
        "5min,600,1h",
        "--json",
        str(out),
    )
    assert code == 0, stderr
    doc = json.loads(out.read_text())
    jsonschema.Draft202012Validator(load_schema()).validate(doc)
    ep = doc["estimated_position"]
    assert ep["n_lop_updates"] == 1 and ep["observations_outside"] == 1
    kinds = [e["update"] for e in ep["epochs"]]
    assert "bearing 1" in kinds and kinds.count("gnss") == ep["n_fix_updates"] - kinds.count(
        "gnss, bearing 1"
    )
    assert [r["interval_s"] for r in ep["fix_interval_study"]] == [300.0, 600.0, 3600.0]
    bad = tmp_path / "bad.toml"
    bad.write_text("[[bearing]]\nlat = 54.7\nlon = 18.9\nbearing_deg = 40.0\n")
    code, _, stderr = run_cli("analyze", log, "--observations", str(bad))
    assert code == 4 and "missing key 'time'" in stderr


def test_observation_file_datum_moves_the_mark_as_pyproj_does(tmp_path):
    """A bearing on a mark charted on ED50 updates the EP exactly as the same mark given in
    WGS-84 by pyproj's own EPSG transformation would; the note names the transformation."""
    pyproj = pytest.importorskip("pyproj")
    from dracc.core.config import Config
    from dracc.ingest.datums import to_wgs84
    from dracc.ingest.timed_observations import read_timed_observations
    from dracc.pipeline.analysis import analyse
    from dracc.pipeline.results import EPOptions

    log = Path(__file__).resolve().parents[1] / "sample_logs" / "voyage_tag.nmea"
    ed50 = (54.7, 18.9)
    moved = to_wgs84([ed50[0]], [ed50[1]], "ED50")
    tr = pyproj.Transformer.from_crs("EPSG:4230", "EPSG:4326", always_xy=True)
    lon_w, lat_w = tr.transform(ed50[1], ed50[0])
    assert abs(moved.lat_deg[0] - lat_w) < 1e-5 and abs(moved.lon_deg[0] - lon_w) < 1e-5
    body = 'time = "2026-03-01T07:00:05Z"\nbearing_deg = 40.0\n'
    a = tmp_path / "ed50.toml"
    a.write_text(f'datum = "ED50"\n[[bearing]]\nlat = {ed50[0]}\nlon = {ed50[1]}\n{body}')
    b = tmp_path / "wgs84.toml"
    b.write_text(
        f"[[bearing]]\nlat = {float(moved.lat_deg[0])!r}\nlon = {float(moved.lon_deg[0])!r}\n{body}"
    )
    eps = [
        analyse(
            [log], Config(), ep=EPOptions(observations=read_timed_observations(p))
        ).estimated_position
        for p in (a, b)
    ]
    np.testing.assert_array_equal(eps[0].lat_rad, eps[1].lat_rad)
    np.testing.assert_array_equal(eps[0].semi_major_m, eps[1].semi_major_m)
    note = [n for n in eps[0].notes if "charted on ED50" in n]
    assert len(note) == 1 and "moved to WGS-84 by ED50 to WGS 84" in note[0]
    assert not any("charted on" in n for n in eps[1].notes)
