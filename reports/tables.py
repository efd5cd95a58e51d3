"""Tables of a study as formatted text and as matplotlib tables (no LaTeX).

Every function takes the study's :class:`oed.study_record.StudyRecord` (``results``), its
:class:`oed.study_record.StudySetup` (``study``) or the library object it names, and returns text, or a
list of rows for :func:`draw_table`.
"""
from __future__ import annotations

import math

import numpy as np

from oed.best_designs import RankedDesignTable

from .view import (fmt_p, fmt_pct, fmt_value, output_display, param_units, sensor_unit,
                   unit_suffix)

__all__ = ["fmt_alpha", "normality_rows", "normality_widths", "normality_checks", "normality_labels",
           "sigma_display", "STUDY_SERIES", "ALL_SERIES", "oed_rows", "oed_table_text", "estimate_rows", "alpha_rows",
           "draw_table", "sigma_rows", "verdict_rows", "smallest_alpha", "criteria_units", "PARAMS_PER_TABLE",
           "content_widths"]


def fmt_alpha(a: float) -> str:
    """alpha_min in percent as in the paper ('<< 0.01' below 1e-4)."""
    if a is None or not np.isfinite(a):
        return "failed"
    return "<< 0.01" if a < 1e-4 else f"{100 * a:.2f}"


#: what the detection's data are called everywhere (terminal, JSON, report): the study's series
STUDY_SERIES = "study series"
#: what the study's own normality check (the sigma_rep used to compose sigma) runs on
ALL_SERIES = "all series"


def sigma_display(study) -> dict:
    """{sensor: (factor, unit)}: sigma_rep and sigma shown as factor * value (model unit) in unit.

    The one display unit of the report (:func:`reports.view.output_display`; the press: um), used
    by the terminal (``DetectionResult.summary(units=...)``), results.json and the report alike.
    """
    f = output_display(study).scale
    return {s: (f, sensor_unit(study, s)) for s in study.sensors}


def normality_labels(study) -> dict:
    """Keyword arguments of ``DetectionResult.summary`` / ``serialize.detection_dict`` that label the
    normality gate like the report: sigma in the display unit, p-values "on the study series"."""
    return dict(units=sigma_display(study), data_name=STUDY_SERIES)


def normality_checks(study, gate=None) -> list:
    """[(name, NormalityCheck)]: the study's check on all series and, when detection ran on other
    series, the gate of Algorithm 1 on the study series (one entry when both are the same series)."""
    if gate is None:
        return [(ALL_SERIES, study.normality)]
    if tuple(gate.series) == tuple(study.normality.series):
        return [(f"{STUDY_SERIES} = {ALL_SERIES}", gate)]
    return [(ALL_SERIES, study.normality), (STUDY_SERIES, gate)]


def normality_rows(study, gate=None) -> tuple[list, list]:
    """Header and rows of the paper's 'Analysis of the measurement data' table (displayed sensor units).

    Shapiro-Wilk p-values (%) and sigma_rep per sensor, each column labelled with the series it
    was computed on (:func:`normality_checks`: all series, and the study series of the gate
    ``gate`` when given); then sigma_man, the sigma used, the unit and how sigma was obtained.
    """
    checks = normality_checks(study, gate)
    disp = sigma_display(study)
    head = ["sensor"]
    for name, _ in checks:
        label = name.replace(" = ", "\n= ")
        head += [f"SW p %\n({label})", f"sigma_rep\n({label})"]
    head += ["sigma_man", "sigma used", "unit", "how sigma was obtained"]
    rows = []
    for k, s in enumerate(study.sensors):
        st = study.sigma_table[k]
        f = disp[s][0]
        row = [s]
        for _, chk in checks:
            row += ["n/a" if not np.isfinite(chk.pvalue[k]) else f"{100 * chk.pvalue[k]:.2f}",
                    f"{f * chk.sigma_rep[k]:.4g}"]
        row += ["-" if not np.isfinite(st["sigma_man"]) else f"{f * st['sigma_man']:.4g}",
                "estimated" if not np.isfinite(st["sigma"]) else f"{f * st['sigma']:.4g}",
                disp[s][1] or "-", st["how"]]
        rows.append(row)
    return head, rows


