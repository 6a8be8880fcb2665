"""plausibility / ``frozen``, ``stuck``, ``out_of_range``: one check per source from the
faults :mod:`dracc.math.faults` finds with the integrity windows (``frozen_min_s``);
rules with false-alarm probability 0.

A finding needs a witness: ``frozen`` and ``stuck`` fail only where another source shows
the ship moving or turning beyond the sensor's resolution.  A source whose repeats the
witnesses show at rest (or steady) passes with that evidence ("at rest: SOG 0.0 kn,
heading spread 0.4 deg"); one whose repeats no other source can judge is
``not_checked``, saying so."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np

from dracc.core.arrays import IntArray
from dracc.core.timefmt import iso_utc
from dracc.frames import Voyage
from dracc.math.faults import RepeatRun, SensorFault
from dracc.math.integrity.helpers import (
    MAX_EVIDENCE,
    by_source,
    not_checked,
    role_of,
    statistic,
    threshold,
    time_window,
)
from dracc.math.integrity.results import Check

__all__ = ["fault_checks"]


def _span(kind: str, start_ns: int, end_ns: int, duration_s: float, n: int) -> dict[str, object]:
    """The fields a fault and a repeat share: when, how long, how many records."""
    return {
        "start": iso_utc(unit="ms", time_ns=start_ns),
        "end": iso_utc(unit="ms", time_ns=end_ns),
        "duration_s": duration_s,
        "records": n,
        "kind": kind,
    }


def _values(values: Iterable[tuple[str, float]]) -> dict[str, float | None]:
    return {k: (float(v) if math.isfinite(v) else None) for k, v in values}


def _fault_evidence(f: SensorFault) -> dict[str, object]:
    return {
        **_span(f.kind, f.start_ns, f.end_ns, f.duration_s, f.n_records),
        "first_line": f.first_line,
        "values": _values(f.values),
    }


def _repeat_evidence(r: RepeatRun) -> dict[str, object]:
    return {
        **_span(r.kind, r.start_ns, r.end_ns, r.duration_s, r.n_records),
        "verdict": r.verdict,
        "evidence": r.evidence,
        "values": _values(r.values),
    }


def _repeats_words(key: str, what: str, runs: Sequence[RepeatRun]) -> str:
    """'GP: position repeated 15.0 min at the longest (3 runs); at rest: SOG ...'."""
    worst = max(runs, key=lambda r: r.duration_s)
    return (
        f"{key}: {what} repeated {worst.duration_s / 60.0:.1f} min at the longest "
        f"({len(runs)} run(s)); {worst.evidence}"
    )


def fault_checks(
    voyage: Voyage,
    faults: Sequence[SensorFault],
    name: str,
    kinds: tuple[str, ...],
    frames: tuple[str, ...],
    rule: str,
    cfg_value: float,
    unit: str,
    repeats: Sequence[RepeatRun] = (),
) -> list[Check]:
    """One check per source of ``frames`` from :mod:`dracc.math.faults` results: fail
    with its faults; else, where ``repeats`` holds runs of the source that no witness
    could judge, ``not_checked``; else pass (with the at-rest evidence of its runs)."""
    checks = []
    times: dict[str, list[IntArray]] = {}
    for frame in frames:
        for key, g in by_source(voyage.frames[frame]):
            times.setdefault(key, []).append(g["time_ns"].to_numpy(np.int64))
    what = "position" if "position" in frames and len(frames) == 1 else "heading"
    for key in sorted(times):
        mine = [f for f in faults if f.source == key and f.kind in kinds]
        runs = [r for r in repeats if r.source == key and r.kind in kinds and r.fault is None]
        t = np.sort(np.concatenate(times[key]))
        role = role_of(voyage, key)
        unjudged = [r for r in runs if r.verdict == "no_witness"]
        if not mine and unjudged:
            checks.append(
                not_checked(
                    "plausibility",
                    name,
                    key,
                    role,
                    "longest_s",
                    "s",
                    rule,
                    _repeats_words(key, what, unjudged),
                    f"{what} repeated for {max(r.duration_s for r in unjudged):.0f} s and no "
                    "other source tells whether the ship "
                    + ("moved" if what == "position" else "turned"),
                    threshold_value=cfg_value,
                    window=time_window(t),
                )
            )
            continue
        ev = tuple(_fault_evidence(f) for f in mine[:MAX_EVIDENCE]) or tuple(
            _repeat_evidence(r) for r in runs[:MAX_EVIDENCE]
        )
        longest = max((f.duration_s for f in mine), default=0.0)
        if mine:
            msg = "; ".join(f.message for f in mine[:3])
        elif runs:
            msg = _repeats_words(key, what, runs)
        else:
            msg = f"{key}: no {name.replace('_', ' ')}"
        checks.append(
            Check(
                "plausibility",
                name,
                key,
                role,
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
                detail={"repeats": len(runs)} if runs else {},
            )
        )
    return checks
