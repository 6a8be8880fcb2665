"""The calibration stage: compass error, log scale and log offset against the reference
positions, one estimate each, in one sign convention (issue 31).

Where the estimated position's filter learned its model (``[dead_reckoning] learn =
true``, :mod:`dracc.math.ep`), the compass error and log scale are that filter's final
posterior, mixed over the grid weights (the spread between grid points in the
covariance, :func:`dracc.pipeline.dr_model.final_posterior`), turned from the filter's
corrections into the sensors' errors:

    compass error  e = compass - true = -eps             (eps: added to the DR course)
    log scale      V_log = (1 + s_e) V_true,  s_e = -s / (1 + s)
                   (s: the filter's V_true = (1 + s) V_log; 1 + s_e = 1 / (1 + s))
    sigma(e) = sigma(eps);  sigma(s_e) = sigma(s) / (1 + s)^2   (|d s_e / d s|, first order)

The filter has no log-offset state: an offset b is folded into the scale at the voyage's
speeds (s_e ~ scale + b / V), so the offset is not determinable from it.

Not determinable: a learned error whose posterior sigma exceeds DETERMINABLE_RATIO times
the sigma of the prior the filter started from (PRIOR_WIDENING x ErrorPrior).  With a
zero-mean prior the posterior mean is the data's estimate shrunk towards zero by the
factor 1 - (sigma_post / sigma_prior)^2; at a ratio of 0.5 the fixes carry three times
the prior's information and the shrinkage is 25 %.  Above it the number says more about
the prior (zero, with the IMO limits widened) than about the sensor.

Without a learned model (``learn = false``, or the estimated position did not run) the
least-squares fit (:mod:`dracc.math.calibration`) over the course and speed the DR used
gives them, with the log offset where speed changes separate it from the scale.
"""

from __future__ import annotations

import math

import numpy as np

from dracc.core.errors import InsufficientDataError
from dracc.core.units import KN_MPS
from dracc.core.vocabulary import DR_OVER_GROUND
from dracc.frames import Voyage
from dracc.math.ep.error_model import EPS, PRIOR_WIDENING, SCALE
from dracc.pipeline.dr_model import final_posterior
from dracc.pipeline.results import CalibrationSection, Estimate
from dracc.pipeline.selection import DRInputs, Fixes, speed_series

#: a learned error is determinable only where its posterior sigma is at most this fraction
#: of its prior sigma (module doc: the prior's pull on the estimate is then <= 25 %)
DETERMINABLE_RATIO = 0.5

#: the calibration section's methods
LEARNED = "learned"
LEAST_SQUARES = "least_squares"

#: calibration segments (reference displacement over each) and current knots
CAL_SEGMENT_S = 600.0
CAL_KNOT_S = 2 * 3600.0

#: how the Missing list starts the reason a calibration was not computed (the audit
#: quotes it where it checks the compass and the log: dracc.pipeline.audit.facts)
NOT_COMPUTED = "calibration not computed"

#: the section's names of the quantities dracc.math.calibration names
_QUANTITY = {
    "compass_error": "compass_error_deg",
    "log_scale": "log_scale",
    "log_offset": "log_offset_kn",
}


def calibration(
    dr: DRInputs, fixes: Fixes, missing: list[str], leeway_from_log: bool = True
) -> CalibrationSection | None:
    """Compass error, log scale and offset against the reference positions: from the
    estimated position's learned model where ``dr.estimated`` is set (``learn = true``),
    else by least squares (dracc.math.calibration); a quantity the data cannot determine
    is None, and ``not_determinable`` says why.  ``leeway_from_log``: the log gives a
    transverse speed (the learned heading error is then the compass's alone)."""
    from dracc.math.calibration import calibrate_from_track

    ft, flat, flon, fdesc = fixes
    if dr.estimated is not None:
        return learned_calibration(dr, fdesc, leeway_from_log)
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
        missing.append(f"{NOT_COMPUTED}: {err}")
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
        method=LEAST_SQUARES,
        n_fixes=int(np.sum(np.isfinite(flat) & np.isfinite(flon))),
    )


def log_measures_transverse(voyage: Voyage) -> bool:
    """Whether the speed log the DR uses gives a transverse speed (VBW): then the DR's
    course carries the leeway (or drift angle) and the learned heading error is the
    compass's alone."""
    speed = speed_series(voyage, [])
    return speed is not None and bool(np.any(np.isfinite(speed[2])))


def correction_to_error(eps_rad: float, s: float) -> tuple[float, float]:
    """The filter's corrections (eps added to the DR course, V_true = (1 + s) V_log) as the
    sensors' errors: (compass error in rad = -eps, log scale error s_e = -s / (1 + s))."""
    return -eps_rad, -s / (1.0 + s)


def _spans(dr: DRInputs) -> tuple[float, float, float]:
    """(course span in deg, speed span in kn, median speed in kn) of the DR velocity: the
    spans between the 5th and 95th percentiles of the samples faster than AT_REST_KN,
    the median over all; NaN where there is none."""
    vn, ve = np.asarray(dr.vn_mps, float), np.asarray(dr.ve_mps, float)
    v = np.hypot(vn, ve)
    fin = np.isfinite(v)
    if not fin.any():
        return math.nan, math.nan, math.nan
    median_kn = float(np.median(v[fin])) / KN_MPS
    ok = fin & (v > AT_REST_KN * KN_MPS)
    if not ok.any():
        return math.nan, math.nan, median_kn
    course = np.arctan2(ve[ok], vn[ok])
    mean = math.atan2(float(np.sin(course).sum()), float(np.cos(course).sum()))
    dev = np.angle(np.exp(1j * (course - mean)))  # on the circle, about the mean course
    c5, c95 = np.percentile(dev, [5.0, 95.0])
    s5, s95 = np.percentile(v[ok], [5.0, 95.0])
    return math.degrees(c95 - c5), (s95 - s5) / KN_MPS, median_kn


