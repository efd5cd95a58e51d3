"""Measurement campaigns: n_M series x n_q inputs x n_S sensors, with per-sensor sigma.

The measurement model is z_ijk = h_k(y_j, p*, q_j) + eps_ijk with eps_ijk ~ N(0, sigma_k^2)
independent (the paper's section 2).  NaN marks a missing value; it is excluded
from every sum, never zero-filled.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from identification.errors import DataError

__all__ = ["Measurements", "DataTerms", "data_terms", "group_means", "common_spread"]


def group_means(z: np.ndarray) -> tuple:
    """(counts, zbar) of values z (..., n_M, n_q, n_S) (NaN: missing; a leading stack axis allowed):
    the number of present values per (input, sensor) (float) and their mean over the series, 0 where
    none, each (..., n_q, n_S)."""
    mask = np.isfinite(z)
    counts = mask.sum(axis=-3).astype(float)
    zsum = np.where(mask, z, 0.0).sum(axis=-3)
    return counts, np.where(counts > 0, zsum / np.maximum(counts, 1), 0.0)


def common_spread(zs: np.ndarray) -> float:
    """The objective's common sigma when sigma is unknown: the standard deviation of the values ``zs`` of the
    selected sensors (NaN: missing), else their mean magnitude, else 1 (same unit as z)."""
    if math.isfinite(zs.sum()):         # no missing value: np.std is nanstd's number, 10x faster
        return float(np.std(zs)) or float(np.mean(np.abs(zs))) or 1.0
    return float(np.nanstd(zs)) or float(np.nanmean(np.abs(zs))) or 1.0


@dataclass(frozen=True)
class DataTerms:
    """The data terms of the reduced weighted least-squares objective (see :func:`data_terms`).

    Attributes
    ----------
    counts : ndarray (..., n_q, n_S)   present values n_jk per (input, sensor)
    zbar : ndarray (..., n_q, n_S)     their means over the series (0 where none; unit of z)
    cw : ndarray (..., n_q, n_S)       weighted counts c_jk = n_jk w_k
    const : ndarray (...) or float     within-group scatter Phi_0 (chi^2 / 2 units)
    """

    counts: np.ndarray
    zbar: np.ndarray
    cw: np.ndarray
    const: np.ndarray


def data_terms(z: np.ndarray, w: np.ndarray, sig: np.ndarray) -> DataTerms:
    r"""The data terms of one data set or a stack of them (the one place they are computed).

    .. math::  \Phi(p) = \tfrac12 \sum_{j,k} c_{jk} (\bar z_{jk} - h_{jk}(p))^2 / \sigma_k^2 + \Phi_0,\qquad
               \Phi_0 = \tfrac12 \sum_{i,j,k} w_k (z_{ijk} - \bar z_{jk})^2 / \sigma_k^2

    ``z`` (..., n_M, n_q, n_S) values (NaN: missing), ``w`` (n_S,) sensor weights, ``sig`` (..., n_S)
    the objective's sigmas (unit of z).
    """
    counts, zbar = group_means(z)
    sig = np.asarray(sig, float)
    dev = np.where(np.isfinite(z), z - zbar[..., None, :, :], 0.0)
    const = 0.5 * np.sum(w * dev ** 2 / sig[..., None, None, :] ** 2, axis=(-3, -2, -1))
    return DataTerms(counts, zbar, counts * w, const)


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a


def _index(arg_name: str, idx, n: int) -> np.ndarray:
    """Normalise an index selection (ints, bools, slice, range) to a sorted-unique int array."""
    if isinstance(idx, slice):
        return np.arange(n)[idx]
    arr = np.asarray(list(idx) if not isinstance(idx, np.ndarray) else idx)
    if arr.dtype == bool:
        if arr.shape != (n,):
            raise DataError(f"{arg_name}: a boolean mask must have length {n}, got {arr.shape}")
        return np.flatnonzero(arr)
    if arr.size == 0:
        raise DataError(f"{arg_name}: the selection is empty")
    if not np.issubdtype(arr.dtype, np.integer):
        raise DataError(f"{arg_name}: indices must be integers or a boolean mask, got dtype {arr.dtype}")
    if arr.min() < -n or arr.max() >= n:
        raise DataError(f"{arg_name}: index out of range for {n} entries: {arr.tolist()}")
    arr = np.where(arr < 0, arr + n, arr)
    if len(np.unique(arr)) != len(arr):
        raise DataError(f"{arg_name}: an index appears twice: {arr.tolist()}")
    return arr


class Measurements:
    """An immutable measurement campaign.

    Parameters
    ----------
    inputs : array_like, shape (n_q, d_q)
        Input vectors q_j (a 1-D array is read as d_q = 1); a model without inputs takes
        ``np.zeros((n_q, 0))``: n_q rows of nothing.
    z : array_like, shape (n_M, n_q, n_S)
        Measured values (series x inputs x sensors); NaN marks a missing value.
    sigma : array_like of shape (n_S,), float, or None
        Standard deviation of each sensor (same unit as z).  ``None`` means a common
        unknown sigma estimated from the residuals, s^2 = RSS / (n - n_p).
    sensors : sequence of str, optional
        Sensor names; when given, the estimator checks them against the model's.
    input_names : sequence of str, optional
    series : sequence of str, optional
        Labels of the series (default ``"1"..."n_M"``).
    allow_empty_sensors : bool
        Accept sensors without any finite value (the subsets of a split over sensors, e.g. the
        early times of :func:`identification.studies.splits.early_late_split`); default False: an error.

    Raises
    ------
    DataError
        On any shape mismatch, non-finite input, infinite value, sensor without
        any finite value, or non-positive / non-finite sigma (the message names
        the argument).
    """

    __slots__ = ("inputs", "z", "sigma", "sensors", "input_names", "series", "allow_empty_sensors")

    def __init__(self, inputs, z, sigma=None, sensors: Sequence[str] | None = None,
                 input_names: Sequence[str] | None = None, series: Sequence[str] | None = None,
                 allow_empty_sensors: bool = False):
        try:
            q = np.asarray(inputs, dtype=float)
        except (TypeError, ValueError) as exc:
            raise DataError(f"inputs: not numeric ({exc})") from None
        if q.ndim == 1:
            q = q[:, None]
        if q.ndim != 2 or q.shape[0] == 0:
            raise DataError(f"inputs: expected shape (n_q, d_q) with n_q >= 1 rows (d_q = 0: a model without "
                            f"inputs), got {q.shape}")
        if not np.all(np.isfinite(q)):
            bad = np.argwhere(~np.isfinite(q))[0]
            raise DataError(f"inputs: non-finite value at row {bad[0]}, column {bad[1]}; inputs must be known")
        try:
            zz = np.asarray(z, dtype=float)
        except (TypeError, ValueError) as exc:
            raise DataError(f"z: not numeric ({exc})") from None
        if zz.ndim != 3:
            raise DataError(f"z: expected shape (n_M, n_q, n_S) = (series, inputs, sensors), got {zz.shape}")
        if zz.shape[1] != q.shape[0]:
            raise DataError(f"z: has {zz.shape[1]} inputs along axis 1 but inputs has {q.shape[0]} rows")
        if zz.shape[0] == 0 or zz.shape[2] == 0:
            raise DataError(f"z: needs at least one series and one sensor, got shape {zz.shape}")
        if np.any(np.isinf(zz)):
            bad = np.argwhere(np.isinf(zz))[0]
            raise DataError(f"z: infinite value at series {bad[0]}, input {bad[1]}, sensor {bad[2]}; "
                            "use NaN for a missing value")
        n_S = zz.shape[2]
        names = tuple(sensors) if sensors is not None else tuple(f"s{k + 1}" for k in range(n_S))
        if len(names) != n_S:
            raise DataError(f"sensors: {len(names)} names given but z has {n_S} sensors")
        finite_per_sensor = np.isfinite(zz).reshape(-1, n_S).sum(axis=0)
        for k in range(n_S):
            if finite_per_sensor[k] == 0 and not allow_empty_sensors:
                raise DataError(f"z: sensor {names[k]!r} (index {k}) has no finite value (NaN only); "
                                "drop it or supply data")
        if sigma is not None:
            try:
                s = np.asarray(sigma, dtype=float)
            except (TypeError, ValueError) as exc:
                raise DataError(f"sigma: not numeric ({exc})") from None
            if s.ndim == 0:
                s = np.full(n_S, float(s))
            if s.shape != (n_S,):
                raise DataError(f"sigma: expected {n_S} values (one per sensor), got shape {s.shape}")
            bad = ~(np.isfinite(s) & (s > 0))
            if np.any(bad):
                k = int(np.flatnonzero(bad)[0])
                raise DataError(f"sigma: must be positive and finite for every sensor; sensor {names[k]!r} "
                                f"has {s[k]!r}")
            sig = _readonly(s)
        else:
            sig = None
        in_names = tuple(input_names) if input_names is not None else tuple(f"q{i + 1}" for i in range(q.shape[1]))
        if len(in_names) != q.shape[1]:
            raise DataError(f"input_names: {len(in_names)} names given but inputs has {q.shape[1]} columns")
        ser = tuple(series) if series is not None else tuple(str(i + 1) for i in range(zz.shape[0]))
        if len(ser) != zz.shape[0]:
            raise DataError(f"series: {len(ser)} labels given but z has {zz.shape[0]} series")
        object.__setattr__(self, "inputs", _readonly(q))
        object.__setattr__(self, "z", _readonly(zz))
        object.__setattr__(self, "sigma", sig)
        object.__setattr__(self, "sensors", names)
        object.__setattr__(self, "input_names", in_names)
        object.__setattr__(self, "series", ser)
        object.__setattr__(self, "allow_empty_sensors", bool(allow_empty_sensors))

    def __setattr__(self, name, value):
        raise AttributeError("Measurements is immutable; use subset(), with_sigma() or select()")

    def __reduce__(self):
        """Pickle through the constructor (the immutable slots cannot be set by pickle's default)."""
        return (Measurements, (self.inputs, self.z, self.sigma, self.sensors, self.input_names, self.series,
                               self.allow_empty_sensors))

    # ------------------------------------------------------------------ sizes
    @property
    def n_M(self) -> int:
        return self.z.shape[0]

    @property
    def n_q(self) -> int:
        return self.z.shape[1]

    @property
    def n_S(self) -> int:
        return self.z.shape[2]

    @property
    def d_q(self) -> int:
        return self.inputs.shape[1]

    def mask(self) -> np.ndarray:
        """Boolean array (n_M, n_q, n_S), True where a value is present."""
        return np.isfinite(self.z)

    def counts(self) -> np.ndarray:
        """Number of present values per (input, sensor), shape (n_q, n_S)."""
        return self.mask().sum(axis=0)

    def means(self) -> np.ndarray:
        """Mean over series per (input, sensor) of present values (NaN where none), (n_q, n_S)."""
        c, zbar = group_means(self.z)
        return np.where(c > 0, zbar, np.nan)

    def n_data(self, weights=None) -> int:
        """Number of present values in the sensors with nonzero weight."""
        w = self.sensor_weights(weights)
        return int(self.counts()[:, w > 0].sum())

    def sensor_weights(self, weights=None) -> np.ndarray:
        """Validated sensor weights omega (n_S,), dimensionless: ones for None, else finite and >= 0."""
        if weights is None:
            return np.ones(self.n_S)
        w = np.asarray(weights, dtype=float)
        if w.shape != (self.n_S,):
            raise DataError(f"weights: expected {self.n_S} sensor weights, got shape {w.shape}")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise DataError(f"weights: must be finite and non-negative, got {w.tolist()}")
        return w

    # ------------------------------------------------------------------ new objects
    def subset(self, inputs=None, series=None) -> "Measurements":
        """A new campaign restricted to the given input rows and/or series (for splits)."""
        qi = np.arange(self.n_q) if inputs is None else _index("inputs", inputs, self.n_q)
        si = np.arange(self.n_M) if series is None else _index("series", series, self.n_M)
        if len(qi) == 0:
            raise DataError("inputs: the selection is empty")
        if len(si) == 0:
            raise DataError("series: the selection is empty")
        z = self.z[np.ix_(si, qi, np.arange(self.n_S))]
        return Measurements(self.inputs[qi], z, self.sigma, sensors=self.sensors,
                            input_names=self.input_names, series=[self.series[i] for i in si],
                            allow_empty_sensors=self.allow_empty_sensors)

    def select(self, sensors) -> "Measurements":
        """A new campaign with only the named (or indexed) sensors, in that order."""
        idx = []
        for s in sensors:
            if isinstance(s, str):
                if s not in self.sensors:
                    raise DataError(f"sensors: unknown sensor {s!r}; available: {', '.join(self.sensors)}")
                idx.append(self.sensors.index(s))
            else:
                idx.append(int(s))
        idx = _index("sensors", np.asarray(idx, dtype=int), self.n_S)
        return Measurements(self.inputs, self.z[:, :, idx], None if self.sigma is None else self.sigma[idx],
                            sensors=[self.sensors[i] for i in idx], input_names=self.input_names,
                            series=self.series)

    def with_sigma(self, sigma) -> "Measurements":
        """The same data with other sensor sigmas (``None``: unknown, estimated)."""
        return Measurements(self.inputs, self.z, sigma, sensors=self.sensors,
                            input_names=self.input_names, series=self.series,
                            allow_empty_sensors=self.allow_empty_sensors)

    def with_z(self, z, allow_empty_sensors: bool | None = None) -> "Measurements":
        """The same inputs, sigma and labels with other values z (e.g. simulated noise); sensors without
        a value are accepted when ``allow_empty_sensors`` (None: as this campaign)."""
        return Measurements(self.inputs, z, self.sigma, sensors=self.sensors,
                            input_names=self.input_names, series=None if np.shape(z)[0] != self.n_M else self.series,
                            allow_empty_sensors=self.allow_empty_sensors if allow_empty_sensors is None
                            else allow_empty_sensors)

    def __repr__(self):
        sig = "unknown" if self.sigma is None else np.array2string(self.sigma, precision=4)
        return (f"Measurements(n_M={self.n_M}, n_q={self.n_q}, n_S={self.n_S}, d_q={self.d_q}, "
                f"sensors={list(self.sensors)}, sigma={sig}, missing={int((~self.mask()).sum())})")
