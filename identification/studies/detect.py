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
sensors (Holm by default; :mod:`identification.studies.normality_gate`); the repeatability standard deviation
of a sensor is std(differences) / sqrt(2) (same unit as z).

The pieces, bottom up: :mod:`~identification.studies.detect_settings` (the settings and statistics),
:mod:`~identification.studies.normality` (line 05), :mod:`~identification.studies.split_tests` (lines
06-08: the fits and statistics of one split), :mod:`~identification.studies.decisions` (lines 09-17),
:mod:`~identification.studies.detection_result` (the result and its summaries); this module checks
the arguments, runs them in order, and sends dynamic models to
:func:`identification.studies.dynamic_detect.detect_dynamic`.  Their public names are importable
from here too.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Sequence

import numpy as np

from models.contract import Model
from models.state import solve_states
from identification.errors import DataError, IdentificationError
from identification.fit.measurements import Measurements
from identification.progress import Progress
from identification.studies.decisions import ModelDecision, decide, model_decisions
from identification.studies.detect_settings import (CORRECTIONS, DEFAULT_STATISTIC, STATISTICS, DetectSettings,
                                                    alpha_field)
from identification.studies.detection_result import DetectionResult
from identification.studies.dynamic_detect import detect_dynamic
from identification.studies.normality import NormalityCheck, NormalityError, normality_check, series_text
from identification.studies.split_tests import FitFailure, SplitTest, run_split_tests
from identification.studies.splits import Split, SplitError

__all__ = ["detect", "DetectSettings", "DetectionResult", "SplitTest", "ModelDecision", "NormalityCheck",
           "NormalityError", "normality_check", "run_split_tests", "decide", "STATISTICS", "CORRECTIONS",
           "DEFAULT_STATISTIC", "alpha_field", "model_decisions", "series_text", "FitFailure"]


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


def _checked_models(model) -> dict:
    """{name: Model} from one Model or a non-empty mapping of them (TypeError, DataError)."""
    if isinstance(model, Mapping):
        models = dict(model)
        if not models:
            raise DataError("model: the mapping of models is empty")
    elif isinstance(model, Model):
        models = {model.name: model}
    else:
        raise TypeError(f"model: expected a models.Model or a mapping of them, got {type(model).__name__}")
    for name, m in models.items():
        if not isinstance(m, Model):
            raise TypeError(f"model[{name!r}]: expected a models.Model, got {type(m).__name__}")
    return models


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
        raise TypeError(f"measurements[{name!r}]: expected an identification.Measurements, got {type(data).__name__}")
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
class _NormalityGate:
    """Line 05 once per distinct campaign z and sensor selection: :func:`normality_check`, then
    raise :class:`NormalityError` (normality="check") or record the override in ``notes``."""

    def __init__(self, settings: DetectSettings, notes: list):
        self.settings = settings
        self.notes = notes
        self.seen: list = []          # (z, selection weights, NormalityCheck) already checked

    def check(self, data: Measurements, wk: np.ndarray) -> NormalityCheck:
        """The gate on ``data`` with the sensors of the validated weights ``wk`` (n_S,)."""
        found = None
        for z, w_seen, chk in self.seen:
            if z is data.z or (z.shape == data.z.shape and np.array_equal(z, data.z, equal_nan=True)):
                if np.array_equal(w_seen, wk):
                    found = chk
        if found is not None:
            return found
        chk = normality_check(data, self.settings.normality_level, wk, self.settings.normality_correction)
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


def _dynamic(model) -> bool:
    ms = model.values() if isinstance(model, Mapping) else (model,)
    return any(getattr(m, "is_dynamic", False) for m in ms)


