"""How large is the model error of every variant, computed by the study (issue 29, static and dynamic models).

:func:`run_model_error` runs :func:`identification.model_error` (kind "auto": the 'no model error' test,
then the error model of the best held-out log score) for every variant on the study's data and splits,
with the sensors of the tests (``[detect] sensors``), into ``StudyResults.model_error``; a variant whose
computation fails is recorded with its reason in ``StudyResults.model_error_errors``, never dropped.

The noise of a reading in that analysis (:func:`error_noise`): a sensor whose sigma the study composes,
sqrt(sigma_rep^2 + sigma_man^2), enters with sigma_rep, the random part the differences between series
see; sigma_man is taken as a systematic error of the sensor (the same at the same reading), which the model
error holds, so a new-reading band that added it again would count it twice.  A sigma given directly is the
user's statement and is kept; without sigma the analysis takes the pure error of the repeated series.
Detection (Algorithm 1) keeps the study's sigma.
:func:`quantify_text` and :func:`quantify_dict` are what ``mudoe quantify`` prints and writes: the sizes of
the error in the unit of each sensor's files.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from identification import model_error, rank_models
from identification.errors import IdentificationError
from identification.studies.model_error import pure_error_notes, unseen_rows
from identification.studies.model_error_result import NEW_CONDITION

from .config import ConfigError
from .study_base import FitFailedError, MissingPieceError, Progress, design_sensors, start_values
from .units import convert

__all__ = ["run_model_error", "curve_labels", "run_model_error_pages", "ranking", "embedded_parameters", "pooled_coverage", "sensor_units", "quantify_text", "quantify_text_full",
           "quantify_dict", "model_error_view", "run_model_error_views", "validate_model_error", "plain_result",
           "next_runs", "error_summary", "error_summaries", "summary_lines", "ErrorNoise", "error_noise",
           "error_data"]


# ---------------------------------------------------------------------------- the noise of the analysis
#: ``ModelErrorResult.sigma_source`` of a result whose noise is sigma_rep of a composed sigma
SIGMA_REP_SOURCE = "sigma_rep (the repeatability of the series; sigma_man left to the model error)"


@dataclass(frozen=True, eq=False)
class ErrorNoise:
    """sigma_k, the standard deviation of one reading of sensor k in the model-error analysis (model units).

    Attributes
    ----------
    sigma : ndarray (n_S,) or None   per sensor; None: the study has no sigma (the pure error of the series)
    composed : tuple of str          the sensors whose study sigma is sqrt(sigma_rep^2 + sigma_man^2): here
                                     their sigma_rep
    sentence : str                   which sigma the bands take and why (the results' first note, quantify,
                                     validate)
    short : str                      the same in one line of a page (the report's model-error pages)
    """

    sigma: np.ndarray | None
    composed: tuple
    sentence: str
    short: str


def _listed(study, names, values) -> str:
    """"F_x 3.35 um, B0_y 1.44 um": standard deviations (model units) in the sensors' file units."""
    units = sensor_units(study)
    return ", ".join("{} {:.3g} {}".format(n, *_in_file_unit(v, units.get(n, ("", "")))) for n, v in
                     zip(names, values))


def error_noise(study, sensors=None) -> ErrorNoise:
    """The noise of the model-error analysis of ``study`` (the sentence names ``sensors``, None: all).

    Per sensor of the study's ``sigma_table``: composed sqrt(sigma_rep^2 + sigma_man^2) -> sigma_rep (sigma_man
    is taken as systematic: the model error holds it); given -> as given; without a study sigma, None (the
    analysis takes the pure error of the repeated series, never the residuals)."""
    shown = tuple(sensors) if sensors else tuple(study.sensors)
    rows = {r["sensor"]: r for r in study.sigma_table}
    if study.sigma is None:
        return ErrorNoise(None, (), "No sigma given: the model-error bands take the pure error of the repeated series "
                                    "as the noise of a reading (never the residuals, which hold the model error).",
                          "Bands: noise the pure error of the repeated series (no sigma given), never the residuals.")
    composed = tuple(s for s in study.sensors if s in rows and math.isfinite(rows[s].get("sigma_man", math.nan))
                     and math.isfinite(rows[s].get("sigma_rep", math.nan)))
    sigma = np.array([rows[s]["sigma_rep"] if s in composed else float(study.sigma[k])
                      for k, s in enumerate(study.sensors)], float)
    given = [s for s in shown if s not in composed]
    listed = _listed(study, given, [sigma[study.sensors.index(s)] for s in given])
    if not composed:
        return ErrorNoise(sigma, (), f"The model-error bands take the sigma given in [[sensors]] ({listed}) as the "
                                     "noise of a new reading, as the user states it.",
                          f"Bands: noise the sigma given in [[sensors]] ({listed}), as the user states it.")
    mine = [s for s in shown if s in composed]
    k = [study.sensors.index(s) for s in mine]
    rep, full = _listed(study, mine, sigma[k]), _listed(study, mine, study.sigma[k])
    others = f", and for the others the sigma given in [[sensors]] ({listed}) as stated" if given else ""
    text = (f"The model-error bands take sigma_rep, the repeatability of the series ({rep}), as the noise of a new "
            f"reading{others}, not the composed sigma sqrt(sigma_rep^2 + sigma_man^2) of the detection ({full}): "
            "sigma_man is taken as a systematic error of the sensor (the same at the same reading, unseen by the "
            "differences between series), which the model error already holds; adding it to every reading "
            "would count it twice.")
    short = (f"Bands: noise sigma_rep ({rep}{'; given: ' + listed if given else ''}), not sqrt(sigma_rep^2 + "
             "sigma_man^2): sigma_man is systematic, held by the model error; adding it again counts it twice.")
    return ErrorNoise(sigma, composed, text, short)


def error_data(study, variant: str, noise: ErrorNoise):
    """``variant``'s data with the noise of the model-error analysis (``noise.sigma``; the study's data as they
    are when no sigma is composed)."""
    data = study.data[variant]
    return data.with_sigma(noise.sigma) if noise.composed else data


def _with_noise(result, noise: ErrorNoise):
    """``result`` with ``noise.sentence`` as its first note; a composed sigma: ``sigma_source``
    :data:`SIGMA_REP_SOURCE` and no check of sigma_rep against the pure error (both measure the series' scatter:
    sigma_rep is no stated sigma), the checks and notes of the sensors given a sigma kept."""
    notes, checks, source = tuple(result.notes), result.pure_error, result.sigma_source
    if noise.composed:
        old = set(pure_error_notes(checks, result.alpha))
        checks = tuple(c for c in checks if c.sensor not in noise.composed)
        notes = tuple(pure_error_notes(checks, result.alpha)) + tuple(n for n in notes if n not in old)
        source = SIGMA_REP_SOURCE
    return dataclasses.replace(result, notes=(noise.sentence,) + notes, pure_error=checks, sigma_source=source)


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
    noise = error_noise(study, [s for s in study.sensors if s in used])
    for v, m in study.models.items():
        if variants is not None and v not in variants:
            continue
        data = error_data(study, v, noise)
        with progress.step(f"model error of {v}"):
            try:
                r = _with_noise(model_error(m, data, start_values(study, v), splits=study.splits, weights=w,
                                            alpha=alpha), noise)
                if embedded and r.kind != "embedded":          # which parameters would carry it (all data, no splits)
                    beside[v] = _with_noise(model_error(m, data, start_values(study, v), kind="embedded", weights=w,
                                                        alpha=alpha), noise)
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


def summary_lines(s) -> list:
    """The terminal lines of an :class:`ErrorSummary`: per sensor the size (max, where, rms), the band to design
    with against the plain one, then the next runs with the mean band before -> after."""
    pct = f"{100 * (1 - s.alpha):g} %"
    lines = [f"  on {s.grid} (size = {s.size_is}; {pct} band of a new reading, median and max):"]
    for z in s.sizes:
        size = ("no error model" if s.kind == "none" else
                f"error max {z.max_abs:.3g} {z.unit} at {z.at}, rms {z.rms:.3g} {z.unit}")
        lines.append(f"    {z.sensor}: {size}; band to design with +-{z.half_median:.3g} {z.unit} (max "
                     f"{z.half_max:.3g}), plain +-{z.plain_median:.3g} (max {z.plain_max:.3g})")
    if s.next_runs:
        lines.append("  measure next: " + "; ".join(s.next_runs) + "; mean band " + ", ".join(
            f"{z.sensor} {z.next_before:.3g} -> {z.next_after:.3g} {z.unit}" for z in s.sizes
            if z.next_before == z.next_before))
        lines.append(f"    ({s.next_how})")
    elif s.next_how:
        lines.append(f"  {s.next_how}")
    return lines


def quantify_text(study, results, summaries=None) -> str:
    """The terminal summary: per variant detected?, kind, size per sensor (file units), embedded parameters,
    pooled held-out coverage with and without the error model, the engineer's summary (``summaries``
    {variant: ErrorSummary}, None: :func:`error_summaries`; :func:`summary_lines`); then which variant to predict
    with and the verdict: "choose X" or "a tie within 2 SE" (the margin's standard error over the splits,
    :mod:`identification.studies.model_ranking`)."""
    units = sensor_units(study)
    if summaries is None:
        summaries = error_summaries(study, results)[0]
    blocks = ["\n".join(_variant_lines(v, r, units, results)
                        + (summary_lines(summaries[v]) if v in summaries else ["  engineer's summary not computed"]))
              for v, r in results.model_error.items()]
    blocks += [f"{v}: model error not computed: {e}" for v, e in results.model_error_errors.items()]
    rank = ranking(results)
    if rank is not None:
        blocks.append("Ranking: " + rank.sentence() + "\nVerdict: " + rank.verdict())
    sens = ", ".join(results.design_sensors) if results.design_sensors else "all"
    head = (f"Model error (sensors {sens}; {results.design_how or 'as configured'})\n"
            + error_noise(study, results.design_sensors).sentence)
    return head + "\n\n" + "\n\n".join(blocks)


def quantify_text_full(study, results, summaries=None) -> str:
    """The text file: the terminal summary, then every variant's full summary."""
    full = [f"---- {v} in full ----\n{r.summary()}" for v, r in results.model_error.items()]
    return quantify_text(study, results, summaries) + "\n\n" + "\n\n".join(full)


def quantify_dict(study, results, summaries=None, summary_errors=None) -> dict:
    """JSON-safe: {"sensors", "design_how", "noise" (:func:`error_noise`'s sentence), "variants": {variant:
    ModelErrorResult.to_dict() plus the sizes in
    file units, the pooled coverages, "summary" (the :class:`ErrorSummary` as a dict, None if it failed) and
    "summary_error" (why it failed, ``summary_errors``; None)},
    "errors": {variant: reason}, "ranking": ModelRanking.to_dict() or None}."""
    from identification.results_protocol import jsonable
    units = sensor_units(study)
    if summaries is None:
        summaries, summary_errors = error_summaries(study, results)
    summary_errors = summary_errors or {}
    variants = {}
    for v, r in results.model_error.items():
        d = r.to_dict()
        d["size_file_units"] = _sensor_sizes(r, units)
        d["pooled_coverage"] = {"plain": pooled_coverage(r, "none"), "with_error": pooled_coverage(r, r.kind)}
        d["embedded_parameters"] = [e.to_dict() for e in embedded_parameters(results, v)]
        d["summary"] = jsonable(summaries[v]) if v in summaries else None
        d["summary_error"] = summary_errors.get(v)
        variants[v] = d
    rank = ranking(results)
    return {"sensors": list(results.design_sensors), "design_how": results.design_how,
            "noise": error_noise(study, results.design_sensors).sentence, "variants": variants,
            "errors": dict(results.model_error_errors), "ranking": None if rank is None else rank.to_dict()}


# ---------------------------------------------------------------------------- mudoe validate
def validate_model_error(study, results, variant: str, progress=None) -> tuple:
    """(text, dict) of ``mudoe validate``'s lines on the model error of the validated ``variant`` on the study's
    data: the held-out coverage of its (1 - alpha) new-reading bands without and with its model error, pooled and
    per split, as :func:`run_model_error` computes it (kind auto, the study's splits and test sensors, the noise of
    :func:`error_noise`, named in a line and the dict's ``noise``; the embedded error beside another chosen error
    model is not fitted); a failure is a line of the text and the dict's ``error``, never an error of the command."""
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
               noise=error_noise(study, r.sensors).sentence,
               n_values=n, coverage_plain=pooled_coverage(r, "none"), coverage_with_error=pooled_coverage(r, r.kind),
               splits=[dict(split=h.split, n_values=h.n_values, coverage_plain=h.coverage_plain,
                            coverage_with_error=h.coverage(r.kind), widening=h.widening(r.kind)) for h in r.heldout])
    level = f"{100 * (1 - r.alpha):g} %"
    head = (f"Held-out coverage of {variant}'s {level} new-reading bands on the study's data (model_error, kind auto; "
            f"sensors {', '.join(r.sensors)}): model error {'DETECTED' if r.detected else 'not detected'} "
            f"(p = {r.test.p_value:.3g}), error model: {r.kind}")
    if not r.heldout:
        return head + "\n  no splits: no held-out coverage", out
    lines = [head, "  " + error_noise(study, r.sensors).sentence,
             f"  pooled: {100 * out['coverage_plain']:.1f} % without the model error, "
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
    noise = error_noise(study, r.sensors)
    data, m = error_data(study, variant, noise), study.models[variant]
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
                              curves=curve_labels(m, data.inputs), noise=noise.short)
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
                          embedded=embedded_parameters(results, variant), noise=noise.short)


