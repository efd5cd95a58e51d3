r"""One experiment of a sequential design under a prior: the robust choice of n sensors at the current estimate.

Before experiment k the estimate is :math:`p_{k-1}` (:math:`p_0` the nominal); the prior
:math:`\{(P_s, \pi_s)\}` given around :math:`p_0` is moved with it, :math:`P^{(k)}_s = p_{k-1} + (P_s - p_0)`
(its spread kept; a point prior at :math:`p_0` becomes exactly :math:`p_{k-1}`), and with
:math:`F_{l,s}` (:math:`S_{l,s}`) the information (second-order term) of sensor l at :math:`P^{(k)}_s` from the
data available before experiment k (:func:`oed.candidate_information.information`), the next set of n sensors
solves, exactly,

.. math::

    \max_{|S| = n} \sum_s \pi_s u_s(S)\ \ (\text{bayes}),\qquad \max_{|S| = n} \min_s c_s(S)\ \ (\text{maximin}),

with :math:`u_s(S) = -\Psi(C_s(S))` of the local engine's covariance of the set at :math:`P^{(k)}_s`
(:func:`oed.criteria.batch_criteria`: D :math:`\log\det C`, A :math:`\operatorname{tr}C`, E
:math:`\lambda_{\max}(C)`), Gauss-Newton :math:`C = (\sum_{l\in S} F_{l,s})^{-1}` or the paper's second-order
(Bard) :math:`C = H^{-1}(\sum_{l\in S}F_{l,s})H^{-1}`, :math:`H = \sum_{l\in S}(F_{l,s} + S_{l,s})`, and
:math:`c_s` standardized against each vector's own best n-set :math:`u^*_s` (D: :math:`(u_s - u^*_s)/n_p`, A, E:
:math:`u_s/|u^*_s|`; :mod:`oed.robust`).  Gauss-Newton: :func:`oed.robust_exact.select_robust_exact`
(enumeration or branch-and-bound with a proven gap; its per-run scaling :math:`M/n` leaves the argmax unchanged).
Second order: complete enumeration (every set's covariance at every vector; the branch-and-bound bounds are
Gauss-Newton only).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace

import numpy as np

from .approx_weights import standardized
from .criteria import Criterion, Kind, batch_criteria
from .prior import Prior, readonly

__all__ = ["RobustStep", "recentred", "robust_sensor_step", "robust_sensor_design", "ENUMERATION_MAX"]

#: largest number of sets the second-order robust step enumerates
ENUMERATION_MAX = 200_000


@dataclass(frozen=True)
class RobustStep:
    """The robust choice of one experiment.

    Attributes
    ----------
    indices : tuple of int        the chosen sensors
    value : float                 bayes: sum_s pi_s u_s; maximin: min_s c_s (D: log of the worst-case efficiency)
    per_sample : ndarray (n_s,)   u_s of the chosen set at every vector
    worst_case_efficiency : float the chosen set's smallest efficiency against each vector's own best n-set
    proven_optimal : bool
    method : str                  "enumerate" or "bnb"
    gap : float                   proven gap (0 when proven)
    prior : Prior                 the prior moved to the current estimate
    """

    indices: tuple
    value: float
    per_sample: np.ndarray
    worst_case_efficiency: float
    proven_optimal: bool
    method: str
    gap: float
    prior: Prior


def recentred(prior: Prior, p0, p) -> Prior:
    r"""The prior moved from the nominal ``p0`` to the estimate ``p``: points :math:`p + (P_s - p_0)` (computed in that
    order, so a point prior at ``p0`` gives ``p`` to the bit), weights unchanged."""
    p0, p = np.asarray(p0, float), np.asarray(p, float)
    return replace(prior, points=readonly(p[None, :] + (np.asarray(prior.points) - p0[None, :])), nominal=readonly(p))


def _efficiency(crit, u, u_star, n_p):
    """Efficiency of utilities u against u_star: D exp((u - u*)/n_p), A, E u*/u."""
    return np.exp((u - u_star) / n_p) if crit is Criterion.D else u_star / u


def robust_sensor_step(infos, prior: Prior, n: int, *, criterion, kind, robust, method, time_limit) -> RobustStep:
    r"""The exact robust choice of ``n`` sensors (module docstring) from ``infos``, one
    :class:`oed.candidate_information.CandidateInformation` per vector of ``prior`` (same order).

    Raises
    ------
    ValueError
        ``method`` not "auto"/"enumerate"/"bnb" ("bnb" with ``kind="second_order"``), more than
        :data:`ENUMERATION_MAX` sets of a second-order step, or no set of n sensors regular at every vector.
    """
    crit, kind_e = Criterion.parse(criterion), Kind.parse(kind)
    if method not in ("auto", "enumerate", "bnb"):
        raise ValueError(f"method: the robust sequential design takes 'auto', 'enumerate' or 'bnb', got {method!r}")
    F = np.stack([np.asarray(i.F, float) for i in infos], axis=1)
    n_p = F.shape[-1]
    if kind_e is Kind.GAUSS_NEWTON:
        return _gauss_newton(F, prior, n, crit, robust, method, time_limit)
    if method == "bnb":
        raise ValueError("method: the second-order robust step is solved by enumeration (the branch-and-bound "
                         "bounds are Gauss-Newton); give method='auto' or 'enumerate'")
    total = math.comb(F.shape[0], n)
    if total > ENUMERATION_MAX:
        raise ValueError(f"n_sensors: {total} sets of {n} of {F.shape[0]} sensors exceed the second-order robust "
                         f"step's enumeration limit {ENUMERATION_MAX}; use kind='gauss_newton' (branch-and-bound)")
    sets = np.array(list(itertools.combinations(range(F.shape[0]), n)), dtype=int)
    W = np.zeros((sets.shape[0], F.shape[0]))
    W[np.arange(sets.shape[0])[:, None], sets] = 1.0
    psi = {Criterion.A: "A", Criterion.D: "logdet", Criterion.E: "E"}[crit]
    U = np.stack([-getattr(batch_criteria(infos[s].F, infos[s].S, W, kind_e), psi) for s in range(prior.n)], axis=1)
    U = np.where(np.isfinite(U), U, -np.inf)
    u_star = U.max(axis=0)
    if not np.all(np.isfinite(u_star)):
        raise ValueError(f"n_sensors: no set of {n} sensors gives a regular covariance at every parameter vector")
    if robust == "bayes":
        vals = np.where(np.all(np.isfinite(U), axis=1), U @ prior.weights, -np.inf)
    else:
        vals = np.min(standardized(crit, U, u_star[None, :], n_p)[0], axis=1)
        vals = np.where(np.all(np.isfinite(U), axis=1), vals, -np.inf)
    k = int(np.argmax(vals))
    eff = float(np.min(_efficiency(crit, U[k], u_star, n_p)))
    return RobustStep(indices=tuple(int(i) for i in sets[k]), value=float(vals[k]), per_sample=readonly(U[k]),
                      worst_case_efficiency=eff, proven_optimal=True, method="enumerate", gap=0.0, prior=prior)


def _gauss_newton(F, prior, n, crit, robust, method, time_limit) -> RobustStep:
    """The Gauss-Newton step by :func:`oed.robust_exact.select_robust_exact`, each vector's own optimum first."""
    from .robust_exact import select_robust_exact
    kw = dict(criterion=crit.value, method=method, time_limit=time_limit)
    u_star = np.array([select_robust_exact(F[:, [s]], [1.0], n, **kw).value for s in range(F.shape[1])])
    r = select_robust_exact(F, prior.weights, n, robust=robust, u_star=u_star if robust == "maximin" else None, **kw)
    eff = float(np.min(_efficiency(crit, np.asarray(r.per_sample), u_star, F.shape[-1])))
    return RobustStep(indices=r.indices, value=r.value, per_sample=r.per_sample, worst_case_efficiency=eff,
                      proven_optimal=r.proven_optimal, method=r.method, gap=r.gap, prior=prior)


