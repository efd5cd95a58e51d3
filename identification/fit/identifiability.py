"""Graded (weak) identifiability: the sloppiest direction of the information matrix.

With the Gauss-Newton information F = J^T Omega J and the parameter magnitudes
D = diag(max(|p_i|, se_i)) (se_i the standard error of p_i when given, so that a parameter at 0, e.g.
on its bound, is measured by its uncertainty and not by 1 in its unit; 1 where both are 0), the
relative information F_r = D F D has eigenpairs
(lambda_i, v_i), lambda_1 <= ... <= lambda_n.  The combination v_1^T (dp / p) of relative
parameter changes has standard error 1 / sqrt(lambda_1), the best determined one v_n^T (dp / p)
1 / sqrt(lambda_n): v_1 is determined sqrt(lambda_n / lambda_1) times worse than v_n.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["SloppyDirection", "sloppy_direction"]


@dataclass(frozen=True)
class SloppyDirection:
    """The worst and best determined combinations of relative parameter changes.

    Attributes
    ----------
    param_names : tuple of str
    scale : ndarray (n_p,)          parameter magnitudes D (model units)
    sloppy, stiff : ndarray (n_p,)  unit eigenvectors of D F D of the smallest / largest eigenvalue
                                    (coefficients of dp_i / |p_i|, sign fixed: largest entry positive)
    eigenvalues : ndarray (n_p,)    eigenvalues of D F D, ascending (dimensionless)
    ratio : float                   sqrt(lambda_max / lambda_min): the standard-error ratio
                                    (inf when F is singular)
    by_stderr : tuple of str        parameters whose magnitude is their standard error (|p| smaller)
    """

    param_names: tuple
    scale: np.ndarray
    sloppy: np.ndarray
    stiff: np.ndarray
    eigenvalues: np.ndarray
    ratio: float
    by_stderr: tuple = ()

    def __post_init__(self):
        for name in ("scale", "sloppy", "stiff", "eigenvalues"):
            a = np.array(getattr(self, name), dtype=float, copy=True)
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    def combination(self, v) -> str:
        """A direction written in parameters, e.g. "k1 - 0.98 k2" (coefficients of relative changes,
        normalised so the largest is 1; entries below 0.01 left out)."""
        v = np.asarray(v, float)
        v = v / v[np.argmax(np.abs(v))]
        terms = []
        for c, name in zip(v, self.param_names):
            if abs(c) < 0.01:
                continue
            mag = "" if abs(abs(c) - 1) < 5e-3 else f"{abs(c):.2g} "
            sign = "-" if c < 0 else "+"
            terms.append((sign, f"{mag}{name}"))
        text = ("-" if terms[0][0] == "-" else "") + terms[0][1]
        return text + "".join(f" {s} {t}" for s, t in terms[1:])

    def __str__(self):
        if not math.isfinite(self.ratio):
            r = "infinitely"
        else:
            r = f"{self.ratio:.3g}x" if self.ratio < 1000 else f"{self.ratio:.3e}x" if self.ratio >= 1e7 \
                else f"{self.ratio:.0f}x"
        rel = "dp/|p|" if not self.by_stderr else f"dp/|p|, dp/se for {', '.join(self.by_stderr)}"
        return (f"weakest direction (relative changes {rel}): {self.combination(self.sloppy)} is determined "
                f"{r} worse than {self.combination(self.stiff)}")


def sloppy_direction(information, p, param_names, stderr=None) -> SloppyDirection | None:
    """The sloppiest and stiffest directions of ``information`` scaled by max(|p|, stderr) (None for one
    parameter).

    Parameters
    ----------
    information : ndarray (n_p, n_p)   Fisher information J^T Omega J (1 / parameter units^2)
    p : ndarray (n_p,)                 the estimate (its magnitudes scale the information)
    param_names : sequence of str
    stderr : ndarray (n_p,), optional  standard errors: the magnitude of a parameter smaller than its own
                                       (e.g. 0 on a bound); non-finite entries are ignored
    """
    F = np.asarray(information, float)
    p = np.asarray(p, float).ravel()
    if F.shape != (p.size, p.size):
        raise ValueError(f"information: expected shape {(p.size, p.size)}, got {F.shape}")
    if p.size < 2:
        return None
    se = np.zeros(p.size) if stderr is None else np.asarray(stderr, float).ravel()
    se = np.where(np.isfinite(se), se, 0.0) if se.shape == p.shape else np.zeros(p.size)
    d = np.maximum(np.abs(p), se)
    by_se = tuple(n for n, a, b in zip(param_names, np.abs(p), se) if b > a)
    d = np.where(d > 0, d, 1.0)
    Fr = 0.5 * (F + F.T) * np.outer(d, d)
    lam, V = np.linalg.eigh(Fr)
    ratio = math.sqrt(lam[-1] / lam[0]) if lam[0] > 0 else math.inf

    def signed(v):
        return v if v[np.argmax(np.abs(v))] > 0 else -v

    return SloppyDirection(tuple(param_names), d, signed(V[:, 0]), signed(V[:, -1]), lam, ratio, by_se)
