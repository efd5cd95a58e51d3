r"""The designs of a time-series study beyond its exact sampling times (issue 30 item 8, issue 31 item 6).

:func:`input_design` is ``[oed] mode = "inputs"``: the next ``n_points`` experiments (constants and control
profiles) of the study at ``p``.  The candidates are the study's experiments within ``[oed] bounds`` and
``n_candidates`` experiments drawn uniformly within the bounds (every column, seeded by ``[oed] seed``); with
F_c the Gauss-Newton information of candidate experiment c read by every instrument at the [dynamic] times,

.. math::

    \min_{w \in \{0,1\}^{n_c},\ \sum_c w_c = n} \Psi\Bigl(\bigl(\textstyle\sum_c w_c F_c\bigr)^{-1}\Bigr)

by :func:`oed.inputs.select_inputs` (``times=``: the collocated model on a mesh controlled at every candidate),
with ``[oed] refine`` the chosen rows then moved continuously within the bounds, everything within ``[oed]
time_limit`` seconds; with ``[oed] prior`` the exact robust choice over the prior
(:func:`mudoe.robust_plans.plan_robust_exact`).  The designed experiments are valued against the current ones
(:class:`oed.dynamic_plans.ExperimentPlan`): the design is of new experiments, planned on its own (the
refinement has no information of the current experiments to add to), and its value is given beside the current
experiments', each current experiment's alone, and the two together.

:func:`approximate_times` is ``approximate = true`` with mode "sensors": the approximate sampling times on the
range of the candidate times for the study's experiments (:func:`oed.select_times` with ``approximate=True``,
robust over ``[oed] prior``), with the local design's efficiency across the prior.
"""
from __future__ import annotations

import numpy as np

from oed.dynamic_plans import ApproximateTimePlan, ExperimentPlan, ExperimentInput

from .config import ConfigError, StudyConfig, config_error

__all__ = ["experiment_inputs", "input_bounds", "candidate_experiments", "input_design", "approximate_times",
           "design_values"]


def experiment_inputs(model) -> tuple:
    """The :class:`oed.dynamic_plans.ExperimentInput` of a dynamic model's input row (constants, then controls)."""
    units = list(model.input_units) + [""] * (len(model.constants) + len(model.controls))
    out = [ExperimentInput(n, units[k]) for k, n in enumerate(model.constants)]
    out += [ExperimentInput(c.name, getattr(c, "unit", "") or "", tuple(c.grid), c.kind) for c in model.controls]
    return tuple(out)


def input_bounds(cfg: StudyConfig, model, Q) -> tuple:
    """(lower, upper) per column of the input row: ``[oed] bounds`` of each input, else the range of the study's
    experiments ``Q`` (a control: over all its grid values).

    Raises
    ------
    ConfigError
        A bound of an input the model does not have (file, line, key).
    """
    inputs = experiment_inputs(model)
    names = [i.name for i in inputs]
    unknown = [n for n in cfg.oed.bounds if n not in names]
    if unknown:
        raise config_error(cfg, "oed", "bounds", f"unknown input {unknown[0]!r}; the model {model.name!r} has "
                           f"{', '.join(names) or 'no inputs'}")
    if not names:
        raise config_error(cfg, "oed", "mode", f"the model {model.name!r} has no inputs: there is no experiment to "
                           "design (mode = \"sensors\" designs its sampling times)")
    lo, hi, k = [], [], 0
    for inp in inputs:
        cols = np.asarray(Q, float)[:, k:k + inp.width]
        a, b = cfg.oed.bounds.get(inp.name, (float(cols.min()), float(cols.max())))
        lo += [a] * inp.width
        hi += [b] * inp.width
        k += inp.width
    return np.array(lo), np.array(hi)


