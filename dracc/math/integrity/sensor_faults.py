"""plausibility / ``frozen``, ``stuck``, ``out_of_range``: one pass/fail check per
source from the faults :mod:`dracc.math.faults` finds with the integrity windows
(``frozen_min_s``); rules with false-alarm probability 0."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from dracc.core.arrays import IntArray
from dracc.core.timefmt import iso_utc
from dracc.frames import Voyage
from dracc.math.faults import SensorFault
from dracc.math.integrity.helpers import (
    MAX_EVIDENCE,
    by_source,
    role_of,
    statistic,
    threshold,
    time_window,
)
from dracc.math.integrity.results import Check

__all__ = ["fault_checks"]


def fault_checks(
    voyage: Voyage,
    faults: Sequence[SensorFault],
    name: str,
    kinds: tuple[str, ...],
    frames: tuple[str, ...],
    rule: str,
    cfg_value: float,
    unit: str,
) -> list[Check]:
    """One pass/fail check per source of ``frames`` from :mod:`dracc.math.faults` results."""
    checks = []
    times: dict[str, list[IntArray]] = {}
    for frame in frames:
        for key, g in by_source(voyage.frames[frame]):
            times.setdefault(key, []).append(g["time_ns"].to_numpy(np.int64))
    for key in sorted(times):
        mine = [f for f in faults if f.source == key and f.kind in kinds]
        t = np.sort(np.concatenate(times[key]))
        ev = tuple(
            {
                "start": iso_utc(unit="ms", time_ns=f.start_ns),
                "end": iso_utc(unit="ms", time_ns=f.end_ns),
                "duration_s": f.duration_s,
                "records": f.n_records,
                "first_line": f.first_line,
                "kind": f.kind,
                "values": {k: (float(v) if math.isfinite(v) else None) for k, v in f.values},
            }
            for f in mine[:MAX_EVIDENCE]
        )
        longest = max((f.duration_s for f in mine), default=0.0)
        msg = (
            "; ".join(f.message for f in mine[:3])
            if mine
            else f"{key}: no {name.replace('_', ' ')}"
        )
        checks.append(
            Check(
                "plausibility",
                name,
                key,
                role_of(voyage, key),
                "fail" if mine else "pass",
                statistic(
                    "longest_s" if name != "out_of_range" else "faults",
                    longest if name != "out_of_range" else len(mine),
                    "s" if name != "out_of_range" else "count",
                ),
                threshold(cfg_value, unit, rule),
                time_window(t),
                0.0,
                msg,
                ev,
            )
        )
    return checks