def run_model_error_views(study, results):
    """``results`` with ``model_error_views``: {variant: ModelErrorView} of every variant whose model error was
    computed (the report's pages "Model error of ..."), each with its :class:`ErrorSummary` (:func:`error_summary`;
    a failure is a note, the summary None) and the ranking of the variants (the page "Model uncertainty")."""
    rank = ranking(results)
    summaries, failed = error_summaries(study, results)
    views = {v: dataclasses.replace(model_error_view(study, results, v), summary=summaries.get(v), ranking=rank)
             for v in results.model_error}
    results = dataclasses.replace(results, model_error_views={**results.model_error_views, **views})
    return results.with_note("; ".join(f"model-error summary of {v} not computed: {e}" for v, e in failed.items())) \
        if failed else results


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


# ---------------------------------------------------------------------------- the engineer's summary (issue 29 item 4)
#: values of the grid over the data's input range where the sizes and bands are taken (a model of one input; a
#: time-series model: experiments, each at every sampling time)
SIZE_LEVELS = {"static": 41, "time series": 9}
#: candidate runs of the next-runs design: a uniform grid over the data's input range (a model of one input;
#: a time-series model, whose every candidate and node is a whole experiment at every sampling time: fewer)
CANDIDATE_LEVELS = {"static": 17, "time series": 9}
#: Gauss-Legendre nodes of the region (the data's input range) of the next-runs design (as CANDIDATE_LEVELS)
REGION_NODES = {"static": 21, "time series": 9}
#: what the size s(q) of the error is for each error model
SIZE_IS = {"discrepancy": "|mean discrepancy|", "embedded": "{level} half-width of the parameters' spread",
           "none": "no error model: 0"}


