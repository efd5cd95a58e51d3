"""Sequential designs under a prior (oed.sequential_robust): a point prior gives the local sequential design bit for
bit; a spread prior chooses differently, each step the exact robust optimum (checked by enumeration), its worst-case
efficiency no worse than the local choice's; the second-order (Bard) criterion; bad input."""
import itertools

import casadi as ca
import numpy as np
import pytest

from identification import Measurements, simulate
from models import Model
from oed import information
from oed.sequential import sequential_design

T = [0.1, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0]           # each sensor reads y = q a exp(-b t) at one time t
P_TRUE, P0 = np.array([2.0, 1.3]), np.array([2.0, 0.6])
SPREAD = {"b": ("uniform", 0.2, 2.0)}


@pytest.fixture(scope="module")
def case():
    m = Model.explicit(["a", "b"], ["q"], [f"y{t:g}" for t in T],
                       h=lambda p, q: ca.vertcat(*[q[0] * p[0] * ca.exp(-p[1] * t) for t in T]), name="decay")
    q = np.array([[1.0], [2.0]])
    sig = np.full(len(T), 0.02)
    H = simulate(m, P_TRUE, q)
    rng = np.random.default_rng(0)
    exps = [Measurements(q, H[None] + sig * rng.standard_normal((2,) + H.shape), sig, sensors=m.sensors)
            for _ in range(3)]
    return m, exps


def _same_estimates(a, b):
    for s, t in zip(a.steps, b.steps):
        assert s.design.chosen == t.design.chosen and np.array_equal(s.p_design, t.p_design)
        assert np.array_equal(s.p, t.p) and np.array_equal(s.stderr, t.stderr) and np.array_equal(s.cov, t.cov)
        assert s.ellipsoid_volume == t.ellipsoid_volume


@pytest.mark.parametrize("robust", ["bayes", "maximin"])
@pytest.mark.parametrize("crit, kind, n", [("D", "gauss_newton", 2), ("E", "gauss_newton", 2), ("A", "gauss_newton", 2),
                                           ("D", "second_order", 3), ("E", "second_order", 3)])
def test_point_prior_gives_the_local_sequential_design_bit_for_bit(case, robust, crit, kind, n):
    # (second order with 2 sensors: the local design's first pair does not bound the estimate, so 3 sensors)
    m, exps = case
    local = sequential_design(m, exps, P0, criterion=crit, kind=kind, n_sensors=n)
    point = sequential_design(m, exps, P0, criterion=crit, kind=kind, n_sensors=n, prior=(P0[None, :], [1.0]),
                              robust=robust)
    _same_estimates(point, local)
    assert all(s.robust is not None and s.robust.worst_case_efficiency == pytest.approx(1.0) for s in point.steps)
    assert all(s.robust is None for s in local.steps)
    assert np.array_equal(point.steps[1].robust.prior.points[0], local.steps[0].p)   # the prior moved to the estimate


def _utilities(m, data, P, crit):
    """u_s of every 2-set of sensors at every vector (Gauss-Newton, -Psi(C)), by brute force: (sets, U)."""
    sets = list(itertools.combinations(range(len(T)), 2))
    U = np.empty((len(sets), P.shape[0]))
    for s, ps in enumerate(P):
        F = information(m, ps, data=data).F
        for k, c in enumerate(sets):
            C = np.linalg.inv(F[list(c)].sum(axis=0))
            U[k, s] = {"D": -np.linalg.slogdet(C)[1], "A": -np.trace(C), "E": -np.linalg.eigvalsh(C)[-1]}[crit]
    return sets, U


@pytest.mark.parametrize("crit", ["D", "E"])
def test_spread_prior_differs_and_is_the_enumerated_maximin_optimum(case, crit):
    m, exps = case
    local = sequential_design(m, exps, P0, criterion=crit, n_sensors=2)
    rob = sequential_design(m, exps, P0, criterion=crit, n_sensors=2, prior=SPREAD, robust="maximin")
    assert rob.chosen != local.chosen
    assert rob.steps[0].design.chosen != local.steps[0].design.chosen      # already the first experiment differs
    data = exps[0]
    for k, step in enumerate(rob.steps):
        sets, U = _utilities(m, data, np.asarray(step.robust.prior.points), crit)
        u_star = U.max(axis=0)
        eff = np.exp((U - u_star) / 2) if crit == "D" else u_star / U            # efficiency of every set per vector
        worst = eff.min(axis=1)
        # the robust choice is the enumerated maximin optimum ...
        assert worst[sets.index(step.robust.indices)] == pytest.approx(worst.max(), rel=1e-9)
        assert step.robust.worst_case_efficiency == pytest.approx(worst.max(), rel=1e-9)
        # ... and the local choice at the same design point is no better in the worst case
        loc = sequential_design(m, [exps[k]], step.p_design, initial=data, criterion=crit, n_sensors=2).steps[0]
        assert worst[sets.index(tuple(loc.design.indices))] <= worst.max() + 1e-12
        data = exps[k]
    assert "maximin" in rob.summary()
    d = rob.to_dict()["steps"][0]["robust"]
    assert len(d["prior_weights"]) == 5 and d["proven_optimal"] and "robust" not in local.to_dict()["steps"][0]


