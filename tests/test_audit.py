"""The audit's logic: the a priori rule, thresholds, idempotence, config validation."""

from __future__ import annotations

import datetime as dt
import math

import pytest
from test_audit_helpers import make_analysis

from dracc.core.config import config_from_dict
from dracc.core.distributions import norm_ppf
from dracc.core.errors import ConfigError, ExitCode, IngestError, InsufficientDataError, NoLogsError
from dracc.pipeline.audit import (
    AuditConfig,
    apriori_chain,
    apriori_seeds,
    audit_config,
    audit_night,
    content_sha256,
    evaluate,
    facts_from_analysis,
    night_of,
    select_logs,
    yesterday_utc,
)
from dracc.pipeline.state import StateStore

# ------------------------------------------------------------------ the a priori rule


def test_apriori_chain_by_hand():
    # conclusions of the INS-deviation paper: the larger of a priori and estimate becomes
    # the new a priori.  Seed 100; nights 80, 120, 110, NaN, 130 -> 100, 120, 120, 120, 130
    steps = apriori_chain(
        100.0, [("d1", 80.0), ("d2", 120.0), ("d3", 110.0), ("d4", math.nan), ("d5", 130.0)]
    )
    assert [s.before for s in steps] == [100.0, 100.0, 120.0, 120.0, 120.0]
    assert [s.after for s in steps] == [100.0, 120.0, 120.0, 120.0, 130.0]
    assert [s.verdict for s in steps] == ["within", "raised", "within", "no data", "raised"]


def test_apriori_chain_without_seed_is_established_by_deviation():
    # "In the absence of a priori values ... their definition by deviation becomes mandatory"
    steps = apriori_chain(None, [("d1", None), ("d2", 50.0), ("d3", 40.0)])
    assert [s.verdict for s in steps] == ["no data", "established", "within"]
    assert [s.after for s in steps] == [None, 50.0, 50.0]


def test_apriori_chain_never_decreases():
    import numpy as np

    rng = np.random.default_rng(7)
    values = rng.lognormal(4.0, 0.5, 200)
    steps = apriori_chain(60.0, [(f"d{i}", float(v)) for i, v in enumerate(values)])
    after = np.array([s.after for s in steps])
    assert np.all(np.diff(after) >= 0)
    np.testing.assert_allclose(after, np.maximum.accumulate(np.maximum(values, 60.0)))


# --------------------------------------------------------------------------- config


def test_audit_config_defaults_and_overrides():
    cfg = config_from_dict(
        {
            "audit": {
                "db": "x.sqlite",
                "limits": {"ins2": {"lon_m": 2500.0}},
                "dr_containment_min": 0.8,
                "required_sources": ["gnss"],
            }
        }
    )
    a = audit_config(cfg)
    assert a.db == "x.sqlite" and a.dr_containment_min == 0.8 and a.required_sources == ("gnss",)
    assert a.limit_for("ins2", "lon") == 2500.0
    assert a.limit_for("ins2", "lat") == 1852.0 and a.limit_for("ins1", "lon") == 1852.0
    assert a.limit_for("ins3", "course") == 0.75


@pytest.mark.parametrize(
    "table, words",
    [
        ({"dbb": "x"}, ["unknown key", "dbb"]),
        ({"limits": {"ins4": {"lat_m": 1.0}}}, ["audit.limits", "ins4"]),
        ({"limits": {"all": {"lat_deg": 1.0}}}, ["audit.limits.all", "lat_deg"]),
        ({"limits": {"all": {"lat_m": -1.0}}}, ["audit.limits.all.lat_m", "positive"]),
        ({"dr_containment_min": 1.5}, ["dr_containment_min", "fraction"]),
        ({"required_sources": ["radar"]}, ["required_sources", "radar"]),
        ({"compass_error_max_deg": "one"}, ["compass_error_max_deg", "number"]),
        ({"apriori_raise_is_finding": 1}, ["apriori_raise_is_finding"]),
    ],
)
def test_audit_config_errors_name_the_key(table, words):
    with pytest.raises(ConfigError) as e:
        audit_config(config_from_dict({"audit": table}))
    assert all(w in str(e.value) for w in words)


