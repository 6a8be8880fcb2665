"""Every configuration key is checked for its type and range when the file is read: a wrong
value is a ConfigError (exit 4) naming ``[section] key`` in one line, never a TypeError deep
inside an analysis (exit 5) nor a value silently taken for another (``strict = "no"``)."""

from __future__ import annotations

import datetime as dt
import math
import re
import subprocess
import sys
import typing
from dataclasses import fields
from pathlib import Path

import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from dracc.core import config as C
from dracc.core.config import (
    Config,
    DeadReckoningConfig,
    ErrorSource,
    config_from_dict,
    load_config,
    validate,
    with_overrides,
)
from dracc.core.errors import ConfigError, ExitCode

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "docs" / "dracc.example.toml"
SAMPLE = REPO / "sample_logs" / "voyage_tag.nmea"
SECTIONS = {
    "ingest": C.IngestConfig,
    "dead_reckoning": C.DeadReckoningConfig,
    "deviation": C.DeviationConfig,
    "faults": C.FaultsConfig,
    "integrity": C.IntegrityConfig,
}

#: wrong-typed values for each annotation a section field has (a new annotation fails
#: test_every_annotation_has_wrong_values until it is added here)
WRONG: dict = {
    bool: [1, 0, "no", "true", [True], {"on": True}],
    float: ["sixty", True, [1.0], {"value": 1.0}, dt.date(2026, 3, 1)],
    int: ["two", 1.5, True, [1], {"n": 1}],
    str: [5, True, ["auto"], {"value": "auto"}],
    str | None: [5, False, ["2026-03-01"]],
    float | None: ["ten", False, [1.0]],
    dict[str, str]: ["INS1", 5, True, ["INS1"], {"K": 5}, {"K": True}, {"K": ["ins1"]}],
    dict[str, float]: ["0", 5, ["0"], {"0": "one"}, {"0": True}, {"0": [1.0]}],
    dict[str, dict[str, float]]: [
        "ins1",
        5,
        [{"lat_m": 1.0}],
        {"ins1": 5},
        {"ins1": "x"},
        {"ins1": {"lat_m": "x"}},
        {"ins1": {"lat_m": True}},
    ],
    tuple[float, ...]: ["86400", 86400.0, {"a": 1.0}, ["a"], [True], [[1.0]]],
    ErrorSource: [
        "big",
        True,
        [0.1],
        {"sigma": "x"},
        {"sigma": True},
        {"sigma": 0.1, "tau_s": "long"},
        {"sigma": 0.1, "tau_s": True},
        {"sigma": 0.1, "tau_s": [1]},
        {"tau_s": 5.0},
        {"sigma": 0.1, "tau": 5.0},
    ],
}


def _hints(cls) -> dict:
    return typing.get_type_hints(cls)


def _wrong_cases():
    for section, cls in SECTIONS.items():
        for f in fields(cls):
            for i, value in enumerate(WRONG.get(_hints(cls)[f.name], [])):
                yield pytest.param(section, f.name, value, id=f"{section}.{f.name}-{i}")


def _names_the_key(msg: str, section: str, key: str) -> bool:
    """``[section] key = ...`` or, inside a table value, ``[section.key] ...`` / ``[section.key.x]``."""
    return re.match(rf"\[{section}(\] {key}\b|\.{key}[\].])", msg) is not None


def test_every_annotation_has_wrong_values():
    for cls in SECTIONS.values():
        for name, tp in _hints(cls).items():
            assert tp in WRONG, f"{cls.__name__}.{name}: {tp!r} has no wrong values in WRONG"


def test_every_field_has_a_rule():
    """The schema covers every field: a new key must be given its range."""
    for cls in SECTIONS.values():
        assert set(C._RULES[cls]) == {f.name for f in fields(cls)}, cls.__name__


@pytest.mark.parametrize("section,key,value", list(_wrong_cases()))
def test_wrong_type_is_a_config_error_naming_the_key(section, key, value):
    with pytest.raises(ConfigError) as e:
        config_from_dict({section: {key: value}})
    msg = str(e.value)
    assert _names_the_key(msg, section, key), msg
    assert "\n" not in msg


