r"""Profile-likelihood intervals and likelihood-ratio regions of a weighted least-squares estimate.

With the reduced-space objective Phi(p) of :mod:`identification.fit.refinement` (chi^2 / 2 units
with the sigmas of the estimate) and its minimum Phi(p_hat), the profile of parameter i is

.. math::

    D_i(\theta) = 2\,\bigl(\min_{p:\,p_i = \theta} \Phi(p) - \Phi(\hat p)\bigr),

the likelihood-ratio statistic with the other parameters re-optimised.  The (1 - alpha)
profile interval is {theta : D_i(theta) <= c} with

* c = chi2_1(1 - alpha) when the sensor sigmas are known;
* c = F(1, n - n_p; 1 - alpha) when sigma was estimated: then Phi uses s^2 = RSS / (n - n_p), so
  D_i = (S(theta) - S_hat) / s^2 is the square of Bates and Watts' profile-t statistic
  tau(theta), and the interval is |tau| <= t(n - n_p; alpha / 2) (lmfit's ``conf_interval``
  uses the same F test).

Each side is followed from p_hat along a continuation path: at every step the fixed value
moves, the other parameters start from the first-order predictor -H_ff^{-1} H_fi d theta and
are re-optimised by exact reduced Newton steps (Hessian J^T Omega J + S from AD, backtracking
line search, bounds as an active set), falling back to Ipopt (:func:`identification.identify`
on a model copy with lower = upper for the fixed parameter).  The crossing D_i = c is
bracketed on the path and found by :func:`scipy.optimize.brentq` on the signed root
tau = sqrt(D_i) (nearly linear in theta).  A side on which D_i stays below c up to the
parameter bound or up to ``max_width`` Wald half-widths is reported as -inf / +inf with a
note.  A step that neither Newton nor Ipopt can solve raises :class:`ProfileError` naming
the value where the path stopped.

:func:`lr_region` computes D_ij(theta_i, theta_j) on a grid for a pair of parameters
(the others re-optimised, warm-started from the previous grid point).

The grid's constrained fits are fits of one model with different fixed values: with
``batch=True`` (default) the rows of the grid but the centre one are solved in batches of a few rows
(:func:`identification.fit.batch.fit_batch` on the derived model of
:func:`identification.fit.fixed.fixed_model`, the fixed values as per-member input columns, so K
points cost K n_q row evaluations per sweep), each point started from its solved neighbour in
the row before the block; points the batch does not converge are solved by the per-point Newton.
``python -m bench.bench_bootstrap_batch --profiles-only`` measured 2.1-4.2x less CPU per grid
point than the per-point path on valley grids (1.4-5.1x on axes grids; 11 x 11 and 25 x 25,
explicit and implicit 3-parameter models; the same statistic to 3e-10).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize, stats

from models.contract import Model
from models.errors import StateSolveError
from identification.errors import IdentificationError
from identification.fit.batch import fit_batch
from identification.fit.entry import fit_model
from identification.fit.fixed import fixed_batch, fixed_model, full_parameters
from identification.fit.measurements import Measurements
from identification.fit.refinement import ReducedPoint, ReducedProblem
from identification.inference.unbounded_intervals import profile_intervals_unbounded
from identification.inference.intervals import (ConfidenceIntervals, profile_threshold, region_threshold,
                                                 resolve_params, validate_alpha)

__all__ = ["ProfileError", "ProfileSettings", "ParameterProfile", "ConfidenceIntervals", "LikelihoodRegion",
           "profile_intervals", "lr_region", "profile_threshold", "region_threshold", "resolve_params",
           "validate_alpha"]


#: rows of the grid solved as one batch by lr_region(batch=True), each point started from its column's point in the
#: solved row before the block (1: row by row; 4 measured fastest of 1, 2, 4 with the same continuation quality)
GRID_BLOCK_ROWS = 4


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


def _readonly(a) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class ParameterProfile:
    """The profile of one parameter: the points computed along both continuation paths.

    Attributes
    ----------
    name : str
    values : ndarray (m,)          fixed values theta (sorted, the estimate included)
    statistic : ndarray (m,)       D(theta) = 2 (Phi_min(theta) - Phi(p_hat))
    tau : ndarray (m,)             signed root sign(theta - theta_hat) sqrt(D)
    params : ndarray (m, n_p)      the re-optimised parameters at each value
    lower, upper : float           interval ends (-inf / +inf on an unbounded side)
    threshold : float              c
    ipopt_steps : int              steps that needed the Ipopt fallback
    """

    name: str
    values: np.ndarray
    statistic: np.ndarray
    tau: np.ndarray
    params: np.ndarray
    lower: float
    upper: float
    threshold: float
    ipopt_steps: int = 0

    def __post_init__(self):
        for name in ("values", "statistic", "tau", "params"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))


# ---------------------------------------------------------------------------- the constrained solver
@dataclass(frozen=True)
class _Solved:
    """A re-optimised point: the reduced point, J^T Omega J there (the curvature of the
    continuation predictor) and whether Ipopt was needed."""

    point: ReducedPoint
    H: np.ndarray
    ipopt: bool


class _Profiler:
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
        self.best = self._solved(start, False)

    def _solved(self, point: ReducedPoint, ipopt: bool) -> _Solved:
        return _Solved(point, self.problem.information(point), ipopt)

    def minimise(self, start: _Solved):
        """Exact Newton on all parameters from ``start``: a _Solved, or the reason of failure (str)."""
        return self._newton([], np.asarray(start.point.p, float), start.point.states)

    def predict(self, base: _Solved, fixed: list, values: np.ndarray) -> np.ndarray:
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

    def solve(self, fixed: list, values, base: _Solved) -> _Solved:
        """min Phi over the free parameters with p[fixed] = values, from the predictor at ``base``.

        When the Newton from the first-order predictor fails (e.g. a flat valley sends the predictor
        across the whole box), it is retried from the zero-order start (the free parameters of
        ``base``) before the Ipopt fallback.  Raises ProfileError (with the reason) when neither
        Newton nor Ipopt converges.
        """
        values = np.atleast_1d(np.asarray(values, float))
        p0 = self.predict(base, fixed, values)
        reason = self._newton(fixed, p0, base.point.states)
        if isinstance(reason, _Solved):
            return reason
        p_zero = np.array(base.point.p, float)
        p_zero[fixed] = values
        p_zero = np.clip(p_zero, self.lo, self.up)
        if not np.array_equal(p_zero, p0):
            retry = self._newton(fixed, p_zero, base.point.states)
            if isinstance(retry, _Solved):
                return retry
            reason = f"{reason}; from the zero-order start: {retry}"
        if not self.settings.ipopt_fallback:
            raise ProfileError(f"reduced Newton failed ({reason}); the Ipopt fallback is disabled",
                               status="profile failed")
        return self._ipopt(fixed, values, p0, base, reason)

    def _newton(self, fixed, p0, states0):
        """Exact Newton on the free parameters; a _Solved on success, else the reason (str)."""
        s = self.se
        free = [k for k in range(p0.size) if k not in fixed]
        try:
            point = self.problem.evaluate(p0, states0)
        except StateSolveError as exc:
            return f"state equation not solvable at the predicted start: {exc}"
        for _ in range(self.settings.max_newton + 1):
            solved = self._solved(point, False)
            if not free:
                return solved
            g = point.gradient
            # active set: a free parameter at a bound whose gradient pushes it outwards stays there
            act = [k for k in free if not ((point.p[k] <= self.lo[k] and g[k] > 0)
                                           or (point.p[k] >= self.up[k] and g[k] < 0))]
            if not act:
                return solved
            gs = g[act] * s[act]
            Fs = solved.H[np.ix_(act, act)] * np.outer(s[act], s[act])
            try:
                LF = np.linalg.cholesky(Fs)
            except np.linalg.LinAlgError:
                LF = None
            if LF is None and not np.any(gs):
                return solved              # exactly stationary where the free parameters have no influence (Vm = 0)
            if LF is not None:
                w = np.linalg.solve(LF, gs)
                if float(w @ w) < self.settings.newton_tol:
                    return solved          # converged: g^T (J^T Omega J)^-1 g below the tolerance
            # the exact Hessian J^T Omega J + S (AD second derivatives) for the Newton step
            Hs = (solved.H + point.sens.hessians(point.lam[None])[0])[np.ix_(act, act)] * np.outer(s[act], s[act])
            try:
                L = np.linalg.cholesky(Hs)
            except np.linalg.LinAlgError:
                if LF is None:
                    return "the Gauss-Newton information of the free parameters is singular"
                L = LF
            v = np.linalg.solve(L, gs)
            dec = float(v @ v)
            if dec < self.settings.newton_tol:
                return solved
            step = -s[act] * np.linalg.solve(L.T, v)
            t = 1.0
            new = None
            for _ls in range(40):
                p_try = np.array(point.p)
                p_try[act] = np.clip(point.p[act] + t * step, self.lo[act], self.up[act])
                try:
                    cand = self.problem.evaluate(p_try, point.states)
                except StateSolveError:
                    cand = None
                if cand is not None and cand.objective <= point.objective - 1e-4 * t * dec:
                    new = cand
                    break
                t *= 0.5
            if new is None:
                if dec < 1e3 * self.settings.newton_tol:
                    return solved            # at round-off: no decrease possible, decrement tiny
                return f"line search failed (Newton decrement {dec:.2e})"
            point = new
        return f"no convergence in {self.settings.max_newton} Newton steps"

    def _ipopt(self, fixed, values, p0, base, reason) -> _Solved:
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
        return self._solved(point, True)

    def statistic(self, solved: _Solved) -> float:
        return 2.0 * (solved.point.objective - self.best.point.objective)


# ---------------------------------------------------------------------------- one side of a profile
class _Side:
    """The continuation path of one side (direction +1 or -1) of one parameter's profile."""

    def __init__(self, prof: _Profiler, i: int, direction: int, c: float):
        self.prof, self.i, self.d, self.c = prof, i, direction, c
        self.name = prof.model.param_names[i]
        self.theta_hat = float(prof.best.point.p[i])
        self.h0 = float(prof.se[i])            # Wald standard error (or scale)
        self.points = []                       # (theta, D, solved)
        self.ipopt_steps = 0

    def _at(self, theta: float, base: _Solved) -> tuple:
        try:
            s = self.prof.solve([self.i], [theta], base)
        except ProfileError as exc:
            raise ProfileError(f"profile of {self.name}: stopped at {self.name} = {theta:.8g} "
                               f"({'upper' if self.d > 0 else 'lower'} side): {exc}", status=exc.status) from None
        D = self.prof.statistic(s)
        if not math.isfinite(D):
            raise ProfileError(f"profile of {self.name}: stopped at {self.name} = {theta:.8g}: the objective is "
                               f"not finite there ({s.point.objective})", status="not finite")
        if D < -1e-6 * max(1.0, self.c):
            err = ProfileError(f"profile of {self.name}: at {self.name} = {theta:.8g} the objective is lower than "
                               f"at the estimate (D = {D:.3g}): the estimate is not the minimum; refit from there",
                               status="not a minimum")
            err.lower_point = s
            raise err
        self.ipopt_steps += int(s.ipopt)
        self.points.append((theta, max(D, 0.0), s))
        return max(D, 0.0), s

    def run(self) -> tuple:
        """(end, note): the crossing theta, or +-inf with a note."""
        prof, i, d, c = self.prof, self.i, self.d, self.c
        bound = prof.up[i] if d > 0 else prof.lo[i]
        limit = self.theta_hat + d * self.prof.settings.max_width * math.sqrt(c) * self.h0
        stop = min(bound, limit) if d > 0 else max(bound, limit)
        base = prof.best
        h_prev = 0.0
        h = math.sqrt(c) * self.h0              # the Wald crossing
        if abs(stop - self.theta_hat) <= 0:
            return self.theta_hat, f"{self.name}: the estimate is at the bound {bound:g}"
        for _ in range(self.prof.settings.max_steps):
            at_stop = abs(h) >= abs(stop - self.theta_hat)
            if at_stop:
                h = abs(stop - self.theta_hat)
            theta = self.theta_hat + d * h
            while True:
                try:
                    D, s = self._at(theta, base)
                    break
                except ProfileError as exc:
                    h_half = h_prev + 0.5 * (h - h_prev)
                    if exc.status in ("not a minimum", "not finite") or h_half - h_prev < 1e-6 * self.h0:
                        raise
                    h, at_stop = h_half, False
                    theta = self.theta_hat + d * h
            tau = math.sqrt(D)
            if D >= c:
                return self._crossing(h_prev, h, base), None
            if at_stop:
                what = f"the bound {bound:g}" if stop == bound else \
                    f"{self.prof.settings.max_width:g} Wald half-widths ({stop:.6g})"
                return d * math.inf, (f"{self.name}: the profile statistic stays below the threshold "
                                      f"({D:.3g} < {c:.3g}) up to {what}; the "
                                      f"{'upper' if d > 0 else 'lower'} end is unbounded")
            # Newton on tau towards sqrt(c) (slight overshoot), growth at most 3x the last step;
            # dtau/dh = d g_i / tau exactly (envelope theorem: dD/dtheta = 2 dPhi/dp_i at the constrained minimum)
            slope = self._slope(s, tau) if tau > 0 else 0.0
            dh_last = h - h_prev
            if slope > 0:
                dh = (1.01 * math.sqrt(c) - tau) / slope
                dh = min(max(dh, 0.1 * dh_last), 3.0 * dh_last)
            else:
                dh = 3.0 * dh_last
            h_prev, base = h, s
            h = h + dh
        return d * math.inf, (f"{self.name}: the profile statistic stays below the threshold after "
                              f"{self.prof.settings.max_steps} continuation steps (last {self.name} = "
                              f"{self.theta_hat + d * h_prev:.6g}); the {'upper' if d > 0 else 'lower'} "
                              "end is treated as unbounded")

    def _slope(self, s: _Solved, tau: float) -> float:
        """dtau/dh at a solved point: d * dPhi/dp_i / tau (h: distance from the estimate)."""
        return self.d * float(s.point.gradient[self.i]) / tau

    def _crossing(self, h_lo: float, h_hi: float, base: _Solved) -> float:
        """The root of tau(h) = sqrt(c) in [h_lo, h_hi] (tau(h_lo) < sqrt(c) <= tau(h_hi)).

        The bracket is first narrowed by safeguarded Newton steps on tau (exact slope, see
        :meth:`_slope`), each aimed slightly across the root so that the bracket shrinks from both
        sides; :func:`scipy.optimize.brentq` then finishes on the narrow bracket.  Every
        evaluation is warm-started from the nearest solved point inside it (towards the estimate), so
        that it stays on the branch of constrained minima the path followed.
        """
        root_c = math.sqrt(self.c)
        # tolerance in Wald standard errors, but never coarser than the bracket itself: when the estimate lies
        # far out in a flat valley (se huge) a tolerance of xtol * se could exceed the whole bracket, and
        # brentq would return an end of it unchecked
        xtol = self.prof.settings.xtol * min(self.h0, h_hi - h_lo)
        hi_s = self.points[-1][2]
        lo = [h_lo, math.sqrt(max(self.prof.statistic(base), 0.0)) - root_c, base]
        hi = [h_hi, math.sqrt(self.points[-1][1]) - root_c, hi_s]
        known = {lo[0]: lo[1], hi[0]: hi[1]}
        solved = {lo[0]: lo[2], hi[0]: hi[2]}

        def g(h):
            if h not in known:
                # warm start from the nearest point on the inside of h: the path's branch of the constrained
                # minimum (a point beyond the crossing, e.g. at a parameter bound, may sit on another branch)
                near = solved[max(k for k in solved if k <= h)]
                D, s = self._at(self.theta_hat + self.d * h, near)
                known[h] = math.sqrt(D) - root_c
                solved[h] = s
            return known[h]

        from_hi = True
        for _ in range(4):
            if hi[0] - lo[0] <= xtol:
                break
            end = hi if from_hi or lo[0] == 0.0 else lo
            tau = end[1] + root_c
            slope = self._slope(end[2], tau) if tau > 0 else 0.0
            if not slope > 0:
                break
            step = -end[1] / slope
            h_n = end[0] + step + math.copysign(max(xtol, 1e-3 * abs(step)), step)
            if not lo[0] < h_n < hi[0]:
                break
            v = g(h_n)
            if v < 0:
                lo = [h_n, v, solved[h_n]]
                from_hi = False
            else:
                hi = [h_n, v, solved[h_n]]
                from_hi = True
        h = optimize.brentq(g, lo[0], hi[0], xtol=xtol, rtol=1e-12)
        return self.theta_hat + self.d * h


