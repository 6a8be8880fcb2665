"""The few probability distributions dracc needs, straight from ``scipy.special``.

``scipy.stats`` builds some hundred distribution objects when it is imported (about half a
second, a fifth of ``dracc analyze`` on a day's log); the special functions underneath are
all the analysis uses.  Each function here is the textbook identity, named as
``scipy.stats`` names it; ``tests/test_distributions.py`` checks every one against
``scipy.stats``.
"""

from __future__ import annotations

import math
from typing import Any, overload

import numpy as np
from scipy import special

from dracc.core.arrays import ArrayLike, FloatArray

_SQRT_2PI = math.sqrt(2.0 * math.pi)


@overload
def norm_cdf(x: float) -> float: ...
@overload
def norm_cdf(x: ArrayLike) -> FloatArray: ...
def norm_cdf(x: ArrayLike) -> Any:
    """Standard normal CDF  Phi(x)."""
    return special.ndtr(x)


@overload
def norm_pdf(x: float) -> float: ...
@overload
def norm_pdf(x: ArrayLike) -> FloatArray: ...
def norm_pdf(x: ArrayLike) -> Any:
    """Standard normal density  exp(-x^2 / 2) / sqrt(2 pi)."""
    x = np.asarray(x, dtype=float)
    return np.exp(-0.5 * x * x) / _SQRT_2PI


@overload
def norm_ppf(q: float) -> float: ...
@overload
def norm_ppf(q: ArrayLike) -> FloatArray: ...
def norm_ppf(q: ArrayLike) -> Any:
    """Standard normal quantile  Phi^-1(q)."""
    return special.ndtri(q)


@overload
def chi2_ppf(q: float, df: float) -> float: ...
@overload
def chi2_ppf(q: ArrayLike, df: ArrayLike) -> FloatArray: ...
def chi2_ppf(q: ArrayLike, df: ArrayLike) -> Any:
    """Chi-square quantile:  F^-1(q) = 2 P^-1(df / 2, q), P the regularised lower gamma."""
    return 2.0 * special.gammaincinv(np.asarray(df, dtype=float) / 2.0, q)


@overload
def chi2_sf(x: float, df: float) -> float: ...
@overload
def chi2_sf(x: ArrayLike, df: ArrayLike) -> FloatArray: ...
def chi2_sf(x: ArrayLike, df: ArrayLike) -> Any:
    """Chi-square survival function  P(X > x), X ~ chi2(df)."""
    return special.chdtrc(df, x)


@overload
def t_ppf(q: float, df: float) -> float: ...
@overload
def t_ppf(q: ArrayLike, df: ArrayLike) -> FloatArray: ...
def t_ppf(q: ArrayLike, df: ArrayLike) -> Any:
    """Student t quantile with ``df`` (real) degrees of freedom."""
    return special.stdtrit(df, q)


@overload
def beta_ppf(q: float, a: float, b: float) -> float: ...
@overload
def beta_ppf(q: ArrayLike, a: ArrayLike, b: ArrayLike) -> FloatArray: ...
def beta_ppf(q: ArrayLike, a: ArrayLike, b: ArrayLike) -> Any:
    """Beta(a, b) quantile: the inverse of the regularised incomplete beta function."""
    return special.betaincinv(a, b, q)


def binom_cdf(k: ArrayLike, n: ArrayLike, p: ArrayLike) -> FloatArray:
    """Binomial CDF  P(K <= k), K ~ B(n, p) (n a whole number);  1 for k >= n, 0 for k < 0."""
    k_floor = np.floor(np.asarray(k, dtype=float))
    n_int = np.asarray(n, dtype=np.int64)
    inner = special.bdtr(np.clip(k_floor, 0, np.maximum(n_int - 1, 0)).astype(np.int64), n_int, p)
    return np.where(k_floor >= n_int, 1.0, np.where(k_floor < 0, 0.0, inner))


@overload
def f_ppf(q: float, dfn: float, dfd: float) -> float: ...
@overload
def f_ppf(q: ArrayLike, dfn: ArrayLike, dfd: ArrayLike) -> FloatArray: ...
def f_ppf(q: ArrayLike, dfn: ArrayLike, dfd: ArrayLike) -> Any:
    """Fisher F(dfn, dfd) quantile, the inverse of :func:`f_cdf` (``special.fdtri``; in terms
    of the regularised incomplete beta I, F = dfd x / (dfn (1 - x)) with x = I^-1_q(dfn/2,
    dfd/2)).  Real degrees of freedom allowed."""
    return special.fdtri(np.asarray(dfn, dtype=float), np.asarray(dfd, dtype=float), q)


@overload
def f_cdf(x: float, dfn: float, dfd: float) -> float: ...
@overload
def f_cdf(x: ArrayLike, dfn: ArrayLike, dfd: ArrayLike) -> FloatArray: ...
def f_cdf(x: ArrayLike, dfn: ArrayLike, dfd: ArrayLike) -> Any:
    """Fisher F(dfn, dfd) CDF  P(F <= x) = I_{dfn x / (dfn x + dfd)}(dfn/2, dfd/2), x >= 0."""
    return special.fdtr(dfn, dfd, x)
