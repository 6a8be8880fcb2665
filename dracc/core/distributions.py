"""The few probability distributions dracc needs, straight from ``scipy.special``.

``scipy.stats`` builds some hundred distribution objects when it is imported (about half a
second, a fifth of ``dracc analyze`` on a day's log); the special functions underneath are
all the analysis uses.  Each function here is the textbook identity, named as
``scipy.stats`` names it; ``tests/test_distributions.py`` checks every one against
``scipy.stats``.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import special

_SQRT_2PI = math.sqrt(2.0 * math.pi)


def norm_cdf(x):
    """Standard normal CDF  Phi(x)."""
    return special.ndtr(x)


def norm_pdf(x):
    """Standard normal density  exp(-x^2 / 2) / sqrt(2 pi)."""
    x = np.asarray(x, dtype=float)
    return np.exp(-0.5 * x * x) / _SQRT_2PI


def norm_ppf(q):
    """Standard normal quantile  Phi^-1(q)."""
    return special.ndtri(q)


def chi2_ppf(q, df):
    """Chi-square quantile:  F^-1(q) = 2 P^-1(df / 2, q), P the regularised lower gamma."""
    return 2.0 * special.gammaincinv(np.asarray(df, dtype=float) / 2.0, q)


def chi2_sf(x, df):
    """Chi-square survival function  P(X > x), X ~ chi2(df)."""
    return special.chdtrc(df, x)


def t_ppf(q, df):
    """Student t quantile with ``df`` (real) degrees of freedom."""
    return special.stdtrit(df, q)


def beta_ppf(q, a, b):
    """Beta(a, b) quantile: the inverse of the regularised incomplete beta function."""
    return special.betaincinv(a, b, q)


def binom_cdf(k, n, p):
    """Binomial CDF  P(K <= k), K ~ B(n, p) (n a whole number);  1 for k >= n, 0 for k < 0."""
    k = np.floor(np.asarray(k, dtype=float))
    n = np.asarray(n, dtype=np.int64)
    inner = special.bdtr(np.clip(k, 0, np.maximum(n - 1, 0)).astype(np.int64), n, p)
    return np.where(k >= n, 1.0, np.where(k < 0, 0.0, inner))


def f_ppf(q, dfn, dfd):
    """Fisher F(dfn, dfd) quantile, the inverse of :func:`f_cdf` (``special.fdtri``; in terms
    of the regularised incomplete beta I, F = dfd x / (dfn (1 - x)) with x = I^-1_q(dfn/2,
    dfd/2)).  Real degrees of freedom allowed."""
    return special.fdtri(np.asarray(dfn, dtype=float), np.asarray(dfd, dtype=float), q)


def f_cdf(x, dfn, dfd):
    """Fisher F(dfn, dfd) CDF  P(F <= x) = I_{dfn x / (dfn x + dfd)}(dfn/2, dfd/2), x >= 0."""
    return special.fdtr(dfn, dfd, x)