def plain_result(result):
    """``result`` (a :class:`identification.ModelErrorResult`) as its plain fit: kind "none", the parameters and
    covariance of the fit without model error, so that its ``predict`` gives the plain bands (h +- z sqrt(g^T C g
    [+ sigma^2])) with no refit."""
    f = result.fit
    plain = dataclasses.replace(f, p=np.asarray(f.plain.p, float).copy(), cov=np.asarray(f.plain.cov, float).copy(),
                                gp=None, embedded=None, alpha_r=None, Vinv_G=None, Vinv=None)
    return dataclasses.replace(result, kind="none", fit=plain, p=plain.p, cov=plain.cov, discrepancies=(),
                               embedded=())


def _file_values(study, values: np.ndarray, sensors) -> np.ndarray:
    """Differences ``values`` (..., len(sensors)) of the named sensors in their files' units."""
    units = sensor_units(study)
    out = np.array(values, float)
    for i, s in enumerate(sensors):
        file_unit, model_unit = units.get(s, ("", ""))
        if file_unit and model_unit and file_unit != model_unit:
            out[..., i] = convert(out[..., i], model_unit, file_unit, difference=True)
    return out


def _input_value(study, model, k: int, v: float) -> tuple:
    """(value, unit) of input ``k`` as the engineer reads it (the first input in its file unit)."""
    unit = (tuple(getattr(model, "input_units", ()) or ()) + ("",) * len(model.inputs))[k] or ""
    if k == 0 and study.units is not None:
        return float(study.units.q_to_file(float(v))), study.units.input_file
    return float(v), unit


