r"""Practical non-identifiability: the best fit runs off to infinity along a direction.

A least-squares objective Phi(p) >= 0 whose infimum is not attained at a finite point is
approached along a path p(t) -> infinity on which some combinations of the parameters stay
finite (Michaelis-Menten y = V_m x / (K + x) observed far below saturation: V_m, K -> inf with
V_m / K fixed, the slope of the linear limit y = (V_m / K) x).  The solver then stops at a far
point where J^T Omega J is numerically singular; that is a property of the data, not of the
model, and :func:`identification.identify` returns it as a result (``Estimate.bounded`` False,
``Estimate.unbounded`` an :class:`Unbounded`) instead of raising.

Certification (:func:`diagnose`), from the point p_s where the solver stopped, in relative
(logarithmic) coordinates u = log|p|:

1. the sloppiest direction v of the relative information D F D (D = diag|p_s|) and its largest
   component j (the driving parameter);
2. the valley: Phi_min(theta) = min {Phi(p) : p_j = theta} (exact reduced Newton on the other
   parameters, J^T Omega J + S by AD), at theta = p_s,j 10^(+-k), k = 1, 2, ... (predictor:
   log-linear along the last step of the valley);
3. a run-off is certified when Phi_min decreases monotonically outwards and converges (the last
   decade changes it by less than :data:`TAIL_TOL`), and rises inwards by more than round-off
   (the valley is not flat).  A valley flat to round-off on both sides is a structural rank
   deficiency at a finite point: :func:`identify` then raises IdentifiabilityError saying so.

The limit Phi_inf is the objective at the outermost valley point; the estimate's p is the
innermost valley point within :data:`REPRESENTATIVE_TOL` (chi^2 / 2 units) of it.  The direction
of the run-off is the last valley step in u (unit vector); the combinations that stay finite are
the monomials p_j / p_i^(u_j / u_i), with relative standard errors from the information restricted
to the complement of u (the limiting model's information).

Profile intervals (:func:`profile_intervals_unbounded`): D_i(theta) = 2 (Phi_min,i(theta) -
Phi_inf), the likelihood-ratio statistic with the supremum of the likelihood; the side towards
which the fit runs off is +-inf (or 0 for a parameter whose magnitude goes to 0), the other
side is found by decade steps of theta from the representative point and brentq on
sqrt(D) - sqrt(c) inside the decade that crosses c.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from models.errors import StateSolveError
from identification.fit import dense
from identification.errors import IdentifiabilityError
from identification.fit.refinement import ReducedPoint, ReducedProblem
from identification.fit.record import FitRecord

__all__ = ["Unbounded", "Diagnosis", "diagnose", "estimate_not_bounded", "identifiability_error", "not_bounded_reason",
           "constrained_minimum", "relative_scale", "move_along", "MAX_DECADES"]

#: the valley has converged when its last decade lowers Phi by less than this (chi^2 / 2 units)
TAIL_TOL = 1e-8
#: the representative point lies within this of the limit Phi_inf (chi^2 / 2 units)
REPRESENTATIVE_TOL = 1e-6
#: decades walked along the valley at most (each way)
MAX_DECADES = 16


@dataclass(frozen=True)
class Unbounded:
    """How the data leave the parameters unbounded (``Estimate.unbounded``).

    Attributes
    ----------
    param_names : tuple of str
    direction : ndarray (n_p,)     unit vector of d log|p_i| along which the best fit runs off
    involved : tuple of str        parameters that run off (|direction_i| >= 0.05 max)
    objective_limit : float        Phi_inf, the infimum of the objective (chi^2 / 2 units, sigma as used)
    p_limit : ndarray (n_p,)       the outermost valley point (Phi there is Phi_inf to TAIL_TOL)
    decades : int                  decades of the driving parameter walked outwards and inwards
    combinations : tuple of (str, float, float)  (text, value, relative standard error) of the
                                   combinations that stay finite (e.g. ("Vm/K", 0.5, 0.012))
    """

    param_names: tuple
    direction: np.ndarray
    involved: tuple
    objective_limit: float
    p_limit: np.ndarray
    decades: int
    combinations: tuple = ()

    def __post_init__(self):
        for name in ("direction", "p_limit"):
            a = np.array(getattr(self, name), dtype=float, copy=True)
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    def ends(self) -> dict:
        """{parameter: "+inf" | "-inf" | "0"} where each involved parameter goes."""
        out = {}
        for i, n in enumerate(self.param_names):
            if n in self.involved:
                out[n] = ("+inf" if self.p_limit[i] > 0 else "-inf") if self.direction[i] > 0 else "0"
        return out

    @property
    def reason(self) -> str:
        """One line: what runs off and what stays finite."""
        ends = ", ".join(f"{n} -> {e}" for n, e in self.ends().items())
        fixed = "; ".join(f"{t} = {v:.6g} stays finite" for t, v, _ in self.combinations)
        return (f"the data do not bound {', '.join(self.involved)}: the best fit runs off to infinity "
                f"({ends}{'; ' + fixed if fixed else ''})")

    def __str__(self):
        return self.reason


def not_bounded_reason(est) -> str:
    """The reason text of an estimate that is not bounded ("" for a bounded one or a non-Estimate)."""
    u = getattr(est, "unbounded", None)
    return "" if u is None else f"not bounded: {u.reason}"


# ---------------------------------------------------------------------------- the valley
def relative_scale(p: np.ndarray, s_p: np.ndarray) -> np.ndarray:
    """Relative scales |p_i| (s_p,i where p_i = 0)."""
    return np.where(np.abs(p) > 0, np.abs(p), s_p)


def constrained_minimum(problem: ReducedProblem, p: np.ndarray, states, fixed: int, max_iter: int = 60):
    """min Phi over all parameters but ``fixed`` (held at p[fixed]) from p by exact reduced Newton.

    Steps d = -(F + S)^{-1} g on the free parameters in relative scaling (Gauss-Newton F where
    F + S is not positive definite), Armijo backtracking, clipped to the bounds.  Converged when
    the decrement g^T M^{-1} g is below 1e-14 max(1, Phi) (chi^2 / 2 units), or at round-off
    (no decrease possible with a decrement below 1e-9 max(1, Phi)).  Returns the ReducedPoint or
    None (state solve or line search failed).
    """
    model = problem.model
    lo, up = model.lower, model.upper
    free = [k for k in range(p.size) if k != fixed and lo[k] < up[k]]     # lower == upper: held by its bounds
    try:
        point = problem.evaluate(np.asarray(p, float), states)
    except StateSolveError:
        return None
    if not free:
        return point
    for _ in range(max_iter):
        d = relative_scale(point.p, problem.p_scale)[free]
        F = problem.information(point)[np.ix_(free, free)] * np.outer(d, d)
        S = point.sens.hessians(point.lam[None])[0][np.ix_(free, free)] * np.outer(d, d)
        L = dense.cholesky_lower(F + S)
        if L is None:
            L = dense.cholesky_lower(F)
            if L is None:
                return None
        v = dense.tri_solve(L, point.gradient[free] * d)
        dec = float(v @ v)
        tol = max(1.0, abs(point.objective))
        if dec <= 1e-14 * tol:
            return point
        step = -d * dense.tri_solve(L, v, trans=1)
        t, new = 1.0, None
        for _ls in range(40):
            q = np.array(point.p, float)
            q[free] = np.clip(point.p[free] + t * step, lo[free], up[free])
            try:
                cand = problem.evaluate(q, point.states)
            except StateSolveError:
                cand = None
            if cand is not None and math.isfinite(cand.objective) and \
                    cand.objective <= point.objective - 1e-4 * t * dec:
                new = cand
                break
            t *= 0.5
        if new is None:
            return point if dec <= 1e-9 * tol else None
        point = new
    return None


def move_along(p: np.ndarray, expo: np.ndarray, j: int, decades: float, lo, up) -> np.ndarray:
    """The predictor: |p_i| scaled by 10^(decades expo_i / expo_j) (log-linear), p_j by 10^(+-decades)."""
    q = p * 10.0 ** (decades * expo / expo[j])
    return np.clip(q, lo, up)


@dataclass
class _Walk:
    points: list          # ReducedPoints along the valley, in walking order
    expo: np.ndarray      # last step's d log|p| (predictor direction)


def _walk(problem, start: ReducedPoint, j: int, expo: np.ndarray, sign: int, n: int, stop=None) -> _Walk:
    """Valley points at p_j 10^(sign k), k = 1..n (fewer when ``stop(points)`` says so or a
    point cannot be solved, or the next value leaves the bounds)."""
    lo, up = problem.model.lower, problem.model.upper
    pts, cur, e = [], start, np.array(expo, float)
    for _ in range(n):
        q = move_along(cur.p, e, j, sign * 1.0, lo, up)
        target = cur.p[j] * 10.0 ** sign
        if not (lo[j] <= target <= up[j]) or not np.isfinite(target):
            break
        q[j] = target
        new = constrained_minimum(problem, q, cur.states, j)
        if new is None:
            break
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.log10(np.abs(new.p)) - np.log10(np.abs(cur.p))
        e = np.where(np.isfinite(step), step, 0.0) * sign
        pts.append(new)
        cur = new
        if stop is not None and stop(pts):
            break
    return _Walk(pts, e)


@dataclass(frozen=True)
class Diagnosis:
    """The outcome of :func:`diagnose`: kind "unbounded" (with the limit and the path), "structural"
    (flat valley: a finite-point rank deficiency) or "none" (no run-off certified)."""

    kind: str
    text: str = ""
    representative: ReducedPoint | None = None
    limit: ReducedPoint | None = None
    direction: np.ndarray | None = None
    decades: int = 0


def _sloppy(problem: ReducedProblem, p_stop: np.ndarray, states):
    """(point, v, j) at p_stop: v the sloppiest direction of the relative information of the parameters
    not held by their bounds, j its largest component; or a Diagnosis "none" saying why not."""
    try:
        point = problem.evaluate(np.asarray(p_stop, float), states)
    except StateSolveError:
        return Diagnosis("none", "the state equation cannot be solved at the point where the fit stopped")
    if not (math.isfinite(point.objective) and np.all(np.isfinite(point.p))):
        return Diagnosis("none", "the objective is not finite where the fit stopped")
    d = relative_scale(point.p, problem.p_scale)
    Fr = problem.information(point) * np.outer(d, d)
    if not np.all(np.isfinite(Fr)):
        return Diagnosis("none", "the information is not finite where the fit stopped")
    free = np.flatnonzero(problem.model.lower < problem.model.upper)      # parameters not held by their bounds
    if free.size == 0:
        return Diagnosis("none", "every parameter is held by its bounds")
    V = np.linalg.eigh(0.5 * (Fr + Fr.T)[np.ix_(free, free)])[1]
    v = np.zeros(point.p.size)
    v[free] = V[:, 0]
    j = int(np.argmax(np.abs(v)))
    if point.p[j] == 0 or not np.all(np.isfinite(v)):
        return Diagnosis("none", "no sloppy direction to follow")
    return point, v, j


def _log_direction(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The unit vector of log|b| - log|a| (0 where a component is 0)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.log(np.abs(b)) - np.log(np.abs(a))
    u = np.where(np.isfinite(u), u, 0.0)
    return u / np.linalg.norm(u)


def diagnose(problem: ReducedProblem, p_stop: np.ndarray, states=None) -> Diagnosis:
    """Whether the fit that stopped at ``p_stop`` runs off to infinity (see the module docstring)."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):   # far valley points may overflow
        return _diagnose(problem, p_stop, states)


