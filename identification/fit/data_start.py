r"""Start trajectories of a collocated ODE's full-space NLP through the data (issue 30 item 1).

The full-space NLP (:func:`identification.fit.estimator.fit_static`, Ipopt on parameters and states
together) may start its states anywhere: unlike a shooting method it does not need a trajectory
consistent with the start values p0.  Where the outputs are linear in the states,

.. math:: h(x, p, u) = H x + c(p),\qquad H \text{ constant (not depending on } x, p, u),

the data tell the states along the row space of H, and the start is

.. math::

    \hat x_j(t) = x_j(t; p_0) + H_{S_j}^{+}\, \delta_j(t), \qquad
    \delta_{jk}(t_i) = \bar z_{jk}(t_i) - h_k(x_j(t_i; p_0), p_0),

with x_j(t; p0) the collocation solution at p0 (the simulation), S_j the sensors with data in
experiment j, H_S^+ the pseudo-inverse of their rows of H, and each sensor's correction delta_jk
interpolated linearly in time between its sampling times (0 at t = 0 when 0 is not one of them:
the initial state is the simulation's; held at its last value after the last).  A state that is an
output (a row of H selects it) then passes through the series means z̄ at every sampling time and
follows the simulation's shape in between; states outside the row space of H (not measured, not
following linearly from the outputs) keep the simulation; the initial point is the simulation's
x_0(p0, u).  Models whose outputs are not of that form (H depends on x, p or u, or c on u), and DAE
models, start from the simulation (:func:`data_trajectories` returns None).

The start only moves where Ipopt begins; the problem and its solution are unchanged.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["data_trajectories", "linear_outputs"]


def linear_outputs(dynamic) -> tuple | None:
    """(H (n_S, n_x), c(p) as a CasADi Function of p) when the outputs are h(x, z, p, u) = H x + c(p) with H
    constant, else None (kept in the dynamic model's cache)."""
    def build():
        if dynamic.n_z:
            return None
        x, z = ca.SX.sym("x", dynamic.n_x), ca.SX.sym("z", dynamic.n_z)
        p, u = ca.SX.sym("p", dynamic.n_p), ca.SX.sym("u", dynamic.n_u)
        h = dynamic.h_fun(x, z, p, u)
        J = ca.jacobian(h, x)
        if ca.depends_on(J, ca.vertcat(x, z, p, u)):
            return None
        c = ca.substitute(h, x, ca.DM.zeros(dynamic.n_x))
        if dynamic.n_u and ca.depends_on(c, u):
            return None
        return np.asarray(ca.evalf(J)), ca.Function("h_offset", [p], [c])
    return dynamic.cache.get_or_make("data_start.linear_outputs", None, build)


def _correction(t_points, t_data, d):
    """The corrections d (n_t,) at the sampling times t_data interpolated linearly at t_points: 0 at t = 0
    when 0 is not a sampling time, held at the last value after the last."""
    if t_data[0] > 0:
        t_data, d = np.r_[0.0, t_data], np.r_[0.0, d]
    return np.interp(t_points, t_data, d)


def data_trajectories(cm, flat, p0, Y_sim) -> np.ndarray | None:
    r"""The start trajectories of every experiment through the data (module docstring), shape (n_q, n_y) like
    ``Y_sim``, or None when the outputs are not linear in the states (or no sensor has data).

    Parameters
    ----------
    cm : models.collocation.CollocatedModel       the collocated ODE (its outputs the data's (sensor, time) pairs)
    flat : identification.Measurements             the flat data of ``cm`` (series means and counts per pair)
    p0 : ndarray (n_p,)                            start values
    Y_sim : ndarray (n_q, n_y)                     the collocation solution at p0 (the simulation)
    """
    dyn = cm.dynamic
    lin = linear_outputs(dyn)
    if lin is None:
        return None
    H, offset = lin
    c = np.asarray(offset(p0)).ravel()
    counts, zbar = flat.counts(), flat.means()                         # (n_q, n_pairs)
    n_x, n_q = dyn.n_x, Y_sim.shape[0]
    t_points = cm.point_times()
    X = Y_sim.reshape(n_q, t_points.size, n_x)
    Xs = X.copy()
    sensor_of = np.array([dyn.sensors.index(s) for s, _ in cm.outputs])
    time_of = np.array([t for _, t in cm.outputs])
    moved = False
    for j in range(n_q):
        rows, D = [], []
        for k in range(dyn.n_S):
            cols = np.flatnonzero((sensor_of == k) & (counts[j] > 0) & np.isfinite(zbar[j]))
            if cols.size == 0 or not np.any(H[k]):
                continue
            order = cols[np.argsort(time_of[cols])]
            tk = time_of[order]
            at = np.argmin(np.abs(t_points[None, :] - tk[:, None]), axis=1)   # sampling times are mesh points
            d = zbar[j, order] - (X[j, at] @ H[k] + c[k])
            rows.append(k)
            D.append(_correction(t_points, tk, d))
        if not rows:
            continue
        Xs[j] += np.column_stack(D) @ np.linalg.pinv(H[rows]).T
        moved = True
    if not moved:
        return None
    Xs[:, 0] = X[:, 0]                                                # the initial state stays x0(p0, u)
    return Xs.reshape(Y_sim.shape)
