"""The report builder: the only module of :mod:`reports` that writes files.

:func:`build_report` writes ``report.pdf`` (multi-page, vector, matplotlib ``PdfPages``),
one PNG per page (150 dpi by default) and ``results.json`` (config, data hash, package
versions, timing, every number of the report).  Everything is first written into a
temporary folder inside ``out_dir`` and moved into place with ``os.replace`` only when
all files are complete: a failure leaves no partial file behind (earlier reports stay).
"""
from __future__ import annotations

import os
import shutil
import tempfile
import textwrap
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

__all__ = ["build_report", "verdict_paragraphs", "PAGE_SIZE"]

#: A4 landscape (inches)
PAGE_SIZE = (11.69, 8.27)


def verdict_paragraphs(results) -> list[tuple[str, str]]:
    """One paragraph per model: the verdict of Algorithm 1 with its numbers (plain text)."""
    out = []
    det = results.detection
    for v in results.study.models:
        parts = []
        e = results.estimates.get(v)
        if e is not None:
            est = ", ".join(f"{n} = {p:.1f} +- {s:.1f} {u}" for n, p, s, u in
                            zip(e.param_names, e.p, e.stderr, e.param_units))
            parts.append(f"Fit on all study data (all sensors): {est}; reduced chi2 {e.reduced_chi2:.3g}.")
            misfit = [n for n in e.notes if n.startswith("residuals exceed the sensor sigmas")]
            if misfit:
                rejected = det is not None and v in det.models and det.decision(v).decision == "reject"
                parts.append(f"Goodness of fit: {misfit[0]}." + ("" if rejected else
                             " The split tests compare parameter sets, and a misfit that is the same in every "
                             "split does not move them: read 'not rejected' together with this line."))
        elif v in results.estimate_errors:
            parts.append(f"The fit on all study data failed: {results.estimate_errors[v]}.")
        if det is not None and v in det.models:
            d = det.decision(v)
            other = "two_sample" if det.settings.statistic != "two_sample" else "likelihood_ratio"
            d2 = det.decision(v, other)
            word = {"reject": "REJECTED: model uncertainty detected", "accept": "not rejected",
                    "undecided": "UNDECIDED"}[d.decision]
            parts.insert(0, f"{v} is {word} ({d.statistic} statistic, {d.correction}, TOL = {100 * d.tol:g} %, "
                            f"{d.n_tests} tests): {d.reason}.")
            if d2.decision != d.decision:
                parts.append(f"The {other} statistic would decide '{d2.decision}' ({d2.reason}).")
            else:
                parts.append(f"The {other} statistic agrees (smallest alpha_min {100 * d2.min_alpha:.3g} %).")
        else:
            why = results.detection_error or "; ".join(n for n in results.notes if "detection" in n) or "not run"
            parts.insert(0, f"{v}: no verdict ({why}).")
        out.append((v, " ".join(parts)))
    return out


def _page(title=None):
    import matplotlib.pyplot as plt
    fig = plt.figure(figsize=PAGE_SIZE)
    if title:
        fig.suptitle(title, x=0.04, y=0.97, ha="left", fontsize=14, weight="bold")
    return fig


def _text(fig, x, y, text, width=150, size=9, **kw):
    wrapped = "\n".join("\n".join(textwrap.wrap(par, width)) if par else "" for par in text.split("\n"))
    fig.text(x, y, wrapped, va="top", ha="left", fontsize=size, family=kw.pop("family", "sans-serif"), **kw)
    return wrapped.count("\n") + 1


