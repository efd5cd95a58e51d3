"""Exact reduced-space Gauss-Newton/Newton iteration of the estimator: explicit models
(:func:`solve_explicit_newton`, no NLP) and the reduced-space start of implicit models with many
inputs (:func:`reduced_start`)."""
from __future__ import annotations

import dataclasses
import functools
import math
import time

import numpy as np

from models.errors import StateSolveError
from models.state import numerics
from models.merged_calls import merging
from identification.fit import dense
from identification.fit import newton as newton_core
from identification.fit.explicit_kernel import ExplicitTerms, explicit_terms
from identification.fit.implicit_start import ImplicitObjective
from identification.fit.ipopt_solver import IpoptResult
from identification.fit.refinement import ReducedPoint
from identification.fit.settings import IdentifySettings
from identification.fit.start import Start

__all__ = ["solve_explicit_newton", "reduced_start"]


#: at most this many Gauss-Newton/Newton iterations and objective evaluations of
#: :func:`solve_explicit_newton` (then Ipopt takes over: a far start should not cost twice)
_NEWTON_MAX_ITER = 60
_NEWTON_MAX_EVALS = 50
#: a Gauss-Newton step halved more often than this ends the line-searched iteration (the
#: Gauss-Newton model is poor there: :func:`_levenberg_marquardt` takes over)
_GN_MAX_HALVINGS = 5


class _ExplicitObjective:
    """Phi(s_p ⊙ x) of an explicit model with the sums of its derivatives w.r.t. the scaled
    parameters x (an :class:`identification.fit.explicit_kernel.ExplicitTerms` with Phi_0 included
    in ``f``): one evaluation of the least-squares kernel for models stated in SX, else the
    reduced point of :class:`ReducedProblem` and NumPy sums (models stated in MX)."""

    def __init__(self, st: Start):
        problem = st.problem
        self._problem, self._sp = problem, st.s_p
        self._outer = np.outer(st.s_p, st.s_p)
        self._kernel = explicit_terms(st.model, st.data.inputs, problem.zbar, problem.cw / st.sig[None, :] ** 2,
                                      st.s_p)

    def point(self, x: np.ndarray) -> ReducedPoint:
        """The reduced point at p = s_p ⊙ x."""
        return self._problem.evaluate(x * self._sp)

    def __call__(self, x: np.ndarray, second_order: bool) -> ExplicitTerms:
        """The terms at p = s_p ⊙ x (``S`` when ``second_order``); raises StateSolveError when
        the evaluation fails."""
        problem = self._problem
        if self._kernel is not None:
            t = self._kernel(x, second_order)
            return t._replace(f=t.f + problem.const)
        sp = self._sp
        point = problem.evaluate(x * sp)
        G = point.sens.G.reshape(-1, sp.size)
        S = point.sens.hessians(point.lam[None])[0] * self._outer if second_order else None
        return ExplicitTerms(point.objective, point.gradient * sp, problem.information(point) * self._outer,
                             (np.abs(point.lam).reshape(-1) @ np.abs(G)) * sp, S)


#: at most this many evaluations of :func:`_levenberg_marquardt`
_LM_MAX_EVALS = 200
#: a collocated ODE (:func:`reduced_start`): at most this many Levenberg-Marquardt evaluations, and no more than
#: this many trial points in a row without trajectories (each costs a failed march); then Ipopt's turn
_LM_TRAJECTORY_MAX_EVALS = 40
_LM_TRAJECTORY_MAX_FAILS = 3