def _diagnose(problem: ReducedProblem, p_stop: np.ndarray, states) -> Diagnosis:
    names = problem.model.param_names
    got = _sloppy(problem, p_stop, states)
    if isinstance(got, Diagnosis):
        return got
    point, v, j = got
    base = constrained_minimum(problem, point.p, point.states, j)
    if base is None:
        return Diagnosis("none", f"the valley through the stopping point cannot be followed ({names[j]} fixed)")
    tol = max(1.0, abs(base.objective))
    round_off = 1e-12 * tol                      # Phi's round-off (sums over the data) with the inner Newton's tolerance
    tail_tol = max(TAIL_TOL, 1e-12 * tol)
    rep_tol = max(REPRESENTATIVE_TOL, 10 * round_off)
    expo = np.where(np.abs(v) >= 1e-3 * abs(v[j]), v, 0.0) * np.sign(v[j])
    up1 = _walk(problem, base, j, expo, +1, 1)
    dn1 = _walk(problem, base, j, expo, -1, 1)
    f_up = up1.points[0].objective if up1.points else math.inf
    f_dn = dn1.points[0].objective if dn1.points else math.inf
    sign = +1 if f_up <= f_dn else -1
    first = up1 if sign > 0 else dn1
    if not first.points:
        return Diagnosis("none", "the valley cannot be followed in either direction")

    def converged(pts):
        f = [base.objective] + [q.objective for q in pts]
        if len(f) < 3:
            return False
        last, prev = f[-2] - f[-1], f[-3] - f[-2]
        # shrinking decrements below the tolerance (geometric tail), or both at round-off (far out);
        # growing ones are a path towards a finite minimum, not a run-off
        return last <= tail_tol and (last <= 0.5 * prev or (max(last, prev) <= round_off
                                                            and last <= 2 * prev + 1e-2 * round_off))

    def done(pts):                   # converged, or a rise: not monotone (a finite minimum), stop walking
        prev = pts[-2].objective if len(pts) >= 2 else first.points[0].objective
        return converged(first.points + pts) or pts[-1].objective > prev + round_off

    out = _walk(problem, first.points[0], j, first.expo, sign, MAX_DECADES - 1, done)
    outward = first.points + out.points
    f_out = np.array([base.objective] + [q.objective for q in outward])
    if np.any(np.diff(f_out) > round_off):
        return Diagnosis("none", "the objective does not decrease monotonically along the valley")
    if not converged(outward):
        return Diagnosis("none", f"the objective still decreases after {len(outward)} decades of {names[j]}")
    f_inf = float(f_out[-1])
    back_expo = -first.expo if np.any(first.expo) else expo

    def risen(pts):
        return pts[-1].objective - f_inf > rep_tol

    inward = _walk(problem, base, j, back_expo * sign, -sign, MAX_DECADES, risen).points
    f_in = np.array([q.objective for q in inward])
    if f_in.size and np.any(f_in < f_inf - max(round_off, tail_tol)):
        return Diagnosis("none", "the valley has a lower point inwards: a finite minimum, not a run-off")
    drop = float(f_out[0] - f_inf)
    rise = float(f_in.max() - f_inf) if f_in.size else 0.0
    if max(drop, rise) <= round_off:
        return Diagnosis("structural", (
            f"the objective is flat to round-off along the valley of {names[j]} over "
            f"{len(inward)} decade(s) inwards and {len(outward)} outwards"), decades=len(inward) + len(outward))
    u = _log_direction(outward[-2].p if len(outward) >= 2 else base.p, outward[-1].p)
    if not np.any(u >= 0.05 * np.abs(u).max()):
        # only magnitudes shrinking towards 0 (which a parameter may cross smoothly): not a run-off
        return Diagnosis("none", "no parameter grows along the valley (it approaches 0, not infinity)")
    rep = next(q for q in inward[::-1] + [base] + outward if q.objective - f_inf <= rep_tol)
    return Diagnosis("unbounded", "", rep, outward[-1], u, len(inward) + len(outward))


