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

:func:`lr_region` (:mod:`identification.inference.likelihood_region`, re-exported here) computes
D_ij(theta_i, theta_j) on a grid for a pair of parameters; the constrained solver is
:mod:`identification.inference.profile_solver`.

Profile intervals and the summary of an estimate the data do not bound
(:func:`profile_intervals_unbounded`, :func:`unbounded_summary`; :mod:`identification.fit.unbounded`
certifies the run-off): D_i(theta) = 2 (Phi_min,i(theta) - Phi_inf), the likelihood-ratio statistic with
the supremum of the likelihood; the side towards which the fit runs off is +-inf (or 0 for a parameter
whose magnitude goes to 0), the other side is found by decade steps of theta from the representative
point and brentq on sqrt(D) - sqrt(c) inside the decade that crosses c.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from models.contract import Model
from models.errors import StateSolveError
from identification.errors import NotBoundedError
from identification.fit.measurements import Measurements
from identification.fit.refinement import ReducedProblem
from identification.fit.unbounded import MAX_DECADES, constrained_minimum, move_along, relative_scale
from identification.inference.intervals import (ConfidenceIntervals, profile_threshold, region_threshold,
                                                 resolve_params, validate_alpha)
from identification.inference.likelihood_region import GRID_BLOCK_ROWS, LikelihoodRegion, lr_region
from identification.inference.profile_solver import (NewtonFailure, ProfileError, ProfileSettings, Profiler, Solved,
                                                      check_pair, readonly)

__all__ = ["ProfileError", "ProfileSettings", "ParameterProfile", "ConfidenceIntervals", "LikelihoodRegion",
           "profile_intervals", "lr_region", "profile_threshold", "region_threshold", "resolve_params",
           "validate_alpha", "GRID_BLOCK_ROWS", "profile_intervals_unbounded", "unbounded_summary"]


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
            object.__setattr__(self, name, readonly(getattr(self, name)))



# ---------------------------------------------------------------------------- one side of a profile
class _Side:
    """The continuation path of one side (direction +1 or -1) of one parameter's profile."""

    def __init__(self, prof: Profiler, i: int, direction: int, c: float):
        self.prof, self.i, self.d, self.c = prof, i, direction, c
        self.name = prof.model.param_names[i]
        self.theta_hat = float(prof.best.point.p[i])
        self.h0 = float(prof.se[i])            # Wald standard error (or scale)
        self.points = []                       # (theta, D, solved)
        self.ipopt_steps = 0

    def _at(self, theta: float, base: Solved) -> tuple:
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

    def _slope(self, s: Solved, tau: float) -> float:
        """dtau/dh at a solved point: d * dPhi/dp_i / tau (h: distance from the estimate)."""
        return self.d * float(s.point.gradient[self.i]) / tau

    def _crossing(self, h_lo: float, h_hi: float, base: Solved) -> float:
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


def _profile_one(prof: Profiler, i: int, c: float) -> tuple:
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
    check_pair(model, data, est)
    settings = settings or ProfileSettings()
    c = profile_threshold(alpha, est.sigma_estimated, est.dof)
    if getattr(est, "unbounded", None) is not None:      # the best fit runs off: D against the infimum
        lower, upper, notes = profile_intervals_unbounded(model, data, est, alpha, idx, c)
        return ConfidenceIntervals(tuple(est.param_names[i] for i in idx), np.asarray(est.p)[idx], lower, upper,
                                   "profile", alpha, tuple(notes))
    prof = Profiler(model, data, est, settings)
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


def _restart(prof: Profiler, lower: Solved, exc: ProfileError) -> str:
    """Re-minimise all parameters from a profile point below the estimate; that minimum becomes the
    reference of every profile.  Returns the note saying so (raises when the Newton fails)."""
    old = prof.best
    new = prof.minimise(lower)
    if isinstance(new, NewtonFailure):
        raise ProfileError(f"{exc}; re-minimising from there failed: {new.reason}", status="not a minimum") from None
    prof.best = new
    names = prof.model.param_names
    return (f"the estimate is not the minimum of the objective: a profile step found Phi lower by "
            f"{old.point.objective - lower.point.objective:.3g} (chi2/2 units); the intervals are those of the "
            f"refined minimum (" + ", ".join(f"{n} = {v:.7g}" for n, v in zip(names, new.point.p))
            + f"), Phi lower by {old.point.objective - new.point.objective:.3g} than at the estimate")

