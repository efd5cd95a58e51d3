"""A split family that diagnoses: which aspect of the data a model misses (paper's closing remark).

The paper's splits ask *whether* a model is wrong.  Splits chosen along one aspect of the
data ask *what* it misses: if the parameters fitted on low inputs differ from those fitted
on high inputs, the model misses an input dependence (a nonlinearity, a contact, a
stiffening); if they differ between phases (e.g. loading and unloading), it misses a
history dependence (friction, hysteresis); if they differ between series, the system
drifted or the series are not repeats.

:func:`diagnostic_splits` builds the family from a study (input range low vs high, every
pair of declared phases, first vs second half of the study series); :func:`diagnose` runs
the split tests of :mod:`identification.studies.detect` on it for every model and corrects the
p-values (alpha_min) of the whole family -- the study's own splits and the diagnostic
ones -- with Holm's step-down procedure.  The report shows the result on the page
"What the model misses".

A study may know why a diagnostic split rejects a model on its data (e.g. from a benchmark
that switched features of a simulator off): it passes :class:`Explanation` s (the study's
``explanations``), and every finding they match is followed by the explanation's text, in the
report and in the terminal.  The words are the study's; this module adds none.

What the study should pass later: the diagnostic family (``[splits] diagnose = true``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from identification.studies.detect import run_split_tests
from identification.progress import Progress
from identification.studies.splits import Split, SplitError, input_range_split, series_split

from .view import phase_labels

__all__ = ["DiagnosticSplit", "DiagnosisRow", "Diagnosis", "Explanation", "diagnostic_splits", "diagnose",
           "holm_adjusted", "findings_text", "MISSES"]

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
class DiagnosticSplit:
    """A split and the aspect of the data it isolates."""

    split: Split
    kind: str          # "input range", "phase" or "series"


def diagnostic_splits(study) -> tuple:
    """The diagnostic family of a study (a tuple of :class:`DiagnosticSplit`).

    * input range: calibrate on the set points with |q| at most the median of the nonzero
      first inputs, validate on the others;
    * phase: for every pair of declared phases (:func:`reports.view.phase_labels`), one
      against the other (the press: loading vs unloading);
    * series: the first half of the study series against the second half (two or more series).

    Splits that cannot be built (e.g. a constant input) and splits the study already holds
    are left out.
    """
    q = np.asarray(study.campaign.q_set, float)
    out = []
    zero = tuple(int(j) for j in np.flatnonzero(q == 0))
    try:
        sp = input_range_split(q, exclude=zero, name="low vs high input")
        out.append(DiagnosticSplit(sp, "input range"))
    except SplitError:
        pass
    phases = phase_labels(study)
    if phases is not None:
        labels = list(dict.fromkeys(phases))
        for a in range(len(labels)):
            for b in range(a + 1, len(labels)):
                ia = [j for j, p in enumerate(phases) if p == labels[a] and j not in zero]
                ib = [j for j, p in enumerate(phases) if p == labels[b] and j not in zero]
                if ia and ib:
                    out.append(DiagnosticSplit(Split(f"{labels[a]} vs {labels[b]} (phase)", ia, ib, None, None,
                                                     f"phase {labels[a]} against phase {labels[b]}"), "phase"))
    n_study = next(iter(study.data.values())).n_M
    if n_study >= 2:
        half = n_study // 2
        out.append(DiagnosticSplit(series_split(q.size, list(range(half)), list(range(half, n_study)),
                                                name="first vs second half of the series"), "series"))
    own = {(sp.cal_inputs, sp.val_inputs, sp.cal_series, sp.val_series) for sp in study.splits}
    return tuple(d for d in out if (d.split.cal_inputs, d.split.val_inputs, d.split.cal_series,
                                    d.split.val_series) not in own)


def holm_adjusted(p) -> np.ndarray:
    """Holm's step-down adjusted p-values: max over k <= i of (m - k + 1) p_(k), capped at 1 (NaN kept last)."""
    p = np.asarray(p, float)
    m = p.size
    order = np.argsort(np.where(np.isfinite(p), p, np.inf), kind="stable")
    adj = np.full(m, math.nan)
    run = 0.0
    for rank, i in enumerate(order):
        if not np.isfinite(p[i]):
            continue
        run = max(run, min(1.0, (m - rank) * p[i]))
        adj[i] = run
    return adj


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


def diagnose(results, statistic: str | None = None, progress: Progress | None = None,
             explanations=None) -> Diagnosis | None:
    """Run the diagnostic family on every model of a study and Holm-correct it with the study's splits.

    Uses the detection's settings, start values and sensors; returns None when detection
    was not run.  Each split costs a calibration, a validation and a pooled fit per model;
    ``progress`` (an :class:`identification.progress.Progress`) shows a bar over them.
    ``explanations`` (:class:`Explanation` s; default the study's ``explanations``) are kept with
    the result and follow the findings they match.
    """
    det = results.detection
    if det is None:
        return None
    study = results.study
    st = statistic or det.settings.statistic
    fam = diagnostic_splits(study)
    rows = []
    for m in det.models:
        model = study.models[m]
        w = np.array([1.0 if s in results.design_sensors else 0.0 for s in study.sensors]) \
            if results.design_sensors else None
        with (progress or Progress(False)).bar(len(fam), f"diagnostic splits {m}", unit="split") as bar:
            tests = run_split_tests(model, study.data[m], [d.split for d in fam], study.p0, weights=w,
                                    settings=det.settings, model_name=m, bar=bar)
        own = [(t.split, "study split", t) for t in det.tests_of(m)]
        new = [(d.split.name, d.kind, t) for d, t in zip(fam, tests)]
        alphas = np.array([t.alpha(st) if t.ok else math.nan for _, _, t in own + new])
        adj = holm_adjusted(alphas)
        for (name, kind, t), a, h in zip(own + new, alphas, adj):
            rows.append(DiagnosisRow(m, name, kind, float(a), float(h), bool(np.isfinite(h) and h < det.settings.tol),
                                     "" if t.ok else f"{t.stage}: {t.error}"))
    if explanations is None:
        explanations = getattr(study, "explanations", ())
    bad = [e for e in explanations if not isinstance(e, Explanation)]
    if bad:
        raise TypeError(f"explanations: expected reports.diagnosis.Explanation, got {type(bad[0]).__name__}")
    return Diagnosis(st, det.settings.tol, tuple(rows), tuple(explanations))
