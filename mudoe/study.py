"""A study: the config turned into models, data, sigma, splits -- and thin runs of the library.

Every function here is a thin layer over :mod:`identification`, :mod:`oed` and :mod:`models`:
it only assembles their arguments from a :class:`mudoe.config.StudyConfig` and collects
their results in a frozen :class:`StudyResults` for the CLI and the report builder (every
``run_*`` returns a new record).  The records live in :mod:`mudoe.study_base`, the models in
:mod:`mudoe.study_models`, the designs in :mod:`mudoe.plans`, and what the report shows beyond the
fits is computed in :mod:`mudoe.fit_assessment`, :mod:`mudoe.band_runs`, :mod:`mudoe.diagnosis_runs`
and :mod:`mudoe.uncertainty_runs` (the report only draws); the runs are importable from here.
Built-in models (the press) enter through :mod:`mudoe.registry`: this module names none.
"""
from __future__ import annotations

import contextlib
import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from identification import Measurements, information_contributions
from identification.studies.detect import NormalityCheck, normality_check
from identification.studies.records import Presentation
from identification.studies.splits import Split, random_splits
from models.campaign import Campaign

from .registry import builtin_model, scenario_splits, simulate_refusal
from .checks import check_data, check_model, study_splits
from .config import ConfigError, StudyConfig, config_error
from .data_io import DataFileError, DataUnits, load_campaign, study_units
from .dynamic_runs import run_oed_dynamic, validation_problem
from .dynamic_study import build_dynamic, prepare_dynamic
from .parameter_units import model_parameters
from .plans import (DiscriminationPlan, PlannedDesign, plan_at_estimate, plan_design, plan_discrimination,
                    plan_without_data)
from .study_base import (FitFailedError, MissingPieceError, Progress, Study, StudyResults, VariantModel,
                         load_factory, oed_variant, require_fit, run_identify, start_values)
from .study_models import build_models, declare_units, config_start_values, is_dynamic_built

__all__ = ["Study", "StudyResults", "VariantModel", "prepare", "load_factory", "start_values", "SimulatedCampaign",
           "simulate_study", "run_identify", "run_oed", "run_detect", "run_validate", "run_diagnosis",
           "run_uncertainty", "run_bands", "design_sensors", "Progress", "MissingPieceError", "FitFailedError", "PlannedDesign",
           "DiscriminationPlan", "plan_design", "plan_without_data", "plan_at_estimate", "plan_discrimination"]


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
        out += scenario_splits(n_q, s.scenarios)
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
        built = build_models(cfg)
    if is_dynamic_built(cfg, built):
        return prepare_dynamic(cfg, {v: b.model for v, b in built.items()}, progress)
    first = next(iter(built.values())).model
    sensors = tuple(first.sensors)
    check_model(cfg, first)
    units = study_units(cfg, first)
    built = {v: dataclasses.replace(b, model=declare_units(b.model, units)) for v, b in built.items()}
    with progress.step(f"load data ({cfg.data.source})", announce=cfg.data.source == "prototype"):
        campaign = load_campaign(cfg, sensors, units)
    n_M = campaign.n_M
    if cfg.data.series is not None:
        bad = [i for i in cfg.data.series if i >= n_M]
        if bad:
            raise config_error(cfg, "data", "series", f"series {bad} out of range: the data hold {n_M} series "
                               "(0-based indices)")
    splits = study_splits(cfg, campaign, _splits)
    check_data(cfg, campaign, splits, next(iter(built.values())).model.n_p)
    m_all = Measurements(campaign.q_set[:, None], campaign.z, None, sensors=sensors, series=campaign.series)
    det = cfg.detect.settings()
    norm = normality_check(m_all, det.normality_level, correction=det.normality_correction)
    sigma, sig_rows = _sigma(cfg, sensors, norm, units)
    models, data, data_all = {}, {}, {}
    for v, b in built.items():
        m, q = b.model, b.inputs(campaign.q_set)
        if tuple(m.sensors) != tuple(sensors):
            raise ConfigError(f"{cfg.path}: model {v} has sensors {list(m.sensors)} but the data {list(sensors)}")
        full = Measurements(q, campaign.z, sigma, sensors=sensors, input_names=m.inputs, series=campaign.series)
        models[v] = m
        data_all[v] = full
        data[v] = full if cfg.data.series is None else full.subset(series=list(cfg.data.series))
    first = next(iter(models.values()))
    p0 = config_start_values(cfg, first)
    builtin = builtin_model(cfg.model.name)
    explanations = builtin.explanations(campaign, tuple(models)) if builtin is not None else ()
    shown = builtin.presentation if builtin is not None and builtin.presentation is not None else Presentation()
    return Study(cfg=cfg, campaign=campaign, sensors=sensors, sigma=sigma, sigma_table=sig_rows, normality=norm,
                 models=models, data=data, data_all=data_all, p0=p0, splits=splits, notes=campaign.notes,
                 units=units, explanations=explanations, presentation=shown)