@pytest.mark.parametrize("section", list(SECTIONS))
@pytest.mark.parametrize("value", [5, "x", [1], True])
def test_a_section_that_is_not_a_table(section, value):
    with pytest.raises(ConfigError, match=rf"^\[{section}\] must be a table, got "):
        config_from_dict({section: value})


@pytest.mark.parametrize("section", ["audit", "fleet", "report", "vessel"])
def test_an_owner_section_that_is_not_a_table(section):
    with pytest.raises(ConfigError, match=rf"^\[{section}\] must be a table"):
        config_from_dict({section: "x"})


# ----------------------------------------------------------------------------- ranges

RANGE_CASES = [
    ("ingest", "gap_s", 0, r"in \(0, "),
    ("ingest", "gap_s", -60.0, r"in \(0, "),
    ("ingest", "gap_s", math.inf, "finite"),
    ("ingest", "gap_s", math.nan, "finite"),
    ("ingest", "backstep_tolerance_s", -0.5, r"in \[0, "),
    ("ingest", "date", "2026-13-01", "YYYY-MM-DD"),
    ("ingest", "date", "1 March 2026", "YYYY-MM-DD"),
    ("ingest", "date", "2026-3-1", "YYYY-MM-DD"),
    ("ingest", "max_line_bytes", 0, r"in \[64, 1,073,741,824\] bytes"),
    ("ingest", "max_chunk_bytes", -1, r"in \[1024, "),
    ("ingest", "memory_cap_mb", 0, r"in \[16, 1,048,576\] MB"),
    ("ingest", "memory_cap_mb", 512.5, "integer"),
    ("ingest", "max_inflate_ratio", 0, r"in \[2, 1,000,000\]"),
    ("ingest", "max_inflate_ratio", math.inf, "finite"),
    ("ingest", "temp_cap_mb", -1, r"in \[1, "),
    ("ingest", "temp_cap_mb", 4096.5, "integer"),
    ("ingest", "sources", {"INS1": "ins4"}, "role must be one of"),
    ("ingest", "quantities", {"Speed (kn)": "stw_knots"}, "not a quantity name"),
    ("dead_reckoning", "reset", "hourly", "duration"),
    ("dead_reckoning", "reset", "0h", "duration"),
    ("dead_reckoning", "reset", "-1h", "duration"),
    ("dead_reckoning", "reset", "", "duration"),
    ("dead_reckoning", "fix_role", "gps", "one of 'gnss', 'ins_mean'"),
    ("dead_reckoning", "max_gap_s", 0.0, r"in \(0, "),
    ("dead_reckoning", "epoch_interval_s", -600, r"in \[0.1, 86,400\] seconds"),
    ("dead_reckoning", "variation_deg", 200.0, "180"),
    ("dead_reckoning", "variation_deg", math.nan, "finite"),
    ("dead_reckoning", "deviation_table", {"north": 1.0}, "heading"),
    ("dead_reckoning", "deviation_table", {"400": 1.0}, "heading"),
    ("dead_reckoning", "deviation_table", {"-10": 1.0}, "heading"),
    ("dead_reckoning", "deviation_table", {"0": 1.0, "360": 2.0}, "twice"),
    ("dead_reckoning", "deviation_table", {"90": 1.0, "90.0": 2.0}, "twice"),
    ("dead_reckoning", "deviation_table", {"90": 270.0}, "180"),
    ("dead_reckoning", "deviation_table", {"90": math.inf}, "finite"),
    ("dead_reckoning", "compass_bias_deg", -0.1, r"in \[0, "),
    ("dead_reckoning", "compass_noise_deg", {"sigma": -0.2, "tau_s": 120}, r"in \[0, "),
    ("dead_reckoning", "compass_noise_deg", {"sigma": math.inf}, "finite"),
    ("dead_reckoning", "log_noise_kn", {"sigma": 0.1, "tau_s": -300}, r"in \[0, "),
    ("dead_reckoning", "log_noise_kn", {"sigma": 0.1, "tau_s": math.nan}, r"in \[0, "),
    ("dead_reckoning", "fix_sigma_m", 0, r"in \(0, "),
    ("deviation", "interval_s", 0, r"in \[1, 86,400\] seconds"),
    ("deviation", "window_s", -86400, r"in \[60, "),
    ("deviation", "offset_s", math.inf, "finite"),
    ("deviation", "kurtosis_windows_s", [86400.0, 0.0], r"in \[60, "),
    ("deviation", "max_interp_gap_s", -1, r"in \[0, "),
    ("deviation", "factor_lat", 0, r"in \(0, "),
    ("deviation", "factor_lon", -1.49, r"in \(0, "),
    ("deviation", "factor_course", 0.0, r"in \(0, "),
    ("deviation", "probability", 1.0, r"\[0.5, 1\)"),
    ("deviation", "probability", 0.3, r"\[0.5, 1\)"),
    ("deviation", "apriori", {"ins4": {"lat_m": 1.0}}, "unit must be one of"),
    ("deviation", "apriori", {"ins1": {"lat": 1.0}}, r"unknown key\(s\): lat"),
    ("deviation", "apriori", {"ins1": {"lat_m": 0}}, r"in \(0, "),
    ("deviation", "confidence", 1.5, r"\[0.5, 1\)"),
    ("deviation", "correlation_time_s", -1.0, r"in \[0, "),
    ("deviation", "min_kurtosis_samples", 0, r"in \[1, "),
    ("deviation", "kurtosis_tol", -0.05, r"in \[0, "),
    ("deviation", "hat_confidence", 0.4, r"\[0.5, 1\)"),
    ("deviation", "hat_draws", 99, r"in \[100, "),
    ("deviation", "seed", -1, r"in \[0, "),
    ("deviation", "velocity_min_gap_s", -0.1, r"in \[0, "),
    ("faults", "max_speed_kn", 0, r"in \(0, "),
    ("faults", "jump_min_m", -500.0, r"in \(0, "),
    ("faults", "frozen_min_s", 0, r"in \(0, "),
    ("faults", "stuck_min_s", -1, r"in \(0, "),
    ("faults", "min_records", 0, r"in \[1, "),
    ("faults", "min_records", 2.5, "integer"),
    ("faults", "moving_min_kn", 0, r"in \(0, "),
    ("faults", "turn_min_deg", 0, r"in \(0, "),
    ("faults", "max_rot_deg_per_min", math.inf, "finite"),
    ("integrity", "false_alarm", 0.5, r"\(0, 0.5\)"),
    ("integrity", "false_alarm", 0.0, r"\(0, 0.5\)"),
    *[
        (
            "integrity",
            f.name,
            0.0,
            r"in \[0.1, " if f.name == "consistency_interval_s" else r"in \(0, ",
        )
        for f in fields(C.IntegrityConfig)
        if f.name != "false_alarm"
    ],
]


