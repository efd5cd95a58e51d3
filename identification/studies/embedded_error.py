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

V is block diagonal (S couples only the observations of one condition): the objective is evaluated block by
block (:func:`block_reml`: one Cholesky per condition, never one of the full N x N matrix), the same numbers as
the dense :func:`general_reml` to round-off.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg, optimize
from scipy.linalg import lapack

__all__ = ["EmbeddedFit", "fit_embedded", "embedded_objective", "general_reml", "block_reml", "condition_blocks", "spd_inverse",
           "embedded_block_objective"]

#: bounds of c_i = log(omega_i / se_i): omega from ~3e-4 to ~400 standard errors
_BOUND = (-8.0, 6.0)
_STARTS = (0.0, 2.0, -3.0)
#: blocks smaller than this are inverted together (batched); larger ones one by one by potri (faster there)
_BATCHED = 48


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


def block_reml(Vs: list, dVs: list, index: list, G: np.ndarray, r: np.ndarray, n_theta: int) -> tuple:
    r"""(-2 l_R without constant, gradient (n_theta,)) of :func:`general_reml` for a block-diagonal V.

    -2 l_R = sum_b log|V_b| + log|A| + r^T P r with A = sum_b G_b^T V_b^{-1} G_b and
    P r = V^{-1} (r - G A^{-1} G^T V^{-1} r) computed block by block; the gradient
    tr(P V_i) - r^T P V_i P r sums over the blocks b that V_i acts on, with the diagonal block
    P_bb = V_b^{-1} - (V_b^{-1} G_b) A^{-1} (V_b^{-1} G_b)^T.

    Parameters
    ----------
    Vs : list of ndarray (n_b, n_b)      the diagonal blocks of V (unit of r squared)
    dVs : list of (ndarray of int (m_b,), ndarray (m_b, n_b, n_b))   per block, the hyperparameters acting on it
                                         and dV_b / d theta of each
    index : list of ndarray of int (n_b,)   per block, its positions in the stacked r (the blocks partition them)
    G : ndarray (N, n_p)                 fixed-effect sensitivities
    r : ndarray (N,)                     residuals
    n_theta : int                        the number of hyperparameters

    Returns (inf, zeros) when a Cholesky fails.  Blocks of one size are stacked and factorised together
    (batched Cholesky, and inverse below ``_BATCHED`` rows: many small blocks cost one call, not one per block).
    """
    groups: dict = {}
    for b, (V, (which, _)) in enumerate(zip(Vs, dVs)):
        groups.setdefault((len(V), len(which)), []).append(b)
    stacks = []
    for bs in groups.values():
        V = Vs[bs[0]]
        Vst = np.stack([Vs[b] for b in bs])
        try:
            L = np.linalg.cholesky(Vst)
        except np.linalg.LinAlgError:
            return np.inf, np.zeros(n_theta)
        Vinv = _batched_inverse(L) if len(V) < _BATCHED else np.stack([spd_inverse(Lb) for Lb in L])
        idx = np.stack([index[b] for b in bs])
        Gb, rb = G[idx], r[idx]                                    # (k, n, n_p), (k, n)
        VG, Vr = Vinv @ Gb, np.einsum("kij,kj->ki", Vinv, rb)
        stacks.append((bs, L, Vinv, Gb, rb, VG, Vr))
    A = sum(np.einsum("kni,knj->ij", Gb, VG) for _, _, _, Gb, _, VG, _ in stacks)
    try:
        LA = linalg.cholesky(A, lower=True)
    except linalg.LinAlgError:
        return np.inf, np.zeros(n_theta)
    Ainv = linalg.cho_solve((LA, True), np.eye(len(A)))
    beta = Ainv @ sum(np.einsum("kni,kn->i", Gb, Vr) for _, _, _, Gb, _, _, Vr in stacks)
    f = 2 * np.sum(np.log(np.diag(LA)))
    grad = np.zeros(n_theta)
    for bs, L, Vinv, Gb, rb, VG, Vr in stacks:
        f += 2 * np.sum(np.log(np.diagonal(L, axis1=1, axis2=2)))
        alpha = Vr - VG @ beta                                     # (k, n): the blocks of P r
        f += float(np.sum(rb * alpha))
        which = np.array([dVs[b][0] for b in bs], int)             # (k, m)
        if which.shape[1]:
            dV = np.stack([dVs[b][1] for b in bs])                 # (k, m, n, n)
            P = Vinv - VG @ Ainv @ np.swapaxes(VG, 1, 2)
            u = np.einsum("kmij,kj->kmi", dV, alpha)
            np.add.at(grad, which, np.einsum("kij,kmij->km", P, dV) - np.einsum("ki,kmi->km", alpha, u))
    return f, grad


