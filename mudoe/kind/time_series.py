r"""The time-series study: an ODE/DAE model (``Model.ode``) of experiments sampled over time, its campaign a
long-format CSV (:mod:`mudoe.kind.long_csv`), its sampling times and experiments the config's ``[dynamic]``
section (:class:`mudoe.config_sections.DynamicConfig`).

The same commands as for a static model; what differs is here: one sigma per instrument
([[sensors]]), splits by experiment ([[splits.custom]], [splits.random]), by time window
(``[splits] time_windows``) and early against late (``[splits] early_late``); the design chooses
sampling times (Algorithm 1, lines 02-03, over time): with F_t the Gauss-Newton information of
every instrument at candidate time t summed over the study's experiments at p,

.. math::

    \min_{w \in \{0,1\}^{n_t},\ \sum_t w_t = n} \Psi\bigl((\textstyle\sum_t w_t F_t)^{-1}\bigr)

(:func:`oed.select_times`, exact; the table lists the ten best designs and the chosen one,
:func:`oed.best_designs.best_designs`); the report draws each experiment's trajectories h_j(t) of the
collocated model at p̂ on a fine grid of ``n_fine`` times (mesh within the fit's error tolerance), with the
data and the delta-method half-widths

.. math::

    q \sqrt{g(t)^T C g(t)} \ \text{(mean)}, \qquad q \sqrt{g(t)^T C g(t) + \sigma^2} \ \text{(new observation)},
    \qquad g = \partial h / \partial p

(exact sensitivities, C the estimate's covariance, q the normal or -- sigma estimated -- Student t
quantile), and the mesh of each fit.  :class:`TimeSeriesKind` is this kind's
:class:`mudoe.kind.base.StudyKind`.
"""
from __future__ import annotations

import contextlib
import copy
import dataclasses
import hashlib
import json
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import stats

from identification.fit.dynamic_data import DynamicMeasurements, instrument_sigma
from identification.fit.dynamic_fit import DiscretisationSettings, controlled_mesh
from identification.studies.detect import POOLED_NOTE, normality_check
from identification.studies.records import MeshSummary, SimulationTruth, Trajectories
from identification.studies.splits import Split, random_splits
from models.cache import Cache
from models.contract import ModelError, Parameter
from models.fileio import atomic_write_texts
from models.sensitivity import sensitivities
from models.state import solve_states
from oed.plan_records import DynamicDesign

from ..config import ConfigError, StudyConfig, config_error
from ..config_errors import entry_error, table_line
from ..data_io import DataFileError
from ..parameter_units import model_parameters
from ..model_error_runs import run_model_error_pages
from ..study_base import Progress, Study, oed_variant, require_fit
from ..units import UnitError, convert
from .base import Simulation, StudyKind
from .long_csv import read_long_csv, write_long_csv

__all__ = ["TimeSeriesKind", "TIME_SERIES", "DynamicCampaign", "experiment_rows", "config_sigma", "build_dynamic",
           "prepare_dynamic", "simulation_truth", "dynamic_splits", "SimulatedDynamic", "simulate_dynamic",
           "time_design", "run_oed_dynamic", "plan_dynamic", "trajectories", "run_trajectories", "mesh_summary",
           "run_discretisation", "validation_problem", "dynamic_template_text"]


# ---------------------------------------------------------------------------- the campaign
@dataclass(frozen=True)
class DynamicCampaign:
    """What the report and results.json record of a dynamic campaign's file."""

    source: str
    files: tuple
    sha256: str
    n_M: int
    n_q: int
    notes: tuple = ()


