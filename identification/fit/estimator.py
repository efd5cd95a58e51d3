"""The full-space weighted least-squares estimator (paper eq. 3) and its covariance (eq. 7).

    min_{p, y_1..y_nq}  sum_k sum_j sum_i  (w_k / 2) ((z_ijk - h_k(y_j, p, q_j)) / sigma_k)^2
    s.t.                E(y_j, p, q_j) = 0,   j = 1..n_q,      lower <= p <= upper

States and parameters are optimisation variables; Ipopt (through CasADi) solves the
NLP with exact first and second derivatives.  Sums over series are folded into
per-(input, sensor) means, so the NLP size does not grow with n_M.  The result is
refined by at most a few exact reduced-space Newton steps (the same derivatives as
the covariance, accepted only if they decrease the objective) and the second-order
covariance

    C = H^{-1} J^T Omega^2 J H^{-T},    H = J^T Omega J + S(Omega)

is evaluated exactly by AD and the implicit function theorem.

For implicit models with many inputs Ipopt is started at the reduced-space optimum
(:mod:`identification.fit.implicit_start`) with its multipliers, so that it verifies that point
(at iteration 0, or after one step at round-off) instead of iterating on the n_q n_y states.

The steps live in their own modules: validation, start and scalings :mod:`identification.fit.start`,
the NLP :mod:`identification.fit.nlp`, the reduced-space Newton of explicit models and the reduced
start :mod:`identification.fit.explicit_newton` (rules of :mod:`identification.fit.newton`), the
checks :mod:`identification.fit.checks` and the result :mod:`identification.fit.assembly`; this
module runs the pipeline (:func:`fit_static`) and gives the information contributions.
"""
from __future__ import annotations

import dataclasses
import functools
import time

import numpy as np

from models.contract import Model
from identification.fit import unbounded
from identification.fit import secondorder
from identification.errors import DataError, IdentifiabilityError, IdentificationError, StateSolveError
from identification.fit.assembly import FullSpaceSolution, PhaseClock, assemble_estimate
from identification.fit.checks import check_identifiability, covariance_from_terms
from identification.fit.data_start import data_trajectories
from identification.fit.explicit_newton import reduced_start, solve_explicit_newton
from identification.fit.implicit_start import nlp_multipliers
from identification.fit.ipopt_solver import solve_nlp, warm_start
from identification.fit.measurements import Measurements
from identification.fit.nlp import build_nlp
from identification.fit.refinement import ReducedProblem, Refinement, refine
from identification.fit.record import FitRecord
from identification.fit.settings import IdentifySettings
from identification.fit.start import (Start, as_start_vector, decrement_unit, make_start, param_scale, predictor,
                                      scalings)
from models.sensitivity import sensitivities
from models.state import solve_states

__all__ = ["fit_static", "static_information", "IdentifySettings", "check_identifiability",
           "covariance_from_terms", "param_scale", "as_start_vector", "LAZY_PASS_MAX_ITER", "DATA_LAZY_PASS_MAX_ITER"]

#: Ipopt iterations of identify's unbounded first pass (lazy_bounds); the press needs 3-4
LAZY_PASS_MAX_ITER = 100
#: the same from start trajectories through the data (IdentifySettings.init): the published ODE benchmarks
#: need 4-6 when the unbounded optimum is the bounded one; otherwise the rates wander below their bounds
#: (methanol: 100 iterations lost before the bounded pass's 10)
DATA_LAZY_PASS_MAX_ITER = 25


def _ipopt_start(st: Start, settings: IdentifySettings, warm) -> tuple:
    """(st with the NLP's scalings, the NLP's start trajectories Y_nlp, Ipopt's scaled start x0, the solver
    cache key) of :func:`_solve_full_space`: from the reduced-space optimum ``warm`` when there is one, else
    from the predictor, with the trajectories through the data (``settings.init``) where the model allows."""
    model, data, s_p, s_y = st.model, st.data, st.s_p, st.s_y
    zbar, cw = st.problem.zbar, st.problem.cw
    Y_nlp = st.Y_init                           # the NLP's start trajectories: through the data (settings.init)
    if settings.init == "data" and model.state_numerics.reduced_space and st.Y_init is not None:
        Y_data = data_trajectories(model, data, st.p0, st.Y_init)
        Y_nlp = st.Y_init if Y_data is None else Y_data
    if s_y is None:                             # scalings left for the NLP (see make_start)
        # cached per (p0, inputs) when Y_init are the start states initial_states keeps (data-independent)
        cached = model.cache.get("identify.initial_states", (st.p0.tobytes(), data.inputs.tobytes()))
        s_y, e_scale = scalings(model, st.p0, data.inputs, st.Y_init, cached is st.Y_init)
        st = dataclasses.replace(st, s_y=s_y, e_scale=e_scale)
    key = (data.inputs.tobytes(), s_p.tobytes(), s_y.tobytes(), st.e_scale.tobytes())
    if warm is not None:
        p_start, Y_start = warm[0].p, warm[0].states
    else:
        p_start, Y_start = predictor(model, st.p0, data.inputs, st.Y_init, zbar, cw, st.sig, s_p,
                                      settings.predictor_step)
        if Y_nlp is not st.Y_init:
            Y_start = Y_nlp
    x0 = np.concatenate([p_start / s_p, (Y_start / s_y[None, :]).ravel()])   # vec(yt) is column-major: y_j stacked
    return st, Y_nlp, x0, key


