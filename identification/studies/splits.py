r"""Calibration / validation splits of a measurement campaign (Algorithm 1, line 06).

A split divides the data points (input j, series i) of a campaign z (n_M x n_q x n_S)
into a calibration set and a validation set,

.. math::

    \mathcal{S}_c = Q_c \times M_c, \qquad \mathcal{S}_v = Q_v \times M_v, \qquad
    \mathcal{S}_c \cap \mathcal{S}_v = \emptyset,

with Q the input (load) indices and M the series indices; every sensor of a selected
point belongs to the set.  Indices are **0-based** (the paper's loads q^d_1..q^d_29 are
indices 0..28 here).  ``series=None`` means "all series of the campaign".

A split may also divide the sensors (``cal_sensors`` / ``val_sensors``: column indices of
the campaign's sensors); a value (series i, input j, sensor k) then belongs to a set when i, j
and k all do, the other values of the subset being missing (NaN).  On the flat data of a dynamic
model (columns ``sensor@time``) this expresses a split over sampling times:
:func:`time_window_split` (calibrate on one time window, validate on another) and
:func:`early_late_split` (early against late sampling times).

On a campaign of time series (:class:`identification.DynamicMeasurements`) a split may also
select readings by time: ``cal_window`` / ``val_window`` are half-open windows [t_lo, t_hi)
(a reading at time t belongs to the set when t_lo <= t < t_hi; None: every time), and the rows
are the experiments (None: every experiment).  Such a split is tested on the dynamic model itself
(:func:`identification.studies.detect.detect`, each fit with its own discretisation control;
:func:`window_rows`, :func:`reading_mask`, :func:`readings`) or, as a split of the (sensor, time)
columns, on the collocated model (:func:`flat_split`).  :func:`time_window_splits` (t < e against
t >= e) and :func:`early_late_dynamic_split` build them.

**One early/late rule** (:func:`early_late_cut`): with t_(0) < ... < t_(n-1) the distinct sampling
times, the cut is t_c = t_(n // 2) and the early readings are those at t < t_c, the late ones
those at t >= t_c (the half-open windows (-inf, t_c) and [t_c, inf)): for an odd n the middle
time is late.  :func:`early_late_split` (columns of the flat data) and
:func:`early_late_dynamic_split` (windows of the time series) both use it, so that the same study
is split the same way on either path, and an early/late split is the time window split at t_c
(``time_windows = [t_c]``).  Until issue 28 ``early_late_split`` cut at t <= t_((n-1) // 2) (the
same partition for an even n, the middle time early for an odd n; a given ``t_split`` itself was
early, now it is late).  What changed, measured: the shipped studies (configs/*.toml) not at all
(the press has no sampling times; reactor and oscillator split early/late with
``early_late_dynamic_split``, already this rule: detect identical, bench/detect_unchanged.py); the
tests splitting 5 times with ``early_late_split`` (tests/identification/studies/
test_dynamic_unchanged.py: early {0.4, 0.8} h instead of {0.4, 0.8, 1.2} h; e.g. the reactor's
alpha_LR 81.8 % -> 95.5 %, the wrong rate law's LR 1445 -> 1827, every assertion still holds) and
the split names ("early t < 1.5 vs late t >= 1.5" instead of "early t <= 1 vs late t > 1").

Constructors: :func:`splits_from_scenarios` (a model's named scenario table, e.g. the
paper's four press scenarios :func:`models.press.press_scenario_rows`), :func:`random_splits`
(Monte Carlo cross-validation), :func:`input_range_split` (by the magnitude of an input),
:func:`series_split` (series against series), :func:`time_window_split` /
:func:`early_late_split` (by sampling time, columns of the flat data), :func:`time_window_splits` /
:func:`early_late_dynamic_split` (by sampling time, windows of a time series) and :class:`Split`
itself for user-defined index sets.
"""
from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from identification.fit.dynamic_data import DynamicMeasurements
from identification.fit.measurements import Measurements

__all__ = ["Split", "SplitError", "splits_from_scenarios", "random_splits", "input_range_split", "series_split",
           "time_window_split", "early_late_split", "early_late_cut", "time_window_splits", "early_late_dynamic_split",
           "flat_split", "window_rows", "reading_mask", "readings", "check_experiments", "window_text"]


class SplitError(ValueError):
    """A split is malformed (empty or overlapping sets, bad index, too few points)."""


