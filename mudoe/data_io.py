"""CSV import and export of measurement campaigns in two layouts.

Paper layout (one file per sensor, like the paper's ``Messungen_*.csv``)::

    force_N,series_1,series_2,...       <- header: force column, then one column per series
    0.0000,0.0000,0.0000,...            <- one row per set point
    114.2857,105.2311,104.9876,...

Tidy long layout (one file)::

    series,index,set_force_N,actual_force_N,sensor,raw_um,value_um
    1,1,0.0000,0.0000,D_y,0.0000,0.0000

Required tidy columns: ``series``, ``set_force``, ``sensor``, ``value`` (or ``raw``);
optional: ``index`` (1-based set-point number; default: order of appearance),
``actual_force``, ``raw``.  A column name may carry its unit as a suffix (``force_N``,
``set_force_kN``, ``value_um``, ``force [lbf]``): any unit pint knows (:mod:`mudoe.units`).  An
input column in another unit of the declared dimension is converted by pint (``force_lbf``
with force_unit = "N"); a unit of another dimension (``force_parsec``) or one pint does not
know is an error naming the file and column; a reading column must carry the declared unit
(its sigma is declared in it).  Empty cells and ``NaN``/``NA`` mark a missing reading; set forces
must be known.  Everything is converted once to the model's units (mm, N).  The units of the data
(declared, in headers, the model's) are resolved in :mod:`mudoe.data_units`.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Sequence

import numpy as np

from models.campaign import Campaign
from models.fileio import atomic_write_text

from . import csv_stream
from .config import StudyConfig
from .csv_stream import DataFileError
from .data_checks import absurd_reading_message
from .data_units import DataUnits, column_unit, split_unit, study_units
from .registry import virtual_prototype

__all__ = ["DataFileError", "DataUnits", "study_units", "Campaign", "read_paper_layout", "read_tidy_layout", "write_paper_layout",
           "write_tidy_layout", "load_campaign", "atomic_write_text", "sha256_files"]

_MISSING = {"", "nan", "na", "n/a", "null", "none"}

#: largest magnitude accepted in a numeric cell; larger values (1e300, ...) are export or unit
#: errors and would overflow the squared residuals of a fit
MAX_MAGNITUDE = 1e15


# ---------------------------------------------------------------------------- helpers
def sha256_files(paths: Sequence) -> str:
    """sha256 over the bytes of the files (in the given order, names included)."""
    h = hashlib.sha256()
    for p in paths:
        h.update(Path(p).name.encode())
        h.update(Path(p).read_bytes())
    return h.hexdigest()




def _number(path, line, col, cell, allow_missing=True):
    c = cell.strip()
    if c.lower() in _MISSING:
        if allow_missing:
            return math.nan
        raise DataFileError(f"{path}:{line}: column {col!r} is empty or NaN; set forces must be known")
    try:
        v = float(c)
    except ValueError:
        raise DataFileError(f"{path}:{line}: column {col!r}: {c!r} is not a number "
                            "(use an empty cell or NaN for a missing reading)") from None
    if math.isinf(v):
        raise DataFileError(f"{path}:{line}: column {col!r}: infinite value {c!r}; use NaN for a missing reading")
    if abs(v) > MAX_MAGNITUDE:
        raise DataFileError(f"{path}:{line}: column {col!r}: {c!r} is out of range (|value| > {MAX_MAGNITUDE:g}); "
                            "check the export and the declared unit")
    if math.isnan(v) and not allow_missing:
        raise DataFileError(f"{path}:{line}: column {col!r} is NaN; set forces must be known")
    return v


def _with_unit(name: str, unit: str) -> str:
    return f"{name}_{unit}" if unit else name


# ---------------------------------------------------------------------------- paper layout
def _read_paper_file(path: Path, units: DataUnits):
    header, offset = csv_stream.read_header(path)
    base, unit = split_unit(header[0], units.input_names() | {"force"})
    if not base.startswith("force") and base not in units.input_names():
        example = f"{units.input_name}_{units.input_file}" if units.input_file else units.input_name
        raise DataFileError(f"{path}:1: wrong header: the first column must be the input {units.input_name!r} "
                            f"(e.g. {example!r}), got {header[0]!r}")
    q_unit = column_unit(path, header[0], unit, units.input_file, units.input_key, convertible=True)
    if len(header) < 2:
        raise DataFileError(f"{path}:1: wrong header: expected the force column then one column per series, "
                            f"got only {header!r}")
    if any(not h for h in header):
        raise DataFileError(f"{path}:1: wrong header: empty column name in {header!r}")
    twice = [h for h in dict.fromkeys(header[1:]) if header[1:].count(h) > 1]
    if twice:
        raise DataFileError(f"{path}:1: wrong header: series column {twice[0]!r} appears twice; name every "
                            "series once")
    cell = partial(_number, path)
    qs, zs = [], []
    for b in csv_stream.blocks(path, len(header), dict.fromkeys(range(len(header)), True), offset=offset):
        qs.append(csv_stream.numbers(b, 0, header[0], cell, allow_missing=False, max_magnitude=MAX_MAGNITUDE))
        zs.append(np.stack([csv_stream.numbers(b, i, header[i], cell, max_magnitude=MAX_MAGNITUDE)
                            for i in range(1, len(header))]))
    if not qs:
        raise DataFileError(f"{path}: no data rows after the header")
    return units.q_from_column(np.concatenate(qs), q_unit), np.concatenate(zs, axis=1), tuple(header[1:])


def read_paper_layout(files: dict, displacement_unit: str = "um", force_unit: str = "N",
                      actual_forces_file=None, units: DataUnits | None = None) -> Campaign:
    """Read one CSV per sensor (force column, then one column per series).

    Parameters
    ----------
    files : dict {sensor: path}
        In the order of the model's sensors.
    displacement_unit, force_unit : str
        Units of the readings and forces in the files (converted to mm and N); used when
        ``units`` is not given.
    actual_forces_file : path, optional
        Actual forces in the same layout (set force, then one column per series).
    units : DataUnits, optional
        Any units: the input and every sensor in the files and in the model (:func:`study_units`).

    Returns
    -------
    Campaign in the model's units (z not force-corrected)

    Raises
    ------
    DataFileError
        Missing file, wrong header, ragged row, text in a numeric column (file and line),
        files that disagree in set forces or series.
    """
    if not files:
        raise DataFileError("files: no sensor files given")
    if units is None:
        units = DataUnits.legacy(displacement_unit, force_unit, len(files))
    q_ref = series_ref = None
    zs, paths = [], []
    first = None
    for sensor, f in files.items():
        path = Path(f)
        q, z, ser = _read_paper_file(path, units)
        if q_ref is None:
            q_ref, series_ref, first = q, ser, path
        else:
            if q.shape != q_ref.shape or not np.allclose(q, q_ref, rtol=1e-9, atol=1e-9):
                raise DataFileError(f"{path}: set forces differ from those of {first} ({q.size} vs {q_ref.size} "
                                    "rows); every sensor file must list the same set points")
            if len(ser) != len(series_ref):
                raise DataFileError(f"{path}:1: {len(ser)} series columns but {first} has {len(series_ref)}")
        zs.append(z)
        paths.append(path)
    z = units.z_to_model(np.stack(zs, axis=2))
    q_act = None
    if actual_forces_file:
        path = Path(actual_forces_file)
        qa_set, qa, ser = _read_paper_file(path, units)
        if qa_set.shape != q_ref.shape or not np.allclose(qa_set, q_ref, rtol=1e-9, atol=1e-9):
            raise DataFileError(f"{path}: set forces differ from those of {first}")
        if qa.shape[0] != z.shape[0]:
            raise DataFileError(f"{path}:1: {qa.shape[0]} series columns but the readings have {z.shape[0]}")
        if np.isnan(qa).any():
            i, j = np.argwhere(np.isnan(qa))[0]
            raise DataFileError(f"{path}:{j + 2}: actual force of series {ser[i]!r} is missing")
        q_act = units.q_to_model(qa)
        paths.append(path)
    return Campaign(q_set=units.q_to_model(q_ref), q_actual=q_act, z=z, sensors=tuple(files), series=series_ref,
                    files=tuple(str(p) for p in paths), source=f"CSV, paper layout ({len(files)} files)",
                    sha256=sha256_files(paths))


def write_paper_layout(directory, q_set, z, sensors: Sequence[str], displacement_unit: str = "um",
                       force_unit: str = "N", series: Sequence[str] | None = None, q_actual=None,
                       stem: str = "measurements_", units: DataUnits | None = None) -> list[Path]:
    """Write z and q_set (model units: mm and N, or ``units``) as one CSV per sensor (atomically).

    The files get the units ``displacement_unit`` / ``force_unit`` (or ``units``' file units).
    With ``q_actual`` (n_M, n_q) also writes ``<stem>actual_forces.csv`` in the same layout.
    Values are written with 17 significant digits (exact round trip).  Returns the paths.
    """
    if units is None:
        units = DataUnits.legacy(displacement_unit, force_unit, len(sensors))
    z = units.z_to_file(z)
    q_set = units.q_to_file(np.asarray(q_set, float).ravel())
    n_M = z.shape[0]
    series = list(series) if series is not None else [f"series_{i + 1}" for i in range(n_M)]
    head = _with_unit(units.input_name, units.input_file) + "," + ",".join(series)
    out = []

    def fmt(v):
        return "NaN" if not np.isfinite(v) else repr(float(v))

    for k, s in enumerate(sensors):
        lines = [head] + [",".join([fmt(q_set[j])] + [fmt(z[i, j, k]) for i in range(n_M)])
                          for j in range(q_set.size)]
        out.append(atomic_write_text(Path(directory) / f"{stem}{s}.csv", "\n".join(lines) + "\n"))
    if q_actual is not None:
        qa = units.q_to_file(q_actual)
        lines = [head] + [",".join([fmt(q_set[j])] + [fmt(qa[i, j]) for i in range(n_M)])
                          for j in range(q_set.size)]
        out.append(atomic_write_text(Path(directory) / f"{stem}actual_forces.csv", "\n".join(lines) + "\n"))
    return out


# ---------------------------------------------------------------------------- tidy layout
def _tidy_columns(path: Path, header: list, value_column: str, units: DataUnits) -> dict:
    """{role: (column index, header text, unit)} of the tidy header; units must agree with the declared ones.

    Roles: series, index, sensor, set_force (the input: ``set_force``, ``input`` or the model's input
    name), actual_force (``actual_<input>``), value, raw; other columns are ignored.
    """
    cols = {}
    same = set(units.output_file)
    for i, h in enumerate(header):
        base, unit = split_unit(h, units.input_names() | units.actual_names() | {"value", "raw"})
        if base in units.input_names():
            role = "set_force"
        elif base in units.actual_names():
            role = "actual_force"
        elif base in ("value", "raw"):
            role = base
        else:
            role, unit = h.lower(), None
        if role in cols:
            raise DataFileError(f"{path}:1: wrong header: column {role!r} appears twice")
        cols[role] = (i, h, unit)
        if role in ("set_force", "actual_force"):
            cols[role] = (i, h, column_unit(path, h, unit, units.input_file, units.input_key, convertible=True))
        elif role in ("value", "raw") and unit is not None:
            if len(same) > 1:
                raise DataFileError(f"{path}:1: column {h!r} carries unit {unit} but the sensors are declared in "
                                    f"different units ({', '.join(sorted(same))}); name the column {role!r}")
            column_unit(path, h, unit, next(iter(same), ""), units.output_key)
    need = ["series", "set_force", "sensor", value_column]
    missing = [c for c in need if c not in cols]
    if missing:
        inp = _with_unit("set_" + units.input_name, units.input_file)
        raise DataFileError(f"{path}:1: wrong header: missing column(s) {', '.join(missing)}; expected "
                            f"series, [index,] {inp}, [actual_...,] sensor, "
                            f"{value_column}_<unit>; got {','.join(header)}")
    return cols


@dataclass(frozen=True)
class _TidyTable:
    """The tidy table's rows as arrays in file order (file units): line, series and sensor codes (in order
    of first appearance: ``series`` / ``sensors`` hold the labels), 1-based set-point index, set force,
    actual force (NaN when absent) and reading."""

    line: np.ndarray
    series_code: np.ndarray
    index: np.ndarray
    sensor_code: np.ndarray
    set_force: np.ndarray
    actual_force: np.ndarray
    value: np.ndarray
    series: list
    sensors: list


def _codes(labels: np.ndarray, known: dict) -> np.ndarray:
    """Integer codes of ``labels``, new labels appended to ``known`` ({label: code}) in order of appearance."""
    import pandas as pd
    inv, uniq = pd.factorize(labels)
    return np.array([known.setdefault(u, len(known)) for u in uniq], np.int64)[inv]


def _first_bad(path, b, bad, msg) -> None:
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise DataFileError(f"{path}:{int(b.lines[i])}: {msg(i)}")


#: the per-row columns of :class:`_TidyTable`, as one block of the file gives them (:func:`_tidy_block`)
_BLOCK_COLUMNS = ("line", "series_code", "index", "sensor_code", "set_force", "actual_force", "value")


def _tidy_block(path, b, cols, value_column, sensors, state) -> dict:
    """One block of the tidy table as arrays, {column of :data:`_BLOCK_COLUMNS`: array} (errors name the
    file and line); ``state`` carries the codes and the running per-(series, sensor) counters across blocks."""
    import pandas as pd
    ser, sen = csv_stream.texts(b, cols["series"][0]), csv_stream.texts(b, cols["sensor"][0])
    _first_bad(path, b, ser == "", lambda i: "column 'series' is empty")
    _first_bad(path, b, sen == "", lambda i: "column 'sensor' is empty")
    if sensors is not None:
        _first_bad(path, b, ~pd.Series(sen).isin(list(sensors)).to_numpy(),
                   lambda i: f"unknown sensor {sen[i]!r}; the model has {', '.join(sensors)}")
    s_code, k_code = _codes(ser, state["series"]), _codes(sen, state["sensors"])
    if "index" in cols:
        t = csv_stream.texts(b, cols["index"][0])
        _first_bad(path, b, ~pd.Series(t).str.fullmatch(r"[+-]?\d+").to_numpy(bool),
                   lambda i: f"column 'index': {t[i]!r} is not an integer")
        idx = t.astype(np.int64)
        _first_bad(path, b, idx < 1, lambda i: f"column 'index' is 1-based, got {idx[i]}")
    else:                                  # order of appearance per (series, sensor)
        keys = s_code * (1 << 24) + k_code
        uk, inv, cnt = np.unique(keys, return_inverse=True, return_counts=True)
        before = np.array([state["count"].get(k, 0) for k in uk.tolist()], np.int64)
        idx = pd.Series(keys).groupby(keys).cumcount().to_numpy() + before[inv] + 1
        state["count"].update(zip(uk.tolist(), (before + cnt).tolist()))
    cell = partial(_number, path)
    num = partial(csv_stream.numbers, b, cell=cell, max_magnitude=MAX_MAGNITUDE)
    qs = num(cols["set_force"][0], cols["set_force"][1], allow_missing=False)
    qa = (num(cols["actual_force"][0], cols["actual_force"][1], allow_missing=False) if "actual_force" in cols
          else np.full(qs.shape, np.nan))
    v = num(cols[value_column][0], cols[value_column][1])
    return dict(line=b.lines, series_code=s_code.astype(np.int32), index=idx.astype(np.int32),
                sensor_code=k_code.astype(np.int32), set_force=qs, actual_force=qa, value=v)


def _tidy_rows(path: Path, header: list, cols: dict, offset: int, value_column: str, sensors) -> _TidyTable:
    """The data rows of the tidy table, read block by block (:mod:`mudoe.csv_stream`)."""
    numeric = {cols[r][0]: True for r in ("set_force", "actual_force", value_column) if r in cols}
    state = dict(series={}, sensors={}, count={})
    parts = [_tidy_block(path, b, cols, value_column, sensors, state)
             for b in csv_stream.blocks(path, len(header), numeric, offset=offset)]
    if not parts:
        raise DataFileError(f"{path}: no data rows after the header")
    arrays = {}
    for name in _BLOCK_COLUMNS:            # one column at a time, freeing the blocks' pieces
        arrays[name] = np.concatenate([p.pop(name) for p in parts])
    return _TidyTable(**arrays, series=list(state["series"]), sensors=list(state["sensors"]))


def _close(a, b) -> np.ndarray:
    """math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-9) elementwise."""
    return np.abs(a - b) <= np.maximum(1e-9 * np.maximum(np.abs(a), np.abs(b)), 1e-9)


def _tidy_arrays(path: Path, t: _TidyTable, sens: tuple):
    """(q_set (n_q,), q_actual (n_M, n_q), z (n_M, n_q, n_S)) in the file's units; NaN where absent."""
    n_M, n_q, n_S = len(t.series), int(t.index.max()), len(sens)
    k = np.array([sens.index(s) for s in t.sensors], np.int64)[t.sensor_code]
    j = t.index.astype(np.int64) - 1
    lin = (t.series_code.astype(np.int64) * n_q + j) * n_S + k
    order = np.argsort(lin, kind="stable")
    dup = order[1:][lin[order][1:] == lin[order][:-1]]
    if dup.size:
        r = int(dup.min())
        raise DataFileError(f"{path}:{t.line[r]}: duplicate row for series {t.series[t.series_code[r]]!r}, index "
                            f"{t.index[r]}, sensor {sens[k[r]]!r}")
    q_set = np.full(n_q, np.nan)
    uj, first = np.unique(j, return_index=True)
    q_set[uj] = t.set_force[first]
    bad = np.flatnonzero(~_close(t.set_force, q_set[j]))
    if bad.size:
        r = int(bad[0])
        raise DataFileError(f"{path}:{t.line[r]}: set force {t.set_force[r]:g} of index {t.index[r]} differs from "
                            f"{q_set[j[r]]:g} given earlier for the same index")
    q_act = np.full(n_M * n_q, np.nan)
    pair = t.series_code.astype(np.int64) * n_q + j
    up, first = np.unique(pair, return_index=True)
    q_act[up] = t.actual_force[first]
    bad = np.flatnonzero(~_close(t.actual_force, q_act[pair]) & ~np.isnan(t.actual_force))
    if bad.size:
        r = int(bad[0])
        raise DataFileError(f"{path}:{t.line[r]}: actual force {t.actual_force[r]:g} differs from "
                            f"{q_act[pair[r]]:g} given for another sensor of series {t.series[t.series_code[r]]!r}, "
                            f"index {t.index[r]}")
    z = np.full(n_M * n_q * n_S, np.nan)
    z[lin] = t.value
    return q_set, q_act.reshape(n_M, n_q), z.reshape(n_M, n_q, n_S)


