r"""Algorithm 1 on a dynamic model: splits by experiment, by time window, early against late.

A dynamic campaign (:class:`DynamicMeasurements`) is tested on its collocation (:mod:`models.collocation`)
on the mesh of the fit of the whole campaign (:func:`identification.fit.dynamic_fit.identify_dynamic`,
discretisation error controlled at p̂).  Every experiment j is cut into the windows
[b_{w-1}, b_w) of the union of the splits' window edges; the row (j, w) of the static problem holds
experiment j's readings in window w (the others NaN, i.e. missing) with experiment j's inputs, so
that a split by experiment, by time window or early against late is a split of these rows and the
pooled fit of a split is the fit of the readings of both sets (eq. of :func:`detect` unchanged).

Normality gate (line 05): pooled per instrument over all (experiment, time) readings
(:meth:`DynamicMeasurements.by_instrument`: Shapiro-Wilk of the differences of consecutive series,
one test per instrument), not per (sensor, time) pair, whose few differences each would make the
gate blind and its multiplicity correction over hundreds of pairs meaningless.

Discretisation: every fit of a split (calibration, validation, pooled) is a dynamic fit with its own
error control (:func:`identification.fit.dynamic_fit.identify_dynamic`: the mesh is refined until the
output error at the readings is below ``tol_sigma`` sigmas and the estimate's shift below ``tol_se``
standard errors).  A split one of whose fits could not bound the error is *undecided* (stage
"discretisation", its reason recorded), never a rejection: detect does not report discretisation
error as model inadequacy.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from identification.fit.dynamic_data import DynamicMeasurements
from identification.fit.dynamic_fit import DiscretisationSettings
from identification.errors import DataError, IdentificationError
from identification.fit.measurements import Measurements
from identification.inference.identify import identify
from identification.studies.decisions import model_decisions
from identification.studies.detection_result import DetectionResult
from identification.studies.normality import NormalityError, normality_check
from identification.studies.split_tests import FitFailure, run_split_tests
from identification.studies.splits import Split, SplitError

__all__ = ["DynamicSplit", "time_window_splits", "early_late_dynamic_split", "detect_dynamic", "flat_split"]


@dataclass(frozen=True)
class DynamicSplit:
    """A calibration / validation split of a time-series campaign.

    Attributes
    ----------
    name : str
    cal_experiments, val_experiments : tuple of int or None   0-based experiments (None: all)
    cal_window, val_window : (float, float) or None           readings with lo <= t < hi (None: all times)
    description : str
    """

    name: str
    cal_experiments: tuple | None = None
    val_experiments: tuple | None = None
    cal_window: tuple | None = None
    val_window: tuple | None = None
    description: str = ""

    def __post_init__(self):
        for what in ("cal_window", "val_window"):
            w = getattr(self, what)
            if w is not None:
                w = (float(w[0]), float(w[1]))
                if not w[0] < w[1]:
                    raise SplitError(f"split {self.name!r}: {what} {list(w)} is empty (expected lo < hi)")
                object.__setattr__(self, what, w)
        for what in ("cal_experiments", "val_experiments"):
            e = getattr(self, what)
            if e is not None:
                object.__setattr__(self, what, tuple(int(j) for j in e))

    def edges(self) -> set:
        """The window edges this split needs (times)."""
        return {v for w in (self.cal_window, self.val_window) if w is not None for v in w if math.isfinite(v)}


def time_window_splits(edges) -> tuple:
    """One split per edge e: the readings at t < e (calibration) against those at t >= e (validation)."""
    e = sorted({float(x) for x in edges})
    if not e:
        raise SplitError("time_windows: give at least one edge (a time cutting the experiments)")
    return tuple(DynamicSplit(f"t < {v:g} vs t >= {v:g}", cal_window=(-math.inf, v), val_window=(v, math.inf),
                              description="time window") for v in e)


def early_late_dynamic_split(data: DynamicMeasurements) -> DynamicSplit:
    """Early against late: the readings at t < t_c against those at t >= t_c, t_c the sampling time at
    index n_t // 2 of the campaign's (union of) sampling times, as a :class:`DynamicSplit` for
    :func:`detect_dynamic` on the DynamicModel (each fit with its own discretisation control).

    Not :func:`identification.studies.splits.early_late_split`, which masks the (sensor, time) columns of the flat
    data for the static tests on a collocated model, and cuts at t <= the time at index (n_t - 1) // 2
    (the same partition for an even number of sampling times, one time more in the early set for an odd one).
    """
    t = data.union_times
    cut = float(t[(t.size) // 2])
    return DynamicSplit(f"early (t < {cut:g}) vs late", cal_window=(-math.inf, cut), val_window=(cut, math.inf),
                        description="early vs late")


def flat_split(sp, pairs, n_q: int) -> Split:
    """The split ``sp`` (:class:`DynamicSplit`, or a :class:`Split` returned unchanged) as a split of the
    flat data of a dynamic model (columns ``pairs`` = (sensor, time), rows the ``n_q`` experiments): the
    calibration columns are the pairs with t in ``cal_window`` (lo <= t < hi), likewise validation.

    Raises
    ------
    SplitError
        A window holds no sampling time, or an experiment index is out of range.
    """
    if isinstance(sp, Split):
        return sp
    if not isinstance(sp, DynamicSplit):
        raise TypeError(f"splits: expected Split or DynamicSplit objects, got {type(sp).__name__}")
    t = np.array([float(tp) for _, tp in pairs])
    sets = []
    for what, exps, win in (("calibration", sp.cal_experiments, sp.cal_window),
                            ("validation", sp.val_experiments, sp.val_window)):
        _check_experiments(sp, what, exps, n_q)
        cols = None if win is None else np.flatnonzero((t >= win[0]) & (t < win[1])).tolist()
        if cols is not None and not cols:
            raise SplitError(f"split {sp.name!r}: the {what} window {list(win)} holds no sampling time; the times "
                             f"are {np.unique(t).tolist()}")
        sets.append((list(range(n_q)) if exps is None else list(exps), cols))
    (qc, kc), (qv, kv) = sets
    return Split(sp.name, qc, qv, description=sp.description or "dynamic split", cal_sensors=kc, val_sensors=kv)


def _windows(splits) -> np.ndarray:
    edges = set()
    for sp in splits:
        if isinstance(sp, DynamicSplit):
            edges |= sp.edges()
    return np.array(sorted(edges))


def _expanded(data: DynamicMeasurements, edges: np.ndarray):
    """(rows [(experiment, window)], static Measurements over the rows) (see the module docstring)."""
    flat = data.flat()
    t_pair = np.array([t for _, t in data.pairs])
    w_pair = np.searchsorted(edges, t_pair, side="right")
    rows, z = [], []
    for j in range(data.n_q):
        for w in range(edges.size + 1):
            zz = np.where((w_pair == w)[None, :], flat.z[:, j, :], np.nan)
            if np.isfinite(zz).any():
                rows.append((j, w))
                z.append(zz)
    z = np.stack(z, axis=1)
    q = flat.inputs[[j for j, _ in rows]]
    return rows, Measurements(q, z, flat.sigma, sensors=flat.sensors, input_names=flat.input_names,
                              series=flat.series)


def _in_window(window, edges, w) -> bool:
    if window is None:
        return True
    lo = -math.inf if w == 0 else edges[w - 1]
    hi = math.inf if w == edges.size else edges[w]
    return window[0] <= lo and hi <= window[1]


def _check_experiments(sp, what: str, exps, n_q: int) -> None:
    """Raise SplitError when an experiment index of ``sp``'s ``what`` set is outside 0..n_q-1."""
    bad = [j for j in exps or () if not 0 <= j < n_q]
    if bad:
        raise SplitError(f"split {sp.name!r}: {what} experiment(s) {bad} out of range (0-based, {n_q} experiments)")


