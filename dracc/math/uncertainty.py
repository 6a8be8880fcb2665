"""The one home of 2M, "inside 2M" and how often a circle holds the truth.

M = sqrt(tr P) (drms, B30) and the circle dracc draws, 2M (B31), of a north/east
covariance P; ``inside`` is the error at most 2M.  How often a correct model puts the
truth inside a circle of radius r depends on the distribution the model predicts:

* Gaussian, e ~ N(0, P): P(|e| <= r) over the principal axes (sigma_1 >= sigma_2),
  with x = r sin(theta) along the major axis (Gauss-Legendre over theta)::

      p(r) = int_0^{pi/2} 2 phi(x/sigma_1)/sigma_1 (2 Phi(sqrt(r^2 - x^2)/sigma_2) - 1) r cos(theta) dtheta

  For r = 2M: 1 - exp(-4) = 0.9817 (circle), 2 Phi(2) - 1 = 0.9545 (line).
* Student-t (a scale mixture): e | lam ~ N(0, lam S) with lam inverse-gamma of shape a,
  scaled so that the drawn P = E[lam] S (covariance matching, dracc.math.ep.forecast):
  lam / E[lam] = (a - 1) / G with G ~ Gamma(a, 1).  Marginally a bivariate t with 2a
  degrees of freedom and covariance P::

      p_t(r) = E_G[ p(r; P (a - 1) / G) ]     (generalised Gauss-Laguerre over G)

  As a grows (many legs learned from) it tends to the Gaussian; with few it has the heavy
  tails a scale learned from few legs has.

``predictive_cdf`` at the observed error is the probability integral transform (PIT):
uniform over the epochs when the stated probabilities are the achieved ones.
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np

from dracc.core import distributions as dist
from dracc.core.arrays import ArrayLike, BoolArray, FloatArray
from dracc.math.ellipse import error_ellipse

__all__ = [
    "GAUSSIAN",
    "drms_m",
    "inside_circle",
    "predictive_cdf",
    "prob_inside",
    "prob_inside_2m",
    "radius_2m_m",
]

#: the shape of a Gaussian predictive (the scale is known)
GAUSSIAN = math.inf

_GL_X, _GL_W = np.polynomial.legendre.leggauss(64)
#: nodes of the generalised Gauss-Laguerre rule over the scale's Gamma distribution
_N_SCALE = 32


def drms_m(P_m2: ArrayLike) -> FloatArray:
    """M = sqrt(tr P) (B30): the drms of a north/east covariance (..., 2, 2) in m^2."""
    P = np.asarray(P_m2, float)
    return np.asarray(np.sqrt(P[..., 0, 0] + P[..., 1, 1]), float)


def radius_2m_m(P_m2: ArrayLike) -> FloatArray:
    """2M = 2 sqrt(tr P) (B31): the radius of the circle dracc draws."""
    return 2.0 * drms_m(P_m2)


def inside_circle(error_m: ArrayLike, radius_m: ArrayLike) -> BoolArray:
    """The error within the circle (a NaN on either side is not inside)."""
    with np.errstate(invalid="ignore"):
        return np.asarray(np.asarray(error_m, float) <= np.asarray(radius_m, float))


def _gaussian_inside(s1: FloatArray, s2: FloatArray, r: FloatArray) -> FloatArray:
    """P(|e| <= r) for e Gaussian with principal sigmas s1 >= s2 (broadcast), module doc."""
    s1, s2, r = (np.asarray(a, float)[..., None] for a in (s1, s2, r))
    theta = 0.5 * np.pi * _GL_X
    x1 = r * np.sin(theta)
    rem = r * np.cos(theta)  # sqrt(r^2 - x1^2)
    with np.errstate(divide="ignore", invalid="ignore"):
        inner = np.where(s2 > 0, 2 * dist.norm_cdf(rem / np.where(s2 > 0, s2, 1.0)) - 1, 1.0)
        dens = dist.norm_pdf(x1 / s1) / s1
    val = np.sum(_GL_W * dens * inner * r * np.cos(theta), axis=-1) * 0.5 * np.pi
    return np.where(s1[..., 0] > 0, val, (r[..., 0] >= 0).astype(float))


@cache
def _scale_rule(shape: float) -> tuple[FloatArray, FloatArray]:
    """(lam / E[lam], weights) at the nodes of the Gamma(shape) rule (module doc): the
    generalised Gauss-Laguerre rule of alpha = shape - 1 by Golub-Welsch, the eigenvalues
    of its Jacobi matrix (diagonal 2k + alpha + 1, off-diagonal sqrt(k (k + alpha))) and
    the first components of its eigenvectors squared (numpy only: scipy.linalg is not
    loaded for it)."""
    alpha = shape - 1.0
    k = np.arange(_N_SCALE, dtype=float)
    off = np.sqrt(k[1:] * (k[1:] + alpha))
    jacobi = np.diag(2.0 * k + alpha + 1.0) + np.diag(off, 1) + np.diag(off, -1)
    g, vec = np.linalg.eigh(jacobi)
    w = vec[0] ** 2 / np.sum(vec[0] ** 2)
    lam = (shape - 1.0) / g
    # 1/G is steep near 0 for a small shape: the rule's mean is 0.998 at shape 3; scaled to
    # exactly 1 so that the mixture's covariance is the P drawn
    return lam / float(lam @ w), w


def prob_inside(P_m2: ArrayLike, radius_m: ArrayLike, shape: ArrayLike = GAUSSIAN) -> FloatArray:
    """How often the predictive of covariance P (..., 2, 2) puts the error within
    ``radius_m`` (...): Gaussian for ``shape`` inf, else Student-t of that shape (> 1,
    per element; module doc)."""
    s1, s2, _ = error_ellipse(P_m2)
    r = np.asarray(radius_m, float)
    a = np.broadcast_to(np.asarray(shape, float), np.shape(s1))
    out = np.asarray(_gaussian_inside(s1, s2, np.broadcast_to(r, np.shape(s1))), float).copy()
    heavy = np.isfinite(a)
    for value in np.unique(a[heavy]):
        sel = heavy & (a == value)
        k, w = _scale_rule(float(max(value, 1.0 + 1e-6)))
        root = np.sqrt(k)
        p = _gaussian_inside(
            s1[sel][:, None] * root,
            s2[sel][:, None] * root,
            np.broadcast_to(r, s1.shape)[sel][:, None],
        )
        out[sel] = p @ w
    return np.asarray(out, float)


def prob_inside_2m(P_m2: ArrayLike, shape: ArrayLike = GAUSSIAN) -> FloatArray:
    """How often a correct model puts the error within 2M (0.954-0.982 when Gaussian)."""
    return prob_inside(P_m2, radius_2m_m(P_m2), shape)


def predictive_cdf(P_m2: ArrayLike, error_m: ArrayLike, shape: ArrayLike = GAUSSIAN) -> FloatArray:
    """The PIT of an observed error distance: P(|e| <= error) under the predictive."""
    return prob_inside(P_m2, error_m, shape)
