"""A study: the config turned into models, data, sigma, splits -- and thin runs of the library.

Every function here is a thin layer over :mod:`identification`, :mod:`oed` and :mod:`models`:
it only assembles their arguments from a :class:`mudoe.config.StudyConfig` and collects
their results in :class:`StudyResults` for the CLI and the report builder.
"""
from __future__ import annotations

import contextlib
import copy
import dataclasses
import math
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from identification import Measurements, identify, information_contributions
from identification.studies.detect import NormalityCheck, normality_check
from identification.progress import Progress as BaseProgress
from identification.studies.splits import Split, random_splits, splits_from_scenarios
from models.campaign import Campaign
from models.contract import Model, ModelError
from models.press import PRESS_SCENARIO_NAMES, press_scenario_rows
from models.shipping import ModelSource

from .checks import call_factory, check_data, check_model, study_splits
from .config import ConfigError, StudyConfig, config_error
from .console import INTERRUPT
from .data_io import DataFileError, DataUnits, load_campaign, study_units
from .parameter_units import model_parameters
from .press import diagnosis_explanations, press_variant

__all__ = ["Study", "StudyResults", "prepare", "load_factory", "SimulatedCampaign", "simulate_study", "run_identify", "run_oed", "run_detect", "run_validate",
           "run_diagnosis", "Progress", "MissingPieceError", "FitFailedError",
           "PlannedDesign", "DiscriminationPlan", "plan_design", "plan_without_data", "plan_at_estimate",
           "plan_discrimination"]


class MissingPieceError(RuntimeError):
    """A library piece this command needs is not available (yet); the message says which."""


class FitFailedError(RuntimeError):
    """A fit the command needs failed (a failed computation, exit 1); the message gives the fit's error."""


# ---------------------------------------------------------------------------- progress
class Progress(BaseProgress):
    """The study's progress: :class:`identification.progress.Progress` with the prefix "mudoe: ".

    Every step checks for Ctrl-C (:data:`mudoe.console.INTERRUPT`) when it starts and ends, so
    that an interrupt a solver turned into a failed fit still stops the run.
    """

    def __init__(self, enabled: bool = True, stream=None):
        super().__init__(enabled, stream, prefix="mudoe: ")

    @contextmanager
    def step(self, label: str, announce: bool = True):
        INTERRUPT.check()
        with super().step(label, announce):
            yield
        INTERRUPT.check()


# ---------------------------------------------------------------------------- the study
@dataclass(frozen=True, eq=False)
class Study:
    """Everything a run needs, assembled from a config.

    Attributes
    ----------
    cfg : StudyConfig
    campaign : Campaign          every series, model units (the press: mm, N)
    sensors : tuple of str       the model's sensors (order of z)
    sigma : ndarray or None      sensor sigma (model units) used by every fit (None: estimated)
    sigma_table : tuple of dict  per sensor: sigma_rep, sigma_man, sigma (model units) and how obtained
    normality : NormalityCheck   Shapiro-Wilk on differences of consecutive series (all series)
    models : dict {variant: Model}
    data : dict {variant: Measurements}   the study's series, with each variant's inputs
    data_all : dict {variant: Measurements}  every series
    p0 : ndarray                 start values
    splits : tuple of Split
    notes : tuple of str         what was done to the data
    units : DataUnits            units of the data in the files and in the model (the one conversion)
    explanations : tuple         what the study knows of its diagnostic rejections
                                 (:class:`reports.diagnosis.Explanation`; the press: the shipped campaign's)
    """

    cfg: StudyConfig
    campaign: Campaign
    sensors: tuple
    sigma: np.ndarray | None
    sigma_table: tuple
    normality: NormalityCheck
    models: dict
    data: dict
    data_all: dict
    p0: np.ndarray
    splits: tuple
    notes: tuple = ()
    units: DataUnits | None = None
    explanations: tuple = ()


@dataclass
class StudyResults:
    """What the commands produced (fields stay None when the command was not run)."""

    study: Study
    estimates: dict = field(default_factory=dict)
    estimate_errors: dict = field(default_factory=dict)
    oed: object = None
    oed_table: object = None
    oed_variant: str = ""
    plan: object = None
    design_sensors: tuple = ()
    design_how: str = ""
    detection: object = None
    detection_error: str = ""
    diagnosis: object = None
    validation: object = None
    trajectories: dict = field(default_factory=dict)     # dynamic studies: {variant: Trajectories}
    discretisation: dict = field(default_factory=dict)   # dynamic studies: {variant: dynamic_runs.MeshSummary}
    timing: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)


