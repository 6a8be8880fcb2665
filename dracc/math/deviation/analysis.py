"""``analyse_deviations``: the whole method of METHODS section 4 in one call.

Sampling, deviations (K1), per unit and channel m_u (K3b), m_y (K5), excess kurtosis
(K6), latitude/longitude covariance and correlation (K7), limiting errors (K8) per
window (a day by default) and over the whole log, kurtosis over 24-72 h windows, the
a priori monitoring rule, the reference check of Table 1 and the three-cornered hat.

Every result is a frozen dataclass whose ``to_dict()`` gives the JSON-ready structure
of the ``deviation`` section of the analysis report (floats, None for NaN), so the
report layer only serialises.

Units: statistics of latitude and longitude are in metres (north, east); of course in
degrees (the paper's channels).  Time is int64 UTC ns inside, ISO 8601 in ``to_dict``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np

from dracc.core.config import DeviationConfig
from dracc.core.errors import ConfigError
from dracc.core.geodesy import k_lambda, k_phi
from dracc.core.numbers import finite_or_none as _f
from dracc.core.timefmt import iso_utc
from dracc.core.units import ARCMIN_RAD
from dracc.core.vocabulary import CHANNEL_KEYS, CHANNELS, INS_ROLES
from dracc.math.deviation import stats
from dracc.math.deviation.hat import three_cornered_hat
from dracc.math.deviation.reference import (
    course_errors_rad,
    k_star_mark,
    kurtosis_mark,
    position_errors_m,
    table1_mark_k,
)
from dracc.math.deviation.sampling import (
    DAY_NS,
    GAP_TOO_LONG,
    OUTSIDE_SPAN,
    REASONS,
    SAMPLED,
    UnitSeries,
    sample_unit,
    sampling_instants,
)


def metres_to_arcmin(north_m, east_m, lat_rad):
    """North/east metres to arc-minutes of latitude and longitude at ``lat_rad``:
    dphi = north k_phi (B18), dlam = east k_lambda (B19), in arc-minutes."""
    lat = np.asarray(lat_rad, dtype=float)
    dlat = np.asarray(north_m, dtype=float) * k_phi(lat) / ARCMIN_RAD  # (B18)
    dlon = np.asarray(east_m, dtype=float) * k_lambda(lat) / ARCMIN_RAD  # (B19)
    return dlat, dlon


# ------------------------------------------------------------------------- results


@dataclass(frozen=True)
class ChannelStats:
    """(K3b)-(K8) for one unit and channel in one window, in the channel's unit (m or deg)."""

    n: int  #: deviations used
    m_u: float  #: RMS of the deviations (K3b)
    k: float  #: factor used: m_y = k m_u (K5)
    m_y: float  #: RMS error estimate (K5)
    kurtosis: float  #: *excess* kurtosis of the deviations (K6); 0 for a normal law
    kurtosis_for_limit: float  #: the kurtosis K_PIE used (the window's own, or the upper bound)
    n_eff: float  #: effective number of independent samples (correlation time)
    k_pie: float  #: (K8) conversion RMS -> limiting error at the probability
    k_hm: float  #: (K8) upper confidence factor of the RMS
    limit: float  #: (K8) limiting error y^(P) = K_PIE K_hm m_y
    apriori: float | None  #: configured a priori RMS, None where none is configured
    exceeds_apriori: bool | None  #: m_y > a priori (None without one)
    new_apriori: float  #: the monitoring rule: max(a priori, m_y); m_y where there is none
    verdict: str  #: 'exceeds', 'within', or 'no a priori: the deviation estimate is mandatory'
    notes: tuple[str, ...] = ()  #: why a figure is missing or how it was obtained

    def to_dict(self) -> dict:
        return {
            "n": int(self.n),
            "m_u": _f(self.m_u),
            "k": _f(self.k),
            "m_y": _f(self.m_y),
            "kurtosis": _f(self.kurtosis),
            "kurtosis_kind": "excess",
            "kurtosis_for_limit": _f(self.kurtosis_for_limit),
            "n_eff": _f(self.n_eff),
            "k_pie": _f(self.k_pie),
            "k_hm": _f(self.k_hm),
            "limit": _f(self.limit),
            "apriori": _f(self.apriori),
            "exceeds_apriori": self.exceeds_apriori,
            "new_apriori": _f(self.new_apriori),
            "verdict": self.verdict,
            "notes": list(self.notes),
        }


