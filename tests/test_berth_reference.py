"""The berth reference in ``analyze`` (seeds/004 with the Table 1 check of seeds/001).

A simulated ship lies still alongside a pier (speed 0, heading fixed), her GNSS removed
from the log.  Independent values: the reference position by hand from the pier geometry
through pyproj's geodesic (the reference point is half a breadth from the pier line, on
the side away from the pier, abeam of the mark), and the INS error RMS from the
simulator's own error series at the sampling instants.
"""

from __future__ import annotations

import functools
import json
import math

import numpy as np
import pytest
from pyproj import Geod

from dracc.core.config import config_from_dict
from dracc.core.errors import ConfigError
from dracc.core.vocabulary import INS_ROLES
from dracc.math.deviation.berth import berth_position
from dracc.pipeline.analysis import analyse_voyage
from dracc.report.json_report import load_schema, to_dict
from dracc.sim import DEFAULT_INS, SimParams, simulate
from tests.test_pipeline import voyage_from_sim

GEOD = Geod(ellps="WGS84")
LAT0, LON0 = 54.6, 18.8  # the simulator's start: the ship's reference point (its antenna)
HALF_BREADTH_M = 10.0
START, END = "2026-03-01T00:00:00Z", "2026-03-01T06:00:00Z"


def _pier(heading_deg: float, side: str) -> dict:
    """A pier 200 m long along ``heading_deg``, its line ``HALF_BREADTH_M`` off the ship's
    reference point on ``side``, and its abeam mark: by pyproj's geodesic."""
    to_pier = heading_deg + (90.0 if side == "starboard" else -90.0)
    mlon, mlat, _ = GEOD.fwd(LON0, LAT0, to_pier, HALF_BREADTH_M)
    alon, alat, _ = GEOD.fwd(mlon, mlat, heading_deg + 180.0, 100.0)
    blon, blat, _ = GEOD.fwd(mlon, mlat, heading_deg, 100.0)
    return {
        "pier": [alat, alon, blat, blon],
        "side": side,
        "half_breadth_m": HALF_BREADTH_M,
        "heading_deg": heading_deg,
        "abeam": [mlat, mlon],
        "sigma_m": 1.0,
    }


@functools.cache
def _sim(ins_scale: float = 1.0, hours: float = 6.0):
    p = SimParams.noiseless(
        duration_s=hours * 3600.0,
        seed=7,
        speed_kn=0.0,
        initial_heading_deg=0.0,
        legs=((0.0, 0.0),),
        compass_hz=1.0,
        aux_hz=0.0,
        ins=DEFAULT_INS,
    ).with_ins_error_scale(ins_scale)
    return simulate(p)


def _analysis(berth: dict | None, ins_scale: float = 1.0, drop_gnss: bool = True):
    sv = _sim(ins_scale)
    cfg: dict = {"deviation": {"interval_s": 600.0}}
    if berth is not None:
        cfg["reference"] = {"alongside": berth}
    voyage = voyage_from_sim(sv, drop_roles=("gnss",) if drop_gnss else ())
    return sv, analyse_voyage(voyage, config_from_dict(cfg))


def _truth_rms(sv, time_ns) -> dict:
    """Each unit's RMS error north and east (m) at the instants, from the simulator."""
    err = sv.errors
    i = np.searchsorted(err["time_ns"].to_numpy(), time_ns)
    return {
        u: {
            "lat": float(np.sqrt(np.mean(err[f"{u}_north_m"].to_numpy()[i] ** 2))),
            "lon": float(np.sqrt(np.mean(err[f"{u}_east_m"].to_numpy()[i] ** 2))),
        }
        for u in INS_ROLES
    }


@pytest.mark.parametrize("heading_deg,side", [(0.0, "starboard"), (33.0, "port"), (251.0, "port")])
def test_berth_position_is_the_hand_computed_one(heading_deg, side):
    b = config_from_dict({"reference": {"alongside": _pier(heading_deg, side)}}).reference
    sol, along, s_across, s_along = berth_position(b.alongside[0], math.radians(heading_deg), None)
    _, _, dist = GEOD.inv(LON0, LAT0, math.degrees(sol.lon_rad), math.degrees(sol.lat_rad))
    assert dist < 0.01  # metres: the ship's reference point, 10 m inside the pier line
    assert along == "abeam mark"
    assert s_across == pytest.approx(1.0, rel=1e-4) and s_along == pytest.approx(2.0, rel=1e-4)


