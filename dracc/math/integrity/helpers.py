"""Helpers shared by the integrity checks: runs of a mask, robust sigmas and the
Bonferroni gate, the statistic/threshold/window records of a :class:`Check`, the
per-source grouping of a frame, and :func:`not_checked` for every check that could not
be made."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from dracc.core import distributions as dist
from dracc.core.arrays import FloatArray, IntArray
from dracc.core.bounds import check_work
from dracc.frames import Voyage
from dracc.math.integrity.results import Check

MAX_EVIDENCE = 10  #: events shown per check (the count of all is in the statistic)


def runs(mask: NDArray[Any]) -> list[tuple[int, int]]:
    """[start, stop) index pairs of the runs of True in ``mask``."""
    m = np.concatenate(([False], np.asarray(mask, dtype=bool), [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def robust_sigma(x: FloatArray) -> float:
    """1.4826 MAD: the normal sigma, unmoved by a minority of outliers."""
    x = x[np.isfinite(x)]
    if len(x) == 0:
        return math.nan
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def tail_sigma(x: FloatArray) -> float:
    """The larger of the MAD sigma and the sigma the 99th percentile of |x| implies (2.576
    sigma for a normal law): a night whose noise has heavier tails than normal widens its
    own gate instead of raising false alarms, and one displaced fix in a hundred moves
    neither."""
    x = x[np.isfinite(x)]
    if len(x) == 0:
        return math.nan
    med = np.median(x)
    return max(robust_sigma(x), float(np.percentile(np.abs(x - med), 99.0) / 2.576))


def z_two_sided(alpha: float, n: int) -> float:
    """Normal quantile with two-sided tail alpha / n (Bonferroni over n instants)."""
    return float(dist.norm_ppf(1.0 - alpha / (2.0 * max(n, 1))))


def time_window(t_ns: IntArray) -> dict[str, int]:
    """{"start_ns", "end_ns"} of sorted times, {} without any."""
    if len(t_ns) == 0:
        return {}
    return {"start_ns": int(t_ns[0]), "end_ns": int(t_ns[-1])}


def statistic(name: str, value: float | None, unit: str) -> dict[str, Any]:
    """A check's ``statistic`` record (value None where not finite)."""
    v = None if value is None or not np.isfinite(value) else float(value)
    return {"name": name, "value": v, "unit": unit}


def threshold(value: float | None, unit: str, rule: str) -> dict[str, Any]:
    """A check's ``threshold`` record (value None where not finite)."""
    v = None if value is None or not np.isfinite(value) else float(value)
    return {"value": v, "unit": unit, "rule": rule}


def by_source(df: pd.DataFrame | None) -> Iterator[tuple[str, pd.DataFrame]]:
    """(source key, its rows) for each source of a frame, rows in time order."""
    if df is None or len(df) == 0:
        return
    for key, g in df.groupby("source", sort=True, observed=True):
        yield str(key), g


def role_of(voyage: Voyage, key: str) -> str | None:
    """The role of source ``key`` (None for a source the voyage does not describe)."""
    s = voyage.sources.get(key)
    return s.role if s is not None else None


def not_checked(
    check: str,
    name: str,
    source: str | None,
    role: str | None,
    statistic_name: str,
    unit: str,
    rule: str,
    message: str,
    why: str,
    *,
    threshold_value: float | None = None,
    threshold_unit: str | None = None,
    window: dict[str, int] | None = None,
) -> Check:
    """A check that could not be made, with why.

    ``unit`` is the statistic's (and, unless ``threshold_unit``, the threshold's);
    ``threshold_value`` the gate the check would have used where it is known;
    ``window`` the records it would have looked at ({} by default)."""
    return Check(
        check,
        name,
        source,
        role,
        "not_checked",
        statistic(statistic_name, None, unit),
        threshold(threshold_value, unit if threshold_unit is None else threshold_unit, rule),
        dict(window or {}),
        0.0,
        message,
        why_not=why,
    )


#: a silence of every compared source longer than this splits the comparison grid
GRID_SILENCE_NS = 3600 * 1_000_000_000


def covered_instants(
    times_ns: list[IntArray], start_ns: int, end_ns: int, step_ns: int, setting: bool = False
) -> IntArray:
    """The comparison grid start_ns + k step_ns in [start_ns, end_ns), without the
    stretches where every compared source is silent for more than an hour: a stray record
    dated years away must not make a grid of years (millions of empty instants).  Without
    such a silence this is exactly ``arange(start_ns, end_ns, step_ns)``.  ``setting``:
    the step is ``[integrity] consistency_interval_s``, refused where it asks more
    instants than a setting may (:func:`dracc.core.bounds.check_work`)."""
    t = np.concatenate([np.asarray(x, dtype=np.int64) for x in times_ns]) if times_ns else None
    t = t[(t >= start_ns) & (t < end_ns)] if t is not None else np.empty(0, np.int64)
    if t.size == 0:
        lo, hi = np.array([start_ns]), np.array([end_ns])
    else:
        t = np.unique(t)
        gaps = np.flatnonzero(np.diff(t) > GRID_SILENCE_NS)
        # segments of data: [the window's start, or the first record after a silence; the
        # last record before a silence, or the window's end); grid points keep their phase
        first = start_ns if t[0] - start_ns <= GRID_SILENCE_NS else int(t[0])
        last = end_ns if end_ns - t[-1] <= GRID_SILENCE_NS else int(t[-1]) + 1
        lo = np.concatenate(([first], t[gaps + 1]))
        hi = np.concatenate((t[gaps] + 1, [last]))
    if setting:
        span_s = float(np.sum(hi - lo)) / 1e9
        check_work("integrity", "consistency_interval_s", step_ns / 1e9, span_s)
    if lo.size == 1 and (int(lo[0]), int(hi[0])) == (start_ns, end_ns):
        return np.arange(start_ns, end_ns, step_ns, dtype=np.int64)
    parts = []
    for a, b in zip(lo.tolist(), hi.tolist(), strict=True):
        k0 = -(-(a - start_ns) // step_ns)
        k1 = -(-(b - start_ns) // step_ns)
        parts.append(start_ns + step_ns * np.arange(k0, k1, dtype=np.int64))
    return np.concatenate(parts)


def shifted_index(instants: IntArray, shift_ns: int) -> tuple[IntArray, NDArray[np.bool_]]:
    """For each instant t, the index of t - shift_ns in ``instants`` and whether it is
    there (a grid with its long silences left out is not regular across them)."""
    want = instants - shift_ns
    idx = np.searchsorted(instants, want)
    inside = idx < len(instants)
    idx_c = np.where(inside, idx, 0)
    return idx_c, inside & (instants[idx_c] == want)


#: why a source of a log without a clock gets no latency, rate or time check
NO_CLOCK = "no clock: the log carries no time (its times are only the order of its records)"


def present_keys(voyage: Voyage) -> set[str]:
    """Source keys with at least one record in any frame."""
    keys: set[str] = set()
    for df in voyage.frames.values():
        if len(df):
            keys.update(str(k) for k in df["source"].unique())
    return keys
