"""The constrained solver of the profile computations (:mod:`identification.inference.profile`):
min Phi(p) over the parameters except a fixed set, by exact reduced Newton steps (Hessian
J^T Omega J + S from AD, backtracking line search, bounds as an active set), falling back to Ipopt
(:func:`identification.fit.problem.fit_model` on a model copy with lower = upper for the fixed
parameters)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from models.contract import Model
from models.errors import StateSolveError
from identification.errors import IdentificationError
from identification.fit import newton as newton_core
from identification.fit.problem import fit_model
from identification.fit.measurements import Measurements
from identification.fit.refinement import ReducedPoint, ReducedProblem

__all__ = ["ProfileError", "ProfileSettings", "Solved", "NewtonFailure", "Profiler", "check_pair", "readonly"]


class ProfileError(IdentificationError):
    """A profile could not be followed (the message names the parameter, the value and the reason)."""


@dataclass(frozen=True)
class ProfileSettings:
    """Options of the profile computations.

    Attributes
    ----------
    newton_tol : float      stop the inner Newton when g^T H^-1 g (objective units) is below it
    max_newton : int        inner Newton iterations before the Ipopt fallback
    max_steps : int         continuation steps per side before the side is declared unbounded
    max_width : float       a side is unbounded when D stays below c up to max_width Wald half-widths
    xtol : float            brentq tolerance on theta, in units of the Wald standard error (of the bracket
                            when that is smaller)
    ipopt_fallback : bool   solve a step with Ipopt when the reduced Newton fails
    """

    newton_tol: float = 1e-12
    max_newton: int = 30
    max_steps: int = 60
    max_width: float = 1e3
    xtol: float = 1e-6
    ipopt_fallback: bool = True

    def __post_init__(self):
        for name in ("newton_tol", "max_width", "xtol"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and v > 0 and math.isfinite(v)):
                raise ValueError(f"{name}: must be a positive finite number, got {v!r}")
        for name in ("max_newton", "max_steps"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ValueError(f"{name}: must be an integer >= 1, got {v!r}")


def readonly(a) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a



@dataclass(frozen=True)
class NewtonFailure:
    """Why the reduced Newton of :class:`Profiler` did not converge (the caller retries or falls back to Ipopt)."""

    reason: str


@dataclass(frozen=True)
class Solved:
    """A re-optimised point: the reduced point, J^T Omega J there (the curvature of the
    continuation predictor) and whether Ipopt was needed."""

    point: ReducedPoint
    H: np.ndarray
    ipopt: bool


class Profiler:
    """Minimises Phi over all parameters except a fixed set (exact reduced Newton, Ipopt fallback)."""

    def __init__(self, model: Model, data: Measurements, est, settings: ProfileSettings):
        self.model, self.data, self.est, self.settings = model, data, est, settings
        se = np.asarray(est.stderr, float)
        scale = np.where(np.isfinite(se) & (se > 0), se, np.maximum(np.abs(est.p), 1.0))
        self.se = scale
        self.problem = ReducedProblem.of(model, data, est.weights, est.sigma, scale)
        self.lo, self.up = model.lower, model.upper
        try:
            start = self.problem.evaluate(np.asarray(est.p, float), est.states)
        except StateSolveError as exc:
            raise ProfileError(f"the state equation cannot be solved at the estimate: {exc}",
                               status="state solve failed") from None
        self.best = self.solved_at(start, False)

    def solved_at(self, point: ReducedPoint, ipopt: bool) -> Solved:
        return Solved(point, self.problem.information(point), ipopt)

    def minimise(self, start: Solved):
        """Exact Newton on all parameters from ``start``: a Solved, or a :class:`NewtonFailure`."""
        return self._newton([], np.asarray(start.point.p, float), start.point.states)

    def predict(self, base: Solved, fixed: list, values: np.ndarray) -> np.ndarray:
        """First-order predictor: p_f = p_f(base) - H_ff^{-1} H_fi (theta - theta_base), clipped to bounds
        (H the Gauss-Newton J^T Omega J: a start for the exact Newton, which makes it exact)."""
        p = np.array(base.point.p, float)
        free = [k for k in range(p.size) if k not in fixed]
        d = np.asarray(values, float) - p[fixed]
        p[fixed] = values
        if free:
            Hff = base.H[np.ix_(free, free)]
            Hfi = base.H[np.ix_(free, fixed)]
            try:
                dp = -np.linalg.solve(Hff, Hfi @ d)
            except np.linalg.LinAlgError:
                dp = np.zeros(len(free))
            if np.all(np.isfinite(dp)):
                p[free] = p[free] + dp
        return np.clip(p, self.lo, self.up)

    def solve(self, fixed: list, values, base: Solved) -> Solved:
        """min Phi over the free parameters with p[fixed] = values, from the predictor at ``base``.

        When the Newton from the first-order predictor fails (e.g. a flat valley sends the predictor
        across the whole box), it is retried from the zero-order start (the free parameters of
        ``base``) before the Ipopt fallback.  Raises ProfileError (with the reason) when neither
        Newton nor Ipopt converges.
        """
        values = np.atleast_1d(np.asarray(values, float))
        p0 = self.predict(base, fixed, values)
        reason = self._newton(fixed, p0, base.point.states)
        if isinstance(reason, Solved):
            return reason
        p_zero = np.array(base.point.p, float)
        p_zero[fixed] = values
        p_zero = np.clip(p_zero, self.lo, self.up)
        if not np.array_equal(p_zero, p0):
            retry = self._newton(fixed, p_zero, base.point.states)
            if isinstance(retry, Solved):
                return retry
            reason = NewtonFailure(f"{reason.reason}; from the zero-order start: {retry.reason}")
        if not self.settings.ipopt_fallback:
            raise ProfileError(f"reduced Newton failed ({reason.reason}); the Ipopt fallback is disabled",
                               status="profile failed")
        return self._ipopt(fixed, values, p0, base, reason.reason)

    def _newton(self, fixed, p0, states0):
        """Exact Newton on the free parameters (the rules of :mod:`identification.fit.newton`: active set,
        convergence test, Armijo backtracking); a Solved on success, else a :class:`NewtonFailure`."""
        free = [k for k in range(p0.size) if k not in fixed]
        try:
            point = self.problem.evaluate(p0, states0)
        except StateSolveError as exc:
            return NewtonFailure(f"state equation not solvable at the predicted start: {exc}")
        for _ in range(self.settings.max_newton + 1):
            solved = self.solved_at(point, False)
            if not free:
                return solved
            # active set: a free parameter at a bound whose gradient pushes it outwards stays there
            act = newton_core.active_set(point.p, point.gradient, self.lo, self.up, free)
            if not act:
                return solved
            got = self._direction(solved, act)
            if not isinstance(got, tuple):
                return got
            step, dec = got

            def trial(t):
                try:
                    return self.problem.evaluate(newton_core.trial_point(point.p, step, t, self.lo, self.up, act),
                                                 point.states)
                except StateSolveError:
                    return None

            new, _ = newton_core.backtrack(
                trial, lambda c, t: newton_core.sufficient_decrease(c.objective, point.objective, t, dec))
            if new is None:
                if dec < 1e3 * self.settings.newton_tol:
                    return solved            # at round-off: no decrease possible, decrement tiny
                return NewtonFailure(f"line search failed (Newton decrement {dec:.2e})")
            point = new
        return NewtonFailure(f"no convergence in {self.settings.max_newton} Newton steps")

    def _direction(self, solved: Solved, act: list):
        """(step, decrement) of the exact Newton step on the parameters ``act`` at ``solved`` (H = J^T Omega J
        + S, J^T Omega J where that is not positive definite); ``solved`` itself when it has converged (the
        Gauss-Newton or Newton decrement below ``newton_tol``), a NewtonFailure when both are singular."""
        s, point = self.se, solved.point
        tol = self.settings.newton_tol
        gs = point.gradient[act] * s[act]
        Fs = solved.H[np.ix_(act, act)] * np.outer(s[act], s[act])
        LF = newton_core.factor(Fs)
        if LF is None and not np.any(gs):
            return solved              # exactly stationary where the free parameters have no influence (Vm = 0)
        if LF is not None and newton_core.converged(newton_core.decrement(LF, gs)[1], tol, 0.0):
            return solved              # converged: g^T (J^T Omega J)^-1 g below the tolerance
        # the exact Hessian J^T Omega J + S (AD second derivatives) for the Newton step
        Hs = (solved.H + point.sens.hessians(point.lam[None])[0])[np.ix_(act, act)] * np.outer(s[act], s[act])
        L = newton_core.factor(Hs)
        if L is None:
            if LF is None:
                return NewtonFailure("the Gauss-Newton information of the free parameters is singular")
            L = LF
        v, dec = newton_core.decrement(L, gs)
        if newton_core.converged(dec, tol, 0.0):
            return solved
        return s[act] * newton_core.direction(L, v), dec

    def _ipopt(self, fixed, values, p0, base, reason) -> Solved:
        names = self.model.param_names
        fixed_model = self.model.with_bounds({names[k]: (float(v), float(v)) for k, v in zip(fixed, values)})
        try:
            est = fit_model(fixed_model, self.data, p0, weights=self.est.weights, Y0=base.point.states)
            # a constrained fit that runs off to infinity (identify certified it, est.bounded False): its
            # point lies on the run-off within the certified tolerance of the constrained infimum, which is
            # the profile's value there
            point = self.problem.evaluate(np.asarray(est.p, float), est.states)
        except (IdentificationError, StateSolveError) as exc:
            raise ProfileError(f"reduced Newton failed ({reason}) and Ipopt failed too: {exc}",
                               status=getattr(exc, "status", "profile failed")) from None
        return self.solved_at(point, True)

    def statistic(self, solved: Solved) -> float:
        return 2.0 * (solved.point.objective - self.best.point.objective)



def check_pair(model: Model, data: Measurements, est) -> None:
    if model is None or data is None:
        raise ValueError("model, data: the profile and bootstrap methods need the model and the measurements "
                         "the estimate was fitted to (conf_int(..., model=model, data=data))")
    if tuple(model.param_names) != tuple(est.param_names):
        raise ValueError(f"model: its parameters {model.param_names} are not those of the estimate "
                         f"{tuple(est.param_names)}")
    if data.z.shape[2] != np.asarray(est.weights).size or data.n_q != np.asarray(est.fitted).shape[0]:
        raise ValueError(f"data: shape {data.z.shape} does not match the estimate "
                         f"({np.asarray(est.fitted).shape[0]} inputs, {np.asarray(est.weights).size} sensors)")
    if (data.sigma is None) != bool(est.sigma_estimated):
        raise ValueError("data: its sigma (known or None) differs from the estimate's; pass the measurements "
                         "the estimate was fitted to")