def test_bayes_step_maximises_the_expected_utility_and_second_order_runs(case):
    m, exps = case
    rob = sequential_design(m, exps[:1], P0, criterion="D", n_sensors=2, prior=SPREAD)
    step = rob.steps[0]
    sets, U = _utilities(m, exps[0], np.asarray(step.robust.prior.points), "D")
    bayes = U @ np.asarray(step.robust.prior.weights)
    assert bayes[sets.index(step.robust.indices)] == pytest.approx(bayes.max(), rel=1e-12)
    # the second-order (Bard) covariance of the local engine, robust: enumeration over every set
    so = sequential_design(m, exps[:1], P0, criterion="D", kind="second_order", n_sensors=3, prior=SPREAD)
    assert so.steps[0].robust.method == "enumerate" and so.steps[0].design.kind == "second_order"


def test_bad_input_names_the_argument(case):
    m, exps = case
    with pytest.raises(ValueError, match="robust: expected 'bayes' or 'maximin'"):
        sequential_design(m, exps, P0, prior=SPREAD, robust="minimax")
    with pytest.raises(ValueError, match="costs: not used by the robust sequential design"):
        sequential_design(m, exps, P0, prior=SPREAD, costs=np.ones(len(T)), budget=2.0)
    with pytest.raises(ValueError, match="method: the second-order robust step is solved by enumeration"):
        sequential_design(m, exps, P0, kind="second_order", prior=SPREAD, method="bnb")
    with pytest.raises(ValueError, match=r"n_sensors: expected an integer in 1\.\.7"):
        sequential_design(m, exps, P0, prior=SPREAD, n_sensors=9)
    with pytest.raises(ValueError, match=r"prior: the sparse rule .* a robust sequential design needs non-negative"):
        from oed.prior import make_prior
        sequential_design(m, exps, P0, prior=make_prior({"a": ("uniform", 1.5, 2.5), **SPREAD}, m, P0,
                                                        rule="sparse", order=3))
    bounded = m.with_bounds({"b": (0.0, 10.0)})
    with pytest.raises(ValueError, match=r"prior: b = -0\.0967978 \(moved to the estimate before experiment 1\) lies outside"):
        sequential_design(bounded, exps, P0, prior={"b": ("uniform", -0.2, 2.0)})


def test_select_sensors_with_data_a_prior_and_the_second_order_criterion(case):
    """select_sensors(data, prior=, kind="second_order"): the second-order covariance at every vector (residuals of
    the data there), the enumerated optimum; Gauss-Newton for comparison."""
    from oed import select_sensors
    from oed.criteria import batch_criteria
    from oed.prior import make_prior
    m, exps = case
    pr = make_prior(SPREAD, m, P_TRUE, order=3)
    so = select_sensors(m, exps[0], P_TRUE, n_sensors=3, criterion="D", kind="second_order", prior=pr)
    sets = list(itertools.combinations(range(len(T)), 3))
    W = np.zeros((len(sets), len(T)))
    for k, c in enumerate(sets):
        W[k, list(c)] = 1.0
    infos = [information(m, ps, data=exps[0]) for ps in pr.points]
    U = np.stack([-batch_criteria(i.F, i.S, W, "second_order").logdet for i in infos], axis=1)
    assert so.indices == sets[int(np.argmax(U @ pr.weights))] and so.proven_optimal and so.method == "enumerate"
    assert so.value == pytest.approx(float(np.max(U @ pr.weights)), rel=1e-12)
    assert "second_order covariance at every parameter vector" in so.notes[0]
    mm = select_sensors(m, exps[0], P_TRUE, n_sensors=3, criterion="D", kind="second_order", prior=pr,
                        robust="maximin")
    c = (U - U.max(axis=0)) / 2
    assert mm.indices == sets[int(np.argmax(c.min(axis=1)))]
    assert mm.efficiency == pytest.approx(float(np.exp(c.min(axis=1).max())), rel=1e-12)
