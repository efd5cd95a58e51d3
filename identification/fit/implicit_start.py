r"""The reduced-space optimum of an implicit model with small (dense) states, as Ipopt's start.

For many inputs the full-space NLP of :func:`identification.identify` is large (n_q n_y state
variables) while the reduced problem is small: the states solve E(y_j, p, q_j) = 0 input by
input, and the objective

.. math:: \Phi(p) = \tfrac12 \sum_{jk} c_{jk} (\bar z_{jk} - h_k(y_j(p), p, q_j))^2 / \sigma_k^2 + \Phi_0

is a function of p alone with the exact gradient J^T lambda and Hessian J^T Omega J + S
(:mod:`identification.fit.refinement`).  :class:`ImplicitObjective` evaluates Phi and its terms in
the scaled parameters x = p / s_p with every input at once: the states by damped Newton from the
states of the nearest point evaluated so far (:func:`solve_states_from`, one mapped evaluation
of E and dE/dy per trial, batched NumPy solves of the n_q small blocks), the sensitivities by
the implicit function theorem (:func:`models.sensitivity.sensitivities`) and S by one adjoint
per input.  The estimator minimises it with the same Gauss-Newton/Newton iteration as for
explicit models and gives Ipopt that optimum with the constraint multipliers

.. math:: \lambda_j = \mu_j / e,\qquad (\partial E/\partial y)_j^T \mu_j = -(\partial h/\partial y)_j^T \ell_j,
          \quad \ell_{jk} = c_{jk} (h_{jk} - \bar z_{jk}) / \sigma_k^2,

(``e`` the equation scaling of the NLP), so that Ipopt starts at a primal-dual point that
satisfies its optimality conditions and only verifies it (or takes the last steps).
"""
from __future__ import annotations

import numpy as np

from models.errors import StateSolveError
from models.sensitivity import sensitivities
from models.state import numerics
from identification.fit.explicit_kernel import ExplicitTerms
from identification.fit.refinement import ReducedPoint, ReducedProblem

__all__ = ["ImplicitObjective", "solve_states_from", "nlp_multipliers", "start_sensitivities", "START_CACHE_SIZE"]

#: entries kept per model of each start-point cache in ``model.cache`` (repeated fits of new data)
START_CACHE_SIZE = 32

#: damped Newton iterations and step halvings per iteration of :func:`solve_states_from`
_STATE_MAX_ITER = 40
_STATE_MAX_HALVINGS = 30


def _row_max_abs(A: np.ndarray) -> np.ndarray:
    """max_i |A[j, i]| for every row j of an (n, m) array with few columns (one ufunc per column:
    ``np.abs(A).max(axis=1)`` is 40x slower for two columns)."""
    out = np.abs(A[:, 0])
    for i in range(1, A.shape[1]):
        np.maximum(out, np.abs(A[:, i]), out=out)
    return out


def _newton_steps(Ey: np.ndarray, E: np.ndarray, active: np.ndarray) -> np.ndarray:
    """dy_j = -(dE/dy)_j^{-1} E_j for the ``active`` inputs (0 for the others), shape (n, n_y).

    One or two states: the closed form (Cramer's rule, forward stable for 2x2 systems), 2-3x
    faster than LAPACK's batched solve, whose per-matrix overhead dominates for tiny blocks;
    more states: ``numpy.linalg.solve``.  (Only the Newton steps use it: the iteration corrects
    their round-off; the sensitivities keep LAPACK.)  Raises LinAlgError on a singular block."""
    m = E.shape[1]
    if m > 2:
        dY = np.zeros_like(E)
        dY[active] = -np.linalg.solve(Ey[active], E[active][:, :, None])[:, :, 0]
        return dY
    if m == 1:
        det = Ey[:, 0, 0]
    else:
        a, b, c, d = Ey[:, 0, 0], Ey[:, 0, 1], Ey[:, 1, 0], Ey[:, 1, 1]
        det = a * d - b * c
    if np.any(active & (det == 0)):
        raise np.linalg.LinAlgError("Singular matrix")
    inv = np.divide(-1.0, det, out=np.zeros_like(det), where=active)
    if m == 1:
        return E * inv[:, None]
    e0, e1 = E[:, 0], E[:, 1]
    return np.column_stack([(d * e0 - b * e1) * inv, (a * e1 - c * e0) * inv])


