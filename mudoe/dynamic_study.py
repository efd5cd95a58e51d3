r"""A study of a dynamic (ODE/DAE) model: the config's ``[dynamic]`` section turned into a study.

The same commands as for a static model (:mod:`mudoe.study` dispatches here): the data are a
long-format CSV (:mod:`mudoe.dynamic_io`) over the experiments of ``[[dynamic.experiments]]``,
one sigma per instrument ([[sensors]]), splits by experiment ([[splits.custom]],
[splits.random]), by time window (``[splits] time_windows``) and early against late
(``[splits] early_late``); the design chooses sampling times (:func:`oed.select_times`); the
report draws each experiment's trajectories h(x(t)) with the data and delta-method bands

.. math::

    h(t) \pm q \sqrt{g(t)^T C g(t)}, \qquad g = \partial h / \partial p

(exact sensitivities of the collocated model on a mesh whose error is within the fit's tolerance).
"""
from __future__ import annotations

import copy
import dataclasses
import hashlib
import math
from dataclasses import dataclass, field

import numpy as np

from identification.studies.detect import normality_check
from identification.fit.dynamic_data import DynamicMeasurements
from identification.studies.splits import Split, random_splits
from models.cache import Cache
from models.contract import ModelError, Parameter

from .config import ConfigError, StudyConfig, config_error
from .config_errors import entry_error
from .data_io import DataFileError
from .parameter_units import model_parameters
from .study_base import Study, load_factory
from .units import UnitError, convert

__all__ = ["DynamicCampaign", "DynamicStudy", "is_dynamic", "is_dynamic_study", "experiment_rows", "prepare_dynamic",
           "dynamic_splits", "simulate_dynamic", "build_dynamic", "instrument_sigma", "write_simulation"]


def is_dynamic(model) -> bool:
    return bool(getattr(model, "is_dynamic", False))


def is_dynamic_study(cfg: StudyConfig, built: dict) -> bool:
    """Whether the study's models ({variant: VariantModel}) are dynamic; [dynamic] needs one."""
    dyn = [is_dynamic(b.model) for b in built.values()]
    if any(dyn) and not all(dyn):
        raise ConfigError(f"{cfg.path}: [model] variants mix dynamic (ODE/DAE) and static models")
    if cfg.dynamic is not None and not any(dyn):
        raise ConfigError(f"{cfg.path}: [dynamic] is for dynamic models (models.Model.ode); {cfg.model.name} "
                          "returns a static model")
    return any(dyn)


@dataclass(frozen=True)
class DynamicCampaign:
    """What the report and results.json record of a dynamic campaign's file."""

    source: str
    files: tuple
    sha256: str
    n_M: int
    n_q: int
    notes: tuple = ()


@dataclass(frozen=True, eq=False)
class DynamicStudy(Study):
    """A :class:`mudoe.study.Study` of a dynamic model: ``data`` are :class:`DynamicMeasurements`,
    ``inputs`` the experiments' input rows (model units), ``times`` the [dynamic] sampling times."""

    inputs: np.ndarray = None
    times: tuple = ()
    p0s: dict = field(default_factory=dict)
    is_dynamic = True

    def start_values(self, variant: str) -> np.ndarray:
        """The start values of a variant's fits (the variants may differ in parameters)."""
        return self.p0s.get(variant, self.p0)


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


