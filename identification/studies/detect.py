r"""Detection of model uncertainty: the paper's Algorithm 1 (lines 01-17), with a calibrated statistic.

For every split (calibration set, validation set) the parameters are identified twice,
p_cal with covariance C_cal and p_val with C_val (paper eqs. 3 and 7), and tested with

.. math::

    \text{paper (line 08):}\quad
    \alpha_\min = 1 - F_{\chi^2_{n_p}}\big((p_v - p_c)^\top C_c^{-1} (p_v - p_c)\big),

    \text{two-sample Wald:}\quad
    \alpha_\min^{(2)} = 1 - F_{\chi^2_{n_p}}\big((p_v - p_c)^\top (C_c + C_v)^{-1} (p_v - p_c)\big),

    \text{likelihood ratio (default):}\quad
    \alpha_\min^{(LR)} = 1 - F_{\chi^2_{n_p}}\big(2\,[\Phi_{c\cup v}(\hat p_{c\cup v})
        - \Phi_c(p_c) - \Phi_v(p_v)]\big),

with Phi = 1/2 sum w r^2 / sigma^2 the objective of eq. 3 on a set and p_{c u v} the fit of
calibration and validation data together (the null hypothesis "one parameter explains
both").  With sigma unknown the likelihood ratio becomes the F (Chow) test
((RSS_{cuv} - RSS_c - RSS_v) / n_p) / ((RSS_c + RSS_v) / (n_c + n_v - 2 n_p)).

The calibration and validation sets hold disjoint data points, so under a correct model
p_v - p_c has covariance C_c + C_v; the paper's statistic ignores C_v and, for sets of
equal size, is about twice a chi^2_{n_p} variable, which inflates its size (measured by
:mod:`identification.studies.montecarlo`).  The two-sample Wald statistic is exact for models
linear in p but, like every Wald test, depends on the parametrisation: for the press,
whose displacements are nearly linear in the compliances 1/k rather than in k, it is
conservative (family-wise size 2.95 % at TOL = 5 %).  The likelihood ratio is invariant
under reparametrisation, equals the two-sample Wald statistic for linear models, and is
calibrated on the press (see ``bench/RESULTS.md``), so it is the default.  A model is rejected when some split has
alpha_min < TOL / n_tests (Bonferroni, lines 09-16); Holm's step-down procedure is
reported alongside (its model-level decision coincides with Bonferroni's, since both
reject the family exactly when the smallest p-value is below TOL / n_tests; they differ
in which individual splits are flagged).

When a fit of a split is not trustworthy (Bates-Watts curvature, :mod:`identification.inference.curvature`;
checked by :func:`detect`), its Wald p-values (two-sample, paper) rest on a linearisation that
fails: they are marked in the summary and the verdict is taken from the likelihood ratio
(invariant under reparametrisation) whatever ``statistic`` was chosen, saying so.  Statistics
that disagree by more than a factor 100 across the decision line get a numbered note.

Line 05 (normality gate): Shapiro-Wilk test, per sensor, of the differences of pairs of
series z_2 - z_1, z_4 - z_3, ... over all inputs, at the family-wise level over the gated
sensors (Holm by default; :mod:`identification.studies.normality`); the repeatability standard deviation
of a sensor is std(differences) / sqrt(2) (same unit as z).  A campaign of time series is gated
pooled per instrument over every (experiment, time) reading (one gate, :class:`_NormalityGate`).

Static and dynamic models take one path: the arguments are checked, the design resolved, the gate
run, the split tests and the decisions computed the same way; what differs is the kind of campaign
(chosen once from the model, :func:`takes_time_series`): a static model's :class:`Measurements` are split by
input rows, series and sensors and :func:`run_split_tests` fits every set, a dynamic model's
:class:`DynamicMeasurements` by experiments and half-open time windows
(:func:`identification.studies.splits.window_rows`: the split tests run on the collocation of the
campaign fit over (experiment, window) rows) and every fit is a dynamic fit with its own
discretisation control (:func:`identification.fit.dynamic_fit.identify_dynamic`: the mesh refined
until the output error at the readings is below ``tol_sigma`` sigmas and the estimate's shift below
``tol_se`` standard errors).  A split one of whose fits could not bound that error is *undecided*
(stage "discretisation", its reason recorded), never a rejection: detect does not report
discretisation error as model inadequacy.

The pieces, bottom up: :mod:`~identification.studies.detect_settings` (the settings and statistics),
:mod:`~identification.studies.normality` (line 05), :mod:`~identification.studies.split_tests` (lines
06-08: the fits and statistics of one split), :mod:`~identification.studies.decisions` (lines 09-17),
:mod:`~identification.studies.detection_result` (the result and its summaries); this module checks
the arguments and runs them in order.  Their public names are importable from here too.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from models.contract import Model
from models.labels import LabelledModel
from models.state import solve_states
from identification.errors import DataError, IdentificationError
from identification.vocabulary import renamed_arguments
from identification.fit.measurements import Measurements
from identification.fit.problem import strategy_for
from identification.inference.results import identify
from identification.progress import Progress
from identification.studies.decisions import ModelDecision, decide, model_decisions
from identification.studies.detect_settings import (CORRECTIONS, DEFAULT_STATISTIC, STATISTICS, DetectSettings,
                                                    alpha_field)
from identification.studies.detection_result import DetectionResult
from identification.studies.normality import NormalityCheck, NormalityError, normality_check, series_text
from identification.studies.split_tests import FitFailure, SplitTest, run_split_tests
from identification.studies.splits import Split, SplitError, reading_mask, readings, window_rows, window_text

__all__ = ["detect", "DetectSettings", "DetectionResult", "SplitTest", "ModelDecision", "NormalityCheck",
           "NormalityError", "normality_check", "run_split_tests", "decide", "STATISTICS", "CORRECTIONS",
           "DEFAULT_STATISTIC", "alpha_field", "model_decisions", "series_text", "FitFailure", "takes_time_series",
           "POOLED_NOTE"]


# ---------------------------------------------------------------------------- detect: validation
def _detect_settings(settings: DetectSettings | None, **given) -> DetectSettings:
    """The settings of a run: ``settings``, or the keywords given (None = the DetectSettings default).

    Raises TypeError when ``settings`` and a keyword it holds are both given.
    """
    given = {k: v for k, v in given.items() if v is not None}
    if settings is None:
        return DetectSettings(**given)
    if not isinstance(settings, DetectSettings):
        raise TypeError(f"settings: expected DetectSettings, got {type(settings).__name__}")
    if given:
        raise TypeError(f"settings and {', '.join(given)}: give the keyword(s) inside settings "
                        f"(dataclasses.replace(settings, {', '.join(f'{k}=...' for k in given)})), not both")
    return settings


def _checked_splits(splits) -> tuple:
    """The splits as a non-empty tuple of Split objects with unique names (SplitError, TypeError)."""
    splits = (splits,) if isinstance(splits, Split) else tuple(splits)
    if not splits:
        raise SplitError("splits: at least one split (test scenario) is needed")
    for sp in splits:
        if not isinstance(sp, Split):
            raise TypeError(f"splits: expected Split objects, got {type(sp).__name__}")
    names = [sp.name for sp in splits]
    if len(set(names)) != len(names):
        raise SplitError(f"splits: names must be unique, got {names}")
    return splits


def _checked_models(model) -> tuple:
    """({name: model}, the kind of campaign they are tested on) from one model or a non-empty mapping of them,
    all static or all dynamic (TypeError, DataError)."""
    if isinstance(model, Mapping):
        models = dict(model)
        if not models:
            raise DataError("model: the mapping of models is empty")
    elif isinstance(model, LabelledModel):
        models = {model.name: model}
    else:
        raise TypeError(f"model: expected a models.Model or a mapping of them, got {type(model).__name__}")
    for name, m in models.items():
        if not isinstance(m, LabelledModel):
            raise TypeError(f"model[{name!r}]: expected a models.Model, got {type(m).__name__}")
    kinds = {_kind(m) for m in models.values()}
    if len(kinds) > 1:
        raise DataError(f"model: {', '.join(models)} mix static and dynamic models; test them in separate calls "
                        "(their data differ)")
    return models, kinds.pop()


def _as_mapping(what, value, names):
    if isinstance(value, Mapping):
        missing = [n for n in names if n not in value]
        if missing:
            raise DataError(f"{what}: no entry for model(s) {missing}")
        return {n: value[n] for n in names}
    return {n: value for n in names}


def _checked_design(design, weights) -> None:
    """``design`` is None, sensor names or weights, exclusive with ``weights`` (DataError)."""
    if weights is not None and design is not None:
        raise DataError("weights, design: give one of them, not both")
    if isinstance(design, str):
        raise DataError(f"design={design!r}: detect takes the design as sensor names or weights, not a criterion "
                        "or a single string; choose the sensors first with oed.select_sensors(model, data, p, "
                        f"criterion={design!r}) and pass the result's .sensors (or .weights) as design")


def _checked_data(name: str, data, splits: tuple) -> Measurements:
    """The campaign of one model, checked against every split's indices (TypeError, SplitError)."""
    if not isinstance(data, Measurements):
        raise TypeError(f"data[{name!r}]: expected an identification.Measurements, got {type(data).__name__}")
    for sp in splits:
        sp.check(data.n_q, data.n_M)
    return data