def read_tidy_layout(path, displacement_unit: str = "um", force_unit: str = "N", value_column: str = "value",
                     sensors: Sequence[str] | None = None, units: DataUnits | None = None) -> Campaign:
    """Read the tidy long table (one row per series, set point and sensor).

    Parameters
    ----------
    path : path
    displacement_unit, force_unit : str
        Declared units (a unit suffix in a column name must agree).
    value_column : {"value", "raw"}
        Which reading column to use.
    sensors : sequence of str, optional
        Expected sensors (order of the result); a sensor in the file outside this list is an error.
    units : DataUnits, optional
        Any units (:func:`study_units`; needs ``sensors``); default force_unit / displacement_unit.

    Raises
    ------
    DataFileError
        Missing file or column, ragged row, text in a numeric column (file and line), duplicate
        rows, unknown sensor, set forces that differ between series.
    """
    path = Path(path)
    header, offset = csv_stream.read_header(path)
    legacy = units is None
    if legacy:
        units = DataUnits.legacy(displacement_unit, force_unit, 1)
    cols = _tidy_columns(path, header, value_column, units)
    table = _tidy_rows(path, header, cols, offset, value_column, sensors)
    order_series, order_sensors = table.series, table.sensors
    sens = tuple(sensors) if sensors is not None else tuple(order_sensors)
    if legacy:
        units = DataUnits.legacy(displacement_unit, force_unit, len(sens))
    absent = [s for s in sens if s not in order_sensors]
    if absent:
        raise DataFileError(f"{path}: no rows for sensor(s) {', '.join(absent)}")
    q_set, q_act, z = _tidy_arrays(path, table, sens)
    q_set = units.q_from_column(q_set, cols["set_force"][2])           # a header in lbf, K, ...: pint
    if "actual_force" in cols:
        q_act = units.q_from_column(q_act, cols["actual_force"][2])
    if np.isnan(q_set).any():
        j = int(np.flatnonzero(np.isnan(q_set))[0])
        raise DataFileError(f"{path}: no row for set-point index {j + 1}")
    has_actual = "actual_force" in cols
    if has_actual and np.isnan(q_act).any():
        i, j = np.argwhere(np.isnan(q_act))[0]
        raise DataFileError(f"{path}: no actual force for series {order_series[i]!r}, index {j + 1}")
    return Campaign(q_set=units.q_to_model(q_set), q_actual=units.q_to_model(q_act) if has_actual else None,
                    z=units.z_to_model(z), sensors=sens,
                    series=tuple(order_series), files=(str(path),), source="CSV, tidy layout",
                    sha256=sha256_files([path]))