def candidate_experiments(cfg: StudyConfig, Q, lo, hi) -> tuple:
    """(candidate rows, their labels, notes): the study's experiments within the bounds ("experiment j", 1-based),
    then ``[oed] n_candidates`` rows drawn uniformly within the bounds ("candidate k")."""
    Q = np.asarray(Q, float)
    inside = np.all((Q >= lo - 1e-12) & (Q <= hi + 1e-12), axis=1)
    notes = ()
    if not inside.all():
        out = [str(j + 1) for j in np.flatnonzero(~inside)]
        notes = (f"experiment(s) {', '.join(out)} of the study lie outside [oed] bounds and are not candidates",)
    rng = np.random.default_rng(cfg.oed.seed)
    R = lo + (hi - lo) * rng.random((cfg.oed.n_candidates, lo.size))
    C = np.vstack([Q[inside], R])
    labels = tuple(f"experiment {j + 1}" for j in np.flatnonzero(inside)) + tuple(
        f"candidate {k + 1}" for k in range(R.shape[0]))
    return C, labels, notes


def design_values(model, p, rows, sigma, times, n_series: int, criterion: str) -> np.ndarray:
    """The criterion value (D: log det C, A: trace C, E: max eig C; inf when singular) of the Gauss-Newton
    covariance of the experiments ``rows`` together, shape (); with ``rows`` (n, d_q)."""
    from oed import criterion_value, information
    rows = np.asarray(rows, float)
    uniq, count = np.unique(rows, axis=0, return_counts=True)
    F = information(model, p, axis="inputs", candidates=uniq, sigma=sigma, times=times, n_series=n_series).F
    return criterion_value(F, w=count.astype(float), criterion=criterion, kind="gauss_newton")


def _efficiency(criterion: str, v_design: float, n_design: int, v_current: float, n_current: int, n_p: int) -> float:
    """Efficiency per experiment of the design against the current experiments (:class:`ExperimentPlan`)."""
    if not np.isfinite(v_design):
        return 0.0
    if not np.isfinite(v_current):
        return float("inf")
    if criterion == "D":
        return float(np.exp((v_current - v_design) / n_p) * n_current / n_design)
    return float(n_current * v_current / (n_design * v_design))


def _each(model, p, Q, sigma, times, n_series, criterion) -> tuple:
    """The criterion value of every current experiment alone."""
    from oed import criterion_value, information
    F = information(model, p, axis="inputs", candidates=Q, sigma=sigma, times=times, n_series=n_series).F
    return tuple(criterion_value(F[[j]], w=[1.0], criterion=criterion, kind="gauss_newton") for j in range(len(Q)))


def _hit(result) -> bool:
    """Whether the design reached its time limit (stated in its notes or its refinement's messages)."""
    texts = list(getattr(result, "notes", ()))
    refined = getattr(result, "refined", None)
    if refined is not None:
        texts += list(refined.messages)
    return any("time limit" in t for t in texts)


