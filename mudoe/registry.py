"""The registry of the models shipped with mudoe: generic code looks a model up by its [model] name.

Every built-in model's knowledge lives in its own study module (the press: :mod:`mudoe.press`), which
describes it as a :class:`mudoe.builtin.BuiltinModel`; this module only lists them.  Generic code
asks :func:`builtin_model` (None for an own factory "package.module:function"), the default study's
model (:data:`DEFAULT_MODEL`), the variants and scenario names a config may use, and the virtual
prototype of ``[data] source = "prototype"``.
"""
from __future__ import annotations

from identification.studies.splits import splits_from_scenarios

from .builtin import BuiltinModel, VirtualPrototype
from .press import PRESS

__all__ = ["BUILTIN_MODELS", "DEFAULT_MODEL", "builtin_model", "default_model", "known_variants", "known_scenarios",
           "virtual_prototype", "scenario_splits", "simulate_refusal"]

#: the built-in models by [model] name
BUILTIN_MODELS = {m.name: m for m in (PRESS,)}

#: the [model] name of the default study (``configs/press.toml``): a config without [model] studies it
DEFAULT_MODEL = PRESS.name


def builtin_model(name: str) -> BuiltinModel | None:
    """The built-in model called ``name``, or None (an own model factory)."""
    return BUILTIN_MODELS.get(name)


def default_model() -> BuiltinModel:
    """The model of the default study (:data:`DEFAULT_MODEL`)."""
    return BUILTIN_MODELS[DEFAULT_MODEL]


def known_variants() -> dict:
    """Built-in models and their variants, ``{model name: (variant, ...)}``.

    The one place the config reads them (the press: friction variants M1, M2, M3).
    """
    return {name: m.variants for name, m in BUILTIN_MODELS.items()}


def known_scenarios() -> tuple:
    """Names of the built-in models' scenarios (``[splits] scenarios``; the paper's four press scenarios);
    the one place the config reads them."""
    return tuple(s for m in BUILTIN_MODELS.values() for s in m.scenarios)


def virtual_prototype() -> VirtualPrototype:
    """The virtual prototype that ``[data] source = "prototype"`` simulates (the default model's: the press's)."""
    return default_model().prototype


def scenario_splits(n_q: int, wanted) -> list:
    """The shipped scenario splits named in ``wanted`` (``[splits] scenarios``; "paper": all of a model's)
    over ``n_q`` set points."""
    out = []
    for m in BUILTIN_MODELS.values():
        names = m.scenarios if "paper" in wanted else wanted
        out += [sp for sp in splits_from_scenarios(m.scenario_rows, n_q) if sp.name in names]
    return out


def simulate_refusal(name: str) -> str | None:
    """Why ``mudoe simulate`` does not apply to the built-in model ``name`` (None: an own model, it does)."""
    if name not in BUILTIN_MODELS:
        return None
    return f"[simulate] is for own models; the {name} simulates its virtual prototype"