def _levenberg_marquardt(st: Start, objective: "_ExplicitObjective", max_evals: int = _LM_MAX_EVALS,
                         max_fails: int | None = None):
    r"""Levenberg-Marquardt iterations on the exact Gauss-Newton model, for starts where the
    line-searched Gauss-Newton/Newton iteration of :func:`solve_explicit_newton` fails.

    In the scaled parameters x: d = -(F + mu diag(F))^{-1} g (F = J^T Omega J, g the gradient,
    both exact by AD), accepted when the objective decreases by at least 1e-4 of the decrease
    the Gauss-Newton model predicts; mu is updated by Nielsen's rule (mu <- mu max(1/3,
    1 - (2 rho - 1)^3) on success, mu <- nu mu and nu <- 2 nu on failure; start mu = 1e-3
    max diag F).  Stops once an undamped-size step (mu < 1e-6) is accepted with the Gauss-Newton
    decrement g^T F^{-1} g below 1e-2 of the objective, or when the objective stalls (relative
    decrease below 1e-10); at most ``max_evals`` evaluations and, when ``max_fails`` is given, at most that
    many trial points in a row where the objective cannot be evaluated (StateSolveError).  Returns the point
    reached (the Newton iteration then finishes from it), or None.
    """
    x = st.p0 / st.s_p
    try:
        cur = objective(x, False)
    except StateSolveError:
        return None
    if not math.isfinite(cur.f):
        return None
    D = np.diag(cur.F).copy()
    mu, nu = 1e-3 * float(D.max()), 2.0
    if not (math.isfinite(mu) and mu > 0):
        return None
    fails = 0
    for _ in range(max_evals):
        D = np.maximum(D, np.diag(cur.F))               # Marquardt's scaling, never shrinking
        L = newton_core.factor(cur.F + mu * np.diag(D))
        if L is None:
            mu, nu = mu * nu, 2 * nu
            if not math.isfinite(mu):
                return None
            continue
        d = newton_core.direction(L, newton_core.decrement(L, cur.g)[0])     # the damped Gauss-Newton step
        pred = -(cur.g @ d + 0.5 * d @ (cur.F @ d))     # decrease predicted by the Gauss-Newton model
        try:
            new = objective(x + d, False)
            fails = 0
        except StateSolveError:
            new, fails = None, fails + 1
            if max_fails is not None and fails > max_fails:
                return None
        rho = (cur.f - new.f) / pred if new is not None and math.isfinite(new.f) and pred > 0 else -1.0
        if rho > newton_core.ARMIJO:                  # the decrease is at least 1e-4 of the predicted one
            stalled = cur.f - new.f <= 1e-10 * abs(cur.f)
            x, cur = x + d, new
            mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
            if stalled:
                return x
            if mu < 1e-6 * float(D.max()):
                Lf = newton_core.factor(cur.F)
                if Lf is not None:
                    if newton_core.decrement(Lf, cur.g)[1] < 1e-2 * max(cur.f, 1e-300):
                        return x
        else:
            mu, nu = mu * nu, 2 * nu
            if not math.isfinite(mu):
                return None
    return None


def solve_explicit_newton(st: Start, settings: IdentifySettings):
    r"""Minimise the reduced objective Phi(p) of an explicit model by exact Newton steps.

    In the scaled parameters x = p / s_p: far from the optimum Gauss-Newton steps d = -F^{-1} g
    (F = J^T Omega J); once a step changes Phi by less than 10 % of the Gauss-Newton
    decrement's prediction, or that decrement is below 1e-4 (chi^2 units), exact Newton steps
    d = -(F + S)^{-1} g with the second-order term S by AD (Gauss-Newton again where F + S is
    not positive definite).  Backtracking (Armijo, halving) on Phi.  Converged when the
    decrement g^T M^{-1} g of the matrix used is below ``settings.refine_decrement`` after a
    Newton step, or a step below 1e-13 parameter scales.  At most 60 iterations and 50
    evaluations.  From a far start (a Gauss-Newton step halved more than
    :data:`_GN_MAX_HALVINGS` times, or no convergence) Levenberg-Marquardt steps on the same
    exact Gauss-Newton model (:func:`_levenberg_marquardt`) bring p closer and the iteration
    restarts from there; when that fails too, the iteration runs once more from p0 with the full
    line search (40 halvings).  Every evaluation is one call of the least-squares kernel over the data
    (:mod:`identification.fit.explicit_kernel`: Phi, g, F and, in the Newton phase, S together), so
    an iteration costs O(n) with a small constant and no NLP is built.

    Returns (result, point, S): the solution as an :class:`IpoptResult` (status
    ``Solve_Succeeded``, the same acceptance as Ipopt's: a stationary point at the tolerance),
    its reduced point and the second-order term S there (unscaled; None when not evaluated), or
    None when the iteration fails (singular F, failed line search, no convergence): the caller
    then solves with Ipopt.  The result may lie outside the parameter bounds (the caller checks).
    """
    t0 = time.perf_counter()
    objective = _ExplicitObjective(st)
    x0 = st.p0 / st.s_p
    got = _newton_from(st, settings, objective, x0, t0, _GN_MAX_HALVINGS)
    if got is None:
        x = _levenberg_marquardt(st, objective)
        if x is not None:
            got = _newton_from(st, settings, objective, x, t0)
    if got is None:                                # e.g. BoxBOD start1: LM stalls on a plateau
        got = _newton_from(st, settings, objective, x0, t0)
    return got


