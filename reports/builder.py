"""The report builder: the only module of :mod:`reports` that writes files.

:func:`build_report` writes ``report.pdf`` (multi-page, vector, matplotlib ``PdfPages``),
one PNG per page (150 dpi by default) and ``results.json`` (config, data hash, package
versions, timing, every number of the report).  Everything is first written into a
temporary folder inside ``out_dir`` and moved into place with ``os.replace`` only when
all files are complete: a failure leaves no partial file behind (earlier reports stay), and
an interrupted process removes the folder and never moves part of the files
(:mod:`models.fileio`).  Pages of an earlier report in the folder (its ``results.json`` lists
them) that the new one does not have are then removed, so no stale page stays beside the new ones.

Pages (:func:`report_pages`): verdict table and verdicts; measured data and model outputs;
normality and sigma; optimal sensor design; estimates; confidence regions of every parameter
pair; alpha_min tables; prediction bands; residual diagnostics; the model error of each variant;
what the model misses (diagnostic splits); the Monte Carlo size study when run.  Every page names the study's
own quantities (:mod:`reports.view`); grids hold at most 6 panels a row and 3 rows a page,
tables at most 25 rows a page (more pages instead of smaller print).  ``results.json``
holds, besides every number, the texts drawn on each page (``pages``).

Everything drawn comes from one :class:`oed.study_record.StudyRecord` the study filled
(:func:`mudoe.report_record.study_record`); the builder reads nothing else and calls nothing of the study.
"""
from __future__ import annotations

import os
import secrets
import shutil
import textwrap
import time
from functools import partial
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from models.fileio import publishing, register_scratch, release_scratch
from oed.best_designs import RankedDesignTable
from oed.study_record import StudyRecord

from .page_layout import PAGE_SIZE, ROWS_PER_PAGE, TEXT_LINE_HEIGHT
from .page_layout import chunks as _chunks, draw_text as _text, new_page as _page, part_label as _part
from .view import STATISTIC_WORDS, fmt_pct, fmt_value

__all__ = ["build_report", "report_pages", "verdict_paragraphs", "page_texts", "pair_grid_sets", "PAGE_SIZE"]

def verdict_paragraphs(results) -> list[tuple[str, str]]:
    """One paragraph per model: the verdict of Algorithm 1 with its numbers and goodness of fit (plain text)."""
    from .tables import smallest_alpha
    out = []
    det = results.detection
    for v in results.study.models:
        parts = []
        e = results.estimates.get(v)
        if e is not None:
            est = ", ".join(f"{n} = {a} +- {b}{(' ' + u) if u else ''}" for n, (a, b), u in
                            zip(e.param_names, (fmt_value(p, s) for p, s in zip(e.p, e.stderr)), e.param_units))
            g = results.assessments[v].goodness
            parts.append(f"Fit on all study data (all sensors): {est}; reduced chi2 {e.reduced_chi2:.3g}.")
            if np.isfinite(g.pvalue):
                rejected = det is not None and v in det.models and det.decision(v).decision == "rejected"
                fails = g.pvalue < 0.05
                parts.append(f"Goodness of fit (chi2 test with the sensor sigmas): {g.text()}: "
                             + ("the fit FAILS it at 5 %: the model or the sigmas are inadequate and the covariance "
                                "understates the uncertainty." if fails else "passes at 5 %.")
                             + (" The split tests compare parameter sets; a misfit that is the same in every split "
                                "does not move them: read 'not rejected' together with this test."
                                if fails and not rejected else ""))
            else:
                parts.append(f"Goodness of fit: {g.text()}.")
            if results.assessments[v].trust == "NOT trustworthy":
                parts.append("Its linearisation is NOT trustworthy (Bates-Watts curvature): do not read its "
                             "confidence ellipses and +- standard errors; use its profile-likelihood intervals "
                             f"(pages 'Uncertainty of {v}').")
        elif v in results.estimate_errors:
            parts.append(f"The fit on all study data failed: {results.estimate_errors[v]}.")
        if det is not None and v in det.models:
            d = det.decision(v)
            other = "two_sample" if det.settings.statistic != "two_sample" else "likelihood_ratio"
            d2 = det.decision(v, other)
            parts.insert(0, f"{v}: {d.decision} ({STATISTIC_WORDS[d.statistic]} statistic, "
                            f"{d.correction}, TOL = {100 * d.tol:g} %, {d.n_tests} tests): {d.reason}.")
            if d2.decision != d.decision:
                parts.append(f"The {STATISTIC_WORDS[other]} statistic decides '{d2.decision}' "
                             f"({d2.reason}).")
            else:
                a2, _ = smallest_alpha(det, v, other)
                parts.append(f"The {STATISTIC_WORDS[other]} statistic agrees (smallest alpha_min {100 * a2:.3g} %).")
        else:
            why = results.detection_error or "; ".join(n for n in results.notes if "detection" in n) or "not run"
            parts.insert(0, f"{v}: no verdict ({why}).")
        out.append((v, " ".join(parts)))
    return out


