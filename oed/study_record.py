"""The one record a report draws: what a study was run on and everything it computed.

The study layer (:mod:`mudoe`) fills a :class:`StudyRecord` from its results and its config
(:func:`mudoe.report_record.study_record`) and hands it to :func:`reports.builder.build_report`; the
report reads only this record and the typed library results it holds.  It calls nothing back: what
the report used to ask the study while drawing (the phases of the set points, the config as a
dict, the display words) is data here, computed before the report is built.

* :class:`ConfigRecord` -- what a report shows of the config (title, dpi, the config's text and its
  values, the study series).
* :class:`DataSource` -- where the data came from (file, sha256, series x rows).
* :class:`StudySetup` -- the study's data, models, sigma, normality check, splits, notes, words and
  phases.
* :class:`StudyRecord` -- the setup and every result: fits, designs, detection, diagnosis,
  uncertainty, bands, Monte Carlo, model error, trajectories, timing, notes.

The record lives in :mod:`oed`, the highest layer whose types it holds (designs:
:mod:`oed.design`, :mod:`oed.best_designs`, :mod:`oed.plan_records`); the records of what the report
draws beyond the library's results are in :mod:`identification.studies.records`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from identification.inference.results import Estimate
from identification.studies.detect import DetectionResult, NormalityCheck
from identification.studies.model_error import ModelErrorResult
from identification.studies.montecarlo import MonteCarloResult
from identification.studies.records import (Diagnosis, FitAssessment, MeshSummary, ModelErrorView, ModelUncertainty,
                                            PredictionBands, Presentation, SimulationTruth, Trajectories)
from models.campaign import Campaign
from models.contract import Model

from .design import DesignResult, DesignTable
from .plan_records import DiscriminationPlan, DynamicDesign, PlannedDesign, RobustPlan

__all__ = ["ConfigRecord", "DataSource", "StudySetup", "StudyRecord"]


@dataclass(frozen=True)
class ConfigRecord:
    """What a report shows of the study's config.

    Attributes
    ----------
    path : str                 the config file ("" when built in memory)
    text : str                 its text as read
    values : dict              every key with its value, defaults filled in (results.json "config")
    title : str                [report] title
    dpi : int                  [report] dpi of the page PNGs (dots per inch)
    uncertainty : str          [report] uncertainty: "untrusted", "all" or "none"
    series : tuple of int or None   [data] series: the 0-based study series (None: all)
    """

    path: str
    text: str
    values: Mapping
    title: str
    dpi: int
    uncertainty: str
    series: tuple | None = None


@dataclass(frozen=True)
class DataSource:
    """Where a study's data came from.

    Attributes
    ----------
    source : str        the data's source (a folder, a file, the virtual prototype)
    files : tuple of str   the files read ("" none)
    sha256 : str        hash of the readings
    n_M : int           series
    n_q : int           set points (static) or experiments (dynamic)
    """

    source: str
    files: tuple
    sha256: str
    n_M: int
    n_q: int


@dataclass(frozen=True, eq=False)
class StudySetup:
    """What a study was run on, as the report shows it (model units throughout).

    Attributes
    ----------
    config : ConfigRecord
    source : DataSource
    campaign : Campaign or None   every series of a static study (q_set (n_q,), z (n_M, n_q, n_S)); None dynamic
    sensors : tuple of str        the model's sensors (order of z)
    sigma : ndarray (n_S,) or None   sensor sigma used by every fit (None: estimated)
    sigma_table : tuple of dict   per sensor: sigma_rep, sigma_man, sigma and how obtained
    normality : NormalityCheck    Shapiro-Wilk on differences of consecutive series (all series)
    models : {variant: Model}
    data : {variant: Measurements or DynamicMeasurements}   the study's series
    p0 : ndarray (n_p,)           start values
    splits : tuple of Split       the study's splits
    notes : tuple of str          what was done to the data
    presentation : Presentation   the words a built-in model's study puts on its pages
    phases : tuple of str or None   a phase label per set point (the press: loading / unloading), None: none
    inputs : ndarray (n_q, d_q) or None   a dynamic study's experiments (input rows); None static
    pages : str                   the pages the study's kind draws beyond the fits: "fits" (bands against the
                                  set point, diagnosis, model error) or "trajectories" (the pages against time)
    input_rows : str              what the study calls its input rows ("set points", "experiments")
    normality_over : str          which readings the normality gate pools (words for the report)
    truth : SimulationTruth or None   the true parameters when the data are a simulation the config
                                  describes (marked on the estimates and confidence regions); None otherwise
    """

    config: ConfigRecord
    source: DataSource
    campaign: Campaign | None
    sensors: tuple
    sigma: np.ndarray | None
    sigma_table: tuple
    normality: NormalityCheck
    models: Mapping[str, Model]
    data: Mapping
    p0: np.ndarray
    splits: tuple
    notes: tuple = ()
    presentation: Presentation = Presentation()
    phases: tuple | None = None
    inputs: np.ndarray | None = None
    pages: str = "fits"
    input_rows: str = "set points"
    normality_over: str = "all set points"
    truth: SimulationTruth | None = None


@dataclass(frozen=True, eq=False)
class StudyRecord:
    """Everything a report draws: the study's setup and what it computed.

    Fields stay empty (None, "", {}) when the study did not compute them.

    Attributes
    ----------
    study : StudySetup
    estimates : {variant: Estimate}           fits on all study data that succeeded
    estimate_errors : {variant: str}          why the others failed
    assessments : {variant: FitAssessment}    goodness of fit and trust of the linearisation of each fit
    oed, oed_table, oed_variant               the sensor design, its table and variant
    plan                                      the planned design of [oed] mode inputs / both /
                                              discrimination / times (:mod:`oed.plan_records`)
    design_sensors, design_how                the sensors of the tests and how they were chosen
    detection, detection_error                Algorithm 1 (or why it stopped)
    diagnosis : Diagnosis or None             the diagnostic split family
    uncertainty : {variant: ModelUncertainty} profile intervals and likelihood-ratio regions
    bands : {variant: PredictionBands}        prediction bands of every fit
    validation : MonteCarloResult or None     the Monte Carlo size study
    model_error : {variant: ModelErrorResult}  size and place of the model error
    model_error_errors : {variant: str}       why model_error failed for the others
    model_error_views : {variant: ModelErrorView}  what the pages "Model error of ..." draw
    trajectories : {variant: Trajectories}    a dynamic study's outputs against time
    discretisation : {variant: MeshSummary}   a dynamic study's mesh of each fit
    timing : {step: seconds}
    notes : tuple of str
    """

    study: StudySetup
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
    model_error_views: Mapping[str, ModelErrorView] = field(default_factory=dict)
    trajectories: Mapping[str, Trajectories] = field(default_factory=dict)
    discretisation: Mapping[str, MeshSummary] = field(default_factory=dict)
    timing: Mapping[str, float] = field(default_factory=dict)
    notes: tuple = ()
