"""Exact first- and second-order sensitivities through the implicit state (paper's appendix).

For every input q_j with state y_j = y(p, q_j) solving E(y, p, q_j) = 0:

    y'(p)   = -(dE/dy)^{-1} dE/dp                                    (first order)
    G_j     = dh/dy y' + dh/dp        total sensitivity of h, (n_S, n_p)

and, for a weight vector lambda in R^{n_S}, the Hessian of phi(p) = lambda^T h(y(p), p, q_j)

    d^2 phi / dp^2 = Z^T  nabla^2_{(y,p)} [lambda^T h + mu^T E]  Z,   Z = [y'; I],
    (dE/dy)^T mu = -(dh/dy)^T lambda,

which is the paper's appendix formula with the y'' term folded into the adjoint mu
(identical in exact arithmetic, one linear solve instead of n_p^2).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sps

from .state import numerics, solve_states_generic

__all__ = ["Sensitivities", "sensitivities"]


class Sensitivities:
    """Model outputs and sensitivities at all inputs.

    Attributes
    ----------
    h : ndarray (n_q, n_S)        model outputs
    G : ndarray (n_q, n_S, n_p)   total derivatives dh/dp through the state
    """

    __slots__ = ("h", "G", "_num", "_p", "_inputs", "_Y", "_cache")

    def __init__(self, h, G, num, p, inputs, Y, cache):
        self.h, self.G = h, G
        self._num, self._p, self._inputs, self._Y, self._cache = num, p, inputs, Y, cache

    @property
    def state_derivatives(self) -> np.ndarray:
        """y'(p) = -(dE/dy)^{-1} dE/dp at every input, shape (n_q, n_y, n_p) (state units per
        parameter unit).  For dense states it is a view of the stored array: do not modify it."""
        n_p = self.G.shape[2]
        return np.stack([Z[:Z.shape[0] - n_p] for _, _, Z in self._cache])

    def adjoint(self, lam: np.ndarray) -> np.ndarray:
        """The adjoint states mu_j solving (dE/dy)_j^T mu_j = -(dh/dy)_j^T lam_j at every input,
        shape (n_q, n_y), for weights ``lam`` (n_q, n_S) (the multipliers of E that make
        lam_j^T h + mu_j^T E stationary in y_j)."""
        lam = np.asarray(lam, float)
        n_y = self._Y.shape[1] if np.ndim(self._Y) == 2 else 0
        out = np.zeros((lam.shape[0], n_y))
        for j, (solve, hy, _) in enumerate(self._cache):
            if solve is not None:
                out[j] = solve(-(hy.T @ lam[j]), trans=1)
        return out

    def hessians(self, lam: np.ndarray) -> np.ndarray:
        """Sum over inputs of d^2/dp^2 [lam_j^T h(y_j(p), p, q_j)] for several weight sets.

        Parameters
        ----------
        lam : ndarray (m, n_q, n_S)
            m weight sets.

        Returns
        -------
        ndarray (m, n_p, n_p)
        """
        lam = np.asarray(lam, float)
        m = lam.shape[0]
        n_p = self.G.shape[2]
        out = np.zeros((m, n_p, n_p))
        for j, (solve, hy, Z) in enumerate(self._cache):
            for a in range(m):
                lj = lam[a, j]
                if not np.any(lj):
                    continue
                if solve is not None:
                    mu = solve(-(hy.T @ lj), trans=1)
                else:
                    mu = np.zeros(0)
                Hl = self._num.point("lag_hess")(self._Y[j], self._p, self._inputs[j], lj, mu)[0]
                out[a] += Z.T @ (Hl @ Z)
        return 0.5 * (out + out.transpose(0, 2, 1))

    def output_hessians(self) -> np.ndarray:
        """d^2 h_jk / dp^2 of every output k at every input j through the state (exact, one adjoint
        per output), shape (n_q, n_S, n_p, n_p) in output units per parameter unit squared."""
        n_q, n_S, n_p = self.G.shape
        eye = np.eye(n_S)
        out = np.zeros((n_q, n_S, n_p, n_p))
        for j, (solve, hy, Z) in enumerate(self._cache):
            for k in range(n_S):
                mu = solve(-(hy.T @ eye[k]), trans=1) if solve is not None else np.zeros(0)
                Hl = self._num.point("lag_hess")(self._Y[j], self._p, self._inputs[j], eye[k], mu)[0]
                out[j, k] = np.asarray(Z.T @ (Hl @ Z))
        return 0.5 * (out + out.transpose(0, 1, 3, 2))


class _BatchedSensitivities(Sensitivities):
    """Dense-state variant: all inputs in one mapped call, batched linear algebra."""

    __slots__ = ()

    @property
    def state_derivatives(self) -> np.ndarray:
        Z = self._cache[2]
        if Z is None:
            return np.zeros((self.G.shape[0], 0, self.G.shape[2]))
        return Z[:, :Z.shape[1] - Z.shape[2], :]

    def adjoint(self, lam: np.ndarray) -> np.ndarray:
        Ey, hy, Z = self._cache
        if Z is None:
            return np.zeros((self.G.shape[0], 0))
        rhs = -np.einsum("jsy,js->jy", hy, np.asarray(lam, float))
        return np.linalg.solve(Ey.transpose(0, 2, 1), rhs[:, :, None])[:, :, 0]

    def hessians(self, lam: np.ndarray) -> np.ndarray:
        lam = np.asarray(lam, float)
        Z = self._cache[2]
        n_q, n_p = self._inputs.shape[0], self.G.shape[2]
        f = self._num.batched("lag_hess", n_q)
        out = np.zeros((lam.shape[0], n_p, n_p))
        for a in range(lam.shape[0]):
            if Z is None:                                   # explicit model: Z = I, no adjoint
                Hl = f(self._Y, self._p, self._inputs, lam[a], np.zeros((n_q, 0)))[0]
                out[a] = Hl.sum(axis=0)
                continue
            Hl = f(self._Y, self._p, self._inputs, lam[a], self.adjoint(lam[a]))[0]
            out[a] = np.einsum("jva,jvw,jwb->ab", Z, Hl, Z, optimize=True)
        return 0.5 * (out + out.transpose(0, 2, 1))

    def output_hessians(self) -> np.ndarray:
        Ey, hy, Z = self._cache
        n_q, n_S, n_p = self.G.shape
        f = self._num.batched("lag_hess", n_q)
        out = np.zeros((n_q, n_S, n_p, n_p))
        for k in range(n_S):
            lam = np.zeros((n_q, n_S))
            lam[:, k] = 1.0
            if Z is None:                                   # explicit model: Z = I, no adjoint
                out[:, k] = f(self._Y, self._p, self._inputs, lam, np.zeros((n_q, 0)))[0]
                continue
            rhs = -hy[:, k, :]
            mu = np.linalg.solve(Ey.transpose(0, 2, 1), rhs[:, :, None])[:, :, 0] if Ey.shape[1] else rhs
            Hl = f(self._Y, self._p, self._inputs, lam, mu)[0]
            out[:, k] = np.einsum("jva,jvw,jwb->jab", Z, Hl, Z)
        return 0.5 * (out + out.transpose(0, 1, 3, 2))


def _sensitivities_batched(model, num, p, inputs, Y):
    """All inputs in one mapped call; for an explicit model G = dh/dp and Z = I (stored as None)."""
    n_q = inputs.shape[0]
    h, Ey, Ep, hy, hp = num.batched("sens", n_q)(Y, p, inputs)
    h = h[:, :, 0]
    if not model.n_y:
        return _BatchedSensitivities(h, hp, num, p, inputs, Y, (None, None, None))
    yp = -np.linalg.solve(Ey, Ep)
    G = np.einsum("jsy,jyp->jsp", hy, yp) + hp
    eye = np.broadcast_to(np.eye(model.n_p), (n_q, model.n_p, model.n_p))
    Z = np.concatenate([yp, eye], axis=1)
    return _BatchedSensitivities(h, G, num, p, inputs, Y, (Ey, hy, Z))


def _dense(a) -> np.ndarray:
    return a.toarray() if sps.issparse(a) else np.asarray(a, float)


def sensitivities(model, p, inputs, Y) -> Sensitivities:
    """Outputs h and total sensitivities G = dh/dp at every input (exact, by AD + IFT), by the model's
    numerics (:attr:`models.Model.state_numerics`)."""
    p = np.asarray(p, float).ravel()
    inputs = np.atleast_2d(np.asarray(inputs, float))
    return model.state_numerics.sensitivities(p, inputs, Y)


def generic_sensitivities(model, p: np.ndarray, inputs: np.ndarray, Y) -> Sensitivities:
    """:func:`sensitivities` by the generic solves y'(p) = -(dE/dy)^{-1} dE/dp input by input (sparse LU), or all
    inputs in one batched call for a small (dense) state."""
    num = numerics(model)
    n_q = inputs.shape[0]
    if num.dense:
        Y = np.zeros((n_q, 0)) if not model.n_y else np.asarray(Y, float)
        return _sensitivities_batched(model, num, p, inputs, Y)
    h = np.zeros((n_q, model.n_S))
    G = np.zeros((n_q, model.n_S, model.n_p))
    cache = []
    for j in range(n_q):
        hj, Ey, Ep, hy, hp = num.point("sens")(Y[j], p, inputs[j])
        h[j] = hj
        hp = _dense(hp).reshape(model.n_S, model.n_p)       # a column comes back 1-D when n_p = 1
        if model.n_y:
            solve = num.factor(Ey)
            Ep = _dense(Ep).reshape(model.n_y, model.n_p)
            yp = -solve(Ep)
            if yp.ndim == 1:
                yp = yp[:, None]
            G[j] = np.asarray(hy @ yp) + hp
            Z = np.vstack([yp, np.eye(model.n_p)])
        else:
            solve, hy = None, np.zeros((model.n_S, 0))
            G[j] = hp
            Z = np.eye(model.n_p)
        cache.append((solve, hy, Z))
    return Sensitivities(h, G, num, p, inputs, Y, cache)


class StateSolve:
    r"""The generic numerics of a model E(y, p, q) = 0 (:attr:`models.Model.state_numerics`): the states by
    Newton input by input (sparse LU of dE/dy; small dense states all inputs at once,
    :func:`models.state.solve_states_generic`), the sensitivities y'(p) = -(dE/dy)^{-1} dE/dp likewise
    (:func:`generic_sensitivities`).  The other strategy is the element marcher of a collocated ODE or index-1 DAE
    (:class:`models.trajectory.TrajectoryNumerics`, :class:`models.dae_march.DAETrajectoryNumerics`); they have the
    same operations and capabilities.

    Attributes
    ----------
    model : models.Model
    reduced_space : bool    False: the fit solves the full-space NLP (the states are unknowns)
    merges_fits : bool      False: batched fits use the batch engine, not merged member fits
    """

    reduced_space = False
    merges_fits = False

    def __init__(self, model):
        self.model = model

    def solve_states(self, p: np.ndarray, inputs: np.ndarray, Y0=None) -> np.ndarray:
        """The states y_j (n_q, n_y) solving E(y_j, p, q_j) = 0 (:func:`models.state.solve_states_generic`)."""
        return solve_states_generic(self.model, p, inputs, Y0)

    def sensitivities(self, p: np.ndarray, inputs: np.ndarray, Y) -> Sensitivities:
        """h and G = dh/dp at the states Y (:func:`generic_sensitivities`)."""
        return generic_sensitivities(self.model, p, inputs, Y)

    def marched_states(self, p, inputs, guess):
        """None: no solve of all inputs from a predicted guess of its own (the caller's solve is used)."""
        return None

    def integrated_outputs(self, p: np.ndarray, inputs: np.ndarray, guess=None) -> np.ndarray:
        """h (n_q, n_S) at the states the model integrates by itself, its own state guess (``y_guess``: for a
        collocated DAE the element march, :func:`models.element_march.march`); ``guess`` is not used."""
        model = self.model
        return np.array([np.asarray(model.h_fun(model.y_guess(p, q), p, q)).ravel() for q in inputs])
