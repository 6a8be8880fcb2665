"""The fleet query layer: Hive-partitioned tables under --out/tables/, read back by DuckDB
(names, types, NULL nights), and ``dracc fleet query "SQL"`` (formats, errors)."""

from __future__ import annotations

import datetime
import io
import json
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pytest
from test_audit_helpers import make_analysis

from dracc.core.errors import ExitCode, FleetError
from dracc.pipeline.fleet import FleetResult, LogTask, fleet_table, fleet_trends, summarise
from dracc.pipeline.fleet.query import HIVE_NULL, hive_value, run_query
from dracc.report.fleet_tables import write_tables

duckdb = pytest.importorskip("duckdb")

#: names a vessel folder may have that a path or a Hive reader could mistake
ODD = ["a b", "Søren/x", "p=q", "50%", "北斗丸", "x%2Fy", HIVE_NULL, "=SUM(A1)", "2026", "NULL"]


def _result(vessels: dict[str, list[tuple[str, float]]], failed: tuple[str, ...] = ()):
    """A fleet result from hand-made analyses: {vessel: [(night, m_y lat of ins1)]}, and one
    failed log for each vessel in ``failed``."""
    tasks, summaries, failures = [], {}, {}
    for i, (vessel, nights) in enumerate(vessels.items()):
        for night, lat in nights:
            t = LogTask(vessel, f"/x/{i}/{night}.nmea", f"{night}.nmea", f"{i}{night}".ljust(64))
            tasks.append(t)
            doc = make_analysis(night, m_y={"ins1": {"lat": lat, "lon": 2 * lat}})
            summaries[t.path] = summarise(doc)
        if vessel in failed:
            t = LogTask(vessel, f"/x/{i}/broken.nmea", "broken.nmea", "f" * 64)
            tasks.append(t)
            failures[t.path] = "line 1: not a log"
    table = fleet_table(tasks, summaries, failures, {})
    ranking = pd.DataFrame(
        {
            "vessel": list(vessels),
            "unit": ["ins1"] * len(vessels),
            "quantity": ["m_y lat"] * len(vessels),
            "rank": pd.array(range(1, len(vessels) + 1), dtype="Int64"),
            "since": pd.Series(
                pa.array([datetime.date(2026, 11, 19)] + [None] * (len(vessels) - 1), pa.date32()),
                dtype=pd.ArrowDtype(pa.date32()),
            ),
            "evidence": [json.dumps({"logs": k}) for k in range(len(vessels))],
        }
    )
    return FleetResult(table, fleet_trends(table), (), len(tasks), 0, ranking)


FLEET = {
    "Aurora": [("2026-11-19", 100.0), ("2026-11-20", 140.0)],
    "Borealis": [("2026-11-20", 80.0)],
}


@pytest.fixture
def out(tmp_path) -> Path:
    res = _result(FLEET, failed=("Borealis",))
    write_tables(res, tmp_path / "out")
    return tmp_path / "out"


def test_hive_value_escapes_as_hive():
    assert hive_value("a/b=c%d e") == "a%2Fb%3Dc%25d e"
    assert hive_value("北斗丸") == "北斗丸"
    assert hive_value(None) == HIVE_NULL and hive_value(pd.NA) == HIVE_NULL
    assert hive_value(datetime.date(2026, 1, 2)) == "2026-01-02"
    assert hive_value(HIVE_NULL) == "%5F_HIVE_DEFAULT_PARTITION__"


def test_partition_layout_and_ranking_files(out):
    files = sorted(str(p.relative_to(out / "tables")) for p in (out / "tables").rglob("*.parquet"))
    assert files == [
        "fleet/vessel=Aurora/night=2026-11-19/part-0.parquet",
        "fleet/vessel=Aurora/night=2026-11-20/part-0.parquet",
        "fleet/vessel=Borealis/night=2026-11-20/part-0.parquet",
        f"fleet/vessel=Borealis/night={HIVE_NULL}/part-0.parquet",
        "ranking/vessel=Aurora/part-0.parquet",
        "ranking/vessel=Borealis/part-0.parquet",
        "trends/vessel=Aurora/night=2026-11-19/part-0.parquet",
        "trends/vessel=Aurora/night=2026-11-20/part-0.parquet",
        "trends/vessel=Borealis/night=2026-11-20/part-0.parquet",
    ]
    # published with the rest: out/tables leads into the current set
    assert (out / "tables").is_symlink() and ".current" in str((out / "tables").readlink())
    ranking = pd.read_parquet(out / "ranking.parquet")
    assert ranking["vessel"].tolist() == ["Aurora", "Borealis"]
    assert pd.read_csv(out / "ranking.csv")["since"].tolist()[0] == "2026-11-19"
    # the partition files hold no partition column; every row is in one of them
    part = pd.read_parquet(out / "tables/fleet/vessel=Aurora/night=2026-11-19/part-0.parquet")
    assert "vessel" not in part.columns and "day" not in part.columns
    total = sum(len(pd.read_parquet(p)) for p in (out / "tables" / "fleet").rglob("*.parquet"))
    assert total == len(pd.read_parquet(out / "fleet.parquet"))


