"""Issue 33: every numeric setting has a physically sensible range (dracc.core.bounds,
used by dracc.core.config's schema), and the work a setting may ask of one log is bounded
(``check_work``).  The cases of the issue: ``epoch_interval_s = 1e-6`` (MemoryError,
26.8 GiB), ``fix_sigma_m = 1e308`` (IndexError), a 100,000-deep array (RecursionError in
the TOML parser), ``[deviation] interval_s = 0.001`` (3 min, 4.3 GB): each is now exit 4
and one line naming the key and its range.
"""

from __future__ import annotations

import math
import re
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

import dracc.core.config as C
from dracc.core.bounds import MAX_CONFIG_BYTES, MAX_INSTANTS, check_work
from dracc.core.config import Config, ErrorSource, _hints
from dracc.core.errors import ConfigError, ExitCode
from dracc.core.reference_config import BerthConfig
from dracc.math.deadreckoning.reckon import dead_reckon
from dracc.math.deviation.sampling import sampling_instants
from dracc.math.integrity.helpers import covered_instants

SAMPLE = Path(__file__).resolve().parents[1] / "sample_logs" / "voyage_tag.nmea"

#: (TOML, the key as the message names it, the range it states)
CASES = [
    ("[dead_reckoning]\nepoch_interval_s = 1e-6", "[dead_reckoning] epoch_interval_s = 1e-06",
     "in [0.1, 86,400] seconds"),
    ("[dead_reckoning]\nfix_sigma_m = 1e308", "[dead_reckoning] fix_sigma_m = 1e+308",
     "in (0, 1,000,000) m"),
    ("[dead_reckoning]\ncompass_bias_deg = 1e308", "[dead_reckoning] compass_bias_deg = 1e+308",
     "in [0, 180] degrees"),
    ("[dead_reckoning]\ncurrent_kn = {sigma = 0.7, tau_s = 1e300}",
     "[dead_reckoning.current_kn] tau_s = 1e+300", "in [0, 1,000,000,000] seconds"),
    ('[dead_reckoning]\nreset = "0.01s"', "[dead_reckoning] reset = '0.01s'",
     "in [30, 31,622,400] seconds"),
    ("[deviation]\ninterval_s = 0.001", "[deviation] interval_s = 0.001",
     "in [1, 86,400] seconds"),
    ("[deviation]\nhat_draws = 100000000", "[deviation] hat_draws = 100000000",
     "in [100, 100,000]"),
    ("[integrity]\nconsistency_interval_s = 1e-4", "[integrity] consistency_interval_s = 0.0001",
     "in [0.1, 86,400] seconds"),
    ("[faults]\nmax_speed_kn = 1e9", "[faults] max_speed_kn = 1000000000.0", "in (0, 1000] kn"),
    ("[deviation]\nkurtosis_windows_s = [" + "86400.0, " * 2000 + "]",
     "[deviation] kurtosis_windows_s", "at most 1,000 items"),
    ('[reference]\nalongside = { pier = [54.5, 18.5, 54.6, 18.6], side = "port", '
     "half_breadth_m = 1e5 }", "half_breadth_m = 100000.0", "in (0, 100] m"),
]  # fmt: skip


@pytest.mark.parametrize(("toml", "key", "allowed"), CASES, ids=[c[1][:48] for c in CASES])
def test_an_out_of_range_setting_is_one_line_exit_4(run_cli, tmp_path, toml, key, allowed):
    cfg = tmp_path / "dracc.toml"
    cfg.write_text(toml + "\n")
    code, _, err = run_cli("analyze", SAMPLE, "-c", cfg)
    assert code == ExitCode.CONFIG, err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert key in err and allowed in err, err


def test_a_100000_deep_array_is_one_line_exit_4(run_cli, tmp_path):
    cfg = tmp_path / "dracc.toml"
    cfg.write_text("[deviation]\nkurtosis_windows_s = " + "[" * 100_000 + "]" * 100_000 + "\n")
    code, _, err = run_cli("analyze", SAMPLE, "-c", cfg)
    assert code == ExitCode.CONFIG and err.count("\n") == 1, err
    assert "nested too deep" in err and str(cfg) in err


