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
nominal ``p`` and its efficiency against the robust one at every parameter vector.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .candidate_information import information
from .criteria import Kind

__all__ = ["robust_exact_inputs"]


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
        ``refine``, ``kind``, ``costs``, ``budget``, ``bounds``, ``include``, ``exclude`` as given.

    Returns
    -------
    oed.robust_exact.RobustExactDesign
        ``names`` the candidates' labels (``q<j>`` or ``q<j>:<sensor>``), ``local_indices`` the local exact
        design at ``p``, ``local_efficiencies`` its efficiency against the robust design at every prior vector.

    Raises
    ------
    ValueError
        Bad input (the message names the argument), e.g. ``refine=True`` (not implemented with a prior).
    """
    from .prior import make_prior
    from .robust_exact import METHODS, ROBUST, exact_over_prior
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
    return replace(r.design, names=names, local_indices=tuple(r.local.indices),
                   local_efficiencies=tuple(float(e) for e in r.local_efficiencies))


def _refuse(unused: dict) -> None:
    """A clear error naming the first argument of the exact route given that the robust one does not take."""
    if unused.get("refine"):
        raise ValueError("refine: the continuous refinement of an exact robust design (prior given) is not "
                         "implemented; leave refine=False (or drop the prior to refine the local design)")
    if Kind.parse(unused.get("kind", "gauss_newton")) is not Kind.GAUSS_NEWTON:
        raise ValueError("kind: the exact robust design uses the Gauss-Newton information at every parameter "
                         f"vector; give kind='gauss_newton' (got {unused['kind']!r})")
    for k in ("costs", "budget", "bounds"):
        if unused.get(k) is not None:
            raise ValueError(f"{k}: not used by the exact robust design (prior is given: it chooses exactly n_points "
                             "candidates); leave it out")
    for k in ("include", "exclude"):
        if len(unused.get(k, ())):
            raise ValueError(f"{k}: not used by the exact robust design (prior is given); leave it out")
