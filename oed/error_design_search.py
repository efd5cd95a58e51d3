r"""The exact search of :mod:`oed.error_design`: n of the candidate runs that minimise the posterior prediction
variance over a region, by enumeration or by a branch-and-bound with proven bounds.

The problem, in whitened and normalised form (:class:`VarianceProblem`): target t (a region point and sensor) has the
variance :math:`d_t` now (in units of its sensor's :math:`\sigma_t^2`, irreducible parts included); candidate c
adds the observations :math:`O_c` whose noise is whitened to the identity, with the covariances :math:`A` (targets x
observations) and :math:`B` (observations x observations) of the current posterior.  Observing a set S gives

.. math::

    v_t(S) = d_t - A_{t,O_S}\,(I + B_{O_S O_S})^{-1} A_{t,O_S}^\top,\qquad
    J(S) = \sum_t w_t v_t(S)\ (\text{integrated}),\quad \max_t v_t(S)\ (\text{worst}),

solved :math:`\min_{|S| = n} J(S)` (dimensionless).

**Relaxation.**  With weights :math:`x\in[0,1]^{n_c}` on the candidates (:math:`x_{o} = x_c` for the observations
of c and :math:`D = \operatorname{diag}(x_o)`),
:math:`v_t(x) = d_t - A_t D^{1/2}(I + D^{1/2} B D^{1/2})^{-1} D^{1/2} A_t^\top` equals
:math:`e_t^\top(\Sigma^{-1} + D)^{-1}e_t` of the joint latent covariance :math:`\Sigma` (a limit where
:math:`\Sigma` is singular), a convex function of x, equal to :math:`v_t(S)` at the indicator of S, with
:math:`\partial v_t / \partial x_c = -\sum_{o\in O_c} \Sigma^{x}_{t,o}{}^2` (:math:`\Sigma^x` the posterior
covariance at x).  A node fixes candidates in (I) and out; its sets are :math:`I\cup T`, T r of the free
candidates, all in the polytope :math:`P = \{x: x_I = 1, x_{out} = 0, \sum_{free} x = r, 0\le x\le 1\}`.  At any
point x of P convexity gives, for every v in P,

* integrated: :math:`J(v) \ge J(x) + \nabla J(x)^\top (v - x)`, minimised over P in closed form (the fixed-in sum
  plus the r smallest free components);
* worst: :math:`\max_t v_t(v) \ge \max_t \min_{P}[v_t(x) + \nabla v_t(x)^\top(v - x)]` and
  :math:`\ge \min_P \sum_t \mu_t[\ldots]` for any weights :math:`\mu` of the simplex (the soft-max weights at x);
  the larger is kept.

Every point x gives valid bounds, so x need not be optimal: it comes from projected-gradient steps with
backtracking (the capped-simplex projection of :mod:`oed.bnb.projection`) on J (worst: on its soft-max
smoothing), warm-started from the parent; a child keeps its parent's bound when that is larger.  Incumbents:
greedy + best-improvement exchange at the root, and the rounding (top-r free by x) of every node's relaxation.
Search: best bound first; branch on the free candidate whose relaxed value is closest to 1/2; a node is pruned when
its bound is at least incumbent - gap_tol |incumbent|.  Exact values of sets come from :meth:`VarianceProblem.values`
on every route, so enumeration and branch-and-bound report the same numbers.
"""
from __future__ import annotations

import heapq
import itertools
import math
import time
from dataclasses import dataclass

import numpy as np

from .bnb.projection import proj_capped_simplex_batch

__all__ = ["VarianceProblem", "SearchOutcome", "search", "greedy_exchange", "SEARCH_METHODS"]

SEARCH_METHODS = ("auto", "enumerate", "bnb", "greedy")
#: soft-max sharpness of the worst-case relaxation, relative to the current largest variance
SOFTMAX_BETA = 60.0