def test_a_huge_configuration_file_is_refused_unread(run_cli, tmp_path):
    cfg = tmp_path / "dracc.toml"
    cfg.write_text("# a comment\n" * (MAX_CONFIG_BYTES // 12 + 10))
    code, _, err = run_cli("analyze", SAMPLE, "-c", cfg)
    assert code == ExitCode.CONFIG and err.count("\n") == 1, err
    assert "more than 1,048,576 bytes" in err


def test_a_command_line_option_goes_through_the_same_ranges(run_cli):
    code, _, err = run_cli("analyze", SAMPLE, "--epoch-interval", "0.01s")
    assert code == ExitCode.USAGE and "epoch_interval_s" in err and "[0.1, 86,400]" in err


# ------------------------------------------------------------------ the defaults


def _numbers(value: object) -> list[float]:
    """The numbers a setting holds (each item of an array or table, a sigma and a tau)."""
    if isinstance(value, ErrorSource):
        return [value.sigma]
    if isinstance(value, (tuple, list)):
        return [float(v) for v in value]
    if isinstance(value, dict):
        return [float(v) for v in value.values() if not isinstance(v, dict)]
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return [float(value)]
    return []


def test_every_numeric_default_lies_inside_its_range():
    defaults = [(getattr(Config(), f.name), f.name) for f in fields(Config) if f.name != "extra"]
    berth = BerthConfig(pier=(54.5, 18.5, 54.6, 18.6), side="port", half_breadth_m=15.0)
    checked = 0
    for section, name in [*defaults, (berth, "reference.alongside")]:
        cls = type(section)
        for f in fields(cls):
            rng = C._RULES[cls][f.name].range
            value = getattr(section, f.name)
            if rng is None or value is None:
                continue
            for v in _numbers(value):
                assert rng.holds(v), f"[{name}] {f.name} = {v}: not {rng.text}"
                checked += 1
            if isinstance(value, ErrorSource):
                assert math.isinf(value.tau_s) or C.TAU_S.holds(value.tau_s)
    assert checked >= 60


def test_every_number_has_a_bounded_range():
    """No numeric key is left open-ended (a finite number anywhere, or only positive)."""
    for cls in C._RULES:
        for name in _hints(cls):
            rng = C._RULES[cls][name].range
            if rng is None or rng is C.FINITE:  # FINITE: the pier's and the mark's lat/lon
                continue
            assert math.isfinite(rng.lo) and math.isfinite(rng.hi), f"{cls.__name__}.{name}"
            assert re.search(r"\d", rng.text), rng.text  # the message states the bounds


# ------------------------------------------------------------------ the work a setting asks


def test_dr_epochs_beyond_the_cap_are_refused_naming_the_least_interval():
    t = np.arange(0.0, 30 * 3600.0, 60.0)  # 30 h: 0.1 s asks 1.08 M epochs
    h, v = np.full(t.size, 0.5), np.full(t.size, 5.0)
    with pytest.raises(ConfigError) as e:
        dead_reckon(t, h, v, lat0_rad=0.9, lon0_rad=0.3, max_gap_s=120.0, epoch_interval_s=0.1)
    msg = str(e.value)
    assert msg.startswith("[dead_reckoning] epoch_interval_s = 0.1: 1,079,400 instants")
    assert "more than the 1,000,000" in msg and "epoch_interval_s >= 0.108" in msg
    track = dead_reckon(t, h, v, lat0_rad=0.9, lon0_rad=0.3, max_gap_s=120.0, epoch_interval_s=1)
    assert track.epoch_index.size > 1000  # within the cap: computed


def test_deviation_instants_beyond_the_cap_are_refused():
    hour_ns = 3600 * 10**9
    assert sampling_instants(0, 50 * hour_ns, 1.0).size == 50 * 3600 + 1
    with pytest.raises(ConfigError, match=r"^\[deviation\] interval_s = 1: 201,600 instants"):
        sampling_instants(0, 56 * hour_ns, 1.0)


def test_comparison_instants_beyond_the_cap_are_refused():
    day_ns = 86_400 * 10**9
    times = [np.arange(0, 5 * day_ns, 10**9, dtype=np.int64)]
    with pytest.raises(ConfigError, match=r"^\[integrity\] consistency_interval_s = 0.1: "):
        covered_instants(times, 0, 5 * day_ns, 10**8, setting=True)
    assert covered_instants(times, 0, 5 * day_ns, 10**10, setting=True).size == 43_200


def test_the_caps_leave_the_defaults_a_year_of_log():
    year_s = 366 * 86_400.0
    d = Config()
    check_work("deviation", "interval_s", d.deviation.interval_s, year_s)
    check_work("integrity", "consistency_interval_s", d.integrity.consistency_interval_s, year_s)
    check_work("dead_reckoning", "epoch_interval_s", 600.0, year_s)
    assert set(MAX_INSTANTS) == {
        ("dead_reckoning", "epoch_interval_s"),
        ("deviation", "interval_s"),
        ("integrity", "consistency_interval_s"),
    }
