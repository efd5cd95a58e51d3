r"""Exact branch-and-bound for Gauss-Newton A-, D-, E-optimal sensor selection.

Solves

.. math::  \min_{w\in\{0,1\}^{n_S}} \Psi\Big(\big(\textstyle\sum_k w_kF_k\big)^{-1}\Big)
           \quad\text{s.t.}\quad \sum_k w_k = m,\ w_k=1\ (k\in I),\ w_k=0\ (k\in O),

with :math:`\Psi\in\{\mathrm{tr},\ \log\det,\ \lambda_{\max}\}`.

Bounds are rigorous for *any* relaxation iterate (they need not be optimal): with
:math:`M(v)=\sum_k v_kF_k` and node polytope :math:`P=\{v\in[0,1]^{n_S}: \sum v=m,\ \text{fixings}\}`,

* D: :math:`-\log\det M(v) \ge -\log\det X + p - \mathrm{tr}(X^{-1}M(v))` for any :math:`X\succ0`
  (concavity of log det, tangent at :math:`X=M(x)`);
* A: :math:`\mathrm{tr}\,M(v)^{-1} \ge 2\,\mathrm{tr}X^{-1} - \mathrm{tr}(X^{-2}M(v))` (convexity);
* E: :math:`\lambda_{\min}(M(v)) \le \mathrm{tr}(Z M(v))` for any :math:`Z\succeq0,\ \mathrm{tr}Z=1`,

so each bound is :math:`h(\max_{v\in P} q^Tv)` with :math:`h` decreasing and the inner
maximum a closed-form "top-r" sum.  The same linear form gives reduced-cost variable
fixing.  :math:`X` (resp. :math:`Z`) comes from a few spectral-projected-gradient steps on
the continuous relaxation (for E a soft-min smoothing of :math:`\lambda_{\min}`), warm
started from the parent node.  Incumbents come from greedy + Fedorov exchange and from
rounding node relaxations.  Branching: most fractional variable; node selection:
best bound first.  Monotonicity (adding a sensor never increases a GN criterion) reduces
``sum w <= m`` to ``sum w = m``.
"""
from __future__ import annotations

import heapq
import time
from dataclasses import dataclass

import numpy as np

from .constraints import DesignConstraints
from .criteria import DEFAULT_SETTINGS, Criterion, CriteriaSettings, batch_criteria

__all__ = ["BnBSettings", "BnBResult", "branch_and_bound", "greedy_exchange"]


@dataclass(frozen=True)
class BnBSettings:
    """Settings for :func:`branch_and_bound`.

    Attributes
    ----------
    time_limit : float
        Wall-clock seconds.
    gap_tol : float
        Optimality tolerance: relative for A and E; absolute on log det C for D
        (i.e. relative on det C).  Nodes with bound >= incumbent - tol are pruned.
    root_iters, node_iters : int
        Maximum relaxation iterations at the root / at other nodes.
    node_limit : int or None
    e_betas : tuple of float
        Soft-min sharpness continuation for the E relaxation (``t = beta / lambda_min``).
    early_branch : bool
        At non-root nodes stop the relaxation (after ``early_branch_min_iters`` iterations)
        once the criterion at the relaxed point is below incumbent - tol: the relaxation
        optimum, hence every bound it can give, is then too small to prune.
    """

    time_limit: float = 60.0
    gap_tol: float = 1e-9
    root_iters: int = 400
    node_iters: int = 40
    node_limit: int | None = None
    e_betas: tuple = (30.0, 300.0, 3000.0)
    early_branch: bool = True
    early_branch_min_iters: int = 3


@dataclass(frozen=True)
class BnBResult:
    """Outcome of :func:`branch_and_bound`.

    ``status`` is one of ``"optimal"`` (gap <= tol), ``"time_limit"``, ``"node_limit"``,
    ``"infeasible"`` (no regular design).  ``gap`` = value - lower_bound (for D on log det).
    """

    w: np.ndarray | None
    value: float
    lower_bound: float
    gap: float
    status: str
    nodes: int
    wall_time: float
    root_bound: float
    initial_incumbent: float


def _proj_capped_simplex(y, r):
    """Euclidean projection of y onto {0 <= x <= 1, sum x = r}."""
    n = y.size
    if r <= 0:
        return np.zeros(n)
    if r >= n:
        return np.ones(n)
    bp = np.sort(np.concatenate([y - 1.0, y]))
    s = np.clip(y[None, :] - bp[:, None], 0.0, 1.0).sum(axis=1)
    i = int(np.searchsorted(-s, -r, side="left"))  # first index with s <= r
    if i <= 0:
        tau = bp[0]
    elif i >= bp.size:
        tau = bp[-1]
    else:
        s0, s1 = s[i - 1], s[i]
        tau = bp[i - 1] if s0 == s1 else bp[i - 1] + (s0 - r) * (bp[i] - bp[i - 1]) / (s0 - s1)
    return np.clip(y - tau, 0.0, 1.0)