def _newton_from(st: Start, settings: IdentifySettings, objective: "_ExplicitObjective", x: np.ndarray,
                 t0: float, max_halvings: int = 40):
    """The iteration of :func:`solve_explicit_newton` from the scaled start x (same returns);
    it gives up when a Gauss-Newton step needs more than ``max_halvings`` halvings.  The rules (line
    search, convergence test) are those of :mod:`identification.fit.newton`."""
    dof = st.n - st.model.n_p
    known = st.data.sigma is not None
    refine_dec, dec_tol = settings.refine_decrement, settings.decrement_tol
    try:
        cur = objective(x, False)
    except StateSolveError:
        return None
    newton = False
    prev_dec = None
    budget = [1]                                   # evaluations so far
    for it in range(1, _NEWTON_MAX_ITER + 1):
        if not math.isfinite(cur.f):
            return None
        if newton and cur.S is None:
            cur = objective(x, True)
        L = newton_core.factor(cur.F + cur.S, cur.F) if newton else newton_core.factor(cur.F)
        if L is None:
            return None
        v, dec = newton_core.decrement(L, cur.g)
        # the decrement in units of the standard errors: with sigma unknown the objective's sigma is
        # a common spread and s^2 = RSS / (n - n_p) is what the standard errors use
        unit = newton_core.decrement_unit(cur.f, None if known else dof)
        if not newton and dec < 1e-4 * unit and getattr(objective, "early_newton", False):
            newton = True                          # Newton steps from this point on (with S here)
            cur = objective(x, True)
            L = newton_core.factor(cur.F + cur.S, cur.F)
            if L is None:
                return None
            v, dec = newton_core.decrement(L, cur.g)
        if newton:
            roundoff = newton_core.gradient_roundoff(functools.partial(dense.tri_solve, L), cur.g_abs)
            if newton_core.converged(dec, refine_dec * unit, roundoff):
                break
            if newton_core.in_quadratic_region(dec, dec_tol * unit) and prev_dec is not None and dec > 0.1 * prev_dec:
                break                              # no more progress at round-off, within 1e-5 std errors
        prev_dec = dec if newton else None
        d = newton_core.direction(L, v)
        if newton_core.tiny_step(d):
            break
        quadratic = newton and newton_core.in_quadratic_region(dec, dec_tol * unit)
        new, x_new = _step(objective, x, d, cur, dec, newton, quadratic, budget, max_halvings)
        if new is newton_core.ABORT:
            return None                            # far from the optimum: Levenberg-Marquardt's turn
        if new is None:
            if quadratic:
                break                              # at round-off: the decrement certifies the optimum
            if not newton:
                newton = True                      # Gauss-Newton cannot descend further: try Newton
                continue
            return None
        gain = cur.f - new.f
        if not newton and (dec < 1e-4 * unit or gain < 0.05 * dec):
            newton = True
        x, cur = x_new, new
    else:
        return None
    return _newton_result(st, objective, x, cur, it, dec, t0)


def _step(objective, x: np.ndarray, d: np.ndarray, cur: ExplicitTerms, dec: float, newton: bool, quadratic: bool,
          budget: list, max_halvings: int) -> tuple:
    """(terms, x_new) after the step d from x: in the quadratic region (Phi cannot resolve the decrease)
    the full step, else (or when that fails) the line search of :func:`identification.fit.newton.backtrack`
    with Armijo's rule; (None, None) when no step is accepted, (ABORT, None) beyond the evaluation
    budget or, in the Gauss-Newton phase, beyond ``max_halvings`` halvings."""
    if quadratic:
        x_new = x + d
        try:                                   # quadratic region: the objective cannot resolve
            new = objective(x_new, True)       # the decrease any more; take the full step
        except StateSolveError:
            new = None
        if new is not None and math.isfinite(new.f):
            return new, x_new
    calls = [0]

    def trial(t):
        k = calls[0]
        calls[0] += 1
        budget[0] += 1
        if budget[0] > _NEWTON_MAX_EVALS or (not newton and k > max_halvings):
            return newton_core.ABORT
        try:     # an objective whose S is cheap to add later takes it only at the accepted point (the loop's next turn)
            return objective(x + t * d, newton and not getattr(objective, "deferred_second_order", False))
        except StateSolveError:      # no states there: halve, or give up (the full-space NLP's turn)
            return newton_core.ABORT if getattr(objective, "abort_on_failure", False) else None

    new, t = newton_core.backtrack(trial, lambda c, t: newton_core.sufficient_decrease(c.f, cur.f, t, dec))
    return new, (x + t * d if new is not None and new is not newton_core.ABORT else None)