def test_odd_vessel_names_round_trip(tmp_path):
    res = _result({v: [("2026-11-20", 100.0 + k)] for k, v in enumerate(ODD)})
    write_tables(res, tmp_path)
    # one folder per vessel, no '/' splitting a name into two levels
    assert len(list((tmp_path / "tables" / "fleet").iterdir())) == len(ODD)
    raw = duckdb.sql(
        f"SELECT DISTINCT vessel FROM read_parquet('{tmp_path}/tables/fleet/**/*.parquet', "
        "hive_partitioning = true, hive_types = {'vessel': VARCHAR, 'night': DATE})"
    ).fetchall()
    assert sorted(r[0] for r in raw) == sorted(ODD)
    got = run_query(tmp_path, "SELECT vessel, m_y FROM fleet WHERE channel = 'lat'")
    assert dict(zip(got["vessel"], got["m_y"], strict=True)) == {
        v: 100.0 + k for k, v in enumerate(ODD)
    }
    ranked = run_query(tmp_path, "SELECT vessel, rank FROM ranking ORDER BY rank")
    assert ranked["vessel"].tolist() == ODD


def test_duckdb_types_and_values_equal_the_flat_table(out):
    types = dict(duckdb_describe(out, "fleet"))
    assert types["period_start_utc"] == "TIMESTAMP WITH TIME ZONE"
    assert types["day"] == "DATE" and types["vessel"] == "VARCHAR"
    assert types["n"] == "BIGINT" and types["m_y"] == "DOUBLE"
    assert dict(duckdb_describe(out, "ranking"))["since"] == "DATE"
    raw = duckdb.sql(
        f"DESCRIBE SELECT * FROM read_parquet('{out}/tables/trends/**/*.parquet', "
        "hive_partitioning = true, hive_types = {'vessel': VARCHAR, 'night': DATE})"
    ).fetchall()
    assert {r[0]: r[1] for r in raw}["night"] == "DATE"
    flat = pd.read_parquet(out / "fleet.parquet")
    view = run_query(out, "SELECT * FROM fleet ORDER BY vessel, period_start_utc NULLS LAST, log")
    assert list(view.columns) == list(flat.columns)
    for col in ("vessel", "log", "status", "ins_unit", "channel"):
        assert view[col].tolist() == flat[col].tolist(), col
    pd.testing.assert_series_equal(view["m_y"], flat["m_y"])
    assert [str(d) for d in view["day"]] == [str(d) for d in flat["day"]]
    assert (view["period_start_utc"].dropna() == flat["period_start_utc"].dropna()).all()


def duckdb_describe(out: Path, view: str) -> list[tuple[str, str]]:
    from dracc.pipeline.fleet.query import connect

    con, _ = connect(out)
    try:
        return [(r[0], r[1]) for r in con.sql(f"DESCRIBE {view}").fetchall()]
    finally:
        con.close()


def test_a_failed_log_has_a_null_night(out):
    raw = duckdb.sql(
        f"SELECT status, night FROM read_parquet('{out}/tables/fleet/**/*.parquet', "
        "hive_partitioning = true, hive_types = {'vessel': VARCHAR, 'night': DATE}) "
        "WHERE log = 'broken.nmea'"
    ).fetchall()
    assert raw == [("failed", None)]
    got = run_query(out, "SELECT vessel, log FROM fleet WHERE day IS NULL")
    assert got.to_dict("records") == [{"vessel": "Borealis", "log": "broken.nmea"}]


def test_a_new_run_replaces_every_partition(out):
    write_tables(_result({"Cassiopeia": [("2026-12-01", 90.0)]}), out)
    assert run_query(out, "SELECT DISTINCT vessel FROM fleet")["vessel"].tolist() == ["Cassiopeia"]


def test_group_by_through_the_cli_as_csv(run_cli, out):
    sql = (
        "SELECT vessel, count(DISTINCT log) AS logs, max(m_y) AS worst_m FROM fleet "
        "WHERE status = 'ok' AND channel = 'lat' GROUP BY vessel ORDER BY worst_m DESC"
    )
    code, text, err = run_cli("fleet", "query", sql, "--out", out, "--format", "csv")
    assert code == ExitCode.OK, err
    got = pd.read_csv(io.StringIO(text))
    t = pd.read_parquet(out / "fleet.parquet")
    t = t[(t["status"] == "ok") & (t["channel"] == "lat")]
    want = t.groupby("vessel").agg(logs=("log", "nunique"), worst_m=("m_y", "max"))
    want = want.sort_values("worst_m", ascending=False).reset_index()
    assert got["vessel"].tolist() == want["vessel"].tolist() == ["Aurora", "Borealis"]
    assert got["logs"].tolist() == want["logs"].tolist() == [2, 1]
    assert got["worst_m"].tolist() == want["worst_m"].tolist()


