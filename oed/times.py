r"""Choosing sampling times of a dynamic model (optimal design over time).

With F_{kt} the information of sensor k at time t summed over the experiments (planned at p,
:func:`oed.candidate_information.information` on axis ``times`` or ``pairs``),

.. math::

    \min_{w \in \{0, 1\}^{n_t}} \Psi\Bigl(\bigl(\textstyle\sum_t w_t \sum_k F_{kt}\bigr)^{-1}\Bigr)

chooses the times at which every instrument reads (``pairs=False``), or, over w in {0, 1}^{n_t n_S},
the (time, sensor) pairs (``pairs=True``), by the engine of
:func:`oed.select_sensors_from_information` (exact, with costs, budget, include/exclude and a proven
bound).
"""
from __future__ import annotations

import warnings

import numpy as np

from .criteria import DEFAULT_CRITERION
from .approximate import ApproximateSettings, approximate_design, check_approximate_route
from .design import DesignResult, select_sensors_from_information
from .candidate_information import information

__all__ = ["time_information", "select_times"]


def time_information(model, p, times, inputs, sigma, sensors=None, pairs: bool = False, n_series: int = 1):
    """Deprecated: :func:`oed.information` with ``axis="times"`` (or ``"pairs"``).  (F, names): the planned
    information per sampling time (all chosen instruments), shape (n_t, n_p, n_p), or per (time, sensor) pair
    (``pairs=True``, time-major), and the candidates' names (``0.5`` or ``cA@0.5``), summed over the
    experiments ``inputs``."""
    warnings.warn('oed.time_information is deprecated; use oed.information(model, p, axis="times" (or "pairs"), '
                  'times=..., inputs=..., sigma=...)', DeprecationWarning, stacklevel=2)
    info = information(model, p, axis="pairs" if pairs else "times", times=times, inputs=inputs, sigma=sigma,
                       sensors=sensors, n_series=n_series)
    return info.F, list(info.labels)


def select_times(model, p, times, inputs, sigma, n_times=None, *, max_times=None, pairs: bool = False,
                 sensors=None, criterion: str = DEFAULT_CRITERION, costs=None, budget=None, include=(), exclude=(),
                 method: str = "auto", time_limit: float = 60.0, n_series: int = 1, approximate: bool = False,
                 prior=None, robust: str = "bayes", approx_settings=None, refine: bool = False):
    """The sampling times (or time x sensor pairs) minimising the A, D or E criterion of the planned
    Gauss-Newton covariance of a dynamic model at p (see the module docstring); or, with
    ``approximate=True``, the approximate design (times and weights) on the range of ``times``
    (:func:`oed.approximate.approximate_design`).

    Parameters
    ----------
    model : models.dynamic.DynamicModel
    p : array_like (n_p,)          nominal parameters
    times : array_like             candidate sampling times (strictly increasing, within the horizon)
    inputs : array_like (n_q, d_q) the experiments (every one sampled at the chosen times)
    sigma : float or array (n_S,)  one standard deviation per instrument
    n_times, max_times : int       exact / largest number of chosen candidates
    pairs : bool                   choose (time, sensor) pairs instead of times
    sensors : sequence of str      instruments considered (default all)
    criterion, costs, budget, include, exclude, method, time_limit
                                   as in :func:`oed.select_sensors_from_information` (names are
                                   ``0.5`` for times, ``cA@0.5`` for pairs)
    n_series : int                 repeated series per experiment
    approximate : bool             the approximate design on [min(times), max(times)] (n_times, costs,
                                   budget, include, exclude, max_times and pairs are then not used)
    prior : None, (P, w), dict     parameter uncertainty (:func:`oed.prior.make_prior`): with ``approximate=True``
                                   the robust approximate design, else the exact robust design of n_times
                                   candidates (:func:`oed.robust_exact.select_robust_exact`: enumeration or
                                   branch-and-bound with a proven gap; ``method`` "auto", "enumerate" or "bnb";
                                   maximin standardized by each parameter vector's own exact n_times optimum)
    robust : {"bayes", "maximin"}
    approx_settings : oed.approximate.ApproximateSettings or None
    refine : bool                  with a prior (exact robust design of times, not pairs): also move the chosen
                                   times continuously within [min(times), max(times)]
                                   (:func:`oed.robust_refine.refine_robust_times`; the result's ``refined``)

    Returns
    -------
    DesignResult (``axis`` "times" or "pairs", ``chosen`` the labels), oed.approximate.ApproximateDesign
    with ``approximate=True``, or oed.robust_exact.RobustExactDesign with a prior and ``approximate=False``
    """
    if refine and (prior is None or approximate or pairs):
        raise ValueError("refine: the refinement of sampling times is for exact robust designs of times (a prior, "
                         "approximate=False, pairs=False)")
    if prior is not None and not approximate:
        for k, v in dict(max_times=max_times, costs=costs, budget=budget).items():
            if v is not None:
                raise ValueError(f"{k}: not used by the exact robust design (prior is given: it chooses exactly "
                                 "n_times candidates); leave it out")
        if len(include) or len(exclude):
            raise ValueError(f"{'include' if len(include) else 'exclude'}: not used by the exact robust design "
                             "(prior is given); leave it out")
        return _robust_exact_times(model, p, times, inputs, sigma, sensors, n_series, criterion, prior, robust,
                                   n_times, pairs, method, time_limit, (refine, approx_settings))
    if approximate or prior is not None:
        return _approximate_times(model, p, times, inputs, sigma, sensors, n_series, criterion, prior, robust,
                                  approximate, approx_settings,
                                  dict(n_times=n_times, max_times=max_times, pairs=pairs, costs=costs, budget=budget,
                                       include=include, exclude=exclude))
    info = information(model, p, axis="pairs" if pairs else "times", times=times, inputs=inputs, sigma=sigma,
                       sensors=sensors, n_series=n_series)
    return select_sensors_from_information(info, criterion=criterion, kind="gauss_newton", n_sensors=n_times,
                                           max_sensors=max_times, costs=costs, budget=budget, include=include,
                                           exclude=exclude, method=method, time_limit=time_limit)