def _indices(split_name: str, what: str, idx, allow_none: bool) -> tuple | None:
    if idx is None:
        if allow_none:
            return None
        raise SplitError(f"split {split_name!r}: {what} must be given")
    if isinstance(idx, (str, bytes)):
        raise SplitError(f"split {split_name!r}: {what} must be integer indices, got {idx!r}")
    try:
        arr = np.asarray(list(idx))
    except TypeError:
        raise SplitError(f"split {split_name!r}: {what} must be a sequence of integer indices, got {idx!r}") from None
    if arr.size == 0:
        raise SplitError(f"split {split_name!r}: {what} is empty")
    if arr.dtype == bool or not np.issubdtype(arr.dtype, np.integer):
        if np.issubdtype(arr.dtype, np.floating) and np.all(np.isfinite(arr)) and np.all(arr == np.round(arr)):
            arr = arr.astype(int)
        else:
            raise SplitError(f"split {split_name!r}: {what} must be integer indices, got {arr.tolist()}")
    if arr.ndim != 1:
        raise SplitError(f"split {split_name!r}: {what} must be a flat list of indices, got shape {arr.shape}")
    if np.any(arr < 0):
        raise SplitError(f"split {split_name!r}: {what} has a negative index {int(arr.min())} "
                         "(indices are 0-based and non-negative)")
    uniq, counts = np.unique(arr, return_counts=True)
    if np.any(counts > 1):
        raise SplitError(f"split {split_name!r}: {what} lists index {int(uniq[counts > 1][0])} twice")
    return tuple(int(v) for v in arr)


def _fmt(idx, one_based: bool = True, prefix: str = "q") -> str:
    if idx is None:
        return "all"
    v = [i + 1 if one_based else i for i in idx]
    if len(v) <= 4:
        return ",".join(f"{prefix}{i}" for i in v)
    steps = np.diff(v)
    if np.all(steps == steps[0]):
        return f"{prefix}{v[0]},{prefix}{v[1]}..{prefix}{v[-1]}" if steps[0] != 1 else f"{prefix}{v[0]}..{prefix}{v[-1]}"
    return ",".join(f"{prefix}{i}" for i in v[:3]) + f",..,{prefix}{v[-1]} ({len(v)})"


def _window(split_name: str, what: str, w) -> tuple | None:
    """A time window as (lo, hi) floats with lo < hi (None: every time), else SplitError."""
    if w is None:
        return None
    try:
        lo, hi = (float(v) for v in w)
    except (TypeError, ValueError):
        raise SplitError(f"split {split_name!r}: {what} must be a time window (t_lo, t_hi), got {w!r}") from None
    if not lo < hi:
        raise SplitError(f"split {split_name!r}: {what} {[lo, hi]} is empty (expected lo < hi)")
    return lo, hi


def window_text(window) -> str:
    """A half-open window [lo, hi) in words: "t < 1.2", "t >= 1.2", "0.5 <= t < 1.2" ("" for None)."""
    if window is None:
        return ""
    lo, hi = window
    if math.isinf(hi):
        return f"t >= {lo:g}"
    return f"t < {hi:g}" if math.isinf(lo) else f"{lo:g} <= t < {hi:g}"


def _common(a, b):
    """The indices in both a and b ("all" when either is None: every index), sorted."""
    return "all" if a is None or b is None else sorted(set(a) & set(b))