def _start_values(name: str, p0, model: Model) -> np.ndarray:
    """p0 of one model as a float vector (n_p,) (DataError naming the model)."""
    try:
        p0v = np.asarray(p0, dtype=float).ravel()
    except (TypeError, ValueError):
        raise DataError(f"p0[{name!r}]: not numeric: {p0!r}") from None
    if p0v.shape != (model.n_p,):
        raise DataError(f"p0[{name!r}]: expected {model.n_p} start values ({', '.join(model.param_names)}), "
                        f"got {p0v.size}")
    return p0v


# ---------------------------------------------------------------------------- detect: design (lines 02-03)
def _design_weights(model: Model, data: Measurements, design, weights, design_how: str | None) -> tuple:
    """(validated sensor weights (n_S,) (ones for all sensors), how they were chosen) from ``design`` or
    ``weights``: the one resolution of the sensor selection, which every later step of :func:`detect` reads."""
    if design is None:
        if weights is None:
            return data.sensor_weights(None), design_how or "all sensors given"
        return data.sensor_weights(weights), design_how or "sensor weights given"
    items = list(design)
    if items and all(isinstance(x, str) for x in items):
        unknown = [x for x in items if x not in model.sensors]
        if unknown:
            raise DataError(f"design: unknown sensor(s) {unknown}; the model has {list(model.sensors)}")
        chosen = [1.0 if s in items else 0.0 for s in model.sensors]
        return data.sensor_weights(chosen), design_how or "sensor names given"
    try:
        w = np.asarray(items, float)
    except (TypeError, ValueError):
        raise DataError(f"design: expected None, sensor names or weights, got {design!r}") from None
    if w.shape != (model.n_S,):
        raise DataError(f"design: expected {model.n_S} sensor weights, got {w.size}")
    return data.sensor_weights(w), design_how or "sensor weights given"


