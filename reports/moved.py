"""The record types that moved out of :mod:`reports` (issue 28): their old names still work, with a warning.

The report owns no record type: the study fills records of :mod:`identification.studies.records` and
:mod:`oed.study_record`.  A module of :mod:`reports` that used to define one of them answers its old
name through :func:`moved`, which warns (DeprecationWarning, one release) and names the new home.
"""
from __future__ import annotations

import warnings

__all__ = ["moved"]


def moved(module: str, home, names):
    """A module ``__getattr__`` for ``module`` answering each of ``names`` from the module ``home``,
    with a DeprecationWarning that names ``home.name``; any other name raises AttributeError."""
    names = frozenset(names)

    def __getattr__(name: str):
        if name in names:
            warnings.warn(f"{module}.{name} is deprecated: use {home.__name__}.{name}", DeprecationWarning,
                          stacklevel=2)
            return getattr(home, name)
        raise AttributeError(f"module {module!r} has no attribute {name!r}")

    return __getattr__