def test_json_lines_into_a_file_and_the_terminal_table(run_cli, out, tmp_path):
    target = tmp_path / "q" / "result.jsonl"
    sql = "SELECT vessel, log, period_start_utc, day, error FROM fleet ORDER BY vessel, log"
    code, text, err = run_cli(
        "fleet", "query", sql, "-o", out, "--format", "json", "--output", target
    )
    assert code == ExitCode.OK and text == "", err
    rows = [json.loads(line) for line in target.read_text(encoding="utf-8").splitlines()]
    assert len(rows) == len(pd.read_parquet(out / "fleet.parquet"))
    broken = next(r for r in rows if r["log"] == "broken.nmea")
    assert broken["day"] is None and broken["period_start_utc"] is None
    ok = rows[0]
    assert ok["day"] == "2026-11-19" and ok["period_start_utc"].endswith("Z")
    assert ok["error"] is None
    code, text, err = run_cli("fleet", "query", "SELECT vessel, rank FROM ranking", "--out", out)
    assert code == ExitCode.OK, err
    lines = text.splitlines()
    assert lines[0].split() == ["vessel", "rank"] and lines[-1] == "(2 rows)"
    assert lines[1].split() == ["Aurora", "1"]


@pytest.mark.parametrize(
    "sql, words",
    [
        ("SELEC vessel FROM fleet", ["the query failed", "syntax error"]),
        ("SELECT * FROM nowhere", ["the query failed", "nowhere", "fleet, trends, ranking"]),
        ("SELECT no_such_column FROM fleet", ["the query failed", "no_such_column"]),
        ("  ", ["empty"]),
    ],
)
def test_bad_sql_is_one_clear_error(run_cli, out, sql, words):
    code, text, err = run_cli("fleet", "query", sql, "--out", out)
    assert code == ExitCode.USAGE and text == ""
    assert err.startswith("error:") and "Traceback" not in err
    assert all(w in err for w in words), err


def test_a_folder_without_tables_says_so(run_cli, tmp_path):
    (tmp_path / "old").mkdir()
    (tmp_path / "old" / "fleet.json").write_text("{}")
    code, _, err = run_cli("fleet", "query", "SELECT 1", "--out", tmp_path / "old")
    assert code == ExitCode.INPUT and "holds no fleet tables" in err and "Traceback" not in err
    code, _, err = run_cli("fleet", "query", "SELECT 1", "--out", tmp_path / "none")
    assert code == ExitCode.INPUT and "no such folder" in err
    code, _, err = run_cli("fleet", "query", "SELECT 1", "--out", tmp_path, "--format", "xml")
    assert code == ExitCode.USAGE and "--format" in err


def test_a_name_too_long_for_a_folder_is_a_clear_error(tmp_path):
    with pytest.raises(FleetError, match="longer than 255 bytes"):
        write_tables(_result({"%" * 100: [("2026-11-20", 100.0)]}), tmp_path)
    assert not (tmp_path / "tables").exists()  # nothing partial published


def test_fleet_group_help_names_both_commands(run_cli):
    code, text, _ = run_cli("fleet", "--help")
    assert code == ExitCode.OK and "query" in text and "run" in text and "./query" in text


# ------------------------------------- issue 33: the query reads the fleet's tables only

SECRET = "private: the office's passwords"


@pytest.fixture(scope="module")
def shared_out(tmp_path_factory) -> Path:
    """Published fleet outputs that no test of the module changes."""
    out = tmp_path_factory.mktemp("shared") / "out"
    write_tables(_result(FLEET, failed=("Borealis",)), out)
    return out


