r"""A damped Newton solve of one collocation element: the rescue of an element whose plain Newton failed.

Element k of a collocated model (:mod:`models.collocation`) has the unknowns V = (x_r, z_r), r = 1..d, that solve

.. math::

    R(V; x_{k0}, p, U_k, h_k) = 0 \qquad \text{(the collocation equations of the element)}.

The element marcher (:func:`models.trajectory.march`) solves them by plain Newton from V = (x_k0, ..., x_k0).
On a stiff model (Robertson's kinetics: rates 0.04, 1e4, 3e7 over 1e5 s) an element of the size the
sampling asks for (1e4 s) holds a solution (Radau IIA is L-stable) that plain Newton from that guess does not
reach: its full steps overshoot the fast quasi-steady state and stall with max |R| ~ 0.3.  Newton with a
backtracking line search on the merit function phi(V) = |R(V)|^2 / 2,

.. math::

    V \leftarrow V - \lambda R_V^{-1} R, \qquad \lambda = 1, 1/2, 1/4, \ldots \text{ until }
    |R(V - \lambda \Delta)| \le (1 - 10^{-4} \lambda) |R(V)|,

(the Armijo condition for the Newton direction, which descends phi wherever R_V is regular) converges there
(30-40 iterations for a 1e5 s element).  Only elements whose plain solve failed are redone, so every
trajectory that was solved before is unchanged to the bit.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from .batched import batched_function

__all__ = ["damped_element_solve", "RESCUE_MAX_ITER"]

#: damped Newton iterations per element before the rescue counts as failed
RESCUE_MAX_ITER = 200
#: Armijo's sufficient decrease of |R| per unit step length
_ARMIJO = 1e-4
#: smallest step length of the line search
_MIN_STEP = 2.0 ** -30


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