# ---------------------------------------------------------------------------- config against the model
def experiment_rows(cfg: StudyConfig, model) -> np.ndarray:
    """The experiments' input rows (n_q, d_q): the constants, then each control's grid values.

    Raises
    ------
    ConfigError
        An unknown or missing input, a control with the wrong number of grid values (file, line, key).
    """
    dyn = cfg.dynamic
    controls = {c.name: c for c in model.controls}
    known = tuple(model.constants) + tuple(controls)
    rows = []
    for k, e in enumerate(dyn.experiments, 1):
        def error(key: str, msg: str) -> ConfigError:        # the line of the k-th [[dynamic.experiments]]
            return entry_error(cfg.path, cfg.text, "dynamic.experiments", k - 1, key, f"experiment {k}: {msg}")
        unknown = [n for n in e if n not in known]
        if unknown:
            has = f"has {', '.join(known)}" if known else "has no inputs (leave the experiment's table empty)"
            raise error(unknown[0], f"unknown input {unknown[0]!r}; the model {model.name!r} {has}")
        missing = [n for n in known if n not in e]
        if missing:
            raise error(next(iter(e), ""), f"no value for input(s) {', '.join(missing)}")
        row = []
        for n in model.constants:
            if isinstance(e[n], tuple):
                raise error(n, f"{n} is a constant input; give one number")
            row.append(e[n])
        for n, c in controls.items():
            v = e[n] if isinstance(e[n], tuple) else (e[n],)
            if len(v) != len(c.grid):
                raise error(n, f"control {n} takes {len(c.grid)} values (one per grid point "
                               f"{', '.join(f'{g:g}' for g in c.grid)}), got {len(v)}")
            row.extend(v)
        rows.append(row)
    return np.array(rows, float).reshape(len(rows), len(model.inputs))    # (n_q, 0) for a model without inputs


def _checked_times(cfg: StudyConfig, model, key: str, times) -> np.ndarray:
    try:
        return model.check_times(np.asarray(times, float), key)
    except ModelError as exc:
        raise config_error(cfg, "dynamic", key, str(exc).split(": ", 1)[-1]) from None


def _bounded(cfg: StudyConfig, m):
    """A copy of the dynamic model with the [[parameters]] bounds (model units)."""
    if not cfg.parameters:
        raise ConfigError(f"{cfg.path}: [[parameters]] give start values for {', '.join(m.param_names)}")
    names = [p.name for p in cfg.parameters]
    missing = [n for n in m.param_names if n not in names]
    if missing:
        raise ConfigError(f"{cfg.path}: [[parameters]] missing start value(s) for {', '.join(missing)}")
    own = dataclasses.replace(cfg, parameters=tuple(pc for pc in cfg.parameters if pc.name in m.param_names))
    pcs = {pc.name: pc for pc in model_parameters(own, m)}
    new = copy.copy(m)
    new.cache = Cache()
    try:
        new.params = tuple(Parameter(p.name, pcs[p.name].lower, pcs[p.name].upper, scale=p.scale,
                                     unit=p.unit or pcs[p.name].unit) for p in m.params)
    except (ModelError, ValueError) as exc:
        raise ConfigError(f"{cfg.path}: [[parameters]] {exc}") from None
    return new, np.array([pcs[n].start for n in m.param_names], float)


def config_sigma(cfg: StudyConfig, model) -> np.ndarray:
    """sigma_s per instrument in the model's units ([[sensors]] sigma converted from the files' unit; NaN
    where not given), through :func:`identification.fit.dynamic_data.instrument_sigma`; sigma_man needs
    the data's repeatability and is composed in :func:`prepare_dynamic`."""
    names = cfg.sensor_names()
    unknown = [n for n in names if n not in model.sensors]
    if unknown:
        raise entry_error(cfg.path, cfg.text, "sensors", names.index(unknown[0]), "name",
                          f"unknown instrument {unknown[0]!r}; the model {model.name!r} measures "
                          f"{', '.join(model.sensors)}")
    missing = [s for s in model.sensors if s not in names]
    if names and missing:
        raise ConfigError(f"{cfg.path}: [[sensors]] no entry for instrument(s) {', '.join(missing)}; give each "
                          "instrument one sigma (not one per time)")
    sig = []
    for s, unit in zip(model.sensors, model.sensor_units):
        sc = cfg.sensors[names.index(s)] if names else None
        v = None if sc is None else sc.sigma
        if v is not None and sc.unit and unit and sc.unit != unit:
            try:
                v = float(convert(v, sc.unit, unit) - convert(0.0, sc.unit, unit))
            except UnitError as exc:
                raise entry_error(cfg.path, cfg.text, "sensors", names.index(s), "unit",
                                  f"instrument {s}: unit {sc.unit!r}: {exc}") from None
        sig.append(math.nan if v is None else v)
    return instrument_sigma(model.sensors, sig, missing=True)