# ---------------------------------------------------------------------------- main entry
def detect(model, measurements, splits: Sequence[Split], p0, tol: float | None = None, statistic: str | None = None,
           correction: str | None = None, weights=None, design=None, normality: str | None = None,
           settings: DetectSettings | None = None, design_how: str | None = None,
           progress: Progress | None = None) -> DetectionResult:
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
        One candidate, or several (e.g. M1, M2, M3) tested on the same splits.
    measurements : Measurements or mapping {name: Measurements}
        The campaign (per model when their inputs differ).  sigma per sensor should be known
        (the paper fixes it); with sigma=None it is estimated and the chi^2 law is approximate.
    splits : sequence of Split
        The n_tests scenarios (e.g. ``splits_from_scenarios(models.press.PRESS_SCENARIOS, 29)``).
    p0 : array_like (n_p,) or mapping {name: array}
        Start values of every fit.
    tol : float, optional
        Family-wise level TOL in (0, 1) (default :class:`DetectSettings`' 5 %).
    statistic : {"likelihood_ratio", "two_sample", "paper"}, optional
        Which alpha_min decides (all three are always reported; default likelihood_ratio).
    correction : {"bonferroni", "holm"}, optional
    weights : array_like (n_S,), optional
        Sensor weights (0/1) of the fits; exclusive with ``design``.
    design : None, sequence of str or array_like (n_S,)
        Lines 02-03, chosen beforehand: sensor names or weights.  An optimal design is chosen
        with ``oed.select_sensors(model, data, p, criterion=...)``; pass its ``sensors``.
    normality : {"check", "override"}, optional
        "check" (default) raises :class:`NormalityError` when a selected sensor fails the
        Shapiro-Wilk gate; "override" records the failure and continues.
    settings : DetectSettings, optional
        All settings at once; exclusive with tol, statistic, correction and normality.
    design_how : str, optional
        How the design was chosen (e.g. "E-optimal design of 2 sensors"), recorded in
        ``DetectionResult.design``; default "sensor names given", "sensor weights given" or
        "all sensors given".
    progress : identification.progress.Progress, optional
        A bar advanced per split fitted (models x splits; default None: no output).

    Returns
    -------
    DetectionResult

    Raises
    ------
    ValueError
        tol outside (0, 1), unknown statistic / correction / normality.
    TypeError
        ``settings`` together with tol, statistic, correction or normality; bad argument types
        (e.g. ``progress`` not a Progress).
    NormalityError
        Line 05 failed and normality="check".
    DataError, SplitError
        Bad arguments (named in the message), e.g. a criterion string as design.  A fit failing
        on a split does not raise: it is recorded and the model's verdict becomes "undecided"
        unless another split rejects it.
    """
    settings = _detect_settings(settings, tol=tol, statistic=statistic, correction=correction, normality=normality)
    if _dynamic(model):           # ODE/DAE models: their collocation, splits by experiment and time window
        if weights is not None:
            raise DataError("weights: a dynamic model takes design= (instrument or sensor@time names)")
        return detect_dynamic(model, measurements, splits, p0, settings=settings, design=design,
                              design_how=design_how, progress=progress)
    splits = _checked_splits(splits)
    models = _checked_models(model)
    names = tuple(models)
    datas = _as_mapping("measurements", measurements, names)
    p0s = _as_mapping("p0", p0, names)
    _checked_design(design, weights)
    if progress is not None and not isinstance(progress, Progress):
        raise TypeError(f"progress: expected an identification.progress.Progress or None, got {type(progress).__name__}")
    notes, tests, normal, designs = [], [], [], []
    gate = _NormalityGate(settings, notes)
    for name in names:
        m = models[name]
        data = _checked_data(name, datas[name], splits)
        w, how = _design_weights(m, data, design, weights, design_how)     # resolved once, passed down
        _check_split_sizes(splits, data, m, w)
        designs.append((name, tuple(s for k, s in enumerate(m.sensors) if w[k] > 0), how))
        normal.append((name, gate.check(data, w)))
        if data.sigma is None:
            notes.append(f"{name}: sigma unknown and estimated per fit; the chi^2 law of alpha_min is then "
                         "approximate")
        p0v = _start_values(name, p0s[name], m)
        tests.extend(_split_tests_shown(progress, m, data, splits, p0v, weights=w, settings=settings, model_name=name,
                                        states0=_start_states(m, p0v, data), curvature=True))
    primary, all_decisions = model_decisions(tuple(tests), names, settings)
    return DetectionResult(settings=settings, models=names, splits=splits, tests=tuple(tests), decisions=primary,
                           all_decisions=all_decisions, normality=tuple(normal), design=tuple(designs),
                           notes=tuple(notes))
