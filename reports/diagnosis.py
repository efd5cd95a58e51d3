"""What a model misses: the records of the diagnostic split family and their plain-language findings.

The paper's splits ask *whether* a model is wrong.  Splits chosen along one aspect of the
data ask *what* it misses: if the parameters fitted on low inputs differ from those fitted
on high inputs, the model misses an input dependence (a nonlinearity, a contact, a
stiffening); if they differ between phases (e.g. loading and unloading), it misses a
history dependence (friction, hysteresis); if they differ between series, the system
drifted or the series are not repeats.

The study computes the family (:mod:`mudoe.diagnosis_runs`: input range low vs high, every
pair of declared phases, first vs second half of the series, Holm's step-down correction over
the study's and the diagnostic splits) into a :class:`identification.studies.records.Diagnosis`;
the report shows it on the page "What the model misses" and this module only words it (the records
``Diagnosis``, ``DiagnosisRow`` and ``Explanation`` live in :mod:`identification.studies.records`;
their old names here still work, deprecated).

A study may know why a diagnostic split rejects a model on its data (e.g. from a benchmark
that switched features of a simulator off): it passes
:class:`identification.studies.records.Explanation` s (the study's ``explanations``), and every
finding they match is followed by the explanation's text, in the report and in the terminal.  The words are the study's; this module adds none.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import identification.studies.records as _records
from identification.studies.records import MISSES

from .moved import moved

__all__ = ["findings_text", "MISSES"]

__getattr__ = moved(__name__, _records, ("DiagnosisRow", "Diagnosis", "Explanation"))

if TYPE_CHECKING:
    from identification.studies.records import Diagnosis


def findings_text(diagnosis: Diagnosis | None, models) -> str:
    """The findings of :meth:`identification.studies.records.Diagnosis.misses` for the terminal: a heading and
    one paragraph each."""
    if diagnosis is None:
        return ""
    found = [s for m in models for s in diagnosis.misses(m)]
    head = (f"What the models miss (diagnostic splits; Holm over the study's and the diagnostic splits at TOL = "
            f"{100 * diagnosis.tol:g} %; not part of the decision):")
    return "\n".join([head] + [f"  - {s}" for s in found] if found else
                     [head, "  no diagnostic split rejects a model."])
