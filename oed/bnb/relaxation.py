r"""Batched continuous relaxations of branch-and-bound nodes.

For each node (fixings ``S``: -1 free, 0 out, 1 in) a spectral projected-gradient method with a
non-monotone (GLL) Armijo search minimises :math:`\phi(x)` over the node polytope
:math:`\{0\le x\le1,\ \sum x=r,\ \text{fixings}\}` (with a budget price :math:`\mu`:
:math:`\phi(x)+\mu c^Tx`), where :math:`\phi = -\log\det M(x)` (D), :math:`\mathrm{tr}M(x)^{-1}`
(A) or the negated soft-min of the eigenvalues of :math:`M(x)` (E, in stages of sharpness).
Every iterate gives a rigorous bound (:mod:`oed.bnb.bounds`); nodes are pruned, fixed by reduced
costs, or ended (relaxation gap closed, early branching, iteration limit) as they go.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..criteria import Criterion
from .bounds import bound_from_s, budget_top, e_bound_refine
from .heuristics import round_relaxations
from .problem import SearchContext, SelectionProblem
from .projection import proj_capped_simplex_batch, rowwise_top

__all__ = ["RelaxedNodes", "NodeBatch", "relax_nodes", "smooth_batch"]


def smooth_batch(prob: SelectionProblem, X, tE):
    r"""Relaxation objective at the rows of X (B, n): ``(phi, Q, primal)``.

    ``phi``: :math:`-\log\det M` (D), :math:`\mathrm{tr}M^{-1}` (A), or minus the soft-min
    :math:`\lambda_1 - \log\sum_i e^{-t_E(\lambda_i-\lambda_1)}/t_E` (E; sharpness ``tE`` (B,));
    ``phi = inf`` where M(x) is not PD (A, D).  ``Q`` (B, n): minus the gradient of ``phi``
    (:math:`q_k=\mathrm{tr}(GF_k)`).  ``primal``: the criterion at x (E: :math:`1/\lambda_1`).
    """
    B = X.shape[0]
    p = prob.p
    M = (X @ prob.Fflat).reshape(B, p, p)
    lam, U = np.linalg.eigh(M)
    l0 = lam[:, 0]
    Ut = U.transpose(0, 2, 1)
    if prob.crit is Criterion.E:
        e = np.exp(-tE[:, None] * (lam - l0[:, None]))
        se = e.sum(axis=1)
        Z = (U * (e / se[:, None])[:, None, :]) @ Ut
        Q = Z.reshape(B, -1) @ prob.Fflat.T
        with np.errstate(divide="ignore"):
            primal = np.where(l0 > 0, 1.0 / np.where(l0 > 0, l0, 1.0), np.inf)
        return -(l0 - np.log(se) / tE), Q, primal
    ok = l0 > 1e-13 * np.abs(lam[:, -1])
    ls = np.where(ok[:, None], lam, 1.0)
    inv = 1.0 / ls
    if prob.crit is Criterion.D:
        fval = -np.log(ls).sum(axis=1)
        wts = inv
    else:
        fval = inv.sum(axis=1)
        wts = inv * inv
    Q = ((U * wts[:, None, :]) @ Ut).reshape(B, -1) @ prob.Fflat.T
    fval = np.where(ok, fval, np.inf)
    return fval, Q, fval.copy()


@dataclass(frozen=True)
class RelaxedNodes:
    """Nodes of a batch that are neither pruned nor leaves: bounds ``lb`` (K,), relaxed points
    ``X`` (K, n), fixings ``S`` (K, n) (possibly tightened) and budget prices ``mu`` (K,)."""

    lb: np.ndarray
    X: np.ndarray
    S: np.ndarray
    mu: np.ndarray


@dataclass(frozen=True)
class _LinearMax:
    """Linear-form maximum per row: ``s`` and, without a budget, the free order and sorted values."""

    s: np.ndarray
    order: np.ndarray | None
    Qs: np.ndarray | None


def relax_nodes(ctx: SearchContext, S, X0, iters, root, lb0, mu0=None) -> RelaxedNodes:
    """Solve the relaxations of the nodes S (B, n) (-1 free, 0 out, 1 in) together.

    ``X0``: warm starts (None: uniform); ``iters``: iteration limit per node; ``root``: no early
    branching; ``lb0``: bounds known beforehand (the parents'); ``mu0``: the parents' budget prices.
    Leaves and rounded relaxations update ``ctx.incumbent``.
    """
    batch = NodeBatch(ctx, S, iters, root, lb0, mu0)
    batch.initialise(X0)
    while batch.iterate():
        pass
    return batch.finish()


class NodeBatch:
    """Per-node state of the batched relaxation solve (rows = nodes).

    Attributes
    ----------
    S : ndarray of int8 (B, n)
        Fixings (-1 free, 0 out, 1 in); tightened by budget screening and reduced-cost fixing.
    best : ndarray (B,)
        Best bound so far.
    keep, act : ndarray of bool (B,)
        Node still alive (not pruned, not a leaf) / still iterating.
    X, f, Q, primal : ndarray
        Relaxed point, objective phi, minus its gradient, criterion at X.
    alpha, fhist : ndarray
        Spectral step length and the last ``nonmonotone`` penalised objective values.
    tE, stage : ndarray
        E only: soft-min sharpness and stage index into ``ctx.betas``.
    sit : ndarray of int
        Iterations in the current stage.
    mu : ndarray
        Budget price (the relaxation minimises phi(x) + mu c^T x).
    """

    def __init__(self, ctx: SearchContext, S, iters, root, lb0, mu0=None):
        self.ctx = ctx
        n = ctx.problem.n
        self.S = S.copy()
        B = self.S.shape[0]
        self.root = root
        self.best = np.array(lb0, dtype=float)
        self.keep = np.ones(B, dtype=bool)
        self.X = np.zeros((B, n))
        self.f = np.full(B, np.inf)
        self.Q = np.zeros((B, n))
        self.primal = np.full(B, np.inf)
        self.alpha = np.ones(B)
        self.fhist = np.full((B, max(1, ctx.settings.nonmonotone)), np.inf)
        self.tE = np.ones(B)
        self.stage = np.zeros(B, dtype=int)
        self.sit = np.zeros(B, dtype=int)
        self.n_it = max(iters // len(ctx.betas), 5) if ctx.is_e else iters
        self.act = np.ones(B, dtype=bool)
        # budget price (inherited from the parent): the relaxation minimises phi(x) + mu c^T x
        self.mu = np.zeros(B) if mu0 is None else np.array(mu0, dtype=float)

    # --- node screening and (re)starts ------------------------------------------------
    def initialise(self, X0):
        """Screen all rows and start them from the warm starts X0 (None: uniform)."""
        I0 = self.screen(np.arange(self.S.shape[0]))
        self.start(I0, None if X0 is None else X0[I0])

    def _drop(self, I, bad, leaf, W_leaf):
        """Offer the leaf designs ``W_leaf``; end the rows of I that are infeasible or leaves."""
        if leaf.any():
            self.ctx.incumbent.offer(W_leaf)
        gone = bad | leaf
        self.keep[I[gone]] = False
        self.act[I[gone]] = False
        return I[~gone]

    def screen(self, I):
        """Drop infeasible rows, evaluate leaves; returns the rows of I still to be solved."""
        if self.ctx.limits.has_budget:
            return self._screen_budget(I)
        S = self.S
        fr = S[I] == -1
        on = S[I] == 1
        r = self.ctx.limits.m - on.sum(axis=1)
        nf = fr.sum(axis=1)
        bad = (r < 0) | (r > nf)
        leaf = ~bad & ((r == 0) | (r == nf))
        return self._drop(I, bad, leaf, on[leaf] | (fr[leaf] & (r[leaf] == nf[leaf])[:, None]))

    def _screen_budget(self, I):
        """:meth:`screen` with a budget: free sensors that no longer fit are fixed out; a node
        is infeasible when its count or budget is exceeded or ``lo`` is out of reach, and a
        leaf when nothing is free, the count is full, or all free sensors fit (then taking all
        of them is best, by monotonicity)."""
        lim = self.ctx.limits
        costs = lim.costs
        n = self.S.shape[1]
        on = self.S[I] == 1
        left = lim.budget - on @ costs
        SI = self.S[I]
        SI[(SI == -1) & (costs[None, :] > left[:, None])] = 0
        self.S[I] = SI
        fr = SI == -1
        n_on = on.sum(axis=1)
        r = lim.m - n_on
        nf = fr.sum(axis=1)
        need = np.maximum(lim.lo - n_on, 0)
        cheap = np.sort(np.where(fr, costs[None, :], np.inf), axis=1)
        cum = np.concatenate([np.zeros((I.size, 1)), np.cumsum(cheap, axis=1)], axis=1)
        reach = cum[np.arange(I.size), np.minimum(need, n)]
        bad = (r < 0) | (left < 0) | (need > nf) | ~(reach <= left)
        allfit = (nf <= r) & ((fr * costs[None, :]).sum(axis=1) <= left)
        leaf = ~bad & ((nf == 0) | (r == 0) | allfit)
        return self._drop(I, bad, leaf, on[leaf] | (fr[leaf] & allfit[leaf][:, None]))

    def start(self, I, Xs, keep_alpha=False):
        """(Re)initialise rows I from warm starts Xs (projected onto the node polytope)."""
        if I.size == 0:
            return
        prob = self.ctx.problem
        p = prob.p
        fr = self.S[I] == -1
        on = self.S[I] == 1
        r = self.ctx.limits.relaxed_count(on, fr)
        nf = fr.sum(axis=1)
        uni = np.where(fr, (r / nf)[:, None], 0.0) + on
        Xi = uni if Xs is None else proj_capped_simplex_batch(Xs, fr, r) + on
        if self.ctx.is_e:
            lam0 = np.linalg.eigvalsh((Xi @ prob.Fflat).reshape(-1, p, p))[:, 0]
            badx = lam0 <= 0
            Xi[badx] = uni[badx]
            lam0[badx] = np.linalg.eigvalsh((Xi[badx] @ prob.Fflat).reshape(-1, p, p))[:, 0]
            self.tE[I] = np.array(self.ctx.betas)[self.stage[I]] / np.maximum(lam0, 1e-300)
        fi, qi, pi = smooth_batch(prob, Xi, self.tE[I])
        badf = ~np.isfinite(fi)
        if badf.any():
            Xi[badf] = uni[badf]
            fi[badf], qi[badf], pi[badf] = smooth_batch(prob, Xi[badf], self.tE[I][badf])
            still = ~np.isfinite(fi)
            if still.any():
                # singular even at the uniform point: prune only if the exact criterion of the
                # largest design of the node is infinite; otherwise keep it unbounded (branch on).
                full = (self.S[I][still] != 0)
                dead = np.isinf(prob.exact(full))
                rows = I[still]
                self.keep[rows[dead]] = False
                self.act[rows] = False
                self.X[rows] = Xi[still]
        self.X[I], self.f[I], self.Q[I], self.primal[I] = Xi, fi, qi, pi
        self.fhist[I] = fi[:, None]
        if not keep_alpha:
            qn = np.linalg.norm(np.where(fr, qi, 0.0), axis=1)
            self.alpha[I] = 1.0 / np.maximum(np.where(np.isfinite(qn), qn, 1.0), 1e-300)
        self.sit[I] = 0

    # --- one iteration over the active rows -----------------------------------------------
    def iterate(self) -> bool:
        """Bound, prune, fix and take one projected-gradient step on every active row; end the
        stages that are done.  Returns False when no row was active."""
        ctx = self.ctx
        I = np.flatnonzero(self.act)
        if I.size == 0:
            return False
        fr = self.S[I] == -1
        on = self.S[I] == 1
        r = ctx.limits.relaxed_count(on, fr)
        lm = self._linear_max(I, fr, on, r)
        lb = bound_from_s(ctx.problem.crit, ctx.problem.p, self.f[I], lm.s)
        self.best[I] = np.maximum(self.best[I], lb)
        th = ctx.incumbent.threshold()
        pruned = self.best[I] >= th
        self.keep[I[pruned]] = False
        self.act[I[pruned]] = False
        fixed = np.zeros(I.size, dtype=bool)
        if np.isfinite(ctx.incumbent.v) and not ctx.limits.has_budget:
            fixed = self._reduced_cost_fixing(I, fr, r, lm, th, pruned)
        # stage end: relaxation gap closed, early branching, iteration limit
        cont = ~pruned & ~fixed
        pI = self.primal[I]
        with np.errstate(invalid="ignore"):
            gapok = np.isfinite(pI) & (pI - lb <= 1e-7 * np.maximum(np.abs(pI), ctx.floor_d))
        # (with a budget the relaxed point may exceed the budget, so primal < th proves nothing)
        eb = ((ctx.settings.early_branch and not self.root) & (self.sit[I] >= ctx.settings.early_branch_min_iters)
              & (pI < th))
        end = cont & (gapok | eb | (self.sit[I] >= self.n_it))
        J = I[cont & ~end]
        if J.size:
            stuck = self._gradient_step(J)
            end_idx = np.concatenate([I[end], J[stuck]])
        else:
            end_idx = I[end]
        if ctx.is_e and eb.any():
            # early branching ends the node in every stage: no Z can give a bound above the
            # relaxation optimum, which is <= primal < incumbent - tol.
            self.act[I[cont & eb]] = False
            end_idx = end_idx[self.act[end_idx]]
        if end_idx.size:
            self._end_stages(end_idx)
        return True

    def _linear_max(self, I, fr, on, r) -> _LinearMax:
        """Maximum of the linear form q^T v over each node polytope (Lagrangian bound with a
        budget, where it also updates the steering price ``mu``)."""
        ctx = self.ctx
        QI = self.Q[I]
        if ctx.limits.has_budget:
            lim = ctx.limits
            top, mu_new = budget_top(QI, fr, lim.m - on.sum(axis=1), lim.costs, lim.budget - on @ lim.costs)
            if ctx.settings.budget_steering:
                # where the price changed, restart the line-search memory at the penalised value
                mu = self.mu
                chg = np.abs(mu_new - mu[I]) > 1e-3 * np.maximum(np.abs(mu[I]), 1e-300)
                mu[I] = mu_new
                Ic = I[chg]
                self.fhist[Ic] = (self.f[Ic] + mu[Ic] * (self.X[Ic] @ lim.costs))[:, None]
            order = Qs = None
        else:
            order, Qs, top = rowwise_top(QI, fr, r)
        return _LinearMax(np.where(on, QI, 0.0).sum(axis=1) + top, order, Qs)

    def _reduced_cost_fixing(self, I, fr, r, lm: _LinearMax, th, pruned):
        """Fix free sensors whose flip (in <-> out of the top-r set) alone lifts the bound to
        ``th``; the fixed rows are re-screened and restarted.  Returns the mask of fixed rows."""
        prob = self.ctx.problem
        n = prob.n
        QI = self.Q[I]
        fI = self.f[I]
        ar = np.arange(I.size)
        q_r = lm.Qs[ar, r - 1]
        q_r1 = lm.Qs[ar, r]
        rank = np.empty_like(lm.order)
        np.put_along_axis(rank, lm.order, np.arange(n)[None, :].repeat(I.size, 0), axis=1)
        chosen = rank < r[:, None]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            lb_in = bound_from_s(prob.crit, prob.p, fI[:, None], (lm.s - q_r)[:, None] + QI)
            lb_out = bound_from_s(prob.crit, prob.p, fI[:, None], (lm.s + q_r1)[:, None] - QI)
        fix0 = fr & ~chosen & (lb_in >= th)
        fix1 = fr & chosen & (lb_out >= th)
        fixed = (fix0 | fix1).any(axis=1) & ~pruned
        if fixed.any():
            J = I[fixed]
            SJ = self.S[J]
            SJ[fix0[fixed]] = 0
            SJ[fix1[fixed]] = 1
            self.S[J] = SJ
            J2 = self.screen(J)
            self.start(J2, self.X[J2])
        return fixed

    def _gradient_step(self, J):
        """One spectral projected-gradient step with non-monotone Armijo backtracking on rows J;
        returns the mask of rows whose search failed (stuck)."""
        ctx = self.ctx
        lim = ctx.limits
        bud = lim.has_budget
        S, X, Q, mu = self.S, self.X, self.Q, self.mu
        n = ctx.problem.n
        frJ = S[J] == -1
        onJ = (S[J] == 1).astype(float)
        rJ = lim.relaxed_count(onJ, frJ)
        QJ = Q[J] - mu[J, None] * lim.costs[None, :] if bud else Q[J]     # -grad of phi + mu c^T x
        Y = proj_capped_simplex_batch(X[J] + self.alpha[J, None] * QJ, frJ, rJ) + onJ
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
            fn, qn, pn = smooth_batch(ctx.problem, Xn, self.tE[J[pend]])
            fp = fn + mu[J[pend]] * (Xn @ lim.costs) if bud else fn
            fref = self.fhist[J[pend]].max(axis=1)  # non-monotone (GLL) reference value
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
                a_new = np.where(sy > 1e-300, ss / np.where(sy > 1e-300, sy, 1.0), self.alpha[Jg] * 4.0)
            self.alpha[Jg] = np.minimum(np.maximum(a_new, 1e-12 / np.maximum(qnorm, 1e-300)), 1e12)
            X[Jg] = X[Jg] + sv
            self.f[Jg], Q[Jg], self.primal[Jg] = fnew[good], qnew[good], pnew[good]
            self.fhist[Jg] = np.concatenate([self.fhist[Jg][:, 1:], fpen[good][:, None]], axis=1)
            self.sit[Jg] += 1
        return stuck

    def _end_stages(self, end_idx):
        """End the current stage of rows end_idx: E moves to the next sharpness (the last stage
        gets the eigenbasis bound refinement); the rows that are done stop iterating."""
        ctx = self.ctx
        if ctx.is_e:
            n_stages = len(ctx.betas)
            nxt = end_idx[self.stage[end_idx] + 1 < n_stages]
            fin = end_idx[self.stage[end_idx] + 1 >= n_stages]
            self.stage[nxt] += 1
            self.start(nxt, self.X[nxt], keep_alpha=True)
            R = fin[self.keep[fin]]
            if ctx.settings.e_refine_iters > 0 and R.size and not ctx.limits.has_budget:
                self._refine_e_bounds(R)
        else:
            fin = end_idx
        self.act[fin] = False

    def _refine_e_bounds(self, R):
        """Re-optimise the E bound of rows R over the eigenbasis weights; prune those now above the threshold."""
        ctx = self.ctx
        onR = self.S[R] == 1
        sR = e_bound_refine(ctx.problem.Fflat, self.X[R], self.S[R] == -1, onR, ctx.limits.m - onR.sum(axis=1),
                            self.tE[R], ctx.settings.e_refine_iters)
        self.best[R] = np.maximum(self.best[R], bound_from_s(ctx.problem.crit, ctx.problem.p, None, sR))
        self.keep[R[self.best[R] >= ctx.incumbent.threshold()]] = False

    def finish(self) -> RelaxedNodes:
        """Round the surviving relaxations (incumbent heuristic) and return the surviving nodes."""
        K = np.flatnonzero(self.keep)
        if K.size:
            round_relaxations(self.ctx, self.S[K], self.X[K])
        return RelaxedNodes(self.best[K], self.X[K], self.S[K], self.mu[K])
