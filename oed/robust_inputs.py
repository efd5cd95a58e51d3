r"""Exact robust input designs: ``n_points`` of the candidate input rows (or (row, sensor) pairs) over a prior.

With :math:`F_{c,s}` the planned information of one run of candidate c (a row :math:`q_j` with every measured
sensor, or a pair :math:`(q_j, k)`; a dynamic model's row is an experiment read at its sampling times) at the
parameter vector :math:`P_s` of the prior (:func:`oed.candidate_information.information`, axis ``inputs`` or
``input_pairs``, evaluated at every :math:`P_s`; units 1/param unit^2), and
:math:`M_s(S) = \frac1n\sum_{c\in S}F_{c,s}`, solved:

.. math::

    \max_{|S| = n} \sum_s \pi_s u(M_s(S))\ \ (\text{bayes}),\qquad
    \max_{|S| = n} \min_s c_s(S)\ \ (\text{maximin}),

by :func:`oed.robust_exact.exact_over_prior` (enumeration when small, else branch-and-bound with a proven gap;
maximin standardized by each vector's own exact n-run optimum), which also gives the local exact design at the
nominal ``p`` and its efficiency against the robust one at every parameter vector.  With ``refine=True`` the
chosen rows then move continuously within ``bounds`` (default the candidates' range) to raise the same criterion
(:mod:`oed.robust_refine`), and a static model's refined design is compared with the approximate robust design.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .candidate_information import information
from .criteria import Kind

__all__ = ["robust_exact_inputs", "refine_robust_inputs"]


def robust_exact_inputs(model, p, *, candidates, sigma, n_points, sensors, criterion, prior, robust, n_series, times,
                        discretisation, method, time_limit, unused: dict):
    r"""The exact robust design :math:`\max_{|S|=n}` of the module docstring, with ``unused`` the arguments of
    :func:`oed.inputs.select_inputs` that this route does not take (any given is refused, named).

    Parameters
    ----------
    model, p, candidates, sigma, sensors, n_series, times, discretisation
        As in :func:`oed.inputs.select_inputs` (``sensors="joint"``: the candidates are (row, sensor) pairs).
    n_points : int
        Candidates chosen (distinct).
    criterion : {"A", "D", "E"}
    prior : (P, w), dict or oed.prior.Prior
        :func:`oed.prior.make_prior` around ``p``.
    robust : {"bayes", "maximin"}
    method : {"auto", "enumerate", "bnb"}
    time_limit : float
        Seconds per :func:`oed.robust_exact.select_robust_exact` solve (the information is not counted).
    unused : dict
        ``refine``, ``kind``, ``costs``, ``budget``, ``bounds``, ``include``, ``exclude`` as given (``refine`` and
        ``bounds`` are used: the continuous refinement of the chosen rows within ``bounds``,
        :func:`refine_robust_inputs`).

    Returns
    -------
    oed.robust_exact.RobustExactDesign
        ``names`` the candidates' labels (``q<j>`` or ``q<j>:<sensor>``), ``local_indices`` the local exact
        design at ``p``, ``local_efficiencies`` its efficiency against the robust design at every prior vector,
        ``refined`` the continuous refinement (``refine=True``).

    Raises
    ------
    ValueError
        Bad input (the message names the argument), e.g. ``refine=True`` of a joint (row, sensor) design.
        ``kind="second_order"`` is taken: planned without data S = 0 at every vector, so it is the Gauss-Newton
        design (noted in ``notes``).
    """
    from .prior import make_prior
    from .robust_exact import METHODS, ROBUST, exact_over_prior
    Kind.parse(unused.get("kind", "gauss_newton"))          # a bad kind names the argument
    _refuse(unused)
    if method not in METHODS:
        raise ValueError(f"method: the exact robust design takes 'auto', 'enumerate' or 'bnb', got {method!r}")
    if robust not in ROBUST:
        raise ValueError(f"robust: expected one of {ROBUST}, got {robust!r}")
    if isinstance(n_points, bool) or not isinstance(n_points, (int, np.integer)) or n_points < 1:
        raise ValueError(f"n_points: the exact robust design needs the number of candidates chosen (an integer >= 1), "
                         f"got {n_points!r}")
    pr = make_prior(prior, model, p)
    joint = isinstance(sensors, str) and sensors == "joint"
    if joint and unused.get("refine"):
        raise ValueError("refine: the continuous refinement is for input designs (sensors=None or names), not for "
                         "joint input-sensor designs")
    axis = "input_pairs" if joint else "inputs"
    labels = []

    def information_at(ps):
        info = information(model, ps, axis=axis, candidates=candidates, sigma=sigma, sensors=sensors,
                           n_series=n_series, times=times, discretisation=discretisation)
        if not labels:
            labels.extend(info.labels)
            if n_points > len(labels):
                raise ValueError(f"n_points: expected an integer in 1..{len(labels)} (the number of candidate "
                                 f"{'pairs' if joint else 'rows'}), got {n_points!r}")
        return info.F

    try:
        r = exact_over_prior(information_at, pr, p, int(n_points), criterion=criterion, robust=robust, names=None,
                             time_limit=time_limit, method=method)
    except ValueError as exc:
        if str(exc).startswith("n: "):      # the engine's number of runs is this verb's n_points
            raise ValueError("n_points: " + str(exc)[3:]) from None
        raise
    names = tuple(labels[i] for i in r.design.indices)
    refined = None
    if unused.get("refine"):
        refined = refine_robust_inputs(model, p, candidates, r.design.indices, pr, r.u_star, sigma=sigma,
                                       sensors=sensors, n_series=n_series, times=times, discretisation=discretisation,
                                       criterion=criterion, robust=robust, bounds=unused.get("bounds"))
    notes = ()
    if Kind.parse(unused.get("kind", "gauss_newton")) is Kind.SECOND_ORDER:
        notes = ("kind='second_order' planned without data: expected residual 0, S = 0 at every parameter vector, "
                 "so the design is the Gauss-Newton one",)
    return replace(r.design, names=names, local_indices=tuple(r.local.indices),
                   local_efficiencies=tuple(float(e) for e in r.local_efficiencies), refined=refined, notes=notes)


def refine_robust_inputs(model, p, candidates, indices, prior, u_star, *, sigma, sensors, n_series, times,
                         discretisation, criterion, robust, bounds=None, settings=None):
    r"""The continuous refinement (:func:`oed.robust_refine.refine_robust`) of the exact robust design's rows
    ``candidates[indices]`` within ``bounds`` (default the candidates' range; first spacing per input the smallest
    gap between the candidates' distinct values), and for a static model its efficiency against the approximate
    robust design on the same range (:func:`oed.approximate.approximate_design`, same prior points).

    Returns
    -------
    oed.robust_refine.RobustRefined
    """
    from .approx_polish import explicit_polisher
    from .approximate import approximate_design
    from .robust_refine import RobustRefineSettings, refine_robust
    if isinstance(sensors, str) and sensors == "joint":
        raise ValueError("refine: the continuous refinement is for input designs (sensors=None or names), not for "
                         "joint input-sensor designs")
    Q = np.asarray(candidates, float)
    Q = Q[:, None] if Q.ndim == 1 else Q
    lo, hi = (Q.min(axis=0), Q.max(axis=0)) if bounds is None else (
        np.broadcast_to(np.asarray(b, float).ravel(), (Q.shape[1],)).copy() for b in bounds)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo <= hi)) or not np.any(hi > lo):
        raise ValueError(f"bounds: the refinement needs finite lower <= upper with a range in at least one input, "
                         f"got {lo}, {hi}")
    spacing = np.array([np.min(np.diff(np.unique(c))) if np.unique(c).size > 1 else (b - a) / 4.0
                        for c, a, b in zip(Q.T, lo, hi)])

    def info(X, P):
        return np.stack([information(model, ps, axis="inputs", candidates=X, sigma=sigma, sensors=sensors,
                                     n_series=n_series, times=times, discretisation=discretisation).F for ps in P],
                        axis=1)
    static = times is None
    sens = None if sensors is None else list(np.atleast_1d(sensors))
    polisher = explicit_polisher(model, prior.points, sigma, sens, n_series) if static else None
    approx = approximate_design(model, p, sigma=sigma, bounds=(lo, hi), criterion=criterion, prior=prior,
                                robust=robust, sensors=sensors, n_series=n_series) if static else None
    return refine_robust(info, Q[list(indices)], prior, (lo, hi), criterion=criterion, robust=robust, u_star=u_star,
                         spacing=spacing, names=tuple(f"q{j}" for j in range(Q.shape[1])), polisher=polisher,
                         approximate=approx, settings=settings or RobustRefineSettings())


def _refuse(unused: dict) -> None:
    """A clear error naming the first argument of the exact route given that the robust one does not take."""
    if unused.get("bounds") is not None and not unused.get("refine"):
        raise ValueError("bounds: used only by the refinement of the exact robust design (refine=True); leave it out")
    for k in ("costs", "budget"):
        if unused.get(k) is not None:
            raise ValueError(f"{k}: not used by the exact robust design (prior is given: it chooses exactly n_points "
                             "candidates); leave it out")
    for k in ("include", "exclude"):
        if len(unused.get(k, ())):
            raise ValueError(f"{k}: not used by the exact robust design (prior is given); leave it out")