@dataclass(frozen=True)
class HatStats:
    """Three-cornered hat for one unit and channel, beside the factor method's m_y.

    ``variance`` may be negative (``negative``): reported, never clamped; ``sigma`` is
    then NaN.  ``var_lower``/``var_upper``: generalized-pivot (Wishart) bounds of the
    variance, with ``dof`` degrees of freedom (fewer than n where errors are correlated).
    ``disagree``: the factor method's m_y^2 lies outside those bounds (None without bounds).
    """

    n: int
    variance: float
    sigma: float
    var_lower: float
    var_upper: float
    negative: bool
    m_y_factor: float
    disagree: bool | None
    dof: float = math.nan

    def to_dict(self) -> dict:
        return {
            "n": int(self.n),
            "variance": _f(self.variance),
            "sigma": _f(self.sigma),
            "var_lower": _f(self.var_lower),
            "var_upper": _f(self.var_upper),
            "negative": bool(self.negative),
            "m_y_factor": _f(self.m_y_factor),
            "disagree": self.disagree,
            "dof": _f(self.dof),
        }


@dataclass(frozen=True)
class ReferenceStats:
    """Table 1 for one unit and channel in one window (errors against the reference)."""

    n: int  #: instants with both a deviation and a reference
    rmse: float  #: plain RMS of the true errors sqrt(sum x^2 / n)
    m_x: float  #: RMS of the errors by (K3b), as the paper's Table 1
    m_u: float  #: RMS of the deviations by (K3b) over the same instants
    k_star: float  #: k* = m_x / m_u
    k: float  #: the factor in use
    mark: str  #: '+' where k* <= k, '-' otherwise
    kurtosis_error: float  #: excess kurtosis of the errors (K6)
    kurtosis_deviation: float  #: excess kurtosis of the deviations (K6), same instants
    kurtosis_mark: str  #: '<', '>', '=': E_dev against E_err
    mark_k: float = math.nan  #: the threshold of the mark (1.5 for the paper's 1.49)
    #: Fisher upper bound of the factor, k_it = k K_FD(0.99; N, N), N independent samples
    k_upper: float = math.nan
    k_fd: float = math.nan
    n_independent: float = math.nan

    def to_dict(self) -> dict:
        return {
            "n": int(self.n),
            "rmse": _f(self.rmse),
            "m_x": _f(self.m_x),
            "m_u": _f(self.m_u),
            "k_star": _f(self.k_star),
            "k": _f(self.k),
            "mark": self.mark,
            "kurtosis_error": _f(self.kurtosis_error),
            "kurtosis_deviation": _f(self.kurtosis_deviation),
            "kurtosis_mark": self.kurtosis_mark,
            "mark_k": _f(self.mark_k),
            "k_upper_fisher": _f(self.k_upper),
            "k_fd": _f(self.k_fd),
            "n_independent": _f(self.n_independent),
            "within_fisher": None
            if math.isnan(self.k_star) or math.isnan(self.k_upper)
            else bool(self.k_star <= self.k_upper),
        }


@dataclass(frozen=True)
class ReferenceAverage:
    """The last row of Table 1: RMS averaged over the windows (days), weights n per day."""

    days: int  #: windows that entered the average (n >= 2)
    m_x: float  #: weighted RMS of the errors
    m_u: float  #: weighted RMS of the deviations
    k_star: float  #: m_x / m_u

    def to_dict(self) -> dict:
        return {
            "days": self.days,
            "m_x": _f(self.m_x),
            "m_u": _f(self.m_u),
            "k_star": _f(self.k_star),
        }


@dataclass(frozen=True)
class UnitStats:
    """Everything for one unit in one window; channels absent where the unit is not analysed."""

    channels: dict[str, ChannelStats]
    cov_lat_lon_m2: float  #: (K7a)
    r_lat_lon: float  #: (K7b)
    hat: dict[str, HatStats]  #: empty unless three units in the channel
    reference: dict[str, ReferenceStats]  #: empty without a reference

    def to_dict(self) -> dict:
        d: dict = {c: s.to_dict() for c, s in self.channels.items()}
        d["cov_lat_lon_m2"] = _f(self.cov_lat_lon_m2)
        d["r_lat_lon"] = _f(self.r_lat_lon)
        return d


@dataclass(frozen=True)
class WindowStats:
    """Statistics over one window (``label`` the start date, or 'all' for the whole log)."""

    label: str
    start_ns: int
    end_ns: int  #: exclusive
    units: dict[str, UnitStats]

    def to_dict(self) -> dict:
        return {
            "label": self.label,
            "start_utc": iso_utc(self.start_ns),
            "end_utc": iso_utc(self.end_ns),
            "units": {u: s.to_dict() for u, s in self.units.items()},
            "hat": {
                u: {c: h.to_dict() for c, h in s.hat.items()}
                for u, s in self.units.items()
                if s.hat
            },
            "reference": {
                u: {c: r.to_dict() for c, r in s.reference.items()}
                for u, s in self.units.items()
                if s.reference
            },
        }


