"""``analyse``: the library API behind ``dracc analyze``.

One call reads the logs, runs dead reckoning, calibration, the current estimate and
the INS deviation statistics, and returns one frozen :class:`Analysis` holding
everything the reports show.  Everything is computed here, once; the renderers in
:mod:`dracc.report` only format what they are given.

What a log lacks (no INS triple, no heading, no speed log, no reference) is not an
error: the section concerned is ``None``, and :attr:`Analysis.missing` says why in a
sentence a navigator reads.  Only a log with nothing usable at all raises
:class:`~dracc.core.errors.InsufficientDataError`.

Units follow the package conventions: radians, metres, seconds and int64 UTC
nanoseconds inside.  The deviation samples and statistics keep the units of the
paper's channels: metres north/east for latitude/longitude, degrees for course
(``CHANNEL_UNITS``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd

from dracc import __version__
from dracc.core.arrays import unique_sorted
from dracc.core.config import Config, DeadReckoningConfig
from dracc.core.errors import InsufficientDataError
from dracc.core.geodesy import circmean, interp_position, offset_ne_m, wrap_2pi, wrap_pi
from dracc.core.units import DEG_RAD, KN_MPS, NS_PER_S
from dracc.core.vocabulary import CHANNEL_KEYS, CHANNEL_UNITS, CHANNELS, INS_ROLES
from dracc.frames import Voyage
from dracc.math.current import CurrentModel, estimate_current
from dracc.math.deadreckoning import (
    course_magnetic_rad,
    covered_span_s,
    dead_reckon,
    deviation_table_rad,
    dr_consistency,
    dr_schedule,
    interp_deviation_rad,
    leeway_from_log_rad,
    speed_from_components_mps,
)
from dracc.math.deviation import DeviationResult, analyse_deviations, unit_series_from_voyage
from dracc.math.ep import (
    MIN_LEARNED_S,
    OUTLIER_NIS,
    ErrorPrior,
    estimate_position,
    heading_prior_rad,
)
from dracc.math.faults import SensorFault, detect_faults, exclude_faults
from dracc.math.fusion import PositionFix
from dracc.math.integrity import IntegrityResult, check_night, dr_innovation_check, with_dr_check

SCHEMA = "dracc.analysis/1"

__all__ = [
    "SCHEMA",
    "CHANNELS",
    "CHANNEL_UNITS",
    "CHANNEL_KEYS",
    "Analysis",
    "analyse",
    "analyse_voyage",
    "DeviationResult",
]

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
    #: the water track: heading and log alone, no current, no learned corrections
    water_lat_rad: np.ndarray
    water_lon_rad: np.ndarray
    #: bool: the row's model was learned from fixes before its leg (scored out of sample)
    scored: np.ndarray


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
    leg_checks: tuple = ()  #: dracc.math.deadreckoning.LegConsistency per scored leg
    dominant_source: str | None = None  #: what the 2M is mostly made of where it fails
    dominant_key: str | None = None  #: the [dead_reckoning] key that sets its prior
    learned: dict | None = None  #: the model learned from the voyage (see _learned_summary)
    reference_sigma_m: float = 0.0  #: the reference's noise, added to P in the comparison
    scored_out_of_sample: bool = False  #: only epochs after the data their model learned from
    #: the reference fixes against the DR with its covariance (the estimated position's
    #: filter): (time_ns, NIS chi^2_2, gate in m) at each fix epoch, NaN while re-anchoring
    fix_innovations: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    fix_source_key: str | None = None  #: the source the reference fixes came from


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
    #: eps = (course-made-good heading used by the DR) - true heading; the correction is -eps
    compass_error_deg: Estimate | None
    log_scale: Estimate | None  #: s in V_log = (1 + s) V_true + b (a fraction)
    log_offset_kn: Estimate | None  #: b; None where speed changes were too small to fit it
    n: int  #: segments used
    segment_s: float
    residual_rms_kn: float  #: RMS of the segment velocity residuals per axis
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

    @property
    def duration_s(self) -> float:
        if self.start_ns is None or self.end_ns is None:
            return math.nan
        return (self.end_ns - self.start_ns) / 1e9


# ===================================================================== computation

#: at most this many points per source in the plotting tracks
TRACK_POINTS = 4000
#: the DR time base: heading and speed held onto a grid of this step (seconds)
DR_STEP_S = 1.0
#: the current filter runs on a grid of this step, updated by a fix every epoch interval
CURRENT_STEP_S = 10.0
#: a reference position is interpolated between samples at most this far apart
REF_MAX_GAP_S = 5.0


def _noop(stage: str, fraction: float) -> None:
    return None


def analyse(
    paths: Sequence[str | Path],
    cfg: Config | None = None,
    progress: Progress | None = None,
    total_bytes: int | None = None,
) -> Analysis:
    """Read the logs ``paths`` (several files of one voyage merge by time) and analyse them.

    ``cfg`` defaults to :class:`~dracc.core.config.Config` (); ``progress(stage, fraction)``
    is called as the work goes on (reading as a fraction of ``total_bytes``, by default
    the size of the files).  Raises :class:`~dracc.core.errors.IngestError` for unreadable
    input and :class:`InsufficientDataError` when the logs hold no record at all;
    everything else that is missing is reported in :attr:`Analysis.missing`.
    """
    from dracc.ingest import read_logs  # the readers are heavy; import on use

    cfg = cfg or Config()
    report = progress or _noop
    if total_bytes is None:
        total_bytes = sum(Path(p).stat().st_size for p in paths if Path(p).is_file())
    report("reading logs", 0.0)
    read = {"n": 0}

    def on_bytes(n: int) -> None:
        read["n"] += n
        if total_bytes:
            report("reading logs", read["n"] / total_bytes)

    voyage = read_logs([Path(p) for p in paths], cfg.ingest, progress=on_bytes)
    report("reading logs", 1.0)
    return analyse_voyage(voyage, cfg, report)


def analyse_voyage(
    voyage: Voyage, cfg: Config | None = None, progress: Progress | None = None
) -> Analysis:
    """Analyse an ingested :class:`~dracc.frames.Voyage` (see :func:`analyse`)."""
    cfg = cfg or Config()
    report = progress or _noop
    missing: list[str] = []
    notes: list[str] = []

    inputs = tuple(
        InputFile(
            path=str(f["path"]),
            format=str(f["format"]),
            lines=int(f["lines"]),
            records=int(f["records"]),
            rejected=dict(f.get("rejected", {})),
            ignored={str(k): int(v) for k, v in f.get("ignored", {}).items()},
        )
        for f in voyage.inputs
    )
    sources = tuple(
        SourceRow(
            key=str(k),
            roles=tuple(s.roles),
            records=int(s.records),
            sentences={str(a): int(b) for a, b in s.sentences.items()},
            first_ns=s.first_ns,
            last_ns=s.last_ns,
        )
        for k, s in voyage.sources.items()
    )
    firsts = [s.first_ns for s in sources if s.first_ns is not None]
    lasts = [s.last_ns for s in sources if s.last_ns is not None]
    if not firsts:
        why = ", ".join(f"{k} {v}" for k, v in voyage.rejects.counts.most_common(4))
        hint = (
            "; the log carries no date: give it with --date YYYY-MM-DD"
            if voyage.rejects.counts.get("no_date")
            else ""
        )
        raise InsufficientDataError(
            "no usable record in "
            + (", ".join(f.path for f in inputs) or "the input")
            + f" ({voyage.lines} lines read, {voyage.rejects.total} rejected"
            + (f": {why}" if why else "")
            + ")"
            + hint
        )
    te = voyage.time_events
    time = TimeSummary(
        duplicates=te.duplicates,
        backsteps=te.backsteps,
        gaps=te.gaps,
        rollovers=te.rollovers,
        implausible_dates=te.implausible_dates,
        decisions=tuple(te.decisions),
    )
    if len(inputs) > 1:
        notes.append(f"{len(inputs)} files merged by time")
    spells = recording_spells(voyage.frames, int(SPELL_GAP_S * NS_PER_S))
    if len(spells) > 1:

        def when(a: int, b: int) -> str:
            fa, fb = (f"{pd.Timestamp(x, tz='UTC'):%Y-%m-%d %H:%MZ}" for x in (a, b))
            return fa if fa == fb else f"{fa} to {fb}"

        shown = "; ".join(f"{when(a, b)} ({n:,} records)" for a, b, n in spells[:6])
        more = f"; and {len(spells) - 6} more" if len(spells) > 6 else ""
        notes.append(
            f"the records fall in {len(spells)} spells more than {SPELL_GAP_S / 3600:g} h "
            f"apart: {shown}{more}. The period spans them all; the statistics use "
            "the instants with readings only (a stray record with a wrong date shows here)"
        )
    unassigned = [s.key for s in sources if not s.roles]
    if unassigned:
        notes.append(
            "sources without a role: " + ", ".join(unassigned) + "; assign one with --role KEY=ROLE"
        )

    tracks = _tracks(voyage)
    report("integrity checks", 0.0)
    integrity = check_night(voyage, cfg.integrity)
    report("integrity checks", 1.0)
    report("sensor faults", 0.0)
    faults, voyage = _sensor_faults(voyage, cfg, notes)
    report("sensor faults", 1.0)

    report("dead reckoning", 0.0)
    dr, fixes, ref, dr_inputs = _dead_reckoning(voyage, cfg.dead_reckoning, missing, notes)
    report("dead reckoning", 1.0)

    if integrity is not None and dr is not None and dr.fix_innovations is not None:
        integrity = with_dr_check(
            integrity,
            dr_innovation_check(
                dr.fix_source_key, dr.reference_role, *dr.fix_innovations, cfg.integrity
            ),
        )
    report("current", 0.0)
    current = None
    if dr is not None and dr_inputs is not None and fixes is not None:
        if dr_inputs.mode == "water" and dr_inputs.estimated is not None:
            current = _current_learned(dr_inputs, fixes)
        elif dr_inputs.mode == "water":
            current = _current(dr_inputs, fixes, cfg.dead_reckoning, missing)
        else:
            missing.append(
                "current not estimated: the log measures over the ground (VBW ground "
                "components), so the DR already moves with the current"
            )
    report("current", 1.0)

    report("deviation statistics", 0.0)
    deviation, dev_ref = _deviation(voyage, cfg, missing)
    report("deviation statistics", 1.0)

    report("calibration", 0.0)
    calibration = None
    if dr_inputs is not None and fixes is not None:
        calibration = _calibration(dr_inputs, fixes, missing)
    report("calibration", 1.0)

    settings = {
        "interval_s": cfg.deviation.interval_s,
        "window_s": cfg.deviation.window_s,
        "probability": cfg.deviation.probability,
        "reset": cfg.dead_reckoning.reset,
        "fix_role": cfg.dead_reckoning.fix_role,
        "epoch_interval_s": cfg.dead_reckoning.epoch_interval_s,
        "max_gap_s": cfg.dead_reckoning.max_gap_s,
        "variation_deg": cfg.dead_reckoning.variation_deg,
        "roles": dict(cfg.ingest.sources),
        "strict": cfg.ingest.strict,
        "ignore_checksum": cfg.ingest.ignore_checksum,
        "date": cfg.ingest.date,
        "faults_exclude": cfg.faults.exclude,
    }
    return Analysis(
        schema=SCHEMA,
        dracc_version=__version__,
        inputs=inputs,
        sources=sources,
        rejected={str(k): int(v) for k, v in voyage.rejects.counts.items()},
        reject_examples={str(k): tuple(v) for k, v in voyage.rejects.examples.items()},
        time=time,
        start_ns=int(min(firsts)),
        end_ns=int(max(lasts)),
        lines=int(voyage.lines),
        tracks=tracks,
        deviation=deviation,
        dead_reckoning=dr,
        calibration=calibration,
        current=current,
        deviation_reference=dev_ref,
        missing=tuple(missing),
        notes=tuple(notes),
        settings=settings,
        faults=faults,
        ignored={str(k): int(v) for k, v in getattr(voyage, "ignored", {}).items()},
        integrity=integrity,
    )


# -------------------------------------------------------------------- sensor faults


def _sensor_faults(
    voyage: Voyage, cfg: Config, notes: list[str]
) -> tuple[tuple[SensorFault, ...], Voyage]:
    """Sensor faults in the raw records (dracc.math.faults); their records are left out of
    what follows only where ``[faults] exclude = true`` (the tracks keep the raw figures)."""
    faults = tuple(detect_faults(voyage, cfg.faults))
    if faults and cfg.faults.exclude:
        voyage, removed = exclude_faults(voyage, list(faults))
        notes.append(
            f"{len(faults)} sensor fault(s): their records are left out of the statistics "
            "([faults] exclude = true): "
            + ", ".join(f"{n} {kind}" for kind, n in sorted(removed.items()))
        )
    elif faults:
        notes.append(
            f"{len(faults)} sensor fault(s) found and reported; their records are still in the "
            "statistics (set [faults] exclude = true to leave them out)"
        )
    return faults, voyage


# ------------------------------------------------------------------------ helpers


def _role_of(voyage: Voyage, key: str) -> str | None:
    s = voyage.sources.get(key)
    return s.role if s is not None else None


def _valid_positions(df: pd.DataFrame) -> pd.DataFrame:
    """Positions with a fix (GGA quality 0 and NaN coordinates left out)."""
    ok = (
        (df["quality"].to_numpy() != 0)
        & np.isfinite(df["lat_rad"].to_numpy())
        & np.isfinite(df["lon_rad"].to_numpy())
    )
    return df[ok]


def _tracks(voyage: Voyage) -> tuple[Track, ...]:
    """Every position source, thinned to at most TRACK_POINTS points, for the plots."""
    pos = voyage.frames.get("position")
    if pos is None or pos.empty:
        return ()
    out = []
    pos = _valid_positions(pos)
    for key, df in pos.groupby("source", observed=True, sort=False):
        if df.empty:
            continue
        step = max(1, math.ceil(len(df) / TRACK_POINTS))
        d = df.iloc[::step]
        out.append(
            Track(
                source=str(key),
                role=_role_of(voyage, str(key)),
                time_ns=d["time_ns"].to_numpy(np.int64),
                lat_rad=d["lat_rad"].to_numpy(float),
                lon_rad=d["lon_rad"].to_numpy(float),
            )
        )
    return tuple(out)


def _hold(
    t_src_ns: np.ndarray, values: np.ndarray, t_grid_ns: np.ndarray, max_age_ns: int
) -> np.ndarray:
    """The last sample at or before each grid time, NaN where it is older than ``max_age_ns``.

    Sample-and-hold, as (B20) holds the velocity over a step; nothing is interpolated."""
    i = np.searchsorted(t_src_ns, t_grid_ns, side="right") - 1
    ok = i >= 0
    out = np.full(t_grid_ns.shape, np.nan)
    j = i[ok]
    out[ok] = np.where(t_grid_ns[ok] - t_src_ns[j] <= max_age_ns, values[j], np.nan)
    return out


def _ref_gap_s(t_ns: np.ndarray) -> float:
    """How far apart two reference positions may be to interpolate between them:
    REF_MAX_GAP_S, or 2.5 typical intervals for a slowly logged reference."""
    if t_ns.size < 2:
        return REF_MAX_GAP_S
    return max(REF_MAX_GAP_S, 2.5 * float(np.median(np.diff(t_ns))) / 1e9)


def _sentence_types(df: pd.DataFrame) -> str:
    """'HDT+THS': the sentence types among the rows (unique on the categorical codes,
    not on a million strings)."""
    return "+".join(sorted({str(x) for x in df["sentence"].unique()}))


def _dedupe_sorted(t_ns: np.ndarray, *cols: np.ndarray):
    """Sort by time and keep one sample per time (strictly increasing times).

    Each column takes the last *finite* value among the samples of one time, so two
    sentences of one instant complement each other whatever order the container put them
    in (a log's VHW and VBW: only VBW carries the transverse speed)."""
    order = np.argsort(t_ns, kind="stable")
    t = t_ns[order]
    starts = np.flatnonzero(np.r_[True, t[1:] != t[:-1]]) if t.size else np.zeros(0, np.int64)
    position = np.arange(t.size)
    out = [t[starts]]
    for c in cols:
        c = c[order]
        if starts.size == 0:
            out.append(c)
            continue
        last_finite = np.maximum.reduceat(np.where(np.isfinite(c), position, -1), starts)
        out.append(np.where(last_finite >= 0, c[np.maximum(last_finite, 0)], np.nan))
    return tuple(out)


# ------------------------------------------------------------------ dead reckoning


@dataclass(frozen=True)
class _DRInputs:
    """What the DR ran on, kept for the current filter."""

    t0_ns: int
    time_s: np.ndarray
    vn_mps: (
        np.ndarray
    )  #: the DR velocity (water mode: through the water, no current), NaN outside legs
    ve_mps: np.ndarray
    heading_rad: (
        np.ndarray
    )  #: course (B2)/(B3) + leeway or drift angle (B5)/(B6), NaN where missing
    speed_mps: np.ndarray  #: speed (B1) through the water or over the ground, NaN where missing
    ref_gap_s: float  #: reference positions are interpolated across gaps up to this
    mode: str  #: 'water' (relative log) or 'ground' (absolute log)
    epoch_interval_s: float = 600.0  #: the DR's epoch spacing (the old filter's fix spacing)
    estimated: object = None  #: dracc.math.ep.EstimatedPosition where the model was learned


def _heading_series(
    voyage: Voyage, cfg: DeadReckoningConfig, missing: list[str], notes: list[str]
) -> tuple[np.ndarray, np.ndarray, str] | None:
    """True heading (B2)/(B3) from the compass: (time_ns, heading_rad, description)."""
    hdg = voyage.frames.get("heading")
    if hdg is None or hdg.empty:
        missing.append(
            "no heading: the log holds no HDT/THS/HDG/HDM sentence; dead reckoning, "
            "current and calibration need one"
        )
        return None
    valid = np.isfinite(hdg["heading_rad"].to_numpy())  # one selection below: one copy of the rows
    compass = voyage.role_sources("compass")
    if compass:
        use = hdg[valid & hdg["source"].isin(compass).to_numpy()]
        who = "compass " + "+".join(compass)
    else:
        other = [
            k
            for k in hdg["source"][valid].unique().tolist()
            if not (set(voyage.sources[k].roles) & {"ins1", "ins2", "ins3", "gnss"})
        ]
        use = hdg[valid & hdg["source"].isin(other).to_numpy()]
        who = "heading source " + "+".join(map(str, other))
        if other:
            notes.append(
                f"no source has the role compass; heading taken from {'+'.join(map(str, other))}"
            )
    if use.empty:
        missing.append(
            "no heading: heading sentences exist but none has a value from a compass "
            "(only empty fields or INS/GNSS headings); dead reckoning not computed"
        )
        return None
    refs = set(use["reference"].dropna().unique().tolist())
    if "T" in refs:
        use = use[use["reference"] == "T"]
        t, h = _dedupe_sorted(use["time_ns"].to_numpy(np.int64), use["heading_rad"].to_numpy(float))
        sent = _sentence_types(use)
        return t, h, f"{who} ({sent}, true)"
    # magnetic: (B2) KDd = KK + d + delta (leeway from the log is added by dead_reckon)
    t, kk, dev, var = _dedupe_sorted(
        use["time_ns"].to_numpy(np.int64),
        use["heading_rad"].to_numpy(float),
        use["deviation_rad"].to_numpy(float),
        use["variation_rad"].to_numpy(float),
    )
    sent = _sentence_types(use)
    desc = f"{who} ({sent}, magnetic"
    if cfg.deviation_table:
        th, td = deviation_table_rad(cfg.deviation_table)
        table_dev = interp_deviation_rad(kk, th, td)
        n_fill = int(np.sum(~np.isfinite(dev)))
        dev = np.where(np.isfinite(dev), dev, table_dev)
        if n_fill:
            desc += ", deviation from the configured table"
    elif np.any(~np.isfinite(dev)):
        n_nan = int(np.sum(~np.isfinite(dev)))
        notes.append(
            f"magnetic heading without deviation at {n_nan} of {dev.size} samples and no "
            "[dead_reckoning] deviation_table: deviation taken as 0 there"
        )
        dev = np.where(np.isfinite(dev), dev, 0.0)
    n_var = int(np.sum(~np.isfinite(var)))
    # many compasses send a zero placeholder (HDG ...,0.0,E): a configured variation
    # (--variation, [dead_reckoning] variation_deg) wins over a zero field, never over a
    # non-zero one; the notes say which was used where
    n_zero = int(np.sum(var == 0.0))
    n_own = int(np.sum(np.isfinite(var) & (var != 0.0)))
    if cfg.variation_deg is not None and (n_var or n_zero):
        fill = ~np.isfinite(var) | (var == 0.0)
        var = np.where(fill, cfg.variation_deg * DEG_RAD, var)
        desc += f", variation {cfg.variation_deg:g}° from the configuration"
        what = " and ".join(
            x
            for x in (
                f"none at {n_var}" if n_var else "",
                f"0.0 (a placeholder) at {n_zero}" if n_zero else "",
            )
            if x
        )
        notes.append(
            f"magnetic variation: the configured {cfg.variation_deg:g}° used at "
            f"{n_var + n_zero} of {var.size} compass samples (the compass sent {what})"
            + (f"; the compass's own non-zero variation kept at {n_own}" if n_own else "")
        )
        n_var = 0
    elif n_zero and cfg.variation_deg is None:
        notes.append(
            f"magnetic variation: the compass sends 0.0 at {n_zero} of {var.size} samples "
            "(often a placeholder); it is used as sent (give --variation DEG if the local "
            "variation is not zero)"
        )
    if n_var:  # none sent, none configured
        missing.append(
            f"magnetic variation: the compass sends none at {n_var} of {var.size} "
            "samples and none is configured; the DR takes it as 0 there, so its "
            "course is off by the local variation (give --variation DEG)"
        )
        var = np.where(np.isfinite(var), var, 0.0)
    desc += ")"
    return t, wrap_2pi(course_magnetic_rad(kk, var, dev)), desc  # (B2)


def _speed_series(voyage: Voyage, missing: list[str]):
    """The log's speed: (time_ns, longitudinal, transverse, description, mode).

    Through the water (VHW, VBW water components; mode 'water', B7-B12) where the log
    gives it; otherwise over the ground (VBW ground components; mode 'ground', B13-B14).
    """
    water = voyage.frames.get("water")
    logs = voyage.role_sources("log")
    if water is None or water.empty:
        missing.append(
            "no speed log: the log holds no VHW/VBW sentence; dead reckoning, current "
            "and calibration need one"
        )
        return None
    frame = water[water["source"].isin(logs)] if logs else water
    for col, col_y, mode, what in (
        ("stw_mps", "stw_transverse_mps", "water", "through the water"),
        ("sog_long_mps", "sog_transverse_mps", "ground", "over the ground"),
    ):
        use = frame[np.isfinite(frame[col].to_numpy())]
        if use.empty:
            continue
        t, v, vy = _dedupe_sorted(
            use["time_ns"].to_numpy(np.int64), use[col].to_numpy(float), use[col_y].to_numpy(float)
        )
        sent = _sentence_types(use)
        who = (
            "log " + "+".join(logs)
            if logs
            else "speed source " + "+".join(map(str, use["source"].unique().tolist()))
        )
        return t, v, vy, f"{who} ({sent}, {what})", mode
    missing.append(
        "no log speed: the log sentences carry no speed value, through the water or "
        "over the ground; dead reckoning not computed"
    )
    return None


def _fixes(voyage: Voyage, cfg: DeadReckoningConfig, missing: list[str], notes: list[str]):
    """Restart fixes and the reference: (time_ns, lat_rad, lon_rad, description) or None."""
    pos = voyage.frames.get("position")
    if pos is None or pos.empty:
        missing.append("no position at all: the DR has no start fix and no reference")
        return None
    pos = _valid_positions(pos)
    gnss = voyage.role_sources("gnss")
    if cfg.fix_role == "gnss" and gnss:
        g = pos[pos["source"].isin(gnss[:1])]
        if len(gnss) > 1:
            notes.append(
                f"several GNSS sources ({', '.join(gnss)}): fixes and reference from {gnss[0]}"
            )
        if not g.empty:
            t, la, lo = _dedupe_sorted(
                g["time_ns"].to_numpy(np.int64),
                g["lat_rad"].to_numpy(float),
                g["lon_rad"].to_numpy(float),
            )
            return t, la, lo, "gnss"
    ins = [r for r in INS_ROLES if voyage.role_sources(r)]
    if ins:
        # the mean of the INS units at the first unit's times (circular mean of longitude)
        series = []
        for r in ins:
            d = pos[pos["source"].isin(voyage.role_sources(r))]
            series.append(
                _dedupe_sorted(
                    d["time_ns"].to_numpy(np.int64),
                    d["lat_rad"].to_numpy(float),
                    d["lon_rad"].to_numpy(float),
                )
            )
        t = series[0][0]
        lats, lons = [], []
        for st, sla, slo in series:
            a, b = interp_position(st, sla, slo, t, REF_MAX_GAP_S * 1e9)
            lats.append(a)
            lons.append(b)
        lat = np.nanmean(np.vstack(lats), axis=0)
        lon = wrap_pi(circmean(np.vstack(lons), axis=0))
        ok = np.isfinite(lat) & np.isfinite(lon)
        if cfg.fix_role == "gnss":
            notes.append(
                f"no GNSS: DR fixes and reference from the mean of the INS units ({', '.join(ins)})"
            )
        return t[ok], lat[ok], lon[ok], "ins_mean"
    # no GNSS or INS role: the position source with the most fixes (e.g. an instrument bus
    # relaying its GPS as II RMC/GLL)
    codes, keys = pd.factorize(pos["source"])  # keys in order of first appearance
    if len(keys):
        key = str(keys[int(np.argmax(np.bincount(codes[codes >= 0], minlength=len(keys))))])
        o = pos[pos["source"] == key]
        role = _role_of(voyage, key)
        notes.append(
            f"no GNSS or INS role: DR fixes and reference from position source {key}"
            + (f" (role {role})" if role else "")
            + "; map the receiver with --role KEY=gnss to choose another"
        )
        t, la, lo = _dedupe_sorted(
            o["time_ns"].to_numpy(np.int64),
            o["lat_rad"].to_numpy(float),
            o["lon_rad"].to_numpy(float),
        )
        return t, la, lo, key
    missing.append("no position fix: the DR has no start position and no reference")
    return None


#: a silence of both heading and speed longer than this is left out of the DR grid
DR_SILENCE_S = 3600.0
#: records further apart than this (in every frame) form separate recording spells
SPELL_GAP_S = 6 * 3600.0


def recording_spells(frames, gap_ns: int) -> list[tuple[int, int, int]]:
    """(first ns, last ns, records) of each spell of recording: the records of all frames,
    cut where none comes for more than ``gap_ns``.  Frames are sorted by time."""
    runs = []
    for df in frames.values():
        if df is None or not len(df):
            continue
        t = df["time_ns"].to_numpy(np.int64)
        cut = np.flatnonzero(np.diff(t) > gap_ns)
        starts, ends = np.r_[0, cut + 1], np.r_[cut, len(t) - 1]
        runs += [(int(t[a]), int(t[b]), int(b - a + 1)) for a, b in zip(starts, ends, strict=True)]
    spells: list[tuple[int, int, int]] = []
    for a, b, n in sorted(runs):
        if spells and a - spells[-1][1] <= gap_ns:
            spells[-1] = (spells[-1][0], max(spells[-1][1], b), spells[-1][2] + n)
        else:
            spells.append((a, b, n))
    return spells


def _dr_grid(
    th: np.ndarray, tv: np.ndarray, t_first: int, t_last: int, step_ns: int, silence_ns: int
) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """The DR time grid: every ``step_ns`` (aligned to multiples of it) from ``t_first`` to
    ``t_last``, leaving out silences of both heading and speed longer than ``silence_ns``
    (the track breaks over them anyway).  One stray record dated years away used to make
    a grid of years (126 million points; fuzz).  Returns (grid, skipped (from, to) pairs)."""
    u = unique_sorted(np.concatenate([th, tv]))
    u = u[(u >= t_first) & (u <= t_last)]
    cut = np.flatnonzero(np.diff(u) > silence_ns)
    starts = np.concatenate(([u[0]], u[cut + 1]))
    ends = np.concatenate((u[cut], [u[-1]]))
    parts = []
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        a0 = a - a % step_ns + (step_ns if a % step_ns else 0)
        parts.append(np.arange(a0, b + 1, step_ns, dtype=np.int64))
    skipped = list(zip(u[cut].tolist(), u[cut + 1].tolist(), strict=True))
    return np.concatenate(parts), skipped


#: what each part of the EP covariance is, and the key that sets its prior
_SOURCE_KEYS = {
    "fix": ("the fixes' noise", "fix_sigma_m"),
    "current": ("the current estimate", "current_kn"),
    "current change": ("the change of the current", "current_kn"),
    "heading": ("the compass and leeway error", "compass_bias_deg"),
    "log scale": ("the log scale error", "log_scale"),
    "noise": ("short-term log and compass noise", "log_noise_kn"),
}


def _dominant_source(est, cons, tr, fix_s) -> tuple[str, str] | None:
    """The part of the EP covariance largest at the epochs that missed (or, when none did,
    at every scored epoch), with the [dead_reckoning] key of its prior."""
    if not cons.n_epochs:
        return None
    idx = np.searchsorted(tr.time_s, cons.time_s)
    miss = ~cons.inside
    pick = idx[miss] if miss.any() else idx
    parts = {k: float(np.nanmean(v[pick])) for k, v in est.forecast.components_m2.items()}
    name = max(parts, key=parts.get)
    return _SOURCE_KEYS[name]


def _learned_summary(est, cfg: DeadReckoningConfig) -> dict:
    """The model learned over the whole voyage (final grid weights) and a ready
    [dead_reckoning] block that reuses it where there is no reference (learn = false)."""
    m = est.model
    hp = m.hyper
    w = m.final_weights
    j = int(np.argmax(w))
    x = w @ m.final_x
    Pm = np.einsum(
        "m,mij->ij", w, m.final_P + (m.final_x - x)[:, :, None] * (m.final_x - x)[:, None, :]
    )
    cbar = x[2:4]
    drift = float(np.hypot(*cbar))
    eps, s = float(x[8]), float(x[9])
    s_eps, s_s = math.sqrt(max(Pm[8, 8], 0.0)), math.sqrt(max(Pm[9, 9], 0.0))
    sig_c, tau_c = float(hp.current_sigma_mps[j]), float(hp.current_tau_s[j])
    noise_kn, noise_tau = float(hp.noise_sigma_mps[j]) / KN_MPS, float(hp.noise_tau_s[j])
    current_kn = math.sqrt(0.5 * drift**2 + sig_c**2) / KN_MPS
    compass_deg = math.degrees(math.hypot(eps, s_eps))
    scale = math.hypot(s, s_s)
    fix_m = est.reference_sigma_m
    block = (
        "\n".join(
            [
                "[dead_reckoning]",
                "learn = false",
                f'compass_bias_deg = {{ sigma = {compass_deg:.3f}, tau_s = "inf" }}',
                "compass_noise_deg = { sigma = 0.0, tau_s = 120 }",
                "leeway_deg = { sigma = 0.0, tau_s = 1800 }",
                f'log_scale = {{ sigma = {scale:.4f}, tau_s = "inf" }}',
                'log_bias_kn = { sigma = 0.0, tau_s = "inf" }',
                f"log_noise_kn = {{ sigma = {noise_kn:.3f}, tau_s = {noise_tau:g} }}",
                f"current_kn = {{ sigma = {current_kn:.3f}, tau_s = {tau_c:g} }}",
                f"fix_sigma_m = {fix_m:.1f}",
            ]
        )
        + "\n"
    )
    return {
        "current_set_deg": float(math.degrees(wrap_2pi(math.atan2(cbar[1], cbar[0])))),
        "current_drift_kn": drift / KN_MPS,
        "current_variation_kn": sig_c / KN_MPS,
        "current_tau_s": tau_c,
        "heading_correction_deg": math.degrees(eps),
        "heading_correction_sigma_deg": math.degrees(s_eps),
        "log_scale_correction": s,
        "log_scale_correction_sigma": s_s,
        "noise_kn": noise_kn,
        "noise_tau_s": noise_tau,
        "fix_sigma_m": fix_m,
        "model_weight": float(w[j]),
        "n_models": int(hp.size),
        "filter_step_s": m.step_s,
        "n_fixes_used": int(m.history.updated.sum()),
        "n_outliers": int(m.n_outliers),
        "config_block": block,
    }


def _error_prior(cfg: DeadReckoningConfig, lat_rad: float, gyro: bool, speed_mps) -> ErrorPrior:
    """What the EP assumes before it has learned anything: the configured current as a
    persistent one, the compass bias (gyro: x sec phi, METHODS section 6) with the leeway,
    the log scale with its offset at the median speed."""
    v = float(np.nanmedian(speed_mps)) if np.any(np.isfinite(speed_mps)) else math.nan
    offset_as_scale = cfg.log_bias_kn.sigma * KN_MPS / v if v > 0.5 else 0.0
    return ErrorPrior(
        current_sigma_mps=cfg.current_kn.sigma * KN_MPS,
        heading_sigma_rad=heading_prior_rad(
            cfg.compass_bias_deg.sigma * DEG_RAD, cfg.leeway_deg.sigma * DEG_RAD, lat_rad, gyro
        ),
        scale_sigma=math.hypot(cfg.log_scale.sigma, offset_as_scale),
        fix_sigma_m=cfg.fix_sigma_m,
    )


def _dead_reckoning(voyage: Voyage, cfg: DeadReckoningConfig, missing: list[str], notes: list[str]):
    """Run the DR on a DR_STEP_S grid from the compass and the log; score it against the reference."""
    heading = _heading_series(voyage, cfg, missing, notes)
    speed = _speed_series(voyage, missing)
    fixes = _fixes(voyage, cfg, missing, notes)
    if heading is None or speed is None or fixes is None:
        if heading is not None or speed is not None:
            missing.append("dead reckoning not computed (see above)")
        return None, fixes, None, None
    th, hdg, hdg_desc = heading
    tv, stw, stw_y, spd_desc, mode = speed
    step_ns = int(DR_STEP_S * NS_PER_S)
    t_first = max(int(th[0]), int(tv[0]))
    t_last = min(int(th[-1]), int(tv[-1]))
    if t_last - t_first < 2 * step_ns:
        missing.append("dead reckoning: heading and speed do not overlap in time")
        return None, fixes, None, None
    grid, skipped = _dr_grid(th, tv, t_first, t_last, step_ns, int(DR_SILENCE_S * NS_PER_S))
    if grid.size < 3:
        missing.append("dead reckoning: heading and speed do not overlap in time")
        return None, fixes, None, None
    for a, b in skipped:
        notes.append(
            f"heading and speed both silent for {(b - a) / NS_PER_S / 3600:,.1f} h "
            f"({pd.Timestamp(a, tz='UTC'):%Y-%m-%d %H:%M:%S} to "
            f"{pd.Timestamp(b, tz='UTC'):%Y-%m-%d %H:%M:%S} UTC): the dead-reckoning "
            "grid skips it (the track breaks there)"
        )
    # a held sample older than this is missing at the grid time; dead_reckon bridges up to max_gap_s
    age = int(
        max(2.0 * DR_STEP_S, 2.0 * np.median(np.diff(tv)) / 1e9 if tv.size > 1 else 0) * NS_PER_S
    )
    age_h = int(
        max(2.0 * DR_STEP_S, 2.0 * np.median(np.diff(th)) / 1e9 if th.size > 1 else 0) * NS_PER_S
    )
    h_g = _hold(th, hdg, grid, age_h)
    v_g = _hold(tv, stw, grid, age)
    vy_g = _hold(tv, stw_y, grid, age) if np.any(np.isfinite(stw_y)) else None
    if vy_g is not None and np.any(~np.isfinite(vy_g) & np.isfinite(v_g)):
        vy_g = np.where(np.isfinite(vy_g), vy_g, 0.0)
    ft, flat, flon, fdesc = fixes
    ref_gap_s = _ref_gap_s(ft)
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
        return None, fixes, None, None
    water = tr
    est = None
    if cfg.learn:
        gyro = hdg_desc.endswith("true)")
        est = estimate_position(
            water,
            fix_s,
            flat,
            flon,
            _error_prior(cfg, float(np.nanmedian(flat)), gyro, v_g),
            ref_max_gap_s=ref_gap_s,
        )
        tr = est.track
    # rows of legs whose model was learned from earlier fixes: the only ones scored
    learned_leg = est.learned_leg if est is not None else np.ones(tr.n_legs, bool)
    learned_row = (tr.leg >= 0) & learned_leg[np.maximum(tr.leg, 0)]
    ei = np.asarray(tr.epoch_index, dtype=np.int64)
    cons = dr_consistency(
        replace(tr, epoch_index=ei[learned_row[ei]]),
        fix_s,
        flat,
        flon,
        max_ref_gap_s=ref_gap_s,
        ref_sigma_m=est.reference_sigma_m if est is not None else 0.0,
    )
    # the actual error at every sample (for the growth plot and the tables)
    rlat, rlon = interp_position(ft, flat, flon, grid, ref_gap_s * 1e9)
    dn, de = offset_ne_m(tr.lat_rad, tr.lon_rad, rlat, rlon)
    ref_err = np.hypot(dn, de)
    on = tr.leg >= 0
    scored_row = learned_row & (tr.since_fix_s > 0)

    def rows(idx):
        return DRTrack(
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
        )

    full = rows(on)
    epochs = rows(ei)
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
    dr_notes = []
    n_bridged = sum(g.bridged for g in tr.gaps)
    if tr.n_breaks:
        dr_notes.append(
            f"{tr.n_breaks} heading/speed gap(s) longer than {cfg.max_gap_s:g} s broke "
            "the track; it restarted at the next fix"
        )
    if n_bridged:
        dr_notes.append(f"{n_bridged} short heading/speed gap(s) bridged by holding the last value")
    if est is not None:
        n_prior = int(np.sum((tr.since_fix_s[ei] > 0) & ~learned_row[ei]))
        dr_notes.append(
            f"estimated position: the water track plus the current and the compass and log "
            f"corrections learned from the {fdesc} fixes before each leg's start fix (never later "
            f"ones); scored out of sample: {cons.n_epochs} epochs of legs whose model had learned "
            f"from at least {min(MIN_LEARNED_S, reset_s) / 60:g} min of fixes; {n_prior} epochs "
            "of earlier legs (the prior only) are shown but not scored"
        )
        if est.model.n_outliers:
            dr_notes.append(
                f"{est.model.n_outliers} fix(es) left out of the learning as outliers "
                f"(innovation beyond chi^2_2 = {OUTLIER_NIS:g} for every model)"
            )
    else:
        dr_notes.append(
            f"heading and speed held onto a {DR_STEP_S:g} s grid; error sources as "
            "configured (learn = false; Gauss-Markov, see docs/dead-reckoning.md)"
        )
    if 0 < cons.n_epochs < 10:
        dr_notes.append(
            f"only {cons.n_epochs} epochs scored: for a short log give a shorter "
            "--epoch-interval (e.g. 1min)"
        )
    if 0 < cons.n_legs < 5:
        dr_notes.append(
            f"only {cons.n_legs} leg(s) scored, and each leg is one trial: the test "
            "calls the circles too small only when the reference lies outside them "
            "in most legs or far outside; a shorter --dr-reset gives more legs"
        )
    dominant = _dominant_source(est, cons, tr, fix_s) if est is not None else None
    if cons.n_epochs:
        consistent = cons.verdict in ("consistent", "conservative")
        verdict = (
            f"{cons.verdict}: reference inside 2M at {100 * cons.inside_fraction:.1f} % of "
            f"{cons.n_epochs} epochs in {cons.n_legs} legs (a correct model gives "
            f"{100 * cons.expected_inside_fraction:.1f} %); RMS error/M "
            f"{cons.rms_error_over_m:.2f} (1 expected); NEES {cons.nees_statistic:.1f} "
            f"(chi^2 {cons.nees_lower:.1f}-{cons.nees_upper:.1f})"
        )
        if dominant is not None and cons.verdict != "consistent":
            verdict += (
                f"; the circle is dominated by {dominant[0]} (key [dead_reckoning] {dominant[1]})"
            )
    else:
        consistent = None
        verdict = (
            "undetermined: no epoch of a leg whose model was learned from earlier fixes "
            "has a reference position"
            if est is not None
            else "undetermined: no reference position at any DR epoch after a fix"
        )
    section = DRSection(
        heading_source=hdg_desc,
        speed_source=spd_desc,
        reset=reset_label,
        epoch_interval_s=float(epoch_s),
        track=full,
        epochs=epochs,
        legs=tuple(legs),
        reference_role=fdesc,
        containment_2m=cons.inside_fraction,
        n_scored=cons.n_epochs,
        expected_inside=cons.expected_inside_fraction,
        error_over_m_rms=cons.rms_error_over_m,
        consistent=consistent,
        verdict=verdict,
        n_gaps_bridged=int(n_bridged),
        n_breaks=int(tr.n_breaks),
        notes=tuple(dr_notes),
        mean_nees=cons.mean_nees,
        nees_statistic=cons.nees_statistic,
        nees_lower=cons.nees_lower,
        nees_upper=cons.nees_upper,
        leg_checks=cons.legs,
        dominant_source=dominant[0] if dominant else None,
        dominant_key=dominant[1] if dominant else None,
        learned=_learned_summary(est, cfg) if est is not None else None,
        reference_sigma_m=cons.reference_sigma_m,
        scored_out_of_sample=est is not None,
        fix_innovations=_fix_innovations(est, grid[0]),
        fix_source_key=_fix_key(voyage, fdesc),
    )
    # course and speed through the water for the calibration: leeway (B5) and speed (B1)
    # from a two-component log, as the DR used them
    if vy_g is not None:
        course_w = wrap_2pi(h_g + leeway_from_log_rad(v_g, vy_g))  # (B3)/(B2) + z (B5)
        speed_w = speed_from_components_mps(v_g, vy_g)  # (B1)
    else:
        course_w, speed_w = h_g, v_g
    inputs = _DRInputs(
        t0_ns=int(grid[0]),
        time_s=time_s,
        vn_mps=water.vn_mps,
        ve_mps=water.ve_mps,
        heading_rad=course_w,
        speed_mps=speed_w,
        ref_gap_s=ref_gap_s,
        mode=mode,
        epoch_interval_s=epoch_s,
        estimated=est,
    )
    return section, fixes, cons, inputs


# ------------------------------------------------------------------------- current


def _fix_innovations(est, t0_ns: int):
    """(time_ns, NIS, gate_m) of the fixes the estimated position's filter weighed, or None."""
    h = est.model.history if est is not None else None
    if h is None or h.nis is None:
        return None
    ok = np.isfinite(h.nis)
    return (t0_ns + np.round(h.time_s[ok] * 1e9).astype(np.int64), h.nis[ok], h.gate_m[ok])


def _fix_key(voyage: Voyage, fdesc: str) -> str | None:
    """The source key of the reference fixes ('gnss': the first GNSS source)."""
    if fdesc == "gnss":
        keys = voyage.role_sources("gnss")
        return keys[0] if keys else None
    if fdesc == "ins_mean":
        return None
    return fdesc


def _drift_and_set(north_mps: float, east_mps: float) -> tuple[float, float]:
    """Drift (m/s) and set (towards, rad in [0, 2 pi)) of a current (north, east)."""
    return math.hypot(north_mps, east_mps), float(wrap_2pi(math.atan2(east_mps, north_mps)))


def _current_learned(dr: _DRInputs, fixes) -> CurrentSection | None:
    """Set and drift as the estimated position uses them (dracc.math.ep).

    The voyage figures are the persistent current learned from every fix (the filter's
    final posterior of cbar, mixed over its grid of models), with its 1-sigma; the series
    for the plot is the filtered current (cbar plus its variation) at each filter step,
    causal, after the first fix.
    """
    m = dr.estimated.model
    h = m.history
    upd = np.flatnonzero(h.updated)
    if upd.size < 2:
        return None
    w = m.final_weights
    x = w @ m.final_x
    dev = m.final_x[:, 2:4] - x[2:4]
    P = np.einsum("m,mij->ij", w, m.final_P[:, 2:4, 2:4] + dev[:, :, None] * dev[:, None, :])
    mean_n, mean_e = float(x[2]), float(x[3])
    drift, set_rad = _drift_and_set(mean_n, mean_e)
    u = np.array([mean_n, mean_e]) / drift if drift > 0 else np.array([1.0, 0.0])
    sigma_d = math.sqrt(max(float(u @ P @ u), 0.0))  # along the drift
    v = np.array([-u[1], u[0]])
    sigma_set = math.sqrt(max(float(v @ P @ v), 0.0)) / drift if drift > 0 else math.nan
    keep = slice(int(upd[0]) + 1, None)
    cn, ce = h.current_ne_mps[keep, 0], h.current_ne_mps[keep, 1]
    note = (
        f"the current the estimated position uses: a persistent current plus its "
        f"Gauss-Markov variation, filtered causally from the {fixes[3]} fixes every "
        f"{m.step_s:g} s ({upd.size} updates) with the compass and log corrections beside "
        "it; voyage figures: the persistent current learned from every fix, with its "
        "1-sigma; the plot: the filtered current at each step"
    )
    return CurrentSection(
        set_deg=Estimate(math.degrees(set_rad), math.degrees(sigma_set)),
        drift_kn=Estimate(drift / KN_MPS, sigma_d / KN_MPS),
        time_ns=(h.time_s[keep] * 1e9).astype(np.int64) + dr.t0_ns,
        set_rad=wrap_2pi(np.arctan2(ce, cn)),
        drift_mps=np.hypot(cn, ce),
        drift_sigma_mps=h.current_sigma_mps[keep],
        n_updates=int(upd.size),
        notes=(note,),
    )


def _current(
    dr: _DRInputs, fixes, cfg: DeadReckoningConfig, missing: list[str]
) -> CurrentSection | None:
    """Set and drift from the Kalman filter of the aided-DR paper (dracc.math.current).

    The filter runs on a CURRENT_STEP_S grid over each stretch where the DR has a water
    velocity, updated by a fix every ``epoch_interval_s``.
    """
    ft, flat, flon, fdesc = fixes
    step = max(1, int(round(CURRENT_STEP_S / DR_STEP_S)))
    t = dr.time_s[::step]
    vn = dr.vn_mps[::step]
    ve = dr.ve_mps[::step]
    ok = np.isfinite(vn) & np.isfinite(ve)
    fix_s = (ft - dr.t0_ns) / 1e9
    model = CurrentModel.from_config(cfg)
    # contiguous stretches of valid velocity
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(np.int8), [0]])))
    times, sets, drifts, sig, cn_all, ce_all = [], [], [], [], [], []
    n_updates = 0
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        if b - a < 3:
            continue
        ts = t[a:b]
        sel = np.flatnonzero((fix_s >= ts[0]) & (fix_s <= ts[-1]))
        if sel.size < 2:
            continue
        # one fix per epoch interval (the first at or after each multiple)
        grid = np.arange(ts[0], ts[-1], dr.epoch_interval_s)
        pick = unique_sorted(np.searchsorted(fix_s, grid, side="left"))
        pick = pick[(pick < fix_s.size)]
        pick = pick[(fix_s[pick] >= ts[0]) & (fix_s[pick] <= ts[-1])]
        if pick.size < 2:
            continue
        start_i = pick[0]
        obs = [
            (float(fix_s[i]), PositionFix.from_sigma(flat[i], flon[i], cfg.fix_sigma_m))
            for i in pick[1:]
        ]
        t_run = ts[ts >= fix_s[start_i]]
        if t_run.size < 2:
            continue
        i0 = np.searchsorted(ts, t_run[0])
        course = np.arctan2(ve[a + i0 : b], vn[a + i0 : b])
        speed = np.hypot(vn[a + i0 : b], ve[a + i0 : b])
        # the filter starts at the first fix, advanced to the first epoch by the DR velocity
        start = PositionFix.from_sigma(flat[start_i], flon[start_i], cfg.fix_sigma_m)
        obs = [o for o in obs if t_run[0] <= o[0] <= t_run[-1]]
        ct = estimate_current(t_run, course, speed, start, obs, model)
        n_updates += len(ct.updates)
        keep = ct.t_s >= (obs[0][0] if obs else np.inf)  # report after the first update
        times.append((ct.t_s[keep] * 1e9).astype(np.int64) + dr.t0_ns)
        sets.append(ct.set_rad[keep])
        drifts.append(ct.drift_mps[keep])
        sig.append(ct.drift_sigma_mps[keep])
        cn_all.append(ct.current_north_mps[keep])
        ce_all.append(ct.current_east_mps[keep])
    if not times or not sum(x.size for x in times):
        missing.append(
            "current not estimated: fewer than two fixes within a stretch of dead reckoning"
        )
        return None
    cn = np.concatenate(cn_all)
    ce = np.concatenate(ce_all)
    s_d = np.concatenate(sig)
    drift, set_rad = _drift_and_set(float(np.mean(cn)), float(np.mean(ce)))
    sigma_d = float(np.sqrt(np.mean(s_d**2)))
    sigma_set = sigma_d / drift if drift > 0 else math.nan
    note = (
        f"voyage figures: the mean of the filtered current over {cn.size} filter epochs "
        f"({CURRENT_STEP_S:g} s grid, a {fdesc} fix every {dr.epoch_interval_s:g} s); sigma: "
        "the filter's RMS 1-sigma (not reduced by averaging). Over a leg the filter cannot tell "
        "current from a constant log or compass error: both are in these figures"
    )
    return CurrentSection(
        set_deg=Estimate(math.degrees(set_rad), math.degrees(sigma_set)),
        drift_kn=Estimate(drift / KN_MPS, sigma_d / KN_MPS),
        time_ns=np.concatenate(times),
        set_rad=np.concatenate(sets),
        drift_mps=np.concatenate(drifts),
        drift_sigma_mps=s_d,
        n_updates=n_updates,
        notes=(note,),
    )