# ---------------------------------------------------------------------------- models
def _build_models(cfg: StudyConfig) -> dict:
    """{variant: (Model, inputs_fn)} with inputs_fn(q_set) -> input matrix (n_q, d_q)."""
    out = {}
    if cfg.model.name == "press":
        for v in cfg.model.variants:
            m, fn = press_variant(v, cfg)
            out[v] = (_apply_parameters(cfg, m), fn)
        return out
    factory = _factory(cfg)
    for v in cfg.model.variants:
        m = call_factory(factory, cfg.model.name, v, lambda msg: config_error(cfg, "model", "name", msg))
        if getattr(m, "is_dynamic", False):           # an ODE/DAE model: mudoe.dynamic_study
            m.origin = ModelSource(cfg.model.name, v)
            out[v] = (m, None)
            continue
        if not isinstance(m, Model):
            raise ConfigError(f"{cfg.path}: [model] name: {cfg.model.name}({v!r}) returned "
                              f"{type(m).__name__}, expected a models.Model")
        m.origin = ModelSource(cfg.model.name, v)     # worker processes may rebuild it from here
        out[v] = (_apply_parameters(cfg, m), getattr(m, "mudoe_inputs", None))
    return out


def _factory(cfg: StudyConfig) -> Callable:
    return load_factory(cfg.model.name, f"{cfg.path}: [model] name")


def load_factory(name: str, where: str) -> Callable:
    """The model factory ``"package.module:function"`` (``where`` starts the error message).

    Raises
    ------
    ConfigError
        The module cannot be imported or has no such function.
    """
    import importlib
    mod_name, _, fn_name = name.partition(":")
    if not mod_name or not fn_name:
        raise ConfigError(f"{where}: expected \"package.module:function\", got {name!r}")
    try:
        mod = importlib.import_module(mod_name)
    except ImportError as exc:
        raise ConfigError(f"{where}: cannot import {mod_name!r} ({exc}); is its folder on PYTHONPATH?") from None
    fn = getattr(mod, fn_name, None)
    if not callable(fn):
        raise ConfigError(f"{where}: {mod_name} has no function {fn_name!r}")
    return fn


def _apply_parameters(cfg: StudyConfig, m: Model) -> Model:
    """A copy of the model with the config's parameter bounds."""
    if not cfg.parameters:
        return m
    names = [p.name for p in cfg.parameters]
    unknown = [n for n in names if n not in m.param_names]
    if unknown:
        raise ConfigError(f"{cfg.path}: [[parameters]] unknown parameter(s) {', '.join(unknown)}; the model has "
                          f"{', '.join(m.param_names)}")
    missing = [n for n in m.param_names if n not in names]
    if missing:
        raise ConfigError(f"{cfg.path}: [[parameters]] missing start value(s) for {', '.join(missing)}")
    cfg = dataclasses.replace(cfg, parameters=model_parameters(cfg, m))
    try:
        new = m.with_bounds({pc.name: (pc.lower, pc.upper) for pc in cfg.parameters})
    except ModelError as exc:
        raise ConfigError(f"{cfg.path}: [[parameters]] {exc}") from None
    units = {pc.name: pc.unit for pc in cfg.parameters if pc.unit}
    new.params = tuple(dataclasses.replace(p, unit=p.unit or units.get(p.name, "")) for p in new.params)
    return new


def _declare_units(m: Model, units: DataUnits) -> Model:
    """The model with the data's model-side units where it declares none (for tables and the report)."""
    q_units = (units.input_model or m.input_units[0],) + tuple(m.input_units[1:])
    s_units = tuple(own or u for own, u in zip(m.sensor_units, units.output_model))
    if q_units == tuple(m.input_units) and s_units == tuple(m.sensor_units):
        return m
    new = copy.copy(m)
    new.input_units = tuple(own or u for own, u in zip(m.input_units, q_units))
    new.sensor_units = s_units
    return new


def _p0(cfg: StudyConfig, m: Model) -> np.ndarray:
    if cfg.parameters:
        d = {p.name: p.start for p in model_parameters(cfg, m)}
        return np.array([d[n] for n in m.param_names], float)
    nominal = getattr(m, "p_nominal", None)
    if nominal is None:
        raise ConfigError(f"{cfg.path}: [[parameters]] give start values for {', '.join(m.param_names)}")
    return np.asarray(nominal, float)


