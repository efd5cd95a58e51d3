r"""Exact reduced-space Newton refinement of a weighted least-squares estimate.

In the reduced space the states are eliminated through E(y_j, p, q_j) = 0 and the
objective of paper eq. 3 is a function of p alone,

.. math::

    \Phi(p) = \tfrac12 \sum_{j,k} c_{jk}\,(\bar z_{jk} - h_k(y_j(p), p, q_j))^2 / \sigma_k^2 + \Phi_0,

with c_jk = (number of series) w_k per input and sensor, zbar the per-(input, sensor)
means and Phi_0 the constant within-group scatter.  Its gradient is g = J^T lambda with
lambda_jk = dPhi/dh_jk = -c_jk (zbar_jk - h_jk) / sigma_k^2, and its exact Hessian is
H = J^T Omega J + S with S the second-order term (by AD and the implicit function theorem,
:meth:`models.sensitivity.Sensitivities.hessians`).  :func:`refine` takes Newton steps
p <- p - H^{-1} g, solved through the QR factor of the weighted Jacobian
(H = D^{-1} R^T K R D^{-1}, :mod:`identification.fit.factor`), while they decrease Phi (or, where
Phi cannot resolve the decrease, while the decrement falls) down to the stated tolerance or to
round-off, and says why it stopped.

The estimator (:func:`identification.identify`) refines Ipopt's solution with it, and the
likelihood-ratio test of :mod:`identification.studies.detect` finds the pooled minimum with it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from models.contract import Model
from models.errors import StateSolveError
from models.sensitivity import Sensitivities, sensitivities
from models.state import solve_states
from identification.fit import dense
from identification.fit import newton as newton_core
from identification.fit.factor import WeightedFactor, newton_system, weighted_factor, weighted_rows
from identification.fit.measurements import Measurements, data_terms

__all__ = ["ReducedProblem", "ReducedPoint", "Refinement", "refine", "gauss_newton_information",
           "newton_decrement"]


def gauss_newton_information(G: np.ndarray, cw: np.ndarray, sig: np.ndarray) -> np.ndarray:
    """J^T Omega J = sum_jk c_jk G_jk^T G_jk / sigma_k^2, shape (n_p, n_p).

    ``G`` (n_q, n_S, n_p) sensitivities, ``cw`` (n_q, n_S) weighted counts, ``sig`` (n_S,).
    One matrix product over the rows (j, k) (BLAS; an einsum of the three factors took 50 ms
    for 1e6 rows).
    """
    A = G.reshape(-1, G.shape[-1])
    return (A * (cw / sig ** 2).reshape(-1, 1)).T @ A


def newton_decrement(H: np.ndarray, grad: np.ndarray, s_p: np.ndarray) -> float:
    """g^T H^{-1} g in objective (chi^2 / 2) units; inf when H is not positive definite.

    ``s_p``: parameter scales (the Cholesky factorisation is of diag(s_p) H diag(s_p)).
    """
    L = dense.cholesky_lower(H * np.outer(s_p, s_p))
    if L is None:
        return float("inf")
    v = dense.tri_solve(L, grad * s_p)
    return float(v @ v)


@dataclass(frozen=True)
class ReducedPoint:
    """The reduced-space objective at one parameter vector.

    Attributes
    ----------
    p : ndarray (n_p,)            parameters
    states : ndarray (n_q, n_y)   states y_j(p)
    sens : Sensitivities          outputs h and sensitivities G at p
    objective : float             Phi(p) (chi^2 / 2 units when sigma is the sensors' sigma)
    gradient : ndarray (n_p,)     dPhi/dp
    lam : ndarray (n_q, n_S)      dPhi/dh_jk = -c_jk (zbar_jk - h_jk) / sigma_k^2
    """

    p: np.ndarray
    states: np.ndarray
    sens: Sensitivities
    objective: float
    gradient: np.ndarray
    lam: np.ndarray


@dataclass(frozen=True)
class ReducedProblem:
    """A weighted least-squares problem in the reduced space (see the module docstring).

    Build it with :meth:`of`, which computes the data terms once.

    Attributes
    ----------
    model : models.Model
    data : Measurements
    weights : ndarray (n_S,)    sensor weights w_k
    sigma : ndarray (n_S,)      sensor standard deviations (same unit as z)
    p_scale : ndarray (n_p,)    parameter scales s_p (same unit as p) of the Newton steps
    zbar : ndarray (n_q, n_S)   per-(input, sensor) means (0 where no value)
    cw : ndarray (n_q, n_S)     weighted counts c_jk = n_jk w_k
    const : float               within-group scatter Phi_0
    """

    model: Model
    data: Measurements
    weights: np.ndarray
    sigma: np.ndarray
    p_scale: np.ndarray
    zbar: np.ndarray
    cw: np.ndarray
    const: float

    @classmethod
    def of(cls, model: Model, data: Measurements, weights, sigma, p_scale) -> "ReducedProblem":
        """The problem of ``data`` with sensor weights and sigmas (1-D arrays of length n_S)."""
        w = np.asarray(weights, float)
        sig = np.asarray(sigma, float)
        terms = data_terms(data.z, w, sig)
        zbar, cw, const = terms.zbar, terms.cw, float(terms.const)
        return cls(model, data, w, sig, np.asarray(p_scale, float), zbar, cw, const)

    def evaluate(self, p: np.ndarray, states0=None) -> ReducedPoint:
        """States (solved from the guess ``states0``), sensitivities, Phi and dPhi/dp at p.

        Raises
        ------
        StateSolveError
            When the state equation cannot be solved at p.
        """
        Y = solve_states(self.model, p, self.data.inputs, Y0=states0)
        return self.point_at(p, Y, sensitivities(self.model, p, self.data.inputs, Y))

    def point_at(self, p: np.ndarray, Y: np.ndarray, sens: Sensitivities) -> ReducedPoint:
        """Phi, dPhi/dp and lambda at p from the states ``Y`` solved there and their
        sensitivities ``sens`` (what :meth:`evaluate` does after the state solve)."""
        dev = self.zbar - sens.h
        with np.errstate(over="ignore"):            # a trial point far off may overflow: f = inf
            f = 0.5 * float(np.sum(self.cw * dev ** 2 / self.sigma ** 2)) + self.const
        lam = -self.cw * dev / self.sigma ** 2                      # d f / d h_jk
        grad = lam.reshape(-1) @ sens.G.reshape(-1, sens.G.shape[-1])
        return ReducedPoint(p, Y, sens, f, grad, lam)

    def information(self, point: ReducedPoint) -> np.ndarray:
        """J^T Omega J at a point (see :func:`gauss_newton_information`)."""
        return gauss_newton_information(point.sens.G, self.cw, self.sigma)


@dataclass(frozen=True)
class Refinement:
    """The result of :func:`refine`.

    Attributes
    ----------
    point : ReducedPoint          the refined point
    S : ndarray (n_p, n_p)        second-order term of the Hessian at ``point.p``
    information : ndarray         J^T Omega J at ``point.p``
    decrement : float             Newton decrement g^T (J^T Omega J + S)^{-1} g (objective units;
                                  inf when the Hessian is not positive definite)
    steps : int                   Newton steps taken
    stop_reason : str             why the refinement stopped (see :func:`refine`)
    factor : WeightedFactor       QR factor of the column-normalised sqrt(Omega) J at ``point.p``
                                  (:mod:`identification.fit.factor`; None if not computed)
    """

    point: ReducedPoint
    S: np.ndarray
    information: np.ndarray
    decrement: float
    steps: int
    stop_reason: str = ""
    factor: WeightedFactor | None = None


#: the gradient's round-off bound: this many ulps of sum |lambda_jk| |G_jk|
_GRAD_ULPS = newton_core.GRAD_ULPS


def _gradient_roundoff(problem: ReducedProblem, point: ReducedPoint, system) -> float:
    """The decrement that round-off alone produces (objective units), the larger of

    * the gradient's sum over the data: e^T H^{-1} e with e = 16 eps sum_jk |lambda_jk| |G_jk|
      (the test of the batch engine);
    * the residuals' own round-off e_jk = 16 eps (|zbar_jk| + |h_jk|): the Newton step moves p by
      the projection of the weighted residual errors onto the n_p columns of sqrt(Omega) J, whose
      squared norm is about n_p max_jk c_jk e_jk^2 / sigma_k^2.
    """
    eps16 = _GRAD_ULPS * np.finfo(float).eps
    G = point.sens.G.reshape(-1, point.p.size)
    grad = newton_core.gradient_roundoff(system.whiten, np.abs(point.lam).reshape(-1) @ np.abs(G))
    e2 = problem.cw / problem.sigma ** 2 * (eps16 * (np.abs(problem.zbar) + np.abs(point.sens.h))) ** 2
    return max(grad, point.p.size * float(e2.max(initial=0.0)))


def point_factor(problem: ReducedProblem, point: ReducedPoint) -> WeightedFactor:
    """The QR factor of the column-normalised sqrt(Omega) J at ``point`` (a stack of one)."""
    return weighted_factor(weighted_rows(point.sens.G, problem.cw, problem.sigma)[None])


def _decrement(fac: WeightedFactor, point: ReducedPoint, S: np.ndarray) -> float:
    """g^T H^{-1} g through the factor; inf when H is not positive definite."""
    system = newton_system(fac, S)
    return float("inf") if system is None else system.step(point.gradient)[1]


def _objective_roundoff(problem: ReducedProblem, point: ReducedPoint) -> float:
    """A bound of the round-off of Phi from the residuals' own round-off:
    16 eps sum_jk |lambda_jk| (|zbar_jk| + |h_jk|) (lambda = dPhi/dh)."""
    return _GRAD_ULPS * np.finfo(float).eps * float(np.sum(np.abs(point.lam) * (np.abs(problem.zbar)
                                                                                 + np.abs(point.sens.h))))


def refine(problem: ReducedProblem, start: ReducedPoint, max_steps: int, stop_decrement: float = 0.0,
           start_S: np.ndarray | None = None, *, dof: int | None = None,
           quadratic_decrement: float = 1e-10) -> Refinement:
    """Exact reduced Newton steps p <- p - (J^T Omega J + S)^{-1} g from ``start``.

    ``start_S``: the second-order term S at ``start.p`` when the caller has it already (saves
    one evaluation of the second derivatives).  ``dof``: with sigma unknown, n - n_p; the
    decrements ``stop_decrement`` and ``quadratic_decrement`` are then in chi^2 units of the
    estimated sigma (unit 2 Phi / dof of the objective), else in objective units.

    A step is taken while the Hessian is positive definite and the state solves succeed.  It is
    kept when Phi does not increase, or, in the quadratic region (decrement below
    ``quadratic_decrement``, or the predicted decrease dec / 2 below 10 times the round-off of Phi:
    Phi cannot resolve the decrease any more), when the decrement falls.  ``stop_reason`` says why it stopped:

    * ``"converged"``: decrement g^T H^{-1} g below ``stop_decrement``;
    * ``"round-off of the gradient"``: decrement below the one round-off in the residuals and the
      gradient's sum over the data produces (the tolerance cannot be resolved in double precision);
    * ``"round-off of p"``: the Newton step is below 8 ulps of every parameter;
    * ``"no progress at round-off"``: in the quadratic region the step raised both Phi and the
      decrement (the previous point is kept: the achieved decrement is the attainable one);
    * ``"objective increased"``: outside the quadratic region a Newton step increased Phi;
    * ``"Hessian not positive definite"``, ``"state solve failed"``, ``"max_steps"``.

    Steps are clipped to the model's parameter bounds.
    """
    at = _At(problem, start, S=start_S)
    steps, reason, dec = 0, "max_steps", None
    for _ in range(max_steps):
        system = newton_system(at.filled().fac, at.S)
        if system is None:
            dec, reason = float("inf"), "Hessian not positive definite"
            break
        dp, dec = system.step(at.point.gradient)
        unit = _unit(at.point, dof)
        reason = _stop_reason(problem, at.point, system, dp, dec, stop_decrement * unit)
        if reason:
            break
        new, reason = _newton_step(problem, at, dp, dec, quadratic_decrement * unit)
        if new is None:
            break
        at, dec, reason = new, None, "max_steps"
        steps += 1
    at.filled()
    if dec is None:
        dec = _decrement(at.fac, at.point, at.S)
    if reason == "max_steps" and dec < stop_decrement * _unit(at.point, dof):
        reason = "converged"
    return Refinement(at.point, at.S, at.F, dec, steps, reason, at.fac)


@dataclass
class _At:
    """A point of :func:`refine` with its second-order term, information and factor (on demand)."""

    problem: ReducedProblem
    point: ReducedPoint
    S: np.ndarray | None = None
    F: np.ndarray | None = None
    fac: WeightedFactor | None = None

    def filled(self) -> "_At":
        if self.S is None:
            self.S = self.point.sens.hessians(self.point.lam[None])[0]
        if self.F is None:
            self.F = self.problem.information(self.point)
        if self.fac is None:
            self.fac = point_factor(self.problem, self.point)
        return self


def _unit(point: ReducedPoint, dof: int | None) -> float:
    """Objective units per decrement unit: 1, or 2 Phi / dof with sigma unknown."""
    return newton_core.decrement_unit(point.objective, dof)


def _stop_reason(problem: ReducedProblem, point: ReducedPoint, system, dp: np.ndarray, dec: float,
                 tol: float) -> str:
    """Why :func:`refine` stops before the step dp ("" when it does not): the convergence test of
    :func:`identification.fit.newton.converged`, naming which bound it met."""
    if newton_core.converged(dec, tol, _gradient_roundoff(problem, point, system)):
        return "converged" if dec <= tol else "round-off of the gradient"
    if np.all(np.abs(dp) <= 8 * np.finfo(float).eps * np.abs(point.p)):
        return "round-off of p"
    return ""


def _newton_step(problem: ReducedProblem, at: _At, dp: np.ndarray, dec: float, quadratic: float) -> tuple:
    """(the point after the step, "") when it is kept, else (None, the reason to stop): kept when Phi
    does not increase or, in the quadratic region (dec <= ``quadratic`` or dec below 20 times Phi's
    round-off), when the decrement falls."""
    model, point = problem.model, at.point
    try:
        new = _At(problem, problem.evaluate(newton_core.trial_point(point.p, dp, 1.0, model.lower, model.upper),
                                            point.states))
    except StateSolveError:
        return None, "state solve failed"
    if newton_core.no_increase(new.point.objective, point.objective):
        return new, ""
    if not newton_core.in_quadratic_region(dec, max(quadratic, 20 * _objective_roundoff(problem, point))):
        return None, "objective increased"
    # the quadratic region: kept while the decrement falls (identification.fit.newton.keep_step)
    if not newton_core.keep_step(new.point.objective, point.objective, True,
                                 _decrement(new.filled().fac, new.point, new.S), dec):
        return None, "no progress at round-off"
    return new, ""