# ---------------------------------------------------------------------------- what the data determine
def restricted_covariance(information: np.ndarray, p: np.ndarray, s_p: np.ndarray, u: np.ndarray) -> np.ndarray:
    r"""Covariance of the relative changes dp / |p| restricted to the complement of u:
    Sigma = Q (Q^T D F D Q)^{-1} Q^T, Q an orthonormal basis of u^perp (D = diag |p|); a^T Sigma a is
    the variance of a^T log|p| for a orthogonal to u (the combinations that stay finite)."""
    n = p.size
    d = relative_scale(p, s_p)
    Fr = information * np.outer(d, d)
    Q = np.linalg.svd(u.reshape(1, -1))[2][1:].T          # (n, n - 1), orthonormal, orthogonal to u
    if Q.shape[1] == 0:
        return np.zeros((n, n))
    M = Q.T @ Fr @ Q
    L = dense.cholesky_lower(0.5 * (M + M.T))
    if L is None:
        return np.full((n, n), np.nan)
    A = dense.tri_solve(L, Q.T)
    return A.T @ A


def combinations(names, p, u, involved, Sigma) -> tuple:
    """(text, value, relative standard error) of p_j / p_i^(u_j / u_i) for the involved i != j (j the
    first involved parameter)."""
    idx = [k for k, n in enumerate(names) if n in involved]
    if len(idx) < 2:
        return ()
    j, out = idx[0], []
    for i in idx[1:]:
        e = u[j] / u[i]
        a = np.zeros(len(names))
        a[j], a[i] = 1.0, -e
        expo = "" if abs(abs(e) - 1) < 0.01 else f"^{abs(e):.3g}"
        text = f"{names[j]}/{names[i]}{expo}" if e > 0 else f"{names[j]}*{names[i]}{expo}"
        value = abs(p[j]) / abs(p[i]) ** e * np.sign(p[j]) * (np.sign(p[i]) if e > 0 else 1.0)
        var = float(a @ Sigma @ a)
        out.append((text, float(value), math.sqrt(var) if var >= 0 else math.nan))
    return tuple(out)


