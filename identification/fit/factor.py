r"""Covariances from an orthogonal factorisation of the weighted Jacobian (issue 20 item 3).

With the rows a_jk = sqrt(c_jk) / sigma_k G_jk (G = dh/dp, c_jk the weighted counts) stacked into
A (n x n_p) and its columns normalised, A D = Q R (Householder QR, D = diag(1 / ||A e_i||)):

.. math::

    J^T \Omega J = D^{-1} R^T R D^{-1},\qquad
    H = J^T \Omega J + S = D^{-1} R^T K R D^{-1},\quad K = I + R^{-T} (D S D) R^{-1},

so that the Gauss-Newton covariance (J^T Omega J)^{-1} J^T Omega^2 J (J^T Omega J)^{-1} and the
second-order one H^{-1} J^T Omega^2 J H^{-T} (paper eq. 7) are

.. math::

    C_{GN} = D R^{-1} P R^{-T} D,\qquad C = D R^{-1} K^{-1} P K^{-1} R^{-T} D,\qquad
    P = (B D R^{-1})^T (B D R^{-1})

with B the rows of sqrt(Omega^2) J (P = I when every weight is 0 or 1, B = A).  Nothing forms
J^T Omega J and inverts it: the error of C_GN grows with cond(A D) instead of its square (NIST
Bennett5, cond 3e8: 6.4 correct digits from the normal equations, 10+ from R).  K is the
Hessian in the metric of the Gauss-Newton information: its eigenvalues are the curvatures of
Phi along the directions of unit Gauss-Newton norm (1 where S = 0); a negative one is a
direction of negative curvature (:mod:`identification.fit.secondorder`).  The singular values of
A D (those of R) are the rank test's (Assumption 3) and are reported with the estimate.

All functions work on stacks: a leading axis of m problems (the batch engine's members);
:func:`identify` passes m = 1.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from identification.fit import dense

__all__ = ["WeightedFactor", "weighted_factor", "normalised_hessian", "covariances", "weighted_rows",
           "estimate_covariances", "NewtonSystem", "newton_system"]


@dataclass(frozen=True)
class WeightedFactor:
    """The QR factor of the column-normalised weighted Jacobians of m problems.

    Attributes
    ----------
    R : ndarray (m, n_p, n_p)     upper triangular, A_r D_r = Q_r R_r
    d : ndarray (m, n_p)          the column scales D = diag(d), d_i = 1 / ||A e_i|| (1 for a zero column)
    sv : ndarray (m, n_p)         singular values of A D (those of R), largest first
    full_rank : ndarray (m,) bool  R is invertible: every column non-zero and sv[-1] > 0
    """

    R: np.ndarray
    d: np.ndarray
    sv: np.ndarray
    full_rank: np.ndarray

    def solve_rt(self, X: np.ndarray) -> np.ndarray:
        """R^{-T} X for a stack X (m, n_p, k) (only where ``full_rank``; else NaN)."""
        return _tri_solve(self.R.transpose(0, 2, 1), X, self.full_rank)

    def solve_r(self, X: np.ndarray) -> np.ndarray:
        """R^{-1} X for a stack X (m, n_p, k) (only where ``full_rank``; else NaN)."""
        return _tri_solve(self.R, X, self.full_rank)


def _tri_solve(T: np.ndarray, X: np.ndarray, ok: np.ndarray) -> np.ndarray:
    out = np.full(X.shape, np.nan)
    if np.any(ok):
        # LU of a triangular matrix (partial pivoting keeps it triangular): backward stable as trtrs
        out[ok] = np.linalg.solve(T[ok], X[ok])
    return out


def weighted_factor(rows: np.ndarray) -> WeightedFactor:
    """QR of the column-normalised weighted Jacobians ``rows`` (m, n, n_p) (rows a_jk, any order).

    A problem with fewer rows than parameters, a zero column or a singular R has ``full_rank``
    False (its covariances are NaN; the rank test names the parameters).
    """
    m, n, n_p = rows.shape
    R = np.zeros((m, n_p, n_p))
    with np.errstate(over="ignore", invalid="ignore"):
        fin = np.isfinite(rows.sum(axis=(1, 2))) if n else np.ones(m, bool)
    if n >= n_p and np.any(fin):
        # QR of A, then its columns scaled: Householder QR commutes with column scaling, and the
        # column norms of A are those of R (Q is orthogonal), so A is read once
        R[fin] = np.linalg.qr(rows[fin] if not np.all(fin) else rows, mode="r")[..., :n_p, :]
    norms = np.sqrt(np.einsum("mij,mij->mj", R, R))
    live = fin & np.all(norms > 0, axis=1) & (n >= n_p)
    d = np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 1.0)
    R = R * d[:, None, :]
    sv = np.zeros((m, n_p))
    if np.any(live):
        sv[live] = np.linalg.svd(R[live], compute_uv=False)
    full = live & (sv[:, -1] > 0) & np.all(np.isfinite(sv), axis=1)
    return WeightedFactor(R, d, sv, full)


def normalised_hessian(fac: WeightedFactor, S: np.ndarray) -> np.ndarray:
    """K = I + R^{-T} (D S D) R^{-1} for stacks S (m, n_p, n_p); symmetric; NaN where R is singular."""
    n_p = S.shape[-1]
    Sd = S * fac.d[:, :, None] * fac.d[:, None, :]
    Y = fac.solve_rt(Sd)                                  # R^-T S_d
    K = np.eye(n_p) + fac.solve_rt(Y.transpose(0, 2, 1)).transpose(0, 2, 1)    # + R^-T S_d R^-1
    return 0.5 * (K + K.transpose(0, 2, 1))


def covariances(fac: WeightedFactor, S: np.ndarray, rows2: np.ndarray | None = None) -> tuple:
    """The covariances of the module docstring for stacks.

    Parameters
    ----------
    fac : WeightedFactor           of the rows a_jk = sqrt(c_jk) / sigma_k G_jk
    S : ndarray (m, n_p, n_p)      second-order terms
    rows2 : ndarray (m, n, n_p), optional
        The rows b_jk = sqrt(c_jk w_k) / sigma_k G_jk of sqrt(Omega^2) J; None when every weight
        is 0 or 1 (then B = A and P = I).

    Returns
    -------
    cov, cov_gn : ndarray (m, n_p, n_p)
        Second-order and Gauss-Newton covariances (for sigma_k as given); NaN where R is singular,
        cov NaN also where K is singular (condition number above 1e15) or not finite.
    K_eig : ndarray (m, n_p)
        Eigenvalues of K, ascending (NaN where R is singular).
    """
    m, n_p = fac.d.shape
    ok = fac.full_rank
    eye = np.broadcast_to(np.eye(n_p), (m, n_p, n_p))
    Rinv = fac.solve_r(eye)                                             # R^-1
    if rows2 is None:
        P = eye
    else:
        M = fac.solve_rt((rows2 * fac.d[:, None, :]).transpose(0, 2, 1))   # (B D R^-1)^T, (m, n_p, n)
        P = M @ M.transpose(0, 2, 1)
    cov_gn = Rinv @ P @ Rinv.transpose(0, 2, 1)
    K = normalised_hessian(fac, S)
    lam = np.full((m, n_p), np.nan)
    V = np.full((m, n_p, n_p), np.nan)
    fin = ok & np.all(np.isfinite(K), axis=(1, 2))
    if np.any(fin):
        lam[fin], V[fin] = np.linalg.eigh(K[fin])
    with np.errstate(divide="ignore", invalid="ignore"):
        amax, amin = np.abs(lam).max(axis=1), np.abs(lam).min(axis=1)
        good = fin & (amin > 0) & (amax <= 1e15 * amin)
        W = Rinv @ (V / np.where(good[:, None], lam, 1.0)[:, None, :]) @ V.transpose(0, 2, 1)   # R^-1 K^-1
    cov = W @ P @ W.transpose(0, 2, 1)
    cov = np.where(good[:, None, None], cov, np.nan)
    dd = fac.d[:, :, None] * fac.d[:, None, :]
    cov, cov_gn = cov * dd, np.where(ok[:, None, None], cov_gn * dd, np.nan)
    return 0.5 * (cov + cov.transpose(0, 2, 1)), 0.5 * (cov_gn + cov_gn.transpose(0, 2, 1)), lam


def weighted_rows(G: np.ndarray, cw: np.ndarray, sig: np.ndarray) -> np.ndarray:
    """The rows sqrt(c_jk) / sigma_k G_jk of sqrt(Omega) J, shape (n_q n_S, n_p), from the
    sensitivities G (n_q, n_S, n_p), weighted counts cw (n_q, n_S) and sigmas sig (n_S,)."""
    return ((np.sqrt(cw) / sig)[:, :, None] * G).reshape(-1, G.shape[-1])


def estimate_covariances(G: np.ndarray, cw: np.ndarray, w: np.ndarray, sig: np.ndarray, S: np.ndarray,
                         fac: WeightedFactor | None = None) -> tuple:
    """The covariances of one estimate through the QR factor (see the module docstring).

    ``G`` (n_q, n_S, n_p) sensitivities, ``cw`` (n_q, n_S) weighted counts c_jk = n_jk w_k,
    ``w`` (n_S,) sensor weights, ``sig`` (n_S,) sigmas, ``S`` (n_p, n_p) the second-order term;
    ``fac`` the factor of these rows when the caller has it (m = 1).

    Returns
    -------
    cov, cov_gn : ndarray (n_p, n_p)   second-order (eq. 7) and Gauss-Newton covariances
    H_ok : bool                        K (hence H) is non-singular: cov is finite
    sv : ndarray (n_p,)                singular values of the column-normalised sqrt(Omega) J
    K_eig : ndarray (n_p,)             eigenvalues of K = I + R^-T D S D R^-1, ascending
    """
    if fac is None:
        fac = weighted_factor(weighted_rows(G, cw, sig)[None])
    binary = bool(np.all((w == 0) | (w == 1)))
    rows2 = None if binary else weighted_rows(G, cw * w[None, :], sig)[None]
    cov, cov_gn, lam = covariances(fac, S[None], rows2)
    return cov[0], cov_gn[0], bool(np.all(np.isfinite(cov[0]))), fac.sv[0], lam[0]


@dataclass(frozen=True)
class NewtonSystem:
    r"""The exact Newton system H dp = -g of one problem through the QR factor:
    H = D^{-1} R^T K R D^{-1} with K = L_K L_K^T (Cholesky), so that

    .. math::

        v^T H^{-1} v = \|L_K^{-1} R^{-T} D v\|^2,\qquad
        dp = -D R^{-1} L_K^{-T} L_K^{-1} R^{-T} D g.

    Positive definiteness is that of K (the Hessian in the Gauss-Newton metric), which round-off
    does not decide the way it decides that of H in the parameters' own scaling (MGH10: the
    eigenvalues of H span 1e-3 .. 2e13).
    """

    R: np.ndarray       # (n_p, n_p) upper triangular
    d: np.ndarray       # (n_p,) column scales
    LK: np.ndarray      # (n_p, n_p) lower Cholesky factor of K

    def whiten(self, v: np.ndarray) -> np.ndarray:
        """L_K^{-1} R^{-T} D v (its squared norm is v^T H^{-1} v)."""
        return dense.tri_solve(self.LK, dense.tri_solve(self.R.T, self.d * v))

    def step(self, g: np.ndarray) -> tuple:
        """(dp, g^T H^{-1} g) of the Newton step dp = -H^{-1} g."""
        w = self.whiten(g)
        dp = -self.d * dense.tri_solve(self.R.T, dense.tri_solve(self.LK, w, trans=1), trans=1)
        return dp, float(w @ w)


def newton_system(fac: WeightedFactor, S: np.ndarray) -> NewtonSystem | None:
    """The :class:`NewtonSystem` of one problem's factor (m = 1) and its second-order term S, or None
    when sqrt(Omega) J is rank deficient or K is not positive definite (H is not)."""
    if not fac.full_rank[0]:
        return None
    K = normalised_hessian(fac, S[None])[0]
    LK = dense.cholesky_lower(K)
    if LK is None:
        return None
    return NewtonSystem(fac.R[0], fac.d[0], LK)
