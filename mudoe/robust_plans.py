"""``[oed] mode = "inputs"`` with a prior (or ``approximate = true``): the robust approximate design (issue 31).

:func:`plan_robust` designs on the candidates' range with :func:`oed.inputs.select_inputs`
(``approximate=True``): the local approximate design at ``p``, and with a prior the pseudo-Bayesian or
maximin one over the prior's parameter vectors, each with its equivalence-theorem certificate; then the
local design's efficiency at every parameter vector of the prior against the robust design
(:func:`oed.design_efficiencies`).  :func:`plan_robust_exact` is ``mode = "sensors"`` with a prior (approximate =
false): the exact robust n-run design of the sensors, or of a dynamic study's sampling times
(:func:`oed.robust_exact.exact_over_prior`: enumeration or branch-and-bound, proven optimal or with its proven
gap); with ``mode = "inputs"``, a prior, ``approximate = false`` and ``n_points``, the exact robust choice of
``n_points`` of the candidate input rows (the information of :func:`oed.inputs.select_inputs`'s exact route).  :func:`config_prior` checks the prior against the model (the
messages name ``[oed] prior.<parameter>`` and its line).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from oed.plan_records import RobustExactPlan, RobustPlan
from .config import ConfigError, StudyConfig
from .config_errors import ConfigContext
from .config_prior import prior_error

__all__ = ["config_prior", "plan_robust", "plan_robust_exact", "robust_sensors_at_estimate"]


def config_prior(cfg: StudyConfig, model, p):
    """The :class:`oed.prior.Prior` of ``[oed] prior`` for ``model`` at the nominal ``p`` (the start values or
    the estimate); None without a prior.

    Raises
    ------
    ConfigError
        A parameter the model does not have, or a distribution the library refuses (bounds that exclude the
        nominal value, a non-positive sd, ...); the message names ``[oed] prior.<parameter>`` and its line.
    """
    from oed.prior import make_prior
    spec = cfg.oed.prior
    if not spec:
        return None
    ctx = ConfigContext(cfg.path, cfg.text)
    names = tuple(model.param_names)
    for name, dist in spec.items():
        if name not in names:
            raise prior_error(ctx, name, f"the model has no parameter {name!r} (it has {', '.join(names)})")
        try:
            make_prior({name: dist}, names, p)
        except ValueError as exc:
            msg = str(exc).partition(": ")[2] or str(exc)
            if "nominal" in msg:
                msg += (" (the nominal value: the [[parameters]] start value of a planned design, else the "
                        "estimate)")
            raise prior_error(ctx, name, msg) from None
    return make_prior(dict(spec), names, p)


def plan_robust(cfg: StudyConfig, variant: str, model, Q, q_set, p, sigma, planned: bool) -> RobustPlan:
    """The approximate designs of ``[oed]`` (local, and robust with a prior) on the range of the candidate rows ``Q``
    (model inputs; ``q_set`` the set points in the model's unit)."""
    from oed import design_efficiencies
    from oed.inputs import select_inputs
    o = cfg.oed
    if Q.shape[1] != 1 or not np.array_equal(Q[:, 0], q_set):
        raise ConfigError(f"{cfg.path}: [oed] prior/approximate: variant {variant} reads the set points through "
                          f"derived inputs ({', '.join(model.inputs)}); an approximate design places the model's "
                          "inputs themselves and needs a model whose one input is the set point")
    prior = config_prior(cfg, model, p)
    notes = tuple(n for n, used in (
        (f"n_points = {o.n_points} not used: an approximate design has as many support points as it needs",
         o.n_points is not None),
        ("the approximate design uses the Gauss-Newton information (kind = \"second_order\" not used)",
         o.kind == "second_order" and not planned)) if used)
    args = dict(candidates=Q, sigma=sigma, criterion=o.criterion, n_series=o.n_series, approximate=True)
    try:
        local = select_inputs(model, p, **args)
        if prior is None:
            return RobustPlan(variant, planned, tuple(float(x) for x in p), tuple(float(x) for x in q_set), local,
                              None, (), notes)
        design = select_inputs(model, p, prior=prior, robust=o.robust or "bayes", **args)
        eff = design_efficiencies(model, local, design, sigma=sigma, n_series=o.n_series)
    except ValueError as exc:
        raise ConfigError(f"{cfg.path}: [oed] {exc}") from None
    return RobustPlan(variant, planned, tuple(float(x) for x in p), tuple(float(x) for x in q_set), design, local,
                      tuple(float(e) for e in eff), notes)


def plan_robust_exact(cfg: StudyConfig, variant: str, model, information_at, labels, n: int, p, planned: bool,
                      mode: str) -> RobustExactPlan:
    """The exact robust design of ``n`` of the candidates ``labels`` over ``[oed] prior``, with
    ``information_at(p_row) -> F (n_candidates, n_p, n_p)`` (Gauss-Newton information of one run of every
    candidate), and the local exact design at ``p`` across the prior; ``mode`` "sensors", "times" or "inputs"
    (the candidate input rows, labelled by their set point)."""
    from oed.robust_exact import exact_over_prior
    o = cfg.oed
    prior = config_prior(cfg, model, p)
    notes = (("the exact robust design uses the Gauss-Newton information (kind = \"second_order\" not used)",)
             if o.kind == "second_order" and not planned else ())
    if not 1 <= n <= len(labels):
        what = {"times": "[dynamic] n_times", "inputs": "[oed] n_points", "both": "[oed] n_points"}.get(
            mode, "[oed] n_sensors")
        raise ConfigError(f"{cfg.path}: {what}: the exact robust design chooses 1..{len(labels)} candidates, got {n}")
    try:
        r = exact_over_prior(information_at, prior, p, n, criterion=o.criterion, robust=o.robust or "bayes",
                             names=[str(x) for x in labels], time_limit=o.time_limit)
    except ValueError as exc:
        raise ConfigError(f"{cfg.path}: [oed] {exc}") from None
    return RobustExactPlan(variant, mode, planned, tuple(float(x) for x in p), tuple(labels), r.design, r.local,
                           tuple(float(e) for e in r.local_efficiencies),
                           tuple(tuple(float(v) for v in row) for row in prior.points),
                           tuple(float(w) for w in prior.weights), tuple(model.param_names), notes)


def robust_sensors_at_estimate(cfg: StudyConfig, variant: str, model, data, p, sigma) -> RobustExactPlan:
    """``[oed] prior`` with data (mode "sensors", approximate = false): the exact robust choice of ``n_sensors``
    (default min(n_p, number of sensors)) sensors over the prior around the estimate ``p``, each sensor's
    Gauss-Newton information planned at the data's input rows and number of series (``data``: the study's
    Measurements of ``variant``; ``sigma`` per sensor, model units) at every parameter vector of the prior
    (:func:`plan_robust_exact`)."""
    from oed import information
    o = cfg.oed
    Q, n_series = np.asarray(data.inputs, float), int(data.n_M)
    n = o.n_sensors if o.n_sensors is not None else min(model.n_p, len(model.sensors))
    plan = plan_robust_exact(cfg, variant, model, lambda ps: information(model, ps, inputs=Q, sigma=sigma,
                                                                         n_series=n_series).F,
                             tuple(model.sensors), n, p, False, "sensors")
    note = (f"with data: each sensor's information at the data's {Q.shape[0]} input rows x {n_series} series "
            "(Gauss-Newton, at every parameter vector of the prior)")
    return dataclasses.replace(plan, notes=plan.notes + (note,))
