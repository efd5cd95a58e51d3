r"""The one Newton core of the reduced-space iterations: acceptance rules, the backtracking line
search, the convergence test and the active set.

Every Newton-type iteration on the reduced objective Phi(p) of paper eq. 3 (the explicit and
implicit reduced-space solves of :mod:`identification.fit.explicit_newton`, the refinement
:func:`identification.fit.refinement.refine`, the batch engine's
:mod:`identification.fit.batch_iteration`, the profile's constrained solver
:class:`identification.inference.profile_solver.Profiler` and the saddle escape of
:mod:`identification.fit.secondorder`) takes its step d with the Newton decrement

.. math::  \delta = g^T M^{-1} g,\qquad d = -M^{-1} g,

(M = J^T Omega J or J^T Omega J + S, in chi^2 / 2 units of Phi) and decides with the rules here.
The explicit/implicit reduced Newton and the profile's solver take the step itself from the Cholesky
factor here (:func:`factor`, :func:`decrement`, :func:`direction`); :func:`identification.fit.refinement.refine`
takes it through the QR factor of the weighted Jacobian (more accurate where J^T Omega J is ill-conditioned)
and the batch engine through stacked factorisations of all members at once.

* :func:`sufficient_decrease` (Armijo): Phi(p + t d) <= Phi(p) - 1e-4 t delta;
* :func:`no_increase`: Phi(p + d) <= Phi(p) (1 + 1e-14) + 1e-300 (where Phi cannot resolve the decrease);
* :func:`keep_step`: a step that raised Phi is kept in the quadratic region while the decrement falls;
* :func:`backtrack`: t = 1, 1/2, 1/4, ... (at most :data:`MAX_HALVINGS`) until a rule accepts;
* :func:`halved_step`: the halving of a step from the last accepted point across evaluations
  (the batch engine, at most :data:`BATCH_MAX_HALVINGS`);
* :func:`decrement_unit`: the decrement's unit (1, or 2 Phi / dof with sigma unknown) and
  :func:`in_quadratic_region`: delta <= decrement_tol, where Phi cannot resolve a decrease;
* :func:`converged`: delta <= max(tolerance, the decrement round-off alone produces), or
  :func:`tiny_step`: every |d_i| / s_p,i below :data:`STEP_TOL`;
* :func:`gradient_roundoff`: that round-off, u^T u with u = L^{-1} (16 eps sum_jk |lambda_jk| |G_jk|);
* :func:`active_set`: with bounds, the free parameters not held at a bound by the gradient, and
  :func:`trial_point`: the trial point clipped to the bounds, moving only the active parameters.

The functions work elementwise on scalars and on stacks (the batch engine's members) with the
same arithmetic, so every caller's numbers are those of its former private copy.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from identification.fit import dense

__all__ = ["ARMIJO", "MAX_HALVINGS", "BATCH_MAX_HALVINGS", "STEP_TOL", "GRAD_ULPS", "ABORT", "sufficient_decrease",
           "no_increase", "keep_step", "backtrack", "halved_step", "converged", "tiny_step", "gradient_roundoff",
           "active_set", "trial_point", "decrement_unit", "in_quadratic_region", "factor", "decrement", "direction"]

#: the Armijo constant of the sufficient decrease
ARMIJO = 1e-4
#: halvings of the line search of one step
MAX_HALVINGS = 40
#: halvings of the batch engine's step back towards the last exact point (one per sweep)
BATCH_MAX_HALVINGS = 30
#: a step below this many parameter scales (inf-norm) has converged
STEP_TOL = 1e-13
#: the gradient's round-off bound: this many ulps of sum |lambda_jk| |G_jk|
GRAD_ULPS = 16


class _Abort:
    """The sentinel a trial of :func:`backtrack` returns to end the search (the caller gives up)."""

    def __repr__(self):
        return "ABORT"


#: returned by a trial of :func:`backtrack` (and then by backtrack itself) to end the search
ABORT = _Abort()


def factor(M: np.ndarray, fallback: np.ndarray | None = None) -> np.ndarray | None:
    """The lower Cholesky factor L of the (scaled) Newton matrix M = L L^T (LAPACK dpotrf), else of
    ``fallback`` (J^T Omega J where J^T Omega J + S is not positive definite); None when neither is
    positive definite."""
    L = dense.cholesky_lower(M)
    if L is None and fallback is not None:
        L = dense.cholesky_lower(fallback)
    return L


def decrement(L: np.ndarray, g: np.ndarray) -> tuple:
    """(v, delta): v = L^{-1} g and the Newton decrement delta = v^T v = g^T M^{-1} g (M = L L^T)."""
    v = dense.tri_solve(L, g)
    return v, float(v @ v)


def direction(L: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The Newton step d = -M^{-1} g = -L^{-T} v from v of :func:`decrement`."""
    d = dense.tri_solve(L, v, trans=1)
    d *= -1.0
    return d