@dataclass(frozen=True)
class KurtosisWindow:
    """Excess kurtosis (K6) of one unit and channel over one long window (24-72 h)."""

    length_s: float
    start_ns: int
    n: int
    kurtosis: float

    def to_dict(self) -> dict:
        return {
            "length_s": self.length_s,
            "start_utc": iso_utc(self.start_ns),
            "n": self.n,
            "kurtosis": _f(self.kurtosis),
        }


@dataclass(frozen=True)
class ChannelMode:
    """How a channel was analysed: which units, the factor, and what a reader must know."""

    units: tuple[str, ...]
    mode: str  #: 'three', 'two', 'one' or 'none'
    factor: float  #: k of (K5); NaN where no statistics
    message: str | None

    def to_dict(self) -> dict:
        return {
            "units": list(self.units),
            "mode": self.mode,
            "factor": _f(self.factor),
            "message": self.message,
        }


@dataclass(frozen=True, eq=False)  # holds arrays: identity, not elementwise ==
class DeviationResult:
    """The ``deviation`` section: samples, per-window and whole-log statistics."""

    interval_s: float
    offset_s: float
    probability: float
    confidence: float
    units: tuple[str, ...]  #: INS roles with any data
    channels: dict[str, ChannelMode]
    time_ns: np.ndarray  #: sampling instants (n,)
    #: unit -> channel -> deviations at the instants (m, m, deg); NaN where not available
    samples: dict[str, dict[str, np.ndarray]]
    #: unit -> channel -> instants where the unit itself had no reading near the instant
    missing: dict[str, dict[str, int]]
    #: mean latitude of the position units at each instant (NaN where incomplete)
    lat_mean_rad: np.ndarray
    whole: WindowStats
    windows: tuple[WindowStats, ...]
    #: unit -> channel -> the long kurtosis windows (24-72 h)
    kurtosis_windows: dict[str, dict[str, tuple[KurtosisWindow, ...]]]
    #: unit -> channel -> the upper bound: the largest kurtosis over the long windows
    kurtosis_upper: dict[str, dict[str, float]]
    #: unit -> channel -> weighted average over the windows (Table 1, last row)
    reference_average: dict[str, dict[str, ReferenceAverage]]
    messages: tuple[str, ...] = field(default_factory=tuple)
    #: channel -> reason ('outside unit span', 'gap too long') -> sampling instants (from the
    #: first reading of any unit to the last) not used in the channel for that reason
    skipped: dict[str, dict[str, int]] = field(default_factory=dict)

    @property
    def factors(self) -> dict[str, float]:
        return {c: m.factor for c, m in self.channels.items()}

    def lat_ref_rad(self) -> float:
        """The log's mean latitude (for arc-minute conversion of whole-log statistics)."""
        ok = ~np.isnan(self.lat_mean_rad)
        return float(np.mean(self.lat_mean_rad[ok])) if np.any(ok) else math.nan

    def to_dict(self, arcmin: bool = False) -> dict:
        """The JSON-ready ``deviation`` section (keys as settled in the reports issue).

        ``arcmin``: also give latitude/longitude deviations in arc-minutes
        (``lat_arcmin``, ``lon_arcmin`` per sample, at the instant's mean latitude) and the
        whole-log ``m_u_arcmin``/``m_y_arcmin`` (at the log's mean latitude).
        """
        samples = []
        if arcmin:
            dlat_am, dlon_am = {}, {}
            for u in self.units:
                dlat_am[u], dlon_am[u] = metres_to_arcmin(
                    self.samples[u]["lat"], self.samples[u]["lon"], self.lat_mean_rad
                )
        for i, t in enumerate(self.time_ns):
            row: dict = {"time_utc": iso_utc(t)}
            for u in self.units:
                row[u] = {CHANNEL_KEYS[c]: _f(self.samples[u][c][i]) for c in CHANNELS}
                if arcmin:
                    row[u]["lat_arcmin"] = _f(dlat_am[u][i])
                    row[u]["lon_arcmin"] = _f(dlon_am[u][i])
            samples.append(row)
        units: dict = {u: s.to_dict() for u, s in self.whole.units.items()}
        if arcmin:
            lat_ref = self.lat_ref_rad()
            for u, s in self.whole.units.items():
                for c in ("lat", "lon"):
                    if c in s.channels:
                        conv = (
                            metres_to_arcmin(1.0, 0.0, lat_ref)[0]
                            if c == "lat"
                            else metres_to_arcmin(0.0, 1.0, lat_ref)[1]
                        )
                        units[u][c]["m_u_arcmin"] = _f(s.channels[c].m_u * conv)
                        units[u][c]["m_y_arcmin"] = _f(s.channels[c].m_y * conv)
        for u, chans in self.kurtosis_upper.items():
            for c, e in chans.items():
                if u in units and c in units[u]:
                    units[u][c]["kurtosis_upper"] = _f(e)
                    units[u][c]["kurtosis_windows"] = [
                        w.to_dict() for w in self.kurtosis_windows[u][c]
                    ]
        reference = {
            u: {c: r.to_dict() for c, r in s.reference.items()}
            for u, s in self.whole.units.items()
            if s.reference
        }
        for u, chans in self.reference_average.items():
            for c, avg in chans.items():
                reference.setdefault(u, {}).setdefault(c, {})["weighted"] = avg.to_dict()
        return {
            "interval_s": self.interval_s,
            "offset_s": self.offset_s,
            "probability": self.probability,
            "confidence": self.confidence,
            "factors": {c: _f(k) for c, k in self.factors.items()},
            "factor_alternatives": factor_alternatives(),
            "channels": {c: m.to_dict() for c, m in self.channels.items()},
            "units_present": list(self.units),
            "missing": self.missing,
            "skipped": self.skipped,
            "samples": samples,
            "units": units,
            "hat": {
                u: {c: h.to_dict() for c, h in s.hat.items()}
                for u, s in self.whole.units.items()
                if s.hat
            },
            "reference": reference,
            "windows": [w.to_dict() for w in self.windows],
            "messages": list(self.messages),
        }


