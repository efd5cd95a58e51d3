"""Deprecated (issue 28): :func:`identify` lives in :mod:`identification.inference.results` with the
Estimate it returns (public path: :func:`identification.identify`); this path re-exports it until its
last importers (:mod:`identification.studies.montecarlo`, :mod:`identification.studies.model_error_fit`)
are switched, then goes."""
from identification.inference.results import identify  # noqa: F401

__all__ = ["identify"]