def _profile_one(prof: _Profiler, i: int, c: float) -> tuple:
    notes = []
    ends = []
    pts = []
    n_ipopt = 0
    for d in (-1, +1):
        side = _Side(prof, i, d, c)
        end, note = side.run()
        ends.append(end)
        if note:
            notes.append(note)
        pts += side.points
        n_ipopt += side.ipopt_steps
    pts.append((float(prof.best.point.p[i]), 0.0, prof.best))
    pts.sort(key=lambda t: t[0])
    th = np.array([t[0] for t in pts])
    D = np.array([t[1] for t in pts])
    P = np.array([t[2].point.p for t in pts])
    tau = np.sign(th - prof.best.point.p[i]) * np.sqrt(D)
    name = prof.model.param_names[i]
    if n_ipopt:
        notes.append(f"{name}: {n_ipopt} profile step(s) were solved by the Ipopt fallback")
    return ParameterProfile(name, th, D, tau, P, float(ends[0]), float(ends[1]), c, n_ipopt), notes


def profile_intervals(model: Model, data: Measurements, est, alpha: float = 0.05, params=None,
                      settings: ProfileSettings | None = None) -> ConfidenceIntervals:
    """Profile-likelihood (1 - alpha) intervals {theta : D_i(theta) <= c} (see the module docstring).

    Parameters
    ----------
    model, data : the model and measurements ``est`` was fitted to (same weights)
    est : Estimate
    alpha : float in (0, 0.5)       miss probability (0.05: 95 % intervals)
    params : names or indices, optional (default all)
    settings : ProfileSettings, optional

    Returns
    -------
    ConfidenceIntervals (method "profile"), with the profiles computed on the way.

    Raises
    ------
    ProfileError
        A continuation step could not be solved (the message names the parameter value and why).
    """
    alpha = validate_alpha(alpha)
    idx = resolve_params(params, tuple(est.param_names))
    _check_pair(model, data, est)
    settings = settings or ProfileSettings()
    c = profile_threshold(alpha, est.sigma_estimated, est.dof)
    if getattr(est, "unbounded", None) is not None:      # the best fit runs off: D against the infimum
        lower, upper, notes = profile_intervals_unbounded(model, data, est, alpha, idx, c)
        return ConfidenceIntervals(tuple(est.param_names[i] for i in idx), np.asarray(est.p)[idx], lower, upper,
                                   "profile", alpha, tuple(notes))
    prof = _Profiler(model, data, est, settings)
    restart_notes = []
    while True:
        profiles, notes = [], []
        try:
            for i in idx:
                pr, nt = _profile_one(prof, i, c)
                profiles.append(pr)
                notes += nt
            break
        except ProfileError as exc:
            lower = getattr(exc, "lower_point", None)
            if lower is None or len(restart_notes) >= 3:
                raise
            restart_notes.append(_restart(prof, lower, exc))
    notes = restart_notes + notes
    names = tuple(est.param_names[i] for i in idx)
    return ConfidenceIntervals(names, np.asarray(est.p)[idx], [p.lower for p in profiles],
                               [p.upper for p in profiles], "profile", alpha, tuple(notes), tuple(profiles))