def _title_page(results):
    from .tables import content_widths, draw_table, verdict_rows
    fig = _page()
    s = results.study
    config = s.config
    fig.text(0.04, 0.95, config.title, fontsize=18, weight="bold", va="top")
    head, rows, flags = verdict_rows(results)
    h = 0.03 * (len(rows) + 1)
    ax = fig.add_axes([0.04, 0.87 - h, 0.92, h])
    widths, size = content_widths(head, rows, 9, 0.92 * PAGE_SIZE[0])
    draw_table(ax, head, rows, flags=flags, fontsize=size, col_widths=widths, title="Verdicts (Algorithm 1)")
    y = 0.87 - h - 0.01
    det = results.detection
    if det is not None:
        y -= 0.022 * _text(fig, 0.04, y, (
            f"Decision and alpha_min: {STATISTIC_WORDS[det.settings.statistic]} statistic; rejected when some "
            f"split's alpha_min is below TOL/n_tests = {100 * det.settings.tol / len(det.splits):.3g} % "
            f"({det.settings.correction}, TOL = {100 * det.settings.tol:g} %, {len(det.splits)} splits); undecided "
            "when a split failed and none rejects. Goodness of fit: chi2 test of all residuals with the sensor "
            "sigmas (fails below 5 %). Linearisation: whether the confidence regions drawn from the "
            "covariance may be read as likelihood regions."), width=175, size=8, color="0.25") + 0.015
    for v, par in verdict_paragraphs(results):
        y -= 0.021 * _text(fig, 0.04, y, par, width=170, size=8.5) + 0.012
    c = s.source
    meta = (f"Config: {config.path}    Data: {c.source}" + (f" ({', '.join(Path(f).name for f in c.files)})"
                                                          if c.files else "")
            + f"\nsha256 of the data: {c.sha256}\n"
            f"{c.n_M} series x {c.n_q} {s.input_rows} x {len(s.sensors)} sensors; study series: "
            f"{'all' if config.series is None else ', '.join(str(i + 1) for i in config.series)} (1-based); "
            f"sensors used by the tests: {', '.join(results.design_sensors) or 'n/a'} ({results.design_how or 'n/a'})\n"
            f"Built {datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC')}")
    y -= 0.02 * _text(fig, 0.04, y, meta, width=175, size=7.5, color="0.35") + 0.015
    mesh = results.discretisation                                # dynamic studies: {variant: MeshSummary}
    notes = [(nt, False) for nt in list(results.notes) + list(s.notes)]
    notes += [(f"{v}: {m.text()}", not m.bounded) for v, m in mesh.items()]
    if notes:
        fig.text(0.04, y, "Notes", fontsize=10, weight="bold", va="top")
        y -= 0.03
        for k, (nt, bad) in enumerate(notes, 1):
            y -= 0.02 * _text(fig, 0.04, y, f"[{k}] {nt}", width=175, size=7.5,
                              **(dict(color="tab:red", weight="bold") if bad else {})) + 0.004
    errors = "the model error of each variant, " if results.model_error_views else ""
    _text(fig, 0.04, 0.045, "Contents: " + ("trajectories against time with prediction bands, normality and sigma, "
          + ("design of the next experiments" if getattr(results.plan, "mode", "") == "inputs" else "sampling-time design")
          + ", estimates, confidence regions, alpha_min tables, " + errors + "residuals against time "
          "and against the outputs." if s.pages == "trajectories" else
          "measurement data and model outputs, normality and sigma, optimal sensor design, "
          "estimates, confidence regions, alpha_min tables, prediction bands, residual diagnostics, "
          + errors + "what the model misses."), width=165, size=8, color="0.4")
    return fig


#: panels per row / rows per page of the grid pages (never shrink below readable)
MAX_COLS, MAX_ROWS = 6, 3
#: lines (title, header, rows, decision) of the alpha_min tables on one page
ALPHA_LINES = 24


def _loops_page(results):
    from .figures import measurement_loops
    s = results.study
    per = MAX_COLS
    parts = _chunks(len(s.sensors), per)
    figs = []
    for n, part in enumerate(parts):
        fig = _page("Measured data and model outputs" + _part(n, len(parts)))
        names = [s.sensors[k] for k in part]
        ncol = min(len(names), 3)
        axes = np.atleast_1d(fig.subplots(int(np.ceil(len(names) / 3)), ncol, squeeze=False).ravel())
        for ax, sname in zip(axes, names):
            measurement_loops(s, results.estimates, sname, ax=ax)
        for ax in axes[len(names):]:
            ax.axis("off")
        fig.subplots_adjust(left=0.06, right=0.98, top=0.88, bottom=0.12, wspace=0.3, hspace=0.4)
        fig.text(0.04, 0.04, "Grey: measured series (dark: used by the study; light: the others). Lines: each "
                 "model's output at its estimate from all study data and all sensors.", fontsize=8)
        figs.append(fig)
    return figs