@dataclass(frozen=True)
class Split:
    """One calibration / validation split (immutable, validated on construction).

    A value (series i, row j, sensor k, at time t for a time series) belongs to the calibration set
    when i, j, k are among its series, rows and sensors and t_lo <= t < t_hi for its window, likewise
    validation; no value may belong to both.

    Parameters
    ----------
    name : str
        Label used in tables and error messages.
    cal_inputs, val_inputs : sequence of int or None
        0-based input rows (the experiments of a time series) of the calibration and validation sets;
        None (every row) only for a split with a time window.
    cal_series, val_series : sequence of int or None
        0-based series indices (None: every series of the campaign).
    description : str
        Free text for reports.
    cal_sensors, val_sensors : sequence of int or None
        0-based sensor (column) indices of each set (None: every sensor); on the flat data of a
        dynamic model a column is one (sensor, sampling time) pair.
    cal_window, val_window : (float, float) or None
        Half-open time windows [t_lo, t_hi) of the readings of each set (model time unit; +-inf
        allowed; None: every time), for campaigns of time series only.

    Raises
    ------
    SplitError
        Empty set or window, repeated or negative index, or a value (series, input, sensor, time) in
        both sets.
    """

    name: str
    cal_inputs: tuple | None
    val_inputs: tuple | None
    cal_series: tuple | None = None
    val_series: tuple | None = None
    description: str = ""
    cal_sensors: tuple | None = None
    val_sensors: tuple | None = None
    cal_window: tuple | None = None
    val_window: tuple | None = None

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.strip():
            raise SplitError(f"name: a split needs a non-empty name, got {self.name!r}")
        n = self.name
        object.__setattr__(self, "cal_window", _window(n, "cal_window", self.cal_window))
        object.__setattr__(self, "val_window", _window(n, "val_window", self.val_window))
        timed = self.timed
        object.__setattr__(self, "cal_inputs", _indices(n, "cal_inputs (calibration inputs)", self.cal_inputs, timed))
        object.__setattr__(self, "val_inputs", _indices(n, "val_inputs (validation inputs)", self.val_inputs, timed))
        object.__setattr__(self, "cal_series", _indices(n, "cal_series (calibration series)", self.cal_series, True))
        object.__setattr__(self, "val_series", _indices(n, "val_series (validation series)", self.val_series, True))
        object.__setattr__(self, "cal_sensors", _indices(n, "cal_sensors (calibration sensors)", self.cal_sensors, True))
        object.__setattr__(self, "val_sensors", _indices(n, "val_sensors (validation sensors)", self.val_sensors, True))
        if timed and (self.cal_sensors is not None or self.val_sensors is not None):
            raise SplitError(f"split {n!r}: a split by time window takes every instrument's readings; choose the "
                             "instruments with the design, or split the (sensor, time) columns with flat_split")
        common_q = _common(self.cal_inputs, self.val_inputs)
        common_s = _common(self.cal_series, self.val_series)
        common_k = _common(self.cal_sensors, self.val_sensors)
        (clo, chi), (vlo, vhi) = (w or (-math.inf, math.inf) for w in (self.cal_window, self.val_window))
        if common_q and common_s and common_k and max(clo, vlo) < min(chi, vhi):
            times = f" and times {window_text((max(clo, vlo), min(chi, vhi)))}" if timed else ""
            raise SplitError(f"split {n!r}: calibration and validation overlap: inputs {common_q} appear in both "
                             f"for series {common_s} and sensors {common_k}{times}; a value may belong to one set "
                             "only")

    @property
    def timed(self) -> bool:
        """Whether a set selects readings by time window (a split of time series)."""
        return self.cal_window is not None or self.val_window is not None

    @property
    def cal_experiments(self):
        """Deprecated (issue 28): ``cal_inputs`` (the experiments of a time series)."""
        warnings.warn("Split.cal_experiments is deprecated; use Split.cal_inputs", DeprecationWarning, stacklevel=2)
        return self.cal_inputs

    @property
    def val_experiments(self):
        """Deprecated (issue 28): ``val_inputs`` (the experiments of a time series)."""
        warnings.warn("Split.val_experiments is deprecated; use Split.val_inputs", DeprecationWarning, stacklevel=2)
        return self.val_inputs

    def edges(self) -> set:
        """The finite window edges of this split (times)."""
        return {v for w in (self.cal_window, self.val_window) if w is not None for v in w if math.isfinite(v)}

    # ------------------------------------------------------------------ checks against a campaign
    def check(self, n_q: int, n_M: int, n_p: int | None = None, n_sensors: int = 1) -> None:
        """Raise :class:`SplitError` when the split does not fit a campaign of n_q inputs and n_M series.

        With ``n_p`` given, each set must hold at least n_p values (points x sensors): fewer
        values than parameters cannot identify the model (rows None count n_q; a time window is
        not counted).
        """
        for what, idx, n in (("cal_inputs", self.cal_inputs, n_q), ("val_inputs", self.val_inputs, n_q),
                             ("cal_series", self.cal_series, n_M), ("val_series", self.val_series, n_M)):
            if idx is not None and max(idx) >= n:
                raise SplitError(f"split {self.name!r}: {what} index {max(idx)} is out of range for a campaign "
                                 f"with {n} {'inputs' if 'inputs' in what else 'series'} (0-based)")
        if n_p is not None:
            for what, qi, si, ki in (("calibration", self.cal_inputs, self.cal_series, self.cal_sensors),
                                     ("validation", self.val_inputs, self.val_series, self.val_sensors)):
                n_pts = (n_q if qi is None else len(qi)) * (n_M if si is None else len(si))
                n_k = n_sensors if ki is None else min(n_sensors, len(ki))
                if n_pts * n_k < n_p:
                    raise SplitError(f"split {self.name!r}: the {what} set has {n_pts} points x {n_k} "
                                     f"sensor(s) = {n_pts * n_k} values for {n_p} parameters; it needs at "
                                     "least as many values as parameters")

    def check_sensors(self, n_S: int) -> None:
        """Raise :class:`SplitError` when a sensor index is out of range for a campaign of n_S sensors."""
        for what, idx in (("cal_sensors", self.cal_sensors), ("val_sensors", self.val_sensors)):
            if idx is not None and max(idx) >= n_S:
                raise SplitError(f"split {self.name!r}: {what} index {max(idx)} is out of range for a campaign "
                                 f"with {n_S} sensors (0-based columns)")

    def _rows(self, which: str) -> tuple:
        """(rows, series, sensors) of the ``which`` set of a split of rows (SplitError for a split by time)."""
        if self.timed:
            raise SplitError(f"split {self.name!r} selects readings by time window; on the flat data of a time "
                             "series take its (sensor, time) columns with identification.studies.splits.flat_split")
        if which == "calibration":
            return self.cal_inputs, self.cal_series, self.cal_sensors
        return self.val_inputs, self.val_series, self.val_sensors

    def value_mask(self, n_M: int, n_q: int, n_S: int, which: str) -> np.ndarray:
        """Boolean (n_M, n_q, n_S): the values of the ``which`` ("calibration" or "validation") set."""
        qi, si, ki = self._rows(which)
        self.check_sensors(n_S)
        m = np.zeros((n_M, n_q, n_S), bool)
        m[np.ix_(range(n_M) if si is None else list(si), list(qi), range(n_S) if ki is None else list(ki))] = True
        return m

    def sensors_of(self, which: str) -> tuple | None:
        """The sensor indices of the ``which`` set (None: all)."""
        return self.cal_sensors if which == "calibration" else self.val_sensors

    def _restricted(self, sub, which: str):
        ki = self.sensors_of(which)
        if ki is None:
            return sub
        self.check_sensors(sub.n_S)
        z = np.array(sub.z, float, copy=True)
        z[:, :, [k for k in range(sub.n_S) if k not in set(ki)]] = np.nan
        return sub.with_z(z, allow_empty_sensors=True)

    def calibration(self, data):
        """The calibration subset of a :class:`Measurements` (values of other sensors missing)."""
        qi, si, _ = self._rows("calibration")
        sub = data.subset(inputs=list(qi), series=None if si is None else list(si))
        return self._restricted(sub, "calibration")

    def validation(self, data):
        """The validation subset of a :class:`Measurements` (values of other sensors missing)."""
        qi, si, _ = self._rows("validation")
        sub = data.subset(inputs=list(qi), series=None if si is None else list(si))
        return self._restricted(sub, "validation")

    def pooled_points(self, n_M: int) -> tuple:
        """The sorted (input, series) pairs of calibration and validation together (0-based)."""
        pts = set()
        for which in ("calibration", "validation"):
            qi, si, _ = self._rows(which)
            for j in qi:
                for i in (range(n_M) if si is None else si):
                    pts.add((j, i))
        return tuple(sorted(pts))

    def pooled(self, data):
        """Calibration and validation data together, as one campaign (the null hypothesis fit).

        Inputs are those of either set (in campaign order); a value that belongs to neither
        set (possible when the sets use different series) is NaN, i.e. missing, so the
        pooled objective is exactly the sum of the calibration and validation objectives.
        """
        pts = self.pooled_points(data.n_M)
        qs = sorted({j for j, _ in pts})
        series = sorted({i for _, i in pts})
        mask = self.pooled_mask(data.n_M, data.n_q, data.n_S)[np.ix_(series, qs, range(data.n_S))]
        z = np.where(mask, data.z[np.ix_(series, qs, range(data.n_S))], np.nan)
        sub = data.subset(inputs=qs, series=series)
        return sub.with_z(z, allow_empty_sensors=self.cal_sensors is not None or self.val_sensors is not None)

    def pooled_mask(self, n_M: int, n_q: int, n_S: int) -> np.ndarray:
        """Boolean (n_M, n_q, n_S): the values of calibration or validation."""
        return self.value_mask(n_M, n_q, n_S, "calibration") | self.value_mask(n_M, n_q, n_S, "validation")

    def pooled_key(self, n_M: int) -> tuple:
        """A hashable key of the pooled data: splits with equal keys share their pooled fit."""
        pts = self.pooled_points(n_M)
        if self.cal_sensors is None and self.val_sensors is None:
            return pts
        return pts, ("sensors", self.cal_inputs, self.cal_series, self.cal_sensors, self.val_inputs,
                     self.val_series, self.val_sensors)

    def label(self, one_based: bool = True) -> tuple[str, str]:
        """Short texts of the calibration and validation sets (1-based like the paper by default)."""
        def one(qi, si, ki, win):
            s = _fmt(qi, one_based)
            s = s if si is None else f"{s} [series {_fmt(si, one_based, '')}]"
            s = s if ki is None else f"{s} [sensors {_fmt(ki, one_based, 's')}]"
            return s if win is None else f"{s} [{window_text(win)}]"
        return (one(self.cal_inputs, self.cal_series, self.cal_sensors, self.cal_window),
                one(self.val_inputs, self.val_series, self.val_sensors, self.val_window))

    def swapped(self) -> "Split":
        """The same split with calibration and validation exchanged."""
        return Split(f"{self.name} (swapped)", self.val_inputs, self.cal_inputs, cal_series=self.val_series,
                     val_series=self.cal_series, description=self.description, cal_sensors=self.val_sensors,
                     val_sensors=self.cal_sensors, cal_window=self.val_window, val_window=self.cal_window)

    def to_dict(self) -> dict:
        """The split as a dict of its fields (``Split(**d)`` rebuilds it; JSON-safe: tuples as lists);
        ``cal_sensors`` / ``val_sensors`` are the 0-based sensor columns of each set (None: all), e.g. the
        (sensor, time) columns of a split by sampling time; a split by time window (:attr:`timed`) also has
        ``cal_window`` / ``val_window``, the half-open windows [t_lo, t_hi) (None: every time; +-inf edges
        become "inf" / "-inf" in JSON, which ``float`` reads back)."""
        def lst(v):
            return None if v is None else [int(x) for x in v]
        out = dict(name=self.name, cal_inputs=lst(self.cal_inputs), val_inputs=lst(self.val_inputs),
                   cal_series=lst(self.cal_series), val_series=lst(self.val_series), description=self.description,
                   cal_sensors=lst(self.cal_sensors), val_sensors=lst(self.val_sensors))
        if self.timed:
            out.update(cal_window=None if self.cal_window is None else [float(v) for v in self.cal_window],
                       val_window=None if self.val_window is None else [float(v) for v in self.val_window])
        return out


