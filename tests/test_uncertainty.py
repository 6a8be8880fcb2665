"""2M, inside and how often a circle holds the error (dracc.math.uncertainty), against
independent values: closed forms, scipy's Gauss-Laguerre rule, Monte Carlo draws."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import special

from dracc.math.uncertainty import (
    _scale_rule,
    drms_m,
    inside_circle,
    predictive_cdf,
    prob_inside,
    prob_inside_2m,
    radius_2m_m,
)


def test_2m_is_twice_the_root_of_the_trace():
    P = np.array([[9.0, 2.0], [2.0, 16.0]])
    assert drms_m(P) == pytest.approx(5.0) and radius_2m_m(P) == pytest.approx(10.0)
    assert inside_circle([10.0, 10.1, np.nan], 10.0).tolist() == [True, False, False]


def test_gaussian_limits_circle_and_line():
    assert prob_inside_2m(np.eye(2) * 4.0) == pytest.approx(1 - math.exp(-4), abs=1e-12)
    assert prob_inside_2m(np.diag([4.0, 0.0])) == pytest.approx(math.erf(2 / math.sqrt(2)))
    # a circle of radius r around a circular Gaussian: 1 - exp(-r^2 / 2 sigma^2)
    assert prob_inside(np.eye(2), 1.5) == pytest.approx(1 - math.exp(-1.125), abs=1e-12)


@pytest.mark.parametrize("shape", [3.0, 4.7, 23.0])
def test_scale_rule_is_scipys_generalised_gauss_laguerre(shape):
    lam, w = _scale_rule(shape)
    g, wg = special.roots_genlaguerre(lam.size, shape - 1.0)
    order, ref = np.argsort(lam), np.argsort((shape - 1.0) / g)
    scipy_lam = ((shape - 1.0) / g)[ref]
    # the same nodes up to the scaling that makes the rule's mean exactly 1 (2e-3 at shape 3)
    assert np.allclose(lam[order] / lam[order][0], scipy_lam / scipy_lam[0], rtol=1e-10)
    assert np.allclose(lam[order], scipy_lam, rtol=2e-3)
    assert np.allclose(w[order], (wg / wg.sum())[ref], atol=1e-12)
    assert float(lam @ w) == pytest.approx(1.0, abs=1e-9)  # the drawn P is E[lam] S


def test_student_t_against_monte_carlo_draws():
    rng = np.random.default_rng(31)
    shape, n = 4.0, 400_000
    P = np.array([[30.0, 10.0], [10.0, 8.0]])
    lam = (shape - 1.0) / rng.gamma(shape, 1.0, n)  # inverse-gamma of mean 1
    e = (rng.standard_normal((n, 2)) @ np.linalg.cholesky(P).T) * np.sqrt(lam)[:, None]
    d = np.hypot(e[:, 0], e[:, 1])
    for r in (radius_2m_m(P), 5.0, 20.0):
        assert prob_inside(P, r, shape) == pytest.approx(np.mean(d <= r), abs=2.5e-3)
    # heavier tails than the Gaussian of the same covariance: less inside 2M
    assert prob_inside_2m(P, shape) < prob_inside_2m(P) - 0.005
    # the PIT of errors drawn from the predictive is uniform
    pit = predictive_cdf(np.broadcast_to(P, (4000, 2, 2)), d[:4000], shape)
    assert np.histogram(pit, 10, (0, 1))[0].min() > 330