@dataclass(frozen=True, eq=False)
class VarianceProblem:
    """The whitened, normalised design problem (module docstring).

    Attributes
    ----------
    d : ndarray (n_T,)          the targets' variances now (sensor sigma^2 units, irreducible parts included)
    A : ndarray (n_T, n_O)      posterior covariance of targets and whitened observations (sigma units)
    B : ndarray (n_O, n_O)      posterior covariance of the whitened observations (dimensionless)
    groups : tuple of ndarray   the observations of every candidate (indices into n_O)
    weights : ndarray (n_T,)    the targets' weights of the integrated criterion (sum 1)
    worst : bool                the criterion is the largest variance (else the weighted mean)
    """

    d: np.ndarray
    A: np.ndarray
    B: np.ndarray
    groups: tuple
    weights: np.ndarray
    worst: bool

    @property
    def n_candidates(self) -> int:
        return len(self.groups)

    def _padded(self) -> tuple:
        """(padded groups (n_c, g_max) with the dummy observation n_O, A and B with that dummy appended)."""
        cache = self.__dict__.get("_pad")
        if cache is None:
            n_O, g = self.A.shape[1], max(len(x) for x in self.groups)
            idx = np.full((len(self.groups), g), n_O, int)
            for c, x in enumerate(self.groups):
                idx[c, :len(x)] = x
            A = np.hstack([self.A, np.zeros((self.A.shape[0], 1))])
            B = np.zeros((n_O + 1, n_O + 1))
            B[:n_O, :n_O] = self.B
            owner = np.empty(n_O, int)
            for c, x in enumerate(self.groups):
                owner[x] = c
            cache = (idx, A, B, owner, np.eye(len(self.groups))[owner])        # one-hot (n_O, n_c)
            object.__setattr__(self, "_pad", cache)
        return cache

    def variances(self, sets) -> np.ndarray:
        """v_t(S) (B, n_T) of a batch of sets (B, n) of candidate indices (sigma^2 units)."""
        sets = np.asarray(sets, int).reshape(len(sets), -1)
        if sets.shape[1] == 0:
            return np.repeat(self.d[None], sets.shape[0], axis=0)
        idx, A, B = self._padded()[:3]
        obs = idx[sets].reshape(sets.shape[0], -1)                       # (B, m)
        M = B[obs[:, :, None], obs[:, None, :]] + np.eye(obs.shape[1])[None]
        L = np.linalg.cholesky(M)
        Y = np.linalg.solve(L, np.transpose(A[:, obs], (1, 2, 0)))        # (B, m, n_T)
        return self.d[None] - np.sum(Y ** 2, axis=1)

    def criterion(self, v: np.ndarray) -> np.ndarray:
        """J of variances v (..., n_T)."""
        return v.max(axis=-1) if self.worst else v @ self.weights

    def values(self, sets) -> np.ndarray:
        """J(S) (B,) of a batch of sets (B, n)."""
        return self.criterion(self.variances(sets))

    def relaxed(self, x: np.ndarray) -> tuple:
        """(v (n_T,), dv/dx (n_T, n_c)) at candidate weights x (n_c,) in [0, 1]."""
        owner, onehot = self._padded()[3:]
        dh = np.sqrt(np.clip(x, 0.0, None))[owner]
        M = np.eye(len(dh)) + dh[:, None] * self.B * dh[None, :]
        W = dh[:, None] * np.linalg.solve(M, dh[:, None] * self.A.T)            # (n_O, n_T); M SPD, >= I
        v = self.d - np.sum(self.A.T * W, axis=0)
        post = self.A - W.T @ self.B
        return v, -(post ** 2) @ onehot


@dataclass(frozen=True)
class SearchOutcome:
    """The set found, its value J, the proven lower bound on every set of n candidates and how it was found.

    ``status``: "optimal" (proven within gap_tol), "time_limit", "node_limit" or "heuristic" (greedy + exchange,
    the bound from the root relaxation); ``gap`` = value - lower_bound (>= 0)."""

    indices: tuple
    value: float
    lower_bound: float
    status: str
    method: str
    nodes: int
    n_evaluated: int

    @property
    def gap(self) -> float:
        return max(self.value - self.lower_bound, 0.0)

    @property
    def proven(self) -> bool:
        return self.status == "optimal"


def _best_in(problem: VarianceProblem, sets: np.ndarray) -> tuple:
    vals = problem.values(sets)
    k = int(np.argmin(vals))
    return sets[k], float(vals[k])


def greedy_exchange(problem: VarianceProblem, n: int, start=None) -> tuple:
    """(set (n,), J, evaluations): greedy additions (each step the candidate of the lowest J), then
    best-improvement exchanges of one chosen for one unchosen candidate until none lowers J."""
    n_c = problem.n_candidates
    count = 0
    if start is None:
        chosen = []
        for _ in range(n):
            rest = [c for c in range(n_c) if c not in chosen]
            sets = np.array([chosen + [c] for c in rest], int)
            best, _ = _best_in(problem, sets)
            count += len(sets)
            chosen = [int(c) for c in best]
    else:
        chosen = [int(c) for c in start]
    value = float(problem.values(np.array([chosen]))[0])
    while n < n_c:
        rest = [c for c in range(n_c) if c not in chosen]
        sets = np.array([chosen[:i] + [c] + chosen[i + 1:] for i in range(n) for c in rest], int)
        best, v = _best_in(problem, sets)
        count += len(sets)
        if v >= value * (1 - 1e-12):
            break
        chosen, value = [int(c) for c in best], v
    return np.array(sorted(chosen), int), value, count


