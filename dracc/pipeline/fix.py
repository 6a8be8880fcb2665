"""``dracc fix`` as one library call: the observations as the navigator gives them
(options and an observation file, :mod:`dracc.ingest.observations`) fused into a fix
(:mod:`dracc.math.fix`: LS (W1) or WLS (W4))."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from dracc.ingest.observations import read_observations
from dracc.math.fix import FixReport, fix_report


def run_fix(
    options: Sequence[tuple[str, Sequence[str]]],
    file: Path | None,
    prior: str | None,
    weighted: bool = True,
) -> FixReport:
    """The fix from the repeated observation ``options`` (``("--range", [...])`` ...),
    the TOML ``file`` and the ``prior`` position text."""
    observations, prior_deg = read_observations(options, file, prior)
    return fix_report(observations, prior_deg, weighted=weighted)
