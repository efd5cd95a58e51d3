r"""Second-order optimality of a stationary point of the reduced objective (issue 20 item 1).

A solver's "success" is a stationary point, g = 0 to its tolerance.  It is a minimum only where
the reduced Hessian H = J^T Omega J + S is positive definite (on the parameters not at a bound).
In the metric of the Gauss-Newton information (:mod:`identification.fit.factor`),

.. math::

    H = D^{-1} R^T K R D^{-1},\qquad K = I + R^{-T} (D S D) R^{-1},

and the eigenvalues mu of K are the curvatures of Phi along directions d = D R^{-1} v of unit
Gauss-Newton norm (||sqrt(Omega) J d|| = 1): Phi(p + t d) = Phi(p) + t g^T d + mu t^2 / 2 + O(t^3).
A smallest eigenvalue mu_1 <= 0 means the point is not a strict minimum.  :func:`check` finds it
and :func:`escape` searches along +-d_1 for a point with a lower objective (from t = 1, doubling
while Phi keeps falling, halving while it does not); the estimator then solves again from there.
When no descent is found the estimator raises a ConvergenceError naming the point, mu_1 and what
to try.  Where mu_1 > 0 the Newton decrement is computed through K (finite even where the
Cholesky factor of H in the parameters' own scaling fails to working precision).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from models.errors import StateSolveError
from identification.errors import ConvergenceError
from identification.fit import newton as newton_core
from identification.fit.factor import WeightedFactor, normalised_hessian, weighted_factor, weighted_rows
from identification.fit.refinement import ReducedPoint, ReducedProblem, Refinement

__all__ = ["SecondOrder", "check", "escape", "ensure_minimum", "MAX_SADDLE_ESCAPES"]

#: at most this many restarts from points found along a direction of negative curvature
MAX_SADDLE_ESCAPES = 3

#: the doublings and halvings of the step along the negative-curvature direction
_MAX_DOUBLINGS = 60
_MAX_HALVINGS = newton_core.MAX_HALVINGS


@dataclass(frozen=True)
class SecondOrder:
    """The second-order test at one stationary point.

    Attributes
    ----------
    eigenvalue : float        smallest eigenvalue mu_1 of K on the free parameters (1 where S = 0)
    direction : ndarray (n_p,) d_1 = D R^{-1} v_1 in parameter units (0 for parameters at a bound),
                              of unit Gauss-Newton norm; its sign makes g^T d_1 <= 0
    decrement : float         g^T H^{-1} g (objective units) through K; inf when mu_1 <= 0
    roundoff : float          the size of mu_1 that round-off in S alone could produce
                              (eps cond(R)^2 ||K - I||, at least 1e-12)
    """

    eigenvalue: float
    direction: np.ndarray
    decrement: float
    roundoff: float

    @property
    def minimum(self) -> bool:
        """True when the reduced Hessian is positive definite (mu_1 > 0)."""
        return self.eigenvalue > 0


def check(problem: ReducedProblem, point: ReducedPoint, S: np.ndarray, free: np.ndarray,
          fac: WeightedFactor | None = None, rank_rtol: float = 0.0) -> SecondOrder | None:
    """The second-order test at ``point`` on the parameters ``free`` (bool, n_p): None when the
    column-normalised weighted Jacobian of the free parameters is rank deficient (relative singular
    value below ``rank_rtol``: the identifiability test reports it) or no parameter is free.
    ``fac``: the factor of all parameters' rows at ``point`` when the caller has it (used when every
    parameter is free)."""
    idx = np.flatnonzero(free)
    if not idx.size:
        return None
    if fac is None or idx.size < point.p.size:
        fac = weighted_factor(weighted_rows(point.sens.G[:, :, idx], problem.cw, problem.sigma)[None])
    if not fac.full_rank[0] or fac.sv[0][-1] < rank_rtol * fac.sv[0][0]:
        return None
    K = normalised_hessian(fac, S[np.ix_(idx, idx)][None])[0]
    if not np.all(np.isfinite(K)):
        return None
    lam, V = np.linalg.eigh(K)
    d_free = fac.d[0] * fac.solve_r(V[:, :1][None])[0][:, 0]        # D R^-1 v_1
    g = point.gradient[idx]
    if g @ d_free > 0:
        d_free = -d_free
    direction = np.zeros(point.p.size)
    direction[idx] = d_free
    w = V.T @ fac.solve_rt((fac.d[0] * g)[None, :, None])[0][:, 0]     # V^T R^-T D g
    dec = float(np.sum(w ** 2 / lam)) if lam[0] > 0 else math.inf
    cond = fac.sv[0][0] / fac.sv[0][-1]
    roundoff = max(1e-12, float(np.finfo(float).eps * cond ** 2 * np.abs(lam - 1).max()))
    return SecondOrder(float(lam[0]), direction, dec, roundoff)


def _objective_roundoff(point: ReducedPoint, problem: ReducedProblem) -> float:
    """A bound of the round-off of Phi: 64 eps (Phi + sum of the terms' magnitudes)."""
    return 64 * np.finfo(float).eps * (abs(point.objective) + abs(problem.const) + 1e-300)


def _trial(problem: ReducedProblem, point: ReducedPoint, p: np.ndarray) -> ReducedPoint | None:
    model = problem.model
    if not (np.all(p > model.lower) and np.all(p < model.upper) and np.all(np.isfinite(p))):
        return None
    try:
        new = problem.evaluate(p, point.states)
    except StateSolveError:
        return None
    return new if math.isfinite(new.objective) else None


def escape(problem: ReducedProblem, point: ReducedPoint, so: SecondOrder) -> ReducedPoint | None:
    """A point p + t d with Phi clearly below Phi(p) (by more than its round-off) along the
    negative-curvature direction d = +-``so.direction``, or None when there is none.

    From t = 1 (one Gauss-Newton standard error when sigma is known) the step is doubled while
    Phi keeps falling (the best point is returned) or halved until Phi falls; both signs are
    tried (the descent sign first).  Trial points outside the bounds or where the states cannot
    be solved count as no descent.
    """
    f0 = point.objective
    tol = _objective_roundoff(point, problem)
    best = None
    for sign in (1.0, -1.0):
        d = sign * so.direction
        found, t = newton_core.backtrack(lambda s, d=d: _trial(problem, point, point.p + s * d),
                                         lambda c, s: c.objective < f0 - tol, _MAX_HALVINGS)
        if found is None:
            continue
        for _ in range(_MAX_DOUBLINGS):
            t *= 2.0
            trial = _trial(problem, point, point.p + t * d)
            if trial is None or not trial.objective < found.objective:
                break
            found = trial
        if best is None or found.objective < best.objective:
            best = found
        if best is not None:
            break
    return best


def ensure_minimum(problem: ReducedProblem, ref: Refinement, free: np.ndarray, resolve, selected,
                   rank_rtol: float = 0.0) -> tuple:
    """Second-order optimality before success.

    At a stationary point whose reduced Hessian (on the ``free`` parameters) is not positive
    definite the point is not a minimum: a point with a lower objective along the negative-curvature
    direction (:func:`escape`) is handed to ``resolve(point) -> (free, Refinement)``, which solves
    the problem again from there; at most :data:`MAX_SADDLE_ESCAPES` times.  A point where the
    column-normalised sqrt(Omega) J has a relative singular value below ``rank_rtol`` is left to
    the identifiability test (Assumption 3).

    Returns
    -------
    (Refinement, escaped)
        The minimum's refinement (its decrement computed through K when the Cholesky factor of H
        failed to working precision) and the saddle points left, as dicts {"p", "rss", "eigenvalue"}
        (``selected``: the sensors of the RSS).

    Raises
    ------
    ConvergenceError
        When no descent is found (naming the point, the eigenvalue and what to try).
    """
    escaped = []
    for escapes in range(MAX_SADDLE_ESCAPES + 1):
        so = check(problem, ref.point, ref.S, free, ref.factor, rank_rtol)
        if so is None:                      # rank deficient: the identifiability test reports it
            return ref, tuple(escaped)
        if so.minimum:
            if not math.isfinite(ref.decrement):
                ref = replace(ref, decrement=so.decrement)
            return ref, tuple(escaped)
        new = escape(problem, ref.point, so) if escapes < MAX_SADDLE_ESCAPES else None
        if new is None:
            raise not_a_minimum(problem.model, ref.point.p, so, escapes)
        resid = problem.data.z[:, :, selected] - ref.point.sens.h[None][:, :, selected]
        escaped.append({"p": ref.point.p.copy(), "rss": float(np.nansum(resid ** 2)), "eigenvalue": so.eigenvalue})
        free, ref = resolve(new)
    raise AssertionError("unreachable")  # pragma: no cover


def not_a_minimum(model, p: np.ndarray, so: SecondOrder, escapes: int) -> ConvergenceError:
    """The ConvergenceError of a stationary point that is not a minimum and has no descent."""
    names = model.param_names
    at = ", ".join(f"{n} = {v:.6g}" for n, v in zip(names, p))
    d = so.direction / max(np.abs(so.direction).max(), 1e-300)
    along = " + ".join(f"{d[i]:.2g} {names[i]}" for i in range(p.size) if abs(d[i]) >= 0.1)
    kind = ("a saddle point" if so.eigenvalue < -so.roundoff else
            "a stationary point whose Hessian is singular to working precision")
    more = f" (after {escapes} restart(s) from lower points)" if escapes else ""
    return ConvergenceError(
        f"the fit of {model.name} stopped at {kind}, not a minimum{more}: {at}; the Hessian "
        f"J^T Omega J + S has eigenvalue {so.eigenvalue:.3g} (in units of the Gauss-Newton curvature; "
        f"round-off level {so.roundoff:.1e}) along {along}, and no lower objective was found along it. "
        "Try other start values (or parameter scales near the expected magnitudes), or bounds on the "
        "parameters", p=p.copy(), eigenvalue=so.eigenvalue, direction=so.direction.copy())
