"""Readers of the TOML values of a study config: one validator each, errors naming file, line and key.

:func:`read_value` reads the value of one key by its schema field (:mod:`mudoe.config_schema`): the
annotation says the type (``X | None`` is read as X: TOML has no null), the metadata the choices,
bounds and unit; :func:`read_table` reads every key of a table; :func:`validated` lets a section's
settings dataclass check the keys it backs.  ``ctx`` is the :class:`mudoe.config_errors.ConfigContext`
of the file (its ``error`` names the line).
"""
from __future__ import annotations

import math
from dataclasses import MISSING, Field, fields

from .config_errors import ConfigContext
from .config_schema import settings_class, settings_keys, settings_values
from .units import UnitError, check_unit, dimension

__all__ = ["check_keys", "require", "tables", "one_of", "unique", "read_str", "read_str_list", "read_value",
           "read_table", "validated"]


def check_keys(ctx: ConfigContext, section: str, table, schema) -> None:
    """``table`` is a TOML table whose keys are fields of the dataclass ``schema``."""
    if not isinstance(table, dict):
        raise ctx.error("", section, f"expected a table, got {type(table).__name__}")
    allowed = {f.name for f in fields(schema)}
    for k in table:
        if k not in allowed:
            raise ctx.error(section, k, f"unknown key {k!r}; allowed keys: {', '.join(sorted(allowed))}")


def require(ctx: ConfigContext, section: str, table: dict, schema, what: str) -> None:
    """Every field of ``schema`` without a default is a key of ``table``."""
    need = [f.name for f in fields(schema) if f.default is MISSING and f.default_factory is MISSING]
    for k in need:
        if k not in table:
            raise ctx.error(section, next(iter(table), ""), f"{what} needs {', '.join(need)}; add {k}")


def tables(ctx: ConfigContext, section: str, key: str, arr) -> list:
    """An array of tables (``[[section.key]]``)."""
    if not isinstance(arr, list) or not all(isinstance(x, dict) for x in arr):
        raise ctx.error(section, key, f"expected [[{section + '.' if section else ''}{key}]] tables")
    return arr


def _names(values) -> str:
    return ", ".join(repr(v) if " " in str(v) else str(v) for v in values)


def one_of(ctx: ConfigContext, section: str, key: str, value, known, what: str = "value", note: str = "") -> None:
    """``value`` is one of ``known``; the message lists them (and ``note`` says what they are)."""
    if value not in known:
        raise ctx.error(section, key, f"unknown {what} {value!r}; use one of: {_names(known)}"
                        + (f" ({note})" if note else ""))


def unique(ctx: ConfigContext, section: str, key: str, names, what: str) -> None:
    if len(set(names)) != len(names):
        raise ctx.error(section, key, f"a {what} is listed twice: {list(names)}")


