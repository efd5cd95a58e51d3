"""The iteration of the batch engine (:mod:`identification.fit.batch`): sweeps until every member
has converged or stopped, with the convergence test of :func:`identification.fit.refinement.refine`
and the step (Gauss-Newton far from the optimum, exact Newton near it) of every member."""
from __future__ import annotations

import numpy as np

from identification.errors import StateSolveError
from identification.fit import newton as newton_core
from identification.fit.batch_data import LEFT_BOUNDS, BatchSettings
from identification.fit.batch_points import Points
from identification.fit.batch_sweep import (Iteration, Prepared, Sweep, evaluate, evaluate_fused,
                                             evaluate_shared)
from identification.fit.settings import IdentifySettings

__all__ = ["iterate"]


def _chol_solve(M: np.ndarray, b: np.ndarray, s_p: np.ndarray) -> tuple:
    """(x, decrement, good) with M x = b and b^T M^{-1} b for a stack M (m, n_p, n_p), through the
    Cholesky factor of diag(s_p) M diag(s_p); ``good`` False (x, decrement NaN) where M is not
    positive definite."""
    m, n_p = b.shape
    Ms = M * np.outer(s_p, s_p)[None]
    good = np.ones(m, bool)
    try:
        L = np.linalg.cholesky(Ms)
    except np.linalg.LinAlgError:
        L = np.broadcast_to(np.eye(n_p), Ms.shape).copy()
        for i in range(m):
            try:
                L[i] = np.linalg.cholesky(Ms[i])
            except np.linalg.LinAlgError:
                good[i] = False
    v = np.linalg.solve(L, (b * s_p)[:, :, None])
    x = s_p * np.linalg.solve(L.transpose(0, 2, 1), v)[:, :, 0]
    dec = np.einsum("ip,ip->i", v[:, :, 0], v[:, :, 0])
    x[~good] = np.nan
    dec[~good] = np.nan
    return x, dec, good, L




