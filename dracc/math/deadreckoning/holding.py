"""Sample-and-hold of the heading and speed channels, and the data gaps that break a track.

Heading and speed are held independently, each from its own last valid sample (as
(B20) holds the velocity), so a union time base of a 10 Hz compass and a 1 Hz log with
NaN where a channel has no sample is the expected input.  A channel missing for at most
``max_gap_s`` is bridged; a longer gap breaks the track.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dracc.core.arrays import BoolArray, FloatArray, IntArray
from dracc.core.geodesy import wrap_2pi
from dracc.math.deadreckoning.heading import (
    leeway_from_log_rad,
    speed_from_components_mps,
)
from dracc.math.deadreckoning.track import Gap

__all__ = ["HeldSamples", "hold_samples"]


@dataclass(frozen=True)
class HeldSamples:
    """Speed and course made good per sample from the held channels, and where they hold."""

    speed_mps: FloatArray  #: (n,) the held log speed ((B1) with a transverse component)
    course_rad: FloatArray  #: (n,) the held heading, plus the leeway angle (B5)/(B6) if given
    step_ok: BoolArray  #: (n-1,) step k (t_k -> t_k+1) has both channels within max_gap_s
    valid: BoolArray  #: (n,) the sample has both a heading and a speed
    next_valid: IntArray  #: (n,) index of the first valid sample at or after k (n: none)
    gaps: tuple[Gap, ...]  #: both channels' gaps, by start time
    n_invalid: int  #: samples without heading or speed


def _hold_channel(
    t: FloatArray, ok: BoolArray, max_gap_s: float, channel: str
) -> tuple[IntArray, BoolArray, list[Gap]]:
    """Sample-and-hold for one channel: (index of the value held at each sample, usable
    steps (n-1,), gaps).  Step k (t_k -> t_k+1) is usable when the interval between the
    valid samples around it is at most ``max_gap_s``; intervals longer than twice the
    channel's typical spacing are reported as gaps (bridged or breaking)."""
    n = t.size
    idx = np.arange(n)
    last = np.maximum.accumulate(np.where(ok, idx, -1))
    nxt = np.minimum.accumulate(np.where(ok, idx, n)[::-1])[::-1]
    lv = last[:-1]
    lv_time = np.where(lv >= 0, t[np.maximum(lv, 0)], -np.inf)
    # end of the interval: the next valid sample, or (trailing invalid samples) the step's end
    end_time = np.where(nxt[1:] >= n, t[1:], t[np.minimum(nxt[1:], n - 1)])
    steps_ok = (lv >= 0) & (end_time - lv_time <= max_gap_s)
    vidx = np.flatnonzero(ok)
    tv = t[vidx]
    dtv = np.diff(tv)
    gaps = []
    if dtv.size:
        typical = float(np.median(dtv))
        for j in np.flatnonzero(dtv > 2.0 * typical):
            gaps.append(Gap(float(tv[j]), float(tv[j + 1]), bool(dtv[j] <= max_gap_s), channel))
    if vidx.size and vidx[-1] < n - 1 and t[-1] - tv[-1] > max_gap_s:
        gaps.append(Gap(float(tv[-1]), math.inf, False, channel))
    if vidx.size and vidx[0] > 0:  # nothing to hold before the first value
        gaps.insert(0, Gap(float(t[0]), float(tv[0]), False, channel))
    return np.maximum(last, 0), steps_ok, gaps


def hold_samples(
    t: FloatArray,
    heading_rad: FloatArray,
    speed_mps: FloatArray,
    transverse_mps: FloatArray | None,
    max_gap_s: float,
) -> HeldSamples:
    """Hold each channel over its gaps up to ``max_gap_s`` and form speed and course.

    With a transverse component the speed is (B1) and the leeway angle (B5)/(B6) is added
    to the heading; the speed channel is valid where both components are.
    """
    n = t.size
    hdg, spd, vy = heading_rad, speed_mps, transverse_mps
    heading_ok = np.isfinite(hdg)
    speed_ok = np.isfinite(spd) if vy is None else np.isfinite(spd) & np.isfinite(vy)
    n_invalid = int(n - np.sum(heading_ok & speed_ok))

    gaps: list[Gap] = []
    step_ok = np.ones(n - 1, dtype=bool)
    held = []
    for channel, ok in (("heading", heading_ok), ("speed", speed_ok)):
        src, ok_steps, ch_gaps = _hold_channel(t, ok, max_gap_s, channel)
        step_ok &= ok_steps
        held.append(src)
        gaps.extend(ch_gaps)
    gaps.sort(key=lambda g: (g.start_s, g.channel))
    src_h, src_v = held
    if vy is not None:
        # (B1) speed and (B5)/(B6) leeway angle from the log's two components
        speed_f = speed_from_components_mps(spd[src_v], vy[src_v])  # (B1)
        course_f: FloatArray = wrap_2pi(
            hdg[src_h] + leeway_from_log_rad(spd[src_v], vy[src_v])
        )  # (B2)/(B3) + z
    else:
        speed_f = spd[src_v]
        course_f = wrap_2pi(hdg[src_h])
    valid = heading_ok & speed_ok
    next_valid = np.minimum.accumulate(np.where(valid, np.arange(n), n)[::-1])[::-1]
    return HeldSamples(
        speed_mps=speed_f,
        course_rad=course_f,
        step_ok=step_ok,
        valid=valid,
        next_valid=next_valid,
        gaps=tuple(gaps),
        n_invalid=n_invalid,
    )