def sufficient_decrease(f_new, f, t, dec):
    """Armijo's rule Phi(p + t d) <= Phi(p) - :data:`ARMIJO` t delta (scalars or arrays)."""
    return f_new <= f - ARMIJO * t * dec


def no_increase(f_new, f):
    """Phi(p_new) <= Phi(p) (1 + 1e-14) + 1e-300: no increase beyond Phi's own round-off."""
    return f_new <= f * (1 + 1e-14) + 1e-300


def keep_step(f_new, f, quadratic, dec_new, dec):
    """Whether the step to p_new is kept: :func:`no_increase`, or in the quadratic region (``quadratic``:
    Phi cannot resolve the decrease) a decrement that falls (scalars or arrays, elementwise)."""
    return no_increase(f_new, f) | (quadratic & (dec_new < dec))


def backtrack(trial: Callable, accept: Callable, max_halvings: int = MAX_HALVINGS, t: float = 1.0) -> tuple:
    """The backtracking line search: ``trial(t)`` at t = 1, 1/2, 1/4, ... (at most ``max_halvings``
    trials) until ``accept(candidate, t)``.

    ``trial`` returns the candidate at p + t d, None where it cannot be evaluated (a failed state
    solve: the step is halved), or :data:`ABORT` to end the search.  Returns (candidate, t) of the
    accepted trial, (None, t) when none was, or (ABORT, t).
    """
    for _ in range(max_halvings):
        cand = trial(t)
        if cand is ABORT:
            return ABORT, t
        if cand is not None and accept(cand, t):
            return cand, t
        t *= 0.5
    return None, t


def halved_step(last: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The step from the last accepted point ``last`` to ``p``, halved: (p - last) / 2 (the next trial
    is last + the halved step)."""
    return 0.5 * (p - last)


def decrement_unit(objective, dof):
    """Objective units per chi^2 unit of the decrement: 1 with sigma known (``dof`` None), else
    2 Phi / max(dof, 1) (the objective's sigma is a common spread; the standard errors use
    s^2 = RSS / (n - n_p)); scalars or arrays."""
    return 1.0 if dof is None else 2.0 * objective / np.maximum(dof, 1)


def in_quadratic_region(dec, tol):
    """delta <= tol: the quadratic region, where Phi cannot resolve the decrease of a step any more
    (``tol`` = decrement_tol in objective units; scalars or arrays)."""
    return dec <= tol


def converged(dec, tol, roundoff):
    """delta <= max(tol, roundoff): the decrement is below the tolerance or at round-off (scalars
    or arrays)."""
    return dec <= np.maximum(tol, roundoff)


def tiny_step(d_scaled) -> bool:
    """Every |d_i| (in parameter scales; the last axis of a stack) below :data:`STEP_TOL`."""
    return np.max(np.abs(d_scaled), axis=-1) < STEP_TOL


def gradient_roundoff(whiten: Callable, g_abs: np.ndarray):
    """The decrement that round-off in the gradient's sum over the data alone produces: u^T u with
    u = ``whiten``(16 eps ``g_abs``) (``whiten`` applies L^{-1} of the Newton matrix M = L L^T;
    ``g_abs`` = sum_jk |lambda_jk| |G_jk|, a stack (m, n_p) allowed)."""
    u = whiten(GRAD_ULPS * np.finfo(float).eps * g_abs)
    return np.einsum("mp,mp->m", u, u) if u.ndim > 1 else float(u @ u)


def trial_point(p: np.ndarray, d: np.ndarray, t: float, lower: np.ndarray, upper: np.ndarray,
                act=None) -> np.ndarray:
    """The trial point p + t d clipped to the bounds [lower, upper]; with an active set ``act`` (a list of
    indices) only those parameters move (the others keep their values)."""
    if act is None:
        return np.clip(p + t * d, lower, upper)
    out = np.array(p)
    out[act] = np.clip(p[act] + t * d, lower[act], upper[act])
    return out


def active_set(p: np.ndarray, g: np.ndarray, lower: np.ndarray, upper: np.ndarray, free) -> list:
    """The parameters of ``free`` that Newton steps move: not those at a bound whose gradient pushes
    them outwards (p_k <= lower_k with g_k > 0, or p_k >= upper_k with g_k < 0)."""
    return [k for k in free if not ((p[k] <= lower[k] and g[k] > 0) or (p[k] >= upper[k] and g[k] < 0))]
