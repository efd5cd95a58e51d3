r"""The static study: a model h(y(p, q), p) of set points q, its campaign a wide CSV (:mod:`mudoe.data_io`).

The readings z_ijk of series i, set point q_j and sensor k are fitted by weighted least squares

.. math::

    \min_p \sum_{i,j,k} \bigl(z_{ijk} - h_k(y(p, q_j), p, q_j)\bigr)^2 / \sigma_k^2

(sigma per sensor from [[sensors]]: given, composed sqrt(sigma_rep^2 + sigma_man^2), or estimated); the
splits are the press scenarios, [splits.random] and [[splits.custom]] over set points, series and
sensor columns; the design chooses sensors (or inputs, :mod:`mudoe.plans`); the report draws the
prediction bands, the diagnostic split family and the model error of every variant.
:class:`StaticKind` is this kind's :class:`mudoe.kind.base.StudyKind`.
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from identification import Measurements, information_contributions
from identification.studies.detect import NormalityCheck, normality_check
from identification.studies.records import Presentation
from identification.studies.splits import Split, random_splits
from models.campaign import Campaign
from models.contract import Model

from ..band_runs import run_bands
from ..checks import check_data, check_model, study_splits
from ..config import ConfigError, StudyConfig, config_error
from ..data_io import (DataFileError, DataUnits, atomic_write_text, load_campaign, study_units, write_paper_layout,
                       write_tidy_layout)
from ..model_error_runs import run_model_error_pages
from ..parameter_units import model_parameters
from ..plans import plan_at_estimate, plan_without_data
from ..registry import builtin_model, scenario_splits, simulate_refusal
from ..study_base import (Progress, Study, StudyResults, oed_variant, require_fit,
                          run_oed)
from ..study_models import build_models, config_start_values, declare_units
from ..units import UNITS
from .base import Simulation, StudyKind

__all__ = ["StaticKind", "STATIC", "prepare_static", "sensor_design", "SimulatedCampaign", "simulate_study",
           "template_text"]


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


# ---------------------------------------------------------------------------- the study
def prepare_static(cfg: StudyConfig, built: dict, progress: Progress) -> Study:
    """The study of the static variants ``built`` ({variant: VariantModel}): the wide-CSV campaign in model
    units, sigma per sensor, the splits, the start values.

    Raises
    ------
    ConfigError, DataFileError, identification.DataError, identification.studies.splits.SplitError
        Bad config or data (the message names the file / key).
    """
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
                 units=units, explanations=explanations, presentation=shown, kind=STATIC)


# ---------------------------------------------------------------------------- the sensor design
def sensor_design(study: Study, results: StudyResults, progress: Progress) -> StudyResults:
    """Lines 02-03 of Algorithm 1: information of every sensor at the estimate, design table, chosen design."""
    from oed.best_designs import design_rows
    from oed.design import select_sensors_from_information
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
    results = dataclasses.replace(results, oed=res, oed_table=table, oed_variant=v, design_sensors=tuple(res.sensors),
                                  design_how=how)
    if not o.prior:
        return results
    from ..robust_plans import robust_sensors_at_estimate      # [oed] prior with data: the exact robust design
    sigma = study.sigma if study.sigma is not None else est.sigma
    with progress.step(f"exact robust sensor design ({o.criterion}, {v}, {o.robust or 'bayes'} over the prior)"):
        plan = robust_sensors_at_estimate(study.cfg, v, study.models[v], study.data[v], est.p, sigma)
    kind = "pseudo-Bayesian" if plan.design.robust == "bayes" else "maximin"
    return dataclasses.replace(results, plan=plan, design_sensors=tuple(plan.design.names),
                               design_how=f"the exact {kind} {o.criterion}-optimal design of {len(plan.design.names)} "
                                          f"sensors over the [oed] prior around the {v} estimate")


# ---------------------------------------------------------------------------- simulate
@dataclass(frozen=True, eq=False)
class SimulatedCampaign(Simulation):
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

    def write(self, cfg: StudyConfig, out) -> tuple:
        """(paths, record): the campaign in the study's [data] layout, file names and units, then simulate.json,
        written into the folder ``out``."""
        c, u, d = self.campaign, self.units, cfg.data
        out = Path(out)
        if d.layout == "tidy":
            paths = [write_tidy_layout(out / Path(d.file).name, c.q_set, c.z, c.sensors, units=u)]
        else:
            paths = write_paper_layout(out, c.q_set, c.z, c.sensors, units=u)
            for k, s in enumerate(c.sensors):
                if s in d.files:                      # the study's own file name of the sensor
                    target = out / Path(d.files[s]).name
                    os.replace(paths[k], target)
                    paths[k] = target
        record = dict(model=cfg.model.name, variant=self.variant, seed=self.seed, n_series=c.n_M,
                      truth=self.truth, truth_units=self.truth_units,
                      sigma_model_units=dict(zip(c.sensors, self.sigma)), layout=d.layout,
                      input_unit=u.input_file, output_units=dict(zip(c.sensors, u.output_file)),
                      files=[str(p) for p in paths])
        paths.append(atomic_write_text(out / "simulate.json", json.dumps(record, indent=1) + "\n"))
        return paths, record


def simulate_study(cfg: StudyConfig, seed: int | None = None, built: dict | None = None) -> SimulatedCampaign:
    r"""Readings simulated from the study's model: z_ijk = h_k(y_j, p_true, q_j) + sigma_k e_ijk.

    y_j solves E(y_j, p_true, q_j) = 0, e_ijk ~ N(0, 1) from ``numpy.random.default_rng(seed)``,
    sigma_k is sensor k's [[sensors]] sigma (or sigma_man) converted to the model's unit, q_j the
    [simulate] set points converted from the [data] input unit; ``[simulate] truth`` (default the
    [[parameters]] start values) in model units; ``built`` the study's variants (default: built here).

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
    built = build_models(cfg) if built is None else built
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


