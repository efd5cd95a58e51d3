"""The schema helpers of a study config: how a section's field declares its TOML key.

A section dataclass (:mod:`mudoe.config_sections`) *is* the schema: its fields are the allowed keys,
a field's default the key's default.  :func:`config_key` adds how the TOML value is checked
(choices, :class:`Bounds`, infinite allowed, a unit of a dimension); :func:`setting` declares a key
backed by a field of a library's settings dataclass (its default, unless the study has its own in
:data:`STUDY_DEFAULTS`, and its validation are that dataclass's).
"""
from __future__ import annotations

from dataclasses import MISSING, Field, dataclass, field, fields

from identification.studies.montecarlo import MonteCarloSettings

__all__ = ["STUDY_DEFAULTS", "Bounds", "POSITIVE", "NON_NEGATIVE", "OPEN_UNIT", "config_key", "setting",
           "settings_keys", "settings_values", "settings_class"]

#: The study's own defaults where they differ from the settings dataclass's, keyed by
#: (settings dataclass, field); every other settings-backed key takes the dataclass's default.
#: ``mudoe validate`` has always run a quick size study, 200 replications from seed 1, while
#: :class:`identification.studies.montecarlo.MonteCarloSettings` defaults to 2000 replications from
#: seed 20261121; a config without these keys keeps giving the numbers it gave before.
STUDY_DEFAULTS = {(MonteCarloSettings, "n_rep"): 200, (MonteCarloSettings, "seed"): 1}


@dataclass(frozen=True)
class Bounds:
    """Allowed numbers: ``v >= low`` (``v > low`` if ``strict``) and, if ``high`` is given, ``v < high``."""

    low: float
    strict: bool = False
    high: float | None = None

    def admits(self, v) -> bool:
        above = v > self.low if self.strict else v >= self.low
        return above and (self.high is None or v < self.high)

    def __str__(self) -> str:
        if self.high is not None:
            return f"lie in ({self.low}, {self.high})"
        if self.low == 0:
            return "be positive" if self.strict else "be non-negative"
        return f"be {'greater than' if self.strict else 'at least'} {self.low}"


POSITIVE = Bounds(0, strict=True)
NON_NEGATIVE = Bounds(0)
OPEN_UNIT = Bounds(0, strict=True, high=1)


def config_key(default, *, choices=None, bounds=None, allow_inf=False, unit=None) -> Field:
    """A config key: its default and how its value is checked (choices, bounds, infinite allowed; ``unit``:
    the value is a unit pint knows, ``"any"`` or of the named dimension, e.g. ``"length"``)."""
    return field(default=default, metadata={"choices": choices, "bounds": bounds, "allow_inf": allow_inf,
                                            "unit": unit})


def _field_of(cls, name: str) -> Field:
    for f in fields(cls):
        if f.name == name:
            return f
    raise AttributeError(f"{cls.__name__} has no field {name!r}")


def setting(settings: type, name: str, bounds: Bounds | None = None) -> Field:
    """A config key backed by field ``name`` of the settings dataclass ``settings``.

    Its default is that field's default (or the study's own, :data:`STUDY_DEFAULTS`); its value is
    validated by ``settings`` itself; ``bounds`` only for what ``settings`` does not check.
    """
    f = _field_of(settings, name)
    if f.default is MISSING:
        raise TypeError(f"name: {settings.__name__}.{name} has no plain default; back the key by a field "
                        "with one")
    default = STUDY_DEFAULTS.get((settings, name), f.default)
    return field(default=default, metadata={"settings": settings, "field": name, "bounds": bounds})


def settings_keys(section) -> dict:
    """``{TOML key: settings field}`` of a section (class or instance): its keys backed by a settings field."""
    return {f.name: f.metadata["field"] for f in fields(section) if "field" in f.metadata}


def settings_values(section) -> dict:
    """``{settings field: value}`` of a section instance: its settings-backed keys under the fields' names."""
    return {fld: getattr(section, key) for key, fld in settings_keys(section).items()}


def settings_class(section) -> type:
    return next(f.metadata["settings"] for f in fields(section) if "settings" in f.metadata)

