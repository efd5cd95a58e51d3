r"""Report pages of the planned designs (``[oed] mode`` inputs, both, discrimination; issue 13).

The sensor design of ``mode = "sensors"`` has its own page (:func:`reports.builder` "oed");
these pages show the design of the other modes, held by ``results.plan``:

* inputs: the chosen rows of the candidate set points (exact design, value, proven lower
  bound), next to their continuous refinement (:func:`oed.refine_inputs`) when it was run;
* both: the chosen (set point, sensor) pairs of the joint design;
* discrimination: the per-reading T map :math:`((h_\text{true} - h_\text{rival})/\sigma)^2`
  over set points x sensors with the chosen readings marked, the chosen readings, and the
  design values (T, with data the divergence, and T_refit with the rival refitted) against the
  evenly spread design of the same budget (the paper's style) and against all candidate readings.

* approximate (``[oed] prior`` or ``approximate = true``, issue 31): the sensitivity function over the
  checked range with its maximum and the line at its optimum (the certificate), the support points and
  weights, and with a prior the local design's efficiency across the prior against the robust one.

The functions read ``results.plan`` of the study's :class:`oed.study_record.StudyRecord`, one of the typed
records of :mod:`oed.plan_records` (``PlannedDesign``, ``RobustPlan`` or ``DiscriminationPlan``); they never
import the study layer.
"""
from __future__ import annotations

import textwrap

import numpy as np

from oed.plan_records import RobustExactPlan, RobustPlan

__all__ = ["design_pages", "robust_exact_page", "approximate_pages"]

PAGE_SIZE = (11.69, 8.27)
ROWS_PER_TABLE = 22


def _page(title):
    import matplotlib.pyplot as plt
    fig = plt.figure(figsize=PAGE_SIZE)
    fig.suptitle(title, x=0.04, y=0.97, ha="left", fontsize=14, weight="bold")
    return fig


def _text(fig, x, y, text, width=110, size=9):
    wrapped = "\n".join("\n".join(textwrap.wrap(par, width)) if par else "" for par in text.split("\n"))
    fig.text(x, y, wrapped, va="top", ha="left", fontsize=size)


def _fmt(v) -> str:
    return f"{v:.4g}" if np.isfinite(v) else str(v)


def design_pages(results) -> list:
    """The design pages of ``results.plan`` (empty when the study ran no planned design).

    Returns
    -------
    list of matplotlib.figure.Figure
    """
    plan = results.plan
    if plan is None:
        return []
    model = results.study.models[plan.variant]
    q_unit = model.input_units[0] if model.input_units and model.input_units[0] else ""
    if plan.mode == "discrimination":
        return _discrimination_pages(plan, q_unit, dict(zip(model.sensors, model.sensor_units)))
    if isinstance(plan, RobustPlan):
        return approximate_pages(plan, f"set point{f' ({q_unit})' if q_unit else ''}")
    if isinstance(plan, RobustExactPlan):
        label = {"inputs": f"set point{f' ({q_unit})' if q_unit else ''}",
                 "both": f"(set point{f' ({q_unit})' if q_unit else ''}, sensor) pair"}.get(plan.mode, "")
        return [robust_exact_page(plan, label)]
    return _input_pages(plan, q_unit, list(model.sensors))


