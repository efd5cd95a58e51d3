"""Confidence ellipsoids and the paper's test statistic alpha_min.

    G(alpha, p*, C) = { p : (p - p*)^T C^{-1} (p - p*) <= chi2_{n_p}(1 - alpha) }

alpha_min is the level at which p_val lies on the boundary of G(alpha, p_cal, C_cal):

    alpha_min = 1 - F_{chi2, n_p}( (p_val - p_cal)^T C_cal^{-1} (p_val - p_cal) ).

The two-sample version uses C_cal + C_val, the covariance of p_val - p_cal for
two independent estimates.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from scipy import stats

__all__ = ["Ellipsoid", "mahalanobis2", "in_region", "alpha_min", "alpha_min_two_sample", "CovarianceError"]


class CovarianceError(ValueError):
    """A covariance matrix is not symmetric positive definite."""


def _check_alpha(alpha: float, name: str = "alpha") -> float:
    alpha = float(alpha)
    if not (0.0 < alpha < 1.0):
        raise ValueError(f"{name} must lie in (0, 1), got {alpha}")
    return alpha


def _chol(C: np.ndarray, name: str) -> np.ndarray:
    C = np.asarray(C, float)
    if C.ndim != 2 or C.shape[0] != C.shape[1]:
        raise CovarianceError(f"{name}: expected a square matrix, got shape {C.shape}")
    if not np.all(np.isfinite(C)):
        raise CovarianceError(f"{name}: contains NaN or Inf")
    if not np.allclose(C, C.T, rtol=1e-8, atol=1e-14 * np.abs(C).max()):
        raise CovarianceError(f"{name}: not symmetric")
    try:
        return sla.cholesky(0.5 * (C + C.T), lower=True)
    except np.linalg.LinAlgError:
        raise CovarianceError(f"{name}: not positive definite (singular covariance: a parameter combination "
                              "is not determined)") from None


def mahalanobis2(p, center, C, name: str = "C") -> float:
    """(p - center)^T C^{-1} (p - center), by Cholesky (no pseudo-inverse)."""
    p = np.asarray(p, float).ravel()
    center = np.asarray(center, float).ravel()
    if p.shape != center.shape:
        raise ValueError(f"p has {p.size} entries but the center has {center.size}")
    L = _chol(C, name)
    if L.shape[0] != p.size:
        raise ValueError(f"{name} is {L.shape[0]}x{L.shape[0]} but p has {p.size} entries")
    v = sla.solve_triangular(L, p - center, lower=True)
    return float(v @ v)


def in_region(p, center, C, alpha: float) -> bool:
    """Membership of p in G(alpha, center, C)."""
    _check_alpha(alpha)
    n = np.asarray(center).size
    return mahalanobis2(p, center, C) <= stats.chi2.ppf(1 - alpha, n)


def alpha_min(p_val, p_cal, C_cal) -> float:
    """The paper's p-value: p_val on the boundary of G(alpha_min, p_cal, C_cal) (chi2, n_p dof)."""
    d2 = mahalanobis2(p_val, p_cal, C_cal, "C_cal")
    return float(stats.chi2.sf(d2, np.asarray(p_cal).size))


def alpha_min_two_sample(p_val, p_cal, C_cal, C_val) -> float:
    """Two-sample Wald p-value of p_val - p_cal with covariance C_cal + C_val (chi2, n_p dof)."""
    C = np.asarray(C_cal, float) + np.asarray(C_val, float)
    d2 = mahalanobis2(p_val, p_cal, C, "C_cal + C_val")
    return float(stats.chi2.sf(d2, np.asarray(p_cal).size))


@dataclass(frozen=True)
class Ellipsoid:
    """The confidence ellipsoid {p : (p - center)^T C^{-1} (p - center) <= gamma2}.

    ``gamma2`` is chi2_{n_p}(1 - alpha) for known sigma, and n_p F_{n_p, dof}(1 - alpha)
    when sigma was estimated from the residuals.
    """

    center: np.ndarray
    cov: np.ndarray
    alpha: float
    gamma2: float
    names: tuple = ()

    def contains(self, p) -> bool:
        return mahalanobis2(p, self.center, self.cov) <= self.gamma2

    def semi_axes(self):
        """Semi-axis lengths (descending) and their directions (columns)."""
        w, V = np.linalg.eigh(self.cov)
        order = np.argsort(w)[::-1]
        return np.sqrt(np.maximum(w[order], 0) * self.gamma2), V[:, order]

    def volume(self) -> float:
        n = self.center.size
        from math import gamma, pi
        return float(pi ** (n / 2) / gamma(n / 2 + 1) * np.sqrt(np.linalg.det(self.cov)) * self.gamma2 ** (n / 2))

    def boundary(self, i: int = 0, j: int = 1, n: int = 200) -> np.ndarray:
        """Points (n, 2) on the boundary of the projection onto parameters (i, j)."""
        idx = [i, j]
        C2 = self.cov[np.ix_(idx, idx)]
        L = _chol(C2, "cov[i,j]")
        t = np.linspace(0, 2 * np.pi, n)
        circ = np.vstack([np.cos(t), np.sin(t)]) * np.sqrt(self.gamma2)
        return (self.center[idx][:, None] + L @ circ).T