class _Problem:
    def __init__(self, F, crit, settings, csettings):
        self.F = F
        self.n, self.p, _ = F.shape
        self.Fflat = F.reshape(self.n, -1)
        self.crit = crit
        self.settings = settings
        self.csettings = csettings
        self.eye = np.eye(self.p)

    # --- exact values -----------------------------------------------------------------
    def exact(self, W):
        """Exact criterion (same code path as enumeration) for boolean designs W (b, n)."""
        res = batch_criteria(self.F, None, W, "gauss_newton", settings=self.csettings, validated=True)
        return res.value(self.crit)

    def tol(self, inc):
        if not np.isfinite(inc):
            return 0.0
        if self.crit is Criterion.D:
            return self.settings.gap_tol
        return self.settings.gap_tol * abs(inc)

    # --- relaxation pieces ------------------------------------------------------------
    def smooth(self, x, tE):
        """phi(x) (objective being minimised), q (gradient = -q), primal criterion value."""
        M = (x @ self.Fflat).reshape(self.p, self.p)
        if self.crit is Criterion.E:
            lam, U = np.linalg.eigh(M)
            l0 = lam[0]
            e = np.exp(-tE * (lam - l0))
            se = e.sum()
            pi = e / se
            soft = l0 - np.log(se) / tE
            Z = (U * pi) @ U.T
            q = self.Fflat @ Z.ravel()
            primal = 1.0 / l0 if l0 > 0 else np.inf
            return -soft, q, primal
        try:
            L = np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            return np.inf, None, np.inf
        Linv = np.linalg.inv(L)
        Minv = Linv.T @ Linv
        if self.crit is Criterion.D:
            f = -2.0 * np.sum(np.log(np.diag(L)))
            q = self.Fflat @ Minv.ravel()
        else:
            f = float(np.trace(Minv))
            q = self.Fflat @ (Minv @ Minv).ravel()
        return f, q, f

    def bound_from_s(self, f, s):
        """h(s): lower bound on the criterion from the linear-form maximum s."""
        if self.crit is Criterion.D:
            return f + self.p - s
        if self.crit is Criterion.A:
            return 2.0 * f - s
        if np.ndim(s) == 0:
            return 1.0 / s if s > 0 else np.inf
        pos = s > 0
        return np.where(pos, 1.0 / np.where(pos, s, 1.0), np.inf)


def _top_r(qf, r):
    """Indices (descending) ordering of qf, and sum of top r."""
    order = np.argsort(-qf, kind="stable")
    return order, float(qf[order[:r]].sum())


def greedy_exchange(prob: _Problem, state, m, W0=None):
    r"""Heuristic for :math:`\min_w \Psi((\sum_k w_kF_k)^{-1})`, :math:`\sum w = m`: greedy forward
    selection (regularised D-ranking until regular) then best-improvement Fedorov exchange.  ``state``: -1 free, 0 out, 1 in.  Returns (boolean w, value)."""
    n = prob.n
    Fflat = prob.Fflat
    p = prob.p
    free = np.flatnonzero(state == -1)
    if W0 is None:
        w = state == 1
        scale = float(np.trace((np.ones(n) @ Fflat).reshape(p, p))) / max(n * p, 1)
        eps = 1e-9 * max(scale, np.finfo(float).tiny)
        while w.sum() < m:
            cand = free[~w[free]]
            Mc = (w @ Fflat).reshape(p, p)
            Ms = Mc[None] + prob.F[cand] + eps * prob.eye[None]
            if prob.crit is Criterion.D or w.sum() < p:
                _, ld = np.linalg.slogdet(Ms)
                score = -ld
            else:
                lam = np.linalg.eigvalsh(Ms)
                score = np.sum(1.0 / lam, axis=1) if prob.crit is Criterion.A else 1.0 / lam[:, 0]
            w[cand[int(np.argmin(score))]] = True
    else:
        w = W0.copy()
    val = float(prob.exact(w[None])[0])
    # Fedorov exchange over free variables
    while True:
        ins = free[w[free]]
        outs = free[~w[free]]
        if ins.size == 0 or outs.size == 0:
            break
        M = (w @ Fflat).reshape(p, p)
        Ms = (M[None, None] - prob.F[ins][:, None] + prob.F[outs][None, :]).reshape(-1, p, p)
        lam = np.linalg.eigvalsh(Ms)
        with np.errstate(divide="ignore", invalid="ignore"):
            pos = lam[:, 0] > 0
            lsafe = np.where(lam > 0, lam, 1.0)
            if prob.crit is Criterion.A:
                sc = np.where(pos, np.sum(1.0 / lsafe, axis=1), np.inf)
            elif prob.crit is Criterion.D:
                sc = np.where(pos, -np.sum(np.log(lsafe), axis=1), np.inf)
            else:
                sc = np.where(pos, 1.0 / lsafe[:, 0], np.inf)
        j = int(np.argmin(sc))
        if not sc[j] < val - prob.tol(val) * 0.5 - 1e-15 * abs(val):
            break
        i_out, j_in = divmod(j, outs.size)
        w2 = w.copy()
        w2[ins[i_out]] = False
        w2[outs[j_in]] = True
        v2 = float(prob.exact(w2[None])[0])
        if not v2 < val:
            break
        w, val = w2, v2
    return w, val


