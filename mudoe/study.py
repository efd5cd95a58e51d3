"""A study: the config turned into models, data, sigma, splits -- and thin runs of the library.

Every function here is a thin layer over :mod:`identification`, :mod:`oed` and :mod:`models`:
it only assembles their arguments from a :class:`mudoe.config.StudyConfig` and collects
their results in a frozen :class:`StudyResults` for the CLI and the report builder (every
``run_*`` returns a new record).  One path for every kind of study: :func:`prepare` builds the
models, chooses their kind once (:func:`mudoe.kind.study_kind`) and lets the kind read the data;
every later step asks ``study.kind`` for what differs (the design, what the report draws, the
size study's problem).  The records live in :mod:`mudoe.study_base`, the models in
:mod:`mudoe.study_models`, the kinds in :mod:`mudoe.kind` (a static study's data, sigma, splits and
sensor design in :mod:`mudoe.kind.static`, a time-series study's in :mod:`mudoe.kind.time_series`),
the input designs in :mod:`mudoe.plans`, and what the report shows beyond the fits is computed in
:mod:`mudoe.fit_assessment`, :mod:`mudoe.band_runs`, :mod:`mudoe.diagnosis_runs` and
:mod:`mudoe.uncertainty_runs` (the report only draws); the runs are importable from here.
Built-in models (the press) enter through :mod:`mudoe.registry`: this module names none.
"""
from __future__ import annotations

import contextlib
import dataclasses

from .config import ConfigError, StudyConfig
from .kind import study_kind
from .kind.base import Simulation
from .kind.static import SimulatedCampaign, simulate_study
from .plans import (DiscriminationPlan, PlannedDesign, plan_at_estimate, plan_design, plan_discrimination)
from .study_base import (FitFailedError, MissingPieceError, Progress, Study, StudyResults, VariantModel,
                         design_sensors, load_factory, require_fit, run_identify, run_oed, start_values)
from .study_models import build_models

__all__ = ["Study", "StudyResults", "VariantModel", "prepare", "load_factory", "start_values", "SimulatedCampaign",
           "simulate_study", "simulate", "run_identify", "run_oed", "run_detect", "run_validate", "run_diagnosis",
           "run_uncertainty", "run_bands", "run_report_pages", "oed_files", "design_sensors", "Progress",
           "MissingPieceError", "FitFailedError", "PlannedDesign", "DiscriminationPlan", "plan_design",
           "plan_without_data", "plan_at_estimate", "plan_discrimination"]


def prepare(cfg: StudyConfig, progress: Progress | None = None, command: str = "") -> Study:
    """Build the models, choose the study's kind from them, and let the kind load the data, compose sigma and
    the splits (:meth:`mudoe.kind.base.StudyKind.prepare`); a ``command`` the kind cannot run is refused before
    the data are read (:meth:`mudoe.kind.base.StudyKind.refusal`).

    Raises
    ------
    ConfigError, DataFileError, identification.DataError, identification.studies.splits.SplitError
        Bad config or data (the message names the file / key), or a command the kind cannot run.
    MissingPieceError
        A model variant needs a package that is not available yet.
    """
    progress = progress or Progress(False)
    with progress.step("build models " + ", ".join(cfg.model.variants), announce=False):
        built = build_models(cfg)
    kind = study_kind(cfg, built)
    why = kind.refusal(command)
    if why:
        raise ConfigError(f"{cfg.path}: {why}")
    return kind.prepare(cfg, built, progress)


def plan_without_data(cfg: StudyConfig, progress: Progress | None = None):
    """``[oed] planned = true``: the design of the study's kind at the [[parameters]] start values, no data
    read (:meth:`mudoe.kind.base.StudyKind.plan_without_data`)."""
    built = build_models(cfg)
    return study_kind(cfg, built).plan_without_data(cfg, built, progress or Progress(False))


def simulate(cfg: StudyConfig, seed: int | None = None) -> Simulation:
    """``mudoe simulate`` of an own model: the campaign of the study's kind (:meth:`Simulation.write
    <mudoe.kind.base.Simulation.write>` writes it; a built-in model without a virtual prototype is refused,
    :func:`mudoe.kind.static.simulate_study`)."""
    built = build_models(cfg)
    return study_kind(cfg, built).simulate(cfg, built, seed)


# ---------------------------------------------------------------------------- runs
def oed_files(study: Study, results: StudyResults, progress: Progress | None = None) -> tuple:
    """``mudoe oed`` with data: (text of oed.txt, object of oed.json) of the study kind's design at the
    estimate (:meth:`mudoe.kind.base.StudyKind.oed_files`)."""
    return study.kind.oed_files(study, results, progress or Progress(False))


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
    """The diagnostic split family on every variant (:func:`mudoe.diagnosis_runs.diagnose`; needs detection; a
    kind without one returns ``results``, :meth:`mudoe.kind.base.StudyKind.diagnose`)."""
    return study.kind.diagnose(study, results, progress or Progress(False))


def run_uncertainty(study: Study, results: StudyResults, which: str | None = None,
                    progress: Progress | None = None) -> StudyResults:
    """Profile-likelihood intervals and likelihood-ratio regions of the fits ``which`` selects
    (:func:`mudoe.uncertainty_runs.run_uncertainty`; default the config's [report] uncertainty)."""
    from .uncertainty_runs import run_uncertainty as run
    return run(study, results, which, progress)


def run_bands(study: Study, results: StudyResults, level: float = 0.95) -> StudyResults:
    """The prediction bands of every fit at ``level`` (:func:`mudoe.band_runs.run_bands`; a time-series study's
    bands are its trajectories', :meth:`mudoe.kind.base.StudyKind.bands`)."""
    return study.kind.bands(study, results, level)


def run_report_pages(study: Study, results: StudyResults, progress: Progress | None = None) -> StudyResults:
    """What the report draws beyond the fits and the tests: the model error of a static study's variants,
    the trajectories and meshes of a time-series study's (:meth:`mudoe.kind.base.StudyKind.report_runs`)."""
    return study.kind.report_runs(study, results, progress or Progress(False))


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
        results = require_fit(study, results, v, progress, "validate", alone=True)     # no other fit is used
        est = results.estimates[v]
        data = study.data[v]
        results = design_sensors(study, results, progress)
        used = results.design_sensors
        model, splits, w = study.kind.validation_problem(study, results, v, est, used)
        inputs, p0 = data.inputs, start_values(study, v)
        where = "" if address is None else f" on the Dask scheduler {address}"
        with progress.step(f"validate: Monte Carlo size study of {v}, {vc.n_runs} replications{where}"):
            validation = validate(model, splits, p0, p=est.p, inputs=inputs, sigma=est.sigma,
                                  n_series=data.n_M, weights=w, name=v, settings=settings)
    return dataclasses.replace(results, validation=validation)
