"""Seeded random OED instances shared by the oed tests."""
from math import comb

import numpy as np

#: A time limit (s) that never decides a test's result (issue 27): the tests' solves are bounded by their node,
#: round or iteration limits and by the size of the instances, not by the speed of a (possibly loaded) machine.
UNTIMED = 1e9


def rank_one(rng, n, p):
    a = rng.standard_normal((n, p))
    return np.einsum("ki,kj->kij", a, a)


def low_rank(rng, n, p, r=2):
    a = rng.standard_normal((n, r, p))
    return np.einsum("kri,krj->kij", a, a)


def second_order_terms(rng, F, scale=0.1):
    """Symmetric indefinite S_k scaled to a fraction of ||F_k||."""
    n, p, _ = F.shape
    b = rng.standard_normal((n, p, p))
    S = b + b.transpose(0, 2, 1)
    nf = np.linalg.norm(F, axis=(1, 2))[:, None, None]
    return scale * S * nf / np.linalg.norm(S, axis=(1, 2))[:, None, None]


def random_instance(seed, max_n=20, max_designs=20_000):
    """(F, n, p, m, criterion) with at most ``max_designs`` designs of size m."""
    rng = np.random.default_rng(seed)
    p = int(rng.integers(2, 7))
    n = int(rng.integers(p + 1, max_n + 1))
    while comb(n, p) > max_designs:  # even m = n_p would be too many designs
        n -= 1
    hi = min(n, p + 5)
    while True:
        m = int(rng.integers(p, hi + 1))
        if comb(n, m) <= max_designs:
            break
        hi = max(p, hi - 1)
    F = rank_one(rng, n, p) if seed % 3 else low_rank(rng, n, p, r=int(rng.integers(1, 3)))
    crit = "ADE"[seed % 3]
    return F, n, p, m, crit, rng
