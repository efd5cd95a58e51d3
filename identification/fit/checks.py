"""The checks of an estimate, one place for the estimator and the batch engine: Assumption 3
(identifiability), plausibility (|p| and finite standard errors), the covariances from the
information terms and the graded (weak) identifiability (:func:`sloppy_direction`).

The graded (weak) identifiability is the sloppiest direction of the information matrix. With the
Gauss-Newton information F = J^T Omega J and the parameter magnitudes D = diag(max(|p_i|, se_i)) (se_i
the standard error of p_i when given, so that a parameter at 0, e.g. on its bound, is measured by its
uncertainty and not by 1 in its unit; 1 where both are 0), the relative information F_r = D F D has
eigenpairs (lambda_i, v_i), lambda_1 <= ... <= lambda_n. The combination v_1^T (dp / p) of relative
parameter changes has standard error 1 / sqrt(lambda_1), the best determined one v_n^T (dp / p)
1 / sqrt(lambda_n): v_1 is determined sqrt(lambda_n / lambda_1) times worse than v_n.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from identification.fit import dense
from identification.errors import IdentifiabilityError, IdentificationError

__all__ = ["check_identifiability", "covariance_from_terms", "ABSURD_SCALES", "check_plausible", "rank_ok",
           "absurd", "bad_stderr", "failed_check", "CheckFailure", "SloppyDirection", "sloppy_direction"]


def check_identifiability(model, G, cw, sig, s_p, rtol, selected, sv=None):
    """Assumption 3: rank(sqrt(Omega) J) = n_p, checked on the column-normalised matrix.

    ``sv``: its singular values when the caller has them (the QR factor of
    :mod:`identification.fit.factor`); a full rank is then confirmed without another pass over the data.
    Returns the condition number of the normalised matrix; raises IdentifiabilityError.
    """
    if sv is not None and sv.size == model.n_p and rank_ok(sv, sv[-1] > 0, rtol):
        return float(sv[0] / sv[-1])
    rows = (np.sqrt(cw) / sig)[:, :, None] * G * s_p[None, None, :]
    J = rows.reshape(-1, model.n_p)
    norms = np.linalg.norm(J, axis=0)
    sens_names = tuple(model.sensors[k] for k in selected)
    dead = [model.param_names[i] for i in range(model.n_p) if not norms[i] > 0]
    if dead:
        raise IdentifiabilityError(
            f"not identifiable: parameter(s) {', '.join(dead)} do not influence the selected sensors "
            f"({', '.join(sens_names)}) at any input (Assumption 3, rank(Omega J) = n_p, fails)",
            params=dead, sensors=sens_names)
    Jn = J / norms
    sv = dense.singular_values(Jn)
    ratio = sv[-1] / sv[0] if sv[0] > 0 else 0.0
    if J.shape[0] < model.n_p or ratio < rtol:
        v = np.linalg.svd(Jn, full_matrices=False)[2][-1] if J.shape[0] >= model.n_p else np.ones(model.n_p)
        involved = [model.param_names[i] for i in np.flatnonzero(np.abs(v) >= 0.1 * np.abs(v).max())]
        raise IdentifiabilityError(
            f"not identifiable: parameters {', '.join(involved)} cannot be told apart with sensors "
            f"({', '.join(sens_names)}): rank(Omega J) < n_p = {model.n_p} (smallest relative singular value "
            f"{ratio:.2e}); add a sensor or input that separates them, or fix one of them",
            params=involved, sensors=sens_names)
    return 1.0 / ratio


def covariance_from_terms(F, F2, S):
    """C = H^{-1} F2 H^{-T} with H = F + S (second order) and (F^{-1} F2 F^{-1}) (Gauss-Newton).

    F = J^T Omega J, F2 = J^T Omega^2 J.  Returns (cov, cov_gn, H, H_ok) where H_ok is False when
    H is singular (condition number of the normalised D H D above 1e15, D = diag(F)^-1/2; cov
    is then NaN).
    """
    H = F + S
    n = F.shape[0]
    Finv_F2 = dense.solve(F, F2)
    cov_gn = dense.solve(F, Finv_F2.T).T
    try:
        # singular means singular after normalising the parameters (D H D with D = diag(F)^-1/2):
        # the condition number of H itself also measures the parameters' units (NIST Hahn1: 1e17)
        d = 1.0 / np.sqrt(np.diag(F))
        sv = dense.singular_values(H * np.outer(d, d))
        with np.errstate(divide="ignore"):
            cond = sv[0] / sv[-1]
        if not np.isfinite(cond) or cond > 1e15:
            raise np.linalg.LinAlgError
        A = dense.solve(H, F2)
        cov = dense.solve(H, A.T).T
        ok = True
    except np.linalg.LinAlgError:
        cov, ok = np.full((n, n), np.nan), False
    return 0.5 * (cov + cov.T), 0.5 * (cov_gn + cov_gn.T), H, ok


#: an estimate farther than this many parameter scales from zero is a failed fit
ABSURD_SCALES = 1e6


def rank_ok(sv: np.ndarray, full_rank, rtol: float):
    """Assumption 3 from the singular values ``sv`` (..., n_p) (largest first) of the column-normalised
    sqrt(Omega) J: full rank and a smallest relative singular value sv_min / sv_max >= ``rtol``
    (a bool, or a bool array for a stack)."""
    sv = np.asarray(sv, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(sv[..., 0] > 0, sv[..., -1] / np.where(sv[..., 0] > 0, sv[..., 0], 1.0), 0.0)
    return full_rank & (ratio >= rtol)


def absurd(p: np.ndarray, s_p: np.ndarray) -> np.ndarray:
    """Per parameter (same shape as ``p``, a stack (..., n_p) allowed): True where p_i is not finite or
    |p_i| > :data:`ABSURD_SCALES` max(s_p,i, 1) (a start value near 0, e.g. 1e-16, must not make every
    value absurd)."""
    return ~(np.isfinite(p) & (np.abs(p) <= ABSURD_SCALES * np.maximum(s_p, 1.0)))


def bad_stderr(cov: np.ndarray, cov_gn: np.ndarray) -> np.ndarray:
    """Per parameter (a stack (..., n_p, n_p) allowed): True where a variance of ``cov`` or ``cov_gn``
    is negative or not finite."""
    d1, d2 = np.einsum("...ii->...i", cov), np.einsum("...ii->...i", cov_gn)
    return ~(np.isfinite(d1) & (d1 >= 0) & np.isfinite(d2) & (d2 >= 0))


@dataclass(frozen=True)
class CheckFailure:
    """A converged point that fails a check of :func:`failed_check` (the batch engine then falls back
    to identify with ``reason``)."""

    reason: str


NOT_IDENTIFIABLE = CheckFailure("Assumption 3 (rank(Omega J) = n_p) fails at the converged point")
ABSURD = CheckFailure("the estimate ran off to absurd values")
NOT_FINITE_SE = CheckFailure("the standard errors are not finite (H singular)")


def failed_check(ident: np.ndarray, p: np.ndarray, s_p: np.ndarray, cov: np.ndarray,
                 cov_gn: np.ndarray) -> list:
    """Per member of a stack: None when the estimate passes the checks, else the :class:`CheckFailure` of
    the first failed one (Assumption 3 ``ident`` False, :func:`absurd`, :func:`bad_stderr`)."""
    far = np.any(absurd(p, s_p), axis=-1)
    bad_se = np.any(bad_stderr(cov, cov_gn), axis=-1)
    return [NOT_IDENTIFIABLE if not ident[i] else ABSURD if far[i] else NOT_FINITE_SE if bad_se[i] else None
            for i in range(p.shape[0])]


def check_plausible(param_names, s_p: np.ndarray, p: np.ndarray, cov: np.ndarray, cov_gn: np.ndarray,
                    status: str) -> None:
    """Reject an estimate at absurd values (:func:`absurd`: |p_i| > :data:`ABSURD_SCALES` max(s_p,i, 1),
    s_p the parameter's declared scale, else |p0_i|, or a non-finite p), or with non-finite standard
    errors (:func:`bad_stderr`, second-order or Gauss-Newton).  Such a point is where the solver
    stopped while the parameters ran off (the data do not bound them), not an estimate.

    Raises
    ------
    IdentificationError
        Naming the parameters and what to do.
    """
    names = param_names
    ref = np.maximum(s_p, 1.0)
    far = np.flatnonzero(absurd(p, s_p))
    if far.size:
        what = ", ".join(f"{names[i]} = {p[i]:.3g} (scale {ref[i]:.3g})" for i in far)
        raise IdentificationError(
            f"the fit failed: the estimate ran off to absurd values ({what}: more than {ABSURD_SCALES:.0e} "
            "times the parameter's scale); the data do not bound these parameters from p0. Try other start "
            "values, bounds on the parameters, or a reparametrisation", status=f"absurd estimate ({status})")
    bad = [names[i] for i in np.flatnonzero(bad_stderr(cov, cov_gn))]
    if bad:
        raise IdentificationError(
            f"the fit failed: the standard errors of {', '.join(bad)} are not finite at p = {np.array2string(p)} "
            "(the Hessian J^T Omega J + S is singular there); the point is not a strict minimum. Try other "
            "start values or bounds on the parameters", status=f"non-finite standard errors ({status})")

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
