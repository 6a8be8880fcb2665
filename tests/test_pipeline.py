"""The pipeline on simulated voyages with known truth, and on logs written by the simulator.

Independent values come from the simulator's truth and error series: the DR against
the true track, the deviations against the written INS errors, the current against the
simulated current, the calibration against the simulated sensor errors.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from dracc.core.config import Config
from dracc.core.geodesy import offset_ne_m
from dracc.core.vocabulary import INS_ROLES
from dracc.frames import KINDS, Rejects, TimeEvents, Voyage, empty_frame
from dracc.ingest import summarize_frames
from dracc.pipeline.analysis import analyse, analyse_voyage
from dracc.pipeline.results import SCHEMA
from dracc.sim import GM, SimParams, simulate
from dracc.sim.params import NO_INS_ERROR


def voyage_from_sim(sv, drop_kinds=(), drop_roles=()) -> Voyage:
    """A Voyage as a perfect reader would return it, roles from the simulator."""
    frames = {}
    drop_keys = [k for k, r in sv.roles.items() if r in drop_roles]
    for k in KINDS:
        df = sv.frames.get(k, empty_frame(k))
        if k in drop_kinds:
            df = empty_frame(k)
        frames[k] = df[~df["source"].astype(str).isin(drop_keys)].reset_index(drop=True)
    sources = summarize_frames(frames, "sim.nmea")
    for key, info in sources.items():
        if key in sv.roles:
            info.roles = [sv.roles[key]]
    n = sum(len(f) for f in frames.values())
    return Voyage(
        frames=frames,
        sources=sources,
        rejects=Rejects(),
        time_events=TimeEvents(),
        inputs=[{"path": "sim.nmea", "format": "nmea", "lines": n, "records": n, "rejected": {}}],
        lines=n,
    )


@functools.cache
def _sim(kind: str):
    if kind == "noiseless":
        p = SimParams.noiseless(duration_s=3 * 3600.0, seed=3, compass_hz=1.0, aux_hz=0.0)
    elif kind == "current":
        # no sensor error; a steady current setting 168 deg while steering 034 deg, then 124
        p = SimParams.noiseless(
            duration_s=3 * 3600.0,
            seed=4,
            compass_hz=1.0,
            aux_hz=0.0,
            initial_heading_deg=34.0,
            legs=((0.0, 34.0), (5400.0, 124.0)),
            current_set_deg=168.0,
            current_drift_kn=0.6,
        )
    elif kind == "calibration":
        # a gyro bias (drawn once, sigma 0.5 deg), log scale +4 %, small noise, four headings
        p = SimParams.noiseless(
            duration_s=4 * 3600.0,
            seed=5,
            compass_hz=1.0,
            aux_hz=0.0,
            gyro_bias_deg=GM(0.5, math.inf),
            log_scale=0.04,
            legs=((0.0, 0.0), (3600.0, 90.0), (7200.0, 200.0), (10800.0, 300.0)),
            log_white_kn=0.02,
            gyro_white_deg=0.02,
        )
    else:  # "realistic": the simulator's defaults, 12 h
        p = SimParams(duration_s=12 * 3600.0, seed=6, compass_hz=1.0, aux_hz=0.0)
    return simulate(p)


@functools.cache
def _analysis(kind: str, **cfg):
    return analyse_voyage(voyage_from_sim(_sim(kind)), Config())


def _truth_at(sv, t_ns):
    tr = sv.truth
    i = np.searchsorted(tr["time_ns"].to_numpy(), t_ns)
    return tr["lat_rad"].to_numpy()[i], tr["lon_rad"].to_numpy()[i]


def test_noiseless_dr_follows_the_truth():
    sv = _sim("noiseless")
    a = _analysis("noiseless")
    dr = a.dead_reckoning
    assert dr is not None and a.schema == SCHEMA
    lat, lon = _truth_at(sv, dr.track.time_ns)
    n, e = offset_ne_m(dr.track.lat_rad, dr.track.lon_rad, lat, lon)
    err = np.hypot(n, e)
    # restarts from exact fixes; 1 s sample-and-hold through 0.5 deg/s turns
    assert np.nanmax(err) < 10.0
    assert len(dr.legs) >= 8 and dr.n_scored >= 15
    assert np.allclose(dr.track.ref_error_m, err, atol=0.5)  # GNSS is the truth here
    assert dr.consistent is True  # a tiny error inside a circle built for real sensors
    # a 3 h log: the automatic schedule restarts every 20 min, an epoch every 200 s
    assert dr.reset == "auto (20min)" and dr.epoch_interval_s == 200.0
    assert dr.epochs.time_ns[1] - dr.epochs.time_ns[0] == 200 * 10**9


def test_deviation_samples_match_the_written_ins_errors():
    """u_j = e_j - mean(e) (K1), with e the simulator's INS errors at the instants."""
    sv = _sim("realistic")
    a = _analysis("realistic")
    d = a.deviation
    assert d is not None and d.units == INS_ROLES and len(d.time_ns) == 13
    err = sv.errors
    i = np.searchsorted(err["time_ns"].to_numpy(), d.time_ns)
    ok = i < len(err)
    for ch, col in (("lat", "north_m"), ("lon", "east_m")):
        e = np.vstack([err[f"{u}_{col}"].to_numpy()[i[ok]] for u in INS_ROLES])
        u_true = e - e.mean(axis=0)
        for j, unit in enumerate(INS_ROLES):
            got = d.samples[unit][ch][ok]
            good = np.isfinite(got)
            assert good.sum() >= 12
            np.testing.assert_allclose(got[good], u_true[j][good], atol=2.0)  # written precision
    # INS2 is the worst unit by construction, and the reference (GNSS) says so too
    ref = {u: d.whole.units[u].reference["lon"].rmse for u in INS_ROLES}
    assert max(ref, key=ref.get) == "ins2"
    assert a.deviation_reference == "gnss"


