"""``analyse``: the library API behind ``dracc analyze``.

One call reads the logs, runs dead reckoning, calibration, the current estimate and
the INS deviation statistics, and returns one frozen :class:`Analysis` holding
everything the reports show.  Everything is computed here, once; the renderers in
:mod:`dracc.report` only format what they are given.

What a log lacks (no INS triple, no heading, no speed log, no reference) is not an
error: the section concerned is ``None``, and :attr:`Analysis.missing` says why in a
sentence a navigator reads.  Only a log with nothing usable at all raises
:class:`~dracc.errors.InsufficientDataError`.

Units follow the package conventions: radians, metres, seconds and int64 UTC
nanoseconds inside.  The deviation samples and statistics keep the units of the
paper's channels: metres north/east for latitude/longitude, degrees for course
(``CHANNEL_UNITS``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

SCHEMA = "dracc.analysis/1"

#: deviation channels and the unit of their statistics
CHANNELS = ("lat", "lon", "course")
CHANNEL_UNITS = {"lat": "m", "lon": "m", "course": "deg"}
#: the sample column of each channel (the JSON keys of ``deviation.samples``)
SAMPLE_KEYS = {"lat": "lat_m", "lon": "lon_m", "course": "course_deg"}

#: ``progress(stage, fraction)``: called with a stage name and 0..1 while work goes on
Progress = Callable[[str, float], None]


# --------------------------------------------------------------------------- ingest


@dataclass(frozen=True)
class InputFile:
    """One input file as the ingest saw it."""

    path: str
    format: str
    lines: int
    records: int
    rejected: dict[str, int]


@dataclass(frozen=True)
class SourceRow:
    """One source key: its roles, records and time span."""

    key: str
    roles: tuple[str, ...]
    records: int
    sentences: dict[str, int]
    first_ns: int | None
    last_ns: int | None


@dataclass(frozen=True)
class TimeSummary:
    """What the time base found (counted, never silently applied)."""

    duplicates: int
    backsteps: int
    gaps: int
    rollovers: int
    implausible_dates: int
    decisions: tuple[str, ...]


@dataclass(frozen=True)
class Track:
    """The positions of one source, thinned for plotting (every record up to ``max_points``)."""

    source: str
    role: str | None
    time_ns: np.ndarray
    lat_rad: np.ndarray
    lon_rad: np.ndarray


# ------------------------------------------------------------------------ deviation


@dataclass(frozen=True)
class ChannelStats:
    """(K3b)-(K8) for one unit and channel, in the channel's unit (m, or deg for course)."""

    n: int  #: samples used
    m_u: float  #: RMS deviation from the mean (K3b)
    m_y: float  #: RMS error estimate m_y = k m_u (K5b)
    kurtosis: float  #: excess kurtosis of the deviations (K6)
    limit: float  #: limiting error at the configured probability (K8)
    apriori: float | None = None  #: the configured a priori RMS, if any
    exceeds_apriori: bool | None = None  #: m_y > a priori (None without an a priori value)
    new_apriori: float | None = None  #: max(a priori, m_y): the monitoring rule


@dataclass(frozen=True)
class HatStats:
    """Three-cornered hat for one unit and channel: the unit's own variance and sigma.

    ``variance`` may be negative with few samples: it is reported, flagged, never clamped;
    ``sigma`` is then NaN.  ``lower``/``upper`` bound sigma at the confidence given in the
    deviation section (NaN where the bound does not exist).
    """

    variance: float
    sigma: float
    lower: float
    upper: float
    negative: bool


@dataclass(frozen=True)
class ReferenceStats:
    """Validation against a reference (the paper's Table 1) for one unit and channel."""

    n: int
    rmse: float  #: true error RMS against the reference
    k_star: float  #: k* = rmse / m_u
    mark: str  #: '+' where k* <= k, '-' otherwise
    kurtosis: float  #: excess kurtosis of the errors
    kurtosis_mark: str  #: '<', '>' or '=': kurtosis of errors against that of deviations


