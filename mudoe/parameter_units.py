"""[[parameters]] in the model's units: start and bounds converted by pint (issue 20 item 6).

A [[parameters]] ``unit`` of the model's dimension (E_a in J/mol for a model in kJ/mol) is
converted, x_model = f x_config (+ offset for temperatures, :func:`mudoe.units.convert`); a unit of
another dimension is a :class:`mudoe.config.ConfigError` naming the parameter and both units.
"""
from __future__ import annotations

import dataclasses
import math

from models.contract import Model

from .config import ConfigError, StudyConfig
from .units import UnitError, convert

__all__ = ["model_parameters"]


def model_parameters(cfg: StudyConfig, m: Model) -> tuple:
    """The [[parameters]] entries with start and bounds in the model's units (converted by pint)."""
    units = dict(zip(m.param_names, (p.unit for p in m.params)))
    return tuple(_parameter_in_model_unit(cfg, pc, units.get(pc.name, "")) for pc in cfg.parameters)


def _parameter_in_model_unit(cfg: StudyConfig, pc, own: str):
    """``pc`` (a [[parameters]] entry) with start and bounds in the model's unit ``own`` (pint's conversion).

    x_model = f x_config (+ offset for temperatures); a unit of another dimension is a ConfigError.
    """
    if not pc.unit or not own or pc.unit == own:
        return pc
    try:
        conv = [float(convert(v, pc.unit, own)) if math.isfinite(v) else v for v in (pc.start, pc.lower, pc.upper)]
    except UnitError as exc:
        raise ConfigError(f"{cfg.path}: [[parameters]] {pc.name}: unit {pc.unit!r} but the model declares {own!r}: "
                          f"{exc}; give the parameter in a unit of the model's dimension (or drop the key)") from None
    return dataclasses.replace(pc, start=conv[0], lower=conv[1], upper=conv[2], unit=own)