# ---------------------------------------------------------------------------- profile intervals
def _side(problem, est, i: int, c: float, f_inf: float) -> tuple:
    """(end, note) of the finite (inward) side of parameter i's profile."""
    u = est.unbounded
    name = est.param_names[i]
    lo, up = problem.model.lower, problem.model.upper
    inward = -1 if u.direction[i] > 0 else +1        # decades of |theta|
    start = constrained_minimum(problem, np.asarray(est.p, float), est.states, i)
    if start is None:
        raise NotBoundedError(f"profile of {name}: the valley cannot be followed from the estimate")
    expo = np.where(np.abs(u.direction) >= 1e-3 * abs(u.direction[i]), u.direction, 0.0) * np.sign(u.direction[i])
    cur = start
    for _k in range(4 * MAX_DECADES):
        theta = cur.p[i] * 10.0 ** inward
        at_bound = not (lo[i] <= theta <= up[i])
        theta = float(np.clip(theta, lo[i], up[i]))
        q = move_along(cur.p, expo, i, float(inward), lo, up)
        q[i] = theta
        new = constrained_minimum(problem, q, cur.states, i)
        if new is None:
            raise NotBoundedError(f"profile of {name}: the constrained fit failed at {name} = {theta:.8g}")
        D = 2.0 * (new.objective - f_inf)
        if D >= c:
            return _crossing(problem, i, cur, new, c, f_inf, expo), None
        if at_bound or theta == 0:
            return inward * math.copysign(math.inf, cur.p[i]), (
                f"{name}: the profile statistic stays below the threshold ({D:.3g} < {c:.3g}) up to the bound "
                f"{theta:g}; that end is unbounded too")
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.log10(np.abs(new.p)) - np.log10(np.abs(cur.p))
        expo = np.where(np.isfinite(step), step, 0.0) * inward
        cur = new
    return inward * math.copysign(math.inf, cur.p[i]), (
        f"{name}: the profile statistic stays below the threshold over {4 * MAX_DECADES} decades; treated as unbounded")


def _crossing(problem, i, out_pt, in_pt, c, f_inf, expo) -> float:
    """theta in [in_pt.p[i], out_pt.p[i]] where sqrt(D) = sqrt(c) (brentq, warm starts from the outer point)."""
    lo, up = problem.model.lower, problem.model.upper
    known = {float(out_pt.p[i]): out_pt}

    def g(theta):
        near = known[min(known, key=lambda t: abs(t - theta))]
        ratio = theta / near.p[i] if near.p[i] != 0 and theta / near.p[i] > 0 else 1.0
        q = move_along(near.p, expo, i, math.log10(ratio), lo, up) if ratio != 1.0 else np.array(near.p, float)
        q[i] = theta
        pt = constrained_minimum(problem, q, near.states, i)
        if pt is None:
            raise NotBoundedError(f"profile of {problem.model.param_names[i]}: the constrained fit failed at "
                                  f"{theta:.8g}")
        known[float(theta)] = pt
        return math.sqrt(max(2.0 * (pt.objective - f_inf), 0.0)) - math.sqrt(c)

    a, b = float(in_pt.p[i]), float(out_pt.p[i])
    return float(optimize.brentq(g, a, b, xtol=1e-12 * max(abs(a), abs(b)), rtol=1e-10))


