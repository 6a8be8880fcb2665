"""Ranking many units under statistical control: peer scores, change points, FDR.

Pure functions over numpy arrays; values are in the *score domain* (the log of an RMS,
a scale error in %, ...) with their standard errors ``se`` (NaN: not known).

Peer score of unit i against the m other units of its group (leave-one-out, so a bad
unit does not hide in its own spread; peers further than 3.5 robust sigmas from the
peers' median are left out, so another bad unit does not hide it either)::

    c_i     = mean of the peers' values
    tau_i^2 = max(r^2, s_peers^2 - mean(se_peers^2))      between-unit spread
    V_i     = se_i^2 + tau_i^2 + (tau_i^2 + mean(se_peers^2)) / m
    z_i     = (x_i - c_i) / sqrt(V_i)

with r the quantity's resolution (the smallest difference that means anything).  With
equal errors this is the prediction test of a new value against m normal ones, exactly
Student's t with m - 1 degrees of freedom; in general z_i is read against t with
Welch-Satterthwaite degrees of freedom nu = (m - 1) / w^2, w = s_peers^2 (1 + 1/m) / V_i
the share of V_i that rests on the peers' sample variance.  One-sided where only one direction is worse, two-sided otherwise.

Change point on one unit's own nightly series x_1..x_n (weights 1/se^2): the
two-segment statistic, the standardised difference of the weighted means after and
before each split k (at least ``min_before`` nights before, one after)::

    z_k = (mean(x_k..x_n) - mean(x_1..x_k-1)) / sqrt(1/W_after + 1/W_before)

maximised over k; its p-value is Bonferroni over the splits (conservative, exact at
the tail where it matters), read against Student's t where the errors' scale was
estimated (degrees of freedom 0.37 times the differences it came from).  ``since`` is the split's first night.

False discovery rate: Benjamini & Hochberg (1995) step-up q-values over the whole fleet.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special  # not scipy.stats: its import costs every dracc command

FloatArray = NDArray[np.float64]

#: 1 / Phi^-1(3/4): the MAD of a normal law times this is its sigma
MAD_TO_SIGMA = 1.482602218505602
#: asymptotic efficiency of the MAD at the normal law (Huber 1981), for its degrees of freedom
MAD_EFFICIENCY = 0.37
#: peers further than this many robust sigmas from the peers' median are not peers
TRIM = 3.5


def bh_qvalues(p: ArrayLike) -> FloatArray:
    """Benjamini-Hochberg adjusted p-values: q_(i) = min_{j>=i} p_(j) m / j, capped at 1.

    NaN p-values stay NaN and are not counted in m."""
    p = np.asarray(p, dtype=np.float64)
    q = np.full(p.shape, np.nan)
    ok = np.isfinite(p)
    m = int(ok.sum())
    if m == 0:
        return q
    order = np.argsort(p[ok], kind="mergesort")
    ranked = p[ok][order] * m / np.arange(1, m + 1)
    adjusted = np.minimum.accumulate(ranked[::-1])[::-1]
    out = np.empty(m)
    out[order] = np.minimum(adjusted, 1.0)
    q[ok] = out
    return q


def tail_p(z: ArrayLike, direction: int, df: ArrayLike = np.inf) -> FloatArray:
    """The p-value of ``z`` read against Student's t with ``df`` (normal for inf):
    upper tail for direction +1, lower tail for -1, both tails for 0."""
    z = np.asarray(z, dtype=np.float64)
    df = np.broadcast_to(np.asarray(df, dtype=np.float64), z.shape)
    finite = np.isfinite(df)
    # upper tails: Student's t (stdtr is its CDF) and the normal law (ndtr)
    law_sf = np.where(
        finite, special.stdtr(np.where(finite, df, 1.0), -np.abs(z)), special.ndtr(-np.abs(z))
    )
    if direction == 0:
        return np.asarray(np.minimum(1.0, 2.0 * law_sf), dtype=np.float64)
    upper = z * direction > 0
    return np.asarray(np.where(upper, law_sf, 1.0 - law_sf), dtype=np.float64)


@dataclass(frozen=True)
class PeerScores:
    """Per unit: the score, its p-value and the peer figures it rests on (NaN where the
    group has too few peers)."""

    z: FloatArray
    p: FloatArray
    center: FloatArray  #: c: the mean of the peers compared with (the score's centre)
    spread: FloatArray  #: tau: the between-unit spread beyond the units' own errors
    peers: NDArray[np.int64]  #: peers compared with
    df: FloatArray  #: degrees of freedom of the t law
    #: n x n, row i: the peers unit i was compared with (after the trim; ``peers`` counts them)
    compared: NDArray[np.bool_] | None = None
    median: FloatArray | None = None  #: the median of the peers compared with


def peer_scores(
    x: ArrayLike,
    se: ArrayLike,
    groups: ArrayLike,
    *,
    direction: int,
    resolution: float,
    min_peers: int = 3,
    peers_of: NDArray[np.bool_] | None = None,
) -> PeerScores:
    """Leave-one-out scores of every unit against the other units of its group, or, with
    ``peers_of`` (n x n, row i: the units unit i is compared with), against those."""
    x = np.asarray(x, dtype=np.float64)
    se = np.nan_to_num(np.asarray(se, dtype=np.float64), nan=0.0)
    n = len(x)
    if peers_of is None:
        g = np.asarray(groups)
        peers_of = g[:, None] == g[None, :]
    mask = np.asarray(peers_of, dtype=bool) & np.isfinite(x)[None, :]
    np.fill_diagonal(mask, False)
    z, p, center, spread, df, median = (np.full(n, np.nan) for _ in range(6))
    peers = np.zeros(n, dtype=np.int64)
    compared = np.zeros((n, n), dtype=bool)
    r2 = float(resolution) ** 2
    for i in np.flatnonzero(np.isfinite(x)):
        xo, so = x[mask[i]], se[mask[i]]
        if len(xo) < min_peers:
            peers[i] = len(xo)
            continue
        # another bad unit among the peers must not hide this one: peers beyond TRIM
        # robust sigmas of the peers' median are left out of the spread
        c0 = float(np.median(xo))
        mad = MAD_TO_SIGMA * float(np.median(np.abs(xo - c0)))
        keep = np.abs(xo - c0) <= TRIM * np.sqrt(mad * mad + so * so + r2)
        xo, so = xo[keep], so[keep]
        m = len(xo)
        peers[i] = m
        if m < min_peers:
            continue
        compared[i, np.flatnonzero(mask[i])[keep]] = True
        median[i] = float(np.median(xo))
        c = float(np.mean(xo))
        s2_own = float(np.mean(so * so))
        s2 = float(np.var(xo, ddof=1))
        tau2 = max(r2, s2 - s2_own)
        var_center = (tau2 + s2_own) / m
        v = se[i] ** 2 + tau2 + var_center
        # the part of V that rests on the peers' sample variance (m - 1 degrees of
        # freedom), also where it came out below their own errors (tau at its floor)
        share = min(1.0, s2 * (1.0 + 1.0 / m) / v)
        center[i], spread[i] = c, math.sqrt(tau2)
        df[i] = (m - 1) / max(share * share, 1e-12)
        z[i] = (x[i] - c) / math.sqrt(v)
    ok = np.isfinite(z)
    p[ok] = tail_p(z[ok], direction, df[ok])
    return PeerScores(z, p, center, spread, peers, df, compared, median)


@dataclass(frozen=True)
class ChangePoint:
    """The most likely change in one series: where, how big, how sure."""

    z: float  #: standardised difference after - before (signed; worse is +direction)
    p: float  #: Bonferroni over the splits
    index: int  #: first element after the change (-1: no split possible)
    before: float  #: weighted mean before
    after: float  #: weighted mean after
    splits: int


NO_CHANGE = ChangePoint(math.nan, math.nan, -1, math.nan, math.nan, 0)


def change_point(
    x: ArrayLike, se: ArrayLike, *, direction: int, min_before: int = 2, df: float = math.inf
) -> ChangePoint:
    """The two-segment change statistic of a series with standard errors ``se`` (all
    finite and > 0), maximised over the splits; see the module text.  ``df``: the degrees
    of freedom of the errors' scale where it was estimated (Student's t), inf if known."""
    x = np.asarray(x, dtype=np.float64)
    w = 1.0 / np.asarray(se, dtype=np.float64) ** 2
    n = len(x)
    ks = np.arange(max(1, min_before), n)
    if len(ks) == 0 or not np.all(np.isfinite(w)) or not np.all(np.isfinite(x)):
        return NO_CHANGE
    cw = np.concatenate(([0.0], np.cumsum(w)))
    cwx = np.concatenate(([0.0], np.cumsum(w * x)))
    wb, wa = cw[ks], cw[n] - cw[ks]
    mb, ma = cwx[ks] / wb, (cwx[n] - cwx[ks]) / wa
    zk = (ma - mb) / np.sqrt(1.0 / wa + 1.0 / wb)
    key = np.abs(zk) if direction == 0 else zk * direction
    j = int(np.argmax(key))
    p1 = float(tail_p(np.array([zk[j]]), direction, df)[0])
    return ChangePoint(
        float(zk[j]), min(1.0, len(ks) * p1), int(ks[j]), float(mb[j]), float(ma[j]), len(ks)
    )


def difference_scale(
    series: list[FloatArray], se: list[FloatArray] | None = None
) -> tuple[float, int]:
    """The robust scale of night-to-night differences over many series (level shifts touch
    one difference each, so a change does not inflate it): 1.4826 median |d| with
    d = (x_t - x_t-1) / sqrt(se_t^2 + se_t-1^2), or the raw difference / sqrt(2) without
    ``se``.  Returns (scale, number of differences); NaN without any."""
    ds = []
    for k, x in enumerate(series):
        x = np.asarray(x, dtype=np.float64)
        if len(x) < 2:
            continue
        d = np.diff(x)
        if se is None:
            d = d / math.sqrt(2.0)
        else:
            s = np.asarray(se[k], dtype=np.float64)
            d = d / np.sqrt(s[1:] ** 2 + s[:-1] ** 2)
        ds.append(d[np.isfinite(d)])
    if not ds:
        return math.nan, 0
    d = np.concatenate(ds)
    if len(d) == 0:
        return math.nan, 0
    return MAD_TO_SIGMA * float(np.median(np.abs(d))), len(d)
