r"""The rescue of a collocation element whose plain Newton solve failed: solved in halves, then damped Newton.

Element k of a collocated model (:mod:`models.collocation`) has the unknowns V = (x_r, z_r), r = 1..d, that solve

.. math::

    R(V; x_{k0}, p, U_k, h_k) = 0 \qquad \text{(the collocation equations of the element)}.

The element marcher (:func:`models.element_march.march`) solves them by plain Newton from V = (x_k0, ..., x_k0).
On a stiff model (Robertson's kinetics: rates 0.04, 1e4, 3e7 over 1e5 s, or a rough start's rates
(0.12, 1e5, 3e6) on the element [4931, 14045] s) an element of the size the sampling asks for holds a
solution (Radau IIA is L-stable) that plain Newton from that guess does not reach (it stalls at
max |R| ~ 0.15); Newton damped by a line search from the same guess may stall too, or land on a spurious
root of the collocation equations (they have several for a long element of a nonlinear model).  So the
rescue continues in the element length: the element is solved in two halves, each by plain Newton or, where
that fails, in halves again (at most :data:`SPLIT_DEPTH` times: 2^SPLIT_DEPTH pieces), and the halves'
collocation polynomials at the element's Radau points start Newton on the element's own equations, damped by
a backtracking line search on phi(V) = |R(V)|^2 / 2,

.. math::

    V \leftarrow V - \lambda R_V^{-1} R, \qquad \lambda = 1, 1/2, 1/4, \ldots \text{ until }
    |R(V - \lambda \Delta)| \le (1 - 10^{-4} \lambda) |R(V)|

(Armijo).  The start lies within the halves' discretisation error of the element's solution, so Newton
converges to the root that continues the solution of the short pieces, not to a spurious one.  The caps
(iterations, line-search halvings, depth) keep a failure cheap: a trial point of a fit's line search at which
the trajectory blows up fails in milliseconds.  Only elements whose plain solve failed are redone, so every
trajectory that was solved before is unchanged to the bit.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from .batched import batched_function

__all__ = ["damped_element_solve", "rescue_elements", "element_failures", "RESIDUAL_TOL", "RESCUE_MAX_ITER",
           "SPLIT_DEPTH"]

#: an element's collocation solution is accepted when max |R| <= RESIDUAL_TOL (1 + max |V|)
RESIDUAL_TOL = 1e-8
#: damped Newton iterations per element before the rescue counts as failed
RESCUE_MAX_ITER = 60
#: how often an element is split in halves (recursively: at most 2^SPLIT_DEPTH pieces) for a start of its
#: damped Newton
SPLIT_DEPTH = 10
#: Armijo's sufficient decrease of |R| per unit step length
_ARMIJO = 1e-4
#: smallest step length of the line search (a row whose step falls below it has stalled)
_MIN_STEP = 2.0 ** -12


def element_failures(V: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Rows (one element of one experiment) whose unknowns V are not finite or whose collocation residual
    R is above RESIDUAL_TOL (1 + max |V|): the element's Newton solve failed."""
    return ~(np.all(np.isfinite(V), axis=1) & (np.max(np.abs(R), axis=1) <= RESIDUAL_TOL * (1 + np.max(np.abs(V), axis=1))))


def rescue_elements(cm, V0: np.ndarray, par: np.ndarray) -> tuple:
    """(V, R) of m elements whose plain Newton failed, each solved from the guess of its halves
    (:func:`split_guess`) by :func:`damped_element_solve` (module docstring).  ``V0`` (m, n_w d) the elements'
    start points repeated, ``par`` (m, n_x + n_p + n_u d + 1) as in :func:`damped_element_solve`; the caller
    judges the result with :func:`element_failures` (rows without a guess keep V0)."""
    V, R = np.array(V0, float), np.full(V0.shape, np.nan)
    n_w = V0.shape[1] // cm.mesh.degree
    for j in range(V0.shape[0]):
        guess = split_guess(cm, V0[j, :n_w], par[j], SPLIT_DEPTH)
        if guess is not None:
            Vj, Rj = damped_element_solve(cm, guess[None], par[j][None])
            V[j], R[j] = Vj[0], Rj[0]
    return V, R


def _solve_one(cm, w: np.ndarray, par: np.ndarray, depth: int) -> np.ndarray | None:
    """One element's solution (n_w d,) from its start w: CasADi's plain Newton, else (``depth`` > 0) the damped
    Newton from :func:`split_guess`; None when neither solves it."""
    V0 = np.tile(w, cm.mesh.degree)
    V = np.asarray(cm.element_functions()[0](V0, par)).ravel()
    R = _blocks(cm, 1)(V[None], par[None])[0][:, :, 0]
    if not element_failures(V[None], R)[0]:
        return V
    guess = split_guess(cm, w, par, depth) if depth > 0 else None
    if guess is None:
        return None
    V, R = damped_element_solve(cm, guess[None], par[None])
    return None if element_failures(V, R)[0] else V[0]