#: a voyage whose course (through the water or over the ground) spans less than this
#: (5-95 %) held one course: its compass error hides in a cross current
ONE_COURSE_DEG = 30.0
#: ... and whose speed spans less than this fraction of its median, one speed: its log
#: scale error hides in a current along the track
ONE_SPEED = 0.1
#: below this median speed (kn) the ship did not move: nothing is learned of either
AT_REST_KN = 0.5


def _motion(course_deg: float, speed_kn: float, median_kn: float, through: str) -> dict[str, str]:
    """Why the motion did or did not separate each error from the current, by quantity."""
    if not median_kn >= AT_REST_KN:  # NaN too: no sample above 0.5 kn
        rest = f"the ship did not move {through} (median speed {median_kn:.1f} kn)"
        return {"compass_error_deg": rest, "log_scale": rest}
    spans = f"the course {through} spans {course_deg:.0f}° and the speed {speed_kn:.1f} kn (5-95 %)"
    compass = log = f"{spans}: a current is told from these errors only by turns and speed changes"
    if course_deg < ONE_COURSE_DEG:
        compass = f"{spans}: one course, the compass error and a cross current cannot be separated"
        if speed_kn < ONE_SPEED * median_kn:
            log = (
                f"{spans}: one course at one speed, the log scale error and a current along "
                "the track cannot be separated"
            )
    return {"compass_error_deg": compass, "log_scale": log}


def learned_calibration(dr: DRInputs, reference: str, leeway_from_log: bool) -> CalibrationSection:
    """The calibration section from the estimated position's learned model (module doc);
    ``dr.estimated`` must be set.  ``leeway_from_log``: the log gives a transverse speed
    (:func:`log_measures_transverse`)."""
    est = dr.estimated
    assert est is not None  # learn = true and the EP ran
    m = est.model
    x, P = final_posterior(m)
    eps, s = float(x[EPS]), float(x[SCALE])
    sig_eps = math.sqrt(max(float(P[EPS, EPS]), 0.0))
    sig_s = math.sqrt(max(float(P[SCALE, SCALE]), 0.0))
    prior_eps = m.prior.heading_sigma_rad * PRIOR_WIDENING
    prior_s = m.prior.scale_sigma * PRIOR_WIDENING
    n_fixes = int(m.history.updated.sum())
    through = "through the water" if dr.mode == "water" else "over the ground"
    course_span, speed_span, speed_kn = _spans(dr)
    motion = _motion(course_span, speed_span, speed_kn, through)

    unknown: dict[str, str] = {}

    def judge(key: str, sig: float, prior: float, shown: str) -> None:
        if n_fixes == 0:
            unknown[key] = f"the filter of the {DR_OVER_GROUND} used no fix"
        elif not (math.isfinite(sig) and math.isfinite(prior) and prior > 0):
            unknown[key] = f"the learned posterior is not finite ({shown})"
        elif sig > DETERMINABLE_RATIO * prior:
            unknown[key] = (
                f"the fixes did not constrain it: σ {shown} of a prior "
                f"{_fmt_prior(key, prior)} (more than {DETERMINABLE_RATIO:g} of it, "
                f"{n_fixes} fixes); {motion[key]}"
            )

    judge("compass_error_deg", sig_eps, prior_eps, f"{math.degrees(sig_eps):.2f}°")
    judge("log_scale", sig_s, prior_s, f"{100 * sig_s:.2f} %")
    unknown["log_offset_kn"] = (
        f"the filter of the {DR_OVER_GROUND} has no log-offset state: an offset is folded into "
        f"the log scale at this voyage's speeds (b / V; median {speed_kn:.1f} kn {through})"
    )
    e_rad, s_e = correction_to_error(eps, s)
    compass = Estimate(math.degrees(e_rad), math.degrees(sig_eps))
    scale = Estimate(s_e, sig_s / (1.0 + s) ** 2)
    angle = "leeway" if dr.mode == "water" else "drift angle"
    if leeway_from_log:
        what = (
            f"compass error = course {through} used by the DR (heading + variation + "
            f"deviation + {angle} from the log's transverse speed) - true course"
        )
    else:
        what = (
            f"compass and {angle} error = course {through} used by the DR (heading + "
            f"variation + deviation; the log gives no transverse speed, so no {angle}) - "
            f"true course: the compass error minus the {angle} (starboard +)"
        )
    notes = (
        f"learned with the {DR_OVER_GROUND} (dracc.math.ep) from {n_fixes} "
        f"{reference} fixes: its final posterior mixed over {int(m.hyper.size)} grid models "
        "(the spread between them in the σ), in the error convention: "
        f"{what} (correct by -error, within +-180°); log: V_log = (1 + s) V_true "
        f"{through}, s = -c / (1 + c) of the filter's correction c; a quantity whose σ "
        f"exceeds {DETERMINABLE_RATIO:g} of its prior σ is not determinable",
    )
    return CalibrationSection(
        reference_role=reference,
        compass_error_deg=None if "compass_error_deg" in unknown else compass,
        log_scale=None if "log_scale" in unknown else scale,
        log_offset_kn=None,
        n=n_fixes,
        segment_s=float(m.step_s),
        residual_rms_kn=math.nan,
        notes=notes,
        not_determinable=unknown,
        method=LEARNED,
        n_fixes=n_fixes,
    )


def _fmt_prior(key: str, prior: float) -> str:
    return f"{math.degrees(prior):.2f}°" if key == "compass_error_deg" else f"{100 * prior:.2f} %"