def _restart(prof: _Profiler, lower: _Solved, exc: ProfileError) -> str:
    """Re-minimise all parameters from a profile point below the estimate; that minimum becomes the
    reference of every profile.  Returns the note saying so (raises when the Newton fails)."""
    old = prof.best
    new = prof.minimise(lower)
    if isinstance(new, str):
        raise ProfileError(f"{exc}; re-minimising from there failed: {new}", status="not a minimum") from None
    prof.best = new
    names = prof.model.param_names
    return (f"the estimate is not the minimum of the objective: a profile step found Phi lower by "
            f"{old.point.objective - lower.point.objective:.3g} (chi2/2 units); the intervals are those of the "
            f"refined minimum (" + ", ".join(f"{n} = {v:.7g}" for n, v in zip(names, new.point.p))
            + f"), Phi lower by {old.point.objective - new.point.objective:.3g} than at the estimate")


def _grid_per_point(prof: _Profiler, idx: list, X: np.ndarray, Y: np.ndarray, C: np.ndarray, ph: np.ndarray) -> tuple:
    """(D, failed, outside, note) of the grid by the per-point solver, warm-started along rows from the
    point nearest the estimate (see :func:`lr_region`)."""
    n = X.shape[0]
    D = np.full((n, n), np.nan)
    failed = []
    outside = 0
    lo, up = prof.lo[idx], prof.up[idx]
    r0, c0 = _grid_centre(X, Y, C, ph)
    row_start = {}
    for rows in (range(r0, n), range(r0 - 1, -1, -1)):
        for r in rows:
            base = row_start.get(r - 1 if rows.step > 0 else r + 1, prof.best)
            for cc in list(range(c0, n)) + list(range(c0 - 1, -1, -1)):
                if cc == c0 - 1:
                    base = row_start.get(r, base)
                v = np.array([X[r, cc], Y[r, cc]])
                if np.any(v < lo) or np.any(v > up):
                    outside += 1
                    continue
                try:
                    s = prof.solve(idx, v, base)
                except ProfileError as exc:
                    failed.append(f"({v[0]:.6g}, {v[1]:.6g}): {exc}")
                    continue
                D[r, cc] = max(prof.statistic(s), 0.0)
                base = s
                if cc == c0:
                    row_start[r] = s
    return D, failed, outside, ""