def _title_page(results, cfg):
    fig = _page()
    s = results.study
    fig.text(0.04, 0.93, cfg.report.title, fontsize=18, weight="bold", va="top")
    c = s.campaign
    meta = (f"Config: {cfg.path}    Data: {c.source}" + (f" ({', '.join(Path(f).name for f in c.files)})"
                                                          if c.files else "")
            + f"\nsha256 of the data: {c.sha256}\n"
            f"{c.n_M} series x {c.n_q} set points x {len(s.sensors)} sensors; study series: "
            f"{'all' if cfg.data.series is None else ', '.join(str(i + 1) for i in cfg.data.series)} (1-based); "
            f"sensors used by the tests: {', '.join(results.design_sensors) or 'n/a'} ({results.design_how or 'n/a'})\n"
            f"Built {datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC')}")
    y = 0.86
    n = _text(fig, 0.04, y, meta, width=170, size=8, color="0.25")
    y -= 0.022 * n + 0.03
    fig.text(0.04, y, "Verdicts (Algorithm 1)", fontsize=12, weight="bold", va="top")
    y -= 0.04
    for v, par in verdict_paragraphs(results):
        n = _text(fig, 0.04, y, par, width=160, size=9.5)
        y -= 0.024 * n + 0.02
    notes = list(results.notes) + list(s.notes)
    if notes:
        fig.text(0.04, y, "Notes", fontsize=11, weight="bold", va="top")
        y -= 0.035
        for k, nt in enumerate(notes, 1):
            n = _text(fig, 0.04, y, f"[{k}] {nt}", width=170, size=8)
            y -= 0.022 * n + 0.005
    fig.text(0.04, 0.03, "Contents: measurement loops, normality and sigma, optimal sensor design, estimates, "
             "confidence ellipses, alpha_min tables, residuals.", fontsize=8, color="0.4")
    return fig


def _loops_page(results):
    from .figures import measurement_loops
    s = results.study
    fig = _page("Measurement loops and model outputs")
    n = len(s.sensors)
    axes = fig.subplots(1, n) if n <= 3 else fig.subplots(int(np.ceil(n / 3)), 3).ravel()
    axes = np.atleast_1d(axes)
    for k, sname in enumerate(s.sensors):
        measurement_loops(s, results.estimates, sname, ax=axes[k])
    for ax in axes[n:]:
        ax.axis("off")
    fig.subplots_adjust(left=0.06, right=0.98, top=0.86, bottom=0.12, wspace=0.3)
    fig.text(0.04, 0.04, "Grey: measured series (dark: used by the study; light: the others). Lines: each model's "
             "output at its estimate from all study data and all sensors.", fontsize=8)
    return fig


def _normality_page(results):
    from .tables import draw_table, normality_rows
    s = results.study
    fig = _page("Analysis of the measurement data (normality gate, sensor sigma)")
    head, rows = normality_rows(s)
    ax = fig.add_axes([0.04, 0.45, 0.92, 0.42])
    draw_table(ax, head, rows, fontsize=9, col_widths=[0.08, 0.14, 0.13, 0.13, 0.14, 0.38])
    pairs = ", ".join(f"z{b + 1}-z{a + 1}" for a, b in s.normality.pairs)
    txt = (f"Shapiro-Wilk test of the differences of consecutive series ({pairs}) over all set points, per "
           f"sensor, at level {100 * s.normality.level:g} % (Algorithm 1, line 05): "
           f"{'passed' if s.normality.passed else 'FAILED'} for every series of the campaign. sigma_rep = "
           "std(differences)/sqrt(2). The sigma used by every fit is composed as in the paper, "
           "sqrt(sigma_rep^2 + sigma_man^2), unless given directly in the config.")
    det = results.detection
    if det is not None:
        for m, chk in det.normality[:1]:
            txt += (f"\nGate on the study series ({', '.join(chk.gated)}): "
                    f"{'passed' if chk.passed else ('FAILED (overridden)' if chk.overridden else 'FAILED')}.")
    if results.detection_error:
        txt += f"\nDetection stopped: {results.detection_error}"
    _text(fig, 0.04, 0.40, txt, width=170, size=9)
    return fig