def normality_widths(head) -> list:
    """Column widths (fractions of the table) of :func:`normality_rows`' table."""
    n_stat = len(head) - 5
    w_stat = 0.115 if n_stat <= 2 else 0.105
    rest = 1.0 - 0.07 - n_stat * w_stat - 0.085 - 0.085 - 0.06
    return [0.07] + [w_stat] * n_stat + [0.085, 0.085, 0.06, rest]


def sigma_rows(study):
    return normality_rows(study)


def criteria_units(study) -> str:
    """Units of the A, D, E criteria of C(w) from the parameter units ('' when they differ or are undeclared)."""
    u = set(param_units(study))
    if len(u) != 1 or "" in u:
        return "A: trace C, D: log det C, E: largest eigenvalue of C (parameters in their own units)"
    (unit,) = u
    return f"C in ({unit})^2; A: trace C, D: log det C, E: largest eigenvalue of C"


def oed_rows(results) -> tuple[list, list]:
    """Header and rows of the OED table (paper Table 'Outcome for the optimal design'), chosen row marked.

    The D criterion is shown as log det C (as in the text and the optimiser).
    """
    t = results.oed_table
    chosen = results.oed.chosen if results.oed is not None else ()
    head = ["combination", "sensors", "Psi_A (trace C)", "Psi_D (log det C)", "Psi_E (max eig C)", "flag"]
    rows = []
    ranked = isinstance(t, RankedDesignTable)       # the ten best designs (oed.best_designs), not every one
    if ranked:
        head[0] = "rank"
    for k, r in enumerate(t.rows, 1):
        mark = "  <= chosen" if tuple(r.sensors) == tuple(chosen) else ""
        first = (str(k) if k <= 10 else "-") if ranked else r.mask + (" (all)" if "0" not in r.mask else "")
        rows.append([first, " ".join(r.sensors), f"{r.A:.4e}",
                     f"{r.logdet:.4f}", f"{r.E:.4e}", (r.flag or "") + mark])
    return head, rows


def oed_table_text(results) -> str:
    """The OED table as fixed-width text, with the chosen design and how it was found."""
    head, rows = oed_rows(results)
    r = results.oed
    names = ", ".join(results.study.models[results.oed_variant].param_names)
    crit = f"{r.criterion} = {r.value:.6g}" + (" (log det C)" if r.criterion == "D" else "")
    lines = [f"Optimal sensor design ({r.criterion}-criterion, {r.kind} covariance) from the {results.oed_variant} "
             f"estimate of ({names}); {criteria_units(results.study)}",
             (results.oed_table.note if isinstance(results.oed_table, RankedDesignTable) else "every combination")
             + ":", _text_table(head, rows), "",
             f"chosen: {', '.join(r.sensors)} ({crit}; method {r.method}, "
             f"{'proven optimal' if r.proven_optimal else 'not proven optimal'})"]
    lines += [f"note: {n}" for n in r.notes]
    return "\n".join(lines)


def _largest_corr(names, C) -> str:
    """'0.987 (k5, k7)': the largest |correlation| of a covariance and its pair."""
    n = len(names)
    if n < 2 or not np.all(np.isfinite(C)):
        return "-"
    se = np.sqrt(np.diag(C))
    if np.any(se <= 0):
        return "-"
    R = C / np.outer(se, se)
    i, j = max(((a, b) for a in range(n) for b in range(a + 1, n)), key=lambda ab: abs(R[ab]))
    return f"{R[i, j]:+.3f} ({names[i]}, {names[j]})"


#: parameters per estimate table (each column holds "value +- error")
PARAMS_PER_TABLE = 5


