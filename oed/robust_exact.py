r"""Exact n-run designs under a prior: the robust criterion of a chosen set, proven optimal by enumeration.

For candidates c with information :math:`F_{c,s}` at the parameter vectors :math:`P_s` of a prior
(:mod:`oed.prior`) and a set :math:`S` of ``n`` candidates, :math:`M_s(S) = \frac1n\sum_{c\in S}F_{c,s}`
(normalised per run, comparable with an approximate design), solved:

.. math::

    \max_{|S| = n} \sum_s \pi_s u(M_s(S))\ \ (\text{bayes}),\qquad
    \max_{|S| = n} \min_s c_s(S)\ \ (\text{maximin}),

with the utilities and standardized utilities of :mod:`oed.robust` (maximin: against the local
optima :math:`u^*_s` given, e.g. the approximate local designs' values, so that :math:`e^{c_s}` (D) is
the efficiency against the approximate optimum).  Every admissible set is evaluated (batched
eigen-decompositions), so the result is proven optimal over the candidates when the enumeration
completes; sizes beyond ``max_designs`` are refused (the branch-and-bound of :mod:`oed.bnb` does not
take robust criteria).  The efficiency against an approximate design :math:`\xi` on a range that
contains the candidates is :math:`\exp((\Phi(S) - \Phi(\xi))/n_p)` (D) or :math:`\Phi(\xi)/\Phi(S)`
(A, E; :math:`\Phi = \sum_s \pi_s u_s`), at most 1 + the approximate design's certified gap.
"""
from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass

import numpy as np

from identification.results_protocol import ResultProtocol, jsonable
from .approx_weights import standardized
from .criteria import DEFAULT_CRITERION, Criterion
from .robust import utilities

__all__ = ["RobustExactDesign", "select_robust_exact"]

ROBUST = ("bayes", "maximin")


@dataclass(frozen=True)
class RobustExactDesign(ResultProtocol):
    """An exact n-run design under a prior (the result protocol: :meth:`summary`, :meth:`to_frame`,
    :meth:`to_dict`, ``_repr_html_``).

    Attributes
    ----------
    indices : tuple of int
        The chosen candidates.
    names : tuple of str
        Their names.
    value : float
        Bayes: :math:`\\sum_s\\pi_s u_s(M_s(S))`; maximin: :math:`\\min_s c_s(S)`.
    per_sample : ndarray (n_s,)
        :math:`u_s(M_s(S))` at every parameter vector.
    proven_optimal : bool
        True: every admissible set was evaluated.
    n_designs : int
        Sets evaluated.
    efficiency : float
        Against the approximate design given (nan without one); maximin: the worst-case efficiency.
    criterion, robust : str
    wall_time : float
    """

    indices: tuple
    names: tuple
    value: float
    per_sample: np.ndarray
    proven_optimal: bool
    n_designs: int
    efficiency: float
    criterion: str
    robust: str
    wall_time: float

    def summary(self) -> str:
        """One-paragraph summary."""
        return (f"exact {self.robust} {self.criterion} design of {len(self.indices)} runs: {list(self.names)}, value "
                f"{self.value:.9g} ({'proven optimal' if self.proven_optimal else 'not proven'}, {self.n_designs} "
                f"sets evaluated), efficiency {self.efficiency:.6f}, {self.wall_time:.2f} s")

    def to_frame(self):
        """The chosen candidates (``index``, ``name``), one row each; ``.attrs``: value, efficiency, criterion,
        robust, proven_optimal."""
        import pandas as pd
        df = pd.DataFrame({"index": [int(i) for i in self.indices], "name": list(self.names)})
        df.attrs.update(value=self.value, efficiency=self.efficiency, criterion=self.criterion, robust=self.robust,
                        proven_optimal=self.proven_optimal)
        return df

    def to_dict(self) -> dict:
        """JSON-safe: every field (per_sample a list; NaN efficiency as null)."""
        return jsonable(self)