def _advance(model, prep: Prepared, it: Iteration, sw: Sweep, s_p: np.ndarray, settings: IdentifySettings,
             bs: BatchSettings, sigma_unknown: bool) -> None:
    """Convergence test (that of identification.fit.refinement.refine) and the next step of every member."""
    n_p = model.n_p
    a = sw.a
    unit = newton_core.decrement_unit(sw.obj, prep.n_data[a] - n_p) if sigma_unknown else np.ones(a.size)
    dN, decN, goodN, LN = _chol_solve(sw.F + sw.S, -sw.g, s_p)
    dG, _, goodG, _ = _chol_solve(sw.F, -sw.g, s_p)
    # the decrement that round-off in the gradient's sum over the data alone produces
    round_off = newton_core.gradient_roundoff(lambda b: np.linalg.solve(LN, b[:, :, None])[:, :, 0], sw.gabs * s_p)
    dec = np.where(goodN, decN, np.inf)
    bad = ~sw.finite
    exact = sw.state_ok & sw.has_S & ~bad
    with np.errstate(invalid="ignore"):
        increased = exact & ~newton_core.no_increase(sw.obj, it.fobj[a])
    # refine's test: a step may not increase Phi.  In the quadratic region (previous decrement below
    # decrement_tol) Phi cannot resolve the decrease any more: the step is kept while the decrement
    # falls, else the previous point is the optimum
    quadratic = it.has_final[a] & newton_core.in_quadratic_region(it.fdec[a], settings.decrement_tol * it.funit[a])
    with np.errstate(invalid="ignore"):
        keep_inc = increased & newton_core.keep_step(sw.obj, it.fobj[a], quadratic, dec, it.fdec[a])
    # outside the quadratic region an increase halves the step from the last exact point (the
    # backtracking of identify's explicit Newton; at most 30 halvings)
    back = increased & ~quadratic & (it.halvings[a] < newton_core.BATCH_MAX_HALVINGS)
    stop_inc = increased & ~keep_inc & ~back
    update = exact & ~stop_inc & ~back
    b = a[update]
    it.halvings[b] = 0
    it.has_final[b] = True
    it.fp[b], it.fY[b], it.fyp[b], it.fh[b], it.fG[b] = sw.P[update], sw.Y[update], sw.yp[update], sw.h[update], \
        sw.G[update]
    it.fF[b], it.fS[b], it.fobj[b], it.fdec[b], it.funit[b] = sw.F[update], sw.S[update], sw.obj[update], \
        dec[update], unit[update]
    it.fsweeps[b] = it.sweeps[b]
    conv = update & goodN & (newton_core.converged(decN, settings.refine_decrement * unit, round_off)
                             | newton_core.tiny_step(dN / s_p))
    it.done[a[conv | (stop_inc & quadratic)]] = True
    step = ~bad & ~stop_inc & ~conv & goodG
    use_N = it.newton[a] & sw.has_S & goodN
    dp = np.where(use_N[:, None], dN, dG)
    big = np.max(np.abs(dp / s_p), axis=1)
    it.newton[a[step & (big < bs.newton_step)]] = True
    # steps are limited relative to max(s_p, |p|): far optima (a wrong model) are reached geometrically
    rel = np.max(np.abs(dp) / np.maximum(s_p, np.abs(sw.P)), axis=1)
    dp = dp * np.where(rel > bs.max_step, bs.max_step / np.where(rel > 0, rel, 1.0), 1.0)[:, None]
    p_new = sw.P + dp
    inside = np.all((p_new > model.lower) & (p_new < model.upper), axis=1)
    for k in np.flatnonzero(back):
        i = a[k]
        d = newton_core.halved_step(it.fp[i], sw.P[k])
        it.P[i] = it.fp[i] + d
        it.Y[i] = it.fY[i] + it.fyp[i] @ d if model.n_y else it.Y[i]
        it.halvings[i] += 1
    step &= ~back
    for k in np.flatnonzero(~step & ~back | ~inside & step):
        i = a[k]
        if bad[k]:
            it.reason[i] = "the model or its derivatives are not finite (or E_y is singular) at the iterate"
        elif stop_inc[k] and not quadratic[k]:
            it.reason[i] = "a Newton step increased the objective before the optimum was reached"
        elif not (conv[k] or stop_inc[k]) and not goodG[k]:
            it.reason[i] = "J^T Omega J is singular at the iterate"
        elif step[k]:
            it.reason[i] = LEFT_BOUNDS
    step &= inside
    it.active[a[~step & ~back]] = False
    b = a[step]
    it.P[b] = p_new[step]
    if model.n_y:
        it.Y[b] = sw.Y[step] + sw.dyE[step] + np.einsum("mjyp,mp->mjy", sw.yp[step], dp[step])


def iterate(model, prep: Prepared, points: Points, s_p, P0, Y0, settings: IdentifySettings,
             bs: BatchSettings, sigma_unknown: bool, start_solved: bool) -> Iteration:
    """Sweeps until every member has converged or stopped (see the module docstring).

    ``start_solved``: the start states solve E = 0 at the start values (the first sweep of
    members sharing the start is then evaluated once, :func:`evaluate_shared`)."""
    it = Iteration.start(P0, Y0, model.n_S)
    first = bool(start_solved)
    for _ in range(bs.max_sweeps):
        a = np.flatnonzero(it.active)
        if not a.size:
            break
        it.sweeps[a] += 1
        shared = first and a.size > 1 and np.all(it.P[a] == it.P[a[0]]) and np.all(it.Y[a] == it.Y[a[0]])
        first = False
        try:
            sw = evaluate_shared(model, prep, points, it, a) if shared else None
            if sw is None and points.fused:
                sw = evaluate_fused(model, prep, points, it, a, bs)
            if sw is None:
                it.dense_sweeps += 1
                sw = evaluate(model, prep, points, it, a, points.symmetric(), bs)
        except StateSolveError as exc:
            for i in a:
                it.reason[i] = f"model evaluation failed: {exc}"
            it.active[a] = False
            break
        _advance(model, prep, it, sw, s_p, settings, bs, sigma_unknown)
    for i in np.flatnonzero(it.active):
        it.reason[i] = f"no convergence in {bs.max_sweeps} sweeps"
    it.active[:] = False
    return it