def input_design(cfg: StudyConfig, variant: str, model, p, Q, sigma, planned: bool, progress) -> ExperimentPlan:
    """``[oed] mode = "inputs"`` of a time-series study (module docstring): the next ``n_points`` experiments at
    ``p`` (``Q`` the study's experiments, ``sigma`` per instrument, model units).

    Raises
    ------
    ConfigError
        Bad bounds (file, line, key), no sigma, or an argument the library refuses (the message names [oed]).
    """
    from oed.inputs import select_inputs
    o = cfg.oed
    if sigma is None:
        raise ConfigError(f"{cfg.path}: [[sensors]] an input design needs every instrument's sigma")
    times = np.asarray(cfg.dynamic.times, float)
    lo, hi = input_bounds(cfg, model, Q)
    C, labels, notes = candidate_experiments(cfg, Q, lo, hi)
    n = o.n_points or 1
    if n > len(C):
        raise config_error(cfg, "oed", "n_points", f"{n} experiments asked for but only {len(C)} candidates "
                           "(raise n_candidates)")
    robust = None
    how = "robust over the prior" if o.prior else ("refined within the bounds" if o.refine else "exact")
    with progress.step(f"input design ({o.criterion}, {variant}, {n} experiment(s) of {len(C)} candidates, {how})"):
        try:
            if o.prior:
                from oed import information
                from .robust_plans import plan_robust_exact
                robust = plan_robust_exact(
                    cfg, variant, model, lambda ps: information(model, ps, axis="inputs", candidates=C, sigma=sigma,
                                                                times=times, n_series=o.n_series).F,
                    labels, n, p, planned, "inputs")
                res, designed = None, C[list(robust.design.indices)]
            else:
                res = select_inputs(model, p, candidates=C, sigma=sigma, n_points=n, times=times,
                                    criterion=o.criterion, n_series=o.n_series, refine=o.refine, bounds=(lo, hi),
                                    time_limit=o.time_limit)
                designed = np.asarray(res.refined.inputs if res.refined is not None else res.inputs, float)
        except ValueError as exc:
            raise ConfigError(f"{cfg.path}: [oed] {exc}") from None
    crit = o.criterion
    vals = {"design": design_values(model, p, designed, sigma, times, o.n_series, crit),
            "current": design_values(model, p, Q, sigma, times, o.n_series, crit),
            "current + design": design_values(model, p, np.vstack([Q, designed]), sigma, times, o.n_series, crit)}
    each = _each(model, p, Q, sigma, times, o.n_series, crit)
    eff = _efficiency(crit, vals["design"], len(designed), vals["current"], len(Q), model.n_p)
    return ExperimentPlan(variant=variant, planned=planned, p=tuple(float(x) for x in p),
                          param_names=tuple(model.param_names), inputs=experiment_inputs(model),
                          lower=tuple(lo.tolist()), upper=tuple(hi.tolist()),
                          current=tuple(tuple(r) for r in np.asarray(Q, float).tolist()),
                          candidates=tuple(tuple(r) for r in C.tolist()), labels=labels, criterion=crit, result=res,
                          designed=tuple(tuple(r) for r in designed.tolist()), values=vals, each=each, efficiency=eff,
                          time_limit=float(o.time_limit), time_limit_hit=_hit(res) if res is not None else False,
                          n_series=o.n_series, robust=robust, notes=notes)


def approximate_times(cfg: StudyConfig, variant: str, model, p, Q, sigma, planned: bool) -> ApproximateTimePlan:
    """``approximate = true`` of a time-series study's sampling times (module docstring).

    Raises
    ------
    ConfigError
        An argument the library refuses (the message names [oed] or [dynamic]).
    """
    from oed import design_efficiencies, select_times
    from .robust_plans import config_prior
    o, dyn = cfg.oed, cfg.dynamic
    cand = np.asarray(dyn.candidates(), float)
    if dyn.pairs:
        raise config_error(cfg, "dynamic", "pairs", "an approximate design weights sampling times (every instrument "
                           "read at each); leave pairs out or set approximate = false")
    prior = config_prior(cfg, model, p)
    notes = ((f"[dynamic] n_times = {dyn.n_times} not used: an approximate design has as many support points as it "
              "needs",) if dyn.n_times is not None else ())
    args = dict(sigma=sigma, criterion=o.criterion, n_series=o.n_series, approximate=True)
    try:
        local = select_times(model, p, cand, Q, **args)
        if prior is None:
            return ApproximateTimePlan(variant, planned, tuple(float(x) for x in p), tuple(float(x) for x in cand),
                                       local, None, (), notes)
        design = select_times(model, p, cand, Q, prior=prior, robust=o.robust or "bayes", **args)
        eff = design_efficiencies(model, local, design, sigma=sigma, inputs=Q, n_series=o.n_series)
    except ValueError as exc:
        raise ConfigError(f"{cfg.path}: [oed] {exc}") from None
    return ApproximateTimePlan(variant, planned, tuple(float(x) for x in p), tuple(float(x) for x in cand), design,
                               local, tuple(float(e) for e in eff), notes)