def _normality_page(results):
    from .tables import ALL_SERIES, draw_table, normality_checks, normality_rows, normality_widths
    s = results.study
    det = results.detection
    gate = det.normality[0][1] if det is not None and det.normality else None
    head, rows = normality_rows(s, gate)
    figs = []
    parts = _chunks(len(rows), ROWS_PER_PAGE)
    for n, part in enumerate(parts):
        fig = _page("Analysis of the measurement data (normality gate, sensor sigma)" + _part(n, len(parts)))
        chunk = [rows[k] for k in part]
        h = min(0.03 * (len(chunk) + 2), 0.75)
        ax = fig.add_axes([0.04, 0.88 - h, 0.92, h])
        draw_table(ax, head, chunk, fontsize=9, col_widths=normality_widths(head))
        figs.append(fig)
    said = []
    for name, chk in normality_checks(s, gate):
        said.append(f"on {'all series' if name == ALL_SERIES else 'the ' + name} ({chk.series_text()}; "
                    f"differences {chk.pairs_text()}): "
                    + ("passed" if chk.passed else ("FAILED (overridden)" if chk.overridden else "FAILED"))
                    + (f" for the sensors used by the tests ({', '.join(chk.gated)})" if chk is gate else "")
                    + (f" (failing: {', '.join(chk.failing())})" if chk.failing() else ""))
    over = s.normality_over
    txt = (f"Normality gate: {(gate or s.normality).gate_text()} (one test per sensor, on the differences of "
           f"consecutive series over {over}), {'; '.join(said)}. sigma_rep = std(differences)/sqrt(2). The sigma used by every "
           "fit is composed as in the paper, sqrt(sigma_rep^2 + sigma_man^2) with sigma_rep on all series, unless "
           "given directly in the config. The terminal (mudoe detect) prints the gate of Algorithm 1 (line 05) on "
           "the study series, in the same unit.")
    if results.detection_error:
        txt += f"\nDetection stopped: {results.detection_error}"
    _text(figs[-1], 0.04, max(0.88 - min(0.03 * (len(part) + 2), 0.75) - 0.05, 0.12), txt, width=160, size=9)
    return figs


def _oed_page(results):
    from .tables import criteria_units, draw_table, oed_rows
    fig = _page("Optimal sensor design")
    if results.oed is None:
        _text(fig, 0.04, 0.85, "Not available: " + "; ".join(n for n in results.notes if "design" in n), size=10)
        return fig
    head, rows = oed_rows(results)
    chosen = [tuple(r.sensors) == tuple(results.oed.chosen) for r in results.oed_table.rows]
    figs = []
    parts = _chunks(len(rows), ROWS_PER_PAGE)
    for n, part in enumerate(parts):
        fig = fig if n == 0 else _page("Optimal sensor design" + _part(n, len(parts)))
        chunk = [rows[k] for k in part]
        h = min(0.03 * (len(chunk) + 1), 0.72)
        ax = fig.add_axes([0.04, 0.88 - h, 0.92, h])
        draw_table(ax, head, chunk, fontsize=9, chosen=[chosen[k] for k in part],
                   col_widths=[0.13, 0.17, 0.15, 0.15, 0.15, 0.25])
        figs.append(fig)
    r = results.oed
    names = ", ".join(results.study.models[results.oed_variant].param_names)
    value = f"log det C = {r.value:.4f}" if r.criterion == "D" else f"{r.criterion} = {r.value:.4e}"
    txt = (f"Criteria of the {results.oed_table.kind.replace('_', '-')} covariance C(w) of ({names}) "
           f"({criteria_units(results.study)}) for "
           + ((results.oed_table.note if isinstance(results.oed_table, RankedDesignTable) else "")
              or "every sensor combination")
           + ", from the information of each sensor "
           f"at the {results.oed_variant} estimate on all study data. Chosen ({r.criterion}-criterion, exactly "
           f"{len(r.chosen)} sensors): {', '.join(r.chosen)} (green), {value}, "
           f"{'proven optimal' if r.proven_optimal else 'not proven optimal'} ({r.method}). "
           + ("The detection tests use these sensors." if tuple(results.design_sensors) in ((), tuple(r.chosen))
              else f"The detection tests use {results.design_how} ({', '.join(results.design_sensors)}; next "
                   "page)."))
    for nt in r.notes:
        txt += f"\nNote: {nt}"
    _text(figs[-1], 0.04, max(0.88 - min(0.03 * (len(part) + 1), 0.72) - 0.05, 0.12), txt, width=170, size=9)
    return figs


