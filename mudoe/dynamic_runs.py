r"""Runs of a dynamic study: the sampling-time design and the trajectories the report draws.

Design (Algorithm 1, lines 02-03, over time): with F_t the Gauss-Newton information of every
instrument at candidate time t summed over the study's experiments at p,

.. math::

    \min_{w \in \{0,1\}^{n_t},\ \sum_t w_t = n} \Psi\bigl((\textstyle\sum_t w_t F_t)^{-1}\bigr),

(:func:`oed.select_times`, exact); the table lists the ten best designs and the chosen one
(:func:`oed.best_designs.best_designs`), never every combination.

Trajectories: for experiment j on a fine grid of ``n_fine`` times over the horizon, the outputs
h_j(t) of the collocated model at p̂ (mesh within the fit's error tolerance), their exact
sensitivities g = dh/dp and the delta-method half-widths q sqrt(g^T C g) (mean) and
q sqrt(g^T C g + sigma^2) (new observation), C the estimate's covariance, q the normal (or
Student t when sigma was estimated) quantile.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import stats

from identification.fit.dynamic_fit import DiscretisationSettings, controlled_mesh
from models.sensitivity import sensitivities
from models.state import solve_states

from .config import ConfigError
from .config_errors import table_line
from .dynamic_records import MeshSummary, Trajectories
from .plan_records import DynamicDesign, design_rows_text
from .study_base import oed_variant, require_fit

__all__ = ["DynamicDesign", "time_design", "run_oed_dynamic", "Trajectories", "trajectories", "run_trajectories",
           "plan_dynamic", "design_rows_text", "validation_problem", "MeshSummary", "mesh_summary",
           "run_discretisation"]


def time_design(cfg, variant: str, model, p, inputs, sigma, planned: bool) -> DynamicDesign:
    """The [oed] criterion's design of [dynamic] n_times candidate times (or pairs) at p."""
    from oed.best_designs import best_designs
    from oed.design import select_sensors_from_information
    from oed.times import time_information
    dyn, o = cfg.dynamic, cfg.oed
    if o.mode != "sensors":
        raise ConfigError(f"{cfg.path}: [oed] mode = {o.mode!r}: a dynamic study designs sampling times "
                          "([dynamic] n_times, candidate_times, pairs); leave mode at \"sensors\"")
    if sigma is None:
        raise ConfigError(f"{cfg.path}: [[sensors]] a sampling-time design needs every instrument's sigma")
    cand = np.asarray(dyn.candidates(), float)
    F, names = time_information(model, p, cand, inputs, sigma, pairs=dyn.pairs)
    n = dyn.n_times or min(model.n_p, len(names))
    res = select_sensors_from_information(F, None, criterion=o.criterion, kind="gauss_newton", n_sensors=n,
                                          sensor_names=names)
    table = best_designs(F, None, names, n, o.criterion, kind="gauss_newton", chosen=res.indices)
    return DynamicDesign(variant, planned, tuple(float(x) for x in p), tuple(float(x) for x in cand), dyn.pairs,
                         res, table)


def run_oed_dynamic(study, results, progress):
    """[oed] of a dynamic study at the estimate of its variant: ``results`` with the sampling times (plan,
    oed, oed_table)."""
    v = oed_variant(study)
    results = require_fit(study, results, v, progress, "oed", "; no information matrix to design with")
    est = results.estimates[v]
    sigma = study.sigma if study.sigma is not None else _instrument_sigma(est, study.sensors)
    with progress.step(f"sampling-time design ({study.cfg.oed.criterion}, {v})"):
        d = time_design(study.cfg, v, study.models[v], est.p, study.inputs, sigma, planned=False)
    return dataclasses.replace(
        results, plan=d, oed=d.result, oed_table=d.table, oed_variant=v, design_sensors=tuple(study.sensors),
        design_how="all instruments at every sampling time of the data (the sampling-time design is for the next "
                   "campaign)")


def _instrument_sigma(est, sensors) -> np.ndarray:
    """sigma per instrument of an estimate of the flat (sensor@time) data."""
    return np.array([est.sigma[[k for k, n in enumerate(est.sensors) if n.split("@")[0] == s][0]] for s in sensors])


def plan_dynamic(cfg, built: dict, progress) -> DynamicDesign:
    """``[oed] planned = true`` for a dynamic model: the time design at the [[parameters]] starts, no data."""
    from .dynamic_study import build_dynamic, instrument_sigma
    models, p0s, Q = build_dynamic(cfg, built)
    v = cfg.oed.variant or list(models)[-1]
    sig = instrument_sigma(cfg, models[v])
    if np.any(np.isnan(sig)):
        s = models[v].sensors[int(np.flatnonzero(np.isnan(sig))[0])]
        names = cfg.sensor_names()
        line = table_line(cfg.text, "sensors", names.index(s), "") if s in names else None
        raise ConfigError(f"{cfg.path}{f':{line}' if line else ''}: [[sensors]] a design without data needs every "
                          f"instrument's sigma; {s!r} has none")
    with progress.step(f"sampling-time design ({cfg.oed.criterion}, {v}, planned)"):
        return time_design(cfg, v, models[v], p0s[v], Q, sig, planned=True)