def _input_label(study, model, row) -> str:
    """"q_P = 1600 N": an input row (model units) as the engineer reads it."""
    out = []
    for k, (name, v) in enumerate(zip(model.inputs, np.atleast_1d(np.asarray(row, float)))):
        v, unit = _input_value(study, model, k, v)
        out.append(f"{name} = {v:.4g}" + (f" {unit}" if unit else ""))
    return ", ".join(out)


def _levels_grid(lo: np.ndarray, hi: np.ndarray, levels: int) -> np.ndarray:
    """The product grid of ``levels`` equally spaced values per input over [lo, hi] (ends included)."""
    axes = [np.linspace(a, b, levels) if b > a else np.array([a]) for a, b in zip(lo, hi)]
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.stack([m.ravel() for m in mesh], axis=1)


def _range_words(study, model, lo, hi) -> str:
    """"q_P 0-1600 N": the data's input range as the engineer reads it."""
    out = []
    for k, name in enumerate(model.inputs):
        a, unit = _input_value(study, model, k, lo[k])
        b, _ = _input_value(study, model, k, hi[k])
        out.append(f"{name} {a:.4g}-{b:.4g}" + (f" {unit}" if unit else ""))
    return ", ".join(out)


def _flat(band, cols) -> tuple:
    """(mean, half) of a band, (n_points, len(cols)): a dynamic model's experiments x times one after the other."""
    mean = np.asarray(band.mean, float)
    half = (np.asarray(band.upper, float) - np.asarray(band.lower, float)) / 2
    n_s = mean.shape[-1]
    return mean.reshape(-1, n_s)[:, cols], half.reshape(-1, n_s)[:, cols]


