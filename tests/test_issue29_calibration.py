"""Issue 29, item 2: calibration of a ship lying still reported a compass error of
+511.4 deg +- 52.7 deg and a log scale of -56 %.

Angles are wrapped to +-180 deg, and a quantity the data cannot determine (a ship at rest,
one steady course and speed) is NOT DETERMINABLE with why, judged from the fit itself.
"""

from __future__ import annotations

import json
import math

import numpy as np
from conftest import SPARSE_RATES
from test_calibration import _gm, _voyage

from dracc.cli.main import main
from dracc.core.geodesy import angdiff
from dracc.core.units import DEG_RAD as D
from dracc.core.units import KN_MPS as KN
from dracc.math.calibration import calibrate_from_track


def test_calibration_at_rest_not_determinable_and_angles_wrapped(run_cli, tmp_path):
    # a ship lying still in the water for 3 h (the log reads its bias and noise only)
    code = main(
        [
            "simulate", "--out", str(tmp_path), "--hours", "3", "--seed", "21",
            "--speed-kn", "0", "--legs", "0:30", "--name", "still", *SPARSE_RATES,
        ]
    )  # fmt: skip
    assert code == 0
    # learn = true (the default): the learned model's errors (issue 31), not determinable
    code, out, err = run_cli("analyze", tmp_path / "still.nmea", "--json", tmp_path / "a.json")
    assert code == 0, err
    cal = json.loads((tmp_path / "a.json").read_text())["calibration"]
    assert cal["method"] == "learned"
    assert cal["compass_error_deg"] is None and cal["log_scale"] is None
    nd = cal["not_determinable"]
    for key in ("compass_error_deg", "log_scale"):
        assert nd[key].startswith("the fixes did not constrain it: σ"), nd[key]
        assert "the ship did not move through the water" in nd[key]
    assert "no log-offset state" in nd["log_offset_kn"]
    assert "compass error NOT DETERMINABLE; log scale NOT DETERMINABLE" in " ".join(out.split())
    # learn = false: the least-squares fit says the same in its words
    (tmp_path / "ls.toml").write_text("[dead_reckoning]\nlearn = false\n")
    code, out, err = run_cli(
        "analyze",
        tmp_path / "still.nmea",
        "-c",
        tmp_path / "ls.toml",
        "--json",
        tmp_path / "b.json",
    )
    assert code == 0, err
    cal = json.loads((tmp_path / "b.json").read_text())["calibration"]
    assert cal["method"] == "least_squares"
    assert cal["compass_error_deg"] is None and cal["log_scale"] is None
    nd = cal["not_determinable"]
    assert nd["compass_error_deg"].startswith("compass error not observable: the ship did not move")
    assert nd["log_scale"].startswith("log scale not determinable: the ship did not move")
    assert "log scale and offset cannot be separated" in nd["log_offset_kn"]
    assert "compass error NOT DETERMINABLE; log scale NOT DETERMINABLE" in " ".join(out.split())

    # a compass reading 178 deg off on a moving ship: the fit's angle on (-180, 180]
    rng, t, course, speed, glat, glon = _voyage(4, hours=8.0)
    hdg = course + 178.0 * D + _gm(rng, t.size, 0.2 * D, 120.0)
    spd = 1.02 * speed + _gm(rng, t.size, 0.05 * KN, 300.0)
    fit = calibrate_from_track(t, hdg, spd, t, glat, glon)
    eps = float(fit.heading_error_rad[0])
    assert -math.pi < eps <= math.pi
    assert abs(angdiff(eps, 178.0 * D)) < 4 * fit.heading_error_sigma_rad[0] + 0.05 * D
    assert "compass_error" not in fit.not_determinable and "log_scale" not in fit.not_determinable
    assert abs(fit.log_scale - 0.02) < 4 * fit.log_scale_sigma


def test_steady_course_and_speed_names_what_cannot_be_separated():
    # one course at one speed: the scale and the compass error hide in the current
    _rng, t, course, speed, glat, glon = _voyage(
        8, hours=6.0, single_course=1.2, constant_speed=6.0
    )
    fit = calibrate_from_track(t, course, 1.01 * speed + 0.1, t, glat, glon)
    nd = fit.not_determinable
    assert set(nd) == {"compass_error", "log_scale", "log_offset"}
    assert (
        "log scale and offset cannot be separated: speed through the water spans 0.0 kn"
        in (nd["log_offset"])
    )
    assert "compass error and current cannot be separated" in nd["compass_error"]
    # the same voyage with turns and speed changes: everything determined again
    _rng, t, course, speed, glat, glon = _voyage(8, hours=6.0, speed_range=(1.5, 8.0))
    fit = calibrate_from_track(t, course, 1.01 * speed + 0.1, t, glat, glon)
    assert not fit.not_determinable
    assert np.isfinite(fit.log_offset_sigma_mps)
