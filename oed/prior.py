r"""Parameter uncertainty as a design input: a prior and its quadrature.

A robust criterion averages or minimises over the parameters, :math:`\int \Psi(M(\xi, p))\,\pi(dp)`
or :math:`\min_{p\in\mathcal P}`; mudoe replaces the prior :math:`\pi` by a finite rule

.. math::  \int f(p)\,\pi(dp) \approx \sum_{s=1}^{n} w_s f(P_s),\qquad w_s \ge 0,\ \sum_s w_s = 1.

A prior is given either as explicit points ``(P, w)`` (P of shape (n, n_p), w of n non-negative
finite weights, normalised to sum 1) or per parameter, ``{"k1": ("uniform", lo, hi), ...}``;
parameters without an entry stay at their nominal value.  Distributions and their arguments:

* ``("uniform", lo, hi)``: Gauss-Legendre nodes on [lo, hi];
* ``("normal", mean, sd)``: Gauss-Hermite (probabilists') nodes mean + sd x;
* ``("lognormal", median, s)``: log p ~ N(log median, s^2), Gauss-Hermite nodes in log p;
* ``("truncnormal", mean, sd, lo, hi)``: Gauss-Legendre nodes on [lo, hi] weighted by the normal
  density, renormalised.

The rule is the tensor product of ``order`` nodes per uncertain parameter (``rule="gauss"``) or
``order`` scrambled Sobol points mapped through the inverse distribution functions
(``rule="qmc"``, equal weights, seeded), or, for the maximin criterion over a box, the tensor grid of
``order`` equispaced values from the lower to the upper bound (``rule="grid"``, bounded distributions
only, equal weights).  The quadrature error of a quantity f is estimated by
:meth:`Prior.error` as :math:`|Q_{m+1} f - Q_m f|` (the tensor rule of the next order; for QMC an
independent scrambled set of the same size; for a sparse rule the level l + 1): an estimate, not a bound.
``rule="sparse"``: the level-``order`` Smolyak sparse grid of the marginals' own Gauss rules
(:mod:`oed.prior_sparse`), exact for polynomials of total degree 2 order - 1; its weights sum to 1 but some
are negative, so it serves to evaluate expectations (:meth:`Prior.mean`, :meth:`Prior.error`); the design
verbs refuse it (their certificates need a non-negative measure).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import special, stats
from scipy.stats import qmc

__all__ = ["Prior", "make_prior", "readonly", "DISTRIBUTIONS"]

#: distribution name -> number of arguments after the name
DISTRIBUTIONS = {"uniform": 2, "normal": 2, "lognormal": 2, "truncnormal": 4}
RULES = ("gauss", "qmc", "grid", "sparse")


def readonly(a) -> np.ndarray:
    """A float copy of ``a`` that cannot be written (the arrays of frozen results)."""
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class Prior:
    r"""A finite rule :math:`\sum_s w_s f(P_s)` for the prior over the parameters.

    Attributes
    ----------
    points : ndarray, shape (n, n_p)
        Parameter vectors (read-only); parameters without a distribution at their nominal value.
    weights : ndarray, shape (n,)
        Weights summing to 1 (read-only); non-negative except for a sparse rule (:mod:`oed.prior_sparse`).
    names : tuple of str
        Parameter names (the model's order).
    rule : str
        ``"points"`` (given), ``"gauss"`` (tensor Gauss), ``"qmc"`` (scrambled Sobol), ``"grid"`` or ``"sparse"``
        (Smolyak).
    order : int
        Nodes per uncertain parameter (gauss, grid), number of points (qmc) or level (sparse); 0 for given points.
    marginals : tuple
        ``(name, distribution, args)`` of every uncertain parameter (empty for given points).
    nominal : ndarray, shape (n_p,)
    seed : int
    """

    points: np.ndarray
    weights: np.ndarray
    names: tuple
    rule: str
    order: int = 0
    marginals: tuple = ()
    nominal: np.ndarray = field(default_factory=lambda: np.zeros(0))
    seed: int = 0

    @property
    def n(self) -> int:
        """Number of parameter vectors of the rule."""
        return int(self.weights.size)

    def mean(self, values) -> float:
        r""":math:`\sum_s w_s f_s` of the values ``f_s`` at the rule's points."""
        return float(np.dot(self.weights, np.asarray(values, float)))

    def next_rule(self) -> "Prior | None":
        """The rule of the next order (gauss, grid: order + 1 nodes per parameter; sparse: level + 1; qmc: an
        independent scrambled set of the same size, seed + 1); None for given points (no error estimate)."""
        if self.rule == "points":
            return None
        spec = {name: (dist,) + tuple(args) for name, dist, args in self.marginals}
        if self.rule in ("gauss", "grid", "sparse"):
            return _build(self.names, self.nominal, spec, self.rule, self.order + 1, self.seed)
        return _build(self.names, self.nominal, spec, "qmc", self.order, self.seed + 1)

    def error(self, f) -> float:
        r"""Estimated quadrature error :math:`|Q' f - Q f|` of ``f`` (a callable of the points (n, n_p)
        returning n values), Q' the rule of :meth:`next_rule`; nan for given points."""
        other = self.next_rule()
        if other is None:
            return float("nan")
        return abs(other.mean(f(other.points)) - self.mean(f(self.points)))

    def summary(self) -> str:
        """One line per uncertain parameter and the rule."""
        head = f"prior: {self.n} points ({self.rule}" + (f", order {self.order})" if self.order else ")")
        return "\n".join([head] + [f"  {n}: {d}{tuple(float(a) for a in args)}" for n, d, args in self.marginals])


def _names_of(model_or_names) -> tuple:
    names = getattr(model_or_names, "param_names", model_or_names)
    return tuple(str(n) for n in names)


def make_prior(prior, model_or_names, p, *, rule: str = "gauss", order: int = 5, seed: int = 0) -> Prior:
    r"""The finite rule :math:`(P_s, w_s)` of a prior (see the module docstring).

    Parameters
    ----------
    prior : (array_like (n, n_p), array_like (n,)) or dict or Prior
        Given points and weights, or per parameter name ``(distribution, *args)``.
    model_or_names : models.Model or sequence of str
        The model (its ``param_names``) or the parameter names.
    p : array_like, shape (n_p,)
        Nominal parameters: the value of parameters without a distribution; it must lie within the
        support of every bounded distribution.
    rule : {"gauss", "qmc", "grid", "sparse"}
    order : int
        Gauss nodes per uncertain parameter, QMC points (a power of 2 is best), or the sparse grid's level.
    seed : int
        Seed of the scrambled Sobol points.

    Raises
    ------
    ValueError
        Negative or non-finite weights, an unknown distribution or parameter, bounds that exclude the
        nominal value, bad shapes; the message names the key or argument.
    """
    names = _names_of(model_or_names)
    p = np.asarray(p, float).ravel()
    if p.shape != (len(names),) or not np.all(np.isfinite(p)):
        raise ValueError(f"p: expected {len(names)} finite nominal values ({', '.join(names)}), got {p}")
    if isinstance(prior, Prior):
        if prior.names != names:
            raise ValueError(f"prior: its parameters {prior.names} are not the model's {names}")
        return prior
    if isinstance(prior, dict):
        if rule not in RULES:
            raise ValueError(f"rule: expected one of {RULES}, got {rule!r}")
        if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order < 1:
            raise ValueError(f"order: expected an integer >= 1, got {order!r}")
        spec = _check_spec(prior, names, p)
        unbounded = [k for k, v in spec.items() if v[0] in ("normal", "lognormal")]
        if rule == "grid" and unbounded:
            raise ValueError(f"prior[{unbounded[0]!r}]: rule='grid' needs bounded distributions (uniform, "
                             "truncnormal); use rule='gauss' or 'qmc'")
        return _build(names, p, spec, rule, int(order), int(seed))
    if isinstance(prior, (tuple, list)) and len(prior) == 2:
        return _given(names, p, *prior)
    raise ValueError("prior: expected (P, w) with P of shape (n, n_p) and weights w, or a dict "
                     "{parameter: (distribution, *args)}, got " + type(prior).__name__)


def _given(names, p, P, w) -> Prior:
    P = np.asarray(P, float)
    w = np.asarray(w, float).ravel()
    if P.ndim != 2 or P.shape[1] != len(names) or P.shape[0] == 0:
        raise ValueError(f"prior: points P must have shape (n, {len(names)}) (one row per parameter vector), "
                         f"got {P.shape}")
    if not np.all(np.isfinite(P)):
        raise ValueError("prior: points P must be finite")
    if w.shape != (P.shape[0],):
        raise ValueError(f"prior: weights w must have one entry per point ({P.shape[0]}), got {w.shape}")
    if not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        bad = int(np.flatnonzero(~np.isfinite(w) | (w < 0))[0]) if np.any(~np.isfinite(w) | (w < 0)) else 0
        raise ValueError(f"prior: weights w must be finite and non-negative with a positive sum; entry {bad} is "
                         f"{w[bad]!r}")
    return Prior(points=readonly(P), weights=readonly(w / w.sum()), names=names, rule="points",
                 nominal=readonly(p))


def _check_spec(spec: dict, names, p) -> dict:
    out = {}
    for key, val in spec.items():
        if key not in names:
            raise ValueError(f"prior: {key!r} is not a parameter of the model ({', '.join(names)})")
        if not isinstance(val, (tuple, list)) or not val or not isinstance(val[0], str):
            raise ValueError(f"prior[{key!r}]: expected (distribution, *args), got {val!r}")
        dist, args = val[0].strip().lower(), tuple(val[1:])
        if dist not in DISTRIBUTIONS:
            raise ValueError(f"prior[{key!r}]: unknown distribution {val[0]!r}; expected one of "
                             f"{', '.join(DISTRIBUTIONS)}")
        if len(args) != DISTRIBUTIONS[dist]:
            raise ValueError(f"prior[{key!r}]: {dist} takes {DISTRIBUTIONS[dist]} arguments, got {len(args)}")
        try:
            a = np.asarray(args, float)
        except (TypeError, ValueError):
            raise ValueError(f"prior[{key!r}]: arguments must be numbers, got {args!r}") from None
        if not np.all(np.isfinite(a)):
            raise ValueError(f"prior[{key!r}]: arguments must be finite, got {args!r}")
        _check_args(key, dist, a, p[names.index(key)])
        out[key] = (dist,) + tuple(float(x) for x in a)
    return out


def _check_args(key, dist, a, nominal):
    if dist == "uniform" or dist == "truncnormal":
        lo, hi = (a[0], a[1]) if dist == "uniform" else (a[2], a[3])
        if not lo < hi:
            raise ValueError(f"prior[{key!r}]: expected lower < upper, got {lo:g}, {hi:g}")
        if not lo <= nominal <= hi:
            raise ValueError(f"prior[{key!r}]: the bounds [{lo:g}, {hi:g}] exclude the nominal value {nominal:g}")
    if dist in ("normal", "truncnormal") and not a[1] > 0:
        raise ValueError(f"prior[{key!r}]: the standard deviation must be positive, got {a[1]:g}")
    if dist == "lognormal" and not (a[0] > 0 and a[1] > 0):
        raise ValueError(f"prior[{key!r}]: lognormal takes a positive median and log-sd, got {a[0]:g}, {a[1]:g}")


def _gauss_1d(dist, a, m, grid=False):
    """(nodes, weights) of the m-node rule of one marginal (``grid``: m equispaced values, equal weights)."""
    if grid:
        lo, hi = (a[0], a[1]) if dist == "uniform" else (a[2], a[3])
        return np.linspace(lo, hi, m) if m > 1 else np.array([0.5 * (lo + hi)]), np.full(m, 1.0 / m)
    if dist in ("normal", "lognormal"):
        x, w = special.roots_hermitenorm(m)
        w = w / np.sqrt(2.0 * np.pi)
        return (a[0] + a[1] * x, w) if dist == "normal" else (a[0] * np.exp(a[1] * x), w)
    lo, hi = (a[0], a[1]) if dist == "uniform" else (a[2], a[3])
    x, w = special.roots_legendre(m)
    nodes = lo + 0.5 * (hi - lo) * (x + 1.0)
    if dist == "truncnormal":
        w = w * stats.norm.pdf(nodes, a[0], a[1])
    return nodes, w / w.sum()


def _ppf(dist, a, u):
    """Inverse distribution function of one marginal at u in (0, 1)."""
    if dist == "uniform":
        return a[0] + (a[1] - a[0]) * u
    if dist == "normal":
        return stats.norm.ppf(u, a[0], a[1])
    if dist == "lognormal":
        return a[0] * np.exp(a[1] * stats.norm.ppf(u))
    lo, hi = (a[2] - a[0]) / a[1], (a[3] - a[0]) / a[1]
    return stats.truncnorm.ppf(u, lo, hi, loc=a[0], scale=a[1])


def _build(names, p, spec: dict, rule: str, order: int, seed: int) -> Prior:
    keys = [n for n in names if n in spec]
    marg = tuple((k, spec[k][0], tuple(spec[k][1:])) for k in keys)
    cols = [names.index(k) for k in keys]
    if not keys:
        P, w = p[None, :].copy(), np.ones(1)
    elif rule in ("gauss", "grid"):
        rules = [_gauss_1d(spec[k][0], np.asarray(spec[k][1:]), order, rule == "grid") for k in keys]
        grids = np.meshgrid(*[r[0] for r in rules], indexing="ij")
        wts = np.meshgrid(*[r[1] for r in rules], indexing="ij")
        P = np.tile(p, (grids[0].size, 1))
        P[:, cols] = np.stack([g.ravel() for g in grids], axis=1)
        w = np.prod(np.stack([v.ravel() for v in wts], axis=1), axis=1)
    elif rule == "sparse":
        from .prior_sparse import sparse_rule
        X, w = sparse_rule([(spec[k][0], np.asarray(spec[k][1:])) for k in keys], order)
        P = np.tile(p, (X.shape[0], 1))
        P[:, cols] = X
    else:
        sobol = qmc.Sobol(d=len(keys), scramble=True, seed=seed)
        m = int(np.log2(order))
        u = sobol.random_base2(m) if 2 ** m == order else sobol.random(order)
        P = np.tile(p, (order, 1))
        P[:, cols] = np.stack([_ppf(spec[k][0], np.asarray(spec[k][1:]), u[:, i]) for i, k in enumerate(keys)], 1)
        w = np.full(order, 1.0 / order)
    return Prior(points=readonly(P), weights=readonly(w / w.sum()), names=tuple(names), rule=rule,
                 order=order, marginals=marg, nominal=readonly(p), seed=seed)
