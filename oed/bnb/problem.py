r"""The data of a branch-and-bound search: the criterion on :math:`M(w)=\sum_k w_kF_k`, the
count/budget limits with the include/exclude fixings, and the incumbent design.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..constraints import DesignConstraints
from ..criteria import Criterion, CriteriaSettings, batch_criteria, gap_tolerance
from .settings import BnBSettings

__all__ = ["SelectionProblem", "NodeLimits", "Incumbent", "SearchContext", "fixings"]


class SelectionProblem:
    r"""Gauss-Newton criterion :math:`\Psi((\sum_k w_kF_k)^{-1})` of validated ``F`` (n, p, p).

    Attributes
    ----------
    F : ndarray, shape (n, p, p)
    Fflat : ndarray, shape (n, p*p)
        ``F`` with each :math:`F_k` flattened (``M(x) = (x @ Fflat).reshape(p, p)``).
    n, p : int
    crit : Criterion
    gap_tol : float
        Optimality tolerance (see :func:`oed.criteria.gap_tolerance`).
    csettings : CriteriaSettings
    eye : ndarray, shape (p, p)
    """

    def __init__(self, F, crit: Criterion, gap_tol: float, csettings: CriteriaSettings):
        self.F = F
        self.n, self.p, _ = F.shape
        self.Fflat = F.reshape(self.n, -1)
        self.crit = crit
        self.gap_tol = gap_tol
        self.csettings = csettings
        self.eye = np.eye(self.p)

    def exact(self, W):
        """Exact criterion (same code path as enumeration) for boolean designs W (b, n)."""
        res = batch_criteria(self.F, None, W, "gauss_newton", settings=self.csettings, validated=True)
        return res.value(self.crit)

    def tol(self, inc):
        """Optimality tolerance at the criterion value ``inc`` (0 when ``inc`` is not finite)."""
        return gap_tolerance(self.crit, inc, self.gap_tol)


def fixings(cons: DesignConstraints, n: int) -> np.ndarray:
    """Sensor states from the include/exclude lists: int8 array (n,), -1 free, 0 out, 1 in."""
    state = np.full(n, -1, dtype=np.int8)
    state[list(cons.include)] = 1
    state[list(cons.exclude)] = 0
    return state


@dataclass(frozen=True)
class NodeLimits:
    r"""Count and budget limits of the search: :math:`lo\le\sum_k w_k\le m`, :math:`c^Tw\le b`.

    Without costs (``costs is None``, ``budget = inf``, ``lo = 0``) the count is exactly ``m``
    (monotonicity of Gauss-Newton criteria).  ``state0``: the root fixings (-1 free, 0 out,
    1 in), with a budget also fixing out the sensors that alone exceed what is left.
    """

    m: int
    state0: np.ndarray
    costs: np.ndarray | None
    budget: float
    lo: int

    @classmethod
    def from_constraints(cls, cons: DesignConstraints, n: int) -> "NodeLimits":
        """Limits of ``cons`` for ``n`` candidates (``m``: the largest admissible size)."""
        state0 = fixings(cons, n)
        if cons.costs is None:
            return cls(cons.max_size, state0, None, np.inf, 0)
        # with a budget the count is lo <= sum w <= m (the budget may stop a design short of m)
        costs = np.asarray(cons.costs, float)
        budget = cons.budget * (1 + 1e-12) + 1e-12          # the tolerance of DesignConstraints
        state0[(state0 == -1) & (costs > budget - costs @ (state0 == 1))] = 0
        return cls(cons.max_size, state0, costs, budget, cons.min_size)

    @property
    def has_budget(self) -> bool:
        """True when the sensors have costs and a budget."""
        return self.costs is not None

    def relaxed_count(self, on, fr):
        """Free sensors the relaxation selects: m - |on| (with a budget at most |free| - 1; any
        relaxed point gives valid bounds, the budget enters through :func:`.bounds.budget_top`)."""
        r = self.m - on.sum(axis=1)
        return np.minimum(r, fr.sum(axis=1) - 1) if self.has_budget else r


class Incumbent:
    """Best design found so far.

    Attributes
    ----------
    w : ndarray of bool or None
    v : float
        Its exact criterion value (``inf`` while there is none).
    """

    def __init__(self, problem: SelectionProblem, w, v):
        self.problem = problem
        self.w = w
        self.v = v

    def threshold(self) -> float:
        """Prune level: nodes whose bound is at least incumbent - tol cannot improve it."""
        return self.v - self.problem.tol(self.v)

    def offer(self, W):
        """Exact values of designs W (b, n); the best replaces the incumbent if smaller; returns the values."""
        v = self.problem.exact(W)
        j = int(np.argmin(v))
        if v[j] < self.v:
            self.w, self.v = W[j].copy(), float(v[j])
        return v


@dataclass(frozen=True)
class SearchContext:
    """What every node relaxation of one search reads: problem, limits, settings, incumbent."""

    problem: SelectionProblem
    limits: NodeLimits
    settings: BnBSettings
    incumbent: Incumbent

    @property
    def is_e(self) -> bool:
        """True for the E criterion (soft-min relaxation in stages of sharpness)."""
        return self.problem.crit is Criterion.E

    @property
    def betas(self) -> tuple:
        """Soft-min sharpness stages (E), or one stage ``(None,)`` (A, D)."""
        return tuple(self.settings.e_betas) if self.is_e else (None,)

    @property
    def floor_d(self) -> float:
        """Floor of the relative relaxation-gap test: 1 for D (gap absolute on log det), else 0."""
        return 1.0 if self.problem.crit is Criterion.D else 0.0
