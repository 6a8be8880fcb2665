"""The clock stage: each source's clock learned from the voyage (:mod:`dracc.math.clock`)
and applied to its records before anything else looks at time.

1. Records sharing a coarse stamp (a 10 Hz gyro behind whole-second TAG stamps) are
   placed inside it by their order (``spread``).
2. A source with its own time of fix (GGA, RMC under a receive stamp) is an **anchor**:
   its offset is the median of ``recv - fix``; its records without a time of fix (an
   INS's HDT, a GNSS's VTG) are received the same way and share it.
3. A heading without an anchor of its own is timed against the anchored headings
   (``heading_rate``), else against the GNSS course in turns (``course_rate``); a log
   against the GNSS speed in speed changes (``speed_rate``).
4. ``[sources.KEY] latency_s`` replaces whatever was learned (``configured``).
5. Every record without a time of fix of a source whose offset is known moves to the
   instant it describes: ``time_ns - offset``.  Records with their own time of fix keep
   it; the time base of the analysis is the GNSS time of fix.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from dracc.core.config import Config
from dracc.core.source_config import source_latencies
from dracc.core.units import DEG_RAD, KN_MPS, NS_PER_S
from dracc.frames import MISSING_NS, Voyage, own_time
from dracc.math.clock import (
    LagEstimate,
    SourceClock,
    hermite,
    rate_lag,
    spread_shared_stamps,
    stamp_resolution_s,
    time_of_fix_offset,
)

__all__ = ["learn_clocks", "source_clocks"]

#: the value that tells two samples of a source apart, per frame kind
PRIMARY = {
    "position": "lat_rad",
    "heading": "heading_rad",
    "ground": "cog_rad",
    "water": "stw_mps",
    "distance": "total_water_m",
    "rot": "rot_radps",
}
MIN_FIXES = 10  #: times of fix beside receive stamps an anchor needs
GRID_S = 1.0  #: the common grid of the slow regressions (course, speed)
#: heading against heading: the yaw's seconds need a finer grid (a central difference
#: over 1 s blunts a 15 s yaw's rate by 3 %, over 0.25 s by 0.2 %)
FINE_GRID_S = 0.25
HOLD_S = 3.0  #: a grid point further than this from a record of a series is missing
#: a turn or yaw shows a heading rate of this spread in a window (rad/s): below, no signal
MIN_HEADING_RATE = 0.02 * DEG_RAD
#: turns only against the course (yaw and the hull's response to it are smoothed away)
MIN_TURN_RATE = 0.05 * DEG_RAD
#: against the GNSS course or speed: the yaw and the hull's response to it smoothed away
SLOW_SMOOTH_S = 31.0
HIGHPASS_S = 61.0  #: heading against heading: the yaw's seconds, not the slow errors
MIN_ACCEL_MPS2 = 0.002  #: a speed change (RMS acceleration in a window) worth timing
#: an offset learned beyond this is not a clock: it is not applied (the time checks speak)
MAX_LEARNED_S = 5.0
#: an offset whose σ is above this is too uncertain to move records by
MAX_SIGMA_S = 0.5


def learn_clocks(voyage: Voyage, cfg: Config) -> tuple[Voyage, dict[str, SourceClock]]:
    """(the voyage with its records moved to the instants they describe, the clock model
    per source key)."""
    keys = sorted(voyage.sources)
    if not keys:
        return voyage, {}
    frames, spread, stamp, spread_mean, slot = _spread(voyage)
    frames = {
        k: df.assign(**{STAMPED: _stamped(df)}) if len(df) else df for k, df in frames.items()
    }
    configured = source_latencies(cfg.extra.get("sources"))
    clocks: dict[str, SourceClock] = {}
    for key in keys:
        clocks[key] = _own_clock(voyage, frames, key, configured)
    _learn_headings(voyage, frames, clocks)
    _learn_logs(voyage, frames, clocks)
    clocks = {
        k: replace(
            c,
            offset_sigma_s=_with_slot(c, slot.get(k, 0.0)),
            spread=spread.get(k, 0),
            spread_mean_s=spread_mean.get(k, 0.0),
            stamp_s=stamp.get(k),
        )
        for k, c in clocks.items()
    }
    return replace(voyage, frames=_apply(frames, clocks)), clocks


def source_clocks(paths: Sequence[Path], cfg: Config) -> dict[str, SourceClock]:
    """Each source's clock in the logs ``paths`` (``dracc inspect``: the logs are read
    into frames for it)."""
    from dracc.ingest import read_logs  # the readers are heavy; import on use

    return learn_clocks(read_logs(list(paths), cfg.ingest), cfg)[1]


def _with_slot(c: SourceClock, slot_s: float) -> float:
    """A learned offset's σ with the placement's inside shared stamps added."""
    if not c.known or c.method in ("configured", "time_of_fix") or not slot_s:
        return c.offset_sigma_s
    return math.hypot(c.offset_sigma_s, slot_s)


STAMPED = "_stamped"  #: the stage's own column: the row's time is a stamp


def _stamped(df: pd.DataFrame) -> np.ndarray:
    """Rows without a time of fix of their own (their time is a stamp)."""
    if STAMPED in df:
        mask: np.ndarray = df[STAMPED].to_numpy(bool)
        return mask
    return ~own_time(df)


def _spread(
    voyage: Voyage,
) -> tuple[
    dict[str, pd.DataFrame],
    dict[str, int],
    dict[str, float | None],
    dict[str, float],
    dict[str, float],
]:
    """Frames with shared stamps spread (step 1); per key the records moved, the stamp
    resolution, the mean move (s) and the σ the placement leaves (s)."""
    frames: dict[str, pd.DataFrame] = {}
    moved: dict[str, int] = {}
    shift: dict[str, float] = {}
    slot: dict[str, float] = {}
    stamp: dict[str, float | None] = {}
    for kind, df in voyage.frames.items():
        if len(df) == 0:
            frames[kind] = df
            continue
        t = df["time_ns"].to_numpy(np.int64).copy()
        stamped = _stamped(df)
        value = df[PRIMARY[kind]].to_numpy(float)
        changed = False
        groups = df.groupby(["source", "sentence"], observed=True, sort=False).indices
        for (key, _), rows in groups.items():
            rows = rows[stamped[rows]]
            if len(rows) < 3 or str(key) in voyage.clockless:
                continue
            res = stamp_resolution_s(t[rows])
            stamp[str(key)] = res if stamp.get(str(key)) is None else stamp[str(key)]
            stamps = t[rows]
            t[rows], n = spread_shared_stamps(stamps, value[rows])
            moved[str(key)] = moved.get(str(key), 0) + n
            changed = changed or n > 0
            if n:
                slot[str(key)] = max(slot.get(str(key), 0.0), _slot_sigma_s(stamps))
        frames[kind] = df.assign(time_ns=t) if changed else df
        if changed:
            d = (t - df["time_ns"].to_numpy(np.int64)) / NS_PER_S
            for key, rows in groups.items():
                if d[rows].any():
                    shift[str(key[0])] = shift.get(str(key[0]), 0.0) + float(d[rows].sum())
    mean = {k: shift[k] / moved[k] for k in shift if moved.get(k)}
    return frames, moved, stamp, mean, slot


def _slot_sigma_s(stamps: np.ndarray) -> float:
    """The σ a placement inside a shared stamp leaves: where in its slot of q/m a record
    was received is unknown, uniform: q / (m √12) (a 10 Hz source behind 1 s stamps:
    0.029 s)."""
    u, m = np.unique(stamps, return_counts=True)
    if len(u) < 2:
        return 0.0
    q_s = float(np.median(np.diff(u))) / NS_PER_S
    return q_s / float(np.median(m)) / math.sqrt(12.0)


def _own_clock(
    voyage: Voyage, frames: dict[str, pd.DataFrame], key: str, configured: dict[str, float]
) -> SourceClock:
    """Steps 2 and 4: configured, clockless, or anchored by the source's time of fix."""
    if key in voyage.clockless:
        return SourceClock(math.nan, math.nan, None, "no_clock")
    recv, fix = [], []
    for df in frames.values():
        if len(df) == 0:
            continue
        rows = (df["source"] == key).to_numpy(bool) & ~_stamped(df)
        rows &= df["recv_ns"].to_numpy(np.int64) != MISSING_NS
        if rows.any():
            recv.append(df["recv_ns"].to_numpy(np.int64)[rows])
            fix.append(df["time_ns"].to_numpy(np.int64)[rows])
    drift = None
    if recv:
        r, f = np.concatenate(recv), np.concatenate(fix)
        o = np.argsort(f, kind="stable")
        offset, sigma, drift = time_of_fix_offset(r[o], f[o])
        if key not in configured and len(r) >= MIN_FIXES:
            return SourceClock(offset, sigma, drift, "time_of_fix", "own time of fix", len(r))
    if key in configured:
        return SourceClock(configured[key], 0.0, drift, "configured", "[sources] latency_s")
    if not _has_stamped(frames, key):
        return SourceClock(math.nan, math.nan, None, "own_time", "no receive stamp beside it")
    return SourceClock(math.nan, math.nan, None, "not_determinable")