# ---------------------------------------------------------------------------- sigma
def _sigma(cfg: StudyConfig, sensors, norm: NormalityCheck, units: DataUnits):
    if not cfg.sensors:
        return None, tuple(dict(sensor=s, how="estimated from the residuals (no [[sensors]] given)",
                                sigma_rep=float(norm.sigma_rep[k]), sigma_man=math.nan, sigma=math.nan)
                           for k, s in enumerate(sensors))
    names = cfg.sensor_names()
    unknown = [n for n in names if n not in sensors]
    if unknown:
        raise ConfigError(f"{cfg.path}: [[sensors]] unknown sensor(s) {', '.join(unknown)}; the model has "
                          f"{', '.join(sensors)}")
    missing = [s for s in sensors if s not in names]
    if missing:
        raise ConfigError(f"{cfg.path}: [[sensors]] no entry for sensor(s) {', '.join(missing)} of the model "
                          f"({', '.join(sensors)}); list every sensor with sigma or sigma_man")
    sig, rows = [], []
    for k, s in enumerate(sensors):
        sc = cfg.sensors[names.index(s)]
        rep = float(norm.sigma_rep[k])
        if sc.sigma is not None:
            v, how, man = units.sigma_to_model(k, sc.sigma), "given", math.nan
        elif sc.sigma_man is not None:
            if not math.isfinite(rep):
                raise DataFileError(f"{cfg.path}: sensor {s!r}: sigma_man needs the repeatability of the data, "
                                    "which needs at least two series; give sigma directly")
            man = units.sigma_to_model(k, sc.sigma_man)
            v, how = math.sqrt(rep ** 2 + man ** 2), "sqrt(sigma_rep^2 + sigma_man^2)"
        else:
            v, how, man = math.nan, "estimated", math.nan
        sig.append(v)
        rows.append(dict(sensor=s, how=how, sigma_rep=rep, sigma_man=man, sigma=v))
    sig = np.array(sig)
    if np.all(np.isnan(sig)):
        return None, tuple(rows)
    if np.any(np.isnan(sig)):
        bad = [s for s, v in zip(sensors, sig) if math.isnan(v)]
        raise ConfigError(f"{cfg.path}: [[sensors]] {', '.join(bad)} lack sigma or sigma_man while others have "
                          "one; give every sensor a sigma, or none (common sigma estimated)")
    return sig, tuple(rows)


# ---------------------------------------------------------------------------- splits
def _splits(cfg: StudyConfig, n_q: int, q_set) -> tuple:
    s = cfg.splits
    out = []
    if s.scenarios:
        allsc = splits_from_scenarios(press_scenario_rows, n_q)
        wanted = PRESS_SCENARIO_NAMES if "paper" in s.scenarios else s.scenarios
        out += [sp for sp in allsc if sp.name in wanted]
    if s.random.n:
        excl = tuple(int(j) for j in np.flatnonzero(np.asarray(q_set) == 0)) if s.random.exclude_zero_force else ()
        out += list(random_splits(n_q, s.random.n, s.random.cal_fraction, s.random.seed, exclude=excl))
    for c in s.custom:
        out.append(Split(c.name, c.cal_inputs, c.val_inputs, c.cal_series, c.val_series, "user split", c.cal_sensors,
                         c.val_sensors))
    names = [sp.name for sp in out]
    if len(set(names)) != len(names):
        raise config_error(cfg, "splits.custom" if s.custom else "splits", "name" if s.custom else "scenarios",
                           f"split names must be unique, got {names}; rename the custom split")
    return tuple(out)


def prepare(cfg: StudyConfig, progress: Progress | None = None) -> Study:
    """Load the data, build the models, compose sigma and the splits of a study.

    Raises
    ------
    ConfigError, DataFileError, identification.DataError, identification.studies.splits.SplitError
        Bad config or data (the message names the file / key).
    MissingPieceError
        A model variant needs a package that is not available yet.
    """
    progress = progress or Progress(False)
    with progress.step("build models " + ", ".join(cfg.model.variants), announce=False):
        built = _build_models(cfg)
    if _dynamic(cfg, built):
        from .dynamic_study import prepare_dynamic
        return prepare_dynamic(cfg, {v: m for v, (m, _) in built.items()}, progress)
    sensors = tuple(next(iter(built.values()))[0].sensors)
    check_model(cfg, next(iter(built.values()))[0])
    units = study_units(cfg, next(iter(built.values()))[0])
    built = {v: (_declare_units(m, units), fn) for v, (m, fn) in built.items()}
    with progress.step(f"load data ({cfg.data.source})", announce=cfg.data.source == "prototype"):
        campaign = load_campaign(cfg, sensors, units)
    n_M = campaign.n_M
    if cfg.data.series is not None:
        bad = [i for i in cfg.data.series if i >= n_M]
        if bad:
            raise config_error(cfg, "data", "series", f"series {bad} out of range: the data hold {n_M} series "
                               "(0-based indices)")
    splits = study_splits(cfg, campaign, _splits)
    check_data(cfg, campaign, splits, next(iter(built.values()))[0].n_p)
    m_all = Measurements(campaign.q_set[:, None], campaign.z, None, sensors=sensors, series=campaign.series)
    det = cfg.detect.settings()
    norm = normality_check(m_all, det.normality_level, correction=det.normality_correction)
    sigma, sig_rows = _sigma(cfg, sensors, norm, units)
    models, data, data_all = {}, {}, {}
    for v, (m, fn) in built.items():
        q = campaign.q_set[:, None] if fn is None else np.asarray(fn(campaign.q_set), float)
        if tuple(m.sensors) != tuple(sensors):
            raise ConfigError(f"{cfg.path}: model {v} has sensors {list(m.sensors)} but the data {list(sensors)}")
        full = Measurements(q, campaign.z, sigma, sensors=sensors, input_names=m.inputs, series=campaign.series)
        models[v] = m
        data_all[v] = full
        data[v] = full if cfg.data.series is None else full.subset(series=list(cfg.data.series))
    first = next(iter(models.values()))
    p0 = _p0(cfg, first)
    explanations = diagnosis_explanations(campaign, tuple(models)) if cfg.model.name == "press" else ()
    return Study(cfg, campaign, sensors, sigma, sig_rows, norm, models, data, data_all, p0, splits,
                 campaign.notes, units, explanations)


