r"""Smolyak sparse-grid rules for a prior of independent marginals (``make_prior(..., rule="sparse")``).

With :math:`U^{i}_k` the i-node Gauss rule of marginal k (exact for polynomials of degree 2i - 1 in the
marginal's variable), the level-L Smolyak rule over the d uncertain parameters is the combination

.. math::

    A_L = \sum_{L-d \le |i| - d \le L-1} (-1)^{L-1-(|i|-d)} \binom{d-1}{L-1-(|i|-d)}\,
          U^{i_1}_1\otimes\cdots\otimes U^{i_d}_d,\qquad i_k \ge 1,

(Smolyak 1963; Gerstner & Griebel 1998, the combination technique), with coinciding nodes merged.  With
this linear growth (i nodes at index i) the rule is exact for every polynomial of total degree
:math:`\le 2L - 1` in the marginals' variables (d = 1: the L-node Gauss rule).  The 1-D Gauss rules are
those of the marginals' own weights, so the exactness is against the prior itself:

* uniform: Gauss-Legendre on [lo, hi];
* normal: Gauss-Hermite (probabilists') in (p - mean)/sd;
* lognormal: Gauss-Hermite in (log p - log median)/s (exact for polynomials in log p);
* truncated normal: the Gauss rule of the truncated normal density on [lo, hi] (Golub-Welsch from its
  recurrence coefficients, by the Stieltjes procedure on a 400-node Gauss-Legendre discretisation of the
  density: the moments to rounding).  This differs from the tensor rule's density-weighted Gauss-Legendre
  nodes, which are not a Gauss rule of that density.

The combination coefficients alternate in sign, so **a sparse rule has negative weights** in general
(they still sum to 1; the sum of their absolute values grows with the level, 2l - 1 for two uniform parameters,
and multiplies any noise in the integrand, e.g. a dynamic model's discretisation error of the information).  Its sum is an estimate of the integral like any rule's; the design verbs that
rest on a non-negative measure (concavity of the expected criterion, the equivalence theorem, the
branch-and-bound bounds) refuse such a rule with a clear error (see :func:`check_non_negative`).
"""
from __future__ import annotations

import itertools
from math import comb

import numpy as np
from scipy import special, stats

__all__ = ["sparse_rule", "gauss_rule_1d", "check_non_negative", "TRUNCNORM_NODES"]

#: Gauss-Legendre nodes of the discretised truncated normal density (Stieltjes procedure)
TRUNCNORM_NODES = 400


def _stieltjes(x, w, m):
    """Recurrence coefficients (alpha, beta) of the first m monic orthogonal polynomials of the discrete measure
    sum_j w_j delta(x_j) (w summing to 1)."""
    alpha, beta = np.zeros(m), np.zeros(m)
    p_prev, p = np.zeros_like(x), np.ones_like(x)
    norm_prev = 1.0
    for k in range(m):
        norm = float(np.dot(w, p * p))
        alpha[k] = float(np.dot(w, x * p * p)) / norm
        beta[k] = norm / norm_prev if k else 1.0
        p_prev, p = p, (x - alpha[k]) * p - (beta[k] * p_prev if k else 0.0)
        norm_prev = norm
    return alpha, beta


def _golub_welsch(alpha, beta):
    """Nodes and weights (summing to 1) of the Gauss rule of the recurrence coefficients."""
    J = np.diag(alpha) + np.diag(np.sqrt(beta[1:]), 1) + np.diag(np.sqrt(beta[1:]), -1)
    x, V = np.linalg.eigh(J)
    return x, V[0] ** 2


def gauss_rule_1d(dist: str, a, m: int) -> tuple:
    """(nodes, weights) of the m-node Gauss rule of one marginal's own density (module docstring), weights
    summing to 1."""
    a = np.asarray(a, float)
    if dist in ("normal", "lognormal"):
        x, w = special.roots_hermitenorm(m)
        w = w / w.sum()
        return (a[0] + a[1] * x, w) if dist == "normal" else (a[0] * np.exp(a[1] * x), w)
    if dist == "uniform":
        x, w = special.roots_legendre(m)
        return a[0] + 0.5 * (a[1] - a[0]) * (x + 1.0), w / w.sum()
    mean, sd, lo, hi = a
    x, w = special.roots_legendre(TRUNCNORM_NODES)
    z = (lo + 0.5 * (hi - lo) * (x + 1.0) - mean) / sd          # standardized, so the recursion is well scaled
    w = w * stats.norm.pdf(z)
    alpha, beta = _stieltjes(z, w / w.sum(), m)
    zn, wn = _golub_welsch(alpha, beta)
    return mean + sd * zn, wn / wn.sum()


def sparse_rule(marginals, level: int) -> tuple:
    r"""(nodes (n, d), weights (n,)) of the level-``level`` Smolyak rule of the module docstring over the
    marginals ``((distribution, args), ...)``; coinciding nodes merged (weights added), weights summing to 1,
    possibly negative."""
    d = len(marginals)
    cache = {}

    def rule(k, i):
        if (k, i) not in cache:
            cache[k, i] = gauss_rule_1d(marginals[k][0], marginals[k][1], i)
        return cache[k, i]

    acc = {}
    for q in range(max(level - d, 0), level):
        coef = (-1) ** (level - 1 - q) * comb(d - 1, level - 1 - q)
        for extra in _compositions(q, d):
            rules = [rule(k, 1 + e) for k, e in enumerate(extra)]
            for combo in itertools.product(*[range(len(r[0])) for r in rules]):
                x = tuple(float(rules[k][0][j]) for k, j in enumerate(combo))
                w = coef * float(np.prod([rules[k][1][j] for k, j in enumerate(combo)]))
                key = tuple(_key(v, marginals[k]) for k, v in enumerate(x))
                old = acc.get(key)
                acc[key] = (x, w) if old is None else (old[0], old[1] + w)
    items = [v for v in acc.values() if v[1] != 0.0]
    X = np.array([v[0] for v in items], float).reshape(-1, d)
    w = np.array([v[1] for v in items], float)
    return X, w / w.sum()


def _key(v, marginal):
    """Merge key of a node: its value rounded to 1e-12 of the marginal's scale (0 and -0 and the tiny roots of
    odd Gauss rules at the centre are one node)."""
    dist, a = marginal
    scale = abs(a[1]) if dist in ("normal", "lognormal", "truncnormal") else abs(a[1] - a[0])
    centre = {"uniform": 0.5 * (a[0] + a[1]), "normal": a[0], "lognormal": a[0], "truncnormal": a[0]}[dist]
    if dist == "lognormal":
        return round(float(np.log(v / a[0]) / a[1]), 12)
    return round(float((v - centre) / scale), 12)


def _compositions(q: int, d: int):
    """Every tuple of d non-negative integers summing to q."""
    if d == 1:
        yield (q,)
        return
    for first in range(q + 1):
        for rest in _compositions(q - first, d - 1):
            yield (first,) + rest


def check_non_negative(prior, what: str) -> None:
    """A clear error when the prior's rule has negative weights (a sparse rule) and ``what`` needs a measure."""
    w = np.asarray(prior.weights, float)
    if np.any(w < 0):
        raise ValueError(f"prior: the {prior.rule} rule (level {prior.order}) has {int(np.sum(w < 0))} negative "
                         f"weights, and {what} needs non-negative ones (a concave expected criterion and its "
                         "certificate); use rule='gauss' or 'qmc', or the sparse rule to evaluate (Prior.mean)")