# ---------------------------------------------------------------------------- constructors
def splits_from_scenarios(scenarios, n_q: int, series: Sequence[int] | None = None) -> tuple:
    """Split objects from a scenario table {name: (calibration rows, validation rows[, description])}.

    Rows are 0-based input indices of a campaign of ``n_q`` inputs; the splits keep the
    table's order.  A model declares its scenarios as such a table (e.g.
    :data:`models.press.PRESS_SCENARIOS`), or as a function n_q -> table when the rows depend
    on the campaign length (e.g. :func:`models.press.press_scenario_rows`).

    Parameters
    ----------
    scenarios : mapping or callable
        The table, or a callable ``scenarios(n_q)`` returning it; a ``ValueError`` of the
        callable (a campaign the scenarios do not fit) is raised as :class:`SplitError`.
    n_q : int
        Number of inputs of the campaign.
    series : sequence of int, optional
        Series used by both sets of every split (e.g. held-out series); None = all.

    Raises
    ------
    SplitError
        The table does not fit n_q inputs, or a scenario is malformed (see :class:`Split`).
    """
    n_q = int(n_q)
    if callable(scenarios):
        try:
            scenarios = scenarios(n_q)
        except ValueError as exc:
            raise SplitError(str(exc)) from None
    if not isinstance(scenarios, Mapping) or not scenarios:
        raise SplitError(f"scenarios: expected a non-empty mapping {{name: (cal_rows, val_rows[, description])}}, "
                         f"got {scenarios!r}")
    s = None if series is None else list(series)
    out = []
    for name, rows in scenarios.items():
        if not isinstance(rows, (tuple, list)) or len(rows) not in (2, 3):
            raise SplitError(f"scenarios[{name!r}]: expected (cal_rows, val_rows) or (cal_rows, val_rows, "
                             f"description), got {rows!r}")
        sp = Split(name, rows[0], rows[1], cal_series=s, val_series=s, description=rows[2] if len(rows) == 3 else "")
        top = max(sp.cal_inputs + sp.val_inputs)
        if top >= n_q:
            raise SplitError(f"n_q: scenario {name!r} uses input row {top} but the campaign has {n_q} inputs "
                             "(0-based rows)")
        out.append(sp)
    return tuple(out)