# ---------------------------------------------------------------------------- the study
def _load(cfg: StudyConfig, model, Q, sigma) -> tuple:
    d = cfg.data
    if d.source != "csv":
        raise config_error(cfg, "data", "source", "a dynamic study reads its data from a long-format CSV file "
                           "(source = \"csv\", file = ...); `mudoe simulate` writes one")
    path = cfg.resolve(d.directory) / d.file
    data = read_long_csv(path, Q, model.sensors, model.sensor_units, sigma=sigma, input_names=model.inputs,
                         times=cfg.dynamic.times)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise DataFileError(f"{path}: cannot read ({exc})") from None
    camp = DynamicCampaign("long-format CSV (series, experiment, time, sensor, value, unit)", (str(path),),
                           hashlib.sha256(raw).hexdigest(), data.n_M, data.n_q)
    if d.series is not None:
        bad = [i for i in d.series if i >= data.n_M]
        if bad:
            raise config_error(cfg, "data", "series", f"{bad} out of range: the data hold {data.n_M} series (0-based)")
    return data, camp


def dynamic_splits(cfg: StudyConfig, data: DynamicMeasurements) -> tuple:
    """The splits of [splits]: custom and random over the experiments, time windows, early vs late."""
    from identification.studies.splits import early_late_dynamic_split, time_window_splits
    s = cfg.splits
    if s.scenarios:
        raise config_error(cfg, "splits", "scenarios", "the press scenarios do not apply to a dynamic study; set "
                           "scenarios = [] and use [[splits.custom]] (experiments), [splits.random], time_windows "
                           "or early_late")
    cols = [c.name for c in s.custom if c.cal_sensors is not None or c.val_sensors is not None]
    if cols:
        raise config_error(cfg, "splits.custom", "cal_sensors", f"split {cols[0]!r}: a dynamic study splits the "
                           "sampling times with [splits] time_windows or early_late, not by sensor columns")
    out = [Split(c.name, c.cal_inputs, c.val_inputs, description="experiments") for c in s.custom]
    if s.random.n:
        out += list(random_splits(data.n_q, s.random.n, s.random.cal_fraction, s.random.seed))
    t = data.union_times
    if s.time_windows:
        bad = [e for e in s.time_windows if not t[0] < e <= t[-1]]
        if bad:
            raise config_error(cfg, "splits", "time_windows", f"edge {bad[0]:g} leaves no reading on one side "
                               f"(the sampling times run from {t[0]:g} to {t[-1]:g})")
        out += list(time_window_splits(s.time_windows))
    if s.early_late:
        out.append(early_late_dynamic_split(data))
    for sp in out:
        if isinstance(sp, Split):
            sp.check(data.n_q, data.n_M)
    names = [sp.name for sp in out]
    if len(set(names)) != len(names):
        raise ConfigError(f"{cfg.path}: [splits] split names must be unique, got {names}")
    return tuple(out)


def build_dynamic(cfg: StudyConfig, built: dict) -> tuple:
    """({variant: bounded model}, p0, experiments Q) of the factory's dynamic models ``built``."""
    if cfg.dynamic is None:
        raise ConfigError(f"{cfg.path}: [model] {cfg.model.name} is a dynamic (ODE/DAE) model: add a [dynamic] "
                          "section with times = [...] and one [[dynamic.experiments]] table per experiment")
    models, p0s = {}, {}
    for v, m in built.items():
        models[v], p0s[v] = _bounded(cfg, m)
    known = {n for m in models.values() for n in m.param_names}
    unknown = [pc.name for pc in cfg.parameters if pc.name not in known]
    if unknown:
        raise config_error(cfg, "parameters", "name", f"unknown parameter(s) {', '.join(unknown)}; the model has "
                           f"{', '.join(sorted(known))}")
    first = next(iter(models.values()))
    Q = experiment_rows(cfg, first)
    _checked_times(cfg, first, "times", cfg.dynamic.times)
    _checked_times(cfg, first, "candidate_times", cfg.dynamic.candidates())
    return models, p0s, Q