def _has_stamped(frames: dict[str, pd.DataFrame], key: str) -> bool:
    return any(
        len(df) and bool(((df["source"] == key).to_numpy(bool) & _stamped(df)).any())
        for df in frames.values()
    )


def _series(
    frames: dict[str, pd.DataFrame], kind: str, key: str, column: str, stamped_only: bool
) -> tuple[np.ndarray, np.ndarray]:
    df = frames.get(kind)
    if df is None or len(df) == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    rows = (df["source"] == key).to_numpy(bool).copy()
    if stamped_only:
        rows &= _stamped(df)
    v = df[column].to_numpy(float)
    rows &= np.isfinite(v)
    if rows.any():  # one sentence, the most frequent: a 1 Hz THS beside a 10 Hz HDT is
        # stamped on its own terms, and mixing the two would make the series jagged
        codes = pd.Categorical(df["sentence"]).codes[rows]
        rows[rows] = codes == np.argmax(np.bincount(codes - codes.min())) + codes.min()
    return df["time_ns"].to_numpy(np.int64)[rows], v[rows]


def _on_grid(t_ns: np.ndarray, v: np.ndarray, grid_ns: np.ndarray, angle: bool) -> np.ndarray:
    """``v`` interpolated onto the grid by cubic Hermite pieces with fourth-order slopes
    (angles unwrapped first: a straight line between 1 Hz samples would blunt a yaw's
    rate by a few per cent and bias the lag as much); NaN away from data.  Records of one
    instant count once."""
    t, first = np.unique(t_ns, return_index=True)
    if len(t) < 4:
        return np.full(len(grid_ns), np.nan)
    x = v[first]
    if angle:
        x = np.unwrap(x)
    out = hermite((t - t[0]) / NS_PER_S, x, (grid_ns - t[0]) / NS_PER_S)
    i = np.clip(np.searchsorted(t, grid_ns), 1, len(t) - 1)
    near = np.minimum(np.abs(grid_ns - t[i - 1]), np.abs(t[i] - grid_ns))
    out[near > HOLD_S * NS_PER_S] = np.nan
    return out


