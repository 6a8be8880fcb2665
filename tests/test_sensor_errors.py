"""One estimate per sensor error, in one sign convention (issue 31, item 2).

With ``learn = true`` the calibration section's compass error and log scale are the
estimated position's learned model (dracc.pipeline.calibration_stage), in the error
convention: compass error = compass - true, V_log = (1 + s) V_true.  Checked against the
simulator's truth: the compass error is the gyro's (the simulated log writes VBW with a
transverse speed, so the DR's course carries the leeway and the compass error is the
gyro's alone); the log scale is the effective one at the voyage's speed, the scale plus
the offset over the speed (the learned filter has no offset state).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_pipeline import voyage_from_sim

from dracc.core.config import Config
from dracc.core.units import KN_MPS
from dracc.pipeline.analysis import analyse_voyage
from dracc.pipeline.audit.measures import night_measures
from dracc.pipeline.calibration_stage import DETERMINABLE_RATIO, correction_to_error
from dracc.pipeline.fleet.ranking import measures_frame, rank_fleet
from dracc.pipeline.results import CalibrationSection
from dracc.sim import GM, SimParams, simulate


def _box_legs(hours: float, first_deg: float) -> tuple[tuple[float, float], ...]:
    """Four legs of equal length, turning about 97 deg between them (the errors and the
    current are told apart by the turns)."""
    return tuple((i * hours * 900.0, (first_deg + 97.0 * i) % 360.0) for i in range(4))


def _truth(sv, p: SimParams) -> tuple[float, float]:
    """(compass error in deg, effective log scale error) the simulated voyage carries."""
    compass_deg = math.degrees(float(np.mean(sv.errors["gyro_err_rad"])))
    v_mps = float(np.mean(sv.truth["stw_mps"]))
    return compass_deg, p.log_scale + p.log_bias_kn * KN_MPS / v_mps


def _calibration(p: SimParams) -> tuple[CalibrationSection, tuple[float, float]]:
    sv = simulate(p)
    # the log writes a transverse speed: the DR takes the leeway from it
    assert np.isfinite(sv.frames["water"]["stw_transverse_mps"].to_numpy(float)).any()
    cal = analyse_voyage(voyage_from_sim(sv), Config()).calibration
    assert cal is not None and cal.method == "learned"
    return cal, _truth(sv, p)


def test_error_convention_of_the_learned_corrections():
    # eps is added to the DR course: a compass reading high needs a negative eps
    assert correction_to_error(-0.01, 0.0)[0] == pytest.approx(0.01)
    # V_true = (1 + s) V_log: a log reading 4 % high is s = 1/1.04 - 1
    assert correction_to_error(0.0, 1 / 1.04 - 1)[1] == pytest.approx(0.04)
    assert 0.0 < DETERMINABLE_RATIO < 1.0


def test_day_long_voyage_within_three_sigma_of_the_truth(capsys):
    p = SimParams(duration_s=24 * 3600.0, seed=31, compass_hz=1.0, aux_hz=0.0)
    cal, (compass_true, scale_true) = _calibration(p)
    ce, ls = cal.compass_error_deg, cal.log_scale
    assert ce is not None and ls is not None, cal.not_determinable
    assert cal.n_fixes == cal.n > 100 and "log_offset_kn" in cal.not_determinable
    with capsys.disabled():  # the issue asks 0.1 deg and 0.5 %: measured, not asserted
        print(
            f"\n24 h: compass error {ce.value:+.3f} ± {ce.sigma:.3f} ° (truth "
            f"{compass_true:+.3f}), log scale {100 * ls.value:+.3f} ± {100 * ls.sigma:.3f} % "
            f"(truth {100 * scale_true:+.3f} %)"
        )
    assert abs(ce.value - compass_true) <= 3 * ce.sigma
    assert abs(ls.value - scale_true) <= 3 * ls.sigma


def test_random_voyages_z_scores_have_a_plausible_spread(capsys):
    rng = np.random.default_rng(3101)
    z = []
    for k in range(6):
        p = SimParams(
            duration_s=6 * 3600.0,
            seed=3110 + k,
            compass_hz=1.0,
            aux_hz=0.0,
            log_scale=float(rng.uniform(-0.05, 0.05)),
            gyro_offset_deg=float(rng.uniform(-1.0, 1.0)),
        )
        cal, (compass_true, scale_true) = _calibration(p)
        for est, truth in ((cal.compass_error_deg, compass_true), (cal.log_scale, scale_true)):
            if est is not None:  # a not determinable one says why instead
                z.append((est.value - truth) / est.sigma)
    z = np.asarray(z)
    with capsys.disabled():
        print(
            f"\nz of 6 voyages: {np.array2string(z, precision=2)}; RMS {np.sqrt(np.mean(z**2)):.2f}"
        )
    assert z.size >= 6  # at least half determinable in 6 h (the others say why)
    assert np.mean(np.abs(z) <= 3.0) >= 0.9
    assert np.sqrt(np.mean(z**2)) < 1.5  # consistency (pyins: rms(error / sd) < 1.5)


def test_fleet_ranks_the_odd_log_first():
    # six sister ships in one sea area, 6 h each with four legs in a calm current (0.05 kn
    # of variation: the log scale to a few tenths of a per cent); D's log reads +6 %
    nights = []
    for k, vessel in enumerate(("A", "B", "C", "D", "E", "F")):
        p = SimParams(
            duration_s=6 * 3600.0,
            seed=3120 + k,
            compass_hz=1.0,
            aux_hz=0.0,
            log_scale=0.06 if vessel == "D" else 0.03,
            start_lat_deg=54.0 + 0.3 * k,
            legs=_box_legs(6.0, 37.0 + 40.0 * k),
            current_noise_kn=GM(0.05, 1800.0),
        )
        a = analyse_voyage(voyage_from_sim(simulate(p)), Config())
        nights.append((vessel, "2026-05-01", night_measures(a)))
    ranking = rank_fleet(measures_frame(nights))
    logs = ranking[ranking.quantity == "log_scale"].sort_values("rank")
    assert len(logs) == 6
    assert logs.iloc[0].vessel == "D", logs[["vessel", "value", "score"]]


@pytest.mark.parametrize(("log_scale", "gyro_deg"), [(0.04, 1.0)])
def test_sign_log_reading_high_and_gyro_reading_high_are_positive(log_scale, gyro_deg):
    p = SimParams(
        duration_s=6 * 3600.0,
        seed=3130,
        compass_hz=1.0,
        aux_hz=0.0,
        log_scale=log_scale,
        gyro_offset_deg=gyro_deg,
        legs=_box_legs(6.0, 10.0),
    )
    cal, (compass_true, scale_true) = _calibration(p)
    assert compass_true > 0.9 and scale_true > 0.04  # the gyro and the log read high
    assert cal.log_scale is not None and cal.log_scale.value > 0.0
    assert cal.compass_error_deg is not None and cal.compass_error_deg.value > 0.0
