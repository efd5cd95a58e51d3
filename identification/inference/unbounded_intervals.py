r"""Profile intervals and the summary of an estimate the data do not bound
(:mod:`identification.fit.unbounded` certifies the run-off).

D_i(theta) = 2 (Phi_min,i(theta) - Phi_inf), the likelihood-ratio statistic with the supremum of
the likelihood; the side towards which the fit runs off is +-inf (or 0 for a parameter whose
magnitude goes to 0), the other side is found by decade steps of theta from the representative
point and brentq on sqrt(D) - sqrt(c) inside the decade that crosses c.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import optimize

from models.errors import StateSolveError
from identification.errors import NotBoundedError
from identification.fit.refinement import ReducedProblem
from identification.fit.unbounded import MAX_DECADES, constrained_minimum, move_along, relative_scale

__all__ = ["profile_intervals_unbounded", "unbounded_summary"]


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
