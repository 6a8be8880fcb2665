"""Issue 33, the fleet's own outputs against what ships send and what a shared folder holds:

1. A symbolic link planted in OUT in place of dracc's own folders (``.runs``, ``cache``)
   was followed: the new set was written out of OUT and the old sets "collected" there
   (files removed). Links in place of ``tables``, ``vessels``, ``.current`` are replaced,
   never followed.
2. Raw ESC and other control characters of a ship's name reached the fleet CSVs, and a
   line break in a name printed a line of its own in the fleet's terminal tables (a fake
   "all within limits" line).
3. The same night came 2-3 times into ``fleet.csv`` (its log and its audit document, the
   same document twice): one night, one set of rows; what was left out is said.
4. SIGTERM in the last moments of ``fleet`` (after publishing) ended the process by the
   signal (exit 143) without a word.
"""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
from test_fleet import CFG, fake_analyser
from test_fleet_documents import _document, _record

from dracc.core import atomic
from dracc.core.errors import ExitCode, OutputError
from dracc.pipeline.fleet import discover, run_fleet
from dracc.pipeline.fleet.query import run_query
from dracc.pipeline.state import StateStore
from dracc.report.fleet_tables import counts_text, input_lines, result_text, write_tables
from dracc.report.terminal import fleet_text
from dracc.report.textout import Layout

EVIL = "Evil\x1b]0;pwned\x07\nall within limits\x1b[2J\r\u202e"  #: OSC, line break, CR, bidi
NIGHT = "2026-05-01"


def _fake_logs(root: Path, vessels: dict[str, list[tuple[str, float]]]) -> Path:
    for vessel, nights in vessels.items():
        (root / vessel).mkdir(parents=True, exist_ok=True)
        for night, lat in nights:
            (root / vessel / f"{night}.nmea").write_text(json.dumps({"night": night, "lat": lat}))
    return root


def _run(tmp_path: Path, inputs: list[Path], out: Path | None = None):
    return run_fleet(
        discover([str(p) for p in inputs]),
        CFG,
        out or tmp_path / "out",
        workers=1,
        analyser=fake_analyser,
    )


def _tree(root: Path) -> dict[str, bytes]:
    return {str(p): p.read_bytes() for p in root.rglob("*") if p.is_file()}


# ------------------------------------------------ 1. OUT's own folders are never followed


@pytest.mark.parametrize("own", [atomic.RUNS, "cache"])
def test_a_link_planted_as_outs_own_folder_is_refused_before_any_log(tmp_path, own):
    """Before: OUT/.runs -> elsewhere put the new set there and removed what else it held
    (the old sets' collection); OUT/cache -> elsewhere read and wrote summaries there."""
    elsewhere = tmp_path / "home"
    (elsewhere / "set-precious").mkdir(parents=True)
    (elsewhere / "set-precious" / "thesis.tex").write_text("years of work")
    (elsewhere / "notes.txt").write_text("keep")
    before = _tree(elsewhere)
    root = _fake_logs(tmp_path / "fleet", {"Aurora": [(NIGHT, 100.0)]})
    out = tmp_path / "out"
    out.mkdir()
    (out / own).symlink_to(elsewhere)
    with pytest.raises(OutputError, match=r"symbolic link .* dracc follows no link there"):
        _run(tmp_path, [root / "Aurora"], out)
    assert not (tmp_path / "fleet" / "calls.log").exists()  # no log was analysed
    assert _tree(elsewhere) == before


def test_a_runs_link_planted_while_the_batch_ran_is_not_followed(tmp_path):
    """The publication itself checks ``.runs`` (the batch may run for hours): exit 6 in
    one line, nothing written or removed where the link leads."""
    elsewhere = tmp_path / "home"
    (elsewhere / "set-precious").mkdir(parents=True)
    (elsewhere / "set-precious" / "thesis.tex").write_text("years of work")
    before = _tree(elsewhere)
    root = _fake_logs(tmp_path / "fleet", {"Aurora": [(NIGHT, 100.0)]})
    res = _run(tmp_path, [root / "Aurora"])
    out = tmp_path / "out"
    write_tables(res, out)  # a first set, published
    first = (out / "fleet.csv").read_bytes()
    os.rename(out / atomic.RUNS, tmp_path / "moved")
    (out / atomic.RUNS).symlink_to(elsewhere)
    with pytest.raises(OutputError) as caught:
        write_tables(res, out)
    assert caught.value.exit_code == ExitCode.OUTPUT and "\n" not in str(caught.value)
    assert _tree(elsewhere) == before
    os.unlink(out / atomic.RUNS)
    os.rename(tmp_path / "moved", out / atomic.RUNS)
    assert (out / "fleet.csv").read_bytes() == first  # the previous set, whole