def random_splits(n_q: int, n_splits: int, cal_fraction: float = 0.5, seed=None,
                  series: Sequence[int] | None = None, exclude: Sequence[int] = (), name: str = "random") -> tuple:
    """Monte Carlo cross-validation: ``n_splits`` random partitions of the inputs (seeded).

    Each split draws round(cal_fraction * m) of the m usable inputs (those not in ``exclude``)
    for calibration, without replacement, and puts the rest into validation.
    """
    if not (0.0 < float(cal_fraction) < 1.0):
        raise SplitError(f"cal_fraction must lie in (0, 1), got {cal_fraction}")
    if int(n_splits) < 1:
        raise SplitError(f"n_splits must be at least 1, got {n_splits}")
    usable = np.array([j for j in range(int(n_q)) if j not in set(exclude)])
    if usable.size < 2:
        raise SplitError(f"n_q, exclude: only {usable.size} usable inputs; a random split needs at least 2")
    k = int(round(cal_fraction * usable.size))
    k = min(max(k, 1), usable.size - 1)
    rng = np.random.default_rng(seed)
    out = []
    s = None if series is None else list(series)
    for r in range(int(n_splits)):
        perm = rng.permutation(usable)
        out.append(Split(f"{name} {r + 1}", sorted(perm[:k]), sorted(perm[k:]), cal_series=s, val_series=s,
                         description=f"random partition {r + 1} (seed {seed})"))
    return tuple(out)


