"""Deprecated (issue 28), removed in the next release: the profile intervals and the summary of an
estimate the data do not bound are part of :mod:`identification.inference.profile`.

The old names keep working for one release, each with a DeprecationWarning naming the new home."""
from __future__ import annotations

import warnings

from identification.inference import profile as _profile_module

__all__ = ["profile_intervals_unbounded", "unbounded_summary"]


def __getattr__(name: str):
    if name in __all__:
        warnings.warn(f"identification.inference.unbounded_intervals.{name} is deprecated; import it from "
                      "identification.inference.profile", DeprecationWarning, stacklevel=2)
        return getattr(_profile_module, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
