"""Figures of an approximate design (issue 31): its equivalence certificate and the local design across the prior.

Each function takes the computed numbers (no study object) and ``ax=None`` and returns the figure; none
writes files (:mod:`reports.builder` does).
"""
from __future__ import annotations

import numpy as np

__all__ = ["sensitivity_plot", "efficiency_curve"]


def _ax(ax, figsize=(6.0, 4.0)):
    import matplotlib.pyplot as plt
    if ax is None:
        _, ax = plt.subplots(figsize=figsize)
    return ax


def _legend_above(ax):
    """The legend in two columns above the axes: never over the curve (the reactor's trough, issue 31 audit)."""
    ax.legend(loc="lower left", bbox_to_anchor=(0.0, 1.01), ncol=2, fontsize=7, frameon=False)


def sensitivity_plot(x, sensitivity, reference: float, support, x_label: str, ax=None):
    """The sensitivity function over the checked points ``x`` (one input column), its maximum marked, the line at
    its optimum value ``reference`` (D: n_p) and the ``support`` points of the design on that line."""
    ax = _ax(ax)
    x, g = np.asarray(x, float).ravel(), np.asarray(sensitivity, float).ravel()
    order = np.argsort(x)
    ax.plot(x[order], g[order], "-", color="tab:blue", lw=1.2, label="sensitivity function (checked points)")
    ax.axhline(reference, color="tab:red", ls="--", lw=1.0, label=f"optimum value {reference:.6g}")
    k = int(np.argmax(g))
    ax.plot([x[k]], [g[k]], "v", color="black", ms=9, label=f"maximum {g[k]:.6g}")
    sup = np.asarray(support, float).ravel()
    ax.plot(sup, np.full(sup.size, reference), "o", color="tab:green", ms=8, mfc="none", mew=2,
            label="support points")
    lo = min(float(g.min()), reference)
    ax.set_ylim(lo - 0.05 * abs(reference), reference + 0.15 * abs(reference))
    ax.set_xlabel(x_label)
    ax.set_ylabel("sensitivity (-)")
    _legend_above(ax)
    return ax.figure


def efficiency_curve(efficiencies, weights, ax=None):
    """The local design's efficiency against the robust one at every parameter vector of the prior, sorted, over
    the cumulative prior weight (1 = as good as the robust design)."""
    ax = _ax(ax)
    e, w = np.asarray(efficiencies, float).ravel(), np.asarray(weights, float).ravel()
    order = np.argsort(e)
    cum = np.cumsum(w[order])
    ax.step(np.concatenate([[0.0], cum]), np.concatenate([[e[order][0]], e[order]]), where="pre", color="tab:blue",
            lw=1.4, label="local design", zorder=2)
    # the reference thin and beneath, the prior mean thick on top: both show where the mean is 1.0000
    ax.axhline(1.0, color="tab:green", ls=(0, (5, 3)), lw=0.8, label="robust design (reference)", zorder=1)
    ax.axhline(float(w @ e), color="0.1", ls=":", lw=2.0, label=f"local design: prior mean {float(w @ e):.4f}",
               zorder=3)
    lo, hi = min(float(e.min()), 1.0), max(float(e.max()), 1.0)
    pad = max(0.1 * (hi - lo), 0.01)        # at least +-1 %: equal designs read as a flat line at 1
    ax.set_ylim(lo - pad, hi + pad)
    ax.ticklabel_format(axis="y", useOffset=False)
    ax.set_xlim(0.0, 1.0)
    ax.set_xlabel("cumulative prior weight (parameter vectors sorted by efficiency)")
    ax.set_ylabel("efficiency against the robust design (-)")
    _legend_above(ax)
    return ax.figure