def profile_intervals_unbounded(model, data, est, alpha: float, idx: list, c: float):
    """Profile-likelihood intervals of an estimate that is not bounded (see the module docstring):
    D_i(theta) = 2 (min_{p_i = theta} Phi - Phi_inf) <= c, with c the threshold of
    :func:`identification.inference.profile.profile_threshold`.

    Returns (lower, upper, notes): per parameter of ``idx`` the ends (+-inf on the side the fit runs
    off to, 0 for a parameter whose magnitude goes to 0) and the notes; the caller
    (:func:`identification.inference.profile.profile_intervals`) makes the ConfidenceIntervals.

    Raises
    ------
    NotBoundedError
        A constrained fit of the finite side failed (the message names the parameter and value).
    """
    u = est.unbounded
    problem = ReducedProblem.of(model, data, est.weights, est.sigma, relative_scale(np.asarray(est.p, float),
                                                                            np.ones(est.p.size)))
    try:
        f_inf = problem.evaluate(np.asarray(u.p_limit, float), est.states).objective
    except StateSolveError as exc:
        raise NotBoundedError(f"profile: the limit point cannot be evaluated: {exc}") from None
    f_inf = min(f_inf, problem.evaluate(np.asarray(est.p, float), est.states).objective)
    lower, upper, notes = [], [], []
    ends = u.ends()
    for i in idx:
        name = est.param_names[i]
        if name not in u.involved:
            se = math.sqrt(est.cov[i, i]) if est.cov[i, i] >= 0 else math.nan
            z = math.sqrt(c)
            lower.append(est.p[i] - z * se)
            upper.append(est.p[i] + z * se)
            notes.append(f"{name}: not involved in the run-off; its interval is the Wald interval of the limiting "
                         "model (information restricted to the directions the data determine)")
            continue
        end, note = _side(problem, est, i, c, f_inf)
        far = {"+inf": math.inf, "-inf": -math.inf, "0": 0.0}[ends[name]]
        lo_, hi_ = sorted((end, far))
        lower.append(lo_)
        upper.append(hi_)
        notes.append(f"{name}: the data do not bound it {'from above' if far == math.inf else 'from below' if far < 0 else 'away from 0'} "
                     f"(the best fit runs off to {ends[name]})")
        if note:
            notes.append(note)
    return lower, upper, notes


# ---------------------------------------------------------------------------- summary
def unbounded_summary(est, alpha: float = 0.05, intervals=None) -> str:
    """The summary of an estimate that is not bounded: what runs off, what the data determine and, when
    the caller passes them (``est.conf_int(alpha, method="profile")``), the profile intervals.  Runs no fit."""
    u = est.unbounded
    lines = [f"Identification of {est.model_name or 'model'}",
             f"  status: NOT BOUNDED ({est.message})",
             f"  data: n = {est.n_data} values, dof = {est.dof}; sensors used: "
             f"{', '.join(s for s, w in zip(est.sensors, est.weights) if w > 0)}",
             f"  objective {est.objective:.6g} (infimum {u.objective_limit:.6g}, approached at infinity), "
             f"RSS {est.rss:.6g}" + (" (sigma estimated)" if est.sigma_estimated else ""), ""]
    pct = f"{100 * (1 - alpha):g}%"
    if intervals is not None:
        lo, hi, ci_notes = np.asarray(intervals.lower), np.asarray(intervals.upper), list(intervals.notes)
    else:
        lo = hi = np.full(est.n_p, np.nan)
        ci_notes = ["profile intervals not computed here (summary() only reads): ci = est.conf_int(method=\"profile\"); "
                    "est.summary(intervals=ci) shows them"]
    w = max(9, max(len(n) for n in est.param_names))
    ends = u.ends()
    lines.append(f"{'parameter':<{w}} {'estimate':>14} {pct + ' profile lower':>20} {pct + ' profile upper':>20}  unit")
    for i, n in enumerate(est.param_names):
        val = f"-> {ends[n]}" if n in ends else f"{est.p[i]:.7g}"
        lines.append(f"{n:<{w}} {val:>14} {lo[i]:>20.7g} {hi[i]:>20.7g}  {est.param_units[i]}")
    lines += ["", "what the data determine (finite along the run-off):"]
    for text, value, rse in u.combinations:
        lines.append(f"  {text} = {value:.7g} (relative std err {100 * rse:.3g} %)")
    for i, n in enumerate(est.param_names):
        if n not in u.involved:
            lines.append(f"  {n} = {est.p[i]:.7g} (std err {est.stderr[i]:.4g}, information restricted to the "
                         "directions the data determine)")
    if not u.combinations and len(u.involved) == est.n_p:
        lines.append("  (no combination of the parameters that run off)")
    lines += ["", "direction the data do not determine (d log|p|): "
              + ", ".join(f"{u.direction[i]:+.3f} {n}" for i, n in enumerate(est.param_names) if n in u.involved)]
    notes = list(est.notes) + ci_notes
    lines += ["", "Notes:"] + [f"[{k}] {t}" for k, t in enumerate(notes, 1)]
    return "\n".join(lines)
