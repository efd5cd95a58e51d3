r"""Branch-and-bound with proven gaps for exact n-run designs under a prior (issue 31 item 4).

For candidates c with information :math:`F_{c,s}` at the prior's parameter vectors :math:`P_s` and a set
:math:`S` of ``n`` candidates, :math:`M_s(S) = \frac1n\sum_{c\in S}F_{c,s}`; solved:

.. math::

    \max_{|S| = n} \Phi(S),\qquad \Phi = \sum_s \pi_s u_s(M_s(S))\ (\text{bayes})\ \text{ or }\
    \min_s c_s(M_s(S))\ (\text{maximin}),

with :math:`u_D = \log\det M`, :math:`u_A = -\operatorname{tr}M^{-1}`, :math:`u_E = -1/\lambda_{\min}(M)` and the
standardized :math:`c_s` of :mod:`oed.robust` (D: :math:`(u_s - u^*_s)/n_p`; A, E: :math:`u_s/|u^*_s|`, both
increasing in :math:`u_s`).

**Node bounds.**  A node fixes candidates in (``I``) and out; every set of the node is :math:`I\cup T`, ``T``
``r`` of the free candidates ``R``.  Its relaxation is the polytope
:math:`P = \{v\in[0,1]^C: v_I = 1,\ v_{out} = 0,\ \sum_R v = r\}`.  At any relaxed point ``x`` with
:math:`X_s = M_s(x)\succ 0` the per-sample bounds of the local branch-and-bound (:mod:`oed.bnb`) hold for
every :math:`v\in P`:

* D: :math:`u_s(M_s(v)) \le \log\det X_s - n_p + \operatorname{tr}(X_s^{-1}M_s(v))` (concavity of log det);
* A: :math:`u_s(M_s(v)) \le -2\operatorname{tr}X_s^{-1} + \operatorname{tr}(X_s^{-2}M_s(v))`;
* E: :math:`\lambda_{\min}(M_s(v)) \le t_s(v) = z_s^TM_s(v)z_s` (``z_s`` the unit eigenvector of
  :math:`\lambda_{\min}(X_s)`), so :math:`u_s \le -1/t_s` (:math:`-\infty` where :math:`t_s\le 0`), and by
  concavity of :math:`-1/t` the affine :math:`u_s \le -2/t_0 + t_s(v)/t_0^2`, :math:`t_0 = \lambda_{\min}(X_s)`.

Each right-hand side is affine in ``v`` (E's first one through :math:`t_s`), so its maximum over ``P`` is a
fixed-in sum plus a top-``r`` sum over the free candidates: :math:`B_s` (the smaller of E's two) bounds
:math:`u_s` over the node.  Then

* bayes: :math:`\Phi \le \sum_s\pi_s B_s` (the sum of per-sample bounds) and
  :math:`\Phi \le \max_{v\in P}\sum_s\pi_s(\text{affine}_s(v))` (one top-``r`` sum of the prior-averaged
  linear form, never above the sum of the affine per-sample maxima); the smaller is kept;
* maximin: :math:`\Phi \le \min_s c_s(B_s)` (the minimum of the per-sample bounds) and
  :math:`\Phi\le\max_{v\in P}\sum_s\mu_s c_s(\text{affine}_s(v))` for the soft-min weights :math:`\mu` of the
  relaxed point (:math:`\min_s c_s \le \sum_s\mu_s c_s`); the smaller is kept.

Every relaxed point gives valid bounds, and a child keeps its parent's bound when that is smaller.  The
relaxed points come from monotone projected-gradient ascent (the projection of :mod:`oed.bnb.projection`) of
:math:`\sum_s\pi_su_s` (bayes) or of the soft-min :math:`-\frac1\beta\log\sum_se^{-\beta c_s}` (maximin) over
``P``, warm-started from the parent.  Incumbents: the rounded relaxations (top-``r`` free candidates) and a
best-improvement exchange from the root's.  Search: best bound first, branching on the free candidate whose
relaxed value is closest to 1/2; a node is pruned when its bound is at most incumbent + tol,
:math:`\text{tol} = \text{gap\_tol}\cdot\max(1, |\Phi_{inc}|)`.  The exact value of a set is the one complete
enumeration computes (:func:`robust_set_values`), so both routes report the same numbers.
"""
from __future__ import annotations

