"""The diagnostic split family of a study: which aspect of the data a model misses (paper's closing remark).

:func:`diagnostic_splits` builds the family from a study (input range low vs high, every pair of
declared phases, first vs second half of the study series); :func:`diagnose` runs the split tests
of :mod:`identification.studies.detect` on it for every model and corrects the p-values
(alpha_min) of the whole family -- the study's own splits and the diagnostic ones -- with Holm's
step-down procedure, into an :class:`identification.studies.records.Diagnosis` the report shows on the page
"What the model misses" (:mod:`reports.diagnosis` words it; the study computes it here).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from identification.progress import Progress
from identification.studies.detect import run_split_tests
from identification.studies.splits import Split, SplitError, input_range_split, series_split
from identification.studies.records import Diagnosis, DiagnosisRow, Explanation

from .report_record import study_phases

__all__ = ["DiagnosticSplit", "diagnostic_splits", "holm_adjusted", "diagnose"]


@dataclass(frozen=True)
class DiagnosticSplit:
    """A split and the aspect of the data it isolates."""

    split: Split
    kind: str          # "input range", "phase" or "series"


def diagnostic_splits(study) -> tuple:
    """The diagnostic family of a study (a tuple of :class:`DiagnosticSplit`).

    * input range: calibrate on the set points with |q| at most the median of the nonzero
      first inputs, validate on the others;
    * phase: for every pair of declared phases (:func:`mudoe.report_record.study_phases`), one
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
    phases = study_phases(study)
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


def diagnose(results, statistic: str | None = None, progress: Progress | None = None,
             explanations=None) -> Diagnosis | None:
    """Run the diagnostic family on every model of a study and Holm-correct it with the study's splits.

    Uses the detection's settings, start values and sensors; returns None when detection
    was not run.  Each split costs a calibration, a validation and a pooled fit per model;
    ``progress`` (an :class:`identification.progress.Progress`) shows a bar over them.
    ``explanations`` (:class:`identification.studies.records.Explanation` s; default the study's ``explanations``) are kept with
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
        explanations = study.explanations
    bad = [e for e in explanations if not isinstance(e, Explanation)]
    if bad:
        raise TypeError(f"explanations: expected identification.studies.records.Explanation, got {type(bad[0]).__name__}")
    return Diagnosis(st, det.settings.tol, tuple(rows), tuple(explanations))