# --------------------------------------------------------------------- calibration

#: calibration segments (reference displacement over each) and current knots
CAL_SEGMENT_S = 600.0
CAL_KNOT_S = 2 * 3600.0
#: the log offset is fitted only where the speed spans at least this much (5-95 %)
CAL_OFFSET_SPREAD_KN = 2.0


def _calibration(dr: _DRInputs, fixes, missing: list[str]) -> CalibrationSection | None:
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


# ----------------------------------------------------------------------- deviation


def _deviation(
    voyage: Voyage, cfg: Config, missing: list[str]
) -> tuple[DeviationResult | None, str | None]:
    """INS deviations from the mean (dracc.math.deviation), with GNSS as the reference where present."""
    present = [r for r in INS_ROLES if voyage.role_sources(r)]
    if len(present) < 2:
        found = f"only one INS unit ({present[0]}) found" if present else "no INS unit found"
        missing.append(
            f"no INS triple: {found}; the deviation statistics need at least "
            "two units (three for the paper's factors); map sources to ins1..ins3 with "
            "--role KEY=ROLE if they are there under another name"
        )
        return None, None
    units = {r: unit_series_from_voyage(voyage, r) for r in present}
    ref_role = "gnss" if voyage.role_sources("gnss") else None
    reference = unit_series_from_voyage(voyage, ref_role) if ref_role else None
    if reference is not None and reference.lat_rad.size == 0:
        reference, ref_role = None, None
    result = analyse_deviations(units, cfg.deviation, reference)
    if len(present) == 2:
        missing.append(
            f"no INS triple: only two units ({', '.join(present)}); statistics use "
            "the first-approximation factor sqrt(2) and no three-cornered hat"
        )
    if ref_role is None:
        missing.append(
            "no reference (GNSS) for the INS: the true error RMS and k* (Table 1) are not computed"
        )
    return result, ref_role