def start_values(study: Study, variant: str) -> np.ndarray:
    """The start values of a variant's fits (a dynamic study's variants may differ in parameters)."""
    return getattr(study, "p0s", {}).get(variant, study.p0)


def _dynamic(cfg: StudyConfig, built: dict) -> bool:
    from .dynamic_study import is_dynamic_study
    return is_dynamic_study(cfg, built)


# ---------------------------------------------------------------------------- runs
def run_identify(study: Study, results: StudyResults, progress: Progress | None = None) -> StudyResults:
    """Identify every variant on the study's data (all sensors); failures are recorded, not raised (an
    estimate the data do not bound is recorded as a failure with its reason, "not bounded: ...")."""
    from identification.errors import IdentificationError
    progress = progress or Progress(False)
    for v, m in study.models.items():
        with progress.step(f"identify {v}"):
            try:
                est = identify(m, study.data[v], start_values(study, v))
            except IdentificationError as exc:
                results.estimate_errors[v] = f"{type(exc).__name__}: {exc}"
                continue
            if not est.bounded:      # no finite estimate: the pages of estimates need one; the reason is kept
                results.estimate_errors[v] = f"not bounded: {est.unbounded.reason}"
                continue
            results.estimates[v] = est
    return results


def _oed_variant(study: Study) -> str:
    return study.cfg.oed.variant or list(study.models)[-1]


def _require_fit(study: Study, results: StudyResults, v: str, progress: Progress, command: str,
                 why: str = "") -> None:
    """Identify the study's variants if ``v`` has no estimate yet; FitFailedError if its fit failed."""
    if v not in results.estimates:
        run_identify(study, results, progress)
    if v not in results.estimates:
        raise FitFailedError(f"{command}: the fit of variant {v} failed ({results.estimate_errors.get(v)}){why}")


def run_oed(study: Study, results: StudyResults, progress: Progress | None = None) -> StudyResults:
    """Lines 02-03 of Algorithm 1: information of every sensor at the estimate, design table, chosen design."""
    try:
        from oed.best_designs import design_rows
        from oed.design import select_sensors_from_information
    except ImportError as exc:
        raise MissingPieceError(f"oed: oed.design is not available ({exc})") from None
    progress = progress or Progress(False)
    if getattr(study, "is_dynamic", False):          # sampling times (mudoe.dynamic_runs)
        from .dynamic_runs import run_oed_dynamic
        run_oed_dynamic(study, results, progress)
        return results
    v = _oed_variant(study)
    _require_fit(study, results, v, progress, "oed", "; no information matrix to design with")
    est = results.estimates[v]
    o = study.cfg.oed
    with progress.step(f"optimal sensor design ({o.criterion}, {v})"):
        F, S = information_contributions(study.models[v], study.data[v], est.p, states=est.states)
        n_default = min(study.models[v].n_p, len(study.sensors))   # fewer sensors than parameters is allowed
        n = o.n_sensors if o.n_sensors is not None or o.max_sensors is not None else n_default
        res = select_sensors_from_information(F, S, criterion=o.criterion, kind=o.kind, n_sensors=n,
                                              max_sensors=o.max_sensors, costs=list(o.costs) if o.costs else None,
                                              budget=o.budget, include=o.include, exclude=o.exclude,
                                              sensor_names=study.sensors)
        table = design_rows(F, S if o.kind == "second_order" else None, study.sensors, o.min_sensors or n_default,
                            res, o.criterion, kind=o.kind)
    results.oed, results.oed_table, results.oed_variant = res, table, v
    results.design_sensors = tuple(res.sensors)
    results.design_how = (f"{o.criterion}-optimal ({o.kind} covariance) design of {len(res.sensors)} sensors "
                          f"at the {v} estimate")
    return results


