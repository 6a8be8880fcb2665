"""The public entry point: estimate_position, the EP track of a water-track DR.

It learns the error model from the fixes (dracc.math.ep.kalman), forecasts every leg
(dracc.math.ep.forecast) and applies the correction and covariance to the DR track:
EstimatedPosition.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import cast

import numpy as np

from dracc.core.arrays import ArrayLike, BoolArray
from dracc.core.geodesy import add_offset_ne, interp_position, offset_ne_m
from dracc.math.deadreckoning import DRTrack, covered_span_s
from dracc.math.ellipse import error_ellipse
from dracc.math.ep.error_model import ErrorPrior, Hyperparameters
from dracc.math.ep.forecast import LegForecast, forecast_legs
from dracc.math.ep.kalman import LearnedModel, learn_error_model
from dracc.math.uncertainty import radius_2m_m

#: a leg is scored out of sample when its start's posterior has seen at least this span of
#: reference data (or one reset interval, if shorter) and MIN_LEARNED_UPDATES fixes
MIN_LEARNED_S = 1800.0
MIN_LEARNED_UPDATES = 3


@dataclass(frozen=True)
class EstimatedPosition:
    """The EP track (a DRTrack with the current and corrections applied) and how it was learned."""

    track: DRTrack  #: positions, P, 2M of the estimated position
    water: DRTrack  #: the water track (no current, no corrections), as dead_reckon gave it
    model: LearnedModel
    forecast: LegForecast
    learned_leg: BoolArray  #: (L,) bool: the leg's model was learned from earlier fixes
    reference_sigma_m: float  #: the fixes' noise per axis, as learned over the whole voyage


def step_ok_of(track: DRTrack) -> BoolArray:
    """(n-1,) steps along which the water track runs continuously (resets included, breaks not)."""
    leg = track.leg
    on = (leg[:-1] >= 0) & (leg[1:] >= 0)
    new_leg = leg[1:] != leg[:-1]
    reasons = np.asarray(track.leg_start_reason + ("",), dtype=object)
    after_gap = new_leg & (reasons[np.where(leg[1:] >= 0, leg[1:], -1)] == "after-gap")
    return cast(BoolArray, on & ~after_gap)  # == on an object array is typed Any


def estimate_position(
    track: DRTrack,
    ref_time_s: ArrayLike,
    ref_lat_rad: ArrayLike,
    ref_lon_rad: ArrayLike,
    prior: ErrorPrior,
    *,
    ref_max_gap_s: float = 5.0,
    step_s: float | None = None,
    hyper: Hyperparameters | None = None,
) -> EstimatedPosition:
    """The estimated position of every leg of a water-track DR, learned causally (module doc).

    ``step_s``: the filter's step; by default 300 s, shorter for logs under 8 h 20 min
    (at least 100 steps, at least 5 s).
    """
    t = track.time_s
    span = covered_span_s(t, 60.0)
    if step_s is None:
        step_s = float(np.clip(span / 100.0, 5.0, 300.0))
    model = learn_error_model(
        t,
        track.vn_mps,
        track.ve_mps,
        step_ok_of(track),
        ref_time_s,
        ref_lat_rad,
        ref_lon_rad,
        track.leg_start_s,
        prior,
        hyper=hyper,
        step_s=step_s,
        ref_max_gap_s=ref_max_gap_s,
    )
    rlat, rlon = interp_position(
        np.asarray(ref_time_s, float), ref_lat_rad, ref_lon_rad, t, ref_max_gap_s
    )
    y_n, y_e = offset_ne_m(rlat, rlon, track.lat_rad, track.lon_rad)
    fc = forecast_legs(
        t, track.vn_mps, track.ve_mps, track.leg, model, ref_offset_ne_m=np.column_stack([y_n, y_e])
    )
    on = track.leg >= 0
    lat = np.full(t.size, np.nan)
    lon = np.full(t.size, np.nan)
    lat[on], lon[on] = add_offset_ne(
        track.lat_rad[on], track.lon_rad[on], fc.offset_ne_m[on, 0], fc.offset_ne_m[on, 1]
    )
    P = fc.P_m2
    radius = radius_2m_m(P)
    smaj, smin, orient = error_ellipse(np.nan_to_num(P))
    nan = ~np.isfinite(radius)
    smaj, smin, orient = (np.where(nan, np.nan, a) for a in (smaj, smin, orient))
    ep = replace(
        track,
        lat_rad=lat,
        lon_rad=lon,
        P_m2=P,
        radius_2m_m=radius,
        semi_major_m=smaj,
        semi_minor_m=smin,
        orientation_rad=orient,
    )
    need_s = min(MIN_LEARNED_S, track.reset_s)
    learned = (model.learned_s >= need_s) & (model.n_updates >= MIN_LEARNED_UPDATES)
    ref_sigma = math.sqrt(float(model.final_weights @ model.hyper.fix_sigma_m**2))
    return EstimatedPosition(
        track=ep,
        water=track,
        model=model,
        forecast=fc,
        learned_leg=learned,
        reference_sigma_m=ref_sigma,
    )
