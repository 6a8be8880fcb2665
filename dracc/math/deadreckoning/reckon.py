"""The dead-reckoning entry point :func:`dead_reckon`: checked inputs, held samples,
velocities over ground, the legs, their propagation and the assembled :class:`DRTrack`."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from dracc.core.arrays import FloatArray, IntArray, unique_sorted
from dracc.core.bounds import check_work
from dracc.core.config import DeadReckoningConfig
from dracc.core.errors import ConfigError, InsufficientDataError
from dracc.math.deadreckoning.error_processes import (
    ErrorProcess,
    error_processes,
    honest_covariance_m2,
)
from dracc.math.deadreckoning.holding import HeldSamples, hold_samples
from dracc.math.deadreckoning.legs import Leg, as_fixes, plan_legs
from dracc.math.deadreckoning.propagation import (
    integrate_ne,
    velocity_ground_ne_mps,
    velocity_water_ne_mps,
)
from dracc.math.deadreckoning.schedule import covered_span_s, dr_schedule
from dracc.math.deadreckoning.track import DRTrack
from dracc.math.ellipse import error_ellipse
from dracc.math.uncertainty import radius_2m_m

__all__ = ["dead_reckon"]


@dataclass(frozen=True)
class _CheckedInputs:
    """The samples as float arrays, checked, and the schedule the DR runs on."""

    t: FloatArray
    heading_rad: FloatArray
    speed_mps: FloatArray
    max_gap_s: float
    reset_s: float
    epoch_interval_s: float


def _check_inputs(
    time_s: ArrayLike,
    heading_rad: ArrayLike,
    speed_mps: ArrayLike,
    cfg: DeadReckoningConfig,
    *,
    mode: str,
    current_ne_mps: ArrayLike | None,
    max_gap_s: float | None,
    reset_s: float | str | None,
    epoch_interval_s: float | None,
) -> _CheckedInputs:
    """Mode, schedule and samples checked, in this order (ValueError, ConfigError,
    InsufficientDataError)."""
    if mode not in ("water", "ground"):
        raise ValueError(f"mode must be 'water' or 'ground', got {mode!r}")
    if mode == "ground" and current_ne_mps is not None:
        raise ValueError("a current applies to a water (relative) log only")
    max_gap = float(cfg.max_gap_s if max_gap_s is None else max_gap_s)
    reset, _, auto_epoch = dr_schedule(cfg, covered_span_s(time_s, max_gap), reset_s)
    epoch_dt = float(auto_epoch if epoch_interval_s is None else epoch_interval_s)
    if not max_gap > 0 or not epoch_dt > 0:
        raise ConfigError(
            f"[dead_reckoning] max_gap_s ({max_gap}) and epoch_interval_s ({epoch_dt}) "
            "must be positive"
        )

    t = np.asarray(time_s, float)
    n = t.size
    hdg = np.asarray(heading_rad, float)
    spd = np.asarray(speed_mps, float)
    if hdg.shape != (n,) or spd.shape != (n,):
        raise ValueError("time_s, heading_rad and speed_mps must be 1-D of equal length")
    if n == 0 or not np.any(np.isfinite(hdg)):
        raise InsufficientDataError(
            "dead reckoning needs a heading: the log has no heading values at all "
            "(it will not assume north)"
        )
    if not np.any(np.isfinite(spd)):
        raise InsufficientDataError("dead reckoning needs a speed: the log has no speed values")
    if np.any(np.diff(t) <= 0) or not np.all(np.isfinite(t)):
        raise ValueError("time_s must be finite and strictly increasing")
    return _CheckedInputs(t, hdg, spd, max_gap, reset, epoch_dt)


def _velocity_over_ground(
    held: HeldSamples, mode: str, current_ne_mps: ArrayLike | None
) -> tuple[FloatArray, FloatArray]:
    """(VN, VE) per sample: water log plus the known current (B7-B12), or ground log (B13, B14)."""
    n = held.speed_mps.size
    if mode == "water":
        if current_ne_mps is not None:
            cur = np.broadcast_to(np.asarray(current_ne_mps, float), (n, 2))
            c_speed: FloatArray | float = np.hypot(cur[:, 0], cur[:, 1])
            c_set: FloatArray | float = np.arctan2(cur[:, 1], cur[:, 0])
        else:
            c_speed, c_set = 0.0, 0.0
        return velocity_water_ne_mps(held.speed_mps, held.course_rad, c_speed, c_set)  # (B7)-(B12)
    return velocity_ground_ne_mps(held.speed_mps, held.course_rad)  # (B13), (B14)


@dataclass(frozen=True)
class _LegsPropagated:
    """Per-sample positions, covariance and leg bookkeeping of all legs (NaN / -1 outside)."""

    lat_rad: FloatArray
    lon_rad: FloatArray
    P_m2: FloatArray
    since_fix_s: FloatArray
    leg: IntArray


def _propagate_legs(
    t: FloatArray,
    vn: FloatArray,
    ve: FloatArray,
    held: HeldSamples,
    legs: Sequence[Leg],
    processes: Sequence[ErrorProcess],
    *,
    covariance: bool,
    covariance_step_s: float | None,
) -> _LegsPropagated:
    """Integrate each leg on the ellipsoid (B16-B22) and propagate its honest covariance."""
    n = t.size
    lat = np.full(n, np.nan)
    lon = np.full(n, np.nan)
    P = np.full((n, 2, 2), np.nan)
    since = np.full(n, np.nan)
    leg_of = np.full(n, -1, dtype=np.int64)
    for leg_id, leg in enumerate(legs):
        sl = slice(leg.start, leg.end + 1)
        la, lo = integrate_ne(t[sl], vn[sl], ve[sl], leg.lat0_rad, leg.lon0_rad)
        if covariance:
            Pl = honest_covariance_m2(
                t[sl],
                held.speed_mps[sl],
                held.course_rad[sl],
                processes,
                P0_m2=leg.sigma0_m**2 * np.eye(2),
                step_s=covariance_step_s,
            )
        else:
            Pl = np.full((leg.end + 1 - leg.start, 2, 2), np.nan)
        keep = slice(leg.start, leg.last)
        m = leg.last - leg.start
        lat[keep] = la[:m]
        lon[keep] = lo[:m]
        P[keep] = Pl[:m]
        since[keep] = t[keep] - t[leg.start]
        leg_of[keep] = leg_id
    return _LegsPropagated(lat, lon, P, since, leg_of)


def _epoch_indices(
    t: FloatArray, lat_rad: FloatArray, epoch_interval_s: float, max_gap_s: float
) -> IntArray:
    """The first sample at or after each multiple of ``epoch_interval_s``, where it is at
    most ``max_gap_s`` late and on a leg."""
    epoch_dt = epoch_interval_s
    # the grid only where a sample can follow within max_gap_s: a stray record years away
    # asks for no grid over the silence (the same epochs as one grid over the whole span)
    cut = np.flatnonzero(np.diff(t) > max_gap_s) + 1
    lo = np.concatenate(([t[0]], t[cut] - max_gap_s))
    hi = np.concatenate((t[cut - 1], [t[-1]]))
    check_work("dead_reckoning", "epoch_interval_s", epoch_dt, float(np.sum(hi - lo)))
    n = t.size
    grid = np.concatenate(
        [
            np.arange(math.ceil(a / epoch_dt) * epoch_dt, b + 1e-9, epoch_dt)
            for a, b in zip(lo, hi, strict=True)
        ]
    )
    ei = np.searchsorted(t, grid, side="left")
    inside = ei < n
    ei, grid = ei[inside], grid[inside]
    epochs: IntArray = unique_sorted(ei[(t[ei] - grid <= max_gap_s) & np.isfinite(lat_rad[ei])])
    return epochs


def _assemble_track(
    inputs: _CheckedInputs,
    held: HeldSamples,
    vn: FloatArray,
    ve: FloatArray,
    legs: Sequence[Leg],
    run: _LegsPropagated,
    mode: str,
) -> DRTrack:
    """The track: 2M (B30, B31), the 1-sigma ellipse, the epochs and the leg summary."""
    P = run.P_m2
    trace = P[:, 0, 0] + P[:, 1, 1]
    radius = radius_2m_m(P)
    smaj, smin, orient = error_ellipse(np.nan_to_num(P))
    nan = ~np.isfinite(trace)
    smaj, smin, orient = (np.where(nan, np.nan, x) for x in (smaj, smin, orient))
    t = inputs.t
    return DRTrack(
        time_s=t,
        lat_rad=run.lat_rad,
        lon_rad=run.lon_rad,
        vn_mps=np.where(run.leg >= 0, vn, np.nan),
        ve_mps=np.where(run.leg >= 0, ve, np.nan),
        P_m2=P,
        radius_2m_m=radius,
        semi_major_m=smaj,
        semi_minor_m=smin,
        orientation_rad=orient,
        since_fix_s=run.since_fix_s,
        leg=run.leg,
        leg_start_s=np.asarray([float(t[leg.start]) for leg in legs]),
        leg_start_reason=tuple(leg.reason for leg in legs),
        epoch_index=_epoch_indices(t, run.lat_rad, inputs.epoch_interval_s, inputs.max_gap_s),
        gaps=held.gaps,
        mode=mode,
        reset_s=inputs.reset_s,
        n_invalid_samples=held.n_invalid,
    )


def dead_reckon(
    time_s: ArrayLike,
    heading_rad: ArrayLike,
    speed_mps: ArrayLike,
    *,
    errors: DeadReckoningConfig | None = None,
    lat0_rad: float | None = None,
    lon0_rad: float | None = None,
    sigma0_m: float | None = None,
    fixes: tuple[ArrayLike, ...] | None = None,
    reset_s: float | str | None = None,
    transverse_mps: ArrayLike | None = None,
    current_ne_mps: ArrayLike | None = None,
    mode: str = "water",
    max_gap_s: float | None = None,
    epoch_interval_s: float | None = None,
    covariance_step_s: float | None = 1.0,
    covariance: bool = True,
) -> DRTrack:
    """Dead-reckon a track from heading and speed samples, with the honest 2M circle.

    time_s (n,) increasing seconds from any epoch.  heading_rad (n,): the *true* heading
    (course through the water for ``mode='water'``, course over ground for 'ground'),
    i.e. (B2) or (B3) already applied (see :func:`course_magnetic_rad`,
    :func:`course_gyro_rad`); speed_mps (n,) the log's longitudinal speed.  NaN marks a
    missing value.  ``transverse_mps`` (n,) the log's transverse component (starboard
    +): speed by (B1), leeway/drift angle by (B5)/(B6) added to the heading.
    ``current_ne_mps`` (2,) or (n, 2) a known current added in water mode (B11, B12).

    Start: (lat0_rad, lon0_rad) with 1-sigma ``sigma0_m`` per axis at time_s[0], or the
    first fix.  ``fixes`` = (time_s, lat_rad, lon_rad[, sigma_m]): the track restarts at
    the first fix at or after ``leg start + reset_s`` (or, after a break, at the first fix
    after the data resume), from the fix advanced to the next sample by the held velocity,
    with P0 = sigma_m^2 I.  ``reset_s``: seconds or "1h"/"watch"/"never" (default
    ``errors.reset``).  ``errors`` (default DeadReckoningConfig()) gives the error sources,
    ``max_gap_s`` and ``epoch_interval_s`` unless overridden.

    Heading and speed are held independently, each from its own last valid sample (as
    (B20) holds the velocity), so a union time base of a 10 Hz compass and a 1 Hz log
    with NaN where a channel has no sample is the expected input.  A channel missing for
    at most ``max_gap_s`` (between two of its valid samples) is bridged; a longer gap
    breaks the track (positions NaN until the next fix).  Intervals longer than twice a
    channel's usual spacing are reported in ``gaps``.  Raises InsufficientDataError when
    there is no heading at all, no speed at all, or no start position.

    ``covariance_step_s``: the correlated error processes are propagated on a grid of
    about this step where the data are denser (see :func:`honest_covariance_m2`);
    None propagates at every sample (exact, slower at 10 Hz).  ``covariance=False`` skips
    the configured covariance (P, 2M and the ellipse are NaN): for a caller that forms its
    own, as :func:`dracc.math.ep.estimate_position` does.
    """
    cfg = errors if errors is not None else DeadReckoningConfig()
    inputs = _check_inputs(
        time_s,
        heading_rad,
        speed_mps,
        cfg,
        mode=mode,
        current_ne_mps=current_ne_mps,
        max_gap_s=max_gap_s,
        reset_s=reset_s,
        epoch_interval_s=epoch_interval_s,
    )
    t = inputs.t
    vy = None if transverse_mps is None else np.asarray(transverse_mps, float)
    held = hold_samples(t, inputs.heading_rad, inputs.speed_mps, vy, inputs.max_gap_s)
    vn, ve = _velocity_over_ground(held, mode, current_ne_mps)

    fx = as_fixes(fixes, cfg.fix_sigma_m)
    sigma0 = float(cfg.fix_sigma_m if sigma0_m is None else sigma0_m)
    processes = error_processes(cfg, mode)
    start = None
    if lat0_rad is not None and lon0_rad is not None:
        start = (float(lat0_rad), float(lon0_rad), sigma0)
    legs = plan_legs(t, vn, ve, held, fx, inputs.reset_s, start)
    run = _propagate_legs(
        t,
        vn,
        ve,
        held,
        legs,
        processes,
        covariance=covariance,
        covariance_step_s=covariance_step_s,
    )
    return _assemble_track(inputs, held, vn, ve, legs, run, mode)
