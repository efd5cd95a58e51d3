"""Report pages of a dynamic (ODE/DAE) study: trajectories against time, residuals against time, the
sampling-time design.

The figures take ``ax=None`` and what the study computed (``results.trajectories``: per variant a
:class:`identification.studies.records.Trajectories` with the outputs on a fine time grid, the delta-method
band half-widths and the standardized residuals; ``results.plan``: the sampling-time design, an
:class:`oed.plan_records.DynamicDesign`; ``results`` is the study's :class:`oed.study_record.StudyRecord`) and return
the figure; :func:`dynamic_pages` replaces the static pages (outputs against the set point, the
sensor-combination table, bands and residuals against the input, the diagnostic splits) in the
report's page list (:func:`reports.builder.report_pages`).
"""
from __future__ import annotations

import textwrap
from functools import partial

import numpy as np

from oed.plan_records import RobustExactPlan

__all__ = ["trajectory_plot", "residual_time_plot", "time_design_plot", "dynamic_pages", "discretisation_lines"]

#: experiments (rows) per trajectory page and instruments (columns)
_ROWS, _COLS = 3, 4
_PAGE = (11.69, 8.27)
_MARK = dict(marker="^", color="tab:red", ms=6, ls="none", clip_on=False)


def _ax(ax):
    import matplotlib.pyplot as plt
    if ax is None:
        _, ax = plt.subplots(figsize=(6.0, 4.0))
    return ax


def _unit(u: str) -> str:
    return f" ({u})" if u else ""


def _inputs_text(model, row) -> str:
    units = list(model.input_units) + [""] * len(row)
    return ", ".join(f"{n} = {v:g}{' ' + u if u else ''}" for n, v, u in zip(model.inputs, row, units))