def _newton_result(st: Start, objective, x: np.ndarray, cur: ExplicitTerms, it: int, dec: float, t0: float):
    """(result, point, S) of the converged iteration at the scaled x, or None (state solve failed)."""
    s_p = st.s_p
    try:
        point = objective.point(x)
    except StateSolveError:
        return None
    res = IpoptResult(x=x, f=point.objective, status="Solve_Succeeded",
                      message=f"exact reduced-space Newton converged in {it} iterations (Newton decrement "
                              f"{dec:.1e}); Ipopt was not needed", accepted=True, iterations=it,
                      wall_time=time.perf_counter() - t0, stats={"solver": "reduced Newton"})
    return res, point, None if cur.S is None else cur.S / np.outer(s_p, s_p)


def reduced_start(st: Start, settings: IdentifySettings):
    r"""The reduced-space optimum of an implicit model with small (dense) states, as Ipopt's start.

    The Gauss-Newton/Newton iteration of explicit models (:func:`_newton_from`, the same line
    search and convergence test) on the reduced objective Phi(p) with the states eliminated
    (:class:`identification.fit.implicit_start.ImplicitObjective`: states by batched damped Newton
    from the nearest point evaluated, sensitivities by the implicit function theorem, S by
    adjoints, all inputs at once).  Used for models with at least
    ``settings.reduced_start_inputs`` inputs.  A collocated ODE whose iteration gives up (a Gauss-Newton step
    halved more than :data:`_GN_MAX_HALVINGS` times, or a trial point without trajectories) takes
    Levenberg-Marquardt steps (:func:`_levenberg_marquardt`, trial points without trajectories raise the
    damping; at most 40 evaluations and 3 such points in a row) and restarts the iteration from their point.  Returns (result, point, S) as
    :func:`solve_explicit_newton`, or None (not used, or the iteration failed: Ipopt then
    starts from the predictor as before).
    """
    model = st.model
    min_inputs = settings.reduced_start_inputs
    trajectory = model.state_numerics.reduced_space     # e.g. a collocated ODE: any number of inputs
    if (not model.n_y or min_inputs is None or
            not (trajectory or (st.data.n_q >= min_inputs and numerics(model).dense))):
        return None
    x0 = st.p0 / st.s_p
    # the marched states at p0 of a reduced-space model (initial_states) are reused at the first point
    # (not inside merged fits, whose evaluations depend on the batch: identification.fit.batch.fit_members)
    # a collocated ODE gives up at the first trial point where its trajectories cannot be solved (a step into a
    # blow-up): the full-space NLP, whose trajectories need not be consistent on the way, takes over from p0
    objective = ImplicitObjective(st.problem, x0, st.Y_init, st.p0 if trajectory and not merging() else None,
                                  abort_on_failure=trajectory)
    # a collocated ODE: Newton steps start at the first point whose Gauss-Newton decrement is below 1e-4 (one
    # point fewer than switching after that point's Gauss-Newton step)
    objective.early_newton = trajectory
    # to round-off (no decrement threshold): Ipopt's test is on the gradient, which a decrement of
    # 1e-24 can leave at 1e-8 when the information is large (many inputs)
    settings = dataclasses.replace(settings, refine_decrement=0.0)
    t0 = time.perf_counter()
    got = _newton_from(st, settings, objective, x0, t0, _GN_MAX_HALVINGS)
    if got is None and trajectory:
        # a collocated ODE from a far start (e.g. stiff kinetics with rates off by 10x in opposite directions):
        # Levenberg-Marquardt on the same exact Gauss-Newton model, as for explicit models, then the
        # iteration from its point; a trial point without trajectories only raises the damping
        x = _levenberg_marquardt(st, objective, _LM_TRAJECTORY_MAX_EVALS, _LM_TRAJECTORY_MAX_FAILS)
        if x is not None:
            got = _newton_from(st, settings, objective, x, t0)
    return got
