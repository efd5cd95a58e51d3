r"""Weights of an approximate design on a finite candidate set (pseudo-Bayesian and standardized maximin).

Pseudo-Bayesian: :math:`\max_{w\in\Delta}\sum_s \pi_s u_s(\sum_x w_x F_s(x))` (utilities of
:mod:`oed.robust`), first by the multiplicative algorithm
:math:`w_x \leftarrow w_x\,(g(x)/\sum_y w_y g(y))^{\delta}` (D: :math:`\delta = 1`, A, E: 1/2), which
finds the support, then by SLSQP on the candidates that carry weight or where :math:`g` is largest, with the
exact gradient :math:`\partial\Phi/\partial w_x = g(x)`.

Standardized maximin: :math:`\max_{w\in\Delta, t} t` s.t. :math:`c_s(w) \ge t` for every parameter vector,
by SLSQP with the exact constraint gradients :math:`\kappa_s d_s(x)`.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

from .criteria import Criterion
from .robust import directional, utilities

__all__ = ["information_of", "multiplicative_weights", "bayes_weights", "maximin_weights", "standardized"]

#: weights below this share of the largest are dropped from the support
SUPPORT_RTOL = 1e-7


def information_of(w, F) -> np.ndarray:
    r""":math:`M_s = \sum_x w_x F_s(x)`, shape (n_s, n_p, n_p), for F of shape (n_x, n_s, n_p, n_p)."""
    return np.einsum("x,xsij->sij", np.asarray(w, float), F)


def _objective(crit, F, prior_w):
    def fun(w):
        U = utilities(crit, information_of(w, F))
        if not np.all(np.isfinite(U.u)):
            return 1e30, np.zeros_like(w)
        return -float(np.dot(prior_w, U.u)), -(directional(U.grad, F) @ prior_w)
    return fun


def _simplex_slsqp(fun, w0, maxiter=1000):
    cons = [{"type": "eq", "fun": lambda w: np.sum(w) - 1.0, "jac": lambda w: np.ones_like(w)}]
    res = minimize(fun, w0, jac=True, method="SLSQP", bounds=[(0.0, 1.0)] * w0.size, constraints=cons,
                   options={"ftol": 1e-14, "maxiter": maxiter})
    w = np.clip(res.x, 0.0, None)
    return w / w.sum()


def multiplicative_weights(F, prior_w, criterion, n_iter: int, w0=None) -> np.ndarray:
    r"""``n_iter`` steps of the multiplicative algorithm :math:`w_x \leftarrow w_x (g(x)/\sum_y w_y g(y))^\delta`
    (D: :math:`\delta = 1`, A, E: 1/2) from ``w0`` (default uniform) for F of shape (n_x, n_s, n_p, n_p)."""
    crit = Criterion.parse(criterion)
    n_x = F.shape[0]
    w = np.full(n_x, 1.0 / n_x) if w0 is None else np.asarray(w0, float) / np.sum(w0)
    delta = 1.0 if crit is Criterion.D else 0.5
    for _ in range(n_iter):
        U = utilities(crit, information_of(w, F))
        if not np.all(np.isfinite(U.u)):
            raise ValueError("candidates: the information of the candidate points is singular at a parameter "
                             "vector; widen the range or check that the parameters are identifiable")
        g = directional(U.grad, F) @ prior_w
        w = w * (g / np.dot(w, g)) ** delta
        w /= w.sum()
    return w


def bayes_weights(F, prior_w, criterion, w0=None, n_multiplicative: int = 100) -> np.ndarray:
    r"""Weights maximising :math:`\sum_s\pi_s u_s(M_s(w))` over the given points: ``n_multiplicative``
    multiplicative steps from ``w0``, then SLSQP with the exact gradient, kept if it improves (module
    docstring); meant for a few well-separated points.

    Parameters
    ----------
    F : ndarray (n_x, n_s, n_p, n_p)
    prior_w : ndarray (n_s,)
    criterion : {"A", "D", "E"}
    w0 : ndarray (n_x,) or None
        Start (default uniform; positive entries).
    n_multiplicative : int

    Returns
    -------
    ndarray (n_x,), non-negative, summing to 1 (weights below a 1e-7 share of the largest set to 0).
    """
    crit = Criterion.parse(criterion)
    w = multiplicative_weights(F, prior_w, crit, n_multiplicative, w0)
    fun = _objective(crit, F, prior_w)
    out = _simplex_slsqp(fun, w)
    if not fun(out)[0] <= fun(w)[0]:        # SLSQP is kept only when it improves on its start
        out = w
    out[out < SUPPORT_RTOL * out.max()] = 0.0
    return out / out.sum()


def standardized(criterion, u, u_star, n_p: int) -> tuple:
    r"""(c, kappa): standardized utilities and their scales (D: :math:`(u - u^*)/n_p`, 1/n_p;
    A, E: :math:`u/|u^*|`, :math:`1/|u^*|`)."""
    u, u_star = np.asarray(u, float), np.asarray(u_star, float)
    if Criterion.parse(criterion) is Criterion.D:
        return (u - u_star) / n_p, np.full(u.shape, 1.0 / n_p)
    return u / np.abs(u_star), 1.0 / np.abs(u_star)


def maximin_weights(F, criterion, u_star, w0=None, maxiter: int = 500) -> np.ndarray:
    r"""Weights of :math:`\max_{w\in\Delta,t} t` s.t. :math:`c_s(w)\ge t` (module docstring), by SLSQP from
    ``w0`` (default uniform).

    Returns
    -------
    ndarray (n_x,), non-negative, summing to 1.
    """
    crit = Criterion.parse(criterion)
    n_x, n_s, n_p = F.shape[0], F.shape[1], F.shape[-1]
    w = np.full(n_x, 1.0 / n_x) if w0 is None else np.asarray(w0, float) / np.sum(w0)
    w = 0.9 * w + 0.1 / n_x

    def parts(z):
        U = utilities(crit, information_of(np.clip(z[:-1], 0.0, None), F))
        c, kappa = standardized(crit, U.u, u_star, n_p)
        return U, c, kappa

    def cons_f(z):
        _, c, _ = parts(z)
        return np.where(np.isfinite(c), c, -1e30) - z[-1]

    def cons_j(z):
        U, _, kappa = parts(z)
        return np.c_[(directional(U.grad, F) * kappa[None, :]).T, -np.ones(n_s)]

    c0 = parts(np.r_[w, 0.0])[1]
    z0 = np.r_[w, float(np.min(c0))]
    cons = [{"type": "eq", "fun": lambda z: np.sum(z[:-1]) - 1.0, "jac": lambda z: np.r_[np.ones(n_x), 0.0]},
            {"type": "ineq", "fun": cons_f, "jac": cons_j}]
    res = minimize(lambda z: (-z[-1], np.r_[np.zeros(n_x), -1.0]), z0, jac=True, method="SLSQP",
                   bounds=[(0.0, 1.0)] * n_x + [(None, None)], constraints=cons,
                   options={"ftol": 1e-14, "maxiter": maxiter})
    out = np.clip(res.x[:-1], 0.0, None)
    out[out < SUPPORT_RTOL * out.max()] = 0.0
    out = out / out.sum()
    if not np.min(parts(np.r_[out, 0.0])[1]) >= np.min(c0):   # kept only when it improves on its start
        out = w
    return out