def test_table1_against_the_berth_equals_that_against_the_truth():
    berth = _pier(0.0, "starboard") | {"start_utc": START, "end_utc": END}
    sv, a = _analysis(berth)
    d = a.deviation
    assert a.deviation_reference == "berth"
    assert len(d.berths) == 1 and d.berths[0].period_source == "configured"
    truth = _truth_rms(sv, d.time_ns)
    for u in INS_ROLES:
        for c in ("lat", "lon"):
            ref = d.whole.units[u].reference[c]
            assert ref.n == len(d.time_ns)
            assert abs(ref.rmse - truth[u][c]) < 1.0, (u, c)  # the berth's sigma
            assert ref.mark in "+-" and math.isfinite(ref.k_star)
        # heading_deg is configured: the course channel has the berth heading as reference
        assert "course" in d.whole.units[u].reference
    doc = to_dict(a)
    dev = doc["deviation"]
    assert dev["reference_source"] == "berth" and dev["berths"][0]["along_source"] == "abeam mark"
    assert any(m.startswith("Reference alongside berth 0") for m in dev["messages"])
    import jsonschema

    jsonschema.validate(json.loads(json.dumps(doc)), load_schema())


def test_detected_alongside_without_abeam_mark():
    """No period, no abeam mark, no heading: the period is found from the INS (errors
    scaled to 2 %), the heading from the compass; across the pier (east) the reference is
    the pier line's, so the east RMS still equals the truth's."""
    berth = {k: v for k, v in _pier(0.0, "starboard").items() if k not in ("abeam", "heading_deg")}
    sv, a = _analysis(berth, ins_scale=0.02)
    d = a.deviation
    (b,) = d.berths
    assert b.period_source == "detected" and b.heading_source == "compass"
    assert b.along_source == "ins mean" and math.isnan(b.sigma_along_m)
    assert b.end_ns - b.start_ns >= 5.9 * 3600e9
    truth = _truth_rms(sv, d.time_ns)
    for u in INS_ROLES:
        assert abs(d.whole.units[u].reference["lon"].rmse - truth[u]["lon"]) < 1.0
        assert "course" not in d.whole.units[u].reference  # no independent heading


def test_a_pier_elsewhere_is_not_used():
    berth = _pier(0.0, "starboard")
    lat1, lon1, lat2, lon2 = berth["pier"]
    berth["pier"] = [lat1 + 0.05, lon1, lat2 + 0.05, lon2]  # 5.5 km north
    del berth["abeam"]
    _, a = _analysis(berth, ins_scale=0.02)
    assert a.deviation_reference is None and a.deviation.berths == ()
    assert any("not found alongside" in m for m in a.missing)
    assert any("no reference (GNSS or a berth)" in m for m in a.missing)


def test_gnss_stays_preferred():
    berth = _pier(0.0, "starboard") | {"start_utc": START, "end_utc": END}
    _, with_berth = _analysis(berth, drop_gnss=False)
    _, without = _analysis(None, drop_gnss=False)
    assert with_berth.deviation_reference == "gnss" and without.deviation_reference == "gnss"
    assert with_berth.deviation.berths[0].n_reference == 0
    for u in INS_ROLES:
        for c in ("lat", "lon"):
            r1 = with_berth.deviation.whole.units[u].reference[c]
            r0 = without.deviation.whole.units[u].reference[c]
            assert r1.rmse == r0.rmse and r1.k_star == r0.k_star


def test_without_the_section_nothing_changes():
    _, a = _analysis(None)
    d = to_dict(a)["deviation"]
    assert a.deviation_reference is None and "berths" not in d
    assert all(not s.reference for s in a.deviation.whole.units.values())
    assert (
        "no reference (GNSS) for the INS: the true error RMS and k* (Table 1) are not computed"
        in a.missing
    )


GOOD = {"pier": [54.5, 18.6, 54.5027, 18.6], "side": "starboard", "half_breadth_m": 10}


@pytest.mark.parametrize(
    "berth,words",
    [
        ({**GOOD, "pier": [54.5, 18.6, 54.5027]}, r"alongside\[0\]\] pier = .*expected 4 numbers"),
        ({**GOOD, "pier": [54.5, 18.6, 54.5, 18.6]}, "less than 1 m apart"),
        ({**GOOD, "pier": [54.5, 18.6, 95.0, 18.6]}, r"latitudes must lie in \[-90, 90\]"),
        ({**GOOD, "side": "sb"}, "side = 'sb': expected one of 'port', 'starboard'"),
        ({**GOOD, "half_breadth_m": -1}, r"half_breadth_m = -1: must be in \(0, 100\] m"),
        ({**GOOD, "heading_deg": 90.0}, "heading_deg = 90.0: not along the pier"),
        ({**GOOD, "heading_deg": 400.0}, r"heading_deg = 400.0: must be in \[0, 360\]"),
        ({**GOOD, "sigma_m": 0}, r"sigma_m = 0: must be in \(0, 1,000,000\) m"),
        ({**GOOD, "abeam": [54.5]}, "abeam = .*expected 2 numbers"),
        ({k: v for k, v in GOOD.items() if k != "side"}, "side is missing"),
        ({**GOOD, "colour": "red"}, "unknown key"),
        ({**GOOD, "start_utc": "tomorrow"}, "start_utc = 'tomorrow': expected a UTC time"),
        ({**GOOD, "start_utc": END, "end_utc": START}, "end_utc = .*must be after start_utc"),
        (
            [
                {**GOOD, "start_utc": START, "end_utc": END},
                {**GOOD, "start_utc": END.replace("06", "05")},
            ],
            "overlap in time",
        ),
        (5, "alongside = 5: expected an array of berth tables"),
        ([5], r"alongside\[0\] = 5: expected a table"),
    ],
)
def test_config_errors_name_the_key(berth, words):
    with pytest.raises(ConfigError, match=words) as e:
        config_from_dict({"reference": {"alongside": berth}})
    assert str(e.value).startswith("[reference") and "\n" not in str(e.value)


