"""Pieces of the batched branch-and-bound: batched capped-simplex projection, and node
bounds (root of a node given by random include/exclude fixings) never exceed the
enumerated optimum of that node."""
import numpy as np
import pytest

from oed.bnb import BnBSettings, branch_and_bound
from oed.bnb.projection import proj_capped_simplex, proj_capped_simplex_batch
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
        X = proj_capped_simplex_batch(Y, free, r)
        for i in range(B):
            np.testing.assert_allclose(X[i, free[i]], proj_capped_simplex(Y[i, free[i]], r[i]), atol=1e-9)
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


def test_e_refined_bound_below_node_optimum():
    """The re-optimised eigenbasis E bound (``e_bound_refine``) at arbitrary relaxed points of
    random nodes never exceeds lambda_min of any admissible design (rank-one and rank-two F_k)."""
    from itertools import combinations

    from oed.bnb.bounds import e_bound_refine

    rng = np.random.default_rng(7)
    checked = 0
    for t in range(80):
        p = int(rng.integers(2, 6))
        n = int(rng.integers(p + 2, 12))
        m = int(rng.integers(p, n))
        rank = 1 + t % 2
        a = rng.standard_normal((n, p, rank))
        F = np.einsum("kiq,kjq->kij", a, a)
        B = 5
        S = np.full((B, n), -1)
        for b in range(B):
            perm = rng.permutation(n)
            n_in = int(rng.integers(0, m))
            n_out = int(rng.integers(0, n - m))
            S[b, perm[:n_in]] = 1
            S[b, perm[n_in:n_in + n_out]] = 0
        free, on = S == -1, S == 1
        r = m - on.sum(axis=1)
        ok = (r >= 1) & (r < free.sum(axis=1))
        if not ok.any():
            continue
        S, free, on, r = S[ok], free[ok], on[ok], r[ok]
        X = proj_capped_simplex_batch(rng.random(S.shape), free, r) + on
        tE = 10.0 ** rng.uniform(-2, 4, size=S.shape[0])
        s = e_bound_refine(F.reshape(n, -1), X, free, on, r, tE, int(rng.integers(1, 40)))
        for b in range(S.shape[0]):
            fr = np.flatnonzero(free[b])
            best = -np.inf
            for c in combinations(fr, int(r[b])):
                w = on[b].copy()
                w[list(c)] = True
                best = max(best, np.linalg.eigvalsh(np.tensordot(w.astype(float), F, 1))[0])
            assert best <= s[b] + 1e-10 * max(1.0, abs(s[b])), (best, s[b])
            checked += 1
    assert checked > 100
