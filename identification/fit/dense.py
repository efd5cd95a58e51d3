"""Small dense linear algebra by direct LAPACK calls (scipy.linalg.lapack).

The identification works on n_p x n_p matrices (n_p = 2..20); ``numpy.linalg`` spends 5-30 us
of Python and ufunc set-up per call on them (``norm(A, 2)`` 30 us), the LAPACK routine itself
well under 1 us, so a fit that makes twenty such calls spends most of its linear-algebra time in
the wrappers.  These functions call the same LAPACK routines directly (1-2 us) and raise
``numpy.linalg.LinAlgError`` where ``numpy.linalg`` would.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.linalg import lapack

__all__ = ["cholesky_lower", "tri_solve", "solve", "singular_values", "sym_eigenvalues"]

_potrf, _trtrs, _gesv, _gesdd, _syevd = lapack.dpotrf, lapack.dtrtrs, lapack.dgesv, lapack.dgesdd, lapack.dsyevd


def cholesky_lower(M: np.ndarray) -> np.ndarray | None:
    """The lower Cholesky factor L (L L^T = M, LAPACK dpotrf), or None when M is not finite or not
    positive definite."""
    if not math.isfinite(M.sum()):
        return None
    L, info = _potrf(M, lower=1, clean=1)
    return L if info == 0 else None


def tri_solve(L: np.ndarray, b: np.ndarray, trans: int = 0) -> np.ndarray:
    """L^{-1} b (``trans=0``) or L^{-T} b (``trans=1``) for a lower triangular L (LAPACK dtrtrs)."""
    return _trtrs(L, b, lower=1, trans=trans)[0]


def solve(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A^{-1} B by LU with partial pivoting (LAPACK dgesv, as ``numpy.linalg.solve``).

    Non-finite entries propagate into the result (as with ``numpy.linalg.solve``).

    Raises
    ------
    numpy.linalg.LinAlgError
        When A is exactly singular.
    """
    x, info = _gesv(A, B)[2:]
    if info != 0:
        raise np.linalg.LinAlgError("solve: the matrix is singular")
    return x


def singular_values(A: np.ndarray) -> np.ndarray:
    """Singular values of A, largest first (LAPACK dgesdd without vectors).

    Raises
    ------
    numpy.linalg.LinAlgError
        When A is not finite or the SVD does not converge.
    """
    if not math.isfinite(A.sum()):
        raise np.linalg.LinAlgError("singular values: the matrix is not finite")
    s, info = _gesdd(A, compute_uv=0, full_matrices=0)[1::2]
    if info != 0:
        raise np.linalg.LinAlgError("singular values: the SVD did not converge")
    return s


def sym_eigenvalues(A: np.ndarray) -> np.ndarray:
    """Eigenvalues of the symmetric matrix A (its lower triangle, as ``numpy.linalg.eigvalsh``),
    ascending (LAPACK dsyevd).

    Raises
    ------
    numpy.linalg.LinAlgError
        When A is not finite or the eigenvalue iteration does not converge.
    """
    if not math.isfinite(A.sum()):
        raise np.linalg.LinAlgError("eigenvalues: the matrix is not finite")
    w, _, info = _syevd(A, compute_v=0, lower=1)
    if info != 0:
        raise np.linalg.LinAlgError("eigenvalues: the iteration did not converge")
    return w