def test_apriori_seeds_from_deviation_section():
    cfg = config_from_dict(
        {"deviation": {"apriori": {"ins1": {"lat_m": 300.0, "course_deg": 0.1}}}}
    )
    assert apriori_seeds(cfg) == {("ins1", "lat"): 300.0, ("ins1", "course"): 0.1}
    with pytest.raises(ConfigError, match=r"deviation.apriori.ins1\] unknown key\(s\): lat;"):
        apriori_seeds(config_from_dict({"deviation": {"apriori": {"ins1": {"lat": 3.0}}}}))


# ------------------------------------------------------------------------ findings


def _kinds(findings):
    return sorted(f.kind for f in findings)


def test_no_findings_within_limits():
    found, skipped = evaluate(facts_from_analysis(make_analysis()), AuditConfig())
    assert found == () and skipped == ()


def test_each_threshold_triggers_just_above_not_at():
    # the per-night checks; the limiting errors are judged over the accuracy window
    # (test_accuracy_window_limit_just_above_not_at)
    a = AuditConfig(
        limits={"all": {"lat_m": 1.0, "lon_m": 1.0, "course_deg": 0.001}},
        dr_containment_min=0.9,
        compass_error_max_deg=1.0,
        log_scale_max_pct=2.0,
        rejected_rate_max_pct=1.0,
    )
    # issue 29: compass and log fail only beyond the limit by z sigma (z at the audit's
    # false alarm 1e-3: 3.09; the helper's sigmas are 0.05 deg and 0.1 %)
    z = norm_ppf(1 - 1e-3)
    at = make_analysis(
        containment=0.9,
        compass_deg=-(1.0 + z * 0.05) + 1e-9,
        log_scale=-(0.02 + z * 0.001) + 1e-9,
        lines=10000,
        rejected=100,
        roles=("ins1", "ins2", "ins3"),
    )
    assert evaluate(facts_from_analysis(at), a)[0] == ()
    above = make_analysis(
        containment=0.8999,
        compass_deg=-(1.01 + z * 0.05),
        log_scale=0.0201 + z * 0.001,
        lines=10000,
        rejected=101,
        roles=("ins1", "ins3"),
    )
    found, _ = evaluate(facts_from_analysis(above), a)
    assert _kinds(found) == [
        "compass_error",
        "dr_containment",
        "log_scale",
        "missing_source",
        "rejected_rate",
    ]
    by = {f.subject: f for f in found}
    assert by["ins2"].kind == "missing_source" and by["ins2"].check == "availability"
    assert by["DR"].value == 0.8999 and by["DR"].limit == 0.9 and by["DR"].check == "consistency"
    assert by["compass"].value == -(1.01 + z * 0.05) and by["compass"].measure == "deg"
    assert by["log"].value == pytest.approx(2.01 + 100 * z * 0.001) and by["log"].measure == "%"
    assert "101 of 10000 lines damaged" in by["inputs"].message and by["inputs"].check == "input"
    # a single night's limiting errors, however large, are not judged night by night
    assert "limit" not in _kinds(found)


def _window_nights(store, lat, *, acfg, hours=24.0):
    """Audit one night per value of ``lat`` (ins1 lat m_y), each ``hours`` long."""
    outs = []
    for i, v in enumerate(lat):
        night = f"2026-11-{17 + i}"
        end = dt.datetime.fromisoformat(f"{night}T00:00:00+00:00") + dt.timedelta(hours=hours)
        period = (f"{night}T00:00:00Z", end.strftime("%Y-%m-%dT%H:%M:%SZ"))
        doc = make_analysis(night, m_y={"ins1": {"lat": v}}, period=period)
        outs.append(_audit(store, doc, acfg=acfg))
    return outs


def _pooled_limit(lat, n=24, k=1.32):
    """The (K8) limiting error of the pooled deviations, from the seed-001 formulas."""
    from dracc.core.config import DeviationConfig
    from dracc.math.deviation import stats

    d = DeviationConfig()
    m_u = math.sqrt(sum(n * (v / k) ** 2 for v in lat) / (n * len(lat)))
    n_eff = len(lat) * float(stats.effective_samples(n, d.interval_s, d.correlation_time_s))
    return float(stats.limiting_error(k * m_u, d.probability, -0.3, d.confidence, n_eff)[0])


