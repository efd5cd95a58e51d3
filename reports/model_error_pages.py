"""The pages "Model error of ...": what the study computed of a variant's model error (issue 29).

For one variant (``results.model_error_views[variant]``, an
:class:`identification.studies.records.ModelErrorView` the study computed, :mod:`mudoe.model_error_runs`):
the verdict of the 'no model error' test and the chosen error model, the discrepancy per sensor against the
first input (a dynamic model: against time, every experiment) with its band, the new-reading bands with and without the error model against the held-out
readings of one split, and the held-out coverage table.  Before them the page "Model uncertainty" of every variant
(:func:`model_uncertainty_page`, the records' :class:`identification.studies.records.ErrorSummary`): how large
the error is in the sensors' units and where, the band to design with, where to measure next and which model to
use (the ranking's verdict), and which sensor sigma the bands take as the noise of a reading (``view.noise``).
Draws only.  (The records ``ModelErrorView`` and ``HeldOutBands`` live in :mod:`identification.studies.records`;
their old names here still work, deprecated.)
"""
from __future__ import annotations

import numpy as np

from typing import TYPE_CHECKING

import identification.studies.records as _records
from identification.studies.model_error import UNSEEN_COVERAGE_CAMPAIGNS, UNSEEN_COVERAGE_MC

from .moved import moved
from .page_layout import draw_text as _text, new_page as _page

__all__ = ["discrepancy_plot", "heldout_band_plot", "coverage_rows", "spread", "model_error_pages", "summary_rows",
           "model_uncertainty_page", "unseen_footnote", "UNSEEN_MARK"]

__getattr__ = moved(__name__, _records, ("HeldOutBands", "ModelErrorView"))

if TYPE_CHECKING:
    from identification.studies.records import ModelErrorView


def _ax(ax, figsize=(6.0, 4.0)):
    import matplotlib.pyplot as plt
    if ax is None:
        _, ax = plt.subplots(figsize=figsize)
    return ax


def _legend_above(ax):
    """The legend in one row above the axes (never over the data)."""
    ax.legend(fontsize=7.5, loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=3, frameon=False, borderaxespad=0.2)


def spread(q, step: float) -> np.ndarray:
    """``q`` with the rows that share a value (e.g. loading and unloading at one set point) moved apart by
    ``step``, centred on their value, so that their bars do not cover each other."""
    q = np.asarray(q, float)
    out = q.copy()
    for value in np.unique(q):
        idx = np.flatnonzero(q == value)
        out[idx] = value + step * (np.arange(idx.size) - (idx.size - 1) / 2)
    return out


def _step(q) -> float:
    q = np.asarray(q, float)
    return 0.006 * (float(np.ptp(q)) if q.size > 1 and np.ptp(q) > 0 else 1.0)


def discrepancy_plot(view: ModelErrorView, k: int, ax=None, legend: bool = True):
    """The discrepancy of sensor ``k`` at every input row with its band (vertical bars), against the first
    input (a dynamic model, ``view.curves``: one curve with its band per experiment, against time; ``legend``
    False leaves their legend to the page, which draws one for all sensors); returns the figure."""
    ax = _ax(ax)
    mean, lo, hi = (np.asarray(a, float)[:, k] for a in view.discrepancy)
    unit = view.units[k]
    pct = f"{100 * (1 - view.result.alpha):g} %"
    if view.curves:                                    # a dynamic model: one curve per experiment against time
        n_t = len(view.q) // len(view.curves)
        ax.axhline(0.0, color="0.6", lw=0.8)
        for j, label in enumerate(view.curves):
            sl = slice(j * n_t, (j + 1) * n_t)
            line, = ax.plot(view.q[sl], mean[sl], lw=1.4, label=label)
            ax.fill_between(view.q[sl], lo[sl], hi[sl], color=line.get_color(), alpha=0.18, lw=0)
        ax.set_xlabel(view.input_label)
        ax.set_ylabel(f"discrepancy of {view.sensors[k]} [{unit}]")
        if legend:
            ax.legend(fontsize=7, loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=min(len(view.curves), 6),
                      frameon=False, borderaxespad=0.2, title=f"{pct} bands", title_fontsize=7, alignment="left")
        ax.grid(alpha=0.3)
        return ax.figure
    x = spread(view.q, 2 * _step(view.q))
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.vlines(x, lo, hi, color="#1f77b4", alpha=0.45, lw=3, label=f"{pct} band")
    ax.plot(x, mean, "o", color="#1f77b4", ms=3.5, label="discrepancy")
    ax.set_xlabel(view.input_label)
    ax.set_ylabel(f"discrepancy of {view.sensors[k]} [{unit}]")
    _legend_above(ax)
    ax.grid(alpha=0.3)
    return ax.figure


