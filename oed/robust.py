r"""Robust design criteria over a finite set of parameter vectors (pseudo-Bayesian and standardized maximin).

For an approximate design :math:`\xi = \{(x_i, w_i)\}` with information
:math:`M_s(\xi) = \sum_i w_i F_s(x_i)` at the parameter vector :math:`P_s`, every criterion is a
concave utility per vector, maximised:

.. math::

    u_D(M) = \log\det M,\qquad u_A(M) = -\operatorname{tr} M^{-1},\qquad u_E(M) = -1/\lambda_{\min}(M),

with supergradient :math:`\nabla u` (D: :math:`M^{-1}`, A: :math:`M^{-2}`, E: :math:`vv^T/\lambda_{\min}^2`,
for a multiple smallest eigenvalue the average of that over an orthonormal basis of its eigenspace).
The directional derivative towards a point x is :math:`d_s(x) = \operatorname{tr}(\nabla u_s F_s(x))`, and
:math:`\sum_i w_i d_s(x_i) = \operatorname{tr}(\nabla u_s M_s)`.

* Pseudo-Bayesian: :math:`\Phi(\xi) = \sum_s \pi_s u_s(M_s(\xi))`; by concavity, for every design
  :math:`\xi'`, :math:`\Phi(\xi') \le \Phi(\xi) + \max_x g(x) - \sum_s\pi_s\operatorname{tr}(\nabla u_s M_s)`
  with :math:`g(x) = \sum_s \pi_s d_s(x)` (the equivalence theorem: :math:`\xi` is optimal iff the gap is 0;
  D: :math:`\max_x g(x) = n_p`).
* Standardized maximin: :math:`\max_\xi \min_s c_s(\xi)` with D: :math:`c_s = (u_s - u_s^*)/n_p`
  (the log D-efficiency), A, E: :math:`c_s = u_s/|u_s^*|` (minus the inverse efficiency); for every
  measure :math:`\mu` on the vectors, :math:`\max_{\xi'}\min_s c_s(\xi') \le \sum_s \mu_s c_s(\xi) +
  \max_x \sum_s \mu_s \kappa_s (d_s(x) - \operatorname{tr}(\nabla u_s M_s))` (the generalized equivalence
  theorem), :math:`\kappa_s` the scale of :math:`c_s`; the smallest such bound is a linear programme in
  :math:`\mu` (:func:`maximin_bound`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog

from .criteria import Criterion

__all__ = ["Utilities", "utilities", "directional", "bayes_gap", "bayes_efficiency_bound", "MaximinBound",
           "maximin_bound", "efficiency_from_c"]

#: relative width of the smallest eigenvalue's cluster treated as one multiple eigenvalue (E)
E_MULTIPLICITY_RTOL = 1e-6


@dataclass(frozen=True)
class Utilities:
    """Utilities u_s, supergradients and their pairing with M_s at every parameter vector.

    Attributes
    ----------
    u : ndarray (n_s,)            -inf where M_s is singular
    grad : ndarray (n_s, n_p, n_p)
    inner : ndarray (n_s,)        tr(grad_s M_s) (D: n_p; A: tr M^-1; E: 1/lambda_min)
    multiplicity : ndarray (n_s,) of int   multiplicity of the smallest eigenvalue (E), else 1
    """

    u: np.ndarray
    grad: np.ndarray
    inner: np.ndarray
    multiplicity: np.ndarray


def utilities(criterion, M) -> Utilities:
    r"""Concave utilities :math:`u(M_s)` and supergradients of a stack of information matrices (module docstring)."""
    crit = Criterion.parse(criterion)
    M = np.asarray(M, float)
    M = 0.5 * (M + np.swapaxes(M, -1, -2))
    lam, V = np.linalg.eigh(M)
    n_s, n_p = lam.shape
    ok = lam[:, 0] > 0
    lam_safe = np.where(ok[:, None], lam, 1.0)
    mult = np.ones(n_s, int)
    if crit is Criterion.D:
        u = np.sum(np.log(lam_safe), axis=1)
        scale = 1.0 / lam_safe
    elif crit is Criterion.A:
        u = -np.sum(1.0 / lam_safe, axis=1)
        scale = 1.0 / lam_safe ** 2
    else:
        low = lam_safe <= lam_safe[:, :1] * (1.0 + E_MULTIPLICITY_RTOL)
        mult = low.sum(axis=1)
        u = -1.0 / lam_safe[:, 0]
        scale = low / (mult[:, None] * lam_safe[:, :1] ** 2)
    grad = np.einsum("sik,sk,sjk->sij", V, scale, V)
    inner = np.sum(scale * lam_safe, axis=1)
    u = np.where(ok, u, -np.inf)
    return Utilities(u=u, grad=grad, inner=inner, multiplicity=mult)


def directional(grad, F) -> np.ndarray:
    r""":math:`d_s(x) = \operatorname{tr}(\nabla u_s F_s(x))`, shape (n_x, n_s), for F of shape (n_x, n_s, n_p, n_p)."""
    return np.einsum("sij,xsij->xs", grad, F)


def bayes_gap(U: Utilities, d, prior_w) -> tuple:
    r"""(g, gap): the prior-averaged directional derivative :math:`g(x) = \sum_s\pi_s d_s(x)` and the
    equivalence-theorem gap :math:`\max_x g(x) - \sum_s \pi_s\operatorname{tr}(\nabla u_s M_s)`, an upper
    bound on :math:`\Phi^* - \Phi(\xi)` when the maximum is over the whole range."""
    g = np.asarray(d) @ np.asarray(prior_w)
    return g, float(np.max(g) - np.dot(prior_w, U.inner))


def bayes_efficiency_bound(criterion, U: Utilities, prior_w, gap: float, n_p: int) -> float:
    r"""Lower bound on the efficiency of the design from the gap :math:`\Phi^* - \Phi \le \Delta`:
    D: :math:`\exp(-\Delta/n_p)` (the ratio of geometric-mean information); A, E: :math:`1 - \Delta/\phi`
    with :math:`\phi = -\Phi` (the ratio :math:`\phi^*/\phi`)."""
    gap = max(float(gap), 0.0)
    if Criterion.parse(criterion) is Criterion.D:
        return float(np.exp(-gap / n_p))
    phi = -float(np.dot(prior_w, U.u))
    return float(max(1.0 - gap / phi, 0.0))


def efficiency_from_c(criterion, c) -> np.ndarray:
    """Efficiency from the standardized utility c: D exp(c), A/E -1/c."""
    c = np.asarray(c, float)
    return np.exp(c) if Criterion.parse(criterion) is Criterion.D else -1.0 / c


@dataclass(frozen=True)
class MaximinBound:
    r"""The generalized-equivalence-theorem bound of a maximin design.

    Attributes
    ----------
    lower : float
        :math:`\min_s c_s(\xi)` of the design.
    upper : float
        The smallest bound :math:`\max_{\xi'}\min_s c_s(\xi') \le` upper over measures :math:`\mu`.
    measure : ndarray (n_s,)
        The worst-case measure :math:`\mu` attaining it.
    sensitivity : ndarray (n_x,)
        :math:`\sum_s\mu_s\kappa_s d_s(x)` over the points checked.
    """

    lower: float
    upper: float
    measure: np.ndarray
    sensitivity: np.ndarray


def maximin_bound(c, kappa, d, inner) -> MaximinBound:
    r"""The smallest generalized-equivalence bound (module docstring) by the linear programme

    .. math::  \min_{\mu\ge 0, z}\ \sum_s \mu_s (c_s - \kappa_s \operatorname{tr}(\nabla u_s M_s)) + z
               \quad\text{s.t.}\quad \sum_s \mu_s\kappa_s d_s(x) \le z\ \forall x,\ \sum_s\mu_s = 1.

    Parameters
    ----------
    c : (n_s,) standardized utilities of the design; kappa : (n_s,) their scales;
    d : (n_x, n_s) directional derivatives over the points checked; inner : (n_s,) tr(grad_s M_s).
    """
    c, kappa, inner = (np.asarray(a, float) for a in (c, kappa, inner))
    B = np.asarray(d, float) * kappa[None, :]
    n_x, n_s = B.shape
    cost = np.r_[c - kappa * inner, 1.0]
    A_ub = np.c_[B, -np.ones(n_x)]
    A_eq = np.r_[np.ones(n_s), 0.0][None, :]
    res = linprog(cost, A_ub=A_ub, b_ub=np.zeros(n_x), A_eq=A_eq, b_eq=[1.0],
                  bounds=[(0, None)] * n_s + [(None, None)], method="highs")
    if res.status != 0:
        raise RuntimeError(f"maximin bound: the linear programme failed ({res.message})")
    mu = np.clip(res.x[:n_s], 0.0, None)
    mu = mu / mu.sum()
    sens = B @ mu
    upper = float(np.dot(mu, c - kappa * inner) + np.max(sens))
    return MaximinBound(lower=float(np.min(c)), upper=upper, measure=mu, sensitivity=sens)
