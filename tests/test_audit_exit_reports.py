"""Issue 32: every exit path of `dracc audit` leaves tonight's --summary, --json and --html.

Cron mails the summary file when the exit code is not 0 (the README's line: `dracc audit …
--summary last-audit.txt || mail -s "dracc audit: exit $?" … < last-audit.txt`).  Each test
starts from last night's reports ("8 findings") and checks that after the run they are
tonight's (or gone), and say why: exit 0 and 1 as before, exit 3 (no logs for the night;
logs with nothing usable), exit 4 (configuration errors), exit 5 (a bug), interrupted by
SIGINT or SIGTERM (exit 130), and the whole cron line under `env -i`.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import jsonschema
import pytest
from conftest import SPARSE_RATES

import dracc.pipeline.audit.run as audit_mod
from dracc.cli.main import main
from dracc.core.errors import ExitCode
from dracc.report import audit_failed
from dracc.report.audit_json import load_schema

NIGHT = "2026-11-18"
STALE = "dracc audit: Aurora, night 2026-11-17: 8 findings\n"
LOOSE = (
    "[audit]\nlimits = { all = { lat_m = 1e9, lon_m = 1e9, course_deg = 1e3 } }\n"
    'required_sources = ["ins1", "ins2", "ins3"]\n'
    "log_scale_max_pct = 10.0\ncompass_error_max_deg = 5.0\n"
)
TIGHT = (
    "[audit]\nlimits = { all = { lat_m = 1.0, lon_m = 1.0, course_deg = 0.0001 } }\n"
    "accuracy_window_h = 6.0\n"
)


@pytest.fixture(scope="module")
def night_log(tmp_path_factory) -> Path:
    """One simulated 8 h night (low rates), as tests/test_audit_cli.py uses."""
    root = tmp_path_factory.mktemp("ship")
    code = main(
        [
            "simulate", "--out", str(root), "--hours", "8", "--seed", "11",
            "--start", f"{NIGHT}T00:00:00Z", "--name", f"nav-{NIGHT}", *SPARSE_RATES,
        ]
    )  # fmt: skip
    assert code == 0
    return root / f"nav-{NIGHT}.nmea"


def _stale(folder: Path) -> dict[str, Path]:
    """Last night's three reports in ``folder``."""
    paths = {
        "summary": folder / "last-audit.txt",
        "json": folder / "last-audit.json",
        "html": folder / "last-audit.html",
    }
    paths["summary"].write_text(STALE)
    paths["json"].write_text(json.dumps({"schema": "dracc.audit/1", "night": "2026-11-17"}))
    paths["html"].write_text("<html><body>8 findings (2026-11-17)</body></html>")
    return paths


def _report_args(paths: dict[str, Path]) -> list[str]:
    return [
        "--summary", str(paths["summary"]),
        "--json", str(paths["json"]),
        "--html", str(paths["html"]),
    ]  # fmt: skip


def _cfg(tmp_path: Path, text: str) -> str:
    p = tmp_path / "dracc.toml"
    p.write_text(text)
    return str(p)


def _run(capsys, *args) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def _check_failed(paths: dict[str, Path], code: int, words: str, night: str | None) -> dict:
    """Tonight's three reports of a failed run: the summary's first line says why."""
    summary = paths["summary"].read_text()
    first = summary.splitlines()[0]
    assert first.startswith(f"dracc audit: FAILED, exit {code} ("), first
    assert words in first, first
    assert "2026-11-17" not in summary and "8 findings" not in summary
    assert summary.rstrip().splitlines()[-1].startswith(f"exit {code} (")
    assert f"night: {night}" in summary if night else "night: not determined" in summary
    assert "ended: 20" in summary and "logs: " in summary
    doc = json.loads(paths["json"].read_text())
    jsonschema.validate(doc, load_schema())
    assert (doc["status"], doc["verdict"], doc["exit_code"]) == ("failed", "failed", code)
    error = doc["error"]
    assert error["exit_code"] == code and words in f"{error['kind']}: {error['message']}"
    assert doc["night"] == night and doc["state"] == "not recorded" and doc["findings"] == []
    assert doc["error"]["inputs"]["logs"] and doc["audited_utc"].endswith("Z")
    page = paths["html"].read_text()
    assert f"FAILED, exit {code}" in page and "8 findings" not in page
    assert not list(paths["summary"].parent.glob(".*.part"))  # atomic: no temporary left
    return doc


