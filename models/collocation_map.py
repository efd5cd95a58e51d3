r"""Outputs and output sensitivities of a collocated dynamic model at many experiments in one call.

For a :class:`models.collocation.CollocatedModel` (an ODE; no algebraic states) the collocation
solution is computed element by element: on element k with start x_k the Radau IIA stage values
V_k solve

.. math::  R(V_k; x_k, p, U_k, h_k) = \sum_j C_{jr} x_{kj} - h_k f(x_{kr}, p, u_{kr}) = 0,

by Newton (CasADi ``rootfinder``), x_{k+1} the last stage (``mapaccum`` over the elements).  The
outputs h at the sampling times and their sensitivities

.. math::  G = \frac{dh}{dp} = h_y \frac{dy}{dp} + h_p,

come from CasADi's derivative of that chain (the implicit-function theorem on every element: one
small dense solve per element, i.e. the block-bidiagonal solve of E_y S = -E_p), and one
CasADi Function evaluates them for all experiments (``map``).  Each element's residual after
Newton is returned as well, so that a failed element is never silent.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from .errors import StateSolveError

__all__ = ["output_sensitivity_function", "mapped_outputs", "outputs_and_sensitivities"]


def _march(cm, p, q):
    """(y, max residual per element) of the collocation solution as expressions of p and q."""
    dyn, d, N = cm.dynamic, cm.mesh.degree, cm.mesh.n_elements
    n_x = dyn.n_x
    rf, R = cm.element_functions()
    ws, pk = ca.MX.sym("ws", n_x), ca.MX.sym("par", dyn.n_p + dyn.n_u * d + 1)
    Vk = rf(ca.repmat(ws, d, 1), ca.vertcat(ws, pk))
    rk = R(Vk, ca.vertcat(ws, pk))
    bad = ca.mmax(ca.fabs(rk)) / (1.0 + ca.mmax(ca.fabs(Vk)))
    step = ca.Function("step", [ws, pk], [Vk[-n_x:], Vk, bad]).mapaccum("march", N)
    U_all = ca.horzcat(*cm.point_inputs(q))
    P = ca.vertcat(ca.repmat(p, 1, N), ca.reshape(U_all, dyn.n_u * d, N), ca.DM(np.diff(cm.mesh.boundaries)).T)
    x0 = dyn.x0_fun(p, cm.initial_input(q))
    _, Vs, bad = step(x0, P)
    return ca.vertcat(x0, ca.vec(Vs)), bad


def output_sensitivity_function(cm, derivatives: bool = True) -> ca.Function:
    """``(p, q) -> (h (n_S,), G (n_S, n_p), residual (1, N))`` of a collocated ODE model (module
    docstring), or without G (``derivatives=False``); cached on the model."""
    if cm.dynamic.n_z:
        raise ValueError("cm: the mapped outputs are for ODE models (no algebraic states)")

    def build():
        p, q = ca.MX.sym("p", cm.n_p), ca.MX.sym("q", cm.n_q_dim)
        y, bad = _march(cm, p, q)
        h = cm.h_fun(y, p, q)
        if derivatives:
            return ca.Function("outputs", [p, q], [h, ca.jacobian(h, p), bad], ["p", "q"], ["h", "G", "residual"])
        return ca.Function("outputs", [p, q], [h, bad], ["p", "q"], ["h", "residual"])
    return cm.cache.get_or_make("output_sensitivity_function", derivatives, build)


def _mapped(cm, derivatives, n):
    f = output_sensitivity_function(cm, derivatives)
    return cm.cache.get_or_make("output_sensitivity_map", (derivatives, n), lambda: f.map(n), maxsize=8)


def mapped_outputs(cm, p, inputs, tol: float = 1e-8) -> np.ndarray:
    """Outputs (n_q, n_S) of a collocated ODE model at p for every input row (one mapped call; the
    collocation solution of :meth:`models.collocation.CollocatedModel.integrated_outputs`)."""
    Q = np.atleast_2d(np.asarray(inputs, float))
    p = np.asarray(p, float).ravel()
    h, bad = (np.asarray(a) for a in _mapped(cm, False, Q.shape[0])(p, Q.T))
    _check(cm, p, Q, h, bad, tol)
    return h.T


def _check(cm, p, Q, h, bad, tol):
    """StateSolveError naming the experiment and element whose Newton solve failed."""
    bad = bad.reshape(Q.shape[0], -1)
    wrong = ~np.isfinite(bad) | (bad > tol)
    if np.any(wrong) or not np.all(np.isfinite(h)):
        j, k = np.argwhere(wrong)[0] if np.any(wrong) else (int(np.argwhere(~np.isfinite(h.T))[0][0]), 0)
        b = cm.mesh.boundaries
        raise StateSolveError(
            f"integration of {cm.dynamic.name!r} failed at p = {p.tolist()}, experiment {int(j) + 1} (inputs "
            f"{Q[int(j)].tolist()}): no collocation solution on the element [{b[int(k)]:g}, {b[int(k) + 1]:g}] "
            "(the trajectory blows up or is too stiff for the element); check p and the inputs, or give a finer mesh")


def outputs_and_sensitivities(cm, p, inputs, tol: float = 1e-8):
    """(h (n_q, n_S), G (n_q, n_S, n_p)) of a collocated ODE model at p for every input row, one
    mapped call; raises :class:`models.errors.StateSolveError` naming the experiment and element
    when an element's Newton solve did not converge (relative residual above ``tol``)."""
    Q = np.atleast_2d(np.asarray(inputs, float))
    p = np.asarray(p, float).ravel()
    h, G, bad = (np.asarray(a) for a in _mapped(cm, True, Q.shape[0])(p, Q.T))
    _check(cm, p, Q, h, bad, tol)
    if not np.all(np.isfinite(G)):
        raise StateSolveError(f"sensitivities of {cm.dynamic.name!r} at p = {p.tolist()} are not finite")
    return h.T, G.reshape(cm.n_S, Q.shape[0], cm.n_p).transpose(1, 0, 2)
