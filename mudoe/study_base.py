"""The records of a study and the one run every command needs: the fit of every variant.

:class:`Study` is everything a run needs, assembled from a config (:func:`mudoe.study.prepare`);
:class:`StudyResults` is everything the commands computed, a frozen record built step by step
(each ``run_*`` of :mod:`mudoe.study` returns a new one, :func:`dataclasses.replace`) and read by
the CLI; the report builder (:mod:`reports`), which computes nothing, reads its
:func:`mudoe.report_record.study_record` (an :class:`oed.study_record.StudyRecord`).  A study carries its kind
(:mod:`mudoe.kind`: static or time series), and what differs between kinds is asked of it
(``study.kind.run_oed(...)``), never of the model.  This module imports no other study module
(:mod:`mudoe.study`, :mod:`mudoe.kind`, :mod:`mudoe.plans` import it).
"""
from __future__ import annotations

import dataclasses
import importlib
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable, Mapping, Sequence

import numpy as np

from identification import identify
from identification.progress import Progress as BaseProgress
from identification.studies.detect import NormalityCheck
from identification.studies.records import Presentation, SimulationTruth
from models.campaign import Campaign
from models.contract import Model

from .config import ConfigError, StudyConfig
from .console import INTERRUPT
from .data_io import DataUnits

if TYPE_CHECKING:          # the types of the results' fields (library and report records)
    from identification.inference.results import Estimate
    from identification.studies.detect import DetectionResult
    from identification.studies.model_error import ModelErrorResult
    from identification.studies.montecarlo import MonteCarloResult
    from identification.studies.records import (Diagnosis, FitAssessment, MeshSummary, ModelErrorView,
                                                ModelUncertainty, PredictionBands, Trajectories)
    from oed.design import DesignResult, DesignTable
    from oed.plan_records import DiscriminationPlan, DynamicDesign, PlannedDesign, RobustPlan

    from .kind.base import StudyKind

__all__ = ["MissingPieceError", "FitFailedError", "Progress", "VariantModel", "Study", "StudyResults",
           "load_factory", "start_values", "run_identify", "require_fit", "oed_variant", "run_oed", "design_sensors"]


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