@pytest.mark.parametrize(
    "section,key,value,words", RANGE_CASES, ids=[f"{s}.{k}-{v!r}" for s, k, v, _ in RANGE_CASES]
)
def test_out_of_range_is_a_config_error_naming_the_key(section, key, value, words):
    with pytest.raises(ConfigError, match=words) as e:
        config_from_dict({section: {key: value}})
    assert _names_the_key(str(e.value), section, key), str(e.value)
    assert "\n" not in str(e.value)


def test_every_numeric_key_has_a_range_case():
    """Each number has at least one out-of-range case above (a new key gets one)."""
    covered = {(s, k) for s, k, _, _ in RANGE_CASES}
    for section, cls in SECTIONS.items():
        for name, tp in _hints(cls).items():
            if (
                tp in (float, int, float | None, tuple[float, ...], dict[str, float], ErrorSource)
                and C._RULES[cls][name].range is not C.FINITE
            ):
                if tp is ErrorSource and name not in (
                    "compass_bias_deg",
                    "compass_noise_deg",
                    "log_noise_kn",
                ):
                    continue  # one schema for all error sources: three cases stand for them
                assert (section, name) in covered, f"{section}.{name}"


ACCEPTED = [
    ({"ingest": {"gap_s": 60}}, lambda c: c.ingest.gap_s == 60.0 and type(c.ingest.gap_s) is float),
    ({"ingest": {"backstep_tolerance_s": 0}}, lambda c: c.ingest.backstep_tolerance_s == 0.0),
    ({"ingest": {"date": "2026-03-01"}}, lambda c: c.ingest.date == "2026-03-01"),
    ({"ingest": {"date": dt.date(2026, 3, 1)}}, lambda c: c.ingest.date == "2026-03-01"),
    (
        {"ingest": {"max_line_bytes": 1e5}},
        lambda c: c.ingest.max_line_bytes == 100000 and type(c.ingest.max_line_bytes) is int,
    ),
    (
        {"ingest": {"sources": {"INS1": "ins1", "HE": "compass"}}},
        lambda c: c.ingest.sources == {"INS1": "ins1", "HE": "compass"},
    ),
    (
        {"ingest": {"quantities": {"Speed (kn)": "stw_kn"}}},
        lambda c: c.ingest.quantities == {"Speed (kn)": "stw_kn"},
    ),
    *[
        ({"dead_reckoning": {"reset": r}}, lambda c, r=r: c.dead_reckoning.reset == r)
        for r in ("auto", "AUTO", "watch", "never", "1h", "4h", "30min", "90s", "0.5h", "1d")
    ],
    (
        {"dead_reckoning": {"fix_role": "ins_mean"}},
        lambda c: c.dead_reckoning.fix_role == "ins_mean",
    ),
    ({"dead_reckoning": {"variation_deg": -3}}, lambda c: c.dead_reckoning.variation_deg == -3.0),
    (
        {"dead_reckoning": {"deviation_table": {"0": 1.5, "90": -0.5, "360": 1.5}}},
        lambda c: c.dead_reckoning.deviation_table["90"] == -0.5,
    ),
    (
        {"dead_reckoning": {"log_scale": 0}},
        lambda c: c.dead_reckoning.log_scale == ErrorSource(0.0),
    ),
    (
        {"dead_reckoning": {"compass_noise_deg": {"sigma": 0.3, "tau_s": 0}}},
        lambda c: c.dead_reckoning.compass_noise_deg == ErrorSource(0.3, 0.0),
    ),
    (
        {"dead_reckoning": {"compass_noise_deg": {"sigma": 0.3, "tau_s": "inf"}}},
        lambda c: c.dead_reckoning.compass_noise_deg == ErrorSource(0.3, math.inf),
    ),
    (
        {"dead_reckoning": {"compass_noise_deg": {"sigma": 0.3, "tau_s": math.inf}}},
        lambda c: c.dead_reckoning.compass_noise_deg == ErrorSource(0.3, math.inf),
    ),
    (
        {"dead_reckoning": {"compass_noise_deg": {"sigma": 1}}},
        lambda c: c.dead_reckoning.compass_noise_deg == ErrorSource(1.0, math.inf),
    ),
    (
        {"deviation": {"kurtosis_windows_s": [86400, 172800]}},
        lambda c: c.deviation.kurtosis_windows_s == (86400.0, 172800.0),
    ),
    ({"deviation": {"kurtosis_windows_s": []}}, lambda c: c.deviation.kurtosis_windows_s == ()),
    ({"deviation": {"offset_s": -1800}}, lambda c: c.deviation.offset_s == -1800.0),
    ({"deviation": {"correlation_time_s": 0}}, lambda c: c.deviation.correlation_time_s == 0.0),
    (
        {"deviation": {"apriori": {"ins1": {"lat_m": 300, "lon_m": 400.0, "course_deg": 0.1}}}},
        lambda c: (
            c.deviation.apriori == {"ins1": {"lat_m": 300.0, "lon_m": 400.0, "course_deg": 0.1}}
        ),
    ),
    (
        {"deviation": {"hat_draws": 100, "seed": 0, "min_kurtosis_samples": 1}},
        lambda c: c.deviation.hat_draws == 100,
    ),
    ({"faults": {"exclude": True, "min_records": 3.0}}, lambda c: c.faults.min_records == 3),
    ({"integrity": {"false_alarm": 0.01}}, lambda c: c.integrity.false_alarm == 0.01),
]