def estimate_rows(results, params: slice | None = None) -> tuple[list, list]:
    """One row per fit: the fit on all study data and both fits of every split.

    Columns: model, data, sensors, each parameter's "value +- standard error" (second-order
    covariance; digits from the error, :func:`reports.view.fmt_value`) with its unit in the
    header (omitted when undeclared), and the largest correlation of the fit with its pair.
    ``params`` selects the parameter columns (all by default).
    """
    models = results.study.models
    names, units = _union_parameters(models, param_units(results.study))
    sel = list(range(len(names)))[params or slice(None)]
    head = ["model", "data", "sensors"] + [f"{names[i]}{unit_suffix(units[i])}" for i in sel] + ["largest |corr|"]

    def row(model, data, sensors, p, C):
        own = list(models[model].param_names) if model in models else list(names)
        ok = np.all(np.isfinite(C)) and np.all(np.isfinite(p))
        se = np.sqrt(np.clip(np.diag(C), 0, None)) if ok else np.full(len(p), np.nan)
        cells = []
        for i in sel:
            if names[i] not in own:              # a variant without this parameter
                cells.append("-")
                continue
            k = own.index(names[i])
            v, s = fmt_value(p[k], se[k])
            cells.append(v if s == "n/a" else f"{v} +- {s}")
        return [model, data, sensors] + cells + [_largest_corr(tuple(own), np.asarray(C, float))]

    rows = []
    for v, e in results.estimates.items():
        used = "all" if np.all(e.weights > 0) else ",".join(s for s, w in zip(e.sensors, e.weights) if w > 0)
        rows.append(row(v, "all study data", used, e.p, e.cov))
    det = results.detection
    if det is not None:
        for t in det.tests:
            sens = ",".join(results.design_sensors)
            rows.append(row(t.model, f"{t.split}: calibration", sens, t.p_cal, t.C_cal))
            rows.append(row(t.model, f"{t.split}: validation", sens, t.p_val, t.C_val))
    return head, rows


def _union_parameters(models: dict, first_units) -> tuple:
    """(names, units) of every variant's parameters, the first variant's first (variants may differ)."""
    names, units = [], []
    for k, m in enumerate(models.values()):
        for j, p in enumerate(m.params):
            if p.name not in names:
                names.append(p.name)
                units.append(first_units[j] if k == 0 else p.unit)
    return tuple(names), tuple(units)


def smallest_alpha(det, model: str, statistic: str | None = None):
    """(alpha_min, split name) of the split with the smallest alpha_min of one model (NaN, '' if none)."""
    st = statistic or det.settings.statistic
    best = (math.nan, "")
    for t in det.tests_of(model):
        a = t.alpha(st) if t.ok else math.nan
        if np.isfinite(a) and not (a >= best[0]):
            best = (a, t.split)
    return best


def verdict_rows(results) -> tuple[list, list, list]:
    """The verdict table of page 1: model, decision, smallest alpha_min and where, goodness of fit, trust.

    Returns header, rows and flags (rejected decisions / failed goodness-of-fit tests marked).
    """
    det = results.detection
    head = ["model", "decision", "smallest alpha_min (%)", "split of the smallest alpha_min",
            "goodness of fit (chi2 p)", "linearisation"]
    rows, flags = [], []
    for v in results.study.models:
        e = results.estimates.get(v)
        if det is not None and v in det.models:
            d = det.decision(v)
            word = d.decision
            a, where = smallest_alpha(det, v)
            a_txt = fmt_pct(a) if np.isfinite(a) else "failed"
        else:
            word, a_txt, where = "no verdict", "n/a", "-"
        if e is not None:
            g, trust = results.assessments[v].goodness, results.assessments[v].trust
            gof = fmt_p(g.pvalue) + ("" if not np.isfinite(g.pvalue) else
                                     (" (fails at 5 %)" if g.pvalue < 0.05 else " (passes at 5 %)"))
            gof_bad = bool(np.isfinite(g.pvalue) and g.pvalue < 0.05)
        else:
            gof, trust, gof_bad = "fit failed", "-", True
        rows.append([v, word, a_txt, where or "-", gof, trust])
        flags.append([False, word == "rejected", word == "rejected", False, gof_bad, trust.startswith("NOT")])
    return head, rows, flags


def alpha_rows(det, statistic: str, start: int = 0, stop: int | None = None) -> tuple[list, list, list]:
    """alpha_min (%) per split (rows) and model (columns) for one statistic; flags of rejected cells.

    ``start``/``stop`` select the splits shown (pagination); the decision row is added after the
    last split.
    """
    head = ["calibration", "validation"] + [f"{m}" for m in det.models]
    rows, flags = [], []
    thr = det.settings.tol / len(det.splits)
    stop = len(det.splits) if stop is None else min(stop, len(det.splits))
    for j in range(start, stop):
        sp = det.splits[j]
        t0 = det.tests_of(det.models[0])[j]
        row = [f"{sp.name}: {t0.cal_label}", t0.val_label]
        fl = [False, False]
        for m in det.models:
            t = det.tests_of(m)[j]
            a = t.alpha(statistic) if t.ok else math.nan
            row.append(fmt_alpha(a))
            fl.append(bool(np.isfinite(a) and a < thr))
        rows.append(row)
        flags.append(fl)
    if stop == len(det.splits):
        verdict = ["decision", f"(TOL/n = {100 * thr:.3g} %)"]
        vf = [False, False]
        for m in det.models:
            d = det.decision(m, statistic, det.settings.correction)
            verdict.append(d.decision)
            vf.append(d.decision == "rejected")
        rows.append(verdict)
        flags.append(vf)
    return head, rows, flags