def _grid(*series: np.ndarray, step_s: float = GRID_S) -> np.ndarray:
    if any(len(s) == 0 for s in series):
        return np.zeros(0, np.int64)
    lo = max(int(s[0]) for s in series)
    hi = min(int(s[-1]) for s in series)
    if hi - lo < 600 * NS_PER_S:
        return np.zeros(0, np.int64)
    return np.arange(lo, hi, int(step_s * NS_PER_S), dtype=np.int64)


def _heading_keys(voyage: Voyage, frames: dict[str, pd.DataFrame]) -> list[str]:
    df = frames["heading"]
    if len(df) == 0:
        return []
    return sorted({str(k) for k in df["source"][_stamped(df)].unique()} - voyage.clockless)


def _learn_headings(
    voyage: Voyage, frames: dict[str, pd.DataFrame], clocks: dict[str, SourceClock]
) -> None:
    """Step 3 for headings: each unanchored heading against the anchored ones, else the
    GNSS course."""
    keys = _heading_keys(voyage, frames)
    anchors = [k for k in keys if clocks[k].known]
    series = {k: _series(frames, "heading", k, "heading_rad", True) for k in keys}
    for key in keys:
        if clocks[key].known:
            continue
        t, h = series[key]
        if len(t) < 10:
            continue
        best: tuple[LagEstimate, str] | None = None
        for a in anchors:
            ta, ha = series[a]
            if len(ta) < 10:
                continue
            g = _grid(t, ta, step_s=FINE_GRID_S)
            if len(g) == 0:
                continue
            est = rate_lag(
                _on_grid(t, h, g, True),
                _on_grid(ta, ha, g, True),
                FINE_GRID_S,
                angle=True,
                min_rate=MIN_HEADING_RATE,
                highpass_s=HIGHPASS_S,
            )
            est = LagEstimate(est.lag_s + clocks[a].offset_s, _hyp(est, clocks[a]), est.windows)
            if est.usable and (best is None or est.sigma_s < best[0].sigma_s):
                best = (est, a)
        if best is not None:
            clocks[key] = _learned(best[0], "heading_rate", best[1])
            continue
        if anchors:  # say what was tried before the course
            clocks[key] = _learned(LagEstimate(math.nan, math.nan, 0), "", ", ".join(anchors))
        course = _gnss_course(voyage, frames)
        if course is not None:
            slow = _slow_lag((t, h), course, True, MIN_TURN_RATE, (t, h))
            if slow is not None and (slow.usable or not anchors):
                clocks[key] = _learned(slow, "course_rate", "GNSS course over ground")


def _hyp(est: LagEstimate, anchor: SourceClock) -> float:
    return math.hypot(est.sigma_s, anchor.offset_sigma_s)


