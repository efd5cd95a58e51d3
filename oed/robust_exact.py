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
eigen-decompositions) when there are at most ``enumeration_limit`` sets (``method="auto"``), so the result
is proven optimal over the candidates when the enumeration completes; larger sizes go to the branch-and-bound
of :mod:`oed.robust_bnb` (the per-sample bounds of :mod:`oed.bnb`, summed (bayes) or minimised (maximin)),
proven optimal or with its proven gap at the time limit.  Both routes compute a set's value the same way.  The efficiency against an approximate design :math:`\xi` on a range that
contains the candidates is :math:`\exp((\Phi(S) - \Phi(\xi))/n_p)` (D) or :math:`\Phi(\xi)/\Phi(S)`
(A, E; :math:`\Phi = \sum_s \pi_s u_s`), at most 1 + the approximate design's certified gap.
"""
from __future__ import annotations

import itertools
import math
import time
import warnings
from dataclasses import dataclass, replace

import numpy as np

from identification.results_protocol import ResultProtocol, jsonable
from .approx_weights import standardized
from .criteria import DEFAULT_CRITERION, Criterion
from .prior_sparse import check_non_negative
from .robust_bnb import RobustBnBSettings, robust_branch_and_bound, robust_set_values

__all__ = ["RobustExactDesign", "select_robust_exact", "set_efficiencies", "ExactOverPrior", "exact_over_prior"]

ROBUST = ("bayes", "maximin")
METHODS = ("auto", "enumerate", "bnb")


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
        True: every admissible set was evaluated, or the branch-and-bound closed its gap.
    n_designs : int
        Sets evaluated exactly.
    efficiency : float
        Against the approximate design given (nan without one); maximin: the worst-case efficiency.
    criterion, robust : str
    wall_time : float
    method : str
        "enumerate" or "bnb".
    status : str
        "optimal", "time_limit" or "node_limit" (then not proven: see ``upper_bound`` and ``gap``).
    upper_bound : float
        Proven: no set of n candidates has a value above it (nan when an enumeration stopped at the time limit).
    gap : float
        upper_bound - value (0 when proven).
    nodes : int
        Branch-and-bound nodes (0 for enumeration).
    local_indices : tuple of int
        The local exact design at the nominal parameters (``select_inputs`` with a prior; empty otherwise).
    local_efficiencies : tuple of float
        That local design's efficiency against this design at every parameter vector of the prior
        (:func:`set_efficiencies`; empty when ``local_indices`` is).
    refined : oed.robust_refine.RobustRefined or None
        The continuous refinement of the chosen points (``refine=True`` of the design verbs), else None.
    notes : tuple of str
        Modelling notes (e.g. a second-order criterion planned without data is the Gauss-Newton one).
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
    method: str = "enumerate"
    status: str = "optimal"
    upper_bound: float = float("nan")
    gap: float = 0.0
    nodes: int = 0
    local_indices: tuple = ()
    local_efficiencies: tuple = ()
    refined: object = None
    notes: tuple = ()

    def summary(self) -> str:
        """One-paragraph summary."""
        proof = ("proven optimal" if self.proven_optimal else
                 f"NOT proven: {self.status}, proven gap {self.gap:.3g} (upper bound {self.upper_bound:.9g})")
        via = f"branch-and-bound, {self.nodes} nodes" if self.method == "bnb" else "enumeration"
        eff = "" if not np.isfinite(self.efficiency) else (
            f", {'worst-case ' if self.robust == 'maximin' else ''}efficiency {self.efficiency:.6f}")
        text = (f"exact {self.robust} {self.criterion} design of {len(self.indices)} runs: {list(self.names)}, value "
                f"{self.value:.9g} ({proof}; {via}, {self.n_designs} sets evaluated){eff}, {self.wall_time:.2f} s")
        if self.local_efficiencies:
            e = np.asarray(self.local_efficiencies, float)
            text += (f"; the local design at the nominal parameters {list(self.local_indices)} has efficiency min "
                     f"{e.min():.6f}, max {e.max():.6f} against it across the prior's {e.size} parameter vectors")
        text += "".join(f"\n  note: {n}" for n in self.notes)
        return text if self.refined is None else text + "\n" + self.refined.summary()

    def to_frame(self):
        """The chosen candidates (``index``, ``name``), one row each; ``.attrs``: value, efficiency, criterion,
        robust, proven_optimal."""
        import pandas as pd
        df = pd.DataFrame({"index": [int(i) for i in self.indices], "name": list(self.names)})
        df.attrs.update(value=self.value, efficiency=self.efficiency, criterion=self.criterion, robust=self.robust,
                        proven_optimal=self.proven_optimal, method=self.method, status=self.status, gap=self.gap)
        return df

    def to_dict(self) -> dict:
        """JSON-safe: every field (per_sample a list; NaN efficiency as null); ``local_indices`` and
        ``local_efficiencies`` only when the local design was compared, ``refined`` only when refined, ``notes`` only
        when there are notes."""
        d = jsonable(self)
        if not self.local_efficiencies:
            del d["local_indices"], d["local_efficiencies"]
        if self.refined is None:
            del d["refined"]
        if not self.notes:
            del d["notes"]
        return d


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


def select_robust_exact(F, prior_w, n, *, criterion=DEFAULT_CRITERION, robust="bayes", u_star=None, names=None,
                        approximate=None, max_designs: int = 5_000_000, batch_size: int = 4096, method: str = "auto",
                        time_limit: float = 60.0, enumeration_limit: int = 100_000,
                        bnb_settings: RobustBnBSettings | None = None) -> RobustExactDesign:
    r"""The exact n-run design :math:`\max_{|S|=n}` of the robust criterion (module docstring), by complete
    enumeration or by branch-and-bound with a proven gap.

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
        ``method="enumerate"``: refuse larger enumerations.
    batch_size : int
        Sets per batch of the enumeration.
    method : {"auto", "enumerate", "bnb"}
        ``auto``: enumeration up to ``enumeration_limit`` sets, else branch-and-bound (:mod:`oed.robust_bnb`).
    time_limit : float
        Wall seconds for either route; at the limit the best set found is returned with ``status="time_limit"``,
        ``proven_optimal=False``, its proven gap, and a ``RuntimeWarning``.
    enumeration_limit : int
    bnb_settings : oed.robust_bnb.RobustBnBSettings or None
        Branch-and-bound settings (its ``time_limit`` is replaced by ``time_limit``).

    Raises
    ------
    ValueError
        Bad input, or more than ``max_designs`` sets to enumerate.
    """
    t0 = time.perf_counter()
    crit = Criterion.parse(criterion)
    F, w, names = _check(F, prior_w, n, robust, u_star, names)
    if method not in METHODS:
        raise ValueError(f"method: expected one of {METHODS}, got {method!r}")
    if isinstance(time_limit, bool) or not isinstance(time_limit, (int, float)) or not time_limit > 0:
        raise ValueError(f"time_limit: expected seconds > 0, got {time_limit!r}")
    total = math.comb(F.shape[0], n)
    if method == "bnb" or (method == "auto" and total > enumeration_limit):
        out = _solve_bnb(F, w, n, crit, robust, u_star, time_limit, bnb_settings)
    else:
        if total > max_designs:
            raise ValueError(f"n: {total} sets of {n} of {F.shape[0]} candidates exceed max_designs={max_designs}; "
                             "use fewer candidates, raise max_designs, or method=\"bnb\"")
        out = _enumerate(F, w, n, crit, robust, u_star, batch_size, total, time_limit, t0)
    if out["indices"] is None:
        raise ValueError(f"n: no set of {n} candidates gives a non-singular information at every parameter vector; "
                         "give more runs or other candidates")
    if out["status"] != "optimal":
        warnings.warn(f"select_robust_exact stopped at its {out['status']} (time_limit={time_limit:g} s): the design "
                      f"is not proven optimal; proven gap {out['gap']:.3g}", RuntimeWarning, stacklevel=2)
    best = np.asarray(out["indices"], int)
    best_v = out["value"]
    best_u = robust_set_values(crit, F, best[None], n, w, robust, u_star)[1][0]
    eff = float("nan")
    if robust == "maximin":
        eff = float(np.exp(best_v) if crit is Criterion.D else -1.0 / best_v)
    elif approximate is not None:
        eff = float(np.exp((best_v - approximate.value) / F.shape[2]) if crit is Criterion.D
                    else approximate.value / best_v)
    return RobustExactDesign(indices=tuple(int(i) for i in best), names=tuple(names[i] for i in best),
                             value=best_v, per_sample=best_u, proven_optimal=out["status"] == "optimal",
                             n_designs=out["count"], efficiency=eff, criterion=crit.value, robust=robust,
                             wall_time=time.perf_counter() - t0, method=out["method"], status=out["status"],
                             upper_bound=out["upper_bound"], gap=out["gap"], nodes=out["nodes"])


def _enumerate(F, w, n, crit, robust, u_star, batch_size, total, time_limit, t0) -> dict:
    """Complete enumeration in batches (stopping at the time limit, then with an unknown upper bound)."""
    best_v, best_set, count, status = -np.inf, None, 0, "optimal"
    it = itertools.combinations(range(F.shape[0]), n)
    while True:
        chunk = np.array(list(itertools.islice(it, batch_size)), dtype=int).reshape(-1, n)
        if chunk.shape[0] == 0:
            break
        v, _ = robust_set_values(crit, F, chunk, n, w, robust, u_star)
        count += chunk.shape[0]
        k = int(np.argmax(v))
        if v[k] > best_v:
            best_v, best_set = float(v[k]), chunk[k]
        if count < total and time.perf_counter() - t0 > time_limit:
            status = "time_limit"
            break
    done = status == "optimal"
    return dict(indices=best_set, value=best_v, status=status, count=count, method="enumerate", nodes=0,
                upper_bound=best_v if done else float("nan"), gap=0.0 if done else float("inf"))


def _solve_bnb(F, w, n, crit, robust, u_star, time_limit, settings) -> dict:
    """The branch-and-bound route (:func:`oed.robust_bnb.robust_branch_and_bound`)."""
    settings = replace(RobustBnBSettings() if settings is None else settings, time_limit=float(time_limit))
    r = robust_branch_and_bound(F, w, n, crit, robust, None if u_star is None else np.asarray(u_star, float),
                                settings)
    return dict(indices=r.indices, value=r.value, status=r.status, count=r.n_evaluated, method="bnb",
                nodes=r.nodes, upper_bound=r.upper_bound, gap=r.gap)


def set_efficiencies(criterion, F, design, reference) -> np.ndarray:
    r"""Efficiency of the n-run set ``design`` against the set ``reference`` (candidate indices, same size) at every
    parameter vector: D :math:`\exp((u_s(M_s(design)) - u_s(M_s(reference)))/n_p)`, A, E
    :math:`u_s(reference)/u_s(design)` (ratios of trace of the inverse / inverse smallest eigenvalue), with
    :math:`M_s = \frac1n\sum F_{c,s}`; ``F`` of shape (n_candidates, n_samples, n_p, n_p).  Returns (n_samples,)."""
    crit = Criterion.parse(criterion)
    F = np.asarray(F, float)
    a, b = np.asarray(design, int)[None], np.asarray(reference, int)[None]
    if a.shape != b.shape:
        raise ValueError(f"design: {a.shape[1]} candidates, reference {b.shape[1]}: the sets must have the same size")
    w = np.full(F.shape[1], 1.0 / F.shape[1])
    ua = robust_set_values(crit, F, a, a.shape[1], w, "bayes", None)[1][0]
    ub = robust_set_values(crit, F, b, b.shape[1], w, "bayes", None)[1][0]
    return np.exp((ua - ub) / F.shape[2]) if crit is Criterion.D else ub / ua


@dataclass(frozen=True)
class ExactOverPrior:
    """The exact robust design of n runs over a prior, the local exact design at the nominal parameters, and the
    local design's efficiency at every parameter vector against the robust one (:func:`set_efficiencies`).

    Attributes
    ----------
    design, local : RobustExactDesign
    local_efficiencies : ndarray (n_samples,)
    u_star : ndarray (n_samples,) or None
        Maximin: each vector's own exact n-run optimum (the standard of the worst-case efficiency).
    """

    design: RobustExactDesign
    local: RobustExactDesign
    local_efficiencies: np.ndarray
    u_star: np.ndarray | None


def exact_over_prior(information_at, prior, p, n, *, criterion=DEFAULT_CRITERION, robust="bayes", names=None,
                     time_limit: float = 60.0, method: str = "auto") -> ExactOverPrior:
    r""":math:`\max_{|S|=n}` of the robust criterion over ``prior`` (:func:`select_robust_exact`, enumeration or
    branch-and-bound) and the local n-run design at ``p``, with ``information_at(p_row) -> F (n_candidates, n_p,
    n_p)`` the information of one run of every candidate.  Maximin standardizes by each parameter vector's own
    exact n-run optimum (so the worst-case efficiency is against the best n-run design at that vector).  ``method``
    and ``time_limit`` (s) apply to each :func:`select_robust_exact` call (local, per-vector optima, robust)."""
    check_non_negative(prior, "an exact robust design")
    F = np.stack([np.asarray(information_at(ps), float) for ps in prior.points], axis=1)
    F0 = np.asarray(information_at(np.asarray(p, float)), float)[:, None]
    kw = dict(criterion=criterion, names=names, time_limit=time_limit, method=method)
    local = select_robust_exact(F0, [1.0], n, **kw)
    u_star = None
    if robust == "maximin":
        u_star = np.array([select_robust_exact(F[:, [s]], [1.0], n, **kw).value for s in range(F.shape[1])])
    design = select_robust_exact(F, prior.weights, n, robust=robust, u_star=u_star, **kw)
    return ExactOverPrior(design=design, local=local, u_star=u_star,
                          local_efficiencies=set_efficiencies(criterion, F, local.indices, design.indices))