def instrument_sigma(cfg: StudyConfig, model) -> tuple:
    """(sigma per instrument in the model's units or None, rows of the sigma table); sigma_man needs
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
    return np.array(sig)


# ---------------------------------------------------------------------------- the study
def _load(cfg: StudyConfig, model, Q, sigma) -> tuple:
    from .dynamic_io import read_long_csv
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


def prepare_dynamic(cfg: StudyConfig, built: dict, progress=None) -> DynamicStudy:
    """The study of dynamic models ``built`` ({variant: model from the factory})."""
    models, p0s, Q = build_dynamic(cfg, built)
    first = next(iter(models.values()))
    sig = instrument_sigma(cfg, first)
    given = None if np.all(np.isnan(sig)) else sig
    if given is not None and np.any(np.isnan(sig)):
        raise ConfigError(f"{cfg.path}: [[sensors]] give every instrument a sigma, or none (estimated)")
    data_all, camp = _load(cfg, first, Q, given)
    det = cfg.detect.settings()
    norm = normality_check(data_all.by_instrument(), det.normality_level, correction=det.normality_correction)
    norm = type(norm)(**{**norm.__dict__, "note": "pooled per instrument over every (experiment, time) reading"})
    rows = tuple(dict(sensor=s, how="given" if given is not None else "estimated from the residuals",
                      sigma_rep=float(norm.sigma_rep[k]), sigma_man=math.nan,
                      sigma=float(sig[k])) for k, s in enumerate(first.sensors))
    data = data_all if cfg.data.series is None else data_all.subset(series=list(cfg.data.series))
    splits = dynamic_splits(cfg, data)
    notes = (f"{data.n_q} experiments, {data.union_times.size} sampling times, {data.n_M} series; one sigma per "
             "instrument",)
    return DynamicStudy(cfg, camp, tuple(first.sensors), given, rows, norm, models, {v: data for v in models},
                        {v: data_all for v in models}, p0s[next(iter(models))], splits, notes, None, (), inputs=Q,
                        times=tuple(cfg.dynamic.times), p0s=p0s)


# ---------------------------------------------------------------------------- simulate
@dataclass(frozen=True, eq=False)
class SimulatedDynamic:
    data: DynamicMeasurements
    variant: str
    truth: dict
    seed: int
    units: tuple = field(default_factory=tuple)


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
    sig = instrument_sigma(cfg, m)
    if np.any(np.isnan(sig)):
        raise ConfigError(f"{cfg.path}: [[sensors]] `mudoe simulate` needs every instrument's sigma (the noise)")
    seed = sc.seed if seed is None else int(seed)
    p = np.array([truth[n] for n in m.param_names], float)
    data = simulate_campaign(m, p, Q, np.asarray(cfg.dynamic.times, float), sig, n_series=sc.n_series, seed=seed)
    return SimulatedDynamic(data, variant, {n: float(truth[n]) for n in m.param_names}, seed, tuple(m.sensor_units))


def factory_models(cfg: StudyConfig) -> dict:
    """{variant: the factory's model} of [model]."""
    factory = load_factory(cfg.model.name, f"{cfg.path}: [model] name")
    return {v: factory(v) for v in cfg.model.variants}


def write_simulation(cfg: StudyConfig, seed: int | None, out, texts: dict | None = None):
    """``mudoe simulate`` of a dynamic study.  ``out=None``: the simulated files' texts {name: text} (the
    long-format CSV of [data] file, simulate.json); else those ``texts`` written into ``out`` as one
    (all or none), returning (paths, record)."""
    import json
    import tempfile
    from pathlib import Path
    from models.fileio import atomic_write_texts
    from .dynamic_io import write_long_csv
    if out is not None:
        paths = atomic_write_texts({Path(out) / name: text for name, text in texts.items() if name != "record"})
        return paths, json.loads(texts["record"])
    sim = simulate_dynamic(cfg, factory_models(cfg), seed)
    d, name = sim.data, Path(cfg.data.file).name
    with tempfile.TemporaryDirectory() as tmp:
        csv_text = write_long_csv(Path(tmp) / name, d, units=sim.units).read_text()
    record = dict(model=cfg.model.name, variant=sim.variant, seed=sim.seed, n_series=d.n_M, n_experiments=d.n_q,
                  times=[float(t) for t in d.union_times], truth=sim.truth,
                  sigma_model_units=dict(zip(d.sensors, (float(s) for s in d.sigma))),
                  units=dict(zip(d.sensors, sim.units)), layout="long (series, experiment, time, sensor, value, unit)",
                  files=[name, "simulate.json"])
    text = json.dumps(record, indent=1) + "\n"
    return {name: csv_text, "simulate.json": text, "record": text}