# ---------------------------------------------------------------------- the method

#: probability of the Fisher upper bound on the factor k (seeds/001: P = 0.99)
FISHER_PROBABILITY = 0.99


def factor_alternatives() -> dict:
    """The factors beside the fixed ones (seeds/001), for the reader to compare: (K5a)'s
    first approximation sqrt(3/2); the second approximation through r from (K4) and (K3a)
    as printed, and with its cross term once; the paper's stated 1.32."""
    return {
        "first_approximation": math.sqrt(1.5),
        "second_approximation_r": float(stats.k_second_approximation()),
        "second_approximation_r_cross_once": float(stats.k_second_approximation(cross=1)),
        "paper_stated_second": 1.32,
        "paper_stated_longitude": 1.49,
    }


def check_config(cfg: DeviationConfig) -> None:
    """Raise ConfigError naming the key for values the method cannot use."""
    for f in fields(DeviationConfig):
        value, default = getattr(cfg, f.name), getattr(DeviationConfig(), f.name)
        if isinstance(default, bool):
            ok = isinstance(value, bool)
        elif isinstance(default, int):
            ok = isinstance(value, int) and not isinstance(value, bool)
        elif isinstance(default, float):
            ok = (
                isinstance(value, (int, float))
                and not isinstance(value, bool)
                and math.isfinite(value)
            )
        else:
            continue
        if not ok:
            raise ConfigError(
                f"[deviation] {f.name} = {value!r}: must be "
                f"{type(default).__name__ if not isinstance(default, float) else 'a finite number'}"
            )
    if cfg.interval_s <= 0 or cfg.window_s <= 0:
        raise ConfigError("[deviation] interval_s and window_s must be positive")
    if cfg.velocity_min_gap_s < 0:
        raise ConfigError(
            f"[deviation] velocity_min_gap_s must be >= 0, got {cfg.velocity_min_gap_s}"
        )
    if cfg.max_interp_gap_s < 0:
        raise ConfigError(f"[deviation] max_interp_gap_s must be >= 0, got {cfg.max_interp_gap_s}")
    for name in ("confidence", "hat_confidence"):
        v = getattr(cfg, name)
        if not 0.5 <= v < 1.0:
            raise ConfigError(f"[deviation] {name} must be in [0.5, 1), got {v}")
    if cfg.correlation_time_s < 0:
        raise ConfigError(
            f"[deviation] correlation_time_s must be >= 0, got {cfg.correlation_time_s}"
        )
    if any(w <= 0 for w in cfg.kurtosis_windows_s):
        raise ConfigError("[deviation] kurtosis_windows_s must all be positive")
    if cfg.hat_draws < 100:
        raise ConfigError(f"[deviation] hat_draws must be >= 100, got {cfg.hat_draws}")
    keys = set(CHANNEL_KEYS.values())
    for unit, table in cfg.apriori.items():
        if unit not in INS_ROLES:
            raise ConfigError(
                f"[deviation.apriori] {unit!r}: unit must be one of {', '.join(INS_ROLES)}"
            )
        if not isinstance(table, dict):
            raise ConfigError(
                f"[deviation.apriori] {unit} must be a table of {', '.join(sorted(keys))}"
            )
        for key, value in table.items():
            if key not in keys:
                raise ConfigError(
                    f"[deviation.apriori.{unit}] unknown key {key!r}; known: "
                    f"{', '.join(sorted(keys))}"
                )
            if not isinstance(value, (int, float)) or not value > 0:
                raise ConfigError(
                    f"[deviation.apriori.{unit}] {key} = {value!r}: must be a positive number"
                )


