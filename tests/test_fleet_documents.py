"""Audit documents and state databases as fleet inputs (edge-first), without raw logs."""

from __future__ import annotations

import hashlib
import json
import sqlite3

import pytest

from dracc.core.config import Config
from dracc.pipeline.fleet import discover, run_fleet
from dracc.pipeline.fleet.documents import expand_documents, sniff
from dracc.pipeline.state import ChannelRow, NightRecord, StateStore

MEASURES = {
    "position": {"lat_deg": 54.5, "lon_deg": 18.7},
    "rows": [
        {
            "unit": "ins1",
            "quantity": "lat_m_y",
            "measure_unit": "m",
            "value": 230.5,
            "sigma": None,
            "dof": 5.0,
            "n": 25,
            "method": "reference",
        },
        {
            "unit": "log",
            "quantity": "log_scale",
            "measure_unit": "%",
            "value": 2.1,
            "sigma": 0.6,
            "dof": None,
            "n": 140,
            "method": "calibration",
        },
    ],
}


def _record(vessel: str, night: str, measures=MEASURES) -> NightRecord:
    return NightRecord(
        vessel=vessel,
        night=night,
        content_sha256="c" * 64,
        settings_sha256="s" * 64,
        audited_utc=f"{night}T23:59:00Z",
        period_start_utc=f"{night}T00:00:00Z",
        period_end_utc=f"{night}T23:59:59Z",
        inputs=("x.nmea",),
        sources={"ins1": "INS1"},
        lines=1000,
        rejected=2,
        rejected_rate=0.002,
        dr_containment_2m=0.96,
        dr_n_scored=100,
        compass_error_deg=0.3,
        compass_error_sigma_deg=0.1,
        log_scale=0.021,
        log_scale_sigma=0.006,
        findings=(),
        missing=(),
        channels=(ChannelRow("ins1", "lat", 25, 170.0, 224.0, 0.1, 500.0),),
        dr_consistent=True,
        dr_nees=20.0,
        measures=measures,
    )


def _document(vessel: str, night: str, factor: float = 1.0) -> dict:
    measures = json.loads(json.dumps(MEASURES))
    measures["rows"][0]["value"] *= factor
    return {
        "schema": "dracc.audit/1",
        "vessel": vessel,
        "night": night,
        "verdict": "ok",
        "logs": {
            "files": ["x.nmea"],
            "lines": 1000,
            "rejected": 2,
            "period": {"start_utc": f"{night}T00:00:00Z", "end_utc": f"{night}T23:59:59Z"},
        },
        "sources": {"ins1": "INS1"},
        "ins": [
            {
                "unit": "ins1",
                "channel": "lat",
                "n": 25,
                "m_u": 170.0,
                "m_y": 224.0,
                "kurtosis": 0.1,
                "limit_error": 500.0,
            }
        ],
        "dead_reckoning": {
            "containment_2m": 0.96,
            "n_scored": 100,
            "consistent": True,
            "nees": 20.0,
        },
        "calibration": {
            "compass_error_deg": 0.3,
            "compass_error_sigma_deg": 0.1,
            "log_scale": 0.021,
            "log_scale_sigma": 0.006,
        },
        "missing": [],
        "measures": measures,
        "analysis": None,
    }


def test_sniff_by_content_not_name(tmp_path):
    (tmp_path / "a.txt").write_text(json.dumps(_document("A", "2026-05-01")))
    (tmp_path / "b.json").write_text('{"schema": "dracc.analysis/1"}')
    (tmp_path / "c.nmea").write_text("$GPGGA,1*00\n")
    with StateStore(tmp_path / "d.bin") as store:
        assert store.journal_mode == "wal"
    assert sniff(str(tmp_path / "a.txt")) == "audit-json"
    assert sniff(str(tmp_path / "b.json")) is None
    assert sniff(str(tmp_path / "c.nmea")) is None
    assert sniff(str(tmp_path / "d.bin")) == "state-db"


def test_documents_and_databases_become_nights_and_the_database_is_not_touched(tmp_path):
    inbox = tmp_path / "inbox"
    inbox.mkdir()
    for k, night in enumerate(("2026-05-01", "2026-05-02")):
        (inbox / f"A-{k}.json").write_text(json.dumps(_document("Aurora", night)))
    db = tmp_path / "ship.sqlite"
    with StateStore(db) as store, store.transaction():
        for night in ("2026-05-01", "2026-05-02", "2026-05-03"):
            store.insert_night(_record("Borealis", night))
    before = hashlib.sha256(db.read_bytes()).hexdigest()
    tasks, summaries, failures = expand_documents(discover([str(inbox), str(db)]))
    assert not failures
    assert sorted((t.vessel, t.log) for t in tasks) == [
        ("Aurora", "A-0.json#2026-05-01"),
        ("Aurora", "A-1.json#2026-05-02"),
        ("Borealis", "ship.sqlite#2026-05-01"),
        ("Borealis", "ship.sqlite#2026-05-02"),
        ("Borealis", "ship.sqlite#2026-05-03"),
    ]
    assert all(s["measures"] == MEASURES for s in summaries.values())
    assert hashlib.sha256(db.read_bytes()).hexdigest() == before  # read-only


