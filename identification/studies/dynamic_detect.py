"""Deprecated (issue 28), removed in the next release: Algorithm 1 on a dynamic model is
:func:`identification.studies.detect.detect` (one path for static and dynamic models) and its splits
are :class:`identification.studies.splits.Split` objects with half-open time windows.

The old names keep working for one release, each with a DeprecationWarning naming the new one:
``DynamicSplit(name, cal_experiments, val_experiments, cal_window, val_window, description)`` builds
``Split(name, cal_experiments, val_experiments, cal_window=..., val_window=..., description=...)``;
``detect_dynamic(...)`` calls ``detect(...)``; ``time_window_splits``, ``early_late_dynamic_split`` and
``flat_split`` are those of :mod:`identification.studies.splits`.
"""
from __future__ import annotations

import warnings

from identification.studies import splits as _splits_module
from identification.studies.detect import detect
from identification.studies.splits import Split

__all__ = ["DynamicSplit", "time_window_splits", "early_late_dynamic_split", "detect_dynamic", "flat_split"]

_MOVED = ("time_window_splits", "early_late_dynamic_split", "flat_split")


def DynamicSplit(name, cal_experiments=None, val_experiments=None, cal_window=None, val_window=None,  # noqa: N802
                 description: str = "") -> Split:
    """Deprecated: ``Split(name, cal_inputs, val_inputs, cal_window=..., val_window=..., description=...)``."""
    warnings.warn("identification.studies.dynamic_detect.DynamicSplit is deprecated; use identification.studies."
                  "splits.Split(name, cal_inputs, val_inputs, cal_window=..., val_window=...)", DeprecationWarning,
                  stacklevel=2)
    return Split(name, cal_experiments, val_experiments, description=description, cal_window=cal_window,
                 val_window=val_window)


def detect_dynamic(model, measurements, splits, p0, *, settings, design=None, design_how=None, progress=None,
                   discretisation=None):
    """Deprecated: :func:`identification.studies.detect.detect` (the same arguments)."""
    warnings.warn("identification.studies.dynamic_detect.detect_dynamic is deprecated; use identification.studies."
                  "detect.detect (static and dynamic models)", DeprecationWarning, stacklevel=2)
    return detect(model, measurements, splits, p0, settings=settings, design=design, design_how=design_how,
                  progress=progress, discretisation=discretisation)


def __getattr__(name: str):
    if name in _MOVED:
        warnings.warn(f"identification.studies.dynamic_detect.{name} is deprecated; import it from "
                      "identification.studies.splits", DeprecationWarning, stacklevel=2)
        return getattr(_splits_module, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