def input_range_split(inputs, threshold: float | None = None, column: int = 0, exclude: Sequence[int] = (),
                      series: Sequence[int] | None = None, name: str | None = None) -> Split:
    """Split by the magnitude of one input: calibrate on |q| <= threshold, validate on |q| > threshold.

    ``threshold`` defaults to the median magnitude of the usable inputs (so both sets hold
    about half of the points); the unit is that of the input column.
    """
    q = np.asarray(inputs, float)
    if q.ndim == 1:
        q = q[:, None]
    if not (0 <= int(column) < q.shape[1]):
        raise SplitError(f"column: input column {column} does not exist (inputs have {q.shape[1]} columns)")
    usable = np.array([j for j in range(q.shape[0]) if j not in set(exclude)])
    if usable.size < 2:
        raise SplitError("inputs, exclude: fewer than 2 usable inputs")
    mag = np.abs(q[usable, int(column)])
    thr = float(np.median(mag)) if threshold is None else float(threshold)
    low, high = usable[mag <= thr], usable[mag > thr]
    label = name or f"|q[{column}]| <= {thr:g} vs > {thr:g}"
    if low.size == 0 or high.size == 0:
        raise SplitError(f"split {label!r}: threshold {thr:g} leaves the {'calibration' if low.size == 0 else 'validation'} "
                         "set empty")
    s = None if series is None else list(series)
    return Split(label, low, high, cal_series=s, val_series=s,
                 description=f"calibrate on small, validate on large input {column} magnitudes")


def series_split(n_q: int, cal_series: Sequence[int], val_series: Sequence[int], inputs: Sequence[int] | None = None,
                 name: str | None = None) -> Split:
    """Calibrate on some series and validate on others, at the same inputs (default all)."""
    qi = list(range(int(n_q))) if inputs is None else list(inputs)
    label = name or f"series {[i + 1 for i in cal_series]} vs {[i + 1 for i in val_series]}"
    return Split(label, qi, qi, cal_series=list(cal_series), val_series=list(val_series),
                 description="repeatability: series against series")


def _pair_times(pairs) -> np.ndarray:
    """The sampling time of every (sensor, time) column of a dynamic model's flat data."""
    try:
        t = np.array([float(tp) for _, tp in pairs])
    except (TypeError, ValueError):
        raise SplitError("pairs: expected the (sensor, time) pairs of the flat data (DynamicMeasurements.pairs "
                         "or the collocated model's outputs)") from None
    if t.size == 0:
        raise SplitError("pairs: no (sensor, time) column")
    return t


def time_window_split(pairs, n_q: int, cal_window, val_window, inputs: Sequence[int] | None = None,
                      series: Sequence[int] | None = None, name: str | None = None) -> Split:
    r"""Calibrate on the sampling times in one window, validate on those in another.

    A column k of the flat data of a dynamic model is the pair (sensor, t_k); the calibration
    set is {t_k in [a_c, b_c]}, the validation set {t_k in [a_v, b_v]} (closed windows in the
    model's time unit, which must not share a column), at the inputs (experiments) ``inputs``
    (default all) and the series ``series`` (default all) for both sets.

    Parameters
    ----------
    pairs : sequence of (sensor, time)
        The flat columns in order (``DynamicMeasurements.pairs``).
    n_q : int
        Experiments of the campaign.
    cal_window, val_window : (float, float)
        Time windows (a, b) of the two sets.
    """
    t = _pair_times(pairs)
    sets = []
    for what, win in (("cal_window", cal_window), ("val_window", val_window)):
        try:
            a, b = (float(v) for v in win)
        except (TypeError, ValueError):
            raise SplitError(f"{what}: expected a time window (start, end), got {win!r}") from None
        if not a <= b:
            raise SplitError(f"{what}: the window ({a:g}, {b:g}) ends before it starts")
        k = np.flatnonzero((t >= a) & (t <= b))
        if k.size == 0:
            raise SplitError(f"{what}: no sampling time lies in ({a:g}, {b:g}); the times are "
                             f"{np.unique(t).tolist()}")
        sets.append((k, a, b))
    (kc, ac, bc), (kv, av, bv) = sets
    qi = list(range(int(n_q))) if inputs is None else list(inputs)
    s = None if series is None else list(series)
    label = name or f"t in [{ac:g}, {bc:g}] vs [{av:g}, {bv:g}]"
    return Split(label, qi, qi, cal_series=s, val_series=s,
                 description=f"calibrate on the sampling times in [{ac:g}, {bc:g}], validate on those in "
                 f"[{av:g}, {bv:g}]", cal_sensors=kc, val_sensors=kv)