def _oed_page(results):
    from .tables import draw_table, oed_rows
    fig = _page("Optimal sensor design")
    if results.oed is None:
        _text(fig, 0.04, 0.85, "Not available: " + "; ".join(n for n in results.notes if "design" in n), size=10)
        return fig
    head, rows = oed_rows(results)
    chosen = [tuple(r.sensors) == tuple(results.oed.sensors) for r in results.oed_table.rows]
    ax = fig.add_axes([0.04, 0.40, 0.92, 0.47])
    draw_table(ax, head, rows, fontsize=9, chosen=chosen, col_widths=[0.13, 0.17, 0.15, 0.15, 0.15, 0.25])
    r = results.oed
    txt = (f"Criteria of the {results.oed_table.kind.replace('_', '-')} covariance C(w) of (k5, k7) (N/mm; A: trace "
           f"(N/mm)^2, D: det (N/mm)^4, E: largest eigenvalue (N/mm)^2) for every sensor combination, from the "
           f"information of each sensor at the {results.oed_variant} estimate on all study data. Chosen "
           f"({r.criterion}-criterion, exactly {len(r.sensors)} sensors): {', '.join(r.sensors)} "
           f"(green), {r.criterion} = {r.value:.4e}, {'proven optimal' if r.proven_optimal else 'not proven optimal'} "
           f"({r.method}). The detection tests use these sensors.")
    for nt in r.notes:
        txt += f"\nNote: {nt}"
    _text(fig, 0.04, 0.35, txt, width=170, size=9)
    return fig


def _estimate_pages(results):
    from .tables import draw_table, estimate_rows
    head, rows = estimate_rows(results)
    per = 30
    figs = []
    for start in range(0, max(len(rows), 1), per):
        chunk = rows[start:start + per]
        part = f" ({start // per + 1}/{(len(rows) - 1) // per + 1})" if len(rows) > per else ""
        fig = _page("Estimates, standard errors (second-order covariance) and correlation" + part)
        ax = fig.add_axes([0.04, 0.06, 0.92, 0.82])
        n_rest = len(head) - 3
        draw_table(ax, head, chunk, fontsize=8, col_widths=[0.06, 0.34, 0.12] + [0.48 / n_rest] * n_rest)
        figs.append(fig)
    return figs


def _ellipse_page(results):
    from .figures import confidence_ellipses
    det = results.detection
    fig = _page("Confidence regions: calibration vs validation estimates")
    if det is None:
        _text(fig, 0.04, 0.85, "Detection was not run: " + (results.detection_error or "see the notes"), size=10)
        return fig
    nm, ns = len(det.models), len(det.splits)
    level = 1 - det.settings.tol / ns
    axes = np.atleast_2d(fig.subplots(nm, ns, squeeze=False))
    for i, m in enumerate(det.models):
        names = results.study.models[m].param_names
        for j, t in enumerate(det.tests_of(m)):
            confidence_ellipses(t, level, names[:2], "N/mm", ax=axes[i, j], statistic=det.settings.statistic)
    h, lab = axes[0, 0].get_legend_handles_labels()
    fig.legend(h, lab, loc="upper right", ncol=5, fontsize=8, frameon=False, bbox_to_anchor=(0.98, 0.955))
    fig.subplots_adjust(left=0.07, right=0.98, top=0.86, bottom=0.12, hspace=0.75, wspace=0.35)
    _text(fig, 0.04, 0.055, f"Regions at level 1 - TOL/n_tests = {100 * level:.4g} % (Bonferroni). Solid: "
             "G(TOL/n, p_cal, C_cal) (paper); dashed: region of p_val; dotted: two-sample region around p_cal "
             "with C_cal + C_val. A red title / point: the split's hypothesis is rejected "
             f"({det.settings.statistic} statistic).", width=190, size=8)
    return fig


