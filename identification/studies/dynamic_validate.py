"""Deprecated (issue 28), removed in the next release: the Monte Carlo validation of a dynamic model is
:func:`identification.studies.montecarlo.validate` (one path for static and dynamic models), its size
study on the collocation at the campaign fit :func:`identification.studies.montecarlo.flat_size_study`.

The old names keep working for one release, each with a DeprecationWarning naming the new one:
``dynamic_size_study`` calls ``flat_size_study``; ``FlatSizeStudy`` is that of the montecarlo module.
"""
from __future__ import annotations

import warnings

from identification.studies import montecarlo as _montecarlo_module

__all__ = ["FlatSizeStudy", "dynamic_size_study"]


def dynamic_size_study(model, data, splits, p0=None, *, p_true=None, weights=None, identify_settings=None,
                       name: str | None = None, discretisation=None):
    """Deprecated: :func:`identification.studies.montecarlo.flat_size_study` (the same arguments)."""
    warnings.warn("identification.studies.dynamic_validate.dynamic_size_study is deprecated; use identification."
                  "studies.montecarlo.flat_size_study", DeprecationWarning, stacklevel=2)
    return _montecarlo_module.flat_size_study(model, data, splits, p0, p_true=p_true, weights=weights,
                                              identify_settings=identify_settings, name=name,
                                              discretisation=discretisation)


def __getattr__(name: str):
    if name == "FlatSizeStudy":
        warnings.warn("identification.studies.dynamic_validate.FlatSizeStudy is deprecated; import it from "
                      "identification.studies.montecarlo", DeprecationWarning, stacklevel=2)
        return _montecarlo_module.FlatSizeStudy
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