# ---------------------------------------------------------------------------- mudoe init
_HEAD = """\
# mudoe study config (TOML).  Every key has a default; README "Config reference" lists them all.
# Indices (series, inputs) are 0-based.  Paths are relative to this file.

[model]
name = "{name}"   # your factory: function(variant) -> models.Model
variants = ["default"]          # names passed to the factory, one fit per variant

[data]
source = "csv"
layout = "{layout}"                # "paper": one file per sensor; "tidy": one long table
directory = "data"              # folder of the CSV files (`mudoe simulate` writes them)
file = "campaign_long.csv"      # tidy layout: the table
{units}
"""

_TAIL = """
[simulate]                      # `mudoe simulate CONFIG --out data`: a campaign from the model itself
# truth = {{}}                  # true parameters (default: the start values above)
# inputs = [1.0, 2.0, 3.0]      # set points in the input unit, or a range:
# input_start = 0.0
# input_stop = 1.0
n_inputs = 11
n_series = 4                    # repeated series; noise from the sensors' sigma
seed = 1

[splits]
scenarios = []                  # the paper's press scenarios do not apply to your model
[splits.random]
n = 4                           # random calibration / validation splits of the inputs
cal_fraction = 0.5
seed = 1
exclude_zero_force = false
# [[splits.custom]]             # your own 0-based index sets
# name = "low vs high"
# cal_inputs = [0, 1, 2]
# val_inputs = [3, 4, 5]

[detect]
tol = 0.05                      # family-wise level
sensors = "all"                 # "all", "oed" (the [oed] design) or a list of sensor names

[oed]
criterion = "D"                 # A | D | E

[validate]
n_runs = 50                     # Monte Carlo replications of `mudoe validate`

[report]
title = "Model uncertainty study"
"""


def _num(v: float) -> str:
    return repr(float(v)) if math.isfinite(v) else ("inf" if v > 0 else "-inf")


def _start(scale, lower: float, upper: float) -> float:
    """A start value: the parameter's scale, else the middle of finite bounds, else 1."""
    if scale:
        return float(scale)
    if math.isfinite(lower) and math.isfinite(upper):
        return (lower + upper) / 2
    return 1.0


