"""The limiting errors over the accuracy window: several nights pooled, then judged.

A single night is too short for a kurtosis that means something (seed 001 asks 72 h),
so the (K8) limiting error of each unit and channel is computed over the newest stored
nights that together cover ``[audit] accuracy_window_h``, and judged against
``[audit.limits]`` once the window is full.

The window holds that many hours, never more: the newest nights whole, and of the oldest
one it needs only the part that completes the window (its statistics weighted by that
part of its hours, ``partial`` in the window's document), so that a window of 72 h is
72 h and never "96.0 h of 72 h" (three nights of 23.99 h and a fourth whole one).  A
part shorter than :data:`HOURS_SHOWN` (what "72.0 h" rounds away) is not taken: the
window is full then.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from dracc.core.numbers import counted, finite_or_none
from dracc.core.timefmt import parse_utc
from dracc.pipeline.audit.findings import Finding, make_finding, not_checked
from dracc.pipeline.audit.limits import AuditConfig
from dracc.pipeline.state import ChannelRow, NightRecord, StateStore

#: the window's hours are said to 0.1 h: a window short by less than half of that is full
HOURS_SHOWN = 0.05


@dataclass(frozen=True)
class PooledChannel:
    """One unit channel over the accuracy window: the nights' deviations pooled."""

    unit: str
    channel: str
    nights: tuple[str, ...]
    hours: float
    n: int
    m_u: float
    m_y: float
    kurtosis: float
    n_eff: float
    limit_error: float  #: (K8) K_PIE K_hm m_y over the window
    limit: float | None  #: the configured limit
    measure: str


def _usable(c: ChannelRow) -> bool:
    return c.m_u is not None and math.isfinite(c.m_u) and c.n > 0


def pool_channels(
    nights: Sequence[tuple[str, float, Sequence[ChannelRow]]],
    dev_cfg,
    weights: Sequence[float] | None = None,
) -> list[PooledChannel]:
    """Pool (night, hours, channel rows) per unit and channel: m_u^2 weighted by n (K3b over
    the union of the nights' deviations), kurtosis weighted by n, independent samples
    summed; the limiting error (K8) from those.  ``weights`` (default 1 each): the part of
    each night in the window (the oldest one's may be less than 1): its hours, samples and
    independent samples count by that part."""
    from dracc.math.deviation import stats

    acc: dict[tuple[str, str], dict] = {}
    for (night, hours, rows), w in zip(nights, weights or [1.0] * len(nights), strict=True):
        for c in rows:
            if not _usable(c):
                continue
            a = acc.setdefault(
                (c.unit, c.channel),
                {
                    "nights": [],
                    "hours": 0.0,
                    "n": 0,
                    "ss": 0.0,
                    "kn": 0.0,
                    "neff": 0.0,
                    "k": None,
                    "measure": c.measure,
                },
            )
            a["nights"].append(night)
            a["hours"] += w * hours
            a["n"] += w * c.n
            assert c.m_u is not None  # _usable
            a["ss"] += w * c.n * c.m_u**2
            if c.kurtosis is not None and math.isfinite(c.kurtosis):
                a["kn"] += w * c.n * c.kurtosis
            a["neff"] += w * float(
                stats.effective_samples(c.n, dev_cfg.interval_s, dev_cfg.correlation_time_s)
            )
            if c.m_y is not None and c.m_u and math.isfinite(c.m_y):
                a["k"] = c.m_y / c.m_u
    out = []
    for (unit, channel), a in sorted(acc.items()):
        m_u = math.sqrt(a["ss"] / a["n"])
        k = a["k"] if a["k"] is not None else stats.K_FIRST_APPROX_THREE
        m_y = k * m_u
        e = a["kn"] / a["n"]
        kp = 1.0 if e <= stats.KURTOSIS_MIN else float(stats.k_pie(dev_cfg.probability, e))
        kh = float(stats.k_hm(dev_cfg.confidence, a["neff"])) if a["neff"] >= 1 else math.nan
        out.append(
            PooledChannel(
                unit,
                channel,
                tuple(a["nights"]),
                a["hours"],
                round(a["n"]),
                m_u,
                m_y,
                e,
                a["neff"],
                kp * kh * m_y,
                None,
                a["measure"],
            )
        )
    return out


