"""The fleet ranking's statistics (dracc.math.ranking) and its table
(dracc.pipeline.fleet.ranking), on hand values and on randomised synthetic fleets."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from dracc.core.config import Config
from dracc.core.errors import ConfigError
from dracc.math.ranking import bh_qvalues, change_point, difference_scale, peer_scores
from dracc.pipeline.fleet.ranking import (
    RANKING_COLUMNS,
    RankingConfig,
    measures_frame,
    rank_fleet,
    ranking_config,
)

# ---------------------------------------------------------------- Benjamini-Hochberg


def test_bh_qvalues_hand_example():
    # m = 5: q_(i) = min_{j>=i} p_(j) 5 / j
    p = [0.01, 0.04, 0.03, 0.5, np.nan, 0.02]
    q = bh_qvalues(p)
    # sorted 0.01 0.02 0.03 0.04 0.5 -> 0.05 0.05 0.05 0.05 0.5
    np.testing.assert_allclose(q[[0, 5, 2, 1, 3]], [0.05, 0.05, 0.05, 0.05, 0.5])
    assert math.isnan(q[4])


def test_bh_qvalues_equal_the_step_up_rule():
    """q_i < alpha exactly for the hypotheses the BH step-up procedure rejects."""
    rng = np.random.default_rng(3)
    for _ in range(50):
        p = np.concatenate([rng.uniform(size=40), rng.uniform(0, 0.003, size=5)])
        alpha = 0.05
        order = np.sort(p)
        below = np.flatnonzero(order <= alpha * np.arange(1, len(p) + 1) / len(p))
        k = below[-1] + 1 if len(below) else 0
        rejected = p <= (order[k - 1] if k else -1)
        assert np.array_equal(bh_qvalues(p) <= alpha, rejected)


# ------------------------------------------------------------------- peer scores


def test_peer_score_is_the_prediction_t_test_with_equal_units():
    """Units with no own error: (x - mean) / (s sqrt(1 + 1/m)) against t with m - 1."""
    x = np.array([1.0, 1.3, 0.8, 1.1, 0.9, 2.4])
    ps = peer_scores(x, np.zeros(6), np.zeros(6), direction=+1, resolution=1e-6)
    peers = x[:5]
    t = (x[5] - peers.mean()) / (peers.std(ddof=1) * math.sqrt(1 + 1 / 5))
    assert ps.z[5] == pytest.approx(t, rel=1e-12)
    assert ps.df[5] == pytest.approx(4.0)
    assert ps.p[5] == pytest.approx(stats.t.sf(t, 4), rel=1e-9)
    assert ps.peers[5] == 5


def test_another_bad_unit_among_the_peers_does_not_hide_one():
    x = np.array([1.0, 1.02, 0.98, 1.01, 0.99, 1.03, 3.0, 3.1])
    ps = peer_scores(x, np.full(8, 0.02), np.zeros(8), direction=+1, resolution=1e-3)
    assert ps.peers[6] == 6  # unit 7 (3.1) is left out of unit 6's peers
    assert ps.p[6] < 1e-6 and ps.p[7] < 1e-6


def test_peer_scores_keep_groups_apart_and_need_peers():
    x = np.array([1.0, 1.1, 0.9, 5.0, 5.1, 4.9, 5.2])
    g = np.array(["a", "a", "a", "b", "b", "b", "b"])
    ps = peer_scores(x, np.zeros(7), g, direction=0, resolution=0.01)
    assert np.all(np.isnan(ps.p[:3]))  # two peers only
    assert np.all(ps.p[3:] > 0.05)  # b's units agree with each other


@pytest.mark.slow
def test_peer_p_values_are_not_anti_conservative_monte_carlo():
    """Null fleets (random size, spread and own errors): P(p < alpha) <= alpha within the
    binomial 99.9 % bound, at alpha 0.05 and 0.005."""
    rng = np.random.default_rng(11)
    ps_all = []
    for _ in range(400):
        m = int(rng.integers(5, 40))
        tau = rng.uniform(0.0, 0.5)
        se = rng.uniform(0.05, 0.4, size=m)
        x = rng.normal(0, tau, size=m) + rng.normal(0, se)
        ps = peer_scores(x, se, np.zeros(m), direction=+1, resolution=0.01)
        ps_all.append(ps.p[np.isfinite(ps.p)])
    p = np.concatenate(ps_all)
    for alpha in (0.05, 0.005):
        bound = stats.binom.ppf(0.999, len(p), alpha) / len(p)
        assert (p < alpha).mean() <= bound, (alpha, (p < alpha).mean())


# ------------------------------------------------------------------- change point


def test_change_point_hand_series():
    x = np.array([0.0, 0.1, -0.1, 0.0, 1.0, 1.1])
    cp = change_point(x, np.full(6, 0.1), direction=+1)
    assert cp.index == 4 and cp.splits == 4
    # z = (1.05 - 0) / (0.1 sqrt(1/2 + 1/4))
    assert cp.z == pytest.approx(1.05 / (0.1 * math.sqrt(0.75)))
    assert cp.p == pytest.approx(4 * stats.norm.sf(cp.z))
    assert change_point(x[::-1], np.full(6, 0.1), direction=+1).p > 0.5  # it got better


@pytest.mark.slow
def test_change_p_values_are_conservative_monte_carlo():
    rng = np.random.default_rng(5)
    p = []
    for _ in range(3000):
        n = int(rng.integers(3, 30))
        se = rng.uniform(0.5, 2.0, size=n)
        p.append(change_point(rng.normal(0, se), se, direction=+1).p)
    p = np.array(p)
    for alpha in (0.05, 0.005):
        bound = stats.binom.ppf(0.999, len(p), alpha) / len(p)
        assert (p < alpha).mean() <= bound


def test_difference_scale_ignores_level_shifts():
    rng = np.random.default_rng(2)
    series = [rng.normal(0, 0.3, 40) + np.where(np.arange(40) > 20, 5.0, 0.0) for _ in range(20)]
    s, n = difference_scale(series)
    assert n == 20 * 39 and s == pytest.approx(0.3, rel=0.1)


# ------------------------------------------------------------- the fleet ranking


def synthetic_fleet(seed: int, vessels: int, nights: int, faults: bool, noise: float = 0.12):
    """Nightly measures with known truth: log-normal INS RMS per INS position, log scale
    around 2 % (sigma 0.6), constant latency; faults: V0 INS2 x3, V1 INS1 x2 over the last
    two nights, V2 log 6 %."""
    rng = np.random.default_rng(seed)
    base = {"ins1": 230.0, "ins2": 600.0, "ins3": 300.0}
    out = []
    for v in range(vessels):
        for d in range(nights):
            rows = []
            for unit, b in base.items():
                f = 1.0
                if faults and v == 0 and unit == "ins2":
                    f = 3.0
                if faults and v == 1 and unit == "ins1" and d >= nights - 2:
                    f = 2.0
                for q in ("lat_m_y", "lon_m_y"):
                    rows.append(
                        {
                            "unit": unit,
                            "quantity": q,
                            "measure_unit": "m",
                            "value": b * f * math.exp(rng.normal(0, noise)),
                            "sigma": None,
                            "dof": 5.0,
                            "n": 25,
                            "method": "reference",
                        }
                    )
            scale = 6.0 if faults and v == 2 else 2.0
            rows.append(
                {
                    "unit": "log",
                    "quantity": "log_scale",
                    "measure_unit": "%",
                    "value": scale + rng.normal(0, 0.6),
                    "sigma": 0.6,
                    "dof": None,
                    "n": 100,
                    "method": "calibration",
                }
            )
            rows.append(
                {
                    "unit": "gnss",
                    "quantity": "latency",
                    "measure_unit": "s",
                    "value": 0.0,
                    "sigma": None,
                    "dof": None,
                    "n": 100,
                    "method": "integrity",
                }
            )
            out.append(
                (
                    f"V{v}",
                    f"2026-03-{d + 1:02d}",
                    {"position": {"lat_deg": 54, "lon_deg": 18}, "rows": rows},
                )
            )
    return measures_frame(out)


def test_ranking_finds_the_seeded_faults_and_names_the_change():
    r = rank_fleet(synthetic_fleet(1, vessels=8, nights=7, faults=True))
    assert list(r.columns) == list(RANKING_COLUMNS)
    found = r[r.q_value < 0.05]
    assert set(zip(found.vessel, found.ins_unit, strict=True)) == {
        ("V0", "ins2"),
        ("V1", "ins1"),
        ("V2", "log"),
    }
    assert list(r["rank"]) == list(range(1, len(r) + 1))
    v1 = found[found.vessel == "V1"]
    assert (v1.since.astype(str) == "2026-03-06").all()
    ev = json.loads(v1.iloc[0].evidence)
    assert ev["change"]["night"] == "2026-03-06" and len(ev["nights"]) == 7
    assert found[found.vessel == "V0"].since.isna().all()  # worse from the start, no change
    # latency is 0 s everywhere: not ranked at all (it would only dilute the FDR)
    assert "latency" not in set(r.quantity)


@pytest.mark.slow
def test_false_discoveries_are_controlled_over_null_fleets():
    """No fault anywhere: a fleet with any discovery is a false one (BH controls that
    family-wise at the FDR level under the complete null): at most 5 % plus the binomial
    99 % bound, over randomised fleets."""
    fleets = 60
    bad = 0
    for s in range(fleets):
        m = rank_fleet(
            synthetic_fleet(
                1000 + s,
                vessels=5 + s % 8,
                nights=3 + s % 6,
                faults=False,
                noise=0.05 + 0.3 * (s % 5) / 4,
            )
        )
        bad += int((m.q_value < 0.05).any())
    assert bad <= stats.binom.ppf(0.99, fleets, 0.05)


def test_peer_groups_follow_the_configured_models():
    f = synthetic_fleet(4, vessels=6, nights=3, faults=False)
    f.loc[(f.vessel == "V5") & (f.unit == "ins1"), "value"] *= 2.6  # a worse model fitted...
    r = rank_fleet(f)
    assert (r[(r.vessel == "V5") & (r.ins_unit == "ins1")].q_value < 0.05).any()
    # ...unless V5's INS1 is said to be another model: then it has no peers to fail against
    cfg = Config()
    cfg.extra["fleet"] = {"ranking": {"models": {"V5/ins1": "other"}}}
    r = rank_fleet(f, ranking_config(cfg))
    row = r[(r.vessel == "V5") & (r.ins_unit == "ins1")]
    assert set(row.peer_group) == {"other"} and row.peer_p.isna().all()


@pytest.mark.parametrize(
    "table",
    [
        {"fdr": 0},
        {"fdr": "x"},
        {"peer_nights": 0},
        {"area_km": -5},
        {"models": {"a": 1}},
        {"x": 1},
    ],
)
def test_ranking_config_errors(table):
    cfg = Config()
    cfg.extra["fleet"] = {"ranking": table}
    with pytest.raises(ConfigError, match=r"\[fleet.ranking\]"):
        ranking_config(cfg)


def test_empty_measures_give_an_empty_typed_ranking():
    r = rank_fleet(measures_frame([]), RankingConfig())
    assert r.empty and list(r.columns) == list(RANKING_COLUMNS)
    assert isinstance(r, pd.DataFrame)


def test_terminal_and_page_lead_with_the_discoveries():
    from dracc.pipeline.fleet.tables import FleetResult, fleet_table, fleet_trends
    from dracc.report.fleet_html import fleet_html
    from dracc.report.terminal import fleet_text

    r = rank_fleet(synthetic_fleet(1, vessels=8, nights=7, faults=True))
    table = fleet_table([], {}, {}, {})
    res = FleetResult(table, fleet_trends(table), (), 0, 0, r)
    text = fleet_text(res, width=100)
    assert text.startswith("fleet ranking: 5 of")
    first = text.splitlines()[2].split()
    assert first[:2] == ["1", str(r.iloc[0].vessel)]
    page = fleet_html(res)
    assert page.split("<h2>")[1].startswith("Ranking")  # the page leads with the ranked list
    for k in range(1, 6):  # each discovery links to its evidence, open
        assert f"href='#ev-{k}'" in page and f"<details id='ev-{k}' open>" in page


def test_logs_are_compared_within_their_sea_area_or_with_the_fleet():
    """Eight logs near 55N 10E and four near 40S 60W (8000+ km apart, within 1000 km among
    themselves); the Atlantic logs read 4 % (an area bias), the Baltic 2 %.  Each is
    compared with its own area's logs; a log alone in its area with the fleet's."""
    rng = np.random.default_rng(9)
    nights = []
    places = [(55.0 + 0.3 * k, 10.0 + 0.5 * k, 2.0) for k in range(8)]
    places += [(-40.0 - 0.4 * k, -60.0 + 0.6 * k, 4.0) for k in range(4)]
    places += [(10.0, 100.0, 2.0)]  # alone in the Indian Ocean
    for v, (lat, lon, scale) in enumerate(places):
        for d in range(3):
            row = {
                "unit": "log",
                "quantity": "log_scale",
                "measure_unit": "%",
                "value": scale + rng.normal(0, 0.2),
                "sigma": 0.2,
                "dof": None,
                "n": 100,
                "method": "calibration",
            }
            pos = {"lat_deg": lat, "lon_deg": lon}
            nights.append((f"V{v:02d}", f"2026-03-0{d + 1}", {"position": pos, "rows": [row]}))
    r = rank_fleet(measures_frame(nights)).set_index("vessel")
    assert (r.q_value >= 0.05).all()  # the Atlantic's 4 % is its area's, not an outlier
    assert (r.loc[[f"V{v:02d}" for v in range(8)], "peers"] == 7).all()
    assert (r.loc[[f"V{v:02d}" for v in range(8, 12)], "peers"] == 3).all()
    assert r.loc["V12", "peer_group"] == "fleet" and r.loc["V12", "peers"] >= 7
    assert set(r.loc[[f"V{v:02d}" for v in range(12)], "peer_group"]) == {"within 1000 km"}
