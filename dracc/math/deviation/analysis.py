"""``analyse_deviations``: the whole method of METHODS section 4 in one call.

Sampling, deviations (K1), per unit and channel m_u (K3b), m_y (K5), excess kurtosis
(K6), latitude/longitude covariance and correlation (K7), limiting errors (K8) per
window (a day by default) and over the whole log, kurtosis over 24-72 h windows, the
a priori monitoring rule, the reference check of Table 1 and the three-cornered hat.

The results are the frozen dataclasses of :mod:`dracc.math.deviation.results` (also
importable from here); the configuration is checked by
:mod:`dracc.math.deviation.validation`.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Iterable
from typing import TypeVar, cast

import numpy as np
from numpy.typing import NDArray

from dracc.core.config import DeviationConfig
from dracc.core.timefmt import iso_utc
from dracc.core.vocabulary import CHANNELS, INS_ROLES
from dracc.math.deviation import stats
from dracc.math.deviation.channels import channel_factors, channel_mode, channel_stats
from dracc.math.deviation.hat import three_cornered_hat
from dracc.math.deviation.reference import (
    course_errors_rad,
    k_star_mark,
    kurtosis_mark,
    position_errors_m,
    table1_mark_k,
)
from dracc.math.deviation.results import (
    ChannelMode,
    ChannelStats,
    DeviationResult,
    HatStats,
    KurtosisWindow,
    ReferenceAverage,
    ReferenceStats,
    UnitStats,
    WindowStats,
    factor_alternatives,
    metres_to_arcmin,
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
from dracc.math.deviation.validation import check_config

__all__ = [
    "FISHER_PROBABILITY",
    # the result types, defined in dracc.math.deviation.results
    "ChannelMode",
    "ChannelStats",
    "DeviationResult",
    "HatStats",
    "KurtosisWindow",
    "ReferenceAverage",
    "ReferenceStats",
    "UnitStats",
    "WindowStats",
    "analyse_deviations",
    "check_config",
    "dedupe",
    "factor_alternatives",
    "metres_to_arcmin",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
ReasonArray = NDArray[np.int8]
_T = TypeVar("_T", bound=Hashable)


#: probability of the Fisher upper bound on the factor k (seeds/001: P = 0.99)
FISHER_PROBABILITY = 0.99


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
    chan_reason: dict[str, ReasonArray] = {}
    for c in CHANNELS:
        # sample_unit always gives the reasons
        rs = [
            cast(ReasonArray, sampled[u].pos_reason if c != "course" else sampled[u].hdg_reason)
            for u in chan_units[c]
        ]
        if rs:
            reasons = np.vstack(rs)
            chan_reason[c] = np.where(
                np.any(reasons == OUTSIDE_SPAN, axis=0),
                OUTSIDE_SPAN,
                np.where(np.any(reasons == GAP_TOO_LONG, axis=0), GAP_TOO_LONG, SAMPLED),
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
    factors = channel_factors(cfg)
    modes = {
        c: channel_mode(pos_units if c != "course" else crs_units, c, factors[c]) for c in CHANNELS
    }

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
                chans[c] = channel_stats(uu, m.factor, e_lim, u, c, cfg)
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


def _valid_times(unit: UnitSeries, part: str) -> IntArray:
    """Times of a unit's valid (non-NaN) position ('pos') or heading ('hdg') readings."""
    if part == "pos":
        ok = ~np.isnan(np.asarray(unit.lat_rad, float)) & ~np.isnan(np.asarray(unit.lon_rad, float))
        times: IntArray = np.asarray(unit.pos_time_ns, np.int64)[ok]
        return times
    ok = ~np.isnan(np.asarray(unit.heading_rad, float))
    times = np.asarray(unit.hdg_time_ns, np.int64)[ok]
    return times


def dedupe(items: Iterable[_T]) -> list[_T]:
    """Items in order, each once."""
    return list(dict.fromkeys(items))
