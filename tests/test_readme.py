"""The README's two commands stay true: the main job runs on the shipped sample as
written, and .ci/run runs exactly the README's test command."""

from __future__ import annotations

import json
import re
import shlex

from conftest import REPO

README = (REPO / "README.md").read_text(encoding="utf-8")


def _two_commands() -> list[str]:
    section = README.split("## Two commands", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```bash\n(.+?)\n```", section, flags=re.S)


def test_readme_has_two_commands():
    blocks = _two_commands()
    assert len(blocks) == 2
    assert "pip install ." in blocks[0] and "dracc analyze sample_logs/" in blocks[0]
    assert "pytest" in blocks[1]


def test_main_job_runs_on_the_shipped_sample_as_written(run_cli, tmp_path, monkeypatch):
    install_and_run = _two_commands()[0]
    dracc_part = install_and_run.split("&&")[-1].strip()
    argv = shlex.split(dracc_part)
    assert argv[0] == "dracc"
    # sample paths are relative to the repository; report paths land in a scratch folder
    argv = [str(REPO / a) if a.startswith("sample_logs/") else a for a in argv[1:]]
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli(*argv)
    assert code == 0, err
    assert "INS deviations" in out
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["schema"] == "dracc.analysis/1"
    # a day at sea: every section of the report is filled
    assert len(report["deviation"]["samples"]) >= 24
    assert report["deviation"]["units"]["ins2"]["lat"]["limit"] is not None
    assert report["dead_reckoning"]["containment_2m"] is not None
    assert report["calibration"] is not None and report["current"] is not None
    html = (tmp_path / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 4


def test_ci_runs_the_readme_test_command():
    test_command = _two_commands()[1].strip()
    ci = (REPO / ".ci" / "run").read_text()
    assert test_command in ci