def heldout_band_plot(view: ModelErrorView, k: int, ax=None):
    """Held-out readings of sensor ``k`` minus the plain prediction, with the new-reading bands with and without
    the error model (vertical bars, side by side), against the first input; returns the figure."""
    ax = _ax(ax)
    h = view.heldout
    unit = view.units[k]
    dx = _step(h.q)
    x = spread(h.q, 4 * dx)
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.vlines(x - dx, h.plain[0][:, k], h.plain[1][:, k], color="0.45", lw=2.5, alpha=0.6,
              label=f"plain: {100 * h.coverage_plain:.0f} % covered")
    if h.with_error is not None:
        row = next((r for r in view.result.heldout if r.split == h.split), None)
        mark = f" {UNSEEN_MARK}" if view.result.kind == "discrepancy" and row is not None and row.unseen_from_one else ""
        ax.vlines(x + dx, h.with_error[0][:, k], h.with_error[1][:, k], color="#d62728", lw=2.5, alpha=0.45,
                  label=f"with {view.result.kind}: {100 * h.coverage_error:.0f} % covered{mark}")
    z = np.asarray(h.readings, float)[:, :, k]
    qq = np.broadcast_to(x[None, :], z.shape)
    ok = np.isfinite(z)
    ax.plot(qq[ok], z[ok], "k.", ms=4, label="readings")
    ax.set_xlabel(view.input_label)
    ax.set_ylabel(f"{view.sensors[k]} - plain prediction [{unit}]")
    _legend_above(ax)
    ax.grid(alpha=0.3)
    return ax.figure


#: the mark of a held-out coverage at a condition not seen, predicted from one condition (not calibrated)
UNSEEN_MARK = "\u2020"


def unseen_footnote(result) -> str:
    """One line under the held-out table when a split predicts a condition not seen from one condition ("" when
    none does): such a coverage is a plug-in from one realisation, with its Monte Carlo coverage."""
    if not any(h.unseen_from_one for h in result.heldout):
        return ""
    c1 = UNSEEN_COVERAGE_MC[0]
    return (f"{UNSEEN_MARK} 'not seen': readings in a condition the calibration part lacks, predicted from one "
            f"condition: not calibrated (such bands covered {UNSEEN_COVERAGE_CAMPAIGNS[1]:.0f}-{c1[1]:.0f} % in "
            "Monte Carlo), a lower bound of the error.")


def coverage_rows(result) -> tuple:
    """(head, rows) of the held-out table: coverage % and median widening of each error model per split, the
    conditions its calibration part holds and the readings in a condition it has not seen (the discrepancy's
    coverage marked :data:`UNSEEN_MARK` when they are predicted from one condition)."""
    head = ["split", "readings", "plain %", "discrepancy %", "widening", "embedded %", "widening",
            "cal. conditions", "not seen"]
    rows = [[h.split, h.n_values, f"{100 * h.coverage_plain:.1f}",
             f"{100 * h.coverage_discrepancy:.1f}" + (f" {UNSEEN_MARK}" if h.unseen_from_one else ""),
             f"{h.widening_discrepancy:.2f}", f"{100 * h.coverage_embedded:.1f}", f"{h.widening_embedded:.2f}",
             h.n_conditions, h.n_unseen if h.unseen else "-"]
            for h in result.heldout]
    return head, rows