import heapq
import time
from dataclasses import dataclass

import numpy as np

from .approx_weights import standardized
from .bnb.projection import proj_capped_simplex_batch
from .criteria import Criterion
from .robust import utilities

__all__ = ["robust_set_values", "RobustBnBSettings", "RobustBnBResult", "robust_branch_and_bound"]

#: soft-min sharpness of the maximin relaxation (on the standardized utilities)
MAXIMIN_BETA = 200.0


def robust_set_values(crit: Criterion, F, combos, n: int, w, robust: str, u_star):
    r"""(:math:`\Phi` per set, utilities (B, n_s)) of a batch of sets ``combos`` (B, n) of candidate indices:
    :math:`M_s = \frac1n\sum_{c}F_{c,s}`, bayes :math:`\sum_s\pi_su_s` (``-inf`` when a :math:`M_s` is
    singular), maximin :math:`\min_s c_s`."""
    M = F[combos].sum(axis=1) / n                                   # (B, n_s, p, p)
    B, n_s, p = M.shape[0], M.shape[1], M.shape[2]
    u = utilities(crit, M.reshape(B * n_s, p, p)).u.reshape(B, n_s)
    if robust == "bayes":
        with np.errstate(invalid="ignore"):
            return np.where(np.all(np.isfinite(u), axis=1), u @ w, -np.inf), u
    c, _ = standardized(crit, u, u_star, p)
    return np.min(c, axis=1), u


@dataclass(frozen=True)
class RobustBnBSettings:
    """Settings of :func:`robust_branch_and_bound`.

    Attributes
    ----------
    time_limit : float
        Wall-clock seconds (checked between batches of nodes).
    gap_tol : float
        Nodes whose bound is at most incumbent + gap_tol * max(1, |incumbent|) are pruned.
    root_iters, node_iters : int
        Projected-gradient steps of the relaxation at the root / at other nodes.
    node_limit : int or None
    batch_size : int
        Best-bound nodes branched together (their children relaxed together).
    """

    time_limit: float = 60.0
    gap_tol: float = 1e-9
    root_iters: int = 300
    node_iters: int = 25
    node_limit: int | None = None
    batch_size: int = 64

    def __post_init__(self):
        if isinstance(self.time_limit, bool) or not (isinstance(self.time_limit, (int, float)) and self.time_limit > 0):
            raise ValueError(f"time_limit: expected seconds > 0, got {self.time_limit!r}")
        if not (isinstance(self.gap_tol, (int, float)) and 0 <= self.gap_tol < np.inf):
            raise ValueError(f"gap_tol: expected a finite number >= 0, got {self.gap_tol!r}")
        for name in ("root_iters", "node_iters", "batch_size"):
            v = getattr(self, name)
            if isinstance(v, bool) or not (isinstance(v, (int, np.integer)) and v >= 1):
                raise ValueError(f"{name}: expected an integer >= 1, got {v!r}")
        if self.node_limit is not None and not (isinstance(self.node_limit, (int, np.integer)) and self.node_limit >= 1):
            raise ValueError(f"node_limit: expected None or an integer >= 1, got {self.node_limit!r}")


@dataclass(frozen=True)
class RobustBnBResult:
    """Outcome of :func:`robust_branch_and_bound`.

    Attributes
    ----------
    indices : ndarray of int or None
        The best set found (None: no set with a finite criterion).
    value : float
        Its :math:`\\Phi` (``-inf`` without one).
    upper_bound : float
        Proven: no set has :math:`\\Phi` above it.
    gap : float
        upper_bound - value (0 when proven).
    status : str
        "optimal", "time_limit", "node_limit" or "infeasible".
    nodes, n_evaluated : int
        Relaxed nodes; sets evaluated exactly.
    root_bound : float
    wall_time : float
    """

    indices: np.ndarray | None
    value: float
    upper_bound: float
    gap: float
    status: str
    nodes: int
    n_evaluated: int
    root_bound: float
    wall_time: float