def branch_and_bound(F, cons: DesignConstraints, criterion, *, settings: BnBSettings = BnBSettings(),
                     criteria_settings: CriteriaSettings = DEFAULT_SETTINGS) -> BnBResult:
    r"""Proven-optimal GN design :math:`\min \Psi((\sum_k w_kF_k)^{-1})` by branch and bound.

    Supports cardinality constraints (``n_sensors`` or ``max_sensors``, reduced to an exact
    count by monotonicity) and forced-in/out sensors.  Costs/budget are not supported
    (use SCIP or enumeration).  ``F`` must already be validated.

    Raises
    ------
    ValueError
        ``costs``: if ``cons`` has costs/budget.
    """
    crit = Criterion.parse(criterion)
    if cons.costs is not None:
        raise ValueError("costs: branch_and_bound does not support costs/budget; use method='scip' or 'enumerate'")
    t0 = time.perf_counter()
    prob = _Problem(F, crit, settings, criteria_settings)
    n, p = prob.n, prob.p
    m = cons.max_size  # monotonicity: the largest admissible size is optimal for GN criteria
    state0 = np.full(n, -1, dtype=np.int8)
    state0[list(cons.include)] = 1
    state0[list(cons.exclude)] = 0

    # feasibility: all available sensors must give a regular information matrix
    avail = state0 != 0
    if np.isinf(prob.exact(avail[None])[0]):
        return BnBResult(None, np.inf, np.inf, np.inf, "infeasible", 0, time.perf_counter() - t0, np.inf, np.inf)

    inc_w, inc_v = greedy_exchange(prob, state0, m)
    init_inc = inc_v
    nodes = 0
    counter = 0
    heap = []
    root_bound = -np.inf

    def solve_node(state, x0, iters):
        """Returns (lb, x, state) with possible extra fixings; lb = inf if pruned."""
        nonlocal inc_w, inc_v
        best_lb = -np.inf
        while True:
            free = np.flatnonzero(state == -1)
            ones = state == 1
            r = m - int(ones.sum())
            if r < 0 or r > free.size:
                return np.inf, None, state
            if r == 0 or r == free.size:
                w = ones.copy()
                w[free] = True if r == free.size else False
                v = float(prob.exact(w[None])[0])
                if v < inc_v:
                    inc_w, inc_v = w, v
                return np.inf, None, state
            x = np.where(ones, 1.0, 0.0)
            xf = x0[free] if x0 is not None else np.full(free.size, r / free.size)
            xf = _proj_capped_simplex(xf, r)
            x[free] = xf
            betas = prob.settings.e_betas if crit is Criterion.E else (None,)
            n_it = max(iters // len(betas), 5)
            fixed_more = False
            for beta in betas:
                tE = 0.0
                if crit is Criterion.E:
                    lam0 = np.linalg.eigvalsh((x @ prob.Fflat).reshape(p, p))[0]
                    if lam0 <= 0:
                        x[free] = r / free.size
                        lam0 = np.linalg.eigvalsh((x @ prob.Fflat).reshape(p, p))[0]
                    tE = beta / max(lam0, 1e-300)
                f, q, primal = prob.smooth(x, tE)
                if not np.isfinite(f):
                    x[free] = r / free.size
                    f, q, primal = prob.smooth(x, tE)
                    if not np.isfinite(f):
                        return np.inf, None, state  # node cannot reach full rank
                alpha = 1.0 / max(np.linalg.norm(q[free]), 1e-300)
                for it in range(n_it):
                    qf = q[free]
                    order, top = _top_r(qf, r)
                    s = float(q[ones].sum()) + top
                    lb = prob.bound_from_s(f, s)
                    best_lb = max(best_lb, lb)
                    thr = inc_v - prob.tol(inc_v)
                    if best_lb >= thr:
                        return np.inf, None, state
                    # reduced-cost fixing with this (valid) linear form
                    if np.isfinite(inc_v):
                        q_r = qf[order[r - 1]]
                        q_r1 = qf[order[r]]
                        chosen = order[:r]
                        other = order[r:]
                        lb_in = prob.bound_from_s(f, s - q_r + qf[other])
                        lb_out = prob.bound_from_s(f, s - qf[chosen] + q_r1)
                        fix0 = other[lb_in >= thr]
                        fix1 = chosen[lb_out >= thr]
                        if fix0.size or fix1.size:
                            state = state.copy()
                            state[free[fix0]] = 0
                            state[free[fix1]] = 1
                            x0 = x
                            fixed_more = True
                            break
                    # relaxation gap check
                    if np.isfinite(primal) and primal - lb <= 1e-7 * max(abs(primal), 1.0 if crit is Criterion.D else 0.0):
                        break
                    # early branching: primal = Psi at a relaxed point >= relaxation optimum >= any bound
                    # this relaxation can give, so once primal < incumbent - tol it can never prune.
                    if (prob.settings.early_branch and iters < prob.settings.root_iters
                            and it >= prob.settings.early_branch_min_iters and primal < thr):
                        break
                    # spectral projected gradient step (minimise phi, gradient -q)
                    y = _proj_capped_simplex(x[free] + alpha * qf, r)
                    d = y - x[free]
                    dn = float(np.dot(d, d))
                    if dn < 1e-24:
                        break
                    slope = -float(np.dot(qf, d))
                    lam_s = 1.0
                    while True:
                        xn = x.copy()
                        xn[free] = x[free] + lam_s * d
                        fn, qn, pn = prob.smooth(xn, tE)
                        if np.isfinite(fn) and fn <= f + 1e-4 * lam_s * slope:
                            break
                        lam_s *= 0.5
                        if lam_s < 1e-8:
                            fn = None
                            break
                    if fn is None:
                        break
                    sv = lam_s * d
                    yv = -(qn[free] - qf)
                    sy = float(np.dot(sv, yv))
                    alpha = float(np.dot(sv, sv)) / sy if sy > 1e-300 else alpha * 4.0
                    alpha = min(max(alpha, 1e-12 / max(np.linalg.norm(qf), 1e-300)), 1e12)
                    x, f, q, primal = xn, fn, qn, pn
                if fixed_more:
                    break
            if fixed_more:
                continue
            # rounding heuristic
            free = np.flatnonzero(state == -1)
            w = state == 1
            w[free[np.argsort(-x[free], kind="stable")[:r]]] = True
            v = float(prob.exact(w[None])[0])
            if v < inc_v:
                w2, v2 = greedy_exchange(prob, state0, m, W0=w)
                inc_w, inc_v = (w2, v2) if v2 < v else (w, v)
            return best_lb, x, state

    lb, x, st = solve_node(state0, None, settings.root_iters)
    nodes = 1
    root_bound = lb if np.isfinite(lb) else inc_v
    status = "optimal"
    if np.isfinite(lb):
        heapq.heappush(heap, (lb, counter, st, x))
    while heap:
        lb, _, st, x = heap[0]
        if lb >= inc_v - prob.tol(inc_v):
            heap = []
            break
        if time.perf_counter() - t0 > settings.time_limit:
            status = "time_limit"
            break
        if settings.node_limit is not None and nodes >= settings.node_limit:
            status = "node_limit"
            break
        heapq.heappop(heap)
        free = np.flatnonzero(st == -1)
        k = free[int(np.argmin(np.abs(x[free] - 0.5)))]
        for val in (1, 0):
            child = st.copy()
            child[k] = val
            clb, cx, cst = solve_node(child, x, settings.node_iters)
            nodes += 1
            clb = max(clb, lb)
            if np.isfinite(clb) and clb < inc_v - prob.tol(inc_v):
                counter += 1
                heapq.heappush(heap, (clb, counter, cst, cx))
    glb = min([h[0] for h in heap], default=inc_v)
    glb = min(glb, inc_v)
    gap = inc_v - glb
    if status == "optimal" and not np.isfinite(inc_v):
        status = "infeasible"
    return BnBResult(w=inc_w, value=inc_v, lower_bound=glb, gap=gap, status=status, nodes=nodes,
                     wall_time=time.perf_counter() - t0, root_bound=root_bound, initial_incumbent=init_inc)