def _robust_exact_times(model, p, times, inputs, sigma, sensors, n_series, criterion, prior, robust, n_times, pairs,
                        method, time_limit, refining=(False, None)):
    """The exact robust route of :func:`select_times` (a prior, ``approximate=False``)."""
    from .prior import make_prior
    from .robust_exact import METHODS, select_robust_exact
    if method not in METHODS:
        raise ValueError(f"method: the exact robust design takes 'auto', 'enumerate' or 'bnb', got {method!r}")
    pr = make_prior(prior, model, p)
    axis = "pairs" if pairs else "times"
    infos = [information(model, ps, axis=axis, times=times, inputs=inputs, sigma=sigma, sensors=sensors,
                         n_series=n_series) for ps in pr.points]
    F = np.stack([i.F for i in infos], axis=1)
    n = min(model.n_p, F.shape[0]) if n_times is None else n_times
    kw = dict(criterion=criterion, method=method, time_limit=time_limit,
              names=list(infos[0].labels))
    u_star = None
    if robust == "maximin":
        u_star = np.array([select_robust_exact(F[:, [s]], [1.0], n, **kw).value for s in range(F.shape[1])])
    design = select_robust_exact(F, pr.weights, n, robust=robust, u_star=u_star, **kw)
    if not refining[0]:
        return design
    from dataclasses import replace
    from .robust_refine import refine_robust_times
    return replace(design, refined=refine_robust_times(model, p, design, times, inputs, sigma, pr, u_star,
                                                       criterion=criterion, robust=robust, sensors=sensors,
                                                       n_series=n_series, approx_settings=refining[1]))


def _approximate_times(model, p, times, inputs, sigma, sensors, n_series, criterion, prior, robust, approximate,
                       settings, exact_args):
    """The ``approximate=True`` route of :func:`select_times`."""
    check_approximate_route(approximate, exact_args)
    t = np.asarray(times, float).ravel()
    if t.size == 0 or not np.all(np.isfinite(t)) or not t.max() > t.min():
        raise ValueError("times: approximate designs need a continuous range of times (at least two distinct finite "
                         f"candidate times; the range is [min, max]), got {t}")
    return approximate_design(model, p, sigma=sigma, bounds=(t.min(), t.max()), criterion=criterion, prior=prior,
                              robust=robust, inputs=inputs, sensors=sensors, n_series=n_series,
                              settings=ApproximateSettings() if settings is None else settings)