def early_late_cut(times) -> float:
    """The one early/late rule: t_c = t_(n // 2) of the n distinct sampling times t_(0) < ... < t_(n-1);
    early readings t < t_c, late ones t >= t_c (the half-open windows (-inf, t_c) and [t_c, inf); for an
    odd n the middle time is late).

    Raises
    ------
    SplitError
        Fewer than two distinct sampling times.
    """
    t = np.unique(np.asarray(times, float))
    t = t[np.isfinite(t)]
    if t.size < 2:
        raise SplitError(f"times: an early / late split needs at least two sampling times, got {t.tolist()}")
    return float(t[t.size // 2])


def early_late_split(pairs, n_q: int, t_split: float | None = None, inputs: Sequence[int] | None = None,
                     series: Sequence[int] | None = None, name: str | None = None) -> Split:
    """Calibrate on the early sampling times t < ``t_split``, validate on the late ones t >= t_split.

    ``t_split`` defaults to :func:`early_late_cut` of the sampling times (the distinct time at index
    n // 2: about half of the times in each set, the middle one of an odd count late).

    A :class:`Split` of the columns of the flat data (tests on the collocated model ``est.model``);
    for :func:`identification.studies.detect.detect` on the DynamicModel itself (a fit per set with its
    own discretisation control) use :func:`early_late_dynamic_split`, the same rule as a time window.
    Before issue 28 this function cut at t <= the time at index (n - 1) // 2 (the middle time of an odd
    count early, ``t_split`` itself early)."""
    t = _pair_times(pairs)
    times = np.unique(t)
    cut = early_late_cut(times) if t_split is None else float(t_split)
    early, late = times[times < cut], times[times >= cut]
    if late.size == 0 or early.size == 0:
        raise SplitError(f"t_split: {cut:g} leaves the {'late' if late.size == 0 else 'early'} set empty; the "
                         f"sampling times are {times.tolist()}")
    return time_window_split(pairs, n_q, (float(early[0]), float(early[-1])), (float(late[0]), float(late[-1])),
                             inputs=inputs, series=series, name=name or f"early t < {cut:g} vs late t >= {cut:g}")


# ---------------------------------------------------------------------------- splits of time series
def time_window_splits(edges) -> tuple:
    """One split per edge e: the readings at t < e (calibration) against those at t >= e (validation), of
    every experiment (windows of a campaign of time series)."""
    e = sorted({float(x) for x in edges})
    if not e:
        raise SplitError("time_windows: give at least one edge (a time cutting the experiments)")
    return tuple(Split(f"t < {v:g} vs t >= {v:g}", None, None, cal_window=(-math.inf, v), val_window=(v, math.inf),
                       description="time window") for v in e)


def early_late_dynamic_split(data) -> Split:
    """Early against late: the readings at t < t_c against those at t >= t_c, t_c = :func:`early_late_cut`
    of the campaign's (union of) sampling times, as a split of the time series ``data``
    (:class:`identification.DynamicMeasurements`) for :func:`identification.studies.detect.detect` on the
    DynamicModel (each fit with its own discretisation control).

    The same rule as :func:`early_late_split`, which masks the (sensor, time) columns of the flat data
    for the tests on a collocated model.
    """
    cut = early_late_cut(data.union_times)
    return Split(f"early (t < {cut:g}) vs late", None, None, cal_window=(-math.inf, cut), val_window=(cut, math.inf),
                 description="early vs late")


def flat_split(sp: Split, pairs, n_q: int) -> Split:
    """The split ``sp`` as a split of the flat data of a dynamic model (columns ``pairs`` = (sensor, time),
    rows the ``n_q`` experiments): the calibration columns are the pairs with t in ``cal_window``
    (lo <= t < hi), likewise validation; a split of given rows without a window is returned unchanged.

    Raises
    ------
    SplitError
        A window holds no sampling time, or an experiment index is out of range.
    """
    if not isinstance(sp, Split):
        raise TypeError(f"splits: expected Split objects, got {type(sp).__name__}")
    if not sp.timed:
        return sp
    t = np.array([float(tp) for _, tp in pairs])
    sets = []
    for what, rows, win in (("calibration", sp.cal_inputs, sp.cal_window), ("validation", sp.val_inputs,
                                                                              sp.val_window)):
        check_experiments(sp, what, rows, n_q)
        cols = None if win is None else np.flatnonzero((t >= win[0]) & (t < win[1])).tolist()
        if cols is not None and not cols:
            raise SplitError(f"split {sp.name!r}: the {what} window {list(win)} holds no sampling time; the times "
                             f"are {np.unique(t).tolist()}")
        sets.append((list(range(n_q)) if rows is None else list(rows), cols))
    (qc, kc), (qv, kv) = sets
    return Split(sp.name, qc, qv, sp.cal_series, sp.val_series, description=sp.description or "dynamic split",
                 cal_sensors=kc, val_sensors=kv)


def check_experiments(sp: Split, what: str, rows, n_q: int) -> None:
    """Raise SplitError when an experiment index of ``sp``'s ``what`` set (``rows``) is outside 0..n_q-1."""
    bad = [j for j in rows or () if not 0 <= j < n_q]
    if bad:
        raise SplitError(f"split {sp.name!r}: {what} experiment(s) {bad} out of range (0-based, {n_q} experiments)")


def _in_window(window, edges, w) -> bool:
    if window is None:
        return True
    lo = -math.inf if w == 0 else edges[w - 1]
    hi = math.inf if w == edges.size else edges[w]
    return window[0] <= lo and hi <= window[1]


def window_rows(data, splits) -> tuple:
    """(rows, splits of rows): a campaign of time series as a static one, the splits as splits of its rows.

    Every experiment j is cut into the windows [b_{w-1}, b_w) of the union of the splits' window edges;
    the row (j, w) of the static campaign (:class:`Measurements` over the (sensor, time) columns of
    ``data.flat()``) holds experiment j's readings in window w (the others NaN, i.e. missing) with
    experiment j's inputs, so that a split by experiment, by time window or early against late is a
    split of these rows and the pooled fit of a split is the fit of the readings of both sets.

    Raises
    ------
    SplitError
        A set of a split holds no reading, or an experiment index is out of range.
    """
    edges = np.array(sorted(set().union(*(sp.edges() for sp in splits))))
    flat = data.flat()
    w_pair = np.searchsorted(edges, np.array([t for _, t in data.pairs]), side="right")
    rows, z = [], []
    for j in range(data.n_q):
        for w in range(edges.size + 1):
            zz = np.where((w_pair == w)[None, :], flat.z[:, j, :], np.nan)
            if np.isfinite(zz).any():
                rows.append((j, w))
                z.append(zz)
    out = Measurements(flat.inputs[[j for j, _ in rows]], np.stack(z, axis=1), flat.sigma, sensors=flat.sensors,
                       input_names=flat.input_names, series=flat.series)
    row_splits = []
    for sp in splits:
        sets = []
        for what, exps, win in (("calibration", sp.cal_inputs, sp.cal_window),
                                ("validation", sp.val_inputs, sp.val_window)):
            check_experiments(sp, what, exps, data.n_q)
            r = [k for k, (j, w) in enumerate(rows) if (exps is None or j in exps) and _in_window(win, edges, w)]
            if not r:
                raise SplitError(f"split {sp.name!r}: the {what} set holds no reading")
            sets.append(r)
        row_splits.append(Split(sp.name, sets[0], sets[1], description=sp.description or "dynamic split"))
    return out, tuple(row_splits)


def reading_mask(data, rows, window) -> np.ndarray:
    """(n_q, n_t) True where a reading of the experiments ``rows`` (None: all) of the time series ``data``
    lies in the half-open ``window`` (None: all times)."""
    t = data.times
    m = np.isfinite(t)
    if rows is not None:
        m &= np.isin(np.arange(data.n_q), list(rows))[:, None]
    if window is not None:
        with np.errstate(invalid="ignore"):
            m &= (t >= window[0]) & (t < window[1])
    return m


def readings(data, mask: np.ndarray) -> DynamicMeasurements:
    """The time series ``data`` restricted to the readings of ``mask`` (n_q, n_t) (experiments without one
    dropped)."""
    rows = [j for j in range(data.n_q) if mask[j].any()]
    times = [data.times[j][mask[j]] for j in rows]
    n_t = max(len(t) for t in times)
    z = np.full((data.n_M, len(rows), n_t, data.n_S), np.nan)
    for r, j in enumerate(rows):
        z[:, r, :len(times[r])] = data.z[:, j, mask[j]]
    f = data.flat()
    return DynamicMeasurements(data.inputs[rows], times if len({len(t) for t in times}) > 1 else np.array(times), z,
                               sigma=data.sigma, sensors=data.sensors, input_names=f.input_names, series=f.series)