def prepare_dynamic(cfg: StudyConfig, built: dict, progress=None) -> Study:
    """The study of dynamic models ``built`` ({variant: model from the factory}): the long-format campaign, one
    sigma per instrument, the splits, the experiments' inputs and the start values of every variant."""
    models, p0s, Q = build_dynamic(cfg, built)
    first = next(iter(models.values()))
    sig = config_sigma(cfg, first)
    given = None if np.all(np.isnan(sig)) else sig
    if given is not None and np.any(np.isnan(sig)):
        raise ConfigError(f"{cfg.path}: [[sensors]] give every instrument a sigma, or none (estimated)")
    data_all, camp = _load(cfg, first, Q, given)
    det = cfg.detect.settings()
    norm = normality_check(data_all.by_instrument(), det.normality_level, correction=det.normality_correction)
    norm = dataclasses.replace(norm, note=POOLED_NOTE)
    rows = tuple(dict(sensor=s, how="given" if given is not None else "estimated from the residuals",
                      sigma_rep=float(norm.sigma_rep[k]), sigma_man=math.nan,
                      sigma=float(sig[k])) for k, s in enumerate(first.sensors))
    data = data_all if cfg.data.series is None else data_all.subset(series=list(cfg.data.series))
    splits = dynamic_splits(cfg, data)
    notes = (f"{data.n_q} experiments, {data.union_times.size} sampling times, {data.n_M} series; one sigma per "
             "instrument",)
    return Study(cfg, camp, tuple(first.sensors), given, rows, norm, models, {v: data for v in models},
                 {v: data_all for v in models}, p0s[next(iter(models))], splits, notes, None, (), kind=TIME_SERIES,
                 inputs=Q, times=tuple(cfg.dynamic.times), p0s=p0s, truth=simulation_truth(cfg, models, p0s))


