"""Long-format CSV of time-series campaigns (dynamic models).

One row per reading::

    series,experiment,time,sensor,value,unit
    1,1,0.2,cA,0.8913,mol/L

``series`` (optional, default 1) and ``experiment`` are 1-based numbers; ``experiment`` k is row k of the
experiment input table given to :func:`read_long_csv`.  ``time`` is in the model's time unit.  ``unit``
(optional) is converted to the sensor's unit of the model (``mudoe.units``).  An empty or NaN value
marks a missing reading; experiments may have their own sampling times (ragged).

Checks, each naming the file and the line: a cell above 1e15 in magnitude (as the static readers), a
negative time, a time that is not one of the declared sampling times (``times``, a study's ``[dynamic]
times``: an error -- a typo such as 0.33 for 0.3 would otherwise become a time of its own; round-off
such as 0.30000000000000004 reads as the declared 0.3), a reading more than
:data:`mudoe.data_checks.ABSURD_RATIO` robust spreads from its instrument's median (an export or unit
error; the check of the static readers, pooled over experiments and times).
"""
from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import NamedTuple, Sequence

import numpy as np

from identification.errors import DataError
from identification.fit.dynamic_data import DynamicMeasurements
from models.dynamic import time_tolerance
from models.fileio import atomic_write_text

from ..data_checks import ABSURD_RATIO, absurd_reading
from ..data_io import MAX_MAGNITUDE, DataFileError
from ..units import UnitError, convert

__all__ = ["read_long_csv", "write_long_csv", "LONG_COLUMNS"]


LONG_COLUMNS = ("series", "experiment", "time", "sensor", "value", "unit")
_MISSING = {"", "nan", "na", "n/a", "null", "none"}


class _Reading(NamedTuple):
    series: int          # 1-based
    experiment: int      # 1-based
    time: float
    sensor: int          # index into the model's sensors
    value: float         # model unit (NaN: missing)
    line: int            # line of the file


def write_long_csv(path, data: DynamicMeasurements, units: Sequence[str] | None = None) -> Path:
    """Write every present reading of ``data`` (atomically); ``units`` per sensor (default none)."""
    units = tuple(units) if units is not None else ("",) * data.n_S
    if len(units) != data.n_S:
        raise ValueError(f"units: {len(units)} given for {data.n_S} sensors")
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(LONG_COLUMNS)
    for i in range(data.n_M):
        for j in range(data.n_q):
            for r, t in enumerate(data.times[j]):
                for k, s in enumerate(data.sensors):
                    v = data.z[i, j, r, k]
                    if np.isfinite(v):
                        w.writerow([i + 1, j + 1, repr(float(t)), s, repr(float(v)), units[k]])
    return atomic_write_text(path, buf.getvalue())


def _number(path, line, col, cell, integer=False):
    try:
        v = float(cell)
    except ValueError:
        raise DataFileError(f"{path}, line {line}: column {col!r} holds {cell!r}, not a number") from None
    if not math.isfinite(v) or (integer and (v != int(v) or v < 1)):
        raise DataFileError(f"{path}, line {line}: column {col!r} holds {cell!r}; expected "
                            f"{'a 1-based number' if integer else 'a finite number'}")
    if abs(v) > MAX_MAGNITUDE:
        raise DataFileError(f"{path}, line {line}: column {col!r}: {cell!r} is out of range (|value| > "
                            f"{MAX_MAGNITUDE:g}); a unit or export error? Fix it or mark the reading missing (empty)")
    return int(v) if integer else v


def _time(path, line, cell, declared) -> float:
    """The time of a row: >= 0 and, with declared sampling times, one of them (within round-off)."""
    t = _number(path, line, "time", cell)
    if t < 0:
        raise DataFileError(f"{path}, line {line}: time {cell!r} is negative; sampling times are >= 0")
    if declared is None or not declared.size:
        return t
    k = int(np.argmin(np.abs(declared - t)))
    if abs(declared[k] - t) > time_tolerance(declared[-1], declared[k]):
        raise DataFileError(f"{path}, line {line}: time {cell!r} is not one of the declared sampling times "
                            f"([dynamic] times; the nearest is {declared[k]:g}); correct the time or add it to "
                            "[dynamic] times")
    return float(declared[k])