class RobustProblem:
    """The data of one search: per-run information scaled by 1/n, flattened for batched products, the
    criterion, the prior weights and the maximin standardization."""

    def __init__(self, F, w, n, crit: Criterion, robust: str, u_star, gap_tol: float):
        self.F = F
        self.C, self.S, self.p = F.shape[0], F.shape[1], F.shape[2]
        self.Fn = (F / n).reshape(self.C, self.S * self.p * self.p)
        self.Fs = (F / n).reshape(self.C, self.S, self.p * self.p)
        self.n, self.w, self.crit, self.robust = n, w, crit, robust
        self.u_star = None if u_star is None else np.asarray(u_star, float)
        if robust == "maximin":
            self.kappa = standardized(crit, np.zeros(self.S), self.u_star, self.p)[1]
        self.gap_tol = gap_tol
        self.evaluated = 0

    def exact(self, sets):
        """:math:`\\Phi` of the sets (B, n) of indices."""
        self.evaluated += len(sets)
        return robust_set_values(self.crit, self.F, sets, self.n, self.w, self.robust, self.u_star)[0]

    def std(self, u):
        """Standardized utilities c_s of utilities u (..., n_s) (maximin)."""
        return standardized(self.crit, u, self.u_star, self.p)[0]

    def tol(self, v):
        """Pruning tolerance at the incumbent value v."""
        return 0.0 if not np.isfinite(v) else self.gap_tol * max(1.0, abs(v))


def _top_sum(Q, free, on, r):
    """Fixed-in sum plus the top-r sum over the free candidates of Q (B, C[, k]) per row (and column)."""
    fixed = np.einsum("bc...,bc->b...", Q, on.astype(float))
    ext = free if Q.ndim == 2 else free[:, :, None]
    Qs = -np.sort(-np.where(ext, Q, -np.inf), axis=1)
    take = np.arange(Q.shape[1])[None, :] < r[:, None]
    if Q.ndim == 3:
        take = take[:, :, None]
    return fixed + np.where(take & np.isfinite(Qs), Qs, 0.0).sum(axis=1)


@dataclass(frozen=True)
class _Point:
    """Relaxation data at points X (B, C): objective, ascent direction, upper bound over the node."""

    obj: np.ndarray
    grad: np.ndarray
    bound: np.ndarray


