"""oed.prior_sparse: Smolyak sparse grids as make_prior(rule="sparse"): polynomial exactness per distribution,
the level l vs l+1 error estimate against the tensor rule on the compartmental model, and the design verbs'
refusal of negative weights."""
import itertools

import numpy as np
import pytest
from scipy import stats

from oed.prior import make_prior
from oed.prior_sparse import gauss_rule_1d

NAMES = ("a", "b", "c")
NOMINAL = np.array([2.0, 0.5, 1.0])
MARGINALS = {
    "uniform": (("uniform", 1.0, 3.0), stats.uniform(1.0, 2.0), lambda x: x),
    "normal": (("normal", 0.5, 0.2), stats.norm(0.5, 0.2), lambda x: x),
    "truncnormal": (("truncnormal", 1.0, 0.5, 0.2, 1.5), stats.truncnorm(-1.6, 1.0, loc=1.0, scale=0.5), lambda x: x),
    # lognormal: the rule is Gauss-Hermite in log p, so exact for polynomials in z = log(p / median) / s ~ N(0, 1)
    "lognormal": (("lognormal", 2.0, 0.3), stats.norm(0.0, 1.0), lambda x: np.log(x / 2.0) / 0.3),
}
NOMINALS = {"uniform": 2.0, "normal": 0.5, "truncnormal": 1.0, "lognormal": 2.0}


@pytest.mark.parametrize("dist", list(MARGINALS))
@pytest.mark.parametrize("level", [1, 2, 3, 4])
def test_sparse_rule_is_exact_for_total_degree_2l_minus_1(dist, level):
    spec, law, var = MARGINALS[dist]
    names = ("a", "b", "c")
    prior = {n: spec for n in names}
    pr = make_prior(prior, names, [NOMINALS[dist]] * 3, rule="sparse", order=level)
    assert pr.rule == "sparse" and pr.order == level and pr.weights.sum() == pytest.approx(1.0, abs=1e-14)
    Z = var(pr.points)
    deg = 2 * level - 1
    for a in itertools.product(range(deg + 1), repeat=3):
        if sum(a) > deg:
            continue
        exact = np.prod([law.moment(k) for k in a])
        got = pr.mean(np.prod(Z ** np.array(a), axis=1))
        assert got == pytest.approx(exact, rel=1e-11, abs=1e-12), (a, got, exact)
    # the guarantee is tight: the pure power of degree 2l is not integrated exactly (every distribution here)
    assert abs(pr.mean(Z[:, 0] ** (2 * level)) - law.moment(2 * level)) > 1e-8


def test_mixed_marginals_and_one_dimension_is_the_gauss_rule():
    prior = {"a": MARGINALS["uniform"][0], "b": MARGINALS["normal"][0], "c": MARGINALS["truncnormal"][0]}
    pr = make_prior(prior, NAMES, NOMINAL, rule="sparse", order=4)
    laws = [MARGINALS[d][1] for d in ("uniform", "normal", "truncnormal")]
    for a in itertools.product(range(8), repeat=3):
        if sum(a) <= 7:
            exact = np.prod([law.moment(k) for law, k in zip(laws, a)])
            assert pr.mean(np.prod(pr.points ** np.array(a), axis=1)) == pytest.approx(exact, rel=1e-11)
    assert np.any(pr.weights < 0)           # the combination technique's weights alternate in sign
    one = make_prior({"a": ("uniform", 1.0, 3.0)}, NAMES, NOMINAL, rule="sparse", order=5)
    gauss = make_prior({"a": ("uniform", 1.0, 3.0)}, NAMES, NOMINAL, rule="gauss", order=5)
    order = np.argsort(one.points[:, 0])
    assert np.allclose(one.points[order], gauss.points, rtol=1e-14)
    assert np.allclose(one.weights[order], gauss.weights, rtol=1e-12)
    assert one.next_rule().order == 6 and one.next_rule().rule == "sparse"
    x, w = gauss_rule_1d("truncnormal", (1.0, 0.5, 0.2, 1.5), 3)
    assert np.all((x > 0.2) & (x < 1.5)) and np.all(w > 0)


