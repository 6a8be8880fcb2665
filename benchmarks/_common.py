"""What the benchmarks share: the simulated 24 h log they all measure on."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def ensure_day_log(workdir: Path, quiet: bool = False) -> Path:
    """WORKDIR/day/voyage.nmea: `dracc simulate --hours 24 --seed 1 --form tag` (~2.3 M lines),
    generated once and reused by later runs."""
    log = workdir / "day" / "voyage.nmea"
    if log.exists():
        return log
    cmd = [
        sys.executable,
        "-m",
        "dracc",
        "simulate",
        "--hours",
        "24",
        "--seed",
        "1",
        "--form",
        "tag",
        "--out",
        str(log.parent),
    ]
    print("generating:", " ".join(cmd[2:]), flush=True)
    subprocess.run(cmd, check=True, cwd=REPO, stdout=subprocess.DEVNULL if quiet else None)
    return log
