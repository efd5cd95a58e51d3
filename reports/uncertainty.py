"""What the report shows of a fit whose linearisation cannot be trusted (issue 12).

For one model's fit on all study data: the (1 - alpha) profile-likelihood intervals next to
the Wald ones, the likelihood-ratio region of every parameter pair (the other parameters
re-optimised) next to the linearised ellipse, the sloppiest direction of the information
matrix, and the sentence that tells the engineer which picture to believe.  Everything is
computed once per model by the study (:mod:`mudoe.uncertainty_runs`) into a
:class:`identification.studies.records.ModelUncertainty` (which words it; its old name here and that of
``PairRegion`` still work, deprecated) and the builder draws it.

Which models get these pages (:data:`UNCERTAINTY_CHOICES`): ``"untrusted"`` (default) the
models whose Bates-Watts curvature says the linearisation is NOT trustworthy
(:func:`mudoe.fit_assessment.linearisation_trust`), ``"all"`` every fitted model, ``"none"`` none.
"""
from __future__ import annotations

import identification.studies.records as _records
from identification.studies.records import UNTRUSTED

from .moved import moved

__all__ = ["UNCERTAINTY_CHOICES", "UNTRUSTED", "uncertainty_models"]

__getattr__ = moved(__name__, _records, ("PairRegion", "ModelUncertainty"))

#: which models get the uncertainty pages
UNCERTAINTY_CHOICES = ("untrusted", "all", "none")


def uncertainty_models(results, which: str = "untrusted") -> list:
    """The variants that get uncertainty pages: those of ``results.uncertainty`` (an
    :class:`oed.study_record.StudyRecord`) (computed by the study,
    :mod:`mudoe.uncertainty_runs`) that ``which`` (one of :data:`UNCERTAINTY_CHOICES`) selects --
    "untrusted" the ones whose linearisation is NOT trustworthy, "all" every one, "none" none."""
    if which not in UNCERTAINTY_CHOICES:
        raise ValueError(f"uncertainty: expected one of {', '.join(repr(c) for c in UNCERTAINTY_CHOICES)}, "
                         f"got {which!r}")
    if which == "none":
        return []
    return [v for v, mu in results.uncertainty.items() if which == "all" or mu.trust == UNTRUSTED]
