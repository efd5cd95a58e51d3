"""Pieces of the batched branch-and-bound: batched capped-simplex projection, and node
bounds (root of a node given by random include/exclude fixings) never exceed the
enumerated optimum of that node."""
import numpy as np
import pytest

from oed.bnb import BnBSettings, _proj_capped_simplex, _proj_capped_simplex_batch, branch_and_bound
from oed.constraints import make_constraints
from oed.criteria import validate_information
from oed.enumeration import enumerate_designs


def test_batched_projection_matches_scalar_projection():
    rng = np.random.default_rng(11)
    for t in range(300):
        B, n = 4, int(rng.integers(2, 25))
        Y = rng.standard_normal((B, n)) * 10 ** rng.uniform(-3, 3)
        if t % 3 == 0:
            Y = np.round(Y)  # ties between breakpoints
        free = rng.random((B, n)) < 0.7
        free[:, :2] = True
        r = np.array([rng.integers(1, k) for k in free.sum(axis=1)])
        X = _proj_capped_simplex_batch(Y, free, r)
        for i in range(B):
            np.testing.assert_allclose(X[i, free[i]], _proj_capped_simplex(Y[i, free[i]], r[i]), atol=1e-9)
            assert np.all(X[i, ~free[i]] == 0)


@pytest.mark.parametrize("crit", "ADE")
def test_node_bounds_below_node_optimum(crit):
    """60 random nodes per criterion (rank-one F, p in 3..6, random fixings)."""
    rng = np.random.default_rng({"A": 1, "D": 2, "E": 3}[crit])
    for _ in range(60):
        p = int(rng.integers(3, 7))
        n = int(rng.integers(p + 3, 15))
        m = int(rng.integers(p, min(n - 1, p + 4) + 1))
        a = rng.standard_normal((n, p))
        F, _ = validate_information(np.einsum("ki,kj->kij", a, a))
        perm = rng.permutation(n)
        n_in = int(rng.integers(0, 3))
        n_out = int(rng.integers(0, n - m))
        cons = make_constraints(n, p, n_sensors=m, include=tuple(int(k) for k in perm[:n_in]),
                                exclude=tuple(int(k) for k in perm[n_in:n_in + n_out]))
        e = enumerate_designs(F, None, cons, crit)
        if not np.isfinite(e.value):
            continue
        b = branch_and_bound(F, cons, crit, settings=BnBSettings(node_limit=1, root_iters=int(rng.integers(3, 60))))
        tol = 1e-8 if crit == "D" else 1e-8 * abs(e.value)
        assert b.root_bound <= e.value + tol, (b.root_bound, e.value)
        assert b.lower_bound <= e.value + tol
        assert b.value >= e.value - tol