def evaluate_points(prob: RobustProblem, X, free, on, r) -> _Point:
    """Objective (bayes: :math:`\\sum\\pi_su_s`; maximin: the soft-min of c_s), its gradient in x and the node
    bound (module docstring) at the relaxed points X (B, C) of nodes (free, on, r)."""
    B, S, p = X.shape[0], prob.S, prob.p
    M = (X @ prob.Fn).reshape(B * S, p, p)
    lam, V = np.linalg.eigh(0.5 * (M + np.swapaxes(M, 1, 2)))
    ok = (lam[:, 0] > 0).reshape(B, S)
    lam_s = np.where(lam > 0, lam, 1.0)
    crit = prob.crit
    if crit is Criterion.D:
        u, a, scale = np.log(lam_s).sum(1), np.log(lam_s).sum(1) - p, 1.0 / lam_s
    elif crit is Criterion.A:
        u = -(1.0 / lam_s).sum(1)
        a, scale = 2.0 * u, 1.0 / lam_s ** 2
    else:
        u, a = -1.0 / lam_s[:, 0], None
        scale = np.zeros_like(lam_s)
        scale[:, 0] = 1.0
    G = np.einsum("kia,ka,kja->kij", V, scale, V).reshape(B, S, p * p)
    q = np.einsum("bsk,csk->bcs", G, prob.Fs)                      # (B, C, S): tr(G_s F_cs)/n (E: z^T F z / n)
    u = np.where(ok, u.reshape(B, S), -np.inf)
    allok = ok.all(axis=1)
    if crit is Criterion.E:     # tangent of -1/t at t0 = lambda_min(X_s): -1/t <= -2/t0 + t/t0^2
        l1 = lam_s[:, 0].reshape(B, 1, S)
        a, qa = -2.0 / l1[:, 0], q / l1 ** 2
    else:
        a, qa = a.reshape(B, S), q
    Bs = a + _top_sum(qa, free, on, r)                             # per-sample maxima of the affine bounds
    if crit is Criterion.E:                                        # and of -1/t_s, t_s >= lambda_min on the node
        t = _top_sum(q, free, on, r)
        with np.errstate(divide="ignore"):
            Bs = np.minimum(Bs, np.where(t > 0, -1.0 / np.where(t > 0, t, 1.0), -np.inf))
    if prob.robust == "bayes":
        obj = np.where(allok, np.where(ok, u, 0.0) @ prob.w, -np.inf)
        grad = qa @ prob.w
        # the sum of the per-sample bounds (-inf when one sample is singular on the whole node), and the maximum of
        # the prior-averaged affine bound (one top-r sum)
        per = np.where(np.isneginf(Bs).any(axis=1), -np.inf, np.where(np.isfinite(Bs), Bs, 0.0) @ prob.w)
        bound = np.minimum(per, a @ prob.w + _top_sum(qa @ prob.w, free, on, r))
    else:
        c = np.where(ok, prob.std(np.where(ok, u, 0.0)), np.inf)
        cmin = c.min(axis=1, keepdims=True)
        e = np.exp(-MAXIMIN_BETA * (c - np.where(np.isfinite(cmin), cmin, 0.0)))
        e[~allok] = 1.0                                            # (rows without a tangent: unused)
        mu = e / e.sum(axis=1, keepdims=True)
        obj = np.where(allok, cmin[:, 0] - np.log(e.sum(axis=1)) / MAXIMIN_BETA, -np.inf)
        grad = np.einsum("bcs,bs->bc", qa, mu * prob.kappa)
        off = prob.std(a) - prob.kappa * a                          # c_s(u) = kappa_s u + off_s
        joint = np.einsum("bs,bs->b", mu, off + prob.kappa * a) + _top_sum(grad, free, on, r)
        bound = np.minimum(prob.std(Bs).min(axis=1), joint)
    bound = np.where(allok, bound, np.inf)                         # no tangent: no bound from this point
    return _Point(obj=obj, grad=np.where(allok[:, None], grad, 0.0), bound=bound)


def relax(prob: RobustProblem, S, X0, iters: int, prune_at: float):
    """Monotone projected-gradient ascent on the nodes S (B, C) (-1 free, 0 out, 1 in) from X0 (None: uniform):
    (best bound per node, relaxed points).  Rows stop once their bound is at most ``prune_at``."""
    free, on = S == -1, S == 1
    r = prob.n - on.sum(axis=1)
    nf = free.sum(axis=1)
    uni = np.where(free, (r / nf)[:, None], 0.0) + on
    X = uni if X0 is None else proj_capped_simplex_batch(X0, free, r) + on
    pt = evaluate_points(prob, X, free, on, r)
    bad = ~np.isfinite(pt.obj)
    if bad.any():                                                  # restart from the uniform point
        X[bad] = uni[bad]
        pt2 = evaluate_points(prob, X[bad], free[bad], on[bad], r[bad])
        pt = _Point(obj=_scatter(pt.obj, pt2.obj, bad), grad=_scatter(pt.grad, pt2.grad, bad),
                    bound=_scatter(pt.bound, pt2.bound, bad))
        # singular at the uniform point of the node: singular for every set of the node (same null space)
        pt.bound[bad & ~np.isfinite(pt.obj)] = -np.inf
    best = pt.bound.copy()
    obj, grad = pt.obj.copy(), pt.grad.copy()
    gn = np.linalg.norm(np.where(free, grad, 0.0), axis=1)
    alpha = 1.0 / np.maximum(gn, 1e-300)
    act = np.isfinite(obj) & (best > prune_at)
    for _ in range(iters):
        I = np.flatnonzero(act)
        if I.size == 0:
            break
        Y = proj_capped_simplex_batch(X[I] + alpha[I, None] * grad[I], free[I], r[I]) + on[I]
        p2 = evaluate_points(prob, Y, free[I], on[I], r[I])
        best[I] = np.minimum(best[I], p2.bound)
        up = p2.obj > obj[I]
        J = I[up]
        X[J], obj[J], grad[J] = Y[up], p2.obj[up], p2.grad[up]
        alpha[J] *= 2.0
        alpha[I[~up]] *= 0.25
        act[I] = (best[I] > prune_at) & (alpha[I] > 1e-12 / np.maximum(gn[I], 1e-300)) & (
            best[I] - obj[I] > 1e-9 * np.maximum(1.0, np.abs(obj[I])))
    return best, X


