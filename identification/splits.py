r"""Calibration / validation splits of a measurement campaign (Algorithm 1, line 06).

A split divides the data points (input j, series i) of a campaign z (n_M x n_q x n_S)
into a calibration set and a validation set,

.. math::

    \mathcal{S}_c = Q_c \times M_c, \qquad \mathcal{S}_v = Q_v \times M_v, \qquad
    \mathcal{S}_c \cap \mathcal{S}_v = \emptyset,

with Q the input (load) indices and M the series indices; every sensor of a selected
point belongs to the set.  Indices are **0-based** (the paper's loads q^d_1..q^d_29 are
indices 0..28 here).  ``series=None`` means "all series of the campaign".

Constructors: :func:`splits_from_scenarios` (a model's named scenario table, e.g. the
paper's four press scenarios :func:`models.press.press_scenario_rows`), :func:`random_splits`
(Monte Carlo cross-validation), :func:`input_range_split` (by the magnitude of an input),
:func:`series_split` (series against series) and :class:`Split` itself for user-defined
index sets.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Sequence

import numpy as np


__all__ = ["Split", "SplitError", "splits_from_scenarios", "random_splits", "input_range_split", "series_split"]


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

    Raises
    ------
    SplitError
        Empty set, repeated or negative index, or a data point (input, series) in both sets.
    """

    name: str
    cal_inputs: tuple
    val_inputs: tuple
    cal_series: tuple | None = None
    val_series: tuple | None = None
    description: str = ""

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.strip():
            raise SplitError(f"name: a split needs a non-empty name, got {self.name!r}")
        n = self.name
        object.__setattr__(self, "cal_inputs", _indices(n, "cal_inputs (calibration inputs)", self.cal_inputs, False))
        object.__setattr__(self, "val_inputs", _indices(n, "val_inputs (validation inputs)", self.val_inputs, False))
        object.__setattr__(self, "cal_series", _indices(n, "cal_series (calibration series)", self.cal_series, True))
        object.__setattr__(self, "val_series", _indices(n, "val_series (validation series)", self.val_series, True))
        common_q = sorted(set(self.cal_inputs) & set(self.val_inputs))
        if self.cal_series is None or self.val_series is None:
            common_s = "all" if (self.cal_series is None or self.val_series is None) else ()
        else:
            common_s = sorted(set(self.cal_series) & set(self.val_series))
        if common_q and common_s:
            raise SplitError(f"split {n!r}: calibration and validation overlap: inputs {common_q} appear in both "
                             f"for series {common_s}; a data point may belong to one set only")

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
            for what, qi, si in (("calibration", self.cal_inputs, self.cal_series),
                                 ("validation", self.val_inputs, self.val_series)):
                n_pts = len(qi) * (n_M if si is None else len(si))
                if n_pts * n_sensors < n_p:
                    raise SplitError(f"split {self.name!r}: the {what} set has {n_pts} points x {n_sensors} "
                                     f"sensor(s) = {n_pts * n_sensors} values for {n_p} parameters; it needs at "
                                     "least as many values as parameters")

    def calibration(self, data):
        """The calibration subset of a :class:`Measurements`."""
        return data.subset(inputs=list(self.cal_inputs), series=None if self.cal_series is None else list(self.cal_series))

    def validation(self, data):
        """The validation subset of a :class:`Measurements`."""
        return data.subset(inputs=list(self.val_inputs), series=None if self.val_series is None else list(self.val_series))

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
        z = np.full((len(series), len(qs), data.n_S), np.nan)
        for j, i in pts:
            z[series.index(i), qs.index(j)] = data.z[i, j]
        sub = data.subset(inputs=qs, series=series)
        return sub.with_z(z)

    def label(self, one_based: bool = True) -> tuple[str, str]:
        """Short texts of the calibration and validation sets (1-based like the paper by default)."""
        def one(qi, si):
            s = _fmt(qi, one_based)
            return s if si is None else f"{s} [series {_fmt(si, one_based, '')}]"
        return one(self.cal_inputs, self.cal_series), one(self.val_inputs, self.val_series)

    def swapped(self) -> "Split":
        """The same split with calibration and validation exchanged."""
        return Split(f"{self.name} (swapped)", self.val_inputs, self.cal_inputs, self.val_series, self.cal_series,
                     self.description)


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
        sp = Split(name, rows[0], rows[1], s, s, rows[2] if len(rows) == 3 else "")
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
        out.append(Split(f"{name} {r + 1}", sorted(perm[:k]), sorted(perm[k:]), s, s,
                         f"random partition {r + 1} (seed {seed})"))
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
    return Split(label, low, high, s, s, f"calibrate on small, validate on large input {column} magnitudes")


def series_split(n_q: int, cal_series: Sequence[int], val_series: Sequence[int], inputs: Sequence[int] | None = None,
                 name: str | None = None) -> Split:
    """Calibrate on some series and validate on others, at the same inputs (default all)."""
    qi = list(range(int(n_q))) if inputs is None else list(inputs)
    label = name or f"series {[i + 1 for i in cal_series]} vs {[i + 1 for i in val_series]}"
    return Split(label, qi, qi, list(cal_series), list(val_series), "repeatability: series against series")
