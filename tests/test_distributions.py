"""dracc.core.distributions against scipy.stats (the independent reference) and hand values."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from dracc.core import distributions as dist


def test_normal_against_scipy_stats_and_hand_values():
    x = np.linspace(-6, 6, 241)
    np.testing.assert_allclose(dist.norm_cdf(x), stats.norm.cdf(x), rtol=1e-14, atol=1e-300)
    np.testing.assert_allclose(dist.norm_pdf(x), stats.norm.pdf(x), rtol=1e-14)
    q = np.array([1e-12, 0.001, 0.025, 0.5, 0.975, 0.999, 1 - 1e-12])
    np.testing.assert_allclose(dist.norm_ppf(q), stats.norm.ppf(q), rtol=1e-13)
    assert float(dist.norm_ppf(0.975)) == pytest.approx(1.959963984540054, abs=1e-12)
    assert 2 * float(dist.norm_cdf(2.0)) - 1 == pytest.approx(0.9544997361036416, abs=1e-14)
    assert float(dist.norm_pdf(0.0)) == pytest.approx(1 / math.sqrt(2 * math.pi), rel=1e-15)


@pytest.mark.parametrize("df", [1, 2, 3.5, 10, 40, 123.25])
def test_chi2_against_scipy_stats(df):
    q = np.array([1e-6, 0.01, 0.05, 0.5, 0.95, 0.99, 1 - 1e-6])
    np.testing.assert_allclose(dist.chi2_ppf(q, df), stats.chi2.ppf(q, df), rtol=1e-12)
    x = np.array([0.0, 0.1, 1.0, df, 3.0 * df, 100.0])
    np.testing.assert_allclose(dist.chi2_sf(x, df), stats.chi2.sf(x, df), rtol=1e-12, atol=1e-300)


def test_chi2_hand_values():
    # chi2(2) is exponential with mean 2: F^-1(q) = -2 ln(1 - q), P(X > x) = exp(-x / 2)
    assert float(dist.chi2_ppf(0.95, 2)) == pytest.approx(-2 * math.log(0.05), rel=1e-13)
    assert float(dist.chi2_sf(3.0, 2)) == pytest.approx(math.exp(-1.5), rel=1e-13)
    # the printed table value chi2_0.95(1) = 3.841
    assert float(dist.chi2_ppf(0.95, 1)) == pytest.approx(3.841458820694124, rel=1e-12)


@pytest.mark.parametrize("df", [2.5, 4.0, 7.0, 30.0, 1e4])
def test_student_t_against_scipy_stats(df):
    q = np.array([0.001, 0.025, 0.5, 0.8, 0.975, 0.999])
    np.testing.assert_allclose(dist.t_ppf(q, df), stats.t.ppf(q, df), rtol=1e-12, atol=1e-15)


def test_student_t_hand_value():
    # t with 2 degrees of freedom: F^-1(q) = (2q - 1) / sqrt(2 q (1 - q))
    q = 0.9
    assert float(dist.t_ppf(q, 2.0)) == pytest.approx(
        (2 * q - 1) / math.sqrt(2 * q * (1 - q)), rel=1e-12
    )


@pytest.mark.parametrize("a", [0.3, 1.0, 2.5, 40.0])
def test_beta_against_scipy_stats(a):
    q = np.array([0.001, 0.05, 0.5, 0.95, 0.999])
    np.testing.assert_allclose(dist.beta_ppf(q, a, a), stats.beta.ppf(q, a, a), rtol=1e-10)
    # Beta(1, 1) is uniform
    np.testing.assert_allclose(dist.beta_ppf(q, 1.0, 1.0), q, rtol=1e-13)


def test_binomial_cdf_against_scipy_stats_and_edges():
    for n in (1, 5, 24, 120):
        for p in (0.05, 0.5, 0.9545, 0.99):
            k = np.arange(-2, n + 3)
            np.testing.assert_allclose(
                dist.binom_cdf(k, n, p), stats.binom.cdf(k, n, p), rtol=1e-12, atol=1e-300
            )
    # hand value: P(K <= 1), K ~ B(3, 1/2) = (1 + 3) / 8
    assert float(dist.binom_cdf(1, 3, 0.5)) == pytest.approx(0.5, rel=1e-15)
    assert float(dist.binom_cdf(2.7, 3, 0.5)) == pytest.approx(7 / 8, rel=1e-15)


@pytest.mark.parametrize("dfn, dfd", [(1, 1), (2, 7), (5, 5), (40, 40), (32, 48), (2.5, 123.25)])
def test_f_against_scipy_stats(dfn, dfd):
    q = np.array([1e-6, 0.01, 0.05, 0.5, 0.95, 0.99, 1 - 1e-6])
    np.testing.assert_allclose(dist.f_ppf(q, dfn, dfd), stats.f.ppf(q, dfn, dfd), rtol=1e-10)
    x = np.array([0.0, 0.1, 1.0, 2.0, 10.0, 100.0])
    np.testing.assert_allclose(
        dist.f_cdf(x, dfn, dfd), stats.f.cdf(x, dfn, dfd), rtol=1e-12, atol=1e-300
    )


def test_f_hand_values():
    # F(2, 2): P(F <= x) = x / (1 + x), so F^-1(q) = q / (1 - q): 0.99 -> 99
    assert float(dist.f_ppf(0.99, 2, 2)) == pytest.approx(99.0, rel=1e-12)
    assert float(dist.f_cdf(3.0, 2, 2)) == pytest.approx(0.75, rel=1e-14)
    # the printed table values F_0.95(40, 40) = 1.69, F_0.99(40, 40) = 2.11
    assert round(float(dist.f_ppf(0.95, 40, 40)), 2) == 1.69
    assert round(float(dist.f_ppf(0.99, 40, 40)), 2) == 2.11