def _factors(cfg: DeviationConfig) -> dict[str, float]:
    if cfg.first_approximation:
        return dict.fromkeys(CHANNELS, stats.K_FIRST_APPROX_THREE)
    return {"lat": cfg.factor_lat, "lon": cfg.factor_lon, "course": cfg.factor_course}


def _channel_stats(u, factor, kurt_limit, unit, channel, cfg: DeviationConfig) -> ChannelStats:
    """(K3b)-(K8) and the a priori rule for one unit/channel/window; ``kurt_limit`` NaN means
    'use this window's own kurtosis'."""
    n = int(stats.count_valid(u))
    m_u = float(stats.rms_k3b(u))  # (K3b)
    m_y = factor * m_u  # (K5)
    e = float(stats.excess_kurtosis_k6(u))  # (K6)
    e_lim = e if math.isnan(kurt_limit) else kurt_limit
    n_eff = float(stats.effective_samples(n, cfg.interval_s, cfg.correlation_time_s))
    notes: list[str] = []
    kp = stats.k_pie(cfg.probability, e_lim)  # (K8)
    if e_lim <= stats.KURTOSIS_MIN:
        # No law has E <= -2; (K6) gets there when the deviations are nearly constant
        # (a bias), through its n - 1.45.  The family's limit at E -> -2 is the two-point
        # law, whose limiting error is its RMS: K_PIE = 1.
        kp = 1.0
        notes.append(
            f"kurtosis {e_lim:.2f} <= -2 (nearly constant deviations): "
            "K_PIE = 1, the two-point limit"
        )
    kh = stats.k_hm(cfg.confidence, n_eff) if n_eff >= 1 else math.nan  # (K8)
    if n_eff < 1:
        notes.append(
            f"fewer than one independent sample (N_eff = {n_eff:.2f} with a "
            f"{cfg.correlation_time_s / 3600:g} h correlation time): no upper "
            "confidence bound, no limiting error"
        )
    limit = kp * kh * m_y  # (K8)
    apriori = cfg.apriori.get(unit, {}).get(CHANNEL_KEYS[channel])
    if apriori is None:
        exceeds, new, verdict = None, m_y, "no a priori: the deviation estimate is mandatory"
    elif math.isnan(m_y):
        exceeds, new, verdict = None, float(apriori), "no estimate"
    else:
        exceeds = bool(m_y > apriori)
        new = max(float(apriori), m_y)  # conclusions: the larger becomes the new a priori
        verdict = "exceeds" if exceeds else "within"
    return ChannelStats(
        n=n,
        m_u=m_u,
        k=factor,
        m_y=m_y,
        kurtosis=e,
        kurtosis_for_limit=e_lim,
        n_eff=n_eff,
        k_pie=float(kp),
        k_hm=float(kh),
        limit=float(limit),
        apriori=None if apriori is None else float(apriori),
        exceeds_apriori=exceeds,
        new_apriori=float(new),
        verdict=verdict,
        notes=tuple(notes),
    )


def _mode(units: list[str], channel: str, factor: float) -> ChannelMode:
    names = ", ".join(units)
    if len(units) >= 3:
        return ChannelMode(tuple(units), "three", factor, None)
    if len(units) == 2:
        return ChannelMode(
            tuple(units),
            "two",
            stats.K_FIRST_APPROX_TWO,
            f"{channel}: only two units ({names}): deviations from their mean are "
            "half their difference; m_y uses the first-approximation factor "
            "sqrt(2) = 1.414, and no three-cornered hat is possible",
        )
    if len(units) == 1:
        return ChannelMode(
            tuple(units),
            "one",
            math.nan,
            f"{channel}: only one unit ({names}): no deviation statistics "
            "(the method needs at least two units, three for its factors)",
        )
    return ChannelMode((), "none", math.nan, f"{channel}: no INS data")


