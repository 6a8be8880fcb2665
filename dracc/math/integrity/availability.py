"""availability / ``dropout``: gaps in a source's records longer than
``dropout_cadences`` of its own median interval and at least ``dropout_min_s``
(a late start or an early end within the night too).  A source of a log without a
clock (:attr:`dracc.frames.Voyage.clockless`) has no cadence to measure: it is
``not_checked``, and its summary has neither cadence nor availability."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from dracc.core.arrays import IntArray, unique_sorted
from dracc.core.config import IntegrityConfig
from dracc.core.timefmt import iso_utc
from dracc.core.units import NS_PER_S
from dracc.frames import Voyage
from dracc.math.integrity.helpers import (
    MAX_EVIDENCE,
    NO_CLOCK,
    not_checked,
    role_of,
    statistic,
    threshold,
    time_window,
)
from dracc.math.integrity.results import Check

__all__ = ["availability_checks", "source_times"]


def source_times(voyage: Voyage) -> dict[str, IntArray]:
    """Each source's distinct record times over every frame, sorted."""
    parts: dict[str, list[IntArray]] = {}
    for df in voyage.frames.values():
        if df is None or len(df) == 0:
            continue
        # only the time column is grouped: copying every column per source cost 0.5 s a day
        for key, times in df["time_ns"].groupby(df["source"], sort=True, observed=True):
            parts.setdefault(str(key), []).append(times.to_numpy(np.int64))
    return {k: unique_sorted(np.concatenate(v)) for k, v in parts.items()}


def availability_checks(
    voyage: Voyage,
    cfg: IntegrityConfig,
    start_ns: int,
    end_ns: int,
    times: Mapping[str, IntArray],
) -> tuple[list[Check], dict[str, tuple[float | None, float | None]]]:
    checks: list[Check] = []
    summary: dict[str, tuple[float | None, float | None]] = {}
    span = max(end_ns - start_ns, 1)
    for key in sorted(times):
        t = times[key]
        if key in voyage.clockless:
            summary[key] = (None, None)
            checks.append(
                _no_dropout_check(voyage, key, f"drop-outs not checked: {NO_CLOCK}", NO_CLOCK)
            )
            continue
        if len(t) < 3:
            summary[key] = (math.nan, math.nan)
            checks.append(
                _no_dropout_check(
                    voyage,
                    key,
                    f"{len(t)} record(s): no cadence to measure against",
                    "fewer than 3 records",
                    time_window(t),
                )
            )
            continue
        d = np.diff(t)
        cadence = float(np.median(d)) / NS_PER_S
        thr_s = max(cfg.dropout_cadences * cadence, cfg.dropout_min_s)
        thr = int(thr_s * NS_PER_S)
        gaps = [(int(t[i]), int(t[i + 1])) for i in np.flatnonzero(d > thr)]
        if t[0] - start_ns > thr:
            gaps.insert(0, (start_ns, int(t[0])))
        if end_ns - t[-1] > thr:
            gaps.append((int(t[-1]), end_ns))
        lost = sum(b - a for a, b in gaps)
        available = 1.0 - lost / span
        summary[key] = (cadence, available)
        longest = max(((b - a) / NS_PER_S for a, b in gaps), default=0.0)
        ev = tuple(
            {
                "from": iso_utc(unit="ms", time_ns=a),
                "to": iso_utc(unit="ms", time_ns=b),
                "duration_s": (b - a) / NS_PER_S,
                "cadences": (b - a) / NS_PER_S / cadence if cadence > 0 else None,
                "edge": "start" if a == start_ns else ("end" if b == end_ns else None),
            }
            for a, b in sorted(gaps, key=lambda g: g[0] - g[1])[:MAX_EVIDENCE]
        )
        msg = (
            f"{key}: silent for {longest:.0f} s at the longest ({len(gaps)} drop-out(s) "
            f"beyond {thr_s:.0f} s against its {cadence:g} s cadence; available "
            f"{100 * available:.1f} % of the night)"
            if gaps
            else f"{key}: no drop-out beyond {thr_s:.0f} s (cadence {cadence:g} s)"
        )
        checks.append(
            Check(
                "availability",
                "dropout",
                key,
                role_of(voyage, key),
                "fail" if gaps else "pass",
                statistic("longest_dropout", longest, "s"),
                threshold(
                    thr_s,
                    "s",
                    f"a gap longer than {cfg.dropout_cadences:g} of the "
                    f"source's own intervals and at least {cfg.dropout_min_s:g} s",
                ),
                {"start_ns": start_ns, "end_ns": end_ns},
                0.0,
                msg,
                ev,
                detail={"cadence_s": cadence, "availability": available},
            )
        )
    return checks, summary


def _no_dropout_check(
    voyage: Voyage, key: str, message: str, why: str, window: dict[str, int] | None = None
) -> Check:
    """The drop-out check of ``key`` that could not be made, with why."""
    return not_checked(
        "availability",
        "dropout",
        key,
        role_of(voyage, key),
        "longest_dropout",
        "s",
        "",
        f"{key}: {message}",
        why,
        window=window,
    )
