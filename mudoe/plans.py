"""Designs of ``[oed] mode`` (sensors, inputs, both, discrimination), before data or at the estimates.

:func:`plan_without_data` designs at the [[parameters]] start values without reading data
(``[oed] planned = true``); :func:`plan_at_estimate` at the estimate of the [oed] variant;
:func:`plan_discrimination` the readings that best separate two variants (issue 13).
"""
from __future__ import annotations

import numpy as np

from models.contract import Model
from oed.plan_records import DiscriminationPlan, PlannedDesign, RobustExactPlan, RobustPlan

from .checks import check_model
from .config import ConfigError, StudyConfig
from .data_io import DataUnits, study_units
from .study_base import Progress, Study, StudyResults, VariantModel, oed_variant, require_fit
from .study_models import build_models, config_start_values

__all__ = ["PlannedDesign", "DiscriminationPlan", "plan_design", "plan_without_data", "plan_at_estimate",
           "plan_discrimination"]


# ---------------------------------------------------------------------------- designs before data (issue 13)
def plan_design(cfg: StudyConfig, variant: str, model: Model, inputs_fn, p, sigma, planned: bool,
                progress: Progress | None = None, *, units: DataUnits) -> PlannedDesign | RobustPlan | RobustExactPlan:
    """The ``[oed]`` design of ``mode`` at ``p`` without data: sensors over the candidate inputs, or inputs.

    ``units`` are the study's (:func:`mudoe.data_units.study_units`, resolved once by the caller): the
    [oed] candidates are in the file's input unit.

    Raises
    ------
    ConfigError
        Missing candidates or sigma; ``mode = "discrimination"`` (see :func:`plan_discrimination`).
    """
    o = cfg.oed
    progress = progress or Progress(False)
    if o.mode == "discrimination":
        raise ConfigError(f"{cfg.path}: [oed] mode = 'discrimination' designs for two variants: "
                          "use plan_discrimination")
    from oed import select_sensors
    from oed.inputs import select_inputs
    q_set = units.q_to_model(o.candidate_points())
    if q_set.size == 0:
        raise ConfigError(f"{cfg.path}: [oed] candidates: a design without data needs candidate inputs")
    Q = q_set[:, None] if inputs_fn is None else np.asarray(inputs_fn(q_set), float)
    if sigma is None:
        raise ConfigError(f"{cfg.path}: [[sensors]] a design needs every sensor's sigma (give sigma = ...)")
    if o.prior and not o.approximate and o.mode == "sensors":
        from .robust_plans import plan_robust_exact
        n = o.n_sensors if o.n_sensors is not None else model.n_p
        with progress.step(f"exact robust sensor design ({o.criterion}, {variant}, {o.robust or 'bayes'} over the "
                           "prior)"):
            return plan_robust_exact(cfg, variant, model, lambda ps: select_information(model, ps, Q, sigma, o),
                                     tuple(model.sensors), n, p, planned, "sensors")
    if o.prior and not o.approximate and o.mode == "inputs" and o.n_points is not None:
        from .robust_plans import plan_robust_exact
        with progress.step(f"exact robust input design ({o.criterion}, {variant}, {o.robust or 'bayes'} over the "
                           "prior)"):
            return plan_robust_exact(cfg, variant, model, lambda ps: input_information(model, ps, Q, sigma, o),
                                     tuple(f"{q:g}" for q in q_set), o.n_points, p, planned, "inputs")
    if o.prior and not o.approximate and o.mode == "both":
        from .robust_plans import plan_robust_exact
        labels = tuple(f"{q:g}:{s}" for q in q_set for s in model.sensors)    # model unit, as mode "inputs"
        with progress.step(f"exact robust joint design ({o.criterion}, {variant}, {o.robust or 'bayes'} over the "
                           "prior)"):
            return plan_robust_exact(cfg, variant, model, lambda ps: pair_information(model, ps, Q, sigma, o),
                                     labels, o.n_points, p, planned, "both")
    if o.prior or o.approximate:
        from .robust_plans import plan_robust
        with progress.step(f"approximate input design ({o.criterion}, {variant}"
                           f"{', ' + (o.robust or 'bayes') + ' over the prior' if o.prior else ', local'})"):
            return plan_robust(cfg, variant, model, Q, q_set, p, sigma, planned)
    common = dict(criterion=o.criterion, kind=o.kind, include=o.include, exclude=o.exclude,
                  costs=list(o.costs) if o.costs else None, budget=o.budget)
    with progress.step(f"{o.mode} design ({o.criterion}, {variant}{', planned' if planned else ''})"):
        if o.mode == "sensors":
            n = o.n_sensors if o.n_sensors is not None or o.max_sensors is not None else model.n_p
            res = select_sensors(model, None, p, inputs=Q, sigma=sigma, n_series=o.n_series, n_sensors=n,
                                 max_sensors=o.max_sensors, **common)
        else:
            if o.include or o.exclude:
                raise ConfigError(f"{cfg.path}: [oed] include/exclude name sensors; mode = {o.mode!r} chooses "
                                  "input points (leave them out)")
            common.update(include=(), exclude=())
            if o.refine and not (Q.shape[1] == 1 and np.array_equal(Q[:, 0], q_set)):
                raise ConfigError(f"{cfg.path}: [oed] refine: variant {variant} reads the set points through derived "
                                  f"inputs ({', '.join(model.inputs)}); the continuous refinement moves the model's "
                                  "inputs themselves and needs a model whose one input is the set point")
            res = select_inputs(model, p, candidates=Q, sigma=sigma, n_points=o.n_points, n_series=o.n_series,
                                sensors="joint" if o.mode == "both" else None, refine=o.refine,
                                time_limit=o.time_limit, **common)
    return PlannedDesign(variant, o.mode, planned, tuple(float(x) for x in p), tuple(float(x) for x in q_set), res)


