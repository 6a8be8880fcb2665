import math

import pytest

from dracc.core.config import Config, config_from_dict, load_config, with_overrides
from dracc.core.errors import ConfigError


def test_defaults_from_imo_standards():
    c = Config()
    assert c.dead_reckoning.compass_bias_deg.sigma == pytest.approx(0.75 / 1.96)
    assert c.dead_reckoning.compass_bias_deg.tau_s == math.inf
    assert c.deviation.factor_lat == 1.32 and c.deviation.factor_lon == 1.49


def test_error_source_forms():
    c = config_from_dict(
        {"dead_reckoning": {"log_scale": 0.01, "compass_noise_deg": {"sigma": 0.3, "tau_s": 200}}}
    )
    assert c.dead_reckoning.log_scale.sigma == 0.01 and c.dead_reckoning.log_scale.tau_s == math.inf
    assert c.dead_reckoning.compass_noise_deg.tau_s == 200


@pytest.mark.parametrize(
    "doc,msg",
    [
        ({"ingest": {"strikt": True}}, "unknown key"),
        ({"nonsense": {}}, "unknown section"),
        ({"ingest": {"sources": {"IN": "ins4"}}}, "role must be one of"),
        ({"deviation": {"probability": 1.5}}, "probability"),
        ({"dead_reckoning": {"compass_bias_deg": "big"}}, "sigma"),
    ],
)
def test_invalid_config_is_named(doc, msg):
    with pytest.raises(ConfigError, match=msg):
        config_from_dict(doc)


def test_load_config_errors(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[ingest\nstrict = true")
    with pytest.raises(ConfigError, match="invalid TOML"):
        load_config(bad)
    good = tmp_path / "good.toml"
    good.write_text('[ingest]\nstrict = true\n[ingest.sources]\nINS2 = "ins2"\n')
    assert load_config(good).ingest.sources == {"INS2": "ins2"}


def test_overrides():
    c = with_overrides(Config(), "deviation", interval_s=7200.0, window_s=None)
    assert c.deviation.interval_s == 7200.0 and c.deviation.window_s == 86400.0


def test_example_config_loads_and_states_the_defaults():
    from pathlib import Path

    example = load_config(Path(__file__).parents[1] / "docs" / "dracc.example.toml")
    d, e = Config().dead_reckoning, example.dead_reckoning
    for name in (
        "compass_bias_deg",
        "compass_noise_deg",
        "log_scale",
        "log_bias_kn",
        "log_noise_kn",
        "current_kn",
        "leeway_deg",
    ):
        assert getattr(e, name).sigma == pytest.approx(getattr(d, name).sigma, rel=2e-3), name
        assert getattr(e, name).tau_s == getattr(d, name).tau_s, name
    for name in (
        "learn",
        "reset",
        "fix_role",
        "max_gap_s",
        "epoch_interval_s",
        "variation_deg",
        "deviation_table",
        "fix_sigma_m",
    ):
        assert getattr(e, name) == getattr(d, name), name
    assert example.deviation == Config().deviation
    assert example.ingest == Config().ingest