def _alpha_page(results):
    from .tables import alpha_rows, draw_table
    det = results.detection
    fig = _page("alpha_min (in %) per split and model, three statistics")
    if det is None:
        _text(fig, 0.04, 0.85, "Detection was not run: " + (results.detection_error or "see the notes"), size=10)
        return fig
    y = 0.88
    for st, label in (("likelihood_ratio", "likelihood ratio: pooled fit vs separate fits"),
                      ("two_sample", "two-sample Wald statistic, C_cal + C_val"),
                      ("paper", "paper's statistic, C_cal only")):
        head, rows, flags = alpha_rows(det, st)
        prim = " (the decision)" if st == det.settings.statistic else ""
        h = 0.03 * (len(rows) + 1)
        ax = fig.add_axes([0.04, y - h - 0.03, 0.92, h])
        n_m = len(det.models)
        draw_table(ax, head, rows, flags=flags, fontsize=8.5, title=f"{label}{prim}",
                   col_widths=[0.38, 0.22] + [0.36 / n_m] * n_m)
        y -= h + 0.065
    _text(fig, 0.04, min(max(y, 0.03), 0.12),
          f"TOL = {100 * det.settings.tol:g} %, n_tests = {len(det.splits)}, correction: {det.settings.correction}. "
          f"Red cells: alpha_min < TOL/n_tests (the split's hypothesis is rejected); a model is rejected when any "
          f"split is red. '<< 0.01' means alpha_min < 0.01 %. The paper's statistic ignores the validation "
          f"estimate's covariance and rejects a correct model more often than TOL (identification.montecarlo).",
          width=170, size=8.5)
    return fig


def _residual_page(results):
    from .figures import residuals_plot
    fig = _page("Residuals of the fits on all study data")
    ests = list(results.estimates.items())
    if not ests:
        _text(fig, 0.04, 0.85, "No successful fit.", size=10)
        return fig
    axes = np.atleast_1d(fig.subplots(1, len(ests)))
    for ax, (v, e) in zip(axes, ests):
        residuals_plot(results.study, e, v, ax=ax)
    fig.subplots_adjust(left=0.06, right=0.98, top=0.86, bottom=0.12, wspace=0.3)
    return fig


def _validation_page(results):
    fig = _page("Monte Carlo check of the test (size study)")
    _text(fig, 0.04, 0.88, results.validation.table(), width=200, size=7.5, family="monospace")
    return fig


def build_report(results, out_dir, dpi: int | None = None) -> list[Path]:
    """Write report.pdf, one PNG per page and results.json into ``out_dir`` (atomically).

    Parameters
    ----------
    results : mudoe.study.StudyResults
    out_dir : path
        Created if missing.
    dpi : int, optional
        PNG resolution (default: the config's [report] dpi, 150).

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

    from .serialize import dumps, package_versions, results_dict

    t0 = time.perf_counter()
    cfg = results.study.cfg
    dpi = int(dpi or cfg.report.dpi)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".report-", dir=out))
    written = []
    try:
        pages = [("title", lambda: _title_page(results, cfg)), ("loops", lambda: _loops_page(results)),
                 ("normality", lambda: _normality_page(results)), ("oed", lambda: _oed_page(results)),
                 ("estimates", lambda: _estimate_pages(results)), ("ellipses", lambda: _ellipse_page(results)),
                 ("alpha_min", lambda: _alpha_page(results)), ("residuals", lambda: _residual_page(results))]
        if results.validation is not None:
            pages.append(("validation", lambda: _validation_page(results)))
        names = []
        with PdfPages(tmp / "report.pdf", metadata={"Title": cfg.report.title, "Creator": "mudoe"}) as pdf:
            k = 0
            for name, make in pages:
                figs = make()
                figs = figs if isinstance(figs, list) else [figs]
                for i, fig in enumerate(figs):
                    k += 1
                    pdf.savefig(fig)
                    png = f"page{k:02d}_{name}{'' if len(figs) == 1 else f'_{i + 1}'}.png"
                    fig.savefig(tmp / png, dpi=dpi)
                    names.append(png)
                    plt.close(fig)
        timing = dict(results.timing)
        timing["report_build"] = time.perf_counter() - t0
        meta = dict(config=cfg.as_dict(), config_text=cfg.text, data_sha256=results.study.campaign.sha256,
                    versions=package_versions(), timing_s=timing,
                    created=datetime.now(timezone.utc).isoformat(timespec="seconds"),
                    files=["report.pdf"] + names + ["results.json"],
                    verdicts=dict(results.detection.verdicts) if results.detection is not None else {},
                    results=results_dict(results))
        (tmp / "results.json").write_text(dumps(meta), encoding="utf-8")
        for name in ["report.pdf"] + names + ["results.json"]:
            os.replace(tmp / name, out / name)
            written.append(out / name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        plt.close("all")
    return written
