"""What a model misses: the records of the diagnostic split family and their plain-language findings.

The paper's splits ask *whether* a model is wrong.  Splits chosen along one aspect of the
data ask *what* it misses: if the parameters fitted on low inputs differ from those fitted
on high inputs, the model misses an input dependence (a nonlinearity, a contact, a
stiffening); if they differ between phases (e.g. loading and unloading), it misses a
history dependence (friction, hysteresis); if they differ between series, the system
drifted or the series are not repeats.

The study computes the family (:mod:`mudoe.diagnosis_runs`: input range low vs high, every
pair of declared phases, first vs second half of the series, Holm's step-down correction over
the study's and the diagnostic splits) into a :class:`Diagnosis`; the report shows it on the
page "What the model misses" and this module only words it.

A study may know why a diagnostic split rejects a model on its data (e.g. from a benchmark
that switched features of a simulator off): it passes :class:`Explanation` s (the study's
``explanations``), and every finding they match is followed by the explanation's text, in the
report and in the terminal.  The words are the study's; this module adds none.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["DiagnosisRow", "Diagnosis", "Explanation", "findings_text", "MISSES"]

#: what a rejection on a split of each kind says the model misses
MISSES = {"input range": "an input dependence: the parameters fitted on small inputs do not hold for large ones "
                         "(a nonlinearity, a contact or a stiffening the model lacks, or a systematic sensor error "
                         "that depends on the reading)",
          "phase": "a history dependence: the parameters differ between phases (friction, hysteresis or another "
                   "direction-dependent effect the model lacks)",
          "series": "a change between series: the system drifted or the series are not repeats of one experiment",
          "study split": "something the study's own split separates (see its description)"}


@dataclass(frozen=True)
class Explanation:
    """What a study knows about why a kind of diagnostic split rejects a model on its data.

    Attributes
    ----------
    model : str    the model (variant) whose rejection it explains
    kind : str     the kind of diagnostic split: "input range", "phase" or "series" (:data:`MISSES`)
    text : str     plain sentences in the study's words, shown after the finding they explain
    """

    model: str
    kind: str
    text: str

    def __post_init__(self):
        if self.kind not in MISSES:
            raise ValueError(f"kind: expected one of {sorted(MISSES)}, got {self.kind!r}")
        if not isinstance(self.text, str) or not self.text.strip():
            raise ValueError("text: an explanation needs words")


@dataclass(frozen=True)
class DiagnosisRow:
    """One model on one split of the family: alpha_min, Holm-adjusted p-value, decision."""

    model: str
    split: str
    kind: str
    alpha: float
    holm: float
    rejected: bool
    error: str = ""


@dataclass(frozen=True)
class Diagnosis:
    """The diagnostic family's results for every model (Holm over the study's and the diagnostic splits).

    ``explanations`` (:class:`Explanation`, from the study) follow the findings they match.
    """

    statistic: str
    tol: float
    rows: tuple
    explanations: tuple = ()

    def misses(self, model: str) -> list[str]:
        """Plain sentences: what the model misses, one per rejected diagnostic split, each followed by
        the study's explanations of that model and kind of split."""
        out = []
        for r in self.rows:
            if r.model == model and r.rejected and r.kind != "study split":
                why = [e.text.strip() for e in self.explanations if e.model == model and e.kind == r.kind]
                out.append(" ".join([f"{model} misses {MISSES[r.kind]} (split '{r.split}', Holm-adjusted p = "
                                     f"{100 * r.holm:.3g} %)."] + why))
        return out


def findings_text(diagnosis: Diagnosis | None, models) -> str:
    """The findings of :meth:`Diagnosis.misses` for the terminal: a heading and one paragraph each."""
    if diagnosis is None:
        return ""
    found = [s for m in models for s in diagnosis.misses(m)]
    head = (f"What the models miss (diagnostic splits; Holm over the study's and the diagnostic splits at TOL = "
            f"{100 * diagnosis.tol:g} %; not part of the decision):")
    return "\n".join([head] + [f"  - {s}" for s in found] if found else
                     [head, "  no diagnostic split rejects a model."])