def _check_split_sizes(splits: tuple, data: Measurements, model: Model, w: np.ndarray) -> None:
    """Every set of every split holds at least n_p values on the sensors selected by ``w`` (n_S,) (SplitError)."""
    n_sel = int(np.count_nonzero(w > 0))
    for sp in splits:
        sp.check(data.n_q, data.n_M, model.n_p, n_sel)


# ---------------------------------------------------------------------------- detect: normality gate (line 05)
#: the note of a gate pooled per instrument over a campaign of time series
POOLED_NOTE = "pooled per instrument over every (experiment, time) reading"


class _NormalityGate:
    """Line 05 once per distinct campaign z and sensor selection: :func:`normality_check`, then
    raise :class:`NormalityError` (normality="check") or record the override in ``notes``.  A campaign
    of time series is gated pooled per instrument (its :meth:`DynamicMeasurements.by_instrument`, the
    note :data:`POOLED_NOTE`), not per (sensor, time) pair, whose few differences each would make the
    gate blind and its multiplicity correction over hundreds of pairs meaningless."""

    def __init__(self, settings: DetectSettings, notes: list):
        self.settings = settings
        self.notes = notes
        self.seen: list = []          # (z, selection weights, NormalityCheck) already checked

    def check(self, data: Measurements, wk: np.ndarray, pooled: str = "") -> NormalityCheck:
        """The gate on ``data`` with the sensors of the validated weights ``wk`` (n_S,); ``pooled`` (a
        note, e.g. :data:`POOLED_NOTE`) says how the readings were pooled into ``data``'s columns."""
        found = None
        for z, w_seen, chk in self.seen:
            if z is data.z or (z.shape == data.z.shape and np.array_equal(z, data.z, equal_nan=True)):
                if np.array_equal(w_seen, wk):
                    found = chk
        if found is not None:
            return found
        chk = normality_check(data, self.settings.normality_level, wk, self.settings.normality_correction)
        if pooled:
            chk = dataclasses.replace(chk, note=pooled + (f"; {chk.note}" if chk.note else ""))
        if not chk.passed:
            chk = self._failed(chk)
        self.seen.append((data.z, wk, chk))
        return chk

    def _failed(self, chk: NormalityCheck) -> NormalityCheck:
        bad = chk.failing()
        adj = "" if chk.correction == "none" else f" ({chk.correction}-adjusted over {len(chk.gated)} sensors)"
        msg = (f"normality gate (Algorithm 1, line 05) failed for sensor(s) {', '.join(bad)}: Shapiro-Wilk "
               f"p-value(s){adj} {', '.join(f'{100 * chk.adjusted[chk.sensors.index(s)]:.3g} %' for s in bad)} "
               f"< {100 * chk.level:g} % on the differences of repeated series"
               + (f" ({chk.note})" if chk.note else "")
               + "; acquire new data, or pass normality='override' to continue on record")
        if self.settings.normality == "check":
            raise NormalityError(msg, chk)
        self.notes.append(f"override: {msg}")
        return dataclasses.replace(chk, passed=False, overridden=True)