def _accuracy_skips(out):
    return [nc for nc in out.not_checked if (nc["check"], nc["name"]) == ("accuracy", "limit")]


@pytest.mark.parametrize("factor, expect", [(1 / 1.001, True), (1.001, False)])
def test_accuracy_window_limit_just_above_not_at(tmp_path, factor, expect):
    lat = (100.0, 120.0, 140.0)
    pooled = _pooled_limit(lat)
    acfg = AuditConfig(limits={"ins1": {"lat_m": pooled * factor}}, accuracy_window_h=72.0)
    with StateStore(tmp_path / "s.sqlite") as store:
        outs = _window_nights(store, lat, acfg=acfg)
    # 24 h and 48 h: the window is not full, the limit is not judged and it is said so
    for out, hours in zip(outs[:2], (24.0, 48.0), strict=True):
        assert [f for f in out.findings if f.kind == "limit"] == []
        (nc,) = _accuracy_skips(out)
        assert "72 h" in nc["why"] and f"{hours:.1f} h" in nc["why"]
        assert out.accuracy["complete"] is False
    last = outs[2]
    assert _accuracy_skips(last) == [] and last.accuracy["complete"] is True
    assert last.accuracy["nights"] == ["2026-11-17", "2026-11-18", "2026-11-19"]
    (row,) = last.accuracy["channels"]
    assert row["limit_error"] == pytest.approx(pooled, rel=1e-9)
    limits = [f for f in last.findings if f.kind == "limit"]
    if not expect:
        assert limits == [] and last.exit_code == ExitCode.OK
        return
    (f,) = limits
    assert (f.check, f.subject, f.role, f.measure) == ("accuracy", "ins1 lat", "ins1", "m")
    assert f.value == pytest.approx(pooled, rel=1e-9) and f.limit == pytest.approx(pooled / 1.001)
    assert f.window["nights"] == ["2026-11-17", "2026-11-18", "2026-11-19"]
    assert f.window["hours"] == pytest.approx(72.0)
    assert "72 h (3 nights)" in f.message and last.exit_code == ExitCode.FINDINGS


def test_accuracy_window_short_nights_are_not_checked(tmp_path):
    # the same nights and the same limiting error, 12 h each: 36 h < 60 h, not judged
    lat = (100.0, 120.0, 140.0)
    acfg = AuditConfig(
        limits={"ins1": {"lat_m": _pooled_limit(lat) / 1.001}}, accuracy_window_h=60.0
    )
    with StateStore(tmp_path / "s.sqlite") as store:
        outs = _window_nights(store, lat, acfg=acfg, hours=12.0)
    assert all(f.kind != "limit" for o in outs for f in o.findings)
    (nc,) = _accuracy_skips(outs[-1])
    assert "36.0 h over 3 nights" in nc["why"] and outs[-1].exit_code == ExitCode.OK
    # a fourth and a fifth night fill the window (60 h): the five nights are pooled and judged
    lat5 = lat + (140.0, 140.0)
    acfg = AuditConfig(
        limits={"ins1": {"lat_m": _pooled_limit(lat5) / 1.001}}, accuracy_window_h=60.0
    )
    with StateStore(tmp_path / "s.sqlite") as store:
        outs = _window_nights(store, lat5, acfg=acfg, hours=12.0)
    assert [o.status for o in outs] == ["unchanged"] * 3 + ["recorded"] * 2
    assert _accuracy_skips(outs[3]) != [] and all(f.kind != "limit" for f in outs[3].findings)
    last = outs[-1]
    assert last.accuracy["nights"] == [f"2026-11-{d}" for d in range(17, 22)]
    assert _accuracy_skips(last) == [] and [f.kind for f in last.findings] == ["limit"]
    assert last.findings[0].value == pytest.approx(_pooled_limit(lat5), rel=1e-9)


