"""The units of a campaign's data: declared in the config and in the files' headers, resolved against the model's.

One home for the units of the data (:mod:`mudoe.data_io` reads the CSV files and calls these at two
points: the header of a column, and the one conversion of the readings to the model's units):

* :class:`DataUnits` -- the input's and each sensor's unit in the files and in the model, and the
  conversions between them (pint, :mod:`mudoe.units`);
* :func:`study_units` -- the :class:`DataUnits` of a study: file units from the config, model units
  from the model, every pair checked once (a unit declared nowhere is an error, never a default);
* :func:`split_unit`, :func:`column_unit` -- the unit a column name carries ("set_force_kN") and
  whether it agrees with the declared one.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .config import StudyConfig
from .config_errors import ConfigError, table_line
from .csv_stream import DataFileError
from .units import UnitError, check_unit, convert, dimension, same_dimension, unit_name

__all__ = ["DataUnits", "study_units", "split_unit", "column_unit"]


@dataclass(frozen=True)
class DataUnits:
    """The units of a campaign in its files and in the model: the one conversion of the data.

    Attributes
    ----------
    input_file, input_model : str       unit of the input (set point) in the files / in the model
    output_file, output_model : tuple   per sensor: unit of the readings in the files / in the model
    input_name : str                    name of the input column ("force" writes ``force_N``)
    input_key, output_key : str         the config keys that declare the file units (for messages)
    """

    input_file: str = "N"
    input_model: str = "N"
    output_file: tuple = ()
    output_model: tuple = ()
    input_name: str = "force"
    input_key: str = "force_unit"
    output_key: str = "displacement_unit"

    @classmethod
    def legacy(cls, displacement_unit: str, force_unit: str, n_sensors: int) -> "DataUnits":
        """Forces in ``force_unit`` and displacements in ``displacement_unit`` (any pint force / length
        unit, e.g. "N", "kN", "lbf" / "mm", "um", "m"), model in N and mm."""
        for key, unit, dim, ex in (("displacement_unit", displacement_unit, "length", "mm, um, m"),
                                   ("force_unit", force_unit, "force", "N, kN, lbf")):
            if not _is(unit, dim):
                raise DataFileError(f"{key}: {unit!r} is not a unit of {dim} (e.g. {ex})")
        return cls(force_unit, "N", (displacement_unit,) * n_sensors, ("mm",) * n_sensors)

    def q_from_column(self, q, unit: str):
        """Input values of a column in its own ``unit`` (its header's, :func:`column_unit`) in the files'
        input unit: pint's conversion (the values as given when the units agree)."""
        return convert(q, unit, self.input_file)

    def q_to_model(self, q):
        return convert(np.asarray(q, float), self.input_file, self.input_model)

    def q_to_file(self, q):
        return convert(np.asarray(q, float), self.input_model, self.input_file)

    def z_to_model(self, z):
        z = np.array(z, float)
        for k, (a, b) in enumerate(zip(self.output_file, self.output_model)):
            z[..., k] = convert(z[..., k], a, b)
        return z

    def z_to_file(self, z):
        z = np.array(z, float)
        for k, (a, b) in enumerate(zip(self.output_file, self.output_model)):
            z[..., k] = convert(z[..., k], b, a)
        return z

    def sigma_to_model(self, k: int, sigma: float) -> float:
        """A standard deviation of sensor k from the file unit to the model unit (no offset)."""
        return float(convert(sigma, self.output_file[k], self.output_model[k], difference=True))

    def input_names(self) -> set:
        """Accepted (lower-case) names of the input column, without a unit suffix."""
        n = self.input_name.lower()
        return {"set_force", "input", "set_input", "q", "q_p", "load", n, "set_" + n}

    def actual_names(self) -> set:
        n = self.input_name.lower()
        return {"actual_force", "actual_input", "actual_" + n}


def _is(unit: str, dim: str) -> bool:
    """Whether ``unit`` ("" = undeclared; an unknown unit is not) is a unit of dimension ``dim``."""
    try:
        return bool(unit) and dimension(unit) == dim
    except UnitError:
        return False


def _input_file_unit(cfg: StudyConfig, model) -> tuple:
    """(file unit, config key) of the input column (:func:`study_units`)."""
    q_model = model.input_units[0] if model.input_units else ""
    if cfg.data.input_unit:
        return cfg.data.input_unit, "input_unit"
    if _is(q_model, "force"):
        return cfg.data.force_unit, "force_unit"
    if q_model:
        return q_model, "input_unit"
    raise ConfigError(f"{cfg.path}: [data] input_unit: the input {model.inputs[0]!r} has no unit (the model declares "
                      "none); declare the unit of the input column, e.g. input_unit = \"N\" or \"degC\" (any unit "
                      "pint knows; \"1\" for a dimensionless input)")


def _sensor_file_unit(cfg: StudyConfig, s: str, u_model: str) -> str:
    """The file unit of sensor ``s`` (:func:`study_units`); never a silent default for an undeclared one."""
    own = next((sc.unit for sc in cfg.sensors if sc.name == s), "")
    if own or cfg.data.output_unit:
        return own or cfg.data.output_unit
    if _is(u_model, "length"):
        return cfg.data.displacement_unit
    if u_model:
        return u_model
    names = [sc.name for sc in cfg.sensors]
    line = table_line(cfg.text, "sensors", names.index(s), "") if s in names else None    # the sensor's entry
    raise ConfigError(f"{cfg.path}{f':{line}' if line else ''}: [[sensors]] unit: sensor {s!r} has no unit (the model "
                      "declares none); declare the unit of its readings, e.g. unit = \"m/s^2\" in its [[sensors]] "
                      "entry or [data] output_unit (any unit pint knows; \"1\" for a dimensionless reading)")


def study_units(cfg: StudyConfig, model) -> DataUnits:
    """The :class:`DataUnits` of a study: file units from the config, model units from the model.

    File unit of the input: ``[data] input_unit``, else ``force_unit`` when the model's input is a
    force, else the model's unit.  File unit of sensor k: its [[sensors]] ``unit``, else
    ``[data] output_unit``, else ``displacement_unit`` when the model's unit is a length, else the
    model's unit.  A unit declared nowhere (model and config) is an error, never a default.  Model
    units: the model's declared ones; an undeclared one is the file's unit (no conversion).

    Raises
    ------
    ConfigError
        A unit is declared nowhere, unknown to pint, or of another dimension than the model's.
    """
    d = cfg.data
    q_model = model.input_units[0] if model.input_units else ""
    q_file, q_key = _input_file_unit(cfg, model)
    out_file = [_sensor_file_unit(cfg, s, u) for s, u in zip(model.sensors, model.sensor_units)]
    out_model = [u or f for u, f in zip(model.sensor_units, out_file)]
    units = DataUnits(q_file, q_model or q_file, tuple(out_file), tuple(out_model),
                      input_name=model.inputs[0] if d.input_unit or q_key == "input_unit" else "force",
                      input_key=q_key, output_key="output_unit" if d.output_unit else "displacement_unit")
    pairs = [(q_file, units.input_model, f"[data] {q_key}", f"input {model.inputs[0]!r}")]
    pairs += [(a, b, f"[[sensors]] unit / [data] {units.output_key}", f"sensor {s!r}")
              for s, a, b in zip(model.sensors, out_file, out_model)]
    for a, b, key, what in pairs:
        try:
            check_unit(b)
        except UnitError as exc:
            raise ConfigError(f"{cfg.path}: the model declares unit {b!r} for {what}: {exc}") from None
        try:
            convert(1.0, a, b)
        except UnitError as exc:
            raise ConfigError(f"{cfg.path}: {key}: {what}: {exc}") from None
    return units


def split_unit(name: str, bases=()) -> tuple[str, str | None]:
    """'set_force_kN' -> ('set_force', 'kN'): a known column name ``bases`` (lower case) and the unit
    after it ("_unit", " unit", "[unit]" or "(unit)"); other names -> (name lower-cased, None).

    The unit is returned as written (checked by :func:`column_unit`); matching the known names
    first keeps a name such as "set_T" from being read as a unit (T is the tesla).
    """
    n = name.strip()
    low = n.lower()
    for b in sorted(bases, key=len, reverse=True):
        if low == b:
            return b, None
        if low.startswith(b) and len(n) > len(b) + 1 and n[len(b)] in "_ [(":
            rest = n[len(b):].strip(" _")
            if rest[:1] in "[(" and rest[-1:] in "])":
                rest = rest[1:-1].strip()
            return b, rest or None
    return low, None


def column_unit(path, col, found, declared, what, convertible: bool = False) -> str:
    """The unit of column ``col``: ``found`` in its header, else ``declared``.

    A header unit must be a unit pint knows and of the declared unit's dimension; unless
    ``convertible`` (the values are then converted by pint), it must be the declared unit itself.
    """
    if found is None or found == declared:
        return declared
    try:
        check_unit(found)
    except UnitError as exc:
        raise DataFileError(f"{path}:1: column {col!r}: {exc}") from None
    if not declared:
        raise DataFileError(f"{path}:1: column {col!r} is in {found} but the config declares no unit for it; "
                            f"declare [data] {what} = {found!r}")
    if not same_dimension(found, declared):
        raise DataFileError(f"{path}:1: column {col!r} is in {found} ({unit_name(found)}, a unit of "
                            f"{dimension(found)}) but the config declares {what} = {declared!r}, a unit of "
                            f"{dimension(declared)}; fix the header or [data] {what}")
    if convertible or convert(1.0, found, declared) == 1.0 and convert(0.0, found, declared) == 0.0:
        return found
    raise DataFileError(f"{path}:1: column {col!r} is in {found} but the config declares "
                        f"{what} = {declared!r}; fix the header or [data] {what}")