# ---------------------------------------------------------------------------- detect: fits and decisions
def _start_states(model: Model, p0: np.ndarray, data: Measurements):
    """States (n_q, n_y) at p0 for every input of ``data`` (warm start of the fits), or None."""
    try:
        return solve_states(model, p0, data.inputs) if data.d_q == model.n_q_dim else None
    except IdentificationError:
        return None          # each fit then reports the failing state solve itself


def _split_tests_shown(progress: Progress | None, model: Model, data: Measurements, splits: tuple, *args,
                       model_name: str, **kwargs) -> tuple:
    """:func:`run_split_tests` with a bar of one model's splits on ``progress`` (none when None)."""
    if progress is None:
        return run_split_tests(model, data, splits, *args, model_name=model_name, **kwargs)
    with progress.bar(len(splits), f"detect {model_name}", unit="split") as bar:
        return run_split_tests(model, data, splits, *args, model_name=model_name, bar=bar, **kwargs)


@dataclass(frozen=True, eq=False)
class _Run:
    """What the models of one :func:`detect` call share."""

    settings: DetectSettings
    splits: tuple
    design: object
    weights: object
    design_how: str | None
    progress: Progress | None
    discretisation: object
    gate: _NormalityGate
    notes: list


@dataclass(frozen=True)
class _ModelTests:
    """The outcome of one model: its design entry, normality check, split tests and the splits tested."""

    design: tuple
    normality: NormalityCheck
    tests: tuple
    splits: tuple


class _Rows:
    """A static model on a campaign of input rows (:class:`Measurements`): a split selects rows, series
    and sensors; :func:`run_split_tests` fits every set."""

    def checked_splits(self, splits) -> tuple:
        """The splits (:func:`_checked_splits`), none by time window."""
        splits = _checked_splits(splits)
        for sp in splits:
            if sp.timed:
                raise SplitError(f"split {sp.name!r} selects readings by time window; a static model's data have no "
                                 "sampling times")
        return splits

    def checked_design(self, design, weights, discretisation) -> None:
        """``design`` / ``weights`` (:func:`_checked_design`); no ``discretisation``."""
        _checked_design(design, weights)
        if discretisation is not None:
            raise DataError("discretisation: only the fits of a dynamic model take a discretisation control")

    def model_tests(self, run: _Run, name: str, m: Model, data, p0) -> _ModelTests:
        """Lines 02-08 for the model ``m`` (named ``name``) on its campaign ``data`` from the start ``p0``."""
        data = _checked_data(name, data, run.splits)
        w, how = _design_weights(m, data, run.design, run.weights, run.design_how)     # resolved once, passed down
        _check_split_sizes(run.splits, data, m, w)
        design = (name, tuple(s for k, s in enumerate(m.sensors) if w[k] > 0), how)
        chk = run.gate.check(data, w)
        if data.sigma is None:
            run.notes.append(f"{name}: sigma unknown and estimated per fit; the chi^2 law of alpha_min is then "
                             "approximate")
        p0v = _start_values(name, p0, m)
        tests = _split_tests_shown(run.progress, m, data, run.splits, p0v, weights=w, settings=run.settings,
                                   model_name=name, states0=_start_states(m, p0v, data), curvature=True)
        return _ModelTests(design, chk, tests, run.splits)


