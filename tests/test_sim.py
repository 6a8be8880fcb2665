"""The simulator's truth and error processes, against independent values."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from geographiclib.geodesic import Geodesic

from dracc.core.errors import ConfigError
from dracc.core.geodesy import E2, angdiff, k_lambda, k_phi, offset_ne_m
from dracc.core.units import DEG_RAD, KN_MPS, NMI_M
from dracc.frames import KIND_COLUMNS, KINDS
from dracc.sim import GM, InsErrorParams, SimParams, gauss_markov, simulate
from dracc.sim.processes import SCHULER_PERIOD_S, ins_errors
from dracc.sim.truth import compass_course_rad, deviation_curve_rad, integrate_track

SHORT = {"duration_s": 900.0, "compass_hz": 2.0}
Q_ANGLE = 0.0005 * DEG_RAD + 1e-12  # half a unit of the 3rd decimal of a degree
Q_SPEED = 0.0005 * KN_MPS + 1e-12
Q_POS_M = 0.5e-6 / 60 * DEG_RAD / k_phi(0.95) + 1e-6  # half a micro-minute, in metres


@pytest.fixture(scope="module")
def noisy():
    return simulate(SimParams(compass="both", seed=7, **SHORT))


@pytest.fixture(scope="module")
def exact():
    return simulate(
        SimParams.noiseless(
            compass="both", current_drift_kn=0.4, legs=((0.0, 350.0), (300.0, 80.0)), **SHORT
        )
    )


def at(v, frame, source):
    """Rows of ``frame`` from ``source`` and the truth rows at their times."""
    f = frame[frame["source"] == source]
    tr = v.truth.set_index("time_ns").loc[f["time_ns"].to_numpy()]
    return f, tr


# ---------------------------------------------------------------- structure and determinism


def test_frames_are_canonical(noisy):
    for kind in KINDS:
        f = noisy.frames[kind]
        assert list(f.columns)[:5] == ["time_ns", "source", "talker", "sentence", "line"]
        assert set(KIND_COLUMNS[kind]) <= set(f.columns)
        assert f["time_ns"].is_monotonic_increasing
        assert f["time_ns"].dtype == np.int64
    lines = np.concatenate([noisy.frames[k]["line"].to_numpy() for k in KINDS])
    # RMC is one line in two frames; with the ZDA lines, every line number 1..N is used once
    u = np.unique(lines)
    assert len(lines) - len(u) == (noisy.frames["ground"]["sentence"] == "RMC").sum()
    assert not np.isin(noisy.zda["line"], u).any()
    allln = np.union1d(u, noisy.zda["line"].to_numpy())
    assert np.array_equal(allln, np.arange(1, allln.max() + 1))
    assert noisy.roles == {
        "GYRO": "compass",
        "LOG": "log",
        "INS1": "ins1",
        "INS2": "ins2",
        "INS3": "ins3",
        "GNSS": "gnss",
    }  # 'both': MAG left unassigned


def test_rates_and_counts(noisy):
    n_s = 900
    pos = noisy.frames["position"]
    assert (pos["source"] == "INS2").sum() == n_s + 1
    hd = noisy.frames["heading"]
    assert (hd["source"] == "GYRO").sum() == 2 * (2 * n_s + 1) - n_s  # HDT 2 Hz + THS 1 Hz
    assert (hd["source"] == "MAG").sum() == 2 * n_s + 1
    assert len(noisy.truth) == 2 * n_s + 1
    assert np.all(np.diff(noisy.truth["time_ns"]) == 500_000_000)


def test_determinism_by_seed():
    a = simulate(SimParams(seed=3, **SHORT))
    b = simulate(SimParams(seed=3, **SHORT))
    c = simulate(SimParams(seed=4, **SHORT))
    for k in KINDS:
        pd.testing.assert_frame_equal(a.frames[k], b.frames[k])
    pd.testing.assert_frame_equal(a.truth, b.truth)
    pd.testing.assert_frame_equal(a.errors, b.errors)
    assert not np.array_equal(a.errors["ins1_north_m"], c.errors["ins1_north_m"])


def test_start_time_and_bad_params():
    v = simulate(SimParams(duration_s=10, start_utc="2024-12-31T23:59:55", compass_hz=1))
    assert v.truth["time_ns"].iloc[0] == pd.Timestamp("2024-12-31T23:59:55Z").value
    with pytest.raises(ConfigError, match="does not divide"):
        simulate(SimParams(duration_s=10, compass_hz=3.0, log_hz=2.0))
    with pytest.raises(ConfigError, match="compass"):
        simulate(SimParams(duration_s=10, compass="sextant"))
    with pytest.raises(ConfigError, match="ISO"):
        simulate(SimParams(duration_s=10, start_utc="yesterday"))
    with pytest.raises(ConfigError, match="duration"):
        simulate(SimParams(duration_s=0))
    with pytest.raises(ConfigError, match="simulate_segments"):
        simulate(SimParams(duration_s=7 * 86400.0))  # 10 Hz for a week: ~10 GB in one piece


# ---------------------------------------------------------------- truth


def test_rhumb_line_against_geographiclib():
    """Constant heading, no current: the track is a rhumb line.  North: the meridian arc
    (GeographicLib); east: tan C times the isometric-latitude difference (closed form)."""
    v = simulate(
        SimParams.noiseless(
            duration_s=6 * 3600.0, compass_hz=1.0, legs=((0.0, 35.0),), speed_kn=15.0
        )
    )
    tr = v.truth
    d_m = 15.0 * KN_MPS * 6 * 3600.0
    c = 35.0 * DEG_RAD
    lat0, lat1 = tr["lat_rad"].iloc[0], tr["lat_rad"].iloc[-1]
    arc = Geodesic.WGS84.Inverse(lat0 / DEG_RAD, 0.0, lat1 / DEG_RAD, 0.0)["s12"]
    assert arc == pytest.approx(d_m * math.cos(c), abs=1e-3)
    e = math.sqrt(E2)

    def iso(p):
        return math.atanh(math.sin(p)) - e * math.atanh(e * math.sin(p))

    dlon = math.tan(c) * (iso(lat1) - iso(lat0))
    assert tr["lon_rad"].iloc[-1] - tr["lon_rad"].iloc[0] == pytest.approx(dlon, rel=1e-9)


def test_velocity_composition(noisy):
    """(B7-B12, B10 corrected): ground = water track + current; the track follows it."""
    tr = noisy.truth
    kdw = tr["heading_rad"] + tr["leeway_rad"]
    np.testing.assert_allclose(
        tr["vn_mps"], tr["stw_mps"] * np.cos(kdw) + tr["current_n_mps"], atol=1e-12
    )
    np.testing.assert_allclose(
        tr["ve_mps"], tr["stw_mps"] * np.sin(kdw) + tr["current_e_mps"], atol=1e-12
    )
    np.testing.assert_allclose(
        np.hypot(tr["stw_long_mps"], tr["stw_transverse_mps"]), tr["stw_mps"], rtol=1e-12
    )
    n_m, e_m = offset_ne_m(
        tr["lat_rad"].to_numpy()[1:],
        tr["lon_rad"].to_numpy()[1:],
        tr["lat_rad"].to_numpy()[:-1],
        tr["lon_rad"].to_numpy()[:-1],
    )
    dt = 0.5
    vn_mid = 0.5 * (tr["vn_mps"].to_numpy()[1:] + tr["vn_mps"].to_numpy()[:-1])
    ve_mid = 0.5 * (tr["ve_mps"].to_numpy()[1:] + tr["ve_mps"].to_numpy()[:-1])
    np.testing.assert_allclose(n_m / dt, vn_mid, atol=1e-6)
    np.testing.assert_allclose(e_m / dt, ve_mid, atol=1e-6)
    assert tr["current_drift_mps"].mean() == pytest.approx(0.5 * KN_MPS, abs=0.3 * KN_MPS)


def test_integrate_track_uses_k_phi_k_lambda():
    vn = np.full(11, 3.0)
    ve = np.full(11, -4.0)
    lat, lon = integrate_track(0.5, 0.1, vn, ve, 1.0)
    assert lat[-1] - lat[0] == pytest.approx(30.0 * k_phi(0.5), rel=1e-5)
    assert lon[-1] - lon[0] == pytest.approx(-40.0 * k_lambda(0.5), rel=1e-4)


def test_legs_turn_at_the_given_rate():
    legs = ((0.0, 350.0), (600.0, 20.0), (1200.0, 290.0))
    v = simulate(
        SimParams.noiseless(duration_s=1800.0, compass_hz=1.0, legs=legs, turn_rate_deg_s=0.5)
    )
    tr = v.truth.set_index("t_s")
    assert tr.loc[599.0, "heading_rad"] == pytest.approx(350 * DEG_RAD)
    assert tr.loc[630.0, "heading_rad"] == pytest.approx(
        5 * DEG_RAD
    )  # 15 deg into 30 (shorter way)
    assert tr.loc[700.0, "heading_rad"] == pytest.approx(20 * DEG_RAD)
    assert tr.loc[1260.0, "heading_rad"] == pytest.approx(350 * DEG_RAD)  # turning to port
    assert tr.loc[1400.0, "heading_rad"] == pytest.approx(290 * DEG_RAD)
    assert tr.loc[630.0, "rot_radps"] == pytest.approx(0.5 * DEG_RAD)
    assert v.params.legs == legs


def test_generated_legs_are_explicit():
    r = 1 / 60.0
    v = simulate(
        SimParams(
            duration_s=12 * 3600.0, compass_hz=r, log_hz=r, ins_hz=r, gnss_hz=r, aux_hz=r, seed=2
        )
    )
    assert v.params.legs is not None and len(v.params.legs) >= 3
    assert v.params.legs[0] == (0.0, 60.0)


def test_compass_course_inverts_b2():
    coeffs = tuple(c * DEG_RAD for c in (0.5, 2.0, -1.5, 0.8, 0.3))
    psi = np.linspace(0, 2 * np.pi, 73)
    kk = compass_course_rad(psi, coeffs, 5.0 * DEG_RAD)
    back = kk + deviation_curve_rad(kk, coeffs) + 5.0 * DEG_RAD  # (B2)
    assert np.max(np.abs(angdiff(back, psi))) < 1e-13
    # hand value: KK = 90 deg gives delta = A + B - E = 0.5 + 2.0 - 0.3
    assert deviation_curve_rad(np.pi / 2, coeffs) == pytest.approx(2.2 * DEG_RAD)


# ---------------------------------------------------------------- noiseless: frames equal truth


def test_noiseless_frames_equal_truth(exact):
    v = exact
    f, tr = at(v, v.frames["heading"], "GYRO")
    assert np.max(np.abs(angdiff(f["heading_rad"], tr["heading_rad"]))) <= Q_ANGLE
    f, tr = at(v, v.frames["heading"], "MAG")
    ktz = f["heading_rad"] + f["deviation_rad"] + f["variation_rad"]  # (B2) with z = 0
    assert np.max(np.abs(angdiff(ktz, tr["heading_rad"]))) <= 3 * Q_ANGLE
    for j in (1, 2, 3):
        f, tr = at(v, v.frames["position"], f"INS{j}")
        n_m, e_m = offset_ne_m(f["lat_rad"], f["lon_rad"], tr["lat_rad"], tr["lon_rad"])
        assert np.max(np.abs(n_m)) < Q_POS_M and np.max(np.abs(e_m)) < Q_POS_M
        f, tr = at(v, v.frames["heading"], f"INS{j}")
        assert np.max(np.abs(angdiff(f["heading_rad"], tr["heading_rad"]))) <= Q_ANGLE
        f, tr = at(v, v.frames["ground"], f"INS{j}")
        assert np.max(np.abs(f["sog_mps"].to_numpy() - tr["sog_mps"].to_numpy())) <= Q_SPEED
    f, tr = at(v, v.frames["position"], "GNSS")
    n_m, e_m = offset_ne_m(f["lat_rad"], f["lon_rad"], tr["lat_rad"], tr["lon_rad"])
    assert np.max(np.hypot(n_m, e_m)) < 2 * Q_POS_M
    f, tr = at(v, v.frames["ground"], "GNSS")
    assert np.max(np.abs(angdiff(f["cog_rad"], tr["cog_rad"]))) <= Q_ANGLE
    f, tr = at(v, v.frames["water"], "LOG")
    vbw = f["sentence"] == "VBW"
    assert np.max(np.abs(f["stw_mps"].to_numpy() - tr["stw_long_mps"].to_numpy())) <= Q_SPEED
    assert (
        np.max(
            np.abs(
                f["sog_long_mps"][vbw].to_numpy() - tr["sog_long_mps"][vbw.to_numpy()].to_numpy()
            )
        )
        <= Q_SPEED
    )
    assert f.loc[~vbw, "sog_long_mps"].isna().all()  # VHW has no ground speed: NaN, not 0
    f, tr = at(v, v.frames["distance"], "LOG")
    assert (
        np.max(np.abs(f["trip_water_m"].to_numpy() - tr["water_distance_m"].to_numpy()))
        <= 0.0005 * NMI_M + 1e-9
    )
    f, tr = at(v, v.frames["rot"], "GYRO")
    assert (
        np.max(np.abs(f["rot_radps"].to_numpy() - tr["rot_radps"].to_numpy()))
        <= 0.005 * DEG_RAD / 60 + 1e-15
    )
    assert (
        v.errors.drop(columns=["time_ns", "current_n_mps", "current_e_mps"]).abs().max().max()
        == 0.0
    )
    assert all(r == pytest.approx(0.0, abs=0.01) for u in v.unit_rms.values() for r in u.values())


# ---------------------------------------------------------------- error processes


def test_noisy_frames_carry_the_errors(noisy):
    v = noisy
    e = v.errors.set_index("time_ns")
    f, tr = at(v, v.frames["heading"], "GYRO")
    g = e.loc[f["time_ns"].to_numpy(), "gyro_err_rad"].to_numpy()
    assert np.max(np.abs(angdiff(f["heading_rad"], tr["heading_rad"]) - g)) <= Q_ANGLE
    assert np.mean(g) / DEG_RAD == pytest.approx(0.3, abs=0.3)  # 0.3 deg offset + noise
    f, tr = at(v, v.frames["water"], "LOG")
    ee = e.loc[f["time_ns"].to_numpy()]
    want = (
        1.02 * tr["stw_long_mps"].to_numpy() + 0.05 * KN_MPS + ee["log_noise_long_mps"].to_numpy()
    )
    assert np.max(np.abs(f["stw_mps"].to_numpy() - want)) <= Q_SPEED
    for j in (1, 2, 3):
        f, tr = at(v, v.frames["position"], f"INS{j}")
        n_m, e_m = offset_ne_m(f["lat_rad"], f["lon_rad"], tr["lat_rad"], tr["lon_rad"])
        ee = e.loc[f["time_ns"].to_numpy()]
        np.testing.assert_allclose(n_m, ee[f"ins{j}_north_m"], atol=0.01)
        np.testing.assert_allclose(e_m, ee[f"ins{j}_east_m"], atol=0.01)


def test_gauss_markov_sigma_and_tau():
    """Across 400 vectorised runs: variance sigma^2 at every time, autocorrelation e^-1 at tau."""
    rng = np.random.default_rng(1)
    sigma, tau, dt = 2.0, 50.0, 1.0
    x = gauss_markov(3000, dt, sigma, tau, rng, runs=400)
    var = np.mean(x**2, axis=0)
    # the variance of a mean of 400 chi-square(1) samples: rel. sd sqrt(2/400) = 7 %
    assert abs(var[0] / sigma**2 - 1) < 4 * math.sqrt(2 / 400)
    assert abs(var[-1] / sigma**2 - 1) < 4 * math.sqrt(2 / 400)
    assert np.mean(var) / sigma**2 == pytest.approx(1.0, abs=0.03)
    lag = int(tau / dt)
    rho = np.mean(x[:, :-lag] * x[:, lag:]) / np.mean(x**2)
    assert rho == pytest.approx(math.exp(-1.0), abs=0.03)
    rho1 = np.mean(x[:, :-1] * x[:, 1:]) / np.mean(x**2)
    assert rho1 == pytest.approx(math.exp(-dt / tau), abs=0.01)
    b = gauss_markov(100, dt, sigma, math.inf, rng, runs=2000)
    assert np.all(b == b[:, :1])
    assert np.std(b[:, 0]) == pytest.approx(sigma, rel=4 / math.sqrt(2 * 2000))
    w = gauss_markov(20000, dt, sigma, 0.0, rng)
    assert abs(np.mean(w[:-1] * w[1:])) / sigma**2 < 4 / math.sqrt(20000)
    with pytest.raises(ConfigError):
        gauss_markov(10, dt, 1.0, -1.0, rng)


def test_schuler_period_in_ins_error_spectrum():
    """Three days of INS error at 10 s: the spectral peak between 1 and 3 h is 84.4 min."""
    dt = 10.0
    t = np.arange(0, 3 * 86400.0, dt)
    p = InsErrorParams(day_n_m=0.0, drift_n_mps=0.0)
    north, *_ = ins_errors(p, t, dt, np.random.default_rng(5))
    spec = np.abs(np.fft.rfft(north - north.mean())) ** 2
    freq = np.fft.rfftfreq(len(t), dt)
    band = (freq > 1 / (3 * 3600.0)) & (freq < 1 / 3600.0)
    peak = freq[band][np.argmax(spec[band])]
    # frequency resolution 1/(3 days): the period is resolved to about +-0.8 min at 84 min
    assert 1 / peak / 60 == pytest.approx(84.4, abs=1.0)
    assert pytest.approx(2 * np.pi * np.sqrt(6371000.0 / 9.81), rel=2e-3) == SCHULER_PERIOD_S


def test_ins_velocity_error_is_position_error_rate():
    dt = 1.0
    t = np.arange(0, 7200.0, dt)
    p = InsErrorParams(gm_m=GM(0.0), white_m=0.0)
    north, east, _, vn, ve = ins_errors(p, t, dt, np.random.default_rng(1))
    np.testing.assert_allclose(np.gradient(north, dt)[1:-1], vn[1:-1], atol=1e-5)
    np.testing.assert_allclose(np.gradient(east, dt)[1:-1], ve[1:-1], atol=1e-5)


def test_unit_rms_matches_errors_and_ins2_is_worst():
    r = 0.1
    v = simulate(
        SimParams(
            duration_s=24 * 3600.0, compass_hz=r, log_hz=r, ins_hz=r, gnss_hz=r, aux_hz=r, seed=11
        )
    )
    e = v.errors
    for j in (1, 2, 3):
        r = v.unit_rms[f"ins{j}"]
        assert r["lat_m"] == pytest.approx(np.sqrt(np.mean(e[f"ins{j}_north_m"] ** 2)), rel=1e-3)
        assert r["lon_m"] == pytest.approx(np.sqrt(np.mean(e[f"ins{j}_east_m"] ** 2)), rel=1e-3)
        assert r["course_deg"] == pytest.approx(
            np.sqrt(np.mean(e[f"ins{j}_heading_rad"] ** 2)) / DEG_RAD, rel=2e-2
        )
        # independently, from the frames against the truth
        f, tr = at(v, v.frames["position"], f"INS{j}")
        n_m, e_m = offset_ne_m(f["lat_rad"], f["lon_rad"], tr["lat_rad"], tr["lon_rad"])
        assert np.sqrt(np.mean(n_m**2)) == pytest.approx(r["lat_m"], rel=1e-4)
        assert np.sqrt(np.mean(e_m**2)) == pytest.approx(r["lon_m"], rel=1e-4)
    for ch in ("lat_m", "lon_m", "course_deg"):
        assert v.unit_rms["ins2"][ch] > max(v.unit_rms["ins1"][ch], v.unit_rms["ins3"][ch])
    # realistic sizes: a few hundred metres to about a nautical mile over a day
    assert 100 < v.unit_rms["ins1"]["lat_m"] < 600
    assert 400 < v.unit_rms["ins2"]["lon_m"] < 2 * NMI_M


def test_ins_error_scale():
    a = simulate(SimParams(seed=1, **SHORT))
    b = simulate(SimParams(seed=1, **SHORT).with_ins_error_scale(2.0))
    np.testing.assert_allclose(b.errors["ins2_north_m"], 2 * a.errors["ins2_north_m"], rtol=1e-12)
    np.testing.assert_allclose(
        b.errors["ins3_heading_rad"], 2 * a.errors["ins3_heading_rad"], rtol=1e-12
    )


def test_ins_unit_scales_scale_one_unit_only():
    a = simulate(SimParams(seed=1, **SHORT))
    b = simulate(SimParams(seed=1, **SHORT).with_ins_unit_scales((1.0, 3.0, 1.0)))
    np.testing.assert_allclose(b.errors["ins2_east_m"], 3 * a.errors["ins2_east_m"], rtol=1e-12)
    np.testing.assert_array_equal(b.errors["ins1_north_m"], a.errors["ins1_north_m"])
    np.testing.assert_array_equal(b.errors["ins3_heading_rad"], a.errors["ins3_heading_rad"])


def test_antimeridian_crossing():
    """Eastward across 180 deg: longitude wraps to -180, the track stays continuous."""
    v = simulate(
        SimParams.noiseless(
            duration_s=1200.0,
            compass_hz=1.0,
            start_lat_deg=-20.0,
            start_lon_deg=179.99,
            legs=((0.0, 90.0),),
        )
    )
    lon = v.truth["lon_rad"].to_numpy()
    assert lon[0] > 0 > lon[-1] and np.all(np.abs(lon) <= np.pi)
    _n_m, e_m = offset_ne_m(
        v.truth["lat_rad"].to_numpy()[1:], lon[1:], v.truth["lat_rad"].to_numpy()[:-1], lon[:-1]
    )
    np.testing.assert_allclose(e_m, 12.0 * KN_MPS, rtol=1e-6)
    f, tr = at(v, v.frames["position"], "INS1")
    assert np.max(np.abs(angdiff(f["lon_rad"], tr["lon_rad"]))) < 1e-9


def test_simulated_gyro_noise_has_its_sigma_and_tau():
    """The wiring of simulate(): its gyro error, less the 0.3 deg offset, is GM(0.1 deg, 300 s)
    + 0.02 deg white.  Ten days at 0.1 Hz hold ~1400 correlation times: the variance is
    within 4 x sqrt(2/1440) = 15 %, the autocorrelation at 300 s within +-0.1 of e^-1."""
    r = 0.1
    v = simulate(
        SimParams(
            duration_s=10 * 86400.0, compass_hz=r, log_hz=r, ins_hz=r, gnss_hz=r, aux_hz=r, seed=4
        )
    )
    x = v.errors["gyro_err_rad"].to_numpy() / DEG_RAD - 0.3
    var_gm, var_w = 0.1**2, 0.02**2
    assert np.var(x) == pytest.approx(var_gm + var_w, rel=0.15)
    lag = 30  # 300 s at 0.1 Hz
    rho = np.mean(x[:-lag] * x[lag:]) / var_gm
    assert rho == pytest.approx(math.exp(-1.0), abs=0.1)
    y = v.errors["log_noise_long_mps"].to_numpy() / KN_MPS
    assert np.var(y) == pytest.approx(0.1**2 + 0.02**2, rel=0.15)


def test_segments_continue_one_voyage():
    """A voyage simulated in segments is one voyage: noiseless, it equals the single run;
    with noise, no error series jumps at a joint more than within a segment."""
    from dracc.sim.model import simulate_segments

    kw = {
        "duration_s": 3 * 1800.0,
        "compass_hz": 1.0,
        "current_drift_kn": 0.7,
        "legs": ((0.0, 20.0), (2000.0, 200.0)),
    }
    whole = simulate(SimParams.noiseless(**kw))
    parts = list(simulate_segments(SimParams.noiseless(**kw), segment_s=1800.0))
    assert len(parts) == 3
    tr = pd.concat([p.truth for p in parts], ignore_index=True)
    assert np.array_equal(tr["time_ns"], whole.truth["time_ns"])
    for c in ("lat_rad", "lon_rad", "heading_rad"):
        np.testing.assert_allclose(tr[c], whole.truth[c], rtol=0, atol=1e-12, err_msg=c)
    np.testing.assert_allclose(
        tr["water_distance_m"], whole.truth["water_distance_m"], rtol=1e-12
    )  # summation order differs: rounding only
    trip = pd.concat([p.frames["distance"]["trip_water_m"] for p in parts]).to_numpy()
    np.testing.assert_allclose(trip, whole.frames["distance"]["trip_water_m"], atol=1e-6)

    noisy = list(simulate_segments(SimParams(seed=2, **kw), segment_s=1800.0))
    err = pd.concat([p.errors for p in noisy], ignore_index=True)
    assert len(err) == len(whole.truth) and err["time_ns"].is_unique
    joints = np.cumsum([len(p.errors) for p in noisy])[:-1]
    for c in ("ins2_north_m", "ins1_heading_rad", "current_n_mps", "gyro_err_rad"):
        d = np.abs(np.diff(err[c].to_numpy()))
        inside = np.delete(d, joints - 1)
        assert d[joints - 1].max() <= inside.max(), c
    # the segments draw their own noise: not a copy of the first segment
    assert not np.allclose(
        noisy[1].errors["gnss_north_m"].to_numpy()[:100],
        noisy[0].errors["gnss_north_m"].to_numpy()[:100],
    )