def trajectory_plot(traj, data, model, j: int, k: int, chosen_times=(), ax=None):
    """Experiment j, instrument k: measured values (every series), the output h(x(t)) at the estimate,
    its band of the mean (shaded) and of a new observation (dashed) against time; the chosen sampling
    times as red triangles on the time axis."""
    ax = _ax(ax)
    t, h = traj.t, traj.h[j, :, k]
    m, w = traj.half_mean[j, :, k], traj.half_new[j, :, k]
    lvl = f"{100 * traj.level:g} %"
    ax.fill_between(t, h - m, h + m, color="tab:blue", alpha=0.3, lw=0, label=f"{lvl} band, mean")
    ax.plot(t, h - w, color="tab:blue", lw=0.7, ls="--", label=f"{lvl} band, new reading")
    ax.plot(t, h + w, color="tab:blue", lw=0.7, ls="--")
    ax.plot(t, h, color="tab:blue", lw=1.2, label="model at the estimate")
    n = int(np.isfinite(data.times[j]).sum())
    for i in range(data.n_M):
        ax.plot(data.times[j, :n], data.z[i, j, :n, k], "o", ms=2.8, color="0.3", mfc="none" if i else "0.3",
                label="measured" + (f" (series {i + 1})" if data.n_M > 1 else ""))
    if len(chosen_times):
        ax.plot(chosen_times, np.zeros(len(chosen_times)), transform=ax.get_xaxis_transform(),
                label="chosen sampling times", **_MARK)
    ax.set_xlabel(f"time{_unit(model.time_unit)}", fontsize=8)
    ax.set_ylabel(f"{model.sensors[k]}{_unit(model.sensor_units[k])}", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(alpha=0.3)
    return ax.figure


def residual_time_plot(traj, data, model, k: int, chosen_times=(), ax=None):
    """Standardized residuals (z - h)/sigma of instrument k against time, one colour per experiment."""
    import matplotlib.pyplot as plt
    ax = _ax(ax)
    cmap = plt.get_cmap("tab10")
    for j in range(data.n_q):
        n = int(np.isfinite(data.times[j]).sum())
        for i in range(data.n_M):
            ax.plot(data.times[j, :n], traj.residuals[i, j, :n, k], "o", ms=2.8, color=cmap(j % 10),
                    mfc="none" if i else cmap(j % 10), label=f"experiment {j + 1}" if i == 0 else None)
    for y in (-2, 2):
        ax.axhline(y, color="0.5", ls="--", lw=0.8)
    ax.axhline(0, color="0.3", lw=0.8)
    if len(chosen_times):
        ax.plot(chosen_times, np.zeros(len(chosen_times)), transform=ax.get_xaxis_transform(), **_MARK)
    ax.set_xlabel(f"time{_unit(model.time_unit)}", fontsize=8)
    ax.set_ylabel(f"(z - h) / sigma of {model.sensors[k]}", fontsize=8)
    ax.set_title(f"instrument {model.sensors[k]}", fontsize=9)
    ax.tick_params(labelsize=7)
    ax.grid(alpha=0.3)
    return ax.figure


def time_design_plot(plan, model, ax=None):
    """The candidate sampling times (grey) and the chosen ones (red) on the time axis."""
    ax = _ax(ax)
    cand = np.asarray(plan.candidates)
    chosen = np.asarray(plan.chosen_times())
    ax.plot(cand, np.zeros_like(cand), "|", color="0.5", ms=14, label="candidate times")
    ax.plot(chosen, np.zeros_like(chosen), "^", color="tab:red", ms=9, label="chosen")
    for tc in chosen:
        ax.annotate(f"{tc:g}", (tc, 0), xytext=(0, 9), textcoords="offset points", ha="center", fontsize=8)
    ax.set_yticks([])
    ax.set_ylim(-1, 1)
    lo, hi = 0.0, max(float(cand.max()), model.horizon or 0.0)
    ax.set_xlim(lo - 0.02 * hi, 1.02 * hi)
    ax.set_xlabel(f"time{_unit(model.time_unit)}", fontsize=9)
    ax.set_title("Candidate and chosen sampling times", fontsize=10)
    ax.legend(fontsize=8, loc="upper right", ncol=2)
    for side in ("left", "right", "top"):
        ax.spines[side].set_visible(False)
    return ax.figure


# ---------------------------------------------------------------------------- pages
def _page(title):
    import matplotlib.pyplot as plt
    fig = plt.figure(figsize=_PAGE)
    fig.suptitle(title, x=0.04, y=0.97, ha="left", fontsize=14, weight="bold")
    return fig


def _text(fig, x, y, text, width=175, size=8, **kw) -> int:
    """Wrapped text from (x, y) down; returns its number of lines."""
    width = min(width, int(175 * 8 / size))          # the page's width at this font size
    lines = textwrap.wrap(text, width)
    fig.text(x, y, "\n".join(lines), va="top", ha="left", fontsize=size, **kw)
    return len(lines)


def discretisation_lines(fig, results, y) -> None:
    """Under the estimates of a dynamic study, from ``y`` down: the discretisation of each fit on all study
    data as the study recorded it (``results.discretisation``), in red when its error is not bounded."""
    mesh = results.discretisation
    if not mesh:
        return
    fig.text(0.04, y, "Discretisation of the fits on all study data", fontsize=9, weight="bold", va="top")
    y -= 0.025
    for v, m in mesh.items():
        red = {} if m.bounded else dict(color="tab:red", weight="bold")
        y -= 0.019 * _text(fig, 0.04, y, f"{v}: {m.text()}", width=170, size=8.5, **red) + 0.006
    _text(fig, 0.04, y, "Every fit of a split (calibration, validation, pooled) controls its own mesh the same "
          "way; a split one of whose fits could not bound its error is undecided, never a rejection.",
          width=170, size=8, color="0.3")


def _chosen(results) -> tuple:
    plan = results.plan
    return plan.chosen_times() if plan is not None and plan.mode == "times" else ()


def _trajectory_pages(results):
    figs = []
    s = results.study
    for v, traj in results.trajectories.items():
        model, data = s.models[v], s.data[v]
        k = -(-data.n_q // _ROWS)                       # pages, the experiments shared evenly (4: 2 + 2)
        edges = [round(i * data.n_q / k) for i in range(k + 1)]
        rows = [range(a, b) for a, b in zip(edges, edges[1:])]
        for n, part in enumerate(rows):
            part_of = f" ({n + 1}/{len(rows)})" if len(rows) > 1 else ""
            fig = _page(f"Trajectories of model {v} against time{part_of}")
            axes = fig.subplots(max(len(p) for p in rows), min(model.n_S, _COLS), squeeze=False)
            for ax in axes[len(part):].ravel():         # every page's panels the same height
                ax.axis("off")
            for r, j in enumerate(part):
                for k in range(min(model.n_S, _COLS)):
                    trajectory_plot(traj, data, model, j, k, _chosen(results), ax=axes[r, k])
                    axes[r, k].set_title(f"experiment {j + 1}: {_inputs_text(model, s.inputs[j])}", fontsize=8)
            handles, labels = axes[0, 0].get_legend_handles_labels()
            fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8, frameon=False,
                       bbox_to_anchor=(0.5, 0.075))
            fig.subplots_adjust(left=0.07, right=0.98, top=0.9, bottom=0.2, wspace=0.22, hspace=0.55)
            _text(fig, 0.04, 0.06, f"Measured readings and the outputs h(x(t)) of {v} at its estimate on a fine time "
                  f"grid ({_grid_error(traj)}). Bands at {100 * traj.level:g} %: h +- q "
                  "sqrt(g^T C g) for the mean (shaded) and h +- q sqrt(g^T C g + sigma^2) for a new reading "
                  f"(dashed), g = dh/dp exact, C the second-order covariance, q the {traj.quantile} quantile. Red "
                  "triangles: the sampling times chosen by the design (for the next campaign).")
            figs.append(fig)
    return figs


def _grid_error(traj) -> str:
    """How accurate the drawn outputs are, as the study computed it (``Trajectories.error_sigma``)."""
    err, tol = traj.error_sigma, traj.tol_sigma
    if not np.isfinite(err):
        return "Radau IIA collocation"
    return (f"Radau IIA collocation, discretisation error at most {100 * err:.2g} % of sigma"
            + (f", below {100 * tol:.2g} %" if np.isfinite(tol) and err <= tol else ""))


def _residual_pages(results):
    figs = []
    s = results.study
    for v, traj in results.trajectories.items():
        model, data = s.models[v], s.data[v]
        fig = _page(f"Residuals of model {v} against time (fit on all study data)")
        axes = fig.subplots(1, min(model.n_S, _COLS), squeeze=False)[0]
        for k, ax in enumerate(axes):
            residual_time_plot(traj, data, model, k, _chosen(results), ax=ax)
        handles, labels = axes[0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 8), fontsize=8, frameon=False,
                   bbox_to_anchor=(0.5, 0.1))
        fig.subplots_adjust(left=0.07, right=0.98, top=0.88, bottom=0.3, wspace=0.25)
        _text(fig, 0.04, 0.08, "Standardized residuals (z - h)/sigma of every reading against its sampling time, one "
              "colour per experiment (filled: series 1, open: later series). Dashed: +-2. A trend over time shared "
              "by the experiments shows dynamics the model misses (a rate law, a delay, a missing state); residuals "
              "growing with time point at an error that accumulates. Red triangles: the chosen sampling times.")
        figs.append(fig)
    return figs


