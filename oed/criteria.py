r"""Design criteria for optimal sensor selection.

For binary sensor weights :math:`w\in\{0,1\}^{n_S}` with per-sensor Gauss-Newton
information :math:`F_k = J_k^T J_k` and second-order (residual curvature) terms
:math:`S_k`, the paper's second-order covariance is

.. math::  C(w) = H(w)^{-1}\Big(\sum_k w_k^2 F_k\Big)H(w)^{-1},\qquad H(w)=\sum_k w_k (F_k+S_k),

and the Gauss-Newton covariance is :math:`C_{GN}(w) = (\sum_k w_k F_k)^{-1}`.

Criteria (all minimised): ``A`` = trace(C), ``D`` = log det(C) (det is reported too),
``E`` = lambda_max(C).  A design with rank(sum_k w_k F_k) < n_p is *singular*: its
criterion is ``+inf`` and it is never chosen.  A design whose diagonally scaled
information matrix has condition number above ``near_singular_cond`` (default 1e10) is
flagged *near-singular* with a reason, but keeps its finite value.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

__all__ = [
    "DEFAULT_CRITERION",
    "Criterion",
    "Kind",
    "CriteriaSettings",
    "BatchCriteria",
    "validate_information",
    "criterion_value",
    "batch_criteria",
    "gap_tolerance",
    "screening_values",
]


#: the criterion of every design verb and of ``[oed] criterion`` when none is given: D, the determinant of the
#: covariance (the volume of the confidence ellipsoid; invariant under a reparametrisation p -> A p + b).  The
#: paper chooses E for the press (section 3); configs/press.toml says so.
DEFAULT_CRITERION = "D"


class Criterion(enum.Enum):
    """Design criterion; ``Criterion.parse("e")`` accepts names case-insensitively."""

    A = "A"
    D = "D"
    E = "E"

    @classmethod
    def parse(cls, value: "Criterion | str") -> "Criterion":
        r"""Return the criterion named by ``value``.

        Solves nothing: maps ``value`` in {A, D, E} (case-insensitive) to the enum.

        Raises
        ------
        ValueError
            If ``value`` is not a valid criterion name; the message lists valid names.
        """
        if isinstance(value, cls):
            return value
        if isinstance(value, str) and value.strip().upper() in cls.__members__:
            return cls[value.strip().upper()]
        raise ValueError(
            f"criterion: unknown design criterion {value!r}; valid names are "
            f"{', '.join(cls.__members__)} (A = trace, D = log det, E = largest eigenvalue of the covariance)"
        )


class Kind(enum.Enum):
    """Which covariance the criterion is applied to."""

    GAUSS_NEWTON = "gauss_newton"
    SECOND_ORDER = "second_order"

    @classmethod
    def parse(cls, value: "Kind | str") -> "Kind":
        """Return the kind named by ``value`` ("gauss_newton" or "second_order")."""
        if isinstance(value, cls):
            return value
        if isinstance(value, str):
            v = value.strip().lower().replace("-", "_")
            for m in cls:
                if m.value == v:
                    return m
        raise ValueError(f"kind: unknown covariance kind {value!r}; valid values are 'gauss_newton', 'second_order'")


@dataclass(frozen=True)
class CriteriaSettings:
    """Numerical tolerances for criterion evaluation.

    Attributes
    ----------
    rank_rtol : float
        A design is singular when lambda_min / lambda_max of the diagonally scaled
        information ``D^{-1/2} M D^{-1/2}`` (``D = diag M``) is ``<= rank_rtol``, or a
        diagonal entry ``M_ii`` is ``<= rank_rtol * max_k (F_k)_ii`` (per parameter: invariant to the
        parameters' units, e.g. rates of 0.04 and 3e7 1/s).
    near_singular_cond : float
        Condition number of the scaled information above which a design is flagged.
    symmetry_rtol, psd_rtol : float
        Input validation tolerances relative to the largest matrix norm.
    """

    rank_rtol: float = 1e-13
    near_singular_cond: float = 1e10
    symmetry_rtol: float = 1e-8
    psd_rtol: float = 1e-8


DEFAULT_SETTINGS = CriteriaSettings()


def gap_tolerance(criterion: Criterion, value: float, gap_tol: float) -> float:
    r"""Optimality tolerance at the criterion value ``value``: ``gap_tol`` for D (absolute on
    :math:`\log\det C`, i.e. relative on :math:`\det C`), :math:`\text{gap\_tol}\,|value|` for A
    and E (relative), 0 when ``value`` is not finite (no incumbent yet).

    Shared by every exact method: a design is proven optimal when ``value - lower_bound`` is
    at most this, and branch-and-bound prunes nodes whose bound is above ``value`` minus this.
    """
    if not np.isfinite(value):
        return 0.0
    return gap_tol if criterion is Criterion.D else gap_tol * abs(value)


def validate_information(F, S=None, *, settings: CriteriaSettings = DEFAULT_SETTINGS):
    r"""Check :math:`F_k=F_k^T\succeq0`, :math:`S_k=S_k^T` and return float arrays ``(F, S)``.

    Checks :math:`F_k = F_k^T \succeq 0` and :math:`S_k = S_k^T` (tolerances relative to
    :math:`\max_k\|F_k\|`), finiteness and shapes ``(n_S, n_p, n_p)``.

    Raises
    ------
    ValueError
        Naming the offending argument (``F`` or ``S``) and sensor index.
    """
    try:
        F = np.asarray(F, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"F: cannot convert information contributions to a float array ({exc})") from exc
    if F.ndim != 3 or F.shape[1] != F.shape[2] or F.shape[0] < 1 or F.shape[1] < 1:
        raise ValueError(f"F: expected shape (n_S, n_p, n_p) with n_S, n_p >= 1, got {F.shape}")
    if not np.all(np.isfinite(F)):
        bad = int(np.argwhere(~np.isfinite(F))[0, 0])
        raise ValueError(f"F: contains NaN or inf (first at sensor {bad})")
    scale = max(float(np.max(np.abs(F))), np.finfo(float).tiny)
    asym = np.max(np.abs(F - F.transpose(0, 2, 1)), axis=(1, 2))
    if np.any(asym > settings.symmetry_rtol * scale):
        k = int(np.argmax(asym))
        raise ValueError(f"F: information matrix of sensor {k} is not symmetric (max |F-F^T| = {asym[k]:.3g}, scale {scale:.3g})")
    F = 0.5 * (F + F.transpose(0, 2, 1))
    lam = np.linalg.eigvalsh(F)[:, 0]
    if np.any(lam < -settings.psd_rtol * scale):
        k = int(np.argmin(lam))
        raise ValueError(f"F: information matrix of sensor {k} is not positive semidefinite (min eigenvalue {lam[k]:.3g}, scale {scale:.3g})")
    if S is None:
        return F, None
    try:
        S = np.asarray(S, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"S: cannot convert second-order terms to a float array ({exc})") from exc
    if S.shape != F.shape:
        raise ValueError(f"S: expected the same shape as F {F.shape}, got {S.shape}")
    if not np.all(np.isfinite(S)):
        bad = int(np.argwhere(~np.isfinite(S))[0, 0])
        raise ValueError(f"S: contains NaN or inf (first at sensor {bad})")
    sscale = max(scale, float(np.max(np.abs(S))))
    asym = np.max(np.abs(S - S.transpose(0, 2, 1)), axis=(1, 2))
    if np.any(asym > settings.symmetry_rtol * sscale):
        k = int(np.argmax(asym))
        raise ValueError(f"S: second-order term of sensor {k} is not symmetric (max |S-S^T| = {asym[k]:.3g})")
    return F, 0.5 * (S + S.transpose(0, 2, 1))


@dataclass(frozen=True)
class BatchCriteria:
    """Criteria of a batch of designs (arrays of length n_designs).

    ``A``, ``logdet`` (log det C), ``det``, ``E`` are ``+inf`` for singular designs;
    ``singular``/``near_singular`` are flags, ``cond`` the scaled condition number,
    ``reason`` a short text per design ('' when regular).
    """

    A: np.ndarray
    logdet: np.ndarray
    det: np.ndarray
    E: np.ndarray
    cond: np.ndarray
    singular: np.ndarray
    near_singular: np.ndarray
    reason: tuple

    def value(self, criterion: Criterion) -> np.ndarray:
        """Objective used for optimisation (D -> log det C)."""
        return {Criterion.A: self.A, Criterion.D: self.logdet, Criterion.E: self.E}[criterion]


def _scaled_eigs(M, F_scale, settings):
    """Singular flags and cond of the diag-scaled M (n_designs, n_p, n_p); ``F_scale`` (n_p,) the largest
    information of every parameter in one candidate, max_k (F_k)_ii."""
    d = np.einsum("bii->bi", M)
    tiny = d <= settings.rank_rtol * F_scale[None, :]
    dsafe = np.where(tiny, 1.0, d)
    s = 1.0 / np.sqrt(dsafe)
    Ms = M * s[:, :, None] * s[:, None, :]
    lam = np.linalg.eigvalsh(Ms)
    lmax = lam[:, -1]
    lmin = lam[:, 0]
    singular = tiny.any(axis=1) | (lmin <= settings.rank_rtol * lmax)
    with np.errstate(divide="ignore", invalid="ignore"):
        cond = np.where(singular, np.inf, lmax / np.where(lmin > 0, lmin, 1.0))
    return singular, cond


def batch_criteria(F, S, W, kind="gauss_newton", *, settings: CriteriaSettings = DEFAULT_SETTINGS,
                   validated: bool = False) -> BatchCriteria:
    r"""Batched :math:`\Psi_A=\mathrm{tr}\,C(w)`, :math:`\Psi_D=\log\det C(w)`, :math:`\Psi_E=\lambda_{\max}(C(w))`.

    Computes :math:`C(w)` (second-order, :math:`H^{-1} G H^{-1}` with
    :math:`G=\sum_k w_k^2F_k`, :math:`H=\sum_k w_k(F_k+S_k)`) or :math:`C_{GN}(w)=G^{-1}`
    for every row ``w`` of ``W`` (shape ``(n_designs, n_S)``) with batched ``eigh``.

    Parameters
    ----------
    F, S : array_like
        Shapes ``(n_S, n_p, n_p)``; ``S`` may be ``None`` (treated as zero).
    W : array_like
        Designs, shape ``(n_designs, n_S)`` (binary in normal use).
    kind : {"gauss_newton", "second_order"}
    validated : bool
        Skip input validation (internal fast path).
    """
    kind = Kind.parse(kind)
    if not validated:
        F, S = validate_information(F, S, settings=settings)
    n_S, n_p, _ = F.shape
    W = np.asarray(W, dtype=float)
    if W.ndim == 1:
        W = W[None, :]
    if W.ndim != 2 or W.shape[1] != n_S:
        raise ValueError(f"w: expected shape (n_designs, {n_S}) or ({n_S},), got {W.shape}")
    if not np.all(np.isfinite(W)):
        raise ValueError("w: contains NaN or inf")
    nb = W.shape[0]
    F_scale = np.max(np.einsum("kii->ki", F), axis=0) if n_S else np.ones(n_p)   # per parameter (units)
    Fflat = F.reshape(n_S, -1)
    gauss_newton = kind is Kind.GAUSS_NEWTON
    G = ((W if gauss_newton else W * W) @ Fflat).reshape(nb, n_p, n_p)     # C_GN(w)^-1 = sum_k w_k F_k
    singular, cond = _scaled_eigs(G, F_scale, settings)
    reason = [""] * nb
    A = np.full(nb, np.inf)
    logdet = np.full(nb, np.inf)
    E = np.full(nb, np.inf)
    ok = ~singular
    if gauss_newton or S is None and np.array_equal(W * W, W):
        if ok.any():
            Gs, sc, log_d = _diag_scaled(G[ok])
            lam = np.linalg.eigvalsh(Gs)
            bad = lam[:, 0] <= 0
            lam_safe = np.where(lam > 0, lam, 1.0)
            C = _unscaled(np.linalg.inv(np.where(bad[:, None, None], np.eye(n_p)[None], Gs)), sc)
            A[ok] = np.where(bad, np.inf, np.trace(C, axis1=1, axis2=2))
            logdet[ok] = np.where(bad, np.inf, -(np.sum(np.log(lam_safe), axis=1) + log_d))
            E[ok] = np.where(bad, np.inf, np.linalg.eigvalsh(C)[:, -1])
            idx = np.flatnonzero(ok)[bad]
            singular[idx] = True
    else:
        Sflat = (np.zeros_like(F) if S is None else S).reshape(n_S, -1)
        H = (W @ (Fflat + Sflat)).reshape(nb, n_p, n_p)
        if ok.any():
            hs_sing, hcond = _scaled_eigs_any(H[ok], settings)
            Gs, sc, log_d = _diag_scaled(G[ok])
            Hs = H[ok] * sc[:, :, None] * sc[:, None, :]        # C = D^-1/2 Hs^-1 Gs Hs^-1 D^-1/2
            sign, logabs = np.linalg.slogdet(Hs)
            hbad = (sign == 0) | hs_sing
            idx_ok = np.flatnonzero(ok)
            Hsafe = np.where(hbad[:, None, None], np.eye(n_p)[None], Hs)
            X = np.linalg.inv(Hsafe)
            C = _unscaled(X @ Gs @ X.transpose(0, 2, 1), sc)
            lam = np.linalg.eigvalsh(C)
            _, logdetGs = np.linalg.slogdet(Gs)
            A[idx_ok] = np.where(hbad, np.inf, np.trace(C, axis1=1, axis2=2))
            logdet[idx_ok] = np.where(hbad, np.inf, logdetGs - 2.0 * logabs - log_d)
            E[idx_ok] = np.where(hbad, np.inf, lam[:, -1])
            for j in np.flatnonzero(hbad):
                singular[idx_ok[j]] = True
                reason[idx_ok[j]] = "singular: H(w) = sum w_k (F_k + S_k) is singular"
            cond[idx_ok] = np.maximum(cond[idx_ok], hcond)
    near = (~singular) & (cond > settings.near_singular_cond)
    for i in range(nb):
        if singular[i] and not reason[i]:
            reason[i] = f"singular: rank(sum w_k F_k) < n_p = {n_p}"
        elif near[i]:
            reason[i] = f"near-singular: condition number of scaled information {cond[i]:.3g} > {settings.near_singular_cond:.3g}"
    with np.errstate(over="ignore"):
        det = np.exp(logdet)
    return BatchCriteria(A=A, logdet=logdet, det=det, E=E, cond=cond, singular=singular,
                         near_singular=near, reason=tuple(reason))


def _diag_scaled(G):
    """(G_s, s, log det D): G = D^1/2 G_s D^1/2 with D = diag G (1 where not positive), s = D^-1/2.

    Parameters in very different units give an information G whose eigenvalues span many decades;
    its inverse and log det are then evaluated on G_s (rounding of cond(G_s) eps, not cond(G) eps)."""
    d = np.einsum("bii->bi", G)
    d = np.where(d > 0, d, 1.0)
    sc = 1.0 / np.sqrt(d)
    return G * sc[:, :, None] * sc[:, None, :], sc, np.log(d).sum(axis=1)


def _unscaled(Cs, sc):
    """D^-1/2 C_s D^-1/2, symmetrised."""
    C = Cs * sc[:, :, None] * sc[:, None, :]
    return 0.5 * (C + C.transpose(0, 2, 1))


def _scaled_eigs_any(H, settings):
    """Singularity/conditioning of a symmetric, possibly indefinite batch (scaled by |diag|)."""
    d = np.abs(np.einsum("bii->bi", H))
    scale = np.maximum(np.max(np.abs(H), axis=(1, 2)), np.finfo(float).tiny)
    dsafe = np.where(d <= settings.rank_rtol * scale[:, None], scale[:, None], d)
    s = 1.0 / np.sqrt(dsafe)
    Hs = H * s[:, :, None] * s[:, None, :]
    lam = np.abs(np.linalg.eigvalsh(Hs))
    lmin = lam.min(axis=1)
    lmax = lam.max(axis=1)
    sing = lmin <= settings.rank_rtol * lmax
    with np.errstate(divide="ignore", invalid="ignore"):
        cond = np.where(sing, np.inf, lmax / np.where(lmin > 0, lmin, 1.0))
    return sing, cond


def screening_values(F, S, W, criterion, kind="gauss_newton") -> np.ndarray:
    r"""Cheap values :math:`\tilde\Psi(w)\le\Psi(C(w))` (up to rounding) for screening a batch of designs.

    Without the rank and conditioning checks of :func:`batch_criteria`:
    A: :math:`\mathrm{tr}\,C` and D: :math:`\log\det C` (the same formulas, so equal up to rounding),
    E: :math:`\max_i C_{ii}\le\lambda_{\max}(C)`, with :math:`C = X G X^T`, :math:`X = H^{-1}`
    (second order) or :math:`C = G^{-1}` (Gauss-Newton).  A singular design may get any value
    (also NaN); only designs whose screening value is not above the incumbent need the exact,
    checked evaluation, so a design is never wrongly discarded.  ``F``, ``S`` validated, ``W``
    boolean (b, n_S).

    Returns
    -------
    ndarray, shape (b,)
        Screening values; ``-inf`` (never screened out) where a determinant is not positive, and
        for the whole batch when a matrix of it is exactly singular.
    """
    crit = Criterion.parse(criterion)
    kind = Kind.parse(kind)
    n_S, n_p, _ = F.shape
    Wf = np.asarray(W, dtype=float)
    G = (Wf @ F.reshape(n_S, -1)).reshape(-1, n_p, n_p)
    second = kind is Kind.SECOND_ORDER and S is not None
    # diagonally scaled as batch_criteria evaluates (G = D^1/2 G_s D^1/2): with parameters of very
    # different units the unscaled log det / inverse carry rounding of cond(G) eps, far above the
    # screening margin, and the best designs were screened out
    Gs, s, log_d = _diag_scaled(G)
    with np.errstate(all="ignore"):
        if second:
            H = (Wf @ (F + S).reshape(n_S, -1)).reshape(-1, n_p, n_p)
            Hs = H * s[:, :, None] * s[:, None, :]
        if crit is Criterion.D:
            sg, lg = np.linalg.slogdet(Gs)
            if not second:
                return np.where(sg > 0, -(lg + log_d), -np.inf)
            sh, lh = np.linalg.slogdet(Hs)
            return np.where((sg > 0) & (sh != 0), lg - 2.0 * lh - log_d, -np.inf)
        try:
            if second:
                X = np.linalg.inv(Hs)
                diag = np.einsum("bij,bij->bi", X @ Gs, X) * s ** 2
            else:
                diag = np.einsum("bii->bi", np.linalg.inv(Gs)) * s ** 2
        except np.linalg.LinAlgError:
            return np.full(len(Wf), -np.inf)
        return diag.sum(axis=1) if crit is Criterion.A else diag.max(axis=1)


def criterion_value(F, S=None, w=None, criterion=DEFAULT_CRITERION, kind="second_order", *,
                    settings: CriteriaSettings = DEFAULT_SETTINGS) -> float:
    r"""Criterion of one design: :math:`\Psi(C(w))` with :math:`\Psi\in\{\mathrm{tr},\log\det,\lambda_{\max}\}`.

    :math:`C(w)=H(w)^{-1}(\sum_k w_k^2F_k)H(w)^{-1}` for ``kind="second_order"`` (``S=None``
    means :math:`S_k=0`) or :math:`C_{GN}(w)=(\sum_k w_kF_k)^{-1}` for ``kind="gauss_newton"``.

    Parameters
    ----------
    F : array_like, shape (n_S, n_p, n_p)
        Per-sensor Gauss-Newton information, symmetric PSD.
    S : array_like or None, shape (n_S, n_p, n_p)
        Per-sensor second-order terms (symmetric, may be indefinite).
    w : array_like, shape (n_S,)
        Sensor weights (required).
    criterion : {"A", "D", "E"} or Criterion
        ``D`` returns log det C.
    kind : {"second_order", "gauss_newton"}

    Returns
    -------
    float
        Criterion value; ``+inf`` for a singular design.
    """
    if w is None:
        raise ValueError("w: sensor weights are required")
    crit = Criterion.parse(criterion)
    F, S = validate_information(F, S, settings=settings)
    w = np.asarray(w, dtype=float)
    if w.shape != (F.shape[0],):
        raise ValueError(f"w: expected shape ({F.shape[0]},) matching F, got {w.shape}")
    res = batch_criteria(F, S, w[None, :], kind, settings=settings, validated=True)
    return float(res.value(crit)[0])
