"""Three-cornered hat: each unit's own error variance from the pairwise differences.

Beyond the paper (METHODS section 4, "going further").  With three units whose errors
are independent, the mean square of a pairwise difference is the sum of the two
units' mean square errors, s_jk^2 = sigma_j^2 + sigma_k^2, so

    sigma_1^2 = 1/2 (s_12^2 + s_13^2 - s_23^2)     and cyclically

(the method of time and frequency metrology for three clocks, e.g. Gray & Allan 1974).
Unlike the fixed factor k of (K5b), it separates one bad unit from two good ones.
With few samples, or correlated units, an estimate can be negative: it is returned as
it is and flagged, never clamped (allantools clamps; dracc does not).

Mean squares, not variances: an INS error's bias is part of its RMS, as in (K3b).

Confidence bounds come from a moving-block bootstrap over the sampling instants:
blocks as long as the INS error correlation time (4-6 h) are drawn with replacement,
the three pairwise difference series together (so their dependence is kept), and the
percentile interval of the resampled sigma^2 is reported.  Seeded: reproducible.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geodesy import angdiff


@dataclass(frozen=True, eq=False)  # holds arrays: identity, not elementwise ==
class HatEstimate:
    """Three-cornered-hat variances of the three units in one channel and window.

    Shapes (3,): one entry per unit, in the order given.  ``variance`` in the channel's
    unit squared (m^2 or deg^2); ``sigma`` = sqrt(variance), NaN where the variance is
    negative (``negative`` True); ``var_lower``/``var_upper`` the bootstrap percentile
    bounds of the variance at ``confidence`` (may be negative, NaN with too few samples).
    """

    variance: np.ndarray
    sigma: np.ndarray
    var_lower: np.ndarray
    var_upper: np.ndarray
    negative: np.ndarray
    n: int
    confidence: float


def pairwise_mean_squares(y, circular: bool = False):
    """s_jk^2 = mean_i (y_ji - y_ki)^2 over instants valid in both, for the pairs
    (1,2), (1,3), (2,3) of ``y`` with shape (3, n).  Returns shape (3,) in that order."""
    d = pair_differences(y, circular)
    return np.nanmean(d * d, axis=-1)


def pair_differences(y, circular: bool = False):
    """The difference series y_1 - y_2, y_1 - y_3, y_2 - y_3; shape (3, n).
    Angles (``circular``) are differenced through :func:`angdiff`."""
    y = np.asarray(y, dtype=float)
    if y.shape[0] != 3:
        raise ValueError(f"three-cornered hat needs exactly three units, got {y.shape[0]}")
    pairs = ((0, 1), (0, 2), (1, 2))
    if circular:
        return np.stack([angdiff(y[a], y[b]) for a, b in pairs])
    return np.stack([y[a] - y[b] for a, b in pairs])


def hat_variances(s2):
    """Each unit's variance from the pairwise mean squares s2 = (s12^2, s13^2, s23^2), last axis:

    sigma_1^2 = 1/2 (s12^2 + s13^2 - s23^2)
    sigma_2^2 = 1/2 (s12^2 + s23^2 - s13^2)
    sigma_3^2 = 1/2 (s13^2 + s23^2 - s12^2)        (METHODS section 4, three-cornered hat)
    """
    s2 = np.asarray(s2, dtype=float)
    s12, s13, s23 = s2[..., 0], s2[..., 1], s2[..., 2]
    return np.stack([0.5 * (s12 + s13 - s23),
                     0.5 * (s12 + s23 - s13),
                     0.5 * (s13 + s23 - s12)], axis=-1)


def block_bootstrap_indices(n: int, block: int, draws: int, rng: np.random.Generator):
    """Moving-block bootstrap: ``draws`` index sets of length n, blocks of ``block`` instants."""
    block = max(1, min(block, n))
    n_blocks = -(-n // block)
    starts = rng.integers(0, n - block + 1, size=(draws, n_blocks))
    idx = (starts[:, :, None] + np.arange(block)).reshape(draws, -1)
    return idx[:, :n]


def three_cornered_hat(y, circular: bool = False, confidence: float = 0.9, block: int = 5,
                       draws: int = 1000, seed: int = 0) -> HatEstimate:
    """Three-cornered hat of ``y`` (shape (3, n), readings or deviations of three units).

    Deviations from the mean give the same differences as the readings
    (u_j - u_k = y_j - y_k), so either can be passed.  Only instants where all three
    are valid count.  ``block``: bootstrap block length in instants (the correlation
    time over the sampling interval).  Bounds are NaN when fewer than 2 blocks exist.
    """
    d = pair_differences(y, circular)
    d = d[:, ~np.any(np.isnan(d), axis=0)]
    n = d.shape[1]
    if n == 0:
        nan3 = np.full(3, np.nan)
        return HatEstimate(nan3, nan3, nan3, nan3, np.zeros(3, bool), 0, confidence)
    s2 = np.mean(d * d, axis=1)
    var = hat_variances(s2)
    lo = hi = np.full(3, np.nan)
    if n >= 2 * max(1, block):
        rng = np.random.default_rng(seed)
        idx = block_bootstrap_indices(n, block, draws, rng)
        sq = (d * d)[:, idx]  # (3 pairs, draws, n)
        boot = hat_variances(np.moveaxis(np.mean(sq, axis=-1), 0, -1))  # (draws, 3)
        alpha = (1.0 - confidence) / 2.0
        lo, hi = np.quantile(boot, [alpha, 1.0 - alpha], axis=0)
    with np.errstate(invalid="ignore"):
        sigma = np.where(var >= 0, np.sqrt(np.abs(var)), np.nan)
    return HatEstimate(variance=var, sigma=sigma, var_lower=lo, var_upper=hi,
                       negative=var < 0, n=n, confidence=confidence)