def _estimate_pages(results):
    from .dynamic_pages import discretisation_lines
    from .tables import PARAMS_PER_TABLE, content_widths, draw_table, estimate_rows
    n_p = len({n for m in results.study.models.values() for n in m.param_names})   # variants may differ
    pparts = _chunks(n_p, PARAMS_PER_TABLE)
    figs = []
    for pk, pp in enumerate(pparts):
        head, rows = estimate_rows(results, slice(pp.start, pp.stop))
        rparts = _chunks(len(rows), ROWS_PER_PAGE)
        for rk, rp in enumerate(rparts):
            k, n = pk * len(rparts) + rk, len(pparts) * len(rparts)
            fig = _page("Estimates +- standard errors (second-order covariance)" + _part(k, n))
            chunk = [rows[i] for i in rp]
            h = min(0.03 * (len(chunk) + 1), 0.82)
            ax = fig.add_axes([0.04, 0.90 - h, 0.92, h])
            widths, size = content_widths(head, rows, 8, 0.92 * PAGE_SIZE[0])     # every page of a part alike
            draw_table(ax, head, chunk, fontsize=size, col_widths=widths)
            discretisation_lines(fig, results, 0.90 - h - 0.03)
            truth = results.study.truth
            if truth is not None:
                units = {p.name: p.unit for m in results.study.models.values() for p in m.params}
                _text(fig, 0.04, 0.11, f"Truth of the simulated data ({truth.source}): " + ", ".join(
                      f"{n} = {v:.6g}{(' ' + units.get(n, '')) if units.get(n) else ''}"
                      for n, v in truth.values.items()) + ".", width=150, size=8.5, weight="bold")
            fig.text(0.04, 0.03, "Digits follow the standard error (two significant digits; the value to the same "
                     "decimal). 'largest |corr|': the strongest correlation between two parameters of that fit.",
                     fontsize=8)
            figs.append(fig)
    return figs


def _ellipse_pages(results):
    """Every parameter pair of every model, one panel per split (at most MAX_ROWS x MAX_COLS panels a page); a
    time series' model of three or more parameters one page of all its pairs, the splits overlaid (GRID_SPLITS a
    page, GRID_PARAMS parameters a grid)."""
    from .figures import confidence_ellipses
    det = results.detection
    if det is None:
        fig = _page("Confidence regions: calibration vs validation estimates")
        _text(fig, 0.04, 0.85, "Detection was not run: " + (results.detection_error or "see the notes"), size=10)
        return fig
    ns = len(det.splits)
    level = 1 - det.settings.tol / ns
    st = det.settings.statistic
    second = "two_sample" if st != "two_sample" else "likelihood_ratio"
    rows = []
    gridded = [m for m in det.models if results.study.pages == "trajectories" and results.study.models[m].n_p > 2]
    for m in det.models:
        model = results.study.models[m]
        n = model.n_p
        if m not in gridded:                             # a panel per split (a time series' model of 3 or more
            rows += [(m, (i, j)) for i in range(n) for j in range(i + 1, n)]      # parameters: a grid of pairs)
    scols = _chunks(ns, MAX_COLS)
    rparts = _chunks(len(rows), MAX_ROWS) if rows else []
    grids = [(m, part, idx) for m in gridded for part in _chunks(ns, GRID_SPLITS)
             for idx in pair_grid_sets(results.study.models[m].n_p)]
    figs = []
    total = len(scols) * len(rparts) + len(grids)
    title = "Confidence regions: calibration vs validation estimates"
    for ci, cols in enumerate(scols if rows else []):
        for ri, rr in enumerate(rparts):
            fig = _page(title + _part(len(figs), total))
            ncol = MAX_COLS if len(scols) > 1 else max(len(cols), 2)
            axes = fig.subplots(MAX_ROWS, ncol, squeeze=False)          # every panel the same size
            for a, r in enumerate(rr):
                m, pair = rows[r]
                model = results.study.models[m]
                tests = det.tests_of(m)
                for b, j in enumerate(cols):
                    confidence_ellipses(tests[j], level, model.param_names, [p.unit for p in model.params],
                                        ax=axes[a, b], statistic=st, pair=pair, second_statistic=second)
            for ax in axes.ravel():
                if not ax.has_data() and not ax.texts:
                    ax.axis("off")
            h, lab = axes[0, 0].get_legend_handles_labels()
            fig.legend(h, lab, loc="upper right", ncol=5, fontsize=8, frameon=False, bbox_to_anchor=(0.98, 0.955))
            fig.subplots_adjust(left=0.07, right=0.98, top=0.86, bottom=0.12, hspace=0.8, wspace=0.4)
            _text(fig, 0.04, 0.055, f"Regions at level 1 - TOL/n_tests = {100 * level:.4g} % (Bonferroni), projected "
                  "on two parameters. Solid: G(TOL/n, p_cal, C_cal) (paper); dashed: region of p_val; dotted: "
                  "two-sample region around p_cal with C_cal + C_val. Panel titles: alpha_min of the decision "
                  f"statistic ({STATISTIC_WORDS[st]}) and of the {STATISTIC_WORDS[second]} statistic; red: the "
                  "split's hypothesis is rejected by the decision statistic. The likelihood-ratio statistic has no "
                  "drawn region.", width=175, size=8)
            figs.append(fig)
    figs += _pair_grid_pages(results, grids, level, title, len(figs), total)
    return figs


#: splits overlaid on one grid of parameter pairs (more: another page); parameters of one grid
GRID_SPLITS, GRID_PARAMS = 4, 6


