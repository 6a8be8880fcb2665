"""The nightly audit as an ETO runs it: the README's cron line under ``env -i``, a night
without logs, the audit document (dracc.audit/1) and page, seeded faults as findings."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import jsonschema
import pytest

from dracc.report.audit_json import load_schema

README = Path(__file__).resolve().parents[1] / "README.md"
DRACC = Path(sys.executable).with_name("dracc")


def _cron_line() -> tuple[str, str]:
    """(PATH line, command) of the README's crontab block."""
    text = README.read_text(encoding="utf-8")
    block = re.search(r"```bash\n(PATH=[^\n]*)\n20 0 \* \* \*\s+([^\n]+)\n```", text)
    assert block, "README: crontab block with a PATH line and a '20 0 * * *' job"
    return block.group(1), block.group(2)


def _simulate(out: Path, *extra: str, hours: str = "3.2", name: str = "nav-2026-11-30") -> Path:
    subprocess.run(
        [
            str(DRACC),
            "simulate",
            "--out",
            str(out),
            "--hours",
            hours,
            "--seed",
            "5",
            "--start",
            "2026-11-30T01:00:00Z",
            "--compass-hz",
            "1",
            "--aux-hz",
            "0",
            "--name",
            name,
            *extra,
        ],
        check=True,
        capture_output=True,
    )
    return out / f"{name}.nmea"


def _run_cron(tmp: Path, logs: Path) -> tuple[int, Path, Path]:
    """Run the README's cron command under ``env -i`` with its paths moved into ``tmp``."""
    path_line, cmd = _cron_line()
    bindir = tmp / "bin"
    bindir.mkdir(exist_ok=True)
    mailbox = tmp / "mailbox"
    fake_mail = bindir / "mail"
    fake_mail.write_text(f'#!/bin/sh\necho "Subject: $2" >> {mailbox}\ncat >> {mailbox}\n')
    fake_mail.chmod(0o755)
    state = tmp / "state"
    state.mkdir(exist_ok=True)
    cfg = tmp / "dracc.toml"
    cfg.write_text('[audit]\nrequired_sources = ["ins1", "ins2", "ins3"]\n')
    cmd = (
        cmd.replace("/opt/dracc/venv/bin/dracc", str(DRACC))
        .replace("/var/log/nmea", str(logs))
        .replace("/var/lib/dracc", str(state))
        .replace("/etc/dracc.toml", str(cfg))
    )
    path = path_line.split("=", 1)[1] + f":{bindir}"  # the fake mail beside the real tools
    proc = subprocess.run(
        ["env", "-i", f"PATH={path}", "sh", "-c", cmd + "; exit 0"],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    return proc.returncode, state, mailbox


@pytest.mark.skipif(shutil.which("env") is None, reason="needs env(1)")
def test_cron_line_under_env_i_mails_the_night_without_logs(tmp_path):
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "nav-2026-11-01.nmea").write_text("")  # another night's file: not tonight's
    # the job runs on 2026-12-01 (the night before); --date is the README's default behaviour
    _, state, mailbox = _run_cron(tmp_path, logs)
    summary = (state / "last-audit.txt").read_text()
    assert "NO DATA" in summary and "no logs for" in summary
    mail = mailbox.read_text()
    assert "Subject: dracc audit: exit 3" in mail and "NO DATA" in mail
    doc = json.loads((state / "last-audit.json").read_text())
    jsonschema.validate(doc, load_schema())
    assert doc["verdict"] == "no data" and doc["exit_code"] == 3 and doc["analysis"] is None
    # the night is recorded: history shows the gap
    hist = subprocess.run(
        [str(DRACC), "audit", "history", "--db", str(state / "audit.sqlite"), "--json", "-"],
        capture_output=True,
        text=True,
        check=True,
    )
    nights = json.loads(hist.stdout)["nights"]
    assert len(nights) == 1 and nights[0]["findings"][0]["kind"] == "no_logs"


