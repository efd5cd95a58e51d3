r"""The pages "Multi-start fit of ...": how the starts of a variant's fit ended (issue 30 item 2).

A fit with ``[identify] starts = N > 1`` minimises the least-squares objective (paper eq. 3, dimensionless)

.. math::

    \Phi(p) = \tfrac12 \sum_{ijk} w_k \bigl((z_{ijk} - h_k(y_j, p, q_j)) / \sigma_k\bigr)^2

from p0 and N - 1 further starts (:mod:`identification.fit.multistart`); the study keeps every start in the
:class:`identification.fit.multistart.MultiStartRecord` of the estimate (``est.diagnostics.starts``).  The page
draws it: the waterfall of the starts' final objectives (sorted, the distinct minima as plateaus, the best
marked) and the table of the distinct minima (objective, how many starts reached each, the parameters there).
Starts that ended along one flat valley (objectives equal within the valley tolerance, no barrier between them)
are one entry: its row gives the range of each parameter that moves along the valley ("lo to hi") and the page
the note saying which parameters the data do not determine, over what range, at what objective.
Draws only: it fits nothing.
"""
from __future__ import annotations

import textwrap

import numpy as np

from .page_layout import PAGE_SIZE, draw_text as _text, new_page as _page
from .tables import PARAMS_PER_TABLE

__all__ = ["waterfall_plot", "minima_rows", "multistart_variants", "multistart_pages", "MINIMA_ROWS", "LOG_SPAN"]