def _design_sensors(study: Study, results: StudyResults, progress: Progress) -> tuple:
    """The sensors of the tests: the OED design, all sensors, or the names given ([detect] sensors)."""
    d = study.cfg.detect
    if d.sensors == "oed":
        if not results.design_sensors:
            run_oed(study, results, progress)
    elif d.sensors == "all":
        results.design_sensors, results.design_how = tuple(study.sensors), "all sensors"
    else:
        results.design_sensors, results.design_how = tuple(d.sensors), "sensors given in [detect] sensors"
    return results.design_sensors


def run_detect(study: Study, results: StudyResults, progress: Progress | None = None) -> StudyResults:
    """Algorithm 1 (lines 05-17) on every variant with the chosen sensors."""
    from identification.studies.detect import detect
    progress = progress or Progress(False)
    design = list(_design_sensors(study, results, progress))
    settings = study.cfg.detect.settings()
    with progress.step(f"detect: {len(study.models)} model(s) x {len(study.splits)} splits x 2 fits"):
        results.detection = detect(study.models, study.data, study.splits, {v: start_values(study, v) for v in study.models},
                                   design=design, settings=settings, progress=progress)
    return results


def run_diagnosis(study: Study, results: StudyResults, progress: Progress | None = None) -> StudyResults:
    """The diagnostic split family on every variant (:func:`reports.diagnosis.diagnose`; needs detection)."""
    from reports.diagnosis import diagnose
    progress = progress or Progress(False)
    if results.detection is None or getattr(study, "is_dynamic", False):   # diagnostic splits: static models
        return results
    with progress.step(f"what the models miss: diagnostic splits of {len(study.models)} model(s)"):
        results.diagnosis = diagnose(results, progress=progress)
    return results


def run_validate(study: Study, results: StudyResults, progress: Progress | None = None,
                 workers: int | None = 1, scheduler: str | None = None) -> StudyResults:
    """Monte Carlo size study of Algorithm 1 for one variant (data simulated from its own estimate).

    The replications run on ``workers`` local processes, or on the Dask scheduler at
    ``scheduler`` (an address; None: ``[validate] scheduler`` of the config, absent: local).
    """
    try:
        from identification.studies.montecarlo import validate
    except ImportError as exc:
        raise MissingPieceError(f"validate: identification.studies.montecarlo is not available ({exc})") from None
    from identification.cluster import connect
    progress = progress or Progress(False)
    vc = study.cfg.validate
    v = vc.variant or next(iter(study.models))
    settings = vc.settings(study.cfg.detect.tol, workers, progress.enabled, study.cfg.detect.normality_correction)
    if scheduler is not None:
        settings = dataclasses.replace(settings, scheduler=scheduler)
    address = settings.scheduler
    # connect before the fits: a scheduler that cannot be reached fails at once
    with contextlib.nullcontext() if address is None else connect(address) as client:
        if client is not None:
            settings = dataclasses.replace(settings, scheduler=client)
        _require_fit(study, results, v, progress, "validate")
        est = results.estimates[v]
        data = study.data[v]
        used = _design_sensors(study, results, progress)
        w = np.array([1.0 if s in used else 0.0 for s in study.sensors])
        model, splits, inputs, p0 = study.models[v], study.splits, data.inputs, start_values(study, v)
        if getattr(study, "is_dynamic", False):      # on the collocation at the estimate (mudoe.dynamic_runs)
            from .dynamic_runs import validation_problem
            model, splits, w = validation_problem(study, results, est, used)
        where = "" if address is None else f" on the Dask scheduler {address}"
        with progress.step(f"validate: Monte Carlo size study of {v}, {vc.n_runs} replications{where}"):
            results.validation = validate(model, splits, p0, p_true=est.p, inputs=inputs, sigma=est.sigma,
                                          n_M=data.n_M, weights=w, name=v, settings=settings)
    return results


# ---------------------------------------------------------------------------- simulate
@dataclass(frozen=True, eq=False)
class SimulatedCampaign:
    """A campaign simulated from the study's own model (``mudoe simulate``).

    Attributes
    ----------
    campaign : Campaign      readings in the model's units
    units : DataUnits        file and model units (the files are written in the file units)
    variant : str            the model variant simulated
    truth : dict             true parameters (model units)
    sigma : tuple of float   noise standard deviation per sensor (model units)
    seed : int
    truth_units : dict       {parameter: the model's unit of its true value} ("" undeclared)
    """

    campaign: Campaign
    units: DataUnits
    variant: str
    truth: dict
    sigma: tuple
    seed: int
    truth_units: dict = field(default_factory=dict)


