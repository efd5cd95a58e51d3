"""The models of a study: every ``[model]`` variant built, bounded by ``[[parameters]]``, with units and start values.

Generic: a built-in model (the press) is built by its :class:`mudoe.builtin.BuiltinModel` (:mod:`mudoe.registry`),
any other by the factory ``"package.module:function"``.
"""
from __future__ import annotations

import copy
import dataclasses
from typing import Callable

import numpy as np

from models.contract import Model, ModelError
from models.labels import LabelledModel
from models.shipping import ModelSource

from .registry import builtin_model
from .checks import call_factory
from .config import ConfigError, StudyConfig, config_error
from .data_io import DataUnits
from .parameter_units import model_parameters
from .study_base import VariantModel, load_factory

__all__ = ["build_models", "apply_parameters", "declare_units", "config_start_values"]


def build_models(cfg: StudyConfig) -> dict:
    """{variant: VariantModel} of the config's variants: a :class:`models.Model` bounded by [[parameters]],
    a model of another kind (an ODE/DAE model) kept as built, without inputs (its study kind bounds it,
    :mod:`mudoe.kind`; :func:`mudoe.kind.study_kind` refuses what is no model)."""
    builtin = builtin_model(cfg.model.name)
    if builtin is not None:
        out = {}
        for v in cfg.model.variants:
            model, inputs_fn = builtin.build(v, cfg)
            out[v] = VariantModel(apply_parameters(cfg, model), inputs_fn)
        return out
    factory = _factory(cfg)
    out = {}
    for v in cfg.model.variants:
        m = call_factory(factory, cfg.model.name, v, lambda msg: config_error(cfg, "model", "name", msg))
        if isinstance(m, LabelledModel):
            m.origin = ModelSource(cfg.model.name, v)     # worker processes may rebuild it from here
        out[v] = VariantModel(apply_parameters(cfg, m), getattr(m, "mudoe_inputs", None)) if isinstance(m, Model) \
            else VariantModel(m)
    return out


def _factory(cfg: StudyConfig) -> Callable:
    return load_factory(cfg.model.name, f"{cfg.path}: [model] name")


def apply_parameters(cfg: StudyConfig, m: Model) -> Model:
    """A copy of the model with the config's parameter bounds."""
    if not cfg.parameters:
        return m
    names = [p.name for p in cfg.parameters]
    unknown = [n for n in names if n not in m.param_names]
    if unknown:
        raise ConfigError(f"{cfg.path}: [[parameters]] unknown parameter(s) {', '.join(unknown)}; the model has "
                          f"{', '.join(m.param_names)}")
    missing = [n for n in m.param_names if n not in names]
    if missing:
        raise ConfigError(f"{cfg.path}: [[parameters]] missing start value(s) for {', '.join(missing)}")
    cfg = dataclasses.replace(cfg, parameters=model_parameters(cfg, m))
    try:
        new = m.with_bounds({pc.name: (pc.lower, pc.upper) for pc in cfg.parameters})
    except ModelError as exc:
        raise ConfigError(f"{cfg.path}: [[parameters]] {exc}") from None
    units = {pc.name: pc.unit for pc in cfg.parameters if pc.unit}
    new.params = tuple(dataclasses.replace(p, unit=p.unit or units.get(p.name, "")) for p in new.params)
    return new


def declare_units(m: Model, units: DataUnits) -> Model:
    """The model with the data's model-side units where it declares none (for tables and the report)."""
    q_units = (units.input_model or m.input_units[0],) + tuple(m.input_units[1:])
    s_units = tuple(own or u for own, u in zip(m.sensor_units, units.output_model))
    if q_units == tuple(m.input_units) and s_units == tuple(m.sensor_units):
        return m
    new = copy.copy(m)
    new.input_units = tuple(own or u for own, u in zip(m.input_units, q_units))
    new.sensor_units = s_units
    return new


def config_start_values(cfg: StudyConfig, m: Model) -> np.ndarray:
    """The [[parameters]] start values of a model (else its ``p_nominal``)."""
    if cfg.parameters:
        d = {p.name: p.start for p in model_parameters(cfg, m)}
        return np.array([d[n] for n in m.param_names], float)
    nominal = getattr(m, "p_nominal", None)
    if nominal is None:
        raise ConfigError(f"{cfg.path}: [[parameters]] give start values for {', '.join(m.param_names)}")
    return np.asarray(nominal, float)