def test_current_set_and_drift_from_the_filter():
    a = _analysis("current")
    c = a.current
    assert c is not None and c.n_updates >= 15
    assert abs((c.set_deg.value - 168.0 + 180.0) % 360.0 - 180.0) < 8.0  # not its mirror image
    assert c.drift_kn.value == pytest.approx(0.6, abs=0.1)


def test_calibration_recovers_gyro_error_and_log_scale():
    sv = _sim("calibration")
    a = _analysis("calibration")
    cal = a.calibration
    assert cal is not None and cal.n >= 20
    ce, ls = cal.compass_error_deg, cal.log_scale
    true_eps_deg = math.degrees(float(sv.errors["gyro_err_rad"].mean()))  # measured - true
    assert abs(true_eps_deg) > 0.2  # the seed draws a bias worth finding
    assert abs(ce.value - true_eps_deg) < max(0.05, 3 * ce.sigma)
    assert abs(ls.value - 0.04) < max(0.005, 3 * ls.sigma)


def test_missing_heading_is_reported_and_the_rest_still_computed():
    sv = _sim("noiseless")
    a = analyse_voyage(voyage_from_sim(sv, drop_kinds=("heading",)))
    assert a.dead_reckoning is None and a.current is None and a.calibration is None
    assert any(m.startswith("no heading") for m in a.missing)
    assert a.deviation is not None  # the INS statistics do not need the compass


def test_two_ins_units_say_so():
    sv = _sim("noiseless")
    a = analyse_voyage(voyage_from_sim(sv, drop_roles=("ins3",)))
    assert a.deviation is not None and a.deviation.units == ("ins1", "ins2")
    assert a.deviation.factors["lat"] == pytest.approx(math.sqrt(2.0))
    assert any("only two units" in m and "sqrt(2)" in m for m in a.missing)


def test_no_ins_and_no_gnss():
    sv = _sim("noiseless")
    a = analyse_voyage(voyage_from_sim(sv, drop_roles=("ins1", "ins2", "ins3", "gnss")))
    assert a.deviation is None and a.dead_reckoning is None
    assert any(m.startswith("no INS triple: no INS unit found") for m in a.missing)
    assert any("no position" in m for m in a.missing)


def test_ins_mean_fixes_when_there_is_no_gnss():
    sv = _sim("noiseless")  # INS without error here: their mean is the truth
    a = analyse_voyage(voyage_from_sim(sv, drop_roles=("gnss",)))
    dr = a.dead_reckoning
    assert dr is not None and dr.reference_role == "ins_mean"
    assert np.nanmax(dr.track.ref_error_m) < 10.0
    assert any("mean of the INS" in n for n in a.notes)


