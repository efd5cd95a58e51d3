"""Units through pint: every unit a data file, a config or a model may declare, and the one conversion.

A unit is any expression pint parses ("um", "N/mm", "m/s^2", "mol/L", "degC", "lbf", "kJ/mol",
"1/min", "%", "1" for dimensionless; "mol/m3" is read as mol/m^3).  Converting values from unit a
to unit b is pint's conversion ``Quantity(v, a).to(b)`` (an affine map for temperatures: degC
has offset 273.15 K); a difference or standard deviation converts by the linear part only (a
sigma of 1 degC is 1 K).  The empty unit ``""`` means "not declared": it converts only to
itself, and the study refuses data whose unit is nowhere declared (never a silent default).
Units of different dimensions (a parsec is a length, not a force) never convert.
"""
from __future__ import annotations

import re
from functools import lru_cache

import numpy as np

__all__ = ["UNITS", "UnitError", "dimension", "convert", "known_units", "same_dimension", "check_unit",
           "unit_name", "registry"]


@lru_cache(maxsize=1)
def registry():
    """The one unit registry of mudoe (pint's default definitions), built at first use: importing pint
    and reading its definitions takes about 0.5 s, which commands without units do not pay."""
    import pint
    return pint.UnitRegistry(autoconvert_offset_to_baseunit=False)


def _errors() -> tuple:
    import pint
    return (pint.errors.PintError, ValueError, TypeError, SyntaxError, AttributeError, KeyError)

#: names of common dimensions (for messages and the data rules): name -> a unit of that dimension
_NAMED = {"dimensionless": "1", "length": "m", "force": "N", "temperature": "K", "time": "s", "mass": "kg",
          "pressure": "Pa", "concentration": "mol/m^3", "voltage": "V", "current": "A", "energy": "J",
          "stiffness": "N/m", "frequency": "1/s", "velocity": "m/s", "acceleration": "m/s^2"}

#: a power written without "^" after a unit symbol: "m3" -> "m^3", "1/mm2" -> "1/mm^2"
_BARE_POWER = re.compile(r"(?<=[A-Za-zµ])([2-4])(?![\d.])")


class UnitError(ValueError):
    """An unknown unit, or a conversion between different dimensions (the message names both)."""


@lru_cache(maxsize=512)
def _parse(unit: str):
    if not isinstance(unit, str):
        raise UnitError(f"a unit must be a string, got {unit!r}")
    text = _BARE_POWER.sub(r"^\1", unit.strip())
    try:
        return registry().parse_units(text)
    except _errors() as exc:
        raise UnitError(f"unknown unit {unit!r} (pint does not know it: {type(exc).__name__}); use e.g. 'mm', 'N', "
                        "'m/s^2', 'mol/L', 'degC', or '1' for dimensionless") from None


def check_unit(unit: str) -> str:
    """``unit`` if it is ``""`` (undeclared) or a unit pint knows, else :class:`UnitError`."""
    if unit == "":
        return unit
    _parse(unit)
    return unit


def unit_name(unit: str) -> str:
    """pint's full name of ``unit`` ("um" -> "micrometer"; "" -> "undeclared")."""
    return "undeclared" if unit == "" else str(_parse(unit))


class _KnownUnits:
    """``u in UNITS``: whether pint knows the unit ``u`` (``""``, undeclared, included); iterates
    over a few common units (:func:`known_units`)."""

    def __contains__(self, unit) -> bool:
        try:
            check_unit(unit)
        except UnitError:
            return False
        return True

    def __iter__(self):
        return iter(known_units())


#: membership test of the units mudoe accepts (any unit pint knows)
UNITS = _KnownUnits()


def known_units() -> tuple:
    """Examples of accepted units for messages (every unit pint knows is accepted)."""
    return ("mm", "um", "m", "N", "kN", "lbf", "K", "degC", "mol/L", "mmol/L", "s", "min", "Pa", "bar", "V", "A",
            "rad", "deg", "%", "1", "m/s^2", "N/mm", "1/min", "kJ/mol")


@lru_cache(maxsize=512)
def _dimensionality(unit: str):
    return _parse(unit).dimensionality


def dimension(unit: str) -> str:
    """The dimension of ``unit``: a common name ("length", "force", "temperature", ...) or pint's
    dimensionality ("[length] / [time] ** 2"); ``""`` is "undeclared"."""
    if unit == "":
        return "undeclared"
    dim = _dimensionality(unit)
    for name, ref in _NAMED.items():
        if _dimensionality(ref) == dim:
            return name
    return dim


def same_dimension(a: str, b: str) -> bool:
    """Whether values in unit ``a`` can be converted to unit ``b``."""
    if a == b:
        return True
    if a == "" or b == "":
        return False
    return _dimensionality(a) == _dimensionality(b)


@lru_cache(maxsize=512)
def _factor(a: str, b: str) -> tuple:
    """(f, offset units): the linear factor of the conversion a -> b (pint's base-unit factors, offsets
    ignored) and whether either unit has an offset (degC, degF)."""
    fa, _ = registry().get_base_units(_parse(a))
    fb, _ = registry().get_base_units(_parse(b))
    zero = registry().Quantity(0.0, _parse(a)).to(_parse(b)).magnitude
    return float(fa) / float(fb), bool(zero != 0.0)


def convert(values, from_unit: str, to_unit: str, difference: bool = False):
    """``values`` in ``from_unit`` expressed in ``to_unit``: pint's conversion v_b = f v_a + o.

    f is the ratio of pint's base-unit factors; units with an offset (degC, degF) go through
    pint's ``Quantity(v, a).to(b)``.  With ``difference=True`` the values are differences or
    standard deviations (v_b = f v_a: a sigma of 1 degC is 1 K).  Raises :class:`UnitError` for
    an unknown unit or different dimensions.
    """
    if from_unit == to_unit:
        return values
    if not same_dimension(from_unit, to_unit):
        raise UnitError(f"cannot convert {from_unit or 'an undeclared unit'} to {to_unit or 'an undeclared unit'}: "
                        f"{dimension(from_unit)} is not {dimension(to_unit)}")
    factor, offset = _factor(from_unit, to_unit)
    scalar = np.isscalar(values)
    v = np.asarray(values, float)
    if offset and not difference:
        out = registry().Quantity(v, _parse(from_unit)).to(_parse(to_unit)).magnitude
    else:
        out = v * factor
    return float(out) if scalar else np.asarray(out, float)
