"""The result of Algorithm 1 (:class:`DetectionResult`): verdicts, split tests, the text summary,
a pandas table (:meth:`DetectionResult.to_frame`) and its HTML view for Jupyter."""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from html import escape
from types import MappingProxyType

import numpy as np

from identification.studies.decisions import ModelDecision
from identification.studies.detect_settings import CORRECTIONS, STATISTICS, DetectSettings
from identification.studies.split_tests import SplitTest
from identification.results_protocol import ResultProtocol, jsonable

__all__ = ["DetectionResult"]


class _Notes:
    """Numbered notes of a summary: ``add(text)`` appends and returns its marker "[k]"."""

    def __init__(self, texts=()):
        self.texts = list(texts)

    def add(self, text: str) -> str:
        self.texts.append(text)
        return f"[{len(self.texts)}]"


def _alpha_mark(a: float, threshold: float) -> str:
    """alpha_min in % for the summary table, "*" when below the per-test level ("n/a" when NaN)."""
    if not np.isfinite(a):
        return "n/a"
    return f"{100 * a:.3g}" + ("*" if a < threshold else "") if a >= 1e-4 else "<0.01*"


def _disagreement(t: SplitTest, threshold: float, tol: float) -> str:
    """A warning when the three alpha_min of a split differ by more than a factor 100 and fall on
    both sides of the per-test level or of TOL ("" otherwise)."""
    a = {st: t.alpha(st) for st in STATISTICS}
    fin = {st: v for st, v in a.items() if np.isfinite(v)}
    if len(fin) < 2:
        return ""
    lo, hi = min(fin.values()), max(fin.values())
    ratio = math.inf if lo <= 0 else hi / lo
    crosses = any(lo < line <= hi for line in (threshold, tol))
    if not (ratio > 100 and crosses):
        return ""
    vals = ", ".join(f"{st} {100 * v:.3g} %" for st, v in fin.items())
    return (f"the statistics disagree by orders of magnitude ({vals}; ratio "
            f"{'inf' if not math.isfinite(ratio) else f'{ratio:.3g}'}) across the decision line: the model is "
            "far from linear in its parameters on this split or a fit is poorly determined; trust the likelihood "
            "ratio and check the fits (curvature, conf_int(method=\"profile\"))")


