"""A bad command-line option value exits 2 in every command (README "Exit codes"), with
one clear error line and no traceback; a bad configuration file stays 4, unreadable
input 3."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

from dracc.core.errors import ExitCode

HAS_DASK = importlib.util.find_spec("distributed") is not None

#: (command and arguments, the words the error names); LOG, DIR, DB and OUT are filled in
BAD = [
    # records
    (["records", "LOG", "--out", "OUT/x.xlsx"], ["--out", ".parquet", ".csv"]),
    # analyze
    (["analyze", "LOG", "--date", "1/3/2026"], ["--date", "YYYY-MM-DD"]),
    (["analyze", "LOG", "--date", "2023-02-30"], ["--date", "YYYY-MM-DD"]),
    (["analyze", "LOG", "--interval", "abc"], ["--interval"]),
    (["analyze", "LOG", "--window", "0"], ["--window", "positive"]),
    (["analyze", "LOG", "--role", "GP=radar"], ["--role", "gnss"]),
    (["analyze", "LOG", "--role", "GP"], ["--role", "KEY=ROLE"]),
    (["analyze", "LOG", "--dr-reset", "sometimes"], ["--dr-reset"]),
    (["analyze", "LOG", "--probability", "1.5"], ["--probability"]),
    (["analyze", "LOG", "--probability", "likely"], ["--probability"]),
    (["analyze", "LOG", "--epoch-interval", "-5min"], ["--epoch-interval"]),
    (["analyze", "LOG", "--variation", "200"], ["--variation"]),
    (["analyze", "LOG", "--fix-role", "moon"], ["--fix-role"]),
    # inspect
    (["inspect", "LOG", "--date", "2023-02-30"], ["--date", "YYYY-MM-DD"]),
    # audit run (and its alias), audit history
    (["audit", "run", "DIR", "--db", "DB", "--date", "20-11-2026"], ["--date", "YYYY-MM-DD"]),
    (["audit", "DIR", "--db", "DB", "--date", "2026-02-30"], ["--date", "YYYY-MM-DD"]),
    (
        ["audit", "DIR", "--db", "DB", "--date", "2026-11-20", "--pattern", "/var/log/*.nmea"],
        ["--pattern", "relative"],
    ),
    (["audit", "history", "--db", "DB", "--unit", "ins4"], ["--unit", "ins1, ins2, ins3"]),
    (["audit", "history", "--db", "DB", "--channel", "speed"], ["--channel", "lat, lon, course"]),
    (["audit", "history", "--db", "DB", "--vessel", "Nobody"], ["--vessel", "Aurora"]),
    # fleet
    (["fleet", "LOG", "--out", "OUT", "--workers", "0"], ["--workers"]),
    (
        ["fleet", "LOG", "--out", "OUT", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"],
        ["--workers", "--scheduler"],
    ),
    pytest.param(
        ["fleet", "LOG", "--out", "OUT", "--scheduler", "nonsense"],
        ["--scheduler", "port"],
        marks=pytest.mark.skipif(not HAS_DASK, reason="needs dask distributed"),
    ),
    pytest.param(
        ["fleet", "LOG", "--out", "OUT", "--scheduler", "foo://x:1"],
        ["--scheduler", "scheme"],
        marks=pytest.mark.skipif(not HAS_DASK, reason="needs dask distributed"),
    ),
    (["fleet", "DIR", "--out", "OUT", "--pattern", "/abs/*.nmea"], ["--pattern"]),
    # fix
    (["fix", "--fix", "abc"], ["--fix"]),
    (["fix", "--fix", "54.6,18.8", "--prior", "x"], ["--prior"]),
    (["fix", "--range", "54.6,18.8,2.4"], ["--range", "unit"]),
    # simulate (no configuration file: every value it cannot use is an option's)
    (["simulate", "--out", "OUT", "--hours", "-1"], ["--hours"]),
    (["simulate", "--out", "OUT", "--hours", "many"], ["--hours"]),
    (["simulate", "--out", "OUT", "--format", "docx"], ["--format"]),
    (["simulate", "--out", "OUT", "--form", "fancy"], ["--form"]),
    (["simulate", "--out", "OUT", "--compass", "brass"], ["compass"]),
    (["simulate", "--out", "OUT", "--start", "yesterday"], ["start"]),
    (["simulate", "--out", "OUT", "--legs", "0:60,x"], ["--legs"]),
    (["simulate", "--out", "OUT", "--segment-hours", "0"], ["--segment-hours"]),
    (["simulate", "--out", "OUT", "--fault", "jmp"], ["--fault", "jmp"]),
    (["simulate", "--out", "OUT", "--fault", "jump:GNSS@5h"], ["--fault"]),
    # watch (a bad value before any socket is opened)
    (["watch", "udp://127.0.0.1:0", "--dropout", "0"], ["--dropout", "positive"]),
    (["watch", "udp://127.0.0.1:0", "--stale", "0"], ["--dropout", "positive"]),  # its old name
]


@pytest.fixture
def places(run_cli, tmp_path):
    """LOG: a small file; DIR: an empty folder; DB: an audit database with vessel Aurora;
    OUT: a folder that does not exist yet."""
    log = tmp_path / "x.nmea"
    log.write_text("$GPGGA,000000.00,5436.000,N,01848.000,E,1,08,1.0,0.0,M,0.0,M,,*00\n")
    folder = tmp_path / "empty"
    folder.mkdir()
    db = tmp_path / "a.sqlite"
    code, _, _ = run_cli("audit", folder, "--date", "2026-11-19", "--db", db, "--vessel", "Aurora")
    assert code == ExitCode.INPUT  # a night without data: the database holds vessel Aurora
    return {"LOG": str(log), "DIR": str(folder), "DB": str(db), "OUT": str(tmp_path / "out")}


def _ids():
    out = []
    for case in BAD:
        args = case.values[0] if hasattr(case, "values") else case[0]
        out.append(" ".join(a for a in args if a not in ("LOG", "DIR", "DB", "OUT")))
    return out


@pytest.mark.parametrize("args, words", BAD, ids=_ids())
def test_bad_option_value_exits_2(run_cli, places, args, words):
    code, out, err = run_cli(*[places.get(a, a) for a in args])
    assert code == ExitCode.USAGE, err
    assert "Traceback" not in err and out == ""
    said = [ln for ln in err.splitlines() if ln.lower().startswith("error:")]
    assert len(said) == 1, err  # one error line (click's own errors add their usage lines)
    assert all(w in said[0] for w in words), said[0]
    out_dir = Path(places["OUT"])
    written = [p for p in out_dir.rglob("*") if p.is_file()] if out_dir.exists() else []
    assert written == []  # nothing was written
    assert [p.name for p in Path(places["DIR"]).iterdir()] == []


def test_every_command_is_covered():
    import typer.main

    import dracc.cli.main  # noqa: F401  (registers every command)
    from dracc.cli.app import app

    covered = {(c.values[0] if hasattr(c, "values") else c[0])[0] for c in BAD}
    assert set(typer.main.get_command(app).commands) <= covered


def test_audit_history_bad_unit_before_the_database(run_cli, tmp_path):
    code, _, err = run_cli("audit", "history", "--db", tmp_path / "none.sqlite", "--unit", "INS9")
    assert code == ExitCode.USAGE and "--unit 'INS9'" in err


def test_a_bad_config_file_stays_4_and_unreadable_input_3(run_cli, places, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[deviation]\nprobability = 2.0\n")
    # the file is wrong, not the option: exit 4 even with good option values
    code, _, err = run_cli("analyze", places["LOG"], "--config", bad, "--probability", "0.9")
    assert code == ExitCode.CONFIG and "[deviation] probability" in err
    code, _, err = run_cli("audit", places["DIR"], "--db", places["DB"], "--config", bad)
    assert code == ExitCode.CONFIG
    pattern = tmp_path / "pattern.toml"
    pattern.write_text('[audit]\npattern = "/var/log/*.nmea"\n')
    code, _, err = run_cli("audit", places["DIR"], "--db", places["DB"], "--config", pattern)
    assert code == ExitCode.CONFIG and "[audit] pattern" in err
    code, _, err = run_cli("analyze", tmp_path / "nope.nmea")
    assert code == ExitCode.INPUT and "no such file" in err
    code, _, err = run_cli("inspect", tmp_path / "nope.nmea", "--date", "2026-11-20")
    assert code == ExitCode.INPUT


@pytest.mark.parametrize(
    "args",
    [
        ["simulate", "--out", "OUT", "--fault", "jump=-3m"],
        ["analyze", "LOG", "--role", "X=radar"],
    ],
)
def test_bad_option_value_exits_2_in_the_real_process(places, args):
    r = subprocess.run(
        [sys.executable, "-m", "dracc", *[places.get(a, a) for a in args]],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2, r.stderr
    assert r.stderr.startswith("error:") and len(r.stderr.strip().splitlines()) == 1
    assert "Traceback" not in r.stderr and r.stdout == ""