def _compartmental_log_det(P):
    """log det M_s of the textbook local D design (t = 0.2288, 1.3886, 18.4168, weights 1/3) of
    eta = theta3 (exp(-theta1 t) - exp(-theta2 t)) at every parameter vector (sigma = 1)."""
    t = np.array([0.2288, 1.3886, 18.4168])[None, :]
    J = np.stack([-P[:, 2:3] * t * np.exp(-P[:, 0:1] * t), P[:, 2:3] * t * np.exp(-P[:, 1:2] * t),
                  np.exp(-P[:, 0:1] * t) - np.exp(-P[:, 1:2] * t)], axis=-1)
    return np.linalg.slogdet(np.einsum("sti,stj->sij", J, J) / 3.0)[1]


@pytest.mark.parametrize("prior", [
    {"theta1": ("uniform", 0.04884, 0.06884), "theta2": ("uniform", 3.298, 5.298)},
    {"theta1": ("uniform", 0.04884, 0.06884), "theta2": ("uniform", 3.298, 5.298), "theta3": ("uniform", 19.8, 23.8)},
    {"theta1": ("lognormal", 0.05884, 0.1), "theta2": ("truncnormal", 4.298, 1.0, 3.0, 6.0),
     "theta3": ("normal", 21.8, 1.0)},
])
def test_expected_log_det_agrees_with_the_tensor_rule_to_the_stated_error(prior):
    names, p0 = ("theta1", "theta2", "theta3"), np.array([0.05884, 4.298, 21.80])
    tensor = make_prior(prior, names, p0, rule="gauss", order=20)
    v_t, e_t = tensor.mean(_compartmental_log_det(tensor.points)), tensor.error(_compartmental_log_det)
    for level in (3, 4):
        sparse = make_prior(prior, names, p0, rule="sparse", order=level)
        v_s, e_s = sparse.mean(_compartmental_log_det(sparse.points)), sparse.error(_compartmental_log_det)
        # the estimate |Q_{l+1} - Q_l| bounds the error of Q_l by twice itself when the next level at least halves
        # the error; that convergence is checked first (the estimate of level l + 1 at most half of level l's)
        assert sparse.next_rule().error(_compartmental_log_det) <= 0.5 * e_s
        assert abs(v_s - v_t) <= 2.0 * e_s + 2.0 * e_t
        assert sparse.n < 100 < tensor.n
    assert e_s < 1e-6


def test_design_verbs_refuse_a_rule_with_negative_weights():
    from models import Model
    import casadi as ca
    from oed.approximate import ApproximateSettings, approximate_design
    from oed.robust_exact import exact_over_prior, select_robust_exact
    m = Model.explicit(["theta1", "theta2", "theta3"], ["t"], ["eta"],
                       h=lambda p, q: p[2] * (ca.exp(-p[0] * q[0]) - ca.exp(-p[1] * q[0])), name="compartmental")
    p0 = np.array([0.05884, 4.298, 21.80])
    prior = {"theta1": ("uniform", 0.04884, 0.06884), "theta2": ("uniform", 3.298, 5.298)}
    with pytest.raises(ValueError, match=r"prior: the sparse rule \(level 3\) has \d+ negative weights, and an "
                                         r"approximate design needs non-negative ones"):
        approximate_design(m, p0, sigma=1.0, bounds=(0.0, 24.0), prior=prior,
                           settings=ApproximateSettings(prior_rule="sparse", prior_order=3))
    sparse = make_prior(prior, m, p0, rule="sparse", order=3)
    with pytest.raises(ValueError, match=r"prior: the sparse rule .* an exact robust design needs non-negative"):
        exact_over_prior(lambda ps: np.eye(3)[None].repeat(4, 0), sparse, p0, 3)
    F = np.tile(np.eye(3), (4, sparse.n, 1, 1))
    with pytest.raises(ValueError, match=r"prior_w: expected \d+ finite non-negative weights"):
        select_robust_exact(F, sparse.weights, 3)
