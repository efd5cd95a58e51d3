r"""Which model variant to predict with, the model error in view (issue 29, item 2).

Every variant's :func:`identification.model_error` holds a held-out table: on every split, the validation
readings z_v predicted from the calibration part, without model error and with the variant's error model.
The held-out predictive log score of a variant and error model is the mean log density of its 95 %-band
predictive distribution N(m_v, s_v^2) at the held-out readings,

.. math::

    S = \frac{1}{N} \sum_{v=1}^{N} \log \varphi\bigl((z_v - m_v) / s_v\bigr) / s_v
    \qquad (\text{log of } 1 / \text{unit of } z),

pooled over the splits (weights: their numbers of readings).  The variants are ranked by their best score
(with or without their error model); the margin of the first over the second is the difference of their
scores per reading and, multiplied by N, the log of the ratio of their held-out predictive likelihoods
(exp(margin_total) times more likely held-out readings).  The scores compare only when the variants were
tested on the same held-out readings (same splits, same numbers of readings); otherwise the ranking says so.

**Standard error of the margin, per split.**  The readings of one split are not independent: they share the
fit on its calibration part and, when the model is wrong, the model error (smooth over the inputs, the same at
an input row's repeated series), so paired per-reading differences would understate the error.  The unit is
the split: with d_s the paired difference of the two variants' scores on split s (each variant with the error
model of its best pooled score) and w_s = n_s / N its share of the readings,

.. math::

    \text{margin} = \sum_s w_s d_s, \qquad
    \mathrm{SE}^2 = \frac{S}{S - 1} \sum_s w_s^2 (d_s - \text{margin})^2

over the S splits taken as independent (the splits of a study may share readings: the SE is then a guide, and
with a handful of splits a rough one).  Verdict: "choose X" when the margin exceeds 2 SE, "a tie within 2 SE"
otherwise; no SE with one split or one variant, or when the variants were scored on different readings.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from identification.results_protocol import ResultProtocol, jsonable, notes_lines
from identification.studies.model_error_result import ModelErrorResult

__all__ = ["rank_models", "ModelRanking", "RankedVariant", "TIE_SE"]

#: the margin must exceed this many standard errors for the verdict "choose X" (else "a tie within 2 SE")
TIE_SE = 2.0


@dataclass(frozen=True)
class RankedVariant:
    """One variant: its pooled held-out log scores (per reading, log of 1 / unit of z) and coverages of the
    new-reading bands without (``plain``) and with its error model (``kind``), ``best`` the higher score."""

    variant: str
    kind: str
    n_values: int
    score_plain: float
    score_error: float
    coverage_plain: float
    coverage_error: float

    @property
    def best(self) -> float:
        return max(self.score_plain, self.score_error)

    @property
    def with_error(self) -> bool:
        """Whether the variant predicts better with its error model than without."""
        return self.kind != "none" and self.score_error > self.score_plain

    def to_dict(self) -> dict:
        return {**{k: getattr(self, k) for k in self.__dataclass_fields__}, "best": self.best,
                "with_error": self.with_error}


@dataclass(frozen=True)
class ModelRanking(ResultProtocol):
    """The variants ranked by held-out predictive log score (module docstring).

    Attributes
    ----------
    rows : tuple of RankedVariant   best first
    use : str                       the variant to predict with
    use_error : bool                with its error model (else its plain bands)
    margin : float                  score per reading of ``use`` minus the runner-up's (NaN with one variant)
    margin_total : float            margin times the held-out readings: log of the predictive likelihood ratio
    runner_up : str                 "" with one variant
    comparable : bool               the variants were scored on the same held-out readings
    notes : tuple of str
    margin_se : float               standard error of ``margin`` over the splits (NaN: none, module docstring)
    split_margins : tuple of (str, int, float)   per split: its name, readings and paired difference d_s
    """

    rows: tuple
    use: str
    use_error: bool
    margin: float
    margin_total: float
    runner_up: str
    comparable: bool
    notes: tuple = ()
    margin_se: float = float("nan")
    split_margins: tuple = ()

    @property
    def decided(self) -> bool:
        """Whether the margin exceeds :data:`TIE_SE` standard errors (False for a tie or without an SE)."""
        return bool(not math.isnan(self.margin_se) and self.margin > TIE_SE * self.margin_se)

    def verdict(self) -> str:
        """One line: "choose X" (margin above 2 SE), "a tie within 2 SE" or why the margin has no SE."""
        if not self.runner_up:
            return f"choose {self.use} (the only variant with a held-out table)"
        if not self.comparable:
            return (f"no verdict: {self.use} and {self.runner_up} were not scored on the same held-out readings "
                    f"(margin {self.margin:+.3g} per reading, no standard error)")
        if math.isnan(self.margin_se):
            return (f"choose {self.use} (margin {self.margin:+.3g} per reading over {self.runner_up}; no standard "
                    f"error: {len(self.split_margins)} split)")
        how = (f"margin {self.margin:+.3g} +- {self.margin_se:.2g} per reading over {self.runner_up} (standard error "
               f"over {len(self.split_margins)} splits)")
        if self.decided:
            return f"choose {self.use}: {how}, {self.margin / self.margin_se:.1f} SE"
        return f"a tie within {TIE_SE:g} SE between {self.use} and {self.runner_up}: {how}"

    def sentence(self) -> str:
        """One line: which variant to predict with, with or without its error model, and by which margin."""
        how = "with its model error" if self.use_error else "without model error"
        if not self.runner_up:
            return f"predict with {self.use} {how} (the only variant with a held-out table)"
        return (f"predict with {self.use} {how}: held-out log score {self.margin:+.3g} per reading over "
                f"{self.runner_up} (predictive likelihood ratio exp({self.margin_total:.3g}))"
                + ("" if self.comparable else "; the variants were not scored on the same readings"))

    def summary(self) -> str:
        lines = ["Model ranking by held-out predictive log score (per reading; higher is better)", self.sentence(),
                 "Verdict: " + self.verdict(), "",
                 f"{'variant':<14} {'kind':<12} {'n':>6} {'plain':>10} {'with error':>10} {'cov. plain':>10} "
                 f"{'cov. error':>10}"]
        for r in self.rows:
            lines.append(f"{r.variant:<14} {r.kind:<12} {r.n_values:>6} {r.score_plain:>10.4g} {r.score_error:>10.4g} "
                         f"{100 * r.coverage_plain:>9.1f}% {100 * r.coverage_error:>9.1f}%")
        return "\n".join(lines + notes_lines(self.notes))

    def to_frame(self):
        import pandas as pd
        frame = pd.DataFrame([r.to_dict() for r in self.rows]).set_index("variant")
        frame.attrs.update(use=self.use, use_error=self.use_error, margin=self.margin, margin_total=self.margin_total,
                           margin_se=self.margin_se, verdict=self.verdict())
        return frame

    def to_dict(self) -> dict:
        return jsonable({"rows": [r.to_dict() for r in self.rows], "use": self.use, "use_error": self.use_error,
                         "margin": self.margin, "margin_total": self.margin_total, "runner_up": self.runner_up,
                         "comparable": self.comparable, "sentence": self.sentence(), "notes": list(self.notes),
                         "margin_se": self.margin_se, "decided": self.decided, "verdict": self.verdict(),
                         "split_margins": [{"split": s, "n_values": n, "margin": d} for s, n, d in self.split_margins]})


def _pooled(result: ModelErrorResult, what: str, kind: str) -> float:
    n = sum(h.n_values for h in result.heldout)
    return float(sum(getattr(h, what)(kind) * h.n_values for h in result.heldout) / n)


def _split_margins(first: ModelErrorResult, k1: str, second: ModelErrorResult, k2: str) -> tuple:
    """(split, readings, d_s) per split: the paired difference of the two variants' held-out scores."""
    return tuple((a.split, a.n_values, float(a.log_score(k1) - b.log_score(k2)))
                 for a, b in zip(first.heldout, second.heldout))