def simulate_study(cfg: StudyConfig, seed: int | None = None) -> SimulatedCampaign:
    r"""Readings simulated from the study's model: z_ijk = h_k(y_j, p_true, q_j) + sigma_k e_ijk.

    y_j solves E(y_j, p_true, q_j) = 0, e_ijk ~ N(0, 1) from ``numpy.random.default_rng(seed)``,
    sigma_k is sensor k's [[sensors]] sigma (or sigma_man) converted to the model's unit, q_j the
    [simulate] set points converted from the [data] input unit; ``[simulate] truth`` (default the
    [[parameters]] start values) in model units.

    Raises
    ------
    ConfigError
        The press (use its virtual prototype), a sensor without sigma, missing true values.
    """
    if cfg.model.name == "press":
        raise ConfigError(f"{cfg.path}: [simulate] is for own models; the press simulates its virtual prototype")
    sc = cfg.simulate
    if not sc.inputs and sc.input_start is None:
        raise ConfigError(f"{cfg.path}: [simulate] give the set points: inputs = [...] or input_start, input_stop "
                          "and n_inputs (in the [data] input unit)")
    built = _build_models(cfg)
    if _dynamic(cfg, built):                 # without [dynamic] (with it the CLI writes the long format)
        from .dynamic_study import build_dynamic
        build_dynamic(cfg, {v: m for v, (m, _) in built.items()})
    variant = sc.variant or next(iter(built))
    m, fn = built[variant]
    units = study_units(cfg, m)
    m = _declare_units(m, units)
    truth = {p.name: p.start for p in model_parameters(cfg, m)}
    unknown = [k for k in sc.truth if k not in m.param_names]
    if unknown:
        raise ConfigError(f"{cfg.path}: [simulate] truth: unknown parameter(s) {', '.join(unknown)}; the model has "
                          f"{', '.join(m.param_names)}")
    truth.update(sc.truth)
    missing = [n for n in m.param_names if n not in truth]
    if missing:
        raise ConfigError(f"{cfg.path}: [simulate] truth: give the true value of {', '.join(missing)}")
    sens = {s.name: s for s in cfg.sensors}
    sigma = []
    for k, s in enumerate(m.sensors):
        given = sens[s].sigma if s in sens and sens[s].sigma is not None else (
            sens[s].sigma_man if s in sens else None)
        if given is None:
            raise ConfigError(f"{cfg.path}: [[sensors]] {s}: `mudoe simulate` needs the sensor's sigma (the noise)")
        sigma.append(units.sigma_to_model(k, given))
    q = units.q_to_model(sc.input_values())
    inputs = q[:, None] if fn is None else np.asarray(fn(q), float)
    p = np.array([truth[n] for n in m.param_names], float)
    seed = sc.seed if seed is None else int(seed)
    h = m.simulate(p, inputs)
    if not np.all(np.isfinite(h)):
        raise ConfigError(f"{cfg.path}: [simulate] the model's output is not finite at the truth {truth} for some "
                          "set point; check truth and the input range")
    rng = np.random.default_rng(seed)
    z = h[None] + np.asarray(sigma) * rng.standard_normal((sc.n_series,) + h.shape)
    camp = Campaign(q_set=q, q_actual=None, z=z, sensors=tuple(m.sensors),
                    source=f"simulated from {cfg.model.name} ({variant}, seed {seed})", seed=seed)
    return SimulatedCampaign(camp, units, variant, {n: float(truth[n]) for n in m.param_names}, tuple(sigma), seed,
                             truth_units={p.name: p.unit for p in m.params})


# ---------------------------------------------------------------------------- designs before data (issue 13)
@dataclass(frozen=True)
class PlannedDesign:
    """A design of ``[oed] mode`` (sensors, inputs or both) at parameters ``p``.

    ``result`` is an :class:`oed.DesignResult` (mode sensors) or an :class:`oed.inputs.InputDesignResult`;
    ``planned`` is True when no data were used (p = the [[parameters]] start values, S = 0).
    """

    variant: str
    mode: str
    planned: bool
    p: tuple
    candidates: tuple
    result: object

    def summary(self) -> str:
        """Text of the design (what was chosen, value, proof)."""
        head = (f"{self.mode} design of variant {self.variant} at p = {list(self.p)} "
                + ("(planned before data: Gauss-Newton, S = 0)" if self.planned else "(at the estimate)"))
        return head + "\n" + self.result.summary()

    def to_dict(self) -> dict:
        """JSON-ready view: the chosen sensors / input points, value, bound and proof."""
        r = self.result
        d = dict(variant=self.variant, mode=self.mode, planned=self.planned, p=list(self.p),
                 candidates=list(self.candidates), criterion=r.criterion, value=r.value,
                 lower_bound=r.lower_bound, proven_optimal=r.proven_optimal, method=r.method,
                 notes=list(r.notes))
        if self.mode == "sensors":
            d.update(sensors=list(r.sensors), indices=list(r.indices))
        else:
            d.update(indices=list(r.indices), set_points=[self.candidates[j] for j in r.indices],
                     pairs=[[j, s] for j, s in r.pairs])
            if r.refined is not None:
                f = r.refined
                d.update(refined=dict(set_points=f.inputs.ravel().tolist(), value=f.value,
                                      start_values=list(f.start_values), n_failed=f.n_failed,
                                      lower=f.lower.tolist(), upper=f.upper.tolist(), wall_time=f.wall_time))
        return d


