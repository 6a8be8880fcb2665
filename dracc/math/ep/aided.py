"""The aided-DR estimated position of seeds/003: fixes and single lines of position, the EP
track at its epochs, and the update-interval study of its Figure 5.

The filter is :func:`dracc.math.current.estimate_current` (state p_N, p_E, c_N, c_E, exact
Gauss-Markov discretisation, EKF update in Joseph form).  This module feeds it and reads it:

- ``run_aided``: GNSS fixes and timed observations (``PositionFix``, ``RangeLOP``,
  ``BearingLOP``, ``LineLOP``) merged in time order; a single line of position has a 1x4 H,
  so the ellipse shrinks only across the line (seeds/003, Figure 4, sequential updates).
- ``epoch_rows``: the filter's epochs thinned to the reporting interval, plus the first
  epoch at or after every update, with the time since the last update and its kind.
- ``interval_study``: the filter re-run with the fixes thinned to each interval; 2M just
  before each update (2 sqrt(trace P^-), (B30)/(B31)) and the out-of-sample containment: the
  fraction of fixes, not yet used, whose innovation lies inside the 95 % ellipse of its
  covariance S = H P^- H^T + R (NIS <= chi^2_2(0.95) = -2 ln 0.05).  seeds/003, Figure 5:
  the covariance stays bounded for every interval but grows with it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dracc.core.arrays import ArrayLike, FloatArray, IntArray
from dracc.math.current import CurrentModel, CurrentTrack, estimate_current
from dracc.math.fusion import Observation, PositionFix

#: chi^2 with 2 degrees of freedom at 0.95: an innovation inside the 95 % ellipse
NIS_95_2DOF = -2.0 * math.log(0.05)


@dataclass(frozen=True)
class TimedUpdate:
    """One measurement for the filter: its time (s), the observation, a label ('gnss', 'range 1')."""

    t_s: float
    obs: Observation
    label: str


@dataclass(frozen=True)
class AidedRun:
    """The filter over one stretch and the updates it used, in time order."""

    track: CurrentTrack
    updates: tuple[TimedUpdate, ...]


def thinned_fixes(fix_s: ArrayLike, t_from: float, t_to: float, interval_s: float) -> IntArray:
    """Indices of one fix per ``interval_s`` (the first at or after each multiple from ``t_from``)
    within [t_from, t_to]; ``fix_s`` ascending."""
    f = np.asarray(fix_s, float)
    grid = np.arange(t_from, t_to, interval_s)
    pick = np.unique(np.searchsorted(f, grid, side="left"))
    pick = pick[pick < f.size]
    return pick[(f[pick] >= t_from) & (f[pick] <= t_to)].astype(np.int64)


def run_aided(
    t_s: ArrayLike,
    course_rad: ArrayLike,
    speed_mps: ArrayLike,
    start: PositionFix,
    updates: Sequence[TimedUpdate],
    model: CurrentModel,
) -> AidedRun:
    """The EP over epochs ``t_s`` from ``start``, updated by ``updates`` (any order; those outside
    (t_s[0], t_s[-1]] are left out)."""
    t = np.asarray(t_s, float)
    used = sorted((u for u in updates if t[0] < u.t_s <= t[-1]), key=lambda u: u.t_s)
    track = estimate_current(t, course_rad, speed_mps, start, [(u.t_s, u.obs) for u in used], model)
    return AidedRun(track, tuple(used))


@dataclass(frozen=True)
class EpochRows:
    """Which filter epochs a report shows, and what happened at each."""

    index: IntArray  #: into the track's epochs
    since_update_s: FloatArray  #: since the last update (the start fix before the first)
    update_kind: tuple[str, ...]  #: the labels of the updates applied since the row before; '' none


def epoch_rows(run: AidedRun, every_s: float) -> EpochRows:
    """The epochs every ``every_s`` from the first, plus the first epoch at or after each update."""
    t = run.track.t_s
    bins = np.floor((t - t[0]) / every_s)
    regular = np.flatnonzero(np.r_[True, bins[1:] != bins[:-1]])
    ut = np.array([u.t_s for u in run.updates], float)
    at = np.searchsorted(t, ut, side="left").clip(0, t.size - 1)
    idx = np.unique(np.concatenate([regular, at, [t.size - 1]])).astype(np.int64)
    last = np.searchsorted(ut, t[idx], side="right") - 1
    ref = np.where(last >= 0, ut[last.clip(0)] if ut.size else t[0], t[0])
    since = t[idx] - ref  # from the start fix before the first update
    kinds = []
    prev = -1
    for k in last:
        kinds.append(", ".join(u.label for u in run.updates[prev + 1 : k + 1]))
        prev = max(prev, int(k))
    return EpochRows(idx, np.asarray(since, float), tuple(kinds))


@dataclass(frozen=True)
class IntervalRow:
    """One row of the update-interval study (seeds/003, Figure 5)."""

    interval_s: float
    n_updates: int  #: updates scored (the fixes after the start fix)
    mean_2m_before_m: float  #: 2M just before an update, mean over the updates
    max_2m_before_m: float
    containment: float  #: fraction of the fixes, before use, inside their 95 % innovation ellipse
    #: the probability the model gives a fix of being inside (a correct model's containment):
    #: 0.95 for one Gaussian model, the mixture's for the learned grid (dracc.math.ep.interval)
    expected_containment: float = 0.95
    #: the error model the filter ran on: "configured" (``CurrentModel.from_config``) or
    #: "learned" (the voyage's learned model, dracc.math.ep.interval)
    model: str = "configured"


def interval_study(
    t_s: ArrayLike,
    course_rad: ArrayLike,
    speed_mps: ArrayLike,
    fix_s: ArrayLike,
    fix_lat_rad: ArrayLike,
    fix_lon_rad: ArrayLike,
    fix_sigma_m: float,
    model: CurrentModel,
    intervals_s: Sequence[float],
) -> list[tuple[FloatArray, FloatArray]]:
    """For each interval: (2M before each update, NIS of each update), flattened over runs.

    The filter starts at the first fix at or after ``t_s[0]`` (as ``thinned_fixes`` picks
    it) and is updated by the later picks.  ``fix_lat_rad``, ``fix_lon_rad``: (m,) or
    (runs, m) (a Monte Carlo batch of the same fix times); ``intervals_s`` as given."""
    t = np.asarray(t_s, float)
    lat = np.atleast_2d(np.asarray(fix_lat_rad, float))
    lon = np.atleast_2d(np.asarray(fix_lon_rad, float))
    fs = np.asarray(fix_s, float)
    out = []
    for interval in intervals_s:
        pick = thinned_fixes(fs, t[0], t[-1], float(interval))
        if pick.size < 2:
            out.append((np.empty(0), np.empty(0)))
            continue
        i0 = int(pick[0])
        run_t = t[t >= fs[i0]]
        start = PositionFix.from_sigma(lat[:, i0].squeeze(), lon[:, i0].squeeze(), fix_sigma_m)
        obs = [
            (
                float(fs[i]),
                PositionFix.from_sigma(lat[:, i].squeeze(), lon[:, i].squeeze(), fix_sigma_m),
            )
            for i in pick[1:]
            if fs[i] <= run_t[-1]
        ]
        k = np.searchsorted(t, run_t[0])
        track = estimate_current(
            run_t, np.asarray(course_rad)[k:], np.asarray(speed_mps)[k:], start, obs, model
        )
        before = np.array(
            [2.0 * np.sqrt(np.trace(u.cov_before_m2, axis1=-2, axis2=-1)) for u in track.updates]
        )
        nis = np.array([np.atleast_1d(u.nis) for u in track.updates])
        out.append((before.ravel(), nis.ravel()))
    return out


def interval_rows(
    intervals_s: Sequence[float],
    study: Sequence[tuple[FloatArray, ...]],
    model: str = "configured",
) -> tuple[IntervalRow, ...]:
    """The table from :func:`interval_study` results (several stretches' pooled per interval):
    (2M before, NIS) per update, or (2M before, NIS, the model's probability of the fix
    inside) as :func:`dracc.math.ep.interval.learned_interval_study` gives them."""
    rows = []
    for interval, (before, nis, *p_in) in zip(intervals_s, study, strict=True):
        n = int(nis.size)
        expected = float(np.mean(p_in[0])) if p_in and n else 0.95 if n else math.nan
        rows.append(
            IntervalRow(
                float(interval),
                n,
                float(before.mean()) if n else math.nan,
                float(before.max()) if n else math.nan,
                float(np.mean(nis <= NIS_95_2DOF)) if n else math.nan,
                expected,
                model,
            )
        )
    return tuple(rows)