def test_accuracy_window_without_duration_counts_the_period(tmp_path):
    # tonight adds the hours of its period to the window, as stored nights are counted
    acfg = AuditConfig(accuracy_window_h=20.0)
    with StateStore(tmp_path / "s.sqlite") as store:
        out = _audit(store, make_analysis("2026-11-20"), acfg=acfg)
    assert out.accuracy["nights"] == ["2026-11-20"] and out.accuracy["complete"] is True
    # the window takes the 20 h it needs of the night's 24 h (issue 32: never longer)
    assert out.accuracy["hours"] == pytest.approx(20.0) and _accuracy_skips(out) == []
    assert out.accuracy["partial"]["of_hours"] == pytest.approx(24.0, abs=0.01)


def test_missing_figures_are_not_checked_and_said_so(tmp_path):
    doc = make_analysis(
        containment=None, compass_deg=None, log_scale=None, m_y={"ins1": {"lat": math.nan}}
    )
    found, skipped = evaluate(facts_from_analysis(doc), AuditConfig())
    assert found == ()
    assert [(d["check"], d["name"], d["role"]) for d in skipped] == [
        ("consistency", "dr", None),
        ("accuracy", "compass_error", "compass"),
        ("accuracy", "log_scale", "log"),
    ]
    why = {d["name"]: d["why"] for d in skipped}
    # a calibration without the figure and without its why: said as such (issue 32)
    assert "no DR track" in why["dr"] and "gives no estimate" in why["compass_error"]
    assert "gives no estimate" in why["log_scale"]
    # no INS statistics: the limiting errors cannot be judged over the window either
    with StateStore(tmp_path / "s.sqlite") as store:
        out = _audit(store, doc)
    (nc,) = _accuracy_skips(out)
    assert "no INS deviation statistics" in nc["why"] and out.exit_code == ExitCode.OK


# ------------------------------------------------- the DR verdict of the analysis

INCONSISTENT = (
    "inconsistent (circle too small): reference inside 2M at 93.3 % of 45 epochs in "
    "9 legs (a correct model gives 95.6 %); RMS error/M 1.16 (1 expected); NEES 80.2 "
    "(chi^2 6.3-37.2)"
)


@pytest.mark.parametrize(
    "text, word",
    [
        ("consistent: reference inside 2M at 100.0 %", "consistent"),
        ("conservative: every epoch inside", "conservative"),
        (INCONSISTENT, "inconsistent"),
        ("Inconsistent: upper case", "inconsistent"),
        ("undetermined: no epoch of a leg whose model was learned", "undetermined"),
        ("inconsistently worded", None),
        ("", None),
        (None, None),
        (3, None),
    ],
)
def test_dr_verdict_word(text, word):
    from dracc.pipeline.audit import dr_verdict_word

    assert dr_verdict_word(text) == word


def test_inconsistent_dr_is_a_finding_even_with_containment_above_the_minimum():
    """Issue: the audit passed a log that analyze called inconsistent (90 % containment
    met, the analysis' NEES test failed)."""
    doc = make_analysis(containment=0.933, verdict=INCONSISTENT, nees=(80.2, 6.3, 37.2))
    facts = facts_from_analysis(doc)
    assert (facts.dr_verdict, facts.dr_consistent, facts.dr_nees) == ("inconsistent", False, 80.2)
    found, skipped = evaluate(facts, AuditConfig())
    (f,) = found
    assert (f.kind, f.subject, f.value, f.limit, f.measure) == (
        "dr_inconsistent",
        "DR",
        80.2,
        37.2,
        "NEES",
    )
    assert f.message == f"DR: {INCONSISTENT}" and skipped == ()


