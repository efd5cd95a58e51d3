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

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from identification.fit.dynamic_fit import DiscretisationSettings, controlled_mesh
from models.sensitivity import sensitivities
from models.state import solve_states

from .config import ConfigError

__all__ = ["DynamicDesign", "time_design", "run_oed_dynamic", "Trajectories", "trajectories", "run_trajectories",
           "plan_dynamic", "design_rows_text", "validation_problem", "MeshSummary", "mesh_summary",
           "run_discretisation"]


@dataclass(frozen=True)
class DynamicDesign:
    """A sampling-time design: the :class:`oed.DesignResult`, the ranked table, the candidates."""

    variant: str
    planned: bool
    p: tuple
    candidates: tuple
    pairs: bool
    result: object
    table: object
    mode = "times"

    def chosen_times(self) -> tuple:
        """The chosen sampling times (sorted)."""
        t = self.candidates
        if not self.pairs:
            return tuple(t[i] for i in self.result.indices)
        n_S = len(self.table.rows[0].mask) // len(t)
        return tuple(sorted({t[i // n_S] for i in self.result.indices}))

    def summary(self) -> str:
        head = (f"sampling-time design of variant {self.variant} at p = {list(self.p)} "
                + ("(planned before data: Gauss-Newton)" if self.planned else "(at the estimate)"))
        text = self.result.summary().replace("  sensors (", "  readings (" if self.pairs else "  sampling times (", 1)
        return head + "\n" + text + "\n" + self.table.note + ":\n" + design_rows_text(self.table)

    def to_dict(self) -> dict:
        r = self.result
        return dict(variant=self.variant, mode="times", planned=self.planned, p=list(self.p),
                    candidates=list(self.candidates), pairs=self.pairs, chosen=list(r.sensors),
                    chosen_times=list(self.chosen_times()), criterion=r.criterion, value=r.value,
                    lower_bound=r.lower_bound, proven_optimal=r.proven_optimal, method=r.method,
                    notes=list(r.notes), table_note=self.table.note,
                    table=[dict(candidates=list(x.sensors), A=x.A, logdet=x.logdet, E=x.E, flag=x.flag)
                           for x in self.table.rows])


def design_rows_text(table) -> str:
    """The ranked designs as text: rank, log det C, trace C, max eig C, the candidates."""
    out = [f"{'rank':>4} {'log det C':>11} {'trace C':>11} {'max eig C':>11}  candidates"]
    for k, r in enumerate(table.rows, 1):
        out.append(f"{k:>4} {r.logdet:>11.4f} {r.A:>11.4e} {r.E:>11.4e}  {', '.join(r.sensors)}"
                   + (f"  ({r.flag})" if r.flag else ""))
    return "\n".join(out)


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


def run_oed_dynamic(study, results, progress) -> None:
    """[oed] of a dynamic study at the estimate of its variant: sampling times (results.oed, oed_table)."""
    from .study import FitFailedError, run_identify
    v = study.cfg.oed.variant or list(study.models)[-1]
    if v not in results.estimates:
        run_identify(study, results, progress)
    if v not in results.estimates:
        raise FitFailedError(f"oed: the fit of variant {v} failed ({results.estimate_errors.get(v)}); no "
                             "information matrix to design with")
    est = results.estimates[v]
    sigma = study.sigma if study.sigma is not None else _instrument_sigma(est, study.sensors)
    with progress.step(f"sampling-time design ({study.cfg.oed.criterion}, {v})"):
        d = time_design(study.cfg, v, study.models[v], est.p, study.inputs, sigma, planned=False)
    results.plan = d
    results.oed, results.oed_table, results.oed_variant = d.result, d.table, v
    results.design_sensors = tuple(study.sensors)
    results.design_how = ("all instruments at every sampling time of the data (the sampling-time design is for "
                          "the next campaign)")


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
        raise ConfigError(f"{cfg.path}: [[sensors]] a design without data needs every instrument's sigma")
    with progress.step(f"sampling-time design ({cfg.oed.criterion}, {v}, planned)"):
        return time_design(cfg, v, models[v], p0s[v], Q, sig, planned=True)


@dataclass(frozen=True)
class Trajectories:
    """Outputs of every experiment on a fine time grid and their delta-method half-widths.

    t (n_t,), h, half_mean, half_new (n_q, n_t, n_S) in the model's units; level, quantile name."""

    t: np.ndarray
    h: np.ndarray
    half_mean: np.ndarray
    half_new: np.ndarray
    level: float
    quantile: str
    residuals: np.ndarray = None     # (n_M, n_q, n_t_data, n_S): (z - h) / sigma at the data's times
    error_sigma: float = math.nan    # largest discretisation error of h on the fine grid, in sigmas
    tol_sigma: float = math.nan      # its tolerance


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


def run_trajectories(study, results, progress) -> None:
    """``results.trajectories``: the trajectories of every fitted variant (for the report)."""
    for v, est in results.estimates.items():
        with progress.step(f"trajectories of {v} with prediction bands"):
            results.trajectories[v] = trajectories(study, est, v)


@dataclass(frozen=True)
class MeshSummary:
    """What a report shows of the discretisation of a dynamic fit (from its
    :class:`identification.fit.dynamic_fit.DiscretisationRecord`).

    degree, n_elements : the Radau IIA mesh; error_pct : largest estimated output error at the
    readings, % of sigma (tol_pct its tolerance); shift_se : largest linearised shift of the estimate
    without discretisation error, in standard errors (tol_se its tolerance); bounded : both within
    their tolerances; reason : why not ("" when bounded).
    """

    degree: int
    n_elements: int
    error_pct: float
    tol_pct: float
    shift_se: float
    tol_se: float
    bounded: bool
    reason: str = ""
    method: str = "Radau IIA collocation"

    def text(self) -> str:
        """One line: mesh, largest output error in % of sigma, bounded or NOT bounded (and why)."""
        head = (f"{self.method}, degree {self.degree}, {self.n_elements} elements; largest discretisation error "
                f"{self.error_pct:.2g} % of sigma")
        if self.bounded:
            return (f"{head} (bounded below {self.tol_pct:.2g} %), estimate shifted by at most {self.shift_se:.2g} "
                    f"standard errors (below {self.tol_se:.2g})")
        why = self.reason or "no finer mesh was tried"
        return (f"{head}, estimate shift {self.shift_se:.3g} standard errors: discretisation error NOT bounded "
                f"(tolerances {self.tol_pct:.2g} % of sigma, {self.tol_se:.2g} standard errors: {why}); the "
                "estimate and its verdicts may reflect the discretisation, not the model")


def mesh_summary(est) -> MeshSummary | None:
    """The :class:`MeshSummary` of a dynamic estimate (None for an estimate without a discretisation record)."""
    rec = getattr(est, "extra", {}).get("discretisation")
    if rec is None:
        return None
    shift = np.abs(np.asarray(rec.shift_se, float))
    return MeshSummary(int(rec.degree), int(rec.n_elements), 100 * float(rec.error_sigma), 100 * float(rec.tol_sigma),
                       float(shift.max()) if shift.size and np.all(np.isfinite(shift)) else math.nan,
                       float(rec.tol_se), bool(rec.bounded), rec.reason)


def run_discretisation(study, results) -> None:
    """``results.discretisation``: {variant: MeshSummary} of every fit on all study data (for the report)."""
    for v, est in results.estimates.items():
        m = mesh_summary(est)
        if m is not None:
            results.discretisation[v] = m


def validation_problem(study, results, est, used) -> tuple:
    """(model, splits, weights) of ``mudoe validate`` on a dynamic study: the collocated model of the
    estimate (mesh controlled at p̂) over its (sensor, time) outputs, every split of the study (by
    experiment; by time window and early against late as splits of the (sensor, time) columns,
    :func:`identification.studies.dynamic_detect.flat_split`), the instruments ``used`` at every time."""
    from identification.studies.dynamic_detect import flat_split
    from identification.studies.splits import SplitError
    try:
        splits = tuple(flat_split(sp, est.model.outputs, est.data.n_q) for sp in study.splits)
    except SplitError as exc:
        raise ConfigError(f"{study.cfg.path}: [splits] {exc}") from None
    w = np.array([1.0 if n.split("@")[0] in used else 0.0 for n in est.sensors])
    return est.model, splits, w
