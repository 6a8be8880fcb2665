"""When a DR restarts from a fix and how often it is reported: the reset and epoch rules."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from dracc.core.config import DeadReckoningConfig
from dracc.core.durations import parse_reset_s

__all__ = ["covered_span_s", "dr_schedule"]

#: where a reset of "auto" stops shrinking: a log of 8 h or more gets hourly legs
_AUTO_RESETS_S = (30.0, 60.0, 120.0, 300.0, 600.0, 900.0, 1200.0, 1800.0, 3600.0)


def dr_schedule(
    cfg: DeadReckoningConfig, span_s: float, reset: str | float | None = None
) -> tuple[float, str, float]:
    """(reset_s, label, epoch_interval_s) for a DR over ``span_s`` seconds.

    ``reset`` overrides ``cfg.reset`` (a duration, "watch", "never" or "auto").

    ``reset = "auto"``: every hour on a log of 8 h or more; on a shorter one the largest of
    30 s, 1, 2, 5, 10, 15, 20, 30 min giving at least 8 legs, so that the consistency test
    has legs to learn from and to score.  ``epoch_interval_s`` unset: 10 min, or a sixth of
    the reset interval where that is shorter (at least 5 s).
    """
    rule = cfg.reset if reset is None else reset
    if str(rule).strip().lower() == "auto":
        fits = [r for r in _AUTO_RESETS_S if r <= span_s / 8.0]
        reset_s = fits[-1] if fits else _AUTO_RESETS_S[0]
        label = f"auto ({_duration_label(reset_s)})"
    else:
        reset_s = parse_reset_s(rule)
        label = str(rule)
    if cfg.epoch_interval_s is not None:
        epoch_s = float(cfg.epoch_interval_s)
    else:
        epoch_s = 600.0 if not math.isfinite(reset_s) else float(np.clip(reset_s / 6.0, 5.0, 600.0))
    return reset_s, label, epoch_s


def covered_span_s(time_s: ArrayLike, max_gap_s: float) -> float:
    """The time the samples cover: the sum of the steps no longer than ``max_gap_s`` (a
    stray record years away adds nothing)."""
    dt = np.diff(np.asarray(time_s, float))
    return float(dt[dt <= max_gap_s].sum())


def _duration_label(s: float) -> str:
    return f"{s / 3600:g}h" if s >= 3600 else f"{s / 60:g}min" if s >= 60 else f"{s:g}s"
