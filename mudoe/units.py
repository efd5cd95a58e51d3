"""The unit table: every unit a data file or a config may declare, and the one conversion.

A value v in unit u is ``factor(u) * v + offset(u)`` in the SI unit of u's dimension
(kelvin for temperatures: degC has offset 273.15); converting from unit a to unit b is
``(factor(a) * v + offset(a) - offset(b)) / factor(b)``.  The empty unit ``""`` means
"not declared" and converts only to itself.  Force and displacement (N, kN, mm, um, m) are one
case of the table, not a special one.
"""
from __future__ import annotations

import numpy as np

__all__ = ["UNITS", "UnitError", "dimension", "convert", "known_units", "same_dimension"]

#: unit: (dimension, factor to the SI unit, offset in the SI unit)
UNITS = {
    "": ("undeclared", 1.0, 0.0), "1": ("dimensionless", 1.0, 0.0), "%": ("dimensionless", 1e-2, 0.0),
    # length
    "m": ("length", 1.0, 0.0), "cm": ("length", 1e-2, 0.0), "mm": ("length", 1e-3, 0.0),
    "um": ("length", 1e-6, 0.0), "nm": ("length", 1e-9, 0.0), "km": ("length", 1e3, 0.0),
    "in": ("length", 0.0254, 0.0),
    # force
    "N": ("force", 1.0, 0.0), "kN": ("force", 1e3, 0.0), "mN": ("force", 1e-3, 0.0), "MN": ("force", 1e6, 0.0),
    # temperature
    "K": ("temperature", 1.0, 0.0), "degC": ("temperature", 1.0, 273.15),
    "degF": ("temperature", 5.0 / 9.0, 273.15 - 32.0 * 5.0 / 9.0),
    # amount concentration (SI: mol/m3)
    "mol/m3": ("concentration", 1.0, 0.0), "mol/L": ("concentration", 1e3, 0.0), "M": ("concentration", 1e3, 0.0),
    "mmol/L": ("concentration", 1.0, 0.0), "mM": ("concentration", 1.0, 0.0), "umol/L": ("concentration", 1e-3, 0.0),
    # time
    "s": ("time", 1.0, 0.0), "ms": ("time", 1e-3, 0.0), "min": ("time", 60.0, 0.0), "h": ("time", 3600.0, 0.0),
    # pressure
    "Pa": ("pressure", 1.0, 0.0), "kPa": ("pressure", 1e3, 0.0), "MPa": ("pressure", 1e6, 0.0),
    "bar": ("pressure", 1e5, 0.0),
    # mass
    "kg": ("mass", 1.0, 0.0), "g": ("mass", 1e-3, 0.0), "mg": ("mass", 1e-6, 0.0),
    # electric
    "V": ("voltage", 1.0, 0.0), "mV": ("voltage", 1e-3, 0.0), "A": ("current", 1.0, 0.0),
    "mA": ("current", 1e-3, 0.0),
    # angle
    "rad": ("angle", 1.0, 0.0), "deg": ("angle", np.pi / 180.0, 0.0),
}


class UnitError(ValueError):
    """An unknown unit, or a conversion between different dimensions (the message names both)."""


def known_units() -> tuple:
    """The declared-unit names of the table (``""`` excluded)."""
    return tuple(u for u in UNITS if u)


def dimension(unit: str) -> str:
    """The dimension of ``unit`` ("length", "temperature", ...)."""
    if unit not in UNITS:
        raise UnitError(f"unknown unit {unit!r}; known units: {', '.join(known_units())}")
    return UNITS[unit][0]


def same_dimension(a: str, b: str) -> bool:
    """Whether values in unit ``a`` can be converted to unit ``b``."""
    return a == b or (dimension(a) == dimension(b) and dimension(a) != "undeclared")


def convert(values, from_unit: str, to_unit: str, difference: bool = False):
    """``values`` in ``from_unit`` expressed in ``to_unit`` (an affine map for temperatures).

    With ``difference=True`` the values are differences or standard deviations (no offset:
    a sigma of 1 degC is 1 K).
    """
    if from_unit == to_unit:
        return values
    if not same_dimension(from_unit, to_unit):
        raise UnitError(f"cannot convert {from_unit or 'an undeclared unit'} to {to_unit or 'an undeclared unit'}: "
                        f"{dimension(from_unit)} is not {dimension(to_unit)}")
    _, fa, oa = UNITS[from_unit]
    _, fb, ob = UNITS[to_unit]
    if difference:
        return np.asarray(values, float) * (fa / fb) if not np.isscalar(values) else values * (fa / fb)
    v = np.asarray(values, float) * fa + (oa - ob)
    out = v / fb
    return float(out) if np.isscalar(values) else out