def _grid_centre(X, Y, C, ph) -> tuple:
    """(row, column) of the grid point nearest the estimate (in standard errors)."""
    sd = np.sqrt(np.abs(np.diag(C))) + 1e-300
    near = ((X - ph[0]) / sd[0]) ** 2 + ((Y - ph[1]) / sd[1]) ** 2
    return tuple(int(k) for k in np.unravel_index(int(np.argmin(near)), near.shape))


@dataclass(frozen=True)
class _GridPoint:
    """A solved grid point: the full parameters, the states and (once needed) the _Solved there."""

    p: np.ndarray
    states: np.ndarray
    solved: _Solved | None = None


def _as_solved(prof: _Profiler, sol: dict, key) -> _Solved:
    """The _Solved of grid point ``key`` (evaluated once for a batch point; the estimate when unsolved)."""
    g = sol.get(key)
    if g is None:
        return prof.best
    if g.solved is None:
        try:
            point = prof.problem.evaluate(g.p, g.states)
        except StateSolveError:
            return prof.best
        g = sol[key] = _GridPoint(g.p, g.states, prof._solved(point, False))
    return g.solved


def _row_per_point(prof: _Profiler, idx, X, Y, r, c0, D, sol, failed, base_of) -> int:
    """Solve the unsolved points of row r one by one, outwards from column c0; the start of a point is
    its solved neighbour in the row (towards c0), else ``base_of(cc)``.  Returns the points solved."""
    n = X.shape[1]
    prev = None
    done = 0
    for cc in list(range(c0, n)) + [None] + list(range(c0 - 1, -1, -1)):
        if cc is None:
            prev = (r, c0) if (r, c0) in sol else None
            continue
        if (r, cc) in sol:
            prev = (r, cc)
            continue
        v = np.array([X[r, cc], Y[r, cc]])
        if np.any(v < prof.lo[idx]) or np.any(v > prof.up[idx]):
            continue
        base = _as_solved(prof, sol, prev) if prev is not None else base_of(cc)
        try:
            s = prof.solve(idx, v, base)
        except ProfileError as exc:
            failed.append(f"({v[0]:.6g}, {v[1]:.6g}): {exc}")
            continue
        D[r, cc] = max(prof.statistic(s), 0.0)
        sol[(r, cc)] = _GridPoint(np.asarray(s.point.p, float), np.asarray(s.point.states, float), s)
        prev = (r, cc)
        done += 1
    return done