def test_files_of_one_voyage_merge_by_time(tmp_path):
    """One file per instrument (as research vessels record) gives the same result as one file."""
    from dracc.sim.nmea_out import write_nmea

    sv = simulate(
        SimParams.noiseless(
            duration_s=1.5 * 3600.0, seed=8, compass_hz=1.0, aux_hz=0.0, ins=(NO_INS_ERROR,) * 3
        )
    )
    whole = tmp_path / "all.nmea"
    write_nmea(sv, whole, form="tag")
    lines = whole.read_bytes().splitlines(keepends=True)
    parts = {}
    for line in lines:
        key = line.split(b"s:", 1)[1].split(b",", 1)[0].split(b"*", 1)[0] if b"s:" in line else b"x"
        parts.setdefault(key, []).append(line)
    paths = []
    for key, ls in parts.items():
        p = tmp_path / f"{key.decode()}.nmea"
        p.write_bytes(b"".join(ls))
        paths.append(p)
    assert len(paths) >= 5
    one = analyse([whole])
    many = analyse(sorted(paths))
    assert len(many.inputs) == len(paths) and any("merged by time" in n for n in many.notes)
    assert one.start_ns == many.start_ns and one.end_ns == many.end_ns
    np.testing.assert_array_equal(
        one.dead_reckoning.track.time_ns, many.dead_reckoning.track.time_ns
    )
    np.testing.assert_allclose(one.dead_reckoning.track.lat_rad, many.dead_reckoning.track.lat_rad)
    for u in INS_ROLES:
        np.testing.assert_allclose(
            one.deviation.samples[u]["lat"], many.deviation.samples[u]["lat"], equal_nan=True
        )