def split_guess(cm, w_start: np.ndarray, par: np.ndarray, depth: int) -> np.ndarray | None:
    """A guess of one element's unknowns (n_w d,): the element solved in two halves (each by
    :func:`_solve_one`, split again at most ``depth - 1`` times), the halves' collocation polynomials
    (Lagrange on each half's d + 1 points) at the element's Radau points; None when a half does not solve.

    ``w_start`` the element's start (x, z), ``par`` its (x_start, p, U, h); u(t) within the element is
    linear in t (constants, and controls constant or linear between grid points, which are element
    boundaries), so the inputs at the halves' points lie on the straight line through U."""
    dyn, d = cm.dynamic, cm.mesh.degree
    n_x, n_p, n_u = dyn.n_x, dyn.n_p, dyn.n_u
    tau = np.asarray(cm.tau)
    p, U, h = par[n_x:n_x + n_p], par[n_x + n_p:-1].reshape(d, n_u), float(par[-1])
    if d > 1 and n_u:                                                   # (2, n_u): slope, value at 0
        line = np.polyfit(tau[1:], U, 1)
    else:
        line = np.vstack([np.zeros((1, n_u)), U[:1]])
    w, pts = np.asarray(w_start, float), []
    for i in range(2):
        s = (i + tau[1:]) / 2                                           # the half's points in [0, 1]
        sub = np.r_[w[:n_x], p, (line[0][None, :] * s[:, None] + line[1][None, :]).ravel(), h / 2]
        V = _solve_one(cm, w, sub, depth - 1)
        if V is None:
            return None
        pts.append(np.vstack([w, V.reshape(d, -1)]))
        w = V[-w.size:]
    return _at_radau_points(np.stack(pts), tau)


def _at_radau_points(pts: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """The piecewise collocation polynomial of ``parts`` equal sub-elements (pts (parts, d + 1, n_w): each
    sub-element's start and Radau-point values) at the whole element's Radau points, stacked (n_w d,)."""
    parts, d = pts.shape[0], tau.size - 1
    out = []
    for t in tau[1:]:
        i = min(int(t * parts), parts - 1)
        s = t * parts - i                                               # position within sub-element i
        basis = np.array([np.prod([(s - tau[r]) / (tau[j] - tau[r]) for r in range(d + 1) if r != j])
                          for j in range(d + 1)])
        out.append(basis @ pts[i])
    return np.concatenate(out)


def _blocks(cm, m: int):
    """(R, R_V) of one element as a function of (V, par), par = (x_start, p, U, h) (the parameters of
    :meth:`models.collocation.CollocatedModel.element_functions`), mapped over m elements; cached on the model."""
    def build():
        R = cm.element_functions()[1]
        V, par = ca.SX.sym("V", R.size1_in(0)), ca.SX.sym("par", R.size1_in(1))
        r = R(V, par)
        return ca.Function("element_rescue_blocks", [V, par], [r, ca.jacobian(r, V)])
    f = cm.cache.get_or_make("element_rescue_blocks", None, build)
    return cm.cache.get_or_make("element_rescue_map", m, lambda: batched_function(f, m), maxsize=8)


def damped_element_solve(cm, V0: np.ndarray, par: np.ndarray, max_iter: int = RESCUE_MAX_ITER) -> tuple:
    r"""V with R(V; par) = 0 for m elements at once by Newton with a backtracking line search (module docstring).

    Parameters
    ----------
    cm : models.collocation.CollocatedModel
    V0 : ndarray (m, n_w d)     the start of every element's unknowns (e.g. its start point repeated)
    par : ndarray (m, n_x + n_p + n_u d + 1)    every element's (x_start, p, U, h)
    max_iter : int

    Returns
    -------
    V : ndarray (m, n_w d)      the unknowns reached (a row stops when max |R| <= 1e-13, its step is below
                                1e-12 (1 + max |V|), or the line search finds no decrease)
    R : ndarray (m, n_w d)      the residuals there (the caller judges them, e.g.
                                :func:`models.trajectory.element_failures`)
    """
    V = np.array(V0, float)
    par = np.ascontiguousarray(par, dtype=float)
    m = V.shape[0]
    blocks = _blocks(cm, m)                     # every evaluation at all m rows: one mapped function
    R, RV = (np.asarray(a) for a in blocks(V, par))
    R = R[:, :, 0]
    active = np.ones(m, bool)
    for _ in range(max_iter):
        norm = np.linalg.norm(R, axis=1)
        active &= np.isfinite(norm) & (np.max(np.abs(R), axis=1) > 1e-13)
        if not np.any(active):
            break
        step = _newton_steps(RV, R, active)
        active &= np.all(np.isfinite(step), axis=1)
        lam = np.where(active, 1.0, 0.0)
        searching = active.copy()
        trial = V.copy()
        while np.any(searching):
            trial[searching] = V[searching] - lam[searching, None] * step[searching]
            r = blocks(trial, par)[0][:, :, 0]
            good = np.all(np.isfinite(r), axis=1) & (np.linalg.norm(r, axis=1) <= (1 - _ARMIJO * lam) * norm)
            searching &= ~good
            lam[searching] *= 0.5
            stuck = searching & (lam < _MIN_STEP)
            searching &= ~stuck
            active &= ~stuck
        dv = np.where(active[:, None], lam[:, None] * step, 0.0)
        V = np.where(active[:, None], trial, V)
        R_new, RV_new = (np.asarray(a) for a in blocks(V, par))
        R, RV = np.where(active[:, None], R_new[:, :, 0], R), np.where(active[:, None, None], RV_new, RV)
        active &= np.max(np.abs(dv), axis=1) > 1e-12 * (1 + np.max(np.abs(V), axis=1))
    return V, np.asarray(blocks(V, par)[0])[:, :, 0]


def _newton_steps(RV: np.ndarray, R: np.ndarray, active: np.ndarray) -> np.ndarray:
    """R_V^{-1} R of the active rows (NaN elsewhere and where R_V is singular)."""
    step = np.full(R.shape, np.nan)
    idx = np.flatnonzero(active)
    try:
        step[idx] = np.linalg.solve(RV[idx], R[idx][:, :, None])[:, :, 0]
    except np.linalg.LinAlgError:               # a singular R_V: row by row, the singular ones left NaN
        for j in idx:
            try:
                step[j] = np.linalg.solve(RV[j], R[j])
            except np.linalg.LinAlgError:
                continue
    return step