def _distinct_rows(q: np.ndarray) -> np.ndarray:
    """The distinct input rows of ``q`` in the data's order."""
    _, first = np.unique(q, axis=0, return_index=True)
    return q[np.sort(first)]


def _points(study, variant: str, result) -> tuple:
    """(input rows, a label per point, the words of where): a model of one input, a grid of :data:`SIZE_LEVELS`
    values over the data's range; several inputs (they may be tied, e.g. a direction or the previous set point) or
    control profiles, the data's distinct input rows.  A time-series model: each row an experiment at the data's
    sampling times (a point is an experiment at a time, experiments x times one after the other)."""
    data, m = study.data[variant], study.models[variant]
    q = np.asarray(data.inputs, float)
    dynamic = study.cfg.dynamic is not None
    if q.shape[1] == 1 and not getattr(m, "controls", ()):
        lo, hi = q.min(axis=0), q.max(axis=0)
        rows = _levels_grid(lo, hi, SIZE_LEVELS["time series" if dynamic else "static"])
        names, where = [_input_label(study, m, row) for row in rows], \
            f"{len(rows)} points over the data's range ({_range_words(study, m, lo, hi)})"
    else:
        rows = _distinct_rows(q)
        names = list(curve_labels(m, rows)) if dynamic else [_input_label(study, m, row) for row in rows]
        where = f"the data's {len(rows)} distinct input rows"
    if not dynamic:
        return rows, names, where
    times = np.asarray(result.discrepancy(rows[:1], result.alpha).grid[0], float)
    unit = getattr(m, "time_unit", "") or ""
    labels = [f"{c}, t = {t:.4g}" + (f" {unit}" if unit else "") for c in names for t in times]
    return rows, labels, where.replace("points", "experiments").replace("input rows", "experiments") \
        + f" at the {len(times)} sampling times"


