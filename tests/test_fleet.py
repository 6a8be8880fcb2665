"""Fleet batch: discovery, safe output paths, resumability, failures, tables, the a priori rule."""

from __future__ import annotations

import datetime
import json
import math
from pathlib import Path

import pandas as pd
import pytest
from test_audit_helpers import make_analysis

from dracc.core.config import config_from_dict
from dracc.core.errors import ConfigError, FleetError, IngestError
from dracc.pipeline.fleet import discover, fleet_config, inside, run_fleet, safe_name, summarise
from dracc.report.fleet_tables import write_tables

CFG = config_from_dict({"deviation": {"apriori": {"ins1": {"lat_m": 120.0}}}})


def fake_analyser(path: str, cfg) -> dict:
    """Stands in for the pipeline: each fake log holds the parameters of its document."""
    text = Path(path).read_text(encoding="utf-8")
    if text.startswith("BAD"):
        return {"ok": False, "error": f"{path}: line 1: not a log"}
    p = json.loads(text)
    doc = make_analysis(
        p["night"],
        m_y={"ins1": {"lat": p["lat"], "lon": 200.0}, "ins2": {"lat": 90.0, "lon": 210.0}},
        containment=p.get("containment", 0.95),
        verdict=p.get("verdict"),
        nees=p.get("nees"),
    )
    # record that a worker really ran (resumability is checked through these marks)
    with open(Path(path).parent.parent / "calls.log", "a", encoding="utf-8") as fh:
        fh.write(Path(path).name + "\n")
    return {"ok": True, "summary": summarise(doc)}


#: the DR verdict of the fake logs, per night (none on 2026-11-18: an older document)
DR = {
    "2026-11-19": {
        "verdict": "consistent: reference inside 2M at 97.5 %",
        "nees": [9.5, 5.1, 34.3],
    },
    "2026-11-20": {
        "verdict": "inconsistent (circle too small): NEES 80.2 (chi^2 6.3-37.2)",
        "nees": [80.2, 6.3, 37.2],
    },
}


def _fleet(tmp_path: Path) -> Path:
    root = tmp_path / "fleet"
    logs = {
        "Aurora": [("2026-11-18", 100.0), ("2026-11-19", 140.0), ("2026-11-20", 130.0)],
        "Borealis": [("2026-11-19", 80.0), ("2026-11-20", 150.0)],
    }
    for vessel, nights in logs.items():
        d = root / vessel
        d.mkdir(parents=True)
        for night, lat in nights:
            (d / f"{night}.nmea").write_text(
                json.dumps({"night": night, "lat": lat, **DR.get(night, {})})
            )
        (d / ".hidden.nmea").write_text("BAD hidden files are skipped")
    (root / "Borealis" / "broken.nmea").write_text("BAD")
    return root


def _calls(root: Path) -> list[str]:
    p = root / "calls.log"
    return sorted(p.read_text().split()) if p.exists() else []


def test_discover_folders_and_globs(tmp_path):
    root = _fleet(tmp_path)
    tasks = discover([root / "Aurora", str(root / "Borealis" / "2026-*.nmea")])
    assert [(t.vessel, t.log) for t in tasks] == [
        ("Aurora", "2026-11-18.nmea"),
        ("Aurora", "2026-11-19.nmea"),
        ("Aurora", "2026-11-20.nmea"),
        ("Borealis", "2026-11-19.nmea"),
        ("Borealis", "2026-11-20.nmea"),
    ]
    assert all(len(t.sha256) == 64 and Path(t.path).is_absolute() for t in tasks)
    with pytest.raises(IngestError, match="matches nothing"):
        discover([str(root / "*.xyz")])
    with pytest.raises(IngestError, match="no such file"):
        discover([root / "Nobody"])