def test_recording_spells_cut_where_no_frame_has_a_record():
    import pandas as pd

    from dracc.pipeline.overview import recording_spells

    h = 3_600_000_000_000
    frames = {
        "position": pd.DataFrame({"time_ns": np.array([0, h, 2 * h, 40 * 24 * h], np.int64)}),
        "heading": pd.DataFrame({"time_ns": np.array([h // 2, 5 * h, 12 * h], np.int64)}),
    }
    # 5 h and 12 h bridge nothing more than 6 h apart... except 5 h -> 12 h (7 h)
    assert recording_spells(frames, 6 * h) == [
        (0, 5 * h, 5),
        (12 * h, 12 * h, 1),
        (40 * 24 * h, 40 * 24 * h, 1),
    ]
    assert recording_spells(frames, 1000 * h) == [(0, 40 * 24 * h, 7)]
    assert recording_spells({"position": pd.DataFrame({"time_ns": np.zeros(0, np.int64)})}, h) == []


def test_a_stray_record_days_away_is_said_and_does_not_fill_the_report(tmp_path):
    """A record with a plausible but wrong date stretches the period: the report says the
    records fall in separate spells, and the hourly sampling keeps to the hours with
    readings (not 960 empty instants and 40 empty days)."""
    from pathlib import Path

    sample = Path(__file__).resolve().parents[1] / "sample_logs" / "voyage_tag.nmea"
    if not sample.exists():
        pytest.skip("sample_logs not generated")

    def line(tag: str, sentence: str) -> str:
        cs = lambda s: f"{functools.reduce(lambda a, c: a ^ ord(c), s, 0):02X}"  # noqa: E731
        return f"\\{tag}*{cs(tag)}\\${sentence}*{cs(sentence)}\n"

    t = 1772344800 + 40 * 86400  # 40 days after the log's first second
    stray = tmp_path / "stray.nmea"
    stray.write_text(
        sample.read_text(encoding="ascii")
        + line(f"s:INS1,c:{t}", "INGGA,060000.00,5436.138899,N,01848.019925,E,1,,,25.0,M,,M,,"),
        encoding="ascii",
    )
    plain, a = analyse([sample]), analyse([stray])
    assert (a.end_ns - a.start_ns) / 3.6e12 > 900  # the period as recorded
    said = [n for n in a.notes if "spells" in n]
    assert len(said) == 1 and "2 spells more than 6 h apart" in said[0] and "(1 records)" in said[0]
    assert not any("spells" in n for n in plain.notes)
    assert len(a.deviation.time_ns) == len(plain.deviation.time_ns) + 1  # + the stray hour
    assert len(a.deviation.windows) == len(plain.deviation.windows) + 1
    assert not any(m.startswith("ins1 lat: missing") for m in a.deviation.messages)  # its own hour


def test_progress_reports_every_stage():
    from pathlib import Path

    sample = Path(__file__).resolve().parents[1] / "sample_logs" / "voyage_tag.nmea"
    if not sample.exists():
        pytest.skip("sample_logs not generated")
    seen: list[tuple[str, float]] = []
    analyse([sample], progress=lambda stage, f: seen.append((stage, f)))
    stages = [s for s, _ in seen]
    for s in (
        "reading logs",
        "sensor faults",
        "dead reckoning",
        "current",
        "deviation statistics",
        "calibration",
    ):
        assert (s, 0.0) in seen and (s, 1.0) in seen, s
    reading = [f for s, f in seen if s == "reading logs"]
    assert reading == sorted(reading) and len(reading) >= 3  # bytes read, as they are read
    assert (
        stages.index("reading logs")
        < stages.index("sensor faults")
        < stages.index("dead reckoning")
    )


def test_ground_log_when_there_is_no_water_speed():
    """A log giving only VBW ground components: DR over the ground (B13, B14), no current."""
    sv = _sim("noiseless")
    v = voyage_from_sim(sv)
    w = v.frames["water"].copy()
    assert np.isfinite(w["sog_long_mps"]).any()
    w["stw_mps"] = np.nan
    w["stw_transverse_mps"] = np.nan
    v.frames["water"] = w
    a = analyse_voyage(v)
    dr = a.dead_reckoning
    assert dr is not None and "over the ground" in dr.speed_source
    assert np.nanmax(dr.track.ref_error_m) < 10.0
    assert a.current is None and any("over the ground" in m for m in a.missing)


def test_magnetic_compass_true_heading_is_true_heading_rad():
    """On a magnetic-compass log the pipeline's true heading (B2) is
    dracc.math.deadreckoning.true_heading_rad of the compass's own fields: one
    implementation.  The variation is blank at every other sample (the configured one
    fills it) and so is the deviation at every third (0 without a table, in both)."""
    from dataclasses import replace

    from dracc.core.config import DeadReckoningConfig
    from dracc.core.geodesy import angdiff
    from dracc.math.deadreckoning import true_heading_rad
    from dracc.pipeline.selection import dedupe_sorted, heading_series

    sv = simulate(
        SimParams.noiseless(
            duration_s=1800.0, seed=7, compass="magnetic", compass_hz=1.0, aux_hz=0.0
        )
    )
    v = voyage_from_sim(sv)
    hdg = v.frames["heading"].copy()
    mag = np.flatnonzero((hdg["source"].astype(str) == "MAG").to_numpy())
    hdg.loc[mag[::2], "variation_rad"] = np.nan
    hdg.loc[mag[::3], "deviation_rad"] = np.nan
    v.frames["heading"] = hdg
    cfg = DeadReckoningConfig(variation_deg=5.0)  # the simulator's variation

    missing: list[str] = []
    notes: list[str] = []
    got = heading_series(v, cfg, missing, notes)
    assert got is not None and "magnetic" in got[2] and not missing
    t, h, _ = got

    m = hdg.iloc[mag]
    t_m, kk, dev, var = dedupe_sorted(
        m["time_ns"].to_numpy(np.int64),
        m["heading_rad"].to_numpy(float),
        m["deviation_rad"].to_numpy(float),
        m["variation_rad"].to_numpy(float),
    )
    want = true_heading_rad(kk, m["reference"].astype(str).to_numpy()[0], dev, var, errors=cfg)
    assert want.n_magnetic == kk.size and want.n_variation_from_config == int(np.sum(np.isnan(var)))
    np.testing.assert_array_equal(t, t_m)
    np.testing.assert_array_equal(h, want.heading_rad)
    # and where the compass sent its deviation, that is the true heading of the simulator
    tr = sv.truth
    i = np.searchsorted(tr["time_ns"].to_numpy(), t)
    sent_dev = np.isfinite(dev)
    err = angdiff(h, tr["heading_rad"].to_numpy()[i])
    assert np.max(np.abs(err[sent_dev])) < 1e-6
    # the DR runs on that heading
    a = analyse_voyage(v, replace(Config(), dead_reckoning=cfg))
    assert a.dead_reckoning is not None and "magnetic" in a.dead_reckoning.heading_source