def test_the_cli_says_one_line_exit_6_for_a_planted_runs_link(run_cli, tmp_path):
    inbox = tmp_path / "inbox"
    inbox.mkdir()
    (inbox / "a.json").write_text(json.dumps(_document("Aurora", NIGHT)))
    out = tmp_path / "out"
    out.mkdir()
    (out / atomic.RUNS).symlink_to(tmp_path)
    code, _, err = run_cli("fleet", inbox, "--out", out, "--workers", "1")
    assert code == ExitCode.OUTPUT and err.count("\n") == 1 and "symbolic link" in err, err


@pytest.mark.parametrize("name", ["tables", "vessels", "fleet.csv", atomic.CURRENT])
def test_links_planted_in_place_of_the_outputs_are_replaced_not_followed(tmp_path, name):
    elsewhere = tmp_path / "elsewhere"
    (elsewhere / "tables").mkdir(parents=True)
    (elsewhere / "fleet.csv").write_text("not dracc's")
    (elsewhere / "tables" / "x").write_text("not dracc's")
    before = _tree(elsewhere)
    root = _fake_logs(tmp_path / "fleet", {"Aurora": [(NIGHT, 100.0)]})
    res = _run(tmp_path, [root / "Aurora"])
    out = tmp_path / "out"
    (out / name).symlink_to(elsewhere / ("tables" if name != "fleet.csv" else "fleet.csv"))
    write_tables(res, out)
    write_tables(res, out)  # and a second set over the first
    assert _tree(elsewhere) == before
    assert os.readlink(out / "tables") == os.path.join(atomic.CURRENT, "tables")
    assert os.readlink(out / atomic.CURRENT).startswith(atomic.RUNS)
    assert "Aurora" in (out / "fleet.csv").read_text()


# -------------------------------------------- 2. names escaped in CSVs and terminal tables


def _evil_result(tmp_path: Path):
    root = _fake_logs(tmp_path / "fleet", {EVIL: [(NIGHT, 100.0)], "Borealis": [(NIGHT, 90.0)]})
    return _run(tmp_path, [root / EVIL, root / "Borealis"])


def test_control_characters_of_a_name_never_reach_the_fleet_csvs_raw(tmp_path):
    res = _evil_result(tmp_path)
    out = tmp_path / "out"
    write_tables(res, out)
    csvs = [out / "fleet.csv", out / "trends.csv", out / "integrity.csv"]
    csvs += sorted((out / "vessels").rglob("*.csv"))
    assert len(csvs) > 4
    for p in csvs:
        text = p.read_text(encoding="utf-8")
        assert not any(c in text for c in "\x1b\x07\r\u202e"), p
        # one record per line: no cell holds a line break
        assert len(text.splitlines()) == len(pd.read_csv(p)) + 1, p
    shown = pd.read_csv(out / "fleet.csv")["vessel"]
    assert r"Evil\x1b]0;pwned\x07\x0aall within limits\x1b[2J\x0d\u202e" in set(shown)
    # Parquet keeps the raw name
    assert EVIL in set(pd.read_parquet(out / "fleet.parquet")["vessel"])


def test_a_line_break_in_a_name_prints_no_line_of_its_own(tmp_path):
    """Before: the fleet table printed 'all within limits…' as a line of its own."""
    res = _evil_result(tmp_path)
    text = fleet_text(dataclasses.replace(res, ranking=pd.DataFrame()), width=300)
    lines = text.splitlines()
    assert not any(line.startswith("all within limits") for line in lines)
    assert not any(c in text for c in "\x1b\x07\r\u202e")
    rows = [line for line in lines if line.startswith("Evil")]
    assert rows and all(r"\x0aall within limits" in line for line in rows)
    failed = dataclasses.replace(
        res, failures=({"vessel": EVIL, "log": "x\n.nmea", "path": "/x", "error": "bad\nline"},)
    )
    said = input_lines(failed)
    assert len(said) == 1 and "\n" not in said[0] and "\x1b" not in said[0]


def test_a_query_result_with_a_line_break_in_a_name_is_one_line_per_row(tmp_path):
    res = _evil_result(tmp_path)
    write_tables(res, tmp_path / "out")
    df = run_query(tmp_path / "out", "SELECT DISTINCT vessel FROM fleet ORDER BY vessel")
    lines = result_text(df, Layout()).splitlines()
    assert len(lines) == 1 + len(df) + 1 and lines[-1] == "(2 rows)"
    assert not any(c in "\n".join(lines) for c in "\x1b\x07\r\u202e")


# ------------------------------------------------- 3. one night, one set of rows


def _one_per_night(table: pd.DataFrame) -> bool:
    ok = table[table["status"] == "ok"]
    return not ok.duplicated(["vessel", "day", "ins_unit", "channel"]).any()


