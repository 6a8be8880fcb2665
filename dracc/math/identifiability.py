"""Whether a least-squares fit determines its parameters: diagnostics of the normal matrix.

Pure numpy, no I/O (issue 29).  For a fit with Jacobian J the normal matrix is
``A = J^T J`` and the covariance ``s^2 A^-1``.  A parameter is not determined where

- it lies in a near-null direction of the correlation-normalised ``A`` (smallest
  eigenvalue below ``ILL_CONDITIONED``): the data cannot tell it from the others
  (:func:`inseparable`);
- fitting another parameter beside it inflates its variance more than ``VIF_MAX``-fold
  (:func:`variance_inflation`), where that other parameter may be left out of the model;
- its sigma against its estimate cannot tell its effect from none (``DETERMINABLE_Z``;
  judged by the caller, who knows the parameter's scale).

:func:`normal_inverse` never gives a parameter without data, or in an exact null
direction, a small variance: it is infinite.
"""

from __future__ import annotations

import numpy as np

from dracc.core.arrays import FloatArray

__all__ = [
    "DETERMINABLE_Z",
    "ILL_CONDITIONED",
    "VIF_MAX",
    "inseparable",
    "normal_inverse",
    "variance_inflation",
]

#: Variance inflation beyond which the log offset cannot be separated from the scale: the
#: scale's variance fitted beside the offset over its variance with the offset held at 0,
#: ``[A^-1]_ss / [A_(-b)^-1]_ss`` of the normal matrix A (Marquardt 1970's threshold of
#: serious collinearity, a factor 3.2 on the sigma).  At one speed it is thousands;
#: measured on simulated 24 h voyages: legs at 1.5-8 m/s 8.9 (fitted), at 4-7 m/s 34.
VIF_MAX = 10.0
#: Smallest eigenvalue of the correlation-normalised normal matrix below which the fit
#: cannot separate its parameters (from the current above all).  A straight leg with yaw
#: noise is not exactly singular (3.8e-5 measured on a simulated 3 h single-course voyage,
#: where the fit then gave a compass error of -0.3 +- 31 deg and a log scale of 175 +-
#: 151 %); voyages with course changes give 0.05-0.2.
ILL_CONDITIONED = 1e-3
#: a quantity is determinable where the fit tells the log's water track from none at 95 %
#: (two-sided): the heading error's sigma below 1/z rad (29 deg), the log scale's below
#: (1 + s)/z (its gain 1/(1 + s) z sigma from 0).  Beyond it the linearised sigma is not
#: even a sigma: the ship lying still fitted +511 +- 53 deg and -56 % (issue 29).
DETERMINABLE_Z = 1.96


def normal_inverse(A: FloatArray) -> FloatArray:
    """A^-1 of a normal matrix, through its correlation form; a parameter in a (near)
    null direction or without data gets an infinite variance, never a small one."""
    d = np.sqrt(np.diag(A))
    out = np.full_like(A, np.nan)
    ok = np.flatnonzero(d > 0)
    np.fill_diagonal(out, np.inf)
    if ok.size:
        An = A[np.ix_(ok, ok)] / np.outer(d[ok], d[ok])
        w, V = np.linalg.eigh(An)
        small = w <= 1e-12 * max(float(w[-1]), 1e-300)
        inv_w = np.where(small, 0.0, 1.0 / np.where(small, 1.0, w))
        inv = (V * inv_w) @ V.T / np.outer(d[ok], d[ok])
        # a parameter carried by a null direction has no finite variance
        null = (V[:, small] ** 2).sum(axis=1) > 1e-6
        inv[null, :] = np.where(np.eye(ok.size, dtype=bool)[null], np.inf, np.nan)
        out[np.ix_(ok, ok)] = inv
    return out


def variance_inflation(A: FloatArray, names: list[str], of: str, beside: str) -> float:
    """The largest variance inflation of the ``of`` parameters from fitting the ``beside``
    ones with them (inf where they cannot be told apart at all)."""
    i = [k for k, nm in enumerate(names) if nm == of]
    keep = [k for k, nm in enumerate(names) if nm != beside]
    joint = np.diag(normal_inverse(A))[i]
    held = np.diag(normal_inverse(A[np.ix_(keep, keep)]))[[keep.index(k) for k in i]]
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(np.isinf(joint), np.inf, joint / held)
    return float(np.max(np.nan_to_num(ratio, nan=np.inf, posinf=np.inf)))


def inseparable(A: FloatArray, names: list[str]) -> set[str]:
    """The parameter groups carrying more than 5 % of any near-null direction of the
    correlation-normalised normal matrix (``ILL_CONDITIONED``), and those without data."""
    d = np.sqrt(np.diag(A))
    out = {names[k] for k in np.flatnonzero(~(d > 0))}
    ok = np.flatnonzero(d > 0)
    w, V = np.linalg.eigh(A[np.ix_(ok, ok)] / np.outer(d[ok], d[ok]))
    weight = (V[:, w < ILL_CONDITIONED] ** 2).sum(axis=1)
    for g in set(names):
        if weight[[i for i, k in enumerate(ok) if names[k] == g]].sum() > 0.05:
            out.add(g)
    return out