def _verdict(view: ModelErrorView) -> str:
    r = view.result
    t = r.test
    lines = [f"'No model error' test: likelihood ratio {t.statistic:.4g}, p = {t.p_value:.3g} "
             f"({t.reference}, alpha {r.alpha:g}): {'DETECTED' if r.detected else 'not detected'}. "
             f"Error model: {r.kind} ({r.how})."]
    if view.embedded:
        lines.append("Embedded error (parameters varying between input rows"
                     + ("" if r.kind == "embedded" else ", fitted beside the chosen error model") + "): "
                     + "; ".join(f"{e.name} {100 * e.relative:.3g} % of |p|" for e in view.embedded) + ".")
    if not r.identifiable:
        lines.append("The parameters are NOT identifiable under the model error (the discrepancy can mimic them).")
    if view.noise:
        lines.append(view.noise)
    return "\n".join(lines)


def model_error_pages(results, variant: str):
    """One page: the verdict, the discrepancy per sensor, the held-out bands per sensor and the coverage table of
    one variant (as the study computed them: ``results.model_error_views[variant]``)."""
    from .tables import draw_table
    view = results.model_error_views[variant]
    r = view.result
    fig = _page(f"Model error of {variant}: {'detected' if r.detected else 'not detected'}, error model {r.kind}")
    n_lines = _text(fig, 0.04, 0.925, _verdict(view), width=160, size=9)    # 160 characters of size 9 fit the page
    n = len(view.sensors)
    top = 0.925 - 0.019 * n_lines - 0.075              # top of the first row of axes
    h, gap = max(0.16, 0.2 - 0.0095 * max(0, n_lines - 4)), 0.08 if n <= 2 else 0.1   # a long verdict: lower plots
    foot = unseen_footnote(r)
    h -= 0.0125 if foot else 0.0                       # two plot rows give room for the table's footnote
    w = (0.87 - gap * (n - 1)) / n
    if r.kind == "none":                               # no discrepancy: the held-out row moves up
        fig.text(0.04, top + 0.045, "No error model (kind none): no discrepancy to show; the bands are the plain "
                 "ones.", fontsize=10, weight="bold")
        row2 = top - 0.035
    else:
        fig.text(0.04, top + 0.045, "The model error per sensor (all data): the discrepancy at every "
                 + ("experiment against time" if view.curves else "input row"), fontsize=10, weight="bold")
        if np.unique(view.q).size < view.q.size and not view.curves:
            fig.text(0.96, top + 0.045, f"rows that share a value of {view.input_label} are drawn side by side, "
                     "in the data's order", fontsize=8, style="italic", ha="right")
        row2 = top - h - 0.135
    if view.heldout is not None:
        fig.text(0.04, row2 + 0.045, f"Held-out split '{view.heldout.split}' (the lowest plain coverage): "
                 "new-reading bands and readings, minus the plain prediction", fontsize=10, weight="bold")
    for k in range(n):
        x = 0.085 + k * (w + gap)
        if r.kind != "none":
            ax = fig.add_axes([x, top - h, w, h])
            discrepancy_plot(view, k, ax, legend=not view.curves)
            if view.curves and k == 0:                 # one legend of the experiments for every sensor, below
                fig.legend(*ax.get_legend_handles_labels(), loc="upper center", bbox_to_anchor=(0.5, top - h - 0.075),
                           ncol=min(len(view.curves), 8), fontsize=8, frameon=False,
                           title=f"{100 * (1 - r.alpha):g} % bands", title_fontsize=8)
        if view.heldout is not None:
            heldout_band_plot(view, k, fig.add_axes([x, row2 - h, w, h]))
    head, rows = coverage_rows(r)
    low = 0.035 if foot else 0.01                       # room for the footnote's line under the table
    ax = fig.add_axes([0.07, low, 0.86, row2 - h - 0.1 - low])
    draw_table(ax, head, rows, fontsize=8, col_widths=[0.24, 0.07, 0.07, 0.11, 0.07, 0.10, 0.07, 0.115, 0.105],
               title=f"Held-out coverage of the {100 * (1 - r.alpha):g} % new-reading bands (each split's "
                     "validation readings predicted from a fit on its calibration part)")
    if foot:
        fig.canvas.draw()                                # under the table as drawn, on the page
        bottom = ax.tables[0].get_window_extent().transformed(fig.transFigure.inverted()).y0
        fig.text(0.07, max(0.008, bottom - 0.022), foot, fontsize=8, style="italic")
    return fig


