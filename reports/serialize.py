"""Plain-JSON views of the library's results (NaN/inf become null / strings, arrays lists).

The report builder and the CLI write every JSON file through :func:`dumps`; the provenance
of a results file (Python and package versions) comes from :func:`package_versions`.  The view of
one result (an Estimate, a DetectionResult, a MonteCarloResult, a design) is that result's own
``to_dict()`` (the result protocol, :mod:`identification.results_protocol`); this module assembles
them with the study's data into results.json.
"""
from __future__ import annotations

import dataclasses
import importlib.metadata
import json
import platform

from identification.results_protocol import jsonable
from oed.dynamic_plans import ExperimentPlan

from .tables import ALL_SERIES, normality_labels, sigma_display

__all__ = ["jsonable", "dumps", "estimate_dict", "detection_dict", "split_dict", "normality_dict", "oed_dict",
           "validation_dict", "study_dict", "results_dict", "package_versions", "diagnosis_dict"]


def package_versions() -> dict:
    """Versions of Python and the packages the results depend on."""
    out = {"python": platform.python_version()}
    for pkg in ("mudoe", "numpy", "scipy", "casadi", "matplotlib", "pyscipopt", "pyomo"):
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def dumps(obj) -> str:
    return json.dumps(jsonable(obj), indent=1, sort_keys=False, allow_nan=False) + "\n"


def estimate_dict(est) -> dict:
    """The essentials of an :class:`identification.Estimate` (:meth:`identification.Estimate.to_dict`)."""
    return est.to_dict()


def normality_dict(chk, units=None, data_name: str = "series") -> dict:
    """A normality check: p-values, sigma_rep as factor * value in unit (``units`` {sensor: (factor,
    unit)}, :func:`reports.tables.sigma_display`), and the series it was computed on
    (:meth:`identification.studies.normality.NormalityCheck.to_dict`)."""
    return chk.to_dict(units, data_name)


def split_dict(s) -> dict:
    """A :class:`identification.studies.splits.Split` as a dict of its fields (``Split(**d)`` rebuilds it;
    :meth:`identification.studies.splits.Split.to_dict`); ``cal_sensors`` / ``val_sensors`` are the 0-based
    sensor columns of each set (None: all), e.g. the (sensor, time) columns of a split by sampling time; a split
    by time window of a time series also has ``cal_window`` / ``val_window`` ([t_lo, t_hi), "inf" / "-inf")."""
    return s.to_dict()


def detection_dict(det, units=None, data_name: str = "series") -> dict:
    """Every split test and every decision of a :class:`identification.studies.detect.DetectionResult`
    (:meth:`identification.DetectionResult.to_dict`).

    ``units`` and ``data_name`` label the normality gate (:func:`normality_dict`)."""
    return det.to_dict(units, data_name)


def oed_dict(res, table, variant: str) -> dict:
    """The chosen design (:meth:`oed.DesignResult.to_dict`) and the table of all combinations
    (:meth:`oed.DesignTable.to_dict`)."""
    t = table.to_dict()
    return dict(variant=variant, chosen=res.to_dict(), kind=t["kind"], table=t["rows"])


def validation_dict(mc) -> dict:
    """Rejection rates (all three statistics) and coverage of a Monte Carlo result
    (:meth:`identification.MonteCarloResult.to_dict`)."""
    return mc.to_dict()


def study_dict(study) -> dict:
    """The study's data, sigma and normality check (all series) of an :class:`oed.study_record.StudySetup`;
    sigma in the report's display unit."""
    c = study.source
    disp = sigma_display(study)
    sigma = None if study.sigma is None else [disp[s][0] * v for s, v in zip(study.sensors, study.sigma)]
    return dict(source=c.source, files=list(c.files), sha256=c.sha256, n_M=c.n_M, n_q=c.n_q,
                sensors=list(study.sensors), series_used=study.config.series, sigma=sigma,
                sigma_unit=[disp[s][1] for s in study.sensors], sigma_table=list(study.sigma_table), p0=study.p0,
                splits=[s.name for s in study.splits], normality=normality_dict(study.normality, disp, ALL_SERIES),
                notes=list(study.notes))


def results_dict(results) -> dict:
    """Everything an :class:`oed.study_record.StudyRecord` holds, JSON-ready (no config, no versions)."""
    out = dict(study=study_dict(results.study),
               estimates={v: estimate_dict(e) for v, e in results.estimates.items()},
               estimate_errors=dict(results.estimate_errors),
               design=dict(sensors=results.design_sensors, how=results.design_how))
    if results.oed is not None:
        out["oed"] = oed_dict(results.oed, results.oed_table, results.oed_variant)
    if results.plan is not None and results.plan.mode == "times":    # a dynamic study's sampling times
        out["time_design"] = results.plan.to_dict()
    if isinstance(results.plan, ExperimentPlan):                # a dynamic study's next experiments
        out["input_design"] = results.plan.to_dict()
    if results.discretisation:                                  # a dynamic study: the mesh of each fit
        out["discretisation"] = {v: dataclasses.asdict(m) for v, m in results.discretisation.items()}
    if results.detection is not None:
        out["detection"] = detection_dict(results.detection, **normality_labels(results.study))
    if results.detection_error:
        out["detection_error"] = results.detection_error
    if results.validation is not None:
        out["validation"] = validation_dict(results.validation)
    if results.model_error or results.model_error_errors:     # a static study's model error (issue 29)
        out["model_error"] = {v: r.to_dict() for v, r in results.model_error.items()}
        out["model_error_errors"] = dict(results.model_error_errors)
    starts = {v: e.diagnostics.starts for v, e in results.estimates.items() if e.diagnostics.starts is not None}
    if starts:                                                  # [identify] starts > 1: every start of each fit
        out["multistart"] = {v: ms.to_dict() for v, ms in starts.items()}
    out["notes"] = list(results.notes)
    return jsonable(out)


def diagnosis_dict(diag) -> dict:
    """The diagnostic split family (:class:`identification.studies.records.Diagnosis`) and its findings per
    model."""
    models = list(dict.fromkeys(r.model for r in diag.rows))
    return dict(statistic=diag.statistic, tol=diag.tol, rows=jsonable(diag.rows),
                misses={m: diag.misses(m) for m in models})
