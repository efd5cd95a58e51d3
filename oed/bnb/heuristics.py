r"""Incumbent heuristics for :math:`\min_w \Psi((\sum_k w_kF_k)^{-1})`: greedy forward selection
with Fedorov exchange, and rounding of node relaxations.
"""
from __future__ import annotations

import numpy as np

from ..criteria import Criterion
from .problem import SearchContext, SelectionProblem

__all__ = ["greedy_exchange", "round_relaxations"]


def greedy_exchange(prob: SelectionProblem, state, m, W0=None, costs=None, budget=np.inf, lo=0):
    r"""Heuristic for :math:`\min_w \Psi((\sum_k w_kF_k)^{-1})`, :math:`\sum w = m` (with ``costs``:
    :math:`lo \le \sum w \le m,\ c^Tw \le` ``budget``): greedy forward selection (regularised
    D-ranking until regular) then best-improvement Fedorov exchange; with a budget, additions
    and exchanges are restricted to what the budget allows and the design is filled up again
    after every exchange.  ``state``: -1 free, 0 out, 1 in.  Returns (boolean w, value); the value
    is inf when no admissible design was found."""
    n = prob.n
    free = np.flatnonzero(state == -1)
    c = np.zeros(n) if costs is None else np.asarray(costs, float)
    scale = float(np.trace((np.ones(n) @ prob.Fflat).reshape(prob.p, prob.p))) / max(n * prob.p, 1)
    eps = 1e-9 * max(scale, np.finfo(float).tiny)
    w = _fill(prob, state == 1 if W0 is None else W0.copy(), free, c, m, budget, eps)
    if w.sum() < lo or c @ w > budget:
        return w, np.inf
    val = float(prob.exact(w[None])[0])
    # Fedorov exchange over free variables
    while True:
        ins = free[w[free]]
        outs = free[~w[free]]
        if ins.size == 0 or outs.size == 0:
            break
        sc = _swap_scores(prob, w, ins, outs)
        if costs is not None:
            swap_cost = c @ w - c[ins][:, None] + c[outs][None, :]
            sc = np.where((swap_cost <= budget).ravel(), sc, np.inf)
        j = int(np.argmin(sc))
        if not sc[j] < val - prob.tol(val) * 0.5 - 1e-15 * abs(val):
            break
        i_out, j_in = divmod(j, outs.size)
        w2 = w.copy()
        w2[ins[i_out]] = False
        w2[outs[j_in]] = True
        if costs is not None:
            w2 = _fill(prob, w2, free, c, m, budget, eps)
        v2 = float(prob.exact(w2[None])[0])
        if not v2 < val:
            break
        w, val = w2, v2
    return w, val


def _fill(prob: SelectionProblem, w, free, c, m, budget, eps):
    """Add the best affordable free sensor to ``w`` (in place) while the count allows: ranked by
    log det of the eps-regularised information while fewer than p sensors are in (always for D),
    else by the criterion.  Returns ``w``."""
    p = prob.p
    while w.sum() < m:
        cand = free[~w[free]]
        cand = cand[c[cand] <= budget - c @ w]
        if cand.size == 0:
            break
        Mc = (w @ prob.Fflat).reshape(p, p)
        Ms = Mc[None] + prob.F[cand] + eps * prob.eye[None]
        if prob.crit is Criterion.D or w.sum() < p:
            _, ld = np.linalg.slogdet(Ms)
            score = -ld
        else:
            lam = np.linalg.eigvalsh(Ms)
            score = np.sum(1.0 / lam, axis=1) if prob.crit is Criterion.A else 1.0 / lam[:, 0]
        w[cand[int(np.argmin(score))]] = True
    return w


def _swap_scores(prob: SelectionProblem, w, ins, outs):
    """Criterion of every exchange ``ins[i] -> outs[j]`` of design ``w`` (flattened (i, j); inf if singular)."""
    p = prob.p
    M = (w @ prob.Fflat).reshape(p, p)
    Ms = (M[None, None] - prob.F[ins][:, None] + prob.F[outs][None, :]).reshape(-1, p, p)
    lam = np.linalg.eigvalsh(Ms)
    with np.errstate(divide="ignore", invalid="ignore"):
        pos = lam[:, 0] > 0
        lsafe = np.where(lam > 0, lam, 1.0)
        if prob.crit is Criterion.A:
            return np.where(pos, np.sum(1.0 / lsafe, axis=1), np.inf)
        if prob.crit is Criterion.D:
            return np.where(pos, -np.sum(np.log(lsafe), axis=1), np.inf)
        return np.where(pos, 1.0 / lsafe[:, 0], np.inf)


def round_relaxations(ctx: SearchContext, S, X):
    """Rounding heuristic on nodes S (K, n) with relaxed points X (K, n): take the free sensors
    by decreasing relaxed value (with a budget: while count and budget allow); the best rounded
    design, improved by :func:`greedy_exchange` when that helps, replaces the incumbent if better."""
    lim, inc = ctx.limits, ctx.incumbent
    n = ctx.problem.n
    K = S.shape[0]
    fr = S == -1
    r = lim.m - (S == 1).sum(axis=1)
    order = np.argsort(-np.where(fr, X, -np.inf), axis=1, kind="stable")
    W = S == 1
    if lim.has_budget:
        left = lim.budget - W @ lim.costs
        cnt = r.copy()
        ar = np.arange(K)
        for col in range(n):
            k = order[:, col]
            add = fr[ar, k] & (cnt > 0) & (lim.costs[k] <= left)
            W[ar[add], k[add]] = True
            left[add] -= lim.costs[k[add]]
            cnt[add] -= 1
        W = W[W.sum(axis=1) >= lim.lo]
    else:
        sel = np.arange(n)[None, :] < r[:, None]
        np.put_along_axis(W, order, np.take_along_axis(W, order, axis=1) | sel, axis=1)
    old = inc.v
    v = ctx.problem.exact(W) if len(W) else np.full(1, np.inf)
    j = int(np.argmin(v))
    if v[j] < old:
        w2, v2 = greedy_exchange(ctx.problem, lim.state0, lim.m, W0=W[j], costs=lim.costs, budget=lim.budget,
                                 lo=lim.lo)
        inc.w, inc.v = (w2, v2) if v2 < v[j] else (W[j].copy(), float(v[j]))