def _scatter(f, g, mask):
    """f with its rows ``mask`` replaced by g (g has one row per True of mask)."""
    out = f.copy()
    out[mask] = g
    return out


class _Incumbent:
    """Best set found: indices (sorted) and value."""

    def __init__(self, prob: RobustProblem):
        self.prob = prob
        self.set, self.v = None, -np.inf

    def offer(self, sets):
        """Evaluate the sets (B, n) exactly; keep the best if it improves."""
        if len(sets) == 0:
            return
        sets = np.sort(np.asarray(sets, int), axis=1)
        v = self.prob.exact(sets)
        j = int(np.argmax(v))
        if v[j] > self.v:
            self.set, self.v = sets[j].copy(), float(v[j])

    def threshold(self) -> float:
        """Nodes whose bound is at most this cannot improve the incumbent beyond the tolerance."""
        return self.v + self.prob.tol(self.v)

    def exchange(self, max_passes: int = 100):
        """Best-improvement one-for-one exchange from the incumbent until no swap improves it."""
        prob = self.prob
        for _ in range(max_passes):
            if self.set is None:
                return
            outs = np.setdiff1d(np.arange(prob.C), self.set)
            if outs.size == 0:
                return
            cand = np.repeat(self.set[None], self.set.size * outs.size, axis=0)
            cand[np.arange(cand.shape[0]), np.repeat(np.arange(self.set.size), outs.size)] = np.tile(outs,
                                                                                                   self.set.size)
            old = self.v
            self.offer(cand)
            if not self.v > old + prob.tol(old):
                return


def _round(X, S, n):
    """The sets of the rounded relaxations: the fixed-in candidates and the largest free x (B, n)."""
    key = np.where(S == 1, 2.0 + X, np.where(S == -1, X, -1.0))
    return np.argsort(-key, axis=1, kind="stable")[:, :n]


def _leaves(S, n):
    """Masks (leaf, dead) of the nodes S (B, C): leaf when the count fixes the set, dead when it is unreachable."""
    on = (S == 1).sum(axis=1)
    nf = (S == -1).sum(axis=1)
    r = n - on
    dead = (r < 0) | (r > nf)
    return ~dead & ((r == 0) | (r == nf)), dead


