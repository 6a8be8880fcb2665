"""The calibration stage: compass error, log scale and log offset against the reference
positions (:mod:`dracc.math.calibration`), from the course and speed the DR used."""

from __future__ import annotations

import math

from dracc.core.errors import InsufficientDataError
from dracc.core.units import KN_MPS
from dracc.pipeline.results import CalibrationSection, Estimate
from dracc.pipeline.selection import DRInputs, Fixes

#: calibration segments (reference displacement over each) and current knots
CAL_SEGMENT_S = 600.0
CAL_KNOT_S = 2 * 3600.0

#: the section's names of the quantities dracc.math.calibration names
_QUANTITY = {
    "compass_error": "compass_error_deg",
    "log_scale": "log_scale",
    "log_offset": "log_offset_kn",
}


def calibration(dr: DRInputs, fixes: Fixes, missing: list[str]) -> CalibrationSection | None:
    """Compass error, log scale and offset against the reference positions
    (dracc.math.calibration); a quantity the data cannot determine is None, and
    ``not_determinable`` says why (judged from the fit, issue 29)."""
    from dracc.math.calibration import calibrate_from_track

    ft, flat, flon, fdesc = fixes
    fix_s = (ft - dr.t0_ns) / 1e9
    notes: list[str] = []
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
            fit_log_offset=True,  # dropped by the fit where it cannot tell it from the scale
        )
    except InsufficientDataError as err:
        missing.append(f"calibration not computed: {err}")
        return None
    unknown = {_QUANTITY[k]: why for k, why in cal.not_determinable.items()}
    eps = float(cal.heading_error_rad[0])
    eps_sig = float(cal.heading_error_sigma_rad[0])
    compass = Estimate(math.degrees(eps), math.degrees(eps_sig))
    scale = Estimate(cal.log_scale, cal.log_scale_sigma)
    offset = None
    if math.isfinite(cal.log_offset_sigma_mps):
        offset = Estimate(cal.log_offset_mps / KN_MPS, cal.log_offset_sigma_mps / KN_MPS)
    through = "through the water" if dr.mode == "water" else "over the ground"
    notes.append(
        f"compass error eps = course {through} used by the DR (heading + "
        f"variation + deviation + leeway/drift angle from the log) - true course "
        f"(correct by -eps, within +-180 deg); "
        f"log: V_log = (1 + s) V_true + b; current fitted beside them, piecewise linear "
        f"with knots every {CAL_KNOT_S / 3600:g} h; {cal.n_segments} segments of "
        f"{CAL_SEGMENT_S:g} s; sigmas inflated for correlated residuals "
        f"(rho {cal.residual_lag1_correlation:.2f})"
    )
    return CalibrationSection(
        reference_role=fdesc,
        compass_error_deg=None if "compass_error_deg" in unknown else compass,
        log_scale=None if "log_scale" in unknown else scale,
        log_offset_kn=None if "log_offset_kn" in unknown else offset,
        n=int(cal.n_segments),
        segment_s=float(cal.segment_s),
        residual_rms_kn=float(cal.residual_rms_mps / KN_MPS),
        notes=tuple(notes),
        not_determinable=unknown,
    )