def _static_split(sp, rows, edges, n_q) -> Split:
    sets = []
    for what, exps, win in (("calibration", sp.cal_experiments, sp.cal_window),
                            ("validation", sp.val_experiments, sp.val_window)):
        _check_experiments(sp, what, exps, n_q)
        r = [k for k, (j, w) in enumerate(rows) if (exps is None or j in exps) and _in_window(win, edges, w)]
        if not r:
            raise SplitError(f"split {sp.name!r}: the {what} set holds no reading")
        sets.append(r)
    return Split(sp.name, sets[0], sets[1], description=sp.description or "dynamic split")


def _gate(settings, name, data: DynamicMeasurements, design, notes):
    """Line 05 pooled per instrument (see the module docstring)."""
    inst = data.by_instrument()
    w = None
    if design is not None and all(isinstance(x, str) for x in design):
        used = {x.split("@")[0] for x in design}
        w = np.array([1.0 if s in used else 0.0 for s in data.sensors])
    chk = normality_check(inst, settings.normality_level, w, settings.normality_correction)
    chk = dataclasses.replace(chk, note=("pooled per instrument over every (experiment, time) reading"
                                         + (f"; {chk.note}" if chk.note else "")))
    if chk.passed:
        return chk
    bad = chk.failing()
    pv = ", ".join(f"{100 * chk.adjusted[chk.sensors.index(s)]:.3g} %" for s in bad)
    msg = (f"normality gate (Algorithm 1, line 05, pooled per instrument) failed for {name}: instrument(s) "
           f"{', '.join(bad)}, Shapiro-Wilk p-value(s) ({chk.correction}-adjusted) {pv} < {100 * chk.level:g} % on "
           "the differences of repeated series over every (experiment, time) reading; acquire new data, or set "
           "normality = 'override' to continue on record")
    if settings.normality == "check":
        raise NormalityError(msg, chk)
    notes.append(f"override: {msg}")
    return dataclasses.replace(chk, overridden=True)