def select_information(model: Model, p, Q, sigma, o):
    """Planned Gauss-Newton information of every sensor at ``p`` (inputs ``Q``, ``[oed] n_series``), (n_S, n_p, n_p)."""
    from oed import information
    return information(model, p, inputs=Q, sigma=sigma, n_series=o.n_series).F


def input_information(model: Model, p, Q, sigma, o):
    """Planned Gauss-Newton information of one run at every candidate input row of ``Q`` (every sensor read,
    ``[oed] n_series``) at ``p``, (n_Q, n_p, n_p)."""
    from oed.candidate_information import information
    return information(model, p, axis="inputs", candidates=Q, sigma=sigma, n_series=o.n_series).F


def pair_information(model: Model, p, Q, sigma, o):
    """Planned Gauss-Newton information of every (candidate input row, sensor) pair at ``p`` (row-major: row j's
    sensors in the model's order, ``[oed] n_series``), (n_Q n_S, n_p, n_p)."""
    from oed.candidate_information import information
    return information(model, p, axis="input_pairs", candidates=Q, sigma=sigma, n_series=o.n_series).F


def plan_without_data(cfg: StudyConfig, progress: Progress | None = None, built: dict | None = None) -> PlannedDesign:
    """``[oed] planned = true`` of a static study: the design at the [[parameters]] start values, no data read
    (``built``: the study's variants, default built here; :func:`mudoe.study.plan_without_data` designs for
    any kind of study)."""
    built = build_models(cfg) if built is None else built
    v = cfg.oed.variant or list(built)[-1]
    model, fn = built[v].model, built[v].inputs_fn
    check_model(cfg, model)
    given = _given_sigma(cfg, model)
    units = study_units(cfg, model)                  # once for the whole plan
    sigma = np.array([units.sigma_to_model(k, given[s]) for k, s in enumerate(model.sensors)], float)
    p = config_start_values(cfg, model)
    bad = (p < model.lower) | (p > model.upper)
    if np.any(bad):
        raise ConfigError(f"{cfg.path}: [[parameters]] start values of {[model.param_names[i] for i in np.flatnonzero(bad)]} "
                          "lie outside their bounds (a planned design uses the start values as nominal parameters)")
    if cfg.oed.mode == "discrimination":
        return plan_discrimination(cfg, v, built, {v: p, cfg.oed.rival: config_start_values(cfg, built[cfg.oed.rival].model)}, sigma,
                                   True, progress=progress, units=units)
    return plan_design(cfg, v, model, fn, p, sigma, True, progress, units=units)


def _given_sigma(cfg: StudyConfig, model: Model) -> dict:
    """Every sensor's ``sigma`` from [[sensors]] (the file's units); without data sigma_man cannot be
    composed."""
    given = {sc.name: sc.sigma for sc in cfg.sensors}
    missing = [s for s in model.sensors if given.get(s) is None]
    if missing:
        raise ConfigError(f"{cfg.path}: [[sensors]] a design without data needs sigma for {', '.join(missing)} "
                          "(sigma_man needs the data's repeatability)")
    return given


def plan_at_estimate(study: Study, results: StudyResults, progress: Progress | None = None) -> PlannedDesign:
    """``[oed] mode`` inputs / both (/ discrimination) with data: the design at the estimate of the variant."""
    progress = progress or Progress(False)
    v = oed_variant(study)
    results = require_fit(study, results, v, progress, "oed", "; no information matrix to design with")
    built = build_models(study.cfg)
    units = study.units if study.units is not None else study_units(study.cfg, study.models[v])
    if study.cfg.oed.mode == "discrimination":
        rival = study.cfg.oed.rival
        results = require_fit(study, results, rival, progress, "oed", "; the rival's predictions need its estimate")
        est = results.estimates[v]
        sigma = study.sigma if study.sigma is not None else est.sigma
        built = {k: VariantModel(study.models[k], built[k].inputs_fn) for k in (v, rival)}
        return plan_discrimination(study.cfg, v, built, {k: results.estimates[k] for k in (v, rival)}, sigma,
                                   False, q_default=study.campaign.q_set, progress=progress, units=units)
    fn = built[v].inputs_fn
    return plan_design(study.cfg, v, study.models[v], fn, results.estimates[v].p, study.sigma, False, progress,
                       units=units)