# ---------------------------------------------------------------------------- inputs / both
def _input_pages(plan, q_unit: str, sensors: list) -> list:
    r = plan.result
    cand = np.asarray(plan.candidates, float)
    joint = plan.mode == "both"
    title = ("Joint input x sensor design" if joint else "Input design") + f" ({r.criterion}, {plan.variant})"
    fig = _page(title)
    ax = fig.add_axes([0.07, 0.60, 0.86, 0.28])
    chosen = sorted(set(r.indices))
    if joint:
        _pair_grid(ax, cand, r, q_unit, sensors)
    else:
        ax.plot(cand, np.zeros_like(cand), "|", color="0.6", ms=18, label="candidate set points")
        ax.plot(cand[chosen], np.zeros(len(chosen)), "o", color="tab:green", ms=11, label="exact design")
    if r.refined is not None:
        lev = r.refined.inputs.ravel()
        ax.plot(lev, np.full(lev.size, 0.35), "v", color="tab:red", ms=11, label="continuous refinement")
        for a, b in zip(cand[list(r.indices)], lev):
            ax.annotate("", (b, 0.3), (a, 0.05), arrowprops=dict(arrowstyle="->", color="0.5", lw=0.8))
    if not joint:
        ax.set_ylim(-0.6, 0.8)
        ax.set_yticks([])
        ax.set_xlabel(f"set point{f' ({q_unit})' if q_unit else ''}")
        ax.legend(loc="upper left", fontsize=8, ncol=3, frameon=False)
        for side in ("left", "right", "top"):
            ax.spines[side].set_visible(False)
    from .tables import draw_table
    if joint:
        head = ["row", f"set point{f' ({q_unit})' if q_unit else ''}", "sensor"]
        rows = [[j, f"{cand[j]:g}", s] for j, s in r.pairs]
    else:
        head = ["row", f"set point{f' ({q_unit})' if q_unit else ''}", "sensors read"]
        rows = [[j, f"{cand[j]:g}", ", ".join(s for jj, s in r.pairs if jj == j)] for j in chosen]
        if r.refined is not None:
            head.append(f"refined set point{f' ({q_unit})' if q_unit else ''}")
            lev = r.refined.inputs.ravel()
            order = {j: k for k, j in enumerate(r.indices)}
            rows = [row + [f"{lev[order[row[0]]]:.6g}"] for row in rows]
    shown = rows[:ROWS_PER_TABLE]
    h = min(0.03 * (len(shown) + 1), 0.45)
    draw_table(fig.add_axes([0.04, 0.52 - h, 0.55, h]), head, shown, fontsize=8)
    crit = "log det C" if r.criterion == "D" else r.criterion
    txt = (f"{'Planned before data at the start values' if plan.planned else 'At the estimate'} of "
           f"{plan.variant}, p = ({', '.join(f'{v:.6g}' for v in plan.p)}). "
           f"Chosen {len(r.pairs) if joint else len(chosen)} of {cand.size * (len(sensors) if joint else 1)} "
           f"candidate {'(set point, sensor) pairs' if joint else 'set points'} by the {r.criterion}-criterion of the "
           f"Gauss-Newton covariance: {crit} = {_fmt(r.value)}, proven lower bound {_fmt(r.lower_bound)}, "
           f"{'proven optimal' if r.proven_optimal else 'not proven optimal'} ({r.method}).")
    if r.refined is not None:
        f = r.refined
        txt += (f"\n\nContinuous refinement (Ipopt through CasADi, exact derivatives, {len(f.start_values)} starts, "
                f"{f.n_failed} failed) of the chosen set points within [{f.lower[0]:g}, {f.upper[0]:g}]"
                f"{f' {q_unit}' if q_unit else ''}: {crit} = {_fmt(f.value)} against {_fmt(r.value)} for the exact "
                f"design on the candidates ({'better' if f.value < r.value else 'no better'} by {abs(r.value - f.value):.3g}).")
    elif not joint:
        txt += "\n\nNo continuous refinement was run ([oed] refine = true runs it)."
    if len(rows) > len(shown):
        txt += f"\n\nThe table shows the first {len(shown)} of {len(rows)} chosen rows (all are in oed.json)."
    for n in r.notes:
        txt += f"\nNote: {n}"
    _text(fig, 0.62, 0.52, txt, width=62)
    return [fig]


def _pair_grid(ax, cand, r, q_unit: str, names: list) -> None:
    """Every candidate (set point, sensor) pair as a grey dot, the chosen pairs in green."""
    jj, kk = np.meshgrid(np.arange(cand.size), np.arange(len(names)), indexing="ij")
    ax.plot(cand[jj.ravel()], kk.ravel(), ".", color="0.6", ms=6, label="candidate pairs")
    ax.plot([cand[j] for j, _ in r.pairs], [names.index(s) for _, s in r.pairs], "o", color="tab:green", ms=11,
            label="chosen pairs")
    ax.set_yticks(range(len(names)), names)
    ax.set_ylim(-0.7, len(names) - 0.3)
    ax.set_xlabel(f"set point{f' ({q_unit})' if q_unit else ''}")
    ax.legend(loc="lower left", bbox_to_anchor=(0.0, 1.0), fontsize=8, ncol=2, frameon=False)


