"""Issue 6: the same voyage as NMEA (TAG blocks, prefixes), CSV (long, wide) and MCAP gives
the same analysis, to rounding."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import SAMPLES

from dracc.core.config import Config
from dracc.pipeline.analysis import analyse
from dracc.pipeline.selection import dedupe_sorted as _dedupe_sorted
from dracc.report.json_report import to_dict

FILES = [
    "voyage_tag.nmea",
    "voyage_prefix.nmea",
    "voyage_long.csv",
    "voyage_wide.csv",
    "voyage.mcap",
]


def _figures(d: dict) -> dict[str, float]:
    """The numbers a navigator reads, flattened."""
    out = {}
    for unit, chans in d["deviation"]["units"].items():
        for ch in ("lat", "lon", "course"):
            for key in ("n", "m_u", "m_y", "kurtosis"):
                out[f"{unit}.{ch}.{key}"] = chans[ch][key]
        out[f"{unit}.r_lat_lon"] = chans["r_lat_lon"]
    dr = d["dead_reckoning"]
    out["dr.containment_2m"] = dr["containment_2m"]
    out["dr.error_over_m_rms"] = dr["error_over_m_rms"]
    out["dr.max_2m"] = max(e["radius_2m_m"] for e in dr["epochs"])
    out["cal.compass_error_deg"] = d["calibration"]["compass_error_deg"]["value"]
    out["cal.log_scale"] = d["calibration"]["log_scale"]["value"]
    out["current.set_deg"] = d["current"]["set_deg"]["value"]
    out["current.drift_kn"] = d["current"]["drift_kn"]["value"]
    return out


@pytest.fixture(scope="module")
def analyses():
    return {f: _figures(to_dict(analyse([SAMPLES / f], Config()))) for f in FILES}


@pytest.mark.parametrize("name", FILES[1:])
def test_same_analysis_as_the_tag_block_log(analyses, name):
    ref, got = analyses[FILES[0]], analyses[name]
    assert got.keys() == ref.keys()
    for key, value in ref.items():
        # NMEA fields are written at their precision (minutes to 6 decimals, degrees and
        # knots to 3): the figures agree to that rounding
        assert got[key] == pytest.approx(value, rel=1e-6, abs=1e-6), key


def test_regression_simultaneous_log_sentences_complement_each_other():
    """A long CSV put a VBW-like record (with the transverse speed) before the VHW of the
    same instant; keeping the last record dropped the leeway and changed the DR."""
    t = np.array([0, 0, 10, 10], dtype=np.int64)
    stw = np.array([6.0, 6.0, 6.1, 6.1])
    transverse = np.array([0.05, np.nan, np.nan, 0.06])
    tt, v, vy = _dedupe_sorted(t, stw, transverse)
    assert tt.tolist() == [0, 10] and v.tolist() == [6.0, 6.1]
    assert vy.tolist() == [0.05, 0.06]
    _, only_nan = _dedupe_sorted(np.array([5, 5]), np.array([math.nan, math.nan]))
    assert np.isnan(only_nan).all()