def enumerate_sets(problem: VarianceProblem, n: int, time_limit: float, batch: int = 2048) -> SearchOutcome:
    """Every set of n candidates, in batches; at the time limit the best so far (status "time_limit", lower
    bound -inf)."""
    t0 = time.perf_counter()
    it = itertools.combinations(range(problem.n_candidates), n)
    best, best_v, count, status = None, np.inf, 0, "optimal"
    total = math.comb(problem.n_candidates, n)
    while True:
        chunk = np.array(list(itertools.islice(it, batch)), int).reshape(-1, n)
        if chunk.shape[0] == 0:
            break
        s, v = _best_in(problem, chunk)
        count += chunk.shape[0]
        if v < best_v:
            best, best_v = s, v
        if count < total and time.perf_counter() - t0 > time_limit:
            status = "time_limit"
            break
    lb = best_v if status == "optimal" else -np.inf
    return SearchOutcome(tuple(int(c) for c in best), best_v, lb, status, "enumerate", 0, count)


# ---------------------------------------------------------------------------- node relaxation and bounds
def _top_small(g: np.ndarray, free: np.ndarray, r: int) -> np.ndarray:
    """The sum of the r smallest entries of g (..., n_c) over the free candidates."""
    if r == 0:
        return np.zeros(g.shape[:-1])
    gf = g[..., free]
    return np.sum(np.partition(gf, r - 1, axis=-1)[..., :r], axis=-1)


def _bound(problem: VarianceProblem, v: np.ndarray, g: np.ndarray, x: np.ndarray, fixed_in: np.ndarray,
           free: np.ndarray, r: int) -> float:
    """The tangent lower bound of J over the node's polytope at the point x (module docstring)."""
    if not problem.worst:
        gw = problem.weights @ g
        return float(problem.weights @ v - gw @ x + gw[fixed_in].sum() + _top_small(gw, free, r))
    base = v - g @ x + g[:, fixed_in].sum(axis=1)
    per_target = float(np.max(base + _top_small(g, free, r)))
    mu = _softmax(v)
    combined = float(mu @ base + _top_small(mu @ g, free, r))
    return max(per_target, combined)


def _softmax(v: np.ndarray) -> np.ndarray:
    beta = SOFTMAX_BETA / max(float(np.max(np.abs(v))), 1e-300)
    e = np.exp(beta * (v - v.max()))
    return e / e.sum()


def _smooth(problem: VarianceProblem, x: np.ndarray) -> tuple:
    """(objective, gradient (n_c,), v, dv/dx) of the relaxation's descent: J, or the soft-max of v (worst)."""
    v, g = problem.relaxed(x)
    if not problem.worst:
        return float(problem.weights @ v), problem.weights @ g, v, g
    beta = SOFTMAX_BETA / max(float(np.max(np.abs(v))), 1e-300)
    m = float(v.max())
    f = m + float(np.log(np.sum(np.exp(beta * (v - m))))) / beta
    return f, _softmax(v) @ g, v, g


def _relax(problem: VarianceProblem, x: np.ndarray, fixed_in, free, r: int, iters: int) -> tuple:
    """(best lower bound, final x) of projected-gradient steps with backtracking from x over the node polytope."""
    if r == 0 or r == int(free.sum()):
        x = fixed_in.astype(float) + free.astype(float) * (r > 0)
        v, g = problem.relaxed(x)
        return _bound(problem, v, g, x, fixed_in, free, r), x

    def project(y):
        return fixed_in + proj_capped_simplex_batch(y[None], free[None], np.array([r]))[0]

    x = project(x)
    f, grad, v, g = _smooth(problem, x)
    best = _bound(problem, v, g, x, fixed_in, free, r)
    step = 1.0 / max(float(np.max(np.abs(grad))), 1e-300)
    for _ in range(iters):
        for _half in range(30):
            y = project(x - step * grad)
            fy, gy, vy, ggy = _smooth(problem, y)
            d = y - x
            if fy <= f + grad @ d + (d @ d) / (2 * step) + 1e-15 * abs(f):
                break
            step /= 2
        else:
            break
        if np.max(np.abs(y - x)) <= 1e-12:
            break
        x, f, grad = y, fy, gy
        best = max(best, _bound(problem, vy, ggy, x, fixed_in, free, r))
        step *= 2
    return best, x