def _sizes(study, variant: str, result, rows, labels) -> list:
    """The :class:`SensorErrorSize` fields of every selected sensor (before the next runs) at ``rows``."""
    cols = [study.sensors.index(s) for s in result.sensors]
    a = result.alpha
    d_mean, d_half = _flat(result.discrepancy(rows, a), cols)
    size = (np.abs(d_mean) if result.kind == "discrepancy" else d_half if result.kind == "embedded"
            else np.zeros_like(d_mean))
    size = np.abs(_file_values(study, size, result.sensors))
    half = _file_values(study, _flat(result.predict(rows, a, new_reading=True), cols)[1], result.sensors)
    plain = _file_values(study, _flat(plain_result(result).predict(rows, a, new_reading=True), cols)[1],
                         result.sensors)
    units = sensor_units(study)
    out = []
    for i, s in enumerate(result.sensors):
        ok = np.isfinite(size[:, i])
        peak = int(np.flatnonzero(ok)[np.argmax(size[ok, i])]) if ok.any() else 0
        out.append(dict(sensor=s, unit=units.get(s, ("", ""))[0] or units.get(s, ("", ""))[1] or "model unit",
                        max_abs=float(np.max(size[ok, i])) if ok.any() else float("nan"),
                        rms=float(np.sqrt(np.mean(size[ok, i] ** 2))) if ok.any() else float("nan"),
                        at=labels[peak], half_median=float(np.nanmedian(half[:, i])),
                        size=size[:, i].copy(), half=half[:, i].copy(), plain=plain[:, i].copy(),
                        half_max=float(np.nanmax(half[:, i])), plain_median=float(np.nanmedian(plain[:, i])),
                        plain_max=float(np.nanmax(plain[:, i]))))
    return out


def _design_inputs(study, model, q: np.ndarray) -> tuple:
    """(candidates, region, region nodes, region words, candidate words) of the next-runs design (model units): one
    input, a uniform grid of :data:`CANDIDATE_LEVELS` values over the data's range and that range as the region
    (:data:`REGION_NODES` Gauss-Legendre nodes); several inputs, the data's distinct input rows for both (their
    inputs may be tied; equal weights)."""
    size = "static" if study.cfg.dynamic is None else "time series"
    if q.shape[1] == 1:
        lo, hi = q.min(axis=0), q.max(axis=0)
        cand = _levels_grid(lo, hi, CANDIDATE_LEVELS[size])
        words = _range_words(study, model, lo, hi)
        return (cand, {model.inputs[0]: (float(lo[0]), float(hi[0]))}, REGION_NODES[size],
                f"the range ({REGION_NODES[size]} Gauss-Legendre nodes)",
                f"a uniform grid of {len(cand)} values over {words}")
    rows = _distinct_rows(q)
    return rows, rows, 1, "them", f"the data's {len(rows)} distinct input rows"


def _mean_new_reading(study, result, des, sensor: str) -> tuple:
    """(before, after): the region's weighted mean half-width of the new-reading band, z sqrt(v + sigma^2), of
    ``sensor`` (file unit) from the design's posterior half-widths z sqrt(v) of model + error."""
    z = float(stats.norm.ppf(1 - des.alpha / 2))
    sig = float(np.asarray(result.sigma, float)[study.sensors.index(sensor)])
    w = np.asarray(des.region_weights, float)
    mk = np.asarray(des.target_sensors) == sensor
    means = [w @ np.sqrt(np.asarray(h, float)[:, mk] ** 2 + (z * sig) ** 2).mean(axis=1)
             for h in (des.half_before, des.half_after)]
    return tuple(float(x) for x in _file_values(study, np.array(means)[:, None], [sensor]).ravel())