# ---------------------------------------------------------------------------- the engineer's summary
#: relative spreads below this (a fraction of |p|) print as "< ±0.01 %": digits there are noise for an engineer
RELATIVE_FLOOR = 1e-4


def relative_spread(relative: float) -> str:
    """"±8.74 %": a parameter's relative spread (a fraction of |p|) in percent to three significant digits, or
    "< ±0.01 %" below :data:`RELATIVE_FLOOR` (not "±0.00383 %"); no-break spaces keep it on one line."""
    if relative != relative:
        return "-"
    if abs(relative) < RELATIVE_FLOOR:
        return f"<\u00a0±{100 * RELATIVE_FLOOR:g}\u00a0%"
    return f"±{100 * relative:.3g}\u00a0%"


def _num(x: float, unit: str = "") -> str:
    return "-" if x != x else f"{x:.3g}" + (f" {unit}" if unit else "")


def _wrap(label: str, width: int = 36) -> str:
    """An input label "a = 1 N, b = 2 N, ..." on lines of at most ``width`` characters, broken after commas."""
    lines = [""]
    for part in label.split(", "):
        if lines[-1] and len(lines[-1]) + 2 + len(part) > width:
            lines.append(part)
        else:
            lines[-1] = f"{lines[-1]}, {part}" if lines[-1] else part
    return "\n".join(lines)


def summary_rows(views) -> tuple:
    """(head, rows, detected flags) of the summary table: per variant and sensor the size of the error (max, where,
    rms), the new-reading band with the error and the plain one (median and max over the grid) and the mean band
    before -> after the next runs, all in the sensor's unit."""
    head = ["variant", "test", "error\nmodel", "sensor", "max |error|", "where", "rms",
            "band to design with\nmedian (max)", "plain band\nmedian (max)", "after next runs\n(mean band)"]
    rows, flags = [], []
    for v in views:
        s = v.summary
        if s is None:
            continue
        for i, z in enumerate(s.sizes):
            u = z.unit
            nxt = "-" if z.next_before != z.next_before else f"{z.next_before:.3g} -> {z.next_after:.3g} {u}"
            p = f"p = {s.p_value:.2g}" if s.p_value > 0 else "p < 1e-300"
            test = f"{'DETECTED' if s.detected else 'not detected'}\n{p}"
            rows.append([s.variant if i == 0 else "", test if i == 0 else "", s.kind if i == 0 else "", z.sensor,
                         _num(z.max_abs, u) if s.kind != "none" else "0", _wrap(z.at) if s.kind != "none" else "-",
                         _num(z.rms, u) if s.kind != "none" else "0",
                         f"±{z.half_median:.3g} ({z.half_max:.3g}) {u}",
                         f"±{z.plain_median:.3g} ({z.plain_max:.3g}) {u}", nxt])
            sized = s.detected and s.kind != "none"       # detected but no error model chosen: nothing to size
            flags.append([(s.detected and k in (0, 1)) or (sized and k in (4, 7)) for k in range(len(head))])
    return head, rows, flags


def _ranking_text(views) -> str:
    rank = next((v.ranking for v in views if v.ranking is not None), None)
    if rank is None:
        return "Which model to use: no ranking (no variant has a held-out table: the study has no splits)."
    text = ("Which model to use for prediction: " + rank.sentence() + ".\nVerdict: " + rank.verdict()
            + (" (the held-out log scores differ by less than their noise: either model predicts as well)"
               if not rank.decided and rank.runner_up and rank.comparable else "") + ".")
    return text.replace(" +- ", " ± ")       # the ranking's plain-text words (also the terminal's) on the page


def _variant_text(s) -> str:
    pct = f"{100 * (1 - s.alpha):g} %"
    parts = [f"{s.variant}: size = {s.size_is}; on {s.grid}; bands of a new reading at {pct}."]
    if s.embedded:
        parts.append("Parameters that carry the error (embedded, varying between conditions): "
                     + "; ".join(f"{e.name}\u00a0{relative_spread(e.relative)}" for e in s.embedded) + ".")
    if s.next_runs:
        parts.append("Measure next: " + "; ".join(s.next_runs) + f" ({s.next_how}).")
    elif s.next_how:
        parts.append(s.next_how[0].upper() + s.next_how[1:] + ".")
    return " ".join(parts)


