r"""Exact branch-and-bound for Gauss-Newton A-, D-, E-optimal sensor selection.

Solves

.. math::  \min_{w\in\{0,1\}^{n_S}} \Psi\Big(\big(\textstyle\sum_k w_kF_k\big)^{-1}\Big)
           \quad\text{s.t.}\quad \sum_k w_k = m,\ w_k=1\ (k\in I),\ w_k=0\ (k\in O),

with :math:`\Psi\in\{\mathrm{tr},\ \log\det,\ \lambda_{\max}\}`, optionally with per-sensor
costs and a budget :math:`c^Tw\le b` (then :math:`lo\le\sum_k w_k\le m`: the budget may stop the
best design short of m sensors).

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
started from the parent node; the children of up to ``batch_size`` best-bound parents are
solved together (batched linear algebra), and for E the bound of a node that ends unpruned
is re-optimised over the eigenbasis weights of Z.  Incumbents come from greedy + Fedorov
exchange and from rounding node relaxations.  Branching: the free variable whose relaxed value is closest to
``branch_target`` (0.65); node selection:
best bound first.  Monotonicity (adding a sensor never increases a GN criterion) reduces
``sum w <= m`` to ``sum w = m``.

With a budget the node polytope is :math:`\{v: \sum v\le r,\ c^Tv\le b_{node}\}`.  The relaxation
point still comes from the count-only polytope (any point gives valid bounds); the budget enters
the bound through the linear maximum, bounded by its Lagrangian dual over the budget multiplier
(:func:`_budget_top`).  Free sensors that no longer fit the node's budget are fixed out, a node
whose free sensors all fit is a leaf (take them all), and the greedy/exchange and rounding
heuristics keep to the budget.  Reduced-cost fixing and the E eigenbasis refinement assume an
exact count and are switched off.
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
    nonmonotone : int
        Memory of the non-monotone (Grippo-Lampariello-Lucidi) Armijo line search of the
        projected-gradient relaxation solve (1 = monotone).
    batch_size : int
        Number of best-bound nodes branched together; their children's relaxations are
        solved simultaneously (vectorised over the batch).
    e_refine_iters : int
        E only: exponentiated-subgradient iterations that re-optimise the eigenvalue weights of
        the bound matrix ``Z = U diag(pi) U^T`` (``U``: eigenvectors of the relaxed FIM) at the
        end of a node's relaxation (0 = off).  See :func:`_e_bound_refine`.
    branch_target : float
        Branch on the free variable whose relaxed value is closest to this (0.5 = most
        fractional; values above 0.5 favour sensors the relaxation nearly selects, which made
        A and E trees smaller on the benchmark instances).
    budget_steering : bool
        With a budget: steer the relaxation towards the budget by minimising
        ``phi(x) + mu c^T x`` with ``mu`` the budget price of the node's Lagrangian bound
        (:func:`_budget_top`), inherited by the children.  Root bounds get tighter on every
        instance measured, but the trees behave differently: 100 x 10 A with m = 20 gap 3 % ->
        0.4 % in 60 s, 50 x 10 A with m = 20 proven in 2.8 s instead of 20 s, while 50 x 10 A and
        100 x 10 D with m = 10 are no longer proven within 60 s (bench/RESULTS.md).  Off by default.
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
    batch_size: int = 128
    nonmonotone: int = 5
    e_refine_iters: int = 30
    branch_target: float = 0.65
    budget_steering: bool = False

    def __post_init__(self):
        if not (isinstance(self.time_limit, (int, float, np.floating)) and self.time_limit > 0):
            raise ValueError(f"time_limit: expected seconds > 0, got {self.time_limit!r}")
        if not (isinstance(self.gap_tol, (int, float, np.floating)) and 0 <= self.gap_tol < np.inf):
            raise ValueError(f"gap_tol: expected a finite number >= 0, got {self.gap_tol!r}")
        for name, low in (("root_iters", 1), ("node_iters", 1), ("early_branch_min_iters", 0), ("batch_size", 1),
                          ("nonmonotone", 1), ("e_refine_iters", 0)):
            v = getattr(self, name)
            if not (isinstance(v, (int, np.integer)) and v >= low):
                raise ValueError(f"{name}: expected an integer >= {low}, got {v!r}")
        if self.node_limit is not None and not (isinstance(self.node_limit, (int, np.integer)) and self.node_limit >= 1):
            raise ValueError(f"node_limit: expected None or an integer >= 1, got {self.node_limit!r}")
        if not (len(self.e_betas) >= 1 and all(float(b) > 0 for b in self.e_betas)):
            raise ValueError(f"e_betas: expected one or more positive sharpness values, got {self.e_betas!r}")
        if not (0.0 <= float(self.branch_target) <= 1.0):
            raise ValueError(f"branch_target: expected a value in [0, 1], got {self.branch_target!r}")


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
    """Euclidean projection of y onto {0 <= x <= 1, sum x = r} (reference for the batched version)."""
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

    def smooth_batch(self, X, tE):
        """Batched :meth:`smooth` for the rows of X (B, n): (phi, Q (B, n), primal); phi = inf if M(x) is not PD (A, D)."""
        B = X.shape[0]
        M = (X @ self.Fflat).reshape(B, self.p, self.p)
        lam, U = np.linalg.eigh(M)
        l0 = lam[:, 0]
        Ut = U.transpose(0, 2, 1)
        if self.crit is Criterion.E:
            e = np.exp(-tE[:, None] * (lam - l0[:, None]))
            se = e.sum(axis=1)
            Z = (U * (e / se[:, None])[:, None, :]) @ Ut
            Q = Z.reshape(B, -1) @ self.Fflat.T
            with np.errstate(divide="ignore"):
                primal = np.where(l0 > 0, 1.0 / np.where(l0 > 0, l0, 1.0), np.inf)
            return -(l0 - np.log(se) / tE), Q, primal
        ok = l0 > 1e-13 * np.abs(lam[:, -1])
        ls = np.where(ok[:, None], lam, 1.0)
        inv = 1.0 / ls
        if self.crit is Criterion.D:
            fval = -np.log(ls).sum(axis=1)
            wts = inv
        else:
            fval = inv.sum(axis=1)
            wts = inv * inv
        Q = ((U * wts[:, None, :]) @ Ut).reshape(B, -1) @ self.Fflat.T
        fval = np.where(ok, fval, np.inf)
        return fval, Q, fval.copy()

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


def greedy_exchange(prob: _Problem, state, m, W0=None, costs=None, budget=np.inf, lo=0):
    r"""Heuristic for :math:`\min_w \Psi((\sum_k w_kF_k)^{-1})`, :math:`\sum w = m` (with ``costs``:
    :math:`lo \le \sum w \le m,\ c^Tw \le` ``budget``): greedy forward selection (regularised
    D-ranking until regular) then best-improvement Fedorov exchange; with a budget, additions
    and exchanges are restricted to what the budget allows and the design is filled up again
    after every exchange.  ``state``: -1 free, 0 out, 1 in.  Returns (boolean w, value); the value
    is inf when no admissible design was found."""
    n = prob.n
    Fflat = prob.Fflat
    p = prob.p
    free = np.flatnonzero(state == -1)
    c = np.zeros(n) if costs is None else np.asarray(costs, float)
    scale = float(np.trace((np.ones(n) @ Fflat).reshape(p, p))) / max(n * p, 1)
    eps = 1e-9 * max(scale, np.finfo(float).tiny)

    def fill(w):
        """Add the best affordable free sensor while the count allows (in place)."""
        while w.sum() < m:
            cand = free[~w[free]]
            cand = cand[c[cand] <= budget - c @ w]
            if cand.size == 0:
                break
            Mc = (w @ Fflat).reshape(p, p)
            Ms = Mc[None] + prob.F[cand] + eps * prob.eye[None]
            if prob.crit is Criterion.D or w.sum() < p:
                _, ld = np.linalg.slogdet(Ms)
                score = -ld
            else:
                lam = np.linalg.eigvalsh(Ms)
                score = np.sum(1.0 / lam, axis=1) if prob.crit is Criterion.A else 1.0 / lam[:, 0]
            w[cand[int(np.argmin(score))]] = True
        return w

    w = fill(state == 1) if W0 is None else fill(W0.copy())
    if w.sum() < lo or c @ w > budget:
        return w, np.inf
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
            w2 = fill(w2)
        v2 = float(prob.exact(w2[None])[0])
        if not v2 < val:
            break
        w, val = w2, v2
    return w, val


def _proj_capped_simplex_batch(Y, free, r):
    """Row-wise projection onto ``{0 <= x_k <= 1 (k free), sum_free x = r}``.

    Parameters
    ----------
    Y : ndarray, shape (B, n)
    free : ndarray of bool, shape (B, n)
        Entries outside ``free`` are returned as 0.  Every row needs ``0 < r < free.sum()``.
    r : ndarray of int, shape (B,)

    Returns
    -------
    ndarray, shape (B, n)
        Exact (up to rounding): ``s(tau) = sum_j c_j (b_j - tau)_+`` over the breakpoints
        ``b = (y, y - 1)`` with signs ``c = (+1, -1)`` is evaluated at all sorted breakpoints
        by cumulative sums, and the root of ``s(tau) = r`` is interpolated on its piece.
    """
    B, n = Y.shape
    rf = r.astype(float)
    lo = np.min(np.where(free, Y, np.inf), axis=1)
    Yc = np.where(free, Y, (lo - 2.0)[:, None])  # non-free: below every relevant tau
    bp = np.concatenate([Yc, Yc - 1.0], axis=1)
    sg = np.concatenate([np.ones((B, n)), -np.ones((B, n))], axis=1)
    order = np.argsort(-bp, axis=1, kind="stable")
    b = np.take_along_axis(bp, order, axis=1)
    c = np.take_along_axis(sg, order, axis=1)
    C0 = np.cumsum(c, axis=1) - c  # exclusive sums over breakpoints above b_k
    C1 = np.cumsum(c * b, axis=1) - c * b
    s = C1 - C0 * b  # s at tau = b_k (nondecreasing in k)
    k = np.minimum(np.count_nonzero(s < rf[:, None], axis=1), 2 * n - 1)
    ar = np.arange(B)
    c0, c1 = C0[ar, k], C1[ar, k]
    with np.errstate(divide="ignore", invalid="ignore"):
        tau = np.where(c0 > 0, (c1 - rf) / np.where(c0 > 0, c0, 1.0), b[ar, k])
    return np.where(free, np.clip(Y - tau[:, None], 0.0, 1.0), 0.0)


def _rowwise_top(Q, free, r):
    """For each row: descending order of Q over ``free`` (non-free last), sorted values and top-r sum."""
    Qf = np.where(free, Q, -np.inf)
    order = np.argsort(-Qf, axis=1, kind="stable")
    Qs = np.take_along_axis(Qf, order, axis=1)
    cs = np.cumsum(np.where(np.isfinite(Qs), Qs, 0.0), axis=1)
    ar = np.arange(Q.shape[0])
    return order, Qs, cs[ar, r - 1]


def _budget_top(Q, free, r, costs, left, iters=40):
    r"""Upper bound on :math:`\max\{q^Tv:\ v\in[0,1]^{free},\ \sum v\le r,\ c^Tv\le b\}` per row.

    Lagrangian relaxation of the budget: for every :math:`\mu\ge0`

    .. math::  \max_{v} q^Tv \le \mu b + \textstyle\sum_{\text{top } r} (q_k - \mu c_k)_+ =: s(\mu),

    a convex piecewise-linear function of :math:`\mu` whose minimum is the LP value.  It is
    minimised by bisection on its slope :math:`b - \sum_{k\in\text{top}} c_k` over
    :math:`[0, \max_k q_k/c_k]`; every evaluated :math:`s(\mu)` is a valid bound and the
    smallest is returned with its multiplier (the relaxation's budget price, used to steer the
    relaxation point towards the budget).

    Parameters
    ----------
    Q : ndarray (B, n)
    free : ndarray of bool (B, n)
    r : ndarray of int (B,)      count still allowed (>= 1)
    costs : ndarray (n,)
    left : ndarray (B,)          budget still available (>= 0)
    """
    B, n = Q.shape
    ar = np.arange(B)[:, None]
    rr = np.minimum(r, free.sum(axis=1))

    def s_of(mu):
        d = np.where(free, np.maximum(Q - mu[:, None] * costs[None, :], 0.0), 0.0)
        ordd = np.argsort(-d, axis=1, kind="stable")
        ds = d[ar, ordd]
        sel = np.arange(n)[None, :] < rr[:, None]
        val = mu * left + np.where(sel, ds, 0.0).sum(axis=1)
        used = np.where(sel & (ds > 0), costs[ordd], 0.0).sum(axis=1)
        return val, left - used                       # s(mu) and its slope

    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(free & (costs[None, :] > 0), Q / costs[None, :], 0.0)
    lo = np.zeros(B)
    hi = np.maximum(ratio.max(axis=1), 0.0)
    best, _ = s_of(lo)
    mu_best = lo.copy()
    val, _ = s_of(hi)
    mu_best = np.where(val < best, hi, mu_best)
    best = np.minimum(best, val)
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        val, slope = s_of(mid)
        mu_best = np.where(val < best, mid, mu_best)
        best = np.minimum(best, val)
        up = slope < 0                                # s still decreasing: the minimum lies right
        lo = np.where(up, mid, lo)
        hi = np.where(up, hi, mid)
    return best, mu_best


def _e_bound_refine(Fflat, X, free, on, r, tE, iters):
    r"""Best E bound over ``Z = U diag(pi) U^T``, ``pi`` in the simplex, for a batch of nodes.

    With ``U`` the eigenvectors of :math:`M(x)` and :math:`c_{ki} = (u_i^Ta_k)^2`, every ``pi``
    gives the rigorous bound :math:`\lambda_{\min}(M(v)) \le s(\pi) = \max_{v\in P}\sum_k v_k
    \sum_i \pi_i c_{ki}` (a fixed-in sum plus a top-r sum over the free sensors).  ``s`` is convex
    and piecewise linear in ``pi``; a subgradient is :math:`\sum_{k\in\text{top}} c_{k\cdot}`.
    Minimised by exponentiated subgradient steps (the minimum equals the eigenvector-cut LP
    :math:`\max t\ \text{s.t.}\ t\le\sum_k v_kc_{ki}\ \forall i,\ v\in P`).

    Parameters
    ----------
    Fflat : ndarray, shape (n, p*p)
        The flattened :math:`F_k`.
    X : ndarray, shape (B, n)
        Relaxed points (only used to build ``U``).
    free, on : ndarray of bool, shape (B, n)
    r : ndarray of int, shape (B,)
        Number of free sensors still to choose (``1 <= r < free.sum()``).
    tE : ndarray, shape (B,)
        Soft-min sharpness: the start is the soft-min weighting ``pi_i ~ exp(-tE (lam_i - lam_1))``.
    iters : int

    Returns
    -------
    ndarray, shape (B,)
        The smallest ``s(pi)`` seen (an upper bound on :math:`\lambda_{\min}` over the node).
    """
    B, n = X.shape
    p = int(round(np.sqrt(Fflat.shape[1])))
    lam, U = np.linalg.eigh((X @ Fflat).reshape(B, p, p))
    UU = np.einsum("bai,bci->biac", U, U).reshape(B, p, p * p)
    C = (UU @ Fflat.T).transpose(0, 2, 1)  # (B, n, p): u_i^T F_k u_i
    Con = np.einsum("bk,bki->bi", on.astype(float), C)
    pi = np.exp(-tE[:, None] * (lam - lam[:, :1]))
    pi = pi / pi.sum(axis=1, keepdims=True)
    pi = 0.9 * pi + 0.1 / p  # keep every direction alive for the multiplicative updates
    best = np.full(B, np.inf)
    ar = np.arange(B)
    rmax = int(r.max())
    for t in range(max(iters, 1)):
        c = np.einsum("bki,bi->bk", C, pi)
        c = np.where(free, c, -np.inf)
        idx = np.argpartition(-c, rmax - 1, axis=1)[:, :rmax] if rmax < n else np.argsort(-c, axis=1)
        cv = np.take_along_axis(c, idx, axis=1)
        o = np.argsort(-cv, axis=1, kind="stable")
        idx = np.take_along_axis(idx, o, axis=1)
        sel = np.arange(idx.shape[1])[None, :] < r[:, None]
        Ct = C[ar[:, None], idx]  # (B, rmax, p)
        g = Con + np.einsum("bk,bki->bi", sel.astype(float), Ct)
        s = np.einsum("bi,bi->b", g, pi)
        best = np.minimum(best, s)
        gs = g / np.maximum(s, 1e-300)[:, None]
        eta = 2.0 / np.sqrt(t + 1.0)
        z = -eta * (gs - gs.min(axis=1, keepdims=True))
        pi = pi * np.exp(z)
        pi /= pi.sum(axis=1, keepdims=True)
    return best


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
    prob = _Problem(F, crit, settings, criteria_settings)
    n, p = prob.n, prob.p
    m = cons.max_size  # monotonicity: the largest admissible size is optimal for GN criteria
    state0 = np.full(n, -1, dtype=np.int8)
    state0[list(cons.include)] = 1
    state0[list(cons.exclude)] = 0
    bud = cons.costs is not None
    if bud:
        # with a budget the count is lo <= sum w <= m (the budget may stop a design short of m)
        costs = np.asarray(cons.costs, float)
        budget = cons.budget * (1 + 1e-12) + 1e-12          # the tolerance of DesignConstraints
        lo = cons.min_size
        state0[(state0 == -1) & (costs > budget - costs @ (state0 == 1))] = 0
    else:
        costs, budget, lo = None, np.inf, 0

    # feasibility: all available sensors must give a regular information matrix
    avail = state0 != 0
    if np.isinf(prob.exact(avail[None])[0]):
        return BnBResult(None, np.inf, np.inf, np.inf, "infeasible", 0, time.perf_counter() - t0, np.inf, np.inf)

    inc = {}
    inc["w"], inc["v"] = greedy_exchange(prob, state0, m, costs=costs, budget=budget, lo=lo)
    init_inc = inc["v"]
    isE = crit is Criterion.E
    betas = tuple(settings.e_betas) if isE else (None,)
    floorD = 1.0 if crit is Criterion.D else 0.0

    def thr():
        return inc["v"] - prob.tol(inc["v"])

    def offer(W):
        """Exact values of designs W (b, n); update the incumbent; returns the values."""
        v = prob.exact(W)
        j = int(np.argmin(v))
        if v[j] < inc["v"]:
            inc["w"], inc["v"] = W[j].copy(), float(v[j])
        return v

    def rsel(on, fr):
        """Free sensors the relaxation selects: m - |on| (with a budget at most |free| - 1; any
        relaxed point gives valid bounds, the budget enters through :func:`_budget_top`)."""
        r = m - on.sum(axis=1)
        return np.minimum(r, fr.sum(axis=1) - 1) if bud else r

    def relax(S, X0, iters, root, lb0, mu0=None):
        """Solve the relaxations of the nodes S (B, n) (-1 free, 0 out, 1 in) together.

        ``lb0``: bounds known beforehand (the parents'); ``mu0``: the parents' budget prices.
        Returns (lb, X, S, mu) for the nodes that are neither pruned nor leaves."""
        S = S.copy()
        B = S.shape[0]
        best = np.array(lb0, dtype=float)
        keep = np.ones(B, dtype=bool)
        X = np.zeros((B, n))
        f = np.full(B, np.inf)
        Q = np.zeros((B, n))
        primal = np.full(B, np.inf)
        alpha = np.ones(B)
        fhist = np.full((B, max(1, settings.nonmonotone)), np.inf)
        tE = np.ones(B)
        stage = np.zeros(B, dtype=int)
        sit = np.zeros(B, dtype=int)
        n_it = max(iters // len(betas), 5) if isE else iters
        act = np.ones(B, dtype=bool)
        # budget price (inherited from the parent): the relaxation minimises phi(x) + mu c^T x
        mu = np.zeros(B) if mu0 is None else np.array(mu0, dtype=float)

        def screen(I):
            """Drop infeasible rows, evaluate leaves; returns the rows of I still to be solved."""
            if bud:
                return screen_budget(I)
            fr = S[I] == -1
            on = S[I] == 1
            r = m - on.sum(axis=1)
            nf = fr.sum(axis=1)
            bad = (r < 0) | (r > nf)
            leaf = ~bad & ((r == 0) | (r == nf))
            if leaf.any():
                offer(on[leaf] | (fr[leaf] & (r[leaf] == nf[leaf])[:, None]))
            gone = bad | leaf
            keep[I[gone]] = False
            act[I[gone]] = False
            return I[~gone]

        def screen_budget(I):
            """:func:`screen` with a budget: free sensors that no longer fit are fixed out; a node
            is infeasible when its count or budget is exceeded or ``lo`` is out of reach, and a
            leaf when nothing is free, the count is full, or all free sensors fit (then taking all
            of them is best, by monotonicity)."""
            on = S[I] == 1
            left = budget - on @ costs
            SI = S[I]
            SI[(SI == -1) & (costs[None, :] > left[:, None])] = 0
            S[I] = SI
            fr = SI == -1
            n_on = on.sum(axis=1)
            r = m - n_on
            nf = fr.sum(axis=1)
            need = np.maximum(lo - n_on, 0)
            cheap = np.sort(np.where(fr, costs[None, :], np.inf), axis=1)
            cum = np.concatenate([np.zeros((I.size, 1)), np.cumsum(cheap, axis=1)], axis=1)
            reach = cum[np.arange(I.size), np.minimum(need, n)]
            bad = (r < 0) | (left < 0) | (need > nf) | ~(reach <= left)
            allfit = (nf <= r) & ((fr * costs[None, :]).sum(axis=1) <= left)
            leaf = ~bad & ((nf == 0) | (r == 0) | allfit)
            if leaf.any():
                offer(on[leaf] | (fr[leaf] & allfit[leaf][:, None]))
            gone = bad | leaf
            keep[I[gone]] = False
            act[I[gone]] = False
            return I[~gone]

        def start(I, Xs, keep_alpha=False):
            """(Re)initialise rows I from warm starts Xs (projected onto the node polytope)."""
            if I.size == 0:
                return
            fr = S[I] == -1
            on = S[I] == 1
            r = rsel(on, fr)
            nf = fr.sum(axis=1)
            uni = np.where(fr, (r / nf)[:, None], 0.0) + on
            Xi = uni if Xs is None else _proj_capped_simplex_batch(Xs, fr, r) + on
            if isE:
                lam0 = np.linalg.eigvalsh((Xi @ prob.Fflat).reshape(-1, p, p))[:, 0]
                badx = lam0 <= 0
                Xi[badx] = uni[badx]
                lam0[badx] = np.linalg.eigvalsh((Xi[badx] @ prob.Fflat).reshape(-1, p, p))[:, 0]
                tE[I] = np.array(betas)[stage[I]] / np.maximum(lam0, 1e-300)
            fi, qi, pi = prob.smooth_batch(Xi, tE[I])
            badf = ~np.isfinite(fi)
            if badf.any():
                Xi[badf] = uni[badf]
                fi[badf], qi[badf], pi[badf] = prob.smooth_batch(Xi[badf], tE[I][badf])
                still = ~np.isfinite(fi)
                if still.any():
                    # singular even at the uniform point: prune only if the exact criterion of the
                    # largest design of the node is infinite; otherwise keep it unbounded (branch on).
                    full = (S[I][still] != 0)
                    dead = np.isinf(prob.exact(full))
                    rows = I[still]
                    keep[rows[dead]] = False
                    act[rows] = False
                    X[rows] = Xi[still]
            X[I], f[I], Q[I], primal[I] = Xi, fi, qi, pi
            fhist[I] = fi[:, None]
            if not keep_alpha:
                qn = np.linalg.norm(np.where(fr, qi, 0.0), axis=1)
                alpha[I] = 1.0 / np.maximum(np.where(np.isfinite(qn), qn, 1.0), 1e-300)
            sit[I] = 0

        I0 = screen(np.arange(B))
        start(I0, None if X0 is None else X0[I0])
        while True:
            I = np.flatnonzero(act)
            if I.size == 0:
                break
            fr = S[I] == -1
            on = S[I] == 1
            r = rsel(on, fr)
            QI = Q[I]
            if bud:
                top, mu_new = _budget_top(QI, fr, m - on.sum(axis=1), costs, budget - on @ costs)
                if settings.budget_steering:
                    # where the price changed, restart the line-search memory at the penalised value
                    chg = np.abs(mu_new - mu[I]) > 1e-3 * np.maximum(np.abs(mu[I]), 1e-300)
                    mu[I] = mu_new
                    Ic = I[chg]
                    fhist[Ic] = (f[Ic] + mu[Ic] * (X[Ic] @ costs))[:, None]
            else:
                order, Qs, top = _rowwise_top(QI, fr, r)
            s = np.where(on, QI, 0.0).sum(axis=1) + top
            fI = f[I]
            lb = prob.bound_from_s(fI, s)
            best[I] = np.maximum(best[I], lb)
            th = thr()
            pruned = best[I] >= th
            keep[I[pruned]] = False
            act[I[pruned]] = False
            fixed = np.zeros(I.size, dtype=bool)
            if np.isfinite(inc["v"]) and not bud:
                ar = np.arange(I.size)
                q_r = Qs[ar, r - 1]
                q_r1 = Qs[ar, r]
                rank = np.empty_like(order)
                np.put_along_axis(rank, order, np.arange(n)[None, :].repeat(I.size, 0), axis=1)
                chosen = rank < r[:, None]
                with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                    lb_in = prob.bound_from_s(fI[:, None], (s - q_r)[:, None] + QI)
                    lb_out = prob.bound_from_s(fI[:, None], (s + q_r1)[:, None] - QI)
                fix0 = fr & ~chosen & (lb_in >= th)
                fix1 = fr & chosen & (lb_out >= th)
                fixed = (fix0 | fix1).any(axis=1) & ~pruned
                if fixed.any():
                    J = I[fixed]
                    SJ = S[J]
                    SJ[fix0[fixed]] = 0
                    SJ[fix1[fixed]] = 1
                    S[J] = SJ
                    J2 = screen(J)
                    start(J2, X[J2])
            # stage end: relaxation gap closed, early branching, iteration limit
            cont = ~pruned & ~fixed
            pI = primal[I]
            with np.errstate(invalid="ignore"):
                gapok = np.isfinite(pI) & (pI - lb <= 1e-7 * np.maximum(np.abs(pI), floorD))
            # (with a budget the relaxed point may exceed the budget, so primal < th proves nothing)
            eb = (settings.early_branch and not root) & (sit[I] >= settings.early_branch_min_iters) & (pI < th)
            end = cont & (gapok | eb | (sit[I] >= n_it))
            J = I[cont & ~end]
            if J.size:
                frJ = S[J] == -1
                onJ = (S[J] == 1).astype(float)
                rJ = rsel(onJ, frJ)
                QJ = Q[J] - mu[J, None] * costs[None, :] if bud else Q[J]     # -grad of phi + mu c^T x
                Y = _proj_capped_simplex_batch(X[J] + alpha[J, None] * QJ, frJ, rJ) + onJ
                Dd = Y - X[J]
                dn = np.einsum("ij,ij->i", Dd, Dd)
                slope = -np.einsum("ij,ij->i", QJ, Dd)
                lam_s = np.ones(J.size)
                ok = dn >= 1e-24
                stuck = ~ok
                pend = np.flatnonzero(ok)
                fnew = np.empty(J.size)
                fpen = np.empty(J.size)
                qnew = np.empty((J.size, n))
                pnew = np.empty(J.size)
                while pend.size:
                    Xn = X[J[pend]] + lam_s[pend, None] * Dd[pend]
                    fn, qn, pn = prob.smooth_batch(Xn, tE[J[pend]])
                    fp = fn + mu[J[pend]] * (Xn @ costs) if bud else fn
                    fref = fhist[J[pend]].max(axis=1)  # non-monotone (GLL) reference value
                    acc = np.isfinite(fp) & (fp <= fref + 1e-4 * lam_s[pend] * slope[pend])
                    a = pend[acc]
                    fnew[a], qnew[a], pnew[a], fpen[a] = fn[acc], qn[acc], pn[acc], fp[acc]
                    rest = pend[~acc]
                    lam_s[rest] *= 0.5
                    fail = lam_s[rest] < 1e-8
                    stuck[rest[fail]] = True
                    pend = rest[~fail]
                good = ~stuck
                Jg = J[good]
                if Jg.size:
                    sv = lam_s[good, None] * Dd[good]
                    yv = -(qnew[good] - Q[Jg]) * frJ[good]
                    sy = np.einsum("ij,ij->i", sv, yv)
                    ss = np.einsum("ij,ij->i", sv, sv)
                    qnorm = np.linalg.norm(Q[Jg] * frJ[good], axis=1)
                    with np.errstate(divide="ignore", invalid="ignore"):
                        a_new = np.where(sy > 1e-300, ss / np.where(sy > 1e-300, sy, 1.0), alpha[Jg] * 4.0)
                    alpha[Jg] = np.minimum(np.maximum(a_new, 1e-12 / np.maximum(qnorm, 1e-300)), 1e12)
                    X[Jg] = X[Jg] + sv
                    f[Jg], Q[Jg], primal[Jg] = fnew[good], qnew[good], pnew[good]
                    fhist[Jg] = np.concatenate([fhist[Jg][:, 1:], fpen[good][:, None]], axis=1)
                    sit[Jg] += 1
                end_idx = np.concatenate([I[end], J[stuck]])
            else:
                end_idx = I[end]
            if isE and eb.any():
                # early branching ends the node in every stage: no Z can give a bound above the
                # relaxation optimum, which is <= primal < incumbent - tol.
                act[I[cont & eb]] = False
                end_idx = end_idx[act[end_idx]]
            if end_idx.size:
                if isE:
                    nxt = end_idx[stage[end_idx] + 1 < len(betas)]
                    fin = end_idx[stage[end_idx] + 1 >= len(betas)]
                    stage[nxt] += 1
                    start(nxt, X[nxt], keep_alpha=True)
                    R = fin[keep[fin]]
                    if settings.e_refine_iters > 0 and R.size and not bud:
                        onR = S[R] == 1
                        sR = _e_bound_refine(prob.Fflat, X[R], S[R] == -1, onR, m - onR.sum(axis=1), tE[R],
                                             settings.e_refine_iters)
                        best[R] = np.maximum(best[R], prob.bound_from_s(None, sR))
                        keep[R[best[R] >= thr()]] = False
                else:
                    fin = end_idx
                act[fin] = False
        K = np.flatnonzero(keep)
        if K.size:
            # rounding heuristic (+ exchange from the rounded point when it improves)
            fr = S[K] == -1
            r = m - (S[K] == 1).sum(axis=1)
            order = np.argsort(-np.where(fr, X[K], -np.inf), axis=1, kind="stable")
            W = S[K] == 1
            if bud:
                # take free sensors by decreasing relaxed value while the count and budget allow
                left = budget - W @ costs
                cnt = r.copy()
                ar = np.arange(K.size)
                for col in range(n):
                    k = order[:, col]
                    add = fr[ar, k] & (cnt > 0) & (costs[k] <= left)
                    W[ar[add], k[add]] = True
                    left[add] -= costs[k[add]]
                    cnt[add] -= 1
                W = W[W.sum(axis=1) >= lo]
            else:
                sel = np.arange(n)[None, :] < r[:, None]
                np.put_along_axis(W, order, np.take_along_axis(W, order, axis=1) | sel, axis=1)
            old = inc["v"]
            v = prob.exact(W) if len(W) else np.full(1, np.inf)
            j = int(np.argmin(v))
            if v[j] < old:
                w2, v2 = greedy_exchange(prob, state0, m, W0=W[j], costs=costs, budget=budget, lo=lo)
                inc["w"], inc["v"] = (w2, v2) if v2 < v[j] else (W[j].copy(), float(v[j]))
        return best[K], X[K], S[K], mu[K]

    lb, x, st, mu_r = relax(state0[None], None, settings.root_iters, True, [-np.inf])
    nodes = 1
    counter = 0
    heap = []
    root_bound = float(lb[0]) if lb.size and np.isfinite(lb[0]) else inc["v"]
    status = "optimal"
    if lb.size:
        heapq.heappush(heap, (float(lb[0]), counter, st[0], x[0], mu_r[0]))
    while heap:
        th = thr()
        if heap[0][0] >= th:
            heap = []
            break
        if time.perf_counter() - t0 > settings.time_limit:
            status = "time_limit"
            break
        if settings.node_limit is not None and nodes >= settings.node_limit:
            status = "node_limit"
            break
        nb = max(1, settings.batch_size)
        if settings.node_limit is not None:
            nb = max(1, min(nb, (settings.node_limit - nodes) // 2))
        parents = []
        while heap and len(parents) < nb and heap[0][0] < th:
            parents.append(heapq.heappop(heap))
        S_c, X_c, lb_p, mu_p = [], [], [], []
        for plb, _, pst, px, pmu in parents:
            free = np.flatnonzero(pst == -1)
            k = free[int(np.argmin(np.abs(px[free] - settings.branch_target)))]
            for val in (1, 0):
                child = pst.copy()
                child[k] = val
                S_c.append(child)
                X_c.append(px)
                mu_p.append(pmu)
                lb_p.append(plb)
        clb, cx, cst, cmu = relax(np.array(S_c), np.array(X_c), settings.node_iters, False, lb_p, mu_p)
        nodes += len(S_c)
        th = thr()
        for i in range(clb.size):
            if clb[i] < th:
                counter += 1
                heapq.heappush(heap, (float(clb[i]), counter, cst[i], cx[i], cmu[i]))
    glb = min([h[0] for h in heap], default=inc["v"])
    glb = min(glb, inc["v"])
    gap = inc["v"] - glb
    if status == "optimal" and not np.isfinite(inc["v"]):
        status = "infeasible"
    return BnBResult(w=inc["w"], value=inc["v"], lower_bound=glb, gap=gap, status=status, nodes=nodes,
                     wall_time=time.perf_counter() - t0, root_bound=root_bound, initial_incumbent=init_inc)