# ---------------------------------------------------------------------------- discrimination designs (issue 13)
def _values(p) -> tuple:
    """The parameter values of an array or an Estimate, as a tuple of float."""
    return tuple(float(v) for v in getattr(p, "p", p))


def _even_rows(n_q: int, k: int) -> list:
    return sorted({int(i) for i in np.round(np.linspace(0, n_q - 1, k))})


def plan_discrimination(cfg: StudyConfig, variant: str, built: dict, params: dict, sigma, planned: bool,
                        q_default=None, progress: Progress | None = None, *, units: DataUnits) -> DiscriminationPlan:
    r"""``[oed] mode = "discrimination"``: the readings that best separate ``variant`` (assumed true) from
    ``[oed] rival`` (:func:`oed.select_discriminating`), each model at ``params`` (start values or
    Estimates).

    The candidates are the [oed] set points (or ``q_default``, the study's set points), each model
    reading them through its own inputs; sigma in model units; the values of a design are per
    series times ``[oed] n_series``; ``units`` the study's (the [oed] candidates are in the file's
    input unit).

    Raises
    ------
    ConfigError
        No candidates, no sigma, or a bad design argument (the message names the [oed] key).
    """
    from oed.discrimination import DiscriminationError, reading_divergences, refit_values, select_discriminating
    o = cfg.oed
    progress = progress or Progress(False)
    (m_a, fn_a), (m_b, fn_b) = ((built[k].model, built[k].inputs_fn) for k in (variant, o.rival))
    pts = o.candidate_points()
    if pts.size:
        q_set = units.q_to_model(pts)
    elif q_default is not None:
        q_set = np.asarray(q_default, float)
    else:
        raise ConfigError(f"{cfg.path}: [oed] candidates: a discrimination design needs candidate set points")
    if sigma is None:
        raise ConfigError(f"{cfg.path}: [[sensors]] a discrimination design needs every sensor's sigma")
    qa = q_set[:, None] if fn_a is None else np.asarray(fn_a(q_set), float)
    qb = q_set[:, None] if fn_b is None else np.asarray(fn_b(q_set), float)
    unknown = [s for s in o.exclude if s not in m_a.sensors]
    if unknown:
        raise ConfigError(f"{cfg.path}: [oed] exclude: unknown sensor(s) {', '.join(unknown)}")
    sensors = tuple(s for s in m_a.sensors if s in m_b.sensors and s not in o.exclude)
    sig = dict(zip(m_a.sensors, np.asarray(sigma, float)))
    args = (m_a, params[variant], m_b, params[o.rival], (qa, qb))
    with progress.step(f"discrimination design ({o.discrimination_criterion}, {variant} vs {o.rival}"
                       f"{', planned' if planned else ''})"):
        try:
            res = select_discriminating(*args, sensors=sensors, sigma=sig, n_points=o.n_points,
                                        n_sensors=o.n_sensors, criterion=o.discrimination_criterion,
                                        n_readings=o.n_readings)
            scores = {"T": reading_divergences(*args, sensors=sensors, sigma=sig, criterion="T")[0]}
            if not planned:
                scores["divergence"] = reading_divergences(*args, sensors=sensors, sigma=sig,
                                                           criterion="divergence")[0]
        except DiscriminationError as exc:
            raise ConfigError(f"{cfg.path}: [oed] {exc}") from None
    n_q, n_S = len(q_set), len(sensors)
    if o.n_readings is not None:
        even = tuple((j, sn) for j in _even_rows(n_q, -(-o.n_readings // n_S)) for sn in sensors)[:o.n_readings]
    else:
        even = tuple((j, sn) for j in _even_rows(n_q, o.n_points or n_q) for sn in res.sensors)
    references = {"evenly spread": even,
                  "all readings": tuple((j, sn) for j in range(n_q) for sn in sensors)}
    for d in scores.values():
        d.setflags(write=False)
    names = ("chosen",) + tuple(references)
    refit = dict(zip(names, refit_values(*args, designs=[res.readings] + list(references.values()), sensors=sensors,
                                         sigma=sig)))
    return DiscriminationPlan(variant, o.rival, planned, _values(params[variant]), _values(params[o.rival]),
                              tuple(float(x) for x in q_set), o.n_series, res, scores, references,
                              dict(zip(m_a.sensors, m_a.sensor_units)), refit)