def write_tidy_layout(path, q_set, z, sensors: Sequence[str], displacement_unit: str = "um",
                      force_unit: str = "N", series: Sequence[str] | None = None, q_actual=None,
                      units: DataUnits | None = None) -> Path:
    """Write z, q_set (model units: mm, N, or ``units``) as the tidy long table (atomically, 17 digits).

    The value column carries the unit when every sensor has the same file unit (``value_um``),
    else it is ``value`` (each sensor in its declared unit).
    """
    if units is None:
        units = DataUnits.legacy(displacement_unit, force_unit, len(sensors))
    z = units.z_to_file(z)
    q_set = units.q_to_file(np.asarray(q_set, float).ravel())
    n_M = z.shape[0]
    series = list(series) if series is not None else [str(i + 1) for i in range(n_M)]

    def fmt(v):
        return "NaN" if not np.isfinite(v) else repr(float(v))

    head = ["series", "index", _with_unit("set_" + units.input_name, units.input_file)]
    if q_actual is not None:
        head.append(_with_unit("actual_" + units.input_name, units.input_file))
        qa = units.q_to_file(q_actual)
    same = set(units.output_file)
    head += ["sensor", _with_unit("value", same.pop() if len(same) == 1 else "")]
    lines = [",".join(head)]
    for i in range(n_M):
        for j in range(q_set.size):
            for k, s in enumerate(sensors):
                row = [series[i], str(j + 1), fmt(q_set[j])]
                if q_actual is not None:
                    row.append(fmt(qa[i, j]))
                row += [s, fmt(z[i, j, k])]
                lines.append(",".join(row))
    return atomic_write_text(path, "\n".join(lines) + "\n")


