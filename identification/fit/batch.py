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
trajectory evaluations merged (:func:`fit_members`: no state-size ceiling).

A member that does not converge (or fails a check, or ends on or outside a parameter bound)
is fitted by the full-space Ipopt estimator :func:`identification.identify` instead, and the
fallback is recorded (which member, why, and identify's error when it failed too): a member
is never dropped.
The parts: the inputs, settings and results :mod:`identification.fit.batch_data`, the mapped point
functions, the data terms, sweeps and iteration :mod:`identification.fit.batch_iteration` (the rules
of :mod:`identification.fit.newton`); the checks of a converged member are identify's
(:mod:`identification.fit.checks`).
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Sequence

import numpy as np

from models.contract import Model
from models.state import numerics, solve_states
from models.merged_calls import run_merged
from identification.errors import DataError, IdentificationError, StateSolveError
from identification.fit.assembly import sigma_rescaling
from identification.fit.batch_data import (LEFT_BOUNDS, BatchData, BatchFit, BatchMember, BatchSettings,
                                           FallbackRecord)
from identification.fit.batch_iteration import Iteration, Points, Prepared, iterate, prepare
from identification.fit.checks import CheckFailure, failed_check, rank_ok
from identification.fit.unbounded import not_bounded_reason
from identification.fit.estimator import IdentifySettings, as_start_vector, fit_static, param_scale
from identification.fit.factor import covariances, weighted_factor
from identification.fit.measurements import Measurements

__all__ = ["fit_batch", "BatchData", "BatchFit", "BatchMember", "FallbackRecord", "BatchSettings"]


# ---------------------------------------------------------------------------- the front door
def _check_batch(model: Model, data, p0, weights) -> tuple:
    """Validated (BatchData, p0, w)."""
    if not isinstance(model, Model):
        raise TypeError(f"model: expected a models.Model, got {type(model).__name__}")
    bd = data if isinstance(data, BatchData) else BatchData.of(data)
    return bd, as_start_vector(model, p0), bd.weights(weights)


def _members(model, prep: Prepared, it: Iteration, k: np.ndarray, s_p: np.ndarray, settings: IdentifySettings,
             sigma_unknown: bool) -> list:
    """The estimates of converged members (local indices ``k`` with their final points in ``it``):
    Assumption 3, the covariance of eq. 7 and plausibility, each the test identify applies
    (:mod:`identification.fit.checks`, :mod:`identification.fit.factor`), batched.  Returns per member a
    BatchMember or the :class:`identification.fit.checks.CheckFailure` of a failed check (the caller
    falls back to identify)."""
    n_p = model.n_p
    m = k.size
    G, F, S, p = it.fG[k], it.fF[k], it.fS[k], it.fp[k]
    cw, sig = prep.cw[k], prep.sig[k]
    # Assumption 3 and the covariances (eq. 7) from the QR factor of the column-normalised
    # sqrt(Omega) J, as identify (identification.fit.factor)
    rows = ((np.sqrt(cw) / sig[:, None, :])[..., None] * G).reshape(m, -1, n_p)
    fac = weighted_factor(rows)
    ident = rank_ok(fac.sv, fac.full_rank, settings.rank_rtol)
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
        s2, factor = sigma_rescaling(rss, dof, sig[:, 0])
    else:
        factor = np.ones(m)
    cov, cov_gn = cov * factor[:, None, None], cov_gn * factor[:, None, None]
    out = failed_check(ident, p, s_p, cov, cov_gn)
    for i in range(m):
        if out[i] is None:
            sig_used = np.full(model.n_S, math.sqrt(s2[i])) if sigma_unknown else sig[i]
            states = it.fY[k[i]][prep.group]
            out[i] = BatchMember(p=p[i], cov=cov[i], cov_gn=cov_gn[i], information=F[i] / factor[i],
                                 S=S[i] / factor[i], H=H[i] / factor[i],
                                 objective=it.fobj[k[i]] / factor[i], rss=float(rss[i]),
                                 n_data=int(n[i]), dof=int(dof[i]), sigma_estimated=sigma_unknown, sigma=sig_used,
                                 states=states, fitted=h_rows[i], decrement=it.fdec[k[i]] / factor[i],
                                 iterations=int(it.fsweeps[k[i]]), state_derivatives=it.fyp[k[i]][prep.group])
    return out


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
    data, p0, w = _check_batch(model, data, p0, weights)
    Y0 = _checked_states(model, data, Y0)
    run = _BatchRun(model, data, p0, w, weights, settings, batch_settings or BatchSettings(), bool(fallback), Y0)
    return run.fit(starts, start_states)


def _checked_states(model, data: BatchData, Y0):
    """Y0 as a float array of the states at p0 ((n_q, n_y), or (R, n_q, n_y) with per-member inputs)."""
    n_y = model.n_y
    if Y0 is not None and n_y:
        Y0 = np.asarray(Y0, float)
        n_q = data.inputs.shape[-2]
        want = (n_q, n_y) if data.shared else (data.n_members, n_q, n_y)
        if Y0.shape != want:
            raise DataError(f"Y0: expected the states at p0 of shape {want}, got {Y0.shape}")
    return Y0


class _BatchRun:
    """One call of :func:`fit_batch`: the validated request, the members handed to identify
    (``fallback``: member -> reason), and the per-member results and fallback records."""

    def __init__(self, model, data: BatchData, p0, w, weights, settings: IdentifySettings, bs: BatchSettings,
                 fallback_on: bool, Y0):
        self.model, self.data, self.p0, self.w, self.weights = model, data, p0, w, weights
        self.settings, self.bs, self.fallback_on, self.Y0 = settings, bs, fallback_on, Y0
        self.R = data.n_members
        self.records, self.results = [], [None] * self.R
        self.fallback = {}

    def fit(self, starts, start_states) -> BatchFit:
        """The batch iteration and the fallbacks (see :func:`fit_batch`)."""
        model, data, R = self.model, self.data, self.R
        Y_ref = self._reference_states(starts, start_states)
        if Y_ref is None:
            return self._unusable(starts)
        n_p, n_y = model.n_p, model.n_y
        n_values = np.isfinite(data.z[..., self.w > 0]).sum(axis=(1, 2, 3))
        for r in np.flatnonzero((n_values < n_p) | ((data.sigma is None) & (n_values <= n_p))):
            self.fallback[int(r)] = "too few values for the parameters"
        q = data.inputs
        prep = prepare(model, data, self.w, Y_ref if n_y else np.zeros(q.shape[:-1] + (0,)))
        s_p = param_scale(model, self.p0)
        Q_u, Y_u, Yst, P0 = self._start_points(prep, Y_ref, starts, start_states)
        members = np.array([r for r in range(R) if r not in self.fallback], int)
        it = prep_m = None
        if members.size:
            prep_m = Prepared(prep.first, prep.group, prep.zb[members], prep.wts[members], prep.const[members],
                              prep.cw[members], prep.sig[members], prep.n_data[members], prep.selected, prep.w,
                              prep.Z[members])
            if data.shared:
                points = Points(model, Q_u, members.size, self.p0, Y_u)
            else:
                # (E_y's symmetry, a shortcut checked again at every sweep, is first tested at one member's start)
                points = Points(model, Q_u[members], members.size, P0[members[0]], Yst[members[0]])
            it = iterate(model, prep_m, points, s_p, P0[members], Yst[members], self.settings, self.bs,
                         data.sigma is None, starts is None and data.shared)
        converged, decrement, sweeps = self._finals(prep_m, it, members, s_p)
        self._run_fallbacks()
        return _collect(model, self.results, self.records, converged, decrement, sweeps,
                        0 if it is None else it.dense_sweeps)

    def _reference_states(self, starts, start_states):
        """The states at p0 (or the members' own start states), None when the batch engine cannot be used."""
        model, data, p0, R = self.model, self.data, self.p0, self.R
        q = data.inputs
        n_q, n_y = q.shape[-2], model.n_y
        usable = (q.shape[-1] == model.n_q_dim and data.z.shape[3] == model.n_S and np.any(self.w > 0)
                  and np.all(p0 >= model.lower) and np.all(p0 <= model.upper) and np.all(np.isfinite(p0))
                  and (not n_y or numerics(model).dense))
        if not usable:
            return None
        try:
            own_all = (not data.shared and starts is not None and start_states is not None
                       and np.all(np.isfinite(np.asarray(starts, float))))
            if self.Y0 is not None:
                return self.Y0
            if own_all:              # every member starts from its own states: no solve at p0
                return np.asarray(start_states, float).reshape(R, n_q, n_y)
            if data.shared:
                return solve_states(model, p0, q)
            # all members' rows in one solve
            return solve_states(model, p0, q.reshape(-1, q.shape[2])).reshape(R, n_q, -1)
        except StateSolveError:
            return None

    def _unusable(self, starts) -> BatchFit:
        """Every member by identify (the batch engine cannot be used)."""
        model, R = self.model, self.R
        n_y = model.n_y
        if n_y and model.state_numerics.merges_fits and self.fallback_on:
            # a collocated ODE: every member by identify, their trajectory evaluations merged (fit_members)
            results, errors = fit_members(model, [self.data.member(r) for r in range(R)], self.p0, self.weights,
                                          self.settings, starts)
            # a failed fit, or an estimate the data do not bound (kept, ok False), is recorded with its reason
            records = [FallbackRecord(int(r), "the fit failed", e) for r, e in sorted(errors.items())]
            records += [FallbackRecord(r, "not bounded by the data", not_bounded_reason(res))
                        for r, res in enumerate(results) if r not in errors and not_bounded_reason(res)]
            ok = np.array([r not in errors for r in range(R)])
            return _collect(model, results, records, ok, decrements(results), np.zeros(R, int))
        why = ("the batch engine handles states of at most 60 variables" if n_y and not numerics(model).dense
               else "the start or the problem is not valid for the batch engine")
        self.fallback.update({r: why for r in range(R)})
        self._run_fallbacks()
        return _collect(model, self.results, self.records, np.zeros(R, bool), np.full(R, np.nan), np.zeros(R, int))

    def _start_points(self, prep: Prepared, Y_ref, starts, start_states) -> tuple:
        """(Q_u, Y_u, Yst, P0): the unique inputs and the states there at p0, and every member's start
        states and start values (``starts`` where finite)."""
        model, data, R = self.model, self.data, self.R
        q = data.inputs
        n_q, n_p, n_y = q.shape[-2], model.n_p, model.n_y
        if data.shared:
            Q_u = q[prep.first]
            Y_u = Y_ref[prep.first] if n_y else np.zeros((Q_u.shape[0], 0))
            Yst = np.tile(Y_u, (R, 1, 1))
        else:
            Q_u = q
            Y_u = Y_ref if n_y else np.zeros((R, n_q, 0))
            Yst = Y_u.copy()
        P0 = np.tile(self.p0, (R, 1))
        if starts is not None:
            S0 = np.asarray(starts, float).reshape(R, n_p)
            if start_states is None and n_y:
                raise DataError("start_states: needed with starts (states at the start values, shape (R, n_q, n_y))")
            own = np.all(np.isfinite(S0), axis=1)
            P0[own] = S0[own]
            if n_y:
                YS = np.asarray(start_states, float).reshape(R, n_q, n_y)
                Yst[own] = YS[own][:, prep.first]
        return Q_u, Y_u, Yst, P0

    def _finals(self, prep_m, it, members, s_p) -> tuple:
        """(converged, decrement, sweeps) of every member; the estimates of the members that converged
        inside the bounds and pass identify's checks go to ``results``, the others to ``fallback``."""
        model, R = self.model, self.R
        converged = np.zeros(R, bool)
        decrement = np.full(R, np.nan)
        sweeps = np.zeros(R, int)
        finals = []
        margin = 1e-6 * s_p
        for k, r in enumerate(members):
            sweeps[r] = it.sweeps[k]
            if not it.done[k]:
                self.fallback[r] = it.reason[k] or "the batch iteration did not converge"
            elif not (np.all(it.fp[k] > model.lower + margin) and np.all(it.fp[k] < model.upper - margin)):
                self.fallback[r] = ("the optimum lies at or beyond a parameter bound (identify solves the bounded "
                                    "problem)")
            else:
                finals.append(k)
        if finals:
            finals = np.array(finals, int)
            for k, res in zip(finals, _members(model, prep_m, it, finals, s_p, self.settings,
                                                self.data.sigma is None)):
                r = members[k]
                if isinstance(res, CheckFailure):
                    self.fallback[r] = f"the converged point failed identify's checks: {res.reason}"
                    continue
                self.results[r] = res
                converged[r] = True
                decrement[r] = res.decrement
        return converged, decrement, sweeps

    def _run_fallbacks(self) -> None:
        """Fit the members in ``fallback`` by identify (or, without fallbacks, record them as not refitted)."""
        model, data, settings, Y0, n_y = self.model, self.data, self.settings, self.Y0, self.model.n_y
        for r, why in sorted(self.fallback.items()):
            if not self.fallback_on:
                self.records.append(FallbackRecord(int(r), why, "not refitted (fallback=False)"))
                self.results[r] = IdentificationError(f"member {r}: {why} (not refitted: fallback=False)")
                continue
            try:
                # a member whose iteration left the bounds is solved with them from the start: the
                # unbounded first pass of identify (lazy_bounds) may run to Ipopt's max_iter first
                use = replace(settings, lazy_bounds=False) if why == LEFT_BOUNDS else settings
                Y0_r = Y0 if Y0 is None or data.shared or not n_y else Y0[r]
                est = fit_static(model, data.member(r), self.p0, weights=self.weights, settings=use, Y0=Y0_r)
                # an estimate the data do not bound is kept (callers test Estimate.bounded) but is no
                # estimate of p: ok False, its reason recorded
                self.records.append(FallbackRecord(int(r), why, not_bounded_reason(est)))
                self.results[r] = est
            except (IdentificationError, DataError) as exc:
                self.records.append(FallbackRecord(int(r), why, f"{type(exc).__name__}: {exc}"))
                self.results[r] = exc


# ---------------------------------------------------------------------------- merged fits of a collocated ODE
# Batched fits of a collocated ODE model (no state-size ceiling): every member by identify, merged.
#
# The batch engine (above) advances members of models with small dense states
# by its own full-space Newton sweeps.  A collocated dynamic model (:mod:`models.collocation`) has
# hundreds of states per experiment, but its state Jacobian is block lower-triangular in the
# elements: :mod:`models.trajectory` solves the trajectories and their exact first and second
# derivatives element by element for all experiments at once.  Here every member is fitted by
# :func:`identification.identify` itself (reduced-space Newton on the trajectories, its checks,
# refinement and covariance) in its own thread, and the members' trajectory evaluations are merged
# (:func:`models.merged_calls.run_merged`): each step evaluates all members' experiments, each at its
# own member's p, in one set of mapped CasADi calls and batched LAPACK solves.  The estimates are
# identify's (the same computations, to round-off).


def fit_members(model, members, p0, weights, settings, starts=None) -> tuple:
    """identify(model, members[r], p0_r, weights, settings) for every member, merged (see the section's comment); p0_r is row r of ``starts`` where it is finite (e.g. the pooled start of a split
    test), else p0.  Returns (results, errors): each member's Estimate or the IdentificationError /
    DataError identify raised (any other exception is raised here, as identify would)."""
    p0 = np.asarray(p0, float)
    starts = None if starts is None else np.asarray(starts, float).reshape(len(members), -1)
    first = [s if starts is not None and np.all(np.isfinite(s)) else p0
             for s in (starts if starts is not None else [None] * len(members))]
    tasks = [lambda d=d, s=s: fit_static(model, d, s, weights=weights, settings=settings) for d, s in zip(members, first)]
    results = run_merged(tasks)
    errors = {}
    for r, res in enumerate(results):
        if isinstance(res, (IdentificationError, DataError)):
            errors[r] = f"{type(res).__name__}: {res}"
        elif isinstance(res, Exception):
            raise res
    return results, errors


def decrements(results) -> np.ndarray:
    """The Newton decrement of every member's estimate (NaN for a failed fit)."""
    return np.array([np.nan if isinstance(r, Exception) else r.diagnostics.newton_decrement
                     for r in results])


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