def plan_design(cfg: StudyConfig, variant: str, model: Model, inputs_fn, p, sigma, planned: bool,
                progress: Progress | None = None) -> PlannedDesign:
    """The ``[oed]`` design of ``mode`` at ``p`` without data: sensors over the candidate inputs, or inputs.

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
    q_set = study_units(cfg, model).q_to_model(o.candidate_points())
    if q_set.size == 0:
        raise ConfigError(f"{cfg.path}: [oed] candidates: a design without data needs candidate inputs")
    Q = q_set[:, None] if inputs_fn is None else np.asarray(inputs_fn(q_set), float)
    if sigma is None:
        raise ConfigError(f"{cfg.path}: [[sensors]] a design needs every sensor's sigma (give sigma = ...)")
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
                                sensors="joint" if o.mode == "both" else None, refine=o.refine, **common)
    return PlannedDesign(variant, o.mode, planned, tuple(float(x) for x in p), tuple(float(x) for x in q_set), res)


def plan_without_data(cfg: StudyConfig, progress: Progress | None = None) -> PlannedDesign:
    """``[oed] planned = true``: the design at the [[parameters]] start values, no data read."""
    built = _build_models(cfg)
    if _dynamic(cfg, built):
        from .dynamic_runs import plan_dynamic
        return plan_dynamic(cfg, {k: m for k, (m, _) in built.items()}, progress or Progress(False))
    v = cfg.oed.variant or list(built)[-1]
    model, fn = built[v]
    check_model(cfg, model)
    sigma = _planned_sigma(cfg, model)
    p = _p0(cfg, model)
    bad = (p < model.lower) | (p > model.upper)
    if np.any(bad):
        raise ConfigError(f"{cfg.path}: [[parameters]] start values of {[model.param_names[i] for i in np.flatnonzero(bad)]} "
                          "lie outside their bounds (a planned design uses the start values as nominal parameters)")
    if cfg.oed.mode == "discrimination":
        return plan_discrimination(cfg, v, built, {v: p, cfg.oed.rival: _p0(cfg, built[cfg.oed.rival][0])}, sigma,
                                   True, progress=progress)
    return plan_design(cfg, v, model, fn, p, sigma, True, progress)


def _planned_sigma(cfg: StudyConfig, model: Model) -> np.ndarray:
    """Every sensor's ``sigma`` from [[sensors]] (converted to the model's units); without data sigma_man
    cannot be composed."""
    given = {sc.name: sc.sigma for sc in cfg.sensors}
    missing = [s for s in model.sensors if given.get(s) is None]
    if missing:
        raise ConfigError(f"{cfg.path}: [[sensors]] a design without data needs sigma for {', '.join(missing)} "
                          "(sigma_man needs the data's repeatability)")
    units = study_units(cfg, model)
    return np.array([units.sigma_to_model(k, given[s]) for k, s in enumerate(model.sensors)], float)


def plan_at_estimate(study: Study, results: StudyResults, progress: Progress | None = None) -> PlannedDesign:
    """``[oed] mode`` inputs / both (/ discrimination) with data: the design at the estimate of the variant."""
    progress = progress or Progress(False)
    v = _oed_variant(study)
    _require_fit(study, results, v, progress, "oed", "; no information matrix to design with")
    built = _build_models(study.cfg)
    if study.cfg.oed.mode == "discrimination":
        rival = study.cfg.oed.rival
        _require_fit(study, results, rival, progress, "oed", "; the rival's predictions need its estimate")
        est = results.estimates[v]
        sigma = study.sigma if study.sigma is not None else est.sigma
        built = {k: (study.models[k], built[k][1]) for k in (v, rival)}
        return plan_discrimination(study.cfg, v, built, {k: results.estimates[k] for k in (v, rival)}, sigma,
                                   False, q_default=study.campaign.q_set, progress=progress)
    fn = built[v][1]
    return plan_design(study.cfg, v, study.models[v], fn, results.estimates[v].p, study.sigma, False, progress)


# ---------------------------------------------------------------------------- discrimination designs (issue 13)
@dataclass(frozen=True)
class DiscriminationPlan:
    r"""A discrimination design (``[oed] mode = "discrimination"``) and its reference designs.

    ``result`` is the :class:`oed.DiscriminationResult` (variant assumed true, rival to be refuted);
    ``scores`` holds the per-reading T matrix ((h_v - h_rival) / sigma)^2 and, with data, the divergence
    matrix (h_v - h_rival)^2 / (2 sigma^2 + V_v + V_rival) (both (n_q, n_S), per series);
    ``references`` the readings of the comparison designs: ``"evenly spread"`` (the paper's style at the
    same number of set points: rows round(linspace(0, n_q - 1, k)), the same sensors; for n_readings
    designs k = ceil(n / n_S) rows x every sensor, the first n of these readings) and ``"all readings"`` (every candidate set
    point x every candidate sensor).
    """

    variant: str
    rival: str
    planned: bool
    p: tuple
    p_rival: tuple
    candidates: tuple
    n_series: int
    result: object
    scores: dict
    references: dict
    sensor_units: dict = field(default_factory=dict)
    refit: dict = field(default_factory=dict)

    mode = "discrimination"

    def values(self, readings) -> dict:
        """{criterion: n_series * sum of the per-reading scores over ``readings``} ((row, sensor) pairs)."""
        cols = self.result.candidate_sensors
        return {name: float(self.n_series * sum(d[j, cols.index(sn)] for j, sn in readings))
                for name, d in self.scores.items()}

    def design_values(self, name: str) -> dict:
        """:meth:`values` of design ``name`` ("chosen" or a reference) and its ``T_refit`` (n_series times
        the rival-refitted T, :func:`oed.discrimination.refit_values`; nan: the rival is not identifiable
        on those readings)."""
        readings = self.result.readings if name == "chosen" else self.references[name]
        out = self.values(readings)
        if name in self.refit:
            out["T_refit"] = self.n_series * self.refit[name]
        return out

    def summary(self) -> str:
        """Text of the design: chosen readings, T and divergence against the reference designs."""
        r = self.result
        head = (f"discrimination design: {self.variant} assumed true, rival {self.rival}, criterion {r.criterion}, "
                f"{self.n_series} series, " + ("planned before data (start values)" if self.planned
                                                 else "at the estimates"))
        lines = [head, r.summary(), "  readings (set point, sensor, h_true - h_rival, T):"]
        diff = r.difference
        for j, sn in r.readings:
            k = r.candidate_sensors.index(sn)
            unit = self.sensor_units.get(sn, "")
            lines.append(f"    {self.candidates[j]:g}  {sn}  {diff[j, k]:+.6g}{' ' + unit if unit else ''}  "
                         f"{self.scores['T'][j, k]:.4g}")
        lines.append("  design values (" + ", ".join(self.design_values("chosen")) + "):")
        for name, readings in (("chosen", r.readings),) + tuple(self.references.items()):
            vals = ", ".join(f"{k} {v:.4g}" for k, v in self.design_values(name).items())
            lines.append(f"    {name}: {len(readings)} readings/series, {vals}")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-ready view: chosen readings (set point, sensor), values, proof and the references."""
        r = self.result
        return dict(variant=self.variant, rival=self.rival, mode=self.mode, planned=self.planned,
                    p=list(self.p), p_rival=list(self.p_rival), candidates=list(self.candidates),
                    n_series=self.n_series, criterion=r.criterion, value=self.n_series * r.value,
                    upper_bound=self.n_series * r.upper_bound, proven_optimal=r.proven_optimal, method=r.method,
                    indices=list(r.indices), sensors=list(r.sensors),
                    set_points=[self.candidates[j] for j in r.indices],
                    readings=[[self.candidates[j], sn] for j, sn in r.readings],
                    values=self.design_values("chosen"),
                    references={name: dict(readings=[[self.candidates[j], sn] for j, sn in rd],
                                           values=self.design_values(name))
                                for name, rd in self.references.items()})


