"""The typed results of one voyage's analysis: what :func:`dracc.pipeline.analysis.analyse`
returns and every renderer, the audit and the fleet read directly.

Frozen dataclasses, SI units inside (radians, metres, seconds, int64 UTC nanoseconds);
the deviation statistics keep the units of the paper's channels (``CHANNEL_UNITS``).
A section that could not be computed is ``None`` and :attr:`Analysis.missing` says why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dracc.ingest.timed_observations import TimedObservation
from dracc.math.clock import SourceClock
from dracc.math.deadreckoning import LegConsistency
from dracc.math.deviation import DeviationResult
from dracc.math.ep.aided import IntervalRow
from dracc.math.faults import SensorFault
from dracc.math.integrity import IntegrityResult

SCHEMA = "dracc.analysis/1"

__all__ = [
    "SCHEMA",
    "Analysis",
    "CalibrationSection",
    "CurrentSection",
    "DRLeg",
    "DRSection",
    "DRTrackResult",
    "EPOptions",
    "Estimate",
    "EstimatedPositionSection",
    "HeadingTrack",
    "InputFile",
    "SourceRow",
    "TimeSummary",
    "Track",
]


# --------------------------------------------------------------------------- ingest


@dataclass(frozen=True)
class InputFile:
    """One input file as the ingest saw it."""

    path: str
    format: str
    lines: int
    records: int
    rejected: dict[str, int]
    #: valid lines or messages dracc does not use, by type (never rejected)
    ignored: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class SourceRow:
    """One source key: its roles, records and time span."""

    key: str
    roles: tuple[str, ...]
    records: int
    sentences: dict[str, int]
    first_ns: int | None
    last_ns: int | None
    #: the role this source was a candidate for and not chosen: it is kept as a witness
    witness_for: str | None = None
    #: why it was chosen for its role, or not chosen, where several were candidates
    choice: str | None = None
    #: its clock against the time base of the analysis (:mod:`dracc.math.clock`)
    clock: SourceClock | None = None


@dataclass(frozen=True)
class TimeSummary:
    """What the time base found (counted, never silently applied)."""

    duplicates: int
    backsteps: int
    gaps: int
    rollovers: int
    implausible_dates: int
    decisions: tuple[str, ...]
    #: the date a log without any date was placed on (``timebase.ASSUMED_DATE``), or None
    assumed_date: str | None = None


@dataclass(frozen=True)
class Track:
    """The positions of one source, thinned for plotting (every record up to ``max_points``)."""

    source: str
    role: str | None
    time_ns: np.ndarray
    lat_rad: np.ndarray
    lon_rad: np.ndarray


@dataclass(frozen=True)
class HeadingTrack:
    """The headings of one source, thinned for the exports: the first record of every
    ``overview.HEADING_STEP_S`` seconds (10 s), NaN headings left out.

    ``reference`` holds 'T' (true), 'M' (magnetic) or '' (not said) per record.
    """

    source: str
    role: str | None
    time_ns: np.ndarray
    heading_rad: np.ndarray
    reference: np.ndarray


# -------------------------------------------------------------------- dead reckoning


@dataclass(frozen=True)
class DRTrackResult:
    """A dead-reckoning track with its accuracy, at full rate or at the reporting epochs.

    The report's view of :class:`dracc.math.deadreckoning.DRTrack` (the integrator's
    output, relative seconds): UTC times, the error against the reference and the water
    track beside each row.  ``semi_major_m``/``semi_minor_m`` are the 1-sigma error-ellipse semi-axes,
    ``orientation_rad`` the direction of the major axis (clockwise from north);
    ``ref_error_m`` is NaN where no reference position exists.
    """

    time_ns: np.ndarray
    lat_rad: np.ndarray
    lon_rad: np.ndarray
    since_fix_s: np.ndarray
    radius_2m_m: np.ndarray  #: 2M = 2 drms (B30, B31)
    semi_major_m: np.ndarray
    semi_minor_m: np.ndarray
    orientation_rad: np.ndarray
    ref_error_m: np.ndarray
    leg: np.ndarray  #: int: index of the leg (restart) each row belongs to
    #: the water track: heading and log alone, no current, no learned corrections
    water_lat_rad: np.ndarray
    water_lon_rad: np.ndarray
    #: bool: the row's model was learned from fixes before its leg (scored out of sample)
    scored: np.ndarray
    #: the reference inside the drawn 2M (1.0, 0.0); NaN where not scored (at the fix,
    #: before anything was learned, no reference): the one "inside" every output shows
    inside: np.ndarray
    p_inside: np.ndarray  #: the stated probability of the reference inside 2M; NaN unscored
    pit: np.ndarray  #: the predictive's P(error below the observed one); NaN unscored


@dataclass(frozen=True)
class DRLeg:
    """One DR leg: from a restart fix to the next restart or a break."""

    index: int
    start_ns: int
    end_ns: int
    fix_source: str  #: where the start fix came from ('gnss', 'ins_mean', ...)
    containment_2m: float  #: fraction of scored epochs with the reference inside 2M (NaN if none)
    n_scored: int
    max_error_m: float


@dataclass(frozen=True)
class DRHonesty:
    """Is the probability stated beside 2M achieved?  (dracc.pipeline.dr_honesty)"""

    predictive: str  #: 'student-t' (learned model) or 'gaussian' (configured model)
    method: str  #: what set the circle's size, one sentence
    inflation_min: float  #: the factor on the model's covariance, over the scored legs
    inflation_max: float
    shape_min: float  #: the Student-t shape (heavier tails when small); NaN for a Gaussian
    n_scored: int
    n_misleading: int  #: scored epochs with the error beyond 2M (a Stanford diagram's)
    stated_inside: float  #: mean stated probability of the reference inside 2M
    n_beyond_99: int  #: scored epochs beyond the predictive's 99 % radius (PIT > 0.99)
    expected_beyond_99: float  #: 1 % of the scored epochs
    pit_counts: tuple[int, ...]  #: PIT histogram, equal bins over [0, 1]: flat when honest
    first_leg_inside: float  #: containment over the first scored leg
    first_leg_stated: float  #: its stated probability


@dataclass(frozen=True)
class DRSection:
    """Dead reckoning (METHODS section 2): track, 2M circles, consistency against a reference."""

    heading_source: str  #: e.g. 'compass (HDT, true)'
    speed_source: str  #: e.g. 'log (VHW, through water)'
    reset: str  #: the restart rule used ('1h', 'watch', 'never', ...)
    epoch_interval_s: float
    track: DRTrackResult  #: full rate
    epochs: DRTrackResult  #: every ``epoch_interval_s``
    legs: tuple[DRLeg, ...]
    reference_role: str | None
    containment_2m: float  #: over epochs after the fix (not at it); NaN without a reference
    n_scored: int  #: epochs scored
    expected_inside: float  #: containment a correct Gaussian error would give (0.954-0.982)
    error_over_m_rms: (
        float  #: sqrt(mean (d/M)^2) over scored epochs: 1 when the covariance is right
    )
    consistent: bool | None  #: None without a reference
    verdict: str  #: one sentence
    n_gaps_bridged: int  #: heading/speed gaps held over (<= max_gap_s)
    n_breaks: int  #: gaps that broke the track (restarted at the next fix)
    notes: tuple[str, ...] = ()
    mean_nees: float = math.nan  #: over the scored epochs, 2 expected
    nees_statistic: float = math.nan  #: sum over legs of the last epoch's NEES ~ chi^2(2 legs)
    nees_lower: float = math.nan
    nees_upper: float = math.nan
    leg_checks: tuple[
        LegConsistency, ...
    ] = ()  #: dracc.math.deadreckoning.LegConsistency per scored leg
    dominant_source: str | None = None  #: what the 2M is mostly made of where it fails
    dominant_key: str | None = None  #: the [dead_reckoning] key that sets its prior
    learned: dict[str, object] | None = (
        None  #: the model learned from the voyage (see dr_model.learned_summary)
    )
    reference_sigma_m: float = 0.0  #: the reference's noise, added to P in the comparison
    scored_out_of_sample: bool = False  #: only epochs after the data their model learned from
    #: the reference fixes against the DR with its covariance (the estimated position's
    #: filter): (time_ns, NIS chi^2_2, gate in m) at each fix epoch, NaN while re-anchoring
    fix_innovations: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    fix_source_key: str | None = None  #: the source the reference fixes came from
    honesty: DRHonesty | None = None  #: stated against achieved (None without a reference)
    #: the scored legs a jump of the reference touched (dracc.math.integrity.causes) where
    #: the DR was called inconsistent, and the verdict word of its test without them
    reference_jump_legs: tuple[int, ...] = ()
    verdict_without_jump_legs: str | None = None


# ----------------------------------------------------------- calibration and current


@dataclass(frozen=True)
class Estimate:
    """A value with its 1-sigma uncertainty, in the unit named by the field that holds it."""

    value: float
    sigma: float


@dataclass(frozen=True)
class CalibrationSection:
    """The compass and log errors against the reference: one estimate each, in the error
    convention (compass error = compass - true; V_log = (1 + s) V_true + b).

    ``method`` "learned": the estimated position's learned model (``learn = true``,
    :mod:`dracc.pipeline.calibration_stage`; n = fixes used, segment_s = the filter step, no
    offset); "least_squares": :mod:`dracc.math.calibration` (n = segments)."""

    reference_role: str
    #: e = (course-made-good heading used by the DR) - true heading; the correction is -e
    compass_error_deg: Estimate | None
    log_scale: Estimate | None  #: s in V_log = (1 + s) V_true + b (a fraction)
    log_offset_kn: Estimate | None  #: b; None where speed changes were too small to fit it
    n: int  #: segments (least squares) or fixes (learned) used
    segment_s: float  #: the segment (least squares) or the filter step (learned)
    residual_rms_kn: float  #: RMS of the segment velocity residuals per axis (NaN: learned)
    notes: tuple[str, ...] = ()
    #: the quantities the data cannot determine (their Estimate None), and why: keys
    #: "compass_error_deg", "log_scale", "log_offset_kn" (issue 29)
    not_determinable: dict[str, str] = field(default_factory=dict)
    method: str = "least_squares"  #: "learned" or "least_squares" (issue 31)
    n_fixes: int = 0  #: reference fixes the estimate used


@dataclass(frozen=True)
class CurrentSection:
    """Current (set towards, drift) estimated by the Kalman filter of the aided-DR paper."""

    set_deg: Estimate  #: direction the current flows towards, true, whole voyage
    drift_kn: Estimate
    time_ns: np.ndarray  #: filter times for the plot
    set_rad: np.ndarray
    drift_mps: np.ndarray
    drift_sigma_mps: np.ndarray
    n_updates: int
    notes: tuple[str, ...] = ()


@dataclass(frozen=True)
class EPOptions:
    """What ``analyze`` adds to the estimated position: the observation file's updates and
    the fix intervals of the update-interval study (none: no study)."""

    observations: tuple[TimedObservation, ...] = ()
    intervals_s: tuple[float, ...] = ()


@dataclass(frozen=True)
class EstimatedPositionSection:
    """The aided-DR estimated position (seeds/003, dracc.math.ep.aided): the EP at the
    reporting epochs and the first epoch after each update, its 1-sigma ellipse and 2M."""

    time_ns: np.ndarray
    lat_rad: np.ndarray
    lon_rad: np.ndarray
    radius_2m_m: np.ndarray  #: 2 sqrt(trace P) (B30, B31)
    semi_major_m: np.ndarray  #: 1-sigma ellipse
    semi_minor_m: np.ndarray
    orientation_rad: np.ndarray  #: of the major axis, clockwise from north
    since_update_s: np.ndarray  #: since the last update (the start fix before the first)
    update_kind: tuple[str, ...]  #: the updates since the row before ('gnss', 'bearing 1'); '' none
    fix_interval_s: float  #: the GNSS fixes used, one per this interval
    n_fix_updates: int
    n_lop_updates: int  #: updates from the observation file
    observations_outside: int  #: file observations outside every stretch of DR, not used
    interval_study: tuple[IntervalRow, ...] = ()  #: --fix-interval (seeds/003, Figure 5)
    notes: tuple[str, ...] = ()


# ---------------------------------------------------------------------- the result


@dataclass(frozen=True)
class Analysis:
    """Everything ``dracc analyze`` computed for one voyage; input of every renderer."""

    schema: str
    dracc_version: str
    inputs: tuple[InputFile, ...]
    sources: tuple[SourceRow, ...]
    rejected: dict[str, int]
    reject_examples: dict[str, tuple[tuple[str, int, str], ...]]
    time: TimeSummary
    start_ns: int | None
    end_ns: int | None
    lines: int
    tracks: tuple[Track, ...]
    #: INS deviation statistics (METHODS section 4), straight from :mod:`dracc.math.deviation`
    deviation: DeviationResult | None
    dead_reckoning: DRSection | None
    calibration: CalibrationSection | None
    current: CurrentSection | None
    #: where the deviation reference came from ('gnss'), None without one
    deviation_reference: str | None = None
    #: what could not be computed, one plain sentence each (e.g. "no INS triple: ...")
    missing: tuple[str, ...] = ()
    #: what the pipeline decided or noticed (merged files, role overrides, ...)
    notes: tuple[str, ...] = ()
    #: the options that shaped the result, for the report header
    settings: dict[str, object] = field(default_factory=dict)
    #: sensor faults (dracc.math.faults), found in the raw records; always reported
    faults: tuple[SensorFault, ...] = ()
    #: valid input dracc does not use, by type (GSV, VDM, comment, ...): counted, not rejected
    ignored: dict[str, int] = field(default_factory=dict)
    #: integrity checks of every source (dracc.math.integrity), None when not run
    integrity: IntegrityResult | None = None
    #: every heading source, thinned (one record per 10 s), for the MCAP export
    headings: tuple[HeadingTrack, ...] = ()
    #: the aided-DR estimated position with fixes and lines of position (seeds/003)
    estimated_position: EstimatedPositionSection | None = None

    @property
    def duration_s(self) -> float:
        if self.start_ns is None or self.end_ns is None:
            return math.nan
        return (self.end_ns - self.start_ns) / 1e9
