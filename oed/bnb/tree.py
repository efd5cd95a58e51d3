r"""Best-bound tree search of the sensor-selection branch-and-bound (see :mod:`oed.bnb`)."""
from __future__ import annotations

import heapq
import time

import numpy as np

from ..constraints import DesignConstraints
from ..criteria import DEFAULT_SETTINGS, Criterion, CriteriaSettings
from .heuristics import greedy_exchange
from .problem import Incumbent, NodeLimits, SearchContext, SelectionProblem
from .relaxation import relax_nodes
from .settings import BnBResult, BnBSettings

__all__ = ["branch_and_bound", "TreeSearch"]


def branch_and_bound(F, cons: DesignConstraints, criterion, *, settings: BnBSettings = BnBSettings(),
                     criteria_settings: CriteriaSettings = DEFAULT_SETTINGS) -> BnBResult:
    r"""Proven-optimal GN design :math:`\min \Psi((\sum_k w_kF_k)^{-1})` by branch and bound.

    Supports cardinality constraints (``n_sensors`` or ``max_sensors``, reduced to an exact
    count by monotonicity when there is no budget), forced-in/out sensors and per-sensor costs
    with a budget.  ``F`` must already be validated.

    Nodes are processed in batches (``settings.batch_size`` best-bound parents, i.e. twice
    as many children); the relaxations of a batch are solved simultaneously with batched
    linear algebra.
    """
    crit = Criterion.parse(criterion)
    t0 = time.perf_counter()
    prob = SelectionProblem(F, crit, settings.gap_tol, criteria_settings)
    # monotonicity: the largest admissible size is optimal for GN criteria
    limits = NodeLimits.from_constraints(cons, prob.n)

    # feasibility: all available sensors must give a regular information matrix
    avail = limits.state0 != 0
    if np.isinf(prob.exact(avail[None])[0]):
        return BnBResult(None, np.inf, np.inf, np.inf, "infeasible", 0, time.perf_counter() - t0, np.inf, np.inf)

    w0, v0 = greedy_exchange(prob, limits.state0, limits.m, costs=limits.costs, budget=limits.budget, lo=limits.lo)
    search = TreeSearch(SearchContext(prob, limits, settings, Incumbent(prob, w0, v0)), t0)
    search.run()
    return search.result()


class TreeSearch:
    """Best-bound-first search over batches of nodes.

    Attributes
    ----------
    ctx : SearchContext
    t0 : float
        Start time (``time.perf_counter``).
    heap : list
        Open nodes ``(bound, counter, fixings, relaxed point, budget price)``.
    nodes : int
        Nodes whose relaxation was solved.
    counter : int
        Tie-breaker of the heap (insertion order).
    status : str
    root_bound, initial_incumbent : float
    """

    def __init__(self, ctx: SearchContext, t0: float):
        self.ctx = ctx
        self.t0 = t0
        self.heap = []
        self.nodes = 0
        self.counter = 0
        self.status = "optimal"
        self.root_bound = np.inf
        self.initial_incumbent = ctx.incumbent.v

    def run(self):
        """Solve the root, then branch batches of best-bound nodes until the heap is empty or a limit is hit."""
        ctx = self.ctx
        settings = ctx.settings
        root = relax_nodes(ctx, ctx.limits.state0[None], None, settings.root_iters, True, [-np.inf])
        self.nodes = 1
        lb = root.lb
        self.root_bound = float(lb[0]) if lb.size and np.isfinite(lb[0]) else ctx.incumbent.v
        if lb.size:
            heapq.heappush(self.heap, (float(lb[0]), self.counter, root.S[0], root.X[0], root.mu[0]))
        while self.heap:
            th = ctx.incumbent.threshold()
            if self.heap[0][0] >= th:
                self.heap = []
                break
            if self._limit_reached():
                break
            self._expand(self._pop_parents(th))

    def _limit_reached(self) -> bool:
        """Set ``status`` and return True when the time or node limit is reached."""
        settings = self.ctx.settings
        if time.perf_counter() - self.t0 > settings.time_limit:
            self.status = "time_limit"
            return True
        if settings.node_limit is not None and self.nodes >= settings.node_limit:
            self.status = "node_limit"
            return True
        return False

    def _pop_parents(self, th):
        """Pop up to ``batch_size`` best-bound nodes below the threshold ``th`` (fewer near the node limit)."""
        settings = self.ctx.settings
        nb = max(1, settings.batch_size)
        if settings.node_limit is not None:
            nb = max(1, min(nb, (settings.node_limit - self.nodes) // 2))
        parents = []
        while self.heap and len(parents) < nb and self.heap[0][0] < th:
            parents.append(heapq.heappop(self.heap))
        return parents

    def _expand(self, parents):
        """Branch every parent on the free sensor whose relaxed value is closest to ``branch_target``
        (child with it in, then out), relax all children together and push the unpruned ones."""
        ctx = self.ctx
        S_c, X_c, lb_p, mu_p = [], [], [], []
        for plb, _, pst, px, pmu in parents:
            free = np.flatnonzero(pst == -1)
            k = free[int(np.argmin(np.abs(px[free] - ctx.settings.branch_target)))]
            for val in (1, 0):
                child = pst.copy()
                child[k] = val
                S_c.append(child)
                X_c.append(px)
                mu_p.append(pmu)
                lb_p.append(plb)
        kids = relax_nodes(ctx, np.array(S_c), np.array(X_c), ctx.settings.node_iters, False, lb_p, mu_p)
        self.nodes += len(S_c)
        th = ctx.incumbent.threshold()
        for i in range(kids.lb.size):
            if kids.lb[i] < th:
                self.counter += 1
                heapq.heappush(self.heap, (float(kids.lb[i]), self.counter, kids.S[i], kids.X[i], kids.mu[i]))

    def result(self) -> BnBResult:
        """The search outcome: incumbent, global lower bound (smallest open bound), gap and status."""
        inc = self.ctx.incumbent
        glb = min([h[0] for h in self.heap], default=inc.v)
        glb = min(glb, inc.v)
        status = self.status
        if status == "optimal" and not np.isfinite(inc.v):
            status = "infeasible"
        return BnBResult(w=inc.w, value=inc.v, lower_bound=glb, gap=inc.v - glb, status=status, nodes=self.nodes,
                         wall_time=time.perf_counter() - self.t0, root_bound=self.root_bound,
                         initial_incumbent=self.initial_incumbent)
