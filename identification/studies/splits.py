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

Constructors: :func:`splits_from_scenarios` (a model's named scenario table, e.g. the
paper's four press scenarios :func:`models.press.press_scenario_rows`), :func:`random_splits`
(Monte Carlo cross-validation), :func:`input_range_split` (by the magnitude of an input),
:func:`series_split` (series against series), :func:`time_window_split` /
:func:`early_late_split` (by sampling time) and :class:`Split` itself for user-defined
index sets.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Sequence

import numpy as np


__all__ = ["Split", "SplitError", "splits_from_scenarios", "random_splits", "input_range_split", "series_split",
           "time_window_split", "early_late_split"]


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


@dataclass(frozen=True)
class Split:
    """One calibration / validation split (immutable, validated on construction).

    Parameters
    ----------
    name : str
        Label used in tables and error messages.
    cal_inputs, val_inputs : sequence of int
        0-based input (load) indices of the calibration and validation sets.
    cal_series, val_series : sequence of int or None
        0-based series indices (None: every series of the campaign).
    description : str
        Free text for reports.
    cal_sensors, val_sensors : sequence of int or None
        0-based sensor (column) indices of each set (None: every sensor); on the flat data of a
        dynamic model a column is one (sensor, sampling time) pair.

    Raises
    ------
    SplitError
        Empty set, repeated or negative index, or a value (series, input, sensor) in both sets.
    """

    name: str
    cal_inputs: tuple
    val_inputs: tuple
    cal_series: tuple | None = None
    val_series: tuple | None = None
    description: str = ""
    cal_sensors: tuple | None = None
    val_sensors: tuple | None = None

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.strip():
            raise SplitError(f"name: a split needs a non-empty name, got {self.name!r}")
        n = self.name
        object.__setattr__(self, "cal_inputs", _indices(n, "cal_inputs (calibration inputs)", self.cal_inputs, False))
        object.__setattr__(self, "val_inputs", _indices(n, "val_inputs (validation inputs)", self.val_inputs, False))
        object.__setattr__(self, "cal_series", _indices(n, "cal_series (calibration series)", self.cal_series, True))
        object.__setattr__(self, "val_series", _indices(n, "val_series (validation series)", self.val_series, True))
        object.__setattr__(self, "cal_sensors", _indices(n, "cal_sensors (calibration sensors)", self.cal_sensors, True))
        object.__setattr__(self, "val_sensors", _indices(n, "val_sensors (validation sensors)", self.val_sensors, True))
        common_q = sorted(set(self.cal_inputs) & set(self.val_inputs))
        if self.cal_series is None or self.val_series is None:
            common_s = "all"
        else:
            common_s = sorted(set(self.cal_series) & set(self.val_series))
        if self.cal_sensors is None or self.val_sensors is None:
            common_k = "all"
        else:
            common_k = sorted(set(self.cal_sensors) & set(self.val_sensors))
        if common_q and common_s and common_k:
            raise SplitError(f"split {n!r}: calibration and validation overlap: inputs {common_q} appear in both "
                             f"for series {common_s} and sensors {common_k}; a value may belong to one set only")

    # ------------------------------------------------------------------ checks against a campaign
    def check(self, n_q: int, n_M: int, n_p: int | None = None, n_sensors: int = 1) -> None:
        """Raise :class:`SplitError` when the split does not fit a campaign of n_q inputs and n_M series.

        With ``n_p`` given, each set must hold at least n_p values (points x sensors): fewer
        values than parameters cannot identify the model.
        """
        for what, idx, n in (("cal_inputs", self.cal_inputs, n_q), ("val_inputs", self.val_inputs, n_q),
                             ("cal_series", self.cal_series, n_M), ("val_series", self.val_series, n_M)):
            if idx is not None and max(idx) >= n:
                raise SplitError(f"split {self.name!r}: {what} index {max(idx)} is out of range for a campaign "
                                 f"with {n} {'inputs' if 'inputs' in what else 'series'} (0-based)")
        if n_p is not None:
            for what, qi, si, ki in (("calibration", self.cal_inputs, self.cal_series, self.cal_sensors),
                                     ("validation", self.val_inputs, self.val_series, self.val_sensors)):
                n_pts = len(qi) * (n_M if si is None else len(si))
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

    def value_mask(self, n_M: int, n_q: int, n_S: int, which: str) -> np.ndarray:
        """Boolean (n_M, n_q, n_S): the values of the ``which`` ("calibration" or "validation") set."""
        qi, si, ki = ((self.cal_inputs, self.cal_series, self.cal_sensors) if which == "calibration"
                      else (self.val_inputs, self.val_series, self.val_sensors))
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
        sub = data.subset(inputs=list(self.cal_inputs), series=None if self.cal_series is None else list(self.cal_series))
        return self._restricted(sub, "calibration")

    def validation(self, data):
        """The validation subset of a :class:`Measurements` (values of other sensors missing)."""
        sub = data.subset(inputs=list(self.val_inputs), series=None if self.val_series is None else list(self.val_series))
        return self._restricted(sub, "validation")

    def pooled_points(self, n_M: int) -> tuple:
        """The sorted (input, series) pairs of calibration and validation together (0-based)."""
        pts = set()
        for qi, si in ((self.cal_inputs, self.cal_series), (self.val_inputs, self.val_series)):
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
        def one(qi, si, ki):
            s = _fmt(qi, one_based)
            s = s if si is None else f"{s} [series {_fmt(si, one_based, '')}]"
            return s if ki is None else f"{s} [sensors {_fmt(ki, one_based, 's')}]"
        return (one(self.cal_inputs, self.cal_series, self.cal_sensors),
                one(self.val_inputs, self.val_series, self.val_sensors))

    def swapped(self) -> "Split":
        """The same split with calibration and validation exchanged."""
        return Split(f"{self.name} (swapped)", self.val_inputs, self.cal_inputs, cal_series=self.val_series,
                     val_series=self.cal_series, description=self.description, cal_sensors=self.val_sensors,
                     val_sensors=self.cal_sensors)

    def to_dict(self) -> dict:
        """The split as a dict of its fields (``Split(**d)`` rebuilds it; JSON-safe: tuples as lists);
        ``cal_sensors`` / ``val_sensors`` are the 0-based sensor columns of each set (None: all), e.g. the
        (sensor, time) columns of a split by sampling time."""
        def lst(v):
            return None if v is None else [int(x) for x in v]
        return dict(name=self.name, cal_inputs=lst(self.cal_inputs), val_inputs=lst(self.val_inputs),
                    cal_series=lst(self.cal_series), val_series=lst(self.val_series), description=self.description,
                    cal_sensors=lst(self.cal_sensors), val_sensors=lst(self.val_sensors))


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


def early_late_split(pairs, n_q: int, t_split: float | None = None, inputs: Sequence[int] | None = None,
                     series: Sequence[int] | None = None, name: str | None = None) -> Split:
    """Calibrate on the early sampling times t <= ``t_split``, validate on the late ones t > t_split.

    ``t_split`` defaults to the median of the distinct sampling times (about half of the
    times in each set).

    A :class:`Split` of the columns of the flat data (tests on the collocated model ``est.model``);
    for :func:`identification.studies.detect` on the DynamicModel itself (a fit per set with its own
    discretisation control) use :func:`identification.studies.dynamic_detect.early_late_dynamic_split`."""
    t = _pair_times(pairs)
    times = np.unique(t)
    if times.size < 2:
        raise SplitError("pairs: an early / late split needs at least two sampling times")
    cut = float(times[(times.size - 1) // 2]) if t_split is None else float(t_split)
    late = times[times > cut]
    if late.size == 0 or not np.any(times <= cut):
        raise SplitError(f"t_split: {cut:g} leaves the {'late' if late.size == 0 else 'early'} set empty; the "
                         f"sampling times are {times.tolist()}")
    return time_window_split(pairs, n_q, (float(times[0]), cut), (float(late[0]), float(times[-1])), inputs=inputs,
                             series=series, name=name or f"early t <= {cut:g} vs late t > {cut:g}")