def trajectories(study, est, variant: str, level: float = 0.95, n_fine: int = 401) -> Trajectories:
    """The trajectories of ``variant`` at its estimate (see the module docstring)."""
    model = study.models[variant]
    data = study.data[variant]
    horizon = model.horizon if model.horizon is not None else float(data.union_times[-1])
    fine, d = np.linspace(0.0, horizon, n_fine), np.asarray(data.union_times, float)
    near = np.min(np.abs(fine[:, None] - d[None, :]), axis=1) <= 1e-9 * max(horizon, 1.0)   # 1.4000000000000001
    t = np.unique(np.r_[fine[~near], d])
    sigma = study.sigma if study.sigma is not None else _instrument_sigma(est, study.sensors)
    cm, err = controlled_mesh(model, est.p, study.inputs, t, sigma)
    Y = solve_states(cm, est.p, study.inputs)
    sens = sensitivities(cm, est.p, study.inputs, Y)
    n_q, n_S = study.inputs.shape[0], model.n_S
    h = np.asarray(sens.h).reshape(n_q, t.size, n_S)
    G = np.asarray(sens.G).reshape(n_q, t.size, n_S, model.n_p)
    var = np.einsum("jtsp,pq,jtsq->jts", G, est.cov, G)
    if est.sigma_estimated:
        q, name = float(stats.t.ppf(0.5 + level / 2, est.dof)), "Student t"
    else:
        q, name = float(stats.norm.ppf(0.5 + level / 2)), "normal"
    s2 = np.asarray(sigma, float)[None, None, :] ** 2
    res = np.full(data.z.shape, np.nan)
    for j in range(n_q):
        n = int(np.isfinite(data.times[j]).sum())
        at = np.searchsorted(t, data.times[j, :n])
        res[:, j, :n] = (data.z[:, j, :n] - h[j, at][None]) / np.asarray(sigma, float)
    return Trajectories(t, h, q * np.sqrt(np.maximum(var, 0)), q * np.sqrt(np.maximum(var, 0) + s2), level, name,
                        res, float(err), DiscretisationSettings().tol_sigma)


def run_trajectories(study, results, progress):
    """``results`` with ``trajectories``: the trajectories of every fitted variant (for the report)."""
    out = dict(results.trajectories)
    for v, est in results.estimates.items():
        with progress.step(f"trajectories of {v} with prediction bands"):
            out[v] = trajectories(study, est, v)
    return dataclasses.replace(results, trajectories=out)


def mesh_summary(est) -> MeshSummary | None:
    """The :class:`MeshSummary` of a dynamic estimate (None for an estimate without a discretisation record)."""
    rec = getattr(est, "extra", {}).get("discretisation")
    if rec is None:
        return None
    shift = np.abs(np.asarray(rec.shift_se, float))
    return MeshSummary(int(rec.degree), int(rec.n_elements), 100 * float(rec.error_sigma), 100 * float(rec.tol_sigma),
                       float(shift.max()) if shift.size and np.all(np.isfinite(shift)) else math.nan,
                       float(rec.tol_se), bool(rec.bounded), rec.reason)


def run_discretisation(study, results):
    """``results`` with ``discretisation``: {variant: MeshSummary} of every fit on all study data (for the
    report)."""
    out = dict(results.discretisation)
    for v, est in results.estimates.items():
        m = mesh_summary(est)
        if m is not None:
            out[v] = m
    return dataclasses.replace(results, discretisation=out)


def validation_problem(study, results, est, used) -> tuple:
    """(model, splits, weights) of ``mudoe validate`` on a dynamic study: the collocated model of the
    estimate (mesh controlled at p̂) over its (sensor, time) outputs, every split of the study (by
    experiment; by time window and early against late as splits of the (sensor, time) columns,
    :func:`identification.studies.splits.flat_split`), the instruments ``used`` at every time."""
    from identification.studies.splits import flat_split
    from identification.studies.splits import SplitError
    try:
        splits = tuple(flat_split(sp, est.model.outputs, est.data.n_q) for sp in study.splits)
    except SplitError as exc:
        raise ConfigError(f"{study.cfg.path}: [splits] {exc}") from None
    w = np.array([1.0 if n.split("@")[0] in used else 0.0 for n in est.sensors])
    return est.model, splits, w