def estimate_not_bounded(st, diag: Diagnosis, stopped: str, t_start: float):
    """The Estimate of a certified run-off at the representative point (``st``: the estimator's start
    record with model, data, problem, weights ``w``, sigmas ``sig``, ``selected``, ``n``, ``s_p``).

    As the estimator's result (sigma unknown: s^2 = RSS / (n - n_p) rescales information, objective
    and covariance), except: the standard errors of the parameters that run off are infinite (their
    rows of cov are NaN), those of the others come from the information restricted to the
    complement of the run-off direction; status "Not_Bounded"; ``unbounded`` describes the run-off.
    """
    model, data, problem = st.model, st.data, st.problem
    point, u = diag.representative, diag.direction
    names = model.param_names
    F = problem.information(point)
    S = point.sens.hessians(point.lam[None])[0]
    resid = data.z - point.sens.h[None]
    rss = float(np.nansum(resid[:, :, st.selected] ** 2))
    dof = st.n - model.n_p
    if data.sigma is None:
        s2 = rss / dof
        factor, sig_used = s2 / st.sig[0] ** 2, np.full(model.n_S, math.sqrt(s2))
    else:
        factor, sig_used = 1.0, st.sig
    involved = tuple(n for n, ui in zip(names, u) if abs(ui) >= 0.05 * np.abs(u).max())
    Sigma = restricted_covariance(F / factor, point.p, st.s_p, u)
    combos = combinations(names, diag.limit.p, u, involved, Sigma)
    d = relative_scale(point.p, st.s_p)
    cov = Sigma * np.outer(d, d)
    for i, n in enumerate(names):
        if n in involved:
            cov[i, :] = np.nan
            cov[:, i] = np.nan
            cov[i, i] = np.inf
    info = Unbounded(tuple(names), u, involved, float(diag.limit.objective / factor), diag.limit.p, diag.decades,
                     combos)
    note = (f"{info.reason}. p is a point on that path where the objective is within "
            f"{max(point.objective / factor - info.objective_limit, 0.0):.1e} (chi2/2 units) of its infimum, not an "
            f"estimate; the standard errors of {', '.join(involved)} are infinite "
            "and their profile intervals have an infinite side (summary(), conf_int(method=\"profile\"))")
    notes = [note, f"the solver stopped on that path: {stopped}"]
    other = _other_side(model, info)
    if other:
        notes.append(other)
    return FitRecord(
        p=point.p, param_names=names, param_units=tuple(par.unit for par in model.params), sensors=model.sensors,
        states=point.states, fitted=point.sens.h, residuals=resid, weights=st.w, sigma=sig_used,
        sigma_estimated=data.sigma is None, n_data=st.n, dof=dof, rss=rss, objective=point.objective / factor,
        information=F / factor, S=S / factor, H=(F + S) / factor, cov=cov, cov_gn=cov.copy(), G=point.sens.G,
        status="Not_Bounded", message="the best fit runs off to infinity: the data do not bound the parameters",
        iterations=0, solve_time=time.perf_counter() - t_start, refinement_steps=0,
        grad_norm=float(np.linalg.norm(point.gradient * st.s_p)),
        notes=tuple(notes),
        model_name=model.name, extra={"solver": "valley walk (identification.fit.unbounded)"}, model=model, data=data,
        unbounded=info)