# ---------------------------------------------------------------------------- records
@dataclass(frozen=True, eq=False)
class VariantModel:
    """A model variant as built from the config: the model and how it reads the set points.

    ``inputs_fn(q_set)`` gives the model's input matrix (n_q, d_q) of the set points q_set; None: the
    model's one input is the set point itself (``q_set[:, None]``).
    """

    model: Model
    inputs_fn: Callable | None = None

    def inputs(self, q_set) -> np.ndarray:
        """The model's input matrix (n_q, d_q) at the set points ``q_set`` (model units)."""
        q = np.asarray(q_set)
        return q[:, None] if self.inputs_fn is None else np.asarray(self.inputs_fn(q), float)


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
                                 (:class:`identification.studies.records.Explanation`; the press's)
    presentation : Presentation  the words a built-in model's study puts on its pages
                                 (:class:`identification.studies.records.Presentation`; empty if own)
    kind : StudyKind             what differs between static and time-series studies (:mod:`mudoe.kind`;
                                 chosen once from the built models, :func:`mudoe.kind.study_kind`)
    inputs : ndarray or None     a time-series study: the experiments' input rows (model units)
    times : tuple of float       a time-series study: the [dynamic] sampling times
    p0s : dict {variant: ndarray}  start values per variant where they differ (a time-series study's
                                 variants may differ in parameters); else ``p0``
    truth : SimulationTruth or None  a time-series study whose data are the config's [simulate] campaign:
                                 its true parameters (:func:`mudoe.kind.time_series.simulation_truth`)
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
    presentation: Presentation = Presentation()
    kind: StudyKind | None = None
    inputs: np.ndarray | None = None
    times: tuple = ()
    p0s: Mapping[str, np.ndarray] = field(default_factory=dict)
    truth: SimulationTruth | None = None

    def start_values(self, variant: str) -> np.ndarray:
        """The start values of a variant's fits (``p0s`` of the variant, else ``p0``)."""
        return self.p0s.get(variant, self.p0)


@dataclass(frozen=True, eq=False)
class StudyResults:
    """What the commands computed; fields stay empty (None, "", ()) when the command was not run.

    Built once per step: every ``run_*`` of :mod:`mudoe.study` returns a new record
    (:func:`dataclasses.replace`) and never changes one in place (nor its mappings).

    Attributes
    ----------
    study : Study
    estimates : {variant: Estimate}           fits on all study data that succeeded
    estimate_errors : {variant: str}          why the others failed
    assessments : {variant: FitAssessment}    goodness of fit and trust of the linearisation of each fit
                                              (:mod:`mudoe.fit_assessment`)
    oed, oed_table, oed_variant               the sensor (or sampling-time) design, its table and variant
    plan                                      [oed] mode inputs / both / discrimination / times:
                                              :mod:`mudoe.plan_records`
    design_sensors, design_how                the sensors of the tests and how they were chosen
    detection, detection_error                Algorithm 1 (or why it stopped)
    diagnosis                                 the diagnostic split family (:mod:`mudoe.diagnosis_runs`)
    uncertainty : {variant: ModelUncertainty} profile intervals and likelihood-ratio regions
                                              (:mod:`mudoe.uncertainty_runs`)
    bands : {variant: PredictionBands}        prediction bands of every fit (:mod:`mudoe.band_runs`)
    validation                                the Monte Carlo size study
    model_error : {variant: ModelErrorResult}  size and place of the model error, static studies
                                              (:mod:`mudoe.model_error_runs`)
    model_error_errors : {variant: str}       why model_error failed for the others
    model_error_embedded : {variant: ModelErrorResult}  the embedded error (which parameters carry it) of the
                                              variants whose chosen error model is another one
    model_error_views : {variant: ModelErrorView}  what the pages "Model error of ..." draw
                                              (:mod:`mudoe.model_error_runs`)
    trajectories : {variant: Trajectories}    time-series studies (:mod:`mudoe.kind.time_series`)
    discretisation : {variant: MeshSummary}   time-series studies (:mod:`mudoe.kind.time_series`)
    timing : {step: seconds}
    notes : tuple of str
    """

    study: Study
    estimates: Mapping[str, Estimate] = field(default_factory=dict)
    estimate_errors: Mapping[str, str] = field(default_factory=dict)
    assessments: Mapping[str, FitAssessment] = field(default_factory=dict)
    oed: DesignResult | None = None
    oed_table: DesignTable | None = None
    oed_variant: str = ""
    plan: PlannedDesign | RobustPlan | DiscriminationPlan | DynamicDesign | None = None
    design_sensors: tuple = ()
    design_how: str = ""
    detection: DetectionResult | None = None
    detection_error: str = ""
    diagnosis: Diagnosis | None = None
    uncertainty: Mapping[str, ModelUncertainty] = field(default_factory=dict)
    bands: Mapping[str, PredictionBands] = field(default_factory=dict)
    validation: MonteCarloResult | None = None
    model_error: Mapping[str, ModelErrorResult] = field(default_factory=dict)
    model_error_errors: Mapping[str, str] = field(default_factory=dict)
    model_error_embedded: Mapping[str, ModelErrorResult] = field(default_factory=dict)
    model_error_views: Mapping[str, ModelErrorView] = field(default_factory=dict)
    trajectories: Mapping[str, Trajectories] = field(default_factory=dict)
    discretisation: Mapping[str, MeshSummary] = field(default_factory=dict)
    timing: Mapping[str, float] = field(default_factory=dict)
    notes: tuple = ()

    def __post_init__(self):
        object.__setattr__(self, "notes", tuple(self.notes))

    def with_note(self, note: str) -> StudyResults:
        """The record with one more note."""
        return dataclasses.replace(self, notes=self.notes + (note,))


# ---------------------------------------------------------------------------- factories, start values
def load_factory(name: str, where: str) -> Callable:
    """The model factory ``"package.module:function"`` (``where`` starts the error message).

    Raises
    ------
    ConfigError
        The module cannot be imported or has no such function.
    """
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


def start_values(study: Study, variant: str) -> np.ndarray:
    """The start values of a variant's fits (a dynamic study's variants may differ in parameters)."""
    return study.start_values(variant)


# ---------------------------------------------------------------------------- the fits
def run_identify(study: Study, results: StudyResults, progress: Progress | None = None,
                 variants: Sequence[str] | None = None) -> StudyResults:
    """Identify every variant (or those named in ``variants``) on the study's data (all sensors) and assess each
    fit (goodness of fit, trust of its linearisation); failures are recorded, not raised (an estimate the data do
    not bound is recorded as a failure with its reason, "not bounded: ...").  ``[identify] starts`` and ``seed``
    are passed to every fit (a multi-start fit keeps its starts in ``est.diagnostics.starts``)."""
    from identification.errors import BadStartError, IdentificationError
    from .fit_assessment import assess
    progress = progress or Progress(False)
    estimates, errors, assessments = dict(results.estimates), dict(results.estimate_errors), dict(results.assessments)
    ident = study.cfg.identify
    unknown = [v for v in variants or () if v not in study.models]
    if unknown:
        raise ValueError(f"variants: unknown {unknown[0]!r}; the study's variants are {', '.join(study.models)}")
    for v, m in study.models.items():
        if variants is not None and v not in variants:
            continue
        with progress.step(f"identify {v}"):
            try:
                est = identify(m, study.data[v], start_values(study, v), starts=ident.starts, seed=ident.seed)
            except BadStartError as exc:     # bad input (e.g. a blow-up at p0): refused, not a failed fit
                raise BadStartError(f"variant {v}: {exc}", status=exc.status) from None
            except IdentificationError as exc:
                errors[v] = f"{type(exc).__name__}: {exc}"
                continue
            if not est.bounded:      # no finite estimate: the pages of estimates need one; the reason is kept
                errors[v] = f"not bounded: {est.unbounded.reason}"
                continue
            estimates[v], assessments[v] = est, assess(est)
    return dataclasses.replace(results, estimates=estimates, estimate_errors=errors, assessments=assessments)


def oed_variant(study: Study) -> str:
    """The variant of the [oed] design (default the last one)."""
    return study.cfg.oed.variant or list(study.models)[-1]


def require_fit(study: Study, results: StudyResults, v: str, progress: Progress, command: str,
                why: str = "", alone: bool = False) -> StudyResults:
    """``results`` with the fits of the study's variants (``alone``: of ``v`` only, for a command whose output
    uses no other fit) if ``v`` has no estimate yet; FitFailedError if its fit failed."""
    if v not in results.estimates:
        results = run_identify(study, results, progress, variants=(v,) if alone else None)
    if v not in results.estimates:
        raise FitFailedError(f"{command}: the fit of variant {v} failed ({results.estimate_errors.get(v)}){why}")
    return results


# ---------------------------------------------------------------------------- the design, the test sensors
def run_oed(study: Study, results: StudyResults, progress: Progress | None = None) -> StudyResults:
    """Lines 02-03 of Algorithm 1 at the estimate of the [oed] variant: the design of the study's kind
    (:meth:`mudoe.kind.base.StudyKind.run_oed`: sensors of a static study, sampling times of a time-series one)."""
    try:
        import oed.best_designs  # noqa: F401 -- the design pieces every kind needs
        import oed.design  # noqa: F401
    except ImportError as exc:
        raise MissingPieceError(f"oed: oed.design is not available ({exc})") from None
    return study.kind.run_oed(study, results, progress or Progress(False))


def design_sensors(study: Study, results: StudyResults, progress: Progress) -> StudyResults:
    """``results`` with the sensors of the tests: the OED design, all sensors, or the names given
    ([detect] sensors)."""
    d = study.cfg.detect
    if d.sensors == "oed":
        return results if results.design_sensors else run_oed(study, results, progress)
    if d.sensors == "all":
        return dataclasses.replace(results, design_sensors=tuple(study.sensors), design_how="all sensors")
    return dataclasses.replace(results, design_sensors=tuple(d.sensors), design_how="sensors given in [detect] sensors")