def _grid_batched(prof: _Profiler, idx: list, X: np.ndarray, Y: np.ndarray, C: np.ndarray, ph: np.ndarray) -> tuple:
    """(D, failed, outside, note) of the grid: the centre row point by point, the others in blocks of
    GRID_BLOCK_ROWS rows as batches of constrained fits (see :func:`lr_region`)."""
    model, data, est = prof.model, prof.data, prof.est
    n = X.shape[0]
    D = np.full((n, n), np.nan)
    failed = []
    lo, up = prof.lo[idx], prof.up[idx]
    inside = (X >= lo[0]) & (X <= up[0]) & (Y >= lo[1]) & (Y <= up[1])
    r0, c0 = _grid_centre(X, Y, C, ph)
    sol = {}                                     # (row, column) -> _GridPoint
    _row_per_point(prof, idx, X, Y, r0, c0, D, sol, failed, lambda cc: prof.best)
    fm = fixed_model(model, idx)
    rest = [k for k in range(model.n_p) if k not in idx]
    p0 = np.asarray(prof.best.point.p, float)[rest]
    ref = prof.best.point.objective
    redo = 0
    for rows, step in ((list(range(r0 + 1, n)), 1), (list(range(r0 - 1, -1, -1)), -1)):
        for b0 in range(0, len(rows), GRID_BLOCK_ROWS):
            block = rows[b0:b0 + GRID_BLOCK_ROWS]
            rb = block[0] - step             # the solved row the block starts from (same column)
            pts = [(r, cc) for r in block for cc in range(n) if inside[r, cc] and (rb, cc) in sol]
            if pts:
                starts = np.array([sol[(rb, cc)].p[rest] for _, cc in pts])
                states = np.array([sol[(rb, cc)].states.reshape(data.n_q, model.n_y) for _, cc in pts])
                values = np.array([[X[r, cc], Y[r, cc]] for r, cc in pts])
                bf = fit_batch(fm, fixed_batch(data.inputs, data.z, est.sigma, values), p0, est.weights,
                               starts=starts, start_states=states, fallback=False)
                for k, (r, cc) in enumerate(pts):
                    if bf.converged[k]:
                        res = bf.results[k]
                        D[r, cc] = max(2.0 * (res.objective - ref), 0.0)
                        sol[(r, cc)] = _GridPoint(full_parameters(model.n_p, idx, res.p, values[k]),
                                                  np.asarray(res.states, float))
            for r in block:
                redo += _row_per_point(prof, idx, X, Y, r, c0, D, sol, failed,
                                       lambda cc, rp=r - step: _as_solved(prof, sol, (rp, cc)))
    note = ""
    if redo:
        note = (f"{redo} grid points were solved point by point (the batch of their row did not converge there, "
                "or their neighbour in the previous row was not solved)")
    return D, failed, int(np.sum(~inside)), note