# ---------------------------------------------------------------------------- approximate (issue 31)
def approximate_pages(plan, x_label: str, what: str = "input") -> list:
    """The approximate design (of input set points, or of a dynamic study's sampling times: ``what``
    "sampling-time"; ``x_label`` the axis with its unit): its sensitivity function (the certificate), the design,
    and with a prior the local design's efficiency across the prior against the robust one."""
    from .approx_figures import efficiency_curve, sensitivity_plot
    from .tables import draw_table
    d, local = plan.design, plan.local
    kind = {"local": "local", "bayes": "pseudo-Bayesian", "maximin": "maximin"}.get(d.robust, d.robust)
    fig = _page(f"Approximate {what} design ({d.criterion}, {kind}, {plan.variant})")
    wide = local is None
    sensitivity_plot(np.asarray(d.checked)[:, 0], d.sensitivity, d.reference, np.asarray(d.points)[:, 0], x_label,
                     ax=fig.add_axes([0.07, 0.50, 0.86 if wide else 0.40, 0.38]))
    if not wide:
        efficiency_curve(plan.local_efficiencies, d.prior.weights, ax=fig.add_axes([0.56, 0.50, 0.38, 0.38]))
    head, rows = [x_label, "weight"], [[f"{x[0]:.6g}", f"{w:.4f}"] for x, w in zip(d.points, d.weights)]
    if not wide:
        head, rows = ["design"] + head, [["robust"] + r for r in rows]
        rows += [["local"] + [f"{x[0]:.6g}", f"{w:.4f}"] for x, w in zip(local.points, local.weights)]
    shown = rows[:ROWS_PER_TABLE // 2]
    h = min(0.03 * (len(shown) + 1), 0.30)
    draw_table(fig.add_axes([0.04, 0.38 - h, 0.34, h]), head, shown, fontsize=8)
    _text(fig, 0.42, 0.38, _approximate_text(plan, kind, what), width=90)
    return [fig]


def _approximate_text(plan, kind: str, what: str = "input") -> str:
    d = plan.design
    over = ("the range of the candidate times, for the study's experiments (every instrument read at each time)"
            if what == "sampling-time" else "the candidates' range")
    txt = (f"{'Planned before data at the start values' if plan.planned else 'At the estimate'} of {plan.variant}, "
           f"p = ({', '.join(f'{v:.6g}' for v in plan.p)}); {kind} {d.criterion}-optimal approximate design over "
           f"{over}, {d.prior.n} parameter vector{'s' if d.prior.n > 1 else ''}"
           f"{f' ({d.prior.rule} rule)' if d.prior.n > 1 else ''}.\n\n"
           f"Certificate (equivalence theorem): the sensitivity function's maximum over the {len(d.sensitivity)} "
           f"checked points is {d.sensitivity_max:.9g} against its optimum value {d.reference:.9g} (gap "
           f"{d.gap:.2g}); efficiency against the optimal approximate design >= {d.efficiency_bound:.6f}.")
    if d.robust == "maximin":
        txt += f" Worst-case efficiency {d.value:.6f}, certified >= {d.worst_case_bound:.6f}."
    if plan.local is not None:
        e, w = np.asarray(plan.local_efficiencies), np.asarray(d.prior.weights)
        txt += (f"\n\nThe local design (at p) across the prior, against the {kind} design: efficiency min "
                f"{e.min():.4f}, prior mean {float(w @ e):.4f}, max {e.max():.4f} (right; above 1 where the local design "
                f"is the better one at that parameter vector: the robust design is best over the prior as a whole).")
    txt += "\n\nThe maximum is over the checked points (a grid refined around each high local maximum), not " \
           "proven over the continuum."
    for n in plan.notes:
        txt += f"\nNote: {n}"
    return txt


def robust_exact_page(plan, axis_label: str = "") -> object:
    """The exact robust design over a prior (:class:`oed.plan_records.RobustExactPlan`): the candidates with the
    robust and the local designs' choices, the local design's efficiency across the prior against the robust one,
    and the proof (method, status, gap).  ``axis_label``: the candidates' axis (times with their unit); sensors
    are drawn by name."""
    from .approx_figures import efficiency_curve
    d, local = plan.design, plan.local
    kind = {"bayes": "pseudo-Bayesian", "maximin": "maximin"}.get(d.robust, d.robust)
    what = {"times": "sampling-time", "inputs": "input", "both": "joint set point x sensor"}.get(plan.mode, "sensor")
    fig = _page(f"Exact robust {what} design ({d.criterion}, {kind}, {plan.variant})")
    ax = fig.add_axes([0.07, 0.50, 0.40, 0.38])
    labels = list(plan.candidates)
    try:
        x = np.array([float(v) for v in labels])
    except ValueError:                                 # sensors, or sensor@time pairs: by position
        x = np.arange(len(labels), dtype=float)
        ax.set_xticks(x)
        ax.set_xticklabels(labels, rotation=90 if len(labels) > 8 else 0, fontsize=7)
    ax.plot(x, np.zeros_like(x), "|", color="0.6", ms=18, label="candidates")
    ax.plot(x[list(d.indices)], np.full(len(d.indices), 0.25), "o", color="tab:green", ms=10, label=f"{kind} design")
    ax.plot(x[list(local.indices)], np.full(len(local.indices), -0.25), "s", mfc="none", color="tab:red", ms=10,
            label="local design at p")
    ax.set_ylim(-0.8, 0.9)
    ax.set_yticks([])
    ax.set_xlabel(axis_label or ("time" if plan.mode == "times" else "sensor"))
    ax.legend(loc="upper left", fontsize=8, ncol=3, frameon=False)
    for side in ("left", "right", "top"):
        ax.spines[side].set_visible(False)
    efficiency_curve(plan.local_efficiencies, plan.prior_weights, ax=fig.add_axes([0.56, 0.50, 0.38, 0.38]))
    _text(fig, 0.07, 0.38, _robust_exact_text(plan, kind), width=150)
    return fig


def _robust_exact_text(plan, kind: str) -> str:
    d, local = plan.design, plan.local
    e, w = np.asarray(plan.local_efficiencies), np.asarray(plan.prior_weights)
    proof = (f"proven optimal by {'complete enumeration' if d.method == 'enumerate' else 'branch-and-bound'}"
             if d.proven_optimal else f"NOT proven optimal: stopped at the {d.status}, proven gap {d.gap:.3g}")
    crit = ({"D": "expected log det of the information per run", "A": "expected -trace of its inverse",
             "E": "expected -1/smallest eigenvalue"}[d.criterion] if d.robust == "bayes" else
            f"worst-case efficiency {d.efficiency:.6f}; standardized worst case")
    txt = (f"{'Planned before data at the start values' if plan.planned else 'At the estimate'} of {plan.variant}, "
           f"p = ({', '.join(f'{v:.6g}' for v in plan.p)}); the prior: {len(w)} parameter vectors. "
           f"{kind[0].upper() + kind[1:]} {d.criterion}-optimal choice of {len(d.indices)} of the {len(plan.candidates)} "
           f"candidates: {', '.join(d.names)} ({crit} {d.value:.9g}; {proof}, {d.n_designs} sets evaluated, "
           f"{d.wall_time:.2f} s).\n\nThe local design at p: {', '.join(local.names)}.  Its efficiency against the "
           f"{kind} design across the prior: min {e.min():.4f}, prior mean {float(w @ e):.4f}, max {e.max():.4f} "
           "(right; above 1 where the local design is the better one at that parameter vector: the robust design is "
           "best over the prior as a whole).")
    if d.robust == "maximin":
        txt += " The worst-case efficiency is against each parameter vector's own best design of as many runs (exact)."
    for n in plan.notes:
        txt += f"\nNote: {n}"
    return txt


# ---------------------------------------------------------------------------- discrimination
def _discrimination_pages(plan, q_unit: str, s_units: dict) -> list:
    import matplotlib.colors as mcolors
    from .tables import draw_table
    r = plan.result
    cand = np.asarray(plan.candidates, float)
    names = list(r.candidate_sensors)
    T = np.asarray(plan.scores["T"])
    fig = _page(f"Discrimination design: {plan.variant} (assumed true) against {plan.rival}")
    ax = fig.add_axes([0.07, 0.60, 0.88, 0.28])
    im = ax.imshow(T.T, aspect="auto", cmap="viridis", origin="upper",
                   norm=mcolors.PowerNorm(0.5, vmin=0.0, vmax=max(float(T.max()), 1e-12)))
    jj = [j for j, _ in r.readings]
    kk = [names.index(s) for _, s in r.readings]
    ax.plot(jj, kk, "s", mfc="none", mec="tab:red", ms=9, mew=1.8, label="chosen reading")
    ax.set_yticks(range(len(names)), names)
    step = max(1, int(np.ceil(cand.size / 30)))
    ax.set_xticks(range(0, cand.size, step), [f"{cand[j]:g}" for j in range(0, cand.size, step)], rotation=90,
                  fontsize=7)
    ax.set_xlabel(f"candidate set point, in load order{f' ({q_unit})' if q_unit else ''}")
    ax.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), fontsize=8, frameon=False)
    fig.colorbar(im, ax=ax, pad=0.01, fraction=0.03).set_label("T per reading", fontsize=8)
    head = [f"set point{f' ({q_unit})' if q_unit else ''}", "sensor", "h_true - h_rival", "T"]
    has_div = "divergence" in plan.scores
    if has_div:
        head.append("divergence")
    rows = []
    for j, s in r.readings:
        k = names.index(s)
        unit = s_units.get(s, "")
        row = [f"{cand[j]:g}", s, f"{r.difference[j, k]:+.4g}{' ' + unit if unit else ''}", f"{T[j, k]:.3g}"]
        if has_div:
            row.append(f"{plan.scores['divergence'][j, k]:.3g}")
        rows.append(row)
    shown = rows[:ROWS_PER_TABLE]
    h = min(0.022 * (len(shown) + 1), 0.46)
    draw_table(fig.add_axes([0.04, 0.49 - h, 0.46, h]), head, shown, fontsize=7)
    keys = list(plan.design_values("chosen"))
    chead = ["design", "readings"] + keys
    crow = []
    for name, readings in (("chosen", r.readings),) + tuple(plan.references.items()):
        v = plan.design_values(name)
        crow.append([name, len(readings)] + [f"{v[k]:.4g}" for k in keys])
    draw_table(fig.add_axes([0.54, 0.49 - 0.03 * 4, 0.44, 0.03 * 4]), chead, crow, fontsize=8,
               chosen=[True, False, False])
    budget = (f"{len(r.readings)} free readings" if r.method == "top-k" and len(set(r.sensors)) != len(r.sensors)
              else f"{len(r.readings)} readings")
    txt = (f"Per reading (set point j, sensor s): T = ((h_true - h_rival) / sigma_s)^2, the non-centrality the "
           f"reading adds to the test of {plan.rival} with its parameters held at "
           + ("their start values (planned before data)" if plan.planned else "its estimate")
           + (", and the divergence (h_true - h_rival)^2 / (2 sigma_s^2 + V_true + V_rival) with the predictive "
              "variances V of both estimates" if has_div else "")
           + f". Chosen by the {r.criterion} criterion: {budget}, value {r.value:.4g} per series "
           f"({'proven optimal' if r.proven_optimal else f'upper bound {r.upper_bound:.4g}'}, {r.method}). "
           f"Design values are per series times {plan.n_series} series. 'evenly spread' is the paper's style at the "
           "same budget (evenly spaced set points, the same sensors); 'all readings' every candidate. "
           f"Refitting {plan.rival} on the new readings lowers T (T is an upper bound of the test's "
           f"non-centrality); T_refit is T with {plan.rival}'s parameters re-estimated on the readings "
           "(linearised), the non-centrality of the likelihood-ratio test to first order.")
    if len(rows) > len(shown):
        txt += f" The table shows the first {len(shown)} of {len(rows)} readings (all are in oed.json)."
    _text(fig, 0.54, 0.30, txt, width=70, size=8.5)
    return [fig]