@dataclass(order=True)
class _Node:
    bound: float
    order: int
    fixed_in: np.ndarray = None
    free: np.ndarray = None
    x: np.ndarray = None


def branch_and_bound(problem: VarianceProblem, n: int, time_limit: float, gap_tol: float = 1e-9,
                     node_limit: int | None = None, root_iters: int = 200, node_iters: int = 5) -> SearchOutcome:
    """min_{|S| = n} J(S) by best-bound branch-and-bound (module docstring); at the time or node limit the best
    set found with the smallest bound of the open nodes."""
    t0 = time.perf_counter()
    n_c = problem.n_candidates
    inc, inc_v, count = greedy_exchange(problem, n)
    fixed_in, free = np.zeros(n_c, bool), np.ones(n_c, bool)
    root_bound, x = _relax(problem, np.full(n_c, n / n_c), fixed_in, free, n, root_iters)
    heap, order, nodes, status = [_Node(root_bound, 0, fixed_in, free, x)], 1, 1, "optimal"

    def consider(fin, fr, r, xr):
        nonlocal inc, inc_v, count
        top = np.flatnonzero(fr)[np.argsort(-xr[fr], kind="stable")[:r]] if r else np.array([], int)
        s = np.sort(np.concatenate([np.flatnonzero(fin), top])).astype(int)
        v = float(problem.values(s[None])[0])
        count += 1
        if v < inc_v:
            inc, inc_v = s, v

    consider(fixed_in, free, n, x)
    floor = np.inf                                         # the smallest bound of a pruned node
    while heap:
        if heap[0].bound >= inc_v - gap_tol * abs(inc_v):
            floor = min(floor, heap[0].bound)
            heap = []
            break
        if time.perf_counter() - t0 > time_limit or (node_limit is not None and nodes >= node_limit):
            status = "time_limit" if time.perf_counter() - t0 > time_limit else "node_limit"
            break
        node = heapq.heappop(heap)
        cand = np.flatnonzero(node.free)
        k = int(cand[np.argmin(np.abs(node.x[cand] - 0.5))])
        for put_in in (True, False):
            fin, fr = node.fixed_in.copy(), node.free.copy()
            fr[k] = False
            fin[k] = put_in
            r = n - int(fin.sum())
            if r < 0 or r > int(fr.sum()):
                continue
            xr = node.x.copy()
            xr[k] = float(put_in)
            b, xr = _relax(problem, xr, fin, fr, r, node_iters)
            b = max(b, node.bound)
            nodes += 1
            consider(fin, fr, r, xr)
            if r == 0 or r == int(fr.sum()):
                continue                                   # a leaf: its one set evaluated
            if b >= inc_v - gap_tol * abs(inc_v):
                floor = min(floor, b)
                continue
            heapq.heappush(heap, _Node(b, order, fin, fr, xr))
            order += 1
    lb = min(inc_v, floor, heap[0].bound if heap else np.inf)
    return SearchOutcome(tuple(int(c) for c in inc), inc_v, float(lb), status, "bnb", nodes, count)


def search(problem: VarianceProblem, n: int, method: str = "auto", time_limit: float = 60.0,
           enumeration_limit: int = 20_000, gap_tol: float = 1e-9, node_limit: int | None = None) -> SearchOutcome:
    """The set of n candidates minimising J by ``method``: "enumerate" (every set), "bnb" (proven optimal within
    gap_tol, or its proven gap at a limit), "greedy" (greedy + exchange, its gap against the root relaxation's
    bound: a heuristic, never called optimal unless that gap closes), "auto" (enumeration up to
    ``enumeration_limit`` sets, else branch-and-bound)."""
    total = math.comb(problem.n_candidates, n)
    if method == "enumerate" or (method == "auto" and total <= enumeration_limit):
        return enumerate_sets(problem, n, time_limit)
    if method == "bnb" or method == "auto":
        return branch_and_bound(problem, n, time_limit, gap_tol, node_limit)
    s, v, count = greedy_exchange(problem, n)
    n_c = problem.n_candidates
    lb, _ = _relax(problem, np.full(n_c, n / n_c), np.zeros(n_c, bool), np.ones(n_c, bool), n, 200)
    status = "optimal" if lb >= v - gap_tol * abs(v) else "heuristic"
    return SearchOutcome(tuple(int(c) for c in s), v, min(float(lb), v), status, "greedy", 1, count + 1)