def _check_pair(model: Model, data: Measurements, est) -> None:
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


# ---------------------------------------------------------------------------- pair regions
def _valley_grid(prof: _Profiler, idx: list, C: np.ndarray, ph: np.ndarray, c: float, n: int, span: float,
                 lim) -> tuple:
    """X, Y (n, n) of the valley grid of :func:`lr_region` (column k: p_i = a_k) and a note ('' or the
    values of a where the profile point could not be solved and the linearised valley was used)."""
    i, j = idx
    model = prof.model
    half = span * math.sqrt(c * C[0, 0])
    a_lo, a_hi = (lim[0] if lim is not None else (ph[0] - half, ph[0] + half))
    a = np.linspace(max(a_lo, model.lower[i]), min(a_hi, model.upper[i]), n)
    v = np.linspace(-span * math.sqrt(c), span * math.sqrt(c), n)
    rest = [k for k in range(model.n_p) if k != i]
    jr = rest.index(j)
    centre = np.empty(n)
    width = np.empty(n)
    lin_sd = math.sqrt(max(C[1, 1] - C[0, 1] ** 2 / C[0, 0], 0.0))
    k0 = int(np.argmin(np.abs(a - ph[0])))
    unsolved = []
    for ks in (range(k0, n), range(k0 - 1, -1, -1)):
        base = prof.best
        for k in ks:
            try:
                s = prof.solve([i], [a[k]], base)
                K = s.H[np.ix_(rest, rest)]
                sd = math.sqrt(float(np.linalg.inv(K)[jr, jr]))
                if not (math.isfinite(sd) and sd > 0):
                    raise np.linalg.LinAlgError("singular")
                centre[k], width[k] = s.point.p[j], sd
                base = s
            except (ProfileError, np.linalg.LinAlgError):
                unsolved.append(a[k])
                centre[k] = ph[1] + C[0, 1] / C[0, 0] * (a[k] - ph[0])
                width[k] = lin_sd
    X = np.tile(a, (n, 1))
    Y = centre[None, :] + v[:, None] * width[None, :]
    note = ""
    if unsolved:
        note = (f"valley grid: the profile of {model.param_names[i]} could not be solved at {len(unsolved)} of {n} "
                "values; the linearised valley was used there")
    return X, Y, note