# ---------------------------------------------------------------------------- from a config
def _force_correct(c: Campaign, where: str) -> Campaign:
    if c.q_actual is None:
        raise DataFileError(f"{where}: force_correction = true needs actual forces (tidy column actual_force_<unit> "
                            "or [data] actual_forces_file)")
    qd, qa = c.q_set[None, :], c.q_actual
    if np.any((qa <= 0) & (qd > 0)):
        i, j = np.argwhere((qa <= 0) & (qd > 0))[0]
        raise DataFileError(f"{where}: actual force {qa[i, j]:g} N of series {c.series[i]!r} at set point "
                            f"{j + 1} is not positive; cannot apply z * q_set / q_actual")
    factor = np.where(qd > 0, qd / np.where(qa > 0, qa, 1.0), 1.0)
    return replace(c, z=c.z * factor[:, :, None], notes=c.notes + ("force correction z * q_set / q_actual applied",))


def load_campaign(cfg: StudyConfig, sensors: Sequence[str], units: DataUnits | None = None) -> Campaign:
    """The campaign of a study in the model's units, with every series (the study's subset is applied later).

    Parameters
    ----------
    cfg : StudyConfig
    sensors : sequence of str
        The model's sensors (order of z).
    units : DataUnits, optional
        File and model units (:func:`study_units`); default the press's (force_unit and
        displacement_unit in the files, N and mm in the model).
    """
    if units is None:
        units = DataUnits.legacy(cfg.data.displacement_unit, cfg.data.force_unit, len(sensors))
    d = cfg.data
    if d.source == "prototype":
        return virtual_prototype().campaign(d, sensors)
    base = cfg.resolve(d.directory)
    if d.layout == "paper":
        files = {}
        for s in sensors:
            files[s] = base / d.files.get(s, f"measurements_{s}.csv")
        extra = [s for s in d.files if s not in sensors]
        if extra:
            raise DataFileError(f"{cfg.path}: [data.files] names unknown sensor(s) {', '.join(extra)}; the model "
                                f"has {', '.join(sensors)}")
        c = read_paper_layout(files, actual_forces_file=base / d.actual_forces_file if d.actual_forces_file
                              else None, units=units)
    else:
        c = read_tidy_layout(base / d.file, value_column=d.value_column, sensors=sensors, units=units)
    if d.force_correction:
        c = _force_correct(c, cfg.path)
    absurd = absurd_reading_message(c, units, cfg.path)
    if absurd:
        raise DataFileError(absurd)
    return c
