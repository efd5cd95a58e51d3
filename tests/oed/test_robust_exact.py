"""oed.robust_exact: exact n-run designs under a prior, by complete enumeration."""
import itertools

import casadi as ca
import numpy as np
import pytest

from models import Model
from oed import approximate_design, information, make_prior, select_times
from oed.approximate import ApproximateSettings
from oed.robust_exact import select_robust_exact

Q = np.array([[1.0, 330.0], [2.0, 350.0], [2.0, 370.0]])
SIGMA = np.array([0.01, 0.008])
P0 = np.array([0.05884, 4.298, 21.80])


@pytest.fixture(scope="module")
def reactor():
    from mudoe.example_reactor import P_TRUE, TIMES, build
    m = build()
    pr = make_prior({"E1": ("uniform", 55.0, 65.0), "E2": ("uniform", 75.0, 85.0)}, m, P_TRUE, order=2)
    F = np.stack([information(m, ps, axis="times", times=TIMES, inputs=Q, sigma=SIGMA).F for ps in pr.points], axis=1)
    return m, P_TRUE, TIMES, pr, F


def test_one_vector_reproduces_the_existing_exact_engine(reactor):
    m, p, times, _, _ = reactor
    F1 = information(m, p, axis="times", times=times, inputs=Q, sigma=SIGMA).F[:, None]
    names = [f"{t:g}" for t in times]
    r = select_robust_exact(F1, [1.0], 4, names=names)
    assert r.proven_optimal and r.n_designs == 210
    assert sorted(r.names) == sorted(select_times(m, p, times, Q, SIGMA, n_times=4).chosen)


def test_bayesian_exact_sampling_times_against_brute_force_and_the_approximate_design(reactor):
    m, p, times, pr, F = reactor
    ap = approximate_design(m, p, sigma=SIGMA, bounds=(times.min(), times.max()), inputs=Q, prior=pr,
                            settings=ApproximateSettings(grid=19, rounds=4))
    r = select_robust_exact(F, pr.weights, 4, approximate=ap)
    best = max(itertools.combinations(range(times.size), 4),
               key=lambda c: sum(w * np.linalg.slogdet(F[list(c), s].sum(axis=0) / 4)[1]
                                 for s, w in enumerate(pr.weights)))
    assert r.indices == best and r.proven_optimal
    assert r.value == pytest.approx(sum(w * np.linalg.slogdet(F[list(best), s].sum(0) / 4)[1]
                                        for s, w in enumerate(pr.weights)), rel=1e-12)
    # an n-run design on candidates inside the range cannot beat the approximate optimum (up to its gap)
    assert 0.5 < r.efficiency <= np.exp(max(ap.gap, 0.0) / 4) + 1e-12


def test_maximin_exact_design_against_brute_force():
    m = Model.explicit(["theta1", "theta2", "theta3"], ["t"], ["eta"],
                       h=lambda p, q: p[2] * (ca.exp(-p[0] * q[0]) - ca.exp(-p[1] * q[0])))
    pr = make_prior({"theta1": ("uniform", 0.04884, 0.06884), "theta2": ("uniform", 2.298, 6.298)}, m, P0,
                    rule="grid", order=2)
    T = np.r_[0.25, np.arange(1.0, 25.0, 1.0)]
    F = np.stack([information(m, ps, axis="inputs", candidates=T[:, None], sigma=1.0).F for ps in pr.points], axis=1)
    u_star = np.array([approximate_design(m, ps, sigma=1.0, bounds=(0.0, 24.0)).value for ps in pr.points])
    r = select_robust_exact(F, pr.weights, 3, robust="maximin", u_star=u_star)
    effs = {c: min(np.exp((np.linalg.slogdet(F[list(c), s].sum(0) / 3)[1] - u_star[s]) / 3) for s in range(pr.n))
            for c in itertools.combinations(range(T.size), 3)}
    best = max(effs, key=effs.get)
    assert r.indices == best and r.efficiency == pytest.approx(effs[best], rel=1e-10)
    assert r.efficiency <= 1.0 + 1e-9


@pytest.mark.parametrize("kwargs, match", [
    (dict(F=np.ones((3, 2, 2)), prior_w=[1.0], n=1), r"F: expected shape"),
    (dict(F=np.tile(np.eye(2), (3, 2, 1, 1)), prior_w=[1.0, -1.0], n=1), r"prior_w: expected 2 finite non-negative"),
    (dict(F=np.tile(np.eye(2), (3, 1, 1, 1)), prior_w=[1.0], n=4), r"n: expected an integer in 1..3"),
    (dict(F=np.tile(np.eye(2), (3, 1, 1, 1)), prior_w=[1.0], n=2, robust="worst"), r"robust: expected one of"),
    (dict(F=np.tile(np.eye(2), (3, 1, 1, 1)), prior_w=[1.0], n=2, robust="maximin"), r"u_star: the maximin"),
    (dict(F=np.tile(np.eye(2), (30, 1, 1, 1)), prior_w=[1.0], n=15, max_designs=1000), r"n: 155117520 sets"),
])
def test_bad_input_names_the_argument(kwargs, match):
    with pytest.raises(ValueError, match=match):
        select_robust_exact(**kwargs)