@dataclass(frozen=True)
class LikelihoodRegion:
    """The likelihood-ratio statistic of a parameter pair on a grid.

    D(a, b) = 2 (min over the other parameters of Phi with (p_i, p_j) = (a, b) - Phi(p_hat)),
    the region {D <= threshold}.

    Attributes
    ----------
    names : (str, str)
    X, Y : ndarray (n, n)           grid values of p_i and p_j (row r, column k); a rectangle
                                    (``grid="axes"``) or the principal axes of the ellipse
                                    (``grid="principal"``)
    statistic : ndarray (n, n)      D on the grid (NaN where the point could not be solved or lies
                                    outside the bounds; see notes)
    threshold : float               chi2_2(1 - alpha) or 2 F(2, dof; 1 - alpha)
    alpha : float
    estimate : ndarray (2,)         (p_i, p_j) at the estimate
    cov : ndarray (2, 2)            their block of the second-order covariance (the linearised ellipse
                                    is d^T cov^-1 d <= threshold)
    notes : tuple of str            unsolved points, a region reaching the edge of the grid
    indices : (int, int)            positions of the pair in the parameter vector
    """

    names: tuple
    X: np.ndarray
    Y: np.ndarray
    statistic: np.ndarray
    threshold: float
    alpha: float
    estimate: np.ndarray
    cov: np.ndarray
    notes: tuple = ()
    indices: tuple = (0, 1)

    def __post_init__(self):
        for name in ("X", "Y", "statistic", "estimate", "cov"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))

    def linearised(self) -> np.ndarray:
        """The quadratic form d^T cov^-1 d on the grid (n, n): the statistic of a linear model."""
        dx, dy = self.X - self.estimate[0], self.Y - self.estimate[1]
        Ci = np.linalg.inv(self.cov)
        return Ci[0, 0] * dx ** 2 + 2 * Ci[0, 1] * dx * dy + Ci[1, 1] * dy ** 2