def _solve_full_space(st: Start, settings: IdentifySettings, clock: PhaseClock | None = None) -> FullSpaceSolution:
    """Step 2 of :func:`identify`: build (or reuse) the scaled NLP and solve it with Ipopt.

    An explicit model is first solved by exact reduced-space Newton steps
    (:func:`identification.fit.explicit_newton.solve_explicit_newton`, with ``explicit_newton``); that solution is kept when it lies
    strictly inside the bounds (no NLP is built), else the bounded problem is solved by Ipopt
    (pass 2), and Ipopt solves it as below when the Newton iteration fails.
    With ``lazy_bounds``, pass 1 solves without the parameter bounds: a pure equality-
    constrained problem, which Ipopt solves by Newton steps without a barrier (3-4 instead of
    6-8 iterations for the press).  Its solution is kept only when it lies strictly inside the
    bounds: it is then a KKT point of the bounded problem too (zero bound multipliers).
    Otherwise, and on any failure, pass 2 solves the bounded problem from the same start.

    An implicit model with small (dense) states and at least ``reduced_start_inputs`` inputs
    starts Ipopt at the reduced-space optimum (:func:`identification.fit.explicit_newton.reduced_start`) with the multipliers that
    make it a primal-dual solution (warm start, no barrier: pass 1 without bounds), so Ipopt
    verifies it at iteration 0 or after one step at round-off; the estimate is then that point
    (and its S), else Ipopt's solution as usual.  When the reduced iteration fails, Ipopt starts
    from the predictor as before.
    """
    model, data, s_p, s_y = st.model, st.data, st.s_p, st.s_y
    newton_passes = None
    if not model.n_y and settings.explicit_newton:
        got = solve_explicit_newton(st, settings)
        if got is not None:
            r0, point, S = got
            margin = 1e-6 * s_p
            lo, up = model.lower, model.upper
            if np.all(point.p > lo + margin) and np.all(point.p < up - margin):
                if clock is not None:
                    clock.lap("reduced-space Newton (explicit model)")
                return FullSpaceSolution(r0, 1, point.p, None, np.zeros(model.n_p, bool), point, S)
            newton_passes = 2                   # outside the bounds: solve the bounded problem
    zbar, cw = st.problem.zbar, st.problem.cw
    par_value = np.concatenate([zbar.ravel(), (cw / st.sig[None, :] ** 2).ravel()])  # column-major of (n_S, n_q)
    bounded = np.any(np.isfinite(model.lower)) or np.any(np.isfinite(model.upper))
    warm = None                                 # (reduced point, S) of the reduced-space optimum
    if newton_passes is None and (settings.lazy_bounds or not bounded):
        got = reduced_start(st, settings)
        if got is not None and np.all(got[1].p > model.lower + 1e-6 * s_p) and \
                np.all(got[1].p < model.upper - 1e-6 * s_p):
            warm = got[1], got[2]
            if model.state_numerics.reduced_space:
                # a collocated ODE: the reduced optimum (states solved to round-off element by element,
                # decrement at round-off) is the estimate, as for explicit models; no NLP is built
                if clock is not None:
                    clock.lap("reduced-space Newton (collocated trajectories)")
                return FullSpaceSolution(got[0], 1, got[1].p, got[1].states, np.zeros(model.n_p, bool), got[1],
                                          got[2])
    st, Y_nlp, x0, key = _ipopt_start(st, settings, warm)
    s_y = st.s_y
    if clock is not None:
        clock.lap("start point of Ipopt")
    free_y = np.full(data.n_q * model.n_y, np.inf)

    def solve(x_start, lbx, ubx, lam_g0=None, ipopt=settings.ipopt):
        return solve_nlp(functools.partial(build_nlp, model, data.inputs, s_p, s_y, st.e_scale), x_start, lbx, ubx,
                         0.0, 0.0, par_value, ipopt if lam_g0 is None else warm_start(ipopt),
                         what=f"identification of {model.name}", key=key, cache=model.cache, lam_g0=lam_g0)

    res = None
    passes = 1 if newton_passes is None else newton_passes
    if passes == 1 and ((settings.lazy_bounds and bounded) or warm is not None):
        free_p = np.full(model.n_p, np.inf)
        try:
            # a capped pass: when the unbounded optimum lies at infinity Ipopt would otherwise
            # run to max_iter (seconds) before pass 2 solves the bounded problem
            r1 = solve(x0, np.concatenate([-free_p, -free_y]), np.concatenate([free_p, free_y]),
                       None if warm is None else nlp_multipliers(warm[0], st.e_scale),
                       dataclasses.replace(settings.ipopt, max_iter=min(settings.ipopt.max_iter, LAZY_PASS_MAX_ITER
                                                                        if Y_nlp is st.Y_init else DATA_LAZY_PASS_MAX_ITER)))
        except IdentificationError:
            r1 = None
        if r1 is not None and r1.accepted:
            p1 = r1.x[:model.n_p] * s_p
            margin = 1e-6 * s_p
            if np.all(p1 > model.lower + margin) and np.all(p1 < model.upper - margin):
                res = r1
        passes = 1 if res is not None else 2
    if res is None:
        res = solve(x0 if passes == 1 else np.concatenate([st.p0 / s_p, (Y_nlp / s_y[None, :]).ravel()]),
                    np.concatenate([model.lower / s_p, -free_y]), np.concatenate([model.upper / s_p, free_y]))
    if clock is not None:
        clock.lap("NLP build, Ipopt set-up and solve")
    p = np.clip(res.x[:model.n_p] * s_p, model.lower, model.upper)  # Ipopt relaxes bounds by ~1e-8
    Y = res.x[model.n_p:].reshape(data.n_q, model.n_y) * s_y[None, :] if model.n_y else None
    at_bound = (np.abs(p - model.lower) <= 1e-7 * s_p) | (np.abs(p - model.upper) <= 1e-7 * s_p)
    if warm is not None and passes == 1 and np.max(np.abs(res.x[:model.n_p] - x0[:model.n_p])) <= 1e-12:
        # Ipopt verified the reduced-space optimum without a step or with a step at round-off (the
        # gradient of a fit to many inputs stays above Ipopt's tolerance at one ulp of p): its point
        # and S are the estimate's
        return FullSpaceSolution(res, passes, warm[0].p, warm[0].states, at_bound, warm[0], warm[1])
    return FullSpaceSolution(res, passes, p, Y, at_bound)