def simulation_truth(cfg: StudyConfig, models: dict, p0s: dict) -> SimulationTruth | None:
    """The true parameters of the study's data when they are the config's own simulation, else None.

    Known when the config has a ``[simulate] truth`` and the data file's folder holds the
    ``simulate.json`` that ``mudoe simulate`` wrote beside it naming the same model, variant and true
    values (the [simulate] truth completed with the [[parameters]] starts, as :func:`simulate_dynamic`
    does, equal to 1e-12 relative); real data beside a [simulate] section show no truth.
    """
    sc = cfg.simulate
    if not sc.truth or cfg.data.source != "csv":
        return None
    variant = sc.variant or next(iter(models))
    if variant not in models:
        return None
    truth = dict(zip(models[variant].param_names, (float(v) for v in p0s[variant])))
    truth.update({k: float(v) for k, v in sc.truth.items()})
    try:
        rec = json.loads((cfg.resolve(cfg.data.directory) / "simulate.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(rec, dict) or rec.get("model") != cfg.model.name or rec.get("variant") != variant:
        return None
    told = rec.get("truth")
    if not isinstance(told, dict) or set(told) != set(truth) or Path(cfg.data.file).name not in rec.get("files", ()):
        return None
    if not all(isinstance(told[n], (int, float)) and math.isclose(told[n], v, rel_tol=1e-12, abs_tol=0.0)
               for n, v in truth.items()):
        return None
    return SimulationTruth(variant, truth, f"[simulate] truth of {Path(cfg.path).name}, the campaign's simulate.json "
                                           f"(variant {variant}, seed {rec.get('seed')})")


# ---------------------------------------------------------------------------- simulate
@dataclass(frozen=True, eq=False)
class SimulatedDynamic(Simulation):
    """A simulated time-series campaign: the data, the variant, the true parameters, the seed, the units."""

    data: DynamicMeasurements
    variant: str
    truth: dict
    seed: int
    units: tuple = field(default_factory=tuple)

    def texts(self, cfg: StudyConfig) -> dict:
        """{file name: text} of the long-format CSV of [data] file and simulate.json (plus "record": its text)."""
        d, name = self.data, Path(cfg.data.file).name
        with tempfile.TemporaryDirectory() as tmp:
            csv_text = write_long_csv(Path(tmp) / name, d, units=self.units).read_text()
        record = dict(model=cfg.model.name, variant=self.variant, seed=self.seed, n_series=d.n_M,
                      n_experiments=d.n_q, times=[float(t) for t in d.union_times], truth=self.truth,
                      sigma_model_units=dict(zip(d.sensors, (float(s) for s in d.sigma))),
                      units=dict(zip(d.sensors, self.units)),
                      layout="long (series, experiment, time, sensor, value, unit)", files=[name, "simulate.json"])
        text = json.dumps(record, indent=1) + "\n"
        return {name: csv_text, "simulate.json": text, "record": text}

    def write(self, cfg: StudyConfig, out) -> tuple:
        """(paths, record): the long-format CSV and simulate.json written into ``out`` as one (all or none)."""
        texts = self.texts(cfg)
        paths = atomic_write_texts({Path(out) / name: text for name, text in texts.items() if name != "record"})
        return paths, json.loads(texts["record"])


def simulate_dynamic(cfg: StudyConfig, built: dict, seed: int | None = None) -> SimulatedDynamic:
    """A campaign z = h(x(t), p_true, u) + sigma e at the [dynamic] times of every experiment
    (:func:`identification.fit.dynamic_fit.simulate_campaign`; [simulate] truth, n_series, seed)."""
    from identification.fit.dynamic_fit import simulate_campaign
    models, p0s, Q = build_dynamic(cfg, built)
    sc = cfg.simulate
    variant = sc.variant or next(iter(models))
    m = models[variant]
    truth = dict(zip(m.param_names, p0s[variant]))
    unknown = [k for k in sc.truth if k not in m.param_names]
    if unknown:
        raise config_error(cfg, "simulate", "truth", f"unknown parameter(s) {', '.join(unknown)}; the model has "
                           f"{', '.join(m.param_names)}")
    truth.update(sc.truth)
    sig = config_sigma(cfg, m)
    if np.any(np.isnan(sig)):
        raise ConfigError(f"{cfg.path}: [[sensors]] `mudoe simulate` needs every instrument's sigma (the noise)")
    seed = sc.seed if seed is None else int(seed)
    p = np.array([truth[n] for n in m.param_names], float)
    data = simulate_campaign(m, p, Q, np.asarray(cfg.dynamic.times, float), sig, n_series=sc.n_series, seed=seed)
    return SimulatedDynamic(data, variant, {n: float(truth[n]) for n in m.param_names}, seed, tuple(m.sensor_units))


# ---------------------------------------------------------------------------- the sampling-time design, the pages
def time_design(cfg, variant: str, model, p, inputs, sigma, planned: bool, progress=None):
    """The [oed] criterion's design of [dynamic] n_times candidate times (or pairs) at p: a
    :class:`oed.plan_records.DynamicDesign`, or with ``[oed] prior`` the exact robust design over the prior
    (:class:`oed.plan_records.RobustExactPlan`); with ``approximate = true`` the approximate sampling times
    (:class:`oed.dynamic_plans.ApproximateTimePlan`, :func:`mudoe.dynamic_plans.approximate_times`); with ``mode =
    "inputs"`` the next experiments (:class:`oed.dynamic_plans.ExperimentPlan`,
    :func:`mudoe.dynamic_plans.input_design`)."""
    from oed.best_designs import best_designs
    from oed import information, select_sensors_from_information
    dyn, o = cfg.dynamic, cfg.oed
    if o.mode not in ("sensors", "inputs"):
        raise ConfigError(f"{cfg.path}: [oed] mode = {o.mode!r}: a dynamic study designs sampling times "
                          "([dynamic] n_times, candidate_times, pairs; mode = \"sensors\") or its next experiments "
                          "(mode = \"inputs\")")
    if sigma is None:
        raise ConfigError(f"{cfg.path}: [[sensors]] a sampling-time design needs every instrument's sigma")
    if o.mode == "inputs":
        from ..dynamic_plans import input_design
        return input_design(cfg, variant, model, p, inputs, sigma, planned, progress or Progress(False))
    if o.approximate:
        from ..dynamic_plans import approximate_times
        return approximate_times(cfg, variant, model, p, inputs, sigma, planned)
    cand = np.asarray(dyn.candidates(), float)
    axis = "pairs" if dyn.pairs else "times"
    info = information(model, p, axis=axis, times=cand, inputs=inputs, sigma=sigma)
    n = dyn.n_times or min(model.n_p, len(info.labels))
    if o.prior:     # the exact robust sampling times over the prior (issue 31)
        from ..robust_plans import plan_robust_exact
        return plan_robust_exact(cfg, variant, model, lambda ps: information(model, ps, axis=axis, times=cand,
                                                                             inputs=inputs, sigma=sigma).F,
                                 info.labels, n, p, planned, "times")
    res = select_sensors_from_information(info, criterion=o.criterion, kind="gauss_newton", n_sensors=n)
    table = best_designs(info.F, None, list(info.labels), n, o.criterion, kind="gauss_newton", chosen=res.indices)
    return DynamicDesign(variant, planned, tuple(float(x) for x in p), tuple(float(x) for x in cand), dyn.pairs,
                         res, table)


def run_oed_dynamic(study, results, progress):
    """[oed] of a dynamic study at the estimate of its variant: ``results`` with the sampling times (plan,
    oed, oed_table)."""
    v = oed_variant(study)
    results = require_fit(study, results, v, progress, "oed", "; no information matrix to design with")
    est = results.estimates[v]
    sigma = (study.sigma if study.sigma is not None
             else instrument_sigma(study.sensors, est.sigma, readings=est.sensors))
    what = "input" if study.cfg.oed.mode == "inputs" else "sampling-time"
    with (progress.step(f"{what} design ({study.cfg.oed.criterion}, {v})") if what != "input"
          else contextlib.nullcontext()):            # the input design reports its own step
        d = time_design(study.cfg, v, study.models[v], est.p, study.inputs, sigma, planned=False, progress=progress)
    ranked = getattr(d, "table", None) is not None   # the local engine's DesignResult and ranked table (else none)
    return dataclasses.replace(
        results, plan=d, oed=d.result if ranked else None, oed_table=d.table if ranked else None, oed_variant=v,
        design_sensors=tuple(study.sensors),
        design_how=f"all instruments at every sampling time of the data (the {what} design is for the next "
                   f"{'experiments' if what == 'input' else 'campaign'})")


def plan_dynamic(cfg, built: dict, progress) -> DynamicDesign:
    """``[oed] planned = true`` for a dynamic model: the time design at the [[parameters]] starts, no data."""
    models, p0s, Q = build_dynamic(cfg, built)
    v = cfg.oed.variant or list(models)[-1]
    sig = config_sigma(cfg, models[v])
    if np.any(np.isnan(sig)):
        s = models[v].sensors[int(np.flatnonzero(np.isnan(sig))[0])]
        names = cfg.sensor_names()
        line = table_line(cfg.text, "sensors", names.index(s), "") if s in names else None
        raise ConfigError(f"{cfg.path}{f':{line}' if line else ''}: [[sensors]] a design without data needs every "
                          f"instrument's sigma; {s!r} has none")
    what = "input" if cfg.oed.mode == "inputs" else "sampling-time"
    with (progress.step(f"{what} design ({cfg.oed.criterion}, {v}, planned)") if what != "input"
          else contextlib.nullcontext()):
        return time_design(cfg, v, models[v], p0s[v], Q, sig, planned=True, progress=progress)


def trajectories(study, est, variant: str, level: float = 0.95, n_fine: int = 401) -> Trajectories:
    """The trajectories of ``variant`` at its estimate (see the module docstring)."""
    model = study.models[variant]
    data = study.data[variant]
    horizon = model.horizon if model.horizon is not None else float(data.union_times[-1])
    fine, d = np.linspace(0.0, horizon, n_fine), np.asarray(data.union_times, float)
    near = np.min(np.abs(fine[:, None] - d[None, :]), axis=1) <= 1e-9 * max(horizon, 1.0)   # 1.4000000000000001
    t = np.unique(np.r_[fine[~near], d])
    sigma = (study.sigma if study.sigma is not None
             else instrument_sigma(study.sensors, est.sigma, readings=est.sensors))
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
    fitted = np.full(data.z.shape[1:], np.nan)
    for j in range(n_q):
        n = int(np.isfinite(data.times[j]).sum())
        at = np.searchsorted(t, data.times[j, :n])
        fitted[j, :n] = h[j, at]
        res[:, j, :n] = (data.z[:, j, :n] - h[j, at][None]) / np.asarray(sigma, float)
    return Trajectories(t, h, q * np.sqrt(np.maximum(var, 0)), q * np.sqrt(np.maximum(var, 0) + s2), level, name,
                        res, float(err), DiscretisationSettings().tol_sigma, fitted=fitted)


def run_trajectories(study, results, progress):
    """``results`` with ``trajectories``: the trajectories of every fitted variant (for the report)."""
    out = dict(results.trajectories)
    for v, est in results.estimates.items():
        with progress.step(f"trajectories of {v} with prediction bands"):
            out[v] = trajectories(study, est, v)
    return dataclasses.replace(results, trajectories=out)


def mesh_summary(est) -> MeshSummary | None:
    """The :class:`MeshSummary` of a dynamic estimate (None for an estimate without a discretisation record)."""
    rec = est.diagnostics.discretisation if hasattr(est, "diagnostics") else None
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


# ---------------------------------------------------------------------------- mudoe init
def _num(v: float) -> str:
    return repr(float(v)) if math.isfinite(v) else ("inf" if v > 0 else "-inf")


_TEMPLATE_TAIL = """
[simulate]                      # `mudoe simulate CONFIG --out data`: a campaign from the model itself
# truth = {{}}                  # true parameters (default: the start values above)
n_series = 2                    # repeated series (the normality gate differences them); noise: the sigmas
seed = 1

[splits]
scenarios = []                  # the paper's press scenarios do not apply
early_late = true               # readings before the median sampling time against the later ones
# time_windows = [{mid}]        # one split per time e: t < e against t >= e
{custom}
[detect]
tol = 0.05                      # family-wise level
sensors = "all"                 # the instruments used by the tests (each at every sampling time)

[oed]
criterion = "D"                 # A | D | E of the sampling-time design

[validate]
n_runs = 50

[report]
title = "Model uncertainty study"
"""


_TEMPLATE_CUSTOM = """[[splits.custom]]               # experiments (0-based) against experiments
name = "first vs second experiment"
cal_inputs = [0]
val_inputs = [1]
"""
#: a model without inputs: one run, so no split by experiment (a repeated run is one more empty table)
_TEMPLATE_NO_CUSTOM = """# [[splits.custom]]             # with repeated runs (more empty [[dynamic.experiments]] tables):
# name = "first vs second run"  # experiments (0-based) against experiments
# cal_inputs = [0]
# val_inputs = [1]
"""


def _template_experiment(model, scale: float) -> str:
    if not model.inputs:
        return ("[[dynamic.experiments]]             # the model has no inputs: one empty table per run "
                "(repeat it for repeated runs)")
    units = list(model.input_units) + [""] * len(model.inputs)
    lines = ["[[dynamic.experiments]]             # EDIT: the inputs of each experiment (model units)"]
    for k, n in enumerate(model.constants):
        lines.append(f"{n} = {scale:g}" + (f"                  # {units[k]}" if units[k] else ""))
    for c in model.controls:
        vals = ", ".join(f"{scale:g}" for _ in c.grid)
        lines.append(f"{c.name} = [{vals}]   # one value per grid point {', '.join(f'{g:g}' for g in c.grid)}"
                     + (f" ({c.unit})" if getattr(c, "unit", "") else ""))
    return "\n".join(lines)


def dynamic_template_text(model, name: str) -> str:
    """The commented TOML template of a dynamic model (see the module docstring)."""
    horizon = model.horizon or 1.0
    times = [round(horizon * k / 10, 10) for k in range(1, 11)]
    unit = f" ({model.time_unit})" if model.time_unit else ""
    parts = [f"""\
# mudoe study config (TOML) of a dynamic model.  README "Config reference" lists every key.
# Indices (series, experiments) are 0-based.  Paths are relative to this file.

[model]
name = "{name}"   # your factory: function(variant) -> models.Model.ode(...)
variants = ["default"]

[data]
source = "csv"
layout = "tidy"
directory = "data"              # `mudoe simulate CONFIG --out data` writes the file
file = "campaign_long.csv"      # long format: series, experiment, time, sensor, value, unit

[dynamic]
times = [{', '.join(f'{t:g}' for t in times)}]   # sampling times{unit}
# candidate_times = [...]       # candidates of the sampling-time design (default: times)
# n_times = {model.n_p}                   # sampling times chosen (default: one per parameter)
# pairs = false                 # choose (time, instrument) pairs instead
{_template_experiment(model, 1.0)}
""" + (f"{_template_experiment(model, 2.0)}\n" if model.inputs else "")]
    for s, u in zip(model.sensors, model.sensor_units):
        parts.append(f'[[sensors]]\nname = "{s}"\nsigma = 0.01                    # one per instrument'
                     f'{" (" + u + ")" if u else ""}, not per time\n' + (f'unit = "{u}"\n' if u else ""))
    for p in model.params:
        start = p.scale or ((p.lower + p.upper) / 2 if math.isfinite(p.lower) and math.isfinite(p.upper) else 1.0)
        unit = f'unit = "{p.unit}"\n' if p.unit else ""
        parts.append(f'[[parameters]]\nname = "{p.name}"\nstart = {_num(start)}               # start value'
                     f'\nlower = {_num(p.lower)}\nupper = {_num(p.upper)}\n' + unit)
    return "\n".join(parts) + _TEMPLATE_TAIL.format(mid=f"{times[len(times) // 2]:g}",
                                          custom=_TEMPLATE_CUSTOM if model.inputs else _TEMPLATE_NO_CUSTOM)


# ---------------------------------------------------------------------------- the kind
class TimeSeriesKind(StudyKind):
    """A time-series study (see the module docstring)."""

    name = "time series"
    report_pages = "trajectories"
    model_error_refusal = ""           # model_error takes a dynamic model through its Problem (issue 29)
    input_rows = "experiments"
    normality_over = "every (experiment, time) reading, pooled per instrument"

    def prepare(self, cfg, built, progress):
        return prepare_dynamic(cfg, {v: b.model for v, b in built.items()}, progress)

    def simulate(self, cfg, built, seed):
        return simulate_dynamic(cfg, {v: b.model for v, b in built.items()}, seed)

    def plan_without_data(self, cfg, built, progress):
        return plan_dynamic(cfg, {v: b.model for v, b in built.items()}, progress)

    def run_oed(self, study, results, progress):
        return run_oed_dynamic(study, results, progress)

    def oed_files(self, study, results, progress) -> tuple:
        """The design at the estimate (its plan record): sampling times, or with mode "inputs" the next
        experiments."""
        plan = self.run_oed(study, results, progress).plan
        return plan.summary(), plan.to_dict()

    def plan_at_estimate(self, study, results, progress):
        """The design :meth:`run_oed` made (its sampling times or next experiments; None if it failed)."""
        return results.plan

    def diagnose(self, study, results, progress):
        """No diagnostic split family (its splits are of set points and series)."""
        return results

    def bands(self, study, results, level):
        """The bands are the trajectories' (:meth:`report_runs`)."""
        return results

    def report_runs(self, study, results, progress):
        """The trajectories of every fit with their bands, the mesh of each fit, and the pages "Model error of
        ..." (the discrepancy against time; :mod:`mudoe.model_error_runs`; a failure becomes a note)."""
        results = run_trajectories(study, run_discretisation(study, results), progress)
        return run_model_error_pages(study, results, progress)

    def validation_problem(self, study, results, variant, est, used) -> tuple:
        return validation_problem(study, results, est, used)

    def template_text(self, model, name):
        return dynamic_template_text(model, name)


#: the time-series kind
TIME_SERIES = TimeSeriesKind()
