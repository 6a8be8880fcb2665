"""The SQLite state store: opening, WAL, busy handling, round trips, errors."""

from __future__ import annotations

import math
import sqlite3
from dataclasses import replace

import pytest

from dracc.core.errors import ConfigError, ExitCode, StateError
from dracc.pipeline.state import AprioriEvent, ChannelRow, NightRecord, StateStore


def _record(night: str = "2026-11-20", m_y: float = 100.0, vessel: str = "Aurora") -> NightRecord:
    return NightRecord(
        vessel=vessel,
        night=night,
        content_sha256="c" * 64,
        settings_sha256="s" * 64,
        audited_utc="2026-11-21T00:20:00Z",
        period_start_utc=f"{night}T00:00:00Z",
        period_end_utc=f"{night}T23:59:59Z",
        inputs=("/logs/a.nmea", "/logs/ü.nmea"),
        sources={"ins1": "INS1"},
        lines=1000,
        rejected=3,
        rejected_rate=0.003,
        dr_containment_2m=math.nan,
        dr_n_scored=0,
        compass_error_deg=0.4,
        compass_error_sigma_deg=0.1,
        log_scale=None,
        log_scale_sigma=None,
        findings=({"kind": "limit", "message": "x"},),
        missing=("no reference",),
        channels=(
            ChannelRow("ins1", "course", 24, 0.07, 0.1, -0.2, 0.3),
            ChannelRow("ins1", "lat", 24, m_y / 1.32, m_y, 0.1, 2 * m_y),
        ),
    )


def test_round_trip_nan_as_null_and_channel_order(tmp_path):
    with StateStore(tmp_path / "s.sqlite") as store:
        assert store.journal_mode == "wal"
        with store.transaction():
            store.insert_night(_record())
        got = store.night("Aurora", "2026-11-20")
    assert got.dr_containment_2m is None and got.log_scale is None  # NaN and None stored as NULL
    assert got.inputs == ("/logs/a.nmea", "/logs/ü.nmea") and got.missing == ("no reference",)
    assert [c.channel for c in got.channels] == ["lat", "course"]  # the paper's order
    assert got.channels[0].measure == "m" and got.channels[1].measure == "deg"
    assert got.channels[0].m_u == pytest.approx(100.0 / 1.32)


def test_unique_night_per_vessel(tmp_path):
    with StateStore(tmp_path / "s.sqlite") as store:
        with store.transaction():
            store.insert_night(_record())
            store.insert_night(_record(vessel="Borealis"))
        with pytest.raises(sqlite3.IntegrityError), store.transaction():
            store.insert_night(_record())
        assert store.vessels() == ["Aurora", "Borealis"]
        # deleting a night takes its statistics with it
        with store.transaction():
            assert store.delete_night("Aurora", "2026-11-20")
        assert store.conn.execute("SELECT COUNT(*) FROM unit_stats").fetchone()[0] == 2


def test_apriori_events_replaced_per_vessel(tmp_path):
    with StateStore(tmp_path / "s.sqlite") as store:
        ev = AprioriEvent(
            "Aurora", "ins1", "lat", "2026-11-20", 120.0, None, "established", {"m_y": 120.0}
        )
        other = AprioriEvent("Borealis", "ins1", "lat", "2026-11-20", 90.0, None, "established", {})
        with store.transaction():
            store.replace_apriori_events("Aurora", [ev])
            store.replace_apriori_events("Borealis", [other])
            store.replace_apriori_events("Aurora", [ev])
        assert store.apriori_events("Aurora") == [ev]
        assert len(store.apriori_events()) == 2


def test_second_writer_waits_then_gives_a_clear_error(tmp_path):
    db = tmp_path / "s.sqlite"
    with StateStore(db) as a, StateStore(db, busy_timeout_s=0.2) as b:
        with a.transaction():
            a.insert_night(_record())
            # a reader still sees the committed state (nothing yet)
            assert b.nights() == []
            with pytest.raises(StateError, match="busy or locked"), b.transaction():
                pass
        with b.transaction():
            b.insert_night(_record("2026-11-21"))
        assert [r.night for r in a.nights()] == ["2026-11-20", "2026-11-21"]


