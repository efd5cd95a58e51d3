r"""Batched weighted least squares: many data sets of one model fitted together.

Monte Carlo replications, bootstrap samples and profile points fit the SAME model with the
same sensors and weights to R data sets z^(r), with common inputs or with each member's own
inputs of one shape (n_q, d_q) (profile points: the fixed parameter values are input columns of
:func:`identification.fit.fixed.fixed_model`).  States and sensitivities depend on
p only, never on the data, so the R fits are advanced together: every sweep evaluates the
model at all (member, input) points in one mapped CasADi call and does the linear algebra
as batched NumPy.  Member r minimises the reduced objective of paper eq. 3,

.. math::

    \Phi_r(p) = \tfrac12 \sum_{j,k} c^{(r)}_{jk} (\bar z^{(r)}_{jk} - h_k(y_j(p), p, q_j))^2 / \sigma_k^2
                + \Phi_{0,r},

(the terms of :class:`identification.fit.refinement.ReducedProblem`), by Newton steps on the
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
point and the test of :func:`identification.fit.refinement.refine` applies: a member has converged
when its Newton decrement g^T (J^T Omega J + S)^{-1} g is below ``refine_decrement`` (chi^2
units; or below the round-off of the gradient's sum), or the Newton step is below 1e-13
parameter scales.  A step that increases Phi is halved back towards the last exact point
(identify's backtracking, at most 30 halvings); in the quadratic region (decrement below
``decrement_tol``, where Phi cannot resolve the decrease) the step is kept while the decrement
falls, else the last exact point is the optimum, as in ``refine``.  The estimate is then
checked as :func:`identification.identify` checks its own (Assumption 3 on the column-
normalised sqrt(Omega) J, |p| below 1e6 parameter scales, finite standard errors), and the
second-order (Bard) covariance C = H^{-1} J^T Omega^2 J H^{-T} comes from the same exact terms
and the same QR factor of sqrt(Omega) J as identify's (:mod:`identification.fit.factor`, batched).

Evaluation: for a model in SX with JIT compilation on (:func:`models.state.set_jit`, as in
the Monte Carlo workers) one compiled CasADi function, mapped over all (member, input)
points, returns every per-point term of a sweep (dy_E, y', G, the point's share of g,
J^T Omega J and S, and of Phi) from one sparse LDL^T factorisation of E_y (AMD ordering;
S by forward-over-reverse AD); NumPy only sums over the inputs and takes the n_p x n_p steps.
The factorisation has no pivoting, so it is used only where it is backward stable: every
pivot positive and E_y symmetric to 1e-12 (checked at every point of every sweep); otherwise,
and without JIT compilation, the sweep takes the dense path (E, h and their derivatives from
CasADi, LU solves of E_y by LAPACK, the Lagrangian Hessian by CasADi).

With common inputs, members that share the start (p0 and the states solved there) share the
first sweep: the model is evaluated once and only the data terms differ, and identical input
rows (same q and the same state at p0) are evaluated once per member (their data terms are
pooled exactly).  With per-member inputs every member is evaluated at its own n_q rows.
Models with more than 60 states (sparse state Jacobians) are not batched: every member is
fitted by identify; for a collocated ODE model the members' fits run together with their
trajectory evaluations merged (:mod:`identification.fit.batch_trajectory`: no state-size ceiling).

A member that does not converge (or fails a check, or ends on or outside a parameter bound)
is fitted by the full-space Ipopt estimator :func:`identification.identify` instead, and the
fallback is recorded (which member, why, and identify's error when it failed too): a member
is never dropped.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable, Sequence

import casadi as ca
import numpy as np

from models.contract import Model
from models.state import numerics, solve_states
from models.trajectory import trajectory_numerics
from identification.errors import DataError, IdentificationError, StateSolveError
from identification.fit.batch_trajectory import decrements, fit_members
from identification.fit.unbounded import not_bounded_reason
from identification.fit.estimator import IdentifySettings, as_start_vector, fit_static, param_scale
from identification.fit.factor import covariances, weighted_factor
from identification.fit.measurements import Measurements

__all__ = ["fit_batch", "BatchData", "BatchFit", "BatchMember", "FallbackRecord", "BatchSettings"]

#: an estimate farther than this many parameter scales from zero is a failed fit (as identify)
ABSURD_SCALES = 1e6
#: the fallback reason of a member whose Newton iteration left the parameter bounds
LEFT_BOUNDS = "the iteration left the parameter bounds"


@dataclass(frozen=True)
class BatchSettings:
    """Settings of the batched Newton iteration (the estimator's own settings are IdentifySettings).

    Attributes
    ----------
    max_sweeps : int        sweeps (model evaluations at all points) before a member falls back
    newton_step : float     after a step shorter than this (parameter scales, inf-norm) a member
                            takes exact Newton steps (before: Gauss-Newton)
    max_step : float        steps longer than this (inf-norm of |dp| / max(s_p, |p|)) are shortened to it
    state_tol : float       state convergence |dy_E|_inf <= state_tol (1 + |y|_inf) at every input
                            (the test of models.state.solve_states)
    """

    max_sweeps: int = 30
    newton_step: float = 0.25
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
    error : str       "" when identify succeeded, else its error ("ExceptionType: message"), or
                      "not bounded: ..." when identify returned an estimate the data do not bound
    """

    member: int
    reason: str
    error: str = ""


def _readonly(a) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class BatchData:
    """R data sets of one model, stacked (the input of :func:`fit_batch`).

    Attributes
    ----------
    inputs : ndarray (n_q, d_q)      the common inputs, or (R, n_q, d_q): each member's own inputs
                                     (same shape; e.g. profile points, whose fixed parameter values
                                     are input columns, :func:`identification.fit.fixed.fixed_model`)
    z : ndarray (R, n_M, n_q, n_S)   values (NaN: missing)
    sigma : ndarray (R, n_S) or None sensor sigmas (None: a common unknown sigma for every member)
    make : callable or None          member -> its Measurements (the data of a fallback fit; None:
                                     ``Measurements(inputs, z[r], sigma[r])``)

    Build it with :meth:`of` from Measurements, or directly from arrays (cheaper for many small
    data sets: no Measurements is built unless a member falls back).
    """

    inputs: np.ndarray
    z: np.ndarray
    sigma: np.ndarray | None
    make: Callable | None = None

    def __post_init__(self):
        q = np.asarray(self.inputs, float)
        z = np.asarray(self.z, float)
        if q.ndim not in (2, 3) or z.ndim != 4 or z.shape[2] != q.shape[-2] or z.shape[0] < 1:
            raise DataError(f"z, inputs: expected z of shape (R >= 1, n_M, n_q, n_S) and inputs (n_q, d_q) or "
                            f"(R, n_q, d_q), got {z.shape} and {q.shape}")
        if q.ndim == 3 and q.shape[0] != z.shape[0]:
            raise DataError(f"inputs: per-member inputs need one (n_q, d_q) array per member of z: expected shape "
                            f"({z.shape[0]}, {q.shape[1]}, {q.shape[2]}), got {q.shape}")
        if self.sigma is not None:
            sig = np.asarray(self.sigma, float)
            if sig.shape != (z.shape[0], z.shape[3]) or not np.all(np.isfinite(sig) & (sig > 0)):
                raise DataError(f"sigma: expected positive finite values of shape {(z.shape[0], z.shape[3])} "
                                f"or None, got {sig.shape}")
            object.__setattr__(self, "sigma", sig)
        object.__setattr__(self, "inputs", q)
        object.__setattr__(self, "z", z)

    @classmethod
    def of(cls, data: Sequence[Measurements]) -> "BatchData":
        """Stack Measurements (all sigmas given or all unknown; members with fewer series are padded
        with missing values).  Inputs of the same shape (n_q, d_q): when they are all equal the batch
        has common inputs, else each member keeps its own (``inputs`` of shape (R, n_q, d_q))."""
        data = tuple(data)
        if not data:
            raise DataError("data: the batch is empty; give at least one Measurements")
        for r, d in enumerate(data):
            if not isinstance(d, Measurements):
                raise TypeError(f"data[{r}]: expected an identification.Measurements, got {type(d).__name__}")
        d0 = data[0]
        for r, d in enumerate(data[1:], 1):
            if d.inputs.shape != d0.inputs.shape:
                raise DataError(f"data[{r}]: its inputs have shape {d.inputs.shape}, data[0]'s {d0.inputs.shape}; a "
                                "batch fits data sets whose inputs have one shape (n_q, d_q) (group the data sets "
                                "by shape, or call identify per data set)")
            if (d.sigma is None) != (d0.sigma is None):
                raise DataError(f"data[{r}]: sigma is {'unknown' if d.sigma is None else 'given'} but not for "
                                "data[0]; a batch needs all sigmas given or all unknown")
            if d.n_S != d0.n_S:
                raise DataError(f"data[{r}]: has {d.n_S} sensors, data[0] has {d0.n_S}")
        n_M = max(d.n_M for d in data)
        z = np.full((len(data), n_M) + d0.z.shape[1:], np.nan)
        for r, d in enumerate(data):
            z[r, :d.n_M] = d.z
        sig = None if d0.sigma is None else np.stack([np.asarray(d.sigma, float) for d in data])
        shared = all(np.array_equal(d.inputs, d0.inputs) for d in data[1:])
        inputs = d0.inputs if shared else np.stack([d.inputs for d in data])
        return cls(inputs, z, sig, data.__getitem__)

    @property
    def n_members(self) -> int:
        return self.z.shape[0]

    @property
    def shared(self) -> bool:
        """True when all members have the same inputs (``inputs`` of shape (n_q, d_q))."""
        return self.inputs.ndim == 2

    def member_inputs(self, r: int) -> np.ndarray:
        """The inputs (n_q, d_q) of member r."""
        return self.inputs if self.shared else self.inputs[r]

    def member(self, r: int) -> Measurements:
        """The Measurements of member r."""
        if self.make is not None:
            return self.make(r)
        return Measurements(self.member_inputs(r), self.z[r], None if self.sigma is None else self.sigma[r])

    def weights(self, weights=None) -> np.ndarray:
        """Validated sensor weights (n_S,): ones for None, else finite and >= 0 (as Measurements.sensor_weights)."""
        n_S = self.z.shape[3]
        if weights is None:
            return np.ones(n_S)
        w = np.asarray(weights, dtype=float)
        if w.shape != (n_S,):
            raise DataError(f"weights: expected {n_S} sensor weights, got shape {w.shape}")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise DataError(f"weights: must be finite and non-negative, got {w.tolist()}")
        return w


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
    state_derivatives : ndarray       y'(p) = -E_y^{-1} E_p at the estimate, (n_q, n_y, n_p)
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
    state_derivatives: np.ndarray
    notes: tuple = ()

    def __post_init__(self):
        for name in ("p", "cov", "cov_gn", "information", "S", "H", "sigma", "states", "fitted", "state_derivatives"):
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
    ok : ndarray (R,) bool               an estimate exists (batch or fallback; False for an estimate
                                         that is not bounded, kept in ``results``)
    fallbacks : tuple of FallbackRecord  members fitted by identify instead (which, why, outcome)
    results : tuple                      per member a BatchMember, an Estimate (fallback) or the
                                         exception identify raised (read with :meth:`result`)
    dense_sweeps : int                   sweeps evaluated by the dense path (NumPy LAPACK solves of
                                         E_y) instead of the fused compiled sweep function (used for
                                         models in SX with JIT compilation on, where E_y is
                                         symmetric positive definite; the shared first
                                         sweep is not counted)
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
    dense_sweeps: int = 0

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


class _Mapped:
    """A CasADi function mapped over n points, evaluated through one reused FunctionBuffer.

    Arguments are C-contiguous (n, d_i) arrays (row = point); outputs are the dense C arrays
    (n, cols, rows) of CasADi's column-major (rows, cols n) results (transpose the last two axes).
    """

    def __init__(self, f, n: int):
        fm = f.map(n)
        sym = fm.mx_in()
        self._f = ca.Function(f"{f.name()}_batch_{n}", sym, [ca.densify(o) for o in fm.call(sym)])
        self.n = n
        self._in = [f.size1_in(i) for i in range(f.n_in())]
        self._out = [(f.size1_out(i), f.size2_out(i)) for i in range(f.n_out())]
        self._buf, self._ev = self._f.buffer()

    def __call__(self, *args) -> list:
        keep = []
        for i, (a, r) in enumerate(zip(args, self._in)):
            a = np.ascontiguousarray(a, dtype=float)
            if a.size != self.n * r:
                raise ValueError(f"argument {i}: expected {self.n} x {r} values, got {a.shape}")
            keep.append(a)
            self._buf.set_arg(i, memoryview(a.reshape(-1)))
        outs = [np.empty((self.n, c, r)) for r, c in self._out]
        for i, o in enumerate(outs):
            self._buf.set_res(i, memoryview(o.reshape(-1)))
        self._ev()
        if self._buf.ret() != 0:
            raise StateSolveError(f"evaluation of {self._f.name()} failed (CasADi return code {self._buf.ret()})")
        return outs


def _point_functions(model) -> dict:
    """The per-point functions of the batch engine (JIT-compiled as the model's others when
    models.state.set_jit is on): ``terms`` (y, p, q) -> (E, h, E_y, E_p, h_y, h_p) and ``lag_hess``."""
    num = numerics(model)
    compiled = num.jit_active()
    got = model.cache.get("batch.point_functions", compiled)
    if got is not None:
        return got
    S = ca.SX if model.symbolic == "SX" else ca.MX
    y, p, q = S.sym("y", model.n_y), S.sym("p", model.n_p), S.sym("q", model.n_q_dim)
    h, Ey, Ep, hy, hp = num.sens(y, p, q)
    terms = ca.Function("batch_terms", [y, p, q], [model.E_fun(y, p, q), h, Ey, Ep, hy, hp])
    fns = {"terms": num.compiled("batch_terms", terms), "lag_hess": num.compiled("lag_hess")}
    return model.cache.put("batch.point_functions", compiled, fns)


#: the outputs of :func:`_sweep_function` that are matrices (y', G, F, S); the others are vectors
_SWEEP_MATRICES = (1, 3, 5, 6)


def _sweep_function(model) -> ca.Function | None:
    r"""The fused per-point function of a sweep, or None when the model does not qualify.

    (y, p, q, wts, zb, c) -> (dy_E, y', h, G, g, F, S, obj, gabs, pivot, asym) at one (member,
    input) point, with lambda_h = c - wts (zb - h) (dPhi/dh at the current states; c = 0 in a
    sweep, unit vectors for the basis of the shared first sweep) and, through one sparse LDL^T
    factorisation of E_y (CasADi ``ldl`` with AMD ordering, no pivoting; valid where E_y is
    symmetric positive definite, which ``pivot`` > 0 and ``asym`` <= 1e-12 certify):

    dy_E = -E_y^{-1} E, y' = -E_y^{-1} E_p, mu = -E_y^{-1} h_y^T lambda_h, G = h_p + h_y y',
    h_lin = h + h_y dy_E, lambda = -wts (zb - h_lin), g = G^T lambda, F = G^T diag(wts) G,
    S = Z^T (d^2/dv^2 (lambda_h^T h + mu^T E)) Z with v = (y, p), Z = [y'; I] (exact AD,
    forward over reverse), obj = 1/2 sum wts (zb - h)^2, gabs = |G|^T |lambda|,
    pivot = min D / max |D|, asym = max |E_y - E_y^T| / max |E_y|.

    Qualifies: a model in SX with states (n_y > 0, dense numerics), a symmetric sparsity pattern of
    E_y, and JIT compilation active (the CasADi virtual machine evaluates this function slower
    than the dense path evaluates its parts).  Kept in ``model.cache``."""
    num = numerics(model)
    if not (model.n_y and num.jit_active()):
        return None
    got = model.cache.get("batch.sweep_function", True)
    if got is not None:
        return got or None
    n_y, n_p, n_S = model.n_y, model.n_p, model.n_S
    y, p, q = ca.SX.sym("y", n_y), ca.SX.sym("p", n_p), ca.SX.sym("q", model.n_q_dim)
    wts, zb, c = ca.SX.sym("wts", n_S), ca.SX.sym("zb", n_S), ca.SX.sym("c", n_S)
    E = model.E_fun(y, p, q)
    h, Ey, Ep, hy, hp = num.sens(y, p, q)
    if not Ey.sparsity().is_symmetric():
        return model.cache.put("batch.sweep_function", True, False) or None
    D, LT, perm = ca.ldl(Ey, True)
    lam_h = c - wts * (zb - h)
    X = ca.ldl_solve(ca.horzcat(-E, -Ep, -ca.mtimes(hy.T, lam_h)), D, LT, perm)
    dyE, yp, mu = X[:, 0], X[:, 1:1 + n_p], X[:, 1 + n_p]
    G = hp + ca.mtimes(hy, yp)
    lam = -wts * (zb - h - ca.mtimes(hy, dyE))
    v = ca.vertcat(y, p)
    lam_s, mu_s, Z_s = ca.SX.sym("lam", n_S), ca.SX.sym("mu", n_y), ca.SX.sym("Z", n_y + n_p, n_p)
    L = ca.dot(lam_s, h) + ca.dot(mu_s, E)
    SZ = ca.Function("sz", [v, q, lam_s, mu_s, Z_s], [ca.mtimes(Z_s.T, ca.jtimes(ca.gradient(L, v), v, Z_s))])
    S = SZ(v, q, lam_h, mu, ca.vertcat(yp, ca.SX.eye(n_p)))
    absD = ca.fabs(D)
    outs = [dyE, yp, h, G, ca.mtimes(G.T, lam), ca.mtimes(G.T, ca.mtimes(ca.diag(wts), G)), S,
            0.5 * ca.dot(wts, (zb - h) ** 2), ca.mtimes(ca.fabs(G).T, ca.fabs(lam)),
            ca.mmin(D) / ca.mmax(absD), ca.mmax(ca.fabs(Ey - Ey.T)) / ca.mmax(ca.fabs(Ey))]
    f = ca.Function("batch_sweep", [y, p, q, wts, zb, c], [ca.densify(o) for o in outs],
                    ["y", "p", "q", "wts", "zb", "c"],
                    ["dyE", "yp", "h", "G", "g", "F", "S", "obj", "gabs", "pivot", "asym"])
    g = num.compiled("batch_sweep", f)
    if g is f:                          # no compiler after all: the dense path
        return model.cache.put("batch.sweep_function", True, False) or None
    return model.cache.put("batch.sweep_function", True, g)


def _mapped(model, name: str, n: int) -> _Mapped:
    """The :class:`_Mapped` evaluator of a point function over n points (kept in ``model.cache``)."""
    key = (name, n, numerics(model).jit_active())
    f = model.cache.get("batch.mapped", key)
    if f is None:
        base = _sweep_function(model) if name == "sweep" else _point_functions(model)[name]
        f = model.cache.put("batch.mapped", key, _Mapped(base, n), maxsize=256)
    return f


class _Points:
    """Mapped evaluation of the model at (member, unique input) points: E, h and derivatives.

    ``Q_u`` (n_u, d_q): the inputs of every member; (R, n_u, d_q): each member's own (the methods
    then take ``members``, the members' positions in Q_u)."""

    def __init__(self, model: Model, Q_u: np.ndarray, R: int, p0: np.ndarray | None = None,
                 Y_u: np.ndarray | None = None):
        self.model, self.Q_u, self.R = model, Q_u, R
        self.n_u = Q_u.shape[-2]
        self.fused = _sweep_function(model) is not None
        self._start = (p0, Y_u)
        self._sym = None

    def symmetric(self) -> bool:
        """:func:`_symmetric` at the start (p0, Y_u), evaluated once, when the dense path first needs it."""
        if self._sym is None:
            p0, Y_u = self._start
            self._sym = p0 is not None and _symmetric(self.model, self, p0, Y_u if Y_u.ndim == 2 else Y_u[0],
                                                      None if self.Q_u.ndim == 2 else np.zeros(1, int))
        return self._sym

    def sweep(self, Y: np.ndarray, P: np.ndarray, wts: np.ndarray, zb: np.ndarray,
              c: np.ndarray | None = None, members: np.ndarray | None = None) -> tuple:
        """The outputs of :func:`_sweep_function` at Y (m, n_u, n_y), P (m, n_p) and the data terms
        wts, zb, c (m, n_u, n_S) (c None: zero), each (m, n_u, ...) (matrices in row-major order)."""
        m, n, Yf, Pf, Qf = self._args(Y, P, members)
        mp = n // self.n_u
        idx = np.minimum(np.arange(mp), m - 1)
        W, Zb = wts[idx].reshape(n, -1), zb[idx].reshape(n, -1)
        C = np.zeros_like(W) if c is None else c[idx].reshape(n, -1)
        outs = _mapped(self.model, "sweep", n)(Yf, Pf, Qf, W, Zb, C)
        k, sh = m * self.n_u, (m, self.n_u)
        res = []
        for i, o in enumerate(outs):
            o = o[:k].reshape(sh + o.shape[1:])
            res.append(o.swapaxes(2, 3) if i in _SWEEP_MATRICES else o[..., 0, :])
        return tuple(res)

    def _args(self, Y, P, members=None):
        m = P.shape[0]
        mp = _padded(m, self.R)
        idx = np.minimum(np.arange(mp), m - 1)
        n = mp * self.n_u
        Yf = Y[idx].reshape(n, -1)
        Pf = np.repeat(P[idx], self.n_u, axis=0)
        if self.Q_u.ndim == 2:
            Qf = np.tile(self.Q_u, (mp, 1))
        else:                        # per-member inputs: the rows of each evaluated member
            Qf = self.Q_u[np.asarray(members)[idx]].reshape(n, -1)
        return m, n, Yf, Pf, Qf

    def terms(self, Y: np.ndarray, P: np.ndarray, members: np.ndarray | None = None) -> tuple:
        """(E, h, Ey, Ep, hy, hp) at Y (m, n_u, n_y), P (m, n_p), each (m, n_u, ...)."""
        m, n, Yf, Pf, Qf = self._args(Y, P, members)
        E, h, Ey, Ep, hy, hp = _mapped(self.model, "terms", n)(Yf, Pf, Qf)
        k, sh = m * self.n_u, (m, self.n_u)
        return (E[:k, 0].reshape(sh + (-1,)), h[:k, 0].reshape(sh + (-1,)),
                *(a[:k].reshape(sh + a.shape[1:]).swapaxes(2, 3) for a in (Ey, Ep, hy, hp)))

    def lag_hessians(self, Y, P, lam, mu, members: np.ndarray | None = None) -> np.ndarray:
        """Hessians of lam^T h + mu^T E w.r.t. (y, p) at every point, (m, n_u, n_y + n_p, n_y + n_p)."""
        m, n, Yf, Pf, Qf = self._args(Y, P, members)
        mp = n // self.n_u
        idx = np.minimum(np.arange(mp), m - 1)
        L = lam[idx].reshape(n, -1)
        Mu = mu[idx].reshape(n, -1)
        Hl = _mapped(self.model, "lag_hess", n)(Yf, Pf, Qf, L, Mu)[0]       # symmetric: no transpose
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
    Z: np.ndarray              # (R, n_M, n_q, n_S) the members' data


def _prepare(model, data: BatchData, w, Y_ref) -> _Prepared:
    """Data terms of every member, as :meth:`identification.fit.refinement.ReducedProblem.of` computes them
    (c_jk = n_jk w_k, zbar the per-(input, sensor) means, Phi_0 the within-group scatter) and the
    objective's sigmas as identify chooses them, pooled over identical input rows:
    sum_{j in u} c_j (zbar_j - h)^2 = C_u (zbar_u - h)^2 + sum_{j in u} c_j (zbar_j - zbar_u)^2 with
    C_u = sum_j c_j and zbar_u = sum_j c_j zbar_j / C_u (exact)."""
    if data.shared:
        first, group = _unique_rows(data.inputs, Y_ref)
    else:                            # per-member inputs: no pooling of rows
        first = group = np.arange(data.inputs.shape[1])
    n_u, R = first.size, data.n_members
    selected = np.flatnonzero(w > 0)
    Z = data.z
    mask = np.isfinite(Z)
    counts = mask.sum(axis=1).astype(float)                                  # (R, n_q, n_S)
    zsum = np.where(mask, Z, 0.0).sum(axis=1)
    zbar = np.where(counts > 0, zsum / np.maximum(counts, 1), 0.0)
    if data.sigma is not None:
        sig = data.sigma
    else:                            # identify's common spread of the selected sensors
        sig = np.empty((R, model.n_S))
        for r in range(R):
            zs = Z[r][:, :, selected]
            sig[r] = float(np.nanstd(zs)) or float(np.nanmean(np.abs(zs))) or 1.0
    cw = counts * w[None, None, :]
    dev = np.where(mask, Z - zbar[:, None], 0.0)
    const = 0.5 * np.sum(w[None, None, None, :] * dev ** 2 / sig[:, None, None, :] ** 2, axis=(1, 2, 3))
    onehot = np.zeros((n_u, group.size))
    onehot[group, np.arange(group.size)] = 1.0
    C = np.einsum("uj,rjs->rus", onehot, cw)
    S1 = np.einsum("uj,rjs->rus", onehot, cw * zbar)
    zu = np.divide(S1, C, out=np.zeros_like(S1), where=C > 0)
    const = const + 0.5 * np.sum(cw * (zbar - zu[:, group]) ** 2 / sig[:, None, :] ** 2, axis=(1, 2))
    n_data = counts[:, :, w > 0].sum(axis=(1, 2)).astype(int)
    return _Prepared(first, group, zu, C / sig[:, None, :] ** 2, const, C, sig, n_data, selected, w, Z)


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
    """Per-member state of :func:`_iterate` (mutable, private to it); the ``f*`` arrays hold each
    member's last exact point (states converged), where it stops when it has converged."""

    P: np.ndarray              # (R, n_p) current parameters
    Y: np.ndarray              # (R, n_u, n_y) current states
    newton: np.ndarray         # (R,) exact Newton phase
    active: np.ndarray         # (R,) still iterating
    done: np.ndarray           # (R,) converged
    reason: list               # why a member stopped without converging
    sweeps: np.ndarray         # (R,) sweeps taken
    has_final: np.ndarray      # (R,) an exact point was reached
    fp: np.ndarray             # (R, n_p)
    fY: np.ndarray             # (R, n_u, n_y)
    fyp: np.ndarray            # (R, n_u, n_y, n_p) state derivatives y'
    fh: np.ndarray             # (R, n_u, n_S)
    fG: np.ndarray             # (R, n_u, n_S, n_p)
    fF: np.ndarray             # (R, n_p, n_p)
    fS: np.ndarray             # (R, n_p, n_p)
    fobj: np.ndarray           # (R,) Phi
    fdec: np.ndarray           # (R,) Newton decrement (inf where H is not positive definite)
    funit: np.ndarray          # (R,) unit of the decrement (1, or s^2 / sigma_0^2 when sigma is unknown)
    fsweeps: np.ndarray        # (R,)
    halvings: np.ndarray       # (R,) step halvings since the last exact point
    dense_sweeps: int = 0      # sweeps evaluated by the dense path (_evaluate)

    @classmethod
    def start(cls, P0, Y0, n_S):
        R, n_p = P0.shape
        n_u, n_y = Y0.shape[1:]
        z = np.zeros
        return cls(P0.copy(), Y0.copy(), z(R, bool), np.ones(R, bool), z(R, bool), [""] * R, z(R, int), z(R, bool),
                   z((R, n_p)), z((R, n_u, n_y)), z((R, n_u, n_y, n_p)), z((R, n_u, n_S)), z((R, n_u, n_S, n_p)),
                   z((R, n_p, n_p)), z((R, n_p, n_p)), np.full(R, np.inf), np.full(R, np.inf), np.ones(R), z(R, int),
                   z(R, int))


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
    gabs: np.ndarray           # (m, n_p) sum over the data of |lambda| |G| (round-off of the gradient)
    state_ok: np.ndarray
    finite: np.ndarray


def _shared_terms_fused(model, points: _Points, P1: np.ndarray, Y1: np.ndarray) -> tuple | None:
    """:func:`_shared_terms` by the fused sweep function: one mapped call at the n_u inputs with
    lambda_h = 0 (h, G, y') and with lambda_h = e_k for every sensor k (T_jk); None when E_y is not
    symmetric positive definite (or not finite) at some input (the caller takes the dense path)."""
    n_S, n_u = model.n_S, points.n_u
    Yk = np.repeat(Y1, n_S + 1, axis=0)
    Pk = np.repeat(P1, n_S + 1, axis=0)
    zero = np.zeros((n_S + 1, n_u, n_S))
    c = zero.copy()
    c[1:] = np.eye(n_S)[:, None, :]
    _, yp, h, G, _, _, S, _, _, piv, asym = _Points(model, points.Q_u, n_S + 1).sweep(Yk, Pk, zero, zero, c)
    with np.errstate(invalid="ignore"):
        good = (np.all(np.isfinite(h[0])) and np.all(np.isfinite(G[0])) and np.all(np.isfinite(yp[0]))
                and np.all(np.isfinite(S)) and np.all(piv > 0) and np.all(asym <= 1e-12))
    if not good:
        return None
    return h[0], G[0], yp[0], S[1:].transpose(1, 0, 2, 3)


def _shared_terms(model, points: _Points, P1: np.ndarray, Y1: np.ndarray) -> tuple:
    """The model terms at a common point (P1 (1, n_p), Y1 (1, n_u, n_y), states solved):
    h (n_u, n_S), G (n_u, n_S, n_p), y' (n_u, n_y, n_p) and T (n_u, n_S, n_p, n_p) with
    T_jk = Z_j^T B_jk Z_j, B_jk the Hessian of the Lagrangian for lambda_h = e_k (see
    :func:`_evaluate_shared`)."""
    n_p, n_y, n_S = model.n_p, model.n_y, model.n_S
    n_u = points.n_u
    if points.fused:
        got = _shared_terms_fused(model, points, P1, Y1)
        if got is not None:
            return got
    E, h, Ey, Ep, hy, hp = (x[0] for x in points.terms(Y1, P1))
    if not (np.all(np.isfinite(h)) and np.all(np.isfinite(Ey)) and np.all(np.isfinite(Ep))):
        raise StateSolveError("the model or its derivatives are not finite at the common start")
    if n_y:
        try:
            yp = -np.linalg.solve(Ey, Ep)
            K = np.linalg.solve(Ey.transpose(0, 2, 1), hy.transpose(0, 2, 1))      # (n_u, n_y, n_S)
        except np.linalg.LinAlgError:
            raise StateSolveError("E_y is singular at the common start") from None
        G = hp + np.einsum("jsy,jyp->jsp", hy, yp)
        Z = np.concatenate([yp, np.broadcast_to(np.eye(n_p), (n_u, n_p, n_p))], axis=1)
    else:
        K, G, Z = np.zeros((n_u, 0, n_S)), hp, np.broadcast_to(np.eye(n_p), (n_u, n_p, n_p))
    eye = np.eye(n_S)
    Yk = np.repeat(Y1, n_S, axis=0).reshape(n_S, n_u, n_y)
    Pk = np.repeat(P1, n_S, axis=0)
    lam_k = np.broadcast_to(eye[:, None, :], (n_S, n_u, n_S))
    mu_k = -K.transpose(2, 0, 1)                                                     # (n_S, n_u, n_y)
    Bk = _Points(model, points.Q_u, n_S).lag_hessians(Yk, Pk, lam_k, mu_k)          # (n_S, n_u, v, v)
    T = np.einsum("jva,kjvw,jwb->jkab", Z, Bk, Z, optimize=True)                     # (n_u, n_S, n_p, n_p)
    return h, G, (Z[:, :n_y, :] if n_y else np.zeros((n_u, 0, n_p))), T


def _evaluate_shared(model, prep: _Prepared, points: _Points, it: _Iteration, a: np.ndarray) -> _Sweep:
    """:func:`_evaluate` when every member in ``a`` is at the same (p, states) with the states solved
    (the common start p0): the model terms are evaluated once and only the data terms differ.

    With K = E_y^{-T} h_y^T the adjoint of member r is mu_r = -K lambda_r, and since the Lagrangian
    Hessian is linear in (lambda, mu), S_r = sum_jk lambda_r,jk Z_j^T B_jk Z_j with
    B_jk = lag_hess(e_k, -K_j e_k) (one evaluation per input and sensor).
    """
    n_p, n_y = model.n_p, model.n_y
    m, n_u = a.size, points.n_u
    P1, Y1 = it.P[a[:1]], it.Y[a[:1]]
    h, G, yp, T = _shared_terms(model, points, P1, Y1)
    zb, wts = prep.zb[a], prep.wts[a]
    lam = -wts * (zb - h[None])
    g = np.einsum("mjs,jsp->mp", lam, G)
    gabs = np.einsum("mjs,jsp->mp", np.abs(lam), np.abs(G))
    F = np.broadcast_to(np.einsum("mjs,jsp,jsr->mpr", wts, G, G), (m, n_p, n_p))
    with np.errstate(over="ignore", invalid="ignore"):
        obj = 0.5 * np.einsum("mjs,mjs->m", wts, (zb - h[None]) ** 2) + prep.const[a]
    S = np.einsum("mjs,jsab->mab", lam, T)
    S = 0.5 * (S + S.transpose(0, 2, 1))
    ones = np.ones(m, bool)
    return _Sweep(a, np.repeat(P1, m, axis=0), np.repeat(Y1, m, axis=0), np.broadcast_to(h, (m,) + h.shape),
                  np.broadcast_to(G, (m,) + G.shape), np.array(F), S, ones, g, obj,
                  np.zeros((m, n_u, n_y)), np.broadcast_to(yp, (m, n_u, n_y, n_p)), gabs, ones, ones.copy())


def _evaluate_fused(model, prep: _Prepared, points: _Points, it: _Iteration, a: np.ndarray,
                    bs: BatchSettings) -> _Sweep | None:
    """:func:`_evaluate` by one mapped call of the fused sweep function (:func:`_sweep_function`):
    every per-point term (states' Newton correction, y', G, the gradient at the corrected states,
    J^T Omega J and S) comes from CasADi and NumPy only sums over the inputs.  None when E_y is not
    certified symmetric positive definite at some point (a pivot that is not positive and finite,
    or asymmetry): the caller then takes the dense path for this sweep."""
    n_p = model.n_p
    P, Y = it.P[a], it.Y[a]
    dyE, yp, h, G, g, F, S, obj, gabs, piv, asym = points.sweep(Y, P, prep.wts[a], prep.zb[a], members=a)
    with np.errstate(invalid="ignore", over="ignore"):
        spd = np.all((piv[..., 0] > 0) & (asym[..., 0] <= 1e-12))
        finite = (np.isfinite(h).all(axis=(1, 2)) & np.isfinite(G).all(axis=(1, 2, 3))
                  & np.isfinite(dyE).all(axis=(1, 2)) & np.isfinite(yp).all(axis=(1, 2, 3)))
    if not spd:                      # a zero, negative or non-finite pivot, or E_y not symmetric
        return None
    g, F, S, gabs = g.sum(axis=1), F.sum(axis=1), S.sum(axis=1), gabs.sum(axis=1)
    with np.errstate(over="ignore", invalid="ignore"):
        obj = obj[..., 0].sum(axis=1) + prep.const[a]
        ynorm = 1.0 + np.abs(Y).max(axis=2)
        state_ok = np.all(np.abs(dyE).max(axis=2) <= bs.state_tol * ynorm, axis=1)
    if not np.all(finite):           # neutral values where a member is not finite (it stops this sweep)
        bad = ~finite
        for arr in (dyE, yp, h, G, g, S, gabs):
            arr[bad] = 0.0
        F[bad] = np.eye(n_p)
        state_ok &= finite
    has_S = (it.newton[a] | state_ok) & finite
    S = np.where(has_S[:, None, None], 0.5 * (S + S.transpose(0, 2, 1)), 0.0)
    return _Sweep(a, P, Y, h, G, F, S, has_S, g, obj, dyE, yp, gabs, state_ok, finite)


def _evaluate(model, prep: _Prepared, points: _Points, it: _Iteration, a: np.ndarray, sym: bool,
              bs: BatchSettings) -> _Sweep:
    """One sweep's model terms at the members ``a``: state correction dy_E, y', G, the gradient at
    the Newton-corrected states, J^T Omega J and (Newton phase or converged states) S."""
    n_p, n_y = model.n_p, model.n_y
    P, Y = it.P[a], it.Y[a]
    m, n_u = a.size, points.n_u
    E, h, Ey, Ep, hy, hp = points.terms(Y, P, a)
    zb, wts = prep.zb[a], prep.wts[a]
    with np.errstate(invalid="ignore", over="ignore"):
        finite = (np.isfinite(h).all(axis=(1, 2)) & np.isfinite(E).all(axis=(1, 2))
                  & np.isfinite(Ey).all(axis=(1, 2, 3)) & np.isfinite(Ep).all(axis=(1, 2, 3)))
    if not np.all(finite):           # neutral values where a member is not finite (it stops this sweep)
        fin3, fin4 = finite[:, None, None], finite[:, None, None, None]
        h, E = np.where(fin3, h, 0.0), np.where(fin3, E, 0.0)
        Ey, Ep, hy = np.where(fin4, Ey, np.eye(n_y)), np.where(fin4, Ep, 0.0), np.where(fin4, hy, 0.0)
    lam_h = -wts * (zb - h)                                               # dPhi/dh at the current states
    mu = None
    if n_y:
        Eyf = Ey
        rhs = [-E[..., None], -Ep]
        if sym:                      # E_y symmetric: the adjoint needs no second factorisation
            rhs.append(-np.matmul(lam_h[:, :, None, :], hy).swapaxes(2, 3))
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
        if sym and np.abs(Ey - Ey.swapaxes(2, 3)).max() <= 1e-12 * np.abs(Ey).max():
            mu = X[..., -1]          # (symmetry checked at every point; else the transpose solve below)
        G = hp + np.matmul(hy, yp)
        h_lin = h + np.matmul(hy, dyE[..., None])[..., 0]
        ynorm = 1.0 + np.abs(Y).max(axis=2)
        state_ok = np.all(np.abs(dyE).max(axis=2) <= bs.state_tol * ynorm, axis=1)
    else:
        dyE, yp = np.zeros((m, n_u, 0)), np.zeros((m, n_u, 0, n_p))
        G, h_lin = hp, h
        state_ok = np.ones(m, bool)
    finite &= np.isfinite(G).all(axis=(1, 2, 3)) & np.isfinite(dyE).all(axis=(1, 2))
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
        Hl = points.lag_hessians(Y[b], P[b], lam_h[b], mu_b, a[b])         # order (y, p)
        if n_y:                      # Z^T Hl Z with Z = [y'; I], summed over the inputs
            ypb = yp[b]
            T = np.matmul(Hl[..., :n_y], ypb) + Hl[..., n_y:]                # (b, n_u, n_y + n_p, n_p)
            Sb = (np.matmul(ypb.swapaxes(2, 3), T[..., :n_y, :]) + T[..., n_y:, :]).sum(axis=1)
        else:
            Sb = Hl.sum(axis=1)
        S[b] = 0.5 * (Sb + Sb.transpose(0, 2, 1))
    gabs = np.einsum("mjs,mjsp->mp", np.abs(lam), np.abs(G))
    return _Sweep(a, P, Y, h, G, F, S, has_S, g, obj, dyE, yp, gabs, state_ok, finite)


def _advance(model, prep: _Prepared, it: _Iteration, sw: _Sweep, s_p: np.ndarray, settings: IdentifySettings,
             bs: BatchSettings, sigma_unknown: bool) -> None:
    """Convergence test (that of identification.fit.refinement.refine) and the next step of every member."""
    n_p = model.n_p
    a = sw.a
    unit = 2 * sw.obj / np.maximum(prep.n_data[a] - n_p, 1) if sigma_unknown else np.ones(a.size)
    dN, decN, goodN, LN = _chol_solve(sw.F + sw.S, -sw.g, s_p)
    dG, _, goodG, _ = _chol_solve(sw.F, -sw.g, s_p)
    # the decrement that round-off in the gradient's sum over the data alone produces
    g_err = 16 * np.finfo(float).eps * sw.gabs * s_p
    u = np.linalg.solve(LN, g_err[:, :, None])[:, :, 0]
    round_off = np.einsum("mp,mp->m", u, u)
    dec = np.where(goodN, decN, np.inf)
    bad = ~sw.finite
    exact = sw.state_ok & sw.has_S & ~bad
    with np.errstate(invalid="ignore"):
        increased = exact & ~(sw.obj <= it.fobj[a] * (1 + 1e-14) + 1e-300)
    # refine's test: a step may not increase Phi.  In the quadratic region (previous decrement below
    # decrement_tol) Phi cannot resolve the decrease any more: the step is kept while the decrement
    # falls, else the previous point is the optimum
    quadratic = it.has_final[a] & (it.fdec[a] <= settings.decrement_tol * it.funit[a])
    keep_inc = increased & quadratic & (dec < it.fdec[a])
    # outside the quadratic region an increase halves the step from the last exact point (the
    # backtracking of identify's explicit Newton; at most 30 halvings)
    back = increased & ~quadratic & (it.halvings[a] < 30)
    stop_inc = increased & ~keep_inc & ~back
    update = exact & ~stop_inc & ~back
    b = a[update]
    it.halvings[b] = 0
    it.has_final[b] = True
    it.fp[b], it.fY[b], it.fyp[b], it.fh[b], it.fG[b] = sw.P[update], sw.Y[update], sw.yp[update], sw.h[update], \
        sw.G[update]
    it.fF[b], it.fS[b], it.fobj[b], it.fdec[b], it.funit[b] = sw.F[update], sw.S[update], sw.obj[update], \
        dec[update], unit[update]
    it.fsweeps[b] = it.sweeps[b]
    conv = update & goodN & ((decN <= np.maximum(settings.refine_decrement * unit, round_off))
                             | (np.max(np.abs(dN / s_p), axis=1) < 1e-13))
    it.done[a[conv | (stop_inc & quadratic)]] = True
    step = ~bad & ~stop_inc & ~conv & goodG
    use_N = it.newton[a] & sw.has_S & goodN
    dp = np.where(use_N[:, None], dN, dG)
    big = np.max(np.abs(dp / s_p), axis=1)
    it.newton[a[step & (big < bs.newton_step)]] = True
    # steps are limited relative to max(s_p, |p|): far optima (a wrong model) are reached geometrically
    rel = np.max(np.abs(dp) / np.maximum(s_p, np.abs(sw.P)), axis=1)
    dp = dp * np.where(rel > bs.max_step, bs.max_step / np.where(rel > 0, rel, 1.0), 1.0)[:, None]
    p_new = sw.P + dp
    inside = np.all((p_new > model.lower) & (p_new < model.upper), axis=1)
    for k in np.flatnonzero(back):
        i = a[k]
        d = 0.5 * (sw.P[k] - it.fp[i])
        it.P[i] = it.fp[i] + d
        it.Y[i] = it.fY[i] + it.fyp[i] @ d if model.n_y else it.Y[i]
        it.halvings[i] += 1
    step &= ~back
    for k in np.flatnonzero(~step & ~back | ~inside & step):
        i = a[k]
        if bad[k]:
            it.reason[i] = "the model or its derivatives are not finite (or E_y is singular) at the iterate"
        elif stop_inc[k] and not quadratic[k]:
            it.reason[i] = "a Newton step increased the objective before the optimum was reached"
        elif not (conv[k] or stop_inc[k]) and not goodG[k]:
            it.reason[i] = "J^T Omega J is singular at the iterate"
        elif step[k]:
            it.reason[i] = LEFT_BOUNDS
    step &= inside
    it.active[a[~step & ~back]] = False
    b = a[step]
    it.P[b] = p_new[step]
    if model.n_y:
        it.Y[b] = sw.Y[step] + sw.dyE[step] + np.einsum("mjyp,mp->mjy", sw.yp[step], dp[step])


def _iterate(model, prep: _Prepared, points: _Points, s_p, P0, Y0, settings: IdentifySettings,
             bs: BatchSettings, sigma_unknown: bool, start_solved: bool) -> _Iteration:
    """Sweeps until every member has converged or stopped (see the module docstring).

    ``start_solved``: the start states solve E = 0 at the start values (the first sweep of
    members sharing the start is then evaluated once, :func:`_evaluate_shared`)."""
    R = P0.shape[0]
    it = _Iteration.start(P0, Y0, model.n_S)
    first = bool(start_solved)
    for _ in range(bs.max_sweeps):
        a = np.flatnonzero(it.active)
        if not a.size:
            break
        it.sweeps[a] += 1
        shared = first and a.size > 1 and np.all(it.P[a] == it.P[a[0]]) and np.all(it.Y[a] == it.Y[a[0]])
        first = False
        try:
            sw = _evaluate_shared(model, prep, points, it, a) if shared else None
            if sw is None and points.fused:
                sw = _evaluate_fused(model, prep, points, it, a, bs)
            if sw is None:
                it.dense_sweeps += 1
                sw = _evaluate(model, prep, points, it, a, points.symmetric(), bs)
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
    """Validated (BatchData, p0, w)."""
    if not isinstance(model, Model):
        raise TypeError(f"model: expected a models.Model, got {type(model).__name__}")
    bd = data if isinstance(data, BatchData) else BatchData.of(data)
    return bd, as_start_vector(model, p0), bd.weights(weights)


def _members(model, prep: _Prepared, it: _Iteration, k: np.ndarray, s_p: np.ndarray, settings: IdentifySettings,
             sigma_unknown: bool) -> list:
    """The estimates of converged members (local indices ``k`` with their final points in ``it``):
    Assumption 3, the covariance of eq. 7 and plausibility, each the test identify applies
    (:func:`identification.fit.estimator.check_identifiability`, :mod:`identification.fit.factor`, |p| and
    finite standard errors), batched.  Returns per member a BatchMember or the reason text of a
    failed check (the caller falls back to identify)."""
    n_p = model.n_p
    m = k.size
    G, F, S, p = it.fG[k], it.fF[k], it.fS[k], it.fp[k]
    cw, sig = prep.cw[k], prep.sig[k]
    out = [""] * m
    # Assumption 3 and the covariances (eq. 7) from the QR factor of the column-normalised
    # sqrt(Omega) J, as identify (identification.fit.factor)
    rows = ((np.sqrt(cw) / sig[:, None, :])[..., None] * G).reshape(m, -1, n_p)
    fac = weighted_factor(rows)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(fac.sv[:, 0] > 0, fac.sv[:, -1] / np.where(fac.sv[:, 0] > 0, fac.sv[:, 0], 1.0), 0.0)
    ident = fac.full_rank & (ratio >= settings.rank_rtol)
    binary = bool(np.all((prep.w == 0) | (prep.w == 1)))
    rows2 = None if binary else ((np.sqrt(cw * prep.w[None, None, :]) / sig[:, None, :])[..., None]
                                 * G).reshape(m, -1, n_p)
    cov, cov_gn, _ = covariances(fac, S, rows2)
    H = F + S
    h_rows = it.fh[k][:, prep.group]                                                 # (m, n_q, n_S)
    resid = prep.Z[k] - h_rows[:, None]
    rss = np.nansum(resid[..., prep.selected] ** 2, axis=(1, 2, 3))
    n = prep.n_data[k]
    dof = n - n_p
    if sigma_unknown:
        s2 = rss / dof
        factor = s2 / sig[:, 0] ** 2
    else:
        factor = np.ones(m)
    cov, cov_gn = cov * factor[:, None, None], cov_gn * factor[:, None, None]
    far = ~np.all(np.isfinite(p) & (np.abs(p) <= ABSURD_SCALES * np.maximum(s_p, 1.0)), axis=1)
    d1, d2 = np.einsum("mii->mi", cov), np.einsum("mii->mi", cov_gn)
    bad_se = ~(np.all(np.isfinite(d1) & (d1 >= 0), axis=1) & np.all(np.isfinite(d2) & (d2 >= 0), axis=1))
    for i in range(m):
        if not ident[i]:
            out[i] = "Assumption 3 (rank(Omega J) = n_p) fails at the converged point"
        elif far[i]:
            out[i] = "the estimate ran off to absurd values"
        elif bad_se[i]:
            out[i] = "the standard errors are not finite (H singular)"
        else:
            sig_used = np.full(model.n_S, math.sqrt(rss[i] / dof[i])) if sigma_unknown else sig[i]
            states = it.fY[k[i]][prep.group]
            out[i] = BatchMember(p=p[i], cov=cov[i], cov_gn=cov_gn[i], information=F[i] / factor[i],
                                 S=S[i] / factor[i], H=H[i] / factor[i],
                                 objective=it.fobj[k[i]] / factor[i], rss=float(rss[i]),
                                 n_data=int(n[i]), dof=int(dof[i]), sigma_estimated=sigma_unknown, sigma=sig_used,
                                 states=states, fitted=h_rows[i], decrement=it.fdec[k[i]] / factor[i],
                                 iterations=int(it.fsweeps[k[i]]), state_derivatives=it.fyp[k[i]][prep.group])
    return out


def _symmetric(model, points: _Points, p0: np.ndarray, Y_u: np.ndarray, members=None) -> bool:
    """True when E_y is symmetric at the start (checked at every unique input to 1e-12 relative; with
    per-member inputs at those of ``members``): the adjoint E_y^{-T} h_y^T lambda then shares the
    factorisation of the other solves."""
    if not model.n_y:
        return False
    try:
        Ey = points.terms(Y_u[None], p0[None], members)[2][0]
    except StateSolveError:
        return False
    return bool(np.all(np.abs(Ey - Ey.transpose(0, 2, 1)) <= 1e-12 * np.abs(Ey).max(axis=(1, 2))[:, None, None]))


def fit_batch(model: Model, data: "Sequence[Measurements] | BatchData", p0, weights=None, settings: IdentifySettings | None = None,
              Y0=None, starts=None, start_states=None, batch_settings: BatchSettings | None = None,
              fallback: bool = True) -> BatchFit:
    """Fit R data sets of one model (same sensors and weights) together; see the module docstring.

    Parameters
    ----------
    model : models.Model
    data : sequence of Measurements, or BatchData
        The R data sets: inputs of one shape (n_q, d_q), common or per member (each member is then
        evaluated at its own n_q rows; identical rows are pooled and the first sweep shared only
        when the inputs are common); sigma given for all or unknown for all (missing values may
        differ).
    p0 : array_like (n_p,)
        Start values (inside the bounds), also the start of identify for a fallback member.
    weights : array_like (n_S,), optional
        Sensor weights (default all ones).
    settings : IdentifySettings, optional
        The estimator's settings: the convergence test (``refine_decrement``, ``decrement_tol``),
        the identifiability test (``rank_rtol``) and the settings of the fallback fits.
    Y0 : array (n_q, n_y), or (R, n_q, n_y) with per-member inputs, optional
        States at p0 (else solved), the start of the members without ``starts``.
    starts : array (R, n_p), optional
        Per-member start values (a row of NaN: start at p0), e.g. the precision-weighted mean of
        two fits for a pooled fit.  Requires ``start_states``.
    start_states : array (R, n_q, n_y), optional
        States at (or near) ``starts``.
    batch_settings : BatchSettings, optional
    fallback : bool
        True (default): a member the batch iteration does not give is fitted by identify.  False:
        it is left without an estimate (``ok`` False, the result an IdentificationError with the
        reason, recorded in ``fallbacks`` with error "not refitted (fallback=False)"), for a caller
        with its own solver.

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
    R, n_p, n_y = data.n_members, model.n_p, model.n_y
    q = data.inputs
    n_q = q.shape[-2]
    if Y0 is not None and n_y:
        Y0 = np.asarray(Y0, float)
        want = (n_q, n_y) if data.shared else (R, n_q, n_y)
        if Y0.shape != want:
            raise DataError(f"Y0: expected the states at p0 of shape {want}, got {Y0.shape}")
    sigma_unknown = data.sigma is None
    records, results = [], [None] * R

    def run_fallbacks():
        for r, why in sorted(fallback.items()):
            if not fallback_on:
                records.append(FallbackRecord(int(r), why, "not refitted (fallback=False)"))
                results[r] = IdentificationError(f"member {r}: {why} (not refitted: fallback=False)")
                continue
            try:
                # a member whose iteration left the bounds is solved with them from the start: the
                # unbounded first pass of identify (lazy_bounds) may run to Ipopt's max_iter first
                use = replace(settings, lazy_bounds=False) if why == LEFT_BOUNDS else settings
                Y0_r = Y0 if Y0 is None or data.shared or not n_y else Y0[r]
                est = fit_static(model, data.member(r), p0, weights=weights, settings=use, Y0=Y0_r)
                # an estimate the data do not bound is kept (callers test Estimate.bounded) but is no
                # estimate of p: ok False, its reason recorded
                records.append(FallbackRecord(int(r), why, not_bounded_reason(est)))
                results[r] = est
            except (IdentificationError, DataError) as exc:
                records.append(FallbackRecord(int(r), why, f"{type(exc).__name__}: {exc}"))
                results[r] = exc

    fallback_on = bool(fallback)
    fallback = {}
    usable = (q.shape[-1] == model.n_q_dim and data.z.shape[3] == model.n_S and np.any(w > 0)
              and np.all(p0 >= model.lower) and np.all(p0 <= model.upper) and np.all(np.isfinite(p0))
              and (not n_y or numerics(model).dense))
    Y_ref = None
    if usable:
        try:
            own_all = (not data.shared and starts is not None and start_states is not None
                       and np.all(np.isfinite(np.asarray(starts, float))))
            if Y0 is not None:
                Y_ref = Y0
            elif own_all:            # every member starts from its own states: no solve at p0
                Y_ref = np.asarray(start_states, float).reshape(R, n_q, n_y)
            elif data.shared:
                Y_ref = solve_states(model, p0, q)
            else:                    # all members' rows in one solve
                Y_ref = solve_states(model, p0, q.reshape(-1, q.shape[2])).reshape(R, n_q, -1)
        except StateSolveError:
            usable = False
    if not usable and n_y and trajectory_numerics(model) is not None and fallback_on:
        # a collocated ODE: every member by identify, their trajectory evaluations merged (batch_trajectory)
        results, errors = fit_members(model, [data.member(r) for r in range(R)], p0, weights, settings, starts)
        # a failed fit, or an estimate the data do not bound (kept, ok False), is recorded with its reason
        records = [FallbackRecord(int(r), "the fit failed", e) for r, e in sorted(errors.items())]
        records += [FallbackRecord(r, "not bounded by the data", not_bounded_reason(res)) for r, res in enumerate(results)
                    if r not in errors and not_bounded_reason(res)]
        ok = np.array([r not in errors for r in range(R)])
        return _collect(model, results, records, ok, decrements(results), np.zeros(R, int))
    if not usable:
        why = ("the batch engine handles states of at most 60 variables" if n_y and not numerics(model).dense
               else "the start or the problem is not valid for the batch engine")
        fallback.update({r: why for r in range(R)})
        run_fallbacks()
        return _collect(model, results, records, np.zeros(R, bool), np.full(R, np.nan), np.zeros(R, int))
    n_values = np.isfinite(data.z[..., w > 0]).sum(axis=(1, 2, 3))
    for r in np.flatnonzero((n_values < n_p) | (sigma_unknown & (n_values <= n_p))):
        fallback[int(r)] = "too few values for the parameters"
    prep = _prepare(model, data, w, Y_ref if n_y else np.zeros(q.shape[:-1] + (0,)))
    s_p = param_scale(model, p0)
    if data.shared:
        Q_u = q[prep.first]
        Y_u = Y_ref[prep.first] if n_y else np.zeros((Q_u.shape[0], 0))
        Yst = np.tile(Y_u, (R, 1, 1))
    else:
        Q_u = q
        Y_u = Y_ref if n_y else np.zeros((R, n_q, 0))
        Yst = Y_u.copy()
    P0 = np.tile(p0, (R, 1))
    if starts is not None:
        S0 = np.asarray(starts, float).reshape(R, n_p)
        if start_states is None and n_y:
            raise DataError("start_states: needed with starts (states at the start values, shape (R, n_q, n_y))")
        own = np.all(np.isfinite(S0), axis=1)
        P0[own] = S0[own]
        if n_y:
            YS = np.asarray(start_states, float).reshape(R, n_q, n_y)
            Yst[own] = YS[own][:, prep.first]
    members = np.array([r for r in range(R) if r not in fallback], int)
    it = None
    if members.size:
        prep_m = _Prepared(prep.first, prep.group, prep.zb[members], prep.wts[members], prep.const[members],
                           prep.cw[members], prep.sig[members], prep.n_data[members], prep.selected, prep.w,
                           prep.Z[members])
        if data.shared:
            points = _Points(model, Q_u, members.size, p0, Y_u)
        else:
            # (E_y's symmetry, a shortcut checked again at every sweep, is first tested at one member's start)
            points = _Points(model, Q_u[members], members.size, P0[members[0]], Yst[members[0]])
        it = _iterate(model, prep_m, points, s_p, P0[members], Yst[members], settings, bs,
                      sigma_unknown, starts is None and data.shared)
    converged = np.zeros(R, bool)
    decrement = np.full(R, np.nan)
    sweeps = np.zeros(R, int)
    finals = []
    margin = 1e-6 * s_p
    for k, r in enumerate(members):
        sweeps[r] = it.sweeps[k]
        if not it.done[k]:
            fallback[r] = it.reason[k] or "the batch iteration did not converge"
        elif not (np.all(it.fp[k] > model.lower + margin) and np.all(it.fp[k] < model.upper - margin)):
            fallback[r] = "the optimum lies at or beyond a parameter bound (identify solves the bounded problem)"
        else:
            finals.append(k)
    if finals:
        finals = np.array(finals, int)
        for k, res in zip(finals, _members(model, prep_m, it, finals, s_p, settings, sigma_unknown)):
            r = members[k]
            if isinstance(res, str):
                fallback[r] = f"the converged point failed identify's checks: {res}"
                continue
            results[r] = res
            converged[r] = True
            decrement[r] = res.decrement
    run_fallbacks()
    return _collect(model, results, records, converged, decrement, sweeps, 0 if it is None else it.dense_sweeps)


def _collect(model, results, records, converged, decrement, sweeps, dense_sweeps: int = 0) -> BatchFit:
    R, n_p = len(results), model.n_p
    p = np.full((R, n_p), np.nan)
    cov = np.full((R, n_p, n_p), np.nan)
    cov_gn = np.full((R, n_p, n_p), np.nan)
    info = np.full((R, n_p, n_p), np.nan)
    obj = np.full(R, np.nan)
    rss = np.full(R, np.nan)
    ok = np.zeros(R, bool)
    for r, res in enumerate(results):
        if isinstance(res, Exception) or res is None or not_bounded_reason(res):
            continue
        ok[r] = True
        p[r], cov[r], cov_gn[r], info[r] = res.p, res.cov, res.cov_gn, res.information
        obj[r], rss[r] = res.objective, res.rss
    return BatchFit(p, cov, cov_gn, info, obj, rss, decrement, sweeps, converged, ok,
                    tuple(sorted(records, key=lambda x: x.member)), tuple(results), int(dense_sweeps))