def _margin_se(split_margins: tuple) -> float:
    """SE of the readings-weighted mean of the splits' differences, the splits taken as independent (NaN with
    fewer than two splits)."""
    if len(split_margins) < 2:
        return float("nan")
    n = np.array([s[1] for s in split_margins], float)
    d = np.array([s[2] for s in split_margins], float)
    w = n / n.sum()
    m = float(w @ d)
    return float(np.sqrt(len(d) / (len(d) - 1) * np.sum(w ** 2 * (d - m) ** 2)))


def rank_models(results: Mapping) -> ModelRanking:
    """S = mean_v log N(z_v; m_v, s_v^2) over the held-out readings (log of 1 / unit of z): rank the variants
    {name: ModelErrorResult} by their best held-out predictive log score with or without their error model.

    Parameters
    ----------
    results : mapping {variant name: ModelErrorResult}
        Each computed with splits (its held-out table); a variant without one is left out with a note.

    Returns
    -------
    ModelRanking
        With the margin's standard error over the splits (``margin_se``, ``split_margins``) and its verdict
        (module docstring).

    Raises
    ------
    ValueError
        ``results`` is not a mapping of ModelErrorResult, or no variant has a held-out table.
    """
    if not isinstance(results, Mapping) or not all(isinstance(r, ModelErrorResult) for r in results.values()):
        raise ValueError("results: expected a mapping {variant: ModelErrorResult}")
    rows, notes = [], []
    for v, r in results.items():
        if not r.heldout:
            notes.append(f"{v} has no held-out table (model_error without splits): not ranked")
            continue
        rows.append(RankedVariant(str(v), r.kind, int(sum(h.n_values for h in r.heldout)),
                                  _pooled(r, "log_score", "none"), _pooled(r, "log_score", r.kind),
                                  _pooled(r, "coverage", "none"), _pooled(r, "coverage", r.kind)))
    if not rows:
        raise ValueError("results: no variant has a held-out table; call model_error with splits")
    rows.sort(key=lambda r: r.best, reverse=True)
    tables = {tuple((h.split, h.n_values) for h in results[r.variant].heldout) for r in rows}
    comparable = len(tables) == 1
    if not comparable:
        notes.append("the variants were scored on different held-out readings (splits or sensors differ): the "
                     "scores do not compare")
    first = rows[0]
    second = rows[1] if len(rows) > 1 else None
    margin = float("nan") if second is None else first.best - second.best
    paired, se = (), float("nan")
    if second is not None and comparable:
        kind = {r.variant: r.kind if r.with_error else "none" for r in (first, second)}
        paired = _split_margins(results[first.variant], kind[first.variant], results[second.variant],
                                kind[second.variant])
        se = _margin_se(paired)
    return ModelRanking(rows=tuple(rows), use=first.variant, use_error=first.with_error, margin=margin,
                        margin_total=margin * first.n_values, runner_up="" if second is None else second.variant,
                        comparable=comparable, notes=tuple(notes), margin_se=se, split_margins=paired)