def test_exit_0_writes_tonights_reports(capsys, night_log, tmp_path):
    paths = _stale(tmp_path)
    code, _, err = _run(
        capsys, "audit", night_log, "--db", tmp_path / "s.sqlite", "--vessel", "Aurora",
        "--config", _cfg(tmp_path, LOOSE), *_report_args(paths),
    )  # fmt: skip
    assert code == ExitCode.OK, err
    text = paths["summary"].read_text()
    assert text.startswith(f"dracc audit: Aurora, night {NIGHT}: all checks made passed")
    doc = json.loads(paths["json"].read_text())
    jsonschema.validate(doc, load_schema())
    assert (doc["verdict"], doc["night"], doc["exit_code"]) == ("ok", NIGHT, 0)
    assert "status" not in doc and "error" not in doc  # an audited night: as before
    assert "all checks made passed" in paths["html"].read_text()


def test_exit_1_writes_tonights_reports(capsys, night_log, tmp_path):
    paths = _stale(tmp_path)
    code, _, err = _run(
        capsys, "audit", night_log, "--db", tmp_path / "s.sqlite",
        "--config", _cfg(tmp_path, TIGHT), *_report_args(paths),
    )  # fmt: skip
    assert code == ExitCode.FINDINGS, err
    first = paths["summary"].read_text().splitlines()[0]
    assert first.startswith(f"dracc audit: default, night {NIGHT}: ") and "findings" in first
    doc = json.loads(paths["json"].read_text())
    jsonschema.validate(doc, load_schema())
    assert (doc["verdict"], doc["night"], doc["exit_code"]) == ("findings", NIGHT, 1)
    assert doc["findings"]


def test_exit_3_logs_with_nothing_usable(capsys, tmp_path):
    paths = _stale(tmp_path)
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "junk-2026-11-20.nmea").write_bytes(b"\x00\x01 no sentences here\n" * 50)
    code, out, err = _run(
        capsys, "audit", logs, "--date", "2026-11-20", "--db", tmp_path / "s.sqlite",
        *_report_args(paths),
    )  # fmt: skip
    assert code == ExitCode.INPUT and err.startswith("error:") and out == ""
    doc = _check_failed(paths, 3, "no usable data", "2026-11-20")
    assert err.strip() == f"error: {doc['error']['message']}"  # the same message as stderr
    assert doc["error"]["inputs"]["logs"] == [str(logs)]
    assert not (tmp_path / "s.sqlite").exists()  # nothing recorded, as before


def test_exit_3_folder_without_the_nights_logs(capsys, tmp_path):
    """A night without logs is recorded (as before): its reports say NO DATA."""
    paths = _stale(tmp_path)
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "nav-2026-11-19.nmea").write_text("")  # another night's log
    code, _, _ = _run(
        capsys, "audit", logs, "--date", "2026-11-20", "--db", tmp_path / "s.sqlite",
        *_report_args(paths),
    )  # fmt: skip
    assert code == ExitCode.INPUT
    first = paths["summary"].read_text().splitlines()[0]
    assert first.startswith("dracc audit: default, night 2026-11-20: NO DATA")
    doc = json.loads(paths["json"].read_text())
    jsonschema.validate(doc, load_schema())
    assert (doc["verdict"], doc["night"], doc["exit_code"]) == ("no data", "2026-11-20", 3)
    assert "NO DATA" in paths["html"].read_text().upper()


@pytest.mark.parametrize(
    "config, db, words",
    [
        ("[audit]\nthreshold = 3\n", True, "[audit] unknown key(s): threshold"),
        ("[vessel]\nname = 'Aurora'\n", False, "no audit database"),
    ],
)
def test_exit_4_configuration_error(capsys, tmp_path, config, db, words):
    paths = _stale(tmp_path)
    logs = tmp_path / "logs"
    logs.mkdir()
    cfg = _cfg(tmp_path, config)
    code, _, err = _run(
        capsys, "audit", logs, "--date", NIGHT, "--config", cfg, "--vessel", "Aurora",
        *(["--db", tmp_path / "s.sqlite"] if db else []), *_report_args(paths),
    )  # fmt: skip
    assert code == ExitCode.CONFIG and words in err
    doc = _check_failed(paths, 4, "configuration error", NIGHT)
    assert words in paths["summary"].read_text().splitlines()[0]
    assert doc["vessel"] == "Aurora" and doc["error"]["inputs"]["config"] == cfg
    assert "Aurora" in paths["summary"].read_text() and cfg in paths["summary"].read_text()


def test_exit_4_night_of_a_folder_without_date_is_yesterday(capsys, tmp_path):
    paths = _stale(tmp_path)
    (tmp_path / "logs").mkdir()
    code, _, _ = _run(
        capsys, "audit", tmp_path / "logs", "--config", _cfg(tmp_path, "[audit]\nx = 1\n"),
        *_report_args(paths),
    )  # fmt: skip
    assert code == ExitCode.CONFIG
    doc = _check_failed(paths, 4, "unknown key", audit_mod.yesterday_utc())
    assert doc["vessel"] is None


