"""oed.prior: prior specifications, their quadrature rules, error estimates and bad input."""
import numpy as np
import pytest
from scipy import stats

from oed.prior import make_prior

NAMES = ("theta1", "theta2", "theta3")
P0 = np.array([0.05884, 4.298, 21.80])


def test_given_points_are_normalised_and_read_only():
    pr = make_prior((np.tile(P0, (2, 1)), [1.0, 3.0]), NAMES, P0)
    assert pr.rule == "points" and pr.n == 2
    assert np.allclose(pr.weights, [0.25, 0.75])
    assert not pr.points.flags.writeable and not pr.weights.flags.writeable
    assert np.isnan(pr.error(lambda P: P[:, 0]))


def test_tensor_gauss_rule_integrates_polynomials_exactly():
    pr = make_prior({"theta1": ("uniform", 0.0, 2.0), "theta2": ("normal", 4.298, 0.5)}, NAMES, np.array(
        [1.0, 4.298, 21.8]), order=4)
    assert pr.n == 16 and np.allclose(pr.points[:, 2], 21.8)
    # E[t1^3] = 2 on U(0, 2); E[t2^2] = mu^2 + sd^2; a 4-node Gauss rule is exact for degree <= 7
    assert pr.mean(pr.points[:, 0] ** 3) == pytest.approx(2.0, rel=1e-13)
    assert pr.mean(pr.points[:, 1] ** 2) == pytest.approx(4.298 ** 2 + 0.25, rel=1e-13)
    # the next-order rule agrees on a polynomial: the error estimate is at rounding level
    assert pr.error(lambda P: P[:, 0] ** 3 * P[:, 1] ** 2) < 1e-12


def test_lognormal_truncnormal_and_error_estimate_of_a_smooth_function():
    pr = make_prior({"theta2": ("lognormal", 4.0, 0.2)}, NAMES, P0, order=8)
    assert pr.mean(pr.points[:, 1]) == pytest.approx(stats.lognorm(0.2, scale=4.0).mean(), rel=1e-10)
    tn = make_prior({"theta1": ("truncnormal", 0.06, 0.01, 0.05, 0.07)}, NAMES, P0, order=12)
    exact = stats.truncnorm((0.05 - 0.06) / 0.01, (0.07 - 0.06) / 0.01, loc=0.06, scale=0.01).mean()
    assert tn.mean(tn.points[:, 0]) == pytest.approx(exact, rel=1e-9)
    f = (lambda P: np.exp(-P[:, 0] * 20.0))
    coarse = make_prior({"theta1": ("uniform", 0.0, 0.2)}, NAMES, P0, order=2)
    true = (1 - np.exp(-4.0)) / 4.0
    assert abs(coarse.mean(f(coarse.points)) - true) < 5 * coarse.error(f)


def test_qmc_and_grid_rules():
    q = make_prior({"theta1": ("uniform", 0.05, 0.07), "theta2": ("normal", 4.3, 1.0)}, NAMES, P0, rule="qmc",
                   order=256, seed=3)
    assert q.n == 256 and np.allclose(q.weights, 1 / 256)
    assert np.all((q.points[:, 0] >= 0.05) & (q.points[:, 0] <= 0.07))
    assert q.next_rule().seed == 4 and q.error(lambda P: P[:, 0]) < 1e-4
    g = make_prior({"theta1": ("uniform", 0.05, 0.07)}, NAMES, P0, rule="grid", order=3)
    assert np.allclose(np.sort(g.points[:, 0]), [0.05, 0.06, 0.07])


@pytest.mark.parametrize("prior, match", [
    ((np.tile(P0, (2, 1)), [1.0, -1.0]), r"prior: weights w must be finite and non-negative"),
    ((np.tile(P0, (2, 1)), [1.0, np.nan]), r"prior: weights w must be finite and non-negative"),
    ((np.tile(P0, (2, 1)), [1.0]), r"prior: weights w must have one entry per point"),
    ((np.ones((2, 2)), [1.0, 1.0]), r"prior: points P must have shape"),
    ({"theta1": ("beta", 1.0, 2.0)}, r"prior\['theta1'\]: unknown distribution 'beta'"),
    ({"theta1": ("uniform", 0.06, 0.07)}, r"prior\['theta1'\]: the bounds \[0.06, 0.07\] exclude the nominal"),
    ({"theta1": ("truncnormal", 0.06, 0.01, 0.06, 0.07)}, r"prior\['theta1'\]: the bounds .* exclude the nominal"),
    ({"k9": ("uniform", 0.0, 1.0)}, r"prior: 'k9' is not a parameter of the model"),
    ({"theta1": ("normal", 0.06, -1.0)}, r"prior\['theta1'\]: the standard deviation must be positive"),
    ({"theta1": ("uniform", 0.0)}, r"prior\['theta1'\]: uniform takes 2 arguments"),
    ({"theta1": "uniform"}, r"prior\['theta1'\]: expected \(distribution, \*args\)"),
    ("uniform", r"prior: expected \(P, w\)"),
])
def test_bad_priors_name_the_key(prior, match):
    with pytest.raises(ValueError, match=match):
        make_prior(prior, NAMES, P0)


def test_bad_rule_and_order():
    with pytest.raises(ValueError, match="rule: expected one of"):
        make_prior({"theta1": ("uniform", 0.05, 0.07)}, NAMES, P0, rule="smolyak")
    with pytest.raises(ValueError, match="order: expected an integer >= 1"):
        make_prior({"theta1": ("uniform", 0.05, 0.07)}, NAMES, P0, order=0)
    with pytest.raises(ValueError, match=r"prior\['theta2'\]: rule='grid' needs bounded"):
        make_prior({"theta2": ("normal", 4.3, 1.0)}, NAMES, P0, rule="grid")