class _TimeSeries:
    """A dynamic model on a campaign of time series (:class:`DynamicMeasurements`): a split selects
    experiments and a time window (:func:`identification.studies.splits.window_rows`); every fit
    (campaign, calibration, validation, pooled) is a dynamic fit with its own discretisation control.
    The split tests run on the collocation of the campaign fit over the (experiment, window) rows with
    these fits; a split one of whose fits could not bound the discretisation error is undecided (stage
    "discretisation", its reason recorded), never a rejection."""

    def checked_splits(self, splits) -> tuple:
        """The splits (:func:`_checked_splits`), by experiment and time window only."""
        splits = _checked_splits(splits)
        for sp in splits:
            if sp.cal_series is not None or sp.val_series is not None:
                raise SplitError(f"split {sp.name!r}: splits of series are not supported on dynamic data")
            if sp.cal_sensors is not None or sp.val_sensors is not None:
                raise SplitError(f"split {sp.name!r}: a split of a dynamic model's time series selects experiments "
                                 "and time windows, not sensor columns (those are splits of the flat data, "
                                 "identification.studies.splits.flat_split)")
        return splits

    def checked_design(self, design, weights, discretisation) -> None:
        """``design`` only (instrument names), no ``weights``."""
        if weights is not None:
            raise DataError("weights: a dynamic model takes design= (instrument or sensor@time names)")

    def model_tests(self, run: _Run, name: str, m, data, p0) -> _ModelTests:
        """Lines 02-08 for the dynamic model ``m`` (named ``name``) on its time series ``data`` from ``p0``."""
        strategy_for(m).check_data(data, f"data[{name!r}]")
        w = _instrument_weights(m, run.design)
        design = (name, tuple(s for k, s in enumerate(m.sensors) if w is None or w[k] > 0),
                  run.design_how or ("instruments given" if run.design is not None else "all instruments"))
        inst = data.by_instrument()
        chk = run.gate.check(inst, inst.sensor_weights(w), pooled=POOLED_NOTE)
        rows, row_splits = window_rows(data, run.splits)
        whole = identify(m, data, _start_values(name, p0, m), weights=w, settings=run.settings.identify,
                         discretisation=run.discretisation)
        fits, pooled, unbounded = _series_fits(m, data, tuple(zip(run.splits, row_splits)), whole.p, w, run)
        res = _split_tests_shown(run.progress, whole.model, rows, row_splits, whole.p, settings=run.settings,
                                 model_name=name, curvature=True, fits=fits, pooled=pooled)
        labels = {sp.name: (_series_label(sp.cal_inputs, sp.cal_window), _series_label(sp.val_inputs, sp.val_window))
                  for sp in run.splits}
        res = [dataclasses.replace(t, cal_label=labels[t.split][0], val_label=labels[t.split][1]) for t in res]
        tests = tuple(_undecided(t, unbounded[t.split]) if t.split in unbounded else t for t in res)
        rec = whole.diagnostics.discretisation
        run.notes.append(f"{name}: every split's fits by Radau IIA collocation with discretisation error control "
                         f"(whole campaign: {rec.n_elements} elements, {100 * rec.error_sigma:.2g} % of sigma); the "
                         "normality gate is pooled per instrument")
        return _ModelTests(design, chk, tests, row_splits)


def _instrument_weights(model, design):
    """Instrument weights (n_S,) from instrument names (None: every instrument)."""
    if design is None:
        return None
    if not all(isinstance(x, str) for x in design):
        raise DataError("design: a dynamic model takes instrument names (each measured at every sampling time)")
    unknown = [x for x in design if x not in model.sensors]
    if unknown:
        raise DataError(f"design: unknown instrument(s) {unknown}; the model has {list(model.sensors)}")
    return np.array([1.0 if s in design else 0.0 for s in model.sensors])


def _series_label(exps, window) -> str:
    """A set of a split of time series in words: "experiment(s) 1, 2, 3; t < 1.2" (1-based)."""
    e = "all experiments" if exps is None else "experiment(s) " + ", ".join(str(j + 1) for j in exps)
    return e if window is None else f"{e}; {window_text(window)}"