def solve_states_from(model, p: np.ndarray, inputs: np.ndarray, Y0: np.ndarray,
                      tol: float = 1e-12) -> np.ndarray:
    r"""States y_j solving E(y_j, p, q_j) = 0 at every input by damped Newton from ``Y0``.

    All inputs at once (dense states): one mapped evaluation of (E, dE/dy) per trial, the
    Newton steps dy_j = -(dE/dy)_j^{-1} E_j batched (:func:`_newton_steps`); every input has its own
    step length, halved while ||E_j||_inf does not decrease by the Armijo fraction 1e-4.  An
    input has converged when its full step satisfies ||dy_j||_inf <= tol (1 + ||y_j||_inf).

    Returns
    -------
    ndarray (n_q, n_y)

    Raises
    ------
    StateSolveError
        When an input does not converge (non-finite values, singular dE/dy, failed line search
        or more than 40 iterations); the caller treats p as infeasible.
    """
    n = inputs.shape[0]
    f = numerics(model).batched("E_y", n)
    Y = np.array(Y0, float)
    E, Ey = f(Y, p, inputs)
    E = E[:, :, 0]
    nE = _row_max_abs(E)
    active = np.ones(n, bool)
    for _ in range(_STATE_MAX_ITER):
        if not (np.all(np.isfinite(nE[active])) and np.all(np.isfinite(Ey[active]))):
            raise StateSolveError(f"state solve at p = {p.tolist()}: non-finite E or dE/dy")
        try:
            dY = _newton_steps(Ey, E, active)
        except np.linalg.LinAlgError:
            raise StateSolveError(f"state solve at p = {p.tolist()}: dE/dy is singular") from None
        size = _row_max_abs(dY)
        ymax = 1 + _row_max_abs(Y)
        done = active & (size <= tol * ymax)
        tiny = size <= 1e-14 * ymax
        step = active.astype(float)
        for _ in range(_STATE_MAX_HALVINGS):
            Y_new = Y + step[:, None] * dY
            E_new, Ey_new = f(Y_new, p, inputs)
            E_new = E_new[:, :, 0]
            n_new = _row_max_abs(E_new)
            decrease = (n_new <= nE * (1 - 1e-4 * step)) | (n_new <= 1e-300)
            good = ~active | done | tiny | (np.isfinite(n_new) & decrease)
            if np.all(good):
                break
            step = np.where(good, step, 0.5 * step)
            tiny = tiny | (step * size <= 1e-14 * ymax)
        else:
            raise StateSolveError(f"state solve at p = {p.tolist()}: line search failed at {np.sum(~good)} inputs")
        Y, E, Ey, nE = Y_new, E_new, Ey_new, n_new
        active &= ~done
        if not np.any(active):
            return Y
    raise StateSolveError(f"state solve at p = {p.tolist()}: {np.sum(active)} inputs did not converge in "
                          f"{_STATE_MAX_ITER} Newton iterations")


def start_sensitivities(model, p0, inputs, Y0):
    """Outputs h, sensitivities G = dh/dp and state derivatives y'(p0) at the start states ``Y0``
    (:func:`models.sensitivity.sensitivities`), kept in ``model.cache`` per (p0, inputs, Y0): they do not depend
    on the data, so the degenerate-start check and the first point of every refit from the same start share
    one evaluation."""
    key = (p0.tobytes(), inputs.tobytes(), np.asarray(Y0).tobytes())
    return model.cache.get_or_make("identify.start_point", key, lambda: sensitivities(model, p0, inputs, Y0),
                                   maxsize=START_CACHE_SIZE)



