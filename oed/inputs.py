"""Which inputs to apply: the front door of input design, for static and dynamic models.

:func:`select_inputs` hands a dynamic model (:meth:`models.Model.ode`) to
:func:`oed.dynamic_inputs.select_dynamic_inputs` and a static one to the engine
:func:`oed.static_inputs.select_static_inputs` (the exact design over candidate rows and its
continuous refinement; the equations are in :mod:`oed.static_inputs`), on which the dynamic design
is built.  The other names are those of :mod:`oed.static_inputs`.
"""
from __future__ import annotations

from .design import DesignSettings
from .dynamic_inputs import select_dynamic_inputs
from .static_inputs import (InputDesignResult, RefinedInputs, RefineSettings, input_information, refine_inputs,
                            select_static_inputs)

__all__ = ["InputDesignResult", "RefinedInputs", "RefineSettings", "input_information", "select_inputs",
           "refine_inputs"]


def select_inputs(model, p, *, candidates, sigma, n_points, sensors=None, criterion="D", kind="gauss_newton",
                  costs=None, budget=None, include=(), exclude=(), n_series=1, method="auto", time_limit=60.0,
                  refine=False, bounds=None, refine_settings: RefineSettings = RefineSettings(),
                  settings: DesignSettings = DesignSettings(), times=None, discretisation=None) -> InputDesignResult:
    r"""Exact optimal choice of ``n_points`` input rows (or input-sensor pairs), optionally refined.

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
        Number of candidates chosen: input rows, or (row, sensor) pairs with ``sensors="joint"``.
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

    Returns
    -------
    InputDesignResult

    Raises
    ------
    ValueError
        Bad input (the message names the argument).
    """
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