def _learned(est: LagEstimate, method: str, basis: str) -> SourceClock:
    """A learned offset, or not_determinable where it is too uncertain or implausible."""
    if not est.usable or est.sigma_s > MAX_SIGMA_S or abs(est.lag_s) > MAX_LEARNED_S:
        why = f"{basis}: " + (
            "no turn, yaw or speed change with records close enough to time it"
            if not est.usable
            else f"{est.lag_s:+.2f} ± {est.sigma_s:.2f} s, not applied"
        )
        return SourceClock(math.nan, math.nan, None, "not_determinable", why, est.windows)
    return SourceClock(est.lag_s, est.sigma_s, None, method, basis, est.windows)


def _gnss(voyage: Voyage) -> str | None:
    keys = voyage.role_sources("gnss")
    return keys[0] if keys else None


def _gnss_course(
    voyage: Voyage, frames: dict[str, pd.DataFrame]
) -> tuple[np.ndarray, np.ndarray] | None:
    key = _gnss(voyage)
    if key is None:
        return None
    t, cog = _series(frames, "ground", key, "cog_rad", False)
    t2, sog = _series(frames, "ground", key, "sog_mps", False)
    if len(t) < 10 or len(t2) != len(t):
        return None
    moving = sog > 2.0 * KN_MPS  # a course is a direction only under way
    return t[moving], cog[moving]


def _learn_logs(
    voyage: Voyage, frames: dict[str, pd.DataFrame], clocks: dict[str, SourceClock]
) -> None:
    """Step 3 for logs: the speed through the water against the GNSS speed over ground
    in speed changes (the current's projection on the heading as a sin/cos term)."""
    gnss = _gnss(voyage)
    df = frames["water"]
    if gnss is None or len(df) == 0:
        return
    tg, sog = _series(frames, "ground", gnss, "sog_mps", False)
    compass = voyage.role_sources("compass")
    th, hdg = _series(frames, "heading", compass[0], "heading_rad", True) if compass else (tg, None)
    for key in sorted({str(k) for k in df["source"][_stamped(df)].unique()}):
        if clocks[key].known or key in voyage.clockless:
            continue
        t, v = _series(frames, "water", key, "stw_mps", True)
        if len(t) < 10 or len(tg) < 10:
            continue
        heading = (th, hdg) if hdg is not None else None
        est = _slow_lag((t, v), (tg, sog), False, MIN_ACCEL_MPS2, heading)
        if est is not None:
            clocks[key] = _learned(est, "speed_rate", f"{gnss} speed over ground")


def _slow_lag(
    x: tuple[np.ndarray, np.ndarray],
    ref: tuple[np.ndarray, np.ndarray],
    angle: bool,
    min_rate: float,
    heading: tuple[np.ndarray, np.ndarray] | None,
) -> LagEstimate | None:
    """A series (times, values) timed against the GNSS's (course or speed) on the 1 s
    grid, smoothed over SLOW_SMOOTH_S, with the current's sin/cos of ``heading``; None
    where they do not overlap."""
    g = _grid(x[0], ref[0])
    if len(g) == 0:
        return None
    return rate_lag(
        _on_grid(*x, g, angle),
        _on_grid(*ref, g, angle),
        GRID_S,
        angle=angle,
        smooth_s=SLOW_SMOOTH_S,
        heading_rad=_on_grid(*heading, g, True) if heading is not None else None,
        min_rate=min_rate,
    )


def _apply(
    frames: dict[str, pd.DataFrame], clocks: dict[str, SourceClock]
) -> dict[str, pd.DataFrame]:
    """Step 5: records without a time of fix moved to ``time_ns - offset``; frames re-sorted."""
    shift = {k: int(round(c.offset_s * NS_PER_S)) for k, c in clocks.items() if c.known}
    out = {}
    for kind, df in frames.items():
        if len(df) == 0:
            out[kind] = df
            continue
        if shift:
            by = _per_row(df["source"], shift)
            df = df.assign(time_ns=df["time_ns"].to_numpy(np.int64) - np.where(_stamped(df), by, 0))
        df = df.drop(columns=STAMPED, errors="ignore")
        t = df["time_ns"].to_numpy(np.int64)
        if (t[1:] < t[:-1]).any():
            df = df.iloc[np.argsort(t, kind="stable")].reset_index(drop=True)
        out[kind] = df
    return out


def _per_row(source: pd.Series, value: dict[str, int]) -> np.ndarray:
    """``value[source]`` per row (0 for other keys), through the categorical's codes."""
    cat = pd.Categorical(source)
    table = np.array([value.get(str(c), 0) for c in cat.categories] + [0], dtype=np.int64)
    out: np.ndarray = table[cat.codes]
    return out