def model_uncertainty_page(results):
    """One page for every variant whose model error the study computed: which model to use (the ranking's
    verdict), the table of :func:`summary_rows` and per variant what the sizes are, the parameters that carry
    the error and the next runs (``view.summary``, computed by the study)."""
    from .tables import draw_table
    views = [v for v in results.model_error_views.values() if v.summary is not None]
    fig = _page("Model uncertainty: how large the model error is, the band to design with, which model to use")
    n = _text(fig, 0.04, 0.925, _ranking_text(views), width=135, size=10, weight="bold")
    top = 0.925 - 0.024 * n - 0.035
    noise = next((v.noise for v in views if v.noise), "")       # which sigma the bands take (the same in every view)
    if noise:
        top -= 0.0165 * _text(fig, 0.04, top + 0.029, noise, width=180, size=8) + 0.003
    head, rows, flags = summary_rows(views)
    heights = [max(str(c).count("\n") + 1 for c in r) for r in rows]
    height = 0.024 * (sum(heights) + 2)
    ax = fig.add_axes([0.04, top - height, 0.92, height])
    where = min(0.2, max(0.1, 0.0058 * max((len(line) for r in rows for line in str(r[5]).split("\n")), default=0)))
    name = max(0.05, 0.0065 * max((len(str(r[0])) for r in rows), default=0) + 0.01)    # the longest variant name
    widths = np.array([name, 0.08, 0.075, 0.05, 0.075, where, 0.07, 0.14, 0.14, 0.13])
    draw_table(ax, head, rows, flags=flags, fontsize=7.5, highlight="#fbe3e1", col_widths=list(widths / widths.sum()),
               title="The model error per sensor over the data's range (the sensors' file units; shaded: detected)")
    for (r, _), cell in ax.tables[0].get_celld().items():       # rows of two lines (test, a long "where")
        if r > 0 and heights[r - 1] > 1:
            cell.set_height(cell.get_height() * heights[r - 1])
    # the table lays itself out in get_window_extent: no draw of the whole page needed
    bottom = ax.tables[0].get_window_extent().transformed(fig.transFigure.inverted()).y0
    text = "\n\n".join(_variant_text(v.summary) for v in views)
    lines = _text(fig, 0.04, bottom - 0.03, text, width=180, size=8)
    curves = [v.summary for v in views if v.summary.x.size and v.summary.kind != "none"]
    room = bottom - 0.03 - 0.0165 * lines - 0.1           # top of the plots, below their title and legend
    if curves and room > 0.15:
        _band_curves(fig, curves, room)
    return fig


def _band_curves(fig, summaries, top: float):
    """Per sensor, against the input: the band to design with (solid), the plain band (dashed) and the size of
    the error (dotted) of every summary with curves (a static model of one input), one colour per variant."""
    sensors = list(dict.fromkeys(z.sensor for s in summaries for z in s.sizes))
    n = len(sensors)
    gap = 0.07
    w = (0.88 - gap * (n - 1)) / n
    fig.text(0.04, top + 0.07, "Over the data's range: the band to design with (solid), the plain band (dashed) and "
             "the size of the error (dotted)", fontsize=10, weight="bold")
    for k, sensor in enumerate(sensors):
        ax = fig.add_axes([0.08 + k * (w + gap), 0.07, w, top - 0.07])
        unit = ""
        for j, s in enumerate(summaries):
            z = next((z for z in s.sizes if z.sensor == sensor), None)
            if z is None or not z.half.size:
                continue
            unit, c = z.unit, f"C{j}"
            ax.plot(s.x, z.half, "-", color=c, lw=1.6, label=f"{s.variant}: band with {s.kind}")
            ax.plot(s.x, z.plain, "--", color=c, lw=1.1, label=f"{s.variant}: plain band")
            ax.plot(s.x, z.size, ":", color=c, lw=1.6, label=f"{s.variant}: {s.size_is}")
        ax.set_xlabel(summaries[0].x_label)
        ax.set_ylabel(f"{sensor}: half-width, size [{unit}]")
        ax.set_ylim(bottom=0.0)
        ax.grid(alpha=0.3)
        _legend_above(ax)