def _label(exps, window) -> str:
    """A set of a split in words: "experiments 1, 2, 3; t < 1.2" (1-based)."""
    e = "all experiments" if exps is None else "experiment(s) " + ", ".join(str(j + 1) for j in exps)
    if window is None:
        return e
    lo, hi = window
    t = f"t >= {lo:g}" if math.isinf(hi) else (f"t < {hi:g}" if math.isinf(lo) else f"{lo:g} <= t < {hi:g}")
    return f"{e}; {t}"


def _mark(t, msg):
    """The split test ``t`` made undecided: no p-value, the reason recorded."""
    nan = math.nan
    return dataclasses.replace(t, ok=False, stage="discretisation", error=msg, alpha_paper=nan,
                               alpha_two_sample=nan, alpha_lr=nan, lr_error=msg)


def _mask(data: DynamicMeasurements, exps, window) -> np.ndarray:
    """(n_q, n_t) True where a reading of ``exps`` (None: all) lies in ``window`` (None: all times)."""
    t = data.times
    m = np.isfinite(t)
    if exps is not None:
        m &= np.isin(np.arange(data.n_q), list(exps))[:, None]
    if window is not None:
        with np.errstate(invalid="ignore"):
            m &= (t >= window[0]) & (t < window[1])
    return m


def _readings(data: DynamicMeasurements, mask: np.ndarray) -> DynamicMeasurements:
    """The campaign restricted to the readings of ``mask`` (experiments without one dropped)."""
    rows = [j for j in range(data.n_q) if mask[j].any()]
    times = [data.times[j][mask[j]] for j in rows]
    n_t = max(len(t) for t in times)
    z = np.full((data.n_M, len(rows), n_t, data.n_S), np.nan)
    for r, j in enumerate(rows):
        z[:, r, :len(times[r])] = data.z[:, j, mask[j]]
    f = data.flat()
    return DynamicMeasurements(data.inputs[rows], times if len({len(t) for t in times}) > 1 else np.array(times), z,
                               sigma=data.sigma, sensors=data.sensors, input_names=f.input_names, series=f.series)


def _fit(model, data, p0, weights, settings, discretisation=None, failed: str = ""):
    """A dynamic fit of a split, or the :class:`FitFailure` of the error it raised (reason
    "<failed><ErrorType>: <message>"; recorded by the split test, never raised)."""
    try:
        return identify(model, data, p0, weights=weights, settings=settings.identify, discretisation=discretisation)
    except (IdentificationError, DataError) as exc:
        return FitFailure.from_error(exc, failed)


def _unbounded(est) -> str:
    """Why the discretisation error of the fit ``est`` is not bounded ("" when it is, or the fit failed)."""
    rec = est.extra.get("discretisation") if not isinstance(est, FitFailure) else None
    return "" if rec is None or rec.bounded else rec.reason or "not bounded"


def _split_fits(model, data, splits, p0, *, weights, settings, ds):
    """(fits [(cal, val)], pooled {points: fit}, unbounded {split: reason}) of every split."""
    fits, pooled, unbounded = [], {}, {}
    for sp, st in splits:
        masks = [_mask(data, sp.cal_experiments, sp.cal_window), _mask(data, sp.val_experiments, sp.val_window)]
        pair = tuple(_fit(model, _readings(data, mk), p0, weights, settings, discretisation=ds) for mk in masks)
        fits.append(pair)
        key = st.pooled_points(data.n_M)
        if key not in pooled:
            pooled[key] = _fit(model, _readings(data, masks[0] | masks[1]), p0, weights, settings, discretisation=ds,
                               failed="pooled fit failed: ")
        why = [f"{what} fit: {_unbounded(e)}" for what, e in zip(("calibration", "validation", "pooled"),
                                                               pair + (pooled[key],)) if _unbounded(e)]
        if why:
            unbounded[sp.name] = "discretisation error not bounded (" + "; ".join(why) + ")"
    return fits, pooled, unbounded


