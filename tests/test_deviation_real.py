"""INS-deviation statistics on real logs (../shared/data/real/openrvdas, RVIB N. B. Palmer).

No real log holds an INS triple; the Palmer's two GNSS receivers (gp02: GLL, seap: Seapath
GGA + HDT) and its gyro (gyr1: HEHDT) recorded the same 10 minutes in separate files.
Taken as two "units" they exercise the two-unit case, sampling of real, irregular
readings, missing instants (gp02 runs on after seap stops), and heading on the circle;
the deviations are checked against an independent GeographicLib distance.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import dracc.ingest as ingest
from dracc.core.config import DeviationConfig, IngestConfig
from dracc.math.deviation import analyse_deviations, sample_unit, unit_series_from_frames

geographiclib = pytest.importorskip("geographiclib.geodesic")


@pytest.fixture(scope="module")
def palmer(real_dir):
    d = real_dir / "openrvdas"
    frames = {
        name: ingest.read_file(d / f"NBP1406_{name}-2014-08-01", IngestConfig()).frames
        for name in ("gp02", "seap", "gyr1")
    }
    ins1 = unit_series_from_frames(frames["gp02"].get("position"), frames["gyr1"].get("heading"))
    ins2 = unit_series_from_frames(frames["seap"].get("position"), frames["seap"].get("heading"))
    return {"ins1": ins1, "ins2": ins2}


def test_two_real_receivers_as_two_units(palmer):
    cfg = DeviationConfig(interval_s=60.0, window_s=3600.0, max_interp_gap_s=5.0)
    res = analyse_deviations(palmer, cfg)
    assert res.channels["lat"].mode == "two" and res.factors["lat"] == pytest.approx(math.sqrt(2))
    assert any("only two units (ins1, ins2)" in m for m in res.messages)
    # gp02 runs 00:00:00.3-00:27:46, seap 00:00:00.7-00:11:54: instants 00:01..00:11
    # have both (00:00 precedes both units' data: not an instant; no reading is held)
    assert res.time_ns[0] == 1406851260 * 10**9
    lat1 = res.samples["ins1"]["lat"]
    both = ~np.isnan(lat1)
    assert both.sum() == 11 and np.all(both[:11])
    assert res.missing["ins2"]["lat"] == len(res.time_ns) - 11
    # the instants after seap's end are skipped, with their reason
    assert res.skipped["lat"] == {"outside unit span": len(res.time_ns) - 11, "gap too long": 0}
    # deviations from the mean of two are half the difference: opposite and equal
    np.testing.assert_allclose(res.samples["ins2"]["lat"][both], -lat1[both], atol=1e-9)
    # independent check: GeographicLib distance between the two receivers' positions at
    # the instants (interpolated the same way) is twice the deviation vector's length
    geod = geographiclib.Geodesic.WGS84
    s1 = sample_unit(palmer["ins1"], res.time_ns, cfg.max_interp_gap_s)
    s2 = sample_unit(palmer["ins2"], res.time_ns, cfg.max_interp_gap_s)
    for i in np.flatnonzero(both):
        dist = geod.Inverse(
            *np.degrees([s1.lat_rad[i], s1.lon_rad[i], s2.lat_rad[i], s2.lon_rad[i]])
        )["s12"]
        dev = math.hypot(lat1[i], res.samples["ins1"]["lon"][i])
        assert 2 * dev == pytest.approx(dist, rel=1e-3, abs=0.01)
    # two receivers on one ship: metres to tens of metres apart, not kilometres
    stats = res.whole.units["ins1"].channels
    assert 0.1 < stats["lat"].m_u < 100 and 0.1 < stats["lon"].m_u < 100
    # heading: the gyro against the Seapath, on the circle, within a few degrees
    crs = res.samples["ins1"]["course"]
    assert np.sum(~np.isnan(crs)) >= 11 and np.nanmax(np.abs(crs)) < 5.0
    assert res.whole.units["ins1"].hat == {}
    # ten minutes against a 5 h correlation time: no limiting error, and the reason given;
    # the receivers' offset is nearly constant: (K6) falls below -2, noted
    lat = stats["lat"]
    assert lat.n_eff < 1 and math.isnan(lat.limit) and math.isnan(lat.k_hm)
    assert any("fewer than one independent sample" in n for n in lat.notes)
    assert lat.kurtosis < -2 and lat.k_pie == 1.0
    # with the samples taken as independent (correlation time 0) the limit exists
    res0 = analyse_deviations(
        palmer,
        DeviationConfig(
            interval_s=60.0, window_s=3600.0, max_interp_gap_s=5.0, correlation_time_s=0.0
        ),
    )
    lat0 = res0.whole.units["ins1"].channels["lat"]
    assert lat0.n_eff == 11 and lat0.limit == pytest.approx(lat0.k_hm * lat0.m_y)


def test_a_unit_ending_early_invents_no_deviation(palmer):
    """seap stops at 00:11:54, gp02 runs on to 00:27: with the default 120 s gap no
    instant outside the two units' common span gets a deviation (holding seap's last fix
    for 00:12 and 00:13 invented deviations of tens of metres), and every deviation is
    half the receivers' true disagreement at that instant, never more."""
    res = analyse_deviations(palmer, DeviationConfig(interval_s=60.0, window_s=3600.0))
    spans = [u.span_ns() for u in palmer.values()]
    pos_spans = [(int(u.pos_time_ns.min()), int(u.pos_time_ns.max())) for u in palmer.values()]
    lo, hi = max(s[0] for s in pos_spans), min(s[1] for s in pos_spans)
    used = ~np.isnan(res.samples["ins1"]["lat"])
    assert used.sum() == 11
    assert np.all((res.time_ns[used] >= lo) & (res.time_ns[used] <= hi))
    assert res.skipped["lat"]["outside unit span"] >= 2  # 00:12 and 00:13 at least
    assert any("outside unit span" in m for m in res.messages)
    assert all(s is not None for s in spans)
    # the true disagreement: distance between the receivers' fixes nearest in time
    geod = geographiclib.Geodesic.WGS84
    a, b = palmer["ins1"], palmer["ins2"]
    for t, n, e in zip(
        res.time_ns[used],
        res.samples["ins1"]["lat"][used],
        res.samples["ins1"]["lon"][used],
        strict=True,
    ):
        ia = np.argsort(np.abs(a.pos_time_ns - t))[:2]
        ib = np.argsort(np.abs(b.pos_time_ns - t))[:2]
        dist = max(
            geod.Inverse(*np.degrees([a.lat_rad[i], a.lon_rad[i], b.lat_rad[k], b.lon_rad[k]]))[
                "s12"
            ]
            for i in ia
            for k in ib
        )
        assert 2 * math.hypot(n, e) <= dist + 0.05