#: distinct minima listed on the page (the others: results.json)
MINIMA_ROWS = 12
#: the waterfall's objective axis is logarithmic when its positive values span this ratio (two decades) or more
LOG_SPAN = 100.0
#: the colour of the best minimum, of the other minima (cycled) and of the starts the data do not bound
_BEST, _OTHERS, _UNBOUNDED = "#2ca02c", ("#1f77b4", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf"), "0.55"


def _ax(ax, figsize=(6.0, 4.0)):
    import matplotlib.pyplot as plt
    if ax is None:
        _, ax = plt.subplots(figsize=figsize)
    return ax


def _ranks(ms) -> tuple:
    """(order, rank): the starts that did not fail sorted by final objective -- the starts of one minimum
    together at its objective, the estimate's start first among them -- and each start's 1-based position in
    that order (0 when it failed)."""
    obj = np.asarray(ms.objective, float)
    level = obj.copy()
    for m in ms.minima:
        level[list(m.starts)] = m.objective
    order = sorted((i for i in range(ms.n_starts) if np.isfinite(obj[i])),
                   key=lambda i: (level[i], i != ms.best, obj[i], i))
    rank = np.zeros(ms.n_starts, int)
    rank[order] = np.arange(1, len(order) + 1)
    return order, rank


def waterfall_plot(ms, ax=None, label: str = ""):
    """The final objective Phi of every start (dimensionless, paper eq. 3) against its rank once sorted: each
    distinct local minimum a plateau (a line over the starts that reached it), the best minimum (the estimate)
    marked, the starts whose fit the data do not bound as open grey triangles; log scale when the objectives
    span :data:`LOG_SPAN` or more.  ``ms``: a :class:`identification.fit.multistart.MultiStartRecord`; returns
    the figure."""
    ax = _ax(ax)
    obj = np.asarray(ms.objective, float)
    order, rank = _ranks(ms)
    for k, m in enumerate(ms.minima):
        r = rank[list(m.starts)]
        colour = _BEST if k == 0 else _OTHERS[(k - 1) % len(_OTHERS)]
        ax.hlines(m.objective, r.min() - 0.4, r.max() + 0.4, color=colour, lw=2.5, alpha=0.8, zorder=2)
        flat = f" (flat valley in {', '.join(m.flat)})" if m.flat else ""
        ax.plot(r, obj[list(m.starts)], "o", color=colour, ms=5, zorder=3,
                label=(f"best minimum{flat}: {m.count} start{'s' if m.count > 1 else ''}" if k == 0 else
                       f"minimum {k + 1}{flat}: {m.count} start{'s' if m.count > 1 else ''}") if k < 6 else None)
    unb = [i for i, o in enumerate(ms.outcome) if o == "not bounded"]
    if unb:
        ax.plot(rank[unb], obj[unb], "^", mfc="none", color=_UNBOUNDED, ms=6, zorder=3,
                label=f"not bounded by the data: {len(unb)} (objective limit)")
    if ms.minima:
        ax.plot(rank[ms.best], obj[ms.best], "*", color="k", ms=13, mfc=_BEST, zorder=4,
                label=f"estimate (start {ms.best + 1}{', p0' if ms.best == 0 else ''})")
    if len(ms.minima) > 6:
        ax.plot([], [], " ", label=f"{len(ms.minima) - 6} more minima (colours repeat)")
    pos = obj[order][obj[order] > 0] if order else np.array([])
    if pos.size == len(order) and pos.size and pos.max() / pos.min() >= LOG_SPAN:
        ax.set_yscale("log")
    elif pos.size and np.ptp(obj[order]) <= 1e-9 * max(1.0, float(np.max(np.abs(obj[order])))):
        mid = float(obj[order][0])                      # one level: a readable range around it, no offset
        ax.set_ylim(mid - 0.01 * max(abs(mid), 1.0), mid + 0.01 * max(abs(mid), 1.0))
        ax.ticklabel_format(axis="y", useOffset=False)
    n = len(order)
    ax.set_xlim(0.3, n + 0.7)
    ax.set_xticks(np.arange(1, n + 1) if n <= 25 else np.unique(np.linspace(1, n, 10).round().astype(int)))
    ax.set_xlabel("start, sorted by its final objective")
    ax.set_ylabel("final objective Phi (dimensionless)")
    ax.set_title(label or f"{ms.reached_best} of {ms.n_starts} starts reached the best minimum", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7.5, loc="best", frameon=True, framealpha=0.85)
    return ax.figure


def minima_rows(ms, units=(), params: slice = slice(None)) -> tuple:
    """(head, rows) of the distinct minima, best first: minimum, objective Phi, how many starts reached it,
    which (1-based; start 1 is p0) and the parameters ``params`` there (``units``: one per parameter); an entry
    along a flat valley is labelled "(valley)", its objective and the parameters that move along it given as
    ranges over its starts ("lo to hi")."""
    names = ms.param_names[params]
    units = tuple(units)[params] if units else ("",) * len(names)
    head = ["minimum", "objective Phi", "starts", "reached from"] + [
        f"{nm} [{u}]" if u else nm for nm, u in zip(names, units)]
    rows = []
    for k, m in enumerate(ms.minima[:MINIMA_ROWS], 1):
        which = ", ".join(str(i + 1) for i in m.starts[:12]) + (", ..." if m.count > 12 else "")
        flat = tuple(m.flat)
        label = ("1 (best)" if k == 1 else str(k)) + (" (valley)" if flat else "")
        phi = f"{m.objective:.8g}"
        if flat:
            high = f"{m.objective_high:.8g}"
            phi += f" to {high}" if high != phi else f" (all within {m.objective_high - m.objective:.1g})"
        cells = [f"{lo:.6g} to {hi:.6g}" if nm in flat else f"{v:.6g}" for nm, v, lo, hi in
                 zip(names, np.asarray(m.p)[params], np.asarray(m.p_low)[params], np.asarray(m.p_high)[params])]
        rows.append([label, phi, str(m.count), which] + cells)
    return head, rows


def multistart_variants(results) -> list:
    """The variants whose fit on all study data ran from more than one start."""
    return [v for v, e in results.estimates.items()
            if e.diagnostics.starts is not None and e.diagnostics.starts.n_starts > 1]


def _summary(ms) -> str:
    """The page's text: how the starts were drawn and how they ended."""
    n, m = ms.n_starts, len(ms.minima)
    bad = ms.failed
    unb = sum(o == "not bounded" for o in ms.outcome)
    out = [f"The fit was run from {n} starts: p0 (start 1, the [[parameters]] start values) and {n - 1} "
           f"scrambled Sobol points in the bounds ({'; '.join(ms.rules)}; seed {ms.seed}); {ms.backend}, "
           f"{ms.wall_time:.3g} s in all."]
    if m:
        out.append(f"{ms.reached_best} of {n} starts reached the best minimum (objective within "
                   f"{ms.objective_tol:.2g}); {m} distinct local minim{'um' if m == 1 else 'a'} (two starts share "
                   f"a minimum when their objectives agree within that tolerance and their parameters within "
                   f"{ms.parameter_tol_se:g} standard errors"
                   + (f"; starts along one flat valley, their objectives within {ms.valley_tol:.2g} and no barrier "
                      "between them, are one entry with the range of each parameter" if np.isfinite(ms.valley_tol)
                      else "")
                   + f"). The estimate is that of start {ms.best + 1}"
                   + (" (p0)." if ms.best == 0 else f"; p0 ended {_p0_end(ms)}."))
        valleys = [str(k) for k, m in enumerate(ms.minima, 1) if m.valley]
        if valleys:
            out.append(f"Minim{'um' if len(valleys) == 1 else 'a'} {', '.join(valleys)} "
                       f"{'is a flat valley' if len(valleys) == 1 else 'are flat valleys'}, not isolated: see the "
                       "box on the right.")
    else:
        out.append(f"None of the {n} starts reached a finite minimum.")
    if bad:
        out.append(f"{len(bad)} start{'s' if len(bad) > 1 else ''} failed (not drawn): "
                   + "; ".join(f"start {i + 1}: {ms.errors[i][:120]}" for i in bad[:3])
                   + ("; ..." if len(bad) > 3 else "") + ".")
    if unb:
        out.append(f"{unb} start{'s' if unb > 1 else ''} ended on a fit the data do not bound (the parameters run "
                   "off; drawn at the objective's limit).")
    if m > 1:
        out.append("Several minima: the objective is not convex over the bounds; the estimate is the lowest one "
                   "found, and a minimum reached by few starts may hide others (more starts, tighter bounds).")
    return " ".join(out)


def _valley_box(fig, ms, y: float, bottom: float) -> None:
    """The notes on the flat valleys under the reading of the waterfall, from height ``y`` down to ``bottom``
    (those that do not fit are named: their notes are in the estimate's summary and results.json)."""
    notes = [(k, m.valley) for k, m in enumerate(ms.minima, 1) if m.valley]
    if not notes:
        return
    fig.text(0.66, y, "Not isolated: flat valleys", fontsize=10, weight="bold", va="top", color="#b03000")
    y -= 0.03
    for n, (k, text) in enumerate(notes):
        lines = len(textwrap.wrap(f"Minimum {k}: {text}.", 60))
        if y - 0.0185 * lines < bottom:
            _text(fig, 0.66, y, "Also flat valleys: minima " + ", ".join(str(j) for j, _ in notes[n:])
                  + " (their notes: the estimate's summary, results.json).", width=60, size=8.5)
            return
        y -= 0.0185 * _text(fig, 0.66, y, f"Minimum {k}{' (best)' if k == 1 else ''}: {text}.", width=60,
                            size=8.5) + 0.01


def _p0_end(ms) -> str:
    if ms.outcome[0] == "failed":
        return "in a failed fit"
    if ms.outcome[0] == "not bounded":
        return "on a fit the data do not bound"
    return f"at objective {ms.objective[0]:.8g}"


def multistart_pages(results, variant: str):
    """One page per part of the parameters: the waterfall of the starts of ``variant``'s fit and its table of
    distinct minima (as the study computed them: ``results.estimates[variant].diagnostics.starts``)."""
    from .tables import content_widths, draw_table
    est = results.estimates[variant]
    ms = est.diagnostics.starts
    figs = []
    n_p = len(ms.param_names)
    parts = [slice(a, min(a + PARAMS_PER_TABLE, n_p)) for a in range(0, max(n_p, 1), PARAMS_PER_TABLE)]
    for k, pp in enumerate(parts):
        title = f"Multi-start fit of {variant}" + (f" ({k + 1}/{len(parts)})" if len(parts) > 1 else "")
        fig = _page(title)
        n_lines = _text(fig, 0.04, 0.925, _summary(ms), width=170, size=9)
        top = 0.925 - 0.019 * n_lines - 0.055
        waterfall_plot(ms, fig.add_axes([0.07, top - 0.45, 0.55, 0.45]))
        head, rows = minima_rows(ms, est.param_units, pp)
        more = (f" (the first {MINIMA_ROWS} of {len(ms.minima)}; all in results.json)"
                if len(ms.minima) > MINIMA_ROWS else "")
        fig.text(0.04, top - 0.53, f"Distinct local minima, best first{more}", fontsize=10, weight="bold")
        h = min(0.032 * (len(rows) + 1), top - 0.57)
        ax = fig.add_axes([0.04, top - 0.55 - h, 0.92, h])
        widths, size = content_widths(head, rows, 8.5, 0.92 * PAGE_SIZE[0])
        draw_table(ax, head, rows, fontsize=size, col_widths=widths)
        fig.text(0.66, top - 0.01, "Reading the waterfall", fontsize=10, weight="bold", va="top")
        lines = _text(fig, 0.66, top - 0.04, "Each point is one start's final objective, the starts sorted from the "
                      "lowest. A flat step (a plateau) is a local minimum that several starts reached; the lowest, "
                      "green, is the estimate (black star). One long lowest plateau: the starts agree on the minimum. "
                      "Steps above it: other local minima, worse fits of the same data; a plateau of one point: a "
                      "minimum only one start found; a plateau marked 'flat valley': starts that stopped at "
                      "different points of a direction the data do not determine, one minimum that is not "
                      "isolated (the table gives its range). Open grey triangles: fits the data do not bound, at "
                      "the objective's limit.", width=60, size=8.5)
        _valley_box(fig, ms, top - 0.04 - 0.0185 * lines - 0.03, top - 0.51)
        figs.append(fig)
    return figs