def robust_branch_and_bound(F, w, n: int, crit: Criterion, robust: str, u_star=None,
                            settings: RobustBnBSettings = RobustBnBSettings()) -> RobustBnBResult:
    r"""The exact n-run robust design :math:`\max_{|S|=n}\Phi(S)` (module docstring) by best-bound
    branch-and-bound, proven optimal or with the proven gap at a time or node limit.

    Parameters
    ----------
    F : ndarray (n_candidates, n_samples, n_p, n_p)
        Validated information of one run of every candidate at every parameter vector.
    w : ndarray (n_samples,)
        Normalised prior weights.
    n : int
        Runs (distinct candidates), 1 <= n <= n_candidates.
    crit : Criterion
    robust : {"bayes", "maximin"}
    u_star : ndarray (n_samples,) or None
        Maximin: the local optima's utilities.
    settings : RobustBnBSettings
    """
    t0 = time.perf_counter()
    prob = RobustProblem(F, w, n, crit, robust, u_star, settings.gap_tol)
    inc = _Incumbent(prob)
    S0 = np.full((1, prob.C), -1, dtype=np.int8)
    leaf, _ = _leaves(S0, n)
    if leaf[0]:
        inc.offer(np.arange(prob.C)[None, :n])
        return _result(inc, [], inc.v, "optimal", 1, t0)
    root_bound, X = relax(prob, S0, None, settings.root_iters, -np.inf)
    inc.offer(_round(X, S0, n))
    inc.exchange()
    heap = [(-float(root_bound[0]), 0, S0[0], X[0])]
    counter, nodes, status = 1, 1, "optimal"
    while heap:
        th = inc.threshold()
        if -heap[0][0] <= th:
            heap = []
            break
        if time.perf_counter() - t0 > settings.time_limit:
            status = "time_limit"
            break
        if settings.node_limit is not None and nodes >= settings.node_limit:
            status = "node_limit"
            break
        parents = []
        while heap and len(parents) < settings.batch_size and -heap[0][0] > th:
            parents.append(heapq.heappop(heap))
        S, X0, pb = _children(parents)
        leaf, dead = _leaves(S, n)
        if leaf.any():
            inc.offer(_leaf_sets(S[leaf], n))
        keep = ~(leaf | dead)
        S, X0, pb = S[keep], X0[keep], pb[keep]
        if S.shape[0] == 0:
            continue
        b, X = relax(prob, S, X0, settings.node_iters, inc.threshold())
        nodes += S.shape[0]
        inc.offer(_round(X, S, n))
        b = np.minimum(b, pb)
        th = inc.threshold()
        for i in np.flatnonzero(b > th):
            heapq.heappush(heap, (-float(b[i]), counter, S[i], X[i]))
            counter += 1
    top = max([-h[0] for h in heap], default=-np.inf)
    return _result(inc, heap, float(root_bound[0]), status, nodes, t0, top)


def _children(parents):
    """Fixings, warm starts and bounds of the two children (candidate in, out) of every parent, branching on the
    free candidate whose relaxed value is closest to 1/2."""
    S, X0, pb = [], [], []
    for nb, _, st, x in parents:
        free = np.flatnonzero(st == -1)
        k = free[int(np.argmin(np.abs(x[free] - 0.5)))]
        for val in (1, 0):
            child = st.copy()
            child[k] = val
            S.append(child)
            X0.append(x)
            pb.append(-nb)
    return np.array(S), np.array(X0), np.array(pb)


def _leaf_sets(S, n):
    """The one set of each leaf node: the fixed-in candidates, plus every free one when they are all needed."""
    return np.argsort(-(S != 0).astype(int) - (S == 1), axis=1, kind="stable")[:, :n]


def _result(inc: _Incumbent, heap, root_bound, status, nodes, t0, top=-np.inf) -> RobustBnBResult:
    """The outcome: incumbent, proven upper bound (the largest open bound, at least the incumbent) and status."""
    ub = max(float(top), inc.v) if status != "optimal" else inc.v
    if inc.set is None or not np.isfinite(inc.v):
        status = "infeasible" if status == "optimal" else status
    return RobustBnBResult(indices=None if inc.set is None else inc.set.copy(), value=inc.v, upper_bound=ub,
                           gap=ub - inc.v if np.isfinite(ub) and np.isfinite(inc.v) else np.inf, status=status,
                           nodes=nodes, n_evaluated=inc.prob.evaluated, root_bound=root_bound,
                           wall_time=time.perf_counter() - t0)
