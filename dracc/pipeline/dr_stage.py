"""The dead-reckoning stage (METHODS section 2): the DR from the compass and the log on
a DR_STEP_S grid, restarted from the fixes, with the estimated position learned from
earlier fixes where ``learn = true``; scored out of sample against the reference.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from dracc.core.config import DeadReckoningConfig
from dracc.core.errors import InsufficientDataError
from dracc.core.geodesy import interp_position, offset_ne_m, wrap_2pi
from dracc.frames import Voyage
from dracc.math.deadreckoning import (
    Consistency,
    DRTrack,
    covered_span_s,
    dead_reckon,
    dr_consistency,
    dr_schedule,
    leeway_from_log_rad,
    speed_from_components_mps,
)
from dracc.math.ep import estimate_position
from dracc.math.integrity.causes import Span
from dracc.math.uncertainty import GAUSSIAN
from dracc.pipeline.dr_honesty import honesty
from dracc.pipeline.dr_model import (
    dominant_source,
    error_prior,
    fix_innovations,
    jump_sentence,
    learned_summary,
    legs_touched,
)
from dracc.pipeline.notes import dr_notes, dr_verdict
from dracc.pipeline.results import DRLeg, DRSection, DRTrackResult
from dracc.pipeline.selection import (
    DRInputs,
    Fixes,
    fix_source_key,
    grid_series,
    heading_series,
    ref_gap_s,
    reference_fixes,
    speed_series,
)


def dead_reckoning(
    voyage: Voyage,
    cfg: DeadReckoningConfig,
    missing: list[str],
    notes: list[str],
    jumps: Mapping[str, Sequence[Span]] | None = None,
) -> tuple[DRSection | None, Fixes | None, DRInputs | None]:
    """Run the DR on a DR_STEP_S grid from the compass and the log; score it against the
    reference.  Returns (section, fixes, what the DR ran on); None where it could not run,
    said in ``missing``.  ``jumps``: per source, the spans of its failed jump check
    (:func:`dracc.math.integrity.causes.jump_spans`): a DR found inconsistent is scored
    again without the legs a jump of its reference touched, and names no part of its 2M
    as the cause where it passes without them."""
    heading = heading_series(voyage, cfg, missing, notes)
    speed = speed_series(voyage, missing)
    fixes = reference_fixes(voyage, cfg, missing, notes)
    if heading is None or speed is None or fixes is None:
        if heading is not None or speed is not None:
            missing.append("dead reckoning not computed (see above)")
        return None, fixes, None
    hdg_desc, (spd_desc, mode) = heading[2], speed[3:]
    series = grid_series(heading, speed, missing, notes)
    if series is None:
        return None, fixes, None
    grid, h_g, v_g, vy_g = (
        series.grid_ns,
        series.heading_rad,
        series.speed_mps,
        series.transverse_mps,
    )
    ft, flat, flon, fdesc = fixes
    gap_s = ref_gap_s(ft)
    time_s = (grid - grid[0]) / 1e9
    fix_s = (ft - grid[0]) / 1e9
    reset_s, reset_label, epoch_s = dr_schedule(cfg, covered_span_s(time_s, cfg.max_gap_s))
    try:
        tr = dead_reckon(
            time_s,
            h_g,
            v_g,
            errors=cfg,
            fixes=(fix_s, flat, flon),
            transverse_mps=vy_g,
            mode=mode,
            covariance=not cfg.learn,
            reset_s=reset_s,
            epoch_interval_s=epoch_s,
        )
    except InsufficientDataError as err:
        missing.append(f"dead reckoning not computed: {err}")
        return None, fixes, None
    water = tr
    est = None
    if cfg.learn:
        gyro = hdg_desc.endswith("true)")
        est = estimate_position(
            water,
            fix_s,
            flat,
            flon,
            error_prior(cfg, float(np.nanmedian(flat)), gyro, v_g),
            ref_max_gap_s=gap_s,
        )
        tr = est.track
    # rows of legs whose model was learned from earlier fixes: the only ones scored
    learned_leg = est.learned_leg if est is not None else np.ones(tr.n_legs, bool)
    learned_row = (tr.leg >= 0) & learned_leg[np.maximum(tr.leg, 0)]
    ei = np.asarray(tr.epoch_index, dtype=np.int64)

    def score(rows: np.ndarray) -> Consistency:
        return dr_consistency(
            replace(tr, epoch_index=ei[rows[ei]]),
            fix_s,
            flat,
            flon,
            max_ref_gap_s=gap_s,
            ref_sigma_m=est.reference_sigma_m if est is not None else 0.0,
            shape=est.forecast.sample_shape if est is not None else GAUSSIAN,
        )

    cons = score(learned_row)
    fkey = fix_source_key(voyage, fdesc)
    touched = legs_touched(tr, int(grid[0]), (jumps or {}).get(fkey or "", ()))
    jump_legs = [lc for lc in cons.legs if touched[lc.leg]]
    rest, without = cons, None
    if jump_legs and cons.verdict.startswith("inconsistent"):
        rest = score(learned_row & ~touched[np.maximum(tr.leg, 0)])
        without = rest.verdict.partition(" (")[0]
    # the actual error at every sample (for the growth plot and the tables)
    rlat, rlon = interp_position(ft, flat, flon, grid, gap_s * 1e9)
    dn, de = offset_ne_m(tr.lat_rad, tr.lon_rad, rlat, rlon)
    ref_err = np.hypot(dn, de)
    scored_row = learned_row & (tr.since_fix_s > 0)
    judged = _per_sample(tr.time_s, cons)

    def rows(idx: np.ndarray) -> DRTrackResult:
        return DRTrackResult(
            time_ns=grid[idx],
            lat_rad=tr.lat_rad[idx],
            lon_rad=tr.lon_rad[idx],
            since_fix_s=tr.since_fix_s[idx],
            radius_2m_m=tr.radius_2m_m[idx],
            semi_major_m=tr.semi_major_m[idx],
            semi_minor_m=tr.semi_minor_m[idx],
            orientation_rad=tr.orientation_rad[idx],
            ref_error_m=ref_err[idx],
            leg=tr.leg[idx].astype(np.int64),
            water_lat_rad=water.lat_rad[idx],
            water_lon_rad=water.lon_rad[idx],
            scored=scored_row[idx],
            inside=judged.inside[idx],
            p_inside=judged.p_inside[idx],
            pit=judged.pit[idx],
        )

    n_prior = int(np.sum((tr.since_fix_s[ei] > 0) & ~learned_row[ei])) if est is not None else 0
    # where the DR passes without the legs its reference's jump touched, the jump is the
    # cause: no part of the 2M is named for it
    blame = est is not None and without in (None, "inconsistent")
    dominant = dominant_source(est, rest, tr, fix_s) if blame and est is not None else None
    consistent, verdict = dr_verdict(cons, est is not None, dominant)
    if without is not None:
        verdict += jump_sentence(str(fkey), jump_legs, cons.n_legs, without)
    section = DRSection(
        heading_source=hdg_desc,
        speed_source=spd_desc,
        reset=reset_label,
        epoch_interval_s=float(epoch_s),
        track=rows(tr.leg >= 0),
        epochs=rows(ei),
        legs=_legs(tr, cons, grid, fdesc),
        reference_role=fdesc,
        containment_2m=cons.inside_fraction,
        n_scored=cons.n_epochs,
        expected_inside=cons.expected_inside_fraction,
        error_over_m_rms=cons.rms_error_over_m,
        consistent=consistent,
        verdict=verdict,
        n_gaps_bridged=int(sum(g.bridged for g in tr.gaps)),
        n_breaks=int(tr.n_breaks),
        notes=tuple(dr_notes(tr, cons, est, cfg, fdesc, reset_s, n_prior)),
        mean_nees=cons.mean_nees,
        nees_statistic=cons.nees_statistic,
        nees_lower=cons.nees_lower,
        nees_upper=cons.nees_upper,
        leg_checks=cons.legs,
        dominant_source=dominant[0] if dominant else None,
        dominant_key=dominant[1] if dominant else None,
        learned=learned_summary(est, cfg) if est is not None else None,
        reference_sigma_m=cons.reference_sigma_m,
        scored_out_of_sample=est is not None,
        fix_innovations=fix_innovations(est, grid[0]),
        fix_source_key=fkey,
        honesty=honesty(cons, est),
        reference_jump_legs=tuple(lc.leg for lc in jump_legs) if without else (),
        verdict_without_jump_legs=without,
    )
    # course and speed through the water for the calibration: leeway (B5) and speed (B1)
    # from a two-component log, as the DR used them
    if vy_g is not None:
        course_w = wrap_2pi(h_g + leeway_from_log_rad(v_g, vy_g))  # (B3)/(B2) + z (B5)
        speed_w = speed_from_components_mps(v_g, vy_g)  # (B1)
    else:
        course_w, speed_w = h_g, v_g
    inputs = DRInputs(
        t0_ns=int(grid[0]),
        time_s=time_s,
        vn_mps=water.vn_mps,
        ve_mps=water.ve_mps,
        heading_rad=course_w,
        speed_mps=speed_w,
        ref_gap_s=gap_s,
        mode=mode,
        epoch_interval_s=epoch_s,
        estimated=est,
    )
    return section, fixes, inputs


class _Judged(NamedTuple):
    """Per DR sample (NaN where not scored): the reference inside the drawn 2M (1/0), the
    stated probability of that, and the PIT of the error."""

    inside: np.ndarray
    p_inside: np.ndarray
    pit: np.ndarray


def _per_sample(time_s: np.ndarray, cons: Consistency) -> _Judged:
    """The consistency's per-epoch judgement spread onto the DR samples."""
    out = _Judged(*(np.full(time_s.size, np.nan) for _ in range(3)))
    k = np.searchsorted(time_s, cons.time_s)
    out.inside[k] = cons.inside
    out.p_inside[k] = cons.p_inside_expected
    out.pit[k] = cons.pit
    return out


def _legs(tr: DRTrack, cons: Consistency, grid: np.ndarray, fdesc: str) -> tuple[DRLeg, ...]:
    """One row per leg of ``tr`` with its scoring from ``cons`` (NaN/0 where unscored)."""
    by_leg = {lc.leg: lc for lc in cons.legs}
    legs = []
    for k in range(tr.n_legs):
        sel = np.flatnonzero(tr.leg == k)
        if sel.size == 0:
            continue
        lc = by_leg.get(k)
        reason = tr.leg_start_reason[k]
        legs.append(
            DRLeg(
                index=k,
                start_ns=int(grid[sel[0]]),
                end_ns=int(grid[sel[-1]]),
                fix_source=f"{fdesc} ({reason})",
                containment_2m=lc.inside_fraction if lc else math.nan,
                n_scored=lc.n_epochs if lc else 0,
                max_error_m=lc.max_error_m if lc else math.nan,
            )
        )
    return tuple(legs)
