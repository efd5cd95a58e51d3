"""Which inputs to apply: the front door of input design, for static and dynamic models.

:func:`select_inputs` hands a dynamic model (:meth:`models.Model.ode`) to
:func:`oed.dynamic_inputs.select_dynamic_inputs` and a static one to the engine
:func:`oed.static_inputs.select_static_inputs` (the exact design over candidate rows and its
continuous refinement; the equations are in :mod:`oed.static_inputs`), on which the dynamic design
is built.  The other names are those of :mod:`oed.static_inputs`.
"""
from __future__ import annotations

import numpy as np

from .approximate import ApproximateSettings, approximate_design, check_approximate_route
from .design import DesignSettings
from .dynamic_inputs import select_dynamic_inputs
from .static_inputs import (InputDesignResult, RefinedInputs, RefineSettings, input_information, refine_inputs,
                            select_static_inputs)

__all__ = ["InputDesignResult", "RefinedInputs", "RefineSettings", "input_information", "select_inputs",
           "refine_inputs"]


def select_inputs(model, p, *, candidates, sigma, n_points=None, sensors=None, criterion="D", kind="gauss_newton",
                  costs=None, budget=None, include=(), exclude=(), n_series=1, method="auto", time_limit=60.0,
                  refine=False, bounds=None, refine_settings: RefineSettings = RefineSettings(),
                  settings: DesignSettings = DesignSettings(), times=None, discretisation=None,
                  approximate: bool = False, prior=None, robust: str = "bayes",
                  approx_settings: ApproximateSettings = ApproximateSettings()):
    r"""Exact optimal choice of ``n_points`` input rows (or input-sensor pairs), optionally refined; or, with
    ``approximate=True``, the approximate design :math:`\max_\xi \sum_s \pi_s u(M_s(\xi))` (or its maximin)
    on the continuous input range (:func:`oed.approximate.approximate_design`).

    Parameters
    ----------
    model : models.Model or models.dynamic.DynamicModel
    p : array_like, shape (n_p,)
        Nominal parameters (within the model's bounds).
    candidates : array_like, shape (n_candidates, d_q)
        Candidate input rows (finite, no duplicates).
    sigma : array_like, shape (n_S,) or float
        Sensor standard deviations (sensor units).
    n_points : int
        (Exact designs, required.)  Number of candidates chosen: input rows, or (row, sensor) pairs
        with ``sensors="joint"``.
    sensors : None, "joint" or sequence of str
        None: every sensor measured at each chosen input; names: those sensors; ``"joint"``:
        the candidates are all (row, sensor) pairs and the sensors are chosen with the inputs.
    criterion : {"A", "D", "E"}
    kind : {"gauss_newton", "second_order"}
        Without data both are the Gauss-Newton criterion (S = 0 at the nominal p; noted).
    costs, budget, include, exclude
        As in :func:`oed.design.select_sensors_from_information`, per candidate (row or pair index).
    n_series : int
        Repetitions of every chosen input.
    method, time_limit, settings
        Engine route (``auto``, ``enumerate``, ``bnb``, ``scip``) and its limits.
    refine : bool
        Also refine the chosen levels continuously (:func:`refine_inputs`, not for joint designs).
    bounds : (array_like, array_like) or None
        Input bounds for the refinement, shape (d_q,) each; default the candidates' range.

    times : array_like or None
        Dynamic models (:meth:`models.Model.ode`) only: the sampling times of every experiment;
        then ``sigma`` is one per instrument, ``sensors`` names instruments and the candidates are
        input rows with the control profiles (:func:`oed.dynamic_inputs.select_dynamic_inputs`).
    discretisation : identification.DiscretisationSettings or None
        Dynamic models: the collocation's tolerance.
    approximate : bool
        Static models: return the approximate design (support points and weights with the
        equivalence-theorem certificate) on ``bounds`` (default the candidates' range), not an exact
        n-run design; ``n_points``, costs, budget, include/exclude, refine and method are then not used.
    prior : None, (P, w), dict or oed.prior.Prior
        Parameter uncertainty (:func:`oed.prior.make_prior`); only with ``approximate=True`` (exact
        robust designs are not implemented).
    robust : {"bayes", "maximin"}
        With a prior: pseudo-Bayesian or standardized maximin criterion.
    approx_settings : oed.approximate.ApproximateSettings

    Returns
    -------
    InputDesignResult, or oed.approximate.ApproximateDesign with ``approximate=True``

    Raises
    ------
    ValueError
        Bad input (the message names the argument).
    """
    if approximate or prior is not None:
        exact_args = dict(n_points=n_points, costs=costs, budget=budget, include=include, exclude=exclude,
                          refine=refine, times=times)
        return _approximate_inputs(model, p, candidates, sigma, sensors, n_series, bounds, approximate, prior, robust,
                                   approx_settings, criterion, exact_args)
    if getattr(model, "is_dynamic", False):
        if times is None:
            raise ValueError("times: a dynamic model needs the sampling times of its experiments")
        return select_dynamic_inputs(model, p, times=times, candidates=candidates, sigma=sigma, n_points=n_points,
                                     sensors=sensors, criterion=criterion, kind=kind, costs=costs, budget=budget,
                                     include=include, exclude=exclude, n_series=n_series, method=method,
                                     time_limit=time_limit, refine=refine, bounds=bounds,
                                     refine_settings=refine_settings, settings=settings,
                                     discretisation=discretisation)
    if times is not None or discretisation is not None:
        raise ValueError("times/discretisation: only for a dynamic model (models.Model.ode)")
    return select_static_inputs(model, p, candidates=candidates, sigma=sigma, n_points=n_points, sensors=sensors,
                                criterion=criterion, kind=kind, costs=costs, budget=budget, include=include,
                                exclude=exclude, n_series=n_series, method=method, time_limit=time_limit,
                                refine=refine, bounds=bounds, refine_settings=refine_settings, settings=settings)


def _approximate_inputs(model, p, candidates, sigma, sensors, n_series, bounds, approximate, prior, robust, settings,
                        criterion, exact_args):
    """The ``approximate=True`` route of :func:`select_inputs` (arguments checked, then
    :func:`oed.approximate.approximate_design` on the input range)."""
    check_approximate_route(approximate, exact_args)
    if getattr(model, "is_dynamic", False):
        raise ValueError("approximate: for a dynamic model the approximate design is over sampling times "
                         "(oed.select_times(..., approximate=True)); approximate input profiles are not implemented")
    if isinstance(sensors, str) and sensors == "joint":
        raise ValueError("sensors: approximate designs take None or sensor names, not 'joint'")
    if bounds is None:
        Q = np.asarray(candidates, float)
        Q = Q[:, None] if Q.ndim == 1 else Q
        if Q.ndim != 2 or Q.shape[0] == 0 or Q.shape[1] != model.n_q_dim or not np.all(np.isfinite(Q)):
            raise ValueError(f"candidates: expected finite rows of shape (n, {model.n_q_dim}) spanning the range")
        if not np.any(Q.max(axis=0) > Q.min(axis=0)):
            raise ValueError("candidates: approximate designs need a continuous range, but every candidate row is "
                             "the same point; give bounds=(lower, upper) or candidates spanning a range")
        bounds = (Q.min(axis=0), Q.max(axis=0))
    return approximate_design(model, p, sigma=sigma, bounds=bounds, criterion=criterion, prior=prior,
                              robust=robust, sensors=sensors, n_series=n_series, settings=settings)