def _check(F, prior_w, n, robust, u_star, names):
    F = np.asarray(F, float)
    if F.ndim != 4 or F.shape[2] != F.shape[3] or F.shape[0] == 0 or F.shape[1] == 0:
        raise ValueError(f"F: expected shape (n_candidates, n_samples, n_p, n_p), got {F.shape}")
    if not np.all(np.isfinite(F)):
        raise ValueError("F: information matrices must be finite")
    w = np.asarray(prior_w, float).ravel()
    if w.shape != (F.shape[1],) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError(f"prior_w: expected {F.shape[1]} finite non-negative weights with a positive sum")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= n <= F.shape[0]:
        raise ValueError(f"n: expected an integer in 1..{F.shape[0]} (the number of candidates), got {n!r}")
    if robust not in ROBUST:
        raise ValueError(f"robust: expected one of {ROBUST}, got {robust!r}")
    if robust == "maximin":
        if u_star is None or np.shape(u_star) != (F.shape[1],) or not np.all(np.isfinite(u_star)):
            raise ValueError("u_star: the maximin criterion needs the local optimum's utility at every parameter "
                             f"vector ({F.shape[1]} finite values, e.g. approximate local designs' values)")
    names = tuple(str(i) for i in range(F.shape[0])) if names is None else tuple(names)
    if len(names) != F.shape[0]:
        raise ValueError(f"names: expected {F.shape[0]} names, got {len(names)}")
    return F, w / w.sum(), names


def _batch_values(crit, F, combos, n, w, robust, u_star):
    """(objective per set, utilities (B, n_s)) of a batch of sets (rows of indices)."""
    M = F[combos].sum(axis=1) / n                                   # (B, n_s, p, p)
    B, n_s, p = M.shape[0], M.shape[1], M.shape[2]
    u = utilities(crit, M.reshape(B * n_s, p, p)).u.reshape(B, n_s)
    if robust == "bayes":
        with np.errstate(invalid="ignore"):
            return np.where(np.all(np.isfinite(u), axis=1), u @ w, -np.inf), u
    c, _ = standardized(crit, u, u_star, p)
    return np.min(c, axis=1), u


def select_robust_exact(F, prior_w, n, *, criterion=DEFAULT_CRITERION, robust="bayes", u_star=None, names=None,
                        approximate=None, max_designs: int = 5_000_000, batch_size: int = 4096) -> RobustExactDesign:
    r"""The exact n-run design :math:`\max_{|S|=n}` of the robust criterion (module docstring) by complete
    enumeration.

    Parameters
    ----------
    F : array_like (n_candidates, n_samples, n_p, n_p)
        Information of one run of every candidate at every parameter vector.
    prior_w : array_like (n_samples,)
        The prior's weights (:attr:`oed.prior.Prior.weights`).
    n : int
        Runs (distinct candidates).
    criterion : {"A", "D", "E"}
    robust : {"bayes", "maximin"}
    u_star : array_like (n_samples,) or None
        Maximin: the local optima's utilities (e.g. ``approximate_design(...).value`` per vector).
    names : sequence of str or None
    approximate : oed.approximate.ApproximateDesign or None
        For the efficiency (bayes: its value; maximin: efficiencies against ``u_star``).
    max_designs : int
        Refuse larger enumerations.
    batch_size : int

    Raises
    ------
    ValueError
        Bad input, or more than ``max_designs`` sets.
    """
    t0 = time.perf_counter()
    crit = Criterion.parse(criterion)
    F, w, names = _check(F, prior_w, n, robust, u_star, names)
    total = math.comb(F.shape[0], n)
    if total > max_designs:
        raise ValueError(f"n: {total} sets of {n} of {F.shape[0]} candidates exceed max_designs={max_designs}; "
                         "use fewer candidates or raise max_designs")
    best_v, best_set, best_u, count = -np.inf, None, None, 0
    it = itertools.combinations(range(F.shape[0]), n)
    while True:
        chunk = np.array(list(itertools.islice(it, batch_size)), dtype=int).reshape(-1, n)
        if chunk.shape[0] == 0:
            break
        v, u = _batch_values(crit, F, chunk, n, w, robust, u_star)
        count += chunk.shape[0]
        k = int(np.argmax(v))
        if v[k] > best_v:
            best_v, best_set, best_u = float(v[k]), chunk[k], u[k]
    if best_set is None:
        raise ValueError(f"n: no set of {n} candidates gives a non-singular information at every parameter vector; "
                         "give more runs or other candidates")
    eff = float("nan")
    if robust == "maximin":
        eff = float(np.exp(best_v) if crit is Criterion.D else -1.0 / best_v)
    elif approximate is not None:
        eff = float(np.exp((best_v - approximate.value) / F.shape[2]) if crit is Criterion.D
                    else approximate.value / best_v)
    return RobustExactDesign(indices=tuple(int(i) for i in best_set), names=tuple(names[i] for i in best_set),
                             value=best_v, per_sample=best_u, proven_optimal=count == total, n_designs=count,
                             efficiency=eff, criterion=crit.value, robust=robust, wall_time=time.perf_counter() - t0)