def test_inconsistent_dr_below_the_minimum_is_one_finding():
    doc = make_analysis(
        containment=0.5, verdict=INCONSISTENT, dominant=("the current", "current_kn")
    )
    (f,) = evaluate(facts_from_analysis(doc), AuditConfig())[0]
    assert f.kind == "dr_inconsistent" and f.measure == "" and f.value is None  # no NEES given
    assert "the circle is dominated by the current (key [dead_reckoning] current_kn)" in f.message
    assert f.message.endswith("; 50.0 % inside 2M is below the audit's minimum of 90.0 %")
    # the dominant source already in the sentence is not said twice
    said = (
        INCONSISTENT + "; the circle is dominated by the current (key [dead_reckoning] current_kn)"
    )
    (g,) = evaluate(
        facts_from_analysis(make_analysis(verdict=said, dominant=("the current", "current_kn"))),
        AuditConfig(),
    )[0]
    assert g.message == f"DR: {said}"


@pytest.mark.parametrize(
    "verdict", ["consistent: inside at 97.8 %", "conservative: every epoch inside"]
)
def test_consistent_or_conservative_dr_keeps_the_containment_check(verdict):
    assert evaluate(facts_from_analysis(make_analysis(verdict=verdict)), AuditConfig()) == ((), ())
    (f,) = evaluate(
        facts_from_analysis(make_analysis(verdict=verdict, containment=0.8)), AuditConfig()
    )[0]
    assert f.kind == "dr_containment"


def test_undetermined_dr_is_not_checked_and_said_so():
    text = "undetermined: no epoch of a leg whose model was learned from earlier fixes"
    found, skipped = evaluate(facts_from_analysis(make_analysis(verdict=text)), AuditConfig())
    assert found == () and skipped == (
        {
            "check": "consistency",
            "name": "dr",
            "source": None,
            "role": None,
            "why": f"DR verdict: {text}",
        },
    )


def test_night_of_period_middle_and_missing_period():
    f = facts_from_analysis(make_analysis("2026-11-20"))
    assert night_of(f) == "2026-11-20"
    doc = make_analysis(period=("2026-11-20T20:00:00Z", "2026-11-21T10:00:00Z"))
    assert night_of(facts_from_analysis(doc)) == "2026-11-21"
    doc = make_analysis(period=(None, None))
    with pytest.raises(InsufficientDataError, match="--date"):
        night_of(facts_from_analysis(doc))


# -------------------------------------------------------- nights in the state store


def _audit(store, doc, *, seeds=None, acfg=None, night=None, content=None, settings="s"):
    facts = facts_from_analysis(doc)
    return audit_night(
        facts,
        store=store,
        acfg=acfg or AuditConfig(),
        seeds=seeds or {},
        vessel="Aurora",
        night=night,
        content_hash=content or facts.period_start_utc,
        settings_hash=settings,
    )


def test_apriori_rule_over_several_nights(tmp_path):
    seeds = {("ins1", "lat"): 120.0}
    lat = {"2026-11-17": 100.0, "2026-11-18": 140.0, "2026-11-19": 130.0, "2026-11-20": 150.0}
    with StateStore(tmp_path / "s.sqlite") as store:
        outs = []
        for night, v in lat.items():
            doc = make_analysis(night, m_y={"ins1": {"lat": v, "lon": 10.0 * len(outs) + 5.0}})
            outs.append(_audit(store, doc, seeds=seeds))
        assert [o.status for o in outs] == ["recorded"] * 4
        hist = store.history(vessel="Aurora", unit="ins1", channel="lat")
        assert [h["apriori_before"] for h in hist] == [120.0, 120.0, 140.0, 140.0]
        assert [h["apriori_after"] for h in hist] == [120.0, 140.0, 140.0, 150.0]
        assert [h["verdict"] for h in hist] == ["within", "raised", "within", "raised"]
        # no seed for longitude: the first night's deviation estimate establishes it
        lon = store.history(vessel="Aurora", unit="ins1", channel="lon")
        assert [h["verdict"] for h in lon] == ["established", "raised", "raised", "raised"]
        ev = [e for e in store.apriori_events("Aurora") if e.channel == "lat"]
        assert [(e.night, e.previous, e.value, e.reason) for e in ev] == [
            ("2026-11-18", 120.0, 140.0, "raised"),
            ("2026-11-20", 140.0, 150.0, "raised"),
        ]
        assert ev[0].evidence["m_y"] == 140.0 and ev[0].evidence["n"] == 24
        assert ev[0].evidence["m_u"] == pytest.approx(140.0 / 1.32)
        # the outcome of the last night carries its own events
        assert [(e.unit, e.channel) for e in outs[-1].apriori_events] == [
            ("ins1", "lat"),
            ("ins1", "lon"),
        ]