#: left padding of a matplotlib table cell as a fraction of its width (matplotlib.table.Cell.PAD)
_CELL_PAD = 0.1
#: smallest font size content_widths shrinks to before it lets the widest columns share the rest
_MIN_FONT = 6.5


def _text_width_pt(text: str, size: float, bold: bool = False) -> float:
    """Width in points of one line of ``text`` in the default sans-serif font at ``size`` points."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextToPath
    prop = FontProperties(size=size, weight="bold" if bold else "normal")
    return TextToPath().get_text_width_height_descent(text, prop, ismath=False)[0]


def content_widths(head, rows, fontsize: float, width_in: float) -> tuple[list, float]:
    """(column widths as fractions of the table, font size) that show every cell in full.

    Each column gets w_c = (widest line of its header (bold) and cells + 6 pt) / (1 - PAD), PAD
    the cell's left padding; the room left over is shared equally.  When the columns need more
    than ``width_in`` inches, the font shrinks (not below 6.5 pt) until they fit; below that the
    widths are scaled down proportionally (the widest cells then touch their border).
    """
    def natural(size):
        w = []
        for c in range(len(head)):
            lines = [(ln, True) for ln in str(head[c]).split("\n")]
            lines += [(ln, False) for r in rows for ln in str(r[c]).split("\n")]
            w.append((max(_text_width_pt(t, size, b) for t, b in lines) + 6.0) / (1 - _CELL_PAD))
        return np.array(w)

    total = 72.0 * width_in
    size = float(fontsize)
    w = natural(size)
    while w.sum() > total and size > _MIN_FONT:
        size = max(_MIN_FONT, size - 0.5)
        w = natural(size)
    if w.sum() <= total:
        w = w + (total - w.sum()) / len(w)
    return list(w / w.sum()), size


def _text_table(head, rows) -> str:
    w = [max(len(str(x)) for x in col) for col in zip(head, *rows)]
    out = ["  ".join(str(h).ljust(w[i]) for i, h in enumerate(head)),
           "  ".join("-" * w[i] for i in range(len(head)))]
    out += ["  ".join(str(c).ljust(w[i]) for i, c in enumerate(r)) for r in rows]
    return "\n".join(out)


def draw_table(ax, head, rows, flags=None, col_widths=None, fontsize=8, title=None, highlight="#f4c7c3",
               chosen=None):
    """Draw a table on ``ax`` (axis switched off); ``flags`` marks cells to highlight, ``chosen`` rows in green."""
    ax.axis("off")
    if not rows:
        ax.text(0.5, 0.5, "(no rows)", ha="center", va="center", transform=ax.transAxes)
        return ax.figure
    tab = ax.table(cellText=[[str(c) for c in r] for r in rows], colLabels=head, loc="upper center",
                   cellLoc="left", colLoc="left", colWidths=col_widths)
    tab.auto_set_font_size(False)
    tab.set_fontsize(fontsize)
    tab.scale(1.0, 1.25)
    for (r, c), cell in tab.get_celld().items():
        cell.set_linewidth(0.3)
        if r == 0:
            cell.set_height(cell.get_height() * max(h.count("\n") + 1 for h in head))
            cell.set_facecolor("#e6e6e6")
            cell.set_text_props(weight="bold")
        elif flags is not None and flags[r - 1][c]:
            cell.set_facecolor(highlight)
            cell.set_text_props(weight="bold")
        elif chosen is not None and chosen[r - 1]:
            cell.set_facecolor("#d5ecd4")
    if title:
        ax.set_title(title, fontsize=fontsize + 2, loc="left")
    return ax.figure