def read_long_csv(path, inputs, sensors: Sequence[str], units: Sequence[str] | None = None, sigma=None,
                  input_names: Sequence[str] | None = None, times=None) -> DynamicMeasurements:
    """The campaign in a long-format CSV file (see the module docstring).

    Parameters
    ----------
    path : str or Path
    inputs : array_like (n_q, d_q)      the experiments' input rows (experiment k is row k)
    sensors : sequence of str           the model's sensors (readings of other sensors raise)
    units : sequence of str, optional   the model's unit per sensor (a file unit is converted to it)
    sigma : array_like (n_S,), optional one per instrument, in the model's units
    times : array_like, optional        the declared sampling times (a study's ``[dynamic] times``): a
                                        reading at another time is an error naming its line

    Raises
    ------
    DataFileError
        Missing file or column, a bad cell, an unknown sensor or experiment, a reading given twice,
        a unit that does not convert (the message names the file and the line).
    """
    path = Path(path)
    try:
        rows = list(csv.reader(path.read_text().splitlines()))
    except OSError as exc:
        raise DataFileError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if not rows:
        raise DataFileError(f"{path}: empty file; expected the header {','.join(LONG_COLUMNS)}")
    header = [h.strip().lower() for h in rows[0]]
    missing = [c for c in ("experiment", "time", "sensor", "value") if c not in header]
    if missing:
        raise DataFileError(f"{path}, line 1: missing column(s) {', '.join(missing)}; the header must hold "
                            "experiment, time, sensor, value (series and unit optional)")
    col = {c: header.index(c) for c in LONG_COLUMNS if c in header}
    q = np.asarray(inputs, float)
    q = q.reshape(1, -1) if q.ndim < 2 else q
    declared = None if times is None else np.sort(np.asarray(times, float).ravel())
    sensors, units = tuple(sensors), tuple(units) if units is not None else None
    recs = []
    for line, row in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in row):
            continue
        if len(row) < len(header):
            raise DataFileError(f"{path}, line {line}: {len(row)} cells for {len(header)} columns")
        series = _number(path, line, "series", row[col["series"]], True) if "series" in col else 1
        exp = _number(path, line, "experiment", row[col["experiment"]], True)
        if exp > q.shape[0]:
            raise DataFileError(f"{path}, line {line}: experiment {exp}, but the input table has {q.shape[0]} rows")
        t = _time(path, line, row[col["time"]], declared)
        s = row[col["sensor"]].strip()
        if s not in sensors:
            raise DataFileError(f"{path}, line {line}: unknown sensor {s!r}; the model has {', '.join(sensors)}")
        cell = row[col["value"]].strip()
        v = math.nan if cell.lower() in _MISSING else _number(path, line, "value", cell)
        unit = row[col["unit"]].strip() if "unit" in col else ""
        if unit and units is not None and unit != units[sensors.index(s)]:
            try:
                v = float(convert(v, unit, units[sensors.index(s)]))
            except UnitError as exc:
                raise DataFileError(f"{path}, line {line}: {exc}") from None
        recs.append(_Reading(series, exp, t, sensors.index(s), v, line))
    if not recs:
        raise DataFileError(f"{path}: no reading")
    return _assemble(path, q, sensors, recs, sigma, input_names)


def _assemble(path, q, sensors, recs, sigma, input_names) -> DynamicMeasurements:
    n_M = max(r.series for r in recs)
    times = [sorted({r.time for r in recs if r.experiment == j + 1}) for j in range(q.shape[0])]
    empty = [j + 1 for j, t in enumerate(times) if not t]
    if empty:
        raise DataFileError(f"{path}: experiment(s) {', '.join(map(str, empty))} of the input table have no reading")
    n_t = max(len(t) for t in times)
    z = np.full((n_M, q.shape[0], n_t, len(sensors)), np.nan)
    seen = {}
    for r in recs:
        key = (r.series, r.experiment, r.time, r.sensor)
        if key in seen:
            raise DataFileError(f"{path}, line {r.line}: series {r.series}, experiment {r.experiment}, time "
                                f"{r.time:g}, sensor {sensors[r.sensor]!r} was already given on line {seen[key]}")
        seen[key] = r.line
        z[r.series - 1, r.experiment - 1, times[r.experiment - 1].index(r.time), r.sensor] = r.value
    _check_absurd(path, z, sensors, seen, times)
    try:
        return DynamicMeasurements(q, [np.asarray(t) for t in times] if len({len(t) for t in times}) > 1
                                   else np.array(times), z, sigma, sensors=sensors, input_names=input_names)
    except DataError as exc:
        raise DataFileError(f"{path}: {exc}") from None


def _check_absurd(path, z, sensors, lines: dict, times: list) -> None:
    """A reading more than ABSURD_RATIO robust spreads from its instrument's median (all experiments and
    times pooled) is refused naming its line (:func:`mudoe.data_checks.absurd_reading`)."""
    n_M, n_q, n_t, n_S = z.shape
    found = absurd_reading(z.reshape(n_M, n_q * n_t, n_S))
    if found is None:
        return
    i, jt, k, ratio = found
    j, r = divmod(jt, n_t)
    v = z[i, j, r, k]
    med = float(np.median(z[..., k][np.isfinite(z[..., k])]))
    line = lines[(i + 1, j + 1, times[j][r], k)]
    raise DataFileError(f"{path}, line {line}: sensor {sensors[k]!r}, series {i + 1}, experiment {j + 1}, time "
                        f"{times[j][r]:g}: reading {v:g} is {ratio:.2g} robust spreads from the sensor's median "
                        f"{med:g} (more than {ABSURD_RATIO:g}; model units): a unit or export error? Fix the value "
                        "or its unit, or mark it missing (empty cell or NaN)")