def test_night_audited_late_recomputes_the_chain(tmp_path):
    with StateStore(tmp_path / "s.sqlite") as store:
        _audit(store, make_analysis("2026-11-18", m_y={"ins1": {"lat": 100.0}}))
        _audit(store, make_analysis("2026-11-20", m_y={"ins1": {"lat": 120.0}}))
        _audit(store, make_analysis("2026-11-19", m_y={"ins1": {"lat": 150.0}}))  # arrives late
        hist = store.history(unit="ins1", channel="lat")
        assert [h["night"] for h in hist] == ["2026-11-18", "2026-11-19", "2026-11-20"]
        assert [h["apriori_after"] for h in hist] == [100.0, 150.0, 150.0]
        assert [h["verdict"] for h in hist] == ["established", "raised", "within"]


def test_same_night_twice_is_recorded_once(tmp_path):
    with StateStore(tmp_path / "s.sqlite") as store:
        doc = make_analysis("2026-11-20")
        first = _audit(store, doc, content="abc")
        before = store.conn.execute("SELECT audited_utc FROM nights").fetchall()
        second = _audit(
            store,
            doc,
            content="abc",
        )
        assert (first.status, second.status) == ("recorded", "unchanged")
        assert store.conn.execute("SELECT COUNT(*) FROM nights").fetchone()[0] == 1
        assert store.conn.execute("SELECT COUNT(*) FROM unit_stats").fetchone()[0] == 9
        assert store.conn.execute("SELECT audited_utc FROM nights").fetchall() == before
        assert second.record.channels == first.record.channels


def test_changed_log_replaces_the_night(tmp_path):
    with StateStore(tmp_path / "s.sqlite") as store:
        _audit(store, make_analysis("2026-11-20", m_y={"ins1": {"lat": 100.0}}), content="v1")
        out = _audit(store, make_analysis("2026-11-20", m_y={"ins1": {"lat": 90.0}}), content="v2")
        assert out.status == "replaced"
        (row,) = store.history()
        assert row["m_y"] == 90.0 and row["apriori_after"] == 90.0
        assert store.night("Aurora", "2026-11-20").content_sha256 == "v2"
        # other settings with the same content also replace it (the statistics depend on them)
        assert (
            _audit(store, make_analysis("2026-11-20"), content="v2", settings="other").status
            == "replaced"
        )


def test_exit_code_follows_findings(tmp_path):
    with StateStore(tmp_path / "s.sqlite") as store:
        ok = _audit(store, make_analysis("2026-11-19"))
        bad = _audit(store, make_analysis("2026-11-20", containment=0.5))
        assert ok.exit_code == ExitCode.OK and bad.exit_code == ExitCode.FINDINGS
        assert [f["kind"] for f in store.night("Aurora", "2026-11-20").findings] == [
            "dr_containment"
        ]


def test_inconsistent_night_exits_1_and_is_stored_with_its_verdict(tmp_path):
    with StateStore(tmp_path / "s.sqlite") as store:
        ok = _audit(
            store, make_analysis("2026-11-19", verdict="consistent: fine", nees=(9.0, 5.1, 34.3))
        )
        bad = _audit(
            store, make_analysis("2026-11-20", verdict=INCONSISTENT, nees=(80.2, 6.3, 37.2))
        )
        assert ok.exit_code == ExitCode.OK and bad.exit_code == ExitCode.FINDINGS
        assert [f.kind for f in bad.findings] == ["dr_inconsistent"]
        rec = store.night("Aurora", "2026-11-20")
        assert [f["kind"] for f in rec.findings] == ["dr_inconsistent"]
        assert (rec.dr_verdict, rec.dr_consistent, rec.dr_nees) == ("inconsistent", False, 80.2)
        assert rec.dr_verdict_text == INCONSISTENT
        assert store.night("Aurora", "2026-11-19").dr_consistent is True
        # audited again unchanged: the finding is evaluated again, nothing written
        again = _audit(
            store, make_analysis("2026-11-20", verdict=INCONSISTENT, nees=(80.2, 6.3, 37.2))
        )
        assert again.status == "unchanged" and again.exit_code == ExitCode.FINDINGS