def _undecided(t: SplitTest, msg: str) -> SplitTest:
    """The split test ``t`` made undecided: no p-value, the reason recorded."""
    nan = math.nan
    return dataclasses.replace(t, ok=False, stage="discretisation", error=msg, alpha_paper=nan,
                               alpha_two_sample=nan, alpha_lr=nan, lr_error=msg)


def _series_fit(model, data, p0, weights, run: _Run, failed: str = ""):
    """A dynamic fit of a set, or the :class:`FitFailure` of the error it raised (reason
    "<failed><ErrorType>: <message>"; recorded by the split test, never raised)."""
    try:
        return identify(model, data, p0, weights=weights, settings=run.settings.identify,
                        discretisation=run.discretisation)
    except (IdentificationError, DataError) as exc:
        return FitFailure.from_error(exc, failed)


def _unbounded(est) -> str:
    """Why the discretisation error of the fit ``est`` is not bounded ("" when it is, or the fit failed)."""
    rec = est.diagnostics.discretisation if not isinstance(est, FitFailure) else None
    return "" if rec is None or rec.bounded else rec.reason or "not bounded"


def _series_fits(model, data, splits, p0, w, run: _Run) -> tuple:
    """(fits [(cal, val)], pooled {points: fit}, unbounded {split: reason}) of every (split, split of rows)."""
    fits, pooled, unbounded = [], {}, {}
    for sp, st in splits:
        masks = [reading_mask(data, sp.cal_inputs, sp.cal_window), reading_mask(data, sp.val_inputs, sp.val_window)]
        pair = tuple(_series_fit(model, readings(data, mk), p0, w, run) for mk in masks)
        fits.append(pair)
        key = st.pooled_points(data.n_M)
        if key not in pooled:
            pooled[key] = _series_fit(model, readings(data, masks[0] | masks[1]), p0, w, run,
                                      failed="pooled fit failed: ")
        why = [f"{what} fit: {_unbounded(e)}" for what, e in zip(("calibration", "validation", "pooled"),
                                                               pair + (pooled[key],)) if _unbounded(e)]
        if why:
            unbounded[sp.name] = "discretisation error not bounded (" + "; ".join(why) + ")"
    return fits, pooled, unbounded


_ROWS, _TIME_SERIES = _Rows(), _TimeSeries()


def takes_time_series(model) -> bool:
    """Whether ``model`` is tested on a campaign of time series (a dynamic model: its splits select
    experiments and time windows, its fits take a discretisation) rather than on input rows: the model's
    strategy answers (:attr:`identification.fit.problem.ProblemStrategy.takes_time_series`), for
    :func:`detect` and :func:`identification.studies.montecarlo.validate`."""
    return strategy_for(model).takes_time_series


def _kind(model):
    """The kind of campaign a model is tested on: time series for a dynamic model, else input rows."""
    return _TIME_SERIES if strategy_for(model).takes_time_series else _ROWS