def _refine_solution(st: Start, sol: FullSpaceSolution, settings: IdentifySettings) -> Refinement:
    """Step 3 of :func:`identify`: states consistent with Ipopt's p, then at most
    ``refine_steps`` exact reduced Newton steps (none when a parameter is at a bound), and
    the Newton decrement g^T H^-1 g, the squared distance to the optimum in standard errors.

    Raises IdentificationError when the states cannot be solved at p, or when Ipopt stalled
    and the refinement did not reach the optimum (decrement above ``decrement_tol``).
    """
    res = sol.result
    try:
        point = sol.point if sol.point is not None else st.problem.evaluate(sol.p, sol.states)
    except StateSolveError as exc:
        raise IdentificationError(f"the state equation cannot be solved at the estimate: {exc}",
                                  status=res.status) from None
    ref = refine(st.problem, point, settings.refine_steps if not np.any(sol.at_bound) else 0,
                 stop_decrement=settings.refine_decrement, start_S=sol.S,
                 dof=st.n - st.model.n_p if st.data.sigma is None else None,
                 quadratic_decrement=settings.decrement_tol)
    unit = decrement_unit(st, ref.point.objective)
    if res.accepted is None and not (ref.decrement <= settings.decrement_tol * unit):
        raise IdentificationError(
            f"Ipopt stalled on the identification of {st.model.name} ({res.status}) and the exact Newton "
            f"refinement did not reach the optimum (Newton decrement {ref.decrement / unit:.2e} > "
            f"{settings.decrement_tol:.0e}; refinement stopped: {ref.stop_reason}); try other start values",
            status=res.status)
    return ref


