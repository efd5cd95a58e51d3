"""The second-order node bound (oed.bnb.second_order) never exceeds the best completion of the node,
found by enumerating every design of the node (seeded small instances, random nodes)."""
from itertools import combinations

import numpy as np
import pytest

from oed.bnb.second_order import perturbation_radii, second_order_node_bound
from oed.criteria import Criterion, batch_criteria, validate_information


def _instance(rng, n, p, scale):
    a = rng.standard_normal((n, int(rng.integers(1, 3)), p))
    F = np.einsum("kri,krj->kij", a, a)
    b = rng.standard_normal((n, p, p))
    S = b + b.transpose(0, 2, 1)
    S *= scale * (np.linalg.norm(F, axis=(1, 2)) / np.linalg.norm(S, axis=(1, 2)))[:, None, None]
    return validate_information(F, S)


@pytest.mark.parametrize("crit", "ADE")
def test_node_bound_never_exceeds_the_node_optimum(crit):
    c = Criterion.parse(crit)
    rng = np.random.default_rng(ord(crit))
    checked = finite = 0
    for _ in range(150):
        p = int(rng.integers(2, 4))
        n = int(rng.integers(p + 2, 10))
        F, S = _instance(rng, n, p, float(rng.choice([0.02, 0.2, 1.0, 3.0])))
        perm = rng.permutation(n)
        d = int(rng.integers(1, min(n - 1, 5)))
        fixed_in, rest = perm[:d], perm[d:]
        free = rest[: int(rng.integers(1, rest.size + 1))]
        r = int(rng.integers(0, min(free.size, 3) + 1))
        W = np.zeros((0, n), dtype=bool)
        for T in combinations(free, r):
            w = np.zeros(n, dtype=bool)
            w[fixed_in] = True
            w[list(T)] = True
            W = np.vstack([W, w])
        so = batch_criteria(F, S, W, "second_order", validated=True).value(c)
        gn = batch_criteria(F, S, W, "gauss_newton", validated=True).value(c)
        if not np.isfinite(so.min()):
            continue
        b = second_order_node_bound(F, S, fixed_in, free, r, crit, gn_bound=float(gn.min()))
        checked += 1
        finite += np.isfinite(b) and b > 0 if crit != "D" else np.isfinite(b)
        assert b <= so.min() + 1e-9 * max(abs(so.min()), 1.0), (b, so.min())
    assert checked >= 60 and finite >= 20          # the bound is exercised, not only its trivial value


def test_radii_bound_the_perturbation_of_every_design():
    rng = np.random.default_rng(5)
    for _ in range(100):
        p = int(rng.integers(2, 5))
        n = int(rng.integers(p + 2, 9))
        F, S = _instance(rng, n, p, float(rng.choice([0.05, 0.5, 2.0])))
        fixed_in = rng.permutation(n)[:p]
        free = np.setdiff1d(np.arange(n), fixed_in)
        r = int(rng.integers(0, 3))
        kappa, tau = perturbation_radii(F, S, fixed_in, free, r)
        if not np.isfinite(kappa):
            continue
        for T in combinations(free, r):
            w = np.r_[fixed_in, list(T)].astype(int)
            G, Sw = F[w].sum(axis=0), S[w].sum(axis=0)
            mu = np.abs(np.linalg.eigvals(np.linalg.solve(G, Sw)).real)
            assert mu.max() <= kappa * (1 + 1e-9) and mu.sum() <= tau * (1 + 1e-9) + 1e-12


def test_no_finite_bound_at_the_root():
    rng = np.random.default_rng(0)
    F, S = _instance(rng, 6, 2, 0.1)
    assert second_order_node_bound(F, S, [], np.arange(6), 3, "D", gn_bound=0.0) == -np.inf
    assert second_order_node_bound(F, S, [], np.arange(6), 3, "A", gn_bound=1.0) == 0.0