def test_fleet_run_table_rule_failures_and_resume(tmp_path):
    root = _fleet(tmp_path)
    out = tmp_path / "out"
    tasks = discover([root / "Aurora", root / "Borealis"])
    res = run_fleet(tasks, CFG, out, workers=2, analyser=fake_analyser)
    assert (res.analysed, res.cached) == (5, 0)  # and broken.nmea failed
    assert [f["log"] for f in res.failures] == ["broken.nmea"]
    assert "not a log" in res.failures[0]["error"]
    t = res.table
    failed = t[t["status"] == "failed"]
    assert failed["log"].tolist() == ["broken.nmea"] and failed["ins_unit"].isna().all()
    a = t[(t["vessel"] == "Aurora") & (t["ins_unit"] == "ins1") & (t["channel"] == "lat")]
    # the monitoring rule, seeded with 120 m: 100 within, 140 raised, 130 within
    assert a["m_y"].tolist() == [100.0, 140.0, 130.0]
    assert a["apriori_after"].tolist() == [120.0, 140.0, 140.0]
    assert a["apriori_verdict"].tolist() == ["within", "raised", "within"]
    b = t[(t["vessel"] == "Borealis") & (t["ins_unit"] == "ins1") & (t["channel"] == "lat")]
    assert b["apriori_verdict"].tolist() == ["within", "raised"]
    lon = t[(t["vessel"] == "Aurora") & (t["ins_unit"] == "ins2") & (t["channel"] == "lon")]
    assert lon["apriori_verdict"].tolist() == ["established", "within", "within"]
    assert set(t["measure_unit"].dropna()) == {"m"} and len(t) == 5 * 4 + 1
    # the DR verdict of each log, on every row of it, beside dr_consistent
    per_log = t[t["status"] == "ok"].drop_duplicates(["vessel", "log"]).set_index(["vessel", "log"])
    assert per_log.loc[("Aurora", "2026-11-18.nmea"), "dr_verdict"] is pd.NA
    assert pd.isna(per_log.loc[("Aurora", "2026-11-18.nmea"), "dr_nees"])
    for vessel in ("Aurora", "Borealis"):
        ok, bad = per_log.loc[(vessel, "2026-11-19.nmea")], per_log.loc[(vessel, "2026-11-20.nmea")]
        assert (ok["dr_verdict"], bool(ok["dr_consistent"]), ok["dr_nees"]) == (
            "consistent",
            True,
            9.5,
        )
        assert (bad["dr_verdict"], bool(bad["dr_consistent"]), bad["dr_nees"]) == (
            "inconsistent",
            False,
            80.2,
        )
    assert t["dr_nees"].dtype == "float64" and t["dr_verdict"].dtype == "string"
    assert t.groupby(["vessel", "log"])["dr_verdict"].nunique(dropna=False).max() == 1
    assert t["day"].dropna().iloc[0] == datetime.date(2026, 11, 18)

    written = write_tables(res, out)
    assert (out / "fleet.parquet").exists() and (out / "trends.csv").exists()
    back = pd.read_parquet(out / "fleet.parquet")
    pd.testing.assert_frame_equal(back, t, check_dtype=False)
    summary = json.loads((out / "fleet.json").read_text())
    assert summary["failures"][0]["log"] == "broken.nmea"
    assert summary["logs"] == 6  # two vessels hold logs of the same names
    assert all(out.resolve() in p.parents for p in written)
    assert _calls(root) == sorted(
        ["2026-11-18.nmea", "2026-11-19.nmea", "2026-11-20.nmea"] * 1
        + ["2026-11-19.nmea", "2026-11-20.nmea"]
    )

    # a re-run analyses only what failed; the table is the same
    again = run_fleet(tasks, CFG, out, workers=2, analyser=fake_analyser)
    assert (again.analysed, again.cached) == (0, 5)  # broken.nmea failed again
    pd.testing.assert_frame_equal(again.table, t)
    assert len(_calls(root)) == 5
    # --force analyses everything again
    forced = run_fleet(tasks, CFG, out, workers=1, force=True, analyser=fake_analyser)
    assert (forced.analysed, forced.cached) == (5, 0) and len(_calls(root)) == 10
    pd.testing.assert_frame_equal(forced.table, t)