def _second_order(st: Start, sol: FullSpaceSolution, ref: Refinement, settings: IdentifySettings,
                  clock: PhaseClock | None = None) -> tuple:
    """Second-order optimality before success (:func:`identification.fit.secondorder.ensure_minimum`):
    from a point found below a saddle along its negative curvature the problem is solved again
    (:func:`_solve_full_space`, :func:`_refine_solution`).  Returns (st, sol, ref, escaped);
    raises ConvergenceError when no descent is found."""
    state = {"st": st, "sol": sol}

    def resolve(new):
        s = dataclasses.replace(state["st"], p0=new.p, Y_init=new.states if st.model.n_y else st.Y_init)
        state["st"], state["sol"] = s, _solve_full_space(s, settings, clock)
        return ~state["sol"].at_bound, _refine_solution(s, state["sol"], settings)

    ref, escaped = secondorder.ensure_minimum(st.problem, ref, ~sol.at_bound, resolve, st.selected,
                                             settings.rank_rtol)
    return state["st"], state["sol"], ref, escaped



def fit_static(model: Model, data: Measurements, p0, weights=None,
               settings: IdentifySettings | None = None, Y0=None) -> FitRecord:
    """Weighted nonlinear least squares in full space (paper eq. 3), with covariance (eq. 7).

    The pipeline: validate and start (:func:`identification.fit.start.make_start`), solve the scaled full-space NLP with
    Ipopt (:func:`_solve_full_space`), refine by exact reduced Newton steps
    (:func:`identification.fit.refinement.refine`), then identifiability, covariance and the
    result (:func:`identification.fit.assembly.assemble_estimate`).

    Parameters
    ----------
    model : models.Model
        A static model; a dynamic one (:meth:`models.Model.ode`) goes through
        :meth:`identification.fit.problem.Problem.fit` (collocation with error control).
    data : Measurements
        z (n_M, n_q, n_S); sigma per sensor, or None for a common unknown sigma.
    p0 : array_like (n_p,)
        Start values (inside the bounds).  States start from the solution of E(y, p0, q_j) = 0.
    weights : array_like (n_S,), optional
        Sensor weights omega (0/1 selects sensors; default all ones).
    settings : IdentifySettings, optional
    Y0 : array (n_q, n_y), optional
        Initial guess of the states (else solved from the model's own guess).

    Returns
    -------
    FitRecord
        The plain record; :func:`identification.identify` returns it as an :class:`identification.Estimate`
        (intervals, regions, summary).

    Raises
    ------
    DataError, TypeError
        Bad input (the message names the argument).
    IdentificationError
        Ipopt failed (carries Ipopt's status), or the state equation could not be solved.
    IdentifiabilityError
        rank(Omega J) < n_p at a finite estimate (structural; names the parameters and sensors).
        When the data do not bound the parameters (the best fit runs off to infinity along a
        direction, :mod:`identification.fit.unbounded`) the result is returned instead, with
        ``Estimate.bounded`` False and the direction in ``Estimate.unbounded``.
    ConvergenceError
        The solver stopped at a stationary point that is not a minimum (the reduced Hessian
        J^T Omega J + S is not positive definite) and no lower point was found along its negative
        curvature (names the point and the eigenvalue); from such a point with descent the problem
        is solved again (:mod:`identification.fit.secondorder`; ``diagnostics.saddle_escapes`` and a note).
    """
    settings = settings or IdentifySettings()
    t_start = time.perf_counter()
    clock = PhaseClock()
    st = make_start(model, data, p0, weights, Y0)
    clock.lap("validation, data, states at p0")
    sol = ref = None
    try:
        sol = _solve_full_space(st, settings, clock)
        ref = _refine_solution(st, sol, settings)
        st, sol, ref, escaped = _second_order(st, sol, ref, settings, clock)
        clock.lap("refinement (states, sensitivities, S at the estimate)")
        est = assemble_estimate(st, sol, ref, settings, t_start, clock, escaped)
    except (IdentificationError, np.linalg.LinAlgError) as exc:
        # did the fit run off to infinity (the data do not bound p: a result) or is the rank
        # deficiency structural (a finite point: the error, saying so)?  identification.fit.unbounded
        # follows the valley from where the fit stopped (from p0 when the solver failed on its way)
        if ref is not None:
            p_stop, y_stop = ref.point.p, ref.point.states
        elif sol is not None:
            p_stop, y_stop = sol.p, sol.states
        else:
            p_stop, y_stop = st.p0, (st.Y_init if model.n_y else None)
        diag = unbounded.diagnose(st.problem, p_stop, y_stop)
        if diag.kind == "unbounded":
            return unbounded.estimate_not_bounded(st, diag, f"{type(exc).__name__}: {exc}", t_start)
        if isinstance(exc, IdentifiabilityError):
            raise unbounded.identifiability_error(exc, diag, p_stop, model.param_names) from None
        raise
    sloppy = est.sloppy_direction
    if sloppy is not None and not np.any(sol.at_bound) and sloppy.ratio ** 2 > settings.ill_conditioned:
        # an ill-conditioned "optimum" may be a point far out on a run-off where the steps became too small
        diag = unbounded.diagnose(st.problem, est.p, est.states)
        if diag.kind == "unbounded":
            return unbounded.estimate_not_bounded(
                st, diag, f"{est.status} at {', '.join(f'{n} = {v:.4g}' for n, v in zip(est.param_names, est.p))} "
                "(ill-conditioned; the objective still decreased beyond it)", t_start)
    return est