@dataclass(frozen=True, eq=False)
class DetectionResult(ResultProtocol):
    """Immutable result of :func:`~identification.studies.detect.detect` (the result protocol:
    :meth:`summary`, :meth:`to_frame`, :meth:`to_dict`, ``_repr_html_``).

    Attributes
    ----------
    settings : DetectSettings
    models : tuple of str
    splits : tuple of Split
    tests : tuple of SplitTest     every (model, split), models outer
    decisions : tuple of ModelDecision   the primary verdict per model (settings' statistic, correction)
    all_decisions : tuple of ModelDecision  every model x statistic x correction
    normality : tuple of (model, NormalityCheck)
    design : tuple of (model, tuple of sensor names used, how chosen)
    notes : tuple of str
    """

    settings: DetectSettings
    models: tuple
    splits: tuple
    tests: tuple
    decisions: tuple
    all_decisions: tuple
    normality: tuple
    design: tuple
    notes: tuple = ()

    def decision(self, model: str | None = None, statistic: str | None = None,
                 correction: str | None = None) -> ModelDecision:
        """The verdict for a model (default: the only / first one); without statistic and correction
        the primary verdict (the likelihood ratio's when a linearisation is not trustworthy)."""
        model = self.models[0] if model is None else model
        if model not in self.models:
            raise KeyError(f"model: {model!r} not in {list(self.models)}")
        if statistic is None and correction is None:
            return next(d for d in self.decisions if d.model == model)
        st = statistic or self.settings.statistic
        co = correction or self.settings.correction
        for d in self.all_decisions:
            if d.model == model and d.statistic == st and d.correction == co:
                return d
        raise KeyError(f"no decision for {(model, st, co)}")

    @property
    def verdicts(self) -> Mapping:
        """{model: "rejected" | "not rejected" | "undecided"} (primary statistic and correction)."""
        return MappingProxyType({d.model: d.decision for d in self.decisions})

    def tests_of(self, model: str) -> tuple:
        return tuple(t for t in self.tests if t.model == model)

    def alphas(self, model: str | None = None, statistic: str | None = None) -> np.ndarray:
        """alpha_min per split (NaN for failed splits)."""
        model = self.models[0] if model is None else model
        st = statistic or self.settings.statistic
        return np.array([t.alpha(st) if t.ok else np.nan for t in self.tests_of(model)])

    # ------------------------------------------------------------------ tables (pandas, Jupyter)
    #: the columns of :meth:`to_frame` read from each :class:`SplitTest`
    FRAME_FIELDS = ("cal_label", "val_label", "ok", "stage", "error", "alpha_lr", "alpha_two_sample", "alpha_paper",
                    "lr", "d2_two_sample", "d2_paper", "n_cal", "n_val", "lr_error", "trustworthy")

    def to_frame(self):
        """One row per (model, split) (models outer, as :attr:`tests`), indexed by ``model`` and ``split``: the
        split test's fields :attr:`FRAME_FIELDS` (the three alpha_min are p-values in [0, 1], NaN when not
        computed; ``lr``, ``d2_*`` in chi^2 units, F units for ``lr`` when sigma is estimated),
        ``split_rejected`` (this split's hypothesis is rejected under the model's primary statistic and
        correction) and ``model_decision`` (the model's primary verdict over all its splits: "rejected" as soon
        as one split is, so a row may read split_rejected False, model_decision "rejected").  ``.attrs`` holds
        tol, statistic and correction."""
        import pandas as pd
        prim = {d.model: d for d in self.decisions}
        rows = [dict(model=t.model, split=t.split, **{f: getattr(t, f) for f in self.FRAME_FIELDS},
                     split_rejected=t.split in prim[t.model].flagged, model_decision=prim[t.model].decision)
                for t in self.tests]
        df = pd.DataFrame(rows, columns=["model", "split", *self.FRAME_FIELDS, "split_rejected", "model_decision"])
        df.attrs.update(tol=self.settings.tol, statistic=self.settings.statistic, correction=self.settings.correction)
        return df.set_index(["model", "split"])

    def _repr_html_(self) -> str:
        """Jupyter's view: the verdict per model, the split table (:meth:`to_frame`) and the full text summary."""
        s = self.settings
        head = (f"<p><b>Detection of model uncertainty (Algorithm 1)</b>: TOL = {100 * s.tol:g} %, n_tests = "
                f"{len(self.splits)}, statistic {escape(s.statistic)}, correction {escape(s.correction)}</p>")
        verdicts = "".join(f"<tr><td>{escape(d.model)}</td><td><b>{escape(d.decision)}</b></td>"
                           f"<td>{escape(d.statistic)}</td><td>{escape(d.reason)}</td></tr>" for d in self.decisions)
        verdicts = ("<table><thead><tr><th>model</th><th>decision</th><th>statistic</th><th>reason</th></tr>"
                    f"</thead><tbody>{verdicts}</tbody></table>")
        table = self.to_frame().to_html(float_format=lambda v: f"{v:.4g}")
        return (head + verdicts + table
                + f"<details><summary>text summary</summary><pre>{escape(self.summary())}</pre></details>")

    def summary(self, units: Mapping | None = None, data_name: str = "series") -> str:
        """Per model: a table of the three statistics per split, the verdicts, numbered notes.

        ``units`` {sensor: (factor, unit)} and ``data_name`` label the normality table
        (:meth:`NormalityCheck.table`; e.g. the display unit and "study series").  Decisions use
        the words "rejected", "not rejected" and "undecided"; ">>" marks the deciding one.
        """
        s = self.settings
        n = len(self.splits)
        notes = _Notes(self.notes)
        explain = {"likelihood_ratio": "(likelihood ratio: pooled fit vs separate calibration and validation fits)",
                   "two_sample": "(Wald on p_val - p_cal with C_cal + C_val)",
                   "paper": "(paper: p_val in G(alpha, p_cal, C_cal))"}
        lines = [f"Detection of model uncertainty (Algorithm 1): TOL = {100 * s.tol:g} %, n_tests = {n}, "
                 f"per-test level TOL/n_tests = {100 * s.tol / n:.4g} %",
                 f"decision statistic: {s.statistic} {explain[s.statistic]}, correction: {s.correction}",
                 ""]
        switched = [d.model for d in self.decisions if d.statistic != s.statistic]
        if switched:
            lines[-1:-1] = [f"  for {', '.join(switched)} the likelihood ratio decides instead: a fit's linearisation "
                            "is not trustworthy (Bates-Watts curvature), the Wald statistics are unreliable"]
        lines += self._normality_lines(notes, units, data_name)
        lines += [f"sensors for {mname}: {', '.join(used)} ({how})" for mname, used, how in self.design]
        if self.design:
            lines.append("")
        for mname in self.models:
            lines += self._model_lines(mname, notes)
        lines.append("* alpha_min < TOL/n_tests; ~ = Wald p-value unreliable (linearisation not trustworthy); "
                     "R = hypothesis of the split rejected (LR, 2-sample, paper); >> = the decision")
        if s.statistic == "paper":
            notes.add("the paper's statistic ignores the validation estimate's covariance C_val; under a correct "
                      "model its size exceeds TOL (see identification.studies.montecarlo)")
        if notes.texts:
            lines += ["", "Notes:"] + [f"[{k}] {t}" for k, t in enumerate(notes.texts, 1)]
        return "\n".join(lines)

    def _normality_lines(self, notes: "_Notes", units: Mapping | None, data_name: str) -> list:
        """The summary's normality-gate blocks, one per distinct check."""
        lines, seen = [], []
        for mname, chk in self.normality:
            if any(chk is c for c in seen):
                continue
            seen.append(chk)
            head = (f"Normality gate (line 05), {chk.gate_text()} on the differences "
                    f"{chk.pairs_text()} of the {data_name} {chk.series_text()}"
                    + (f" [data of {mname}]" if len(self.models) > 1 else ""))
            status = "passed" if chk.passed else ("FAILED, overridden by the user "
                                                  + notes.add("normality='override': the Gaussian error assumption "
                                                              "failed its check; the p-values below rely on it")
                                                  if chk.overridden else "FAILED")
            lines += [head + f": {status}", chk.table(units, data_name)]
            if chk.note:
                lines[-1] += " " + notes.add(chk.note)
            lines.append("")
        return lines

    def _model_lines(self, mname: str, notes: "_Notes") -> list:
        """The summary's block of one model: a row per split, then every decision."""
        s = self.settings
        thr = s.tol / len(self.splits)
        w = max(10, max(len(sp.name) for sp in self.splits))
        lines = [f"Model {mname}",
                 f"  {'split':<{w}} {'calibration':<22} {'validation':<22} {'alpha LR %':>10} "
                 f"{'alpha 2-sample %':>16} {'alpha paper %':>13}  Bonf. LR/2s/paper  Holm LR/2s/paper"]
        dec = {(d.statistic, d.correction): d for d in self.all_decisions if d.model == mname}
        prim = self.decision(mname)
        for t in self.tests_of(mname):
            if not t.ok:
                lines.append(f"  {t.split:<{w}} {t.cal_label:<22} {t.val_label:<22} {'failed':>10} {'failed':>16} "
                             f"{'failed':>13}  " + notes.add(f"{mname}, {t.split}: {t.stage} failed: {t.error}"))
                continue
            m = {st: _alpha_mark(t.alpha(st), thr) for st in STATISTICS}
            if t.trustworthy is False:
                m = {st: v + ("~" if st != "likelihood_ratio" else "") for st, v in m.items()}
            fl = ["".join("R" if t.split in dec[(st, co)].flagged else "-" for st in STATISTICS)
                  for co in CORRECTIONS]
            lines.append(f"  {t.split:<{w}} {t.cal_label:<22} {t.val_label:<22} {m['likelihood_ratio']:>10} "
                         f"{m['two_sample']:>16} {m['paper']:>13}  {fl[0]:>17}  {fl[1]:>16}")
            if t.lr_error:
                lines[-1] += " " + notes.add(f"{mname}, {t.split}: likelihood ratio not computed: {t.lr_error}")
            if t.trustworthy is False:
                lines[-1] += " " + notes.add(
                    f"{mname}, {t.split}: linearisation NOT trustworthy ({t.curvature_note}); the Wald columns "
                    "(2-sample, paper; marked ~) rest on it and are unreliable: the likelihood ratio decides")
            disagree = _disagreement(t, thr, s.tol)
            if disagree:
                lines[-1] += " " + notes.add(f"{mname}, {t.split}: {disagree}")
            for nt in t.notes:
                lines[-1] += " " + notes.add(f"{mname}, {t.split}: {nt}")
        for st in STATISTICS:
            for co in CORRECTIONS:
                d = dec[(st, co)]
                primary = st == prim.statistic and co == prim.correction
                reason = prim.reason if primary else d.reason
                lines.append(f"  {'>> ' if primary else '   '}{st:<16} {co:<10}: {d.decision:<12} ({reason})")
        lines.append("")
        return lines

    def __repr__(self):
        v = ", ".join(f"{m}: {d}" for m, d in self.verdicts.items())
        return f"DetectionResult({v}; {len(self.splits)} splits, statistic={self.settings.statistic})"

    #: the fields of every split test in :meth:`to_dict` (key: attribute of :class:`SplitTest`)
    DICT_TEST_FIELDS = dict(model="model", split="split", calibration="cal_label", validation="val_label", ok="ok",
                            stage="stage", error="error", p_cal="p_cal", p_val="p_val", C_cal="C_cal", C_val="C_val",
                            d2_paper="d2_paper", d2_two_sample="d2_two_sample", alpha_paper="alpha_paper",
                            alpha_two_sample="alpha_two_sample", lr="lr", alpha_lr="alpha_lr", lr_error="lr_error",
                            n_cal="n_cal", n_val="n_val")

    def to_dict(self, units: Mapping | None = None, data_name: str = "series") -> dict:
        """Every split test and every decision as JSON-safe values (what a report's results.json holds under
        "detection"): settings, models, splits (:meth:`Split.to_dict`), verdicts, tests (the p-values and
        statistics of :attr:`DICT_TEST_FIELDS`, chi^2 units; NaN as null), decisions (``primary``: the settings'
        statistic and correction), normality (:meth:`NormalityCheck.to_dict`, labelled by ``units``
        {sensor: (factor, unit)} and ``data_name`` as in :meth:`summary`), design and notes."""
        tests = [dict({k: getattr(t, f) for k, f in self.DICT_TEST_FIELDS.items()}, notes=list(t.notes))
                 for t in self.tests]
        decisions = [jsonable(d) for d in self.all_decisions]
        for d, dd in zip(self.all_decisions, decisions):
            dd["primary"] = (d.statistic == self.settings.statistic and d.correction == self.settings.correction)
        norm = [dict(model=m, **c.to_dict(units, data_name)) for m, c in self.normality]
        return jsonable(dict(settings=jsonable(self.settings), models=list(self.models),
                             splits=[s.to_dict() for s in self.splits], verdicts=dict(self.verdicts), tests=tests,
                             decisions=decisions, normality=norm,
                             design=[dict(model=m, sensors=u, how=h) for m, u, h in self.design],
                             notes=list(self.notes)))
