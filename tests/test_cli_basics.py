"""Every command has help; --version; documented exit codes; errors as one line on stderr."""

from __future__ import annotations

import subprocess
import sys

import pytest

import dracc.cli.main  # noqa: F401  (registers every command on app)
from dracc import __version__
from dracc.cli.app import app
from dracc.core.errors import ExitCode


def _commands():
    import typer.main

    group = typer.main.get_command(app)
    return sorted(group.commands)


def test_version(run_cli):
    code, out, _ = run_cli("--version")
    assert code == ExitCode.OK and out.strip() == f"dracc {__version__}"


def test_root_help_lists_commands(run_cli):
    code, out, _ = run_cli("--help")
    assert code == ExitCode.OK
    for name in _commands():
        assert name in out


@pytest.mark.parametrize("name", _commands())
def test_every_command_has_help(run_cli, name):
    code, out, _ = run_cli(name, "--help")
    assert code == ExitCode.OK
    assert "Usage" in out and len(out.splitlines()) > 3


def test_unknown_command_is_usage_error(run_cli):
    code, _, err = run_cli("no-such-command")
    assert code == ExitCode.USAGE and "no-such-command" in err


def test_missing_input_is_one_line_error(run_cli, tmp_path):
    code, _out, err = run_cli("inspect", tmp_path / "missing.nmea")
    assert code == ExitCode.INPUT
    assert (
        err.startswith("error:") and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    )


def test_console_script_runs_as_module():
    r = subprocess.run(
        [sys.executable, "-m", "dracc", "--version"], capture_output=True, text=True, timeout=60
    )
    assert r.returncode == 0 and __version__ in r.stdout


def test_exit_codes_are_stable():
    # Documented in the README; scripts and cron depend on these numbers.
    assert [int(c) for c in ExitCode] == [0, 1, 2, 3, 4, 5, 6, 130]


def test_regression_cli_runs_without_click_installed():
    """typer >= 0.20 vendors click and does not install it: a plain `pip install .` had no
    click, and `import click` in the entry point failed before any command ran."""
    code = (
        "import sys; sys.modules['click'] = None\n"  # any `import click` now fails
        "from dracc.cli.main import main\n"
        "assert main(['--version']) == 0\n"
        "assert main(['no-such-command']) == 2\n"
        "assert main(['inspect', '/nonexistent/log.nmea']) == 3\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr


def _analyze_process(*args, stdout=subprocess.PIPE):
    return subprocess.run(
        [sys.executable, "-m", "dracc", "analyze", "sample_logs/voyage_tag.nmea", *args],
        stdout=stdout,
        stderr=subprocess.PIPE,
        timeout=300,
        cwd=__import__("pathlib").Path(__file__).resolve().parents[1],
    )


def test_quick_exit_after_analyze_loses_no_output(tmp_path):
    """A successful analyze ends the process with os._exit (no heap teardown): the report
    on stdout, the summary in a file and the messages on stderr are all there, whole."""
    import json

    r = _analyze_process("--json", "-")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)  # the whole document, flushed before the exit
    assert doc["schema"] == "dracc.analysis/1" and doc["deviation"]["units"]
    summary = tmp_path / "summary.txt"
    with summary.open("wb") as fh:
        r = _analyze_process(
            "--json", str(tmp_path / "r.json"), "--html", str(tmp_path / "r.html"), stdout=fh
        )
    assert r.returncode == 0
    text = summary.read_text(encoding="utf-8")
    assert text.startswith("dracc analyze") and "\nCurrent\n" in text and text.endswith("\n")
    assert f"wrote {tmp_path / 'r.html'}" in r.stderr.decode()
    assert json.loads((tmp_path / "r.json").read_text(encoding="utf-8"))["schema"]
    assert (tmp_path / "r.html").read_text(encoding="utf-8").rstrip().endswith("</html>")


def test_a_failing_analyze_still_exits_with_its_code():
    r = subprocess.run(
        [sys.executable, "-m", "dracc", "analyze", "no/such/log.nmea"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == ExitCode.INPUT and "no/such/log.nmea" in r.stderr


def test_the_cli_runs_blas_on_one_thread_unless_told_otherwise():
    """Idle OpenBLAS threads spin after each call and took CPU from the ingest workers."""
    # OpenBLAS threads keep the interpreter's name; pyarrow's jemalloc thread has its own
    code = (
        "import os, dracc.cli.main, numpy; a = numpy.ones((300, 300)); a @ a; "
        "names = [open(f'/proc/self/task/{t}/comm').read().strip() "
        "for t in os.listdir('/proc/self/task')]; "
        "print(os.environ['OPENBLAS_NUM_THREADS'], names.count(names[0]))"
    )
    env = {k: v for k, v in __import__("os").environ.items() if k != "OPENBLAS_NUM_THREADS"}
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env
    )
    assert r.returncode == 0 and r.stdout.split() == ["1", "1"], (
        r.stdout + r.stderr
    )  # no BLAS thread
    env["OPENBLAS_NUM_THREADS"] = "3"
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env
    )
    assert r.stdout.split()[0] == "3"