def test_config_forms():
    one = config_from_dict({"reference": {"alongside": GOOD}}).reference.alongside
    many = config_from_dict({"reference": {"alongside": [GOOD, GOOD]}}).reference.alongside
    assert len(one) == 1 and len(many) == 2 and one[0].half_breadth_m == 10.0
    b = config_from_dict(
        {"reference": {"alongside": {**GOOD, "start_utc": "2026-03-01T01:00:00+01:00"}}}
    ).reference.alongside[0]
    assert b.start_utc == "2026-03-01T00:00:00Z" and b.start_ns == 1772323200 * 10**9
    assert config_from_dict({}).reference.alongside == ()


def test_a_pier_charted_on_ed50_is_moved_to_wgs84_first():
    """seeds/004 §2: the pier given on ED50 (its WGS-84 ends moved to ED50 by pyproj's EPSG
    transformation) gives the berth of the WGS-84 pier, and the message names the move."""
    pyproj = pytest.importorskip("pyproj")
    wgs = _pier(0.0, "starboard") | {"start_utc": START, "end_utc": END}
    to_ed50 = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:4230", always_xy=True)
    pier = wgs["pier"]
    lon_a, lat_a = to_ed50.transform(pier[1], pier[0])
    lon_b, lat_b = to_ed50.transform(pier[3], pier[2])
    lon_m, lat_m = to_ed50.transform(wgs["abeam"][1], wgs["abeam"][0])
    ed50 = wgs | {"pier": [lat_a, lon_a, lat_b, lon_b], "abeam": [lat_m, lon_m], "datum": "ED50"}
    assert GEOD.inv(lon_a, lat_a, pier[1], pier[0])[2] > 50  # ED50 is ~100 m off here
    _, a = _analysis(wgs)
    _, b = _analysis(ed50)
    for u in INS_ROLES:
        for c in ("lat", "lon"):
            ra = a.deviation.whole.units[u].reference[c].rmse
            rb = b.deviation.whole.units[u].reference[c].rmse
            assert abs(ra - rb) < 1.0, (u, c, ra, rb)  # the transformations' ~0.4 m
    assert any("pier charted on ED50, moved to WGS-84" in m for m in b.deviation.messages)
    bad = wgs | {"datum": "ED99"}
    with pytest.raises(ConfigError, match="ED99"):
        _analysis(bad)


def test_the_nightly_audit_checks_the_ins_against_the_berth(tmp_path):
    """A night alongside without GNSS: `dracc audit` (same analysis) gives the INS check
    against the berth, and the night's measures rank the units by it (method reference)."""
    from dracc.pipeline.audit import run_audit
    from dracc.report.audit_json import to_dict as audit_doc
    from dracc.sim.nmea_out import write_nmea

    sv = _sim(1.0, hours=3.0)
    full = tmp_path / "full.nmea"
    write_nmea(sv, full, form="tag")
    log = tmp_path / "alongside.nmea"
    log.write_text(
        "\n".join(ln for ln in full.read_text().splitlines() if "s:GNSS" not in ln) + "\n"
    )
    berth = _pier(0.0, "starboard") | {"start_utc": START, "end_utc": "2026-03-01T03:00:00Z"}
    cfg = config_from_dict({"deviation": {"interval_s": 600.0}, "reference": {"alongside": berth}})
    o = run_audit([log], cfg, db=tmp_path / "a.sqlite", vessel="Pier")
    assert o.analysis is not None and o.analysis.deviation_reference == "berth"
    doc = audit_doc(o)
    assert doc["analysis"]["deviation"]["reference_source"] == "berth"
    rows = {(r["unit"], r["quantity"]): r for r in doc["measures"]["rows"]}
    assert rows[("ins2", "lat_m_y")]["method"] == "reference"
    truth = _truth_rms(sv, o.analysis.deviation.time_ns)
    assert abs(rows[("ins2", "lat_m_y")]["value"] - truth["ins2"]["lat"]) < 2.0