@pytest.fixture(scope="module")
def faulted_audit(tmp_path_factory) -> Path:
    """A night with a GNSS jump and an INS3 drop-out, audited with --json, --html, --summary."""
    tmp = tmp_path_factory.mktemp("faulted")
    log = _simulate(
        tmp / "sim", "--fault", "jump:GNSS@1h=670m", "--fault", "dropout:INS3@1.5h+25min"
    )
    out = tmp / "out"
    out.mkdir()
    proc = subprocess.run(
        [
            str(DRACC),
            "audit",
            str(log),
            "--db",
            str(out / "a.sqlite"),
            "--date",
            "2026-11-30",
            "--json",
            str(out / "a.json"),
            "--html",
            str(out / "a.html"),
            "--summary",
            str(out / "s.txt"),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 1, proc.stderr
    return out


@pytest.mark.slow
def test_audit_page_in_a_real_browser(faulted_audit, tmp_path):
    """The audit page loads in Chromium with its sections in order, no script, no request."""
    from test_report_html import _BROWSER_HOSTS, _probe

    page = tmp_path / "a.html"
    shutil.copy(faulted_audit / "a.html", page)
    data, urls = _probe(tmp_path, page)
    heads = data["heads"]
    assert heads.index("Findings") < heads.index("Not checked") < heads.index("The analysis")
    assert "Integrity per source" in heads
    assert data["scripts"] == 0 and data["links"] == 0
    assert all(i["complete"] and i["w"] > 300 for i in data["imgs"])
    assert not [
        u
        for u in urls
        if not u.startswith(("file:", "data:"))
        and not any(host in u.split("/")[2] for host in _BROWSER_HOSTS)
    ]
    assert "Verdict" in data["body"] and "GNSS" in data["body"]


def test_audit_json_and_html_lead_with_findings(faulted_audit):
    out = faulted_audit
    doc = json.loads((out / "a.json").read_text())
    jsonschema.validate(doc, load_schema())
    assert doc["schema"] == "dracc.audit/1" and doc["verdict"] == "findings"
    assert doc["analysis"]["schema"] == "dracc.analysis/1"
    by = {(f["check"], f["source"]) for f in doc["findings"]}
    assert ("plausibility", "GNSS") in by and ("availability", "INS3") in by
    for f in doc["findings"]:
        for key in (
            "check",
            "source",
            "role",
            "clause",
            "statistic",
            "threshold",
            "window",
            "evidence",
            "message",
        ):
            assert key in f
    assert all(set(n) >= {"check", "name", "why"} for n in doc["not_checked"])
    summary = (out / "s.txt").read_text().splitlines()
    assert re.match(r"dracc audit: default, night 2026-11-30: \d+ findings", summary[0])
    assert summary[1] == "findings:" and any("GNSS" in s and "jump" in s for s in summary[2:6])
    page = (out / "a.html").read_text()
    # the verdict and the findings come before the analysis
    assert page.index("id='verdict'") < page.index("id='findings'") < page.index("id='analysis'")
    assert "GNSS" in page[page.index("id='findings'") : page.index("id='not-checked'")]


def test_clean_night_has_no_integrity_finding(tmp_path):
    log = _simulate(tmp_path / "sim")
    out = tmp_path / "out"
    out.mkdir()
    proc = subprocess.run(
        [
            str(DRACC),
            "audit",
            str(log),
            "--db",
            str(out / "a.sqlite"),
            "--date",
            "2026-11-30",
            "--json",
            str(out / "a.json"),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode in (0, 1), proc.stderr
    doc = json.loads((out / "a.json").read_text())
    beyond = [f for f in doc["findings"] if f["check"] not in ("accuracy",)]
    assert beyond == [], beyond
    # limiting errors wait for the accuracy window; said so, not silently skipped
    assert any(n["check"] == "accuracy" and "72 h" in n["why"] for n in doc["not_checked"])
    assert doc["false_alarm_per_night"] is not None and doc["false_alarm_per_night"] < 0.05


REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"


@pytest.mark.skipif(not (REAL / "gpsd" / "bundg_zeus_9.log").is_file(), reason="real logs absent")
def test_real_log_unused_sentences_are_ignored_not_an_input_finding(tmp_path):
    log = REAL / "gpsd" / "bundg_zeus_9.log"
    proc = subprocess.run(
        [
            str(DRACC),
            "audit",
            str(log),
            "--db",
            str(tmp_path / "a.sqlite"),
            "--json",
            str(tmp_path / "a.json"),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode in (0, 1), proc.stderr
    doc = json.loads((tmp_path / "a.json").read_text())
    assert [f for f in doc["findings"] if f["check"] == "input"] == []
    assert sum(doc["logs"]["ignored"].values()) >= 2500
    assert os.path.getsize(tmp_path / "a.json") > 0