def test_changed_log_or_settings_is_analysed_again(tmp_path):
    root = _fleet(tmp_path)
    out = tmp_path / "out"
    tasks = discover([root / "Aurora"])
    run_fleet(tasks, CFG, out, workers=1, analyser=fake_analyser)
    (root / "Aurora" / "2026-11-20.nmea").write_text(
        json.dumps({"night": "2026-11-20", "lat": 99.0})
    )
    res = run_fleet(discover([root / "Aurora"]), CFG, out, workers=1, analyser=fake_analyser)
    assert (res.analysed, res.cached) == (1, 2)
    other = config_from_dict({"deviation": {"interval_s": 7200.0}})
    assert run_fleet(tasks, other, out, workers=1, analyser=fake_analyser).analysed == 3


def test_unreadable_cache_entry_is_redone(tmp_path):
    root = _fleet(tmp_path)
    out = tmp_path / "out"
    tasks = discover([root / "Aurora"])
    run_fleet(tasks, CFG, out, workers=1, analyser=fake_analyser)
    victim = sorted((out / "cache").rglob("*.json"))[0]
    victim.write_text("{half a fi")
    assert run_fleet(tasks, CFG, out, workers=1, analyser=fake_analyser).analysed == 1


def test_trends_pool_rms_per_day():
    from dracc.pipeline.fleet import fleet_trends

    t = pd.DataFrame(
        {
            "vessel": ["V"] * 2,
            "log": ["a", "b"],
            "sha256": ["1", "2"],
            "status": ["ok"] * 2,
            "day": ["d"] * 2,
            "ins_unit": ["ins1"] * 2,
            "channel": ["lat"] * 2,
            "measure_unit": ["m"] * 2,
            "n": [10, 30],
            "m_y": [100.0, 200.0],
            "apriori_after": [100.0, 200.0],
            "dr_containment_2m": [1.0, 0.5],
            "dr_n_scored": [10, 30],
        }
    )
    (row,) = fleet_trends(t).to_dict("records")
    # sqrt((10*100^2 + 30*200^2)/40) = sqrt(32500)
    assert row["m_y"] == pytest.approx(math.sqrt(32500.0)) and row["n"] == 40 and row["logs"] == 2
    assert row["dr_containment_2m"] == pytest.approx((10 * 1.0 + 30 * 0.5) / 40)
    assert row["apriori_after"] == 200.0


@pytest.mark.parametrize(
    "name",
    [
        "..",
        ".",
        "../../etc",
        "/abs/path",
        "a/../../b",
        "C:\\x",
        "",
        "nul",
        "tab\there",
        "...",
        "x" * 300,
    ],
)
def test_output_paths_never_escape(tmp_path, name):
    p = inside(tmp_path, "vessels", name, "fleet.csv")
    assert tmp_path.resolve() in p.parents and p.name == "fleet.csv"
    assert len(p.relative_to(tmp_path.resolve()).parts) == 3


def test_safe_name_keeps_unicode_and_keeps_names_apart():
    assert safe_name("Søren Kierkegaard") == "Søren Kierkegaard"
    assert safe_name("北斗丸") == "北斗丸"
    assert safe_name("a/b") != safe_name("a_b") and safe_name("a/b").startswith("a_b-")
    assert safe_name("..") != safe_name(".")


def test_fleet_config_validation():
    assert fleet_config(config_from_dict({"fleet": {"workers": 3}})).workers == 3
    with pytest.raises(ConfigError, match=r"\[fleet\] unknown key\(s\): worker"):
        fleet_config(config_from_dict({"fleet": {"worker": 3}}))
    with pytest.raises(ConfigError, match="workers must be a positive integer"):
        fleet_config(config_from_dict({"fleet": {"workers": 0}}))


