"""The result types of :func:`~dracc.math.deviation.analyse_deviations`.

Every result is a frozen dataclass whose ``to_dict()`` gives the JSON-ready structure
of the ``deviation`` section of the analysis report (floats, None for NaN), so the
report layer only serialises.  Statistics of latitude and longitude are in metres
(north, east), of course in degrees; time is int64 UTC ns inside, ISO 8601 in
``to_dict``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dracc.core.geodesy import k_lambda, k_phi
from dracc.core.numbers import finite_or_none as _f
from dracc.core.timefmt import iso_utc
from dracc.core.units import ARCMIN_RAD
from dracc.core.vocabulary import CHANNEL_KEYS, CHANNELS
from dracc.math.deviation import stats
from dracc.math.deviation.berth import BerthReference

__all__ = [
    "ChannelMode",
    "ChannelStats",
    "DeviationResult",
    "HatStats",
    "KurtosisWindow",
    "ReferenceAverage",
    "ReferenceStats",
    "UnitStats",
    "WindowStats",
    "factor_alternatives",
    "metres_to_arcmin",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def metres_to_arcmin(
    north_m: ArrayLike, east_m: ArrayLike, lat_rad: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """North/east metres to arc-minutes of latitude and longitude at ``lat_rad``:
    dphi = north k_phi (B18), dlam = east k_lambda (B19), in arc-minutes."""
    lat = np.asarray(lat_rad, dtype=float)
    dlat: FloatArray = np.asarray(north_m, dtype=float) * k_phi(lat) / ARCMIN_RAD  # (B18)
    dlon: FloatArray = np.asarray(east_m, dtype=float) * k_lambda(lat) / ARCMIN_RAD  # (B19)
    return dlat, dlon


def factor_alternatives() -> dict[str, Any]:
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

    def to_dict(self) -> dict[str, Any]:
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

    def to_dict(self) -> dict[str, Any]:
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

    def to_dict(self) -> dict[str, Any]:
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

    def to_dict(self) -> dict[str, Any]:
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

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {c: s.to_dict() for c, s in self.channels.items()}
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

    def to_dict(self) -> dict[str, Any]:
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

    def to_dict(self) -> dict[str, Any]:
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

    def to_dict(self) -> dict[str, Any]:
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
    time_ns: IntArray  #: sampling instants (n,)
    #: unit -> channel -> deviations at the instants (m, m, deg); NaN where not available
    samples: dict[str, dict[str, FloatArray]]
    #: unit -> channel -> instants where the unit itself had no reading near the instant
    missing: dict[str, dict[str, int]]
    #: mean latitude of the position units at each instant (NaN where incomplete)
    lat_mean_rad: FloatArray
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
    #: the berth references (:mod:`.berth`) of ``[reference] alongside``; empty without one
    berths: tuple[BerthReference, ...] = ()

    @property
    def factors(self) -> dict[str, float]:
        return {c: m.factor for c, m in self.channels.items()}

    def lat_ref_rad(self) -> float:
        """The log's mean latitude (for arc-minute conversion of whole-log statistics)."""
        ok = ~np.isnan(self.lat_mean_rad)
        return float(np.mean(self.lat_mean_rad[ok])) if np.any(ok) else math.nan

    def to_dict(self, arcmin: bool = False) -> dict[str, Any]:
        """The JSON-ready ``deviation`` section (keys as settled in the reports issue).

        ``arcmin``: also give latitude/longitude deviations in arc-minutes
        (``lat_arcmin``, ``lon_arcmin`` per sample, at the instant's mean latitude) and the
        whole-log ``m_u_arcmin``/``m_y_arcmin`` (at the log's mean latitude).
        """
        samples: list[dict[str, Any]] = []
        if arcmin:
            dlat_am: dict[str, FloatArray] = {}
            dlon_am: dict[str, FloatArray] = {}
            for u in self.units:
                dlat_am[u], dlon_am[u] = metres_to_arcmin(
                    self.samples[u]["lat"], self.samples[u]["lon"], self.lat_mean_rad
                )
        for i, t in enumerate(self.time_ns):
            row: dict[str, Any] = {"time_utc": iso_utc(t)}
            for u in self.units:
                row[u] = {CHANNEL_KEYS[c]: _f(self.samples[u][c][i]) for c in CHANNELS}
                if arcmin:
                    row[u]["lat_arcmin"] = _f(dlat_am[u][i])
                    row[u]["lon_arcmin"] = _f(dlon_am[u][i])
            samples.append(row)
        units: dict[str, Any] = {u: s.to_dict() for u, s in self.whole.units.items()}
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
        reference: dict[str, dict[str, dict[str, Any]]] = {
            u: {c: r.to_dict() for c, r in s.reference.items()}
            for u, s in self.whole.units.items()
            if s.reference
        }
        for u, averages in self.reference_average.items():
            for c, avg in averages.items():
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
        } | ({"berths": [b.to_dict() for b in self.berths]} if self.berths else {})