def analyse_deviations(
    units: dict[str, UnitSeries],
    cfg: DeviationConfig | None = None,
    reference: UnitSeries | None = None,
) -> DeviationResult:
    """INS accuracy from deviations from the mean of three (METHODS section 4, K1-K8).

    ``units``: role ('ins1'..'ins3') -> readings; ``reference``: GNSS (or berth)
    readings for the Table 1 check, or None.  Fewer than three units is not an error:
    two units give first-approximation statistics (sqrt 2), one or none gives no
    statistics; :attr:`DeviationResult.channels` says which, with a message.
    Raises ConfigError for configuration values the method cannot use.
    """
    cfg = cfg or DeviationConfig()
    check_config(cfg)
    for name in units:
        if name not in INS_ROLES:
            raise ValueError(f"unit {name!r} is not one of {INS_ROLES}")
    names = [u for u in INS_ROLES if u in units]
    spans = [s for s in (units[u].span_ns() for u in names) if s is not None]
    if spans:
        # candidate instants over the readings of all units; whether a channel may use
        # an instant is decided below from each unit's own span and gaps (never widened:
        # a reading is not held past the end of a unit's data, nor before its start)
        instants = sampling_instants(
            min(s[0] for s in spans), max(s[1] for s in spans), cfg.interval_s, cfg.offset_s
        )
    else:
        instants = np.empty(0, np.int64)
    sampled = {
        u: sample_unit(units[u], instants, cfg.max_interp_gap_s, cfg.velocity_min_gap_s)
        for u in names
    }
    # which units each channel has (any reading at all), and why an instant is not used
    # in a channel: outside the span of one of its units, or a gap too long in one
    chan_units = {
        "lat": [u for u in names if len(_valid_times(units[u], "pos"))],
        "course": [u for u in names if len(_valid_times(units[u], "hdg"))],
    }
    chan_units["lon"] = chan_units["lat"]
    chan_reason = {}
    for c in CHANNELS:
        rs = [
            sampled[u].pos_reason if c != "course" else sampled[u].hdg_reason for u in chan_units[c]
        ]
        if rs:
            rs = np.vstack(rs)
            chan_reason[c] = np.where(
                np.any(rs == OUTSIDE_SPAN, axis=0),
                OUTSIDE_SPAN,
                np.where(np.any(rs == GAP_TOO_LONG, axis=0), GAP_TOO_LONG, SAMPLED),
            )
        else:
            chan_reason[c] = np.full(len(instants), OUTSIDE_SPAN, np.int8)
    # an instant at which no unit has a reading (a pause in the recording, or a stray
    # record days away) is not an instant of the method: left out, not counted as missing.
    # An instant some unit has is listed (its readings are real), but a channel uses it
    # only where every unit of the channel is sampled there (inside its data, no long
    # gap): outside the common span its deviations are NaN, never a held reading.
    keep = np.zeros(len(instants), dtype=bool)
    for su in sampled.values():
        keep |= ~np.isnan(su.lat_rad) | ~np.isnan(su.heading_rad)
    # every candidate instant a channel does not use, by its reason
    skipped = {
        c: {REASONS[k]: int(np.sum(chan_reason[c] == k)) for k in (OUTSIDE_SPAN, GAP_TOO_LONG)}
        for c in CHANNELS
        if chan_units[c]
    }
    if not keep.all():
        instants = instants[keep]
        sampled = {u: su.select(keep) for u, su in sampled.items()}
    n_inst = len(instants)
    nan = np.full(n_inst, np.nan)

    pos_units = [u for u in names if np.any(~np.isnan(sampled[u].lat_rad))]
    crs_units = [u for u in names if np.any(~np.isnan(sampled[u].heading_rad))]
    present = tuple(u for u in names if u in pos_units or u in crs_units)
    factors = _factors(cfg)
    modes = {c: _mode(pos_units if c != "course" else crs_units, c, factors[c]) for c in CHANNELS}

    # (K1) deviations per channel, units along axis 0
    dev = {u: {c: nan.copy() for c in CHANNELS} for u in present}
    lat_mean = nan
    if len(pos_units) >= 2:
        lat = np.vstack([sampled[u].lat_rad for u in pos_units])
        lon = np.vstack([sampled[u].lon_rad for u in pos_units])
        north, east, lat_mean = stats.deviations_position_m(lat, lon)  # (K1), metres
        for j, u in enumerate(pos_units):
            dev[u]["lat"], dev[u]["lon"] = north[j], east[j]
    if len(crs_units) >= 2:
        hdg = np.vstack([sampled[u].heading_rad for u in crs_units])
        crs = np.degrees(stats.deviations_course_rad(hdg))  # (K1) on the circle, degrees
        for j, u in enumerate(crs_units):
            dev[u]["course"] = crs[j]
    missing = {
        u: {
            "lat": int(np.sum(np.isnan(sampled[u].lat_rad))),
            "lon": int(np.sum(np.isnan(sampled[u].lon_rad))),
            "course": int(np.sum(np.isnan(sampled[u].heading_rad))),
        }
        for u in present
    }

    # reference errors at the instants (Table 1)
    err: dict[str, dict[str, np.ndarray]] = {}
    if reference is not None and n_inst:
        ref = sample_unit(reference, instants, cfg.max_interp_gap_s, cfg.velocity_min_gap_s)
        for u in present:
            xn, xe = position_errors_m(
                sampled[u].lat_rad, sampled[u].lon_rad, ref.lat_rad, ref.lon_rad
            )
            xc = np.degrees(course_errors_rad(sampled[u].heading_rad, ref.heading_rad))
            err[u] = {"lat": xn, "lon": xe, "course": xc}

    # kurtosis over the long windows (24-72 h) and its upper bound (conclusions)
    origin = int(instants[0] - instants[0] % DAY_NS) if n_inst else 0
    kwin: dict[str, dict[str, tuple[KurtosisWindow, ...]]] = {}
    kup: dict[str, dict[str, float]] = {}
    for u in present:
        kwin[u], kup[u] = {}, {}
        for c in CHANNELS:
            if u not in modes[c].units or modes[c].mode == "one":
                continue
            wins = []
            for length_s in cfg.kurtosis_windows_s:
                idx = stats.window_index(instants, length_s, origin)
                for k in np.unique(idx):
                    sel = dev[u][c][idx == k]
                    wins.append(
                        KurtosisWindow(
                            float(length_s),
                            origin + int(k) * int(round(length_s * 1e9)),
                            int(stats.count_valid(sel)),
                            float(stats.excess_kurtosis_k6(sel)),
                        )
                    )
            kwin[u][c] = tuple(wins)
            good = [
                w.kurtosis
                for w in wins
                if w.n >= cfg.min_kurtosis_samples and not math.isnan(w.kurtosis)
            ]
            kup[u][c] = max(good) if good else math.nan

    def window(label: str, sel: np.ndarray, start_ns: int, end_ns: int, whole: bool) -> WindowStats:
        out: dict[str, UnitStats] = {}
        for u in present:
            chans: dict[str, ChannelStats] = {}
            refs: dict[str, ReferenceStats] = {}
            for c in CHANNELS:
                m = modes[c]
                if u not in m.units or m.mode == "one":
                    continue
                uu = dev[u][c][sel]
                # whole log: the upper bound over the 24-72 h windows (NaN where none
                # qualifies: then the log's own kurtosis); a window: its own kurtosis
                e_lim = kup[u].get(c, math.nan) if whole else math.nan
                chans[c] = _channel_stats(uu, m.factor, e_lim, u, c, cfg)
                if u in err:
                    x = err[u][c][sel]
                    both = ~np.isnan(x) & ~np.isnan(uu)
                    if np.any(both):
                        xb, ub = x[both], uu[both]
                        m_x, m_uu = float(stats.rms_k3b(xb)), float(stats.rms_k3b(ub))
                        ks = m_x / m_uu if m_uu > 0 else math.nan
                        e_x = float(stats.excess_kurtosis_k6(xb))
                        e_u = float(stats.excess_kurtosis_k6(ub))
                        k_it, k_fd, n_ind = stats.k_upper_fisher(
                            m.factor,
                            int(both.sum()),
                            cfg.interval_s,
                            cfg.correlation_time_s,
                            FISHER_PROBABILITY,
                        )
                        refs[c] = ReferenceStats(
                            n=int(both.sum()),
                            rmse=float(stats.rms_plain(xb)),
                            m_x=m_x,
                            m_u=m_uu,
                            k_star=ks,
                            k=m.factor,
                            mark=k_star_mark(ks, m.factor, c),
                            kurtosis_error=e_x,
                            kurtosis_deviation=e_u,
                            kurtosis_mark=kurtosis_mark(e_x, e_u, cfg.kurtosis_tol),
                            mark_k=table1_mark_k(m.factor, c),
                            k_upper=float(k_it),
                            k_fd=float(k_fd),
                            n_independent=float(n_ind),
                        )
            cov, r = (
                stats.lat_lon_covariance(dev[u]["lat"][sel], dev[u]["lon"][sel])
                if "lat" in chans
                else (math.nan, math.nan)
            )  # (K7)
            out[u] = UnitStats(
                channels=chans,
                cov_lat_lon_m2=float(cov),
                r_lat_lon=float(r),
                hat={},
                reference=refs,
            )
        # three-cornered hat per channel with three units
        block = max(1, math.ceil(cfg.correlation_time_s / cfg.interval_s))
        for c in CHANNELS:
            m = modes[c]
            if m.mode != "three":
                continue
            y = np.vstack([dev[u][c][sel] for u in m.units])
            h = three_cornered_hat(
                y,
                circular=False,
                confidence=cfg.hat_confidence,
                block=block,
                draws=cfg.hat_draws,
                seed=cfg.seed,
                corr_instants=cfg.correlation_time_s / cfg.interval_s,
            )
            for j, u in enumerate(m.units):
                m_y = out[u].channels[c].m_y
                lo, hi = h.var_lower[j], h.var_upper[j]
                disagree = (
                    None if (np.isnan(lo) or np.isnan(m_y)) else bool(not lo <= m_y * m_y <= hi)
                )
                out[u].hat[c] = HatStats(
                    n=h.n,
                    variance=float(h.variance[j]),
                    sigma=float(h.sigma[j]),
                    var_lower=float(lo),
                    var_upper=float(hi),
                    negative=bool(h.negative[j]),
                    m_y_factor=m_y,
                    disagree=disagree,
                    dof=float(h.dof),
                )
        return WindowStats(label, start_ns, end_ns, out)

    if n_inst:
        whole = window(
            "all",
            np.ones(n_inst, bool),
            int(instants[0]),
            int(instants[-1]) + int(round(cfg.interval_s * 1e9)),
            True,
        )
        idx = stats.window_index(instants, cfg.window_s, origin)
        w_ns = int(round(cfg.window_s * 1e9))
        windows = tuple(
            window(
                str(iso_utc(origin + int(k) * w_ns))[:10]
                if cfg.window_s == 86400.0
                else str(iso_utc(origin + int(k) * w_ns)),
                idx == k,
                origin + int(k) * w_ns,
                origin + (int(k) + 1) * w_ns,
                False,
            )
            for k in np.unique(idx)
        )
    else:
        whole = WindowStats("all", 0, 0, {})
        windows = ()

    # Table 1, last row: weighted over the windows
    ref_avg: dict[str, dict[str, ReferenceAverage]] = {}
    for u in present:
        for c in CHANNELS:
            rows = [
                w.units[u].reference[c]
                for w in windows
                if u in w.units and c in w.units[u].reference
            ]
            if rows:
                n = [r.n for r in rows]
                mx = stats.weighted_rms([r.m_x for r in rows], n)
                mu = stats.weighted_rms([r.m_u for r in rows], n)
                used = sum(1 for r in rows if r.n >= 2 and not math.isnan(r.m_x))
                ref_avg.setdefault(u, {})[c] = ReferenceAverage(
                    used, mx, mu, mx / mu if mu > 0 else math.nan
                )

    messages = [m.message for m in modes.values() if m.message]
    if reference is not None and not err:
        messages.append("reference given but no sampling instants: no Table 1 check")
    if not n_inst:
        messages.append("no sampling instants: the INS readings span no sampling instant")
    for u in present:
        for c, k in missing[u].items():
            if k and u in modes[c].units:
                messages.append(
                    f"{u} {c}: missing at {k} of {n_inst} instants "
                    f"(outside its data, or no reading within "
                    f"{cfg.max_interp_gap_s:g} s on each side)"
                )
    for c, why in skipped.items():
        if sum(why.values()) and modes[c].mode in ("three", "two"):
            messages.append(
                f"{c}: instants not used: " + ", ".join(f"{k} {n}" for k, n in why.items() if n)
            )
    return DeviationResult(
        interval_s=cfg.interval_s,
        offset_s=cfg.offset_s,
        probability=cfg.probability,
        confidence=cfg.confidence,
        units=present,
        channels=modes,
        time_ns=instants,
        samples=dev,
        missing=missing,
        skipped=skipped,
        lat_mean_rad=lat_mean,
        whole=whole,
        windows=windows,
        kurtosis_windows=kwin,
        kurtosis_upper=kup,
        reference_average=ref_avg,
        messages=tuple(dedupe(messages)),
    )


def _valid_times(unit: UnitSeries, part: str) -> np.ndarray:
    """Times of a unit's valid (non-NaN) position ('pos') or heading ('hdg') readings."""
    if part == "pos":
        ok = ~np.isnan(np.asarray(unit.lat_rad, float)) & ~np.isnan(np.asarray(unit.lon_rad, float))
        return np.asarray(unit.pos_time_ns, np.int64)[ok]
    ok = ~np.isnan(np.asarray(unit.heading_rad, float))
    return np.asarray(unit.hdg_time_ns, np.int64)[ok]


def dedupe(items):
    """Items in order, each once."""
    seen: set = set()
    return [x for x in items if not (x in seen or seen.add(x))]