def next_runs(study, variant: str, result, n: int) -> tuple:
    """(labels of the chosen runs, how, {sensor: (before, after)}): the ``n`` input rows that most shrink the
    prediction band (model + error) over where the data lie, :func:`oed.select_error_design` with the integrated
    criterion (:func:`_design_inputs`: candidates and region), each run as many series as the data's; before and
    after are the mean half-width of the new-reading band over the region (file units).  None proposed (empty
    labels, ``how`` says why) for ``n`` = 0, an error model "none", control profiles, or what the design refuses."""
    from oed import select_error_design
    if n == 0 or result.kind not in ("discrepancy", "embedded"):
        return (), ("" if n == 0 else "no error model: no runs to learn it"), {}
    data, m = study.data[variant], study.models[variant]
    if getattr(m, "controls", ()):
        return (), "next runs not offered: the inputs are control profiles (no candidate runs to choose from)", {}
    cand, region, nodes, region_words, cand_words = _design_inputs(study, m, np.asarray(data.inputs, float))
    if n > len(cand):
        return (), f"next runs not offered: {n} runs asked for, {len(cand)} candidates", {}
    repeats = max(1, int(getattr(data, "n_M", 1) or 1))
    try:
        des = select_error_design(result, cand, n, region=region, criterion="integrated", region_size=nodes,
                                  repeats=repeats, time_limit=20.0)
    except ValueError as exc:
        return (), f"next runs not offered: {str(exc).splitlines()[0]}", {}
    shrink = {s: _mean_new_reading(study, result, des, s) for s in dict.fromkeys(des.target_sensors)}
    how = (f"{n} run(s) of {repeats} series from {cand_words} that most shrink the mean band over {region_words}; "
           "oed.select_error_design, integrated criterion, "
           + ("proven optimal" if des.proven else f"NOT proven optimal: {des.status}"))
    return tuple(_input_label(study, m, row) for row in des.chosen_inputs), how, shrink


def error_summary(study, results, variant: str, n_next: int | None = None):
    """The :class:`identification.studies.records.ErrorSummary` of ``variant``'s model error (computed in
    ``results.model_error``): the size of the error per sensor in the files' units, its peak, the new-reading band
    with and without it over the data's input range (:func:`_points`), the parameters that carry it and the next
    runs (``n_next``, default ``[quantify] next_runs``; :func:`next_runs`)."""
    from identification.studies.records import ErrorSummary, SensorErrorSize
    r = results.model_error[variant]
    n_next = study.cfg.quantify.next_runs if n_next is None else n_next
    rows, labels, where = _points(study, variant, r)
    runs, how, shrink = next_runs(study, variant, r, n_next)
    curves = study.cfg.dynamic is None and rows.shape[1] == 1           # a static model of one input: its grid
    sizes = tuple(SensorErrorSize(**{k: x for k, x in d.items() if curves or k not in ("size", "half", "plain")},
                                  next_before=shrink.get(d["sensor"], (np.nan, np.nan))[0],
                                  next_after=shrink.get(d["sensor"], (np.nan, np.nan))[1])
                  for d in _sizes(study, variant, r, rows, labels))
    u = study.units
    m = study.models[variant]
    x_label = m.inputs[0] + (f" [{u.input_file}]" if u is not None and u.input_file else
                             f" [{m.input_units[0]}]" if getattr(m, "input_units", ("",))[0] else "")
    return ErrorSummary(variant=variant, kind=r.kind, detected=bool(r.detected), p_value=float(r.test.p_value),
                        alpha=float(r.alpha), grid=where, sizes=sizes,
                        size_is=SIZE_IS.get(r.kind, r.kind).format(level=f"{100 * (1 - r.alpha):g} %"),
                        embedded=tuple(embedded_parameters(results, variant)), next_runs=runs, next_how=how,
                        x=_first_input(study, rows) if curves else np.zeros(0), x_label=x_label if curves else "")


def error_summaries(study, results, n_next: int | None = None) -> tuple:
    """({variant: ErrorSummary}, {variant: reason}) of every variant whose model error was computed
    (:func:`error_summary`); a variant whose summary fails is in the second with its reason, never dropped."""
    done, failed = {}, {}
    for v in results.model_error:
        try:
            done[v] = error_summary(study, results, v, n_next)
        except (IdentificationError, ValueError, np.linalg.LinAlgError) as exc:
            failed[v] = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return done, failed
