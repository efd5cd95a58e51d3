r"""Continuous refinement of the support points of an approximate design of an explicit static model.

With the design's supergradients fixed, every support point moves to a local maximum of the
sensitivity function

.. math::  \phi(x) = \sum_s a_s \operatorname{tr}\bigl(\nabla u_s\, J_s(x)^T W J_s(x)\bigr),\qquad
           J_s(x) = \partial h/\partial p\,(P_s, x),\ W = \operatorname{diag}(n_\text{series}/\sigma_k^2),

(:math:`a_s` the prior weights, or the worst-case measure times the standardization scale) within the
input bounds, by L-BFGS-B with the exact gradient :math:`\partial\phi/\partial x` from CasADi (the
function mapped over the parameter vectors); the weights are then re-optimised by the caller.  Only
explicit models (no state): for implicit and dynamic models the grid refinement of
:mod:`oed.approximate` is the only refinement.
"""
from __future__ import annotations

import casadi as ca
import numpy as np
from scipy.optimize import minimize

__all__ = ["SensitivityPolisher", "explicit_polisher"]


class SensitivityPolisher:
    """:math:`\\phi(x)` and its gradient for an explicit static model at a set of parameter vectors (see the
    module docstring); :meth:`polish` moves points to local maxima of :math:`\\phi` in a box."""

    def __init__(self, fun: ca.Function, P: np.ndarray):
        self._P = np.asarray(P, float)
        self._fm = fun.map(self._P.shape[0])
        self._n_p = self._P.shape[1]

    def value_grad(self, x, A) -> tuple:
        r""":math:`(\phi(x), \nabla_x\phi(x))` for the weighted supergradients A of shape (n_s, n_p, n_p)."""
        n_s = self._P.shape[0]
        Ah = np.hstack(list(np.asarray(A, float)))
        v, g = self._fm(np.tile(np.asarray(x, float)[:, None], (1, n_s)), self._P.T, Ah)
        return float(np.sum(np.asarray(v))), np.asarray(g).sum(axis=1)

    def polish(self, X, A, lo, hi) -> np.ndarray:
        """Every row of X moved to a local maximum of phi within [lo, hi] (L-BFGS-B, exact gradient); a row is
        kept where the search does not improve phi."""
        out = []
        for x0 in np.asarray(X, float):
            f0 = self.value_grad(x0, A)[0]
            res = minimize(lambda x: tuple(-np.asarray(v) for v in self.value_grad(x, A)), x0, jac=True,
                           method="L-BFGS-B", bounds=list(zip(lo, hi)), options={"ftol": 1e-15, "gtol": 1e-12})
            x1 = np.clip(res.x, lo, hi)
            out.append(x1 if self.value_grad(x1, A)[0] > f0 else x0)
        return np.array(out)


def explicit_polisher(model, P, sigma, sensors, n_series) -> SensitivityPolisher | None:
    """The polisher of an explicit static model (None for an implicit one; a dynamic model's design points are
    times, which :func:`oed.approximate.approximate_design` does not polish)."""
    if getattr(model, "n_y", 1) != 0:
        return None
    sig = np.broadcast_to(np.asarray(sigma, float).ravel(), (model.n_S,))
    chosen = range(model.n_S) if sensors is None else [model.sensors.index(s) for s in sensors]
    W = np.array([float(n_series) / sig[k] ** 2 if k in chosen else 0.0 for k in range(model.n_S)])
    S = ca.SX if model.symbolic == "SX" else ca.MX
    p, q, A = S.sym("p", model.n_p), S.sym("q", model.n_q_dim), S.sym("A", model.n_p, model.n_p)
    J = ca.jacobian(model.h_fun(S(0, 1), p, q), p)
    phi = ca.trace(ca.mtimes([A, J.T, ca.diag(ca.DM(W)), J]))
    return SensitivityPolisher(ca.Function("phi", [q, p, A], [phi, ca.gradient(phi, q)]), P)