def _design_page(results):
    from .tables import criteria_units, draw_table
    fig = _page("Sampling-time design")
    plan = results.plan
    if plan is None or plan.mode != "times":
        _text(fig, 0.04, 0.85, "Not available: " + "; ".join(n for n in results.notes if "design" in n), size=10)
        return fig
    if isinstance(plan, RobustExactPlan):
        import matplotlib.pyplot as plt
        plt.close(fig)
        from .design_pages import robust_exact_page
        return robust_exact_page(plan, f"time{_unit(results.study.models[plan.variant].time_unit)}")
    r, model = plan.result, results.study.models[plan.variant]
    head = ["rank", "log det C", "trace C", "max eig C",
            f"sampling times{_unit(model.time_unit)}" if not plan.pairs else "readings", ""]
    rows, chosen = [], []
    for k, row in enumerate(plan.table.rows, 1):
        is_c = tuple(row.sensors) == tuple(r.chosen)
        rows.append([str(k) if k <= 10 else "-", f"{row.logdet:.4f}", f"{row.A:.4e}", f"{row.E:.4e}",
                     ", ".join(row.sensors), ("chosen " if is_c else "") + (row.flag or "")])
        chosen.append(is_c)
    h = 0.03 * (len(rows) + 1)
    ax = fig.add_axes([0.04, 0.88 - h, 0.92, h])
    draw_table(ax, head, rows, fontsize=9, chosen=chosen, col_widths=[0.06, 0.12, 0.12, 0.12, 0.46, 0.12])
    names = ", ".join(model.param_names)
    value = f"log det C = {r.value:.4f}" if r.criterion == "D" else f"{r.criterion} = {r.value:.4e}"
    _text(fig, 0.04, 0.86 - h, (
        f"{plan.table.note[0].upper() + plan.table.note[1:]} ({'readings' if plan.pairs else 'sampling times'}), by "
        f"the {r.criterion}-criterion of the Gauss-Newton covariance C of ({names}) planned at the {plan.variant} "
        f"estimate for the study's {len(results.study.inputs)} experiments, every instrument reading at each chosen "
        f"time. Chosen: {', '.join(r.chosen)} (green), {value}, "
        f"{'proven optimal' if r.proven_optimal else 'not proven optimal'} ({r.method}). The tests of "
        f"Algorithm 1 use every reading of the data; the design is for the next campaign. Criteria: "
        f"{criteria_units(results.study)}."),
        size=9)
    ax2 = fig.add_axes([0.08, 0.1, 0.84, 0.16])
    time_design_plot(plan, model, ax=ax2)
    return fig


def dynamic_pages(pages: list, results) -> list:
    """The report's page list with the static pages replaced by the dynamic ones (see the module docstring)."""
    swap = {"loops": ("trajectories", partial(_trajectory_pages, results)),
            "oed": ("time_design", partial(_design_page, results)),
            "residuals": ("residuals", partial(_residual_pages, results))}
    drop = {"bands", "design", "misses"}
    return [swap.get(name, (name, make)) for name, make in pages if name not in drop]
