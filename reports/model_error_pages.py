"""The pages "Model error of ...": what the study computed of a variant's model error (issue 29).

For one variant (``results.model_error_views[variant]``, an
:class:`identification.studies.records.ModelErrorView` the study computed, :mod:`mudoe.model_error_runs`):
the verdict of the 'no model error' test and the chosen error model, the discrepancy per sensor against the
first input (a dynamic model: against time, every experiment) with its band, the new-reading bands with and without the error model against the held-out
readings of one split, and the held-out coverage table.  Draws only.  (The records ``ModelErrorView`` and
``HeldOutBands`` live in :mod:`identification.studies.records`; their old names here still work, deprecated.)
"""
from __future__ import annotations

import numpy as np

from typing import TYPE_CHECKING

import identification.studies.records as _records

from .moved import moved
from .page_layout import draw_text as _text, new_page as _page

__all__ = ["discrepancy_plot", "heldout_band_plot", "coverage_rows", "spread", "model_error_pages"]

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
        ax.vlines(x + dx, h.with_error[0][:, k], h.with_error[1][:, k], color="#d62728", lw=2.5, alpha=0.45,
                  label=f"with {view.result.kind}: {100 * h.coverage_error:.0f} % covered")
    z = np.asarray(h.readings, float)[:, :, k]
    qq = np.broadcast_to(x[None, :], z.shape)
    ok = np.isfinite(z)
    ax.plot(qq[ok], z[ok], "k.", ms=4, label="readings")
    ax.set_xlabel(view.input_label)
    ax.set_ylabel(f"{view.sensors[k]} - plain prediction [{unit}]")
    _legend_above(ax)
    ax.grid(alpha=0.3)
    return ax.figure


def coverage_rows(result) -> tuple:
    """(head, rows) of the held-out table: coverage % and median widening of each error model per split."""
    head = ["split", "readings", "plain %", "discrepancy %", "widening", "embedded %", "widening"]
    rows = [[h.split, h.n_values, f"{100 * h.coverage_plain:.1f}", f"{100 * h.coverage_discrepancy:.1f}",
             f"{h.widening_discrepancy:.2f}", f"{100 * h.coverage_embedded:.1f}", f"{h.widening_embedded:.2f}"]
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
    return "\n".join(lines)


def model_error_pages(results, variant: str):
    """One page: the verdict, the discrepancy per sensor, the held-out bands per sensor and the coverage table of
    one variant (as the study computed them: ``results.model_error_views[variant]``)."""
    from .tables import draw_table
    view = results.model_error_views[variant]
    r = view.result
    fig = _page(f"Model error of {variant}: {'detected' if r.detected else 'not detected'}, error model {r.kind}")
    n_lines = _text(fig, 0.04, 0.925, _verdict(view), width=175, size=9)
    n = len(view.sensors)
    top = 0.925 - 0.019 * n_lines - 0.075              # top of the first row of axes
    h, gap = 0.2, 0.08 if n <= 2 else 0.1
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
    ax = fig.add_axes([0.07, 0.01, 0.86, row2 - h - 0.11])
    draw_table(ax, head, rows, fontsize=8, col_widths=[0.32, 0.09, 0.09, 0.13, 0.09, 0.12, 0.09],
               title=f"Held-out coverage of the {100 * (1 - r.alpha):g} % new-reading bands (each split's "
                     "validation readings predicted from a fit on its calibration part)")
    return fig