def robust_sensor_design(infos, prior: Prior, n: int, *, criterion, kind, robust, method, time_limit, names=None):
    r"""The robust choice of ``n`` sensors of :func:`robust_sensor_step` as an
    :class:`oed.robust_exact.RobustExactDesign` (``select_sensors(..., prior=, kind="second_order")`` with data:
    the second-order covariance at every vector, by enumeration); ``efficiency`` the worst-case efficiency for
    maximin (nan for bayes)."""
    import time
    from .robust_exact import RobustExactDesign
    t0 = time.perf_counter()
    step = robust_sensor_step(infos, prior, n, criterion=criterion, kind=kind, robust=robust, method=method,
                              time_limit=time_limit)
    labels = tuple(infos[0].labels) if names is None else tuple(names)
    n_sets = math.comb(np.asarray(infos[0].F).shape[0], n) if step.method == "enumerate" else 0
    return RobustExactDesign(indices=step.indices, names=tuple(labels[i] for i in step.indices), value=step.value,
                             per_sample=step.per_sample, proven_optimal=step.proven_optimal, n_designs=n_sets,
                             efficiency=step.worst_case_efficiency if robust == "maximin" else float("nan"),
                             criterion=Criterion.parse(criterion).value, robust=robust,
                             wall_time=time.perf_counter() - t0, method=step.method, upper_bound=step.value,
                             gap=step.gap, notes=(f"{Kind.parse(kind).value} covariance at every parameter vector "
                                                  "(u = -Psi(C)), every set enumerated",))