def test_apriori_raise_as_finding_when_configured(tmp_path):
    a = AuditConfig(apriori_raise_is_finding=True)
    with StateStore(tmp_path / "s.sqlite") as store:
        out = _audit(
            store,
            make_analysis("2026-11-20", m_y={"ins2": {"lon": 300.0}}),
            seeds={("ins2", "lon"): 250.0},
            acfg=a,
        )
        (f,) = out.findings
        assert (
            f.kind == "apriori_raised" and (f.value, f.limit) == (300.0, 250.0) and f.measure == "m"
        )


def test_rollback_leaves_state_untouched(tmp_path):
    with StateStore(tmp_path / "s.sqlite") as store:
        _audit(store, make_analysis("2026-11-19"))
        with pytest.raises(RuntimeError), store.transaction():
            store.delete_night("Aurora", "2026-11-19")
            raise RuntimeError("killed")
        assert [r.night for r in store.nights()] == ["2026-11-19"]
        assert store.journal_mode == "wal"


# ------------------------------------------------------------------ choosing the logs


def test_select_logs_by_date_in_name(tmp_path):
    for name in (
        "nav-2026-11-20.nmea",
        "nav-20261120-b.nmea",
        "nav_2026_11_20.log",
        "nav-2026-11-19.nmea",
        ".nav-2026-11-20.nmea.part",
    ):
        (tmp_path / name).write_text("x")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "ins-2026-11-20.nmea").write_text("y")
    got = select_logs([tmp_path], "2026-11-20", "*")
    assert [p.name for p in got] == [
        "nav-2026-11-20.nmea",
        "nav-20261120-b.nmea",
        "nav_2026_11_20.log",
    ]
    got = select_logs([tmp_path], "2026-11-20", "**/*.nmea")
    assert [p.name for p in got] == [
        "nav-2026-11-20.nmea",
        "nav-20261120-b.nmea",
        "ins-2026-11-20.nmea",
    ]
    with pytest.raises(NoLogsError, match=r"no logs for 2026-11-18 matching '\*' in "):
        select_logs([tmp_path], "2026-11-18", "*")
    with pytest.raises(NoLogsError, match=r"no logs for 2026-11-20 matching '\*\.csv' in "):
        select_logs([tmp_path], "2026-11-20", "*.csv")
    assert issubclass(NoLogsError, IngestError)  # exit 3 where it is not a night without data
    with pytest.raises(IngestError, match="no such file"):
        select_logs([tmp_path / "nope"], None, "*")


def test_content_hash_ignores_names_and_order(tmp_path):
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    a.write_bytes(b"one")
    b.write_bytes(b"two")
    c.write_bytes(b"one")
    assert content_sha256([a, b]) == content_sha256([b, a])
    assert content_sha256([c, b]) == content_sha256([a, b])
    before = content_sha256([a, b])
    b.write_bytes(b"two!")
    assert content_sha256([a, b]) != before


def test_yesterday_utc():
    assert yesterday_utc(dt.datetime(2026, 3, 1, 0, 30, tzinfo=dt.timezone.utc)) == "2026-02-28"


@pytest.mark.parametrize(
    "table, word", [({"name": 5}, "name"), ({"name": "  "}, "name"), ({"nmae": "Aurora"}, "nmae")]
)
def test_vessel_table_is_checked_not_silently_default(table, word):
    from dracc.core.config import Config
    from dracc.core.errors import ConfigError
    from dracc.pipeline.audit import AuditConfig, vessel_name

    with pytest.raises(ConfigError, match=word):
        vessel_name(Config(extra={"vessel": table}), AuditConfig(), None)
    assert (
        vessel_name(Config(extra={"vessel": {"name": "Aurora"}}), AuditConfig(), None) == "Aurora"
    )
