"""The systemd units shipped for the nightly audit (docs/systemd/) parse, do what the
docs say, and start a command the real CLI accepts: the README's cron line's.

``systemd-analyze verify`` checks them where it is installed (with the unit's dracc
path pointed at this machine's, as the command must exist); a parser test of the
sections and keys runs everywhere.
"""

from __future__ import annotations

import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from cli_lines import parse
from conftest import REPO

UNITS = REPO / "docs" / "systemd"
SERVICE, TIMER, MAIL = "dracc-audit.service", "dracc-audit.timer", "dracc-audit-mail.service"

#: the keys the units may use, per section (a misspelt key is ignored by systemd with a
#: warning: here it fails)
KNOWN = {
    "Unit": {"Description", "Documentation", "After", "Wants", "Requires", "OnFailure"},
    "Service": {
        "Type", "User", "Group", "ExecStart", "StateDirectory", "CacheDirectory",
        "Environment", "TimeoutStartSec", "Nice", "IOSchedulingClass", "NoNewPrivileges",
        "ProtectSystem", "ProtectHome", "PrivateTmp", "PrivateDevices", "PrivateNetwork",
        "ReadWritePaths",
    },
    "Timer": {"OnCalendar", "Persistent", "AccuracySec", "RandomizedDelaySec", "Unit"},
    "Install": {"WantedBy"},
}  # fmt: skip


def read_unit(text: str) -> dict[str, dict[str, list[str]]]:
    """A unit file as {section: {key: [values]}} (a key may repeat; a line ending in a
    backslash continues on the next, as systemd reads it)."""
    sections: dict[str, dict[str, list[str]]] = {}
    current = None
    text = re.sub(r"\s*\\\n\s*", " ", text)
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line[0] in "#;":
            continue
        m = re.fullmatch(r"\[([A-Za-z]+)\]", line)
        if m:
            current = sections.setdefault(m.group(1), {})
            continue
        key, sep, value = line.partition("=")
        assert sep and current is not None, f"line {n}: {raw!r} is no key=value in a section"
        current.setdefault(key.strip(), []).append(value.strip())
    return sections


def _one(unit: dict, section: str, key: str) -> str:
    (value,) = unit[section][key]
    return value


@pytest.fixture(scope="module")
def units() -> dict[str, dict]:
    return {name: read_unit((UNITS / name).read_text()) for name in (SERVICE, TIMER, MAIL)}


def _cron_argv() -> list[str]:
    """The dracc command of the README's crontab line (before ``|| mail``)."""
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    (line,) = re.findall(r"^20 0 \* \* \* +(/\S+/dracc audit .+?) \|\| mail", readme, flags=re.M)
    return shlex.split(line)


def test_units_have_known_sections_and_keys(units):
    for name, unit in units.items():
        for section, keys in unit.items():
            assert section in KNOWN, (name, section)
            assert set(keys) <= KNOWN[section], (name, section, set(keys) - KNOWN[section])


def test_the_service_is_a_oneshot_audit_as_an_unprivileged_user(units):
    svc = units[SERVICE]
    assert _one(svc, "Service", "Type") == "oneshot"
    user = _one(svc, "Service", "User")
    assert user not in ("root", "0") and _one(svc, "Service", "Group") not in ("root", "0")
    assert _one(svc, "Service", "NoNewPrivileges") == "true"
    assert _one(svc, "Service", "ProtectSystem") == "strict"
    assert _one(svc, "Unit", "OnFailure") == MAIL
    assert "Install" not in svc  # started by the timer, never enabled on its own


def test_the_service_runs_the_readme_cron_command_and_the_cli_accepts_it(units):
    argv = shlex.split(_one(units[SERVICE], "Service", "ExecStart"))
    assert argv[0].startswith("/") and argv[0].endswith("/dracc")  # a full path, no PATH
    assert argv == _cron_argv()
    values = parse(argv[1:])
    # tonight's three reports and the state, all in the unit's StateDirectory
    state = Path("/var/lib") / _one(units[SERVICE], "Service", "StateDirectory")
    written = [values[k] for k in ("summary_out", "json_out", "html_out", "db")]
    assert all(v is not None for v in written), values
    assert all(Path(v).parent == state for v in written), written
    assert values["logs"] and values["config"] is not None


def test_the_timer_runs_nightly_and_catches_up(units):
    timer = units[TIMER]
    assert _one(timer, "Timer", "OnCalendar") == "*-*-* 00:20:00 UTC"  # the cron line's 20 0
    assert _one(timer, "Timer", "Persistent") == "true"
    assert _one(timer, "Timer", "Unit") == SERVICE
    assert _one(timer, "Install", "WantedBy") == "timers.target"


def test_the_mail_unit_sends_the_summary_the_service_wrote(units):
    mail = units[MAIL]
    svc = units[SERVICE]
    assert _one(mail, "Service", "Type") == "oneshot"
    assert _one(mail, "Service", "User") == _one(svc, "Service", "User")
    command = shlex.split(_one(mail, "Service", "ExecStart"))
    assert command[:2] == ["/bin/sh", "-c"]
    summary = parse(shlex.split(_one(svc, "Service", "ExecStart"))[1:])["summary_out"]
    assert command[2].startswith("mail -s ") and command[2].endswith(f"< {summary}")
    assert f"ExecMainStatus --value {SERVICE}" in command[2]


def test_the_parser_can_fail():
    with pytest.raises(AssertionError, match="no key=value"):
        read_unit("[Service]\nType oneshot\n")
    unit = read_unit("[Service]\nExecStart=/bin/dracc audit \\\n    /logs --db x\n")
    assert unit["Service"]["ExecStart"] == ["/bin/dracc audit /logs --db x"]


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="no systemd-analyze here")
def test_systemd_analyze_verifies_the_units(tmp_path):
    """systemd's own reading: no unknown key, no bad value, the units it names exist.
    verify insists that ExecStart's program exists: this machine's dracc stands in for
    /opt/dracc/venv/bin/dracc."""
    dracc = Path(sys.executable).with_name("dracc")
    here = str(dracc) if dracc.exists() else shutil.which("dracc")
    assert here, "no dracc executable to stand in for the unit's"
    for name in (SERVICE, TIMER, MAIL):
        text = (UNITS / name).read_text().replace("/opt/dracc/venv/bin/dracc", here)
        (tmp_path / name).write_text(text)
    done = subprocess.run(
        ["systemd-analyze", "verify", "--man=no", *(f"./{n}" for n in (TIMER, SERVICE, MAIL))],
        cwd=tmp_path, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    complaints = [ln for ln in done.stderr.splitlines() if "dracc-audit" in ln]
    assert done.returncode == 0 and not complaints, done.stderr
