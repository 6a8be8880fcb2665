"""Dead reckoning on WGS-84 with honest 2M circles (B1-B31), and its consistency against a reference.

Source: Banachowicz, Banachowicz & Wolski, "The accuracy assessment in dead reckoning
navigation" (seeds/000); corrected statements in METHODS.md section 2.

Modules, in the order a DR runs through them
    heading           course made good and speed (B1-B6), the true heading (B2, B3)
    holding           sample-and-hold of heading and speed, the gaps that break a track
    propagation       velocity over ground (B7-B14), integration on the ellipsoid (B16-B22)
    aided_speed       the acceleration-aided speed between log readings (B15)
    legs              the restart rules: where each leg starts and ends
    error_processes   the honest covariance from Gauss-Markov error sources
    paper_covariance  the paper's covariance (B23-B31) and M (2M: dracc.math.uncertainty)
    schedule          the reset interval and the reporting epochs
    track             the result, DRTrack, and the Gap it reports
    reckon            dead_reckon, the entry point tying these together
    consistency       does a reference lie inside the 2M circle as often as it should?

Glossary (paper symbols, used inside the kernels)
    KK     compass course (magnetic compass reading)            ``compass_rad``
    KZ     gyro compass course                                   ``gyro_rad``
    KDd    course made good (over ground / through the water)    ``course_rad``
    d      variation (declination), east positive                ``variation_rad``
    delta  deviation, east positive                              ``deviation_rad``
    pz     total gyro compass correction                         ``correction_rad``
    z      total leeway z = alpha + beta (drift + leeway angle)  ``leeway_rad``
    V      speed (Vw through the water, Vd over the ground)      ``speed_mps``
    Vp, Kp current drift and set (towards)                       ``current_*``
    k_phi, k_lambda  (B18), (B19): radians per metre north / east (dracc.core.geodesy)
    P      position covariance; ``P_m2`` in metres north/east, ``P_rad2`` in (phi, lambda)
    M      mean position error (drms), the "2M circle" radius 2M (B30, B31)
"""

from __future__ import annotations

from dracc.math.deadreckoning.aided_speed import (
    aided_speed_between_readings_mps,
    aided_speed_mps,
    log_frame_rate_mps2,
)
from dracc.math.deadreckoning.consistency import (
    Consistency,
    LegConsistency,
    dr_consistency,
)
from dracc.math.deadreckoning.error_processes import (
    ErrorProcess,
    error_processes,
    gauss_markov_position_covariance_m2,
    honest_covariance_m2,
)
from dracc.math.deadreckoning.heading import (
    TrueHeading,
    course_gyro_rad,
    course_magnetic_rad,
    deviation_curve_rad,
    deviation_table_rad,
    interp_deviation_rad,
    leeway_from_log_rad,
    speed_from_components_mps,
    total_leeway_rad,
    true_heading_rad,
)
from dracc.math.deadreckoning.paper_covariance import (
    covariance_b23_rad2,
    covariance_m2_from_rad2,
    mean_error_m,
    sigma_course_rad,
    speed_covariance_rad2,
)
from dracc.math.deadreckoning.propagation import (
    integrate_ne,
    velocity_ground_ne_mps,
    velocity_water_ne_mps,
)
from dracc.math.deadreckoning.reckon import dead_reckon
from dracc.math.deadreckoning.schedule import covered_span_s, dr_schedule
from dracc.math.deadreckoning.track import DRTrack, Gap

__all__ = [
    "Consistency",
    "DRTrack",
    "ErrorProcess",
    "Gap",
    "LegConsistency",
    "TrueHeading",
    "aided_speed_between_readings_mps",
    "aided_speed_mps",
    "course_gyro_rad",
    "course_magnetic_rad",
    "covariance_b23_rad2",
    "covariance_m2_from_rad2",
    "covered_span_s",
    "dead_reckon",
    "deviation_curve_rad",
    "deviation_table_rad",
    "dr_consistency",
    "dr_schedule",
    "error_processes",
    "gauss_markov_position_covariance_m2",
    "honest_covariance_m2",
    "integrate_ne",
    "interp_deviation_rad",
    "leeway_from_log_rad",
    "log_frame_rate_mps2",
    "mean_error_m",
    "sigma_course_rad",
    "speed_covariance_rad2",
    "speed_from_components_mps",
    "total_leeway_rad",
    "true_heading_rad",
    "velocity_ground_ne_mps",
    "velocity_water_ne_mps",
]
