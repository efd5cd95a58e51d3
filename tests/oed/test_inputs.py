"""select_inputs (issue 13 item 3): exact input designs against brute force, joint with sensors, refinement."""
import itertools

import casadi as ca
import numpy as np
import pytest

from models import Model
from oed import information
from oed.inputs import RefineSettings, refine_inputs, select_inputs


def _exp_model(n_sensors=1):
    """h_1 = b1 (1 - exp(-b2 x)); h_2 = b1 exp(-b2 x) (analytic gradients below)."""
    hs = [lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])), lambda p, q: p[0] * ca.exp(-p[1] * q[0])]
    return Model.explicit(params=["b1", "b2"], inputs=["x"], sensors=["y1", "y2"][:n_sensors],
                          h=lambda p, q: ca.vertcat(*[h(p, q) for h in hs[:n_sensors]]))


def _grad(p, x):
    """Analytic dh/dp of both sensors at x: (2 sensors, 2 params)."""
    e = np.exp(-p[1] * x)
    return np.array([[1 - e, p[0] * x * e], [e, -p[0] * x * e]])


def _value(M, crit):
    ev = np.linalg.eigvalsh(M)
    if ev[0] <= 1e-12 * max(ev[-1], 1e-300):
        return np.inf
    return {"A": np.sum(1 / ev), "D": -np.sum(np.log(ev)), "E": 1 / ev[0]}[crit]


P = np.array([240.0, 5e-3])


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("crit", ["A", "D", "E"])
def test_select_inputs_matches_brute_force(seed, crit):
    rng = np.random.default_rng(seed)
    m = _exp_model(2)
    Q = np.sort(rng.uniform(1, 1000, 12))
    sig = np.array([0.5, 0.2])
    n_series = 3
    Fjk = np.array([[n_series * np.outer(g, g) / s ** 2 for g, s in zip(_grad(P, x), sig)] for x in Q])
    info = information(m, P, axis="input_pairs", candidates=Q, sigma=sig, n_series=n_series)
    np.testing.assert_allclose(info.F, Fjk.reshape(-1, 2, 2), rtol=1e-10)
    assert info.labels[:3] == ("q0:y1", "q0:y2", "q1:y1") and info.S is None
    # every sensor at each chosen input
    best = min(itertools.combinations(range(len(Q)), 3), key=lambda c: _value(Fjk[list(c)].sum((0, 1)), crit))
    r = select_inputs(m, P, candidates=Q, sigma=sig, n_points=3, criterion=crit, n_series=n_series)
    assert r.proven_optimal and r.indices == best
    assert r.value == pytest.approx(_value(Fjk[list(best)].sum((0, 1)), crit), rel=1e-8)
    # only sensor y2, with costs and a budget
    costs = rng.uniform(1, 3, len(Q))
    ok = [c for c in itertools.combinations(range(len(Q)), 3) if costs[list(c)].sum() <= 6.0]
    best = min(ok, key=lambda c: _value(Fjk[list(c), 1].sum(0), crit))
    r = select_inputs(m, P, candidates=Q, sigma=sig, n_points=3, sensors=["y2"], criterion=crit,
                      n_series=n_series, costs=costs, budget=6.0)
    assert r.proven_optimal and r.indices == best
    # joint: input x sensor pairs
    Fp = Fjk.reshape(-1, 2, 2)
    best = min(itertools.combinations(range(len(Fp)), 3), key=lambda c: _value(Fp[list(c)].sum(0), crit))
    r = select_inputs(m, P, candidates=Q, sigma=sig, n_points=3, sensors="joint", criterion=crit,
                      n_series=n_series)
    assert r.proven_optimal and r.pairs == tuple((c // 2, m.sensors[c % 2]) for c in best)
    assert r.axis == r.design.axis == "input_pairs" and r.chosen == tuple(info.labels[c] for c in best)
    assert r.value == pytest.approx(_value(Fp[list(best)].sum(0), crit), rel=1e-8)


def test_branch_and_bound_route_agrees_with_enumeration():
    m = _exp_model(2)
    Q = np.linspace(1, 1000, 30)
    kw = dict(candidates=Q, sigma=[0.5, 0.2], n_points=4, sensors="joint", criterion="D")
    a = select_inputs(m, P, method="enumerate", **kw)
    b = select_inputs(m, P, method="bnb", **kw)
    assert a.proven_optimal and b.proven_optimal and a.pairs == b.pairs and b.method == "bnb"


@pytest.mark.parametrize("crit", ["A", "D", "E"])
def test_refinement_reaches_the_fine_grid_optimum(crit):
    """The refined levels are no worse than the best design on a 10x finer grid (exact enumeration)."""
    m = _exp_model(1)
    coarse = np.linspace(10, 800, 12)
    r = select_inputs(m, P, candidates=coarse, sigma=0.1, n_points=2, criterion=crit, refine=True,
                      refine_settings=RefineSettings(n_starts=3))
    fine = select_inputs(m, P, candidates=np.linspace(10, 800, 320), sigma=0.1, n_points=2, criterion=crit)
    assert r.refined is not None and r.refined.value <= r.value * (1 + 1e-9) + 1e-12
    assert r.refined.value <= fine.value + 1e-6 * abs(fine.value)
    assert np.all(r.refined.inputs >= 10 - 1e-9) and np.all(r.refined.inputs <= 800 + 1e-9)


def test_refinement_of_an_implicit_model_uses_the_implicit_sensitivity():
    """E(y, p, q) = y + p0 y^3 - p1 q = 0, h = y: refinement agrees with a fine-grid exact design."""
    m = Model(params=["a", "b"], inputs=["q"], sensors=["y"], n_y=1,
              E=lambda y, p, q: y[0] + p[0] * y[0] ** 3 - p[1] * q[0], h=lambda y, p, q: y[0])
    p = [0.3, 1.2]
    r = select_inputs(m, p, candidates=np.linspace(0.1, 3, 8), sigma=0.01, n_points=2, criterion="D", refine=True,
                      refine_settings=RefineSettings(n_starts=3))
    fine = select_inputs(m, p, candidates=np.linspace(0.1, 3, 200), sigma=0.01, n_points=2, criterion="D")
    assert r.refined.value <= r.value + 1e-9 and r.refined.value <= fine.value + 1e-6


@pytest.mark.parametrize("kw, match", [
    (dict(candidates=[1.0, np.nan, 3.0]), "candidates: non-finite value at row 1"),
    (dict(candidates=[1.0, 2.0, 1.0]), r"candidates: duplicate rows \[0, 2\]"),
    (dict(n_points=4), "n_points: expected an integer in 1..3"),
    (dict(n_points=1), "n_points: no admissible design of 1 input rows identifies the parameters"),
    (dict(costs=[5.0, 5.0, 5.0], budget=1.0), "budget: 1 is below the cheapest"),
    (dict(p=[240.0, -1.0]), r"p: nominal parameters \['b2'\] lie outside their bounds"),
    (dict(sigma=[-1.0]), "sigma: expected 1 positive"),
    (dict(sensors=["zz"]), "sensors: expected None, 'joint' or names"),
])
def test_bad_input_names_the_argument(kw, match):
    m = _exp_model(1).with_bounds({"b2": (0.0, 1.0)})
    args = dict(p=P, candidates=[1.0, 2.0, 3.0], sigma=[0.1], n_points=2)
    args.update(kw)
    p = args.pop("p")
    with pytest.raises(ValueError, match=match):
        select_inputs(m, p, **args)
