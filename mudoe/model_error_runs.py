"""How large is the model error of every variant, computed by the study (issue 29, static and dynamic models).

:func:`run_model_error` runs :func:`identification.model_error` (kind "auto": the 'no model error' test,
then the error model of the best held-out log score) for every variant on the study's data and splits,
with the sensors of the tests (``[detect] sensors``), into ``StudyResults.model_error``; a variant whose
computation fails is recorded with its reason in ``StudyResults.model_error_errors``, never dropped.
:func:`quantify_text` and :func:`quantify_dict` are what ``mudoe quantify`` prints and writes: the sizes of
the error in the unit of each sensor's files.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from identification import model_error, rank_models
from identification.errors import IdentificationError
from identification.studies.model_error import unseen_rows
from identification.studies.model_error_result import NEW_CONDITION

from .config import ConfigError
from .study_base import FitFailedError, MissingPieceError, Progress, design_sensors, start_values
from .units import convert

__all__ = ["run_model_error", "curve_labels", "run_model_error_pages", "ranking", "embedded_parameters", "pooled_coverage", "sensor_units", "quantify_text", "quantify_text_full",
           "quantify_dict", "model_error_view", "run_model_error_views", "validate_model_error"]

def run_model_error(study, results, progress=None, alpha: float = 0.05, variants=None, embedded: bool = True):
    """``results`` with ``model_error``: {variant: ModelErrorResult} on the study's data and splits with the
    sensors of the tests, and ``model_error_errors``: {variant: reason} of the failed ones; ``variants`` those
    computed (None: every variant), ``embedded`` False skips the embedded error fitted beside another chosen
    error model (which parameters would carry it).

    Raises
    ------
    ConfigError
        The study's kind has no model error (``study.kind.model_error_refusal``; every kind has one today).
    """
    if study.kind.model_error_refusal:
        raise ConfigError(f"{study.cfg.path}: {study.kind.model_error_refusal}")
    progress = progress or Progress(False)
    results = design_sensors(study, results, progress)
    used = set(results.design_sensors)
    w = np.array([1.0 if s in used else 0.0 for s in study.sensors]) if used else None
    done, failed = dict(results.model_error), dict(results.model_error_errors)
    beside = dict(results.model_error_embedded)
    for v, m in study.models.items():
        if variants is not None and v not in variants:
            continue
        with progress.step(f"model error of {v}"):
            try:
                r = model_error(m, study.data[v], start_values(study, v), splits=study.splits, weights=w,
                                alpha=alpha)
                if embedded and r.kind != "embedded":          # which parameters would carry it (all data, no splits)
                    beside[v] = model_error(m, study.data[v], start_values(study, v), kind="embedded", weights=w,
                                            alpha=alpha)
                done[v] = r
            except (IdentificationError, ValueError, np.linalg.LinAlgError) as exc:
                failed[v] = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return dataclasses.replace(results, model_error=done, model_error_errors=failed, model_error_embedded=beside)


def embedded_parameters(results, variant: str) -> tuple:
    """The :class:`~identification.studies.model_error_result.EmbeddedParameter` of ``variant``'s embedded error
    (the chosen error model's, else the one fitted beside it; () when none was fitted)."""
    r = results.model_error.get(variant)
    if r is not None and r.kind == "embedded":
        return r.embedded
    e = results.model_error_embedded.get(variant)
    return () if e is None else e.embedded


def pooled_coverage(result, kind: str) -> float | None:
    """The held-out coverage of ``kind``'s new-reading bands pooled over the splits (None without splits)."""
    n = sum(h.n_values for h in result.heldout)
    if n == 0:
        return None
    return float(sum(h.coverage(kind) * h.n_values for h in result.heldout) / n)


def sensor_units(study) -> dict:
    """{sensor: (unit of its files, unit in the model)}; without the study's units (a time-series study reads its
    files into the model's units) the model's own sensor units for both, else ("", "")."""
    u = study.units
    if u is None or len(u.output_file) != len(study.sensors):
        model = next(iter(study.models.values()), None)
        own = dict(zip(getattr(model, "sensors", ()), getattr(model, "sensor_units", ()) or ()))
        return {s: (own.get(s, "") or "", own.get(s, "") or "") for s in study.sensors}
    return {s: (u.output_file[k], u.output_model[k]) for k, s in enumerate(study.sensors)}


def _in_file_unit(value: float, units: tuple) -> tuple:
    """(value, unit) of a standard deviation in the sensor's file unit (the model unit if it cannot convert)."""
    file_unit, model_unit = units
    if not file_unit or not model_unit or file_unit == model_unit:
        return float(value), model_unit or "(model unit)"
    return float(convert(value, model_unit, file_unit, difference=True)), file_unit


def _sensor_sizes(result, units: dict) -> list:
    """Per sensor of the discrepancy: amplitude, rough part and sigma in the sensor's file unit."""
    out = []
    for d in result.discrepancies:
        u = units.get(d.sensor, ("", ""))
        s, unit = _in_file_unit(d.amplitude, u)
        out.append(dict(sensor=d.sensor, unit=unit, amplitude=s, rough=_in_file_unit(d.rough, u)[0],
                        sigma=_in_file_unit(d.sigma, u)[0], length_scales=list(d.length_scales)))
    return out


def _variant_lines(v: str, r, units: dict, results) -> list:
    lines = [f"{v}: model error {'DETECTED' if r.detected else 'not detected'} (p = {r.test.p_value:.3g}, alpha "
             f"{r.alpha:g}); error model: {r.kind}"]
    sizes = _sensor_sizes(r, units)
    if sizes:
        lines.append("  size per sensor: " + "; ".join(
            f"{d['sensor']} {d['amplitude']:.3g} {d['unit']} (rough part {d['rough']:.2g} {d['unit']}, noise sigma "
            f"{d['sigma']:.3g} {d['unit']})"
            for d in sizes))
    emb = embedded_parameters(results, v)
    if emb:
        how = "" if r.kind == "embedded" else " (if embedded: fitted beside the chosen error model)"
        lines.append(f"  embedded error{how}: " + "; ".join(
            f"{e.name} {100 * e.relative:.3g} % of |p| (omega {e.omega:.4g})" for e in emb))
    if r.kind == "none":
        lines.append("  no error model: the bands are the plain ones")
    if not r.identifiable:
        lines.append("  the parameters are NOT identifiable under the model error")
    plain, chosen = pooled_coverage(r, "none"), pooled_coverage(r, r.kind)
    if plain is not None:
        lines.append(f"  held-out coverage of the {100 * (1 - r.alpha):g} % new-reading bands: {100 * plain:.1f} % "
                     f"without the model error, {100 * chosen:.1f} % with it ({r.kind}), "
                     f"{sum(h.n_values for h in r.heldout)} readings in {len(r.heldout)} split(s)")
    else:
        lines.append("  no splits: no held-out coverage")
    return lines


def ranking(results):
    """The :class:`identification.ModelRanking` of the variants whose model error has a held-out table (None
    when none has)."""
    with_table = {v: r for v, r in results.model_error.items() if r.heldout}
    return rank_models(with_table) if with_table else None


def quantify_text(study, results) -> str:
    """The terminal summary: per variant detected?, kind, size per sensor (file units), embedded parameters,
    pooled held-out coverage with and without the error model; then which variant to predict with and the
    verdict: "choose X" or "a tie within 2 SE" (the margin's standard error over the splits,
    :mod:`identification.studies.model_ranking`)."""
    units = sensor_units(study)
    blocks = ["\n".join(_variant_lines(v, r, units, results)) for v, r in results.model_error.items()]
    blocks += [f"{v}: model error not computed: {e}" for v, e in results.model_error_errors.items()]
    rank = ranking(results)
    if rank is not None:
        blocks.append("Ranking: " + rank.sentence() + "\nVerdict: " + rank.verdict())
    sens = ", ".join(results.design_sensors) if results.design_sensors else "all"
    head = f"Model error (sensors {sens}; {results.design_how or 'as configured'})"
    return head + "\n\n" + "\n\n".join(blocks)


def quantify_text_full(study, results) -> str:
    """The text file: the terminal summary, then every variant's full summary."""
    full = [f"---- {v} in full ----\n{r.summary()}" for v, r in results.model_error.items()]
    return quantify_text(study, results) + "\n\n" + "\n\n".join(full)


def quantify_dict(study, results) -> dict:
    """JSON-safe: {"sensors", "design_how", "variants": {variant: ModelErrorResult.to_dict() plus the sizes in
    file units and the pooled coverages}, "errors": {variant: reason}, "ranking": ModelRanking.to_dict() or
    None}."""
    units = sensor_units(study)
    variants = {}
    for v, r in results.model_error.items():
        d = r.to_dict()
        d["size_file_units"] = _sensor_sizes(r, units)
        d["pooled_coverage"] = {"plain": pooled_coverage(r, "none"), "with_error": pooled_coverage(r, r.kind)}
        d["embedded_parameters"] = [e.to_dict() for e in embedded_parameters(results, v)]
        variants[v] = d
    rank = ranking(results)
    return {"sensors": list(results.design_sensors), "design_how": results.design_how, "variants": variants,
            "errors": dict(results.model_error_errors), "ranking": None if rank is None else rank.to_dict()}


# ---------------------------------------------------------------------------- mudoe validate
def validate_model_error(study, results, variant: str, progress=None) -> tuple:
    """(text, dict) of ``mudoe validate``'s lines on the model error of the validated ``variant`` on the study's
    data: the held-out coverage of its (1 - alpha) new-reading bands without and with its model error, pooled and
    per split, as :func:`run_model_error` computes it (kind auto, the study's splits and test sensors; the embedded
    error beside another chosen error model is not fitted); a failure is a line of the text and the dict's
    ``error``, never an error of the command."""
    out = {"variant": variant, "error": None}
    if study.kind.model_error_refusal:
        out["error"] = study.kind.model_error_refusal
    else:
        results = run_model_error(study, results, progress, variants=(variant,), embedded=False)
        out["error"] = results.model_error_errors.get(variant)
    if out["error"] is not None:
        return f"Held-out coverage with the model error of {variant}: not computed: {out['error']}", out
    r = results.model_error[variant]
    n = sum(h.n_values for h in r.heldout)
    out.update(detected=r.detected, p_value=r.test.p_value, kind=r.kind, alpha=r.alpha, sensors=list(r.sensors),
               n_values=n, coverage_plain=pooled_coverage(r, "none"), coverage_with_error=pooled_coverage(r, r.kind),
               splits=[dict(split=h.split, n_values=h.n_values, coverage_plain=h.coverage_plain,
                            coverage_with_error=h.coverage(r.kind), widening=h.widening(r.kind)) for h in r.heldout])
    level = f"{100 * (1 - r.alpha):g} %"
    head = (f"Held-out coverage of {variant}'s {level} new-reading bands on the study's data (model_error, kind auto; "
            f"sensors {', '.join(r.sensors)}): model error {'DETECTED' if r.detected else 'not detected'} "
            f"(p = {r.test.p_value:.3g}), error model: {r.kind}")
    if not r.heldout:
        return head + "\n  no splits: no held-out coverage", out
    lines = [head, f"  pooled: {100 * out['coverage_plain']:.1f} % without the model error, "
                   f"{100 * out['coverage_with_error']:.1f} % with it ({r.kind}), {n} readings in {len(r.heldout)} "
                   "split(s)"]
    lines += [f"  {h.split}: {100 * h.coverage_plain:.1f} % -> {100 * h.coverage(r.kind):.1f} % ({h.n_values} readings, "
              f"band x {h.widening(r.kind):.2f})" for h in r.heldout]
    return "\n".join(lines), out


# ---------------------------------------------------------------------------- what the report's pages draw
def _to_file_z(study, z: np.ndarray, columns) -> np.ndarray:
    """Values (..., len(columns)) of the sensors ``columns`` (indices into study.sensors) in their files'
    units (differences: no offset)."""
    units = sensor_units(study)
    out = np.array(z, float)
    for i, k in enumerate(columns):
        file_unit, model_unit = units[study.sensors[k]]
        if file_unit and model_unit and file_unit != model_unit:
            out[..., i] = convert(out[..., i], model_unit, file_unit, difference=True)
    return out


def _first_input(study, q: np.ndarray) -> np.ndarray:
    q0 = np.asarray(q, float)[:, 0]
    return q0 if study.units is None else np.asarray(study.units.q_to_file(q0), float)


def model_error_view(study, results, variant: str):
    """The :class:`identification.studies.records.ModelErrorView` of ``variant``: its discrepancy (all data) at the
    study's input rows, and the new-reading bands with and without the error model, each fitted on the
    calibration part of the split of the lowest plain held-out coverage, at its validation readings (file
    units, relative to the plain prediction).  A dynamic model: its discrepancy at every experiment against the
    sampling times, without the held-out bands (the coverage table of every split only)."""
    from identification.studies.records import HeldOutBands, ModelErrorView
    r = results.model_error[variant]
    data, m = study.data[variant], study.models[variant]
    cols = [study.sensors.index(s) for s in r.sensors]
    units = tuple(sensor_units(study)[s][0] or "model unit" for s in r.sensors)
    d = r.discrepancy(data.inputs, r.alpha)
    if d.grid:                     # over sampling times (a dynamic model): every experiment against time
        flat = {a: getattr(d, a).reshape(-1, d.mean.shape[-1]) for a in ("mean", "lower", "upper")}
        disc = tuple(_to_file_z(study, flat[a][:, cols], cols) for a in ("mean", "lower", "upper"))
        unit = getattr(m, "time_unit", "") or ""
        return ModelErrorView(variant=variant, result=r, sensors=r.sensors,
                              units=tuple(sensor_units(study)[s][0] or "model unit" for s in r.sensors),
                              input_label="t" + (f" [{unit}]" if unit else ""),
                              q=np.tile(d.grid[0], d.mean.shape[0]), discrepancy=disc, heldout=None,
                              embedded=embedded_parameters(results, variant),
                              curves=curve_labels(m, data.inputs))
    disc = tuple(_to_file_z(study, getattr(d, a)[:, cols], cols) for a in ("mean", "lower", "upper"))
    held = None
    if r.heldout:
        h = min(r.heldout, key=lambda h: h.coverage_plain)
        split = next(sp for sp in study.splits if sp.name == h.split)
        cal, val = split.calibration(data), split.validation(data)
        w = np.array([1.0 if s in r.sensors else 0.0 for s in study.sensors])
        kinds = ("none",) if r.kind == "none" else ("none", r.kind)
        unseen = unseen_rows(split, data)            # as the held-out table predicts them: a new draw of the error
        condition = [NEW_CONDITION if u else None for u in unseen]
        bands = [model_error(m, cal, start_values(study, variant), kind=k, weights=w, alpha=r.alpha)
                 .predict(val.inputs, r.alpha, new_reading=True,
                          condition=condition if k == "discrepancy" else None) for k in kinds]
        mean = bands[0].mean[:, cols]
        rel = [tuple(_to_file_z(study, getattr(b, a)[:, cols] - mean, cols) for a in ("lower", "upper"))
               for b in bands]
        resid = _to_file_z(study, val.z[:, :, cols] - mean[None], cols)
        held = HeldOutBands(h.split, _first_input(study, val.inputs), resid, rel[0], rel[-1] if len(rel) > 1 else None,
                            h.coverage_plain, h.coverage(r.kind))
    u = study.units
    q_label = m.inputs[0] + (f" [{u.input_file}]" if u is not None and u.input_file else "")
    return ModelErrorView(variant=variant, result=r, sensors=r.sensors, units=units, input_label=q_label,
                          q=_first_input(study, data.inputs), discrepancy=disc, heldout=held,
                          embedded=embedded_parameters(results, variant))


def run_model_error_views(study, results):
    """``results`` with ``model_error_views``: {variant: ModelErrorView} of every variant whose model error was
    computed (the report's pages "Model error of ...")."""
    views = {v: model_error_view(study, results, v) for v in results.model_error}
    return dataclasses.replace(results, model_error_views={**results.model_error_views, **views})


def run_model_error_pages(study, results, progress=None):
    """``results`` with the model error of every variant and what its report pages draw
    (:func:`run_model_error`, :func:`run_model_error_views`); a study-wide failure and each variant's failure
    become notes of the results, never an error of the report.  ``[report] model_error = false``: nothing
    computed, a note says the pages were skipped."""
    if not study.cfg.report.model_error:
        return results.with_note("model-error pages skipped ([report] model_error = false)")
    try:
        results = run_model_error_views(study, run_model_error(study, results, progress))
    except (MissingPieceError, FitFailedError) as exc:
        results = results.with_note(f"model error not available: {exc}")
    return results.with_note("; ".join(f"model error of {v} not computed: {e}"
                                       for v, e in results.model_error_errors.items())) \
        if results.model_error_errors else results


def curve_labels(model, inputs) -> tuple:
    """A legend label per experiment: its input values when they are few (e.g. "F = 2"), else "experiment k"
    (a control profile has one value per grid step; the report's Experiments page lists them)."""
    rows = np.asarray(inputs, float)
    if getattr(model, "controls", ()) or rows.ndim != 2 or rows.shape[1] > 2 or rows.shape[1] == 0:
        return tuple(f"experiment {j + 1}" for j in range(rows.shape[0]))
    return tuple(", ".join(f"{n} = {v:g}" for n, v in zip(model.inputs, row)) for row in rows)
