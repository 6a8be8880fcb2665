"""Report layer: JSON against its schema, the terminal summary against golden files, tables.

The Analysis objects here are built by hand (``make_analysis``) so the renderers are
tested on their own; the pipeline tests feed them real computations.
Regenerate the golden files with ``DRACC_UPDATE_GOLDEN=1 python -m pytest tests/test_report.py``.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import os
from pathlib import Path

import jsonschema
import numpy as np
import pandas as pd
import pytest

from dracc.core.config import DeviationConfig
from dracc.core.distributions import chi2_ppf
from dracc.core.geodesy import add_offset_ne
from dracc.core.timefmt import iso_utc
from dracc.math.deadreckoning import LegConsistency
from dracc.math.deviation import UnitSeries, analyse_deviations
from dracc.pipeline.results import (
    SCHEMA,
    Analysis,
    CalibrationSection,
    CurrentSection,
    DRLeg,
    DRSection,
    DRTrackResult,
    Estimate,
    InputFile,
    SourceRow,
    TimeSummary,
    Track,
)
from dracc.report import json_report, tables, terminal

GOLDEN = Path(__file__).parent / "golden"
T0_NS = 1_772_323_200 * 10**9  # 2026-03-01T00:00:00Z
H_NS = 3600 * 10**9
HOSTILE = '<script>alert("x")</script><img src="http://example.com/x.png">'


@functools.lru_cache(maxsize=1)
def _deviation():
    """Deviations computed by dracc.math.deviation from three units with known, deterministic errors:
    readings every minute for 25 h; errors are sinusoids of 6 h period with amplitudes
    (m north, m east, deg) 100/150/0.05 for ins1, 200/300/0.1 for ins2, 240/180/0.06 for ins3;
    ins3's latitude error is in phase with ins2's (a shared error), which the three-cornered
    hat shows as a negative variance for ins2: sigma_2^2 = (35100 + 800 - 45920)/2 < 0."""
    t = T0_NS + np.arange(0, 25 * 3600 + 1, 60, dtype=np.int64) * 10**9
    x = (t - T0_NS) / 1e9 / (6 * 3600) * 2 * np.pi
    lat0, lon0 = np.radians(54.0), np.radians(10.0)
    heading = np.full(t.size, np.radians(60.0))
    units = {}
    for k, (name, (an, ae, ac, ph)) in enumerate(
        {
            "ins1": (100, 150, 0.05, 0.0),
            "ins2": (200, 300, 0.1, 2.1),
            "ins3": (240, 180, 0.06, 2.1),
        }.items()
    ):
        la, lo = add_offset_ne(lat0, lon0, an * np.sin(x + ph), ae * np.cos(x + 1.3 * k))
        units[name] = UnitSeries(
            pos_time_ns=t,
            lat_rad=la,
            lon_rad=lo,
            hdg_time_ns=t,
            heading_rad=heading + np.radians(ac * np.sin(x + 0.7 * k)),
        )
    ref = UnitSeries(pos_time_ns=t, lat_rad=np.full(t.size, lat0), lon_rad=np.full(t.size, lon0))
    cfg = DeviationConfig(
        apriori={"ins1": {"lat_m": 150.0}, "ins2": {"lat_m": 150.0}}, hat_draws=200
    )
    return analyse_deviations(units, cfg, ref)


def _dr_track(n: int, step_s: float, with_ref: bool) -> DRTrackResult:
    t = T0_NS + (np.arange(n) * step_s * 1e9).astype("int64")
    since = np.mod(np.arange(n) * step_s, 3600.0)
    leg = (np.arange(n) * step_s // 3600.0).astype("int64")
    lat = np.radians(54.0) + np.arange(n) * step_s * 5.0 / 6_371_000.0
    lon = np.radians(10.0) + np.arange(n) * step_s * 3.0 / 3_750_000.0
    r2m = 20.0 + 0.02 * since
    # the water track: the estimated position without a current of 0.25 m/s towards the
    # north-east that the EP learned (it starts at each leg's fix as the EP does)
    water_lat = lat - since * 0.25 * math.cos(math.radians(45.0)) / 6_371_000.0
    water_lon = lon - since * 0.25 * math.sin(math.radians(45.0)) / 3_750_000.0
    return DRTrackResult(
        time_ns=t,
        lat_rad=lat,
        lon_rad=lon,
        since_fix_s=since,
        radius_2m_m=r2m,
        semi_major_m=0.6 * r2m,
        semi_minor_m=0.3 * r2m,
        orientation_rad=np.full(n, np.radians(30.0)),
        ref_error_m=0.5 * r2m if with_ref else np.full(n, np.nan),
        leg=leg,
        water_lat_rad=water_lat,
        water_lon_rad=water_lon,
        # leg 0 has only the prior (no earlier fix to learn from): not scored
        scored=(leg >= 1) & (since > 0),
        inside=np.where((leg >= 1) & (since > 0) & with_ref, 1.0, np.nan),
        p_inside=np.where((leg >= 1) & (since > 0) & with_ref, 0.97, np.nan),
        pit=np.where((leg >= 1) & (since > 0) & with_ref, 0.4, np.nan),
    )


#: DRSection.learned as dracc.pipeline.dr_model.learned_summary makes it
LEARNED = {
    "current_set_deg": 45.0,
    "current_drift_kn": 0.49,
    "current_variation_kn": 0.15,
    "current_tau_s": 1800.0,
    "noise_kn": 0.1,
    "noise_tau_s": 600.0,
    "fix_sigma_m": 3.0,
    "model_weight": 0.93,
    "n_models": 576,
    "filter_step_s": 300.0,
    "n_fixes_used": 288,
    "n_outliers": 1,
    "config_block": (
        "[dead_reckoning]\nlearn = false\n"
        'compass_bias_deg = { sigma = 0.333, tau_s = "inf" }\n'
        "current_kn = { sigma = 0.397, tau_s = 1800 }\nfix_sigma_m = 3.0\n"
    ),
}


#: why a learned calibration has no log offset (dracc.pipeline.calibration_stage)
LEARNED_NO_OFFSET = (
    "the filter of the DR over the ground has no log-offset state: an offset is folded into the "
    "log scale at this voyage's speeds (b / V; median 12.0 kn through the water)"
)

#: the least-squares calibration of the same voyage (learn = false)
LEAST_SQUARES = CalibrationSection(
    reference_role="gnss",
    compass_error_deg=Estimate(0.31, 0.04),
    log_scale=Estimate(0.029, 0.002),
    log_offset_kn=Estimate(0.05, 0.02),
    n=140,
    segment_s=600.0,
    residual_rms_kn=0.08,
    method="least_squares",
    n_fixes=1500,
)


def _leg_checks() -> tuple[LegConsistency, ...]:
    """Legs 1-24 scored (leg 0 had nothing to learn from), five epochs each."""
    return tuple(
        LegConsistency(
            leg=i,
            start_s=3600.0 * i,
            n_epochs=5,
            n_inside=4 if i % 5 == 0 else 5,
            inside_fraction=0.8 if i % 5 == 0 else 1.0,
            rms_error_over_m=0.7,
            max_error_m=45.0,
            mean_nees=1.5 + 0.1 * (i % 4),
            last_nees=1.0 + 0.5 * (i % 3),
            nees_upper=9.21,
        )
        for i in range(1, 25)
    )


def make_analysis(kind: str = "full") -> Analysis:
    """A hand-built Analysis: 'full' (every section), 'bare' (positions only), 'hostile'."""
    hostile = kind == "hostile"
    key1 = HOSTILE if hostile else "INS1"
    sources = (
        SourceRow(
            key=key1,
            roles=("ins1",),
            records=90_000,
            sentences={"GGA": 30_000, "HDT": 30_000, "VTG": 30_000},
            first_ns=T0_NS,
            last_ns=T0_NS + 25 * H_NS,
        ),
        SourceRow(
            key="INS2",
            roles=("ins2",),
            records=90_000,
            sentences={"GGA": 30_000, "HDT": 30_000},
            first_ns=T0_NS,
            last_ns=T0_NS + 25 * H_NS,
        ),
        SourceRow(
            key="INS3",
            roles=("ins3",),
            records=90_000,
            sentences={"GGA": 30_000},
            first_ns=T0_NS,
            last_ns=T0_NS + 25 * H_NS,
        ),
        SourceRow(
            key="GP",
            roles=("gnss",),
            records=270_000,
            sentences={"GGA": 90_000, "RMC": 90_000, "ZDA": 90_000},
            first_ns=T0_NS,
            last_ns=T0_NS + 25 * H_NS,
        ),
        SourceRow(
            key="HE",
            roles=("compass",),
            records=900_000,
            sentences={"HDT": 900_000},
            first_ns=T0_NS,
            last_ns=T0_NS + 25 * H_NS,
        ),
        SourceRow(
            key="VW",
            roles=("log",),
            records=90_000,
            sentences={"VHW": 90_000},
            first_ns=T0_NS,
            last_ns=T0_NS + 25 * H_NS,
        ),
    )
    n_pos = 200
    tt = T0_NS + np.linspace(0, 25 * H_NS, n_pos).astype("int64")
    lat = np.radians(54.0) + np.linspace(0, 0.01, n_pos)
    lon = np.radians(10.0) + np.linspace(0, 0.02, n_pos)
    tracks = tuple(
        Track(
            source=s.key,
            role=s.roles[0],
            time_ns=tt,
            lat_rad=lat + 1e-6 * i,
            lon_rad=lon - 1e-6 * i,
        )
        for i, s in enumerate(sources)
        if s.roles[0] in ("ins1", "ins2", "ins3", "gnss")
    )
    a_common = {
        "schema": SCHEMA,
        "dracc_version": "0.1.0",
        "inputs": (
            InputFile(
                path=f"/logs/{HOSTILE if hostile else 'voyage'}.nmea",
                format="nmea",
                lines=1_530_012,
                records=1_530_000,
                rejected={"checksum": 10, "truncated": 2},
            ),
        ),
        "sources": sources,
        "rejected": {"checksum": 10, "truncated": 2},
        "reject_examples": {"checksum": (("/logs/voyage.nmea", 17, "$INGGA,bad*00"),)},
        "time": TimeSummary(
            duplicates=0,
            backsteps=1,
            gaps=2,
            rollovers=1,
            implausible_dates=0,
            decisions=("date from RMC",),
        ),
        "start_ns": T0_NS,
        "end_ns": T0_NS + 25 * H_NS,
        "lines": 1_530_012,
        "tracks": tracks,
        "settings": {"interval_s": 3600.0, "reset": "1h"},
    }
    if kind == "bare":
        return Analysis(
            **a_common,
            deviation=None,
            dead_reckoning=None,
            calibration=None,
            current=None,
            missing=(
                "no INS triple: only 1 INS unit (ins1) found; deviation statistics need "
                "at least two",
                "no heading: no HDT/THS/HDG/HDM sentence with a value; dead reckoning not computed",
            ),
            notes=("role ins1 assigned by --role",),
        )
    dev = _deviation()
    track = _dr_track(25 * 360, 10.0, with_ref=True)
    pick = np.arange(0, len(track.time_ns), 60)
    epochs = DRTrackResult(**{f: getattr(track, f)[pick] for f in track.__dataclass_fields__})
    checks = _leg_checks()
    legs = tuple(
        DRLeg(
            index=i,
            start_ns=T0_NS + i * H_NS,
            end_ns=T0_NS + (i + 1) * H_NS,
            fix_source="gnss",
            containment_2m=(1.0 if i % 5 else 0.8) if i else math.nan,
            n_scored=5 if i else 0,
            max_error_m=45.0 if i else math.nan,
        )
        for i in range(25)
    )
    nees_sum = sum(c.last_nees for c in checks)
    dr = DRSection(
        heading_source="compass HE (HDT, true)",
        speed_source="log VW (VHW, through water)",
        reset="1h",
        epoch_interval_s=600.0,
        track=track,
        epochs=epochs,
        legs=legs,
        reference_role="gnss",
        containment_2m=0.96,
        n_scored=120,
        expected_inside=0.975,
        error_over_m_rms=0.71,
        consistent=True,
        verdict=f"consistent: 96.0 % inside 2M (expected 95-98 %); NEES {nees_sum:.1f}",
        n_gaps_bridged=2,
        n_breaks=0,
        notes=("heading and speed held onto a 1 s grid",),
        mean_nees=float(np.mean([c.mean_nees for c in checks])),
        nees_statistic=nees_sum,
        nees_lower=float(chi2_ppf(0.005, 2 * len(checks))),
        nees_upper=float(chi2_ppf(0.995, 2 * len(checks))),
        leg_checks=checks,
        dominant_source="the change of the current",
        dominant_key="current_kn",
        learned=dict(LEARNED),
        reference_sigma_m=3.0,
        scored_out_of_sample=True,
    )
    # learn = true: the compass and log errors are the learned model's (issue 31)
    cal = CalibrationSection(
        reference_role="gnss",
        compass_error_deg=Estimate(0.31, 0.04),
        log_scale=Estimate(0.029, 0.002),
        log_offset_kn=None,
        n=288,
        segment_s=300.0,
        residual_rms_kn=math.nan,
        not_determinable={"log_offset_kn": LEARNED_NO_OFFSET},
        method="learned",
        n_fixes=288,
    )
    ct = T0_NS + np.arange(0, 25 * 3600, 600, dtype="int64") * 10**9
    cur = CurrentSection(
        set_deg=Estimate(168.0, 12.0),
        drift_kn=Estimate(0.4, 0.1),
        time_ns=ct,
        set_rad=np.full(len(ct), np.radians(168.0)),
        drift_mps=np.full(len(ct), 0.2),
        drift_sigma_mps=np.full(len(ct), 0.05),
        n_updates=25,
    )
    missing = ("no magnetic compass: deviation curve not estimated",) if not hostile else (HOSTILE,)
    return Analysis(
        **a_common,
        deviation=dev,
        dead_reckoning=dr,
        calibration=cal,
        current=cur,
        deviation_reference="gnss",
        missing=missing,
        notes=(HOSTILE,) if hostile else (),
    )


@pytest.fixture(scope="module")
def validator():
    schema = json_report.load_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema, format_checker=jsonschema.FormatChecker())


@pytest.mark.parametrize("kind", ["full", "bare", "hostile"])
def test_json_validates_against_schema(validator, kind):
    doc = json.loads(json_report.dumps(make_analysis(kind)))
    errors = sorted(validator.iter_errors(doc), key=str)
    assert not errors, errors[0]
    assert doc["schema"] == "dracc.analysis/1"


def test_schema_rejects_a_broken_report(validator):
    """The schema is not vacuous: a missing key or a wrong type fails."""
    doc = json_report.to_dict(make_analysis("full"))
    bad = json.loads(json.dumps(doc))
    del bad["deviation"]["units"]["ins1"]["lat"]["m_u"]
    assert list(validator.iter_errors(bad))
    bad = json.loads(json.dumps(doc))
    bad["dead_reckoning"]["epochs"][0]["radius_2m_m"] = "12 m"
    assert list(validator.iter_errors(bad))
    bad = json.loads(json.dumps(doc))
    bad["deviation"]["units"]["ins4"] = bad["deviation"]["units"]["ins1"]
    assert list(validator.iter_errors(bad))
    # the estimated-position keys are typed; the learned model and the NEES are complete
    for path in (
        ("nees", "upper"),
        ("learned_model", "config_block"),
        ("learned_model", "n_models"),
    ):
        bad = json.loads(json.dumps(doc))
        node = bad["dead_reckoning"]
        for k in path[:-1]:
            node = node[k]
        del node[path[-1]]
        assert list(validator.iter_errors(bad)), f"{path} may be missing"
    for path, value in (
        (("epochs", 3, "scored"), 1),
        (("learned_model", "config_block"), ["x"]),
        (("learned_model", "current_drift_kn"), "0.5 kn"),
        (("nees", "statistic"), "36"),
        (("learned_model",), "none"),
        (("legs", 0, "mean_nees"), "-"),
    ):
        bad = json.loads(json.dumps(doc))
        node = bad["dead_reckoning"]
        for k in path[:-1]:
            node = node[k]
        node[path[-1]] = value
        assert list(validator.iter_errors(bad)), f"{path} = {value!r} accepted"


#: keys added with the estimated position: optional in the schema (reports written before
#: them stay dracc.analysis/1), always written
EP_KEYS = {
    "dead_reckoning": (
        "mean_nees",
        "nees",
        "dominant_source",
        "dominant_key",
        "learned_model",
        "reference_sigma_m",
        "scored_out_of_sample",
    ),
    "epoch": ("water_lat_deg", "water_lon_deg", "scored"),
    "leg": ("mean_nees", "last_nees", "nees_upper"),
}


@pytest.mark.parametrize("kind", ["full", "hostile"])
def test_json_writes_every_key_the_schema_declares(kind):
    """Nothing optional is left out: the DR section, each epoch and each leg carry every
    property of the schema, the estimated-position keys included."""
    defs = json_report.load_schema()["$defs"]
    dr = json_report.to_dict(make_analysis(kind))["dead_reckoning"]
    assert set(dr) == set(defs["dead_reckoning"]["properties"])
    assert all(set(e) == set(defs["epoch"]["properties"]) for e in dr["epochs"])
    assert all(set(leg) == set(defs["leg"]["properties"]) for leg in dr["legs"])
    assert set(dr["learned_model"]) == set(defs["learned_model"]["properties"])
    for where, keys in EP_KEYS.items():
        assert set(keys) <= set(defs[where]["properties"]), where


def test_schema_accepts_a_report_written_before_the_estimated_position(validator):
    doc = json.loads(json_report.dumps(make_analysis("full")))
    dr = doc["dead_reckoning"]
    for k in EP_KEYS["dead_reckoning"]:
        del dr[k]
    for e in dr["epochs"]:
        for k in EP_KEYS["epoch"]:
            del e[k]
    for leg in dr["legs"]:
        for k in EP_KEYS["leg"]:
            del leg[k]
    assert not list(validator.iter_errors(doc))


def test_json_content_and_units():
    a = make_analysis("full")
    doc = json.loads(json_report.dumps(a))
    assert doc["period"] == {
        "start_utc": "2026-03-01T00:00:00Z",
        "end_utc": "2026-03-02T01:00:00Z",
        "duration_s": 90000.0,
    }
    assert doc["sources"]["gnss"] == {"keys": ["GP"], "records": 270_000}
    assert doc["inputs"][0]["rejected"] == {"checksum": 10, "truncated": 2}
    dev = doc["deviation"]
    assert dev["interval_s"] == 3600.0 and dev["factors"] == {
        "lat": 1.32,
        "lon": 1.49,
        "course": 1.49,
    }
    assert dev["reference_source"] == "gnss"
    assert len(dev["samples"]) == 26
    s3 = dev["samples"][3]  # x = pi: lat errors 0, -200 sin 2.1, -240 sin 2.1 -> mean -126.57
    assert s3["time_utc"] == "2026-03-01T03:00:00Z"
    assert s3["ins1"]["lat_m"] == pytest.approx(440.0 * math.sin(2.1) / 3.0, rel=1e-4)
    mean_c = (0.1 * math.sin(math.pi + 0.7) + 0.06 * math.sin(math.pi + 1.4)) / 3.0
    assert s3["ins1"]["course_deg"] == pytest.approx(-mean_c, rel=1e-3)
    u = dev["units"]["ins1"]
    assert u["lat"]["kurtosis_kind"] == "excess"
    assert u["lat"]["m_y"] == pytest.approx(1.32 * u["lat"]["m_u"])  # (K5b)
    assert u["lat"]["exceeds_apriori"] is True and u["lat"]["new_apriori"] == u["lat"]["m_y"]
    assert -1.0 <= u["r_lat_lon"] <= 1.0
    # ins2 and ins3 share a latitude error: the hat's variance for ins2 is negative, not clamped
    h2 = dev["hat"]["ins2"]["lat"]
    assert h2["negative"] is True and h2["sigma"] is None and h2["variance"] < 0
    # errors 100 sin(2 pi i/6), i = 0..25: RMS = 100 sqrt(12.75/26)
    assert dev["reference"]["ins1"]["lat"]["rmse"] == pytest.approx(
        100 * math.sqrt(12.75 / 26), rel=1e-3
    )
    assert [w["label"] for w in dev["windows"]] == ["2026-03-01", "2026-03-02"]
    dr = doc["dead_reckoning"]
    assert len(dr["epochs"]) == 25 * 6
    e1 = dr["epochs"][1]
    assert e1["time_utc"] == "2026-03-01T00:10:00Z" and e1["since_fix_s"] == 600.0
    assert e1["radius_2m_m"] == pytest.approx(32.0)
    assert e1["ellipse"]["orientation_deg"] == pytest.approx(30.0)
    assert e1["lat_deg"] == pytest.approx(math.degrees(math.radians(54.0) + 600.0 * 5 / 6_371_000))
    assert dr["containment_2m"] == 0.96
    # the estimated position: epochs carry the water track and whether they were scored
    want_water_lat = math.degrees(
        math.radians(54.0)
        + 600.0 * 5 / 6_371_000
        - 600.0 * 0.25 * math.cos(math.radians(45.0)) / 6_371_000
    )
    assert e1["water_lat_deg"] == pytest.approx(want_water_lat, abs=1e-12)
    assert e1["water_lat_deg"] < e1["lat_deg"] and e1["water_lon_deg"] < e1["lon_deg"]
    assert e1["scored"] is False  # leg 0: the prior only
    e7 = dr["epochs"][7]
    assert e7["leg"] == 1 and e7["since_fix_s"] == 600.0 and e7["scored"] is True
    assert dr["epochs"][6]["scored"] is False  # at the fix
    assert sum(e["scored"] for e in dr["epochs"]) == 24 * 5
    assert dr["scored_out_of_sample"] is True and dr["n_scored"] == 120
    checks = a.dead_reckoning.leg_checks
    assert dr["nees"] == {
        "statistic": pytest.approx(sum(c.last_nees for c in checks)),
        "lower": pytest.approx(a.dead_reckoning.nees_lower),
        "upper": pytest.approx(a.dead_reckoning.nees_upper),
    }
    assert dr["nees"]["lower"] < dr["nees"]["statistic"] < dr["nees"]["upper"]
    assert dr["mean_nees"] == pytest.approx(np.mean([c.mean_nees for c in checks]))
    leg0, leg2 = dr["legs"][0], dr["legs"][2]
    assert (
        leg0["n_scored"] == 0
        and leg0["mean_nees"] is None
        and leg0["last_nees"] is None
        and leg0["nees_upper"] is None
    )
    assert (
        leg2["mean_nees"] == pytest.approx(1.7)
        and leg2["last_nees"] == pytest.approx(2.0)
        and leg2["nees_upper"] == 9.21
    )
    assert (
        dr["dominant_source"] == "the change of the current" and dr["dominant_key"] == "current_kn"
    )
    assert dr["reference_sigma_m"] == 3.0
    assert dr["learned_model"] == LEARNED
    assert isinstance(dr["learned_model"]["config_block"], str)
    assert dr["learned_model"]["config_block"].startswith("[dead_reckoning]\nlearn = false\n")
    assert isinstance(dr["learned_model"]["n_models"], int)
    assert doc["calibration"]["compass_error_deg"] == {"value": 0.31, "sigma": 0.04}
    assert doc["calibration"]["method"] == "learned" and doc["calibration"]["n_fixes"] == 288
    assert doc["calibration"]["log_offset_kn"] is None
    assert doc["calibration"]["not_determinable"] == {"log_offset_kn": LEARNED_NO_OFFSET}
    # the learned model keeps no second, correction-signed copy of the sensor errors
    assert not {k for k in dr["learned_model"] if "correction" in k}
    cur = doc["current"]
    assert cur["set_deg"]["value"] == 168.0
    assert cur["series"][0]["drift_kn"] == pytest.approx(0.2 * 3600 / 1852)
    assert cur["series"][0]["set_deg"] == pytest.approx(168.0)


def _not_learned(a: Analysis) -> Analysis:
    """The same analysis as with ``learn = false``: the DR is the water track, nothing
    learned, every epoch after a fix scored, no NEES over legs."""
    dr = a.dead_reckoning
    tr = dataclasses.replace(
        dr.track,
        water_lat_rad=dr.track.lat_rad,
        water_lon_rad=dr.track.lon_rad,
        scored=dr.track.since_fix_s > 0,
    )
    ep = dataclasses.replace(
        dr.epochs,
        water_lat_rad=dr.epochs.lat_rad,
        water_lon_rad=dr.epochs.lon_rad,
        scored=dr.epochs.since_fix_s > 0,
    )
    return dataclasses.replace(
        a,
        dead_reckoning=dataclasses.replace(
            dr,
            track=tr,
            epochs=ep,
            learned=None,
            scored_out_of_sample=False,
            dominant_source=None,
            dominant_key=None,
            leg_checks=(),
            mean_nees=math.nan,
            nees_statistic=math.nan,
            nees_lower=math.nan,
            nees_upper=math.nan,
            reference_sigma_m=0.0,
        ),
        calibration=LEAST_SQUARES,
    )


def test_json_without_a_learned_model(validator):
    doc = json.loads(json_report.dumps(_not_learned(make_analysis("full"))))
    assert not list(validator.iter_errors(doc))
    dr = doc["dead_reckoning"]
    assert dr["learned_model"] is None and dr["scored_out_of_sample"] is False
    assert (
        dr["nees"] == {"statistic": None, "lower": None, "upper": None} and dr["mean_nees"] is None
    )
    assert dr["dominant_source"] is None and dr["dominant_key"] is None
    assert all(leg["mean_nees"] is None for leg in dr["legs"])
    e1 = dr["epochs"][1]
    assert e1["water_lat_deg"] == e1["lat_deg"] and e1["scored"] is True
    cal = doc["calibration"]
    assert cal["method"] == "least_squares" and cal["n"] == 140 and cal["n_fixes"] == 1500
    assert cal["log_offset_kn"] == {"value": 0.05, "sigma": 0.02}


def test_json_bare_says_what_is_missing():
    doc = json.loads(json_report.dumps(make_analysis("bare")))
    assert doc["deviation"] is None and doc["dead_reckoning"] is None
    assert any(m.startswith("no INS triple") for m in doc["missing"])
    assert any(m.startswith("no heading") for m in doc["missing"])


def test_iso_utc():
    assert iso_utc(T0_NS) == "2026-03-01T00:00:00Z"
    assert iso_utc(T0_NS + 1_500_000_000) == "2026-03-01T00:00:01.500Z"
    assert iso_utc(None) is None


@pytest.mark.parametrize("kind", ["full", "bare", "hostile"])
def test_terminal_summary_golden(kind):
    text = terminal.render_text(make_analysis(kind))
    path = GOLDEN / f"summary_{kind}.txt"
    if os.environ.get("DRACC_UPDATE_GOLDEN"):
        path.parent.mkdir(exist_ok=True)
        path.write_text(text, encoding="utf-8")
    assert text == path.read_text(encoding="utf-8")


def test_terminal_summary_content():
    text = terminal.render_text(make_analysis("full"))
    for needle in (
        "2026-03-01 00:00Z → 2026-03-02 01:00Z (25 h 00 min)",
        "rejected 12 lines: checksum 10",
        "2M       of the DR over the ground, largest 80 m: reference (gnss) inside 2M at 96.0 %",
        "scored   120 epochs out of sample",
        "5 prior-only epochs unscored",
        "NEES     36.0 over 24 scored legs (chi² 26.5-77.0)",
        "learned  current set 45 ° drift 0.49 kn; noise 0.10 kn; compass and log errors: "
        "see Calibration",
        "against gnss (learned with the DR over the ground from 288 fixes)",
        "log offset NOT DETERMINABLE",
        "excess",
        "neg. var.",
        "1.76 k low",
        "exceeds→178.6",
        "compass error 0.31 ± 0.04 °",
        "log scale 2.90 ±",
        "set 168 ± 12 ° (towards), drift 0.40 ± 0.10 kn",
    ):
        assert needle in text, needle
    bare = terminal.render_text(make_analysis("bare"))
    assert (
        "no INS triple" in bare
        and "no heading" in bare
        and bare.count("not computed (see Missing)") == 4
    )


def test_terminal_dominant_source_only_when_not_consistent():
    a = make_analysis("full")
    assert "dominant" not in terminal.render_text(a)  # consistent: nothing to blame
    for verdict in (
        "inconsistent (circle too small): reference inside 2M at 80.0 %",
        "conservative: reference inside 2M at 100.0 %",
    ):
        dr = dataclasses.replace(a.dead_reckoning, verdict=verdict, consistent=verdict[0] == "c")
        text = terminal.render_text(dataclasses.replace(a, dead_reckoning=dr))
        line = next(ln for ln in text.splitlines() if ln.startswith("dominant"))
        assert line == "dominant the change of the current ([dead_reckoning] current_kn)"


def test_terminal_without_a_learned_model():
    text = terminal.render_text(_not_learned(make_analysis("full")))
    assert "2M       of the water track, largest 80 m" in text
    assert "scored   120 epochs after a fix, error model as configured (learn = false)" in text
    assert "NEES     -; RMS error/M 0.71" in text
    assert "learned " not in text and "DR over the ground" not in text


def test_terminal_does_not_interpret_markup():
    text = terminal.render_text(make_analysis("hostile"))
    assert HOSTILE in text


def test_tables_roundtrip(tmp_path):
    a = make_analysis("full")
    written = tables.write_tables(a, tmp_path)
    names = sorted(p.name for p in written)
    assert names == sorted(
        f"{n}.{ext}"
        for n in ("dr_track", "dr_epochs", "deviation_samples", "unit_stats")
        for ext in ("csv", "parquet")
    )
    track = pd.read_parquet(tmp_path / "dr_track.parquet")
    assert len(track) == len(a.dead_reckoning.track.time_ns)
    assert str(track["time_utc"].dt.tz) == "UTC"
    assert track["time_utc"].iloc[1] == pd.Timestamp("2026-03-01T00:00:10Z")
    np.testing.assert_allclose(track["lat_deg"], np.degrees(a.dead_reckoning.track.lat_rad))
    csv = pd.read_csv(tmp_path / "dr_track.csv")
    assert csv["time_utc"].iloc[1] == "2026-03-01T00:00:10Z"  # fewest digits, as records
    np.testing.assert_allclose(csv["radius_2m_m"], a.dead_reckoning.track.radius_2m_m)
    # the water track and the scored flag, in both formats
    for df in (track, csv):
        assert list(df.columns)[-3:] == ["water_lat_deg", "water_lon_deg", "scored"]
        np.testing.assert_allclose(
            df["water_lat_deg"], np.degrees(a.dead_reckoning.track.water_lat_rad)
        )
        np.testing.assert_allclose(
            df["water_lon_deg"], np.degrees(a.dead_reckoning.track.water_lon_rad)
        )
        assert df["scored"].dtype == bool
        np.testing.assert_array_equal(df["scored"], a.dead_reckoning.track.scored)
    assert not track["scored"].iloc[:360].any() and track["scored"].iloc[361]
    epochs = pd.read_parquet(tmp_path / "dr_epochs.parquet")
    assert len(epochs) == 150 and int(epochs["scored"].sum()) == 120
    np.testing.assert_allclose(
        epochs["water_lon_deg"], np.degrees(a.dead_reckoning.epochs.water_lon_rad)
    )
    samples = pd.read_parquet(tmp_path / "deviation_samples.parquet")
    assert list(samples.columns)[:4] == ["time_utc", "ins1_lat_m", "ins1_lon_m", "ins1_course_deg"]
    assert samples["ins1_lat_m"].iloc[3] == pytest.approx(440.0 * math.sin(2.1) / 3.0, rel=1e-4)
    stats = pd.read_csv(tmp_path / "unit_stats.csv")
    row = stats[
        (stats.window == "all") & (stats.ins_unit == "ins2") & (stats.channel == "lat")
    ].iloc[0]
    ref = a.deviation.whole.units["ins2"]
    assert row["m_u"] == pytest.approx(ref.channels["lat"].m_u) and row["measure_unit"] == "m"
    assert row["k_star"] == pytest.approx(ref.reference["lat"].k_star)
    assert bool(row["hat_negative"]) is True
    assert set(stats["window"]) == {"all", "2026-03-01", "2026-03-02"}


def test_tables_bare_writes_nothing(tmp_path):
    assert tables.write_tables(make_analysis("bare"), tmp_path) == []


def test_tables_readable_by_duckdb(tmp_path):
    duckdb = pytest.importorskip("duckdb")
    tables.write_tables(make_analysis("full"), tmp_path)
    n = duckdb.sql(f"select count(*) from '{tmp_path / 'dr_track.parquet'}'").fetchall()[0][0]
    assert n == 25 * 360
    rows = duckdb.sql(
        f"select ins_unit, max(m_u) from read_csv_auto('{tmp_path / 'unit_stats.csv'}') "
        "where channel = 'lat' group by ins_unit order by ins_unit"
    ).fetchall()
    assert [r[0] for r in rows] == ["ins1", "ins2", "ins3"] and all(r[1] > 0 for r in rows)