def test_interrupted_in_process(capsys, monkeypatch, tmp_path):
    paths = _stale(tmp_path)
    log = tmp_path / f"nav-{NIGHT}.nmea"
    log.write_text("$GPZDA,000000.00,18,11,2026,00,00*6B\n")

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(audit_mod, "analyse_voyage", interrupted)
    code, _, err = _run(capsys, "audit", log, "--db", tmp_path / "s.sqlite", *_report_args(paths))
    assert code == ExitCode.INTERRUPTED and "interrupted" in err
    _check_failed(paths, 130, "interrupted", None)  # files only: the logs' dates would say


def test_internal_error_and_a_page_that_cannot_be_rendered(capsys, monkeypatch, tmp_path):
    """Exit 5 (a bug) writes tonight's reports too; a report that cannot be written is
    removed, never left from an earlier night."""
    paths = _stale(tmp_path)
    log = tmp_path / f"nav-{NIGHT}.nmea"
    log.write_text("x\n")

    def bug(*args, **kwargs):
        raise RuntimeError("a bug")

    def no_page(f):
        raise OSError("disk full")

    monkeypatch.setattr(audit_mod, "analyse_voyage", bug)
    monkeypatch.setattr(audit_failed, "failed_page", no_page)
    code, _, err = _run(
        capsys, "audit", log, "--date", NIGHT, "--db", tmp_path / "s.sqlite",
        *_report_args(paths),
    )  # fmt: skip
    assert code == ExitCode.INTERNAL and "RuntimeError: a bug" in err
    assert not paths["html"].exists()  # last night's page is gone
    first = paths["summary"].read_text().splitlines()[0]
    assert first.startswith("dracc audit: FAILED, exit 5 (internal error)") and "a bug" in first
    doc = json.loads(paths["json"].read_text())
    jsonschema.validate(doc, load_schema())
    assert doc["exit_code"] == 5 and doc["night"] == NIGHT


#: a dracc process whose analysis waits (a flag file says it started) for the signal
_WAITING = """
import sys, time
from pathlib import Path
import dracc.pipeline.audit.run as audit_mod
from dracc.cli.main import main

flag = Path(sys.argv[1])

def waiting(*args, **kwargs):
    flag.write_text("analysing")
    time.sleep(120)

audit_mod.analyse_voyage = waiting
sys.argv = ["dracc", *sys.argv[2:]]
main()
"""


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_interrupted_by_a_signal(night_log, tmp_path, signum):
    paths = _stale(tmp_path)
    flag = tmp_path / "started"
    proc = subprocess.Popen(
        [
            sys.executable, "-c", _WAITING, str(flag),
            "audit", str(night_log), "--date", NIGHT, "--db", str(tmp_path / "s.sqlite"),
            *_report_args(paths),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
    )  # fmt: skip
    deadline = time.monotonic() + 60
    while not flag.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    if not flag.exists():
        proc.kill()
        pytest.fail(f"the audit did not start: {proc.communicate(timeout=10)}")
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == ExitCode.INTERRUPTED, err
    doc = _check_failed(paths, 130, "interrupted", NIGHT)
    if signum == signal.SIGTERM:
        assert f"signal {int(signal.SIGTERM)}" in doc["error"]["message"]


def test_the_cron_line_under_env_i(tmp_path):
    """The README's cron line, run as cron runs it: an empty environment but PATH, dracc
    named by its full path, `mail` a stand-in that keeps the subject and the body."""
    paths = _stale(tmp_path)
    logs = tmp_path / "nmea"
    logs.mkdir()
    cfg = _cfg(tmp_path, "[audit]\nthreshold = 3\n")
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    mail = bin_dir / "mail"
    mail.write_text(
        f'#!/bin/sh\nprintf "%s\\n" "$2" > {tmp_path}/mailed.txt\ncat >> {tmp_path}/mailed.txt\n'
    )
    mail.chmod(0o755)
    dracc = Path(sys.executable).with_name("dracc")
    command = f"{dracc}" if dracc.exists() else f"{sys.executable} -m dracc"
    line = (
        f"{command} audit {logs} --pattern '*.nmea' --db {tmp_path}/audit.sqlite "
        f"--config {cfg} --summary {paths['summary']} --json {paths['json']} "
        f'--html {paths["html"]} || mail -s "dracc audit: exit $?" eto@ship '
        f"< {paths['summary']}"
    )
    env = {"PATH": f"{bin_dir}:/usr/bin:/bin"}  # cron's PATH, and the stand-in mail
    done = subprocess.run(
        ["/bin/sh", "-c", line], env=env, cwd=tmp_path, capture_output=True, text=True,
        timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr  # mail ran
    mailed = (tmp_path / "mailed.txt").read_text().splitlines()
    assert mailed[0] == "dracc audit: exit 4"
    assert mailed[1].startswith("dracc audit: FAILED, exit 4 (configuration error): ")
    assert "8 findings" not in "\n".join(mailed)
    _check_failed(paths, 4, "unknown key(s): threshold", audit_mod.yesterday_utc())
