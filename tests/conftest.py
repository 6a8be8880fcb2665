"""Shared fixtures: where the real logs are, and a CLI runner."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
#: real logs recorded by others (../shared/data/real beside the repository)
REAL = Path(os.environ.get("DRACC_REAL_DATA", REPO.parent / "shared" / "data" / "real"))
SAMPLES = REPO / "sample_logs"


@pytest.fixture(scope="session")
def real_dir() -> Path:
    if not REAL.is_dir():
        pytest.skip(f"real data folder not found at {REAL}")
    return REAL


@pytest.fixture
def run_cli(capsys):
    """Run ``dracc ARGS`` in-process; return (exit_code, stdout, stderr)."""
    from dracc.cli.main import main

    def run(*args: str):
        code = main([str(a) for a in args])
        cap = capsys.readouterr()
        return code, cap.out, cap.err

    return run
