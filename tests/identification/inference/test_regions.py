"""Confidence ellipsoids and alpha_min (paper eq. 6 and Algorithm 1 line 08)."""
import numpy as np
import pytest
from scipy import stats

from identification import CovarianceError, alpha_min, alpha_min_two_sample, in_region, mahalanobis2


def test_alpha_min_puts_p_val_on_the_boundary():
    C = np.array([[4.0, 1.0], [1.0, 2.0]])
    p_cal = np.array([1.0, -1.0])
    p_val = np.array([3.0, 0.5])
    a = alpha_min(p_val, p_cal, C)
    d2 = (p_val - p_cal) @ np.linalg.solve(C, p_val - p_cal)
    assert a == pytest.approx(stats.chi2.sf(d2, 2), rel=1e-14)
    # on the boundary: inside for any larger region, outside for any smaller
    assert in_region(p_val, p_cal, C, a * 0.999)
    assert not in_region(p_val, p_cal, C, min(a * 1.001, 0.999))


def test_two_sample_uses_the_sum_of_covariances():
    C1, C2 = np.diag([1.0, 2.0]), np.diag([3.0, 1.0])
    a = alpha_min_two_sample([2.0, 1.0], [0.0, 0.0], C1, C2)
    assert a == pytest.approx(stats.chi2.sf(4 / 4 + 1 / 3, 2), rel=1e-14)
    assert a > alpha_min([2.0, 1.0], [0.0, 0.0], C1)


def test_alpha_min_is_uniform_under_the_null():
    """Monte Carlo: for p_val ~ N(p_cal, C), alpha_min ~ U(0,1); KS test at 1 %, 4000 draws."""
    rng = np.random.default_rng(0)
    C = np.array([[2.0, 0.6, 0.0], [0.6, 1.0, 0.2], [0.0, 0.2, 0.5]])
    L = np.linalg.cholesky(C)
    a = [alpha_min(L @ rng.standard_normal(3), np.zeros(3), C) for _ in range(4000)]
    assert stats.kstest(a, "uniform").pvalue > 0.01


def test_singular_covariance_is_an_error_not_a_pseudo_inverse():
    with pytest.raises(CovarianceError, match="not positive definite"):
        mahalanobis2([1, 1], [0, 0], np.array([[1.0, 1.0], [1.0, 1.0]]))
    with pytest.raises(CovarianceError, match="NaN"):
        alpha_min([1, 1], [0, 0], np.array([[np.nan, 0], [0, 1.0]]))
    with pytest.raises(ValueError, match="alpha must lie in"):
        in_region([0, 0], [0, 0], np.eye(2), 1.5)