# ---------------------------------------------------------------------------- runs
def run_oed(study: Study, results: StudyResults, progress: Progress | None = None) -> StudyResults:
    """Lines 02-03 of Algorithm 1: information of every sensor at the estimate, design table, chosen design."""
    try:
        from oed.best_designs import design_rows
        from oed.design import select_sensors_from_information
    except ImportError as exc:
        raise MissingPieceError(f"oed: oed.design is not available ({exc})") from None
    progress = progress or Progress(False)
    if study.is_dynamic:                             # sampling times (mudoe.dynamic_runs)
        return run_oed_dynamic(study, results, progress)
    v = oed_variant(study)
    results = require_fit(study, results, v, progress, "oed", "; no information matrix to design with")
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
    how = f"{o.criterion}-optimal ({o.kind} covariance) design of {len(res.sensors)} sensors at the {v} estimate"
    return dataclasses.replace(results, oed=res, oed_table=table, oed_variant=v, design_sensors=tuple(res.sensors),
                               design_how=how)


def design_sensors(study: Study, results: StudyResults, progress: Progress) -> StudyResults:
    """``results`` with the sensors of the tests: the OED design, all sensors, or the names given
    ([detect] sensors)."""
    d = study.cfg.detect
    if d.sensors == "oed":
        return results if results.design_sensors else run_oed(study, results, progress)
    if d.sensors == "all":
        return dataclasses.replace(results, design_sensors=tuple(study.sensors), design_how="all sensors")
    return dataclasses.replace(results, design_sensors=tuple(d.sensors), design_how="sensors given in [detect] sensors")


def run_detect(study: Study, results: StudyResults, progress: Progress | None = None) -> StudyResults:
    """Algorithm 1 (lines 05-17) on every variant with the chosen sensors."""
    from identification.studies.detect import detect
    progress = progress or Progress(False)
    results = design_sensors(study, results, progress)
    design = list(results.design_sensors)
    settings = study.cfg.detect.settings()
    with progress.step(f"detect: {len(study.models)} model(s) x {len(study.splits)} splits x 2 fits"):
        detection = detect(study.models, study.data, study.splits, {v: start_values(study, v) for v in study.models},
                           design=design, settings=settings, progress=progress)
    return dataclasses.replace(results, detection=detection)


def run_diagnosis(study: Study, results: StudyResults, progress: Progress | None = None) -> StudyResults:
    """The diagnostic split family on every variant (:func:`mudoe.diagnosis_runs.diagnose`; needs detection)."""
    from .diagnosis_runs import diagnose
    progress = progress or Progress(False)
    if results.detection is None or study.is_dynamic:     # diagnostic splits: static models
        return results
    with progress.step(f"what the models miss: diagnostic splits of {len(study.models)} model(s)"):
        return dataclasses.replace(results, diagnosis=diagnose(results, progress=progress))


def run_uncertainty(study: Study, results: StudyResults, which: str | None = None,
                    progress: Progress | None = None) -> StudyResults:
    """Profile-likelihood intervals and likelihood-ratio regions of the fits ``which`` selects
    (:func:`mudoe.uncertainty_runs.run_uncertainty`; default the config's [report] uncertainty)."""
    from .uncertainty_runs import run_uncertainty as run
    return run(study, results, which, progress)


def run_bands(study: Study, results: StudyResults, level: float = 0.95) -> StudyResults:
    """The prediction bands of every fit at ``level`` (:func:`mudoe.band_runs.run_bands`)."""
    from .band_runs import run_bands as run
    return run(study, results, level)


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
        results = require_fit(study, results, v, progress, "validate")
        est = results.estimates[v]
        data = study.data[v]
        results = design_sensors(study, results, progress)
        used = results.design_sensors
        w = np.array([1.0 if s in used else 0.0 for s in study.sensors])
        model, splits, inputs, p0 = study.models[v], study.splits, data.inputs, start_values(study, v)
        if study.is_dynamic:                         # on the collocation at the estimate (mudoe.dynamic_runs)
            model, splits, w = validation_problem(study, results, est, used)
        where = "" if address is None else f" on the Dask scheduler {address}"
        with progress.step(f"validate: Monte Carlo size study of {v}, {vc.n_runs} replications{where}"):
            validation = validate(model, splits, p0, p_true=est.p, inputs=inputs, sigma=est.sigma,
                                  n_M=data.n_M, weights=w, name=v, settings=settings)
    return dataclasses.replace(results, validation=validation)


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
        A built-in model (the press: use its virtual prototype), a sensor without sigma, missing true values.
    """
    refusal = simulate_refusal(cfg.model.name)
    if refusal is not None:
        raise ConfigError(f"{cfg.path}: {refusal}")
    sc = cfg.simulate
    if not sc.inputs and sc.input_start is None:
        raise ConfigError(f"{cfg.path}: [simulate] give the set points: inputs = [...] or input_start, input_stop "
                          "and n_inputs (in the [data] input unit)")
    built = build_models(cfg)
    if is_dynamic_built(cfg, built):         # without [dynamic] (with it the CLI writes the long format)
        build_dynamic(cfg, {v: b.model for v, b in built.items()})
    variant = sc.variant or next(iter(built))
    m, fn = built[variant].model, built[variant].inputs_fn
    units = study_units(cfg, m)
    m = declare_units(m, units)
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
