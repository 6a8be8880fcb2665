"""The calibration stage: compass error, log scale and log offset against the reference
positions (:mod:`dracc.math.calibration`), from the course and speed the DR used."""

from __future__ import annotations

import math

import numpy as np

from dracc.core.errors import InsufficientDataError
from dracc.core.units import KN_MPS
from dracc.pipeline.results import CalibrationSection, Estimate
from dracc.pipeline.selection import DRInputs, Fixes

#: calibration segments (reference displacement over each) and current knots
CAL_SEGMENT_S = 600.0
CAL_KNOT_S = 2 * 3600.0
#: the log offset is fitted only where the speed spans at least this much (5-95 %)
CAL_OFFSET_SPREAD_KN = 2.0


def calibration(dr: DRInputs, fixes: Fixes, missing: list[str]) -> CalibrationSection | None:
    """Compass error, log scale and offset against the reference positions (dracc.math.calibration)."""
    from dracc.math.calibration import calibrate_from_track

    ft, flat, flon, fdesc = fixes
    fix_s = (ft - dr.t0_ns) / 1e9
    notes: list[str] = []
    spd = dr.speed_mps[np.isfinite(dr.speed_mps)]
    spread_mps = float(np.ptp(np.percentile(spd, [5, 95]))) if spd.size else 0.0
    fit_offset = spread_mps >= CAL_OFFSET_SPREAD_KN * KN_MPS
    if not fit_offset:
        notes.append(
            f"log offset not fitted: the log speed spans only {spread_mps / KN_MPS:.1f} kn "
            f"(5-95 %), less than {CAL_OFFSET_SPREAD_KN:g} kn, too little to separate an "
            "offset from the scale; the scale absorbs it"
        )
    try:
        cal = calibrate_from_track(
            dr.time_s,
            dr.heading_rad,
            dr.speed_mps,
            fix_s,
            flat,
            flon,
            segment_s=CAL_SEGMENT_S,
            current_knot_s=CAL_KNOT_S,
            max_ref_gap_s=dr.ref_gap_s,
            fit_log_offset=fit_offset,
        )
    except InsufficientDataError as err:
        missing.append(f"calibration not computed: {err}")
        return None
    eps = float(cal.heading_error_rad[0])
    eps_sig = float(cal.heading_error_sigma_rad[0])
    offset = None
    if math.isfinite(cal.log_offset_sigma_mps):
        offset = Estimate(cal.log_offset_mps / KN_MPS, cal.log_offset_sigma_mps / KN_MPS)
    through = "through the water" if dr.mode == "water" else "over the ground"
    notes.append(
        f"compass error eps = course {through} used by the DR (heading + "
        f"variation + deviation + leeway/drift angle from the log) - true course "
        f"(correct by -eps); "
        f"log: V_log = (1 + s) V_true + b; current fitted beside them, piecewise linear "
        f"with knots every {CAL_KNOT_S / 3600:g} h; {cal.n_segments} segments of "
        f"{CAL_SEGMENT_S:g} s; sigmas inflated for correlated residuals "
        f"(rho {cal.residual_lag1_correlation:.2f})"
    )
    return CalibrationSection(
        reference_role=fdesc,
        compass_error_deg=Estimate(math.degrees(eps), math.degrees(eps_sig)),
        log_scale=Estimate(cal.log_scale, cal.log_scale_sigma),
        log_offset_kn=offset,
        n=int(cal.n_segments),
        segment_s=float(cal.segment_s),
        residual_rms_kn=float(cal.residual_rms_mps / KN_MPS),
        notes=tuple(notes),
    )