def test_not_a_database(tmp_path):
    junk = tmp_path / "junk.sqlite"
    junk.write_bytes(b"this is not a database at all" * 100)
    with pytest.raises(StateError, match=r"junk.sqlite: cannot open the audit database") as e:
        StateStore(junk)
    assert e.value.exit_code == ExitCode.INPUT
    with pytest.raises(ConfigError, match="is a directory"):
        StateStore(tmp_path)


def test_newer_schema_is_refused(tmp_path):
    db = tmp_path / "s.sqlite"
    StateStore(db).close()
    con = sqlite3.connect(db)
    con.execute("UPDATE meta SET value = '99' WHERE key = 'schema'")
    con.commit()
    con.close()
    with pytest.raises(StateError, match="schema 99"):
        StateStore(db)


def _v1_database(db) -> None:
    """A state file as schema 1 wrote it (nights without the DR verdict and measures
    columns), one night."""
    import re

    from dracc.pipeline import state

    v2_only = "|".join([*(name for name, _ in state._NIGHT_COLUMNS_V2), "measures_json"])
    ddl = "\n".join(
        line for line in state._DDL.splitlines() if not re.match(rf"\s+({v2_only})\s", line)
    )
    con = sqlite3.connect(db)
    con.executescript(ddl)
    con.execute("INSERT INTO meta (key, value) VALUES ('schema', '1')")
    con.execute(
        "INSERT INTO nights (vessel, night, content_sha256, settings_sha256, audited_utc, "
        "inputs_json, sources_json, dr_containment_2m, findings_json, missing_json) "
        "VALUES ('Aurora', '2026-11-19', 'c', 's', '2026-11-20T00:20:00Z', '[]', '{}', 0.97, "
        "'[]', '[]')"
    )
    con.commit()
    con.close()


def test_schema_1_database_is_migrated_in_place(tmp_path):
    db = tmp_path / "old.sqlite"
    _v1_database(db)
    cols = {r[1] for r in sqlite3.connect(db).execute("PRAGMA table_info(nights)")}
    assert "dr_verdict" not in cols
    with StateStore(db) as store:
        old = store.night("Aurora", "2026-11-19")
        assert (
            old.dr_containment_2m == 0.97
            and (old.dr_verdict, old.dr_consistent, old.dr_nees) == (None,) * 3
        )
        with store.transaction():
            store.insert_night(
                replace(
                    _record("2026-11-20"),
                    dr_verdict="inconsistent",
                    dr_verdict_text="inconsistent (circle too small): x",
                    dr_consistent=False,
                    dr_nees=80.2,
                )
            )
    con = sqlite3.connect(db)
    assert con.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone()[0] == "3"
    cols = [r[1] for r in con.execute("PRAGMA table_info(nights)")]
    assert cols[-5:] == [
        "dr_verdict",
        "dr_verdict_text",
        "dr_consistent",
        "dr_nees",
        "measures_json",
    ]
    con.close()
    with StateStore(db) as store:  # opening it again changes nothing
        new = store.night("Aurora", "2026-11-20")
        assert (new.dr_verdict, new.dr_consistent, new.dr_nees) == ("inconsistent", False, 80.2)
        assert [r.night for r in store.nights()] == ["2026-11-19", "2026-11-20"]


def test_verdict_round_trip_and_null(tmp_path):
    with StateStore(tmp_path / "s.sqlite") as store:
        with store.transaction():
            store.insert_night(
                replace(
                    _record("2026-11-19"),
                    dr_verdict="conservative",
                    dr_consistent=True,
                    dr_nees=math.nan,
                )
            )
            store.insert_night(_record("2026-11-20"))
        a, b = store.night("Aurora", "2026-11-19"), store.night("Aurora", "2026-11-20")
    assert (a.dr_verdict, a.dr_consistent, a.dr_nees) == ("conservative", True, None)
    assert (b.dr_verdict, b.dr_consistent, b.dr_nees) == (None, None, None)