class ImplicitObjective:
    """Phi(s_p ⊙ x) of an implicit model with dense states and its terms w.r.t. the scaled
    parameters x, as an :class:`identification.fit.explicit_kernel.ExplicitTerms` (the call of the
    estimator's explicit objective), with the states solved from the nearest point evaluated
    so far (the last few are kept; the first guess is the states at p0), predicted to first
    order by its state sensitivities y'(p) (else from its states as they are).

    Parameters
    ----------
    problem : ReducedProblem
    x0 : ndarray (n_p,)      scaled start parameters
    Y0 : ndarray (n_q, n_y)  states at s_p ⊙ x0
    p0 : ndarray (n_p,), optional
        The start values when ``Y0`` are the marched states at exactly p0 of a model solved in the reduced
        space (:func:`identification.fit.start.initial_states`): the point at p0 then reuses them and the
        start's cached sensitivities (:func:`identification.fit.start.start_sensitivities`) instead of
        marching again.
    abort_on_failure : bool
        A trial point of the line search whose states cannot be solved ends the iteration (the caller solves
        the full-space NLP instead) rather than halving the step.
    """

    _KEEP = 2
    #: S of a point is added by a second call with ``second_order`` at no other cost (the point is kept): the
    #: line search asks for it only at the point it accepts (:func:`identification.fit.explicit_newton`)
    deferred_second_order = True
    #: Newton steps (with S) from the first point whose Gauss-Newton decrement is below 1e-4 (set by
    #: :func:`identification.fit.explicit_newton.reduced_start` for a collocated ODE)
    early_newton = False

    def __init__(self, problem: ReducedProblem, x0: np.ndarray, Y0: np.ndarray, p0: np.ndarray | None = None,
                 abort_on_failure: bool = False):
        self._problem, self._sp = problem, problem.p_scale
        self.abort_on_failure = abort_on_failure
        self._outer = np.outer(self._sp, self._sp)
        self._seen = [(np.array(x0, float), np.asarray(Y0, float), None)]      # (x, states, point or None)
        # (p0,) when Y0 are the marched states at exactly p0 (initial_states of a reduced-space model)
        self._start = (np.asarray(p0, float),) if p0 is not None else None

    def _nearest(self, x: np.ndarray):
        return min(self._seen, key=lambda e: float(np.max(np.abs(e[0] - x))))

    def point(self, x: np.ndarray) -> ReducedPoint:
        """The reduced point at p = s_p ⊙ x (states, sensitivities, Phi, gradient), evaluated
        once per x; raises StateSolveError when the states cannot be solved there."""
        x = np.asarray(x, float)
        near = self._nearest(x)
        if near[2] is not None and np.array_equal(near[0], x):
            return near[2]
        problem = self._problem
        p = x * self._sp
        if near[2] is None and self._start is not None and np.array_equal(p, self._start[0]):
            # the start of a model solved in the reduced space: its states at p0 are the marched ones the
            # solve below would give, bit for bit, and its sensitivities there are shared by refits
            pt = problem.point_at(p, near[1], start_sensitivities(problem.model, p, problem.data.inputs, near[1]))
            self._seen = ([e for e in self._seen if not np.array_equal(e[0], x)] + [(x.copy(), near[1], pt)])[-self._KEEP:]
            return pt
        # first-order prediction y(p) ~ y(p') + y'(p') (p - p')
        guess = None if near[2] is None else near[1] + near[2].sens.state_derivatives @ (p - near[2].p)
        # a collocated ODE: Newton on all trajectories from it with y'(p) from the last iteration's blocks
        fused = getattr(problem.model.state_numerics, "states_and_sensitivities", None)
        got = None if fused is None else fused(p, problem.data.inputs, guess)
        if got is not None:
            pt = problem.point_at(p, got[0], got[1])
            self._seen = ([e for e in self._seen if not np.array_equal(e[0], x)] + [(x.copy(), got[0], pt)])[-self._KEEP:]
            return pt
        # the model's own solve from it (a collocated ODE: Newton on all trajectories, else marched), if it has one
        Y = problem.model.state_numerics.marched_states(p, problem.data.inputs, guess)
        if Y is None and guess is not None:
            try:
                Y = solve_states_from(problem.model, p, problem.data.inputs, guess)
            except StateSolveError:
                Y = None
        if Y is None:
            Y = solve_states_from(problem.model, p, problem.data.inputs, near[1])
        pt = problem.point_at(p, Y, sensitivities(problem.model, p, problem.data.inputs, Y))
        self._seen = ([e for e in self._seen if not np.array_equal(e[0], x)] + [(x.copy(), Y, pt)])[-self._KEEP:]
        return pt

    def __call__(self, x: np.ndarray, second_order: bool) -> ExplicitTerms:
        """The terms at p = s_p ⊙ x (``S`` when ``second_order``); raises StateSolveError when
        the states cannot be solved."""
        pt = self.point(x)
        problem, sp = self._problem, self._sp
        G = pt.sens.G.reshape(-1, sp.size)
        S = pt.sens.hessians(pt.lam[None])[0] * self._outer if second_order else None
        return ExplicitTerms(pt.objective, pt.gradient * sp, problem.information(pt) * self._outer,
                             (np.abs(pt.lam).reshape(-1) @ np.abs(G)) * sp, S)


def nlp_multipliers(point: ReducedPoint, e_scale: np.ndarray) -> np.ndarray:
    r"""The multipliers lambda_j = mu_j / e of the NLP's scaled constraints e ⊙ E(y_j, p, q_j) = 0
    at a reduced point (see the module docstring), stacked input by input, shape (n_q n_y,).

    At the reduced optimum they make the full-space Lagrangian stationary in the states (and,
    since the reduced gradient J^T lambda is zero there, in the parameters)."""
    mu = point.sens.adjoint(point.lam)
    return (mu / e_scale[None, :]).ravel()