def template_text(model: Model | None = None, name: str = "mypackage.mymodel:build") -> str:
    """The commented TOML template for ``model`` (placeholders when None)."""
    if model is None:
        sensors = [("y1", "")]
        params = [("p1", 1.0, -math.inf, math.inf, "")]
        units = "# data units are the model's own unless declared (README \"Data formats\")"
        layout = "tidy"
    else:
        sensors = [(s, u if u in UNITS else "") for s, u in zip(model.sensors, model.sensor_units)]
        params = [(p.name, _start(p.scale, p.lower, p.upper), p.lower, p.upper, p.unit) for p in model.params]
        q_unit = model.input_units[0] if model.input_units and model.input_units[0] in UNITS else ""
        units = (f"input_unit = \"{q_unit}\"   # unit of the input column {model.inputs[0]!r} in the files "
                 "(any unit of mudoe.units.UNITS; converted once to the model's)\n"
                 "# output_unit = \"\"           # unit of the readings in the files (default: the model's); "
                 "per sensor: unit = \"...\"")
        layout = "tidy"
    parts = [_HEAD.format(name=name, layout=layout, units=units)]
    for s, u in sensors:
        parts.append(f'[[sensors]]\nname = "{s}"\nsigma = 1.0                     # standard deviation of a reading'
                     f'{" (" + u + ")" if u else ""}; or sigma_man\n' + (f'unit = "{u}"\n' if u else ""))
    for n, start, lo, up, u in params:
        parts.append(f'[[parameters]]\nname = "{n}"\nstart = {_num(start)}               # start value of the fit'
                     f'\nlower = {_num(lo)}\nupper = {_num(up)}\n' + (f'unit = "{u}"\n' if u else ""))
    return "\n".join(parts) + _TAIL.format()


# ---------------------------------------------------------------------------- the kind
class StaticKind(StudyKind):
    """A static study (see the module docstring)."""

    name = "static"
    report_pages = "fits"

    def prepare(self, cfg, built, progress):
        return prepare_static(cfg, built, progress)

    def simulate(self, cfg, built, seed):
        return simulate_study(cfg, seed, built)

    def plan_without_data(self, cfg, built, progress):
        return plan_without_data(cfg, progress, built)

    def run_oed(self, study, results, progress):
        return sensor_design(study, results, progress)

    def oed_files(self, study, results, progress) -> tuple:
        """The sensor design at the estimate (``[oed] mode = "sensors"``), else the input design of mode
        inputs / both / discrimination (:func:`mudoe.plans.plan_at_estimate`)."""
        from reports.serialize import oed_dict
        from reports.tables import oed_table_text
        if study.cfg.oed.mode != "sensors":
            plan = plan_at_estimate(study, results, progress)
            return plan.summary(), plan.to_dict()
        results = run_oed(study, results, progress)
        local = oed_dict(results.oed, results.oed_table, results.oed_variant)
        if results.plan is None:
            return oed_table_text(results), local
        text = (results.plan.summary() + "\n\nThe local sensor design at the estimate (the information of the data, "
                f"{study.cfg.oed.kind} covariance):\n" + oed_table_text(results))
        return text, dict(results.plan.to_dict(), sensor_design=local)

    def plan_at_estimate(self, study, results, progress):
        """:func:`mudoe.plans.plan_at_estimate` (the design of mode inputs / both / discrimination)."""
        return plan_at_estimate(study, results, progress)

    def diagnose(self, study, results, progress):
        from ..diagnosis_runs import diagnose
        if results.detection is None:
            return results
        with progress.step(f"what the models miss: diagnostic splits of {len(study.models)} model(s)"):
            return dataclasses.replace(results, diagnosis=diagnose(results, progress=progress))

    def bands(self, study, results, level):
        return run_bands(study, results, level)

    def report_runs(self, study, results, progress):
        """The pages "Model error of ..." (:mod:`mudoe.model_error_runs`); a failure becomes a note."""
        return run_model_error_pages(study, results, progress)

    def validation_problem(self, study, results, variant, est, used) -> tuple:
        """The model of ``variant`` itself, the study's splits, the sensors ``used``."""
        return study.models[variant], study.splits, np.array([1.0 if s in used else 0.0 for s in study.sensors])

    def template_text(self, model, name):
        return template_text(model, name)


#: the static kind
STATIC = StaticKind()