@pytest.mark.parametrize("doc,ok", ACCEPTED, ids=[repr(d) for d, _ in ACCEPTED])
def test_valid_values_are_accepted_and_converted(doc, ok):
    assert ok(config_from_dict(doc))


# ----------------------------------------------------------- defaults, example, owners


def test_the_defaults_pass_the_validator_unchanged():
    c = Config()
    v = validate(c)
    assert v == c
    for name in SECTIONS:
        for f in fields(getattr(c, name)):
            assert type(getattr(getattr(v, name), f.name)) is type(
                getattr(getattr(c, name), f.name)
            )


def test_the_example_config_loads_and_its_examples_are_valid(tmp_path):
    example = load_config(EXAMPLE)  # the DR sigmas are rounded there: see test_config
    assert validate(example) == example
    for name in ("ingest", "deviation", "faults", "integrity"):
        assert getattr(example, name) == getattr(Config(), name), name
    # the commented-out examples (source roles, a deviation table, a priori RMS, date ...)
    # are valid too once uncommented
    lines, n = [], 0
    for line in EXAMPLE.read_text().splitlines():
        m = re.match(r"^# ?(\S.*)$", line)
        if m and "=" in m.group(1):
            try:
                tomllib.loads(m.group(1))
            except tomllib.TOMLDecodeError:
                pass
            else:
                line, n = m.group(1), n + 1
        lines.append(line)
    assert n >= 10
    p = tmp_path / "examples.toml"
    p.write_text("\n".join(lines) + "\n")
    c = load_config(p)
    assert c.ingest.sources["GP"] == "gnss" and c.ingest.date == "2026-03-01"
    assert c.dead_reckoning.deviation_table == {"0": 1.5, "90": -0.5, "180": -1.0, "270": 0.5}
    assert c.deviation.apriori["ins1"]["lon_m"] == 400.0