@pytest.mark.parametrize(
    "sql",
    [
        "SELECT * FROM read_text('{secret}')",
        "SELECT * FROM read_csv('{secret}')",
        "SELECT * FROM glob('{tmp}/*')",
        "COPY (SELECT 1) TO '{out}/fleet.csv'",
        "COPY (SELECT 1) TO '{tmp}/x.csv'",
        "COPY fleet TO '{out}/tables/fleet/x.parquet'",
        "EXPORT DATABASE '{tmp}/exported'",
        "ATTACH '{tmp}/new.db'",
        "INSTALL httpfs",
        "LOAD httpfs",
        "SET enable_external_access = true",
        "RESET enable_external_access",
        "SET temp_directory = '{tmp}/spill'",
        "SET enable_external_access = true; SELECT * FROM read_text('{secret}')",
        "SELECT * FROM 'https://example.com/x.csv'",
    ],
)
def test_a_query_beyond_the_fleet_tables_is_refused(
    run_cli, shared_out, tmp_path, monkeypatch, sql
):
    """Issue 33: read_text read a private file, COPY … TO replaced the published fleet.csv,
    ATTACH created a database, extensions installed themselves: each is refused in one
    line (exit 2) that says what is allowed, and nothing is written anywhere."""
    out = shared_out
    monkeypatch.chdir(tmp_path)  # ATTACH 'new.db' and DuckDB's spill folder would land here
    secret = tmp_path / "secret.txt"
    secret.write_text(SECRET)
    before = _tree(tmp_path)
    published = (out / "fleet.csv").read_bytes()
    query = sql.format(secret=secret, tmp=tmp_path, out=out)
    code, text, err = run_cli("fleet", "query", query, "--out", out)
    assert code == ExitCode.USAGE and text == "", err
    assert err.count("\n") == 1 and err.startswith("error: the query failed:"), err
    assert "refused; dracc fleet query only reads the views" in err, err
    assert SECRET not in err
    assert _tree(tmp_path) == before
    assert (out / "fleet.csv").read_bytes() == published


def _tree(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` (through no link) and its bytes."""
    return {str(p): p.read_bytes() for p in root.rglob("*") if p.is_file() and not p.is_symlink()}


def test_queries_that_stay_in_the_tables_still_work(run_cli, shared_out):
    """Several statements, a temporary table, a macro: all in memory, all allowed."""
    sql = (
        "CREATE TEMP TABLE w AS SELECT vessel, max(m_y) AS worst FROM fleet GROUP BY vessel; "
        "CREATE MACRO twice(x) AS 2 * x; SELECT vessel, twice(worst) AS w2 FROM w ORDER BY 1"
    )
    code, text, err = run_cli("fleet", "query", sql, "--out", shared_out, "--format", "csv")
    assert code == ExitCode.OK, err
    assert pd.read_csv(io.StringIO(text))["vessel"].tolist() == ["Aurora", "Borealis"]


def test_a_tables_link_out_of_the_folder_is_not_followed(run_cli, out, tmp_path):
    """A ``tables`` planted in DIR that leads elsewhere is not read (exit 3)."""
    elsewhere = tmp_path / "elsewhere"
    write_tables(_result({"Intruder": [("2026-11-20", 1.0)]}), elsewhere)
    (out / "tables").unlink()
    (out / "tables").symlink_to(elsewhere.resolve() / "tables")
    code, text, err = run_cli("fleet", "query", "SELECT vessel FROM fleet", "--out", out)
    assert code == ExitCode.INPUT and "leads out of" in err and "Intruder" not in text


def test_a_linked_file_among_the_tables_is_not_read(run_cli, out, tmp_path):
    secret = tmp_path / "secret.parquet"
    secret.write_bytes((out / "fleet.parquet").read_bytes())
    (out / "tables" / "fleet" / "vessel=Aurora" / "night=2026-11-19" / "x.parquet").symlink_to(
        secret
    )
    code, _, err = run_cli("fleet", "query", "SELECT 1 FROM fleet", "--out", out)
    assert code == ExitCode.INPUT and "not a file dracc wrote" in err


def test_an_interrupt_stops_a_long_query_at_once(shared_out):
    """Ctrl-C (or SIGTERM, which dracc turns into the same) during a query that would run
    for minutes ends it within seconds: DuckDB only sees an interrupt it is told of."""
    import _thread
    import threading
    import time

    timer = threading.Timer(1.0, _thread.interrupt_main)
    t0 = time.monotonic()
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            run_query(shared_out, "SELECT count(*) FROM range(1000000000000) a, range(10) b")
    finally:
        timer.cancel()
    assert time.monotonic() - t0 < 10.0


def test_out_of_memory_says_nothing_spills_to_disk():
    """No temp_directory: a query larger than memory fails in one line saying so, where
    DuckDB's own message suggests a SET that is refused."""
    from dracc.pipeline.fleet.query import _one_line

    e = duckdb.OutOfMemoryException(
        "Out of Memory Error: could not allocate block of size 256.0 KiB (95.2 MiB/95.3 MiB "
        "used)\nDatabase is launched in in-memory mode and no temporary directory is "
        "specified.\nUnused blocks cannot be offloaded to disk.\n\nLaunch the database with "
        "a persistent storage back-end\nOr set SET temp_directory='/path"
    )
    msg = _one_line(duckdb, e, "out", ["fleet"])
    assert "\n" not in msg and "temp_directory" not in msg
    assert msg.startswith("Out of Memory Error: could not allocate block of size 256.0 KiB")
    assert msg.endswith("it spills nothing to disk; narrow it (WHERE, fewer columns)")
