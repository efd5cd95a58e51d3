"""Report page of a time-series study's design of its next experiments (``[oed] mode = "inputs"``, issue 30 item 8).

It draws what :class:`oed.dynamic_plans.ExperimentPlan` holds: each control's profile u(t) of the designed
experiments (bold) over the study's current experiments (thin, grey) within the bounds (dotted), each constant
within its bounds (the designed value against the current ones), the table of the designed and current
experiments' constants with each one's criterion value alone, and the text with the values of the design, of the
current experiments and of both together, the choice's proof and the time limit.  With a prior the exact robust
choice's page follows (:func:`reports.design_pages.robust_exact_page`).
"""
from __future__ import annotations

import textwrap

import numpy as np

from oed.dynamic_plans import row_groups

__all__ = ["input_design_pages", "profile_plot", "constants_plot"]

_PAGE = (11.69, 8.27)
_DESIGNED = ("tab:red", "tab:blue", "tab:green", "tab:orange")


def _unit(u: str) -> str:
    return f" ({u})" if u else ""


def _crit(criterion: str) -> str:
    return {"D": "log det C", "A": "trace C", "E": "max eig C"}[criterion]


def profile_plot(plan, k: int, horizon: float, time_unit: str = "", ax=None):
    """Control ``k`` of ``plan.inputs`` (a control) against time: the designed profiles in colour, the current
    experiments' in grey, the bounds dotted."""
    import matplotlib.pyplot as plt
    if ax is None:
        _, ax = plt.subplots(figsize=(6.0, 4.0))
    inp = plan.inputs[k]
    t = np.r_[np.asarray(inp.grid, float), horizon]
    style = dict(drawstyle="steps-post" if inp.kind == "constant" else "default")
    for j, row in enumerate(plan.current):
        v = row_groups(plan.inputs, row)[k][1]
        ax.plot(t, np.r_[v, v[-1]], color="0.6", lw=0.9, label="current experiments" if j == 0 else None, **style)
    for j, row in enumerate(plan.designed):
        v = row_groups(plan.inputs, row)[k][1]
        ax.plot(t, np.r_[v, v[-1]], color=_DESIGNED[j % len(_DESIGNED)], lw=2.2, label=f"designed {j + 1}", **style)
    col = sum(i.width for i in plan.inputs[:k])
    for b in (plan.lower[col], plan.upper[col]):
        ax.axhline(b, color="0.3", ls=":", lw=1.0)
    ax.set_xlim(0.0, horizon)
    ax.set_xlabel(f"time{_unit(time_unit)}", fontsize=9)
    ax.set_ylabel(f"{inp.name}(t){_unit(inp.unit)}", fontsize=9)
    ax.set_title(f"control {inp.name}: designed and current profiles (dotted: bounds)", fontsize=10)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=3, frameon=False)
    ax.grid(alpha=0.3)
    return ax.figure


def constants_plot(plan, ax=None):
    """Every constant input within its bounds (each on its own row, the bounds at the ends): the current
    experiments' values (grey, numbered) and the designed ones (colour)."""
    import matplotlib.pyplot as plt
    if ax is None:
        _, ax = plt.subplots(figsize=(6.0, 3.0))
    consts = [(k, i) for k, i in enumerate(plan.inputs) if not i.grid]
    for r, (k, inp) in enumerate(consts):
        col = sum(i.width for i in plan.inputs[:k])
        lo, hi = plan.lower[col], plan.upper[col]
        span = hi - lo if hi > lo else 1.0
        ax.plot([0, 1], [r, r], color="0.3", lw=1.0)
        ax.text(-0.02, r, f"{inp.name}{_unit(inp.unit)}\n[{lo:.4g}, {hi:.4g}]", ha="right", va="center", fontsize=8)
        others = [row[col] for row in plan.candidates[sum(c.startswith("experiment") for c in plan.labels):]]
        ax.plot((np.asarray(others) - lo) / span, np.full(len(others), r), "x", color="0.75", ms=6,
                label="random candidates" if r == 0 and others else None)
        at = {}                                          # the current experiments, numbered, one label per value
        for j, row in enumerate(plan.current):
            at.setdefault(round(float(row[col]), 12), []).append(str(j + 1))
        for value, which in at.items():
            x = (value - lo) / span
            ax.plot(x, r, "o", color="0.5", ms=7, label="current experiments" if r == 0 and which[0] == "1" else None)
            ax.annotate(", ".join(which), (x, r), xytext=(0, 7), textcoords="offset points", ha="center",
                        fontsize=7, color="0.3")
        for j, row in enumerate(plan.designed):
            ax.plot((row[col] - lo) / span, r, "D", color=_DESIGNED[j % len(_DESIGNED)], ms=9,
                    label=f"designed {j + 1}" if r == 0 else None)
    ax.set_xlim(-0.05, 1.05)
    ax.set_ylim(-0.6, len(consts) - 0.4)
    ax.set_xticks([0, 0.5, 1], ["lower", "middle", "upper"], fontsize=8)
    ax.set_yticks([])
    ax.set_title("constants within their bounds (numbers: the current experiments)", fontsize=10)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=4, frameon=False)
    for side in ("left", "right", "top"):
        ax.spines[side].set_visible(False)
    return ax.figure