def _other_side(model, info: Unbounded) -> str:
    """A caveat when no bound excludes the other side of infinity (e.g. Vm, K < 0 for Vm, K -> +inf):
    the run-off is certified along its path, and beyond infinity the objective can be lower."""
    open_ = [n for i, n in enumerate(info.param_names) if n in info.involved and info.direction[i] > 0
             and (model.lower[i] == -np.inf if info.p_limit[i] > 0 else model.upper[i] == np.inf)]
    if not open_:
        return ""
    return (f"no bound excludes the other sign of {', '.join(open_)} (the other side of infinity along this path), "
            "where the objective can be lower (a finite minimum of the other sign); the run-off is the best fit "
            "within the signs of the path: declare the physical bounds (e.g. lower = 0) if the other sign has no "
            "meaning")


def identifiability_error(exc: IdentifiabilityError, diag: Diagnosis, p_stop, names) -> IdentifiabilityError:
    """The IdentifiabilityError raised after :func:`diagnose` found no run-off to infinity: structural (a
    valley flat to round-off at a finite point), or a rank deficiency where the fit stopped (named, with
    why no run-off could be certified)."""
    if diag.kind == "structural":
        text = (f"structurally not identifiable at a finite point: {exc}; {diag.text} (a rank deficiency at a "
                "finite point, not data that fail to bound the parameters: a fit that runs off to infinity is "
                "returned as a result with Estimate.bounded False)")
    else:
        where = ", ".join(f"{n} = {v:.4g}" for n, v in zip(names, np.asarray(p_stop, float)))
        text = (f"{exc}; at the point where the fit stopped ({where}) no run-off to infinity could be certified "
                f"({diag.text}): try other start values or bounds on the parameters")
    return IdentifiabilityError(text, getattr(exc, "params", ()), getattr(exc, "sensors", ()))
