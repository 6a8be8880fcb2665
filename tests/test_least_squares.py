"""calibration.levenberg_marquardt: known minima and scipy.optimize.least_squares as reference."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import optimize

from dracc.math.calibration import levenberg_marquardt


def test_rosenbrock_reaches_its_minimum_from_the_textbook_start():
    def resid(x):
        return np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])

    def jac(x):
        return np.array([[-20.0 * x[0], 10.0], [-1.0, 0.0]])

    sol = levenberg_marquardt(resid, jac, np.array([-1.2, 1.0]))
    np.testing.assert_allclose(sol.x, [1.0, 1.0], atol=1e-8)
    assert float(sol.fun @ sol.fun) < 1e-16
    np.testing.assert_allclose(sol.jac, jac(sol.x))


def test_noisy_exponential_fit_matches_scipy_least_squares():
    rng = np.random.default_rng(7)
    t = np.linspace(0, 4, 60)
    y = 2.5 * np.exp(-1.3 * t) + 0.4 + rng.normal(0, 0.02, t.size)

    def resid(p):
        return p[0] * np.exp(-p[1] * t) + p[2] - y

    def jac(p):
        e = np.exp(-p[1] * t)
        return np.column_stack([e, -p[0] * t * e, np.ones_like(t)])

    ours = levenberg_marquardt(resid, jac, np.array([1.0, 0.5, 0.0]))
    ref = optimize.least_squares(
        resid, [1.0, 0.5, 0.0], jac=jac, method="lm", x_scale="jac", ftol=1e-12, xtol=1e-12
    )
    np.testing.assert_allclose(ours.x, ref.x, rtol=1e-7)
    assert float(ours.fun @ ours.fun) == pytest.approx(float(ref.fun @ ref.fun), rel=1e-10)


def test_a_linear_problem_is_solved_exactly_and_a_dead_parameter_does_not_break_it():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(40, 3))
    b = rng.normal(size=40)
    A[:, 2] = 0.0  # a parameter with no effect: the damping keeps the step finite

    sol = levenberg_marquardt(lambda x: A @ x - b, lambda x: A, np.zeros(3))
    expect = np.linalg.lstsq(A[:, :2], b, rcond=None)[0]
    np.testing.assert_allclose(sol.x[:2], expect, rtol=1e-8)
    assert np.isfinite(sol.x).all()
