"""Long-format CSV of time-series campaigns (dynamic models).

One row per reading::

    series,experiment,time,sensor,value,unit
    1,1,0.2,cA,0.8913,mol/L

``series`` (optional, default 1) and ``experiment`` are 1-based numbers; ``experiment`` k is row k of the
experiment input table given to :func:`read_long_csv`.  ``time`` is in the model's time unit.  ``unit``
(optional) is converted to the sensor's unit of the model (``mudoe.units``).  An empty or NaN value
marks a missing reading; experiments may have their own sampling times (ragged).
"""
from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import NamedTuple, Sequence

import numpy as np

from identification.fit.dynamic_data import DynamicMeasurements
from models.fileio import atomic_write_text

from .data_io import DataFileError
from .units import UnitError, convert

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
    return int(v) if integer else v


def read_long_csv(path, inputs, sensors: Sequence[str], units: Sequence[str] | None = None, sigma=None,
                  input_names: Sequence[str] | None = None) -> DynamicMeasurements:
    """The campaign in a long-format CSV file (see the module docstring).

    Parameters
    ----------
    path : str or Path
    inputs : array_like (n_q, d_q)      the experiments' input rows (experiment k is row k)
    sensors : sequence of str           the model's sensors (readings of other sensors raise)
    units : sequence of str, optional   the model's unit per sensor (a file unit is converted to it)
    sigma : array_like (n_S,), optional one per instrument, in the model's units

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
    q = np.atleast_2d(np.asarray(inputs, float))
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
        t = _number(path, line, "time", row[col["time"]])
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
    return DynamicMeasurements(q, [np.asarray(t) for t in times] if len({len(t) for t in times}) > 1
                               else np.array(times), z, sigma, sensors=sensors, input_names=input_names)
