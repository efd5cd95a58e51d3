r"""Batched weighted least squares: many data sets of one model fitted together.

Monte Carlo replications, bootstrap samples and profile points fit the SAME model with the
same inputs, sensors and weights to R data sets z^(r).  States and sensitivities depend on
p only, never on the data, so the R fits are advanced together: every sweep evaluates the
model at all (member, input) points in one mapped CasADi call and does the linear algebra
as batched NumPy.  Member r minimises the reduced objective of paper eq. 3,

.. math::

    \Phi_r(p) = \tfrac12 \sum_{j,k} c^{(r)}_{jk} (\bar z^{(r)}_{jk} - h_k(y_j(p), p, q_j))^2 / \sigma_k^2
                + \Phi_{0,r},

(the terms of :class:`identification.refinement.ReducedProblem`), by Newton steps on the
equality-constrained problem in (p, y_1..y_nq) (the problem Ipopt solves in the first,
bound-free pass of :func:`identification.identify`).  Per sweep and point one factorisation of
E_y gives the state correction dy_E = -E_y^{-1} E, the state derivatives y' = -E_y^{-1} E_p and
(for the exact Hessian) the adjoint mu = -E_y^{-T} h_y^T lambda; with G = h_p + h_y y' and
lambda = dPhi/dh the step is

.. math::

    d_p = -M^{-1} G^T \lambda_{lin},\qquad y \leftarrow y + dy_E + y' d_p,

with M = J^T Omega J (Gauss-Newton, far from the optimum) or J^T Omega J + S (exact Newton,
S by AD and the implicit function theorem as :meth:`models.sensitivity.Sensitivities.hessians`),
and lambda_lin evaluated at the Newton-corrected states.  Once the states are converged (the
state solver's test |dy_E| <= 1e-12 (1 + |y|) at every input) the point is an exact reduced
point and the test of :func:`identification.refinement.refine` applies: a member has converged
when its Newton decrement g^T (J^T Omega J + S)^{-1} g is below ``refine_decrement`` (chi^2
units; or below the round-off of the gradient's sum), or the Newton step is below 1e-13
parameter scales; a step that increases Phi ends the iteration as in ``refine`` (accepted only
when the decrement is below ``decrement_tol``).  The estimate is then checked as
:func:`identification.identify` checks its own (Assumption 3, plausibility, finite covariance),
and the second-order (Bard) covariance C = H^{-1} J^T Omega^2 J H^{-T} comes from the same
exact terms (:func:`identification.estimator.covariance_from_terms`).

A member that does not converge (or fails a check, or ends on or outside a parameter bound)
is fitted by the full-space Ipopt estimator :func:`identification.identify` instead, and the
fallback is recorded (which member, why, and identify's error when it failed too): a member
is never dropped.  Input rows that are identical (same q and same state at p0) are evaluated
once per member (their data terms are pooled exactly).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from models.contract import Model
from models.state import numerics, solve_states
from .errors import DataError, IdentifiabilityError, IdentificationError, StateSolveError
from .estimator import IdentifySettings, check_identifiability, covariance_from_terms, identify
from .measurements import Measurements
from .refinement import ReducedProblem

__all__ = ["fit_batch", "BatchFit", "BatchMember", "FallbackRecord", "BatchSettings"]

#: an estimate farther than this many parameter scales from zero is a failed fit (as identify)
ABSURD_SCALES = 1e6


@dataclass(frozen=True)
class BatchSettings:
    """Settings of the batched Newton iteration (the estimator's own settings are IdentifySettings).

    Attributes
    ----------
    max_sweeps : int        sweeps (model evaluations at all points) before a member falls back
    newton_step : float     largest Gauss-Newton step (in parameter scales, inf-norm) from which on
                            exact Newton steps are taken
    max_step : float        steps longer than this (parameter scales, inf-norm) are shortened to it
    state_tol : float       state convergence |dy_E|_inf <= state_tol (1 + |y|_inf) at every input
                            (the test of models.state.solve_states)
    """

    max_sweeps: int = 30
    newton_step: float = 0.05
    max_step: float = 0.5
    state_tol: float = 1e-12

    def __post_init__(self):
        if not (isinstance(self.max_sweeps, (int, np.integer)) and self.max_sweeps >= 1):
            raise ValueError(f"max_sweeps: expected an integer >= 1, got {self.max_sweeps!r}")
        for name in ("newton_step", "max_step", "state_tol"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float, np.floating)) and np.isfinite(v) and v > 0):
                raise ValueError(f"{name}: expected a finite number > 0, got {v!r}")


@dataclass(frozen=True)
class FallbackRecord:
    """A member fitted by :func:`identification.identify` instead of the batch iteration.

    Attributes
    ----------
    member : int      index of the data set
    reason : str      why the batch iteration did not give its estimate
    error : str       "" when identify succeeded, else its error ("ExceptionType: message")
    """

    member: int
    reason: str
    error: str = ""


def _readonly(a) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class BatchMember:
    """The estimate of one member, with the fields of :class:`identification.Estimate` that the
    split tests and Monte Carlo studies read (same meaning and units).

    Attributes
    ----------
    p : ndarray (n_p,)                estimate
    cov, cov_gn : ndarray (n_p, n_p)  second-order (Bard) and Gauss-Newton covariances
    information, S, H : ndarray       J^T Omega J, the second-order term and their sum
    objective : float                 0.5 sum w ((z - h)/sigma)^2 (sigma as used, as Estimate.objective)
    rss : float                       unweighted residual sum of squares over the selected sensors
    n_data, dof : int                 used values and n - n_p
    sigma_estimated : bool
    sigma : ndarray (n_S,)            sigmas of the covariance (estimated when unknown)
    states : ndarray (n_q, n_y)       states at the estimate
    fitted : ndarray (n_q, n_S)       model outputs at the estimate
    decrement : float                 Newton decrement g^T H^-1 g at the estimate (chi^2 units)
    iterations : int                  sweeps of the batch iteration
    notes : tuple                     always empty: the batch engine does not write the
                                      estimator's diagnostic notes (identify's summary does)
    """

    p: np.ndarray
    cov: np.ndarray
    cov_gn: np.ndarray
    information: np.ndarray
    S: np.ndarray
    H: np.ndarray
    objective: float
    rss: float
    n_data: int
    dof: int
    sigma_estimated: bool
    sigma: np.ndarray
    states: np.ndarray
    fitted: np.ndarray
    decrement: float
    iterations: int
    notes: tuple = ()

    def __post_init__(self):
        for name in ("p", "cov", "cov_gn", "information", "S", "H", "sigma", "states", "fitted"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))


@dataclass(frozen=True, eq=False)
class BatchFit:
    """Estimates of R data sets of one model (:func:`fit_batch`); NaN rows where a member failed.

    Attributes
    ----------
    p : ndarray (R, n_p)                 estimates
    cov, cov_gn : ndarray (R, n_p, n_p)  second-order (Bard) and Gauss-Newton covariances
    information : ndarray (R, n_p, n_p)  J^T Omega J (rescaled by s^2 / sigma_0^2 when sigma is estimated)
    objective : ndarray (R,)             objective at the estimate (as Estimate.objective)
    rss : ndarray (R,)                   residual sums of squares over the selected sensors
    decrement : ndarray (R,)             Newton decrements at the estimates (NaN for fallbacks)
    iterations : ndarray (R,) int        sweeps of the batch iteration (0 for fallbacks)
    converged : ndarray (R,) bool        the batch iteration gave the estimate
    ok : ndarray (R,) bool               an estimate exists (batch or fallback)
    fallbacks : tuple of FallbackRecord  members fitted by identify instead (which, why, outcome)
    results : tuple                      per member a BatchMember, an Estimate (fallback) or the
                                         exception identify raised (read with :meth:`result`)
    """

    p: np.ndarray
    cov: np.ndarray
    cov_gn: np.ndarray
    information: np.ndarray
    objective: np.ndarray
    rss: np.ndarray
    decrement: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    ok: np.ndarray
    fallbacks: tuple
    results: tuple = field(repr=False)

    def __post_init__(self):
        for name in ("p", "cov", "cov_gn", "information", "objective", "rss", "decrement"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))
        for name, dt in (("iterations", int), ("converged", bool), ("ok", bool)):
            a = np.array(getattr(self, name), dtype=dt, copy=True)
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    @property
    def n_members(self) -> int:
        return len(self.results)

    def result(self, member: int):
        """The estimate of one member (a BatchMember, or identify's Estimate for a fallback).

        Raises
        ------
        IdentificationError, DataError
            The error identify raised for a member whose fallback failed too.
        """
        r = self.results[member]
        if isinstance(r, Exception):
            raise r
        return r


# ---------------------------------------------------------------------------- helpers
def _param_scale(model: Model, p0: np.ndarray) -> np.ndarray:
    """Parameter scales s_p as identify uses them: the declared scale, else |p0|, else the bound
    range, else 1."""
    s = np.empty(model.n_p)
    for i, par in enumerate(model.params):
        if par.scale is not None:
            s[i] = par.scale
        elif p0[i] != 0:
            s[i] = abs(p0[i])
        elif math.isfinite(par.lower) and math.isfinite(par.upper) and par.upper > par.lower:
            s[i] = par.upper - par.lower
        else:
            s[i] = 1.0
    return s


def _objective_sigma(model: Model, data: Measurements, selected: np.ndarray) -> np.ndarray:
    """The sigmas of the objective: the data's, or (sigma unknown) the common spread identify uses."""
    if data.sigma is not None:
        return np.asarray(data.sigma, float)
    zs = data.z[:, :, selected]
    spread = float(np.nanstd(zs)) or float(np.nanmean(np.abs(zs))) or 1.0
    return np.full(model.n_S, spread)


def _unique_rows(inputs: np.ndarray, Y: np.ndarray) -> tuple:
    """(first row of each group, group of each row): rows with equal q and equal states at p0."""
    n = inputs.shape[0]
    group = np.full(n, -1)
    firsts = []
    scale = 1.0 + (np.abs(Y).max() if Y.size else 0.0)
    for j in range(n):
        for g, i in enumerate(firsts):
            if np.array_equal(inputs[j], inputs[i]) and (not Y.size or np.max(np.abs(Y[j] - Y[i])) <= 1e-10 * scale):
                group[j] = g
                break
        else:
            group[j] = len(firsts)
            firsts.append(j)
    return np.array(firsts, int), group


def _padded(m: int, R: int) -> int:
    """Members of one mapped evaluation: R when more than half are active, else the next power of two
    (few distinct map sizes, so few mapped CasADi functions are built)."""
    if 2 * m > R:
        return R
    return 1 << max(0, (m - 1).bit_length())


class _Points:
    """Mapped evaluation of the model at (member, unique input) points: E, h and derivatives."""

    def __init__(self, model: Model, Q_u: np.ndarray, R: int):
        self.model, self.num, self.Q_u, self.R = model, numerics(model), Q_u, R
        self.n_u = Q_u.shape[0]

    def _args(self, Y, P):
        m = P.shape[0]
        mp = _padded(m, self.R)
        idx = np.minimum(np.arange(mp), m - 1)
        n = mp * self.n_u
        Yf = Y[idx].reshape(n, -1)
        Pf = np.repeat(P[idx], self.n_u, axis=0)
        Qf = np.tile(self.Q_u, (mp, 1))
        return m, n, Yf, Pf, Qf

    def terms(self, Y: np.ndarray, P: np.ndarray) -> tuple:
        """(E, h, Ey, Ep, hy, hp) at Y (m, n_u, n_y), P (m, n_p), each (m, n_u, ...)."""
        m, n, Yf, Pf, Qf = self._args(Y, P)
        h, Ey, Ep, hy, hp = self.num.batched("sens", n)(Yf, Pf, Qf)
        if self.model.n_y:
            E = self.num.batched("E_y", n)(Yf, Pf, Qf)[0][:, :, 0]
        else:
            E = np.zeros((n, 0))
        out = (E, h[:, :, 0], Ey, Ep, hy, hp)
        k = m * self.n_u
        return tuple(a[:k].reshape((m, self.n_u) + a.shape[1:]) for a in out)

    def lag_hessians(self, Y, P, lam, mu) -> np.ndarray:
        """Hessians of lam^T h + mu^T E w.r.t. (y, p) at every point, (m, n_u, n_y + n_p, n_y + n_p)."""
        m, n, Yf, Pf, Qf = self._args(Y, P)
        mp = n // self.n_u
        idx = np.minimum(np.arange(mp), m - 1)
        L = lam[idx].reshape(n, -1)
        Mu = mu[idx].reshape(n, -1)
        Hl = self.num.batched("lag_hess", n)(Yf, Pf, Qf, L, Mu)[0]
        k = m * self.n_u
        return Hl[:k].reshape((m, self.n_u) + Hl.shape[1:])


@dataclass(frozen=True)
class _Prepared:
    """The data terms of all members on the unique inputs (see :func:`_prepare`)."""

    first: np.ndarray          # (n_u,) first input row of each group
    group: np.ndarray          # (n_q,) group of each input row
    zb: np.ndarray             # (R, n_u, n_S) pooled means
    wts: np.ndarray            # (R, n_u, n_S) pooled weighted counts / sigma^2
    const: np.ndarray          # (R,) constant part of Phi
    cw: np.ndarray             # (R, n_u, n_S) pooled weighted counts
    sig: np.ndarray            # (R, n_S) sigmas of the objective
    n_data: np.ndarray         # (R,) used values
    selected: np.ndarray       # sensors with w > 0
    w: np.ndarray              # (n_S,) sensor weights


def _prepare(model, data, w, Y_ref) -> _Prepared:
    """Data terms c, zbar, Phi_0 of every member (ReducedProblem.of), pooled over identical input rows:
    sum_{j in u} c_j (zbar_j - h)^2 = C_u (zbar_u - h)^2 + sum_{j in u} c_j (zbar_j - zbar_u)^2 with
    C_u = sum_j c_j and zbar_u = sum_j c_j zbar_j / C_u (exact)."""
    first, group = _unique_rows(data[0].inputs, Y_ref)
    n_u, R, n_S = first.size, len(data), model.n_S
    selected = np.flatnonzero(w > 0)
    zb = np.zeros((R, n_u, n_S))
    cwu = np.zeros((R, n_u, n_S))
    const = np.zeros(R)
    sig = np.zeros((R, n_S))
    n_data = np.zeros(R, int)
    onehot = np.zeros((n_u, group.size))
    onehot[group, np.arange(group.size)] = 1.0
    for r, d in enumerate(data):
        s = _objective_sigma(model, d, selected)
        prob = ReducedProblem.of(model, d, w, s, np.ones(model.n_p))
        C = onehot @ prob.cw
        S1 = onehot @ (prob.cw * prob.zbar)
        zu = np.divide(S1, C, out=np.zeros_like(S1), where=C > 0)
        extra = 0.5 * float(np.sum(prob.cw * (prob.zbar - zu[group]) ** 2 / s ** 2))
        zb[r], cwu[r], const[r], sig[r] = zu, C, prob.const + extra, s
        n_data[r] = d.n_data(w)
    return _Prepared(first, group, zb, cwu / sig[:, None, :] ** 2, const, cwu, sig, n_data, selected, w)


def _chol_solve(M: np.ndarray, b: np.ndarray, s_p: np.ndarray) -> tuple:
    """(x, decrement, good) with M x = b and b^T M^{-1} b for a stack M (m, n_p, n_p), through the
    Cholesky factor of diag(s_p) M diag(s_p); ``good`` False (x, decrement NaN) where M is not
    positive definite."""
    m, n_p = b.shape
    Ms = M * np.outer(s_p, s_p)[None]
    good = np.ones(m, bool)
    try:
        L = np.linalg.cholesky(Ms)
    except np.linalg.LinAlgError:
        L = np.broadcast_to(np.eye(n_p), Ms.shape).copy()
        for i in range(m):
            try:
                L[i] = np.linalg.cholesky(Ms[i])
            except np.linalg.LinAlgError:
                good[i] = False
    v = np.linalg.solve(L, (b * s_p)[:, :, None])
    x = s_p * np.linalg.solve(L.transpose(0, 2, 1), v)[:, :, 0]
    dec = np.einsum("ip,ip->i", v[:, :, 0], v[:, :, 0])
    x[~good] = np.nan
    dec[~good] = np.nan
    return x, dec, good, L


# ---------------------------------------------------------------------------- the iteration
@dataclass
class _Iteration:
    """Per-member state of :func:`_iterate` (mutable, private to it)."""

    P: np.ndarray              # (R, n_p) current parameters
    Y: np.ndarray              # (R, n_u, n_y) current states
    newton: np.ndarray         # (R,) exact Newton phase
    active: np.ndarray         # (R,) still iterating
    done: np.ndarray           # (R,) converged
    reason: list               # why a member stopped without converging
    prev_obj: np.ndarray       # (R,) Phi at the previous exact point (inf before the first)
    sweeps: np.ndarray         # (R,) sweeps taken
    final: dict                # member -> its last exact point (dict of arrays)


@dataclass(frozen=True)
class _Sweep:
    """Terms of one sweep at the active members ``a`` (local index k = position in ``a``)."""

    a: np.ndarray
    P: np.ndarray
    Y: np.ndarray
    h: np.ndarray
    G: np.ndarray
    F: np.ndarray
    S: np.ndarray
    has_S: np.ndarray
    g: np.ndarray
    obj: np.ndarray
    dyE: np.ndarray
    yp: np.ndarray
    lam: np.ndarray
    state_ok: np.ndarray
    finite: np.ndarray


def _evaluate(model, prep: _Prepared, points: _Points, it: _Iteration, a: np.ndarray, sym: bool,
              bs: BatchSettings) -> _Sweep:
    """One sweep's model terms at the members ``a``: state correction dy_E, y', G, the gradient at
    the Newton-corrected states, J^T Omega J and (Newton phase or converged states) S."""
    n_p, n_y = model.n_p, model.n_y
    P, Y = it.P[a], it.Y[a]
    m, n_u = a.size, points.n_u
    E, h, Ey, Ep, hy, hp = points.terms(Y, P)
    zb, wts = prep.zb[a], prep.wts[a]
    with np.errstate(invalid="ignore", over="ignore"):
        finite = (np.all(np.isfinite(h.reshape(m, -1)), axis=1) & np.all(np.isfinite(E.reshape(m, -1)), axis=1)
                  & np.all(np.isfinite(Ey.reshape(m, -1)), axis=1) & np.all(np.isfinite(Ep.reshape(m, -1)), axis=1))
    lam_h = -wts * (zb - np.where(finite[:, None, None], h, 0.0))        # dPhi/dh at the current states
    mu = None
    if n_y:
        fin4 = finite[:, None, None, None]
        Eyf = np.where(fin4, Ey, np.eye(n_y))
        rhs = [-np.where(finite[:, None, None], E, 0.0)[..., None], -np.where(fin4, Ep, 0.0)]
        if sym:                      # E_y symmetric: the adjoint needs no second factorisation
            rhs.append(-np.einsum("mjsy,mjs->mjy", np.where(fin4, hy, 0.0), lam_h)[..., None])
        B = np.concatenate(rhs, axis=3)
        try:
            X = np.linalg.solve(Eyf, B)
        except np.linalg.LinAlgError:          # a singular E_y: find the members it belongs to
            X = np.full(B.shape, np.nan)
            for k in range(m):
                try:
                    X[k] = np.linalg.solve(Eyf[k], B[k])
                except np.linalg.LinAlgError:
                    finite[k] = False
        dyE, yp = X[..., 0], X[..., 1:1 + n_p]
        if sym:
            mu = X[..., -1]
        G = hp + np.einsum("mjsy,mjyp->mjsp", hy, yp)
        h_lin = h + np.einsum("mjsy,mjy->mjs", hy, dyE)
        ynorm = 1.0 + np.abs(Y).max(axis=2)
        state_ok = np.all(np.abs(dyE).max(axis=2) <= bs.state_tol * ynorm, axis=1)
    else:
        dyE = yp = np.zeros((m, n_u, 0))
        G, h_lin = hp, h
        state_ok = np.ones(m, bool)
    finite &= np.all(np.isfinite(G.reshape(m, -1)), axis=1) & np.all(np.isfinite(dyE.reshape(m, -1)), axis=1)
    lam = -wts * (zb - h_lin)
    g = np.einsum("mjs,mjsp->mp", lam, G)
    F = np.einsum("mjs,mjsp,mjsr->mpr", wts, G, G)
    with np.errstate(over="ignore", invalid="ignore"):
        obj = 0.5 * np.einsum("mjs,mjs->m", wts, (zb - h) ** 2) + prep.const[a]
    has_S = (it.newton[a] | state_ok) & finite
    S = np.zeros((m, n_p, n_p))
    if np.any(has_S):
        b = np.flatnonzero(has_S)
        if n_y and mu is None:
            rhs_mu = -np.einsum("mjsy,mjs->mjy", hy[b], lam_h[b])
            mu_b = np.linalg.solve(Ey[b].transpose(0, 1, 3, 2), rhs_mu[..., None])[..., 0]
        else:
            mu_b = mu[b] if n_y else np.zeros((b.size, n_u, 0))
        Hl = points.lag_hessians(Y[b], P[b], lam_h[b], mu_b)
        eye = np.broadcast_to(np.eye(n_p), (b.size, n_u, n_p, n_p))
        Z = np.concatenate([yp[b], eye], axis=2) if n_y else eye
        Sb = np.einsum("mjva,mjvw,mjwb->mab", Z, Hl, Z, optimize=True)
        S[b] = 0.5 * (Sb + Sb.transpose(0, 2, 1))
    return _Sweep(a, P, Y, h, G, F, S, has_S, g, obj, dyE, yp, lam, state_ok, finite)


def _advance(model, prep: _Prepared, it: _Iteration, sw: _Sweep, s_p: np.ndarray, settings: IdentifySettings,
             bs: BatchSettings, sigma_unknown: bool) -> None:
    """Convergence test (that of identification.refinement.refine) and the next step of every member."""
    n_p = model.n_p
    a = sw.a
    unit = 2 * sw.obj / np.maximum(prep.n_data[a] - n_p, 1) if sigma_unknown else np.ones(a.size)
    dN, decN, goodN, LN = _chol_solve(sw.F + sw.S, -sw.g, s_p)
    dG, decG, goodG, _ = _chol_solve(sw.F, -sw.g, s_p)
    # the decrement that round-off in the gradient's sum over the data alone produces
    g_err = 16 * np.finfo(float).eps * np.einsum("mjs,mjsp->mp", np.abs(sw.lam), np.abs(sw.G)) * s_p
    u = np.linalg.solve(LN, g_err[:, :, None])[:, :, 0]
    round_off = np.einsum("mp,mp->m", u, u)
    for k, i in enumerate(a):
        if not sw.finite[k]:
            it.reason[i] = "the model or its derivatives are not finite (or E_y is singular) at the iterate"
            it.active[i] = False
            continue
        exact = sw.state_ok[k] and sw.has_S[k]
        if exact:
            prev = it.final.get(i)
            dec_k = decN[k] if goodN[k] else np.inf
            if not sw.obj[k] <= it.prev_obj[i] * (1 + 1e-14) + 1e-300:
                # refine's test: a step may not increase Phi.  In the quadratic region (previous
                # decrement below decrement_tol) Phi cannot resolve the decrease any more: the
                # step is kept while the decrement falls, else the previous point is the optimum
                quadratic = prev is not None and prev["decrement"] <= settings.decrement_tol * prev["unit"]
                if not quadratic or not dec_k < prev["decrement"]:
                    if quadratic:
                        it.done[i] = True
                    else:
                        it.reason[i] = "a Newton step increased the objective before the optimum was reached"
                    it.active[i] = False
                    continue
            it.prev_obj[i] = sw.obj[k]
            it.final[i] = dict(p=sw.P[k], Y=sw.Y[k], h=sw.h[k], G=sw.G[k], F=sw.F[k], S=sw.S[k], obj=sw.obj[k],
                               decrement=dec_k, unit=unit[k], sweeps=int(it.sweeps[i]))
            if goodN[k] and (decN[k] <= max(settings.refine_decrement * unit[k], round_off[k])
                             or np.max(np.abs(dN[k] / s_p)) < 1e-13):
                it.done[i] = True
                it.active[i] = False
                continue
        if not goodG[k]:
            it.reason[i] = "J^T Omega J is singular at the iterate"
            it.active[i] = False
            continue
        if not it.newton[i] and np.max(np.abs(dG[k] / s_p)) < bs.newton_step:
            it.newton[i] = True
        dp = dN[k] if (it.newton[i] and sw.has_S[k] and goodN[k]) else dG[k]
        big = np.max(np.abs(dp / s_p))
        if big > bs.max_step:
            dp = dp * (bs.max_step / big)
        p_new = sw.P[k] + dp
        if not (np.all(p_new > model.lower) and np.all(p_new < model.upper)):
            it.reason[i] = "the iteration left the parameter bounds"
            it.active[i] = False
            continue
        it.P[i] = p_new
        if model.n_y:
            it.Y[i] = sw.Y[k] + sw.dyE[k] + sw.yp[k] @ dp


def _iterate(model, prep: _Prepared, points: _Points, s_p, P0, Y0, settings: IdentifySettings,
             bs: BatchSettings, sym: bool, sigma_unknown: bool) -> _Iteration:
    """Sweeps until every member has converged or stopped (see the module docstring)."""
    R = P0.shape[0]
    it = _Iteration(P0.copy(), Y0.copy(), np.zeros(R, bool), np.ones(R, bool), np.zeros(R, bool), [""] * R,
                    np.full(R, np.inf), np.zeros(R, int), {})
    for _ in range(bs.max_sweeps):
        a = np.flatnonzero(it.active)
        if not a.size:
            break
        it.sweeps[a] += 1
        try:
            sw = _evaluate(model, prep, points, it, a, sym, bs)
        except StateSolveError as exc:
            for i in a:
                it.reason[i] = f"model evaluation failed: {exc}"
            it.active[a] = False
            break
        _advance(model, prep, it, sw, s_p, settings, bs, sigma_unknown)
    for i in np.flatnonzero(it.active):
        it.reason[i] = f"no convergence in {bs.max_sweeps} sweeps"
    it.active[:] = False
    return it


# ---------------------------------------------------------------------------- the front door
def _check_batch(model: Model, data, p0, weights) -> tuple:
    """Validated (data tuple, p0, w): one model, shared inputs, all sigmas known or all unknown."""
    if not isinstance(model, Model):
        raise TypeError(f"model: expected a models.Model, got {type(model).__name__}")
    data = tuple(data)
    if not data:
        raise DataError("data: the batch is empty; give at least one Measurements")
    for r, d in enumerate(data):
        if not isinstance(d, Measurements):
            raise TypeError(f"data[{r}]: expected an identification.Measurements, got {type(d).__name__}")
    q = data[0].inputs
    for r, d in enumerate(data[1:], 1):
        if d.inputs.shape != q.shape or not np.array_equal(d.inputs, q):
            raise DataError(f"data[{r}]: its inputs differ from data[0]'s; a batch fits data sets with the same "
                            "inputs (group the data sets by inputs, or call identify per data set)")
        if (d.sigma is None) != (data[0].sigma is None):
            raise DataError(f"data[{r}]: sigma is {'unknown' if d.sigma is None else 'given'} but not for data[0]; "
                            "a batch needs all sigmas given or all unknown")
        if d.n_S != data[0].n_S:
            raise DataError(f"data[{r}]: has {d.n_S} sensors, data[0] has {data[0].n_S}")
    try:
        p0 = np.asarray(p0, dtype=float).ravel()
    except (TypeError, ValueError):
        raise DataError(f"p0: not numeric: {p0!r}") from None
    if p0.shape != (model.n_p,):
        raise DataError(f"p0: expected {model.n_p} values ({', '.join(model.param_names)}), got {p0.size}")
    w = data[0].sensor_weights(weights)
    return data, p0, w


def _member(model, prep: _Prepared, r: int, fin: dict, data: Measurements, s_p: np.ndarray,
            settings: IdentifySettings) -> BatchMember:
    """The estimate of a converged member: identifiability, covariance (eq. 7) and plausibility as
    identify checks them; raises IdentificationError (the caller falls back) when a check fails."""
    n_p = model.n_p
    G, cw, sig = fin["G"], prep.cw[r], prep.sig[r]
    check_identifiability(model, G, cw, sig, s_p, settings.rank_rtol, prep.selected)
    F, S = fin["F"], fin["S"]
    F2 = np.einsum("jk,jkp,jkr->pr", cw * prep.w[None, :] / sig ** 2, G, G)
    h_rows = fin["h"][prep.group]
    resid = data.z - h_rows[None]
    rss = float(np.nansum(resid[:, :, prep.selected] ** 2))
    n = int(prep.n_data[r])
    dof = n - n_p
    if data.sigma is None:
        s2 = rss / dof
        factor = s2 / sig[0] ** 2
        sig_used = np.full(model.n_S, math.sqrt(s2))
    else:
        factor, sig_used = 1.0, sig
    cov, cov_gn, H, _ = covariance_from_terms(F, F2, S)
    cov, cov_gn = cov * factor, cov_gn * factor
    p = fin["p"]
    ref = np.maximum(s_p, 1.0)
    if not np.all(np.isfinite(p) & (np.abs(p) <= ABSURD_SCALES * ref)):
        raise IdentificationError("the estimate ran off to absurd values", status="absurd estimate")
    d1, d2 = np.diag(cov), np.diag(cov_gn)
    if not (np.all(np.isfinite(d1) & (d1 >= 0)) and np.all(np.isfinite(d2) & (d2 >= 0))):
        raise IdentificationError("non-finite standard errors", status="non-finite standard errors")
    states = fin["Y"][prep.group] if model.n_y else np.zeros((prep.group.size, 0))
    return BatchMember(p=p, cov=cov, cov_gn=cov_gn, information=F / factor, S=S / factor, H=H / factor,
                       objective=fin["obj"] / factor if data.sigma is None else fin["obj"], rss=rss, n_data=n,
                       dof=dof, sigma_estimated=data.sigma is None, sigma=sig_used, states=states, fitted=h_rows,
                       decrement=fin["decrement"] / factor, iterations=fin["sweeps"])


def _symmetric(model, points: _Points, p0: np.ndarray, Y_u: np.ndarray) -> bool:
    """True when E_y is symmetric at the start (checked at every unique input to 1e-12 relative):
    the adjoint E_y^{-T} h_y^T lambda then shares the factorisation of the other solves."""
    if not model.n_y:
        return False
    Ey = points.terms(Y_u[None], p0[None])[2][0]
    return bool(np.all(np.abs(Ey - Ey.transpose(0, 2, 1)) <= 1e-12 * np.abs(Ey).max(axis=(1, 2))[:, None, None]))


def fit_batch(model: Model, data: Sequence[Measurements], p0, weights=None, settings: IdentifySettings | None = None,
              Y0=None, starts=None, start_states=None, batch_settings: BatchSettings | None = None) -> BatchFit:
    """Fit R data sets of one model (same inputs, sensors and weights) together; see the module docstring.

    Parameters
    ----------
    model : models.Model
    data : sequence of Measurements
        The R data sets: the same inputs (n_q, d_q); sigma given for all or unknown for all
        (missing values may differ).
    p0 : array_like (n_p,)
        Start values (inside the bounds), also the start of identify for a fallback member.
    weights : array_like (n_S,), optional
        Sensor weights (default all ones).
    settings : IdentifySettings, optional
        The estimator's settings: the convergence test (``refine_decrement``, ``decrement_tol``),
        the identifiability test (``rank_rtol``) and the settings of the fallback fits.
    Y0 : array (n_q, n_y), optional
        States at p0 (else solved), the start of the members without ``starts``.
    starts : array (R, n_p), optional
        Per-member start values (a row of NaN: start at p0), e.g. the precision-weighted mean of
        two fits for a pooled fit.  Requires ``start_states``.
    start_states : array (R, n_q, n_y), optional
        States at (or near) ``starts``.
    batch_settings : BatchSettings, optional

    Returns
    -------
    BatchFit
        Every member has an estimate (batch, or identify's as fallback) or identify's error.

    Raises
    ------
    DataError, TypeError
        Bad input for the batch as a whole (the message names the argument); a single member's
        bad data is its fallback's error instead.
    """
    settings = settings or IdentifySettings()
    bs = batch_settings or BatchSettings()
    data, p0, w = _check_batch(model, data, p0, weights)
    R, n_p, n_y = len(data), model.n_p, model.n_y
    q = data[0].inputs
    records, results = [], [None] * R
    fallback = {}                                   # member -> reason

    def run_fallbacks():
        for r, why in sorted(fallback.items()):
            try:
                est = identify(model, data[r], p0, weights=weights, settings=settings, Y0=Y0)
                records.append(FallbackRecord(r, why))
                results[r] = est
            except (IdentificationError, DataError) as exc:
                records.append(FallbackRecord(r, why, f"{type(exc).__name__}: {exc}"))
                results[r] = exc

    usable = (q.shape[1] == model.n_q_dim and data[0].n_S == model.n_S and np.any(w > 0)
              and np.all(p0 >= model.lower) and np.all(p0 <= model.upper) and np.all(np.isfinite(p0))
              and (not n_y or numerics(model).dense))
    Y_ref = None
    if usable:
        try:
            Y_ref = np.asarray(Y0, float) if Y0 is not None else solve_states(model, p0, q)
        except StateSolveError:
            usable = False
    if not usable:
        why = ("the batch engine handles states of at most 60 variables" if n_y and not numerics(model).dense
               else "the start or the problem is not valid for the batch engine")
        fallback.update({r: why for r in range(R)})
        run_fallbacks()
        return _collect(model, results, records, np.zeros(R, bool), np.full(R, np.nan), np.zeros(R, int))
    for r, d in enumerate(data):
        n = d.n_data(w)
        if n < n_p or (d.sigma is None and n <= n_p):
            fallback[r] = "too few values for the parameters"
    prep = _prepare(model, data, w, Y_ref if n_y else np.zeros((q.shape[0], 0)))
    Q_u = q[prep.first]
    points = _Points(model, Q_u, R)
    s_p = _param_scale(model, p0)
    Y_u = Y_ref[prep.first] if n_y else np.zeros((Q_u.shape[0], 0))
    P0 = np.tile(p0, (R, 1))
    Yst = np.tile(Y_u, (R, 1, 1))
    if starts is not None:
        S0 = np.asarray(starts, float).reshape(R, n_p)
        if start_states is None and n_y:
            raise DataError("start_states: needed with starts (states at the start values, shape (R, n_q, n_y))")
        own = np.all(np.isfinite(S0), axis=1)
        P0[own] = S0[own]
        if n_y:
            YS = np.asarray(start_states, float).reshape(R, q.shape[0], n_y)
            Yst[own] = YS[own][:, prep.first]
    sym = _symmetric(model, points, p0, Y_u)
    members = np.array([r for r in range(R) if r not in fallback], int)
    it = None
    if members.size:
        prep_m = _Prepared(prep.first, prep.group, prep.zb[members], prep.wts[members], prep.const[members],
                           prep.cw[members], prep.sig[members], prep.n_data[members], prep.selected, prep.w)
        points.R = members.size
        it = _iterate(model, prep_m, points, s_p, P0[members], Yst[members], settings, bs, sym,
                      data[0].sigma is None)
    converged = np.zeros(R, bool)
    decrement = np.full(R, np.nan)
    sweeps = np.zeros(R, int)
    for k, r in enumerate(members):
        sweeps[r] = it.sweeps[k]
        if not it.done[k]:
            fallback[r] = it.reason[k] or "the batch iteration did not converge"
            continue
        fin = it.final[k]
        margin = 1e-6 * s_p
        if not (np.all(fin["p"] > model.lower + margin) and np.all(fin["p"] < model.upper - margin)):
            fallback[r] = "the optimum lies at or beyond a parameter bound (identify solves the bounded problem)"
            continue
        try:
            results[r] = _member(model, prep_m, k, fin, data[r], s_p, settings)
        except (IdentificationError, IdentifiabilityError) as exc:
            fallback[r] = f"the converged point failed identify's checks: {exc}"
            continue
        converged[r] = True
        decrement[r] = results[r].decrement
    run_fallbacks()
    return _collect(model, results, records, converged, decrement, sweeps)


def _collect(model, results, records, converged, decrement, sweeps) -> BatchFit:
    R, n_p = len(results), model.n_p
    p = np.full((R, n_p), np.nan)
    cov = np.full((R, n_p, n_p), np.nan)
    cov_gn = np.full((R, n_p, n_p), np.nan)
    info = np.full((R, n_p, n_p), np.nan)
    obj = np.full(R, np.nan)
    rss = np.full(R, np.nan)
    ok = np.zeros(R, bool)
    for r, res in enumerate(results):
        if isinstance(res, Exception) or res is None:
            continue
        ok[r] = True
        p[r], cov[r], cov_gn[r], info[r] = res.p, res.cov, res.cov_gn, res.information
        obj[r], rss[r] = res.objective, res.rss
    return BatchFit(p, cov, cov_gn, info, obj, rss, decrement, sweeps, converged, ok,
                    tuple(sorted(records, key=lambda x: x.member)), tuple(results))
