"""Tables of a study as formatted text and as matplotlib tables (no LaTeX).

Every function takes a :class:`mudoe.study.StudyResults` (or the library object it names)
and returns text, or a list of rows for :func:`draw_table`.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["fmt_alpha", "normality_rows", "oed_rows", "oed_table_text", "estimate_rows", "alpha_rows",
           "draw_table", "sigma_rows"]


def fmt_alpha(a: float) -> str:
    """alpha_min in percent as in the paper ('<< 0.01' below 1e-4)."""
    if a is None or not np.isfinite(a):
        return "failed"
    return "<< 0.01" if a < 1e-4 else f"{100 * a:.2f}"


def normality_rows(study) -> tuple[list, list]:
    """Header and rows of the paper's 'Analysis of the measurement data' table (um)."""
    n = study.normality
    head = ["sensor", "Shapiro-Wilk p (%)", "sigma_rep (um)", "sigma_man (um)", "sigma used (um)", "how sigma was obtained"]
    rows = []
    for k, s in enumerate(n.sensors):
        st = study.sigma_table[k]
        rows.append([s, "n/a" if not np.isfinite(n.pvalue[k]) else f"{100 * n.pvalue[k]:.2f}",
                     f"{1e3 * n.sigma_rep[k]:.4g}",
                     "-" if not np.isfinite(st["sigma_man"]) else f"{1e3 * st['sigma_man']:.4g}",
                     "estimated" if not np.isfinite(st["sigma"]) else f"{1e3 * st['sigma']:.4g}", st["how"]])
    return head, rows


def sigma_rows(study):
    return normality_rows(study)


def oed_rows(results) -> tuple[list, list]:
    """Header and rows of the OED table (paper Table 'Outcome for the optimal design'), chosen row marked."""
    t = results.oed_table
    chosen = results.oed.sensors if results.oed is not None else ()
    head = ["combination", "sensors", "Psi_A", "Psi_D (det)", "Psi_E", "flag"]
    rows = []
    for r in t.rows:
        mark = "  <= chosen" if tuple(r.sensors) == tuple(chosen) else ""
        rows.append([r.mask + (" (all)" if "0" not in r.mask else ""), " ".join(r.sensors), f"{r.A:.4e}",
                     f"{r.det:.4e}", f"{r.E:.4e}", (r.flag or "") + mark])
    return head, rows


def oed_table_text(results) -> str:
    """The OED table as fixed-width text, with the chosen design and how it was found."""
    head, rows = oed_rows(results)
    r = results.oed
    lines = [f"Optimal sensor design ({r.criterion}-criterion, {r.kind} covariance) from the {results.oed_variant} "
             f"estimate; units of the criteria: parameters in N/mm",
             _text_table(head, rows), "",
             f"chosen: {', '.join(r.sensors)} ({r.criterion} = {r.value:.4e}; method {r.method}, "
             f"{'proven optimal' if r.proven_optimal else 'not proven optimal'})"]
    lines += [f"note: {n}" for n in r.notes]
    return "\n".join(lines)


def estimate_rows(results) -> tuple[list, list]:
    """One row per fit: the fit on all study data and both fits of every split.

    Columns: model, data, sensors, each parameter's estimate and standard error (second-order
    covariance, unit of the parameter), and the correlation of the first two parameters.
    """
    first = next(iter(results.study.models.values()))
    names, units = first.param_names, [p.unit for p in first.params]
    head = ["model", "data", "sensors"]
    for n, u in zip(names, units):
        head += [f"{n} ({u})", f"std err {n}"]
    if len(names) >= 2:
        head.append(f"corr({names[0]},{names[1]})")

    def row(model, data, sensors, p, C):
        ok = np.all(np.isfinite(C)) and np.all(np.isfinite(p))
        se = np.sqrt(np.diag(C)) if ok else np.full(len(p), np.nan)
        r = [model, data, sensors]
        for i in range(len(names)):
            r += [f"{p[i]:.2f}" if np.isfinite(p[i]) else "failed", f"{se[i]:.2f}" if np.isfinite(se[i]) else "-"]
        if len(names) >= 2:
            r.append(f"{C[0, 1] / (se[0] * se[1]):.3f}" if ok and se[0] > 0 and se[1] > 0 else "-")
        return r

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


def alpha_rows(det, statistic: str) -> tuple[list, list, list]:
    """alpha_min (%) per split (rows) and model (columns) for one statistic; flags of rejected cells."""
    head = ["calibration", "validation"] + [f"{m}" for m in det.models]
    rows, flags = [], []
    thr = det.settings.tol / len(det.splits)
    for j, sp in enumerate(det.splits):
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
    verdict = ["decision", f"(TOL/n = {100 * thr:.3g} %)"]
    vf = [False, False]
    for m in det.models:
        d = det.decision(m, statistic, det.settings.correction)
        verdict.append(d.decision.upper())
        vf.append(d.decision == "reject")
    rows.append(verdict)
    flags.append(vf)
    return head, rows, flags


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