def static_information(model: Model, data: Measurements | None, p, states=None, *, inputs=None,
                       sigma=None, n_series=1):
    """Per-sensor Gauss-Newton information and second-order terms at p.

    F_k = sum_j c_jk G_jk^T G_jk / sigma_k^2,
    S_k = sum_j d^2/dp^2 [ -c_jk (zbar_jk - h_k(y_j(p), p, q_j)) / sigma_k^2 ]

    so that for sensor weights w:  J^T Omega J = sum_k w_k F_k,  S(Omega) = sum_k w_k S_k and
    J^T Omega^2 J = sum_k w_k^2 F_k.

    Without data (``data=None``; ``inputs``, ``sigma`` and ``n_series`` given) the design is
    planned before measuring: c_jk = n_series and the expected residual zbar - h is 0 at the
    nominal p, so S_k = 0 and the second-order covariance equals the Gauss-Newton one.

    A dynamic model goes through :meth:`identification.fit.problem.Problem.information`.

    Returns
    -------
    F, S : ndarray (n_S, n_p, n_p)
    """
    p = np.asarray(p, float).ravel()
    if p.shape != (model.n_p,):
        raise DataError(f"p: expected {model.n_p} values, got {p.size}")
    if data is None:
        return _planned_information(model, p, inputs, sigma, n_series, states)
    if inputs is not None or sigma is not None:
        raise DataError("inputs/sigma: give them only when data is None (the data carry their own)")
    if data.sigma is None:
        raise DataError("data.sigma: information contributions need known sensor sigmas")
    sig = np.asarray(data.sigma, float)
    w = np.ones(model.n_S)
    Y = solve_states(model, p, data.inputs, Y0=states)
    sens = sensitivities(model, p, data.inputs, Y)
    terms = ReducedProblem.of(model, data, w, sig, np.ones(model.n_p))
    zbar, cw = terms.zbar, terms.cw
    F = np.einsum("jk,jkp,jkr->kpr", cw / sig ** 2, sens.G, sens.G)
    lam = -cw * (zbar - sens.h) / sig ** 2
    lam_k = np.zeros((model.n_S, data.n_q, model.n_S))
    for k in range(model.n_S):
        lam_k[k, :, k] = lam[:, k]
    S = sens.hessians(lam_k)
    return F, S


def _planned_information(model: Model, p, inputs, sigma, n_series, states):
    """F_k = n_series sum_j G_jk^T G_jk / sigma_k^2 and S_k = 0 (no data: expected residual 0)."""
    if inputs is None or sigma is None:
        raise DataError("data: None needs inputs= (candidate input rows) and sigma= (one per sensor)")
    q = np.asarray(inputs, float)
    q = q[:, None] if q.ndim == 1 else q
    if q.ndim != 2 or q.shape[0] == 0 or not np.all(np.isfinite(q)):
        raise DataError(f"inputs: expected a finite array (n_q, d_q) with n_q >= 1, got shape {q.shape}")
    sig = np.broadcast_to(np.asarray(sigma, float), (model.n_S,))
    if not np.all(np.isfinite(sig) & (sig > 0)):
        raise DataError(f"sigma: expected {model.n_S} positive finite values, got {np.asarray(sigma)!r}")
    if isinstance(n_series, bool) or not isinstance(n_series, (int, np.integer)) or n_series < 1:
        raise DataError(f"n_series: expected an integer >= 1, got {n_series!r}")
    Y = solve_states(model, p, q, Y0=states)
    G = sensitivities(model, p, q, Y).G
    F = float(n_series) * np.einsum("k,jkp,jkr->kpr", 1.0 / sig ** 2, G, G)
    return F, np.zeros_like(F)
