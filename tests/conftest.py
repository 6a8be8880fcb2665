"""Shared fixtures: where the real logs are, and a CLI runner."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: real logs recorded by others (../shared/data/real beside the repository)
REAL = Path(os.environ.get("DRACC_REAL_DATA", REPO.parent / "shared" / "data" / "real"))
SAMPLES = REPO / "sample_logs"
#: `dracc simulate` rates of a sparse voyage: a night of log in a few hundred kB, for the
#: audit, fleet and interruption tests that need many nights
SPARSE_RATES = (
    "--compass-hz", "0.2", "--log-hz", "0.2", "--ins-hz", "0.1",
    "--gnss-hz", "0.2", "--aux-hz", "0", "--truth-hz", "0.01",
)  # fmt: skip
#: set (CI sets it) to make missing real logs a failure instead of a skip
REQUIRE_REAL = os.environ.get("DRACC_REQUIRE_REAL_DATA", "") not in ("", "0")
REAL_MISSING = (
    f"real logs not found at {REAL}: put the shared data/real folder there "
    "(../shared/data/real beside the repository) or set DRACC_REAL_DATA"
)


def real_path(*parts: str) -> Path:
    """A real log (or folder) under REAL; skips the test, with where the data goes, when it
    is absent (fails instead under DRACC_REQUIRE_REAL_DATA=1, as in CI)."""
    path = REAL.joinpath(*parts)
    if not path.exists():
        if REQUIRE_REAL:
            pytest.fail(f"{path} is missing and DRACC_REQUIRE_REAL_DATA is set")
        pytest.skip(REAL_MISSING)
    return path


def pytest_report_header(config) -> str:
    return f"real logs: {REAL}" if REAL.is_dir() else f"real logs: none ({REAL_MISSING})"


def pytest_sessionstart(session) -> None:
    if REQUIRE_REAL and not REAL.is_dir():
        raise pytest.UsageError(f"DRACC_REQUIRE_REAL_DATA is set but {REAL} is not a folder")


@pytest.fixture(scope="session")
def real_dir() -> Path:
    return real_path()


@pytest.fixture
def run_cli(capsys):
    """Run ``dracc ARGS`` in-process; return (exit_code, stdout, stderr)."""
    from dracc.cli.main import main

    def run(*args: str):
        code = main([str(a) for a in args])
        cap = capsys.readouterr()
        return code, cap.out, cap.err

    return run