@dataclass(frozen=True)
class UnitStats:
    """Everything computed for one INS unit over one window."""

    unit: str
    channels: dict[str, ChannelStats]  #: 'lat', 'lon', 'course' (those with data)
    r_lat_lon: float  #: correlation of latitude and longitude deviations (K7)
    hat: dict[str, HatStats]  #: per channel; empty with fewer than three units
    reference: dict[str, ReferenceStats]  #: per channel; empty without a reference


@dataclass(frozen=True)
class DeviationWindow:
    """Statistics over one window (a day by default) or the whole log (``label='all'``)."""

    label: str
    start_ns: int
    end_ns: int
    units: dict[str, UnitStats]


@dataclass(frozen=True)
class DeviationSection:
    """INS accuracy from deviations from the mean (METHODS section 4)."""

    interval_s: float
    factors: dict[str, float]  #: channel -> k used for m_y (sqrt(2) etc. with two units)
    probability: float
    units: tuple[str, ...]  #: the INS roles present ('ins1', 'ins2', 'ins3')
    time_ns: np.ndarray  #: sampling instants, shape (n,)
    #: unit -> channel -> deviations at the instants (m, m, deg), NaN where missing
    samples: dict[str, dict[str, np.ndarray]]
    whole: DeviationWindow
    windows: tuple[DeviationWindow, ...]  #: per day (or the configured window)
    reference_role: str | None  #: where the reference came from ('gnss'), None if none
    notes: tuple[str, ...] = ()


# -------------------------------------------------------------------- dead reckoning


@dataclass(frozen=True)
class DRTrack:
    """A dead-reckoning track with its accuracy, at full rate or at the reporting epochs.

    ``semi_major_m``/``semi_minor_m`` are the 1-sigma error-ellipse semi-axes,
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
class DRSection:
    """Dead reckoning (METHODS section 2): track, 2M circles, consistency against a reference."""

    heading_source: str  #: e.g. 'compass (HDT, true)'
    speed_source: str  #: e.g. 'log (VHW, through water)'
    reset: str  #: the restart rule used ('1h', 'watch', 'never', ...)
    epoch_interval_s: float
    track: DRTrack  #: full rate
    epochs: DRTrack  #: every ``epoch_interval_s``
    legs: tuple[DRLeg, ...]
    reference_role: str | None
    containment_2m: float  #: over epochs after the fix (not at it); NaN without a reference
    n_scored: int  #: epochs scored
    error_over_m_rms: float  #: RMS of actual error / M over scored epochs (1/sqrt(2)·... see docs)
    consistent: bool | None  #: None without a reference
    verdict: str  #: one sentence
    notes: tuple[str, ...] = ()


# ----------------------------------------------------------- calibration and current


@dataclass(frozen=True)
class Estimate:
    """A value with its 1-sigma uncertainty, in the unit named by the field that holds it."""

    value: float
    sigma: float


@dataclass(frozen=True)
class CalibrationSection:
    """Sensor calibration against the reference."""

    reference_role: str
    compass_error_deg: Estimate | None  #: add to the compass heading to get true heading
    log_scale: Estimate | None  #: multiply the log speed by (1 + scale) ... see docs; fraction
    log_offset_kn: Estimate | None
    n: int  #: samples used
    notes: tuple[str, ...] = ()


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
    deviation: DeviationSection | None
    dead_reckoning: DRSection | None
    calibration: CalibrationSection | None
    current: CurrentSection | None
    #: what could not be computed, one plain sentence each (e.g. "no INS triple: ...")
    missing: tuple[str, ...] = ()
    #: what the pipeline decided or noticed (merged files, role overrides, ...)
    notes: tuple[str, ...] = ()
    #: the options that shaped the result, for the report header
    settings: dict[str, object] = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        if self.start_ns is None or self.end_ns is None:
            return math.nan
        return (self.end_ns - self.start_ns) / 1e9