def test_unreachable_scheduler_is_one_clear_error(tmp_path):
    pytest.importorskip("distributed")
    import socket

    root = _fleet(tmp_path)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(FleetError, match="cannot reach the Dask scheduler"):
        run_fleet(
            discover([root / "Aurora"]),
            CFG,
            tmp_path / "out",
            scheduler=f"tcp://127.0.0.1:{port}",
            connect_timeout_s=1.0,
            analyser=fake_analyser,
        )


def test_an_unexpected_error_in_one_log_is_reported_not_raised(monkeypatch, tmp_path):
    # (the reader's own pool inside a daemonic Dask worker used to raise here; the reader now
    # parses alone there: tests/test_ingest_nmea.py)
    import dracc.pipeline.fleet.batch as batch
    from dracc.pipeline.fleet import analyse_log

    def boom(paths, cfg, progress=None):
        raise AssertionError("an unforeseen state")

    monkeypatch.setattr(batch, "analyse_voyage", boom)
    res = analyse_log(str(tmp_path / "big.nmea"), CFG)
    assert not res["ok"] and res["error"].startswith("internal error (AssertionError")


def _another_version(doc):
    doc["dracc_version"] = "0.0.1"


def _first_summary_schema(doc):
    # a /1 summary has no DR verdict: the log is analysed again rather than shown without one
    doc["schema"] = "dracc.fleet.cache/1"
    del doc["summary"]["dr"]["verdict"], doc["summary"]["dr"]["nees"]


@pytest.mark.parametrize("tamper", [_another_version, _first_summary_schema])
def test_cache_of_another_version_or_schema_is_redone(tmp_path, tamper):
    root = _fleet(tmp_path)
    out = tmp_path / "out"
    tasks = discover([root / "Aurora"])
    run_fleet(tasks, CFG, out, workers=1, analyser=fake_analyser)
    entry = sorted((out / "cache").rglob("*.json"))[0]
    doc = json.loads(entry.read_text())
    tamper(doc)
    entry.write_text(json.dumps(doc))
    assert run_fleet(tasks, CFG, out, workers=1, analyser=fake_analyser).analysed == 1


def test_table_rule_equals_the_reference_chain():
    # the fleet table applies dracc.pipeline.audit.rule.apriori_chain per vessel, unit and channel
    import numpy as np

    from dracc.pipeline.audit import apriori_chain
    from dracc.pipeline.fleet import LogTask, fleet_table

    rng = np.random.default_rng(3)
    tasks, summaries = [], {}
    for i in range(12):
        vessel = "AB"[i % 2]
        night = f"2026-11-{10 + i // 2:02d}"
        lat = float(rng.lognormal(5, 0.4)) if i % 5 else float("nan")
        doc = make_analysis(night, m_y={"ins1": {"lat": lat, "lon": float(rng.lognormal(5, 0.4))}})
        t = LogTask(vessel, f"/x/{vessel}/{night}.nmea", f"{night}.nmea", f"{i:064d}")
        tasks.append(t)
        summaries[t.path] = summarise(doc)
    seeds = {("ins1", "lat"): 150.0}
    t = fleet_table(tasks, summaries, {}, seeds)
    for (_vessel, unit, channel), g in t.groupby(["vessel", "ins_unit", "channel"]):
        steps = apriori_chain(
            seeds.get((unit, channel)),
            [(lg, None if pd.isna(m) else m) for lg, m in zip(g["log"], g["m_y"], strict=True)],
        )
        assert g["apriori_verdict"].tolist() == [s.verdict for s in steps]
        np.testing.assert_array_equal(
            g["apriori_after"].to_numpy(), [np.nan if s.after is None else s.after for s in steps]
        )
        assert g["period_start_utc"].is_monotonic_increasing
    assert "no data" in set(t["apriori_verdict"]) and "raised" in set(t["apriori_verdict"])
