"""Plain-JSON views of the library's results (NaN/inf become null / strings, arrays lists).

The report builder and the CLI write every JSON file through :func:`dumps`; the provenance
of a results file (Python and package versions) comes from :func:`package_versions`.
"""
from __future__ import annotations

import dataclasses
import importlib.metadata
import json
import math
import platform

import numpy as np

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


def jsonable(obj):
    """Recursively convert numpy arrays/scalars, tuples, dataclasses to JSON-safe values."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        if math.isnan(v):
            return None
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return v
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if obj is None or isinstance(obj, (str, int)):
        return obj
    return str(obj)


def dumps(obj) -> str:
    return json.dumps(jsonable(obj), indent=1, sort_keys=False, allow_nan=False) + "\n"


def estimate_dict(est) -> dict:
    """The essentials of an :class:`identification.Estimate`."""
    return dict(model=est.model_name, params=list(est.param_names), units=list(est.param_units), p=est.p,
                stderr=est.stderr, stderr_gn=est.stderr_gn, cov=est.cov, cov_gn=est.cov_gn,
                correlation=est.correlation, conf_int_95=np.asarray(est.conf_int(0.05)), status=est.status,
                message=est.message, iterations=est.iterations, solve_time=est.solve_time, n_data=est.n_data,
                dof=est.dof, objective=est.objective, rss=est.rss, reduced_chi2=est.reduced_chi2,
                sigma=est.sigma, sigma_estimated=est.sigma_estimated, sensors=list(est.sensors),
                weights=est.weights, notes=list(est.notes))


def normality_dict(chk, units=None, data_name: str = "series") -> dict:
    """A normality check: p-values, sigma_rep as factor * value in unit (``units`` {sensor: (factor,
    unit)}, :func:`reports.tables.sigma_display`), and the series it was computed on."""
    units = units or {}
    fu = [units.get(s, (1.0, "")) for s in chk.sensors]
    return dict(computed_on=f"{data_name} {chk.series_text()}".strip(), series=list(chk.series),
                sensors=chk.sensors, pvalue=chk.pvalue, sigma_rep=[f * v for (f, _), v in zip(fu, chk.sigma_rep)],
                sigma_rep_unit=[u for _, u in fu], passed=chk.passed, overridden=chk.overridden, level=chk.level,
                correction=chk.correction, pvalue_adjusted=chk.adjusted, gated=list(chk.gated), gate=chk.gate_text(),
                note=chk.note)


def split_dict(s) -> dict:
    """A :class:`identification.studies.splits.Split` as a dict of its fields (``Split(**d)`` rebuilds it);
    ``cal_sensors`` / ``val_sensors`` are the 0-based sensor columns of each set (None: all), e.g. the
    (sensor, time) columns of a split by sampling time."""
    return dict(name=s.name, cal_inputs=s.cal_inputs, val_inputs=s.val_inputs, cal_series=s.cal_series,
                val_series=s.val_series, description=s.description, cal_sensors=s.cal_sensors,
                val_sensors=s.val_sensors)


def detection_dict(det, units=None, data_name: str = "series") -> dict:
    """Every split test and every decision of a :class:`identification.studies.detect.DetectionResult`.

    ``units`` and ``data_name`` label the normality gate (:func:`normality_dict`)."""
    tests = []
    for t in det.tests:
        tests.append(dict(model=t.model, split=t.split, calibration=t.cal_label, validation=t.val_label, ok=t.ok,
                          stage=t.stage, error=t.error, p_cal=t.p_cal, p_val=t.p_val, C_cal=t.C_cal, C_val=t.C_val,
                          d2_paper=t.d2_paper, d2_two_sample=t.d2_two_sample, alpha_paper=t.alpha_paper,
                          alpha_two_sample=t.alpha_two_sample, lr=t.lr, alpha_lr=t.alpha_lr, lr_error=t.lr_error,
                          n_cal=t.n_cal, n_val=t.n_val, notes=list(t.notes)))
    decisions = [jsonable(d) for d in det.all_decisions]
    for d, dd in zip(det.all_decisions, decisions):
        dd["primary"] = (d.statistic == det.settings.statistic and d.correction == det.settings.correction)
    norm = [dict(model=m, **normality_dict(c, units, data_name)) for m, c in det.normality]
    return dict(settings=jsonable(det.settings), models=list(det.models),
                splits=[split_dict(s) for s in det.splits],
                verdicts=dict(det.verdicts), tests=tests, decisions=decisions, normality=norm,
                design=[dict(model=m, sensors=u, how=h) for m, u, h in det.design], notes=list(det.notes))


def oed_dict(res, table, variant: str) -> dict:
    """The chosen design and the table of all combinations."""
    rows = [dict(mask=r.mask, sensors=r.sensors, A=r.A, det=r.det, logdet=r.logdet, E=r.E, flag=r.flag,
                 reason=r.reason) for r in table.rows]
    return dict(variant=variant, chosen=dict(sensors=res.chosen, weights=res.weights, criterion=res.criterion,
                                             kind=res.kind, value=res.value, proven_optimal=res.proven_optimal,
                                             method=res.method, status=res.status, notes=list(res.notes)),
                kind=table.kind, table=rows)


def validation_dict(mc) -> dict:
    """Rejection rates (all three statistics) and coverage of a Monte Carlo result."""
    out = dict(kind=mc.kind, models=list(mc.models), n_rep=mc.n_rep, tol=mc.tol, seed=mc.seed,
               wall_time=mc.wall_time, description=mc.description, rates={})
    for m in mc.models:
        for st in ("paper", "two_sample", "likelihood_ratio"):
            r = mc.rejection_rate(m, st)
            out["rates"][f"{m}/{st}"] = dict(rate=r.rate, lo=r.lo, hi=r.hi, k=r.k, n=r.n)
    if mc.kind == "size":
        cov = {}
        for m in mc.models:
            for j, sp in enumerate(mc.splits):
                c, v = mc.coverage(m, j, "cal"), mc.coverage(m, j, "val")
                cov[f"{m}/{sp.name}"] = dict(cal=c.rate, val=v.rate)
        out["coverage"] = cov
    out["table"] = mc.table()
    return out


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
    out["notes"] = list(results.notes)
    return jsonable(out)


def diagnosis_dict(diag) -> dict:
    """The diagnostic split family (:class:`identification.studies.records.Diagnosis`) and its findings per
    model."""
    models = list(dict.fromkeys(r.model for r in diag.rows))
    return dict(statistic=diag.statistic, tol=diag.tol, rows=jsonable(diag.rows),
                misses={m: diag.misses(m) for m in models})