def pair_grid_sets(n_p: int) -> list:
    """The parameter indices of each grid of pairs: all of them up to GRID_PARAMS; beyond, blocks of
    GRID_PARAMS / 2 taken two at a time (every pair on some grid)."""
    if n_p <= GRID_PARAMS:
        return [tuple(range(n_p))]
    blocks = _chunks(n_p, GRID_PARAMS // 2)
    return [tuple(blocks[i]) + tuple(blocks[j]) for i in range(len(blocks)) for j in range(i + 1, len(blocks))]


def _pair_grid_pages(results, grids, level, title, first, total):
    """Models of 3 or more parameters: one page per model (and per GRID_SPLITS splits), every pair in a
    lower-triangular grid with the splits overlaid (:func:`reports.region_figures.split_pair_grid`)."""
    from .region_figures import split_pair_grid
    det = results.detection
    st = det.settings.statistic
    second = "two_sample" if st != "two_sample" else "likelihood_ratio"
    truth = results.study.truth
    figs = []
    for k, (m, part, idx) in enumerate(grids):
        model = results.study.models[m]
        tests = [det.tests_of(m)[j] for j in part]
        known = truth is not None and truth.variant == m and all(n in truth.values for n in model.param_names)
        some = "" if len(idx) == model.n_p else f" ({', '.join(model.param_names[i] for i in idx)})"
        fig = _page(f"{title}, model {m}{some}" + _part(first + k, total))
        split_pair_grid(fig, tests, level, model.param_names, [p.unit for p in model.params], statistic=st,
                        second_statistic=second,
                        truth=[truth.values[n] for n in model.param_names] if known else None,
                        rect=(0.08, 0.16, 0.97, 0.9), indices=idx)
        _text(fig, 0.04, 0.075, f"Every pair of the parameters of {m}, the splits overlaid (one colour each), regions "
              f"at level 1 - TOL/n_tests = {100 * level:.4g} % (Bonferroni) projected on the pair. Solid: G(TOL/n, "
              "p_cal, C_cal) (paper); dashed: region of p_val; dotted: two-sample region around p_cal with C_cal + "
              f"C_val. Legend: alpha_min of the decision statistic ({STATISTIC_WORDS[st]}) and of the "
              f"{STATISTIC_WORDS[second]} statistic per split; a red-edged square: the split's hypothesis is rejected "
              "by the decision statistic. The likelihood-ratio statistic has no drawn region."
              + (f" Star: the true parameters of the simulated data ({truth.source})." if known else ""),
              width=175, size=8)
        figs.append(fig)
    return figs


def _alpha_pages(results):
    from .tables import alpha_rows, draw_table
    det = results.detection
    title = "alpha_min (in %) per split and model, three statistics"
    if det is None:
        fig = _page(title)
        _text(fig, 0.04, 0.85, "Detection was not run: " + (results.detection_error or "see the notes"), size=10)
        return fig
    stats_ = (("likelihood_ratio", "likelihood ratio: pooled fit vs separate fits"),
              ("two_sample", "two-sample Wald statistic, C_cal + C_val"),
              ("paper", "paper's statistic, C_cal only"))
    ns = len(det.splits)
    n_m = len(det.models)
    blocks = []                     # (statistic, label, split range)
    for st, label in stats_:
        for part in _chunks(ns, ALPHA_LINES - 3):
            blocks.append((st, label, part))
    pages, lines = [[]], 0
    for blk in blocks:                  # pack whole tables, at most ALPHA_LINES table lines a page
        size = len(blk[2]) + 3
        if pages[-1] and lines + size > ALPHA_LINES:
            pages.append([])
            lines = 0
        pages[-1].append(blk)
        lines += size
    figs = []
    for pk, page in enumerate(pages):
        fig = _page(title + _part(pk, len(pages)))
        y = 0.88
        for st, label, part in page:
            head, rows, flags = alpha_rows(det, st, part.start, part.stop)
            prim = " (the decision)" if st == det.settings.statistic else ""
            h = 0.028 * (len(rows) + 1)
            ax = fig.add_axes([0.04, y - h - 0.03, 0.92, h])
            draw_table(ax, head, rows, flags=flags, fontsize=8.5, title=f"{label}{prim}",
                       col_widths=[0.38, 0.22] + [0.36 / n_m] * n_m)
            y -= h + 0.065
        _text(fig, 0.04, min(max(y, 0.03), 0.12),
              f"TOL = {100 * det.settings.tol:g} %, n_tests = {ns}, correction: {det.settings.correction}. "
              f"Red cells: alpha_min < TOL/n_tests (the split's hypothesis is rejected); a model is rejected when "
              f"any split is red. '<< 0.01' means alpha_min < 0.01 %. The paper's statistic ignores the validation "
              f"estimate's covariance and rejects a correct model more often than TOL (shown by the Monte Carlo "
              f"size study of the test).", width=170, size=8.5)
        figs.append(fig)
    return figs


def _band_pages(results):
    """Prediction bands of every model's fitted outputs as the study computed them (``results.bands``), at
    most 6 sensors a page."""
    from .figures import prediction_band_plot
    figs = []
    for v, e in results.estimates.items():
        if v not in results.bands:
            fig = _page(f"Prediction bands of {v}")
            _text(fig, 0.04, 0.85, "Not computed by the study (mudoe.study.run_bands).", size=10)
            figs.append(fig)
            continue
        bands, level = results.bands[v], results.bands[v].level
        sens = [s for s, w in zip(e.sensors, e.weights) if w > 0]
        parts = _chunks(len(sens), MAX_COLS)
        for n, part in enumerate(parts):
            fig = _page(f"Prediction bands of {v} (delta method, exact sensitivities)" + _part(n, len(parts)))
            names = [sens[k] for k in part]
            ncol = min(len(names), 3)
            axes = fig.subplots(int(np.ceil(len(names) / 3)), ncol, squeeze=False).ravel()
            for ax, s in zip(axes, names):
                prediction_band_plot(results.study, e, v, s, bands, ax=ax)
            for ax in axes[len(names):]:
                ax.axis("off")
            fig.subplots_adjust(left=0.06, right=0.98, top=0.88, bottom=0.14, wspace=0.3, hspace=0.4)
            q = "Student t" if e.sigma_estimated else "normal"
            _text(fig, 0.04, 0.06, f"Bands at {100 * level:g} %: h +- q sqrt(g^T C g) for the mean response (shaded) "
                  "and h +- q sqrt(g^T C g + sigma^2) for a new observation (dashed), g = dh/dp the exact "
                  f"sensitivities at each set point, C the second-order covariance, q the {q} quantile. Measured "
                  "values outside the dashed band more often than 5 % point to what the model misses.",
                  width=175, size=8)
            figs.append(fig)
    return figs


def _residual_pages(results):
    """Per model: standardized residuals against the input and in measurement order, normal probability plot."""
    from .figures import normal_probability_plot, residuals_plot, residuals_vs_order
    from .view import phase_labels
    if not results.estimates:
        fig = _page("Residual diagnostics")
        _text(fig, 0.04, 0.85, "No successful fit.", size=10)
        return fig
    phases = phase_labels(results.study)
    ph = ("markers distinguish the phases (" + ", ".join(dict.fromkeys(phases)) + ")"
          if phases is not None else "no phases declared")
    figs = []
    for v, e in results.estimates.items():
        fig = _page(f"Residual diagnostics of {v} (fit on all study data)")
        axes = fig.subplots(1, 3)
        residuals_plot(results.study, e, v, ax=axes[0])
        residuals_vs_order(results.study, e, v, ax=axes[1])
        normal_probability_plot(e, v, ax=axes[2])
        fig.subplots_adjust(left=0.06, right=0.98, top=0.86, bottom=0.22, wspace=0.3)
        _text(fig, 0.04, 0.1, f"Standardized residuals (z - h)/sigma of the sensors used by the fit; colours: "
              f"sensors; {ph}. Dashed lines: +-2. Left: a trend over the input shows a missing input dependence. "
              "Middle: series after series; a drift or a step between series shows a change during the campaign. "
              "Right: points on the red line are Gaussian with the assumed sigma; a slope above 1 means the "
              f"residuals are larger than sigma. Goodness of fit: {results.assessments[v].goodness.text()}.", width=175,
              size=8)
        figs.append(fig)
    return figs


def _misses_pages(results, diagnosis):
    """'What the model misses': the diagnostic split family, Holm-corrected, and its plain-language findings."""
    from .diagnosis import MISSES
    from .tables import draw_table
    title = "What the model misses (diagnostic splits, Holm-corrected)"
    if diagnosis is None:
        fig = _page(title)
        _text(fig, 0.04, 0.85, "Not available: detection was not run.", size=10)
        return fig
    head = ["model", "kind", "split", "alpha_min (%)", "Holm-adjusted (%)", "decision"]
    rows, flags = [], []
    for r in diagnosis.rows:
        rows.append([r.model, r.kind, r.split, fmt_pct(r.alpha) if not r.error else "failed",
                     fmt_pct(r.holm) if np.isfinite(r.holm) else "-", "rejected" if r.rejected else "not rejected"])
        flags.append([False, False, False, r.rejected, r.rejected, r.rejected])
    parts = _chunks(len(rows), ROWS_PER_PAGE)
    figs = []
    for n, part in enumerate(parts):
        fig = _page(title + _part(n, len(parts)))
        chunk = [rows[k] for k in part]
        h = 0.027 * (len(chunk) + 1)
        ax = fig.add_axes([0.04, 0.89 - h, 0.92, h])
        draw_table(ax, head, chunk, flags=[flags[k] for k in part], fontsize=8,
                   col_widths=[0.08, 0.12, 0.36, 0.13, 0.15, 0.16])
        figs.append(fig)
    findings = [s for m in results.study.models for s in diagnosis.misses(m)]
    kinds = sorted({r.kind for r in diagnosis.rows if r.kind != "study split"})
    txt = (f"Splits along one aspect of the data ask what a model misses: {'; '.join(f'{k}: {MISSES[k]}' for k in kinds)}"
           f". alpha_min of the {STATISTIC_WORDS[diagnosis.statistic]} statistic; Holm's step-down correction over "
           f"the study's splits and the diagnostic ones together, per model, at TOL = {100 * diagnosis.tol:g} %. "
           "The decision of page 1 uses the study's splits only.\n\n"
           + ("Findings:\n" + "\n".join(f"- {f}" for f in findings) if findings
              else "Findings: no diagnostic split rejects a model."))
    lines = "\n".join("\n".join(textwrap.wrap(par, 160)) if par else "" for par in txt.split("\n")).split("\n")
    fig, y = figs[-1], 0.89 - 0.027 * (len(parts[-1]) + 1) - 0.04
    while lines:                                    # as many lines as fit above the margin, the rest on new pages
        fit = max(0, int((y - 0.03) / TEXT_LINE_HEIGHT))
        if fit == 0:
            fig, y = _page(title + " (findings)"), 0.88
            figs.append(fig)
            continue
        _text(fig, 0.04, y, "\n".join(lines[:fit]), width=160, size=9)
        lines, y = lines[fit:], 0.0
    return figs


def page_texts(fig) -> list[str]:
    """Every text drawn on a page in reading order (top to bottom, then left to right).

    Titles, captions, axis and tick labels, legends and every table cell: what a reader of
    the page sees, for checks and for results.json.  Call after the page was drawn.
    """
    from matplotlib.table import Table
    from matplotlib.text import Text
    renderer = fig.canvas.get_renderer()
    found = []

    def walk(artist):
        if isinstance(artist, Table):
            for cell in artist.get_celld().values():
                t = cell.get_text()
                if t.get_text().strip():
                    found.append((cell.get_window_extent(renderer), t.get_text()))
            return
        if isinstance(artist, Text):
            if artist.get_visible() and artist.get_text().strip():
                found.append((artist.get_window_extent(renderer), artist.get_text()))
            return
        for child in artist.get_children():
            walk(child)

    walk(fig)
    found.sort(key=lambda bt: (-round(bt[0].y1 / 4), bt[0].x0))
    return [t for _, t in found]


def _validation_page(results):
    fig = _page("Monte Carlo check of the test (size study)")
    _text(fig, 0.04, 0.88, results.validation.summary(), width=200, size=7.5, family="monospace")
    return fig


def report_pages(results: StudyRecord, diagnosis=None, with_diagnosis: bool = True,
                 uncertainty: str = "untrusted") -> list:
    """The pages of a report in order: (name, function returning a figure or a list of figures).

    The one place where pages are listed; every page draws what the study computed (``results``, the
    :class:`oed.study_record.StudyRecord` of :func:`mudoe.report_record.study_record`).
    ``diagnosis`` (:class:`identification.studies.records.Diagnosis`, the study's ``results.diagnosis``) is shown on
    the page "What the model misses" when ``with_diagnosis``.  ``uncertainty`` (one of
    ``reports.uncertainty.UNCERTAINTY_CHOICES``): which of the models whose uncertainty the study
    computed (``results.uncertainty``) get the profile-likelihood / likelihood-ratio pages after the
    confidence regions -- "untrusted" (the models whose linearisation is NOT trustworthy), "all" or "none".
    """
    from .uncertainty import uncertainty_models
    from .uncertainty_pages import uncertainty_pages
    _require_record(results)
    pages = [("title", partial(_title_page, results)), ("loops", partial(_loops_page, results)),
             ("normality", partial(_normality_page, results)), ("oed", partial(_oed_page, results)),
             ("estimates", partial(_estimate_pages, results))]
    from .multistart_pages import multistart_pages, multistart_variants
    pages += [(f"multistart{k}", partial(multistart_pages, results, v))      # [identify] starts > 1
              for k, v in enumerate(multistart_variants(results), 1)]
    pages.append(("ellipses", partial(_ellipse_pages, results)))
    for k, v in enumerate(uncertainty_models(results, uncertainty), 1):
        pages.append((f"uncertainty{k}", partial(uncertainty_pages, results, v)))
    pages += [("alpha_min", partial(_alpha_pages, results)), ("bands", partial(_band_pages, results)),
              ("residuals", partial(_residual_pages, results))]
    if results.model_error_views:                        # issue 29: every variant whose model error was computed
        from .model_error_pages import model_error_pages, model_uncertainty_page
        if any(v.summary is not None for v in results.model_error_views.values()):
            pages.append(("model_uncertainty", partial(model_uncertainty_page, results)))
        pages += [(f"model_error{k}", partial(model_error_pages, results, v))
                  for k, v in enumerate(results.model_error_views, 1)]
    if results.plan is not None:                         # [oed] mode inputs / both / discrimination
        from .design_pages import design_pages
        pages.insert([n for n, _ in pages].index("oed") + 1, ("design", partial(design_pages, results)))
    if with_diagnosis:
        pages.append(("misses", partial(_misses_pages, results, diagnosis)))
    if results.validation is not None:
        pages.append(("validation", partial(_validation_page, results)))
    if results.study.pages == "trajectories":            # time series: reports.dynamic_pages
        from .dynamic_pages import dynamic_pages
        pages = dynamic_pages(pages, results)
    return pages


def _require_record(results) -> None:
    """TypeError unless ``results`` is a :class:`oed.study_record.StudyRecord` (what the study fills)."""
    if not isinstance(results, StudyRecord):
        raise TypeError(f"results: expected an oed.study_record.StudyRecord, got {type(results).__name__}; a "
                        "study's results give theirs with mudoe.report_record.study_record(results)")


def _previous_pages(out: Path) -> set:
    """The page PNGs of the report in ``out`` (the ``files`` of its results.json; empty if none)."""
    import json
    try:
        files = json.loads((out / "results.json").read_text(encoding="utf-8")).get("files", [])
    except (OSError, ValueError, AttributeError):
        return set()
    return {f for f in files if isinstance(f, str) and f.startswith("page") and f.endswith(".png")
            and Path(f).name == f}


def build_report(results: StudyRecord, out_dir, dpi: int | None = None, diagnose: bool = True,
                 uncertainty: str | None = None, progress=None) -> list[Path]:
    """Write report.pdf, one PNG per page and results.json into ``out_dir`` (atomically).

    Parameters
    ----------
    results : oed.study_record.StudyRecord
        What the study computed (:func:`mudoe.report_record.study_record` of its results).
    out_dir : path
        Created if missing.
    dpi : int, optional
        PNG resolution (default: the config's [report] dpi, 150).
    diagnose : bool
        Show the page "What the model misses": the diagnostic split family the study computed
        (``results.diagnosis``, :func:`mudoe.study.run_diagnosis`; "not available" without it).
    uncertainty : "untrusted", "all" or "none", optional
        Which of the models whose uncertainty the study computed (``results.uncertainty``,
        :func:`mudoe.study.run_uncertainty`) get the pages "Uncertainty of ...": profile-likelihood
        intervals next to the Wald ones and the likelihood-ratio region of every parameter pair next
        to its ellipse (default: the config's [report] uncertainty, "untrusted": the models whose
        linearisation is NOT trustworthy).
    progress : identification.progress.Progress, optional
        A bar over the pages (default None: no output).

    Returns
    -------
    list of Path
        The written files.

    Raises
    ------
    Exception
        Whatever failed; the temporary files are removed first and no file in ``out_dir``
        is replaced.
    """
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.backends.backend_pdf import PdfPages

    from .serialize import diagnosis_dict, dumps, package_versions, results_dict

    from identification.progress import Progress

    from .uncertainty import UNCERTAINTY_CHOICES
    if uncertainty is not None and uncertainty not in UNCERTAINTY_CHOICES:
        raise ValueError(f"uncertainty: expected one of {', '.join(repr(c) for c in UNCERTAINTY_CHOICES)}, "
                         f"got {uncertainty!r}")
    _require_record(results)
    config = results.study.config
    uncertainty = config.uncertainty if uncertainty is None else uncertainty
    t0 = time.perf_counter()
    dpi = int(dpi or config.dpi)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    previous = _previous_pages(out)
    tmp = out / f".report-{secrets.token_hex(6)}"
    register_scratch(tmp)           # before it exists: an interrupted process removes it (models.fileio)
    written = []
    try:
        tmp.mkdir(mode=0o700)
        diagnosis = results.diagnosis
        pages = report_pages(results, diagnosis, diagnose, uncertainty)
        names, texts = [], []
        with PdfPages(tmp / "report.pdf", metadata={"Title": config.title, "Creator": "mudoe"}) as pdf, \
                (progress or Progress(False)).bar(len(pages), "report pages", unit="page") as bar:
            k = 0
            for name, make in pages:
                figs = make()
                figs = figs if isinstance(figs, list) else [figs]
                bar.total += len(figs) - 1          # the bar counts the pages written (a maker may give several)
                bar.refresh()
                for i, fig in enumerate(figs):
                    k += 1
                    pdf.savefig(fig)
                    png = f"page{k:02d}_{name}{'' if len(figs) == 1 else f'_{i + 1}'}.png"
                    fig.savefig(tmp / png, dpi=dpi)
                    names.append(png)
                    texts.append(dict(file=png, texts=page_texts(fig)))
                    plt.close(fig)
                    bar.update(1)
        timing = dict(results.timing)
        timing["report_build"] = time.perf_counter() - t0
        meta = dict(config=config.values, config_text=config.text, data_sha256=results.study.source.sha256,
                    versions=package_versions(), timing_s=timing,
                    created=datetime.now(timezone.utc).isoformat(timespec="seconds"),
                    files=["report.pdf"] + names + ["results.json"],
                    verdicts=dict(results.detection.verdicts) if results.detection is not None else {},
                    results=results_dict(results), pages=texts,
                    diagnosis=diagnosis_dict(diagnosis) if diagnosis is not None else None)
        (tmp / "results.json").write_text(dumps(meta), encoding="utf-8")
        with publishing():          # all files or none: an interrupt waits for the moves (models.fileio)
            for name in ["report.pdf"] + names + ["results.json"]:
                os.replace(tmp / name, out / name)
                written.append(out / name)
            for name in sorted(previous - set(names)):      # pages of the previous report this one does not have
                (out / name).unlink(missing_ok=True)
    except OSError as exc:
        if exc.filename is None:           # e.g. [Errno 28] from a buffered write: name the folder
            raise OSError(exc.errno, f"{exc.strerror} (writing the report into {out})", str(out)) from None
        raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        release_scratch(tmp)
        plt.close("all")
    return written