def _batched_inverse(L: np.ndarray) -> np.ndarray:
    """V^{-1} (k, n, n) of a stack of lower Cholesky factors L (k, n, n): (L^{-1})^T L^{-1}."""
    Linv = np.linalg.solve(L, np.broadcast_to(np.eye(L.shape[1]), L.shape))
    return np.swapaxes(Linv, 1, 2) @ Linv


def spd_inverse(L: np.ndarray) -> np.ndarray:
    """V^{-1} (n, n) from the lower Cholesky factor L of V (LAPACK potri: about half the work of solving
    against the identity)."""
    inv, info = lapack.dpotri(L, lower=1)
    if info != 0:
        raise linalg.LinAlgError(f"potri failed (info {info}): the Cholesky factor is singular")
    return np.tril(inv) + np.tril(inv, -1).T


def condition_blocks(rows: np.ndarray) -> list:
    """The positions (index arrays) of every condition label in ``rows`` (N,), in order of first appearance."""
    rows = np.asarray(rows)
    _, first, inverse = np.unique(rows, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    return [np.flatnonzero(inverse == k) for k in order]


def _block_covariance(c: np.ndarray, Gs: np.ndarray, index: list, noise: np.ndarray, se: np.ndarray) -> tuple:
    """(V_b per condition, [(all hyperparameters, dV_b / dc)]) of the embedded error's covariance (conditions of
    one size built together)."""
    om2 = (se * np.exp(c)) ** 2
    which = np.arange(len(c))
    Vs, dVs = [None] * len(index), [None] * len(index)
    sizes = np.array([len(i) for i in index])
    for n in np.unique(sizes):
        bs = np.flatnonzero(sizes == n)
        idx = np.stack([index[b] for b in bs])                       # (k, n)
        g = Gs[idx]                                                  # (k, n, n_p)
        parts = g.transpose(0, 2, 1)[:, :, :, None] * g.transpose(0, 2, 1)[:, :, None, :]   # (k, n_p, n, n)
        V = np.tensordot(parts, om2, axes=([1], [0]))               # (k, n, n)
        V[:, np.arange(n), np.arange(n)] += noise[idx]
        dV = 2 * om2[None, :, None, None] * parts
        for j, b in enumerate(bs):
            Vs[b], dVs[b] = V[j], (which, dV[j])
    return Vs, dVs


def _covariance(c: np.ndarray, Gs: np.ndarray, same_row: np.ndarray, noise: np.ndarray, se: np.ndarray) -> tuple:
    om2 = (se * np.exp(c)) ** 2
    parts = [np.outer(Gs[:, i], Gs[:, i]) * same_row for i in range(len(c))]
    V = np.diag(noise) + sum(o * part for o, part in zip(om2, parts))
    return V, [2 * o * part for o, part in zip(om2, parts)]


def embedded_objective(c, Gs, same_row, noise, se, r) -> tuple:
    """(-2 l_R(c), exact gradient) of the embedded error in c = log(omega / se) (dense V; the reference of
    :func:`embedded_block_objective`)."""
    V, dVs = _covariance(np.asarray(c, float), Gs, same_row, noise, se)
    return general_reml(V, dVs, Gs, r)


def embedded_block_objective(c, Gs, index, noise, se, r) -> tuple:
    """(-2 l_R(c), exact gradient) of the embedded error in c = log(omega / se), block by block over the
    conditions ``index`` (:func:`condition_blocks`)."""
    c = np.asarray(c, float)
    Vs, dVs = _block_covariance(c, Gs, index, noise, se)
    return block_reml(Vs, dVs, index, Gs, r, len(c))


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
    index = condition_blocks(rows)
    n_p = Gs.shape[1]
    best = None
    for x0 in (np.full(n_p, st) for st in _STARTS) if starts is None else starts:
        if not np.isfinite(embedded_block_objective(x0, Gs, index, noise, se, r)[0]):
            continue
        res = optimize.minimize(embedded_block_objective, x0, args=(Gs, index, noise, se, r), jac=True,
                                method="L-BFGS-B", bounds=[_BOUND] * n_p, options={"maxiter": 300})
        if np.isfinite(res.fun) and (best is None or res.fun < best.fun):
            best = res
    if best is None:
        raise np.linalg.LinAlgError("the embedded error's covariance V or G^T V^-1 G is not positive definite at "
                                    "any start (Cholesky failed)")
    c = np.asarray(best.x, float)
    same_row = (rows[:, None] == rows[None, :]).astype(float)
    return EmbeddedFit(se * np.exp(c), c, _covariance(c, Gs, same_row, noise, se)[0], float(best.fun), bool(best.success))