def lr_region(model: Model, data: Measurements, est, pair, alpha: float = 0.05, n_grid: int = 25,
              span: float = 1.6, grid: str = "principal", settings: ProfileSettings | None = None,
              limits=None, batch: bool = True) -> LikelihoodRegion:
    """Likelihood-ratio statistic of the pair ``pair = (i, j)`` on an n_grid x n_grid grid.

    ``grid="principal"`` (default): the grid p = p_hat + V diag(sqrt(w)) (u, v) with C = V diag(w) V^T
    the pair's covariance block and u, v in [-span sqrt(c), span sqrt(c)], so that the linearised
    ellipse is the circle of radius sqrt(c) and a thin, strongly correlated region still falls on
    many grid points; ``grid="valley"``: a curvilinear grid that follows the valley of the objective
    -- columns at n_grid values a of p_i (``limits[0]``, or span x the ellipse's half-width), rows
    across it at p_j = b*(a) + v sd_j(a), b*(a) the profile of p_i (p_j and the others re-optimised),
    sd_j(a) the standard error of p_j there with p_i fixed and v in [-span sqrt(c), span sqrt(c)] --
    for thin curved regions (strong correlation) that no rectangle resolves; ``grid="axes"``: the rectangle of span x the ellipse's half-extents, or
    ``limits = ((lo_i, hi_i), (lo_j, hi_j))`` when given (parameter units, clipped to the bounds; e.g.
    the extent of the profile traces, when the region reaches far beyond the ellipse).  The other
    parameters are re-optimised at every grid point (exact reduced Newton, Ipopt fallback),
    warm-started along rows from the grid centre.  A point that cannot be solved or lies outside the
    bounds is NaN, counted in ``notes``; a region that reaches the edge of the grid is noted too.

    ``batch=True`` (default): the row through the point nearest the estimate is solved point by
    point as above; the other rows, in blocks of :data:`GRID_BLOCK_ROWS` outwards from it, are one
    :func:`identification.fit.batch.fit_batch` call per block on the derived model
    :func:`identification.fit.fixed.fixed_model` (the pair's values as per-member input columns), each
    point started from its column's solved point in the row before the block (towards the
    centre); a point the batch does not converge (or ends on a bound) is solved point by point
    from its neighbour, counted in ``notes``.  ``batch=False``, or a model of two parameters (no
    free parameter left): every point by the per-point solver.
    """
    alpha = validate_alpha(alpha)
    idx = resolve_params(list(pair), tuple(est.param_names))
    if len(idx) != 2:
        raise ValueError(f"pair: expected two different parameters, got {pair!r}")
    if not (isinstance(n_grid, (int, np.integer)) and n_grid >= 3):
        raise ValueError(f"n_grid: expected an integer >= 3, got {n_grid!r}")
    if not (span > 0 and math.isfinite(span)):
        raise ValueError(f"span: expected a positive number, got {span!r}")
    if grid not in ("principal", "axes", "valley"):
        raise ValueError(f"grid: expected 'principal', 'axes' or 'valley', got {grid!r}")
    if limits is not None:
        lim = np.asarray(limits, float)
        if lim.shape != (2, 2) or not np.all(np.isfinite(lim)) or np.any(lim[:, 1] <= lim[:, 0]):
            raise ValueError(f"limits: expected ((lo_i, hi_i), (lo_j, hi_j)) with finite lo < hi, got {limits!r}")
        if grid == "principal":
            grid = "axes"
    valley_note = ""
    _check_pair(model, data, est)
    if getattr(est, "unbounded", None) is not None:     # no finite minimum to grid around
        est.require_bounded("lr_region")
    settings = settings or ProfileSettings()
    prof = _Profiler(model, data, est, settings)
    c = region_threshold(alpha, est.sigma_estimated, est.dof)
    C = np.asarray(est.cov)[np.ix_(idx, idx)]
    if not np.all(np.isfinite(C)):
        C = np.asarray(est.cov_gn)[np.ix_(idx, idx)]
    ph = np.asarray(est.p, float)[idx]
    n = int(n_grid)
    if grid == "axes":
        half = span * np.sqrt(c * np.diag(C))
        box = lim if limits is not None else np.column_stack([ph - half, ph + half])
        x = np.linspace(max(box[0, 0], model.lower[idx[0]]), min(box[0, 1], model.upper[idx[0]]), n)
        y = np.linspace(max(box[1, 0], model.lower[idx[1]]), min(box[1, 1], model.upper[idx[1]]), n)
        X, Y = np.meshgrid(x, y)
    elif grid == "valley":
        X, Y, valley_note = _valley_grid(prof, idx, C, ph, c, n, span, lim if limits is not None else None)
    else:
        w, V = np.linalg.eigh(0.5 * (C + C.T))
        L = V * np.sqrt(np.clip(w, 0.0, None))[None, :]
        u = np.linspace(-span * math.sqrt(c), span * math.sqrt(c), n)
        U, W = np.meshgrid(u, u)
        X = ph[0] + L[0, 0] * U + L[0, 1] * W
        Y = ph[1] + L[1, 0] * U + L[1, 1] * W
    solve = _grid_batched if batch and model.n_p > 2 else _grid_per_point      # (a pair alone: nothing to fit)
    D, failed, outside, batch_note = solve(prof, idx, X, Y, C, ph)
    notes = [valley_note] if valley_note else []
    if batch_note:
        notes.append(batch_note)
    if failed:
        notes.append(f"{len(failed)} of {D.size} grid points could not be solved (NaN); first: {failed[0]}")
    if outside:
        notes.append(f"{outside} of {D.size} grid points lie outside the parameter bounds (NaN)")
    edge = np.concatenate([D[0], D[-1], D[:, 0], D[:, -1]])
    if np.any(edge[np.isfinite(edge)] <= c):
        notes.append("the region reaches the edge of the grid: it extends beyond it (use a larger span)")
    return LikelihoodRegion((est.param_names[idx[0]], est.param_names[idx[1]]), X, Y, D, c, alpha, ph, C,
                            tuple(notes), tuple(idx))
