"""Measurements over time: n_M series x n_q experiments x n_t sampling times x n_S sensors.

z_ijtk = h_k(x_j(t), p*, u_j(t)) + eps_ijtk, eps ~ N(0, sigma_k^2) independent, one sigma per
instrument (not per time).  Experiments may have their own sampling times (ragged): ``times`` is
then one row per experiment padded with NaN, and the matching entries of z are NaN (missing,
never imputed).  :meth:`DynamicMeasurements.flat` maps the campaign onto the static form
(series, experiments, ``sensor@time``) over the union of all sampling times, which the
collocated model of :mod:`models.collocation` predicts.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from models.collocation import pair_name
from models.dynamic import TIME_RTOL, merge_times, same_instant_gaps
from identification.errors import DataError
from identification.fit.measurements import Measurements

__all__ = ["DynamicMeasurements", "instrument_sigma"]


def _readonly(a) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a


def _selection(arg: str, idx, n: int) -> np.ndarray:
    """The distinct indices chosen by ints, a boolean mask of length n or a slice (DataError naming ``arg``)."""
    try:
        out = np.arange(n)[idx if isinstance(idx, (slice, np.ndarray)) else np.asarray(list(idx), dtype=int)]
    except (IndexError, TypeError, ValueError) as exc:
        raise DataError(f"{arg}: not a valid selection of {n} entries ({exc})") from None
    if out.size == 0 or np.unique(out).size != out.size:
        raise DataError(f"{arg}: the selection is empty or names an entry twice: {out.tolist()}")
    return out


def _times_table(times, n_q: int) -> np.ndarray:
    """Sampling times as an (n_q, n_t) array, NaN-padded at the end of a row (ragged experiments)."""
    if isinstance(times, (list, tuple)) and times and all(np.ndim(r) == 1 for r in times) \
            and len({len(r) for r in times}) > 1:
        n_t = max(len(r) for r in times)
        t = np.full((len(times), n_t), np.nan)
        for j, r in enumerate(times):
            t[j, :len(r)] = np.asarray(r, float)
    else:
        try:
            t = np.asarray(times, dtype=float)
        except (TypeError, ValueError) as exc:
            raise DataError(f"times: not numeric ({exc})") from None
        if t.ndim == 1:
            t = np.broadcast_to(t, (n_q, t.size))
    if t.ndim != 2 or t.shape[0] != n_q or t.shape[1] == 0:
        raise DataError(f"times: expected one row of sampling times per experiment ({n_q} rows) or one common "
                        f"row, got shape {np.shape(times)}")
    for j, row in enumerate(t):
        ok = np.isfinite(row)
        n = int(ok.sum())
        if n == 0:
            raise DataError(f"times: experiment {j + 1} has no sampling time")
        if not np.all(ok[:n]) or np.any(np.isinf(row)):
            raise DataError(f"times: experiment {j + 1}: NaN may only pad the end of a row (ragged times), "
                            "and times must be finite")
        r = row[:n]
        if r[0] < 0:
            raise DataError(f"times: experiment {j + 1} has a negative sampling time {r[0]:g}")
        if np.any(np.diff(r) <= 0):
            i = int(np.flatnonzero(np.diff(r) <= 0)[0])
            raise DataError(f"times: experiment {j + 1}: sampling times must be strictly increasing; "
                            f"{r[i + 1]:g} follows {r[i]:g}")
    return _merged(t)


def _merged(t: np.ndarray) -> np.ndarray:
    """The times with every time within round-off of another (:func:`models.dynamic.time_tolerance` with the
    last time as the horizon) replaced by one value for all experiments, so that round-off never makes two
    instants."""
    finite = t[np.isfinite(t)]
    horizon = finite.max()
    for j, row in enumerate(t):
        r = row[np.isfinite(row)]
        twins = same_instant_gaps(r, horizon)
        if np.any(twins):
            i = int(np.flatnonzero(twins)[0])
            raise DataError(f"times: experiment {j + 1}: the sampling times {float(r[i])!r} and {float(r[i + 1])!r} "
                            f"differ by round-off only (less than {TIME_RTOL:g} of their size); give that time once")
    union = merge_times(finite, horizon=horizon)
    if union.size == np.unique(finite).size:
        return t
    out = t.copy()
    ok = np.isfinite(t)
    near = np.abs(t[ok][:, None] - union[None, :]).argmin(axis=1)
    out[ok] = union[near]
    return out


def _inputs_table(inputs, zz: np.ndarray) -> np.ndarray:
    """The input rows (n_q, d_q); ``None`` (or an (n_q, 0) array) for experiments without inputs: one empty
    row per experiment of z (axis 1)."""
    if inputs is None:
        if zz.ndim != 4:
            raise DataError(f"z: expected shape (series, experiments, times, sensors), got {zz.shape}")
        return np.zeros((zz.shape[1], 0))
    try:
        q = np.asarray(inputs, dtype=float)
    except (TypeError, ValueError) as exc:
        raise DataError(f"inputs: not numeric ({exc})") from None
    q = q[:, None] if q.ndim == 1 else q
    if q.ndim != 2 or q.shape[0] == 0:
        raise DataError(f"inputs: expected one row per experiment, shape (n_q, d_q) (np.zeros((n_q, 0)) or None "
                        f"for experiments without inputs), got shape {q.shape}")
    return q


class DynamicMeasurements:
    """An immutable campaign of time series.

    Parameters
    ----------
    inputs : array_like (n_q, d_q) or None
                                        experiment input rows (constants, then control grid values); a model
                                        without inputs: None or np.zeros((n_q, 0)) (n_q from z)
    times : array_like                  sampling times: (n_t,) common to all experiments, (n_q, n_t) per
                                        experiment padded with NaN, or a list of 1-D arrays (ragged)
    z : array_like (n_M, n_q, n_t, n_S) measured values; NaN marks a missing value
    sigma : array_like (n_S,), float or None
                                        one standard deviation per instrument (unit of z); None: unknown
    sensors, input_names, series : sequence of str, optional

    Raises
    ------
    DataError
        Bad shapes, times (negative, not increasing, NaN inside a row), a value at a padded time,
        and everything :class:`Measurements` refuses (the message names the argument).
    """

    __slots__ = ("times", "sensors", "_flat", "_z", "_sigma", "pairs")

    def __init__(self, inputs, times, z, sigma=None, sensors: Sequence[str] | None = None,
                 input_names: Sequence[str] | None = None, series: Sequence[str] | None = None):
        zz = np.asarray(z, dtype=float)
        q = _inputs_table(inputs, zz)
        n_q = q.shape[0]
        t = _times_table(times, n_q)
        if zz.ndim != 4 or zz.shape[1:3] != t.shape:
            raise DataError(f"z: expected shape (series, experiments, times, sensors) = (n_M, {t.shape[0]}, "
                            f"{t.shape[1]}, n_S), got {zz.shape}")
        pad = ~np.isfinite(t)
        if np.any(np.isfinite(zz[:, pad, :])):
            j, i = np.argwhere(pad)[0]
            raise DataError(f"z: experiment {j + 1} has a value at sample {i + 1}, where it has no sampling time")
        n_S = zz.shape[3]
        names = tuple(sensors) if sensors is not None else tuple(f"s{k + 1}" for k in range(n_S))
        if len(names) != n_S:
            raise DataError(f"sensors: {len(names)} names given but z has {n_S} sensors")
        union = np.unique(t[np.isfinite(t)])
        col = {float(v): i for i, v in enumerate(union)}
        flat = np.full((zz.shape[0], n_q, union.size, n_S), np.nan)
        for j in range(n_q):
            n = int(np.isfinite(t[j]).sum())
            flat[:, j, [col[float(v)] for v in t[j, :n]], :] = zz[:, j, :n, :]
        flat = flat.reshape(zz.shape[0], n_q, -1)
        keep = np.flatnonzero(np.isfinite(flat).any(axis=(0, 1)))      # (sensor, time) pairs with data
        pairs = tuple((names[i % n_S], float(union[i // n_S])) for i in keep)
        s = s_inst = None
        if sigma is not None:
            try:
                s_inst = np.asarray(sigma, dtype=float)
            except (TypeError, ValueError) as exc:
                raise DataError(f"sigma: not numeric ({exc})") from None
            s_inst = np.full(n_S, float(s_inst)) if s_inst.ndim == 0 else s_inst
            if s_inst.shape != (n_S,):
                raise DataError(f"sigma: expected {n_S} values (one per instrument, not per time), "
                                f"got shape {s_inst.shape}")
            s = np.tile(s_inst, union.size)[keep]
        if keep.size == 0:
            raise DataError("z: no finite value (NaN only)")
        fm = Measurements(q, flat[:, :, keep], s, sensors=[pair_name(k, v) for k, v in pairs],
                          input_names=input_names, series=series)
        t = _readonly(t)
        for name, value in (("times", t), ("sensors", names), ("_flat", fm), ("_z", _readonly(zz)),
                            ("_sigma", None if s_inst is None else _readonly(s_inst)), ("pairs", pairs)):
            object.__setattr__(self, name, value)

    def __setattr__(self, name, value):
        raise AttributeError("DynamicMeasurements is immutable; use subset() or with_sigma()")

    def __reduce__(self):
        f = self._flat
        return (DynamicMeasurements, (f.inputs, self.times, self._z, self.sigma, self.sensors, f.input_names,
                                      f.series))

    # ------------------------------------------------------------------ views
    @property
    def z(self) -> np.ndarray:
        """The values, (n_M, n_q, n_t, n_S)."""
        return self._z

    @property
    def inputs(self) -> np.ndarray:
        return self._flat.inputs

    @property
    def sigma(self):
        """One sigma per instrument (n_S,), or None when unknown."""
        return self._sigma

    @property
    def n_M(self) -> int:
        return self._z.shape[0]

    @property
    def n_q(self) -> int:
        return self._z.shape[1]

    @property
    def n_S(self) -> int:
        return len(self.sensors)

    @property
    def union_times(self) -> np.ndarray:
        """All sampling times of the campaign, sorted."""
        return np.unique(self.times[np.isfinite(self.times)])

    def flat(self) -> Measurements:
        """The static form: z (n_M, n_q, n_pairs) over the (sensor, time) pairs with data (:attr:`pairs`,
        time-major over the union of the sampling times), sensors ``sensor@time``, NaN where an
        experiment has no sample there."""
        return self._flat

    def by_instrument(self) -> Measurements:
        """The readings with one column per instrument: z (n_M, n_rows, n_S) over the (experiment, time)
        rows that exist, inputs (experiment number, time).  For checks pooled per instrument over
        times, e.g. ``identification.normality_check(data.by_instrument())`` (Algorithm 1's gate on the
        flat data tests every (sensor, time) pair on its own)."""
        j, i = np.nonzero(np.isfinite(self.times))
        return Measurements(np.c_[j + 1, self.times[j, i]], self._z[:, j, i, :], self.sigma, sensors=self.sensors,
                            input_names=("experiment", "time"), series=self._flat.series)

    def subset(self, inputs=None, series=None) -> "DynamicMeasurements":
        """The campaign restricted to some experiments and/or series (their own sampling times kept)."""
        qi = np.arange(self.n_q) if inputs is None else _selection("inputs", inputs, self.n_q)
        si = np.arange(self.n_M) if series is None else _selection("series", series, self.n_M)
        t = self.times[qi]
        n_t = int(np.isfinite(t).sum(axis=1).max())
        f = self._flat
        return DynamicMeasurements(f.inputs[qi], t[:, :n_t], self._z[np.ix_(si, qi)][:, :, :n_t], self.sigma,
                                   self.sensors, f.input_names, [f.series[i] for i in si])

    def with_sigma(self, sigma) -> "DynamicMeasurements":
        f = self._flat
        return DynamicMeasurements(f.inputs, self.times, self._z, sigma, self.sensors, f.input_names, f.series)

    def with_z(self, z) -> "DynamicMeasurements":
        """The same inputs, times, sigma and labels with other values z (n_M', n_q, n_t, n_S)."""
        f = self._flat
        return DynamicMeasurements(f.inputs, self.times, z, self.sigma, self.sensors, f.input_names,
                                   f.series if np.shape(z)[0] == self.n_M else None)

    def __repr__(self):
        sig = "unknown" if self.sigma is None else np.array2string(self.sigma, precision=4)
        return (f"DynamicMeasurements(n_M={self.n_M}, n_q={self.n_q}, times={self.union_times.size}, "
                f"sensors={list(self.sensors)}, sigma={sig}, missing={int((~np.isfinite(self._z)).sum())})")


def instrument_sigma(instruments: Sequence[str], sigma, *, readings: Sequence[str] | None = None,
                     missing: bool = False) -> np.ndarray:
    r"""sigma_s, s = 1..n_S: one standard deviation per instrument (in the unit of its readings).

    eps_ijtk ~ N(0, sigma_k^2) with one sigma per instrument k, not per time: the one place that turns
    a scalar, a list per instrument, or the sigma of the flat ``sensor@time`` readings of a collocated
    fit into that (n_S,) array.

    Parameters
    ----------
    instruments : sequence of str
        The instruments' names, in order (``model.sensors`` of a dynamic model).
    sigma : float or array_like
        One value for all instruments, n_S values (one per instrument), or, with ``readings``, one value
        per reading.
    readings : sequence of str, optional
        Names ``instrument@time`` of the readings that ``sigma`` belongs to (an estimate's ``sensors``):
        an instrument's sigma is that of its first reading.
    missing : bool
        Allow NaN (an instrument whose sigma is not given); every other value must be positive finite.

    Returns
    -------
    numpy.ndarray (n_S,)

    Raises
    ------
    ValueError
        ``sigma`` not n_S positive finite values, or an instrument without reading.
    """
    names = list(instruments)
    if readings is not None:
        sig_r = np.asarray(sigma, dtype=float).ravel()
        inst = [str(r).split("@")[0] for r in readings]
        if sig_r.shape != (len(inst),):
            raise ValueError(f"sigma: expected {len(inst)} values (one per reading), got {sigma!r}")
        absent = [s for s in names if s not in inst]
        if absent:
            raise ValueError(f"readings: no reading of instrument(s) {', '.join(absent)}")
        sig = np.array([sig_r[inst.index(s)] for s in names])
    else:
        sig = np.asarray(sigma, dtype=float).ravel()
        if sig.size == 1:
            sig = np.full(len(names), float(sig[0]))
    ok = np.isfinite(sig) & (sig > 0)
    if missing:
        ok |= np.isnan(sig)
    if sig.shape != (len(names),) or not np.all(ok):
        raise ValueError(f"sigma: expected {len(names)} positive finite values (one per instrument: "
                         f"{', '.join(names)}), got {sigma!r}")
    return sig
