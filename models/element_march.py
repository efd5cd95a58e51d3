r"""The element marcher of a collocated ODE/DAE: the collocation equations solved one element after the
other, all experiments at once (``mapaccum`` of one element's Newton solve, CasADi's rootfinder), an element
whose plain Newton fails solved again by :mod:`models.element_rescue`, and the failure message that names the
experiment, the element and, for an ODE, the time of a blow-up (:mod:`models.blow_up`).

:class:`models.trajectory.TrajectoryNumerics` (ODEs) and :class:`models.dae_march.DAETrajectoryNumerics` march
with :func:`march`; :func:`march_symbolic` is its symbolic form for the mapped outputs of
:mod:`models.trajectory`.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from .blow_up import ElementFailure
from .errors import StateSolveError
from .element_rescue import element_failures, rescue_elements

__all__ = ["march_functions", "march_failure", "march", "rescue_march", "march_symbolic", "MARCH_IN_CASADI_MAX"]

#: up to this many experiments the elements are solved inside one CasADi call (its rootfinder,
#: mapped); more experiments are solved element by element with batched NumPy (fewer calls per point)
MARCH_IN_CASADI_MAX = 8


def march_functions(cm) -> tuple:
    """(march, residuals, Umap) of a collocated model: march(w_0, P) -> (W_end, V) solves the elements one
    after the other (``mapaccum`` of one element's Newton solve, CasADi's rootfinder of
    :meth:`models.collocation.CollocatedModel.element_functions`; column k of P is (p, U_k, h_k));
    residuals(V, (x_start, P)) are the elements' collocation residuals; U = Umap q the inputs at every
    point (linear in q).  Cached on the model."""
    def build():
        dyn, d, N = cm.dynamic, cm.mesh.degree, cm.mesh.n_elements
        rf, R = cm.element_functions()
        n_w = dyn.n_x + dyn.n_z
        ws, par = ca.SX.sym("ws", n_w), ca.SX.sym("par", dyn.n_p + dyn.n_u * d + 1)
        V = rf(ca.repmat(ws, d, 1), ca.vertcat(ws[:dyn.n_x], par))
        march_f = ca.Function("step", [ws, par], [V[-n_w:], V]).mapaccum("march", N)
        return march_f, R.map(N), cm.point_input_map()
    return cm.cache.get_or_make("march_functions", None, build)


def march_failure(cm, p, inputs, j: int, k: int) -> StateSolveError:
    """The one failure of the marcher: no collocation solution on element k of experiment j (0-based).

    An :class:`models.blow_up.ElementFailure`: for an ODE its message says whether the trajectory blows up (with
    the time; :func:`models.blow_up.blow_up_of` gives the :class:`models.errors.BlowUpError`) or the element is too
    stiff, diagnosed by a SciPy integration of the experiment when the message is read (never in the numerics)."""
    b = np.asarray(cm.mesh.boundaries)
    p = p if np.ndim(p) == 1 else np.asarray(p)[j]
    q = np.asarray(inputs)[j]
    where = (f"integration of {cm.dynamic.name!r} failed at p = {np.asarray(p).tolist()}, inputs {q.tolist()}: "
             f"no collocation solution on the element [{b[k]:g}, {b[k + 1]:g}] of experiment {j + 1}")
    return ElementFailure(where, cm.dynamic, p, q, float(b[-1]))


def march(cm, W0: np.ndarray, p, U: np.ndarray, inputs) -> np.ndarray:
    r"""The element marcher: every experiment's collocation solution element after element (Newton on
    R(V_k; w_k0, p, U_k, h_k) = 0, the module docstring), all experiments at once.

    Up to :data:`MARCH_IN_CASADI_MAX` experiments (or with algebraic states) in one CasADi call (the
    ``mapaccum`` of CasADi's rootfinder, :func:`march_functions`, mapped over the experiments); more
    experiments of an ODE element by element with batched NumPy Newton steps
    (:meth:`TrajectoryNumerics.element_newton`, fewer calls per point).  Every element's residual is
    checked (:func:`element_failures`); an experiment with a failed element is marched again from that
    element with Newton damped by a line search where plain Newton fails (:func:`rescue_march`, a stiff
    model on long elements), which leaves every element solved before unchanged.

    Parameters
    ----------
    cm : models.collocation.CollocatedModel
    W0 : ndarray (n, n_w)          the initial points (x(0), z(0)) of the n experiments
    p : ndarray (n_p,) or (n, n_p) the parameters, shared or one row per experiment
    U : ndarray (n, N, n_u d)      the inputs at every element's d points
    inputs : ndarray (n, d_q)      the experiments' input rows (named in the failure message)

    Returns
    -------
    V : ndarray (n, N, n_w d)      every element's unknowns at its d Radau points

    Raises
    ------
    StateSolveError
        :func:`march_failure` of the first element whose residual is above the tolerance.
    """
    n, N = U.shape[0], U.shape[1]
    steps = np.diff(np.asarray(cm.mesh.boundaries))
    if n > MARCH_IN_CASADI_MAX and not cm.dynamic.n_z:
        num, xs, V = cm.state_numerics, W0, []
        for k in range(N):
            V.append(num.element_newton(xs, p, U[:, k], steps[k], inputs, k))
            xs = V[-1][:, -W0.shape[1]:]
        return np.stack(V, axis=1)
    P = np.concatenate([np.broadcast_to(p.reshape(-1, 1, p.shape[-1]), (n, N, p.shape[-1])), U,
                        np.broadcast_to(steps[None, :, None], (n, N, 1))], axis=2)   # (n, N, n_par)
    march_f = march_functions(cm)[0]
    fm = cm.cache.get_or_make("march_map", n, lambda: march_f.map(n), maxsize=8)
    W_end, V = (np.asarray(a) for a in fm(ca.DM(np.ascontiguousarray(W0.T)),
                                          ca.DM(np.ascontiguousarray(P.reshape(n * N, -1).T))))
    V, W_end = V.T.reshape(n, N, -1), W_end.T.reshape(n, N, -1)
    n_x, m = cm.dynamic.n_x, n * N
    XS = np.concatenate([W0[:, None, :n_x], W_end[:, :-1, :n_x]], axis=1)
    residual = cm.cache.get_or_make("element_residual_map", m, lambda: cm.element_functions()[1].map(m), maxsize=8)
    R = np.asarray(residual(V.reshape(m, -1).T, np.concatenate([XS, P], axis=2).reshape(m, -1).T)).T
    bad = element_failures(V.reshape(m, -1), R).reshape(n, N)
    if np.any(bad):
        return rescue_march(cm, W0, P, V, bad, p, inputs)
    return V


def rescue_march(cm, W0: np.ndarray, P: np.ndarray, V: np.ndarray, bad: np.ndarray, p, inputs) -> np.ndarray:
    """The march of :func:`march` again for the experiments with a failed element, from their first failed
    element on: each element by CasADi's plain Newton (the element's rootfinder, mapped) and, where that
    fails, by Newton with a line search (:func:`models.element_rescue.rescue_elements`).

    ``P`` (n, N, n_par) every element's (p, U_k, h_k), ``V`` (n, N, n_w d) the marched unknowns, ``bad``
    (n, N) the failed elements.  Returns V with those experiments' elements replaced; raises
    :func:`march_failure` of the first element that neither solves."""
    n_x, n_w = cm.dynamic.n_x, W0.shape[1]
    V = np.array(V, float)
    rows = np.flatnonzero(np.any(bad, axis=1))
    first = np.argmax(bad[rows], axis=1)
    rf = cm.element_functions()[0]
    for k in range(int(first.min()), V.shape[1]):
        js = rows[first <= k]
        ws = W0[js] if k == 0 else V[js, k - 1, -n_w:]
        par = np.concatenate([ws[:, :n_x], P[js, k]], axis=1)
        V0 = np.tile(ws, (1, cm.mesh.degree))
        rfm = cm.cache.get_or_make("element_rootfinder_map", js.size, lambda: rf.map(js.size), maxsize=8)
        Vk = np.asarray(rfm(ca.DM(np.ascontiguousarray(V0.T)), ca.DM(np.ascontiguousarray(par.T)))).T
        Rk = _element_residuals(cm, Vk, par)
        failed = element_failures(Vk, Rk)
        if np.any(failed):
            Vk[failed], Rk[failed] = rescue_elements(cm, V0[failed], par[failed])
            failed = element_failures(Vk, Rk)
            if np.any(failed):
                raise march_failure(cm, p, inputs, int(js[np.flatnonzero(failed)[0]]), k)
        V[js, k] = Vk
    return V


def _element_residuals(cm, V: np.ndarray, par: np.ndarray) -> np.ndarray:
    """The collocation residuals (m, n_w d) of m elements at their unknowns V (m, n_w d), par = (x_start, p, U, h)."""
    R = cm.element_functions()[1]
    Rm = cm.cache.get_or_make("element_residual_map", V.shape[0], lambda: R.map(V.shape[0]), maxsize=8)
    return np.asarray(Rm(ca.DM(np.ascontiguousarray(V.T)), ca.DM(np.ascontiguousarray(par.T)))).T


def march_symbolic(cm, p, q):
    """(y, max residual / (1 + max |V|) per element) of the collocation solution of an ODE as CasADi
    expressions of p and q: :func:`march_functions`' march in a graph (for its exact derivatives)."""
    dyn, d, N = cm.dynamic, cm.mesh.degree, cm.mesh.n_elements
    march_f, residuals, _ = march_functions(cm)
    U_all = ca.horzcat(*cm.point_inputs(q))
    P = ca.vertcat(ca.repmat(p, 1, N), ca.reshape(U_all, dyn.n_u * d, N), ca.DM(np.diff(cm.mesh.boundaries)).T)
    x0 = dyn.x0_fun(p, cm.initial_input(q))
    W_end, Vs = march_f(x0, P)
    R = residuals(Vs, ca.vertcat(ca.horzcat(x0, W_end[:, :-1]), P))
    v, r = ca.MX.sym("v", Vs.size1()), ca.MX.sym("r", R.size1())
    crit = ca.Function("crit", [v, r], [ca.mmax(ca.fabs(r)) / (1.0 + ca.mmax(ca.fabs(v)))]).map(N)
    return ca.vertcat(x0, ca.vec(Vs)), crit(Vs, R)