def _values(p) -> tuple:
    """The parameter values of an array or an Estimate, as a tuple of float."""
    return tuple(float(v) for v in getattr(p, "p", p))


def _even_rows(n_q: int, k: int) -> list:
    return sorted({int(i) for i in np.round(np.linspace(0, n_q - 1, k))})


def plan_discrimination(cfg: StudyConfig, variant: str, built: dict, params: dict, sigma, planned: bool,
                        q_default=None, progress: Progress | None = None) -> DiscriminationPlan:
    r"""``[oed] mode = "discrimination"``: the readings that best separate ``variant`` (assumed true) from
    ``[oed] rival`` (:func:`oed.select_discriminating`), each model at ``params`` (start values or
    Estimates).

    The candidates are the [oed] set points (or ``q_default``, the study's set points), each model
    reading them through its own inputs; sigma in model units; the values of a design are per
    series times ``[oed] n_series``.

    Raises
    ------
    ConfigError
        No candidates, no sigma, or a bad design argument (the message names the [oed] key).
    """
    from oed.discrimination import DiscriminationError, reading_divergences, refit_values, select_discriminating
    o = cfg.oed
    progress = progress or Progress(False)
    (m_a, fn_a), (m_b, fn_b) = built[variant], built[o.rival]
    pts = o.candidate_points()
    if pts.size:
        q_set = study_units(cfg, m_a).q_to_model(pts)
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