def test_fleet_from_documents_alone(tmp_path):
    inbox = tmp_path / "inbox"
    inbox.mkdir()
    for i, v in enumerate(("A", "B", "C", "D", "E")):
        for k, night in enumerate(("2026-05-01", "2026-05-02", "2026-05-03")):
            factor = 3.0 if v == "E" else 1.0 + 0.03 * ((i + 2 * k) % 3 - 1)
            (inbox / f"{v}-{night}.json").write_text(json.dumps(_document(v, night, factor)))
    res = run_fleet(discover([str(inbox)]), Config(), tmp_path / "out", workers=1)
    assert res.analysed == 0 and res.cached == 0 and not res.failures
    assert set(res.table["vessel"]) == {"A", "B", "C", "D", "E"}
    assert res.table["day"].astype(str).tolist().count("2026-05-02") == 5
    r = res.ranking
    # the log scale is 2.1 % on every ship every night: not ranked; E's INS1 heads the list
    assert set(r.quantity) == {"lat_m_y"} and len(r) == 5
    assert (r.iloc[0].vessel, r.iloc[0].ins_unit) == ("E", "ins1") and r.iloc[0].score > 5


def test_a_damaged_document_is_one_failure_and_the_rest_goes_on(tmp_path):
    inbox = tmp_path / "inbox"
    inbox.mkdir()
    (inbox / "good.json").write_text(json.dumps(_document("A", "2026-05-01")))
    (inbox / "cut.json").write_text(json.dumps(_document("A", "2026-05-02"))[:-40])
    res = run_fleet(discover([str(inbox)]), Config(), tmp_path / "out", workers=1)
    assert len(res.failures) == 1 and "not a readable audit document" in res.failures[0]["error"]
    assert (res.table["status"] == "ok").sum() >= 1


def test_a_schema_2_database_is_read_and_migrated_by_the_audit(tmp_path):
    """An older ship database (schema 2, no measures) reads ashore; the next audit on
    board migrates it to 3 in place."""
    db = tmp_path / "old.sqlite"
    with StateStore(db) as store, store.transaction():
        store.insert_night(_record("C", "2026-05-01", measures=None))
    con = sqlite3.connect(db)
    con.execute("ALTER TABLE nights DROP COLUMN measures_json")
    con.execute("UPDATE meta SET value = '2' WHERE key = 'schema'")
    con.commit()
    con.close()
    tasks, summaries, failures = expand_documents(discover([str(db)]))
    assert not failures and len(tasks) == 1
    assert next(iter(summaries.values()))["measures"] == {}
    with StateStore(db) as store:  # the audit's own open migrates
        assert store.nights()[0].measures is None
    con = sqlite3.connect(db)
    assert con.execute("SELECT value FROM meta WHERE key='schema'").fetchone() == ("3",)
    con.close()


def test_a_database_of_another_schema_is_a_clear_failure(tmp_path):
    db = tmp_path / "x.sqlite"
    con = sqlite3.connect(db)
    con.execute("CREATE TABLE meta (key TEXT, value TEXT)")
    con.execute("INSERT INTO meta VALUES ('schema', '99')")
    con.commit()
    con.close()
    _, _, failures = expand_documents(discover([str(db)]))
    assert next(iter(failures.values())).endswith("is not 1 to 3")


@pytest.mark.parametrize(
    "fields",
    [
        {"verdict": "no data"},
        # a run that ended without a verdict (dracc.report.audit_failed): night may be null
        {"verdict": "failed", "status": "failed", "night": None},
    ],
)
def test_a_night_without_data_adds_no_row(tmp_path, fields):
    doc = {**_document("A", "2026-05-01"), **fields}
    (tmp_path / "n.json").write_text(json.dumps(doc))
    tasks, summaries, failures = expand_documents(discover([str(tmp_path / "n.json")]))
    assert tasks == [] and summaries == {} and failures == {}


def test_an_oversized_document_is_refused_without_reading_it(tmp_path, monkeypatch):
    import dracc.pipeline.fleet.documents as documents

    monkeypatch.setattr(documents, "MAX_DOCUMENT_BYTES", 1000)
    (tmp_path / "big.json").write_text(json.dumps(_document("A", "2026-05-01")) + " " * 2000)
    _, summaries, failures = expand_documents(discover([str(tmp_path / "big.json")]))
    assert summaries == {} and "is not a nightly audit document" in next(iter(failures.values()))