# ---------------------------------------------------------------------------- main entry
@renamed_arguments(measurements="data", tol="alpha")
def detect(model, data, splits: Sequence[Split], p0, alpha: float | None = None, statistic: str | None = None,
           correction: str | None = None, weights=None, design=None, normality: str | None = None,
           settings: DetectSettings | None = None, design_how: str | None = None,
           progress: Progress | None = None, discretisation=None) -> DetectionResult:
    r"""Algorithm 1: is the model rejected by calibration / validation tests?

    For each split: p_cal, C_cal and p_val, C_val by :func:`identify` (eqs. 3, 7), then

        alpha_paper = 1 - F_chi2(n_p)((p_val - p_cal)^T C_cal^{-1} (p_val - p_cal))
        alpha_2s    = 1 - F_chi2(n_p)((p_val - p_cal)^T (C_cal + C_val)^{-1} (p_val - p_cal))
        alpha_LR    = 1 - F_chi2(n_p)(2 [Phi_pooled(p_pooled) - Phi_cal(p_cal) - Phi_val(p_val)])

    (chi^2 units, dimensionless p-values; p_pooled from one more fit of calibration and
    validation data together) and the model is rejected when some alpha_min of the chosen
    statistic is below TOL / n_tests (Bonferroni; Holm reported as well).  All splits are
    evaluated (the paper stops at the first rejection; the verdict is the same).

    Steps: validate the arguments, the sensor design (lines 02-03, given), the normality gate
    (line 05), the split fits and statistics (lines 06-08, :func:`run_split_tests`), the
    decisions (lines 09-17, :func:`decide`), the result.

    Parameters
    ----------
    model : models.Model or mapping {name: Model}
        One candidate, or several (e.g. M1, M2, M3) tested on the same splits; all static or all
        dynamic (ODE/DAE models).
    data : Measurements or mapping {name: Measurements}
        The campaign (per model when their inputs differ); :class:`DynamicMeasurements` for a
        dynamic model.  sigma per sensor should be known (the paper fixes it); with sigma=None it
        is estimated and the chi^2 law is approximate.
    splits : sequence of Split
        The n_tests scenarios (e.g. ``splits_from_scenarios(models.press.PRESS_SCENARIOS, 29)``); on
        time series by experiment and time window (e.g. ``time_window_splits([e])``,
        ``early_late_dynamic_split(data)``), not by series or sensor columns.
    p0 : array_like (n_p,) or mapping {name: array}
        Start values of every fit.
    alpha : float, optional
        Family-wise level TOL in (0, 1) (default :class:`DetectSettings`' 5 %).
    statistic : {"likelihood_ratio", "two_sample", "paper"}, optional
        Which alpha_min decides (all three are always reported; default likelihood_ratio).
    correction : {"bonferroni", "holm"}, optional
    weights : array_like (n_S,), optional
        Sensor weights (0/1) of the fits; exclusive with ``design``.
    design : None, sequence of str or array_like (n_S,)
        Lines 02-03, chosen beforehand: sensor names or weights (a dynamic model: instrument names,
        each measured at every sampling time).  An optimal design is chosen
        with ``oed.select_sensors(model, data, p, criterion=...)``; pass its ``sensors``.
    normality : {"check", "override"}, optional
        "check" (default) raises :class:`NormalityError` when a selected sensor fails the
        Shapiro-Wilk gate; "override" records the failure and continues.
    settings : DetectSettings, optional
        All settings at once; exclusive with alpha, statistic, correction and normality.
    design_how : str, optional
        How the design was chosen (e.g. "E-optimal design of 2 sensors"), recorded in
        ``DetectionResult.design``; default "sensor names given", "sensor weights given" or
        "all sensors given".
    progress : identification.progress.Progress, optional
        A bar advanced per split fitted (models x splits; default None: no output).
    discretisation : identification.fit.dynamic_fit.DiscretisationSettings, optional
        The discretisation error control of every fit of a dynamic model (default
        ``DiscretisationSettings()``); a static model takes none.

    Returns
    -------
    DetectionResult

    Raises
    ------
    ValueError
        alpha outside (0, 1), unknown statistic / correction / normality.
    TypeError
        ``settings`` together with alpha, statistic, correction or normality; bad argument types
        (e.g. ``progress`` not a Progress).
    NormalityError
        Line 05 failed and normality="check".
    DataError, SplitError
        Bad arguments (named in the message), e.g. a criterion string as design.  A fit failing
        on a split does not raise: it is recorded and the model's verdict becomes "undecided"
        unless another split rejects it.
    """
    settings = _detect_settings(settings, tol=alpha, statistic=statistic, correction=correction, normality=normality)
    models, kind = _checked_models(model)
    names = tuple(models)
    splits = kind.checked_splits(splits)
    datas = _as_mapping("data", data, names)
    p0s = _as_mapping("p0", p0, names)
    kind.checked_design(design, weights, discretisation)
    if progress is not None and not isinstance(progress, Progress):
        raise TypeError(f"progress: expected an identification.progress.Progress or None, got {type(progress).__name__}")
    notes = []
    run = _Run(settings=settings, splits=splits, design=design, weights=weights, design_how=design_how,
               progress=progress, discretisation=discretisation, gate=_NormalityGate(settings, notes), notes=notes)
    outs = [kind.model_tests(run, name, models[name], datas[name], p0s[name]) for name in names]
    tests = tuple(t for o in outs for t in o.tests)
    primary, all_decisions = model_decisions(tests, names, settings)
    return DetectionResult(settings=settings, models=names, splits=outs[-1].splits, tests=tests, decisions=primary,
                           all_decisions=all_decisions, normality=tuple((n, o.normality) for n, o in zip(names, outs)),
                           design=tuple(o.design for o in outs), notes=tuple(notes))