def _as_dynamic(sp) -> DynamicSplit:
    if isinstance(sp, Split):           # a split of the experiments
        if sp.cal_series is not None or sp.val_series is not None:
            raise SplitError(f"split {sp.name!r}: splits of series are not supported on dynamic data")
        return DynamicSplit(sp.name, sp.cal_inputs, sp.val_inputs, description=sp.description)
    if not isinstance(sp, DynamicSplit):
        raise TypeError(f"splits: expected Split or DynamicSplit objects, got {type(sp).__name__}")
    return sp


def _weights(model, design):
    """Instrument weights (n_S,) from instrument names (None: every instrument)."""
    if design is None:
        return None
    if not all(isinstance(x, str) for x in design):
        raise DataError("design: a dynamic model takes instrument names (each measured at every sampling time)")
    unknown = [x for x in design if x not in model.sensors]
    if unknown:
        raise DataError(f"design: unknown instrument(s) {unknown}; the model has {list(model.sensors)}")
    return np.array([1.0 if s in design else 0.0 for s in model.sensors])


def detect_dynamic(model, measurements, splits, p0, *, settings, design=None, design_how=None, progress=None,
                   discretisation: DiscretisationSettings | None = None):
    """Algorithm 1 on dynamic models and their time series (see the module docstring); the arguments
    are those of :func:`identification.studies.detect.detect` (``design``: instrument names, each measured at
    every sampling time); splits are :class:`DynamicSplit` or :class:`Split` (by experiment);
    ``discretisation`` the error control of every fit (default :class:`DiscretisationSettings`)."""
    models = dict(model) if isinstance(model, Mapping) else {model.name: model}
    names = tuple(models)
    splits = tuple(_as_dynamic(sp) for sp in ((splits,) if isinstance(splits, (Split, DynamicSplit)) else splits))
    if not splits:
        raise SplitError("splits: at least one split (test scenario) is needed")
    if len({sp.name for sp in splits}) != len(splits):
        raise SplitError(f"splits: names must be unique, got {[sp.name for sp in splits]}")
    edges = _windows(splits)
    notes, normal, tests, designs, static = [], [], [], [], ()
    for n in names:
        m = models[n]
        data = measurements[n] if isinstance(measurements, Mapping) else measurements
        if not isinstance(data, DynamicMeasurements):
            raise TypeError(f"measurements[{n!r}]: a dynamic model needs identification.DynamicMeasurements, "
                            f"got {type(data).__name__}")
        w = _weights(m, design)
        designs.append((n, tuple(s for k, s in enumerate(m.sensors) if w is None or w[k] > 0),
                        design_how or ("instruments given" if design is not None else "all instruments")))
        normal.append((n, _gate(settings, n, data, design, notes)))
        rows, flat = _expanded(data, edges)
        static = tuple(_static_split(sp, rows, edges, data.n_q) for sp in splits)
        p_start = p0[n] if isinstance(p0, Mapping) else p0
        whole = identify(m, data, p_start, weights=w, settings=settings.identify, discretisation=discretisation)
        fits, pooled, unbounded = _split_fits(m, data, tuple(zip(splits, static)), whole.p, weights=w,
                                              settings=settings, ds=discretisation)
        res = run_split_tests(whole.model, flat, static, whole.p, settings=settings, model_name=n,
                              curvature=True, fits=fits, pooled=pooled)
        labels = {sp.name: (_label(sp.cal_experiments, sp.cal_window), _label(sp.val_experiments, sp.val_window))
                  for sp in splits}
        res = [dataclasses.replace(t, cal_label=labels[t.split][0], val_label=labels[t.split][1]) for t in res]
        tests += [_mark(t, unbounded[t.split]) if t.split in unbounded else t for t in res]
        rec = whole.extra["discretisation"]
        notes.append(f"{n}: every split's fits by Radau IIA collocation with discretisation error control "
                     f"(whole campaign: {rec.n_elements} elements, {100 * rec.error_sigma:.2g} % of sigma); the "
                     "normality gate is pooled per instrument")
    primary, all_dec = model_decisions(tuple(tests), names, settings)
    return DetectionResult(settings=settings, models=names, splits=static, tests=tuple(tests), decisions=primary,
                           all_decisions=all_dec, normality=tuple(normal), design=tuple(designs), notes=tuple(notes))
