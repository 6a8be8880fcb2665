"""Issue 32: the fleet outputs carry each night's findings and integrity results, from raw
logs and from the audit documents alike; the fleet table and the ranking give one number
for one unit and night; the page's latest figures are each one night's.

Two vessels, two one-hour nights each (sparse rates); Borealis' second night has a frozen
INS2 and a GNSS jump (``dracc simulate --fault``)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd
import pytest
from conftest import SPARSE_RATES

from dracc.cli.main import main
from dracc.core.config import load_config
from dracc.core.vocabulary import column_kind
from dracc.pipeline.fleet import discover, run_fleet
from dracc.pipeline.fleet.findings import FINDING_COLUMNS, INTEGRITY_COLUMNS
from dracc.pipeline.fleet.query import run_query
from dracc.report.fleet_html import fleet_html
from dracc.report.fleet_tables import write_tables
from dracc.report.terminal import fleet_text

NIGHTS = ("2026-11-18", "2026-11-19")
FAULTY = ("Borealis", NIGHTS[1])
FAULTS = ("--fault", "freeze:INS2@20min+20min", "--fault", "jump:GNSS@30min=670m")


@pytest.fixture(scope="module")
def fleet(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("findings")
    for v, vessel in enumerate(("Aurora", "Borealis")):
        (root / vessel).mkdir()
        for n, night in enumerate(NIGHTS):
            args = ["simulate", "--out", str(root / "sim"), "--hours", "1"]
            args += ["--seed", str(50 + 2 * v + n), "--start", f"{night}T00:00:00Z"]
            args += ["--name", f"{vessel}-{night}", *SPARSE_RATES]
            if (vessel, night) == FAULTY:
                args += FAULTS
            assert main(args) == 0
            (root / "sim" / f"{vessel}-{night}.nmea").rename(root / vessel / f"{night}.nmea")
    return root


@pytest.fixture(scope="module")
def raw(fleet, tmp_path_factory):
    """The fleet run from the raw logs, its outputs written."""
    out = tmp_path_factory.mktemp("raw")
    res = run_fleet(
        discover([fleet / "Aurora", fleet / "Borealis"]), load_config(None), out, workers=2
    )
    write_tables(res, out, extra={"fleet.html": fleet_html(res)})
    return res, out


def _failed(findings: pd.DataFrame, vessel: str, night: str) -> pd.DataFrame:
    f = findings[(findings["status"] == "fail") & (findings["vessel"] == vessel)]
    return f[f["night"].astype(str) == night]


def test_findings_name_the_frozen_ins2_and_the_gnss_jump(raw):
    res, _ = raw
    f = res.findings
    assert list(f.columns) == list(FINDING_COLUMNS)
    assert all(column_kind(c) is not None for c in (*FINDING_COLUMNS, *INTEGRITY_COLUMNS))
    faulty = _failed(f, *FAULTY)
    by = {(r["check"], r["name"], r["source"]): r for _, r in faulty.iterrows()}
    frozen = by[("plausibility", "frozen", "INS2")]
    jump = by[("plausibility", "jump", "GNSS")]
    assert "frozen" in frozen["message"] and "jump" in jump["message"]
    for r in (frozen, jump):  # the window of the records the check looked at, that night
        assert str(r["window_start_utc"].date()) == FAULTY[1] <= str(r["window_end_utc"].date())
    # the GNSS jump's consequences are listed under it, not as findings of their own
    assert "contradiction" not in set(faulty["name"])
    assert "contradiction" in str(jump["consequences"])
    for vessel, night in (("Aurora", NIGHTS[0]), ("Aurora", NIGHTS[1]), ("Borealis", NIGHTS[0])):
        clean = _failed(f, vessel, night)
        assert not set(clean["name"]) & {"frozen", "jump"}, clean
    skipped = f[f["status"] == "not_checked"]
    assert len(skipped) and (skipped["message"].str.len() > 0).all()  # each says why


def test_integrity_counts_per_vessel_and_night(raw):
    res, _ = raw
    ig = res.integrity
    assert list(ig.columns) == list(INTEGRITY_COLUMNS)
    assert len(ig) == 4 and ig[["vessel", "log"]].drop_duplicates().shape[0] == 4
    assert (ig["checks_made"] == ig["checks_passed"] + ig["checks_failed"]).all()
    row = ig[(ig["vessel"] == FAULTY[0]) & (ig["night"].astype(str) == FAULTY[1])].iloc[0]
    # every failed check is a finding or a finding's consequence: at least the two causes
    assert row["checks_failed"] >= len(_failed(res.findings, *FAULTY)) >= 2
    assert row["checks_not_checked"] >= 0 and row["checks_made"] > 10


def test_findings_and_integrity_are_written_and_queryable(raw):
    res, out = raw
    for name, df in (("findings", res.findings), ("integrity", res.integrity)):
        back = pd.read_parquet(out / f"{name}.parquet")
        assert list(back.columns) == list(df.columns) and len(back) == len(df)
        csv = pd.read_csv(out / f"{name}.csv")
        assert list(csv.columns) == list(df.columns) and len(csv) == len(df)
        assert (out / "tables" / name / "vessel=Borealis" / f"night={FAULTY[1]}").is_dir()
    assert (out / "vessels" / "Borealis" / "findings.csv").exists()
    q = run_query(
        out,
        "SELECT f.vessel, f.night, f.source, i.checks_failed FROM findings f "
        "JOIN integrity i USING (vessel, log) WHERE f.name = 'frozen' AND f.status = 'fail'",
    )
    assert q.shape[0] == 1 and tuple(q.iloc[0, :3].astype(str)) == (*FAULTY, "INS2")
    assert q.iloc[0]["checks_failed"] >= 2


def test_fleet_table_and_ranking_give_one_number_per_unit_and_night(raw):
    """Every INS unit, channel and night: the ranking's figure of that night (its
    evidence) is the fleet table's rms_error, and every such figure of the table is
    ranked; the page and the terminal show that number beside the latest night."""
    res, _ = raw
    t = res.table[res.table["rms_error"].notna()]
    table = {
        (r["vessel"], r["ins_unit"], r["channel"], str(r["day"])): r["rms_error"]
        for _, r in t.iterrows()
    }
    ranked: dict[tuple, float] = {}
    for _, r in res.ranking[res.ranking["quantity"].str.endswith("_m_y")].iterrows():
        channel = str(r["quantity"]).removesuffix("_m_y")
        for n in json.loads(r["evidence"])["nights"]:
            ranked[(r["vessel"], r["ins_unit"], channel, n["night"])] = n["value"]
    assert len(table) >= 2 * 2 * 3 * 2 - 4  # two vessels, nights, three units, lat/lon at least
    assert set(ranked) == set(table)
    for key, value in table.items():
        assert ranked[key] == pytest.approx(value, rel=1e-12), key
    # the methods the ranking names for the last night are the table's
    assert set(res.table["rms_error_method"].dropna()) <= {"reference", "hat", "factor"}
    page = fleet_html(res)
    latest = page[page.index("Latest night per vessel") : page.index("Findings and integrity")]
    last = t[t["day"].astype(str) == NIGHTS[1]]
    for _, r in last.iterrows():
        digits = 3 if r["measure_unit"] == "deg" else 1
        assert f"{r['rms_error']:,.{digits}f} {r['measure_unit']} ({r['rms_error_method']})" in (
            latest
        )
    text = fleet_text(res, width=160)
    r = last.iloc[0]
    assert "RMS error" in text and f"{r['rms_error']:,.0f}m" in text


def test_latest_figures_are_one_night_each_and_say_so(raw):
    res, _ = raw
    page = fleet_html(res)
    latest = page[page.index("Latest night per vessel") : page.index("Findings and integrity")]
    assert " to " not in latest  # no range beside single-night values
    assert f"<td>{NIGHTS[1]}</td>" in latest and f"<td>{NIGHTS[0]}</td>" not in latest
    span = page[page.index("Logs per vessel in this run") : page.index("Latest night per vessel")]
    assert "first night" in span and "last night" in span and f"<td>{NIGHTS[0]}</td>" in span
    assert "value, last nights pooled" in page  # the ranking's figure says it is pooled
    assert "Findings and integrity per vessel and night" in page
    findings = page[page.index("Findings and integrity") :]
    assert "INS2" in findings and "frozen" in findings and "jump" in findings


def _audit(log: Path, vessel: str, night: str, db: Path, target: Path, *brief: str) -> None:
    code = main(
        ["audit", str(log), "--db", str(db), "--vessel", vessel, "--date", night]
        + ["--json", str(target), *brief]
    )
    assert code == 1  # findings


def _rows(df: pd.DataFrame) -> set[tuple]:
    f = df[(df["status"] == "fail") & (df["check"] != "accuracy")]  # accuracy: over a window
    return {
        (r["vessel"], str(r["night"]), r["check"], r["name"], r["source"], r["message"])
        for _, r in f.iterrows()
    }


def test_audit_documents_give_the_raw_logs_findings_and_counts(raw, fleet, tmp_path):
    """The faulty night audited on board: a full and a brief audit document (``--brief``,
    what a ship sends ashore) give the fleet the findings and integrity counts the raw log
    gave; the audit database gives the findings (it keeps no counts: NULL)."""
    res, _ = raw
    log = fleet / FAULTY[0] / f"{FAULTY[1]}.nmea"
    docs = tmp_path / "docs" / FAULTY[0]
    docs.mkdir(parents=True)
    _audit(log, *FAULTY, tmp_path / "full.sqlite", docs / "full.json")
    _audit(log, *FAULTY, tmp_path / "brief.sqlite", docs / "brief.json", "--brief")
    assert json.loads((docs / "brief.json").read_text())["analysis"] is None
    shutil.copy(tmp_path / "full.sqlite", docs / "state.sqlite")
    # together, the three are one night given three times: the first audit document's is
    # kept (brief.json, in the order the folder is read), the database's left out
    got = run_fleet(discover([docs]), load_config(None), tmp_path / "out", workers=1)
    assert got.documents == 1 and not got.failures and len(got.duplicates) == 2
    assert set(got.table["log"]) == {f"brief.json#{FAULTY[1]}"}
    want = _rows(res.findings[res.findings["vessel"] == FAULTY[0]])
    want = {r for r in want if r[1] == FAULTY[1]}
    assert {(r[3], r[4]) for r in want} >= {("frozen", "INS2"), ("jump", "GNSS")}
    raw_counts = res.integrity[
        (res.integrity["vessel"] == FAULTY[0]) & (res.integrity["night"].astype(str) == FAULTY[1])
    ][list(INTEGRITY_COLUMNS[3:])].iloc[0]
    for doc in ("full.json", "brief.json", "state.sqlite"):  # each alone
        got = run_fleet(discover([docs / doc]), load_config(None), tmp_path / doc, workers=1)
        assert got.documents == 1 and not got.failures
        log_name = f"{doc}#{FAULTY[1]}"
        assert _rows(got.findings[got.findings["log"] == log_name]) == want, doc
        counts = got.integrity[got.integrity["log"] == log_name][list(INTEGRITY_COLUMNS[3:])]
        notes = got.findings[got.findings["status"] == "not_checked"]
        if doc == "state.sqlite":  # the database keeps no counts, nor the checks not made
            assert counts.isna().all(axis=None) and notes.empty
        else:
            assert counts.iloc[0].tolist() == raw_counts.tolist(), doc
            assert set(notes["log"]) == {log_name}