def _table(plan) -> tuple:
    """(head, rows, highlighted): the designed and the current experiments, their constants and value alone."""
    consts = [(k, i) for k, i in enumerate(plan.inputs) if not i.grid]
    head = ["experiment"] + [f"{i.name}{_unit(i.unit)}" for _, i in consts] + [f"{_crit(plan.criterion)} alone"]
    rows, hi = [], []
    for j, row in enumerate(plan.designed):
        groups = row_groups(plan.inputs, row)
        alone = f"{plan.values['design']:.5g}" if len(plan.designed) == 1 else ""
        rows.append([f"designed {j + 1}"] + [f"{groups[k][1][0]:.4g}" for k, _ in consts] + [alone])
        hi.append(True)
    for j, row in enumerate(plan.current):
        groups = row_groups(plan.inputs, row)
        rows.append([f"current {j + 1}"] + [f"{groups[k][1][0]:.4g}" for k, _ in consts]
                    + [f"{plan.each[j]:.5g}"])
        hi.append(False)
    return head, rows, hi


def _text(plan) -> str:
    v, crit = plan.values, _crit(plan.criterion)
    n_d, n_c = len(plan.designed), len(plan.current)
    if plan.robust is not None:
        d = plan.robust.design
        how = (f"the exact {'pseudo-Bayesian' if d.robust == 'bayes' else 'maximin'} choice over the prior "
               f"({'proven optimal' if d.proven_optimal else f'proven gap {d.gap:.3g}'}; next page)")
    else:
        r = plan.result
        how = (f"the exact choice ({'proven optimal' if r.proven_optimal else 'not proven optimal'}, {r.method})"
               + ("" if r.refined is None else
                  ", the continuous refinement within the bounds (Ipopt) not finished: the exact levels are kept"
                  if r.refined.n_failed == len(r.refined.start_values) else
                  f", then refined continuously within the bounds (Ipopt, exact CasADi derivatives, "
                  f"{len(r.refined.start_values)} starts, {r.refined.n_failed} not finished)"))
    txt = (f"{'Planned before data at the start values' if plan.planned else 'At the estimate'} of {plan.variant}, "
           f"p = ({', '.join(f'{x:.4g}' for x in plan.p)}). {n_d} new experiment(s) chosen among "
           f"{len(plan.candidates)} candidates (the study's experiments within the bounds and random ones within "
           f"them): {', '.join(plan.chosen)}, by {how}, for the {plan.criterion}-criterion of the Gauss-Newton "
           f"covariance C, every instrument read at every sampling time, {plan.n_series} series each"
           + (" (the design repeats a current experiment: no candidate does better)"
              if any(c.startswith("experiment") for c in plan.chosen) and not plan.refined else "") + ".\n\n"
           f"{crit}: designed {v['design']:.6g}; the {n_c} current experiments {v['current']:.6g}; current + "
           f"designed {v['current + design']:.6g} (lower is better). Efficiency per experiment of the design "
           f"against the current experiments: {plan.efficiency:.4g} (above 1: one designed experiment is worth "
           f"more than an average current one). The design is of new experiments on their own; the value "
           f"'current + designed' is what the campaign would reach with them."
           + (" 'inf' in the table: that experiment alone does not identify the parameters."
              if not all(np.isfinite(plan.each)) else ""))
    for j, row in enumerate(plan.designed, 1):
        parts = [f"{i.name} = {v[0]:.5g}{' ' + i.unit if i.unit else ''}" if not i.grid else
                 f"{i.name} = [{', '.join(f'{x:.4g}' for x in v)}]{' ' + i.unit if i.unit else ''} at "
                 f"{', '.join(f'{g:g}' for g in i.grid)}" for i, v in row_groups(plan.inputs, row)]
        txt += f"\n\nDesigned experiment {j}: " + "; ".join(parts) + "."
    if plan.time_limit_hit:
        txt += (f"\n\nTIME LIMIT: the design reached [oed] time_limit = {plan.time_limit:g} s "
                f"({plan.time_limit_reason}); raise it to finish.")
    notes = list(plan.notes) + list(plan.result.notes if plan.result is not None else ())
    for n in notes:
        txt += f"\nNote: {n}"
    return txt


def input_design_pages(plan, model) -> list:
    """The page of ``plan`` (an :class:`oed.dynamic_plans.ExperimentPlan`) for the dynamic ``model`` (its horizon
    and time unit), with a prior followed by the exact robust choice's page.

    Returns
    -------
    list of matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt
    from .tables import draw_table
    fig = plt.figure(figsize=_PAGE)
    fig.suptitle(f"Design of the next experiment{'s' if len(plan.designed) > 1 else ''} ({plan.criterion}, "
                 f"{plan.variant})", x=0.04, y=0.97, ha="left", fontsize=14, weight="bold")
    controls = [k for k, i in enumerate(plan.inputs) if i.grid]
    has_consts = any(not i.grid for i in plan.inputs)
    panels = controls[:2] + (["constants"] if has_consts else [])
    horizon = float(model.horizon or max(max(i.grid) for i in plan.inputs if i.grid) * 1.1)
    width = 0.88 / max(len(panels), 1)
    for n, what in enumerate(panels):
        ax = fig.add_axes([0.07 + n * width + (0.06 if what == "constants" else 0.0), 0.52,
                           width - (0.11 if what == "constants" else 0.06), 0.36])
        if what == "constants":
            constants_plot(plan, ax=ax)
        else:
            profile_plot(plan, what, horizon, model.time_unit, ax=ax)
    head, rows, hi = _table(plan)
    shown = rows[:16]
    h = min(0.026 * (len(shown) + 1), 0.42)
    draw_table(fig.add_axes([0.04, 0.40 - h, 0.36, h]), head, shown, fontsize=8, chosen=hi[:len(shown)])
    wrapped = "\n".join("\n".join(textwrap.wrap(par, 95)) if par else "" for par in _text(plan).split("\n"))
    fig.text(0.43, 0.40, wrapped, va="top", ha="left", fontsize=8.5)
    figs = [fig]
    if plan.robust is not None:
        from .design_pages import robust_exact_page
        figs.append(robust_exact_page(plan.robust, "candidate experiment"))
    return figs