def accuracy_findings(
    store: StateStore,
    vessel: str,
    night: str,
    acfg: AuditConfig,
    dev_cfg,
    tonight: tuple[float, Sequence[ChannelRow]] | None = None,
) -> tuple[tuple[Finding, ...], tuple[dict, ...], dict]:
    """The limiting errors over the accuracy window ending with ``night``: the stored
    nights up to it, newest first, until they cover ``accuracy_window_h`` (the oldest in
    part, see the module docstring).  Findings
    where a pooled limiting error exceeds its limit; not checked while the window is short.
    ``tonight``: (hours, channel rows) of ``night`` not yet stored (it replaces a stored one).
    Returns (findings, not_checked, the window as a JSON-ready dict)."""
    candidates = [
        (r.night, _hours(r), r.channels)
        for r in store.nights(vessel)
        if r.night < night or (r.night == night and tonight is None)
    ]
    if tonight is not None:
        candidates.append((night, float(tonight[0]), tuple(tonight[1])))
    chosen, weights, hours = [], [], 0.0
    for n, h, rows in sorted(candidates, key=lambda c: c[0], reverse=True):
        need = acfg.accuracy_window_h - hours
        if need < HOURS_SHOWN:
            break
        if h <= 0 or not any(_usable(c) for c in rows):  # no INS statistics: no hours to add
            continue
        chosen.append((n, h, rows))
        weights.append(min(1.0, need / h))
        hours += weights[-1] * h
    partial = None
    if chosen and weights[-1] < 1.0:  # the oldest night, in part
        n, h, _ = chosen[-1]
        partial = {"night": n, "hours": weights[-1] * h, "of_hours": h}
    doc: dict[str, Any] = {
        "window_h": acfg.accuracy_window_h,
        "hours": hours,
        "nights": [n for n, _, _ in reversed(chosen)],
        "partial": partial,
        "channels": [],
    }
    if not chosen:
        return (
            (),
            (not_checked("accuracy", "limit", "no INS deviation statistics in the stored nights"),),
            doc,
        )
    pooled = pool_channels(list(reversed(chosen)), dev_cfg, list(reversed(weights)))
    found, skipped = [], []
    complete = acfg.accuracy_window_h - hours < HOURS_SHOWN
    for p in pooled:
        lim = acfg.limit_for(p.unit, p.channel)
        doc["channels"].append(
            {
                "unit": p.unit,
                "channel": p.channel,
                "measure": p.measure,
                "n": p.n,
                "n_eff": finite_or_none(p.n_eff),
                "m_u": finite_or_none(p.m_u),
                "m_y": finite_or_none(p.m_y),
                "kurtosis": finite_or_none(p.kurtosis),
                "limit_error": finite_or_none(p.limit_error),
                "limit": lim,
            }
        )
        if lim is None:
            continue
        if not complete:
            continue
        if not math.isfinite(p.limit_error):
            skipped.append(
                not_checked(
                    "accuracy",
                    "limit",
                    f"{p.unit} {p.channel}: no limiting "
                    f"error over the window (N_eff {p.n_eff:.2f})",
                    role=p.unit,
                )
            )
        elif p.limit_error > lim:
            found.append(
                make_finding(
                    "accuracy",
                    "limit",
                    f"{p.unit} {p.channel}",
                    p.limit_error,
                    lim,
                    p.measure,
                    f"{p.unit} {p.channel}: limiting error {p.limit_error:.4g} {p.measure} over "
                    f"{hours:.0f} h ({counted(len(p.nights), 'night')}) > {lim:.4g} {p.measure}",
                    role=p.unit,
                    statistic_name="limiting_error",
                    rule="[audit.limits]: K8 limiting error at the "
                    "configured probability, pooled over the accuracy window",
                    window={"nights": list(p.nights), "hours": p.hours},
                    evidence=(
                        {
                            "m_y": p.m_y,
                            "m_u": p.m_u,
                            "n": p.n,
                            "n_eff": p.n_eff,
                            "kurtosis": p.kurtosis,
                        },
                    ),
                )
            )
    if not complete:
        skipped.append(
            not_checked(
                "accuracy",
                "limit",
                f"the limiting errors are judged over "
                f"{acfg.accuracy_window_h:g} h of logs; {hours:.1f} h over "
                f"{counted(len(chosen), 'night')} so far ([audit] accuracy_window_h)",
            )
        )
    doc["complete"] = complete
    return tuple(found), tuple(skipped), doc


def _hours(rec: NightRecord) -> float:
    return period_hours(rec.period_start_utc, rec.period_end_utc)


def period_hours(start_utc: str | None, end_utc: str | None) -> float:
    if not start_utc or not end_utc:
        return 0.0
    return (parse_utc(end_utc) - parse_utc(start_utc)).total_seconds() / 3600.0
