"""oed.select_inputs with a prior and approximate=False: the exact robust choice of n_points candidate rows."""
import itertools

import casadi as ca
import numpy as np
import pytest

from models import Model
from oed import information, make_prior, select_inputs
from oed.robust_exact import RobustExactDesign

T = np.array([0.1, 0.3, 0.6, 1.0, 1.5, 2.2, 3.0, 4.5])     # 8 candidate inputs
P0 = np.array([2.0, 0.8])                                  # a, b of y = a exp(-b t)
PRIOR = {"b": ("uniform", 0.3, 2.5)}                        # 5 Gauss points (order 5)


@pytest.fixture(scope="module")
def expo():
    return Model.explicit(["a", "b"], ["t"], ["y"], h=lambda p, q: p[0] * ca.exp(-p[1] * q[0]))


def _F(p):
    """One run's information at every candidate from the closed-form gradient (sigma = 0.1)."""
    g = np.stack([np.exp(-p[1] * T), -p[0] * T * np.exp(-p[1] * T)], axis=1)
    return g[:, :, None] * g[:, None, :] / 0.1 ** 2


def _u(F, c):
    return np.linalg.slogdet(F[list(c)].sum(axis=0) / len(c))[1]


def test_bayes_exact_inputs_against_brute_force(expo):
    pr = make_prior(PRIOR, expo, P0)
    assert pr.n == 5
    Fs = [_F(ps) for ps in pr.points]
    sets = list(itertools.combinations(range(T.size), 3))
    bayes = {c: sum(w * _u(F, c) for w, F in zip(pr.weights, Fs)) for c in sets}
    best = max(bayes, key=bayes.get)
    r = select_inputs(expo, P0, candidates=T[:, None], sigma=0.1, n_points=3, prior=PRIOR)
    assert isinstance(r, RobustExactDesign) and r.proven_optimal and r.method == "enumerate"
    assert r.indices == best and r.names == tuple(f"q{j}" for j in best)
    assert r.value == pytest.approx(bayes[best], rel=1e-10)
    local = max(sets, key=lambda c: _u(_F(P0), c))
    assert r.local_indices == local != best           # this prior moves the design off the local one
    eff = [np.exp((_u(F, local) - _u(F, best)) / 2) for F in Fs]
    np.testing.assert_allclose(r.local_efficiencies, eff, rtol=1e-10)
    assert "local design" in r.summary() and r.to_dict()["local_indices"] == list(local)
    # the branch-and-bound route proves the same set
    b = select_inputs(expo, P0, candidates=T[:, None], sigma=0.1, n_points=3, prior=PRIOR, method="bnb")
    assert b.method == "bnb" and b.proven_optimal and b.indices == best


def test_maximin_exact_inputs_against_brute_force(expo):
    pr = make_prior(PRIOR, expo, P0)
    Fs = [_F(ps) for ps in pr.points]
    sets = list(itertools.combinations(range(T.size), 3))
    u_star = [max(_u(F, c) for c in sets) for F in Fs]
    worst = {c: min(np.exp((_u(F, c) - us) / 2) for F, us in zip(Fs, u_star)) for c in sets}
    best = max(worst, key=worst.get)
    r = select_inputs(expo, P0, candidates=T[:, None], sigma=0.1, n_points=3, prior=PRIOR, robust="maximin")
    assert r.robust == "maximin" and r.proven_optimal and r.indices == best
    assert r.efficiency == pytest.approx(worst[best], rel=1e-10) and r.efficiency <= 1.0 + 1e-12


def test_joint_input_sensor_pairs_against_brute_force():
    m = Model.explicit(["a", "b"], ["t"], ["y", "z"],
                       h=lambda p, q: ca.vertcat(p[0] * ca.exp(-p[1] * q[0]), p[0] * q[0] / (1 + p[1] * q[0])))
    pr = make_prior(PRIOR, m, P0)
    sig = [0.1, 0.2]
    r = select_inputs(m, P0, candidates=T[:6, None], sigma=sig, n_points=3, prior=pr, sensors="joint")
    Fs = [information(m, ps, axis="input_pairs", candidates=T[:6, None], sigma=sig).F for ps in pr.points]
    bayes = {c: sum(w * _u(F, c) for w, F in zip(pr.weights, Fs)) for c in itertools.combinations(range(12), 3)}
    best = max(bayes, key=bayes.get)
    assert r.proven_optimal and r.indices == best
    assert r.names == tuple(f"q{c // 2}:{'yz'[c % 2]}" for c in best)


def test_dynamic_reactor_experiments_against_brute_force():
    from mudoe.example_reactor import P_TRUE, TIMES, build
    m = build()
    Q = np.array([[1.0, 330.0], [2.0, 350.0], [2.0, 370.0], [1.5, 340.0]])
    sigma = np.array([0.01, 0.008])
    P = np.array([P_TRUE, P_TRUE * [1, 0.95, 1, 1], P_TRUE * [1, 1.05, 1, 1.05]])
    w = np.array([0.5, 0.25, 0.25])
    r = select_inputs(m, P_TRUE, candidates=Q, sigma=sigma, n_points=2, times=TIMES, prior=(P, w))
    Fs = [information(m, ps, axis="inputs", candidates=Q, times=TIMES, sigma=sigma).F for ps in P]
    bayes = {c: sum(wi * _u(F, c) for wi, F in zip(w, Fs)) for c in itertools.combinations(range(4), 2)}
    best = max(bayes, key=bayes.get)
    assert r.proven_optimal and r.indices == best and r.value == pytest.approx(bayes[best], rel=1e-10)
    assert len(r.local_efficiencies) == 3 and all(0 < e <= 1 + 1e-12 for e in r.local_efficiencies)


@pytest.mark.parametrize("kwargs, match", [
    (dict(prior={"zz": ("uniform", 0.3, 2.5)}), r"prior: 'zz' is not a parameter of the model"),
    (dict(prior=PRIOR, refine=True, sensors="joint"), r"refine: the continuous refinement is for input designs"),
    (dict(prior=PRIOR, bounds=(0.1, 4.5)), r"bounds: used only by the refinement of the exact robust design"),
    (dict(prior=PRIOR, costs=np.ones(8), budget=3.0), r"costs: not used by the exact robust design"),
    (dict(prior=PRIOR, kind="third_order"), r"kind: unknown covariance kind 'third_order'"),
    (dict(prior=PRIOR, method="scip"), r"method: the exact robust design takes"),
    (dict(prior=PRIOR, n_points=9), r"n_points: expected an integer in 1..8"),
    (dict(prior=PRIOR, n_points=None), r"n_points: the exact robust design needs"),
])
def test_bad_input_names_the_argument(expo, kwargs, match):
    args = dict(candidates=T[:, None], sigma=0.1, n_points=3) | kwargs
    with pytest.raises(ValueError, match=match):
        select_inputs(expo, P0, **args)


def test_second_order_planned_is_the_gauss_newton_design_noted(expo):
    gn = select_inputs(expo, P0, candidates=T[:, None], sigma=0.1, n_points=3, prior=PRIOR)
    so = select_inputs(expo, P0, candidates=T[:, None], sigma=0.1, n_points=3, prior=PRIOR, kind="second_order")
    assert so.indices == gn.indices and so.value == gn.value and not gn.notes
    assert "S = 0 at every parameter vector" in so.notes[0] and "note: kind='second_order'" in so.summary()
