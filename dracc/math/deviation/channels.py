"""How each channel is analysed and its statistics in one window.

:func:`channel_mode`: which units a channel has and the factor k of (K5) that follows
(three units: the configured factor; two: the first approximation sqrt 2; one or none:
no statistics); :func:`channel_factors` the configured factors; :func:`channel_stats`
(K3b)-(K8) and the a priori monitoring rule for one unit and channel.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dracc.core.config import DeviationConfig
from dracc.core.vocabulary import CHANNEL_KEYS, CHANNELS
from dracc.math.deviation import stats
from dracc.math.deviation.results import ChannelMode, ChannelStats

__all__ = ["channel_factors", "channel_mode", "channel_stats"]


def channel_factors(cfg: DeviationConfig) -> dict[str, float]:
    if cfg.first_approximation:
        return dict.fromkeys(CHANNELS, stats.K_FIRST_APPROX_THREE)
    return {"lat": cfg.factor_lat, "lon": cfg.factor_lon, "course": cfg.factor_course}


def channel_stats(
    u: NDArray[np.float64],
    factor: float,
    kurt_limit: float,
    unit: str,
    channel: str,
    cfg: DeviationConfig,
) -> ChannelStats:
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


def channel_mode(units: list[str], channel: str, factor: float) -> ChannelMode:
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
