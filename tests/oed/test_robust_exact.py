"""oed.robust_exact: exact n-run designs under a prior, by complete enumeration and by branch-and-bound."""
import itertools

import casadi as ca
import numpy as np
import pytest

from models import Model
from oed import approximate_design, information, make_prior, select_times
from oed.approximate import ApproximateSettings
from oed.robust_bnb import RobustBnBSettings
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
    (dict(F=np.tile(np.eye(2), (30, 1, 1, 1)), prior_w=[1.0], n=15, max_designs=1000, method="enumerate"),
     r"n: 155117520 sets"),
    (dict(F=np.tile(np.eye(2), (3, 1, 1, 1)), prior_w=[1.0], n=2, method="scip"), r"method: expected one of"),
    (dict(F=np.tile(np.eye(2), (3, 1, 1, 1)), prior_w=[1.0], n=2, time_limit=0), r"time_limit: expected seconds"),
])
def test_bad_input_names_the_argument(kwargs, match):
    with pytest.raises(ValueError, match=match):
        select_robust_exact(**kwargs)


def _random_instance(rng, C, S, p):
    """Rank-1 or rank-2 information per (candidate, sample), the samples a perturbation of a common direction."""
    A = rng.normal(size=(C, 1, 2, p)) + 0.4 * rng.normal(size=(C, S, 2, p))
    A[:, :, 1] *= rng.integers(0, 2, size=(C, 1, 1))
    return np.einsum("csri,csrj->csij", A, A), rng.uniform(0.2, 1.0, S)


@pytest.mark.parametrize("criterion", ["A", "D", "E"])
@pytest.mark.parametrize("robust", ["bayes", "maximin"])
def test_branch_and_bound_agrees_with_enumeration_on_random_instances(criterion, robust):
    rng = np.random.default_rng(31 + ord(criterion) + len(robust))
    for _ in range(6):
        C, S, p = int(rng.integers(7, 12)), int(rng.integers(1, 4)), int(rng.integers(2, 4))
        n = int(rng.integers(p, p + 3))
        F, w = _random_instance(rng, C, S, p)
        u_star = None
        if robust == "maximin":     # each vector's own exact optimum
            u_star = np.array([select_robust_exact(F[:, [s]], [1.0], n, criterion=criterion).value for s in range(S)])
        e = select_robust_exact(F, w, n, criterion=criterion, robust=robust, u_star=u_star, method="enumerate")
        b = select_robust_exact(F, w, n, criterion=criterion, robust=robust, u_star=u_star, method="bnb")
        assert e.method == "enumerate" and b.method == "bnb" and b.nodes >= 1
        assert b.proven_optimal and b.status == "optimal" and b.gap == 0.0
        assert b.value == pytest.approx(e.value, rel=1e-9, abs=1e-9)
        # the reported value is the set's value as enumeration computes it
        again = select_robust_exact(F[list(b.indices)], w, n, criterion=criterion, robust=robust, u_star=u_star)
        assert again.value == b.value


def test_auto_routes_large_sizes_to_branch_and_bound_proven_optimal():
    rng = np.random.default_rng(7)
    F, w = _random_instance(rng, 30, 4, 3)
    r = select_robust_exact(F, w, 8, method="auto", time_limit=60.0)     # 5.9 million sets
    assert r.method == "bnb" and r.proven_optimal and r.gap == 0.0 and r.upper_bound == r.value
    assert r.n_designs < 100_000 and "branch-and-bound" in r.summary()
    small = select_robust_exact(F[:10], w, 4, method="auto")
    assert small.method == "enumerate" and small.n_designs == 210


def test_time_limit_is_honoured_and_reported():
    """A limit below any run time stops either route at its first check: the best set so far, status, the proven
    gap (branch-and-bound) and a warning; a node limit likewise."""
    rng = np.random.default_rng(8)
    F, w = _random_instance(rng, 60, 6, 4)
    for method in ("bnb", "enumerate"):
        with pytest.warns(RuntimeWarning, match="not proven optimal"):
            r = select_robust_exact(F, w, 12, criterion="E", method=method, time_limit=1e-9, max_designs=10 ** 13)
        assert r.status == "time_limit" and not r.proven_optimal and "NOT proven" in r.summary()
        if method == "bnb":
            assert np.isfinite(r.gap) and r.gap > 0 and r.upper_bound >= r.value and r.nodes == 1
        else:
            assert r.gap == np.inf and np.isnan(r.upper_bound) and r.n_designs == 4096
    with pytest.warns(RuntimeWarning, match="node_limit"):
        r = select_robust_exact(F, w, 12, criterion="E", method="bnb", bnb_settings=RobustBnBSettings(node_limit=3))
    assert r.status == "node_limit" and r.gap > 0 and r.upper_bound > r.value


def test_select_times_with_a_prior_and_not_approximate_is_the_exact_robust_design(reactor):
    m, p, times, pr, F = reactor
    prior = {"E1": ("uniform", 55.0, 65.0), "E2": ("uniform", 75.0, 85.0)}
    ref = select_robust_exact(F, pr.weights, 4, names=[f"{t:g}" for t in times])
    for method in ("enumerate", "bnb"):
        r = select_times(m, p, times, Q, SIGMA, n_times=4, prior=make_prior(prior, m, p, order=2), method=method)
        assert r.method == method and r.proven_optimal and r.names == ref.names
        assert r.value == pytest.approx(ref.value, rel=1e-12)
    with pytest.raises(ValueError, match="costs: not used by the exact robust design"):
        select_times(m, p, times, Q, SIGMA, n_times=4, prior=prior, costs=[1.0] * times.size, budget=3.0)
    with pytest.raises(ValueError, match="method: the exact robust design takes"):
        select_times(m, p, times, Q, SIGMA, n_times=4, prior=prior, method="scip")


def test_select_sensors_with_a_prior_is_the_exact_robust_design():
    from identification import information_contributions
    from models.press import press_model
    from oed import select_sensors
    m, p = press_model(extra_sensors=True), np.array([500.0, 500.0])
    prior = {"k5": ("uniform", 400.0, 600.0), "k7": ("uniform", 400.0, 600.0)}
    pr = make_prior(prior, m, p, order=3)
    Q = np.array([[500.0]])
    F = np.stack([information_contributions(m, None, ps, inputs=Q, sigma=0.01)[0] for ps in pr.points], axis=1)
    ref = select_robust_exact(F, pr.weights, 4, criterion="E", names=list(m.sensors), method="enumerate")
    r = select_sensors(m, None, p, inputs=Q, sigma=np.full(m.n_S, 0.01), n_sensors=4, criterion="E",
                       kind="gauss_newton", prior=pr, method="bnb")
    assert r.method == "bnb" and r.proven_optimal and r.names == ref.names
    assert r.value == pytest.approx(ref.value, rel=1e-9)
    with pytest.raises(ValueError, match="exclude: not used by the exact robust design"):
        select_sensors(m, None, p, inputs=Q, sigma=np.full(m.n_S, 0.01), n_sensors=4, prior=pr, exclude=["D_y"],
                       kind="gauss_newton")
    # second order planned without data: S = 0 at every vector, so the Gauss-Newton design, noted
    so = select_sensors(m, None, p, inputs=Q, sigma=np.full(m.n_S, 0.01), n_sensors=4, criterion="E", prior=pr,
                        kind="second_order", method="bnb")
    assert so.names == r.names and so.value == r.value and "S = 0 at every parameter vector" in so.notes[0]
    assert "notes" in so.to_dict() and "notes" not in r.to_dict()