def test_a_night_from_its_log_and_its_audit_document_is_the_logs(tmp_path):
    """Before: fleet.csv held the night twice, once from each."""
    root = _fake_logs(tmp_path / "fleet", {"Aurora": [(NIGHT, 100.0)]})
    inbox = tmp_path / "inbox"
    inbox.mkdir()
    (inbox / "aurora.json").write_text(json.dumps(_document("Aurora", NIGHT)))
    res = _run(tmp_path, [root / "Aurora", inbox])
    assert _one_per_night(res.table) and set(res.table["log"]) == {f"{NIGHT}.nmea"}
    assert (res.analysed, res.documents, res.logs) == (1, 0, 1)
    (dup,) = res.duplicates
    assert dup["log"] == f"aurora.json#{NIGHT}"
    assert dup["why"] == f"night {NIGHT} is analysed from its log Aurora/{NIGHT}.nmea"
    assert counts_text(res).endswith("; 1 night given twice left out")
    assert input_lines(res) == [f"left out: Aurora/aurora.json#{NIGHT} — {dup['why']}"]
    out = tmp_path / "out"
    write_tables(res, out)
    summary = json.loads((out / "fleet.json").read_text())
    assert summary["duplicates"] == 1 and summary["duplicate_inputs"][0]["why"] == dup["why"]
    assert _one_per_night(pd.read_parquet(out / "fleet.parquet"))
    assert len(res.findings) == 0 or not res.findings["log"].str.contains("#").any()


def test_the_same_document_twice_and_a_database_of_the_same_night_give_one_night(tmp_path):
    inbox = tmp_path / "inbox"
    inbox.mkdir()
    doc = json.dumps(_document("Aurora", NIGHT))
    (inbox / "b.json").write_text(doc)
    (inbox / "a-copy.json").write_text(doc)
    with StateStore(tmp_path / "ship.sqlite") as store, store.transaction():
        store.insert_night(_record("Aurora", NIGHT))
        store.insert_night(_record("Aurora", "2026-05-02"))
    res = _run(tmp_path, [tmp_path / "ship.sqlite", inbox])
    assert _one_per_night(res.table)
    # an audit document before a database's night, then the first given
    assert sorted(set(res.table["log"])) == [f"a-copy.json#{NIGHT}", "ship.sqlite#2026-05-02"]
    assert res.documents == 2 and res.logs == 2
    assert sorted(d["log"] for d in res.duplicates) == [f"b.json#{NIGHT}", f"ship.sqlite#{NIGHT}"]
    assert all("is read from Aurora/a-copy.json" in d["why"] for d in res.duplicates)


def test_the_same_log_twice_is_one_log_and_two_logs_of_a_night_stay_two(tmp_path):
    root = _fake_logs(tmp_path / "fleet", {"Aurora": [(NIGHT, 100.0)]})
    log = root / "Aurora" / f"{NIGHT}.nmea"
    (root / "Aurora" / "copy.nmea").write_bytes(log.read_bytes())
    (root / "Aurora" / "other.nmea").write_text(json.dumps({"night": NIGHT, "lat": 120.0}))
    res = _run(tmp_path, [root / "Aurora"])
    assert sorted(set(res.table["log"])) == [f"{NIGHT}.nmea", "other.nmea"]
    (dup,) = res.duplicates
    assert dup["log"] == "copy.nmea" and dup["why"].startswith("the same bytes as Aurora/")
    assert res.analysed + res.cached == 2 and res.logs == 2


# ------------------------------------------------ 4. SIGTERM at the very end of fleet


def test_sigterm_after_the_fleet_published_and_said_so_is_no_silent_143(tmp_path):
    """Before: the signal came in the interpreter's shutdown (0.1-0.5 s after the last
    line) and ended the process by the default action, exit 143, without a word."""
    inbox = tmp_path / "inbox"
    inbox.mkdir()
    for v in ("Aurora", "Borealis"):
        (inbox / f"{v}.json").write_text(json.dumps(_document(v, NIGHT)))
    out = tmp_path / "out"
    p = subprocess.Popen(
        [sys.executable, "-m", "dracc", "fleet", str(inbox), "--out", str(out), "-j", "1"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        seen = b""
        deadline = time.monotonic() + 120
        while b"tables and fleet.html in" not in seen:
            chunk = p.stderr.read1(4096)
            if not chunk or time.monotonic() > deadline:
                pytest.fail(f"fleet never said it was done: {seen!r}")
            seen += chunk
        time.sleep(0.03)  # into what was the interpreter's shutdown (0.7-1.9 s of it)
        p.send_signal(signal.SIGTERM)
        rest = p.communicate(timeout=60)[1]
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    err = (seen + rest).decode()
    assert p.returncode in (ExitCode.OK, ExitCode.INTERRUPTED), (p.returncode, err)
    assert "Traceback" not in err
    if p.returncode == ExitCode.INTERRUPTED:
        assert err.rstrip().splitlines()[-1].startswith("error: interrupted")
    assert json.loads((out / "fleet.json").read_text())["vessels"] == ["Aurora", "Borealis"]