def test_overrides_are_checked_too():
    with pytest.raises(ConfigError, match=r"^\[ingest\] gap_s = 'x'"):
        with_overrides(Config(), "ingest", gap_s="x")
    with pytest.raises(ConfigError, match=r"^\[dead_reckoning\] reset = 'hourly'"):
        with_overrides(Config(), "dead_reckoning", reset="hourly")


def test_apriori_channels_are_the_deviation_analysis_channels():
    from dracc.core.vocabulary import CHANNEL_KEYS

    assert set(C._APRIORI_KEYS) == set(CHANNEL_KEYS.values()) == set(CHANNEL_KEYS.values())


# ------------------------------------------------------------------------------- CLI

CLI_CASES = [
    ('[ingest]\nstrict = "no"\n', "[ingest] strict"),
    ('[ingest]\ngap_s = "sixty"\n', "[ingest] gap_s"),
    ('[ingest]\nsources = "INS1"\n', "[ingest] sources"),
    (
        '[dead_reckoning]\ncompass_noise_deg = { sigma = 0.2, tau_s = "two minutes" }\n',
        "[dead_reckoning.compass_noise_deg] tau_s",
    ),
    ("[dead_reckoning.deviation_table]\nnorth = 1.0\n", "[dead_reckoning.deviation_table] north"),
    ("[deviation]\nhat_draws = 1000.5\n", "[deviation] hat_draws"),
    ("[faults]\nexclude = 1\n", "[faults] exclude"),
    ("[dead_reckoning]\nreset = 3600\n", "[dead_reckoning] reset"),
]


@pytest.mark.skipif(not SAMPLE.exists(), reason="sample_logs not generated")
@pytest.mark.parametrize("text,words", CLI_CASES, ids=[w for _, w in CLI_CASES])
def test_cli_bad_config_is_exit_4_in_one_line(run_cli, tmp_path, text, words):
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    code, out, err = run_cli("analyze", "--config", bad, SAMPLE)
    assert code == ExitCode.CONFIG, err
    assert err.startswith("error: ") and words in err, err
    assert err.strip().count("\n") == 0 and "Traceback" not in err and out == ""


@pytest.mark.skipif(not SAMPLE.exists(), reason="sample_logs not generated")
def test_cli_bad_config_in_a_real_process(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[ingest]\nstrict = "no"\n')
    r = subprocess.run(
        [sys.executable, "-m", "dracc", "analyze", "--config", str(bad), str(SAMPLE)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == ExitCode.CONFIG, r.stderr
    assert r.stderr.strip() == "error: [ingest] strict = 'no': expected true or false, got a string"
    assert r.stdout == ""


def test_dataclass_built_in_python_is_checked_by_validate():
    bad = Config(dead_reckoning=DeadReckoningConfig(max_gap_s="30"))  # type: ignore[arg-type]
    with pytest.raises(
        ConfigError, match=r"^\[dead_reckoning\] max_gap_s = '30': expected a number"
    ):
        validate(bad)
