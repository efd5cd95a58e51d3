r"""Embedded model error: the parameters vary between conditions.

In every condition g (an input row, or a group of input rows the user names) the model holds with its own
parameters p + b_g, b_g ~ N(0, Omega), Omega = diag(omega_i^2) (omega_i in the unit of parameter i),
independent between conditions.
Linearised at the plain fit, the residual means r = zbar - h(p) of the selected sensors have the covariance

.. math::

    V(\omega) = D + \big(G\,\Omega\,G^\top\big) \circ S,\qquad S_{oo'} = [g(o) = g(o')],

with D = diag(sigma_k^2 / n_jk) and G the stacked sensitivities dh/dp: the error is shaped by the model's
own sensitivities (it couples the sensors of one condition) instead of being free like an output
discrepancy.  omega maximises the restricted (REML) likelihood

.. math::

    -2\ell_R(\omega) = \log|V| + \log|G^\top V^{-1} G| + r^\top P r,\qquad
    \partial(-2\ell_R)/\partial c_i = \operatorname{tr}(P V_i) - r^\top P V_i P r,

in c_i = log(omega_i / se_i) (se_i the plain fit's standard error; V_i = dV/dc_i = 2 omega_i^2
(g_i g_i^T) o S, analytic), by L-BFGS-B from a few starts.  A new condition's output then scatters by
g*^T Omega g* on top of the parameter uncertainty.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg, optimize

__all__ = ["EmbeddedFit", "fit_embedded", "embedded_objective", "general_reml"]

#: bounds of c_i = log(omega_i / se_i): omega from ~3e-4 to ~400 standard errors
_BOUND = (-8.0, 6.0)
_STARTS = (0.0, 2.0, -3.0)


def general_reml(V: np.ndarray, dVs: list, G: np.ndarray, r: np.ndarray) -> tuple:
    """(-2 l_R without constant, gradient) for a residual covariance V (N, N) with derivatives dVs,
    fixed effects G (N, n_p), residuals r (N,); (inf, zeros) when a Cholesky fails."""
    try:
        L = linalg.cholesky(V, lower=True)
        Vinv = linalg.cho_solve((L, True), np.eye(len(V)))
        VG = Vinv @ G
        LA = linalg.cholesky(G.T @ VG, lower=True)
    except linalg.LinAlgError:
        return np.inf, np.zeros(len(dVs))
    P = Vinv - VG @ linalg.cho_solve((LA, True), VG.T)
    alpha = P @ r
    f = 2 * np.sum(np.log(np.diag(L))) + 2 * np.sum(np.log(np.diag(LA))) + float(r @ alpha)
    return f, np.array([np.sum(P * dV) - alpha @ dV @ alpha for dV in dVs])


def _covariance(c: np.ndarray, Gs: np.ndarray, same_row: np.ndarray, noise: np.ndarray, se: np.ndarray) -> tuple:
    om2 = (se * np.exp(c)) ** 2
    parts = [np.outer(Gs[:, i], Gs[:, i]) * same_row for i in range(len(c))]
    V = np.diag(noise) + sum(o * part for o, part in zip(om2, parts))
    return V, [2 * o * part for o, part in zip(om2, parts)]


def embedded_objective(c, Gs, same_row, noise, se, r) -> tuple:
    """(-2 l_R(c), exact gradient) of the embedded error in c = log(omega / se)."""
    V, dVs = _covariance(np.asarray(c, float), Gs, same_row, noise, se)
    return general_reml(V, dVs, Gs, r)


@dataclass(frozen=True)
class EmbeddedFit:
    """omega (n_p,) (parameter units), c = log(omega / se), the residual covariance V (N, N) and whether the
    optimiser converged."""

    omega: np.ndarray
    c: np.ndarray
    V: np.ndarray
    reml: float
    converged: bool

    @property
    def Omega(self) -> np.ndarray:
        return np.diag(self.omega ** 2)


def fit_embedded(Gs: np.ndarray, rows: np.ndarray, noise: np.ndarray, se: np.ndarray, r: np.ndarray,
                 starts=None) -> EmbeddedFit:
    """The REML omega for stacked sensitivities Gs (N, n_p) in conditions ``rows`` (N,) (labels: equal labels
    share b), noise variances (N,),
    the plain fit's standard errors se (n_p,) and residuals r (N,), from each of ``starts`` (arrays of c (n_p,);
    None: the constant starts ``_STARTS``).  numpy.linalg.LinAlgError when no start
    gives positive definite V and G^T V^-1 G."""
    same_row = (rows[:, None] == rows[None, :]).astype(float)
    n_p = Gs.shape[1]
    best = None
    for x0 in (np.full(n_p, st) for st in _STARTS) if starts is None else starts:
        if not np.isfinite(embedded_objective(x0, Gs, same_row, noise, se, r)[0]):
            continue
        res = optimize.minimize(embedded_objective, x0, args=(Gs, same_row, noise, se, r), jac=True,
                                method="L-BFGS-B", bounds=[_BOUND] * n_p, options={"maxiter": 300})
        if np.isfinite(res.fun) and (best is None or res.fun < best.fun):
            best = res
    if best is None:
        raise np.linalg.LinAlgError("the embedded error's covariance V or G^T V^-1 G is not positive definite at "
                                    "any start (Cholesky failed)")
    c = np.asarray(best.x, float)
    return EmbeddedFit(se * np.exp(c), c, _covariance(c, Gs, same_row, noise, se)[0], float(best.fun), bool(best.success))