def _num(ctx, section, key, v, *, integer=False, bounds=None, allow_inf=False, what=""):
    """A TOML number (an integer if ``integer``), finite unless ``allow_inf``, within ``bounds``."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ctx.error(section, key, f"expected a number, got {v!r}")
    if integer and not isinstance(v, int):
        raise ctx.error(section, key, f"expected an integer, got {v!r}")
    if math.isnan(v) or (math.isinf(v) and not allow_inf):
        raise ctx.error(section, key, f"expected a finite number, got {v!r}")
    if bounds is not None and not bounds.admits(v):
        raise ctx.error(section, key, f"{what}must {bounds}, got {v!r}")
    return v


def read_str(ctx, section, key, v, choices=None):
    if not isinstance(v, str):
        raise ctx.error(section, key, f"expected a string, got {v!r}")
    if choices is not None:
        one_of(ctx, section, key, v, choices)
    return v


def _unit(ctx, section, key, v, dim):
    """A unit pint knows ("" = undeclared, unless ``dim`` names the dimension it must have)."""
    try:
        check_unit(v)
    except UnitError as exc:
        raise ctx.error(section, key, str(exc)) from None
    if dim != "any" and (v == "" or dimension(v) != dim):
        got = "nothing" if v == "" else f"{v!r}, a unit of {dimension(v)}"
        raise ctx.error(section, key, f"expected a unit of {dim} (e.g. {_DIM_EXAMPLES.get(dim, '')}), got {got}")
    return v


_DIM_EXAMPLES = {"length": "'mm', 'um', 'm', 'in'", "force": "'N', 'kN', 'lbf'"}


def _bool(ctx, section, key, v):
    if not isinstance(v, bool):
        raise ctx.error(section, key, f"expected true or false, got {v!r}")
    return v


def _int_list(ctx, section, key, v):
    if not isinstance(v, list) or not all(isinstance(x, int) and not isinstance(x, bool) for x in v):
        raise ctx.error(section, key, f"expected a list of integer indices (0-based), got {v!r}")
    if any(x < 0 for x in v):
        raise ctx.error(section, key, f"indices are 0-based and non-negative, got {v!r}")
    return tuple(v)


def read_str_list(ctx, section, key, v):
    if isinstance(v, str):
        v = [v]
    if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
        raise ctx.error(section, key, f"expected a list of strings, got {v!r}")
    return tuple(v)


def _str_table(ctx, section, key, v):
    if not isinstance(v, dict) or not all(isinstance(x, str) for x in v.values()):
        raise ctx.error(section, key, f"expected a table {{sensor = \"file.csv\"}}, got {v!r}")
    return dict(v)


def _float_list(ctx, section, key, v):
    """A non-empty TOML list of finite numbers (to give none, leave the key out)."""
    if not isinstance(v, list) or not v:
        raise ctx.error(section, key, f"expected a non-empty list of numbers, got {v!r}")
    for x in v:
        _num(ctx, section, key, x)
    return tuple(float(x) for x in v)


def _float_table(ctx, section, key, v):
    if not isinstance(v, dict):
        raise ctx.error(section, key, f"expected a table {{name = value}}, got {v!r}")
    for x in v.values():
        _num(ctx, section, key, x)
    return {k: float(x) for k, x in v.items()}


#: readers of the other annotations of schema fields (``X | None`` is read as X: TOML has no null)
_READERS = {"bool": _bool, "tuple[str, ...]": read_str_list, "tuple[int, ...]": _int_list, "dict[str, str]": _str_table,
            "tuple[float, ...]": _float_list, "dict[str, float]": _float_table}


def read_value(ctx: ConfigContext, section: str, f: Field, v, what: str = ""):
    """The TOML value ``v`` of the key ``f`` (a schema field), checked by its annotation and metadata.

    Numbers keep their TOML type (an integer ``sigma = 5`` stays 5); ``what`` prefixes a bounds message.
    """
    kind, meta = f.type.removesuffix(" | None"), f.metadata
    if kind in ("int", "float"):
        return _num(ctx, section, f.name, v, integer=kind == "int", bounds=meta.get("bounds"),
                    allow_inf=meta.get("allow_inf", False), what=what)
    if kind == "str":
        v = read_str(ctx, section, f.name, v, meta.get("choices"))
        return v if meta.get("unit") is None else _unit(ctx, section, f.name, v, meta["unit"])
    if kind not in _READERS:
        raise TypeError(f"{section}.{f.name}: no reader for a {f.type!r} key")
    return _READERS[kind](ctx, section, f.name, v)


def read_table(ctx: ConfigContext, section: str, schema, table, skip=()) -> dict:
    """The keys of ``table`` (fields of ``schema``), each read by :func:`read_value`; ``skip``: read by the caller."""
    check_keys(ctx, section, table, schema)
    return {f.name: read_value(ctx, section, f, table[f.name]) for f in fields(schema)
            if f.name in table and f.name not in skip}


def validated(ctx: ConfigContext, section: str, cfg):
    """``cfg`` once its settings dataclass accepts the values of the keys it backs."""
    try:
        settings_class(cfg)(**settings_values(cfg))
    except (TypeError, ValueError) as exc:
        name, _, msg = str(exc).partition(": ")
        key = next((k for k, fld in settings_keys(cfg).items() if fld == name), "")
        raise ctx.error(section, key, msg if key else str(exc)) from None
    return cfg

