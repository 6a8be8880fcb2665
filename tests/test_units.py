"""dracc.core.units: edge conversions and the JSON-ready float."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dracc.core import units
from dracc.core.numbers import finite_or_none


def test_knots_exact():
    assert units.kn_to_mps(3600.0) == pytest.approx(1852.0, abs=1e-9)
    assert units.mps_to_kn(1852.0 / 3600.0) == pytest.approx(1.0, abs=1e-15)


@pytest.mark.parametrize(
    "x, want",
    [
        (None, None),
        (math.nan, None),
        (math.inf, None),
        (-math.inf, None),
        (np.float32("nan"), None),
        (np.float64(2.5), 2.5),
        (3, 3.0),
        (-0.0, -0.0),
        (np.int64(7), 7.0),
    ],
)
def test_finite_or_none(x, want):
    got = finite_or_none(x)
    assert got == want
    assert got is None or type(got) is float


def test_jsonable_keeps_types_and_drops_nan():
    from pathlib import Path

    from dracc.core.numbers import jsonable

    got = jsonable(
        {1: (np.int64(3), np.float32(0.5), np.bool_(True)), "x": [math.nan, -math.inf, "a"]}
    )
    assert got == {"1": [3, 0.5, True], "x": [None, None, "a"]}
    assert type(got["1"][0]) is int and type(got["1"][2]) is bool
    assert jsonable(Path("a/b")) == "a/b" and jsonable(None) is None
