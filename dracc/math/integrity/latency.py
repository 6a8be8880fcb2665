"""latency: receive time minus the record's own time of fix, per source, as a
distribution (p50, p95, p99, max, min); spells of at least ``spell_min_s`` with the time
of fix more than ``latency_max_s`` behind the logger clock fail.

The sign says which clock leads: a positive latency is a time of fix behind the logger's
clock (data that old on receipt, or the clocks apart), judged here; a negative one a time
of fix ahead of it, which no delay makes: a clock offset, never "old" data, judged by the
time checks (:mod:`.time_checks`, ``time/leap_second``) and not failed here too.  A source
of a log without a clock (:attr:`dracc.frames.Voyage.clockless`: its times are only the order of
its records) is ``not_checked``."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from dracc.core.arrays import IntArray
from dracc.core.config import IntegrityConfig
from dracc.core.timefmt import iso_utc
from dracc.core.units import NS_PER_S
from dracc.frames import MISSING_NS, Voyage
from dracc.math.integrity.clock_steps import WEEK_ROLLOVER_NS, WEEK_ROLLOVER_TOL_NS
from dracc.math.integrity.helpers import (
    MAX_EVIDENCE,
    NO_CLOCK,
    by_source,
    not_checked,
    present_keys,
    role_of,
    runs,
    statistic,
    threshold,
    time_window,
)
from dracc.math.integrity.results import Check

__all__ = ["clock_lead_words", "latency_checks"]


def clock_lead_words(latency_s: float) -> str:
    """Which clock leads, in words: 'the receiver's time of fix is 2.17 s behind the
    logger clock' (latency > 0) or '... ahead of ...' (< 0, a clock offset)."""
    if latency_s >= 0:
        return f"the receiver's time of fix is {latency_s:.2f} s behind the logger clock"
    return (
        f"the receiver's time of fix is {-latency_s:.2f} s ahead of the logger clock "
        "(a clock offset: no delay makes data arrive before its time of fix)"
    )


def latency_checks(
    voyage: Voyage, cfg: IntegrityConfig
) -> tuple[list[Check], dict[str, dict[str, float]]]:
    checks, dists = [], {}
    per: dict[str, list[tuple[IntArray, IntArray, NDArray[Any]]]] = {}
    for df in voyage.frames.values():
        if len(df) == 0 or "recv_ns" not in df:
            continue
        recv = df["recv_ns"].to_numpy(np.int64)
        has = recv != MISSING_NS
        if not has.any():
            continue
        sub = df[has]
        for key, g in by_source(sub):
            if key in voyage.clockless:
                continue
            per.setdefault(key, []).append(
                (
                    g["time_ns"].to_numpy(np.int64),
                    g["recv_ns"].to_numpy(np.int64),
                    g["line"].to_numpy(),
                )
            )
    max_ns = cfg.latency_max_s * NS_PER_S
    spell_ns = int(cfg.spell_min_s * NS_PER_S)
    rule = (
        f"receive time - time of fix above this for at least {cfg.spell_min_s:g} s (a time "
        "of fix ahead of the logger clock: time/leap_second)"
    )
    for key in sorted(voyage.clockless & present_keys(voyage)):
        checks.append(
            not_checked(
                "latency",
                "latency",
                key,
                role_of(voyage, key),
                "longest_late_spell",
                "s",
                rule,
                f"{key}: latency not checked: {NO_CLOCK}",
                NO_CLOCK,
                threshold_value=cfg.latency_max_s,
            )
        )
    for key in sorted(per):
        t = np.concatenate([p[0] for p in per[key]])
        r = np.concatenate([p[1] for p in per[key]])
        ln = np.concatenate([p[2] for p in per[key]])
        o = np.argsort(t, kind="stable")
        t, r, ln = t[o], r[o], ln[o]
        lat_s = (r - t) / NS_PER_S
        q = np.percentile(lat_s, [50, 95, 99])
        dists[key] = {
            "n": int(len(lat_s)),
            "p50": float(q[0]),
            "p95": float(q[1]),
            "p99": float(q[2]),
            "max": float(lat_s.max()),
            "min": float(lat_s.min()),
        }
        # behind the logger clock; ahead of it: time/leap_second; 1024 weeks behind (a GPS
        # week rollover): time/week_rollover
        rolled = np.abs((r - t) - WEEK_ROLLOVER_NS) <= WEEK_ROLLOVER_TOL_NS
        bad = ((r - t) > max_ns) & ~rolled
        evidence: list[dict[str, Any]] = []
        longest = 0.0
        for a, b in runs(bad):
            dur = (t[b - 1] - t[a]) / NS_PER_S
            longest = max(longest, dur)
            if t[b - 1] - t[a] >= spell_ns and len(evidence) < MAX_EVIDENCE:
                evidence.append(
                    {
                        "start": iso_utc(unit="ms", time_ns=t[a]),
                        "end": iso_utc(unit="ms", time_ns=t[b - 1]),
                        "duration_s": dur,
                        "records": b - a,
                        "first_line": int(ln[a]),
                        "median_latency_s": float(np.median(lat_s[a:b])),
                    }
                )
        failed = bool(evidence)
        # the spell furthest from the logger clock, with its sign
        worst = max((e["median_latency_s"] for e in evidence), key=abs, default=0.0)
        msg = (
            f"{key}: {clock_lead_words(worst)} for {longest:.0f} s at the longest "
            f"(limit {cfg.latency_max_s:g} s; latency p50 {q[0]:.2f} s, "
            f"p95 {q[1]:.2f} s)"
            if failed
            else f"{key}: latency p50 {q[0]:.2f} s, p95 {q[1]:.2f} s, max "
            f"{lat_s.max():.2f} s over {len(lat_s)} records"
        )
        if rolled.any():
            msg += (
                f"; {int(rolled.sum())} records 1024 weeks behind the logger clock: a GPS week "
                "rollover, judged by time/week_rollover"
            )
        if q[0] < -cfg.latency_max_s:
            msg += (
                f"; the time of fix is {-q[0]:.2f} s ahead of the logger clock (median): a "
                "clock offset, judged by time/leap_second"
            )
        checks.append(
            Check(
                "latency",
                "latency",
                key,
                role_of(voyage, key),
                "fail" if failed else "pass",
                statistic("longest_late_spell", longest, "s"),
                threshold(cfg.latency_max_s, "s", rule),
                time_window(t),
                0.0,
                msg,
                tuple(evidence),
                detail={"latency_s": dists[key], "worst_spell_latency_s": worst},
            )
        )
    return checks, dists
