"""Report pages of a dynamic (ODE/DAE) study: the experiments' inputs (a model with controls: the full table
once), trajectories against time (the controls u(t) and constants beside them, titles a short summary of the
inputs, repeated series in their own marker and colour side by side), residuals against time and against
every output of the model at the estimate, the sampling-time design.

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

from oed.dynamic_plans import ApproximateTimePlan, ExperimentPlan
from oed.plan_records import RobustExactPlan

__all__ = ["trajectory_plot", "residual_time_plot", "residual_output_plot", "control_plot", "time_design_plot",
           "dynamic_pages", "discretisation_lines", "inputs_summary", "series_style"]

#: experiments (rows) per trajectory page and instruments (columns)
_ROWS, _COLS = 3, 4
_PAGE = (11.69, 8.27)
_MARK = dict(marker="^", color="tab:red", ms=6, ls="none", clip_on=False)
#: repeated series: marker, colour of the measured points (series 1 as before, the later ones apart)
_SERIES_MARKS = ("o", "s", "^", "D", "v", "P")
_SERIES_COLOURS = ("0.25", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:pink")
#: series drawn side by side: offset of series i from the reading's time, as a fraction of the horizon
_SERIES_OFFSET = 0.004
#: experiments per row of the input table, grid values per column block
_TABLE_ROWS, _TABLE_COLS = 22, 12


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


def _control_values(model, row) -> list:
    """[(Control, its grid values from the input row)] of a model's controls."""
    out, k = [], len(model.constants)
    for c in model.controls:
        out.append((c, np.asarray(row[k:k + len(c.grid)], float)))
        k += len(c.grid)
    return out


def inputs_summary(model, row) -> str:
    """A short summary of one experiment's inputs: every constant with its value, every control as its range
    over its grid ("u: -12 .. 12 V on 10 steps"; one value when it is constant)."""
    if not model.controls:
        return _inputs_text(model, row)
    units = list(model.input_units) + [""] * len(row)
    parts = [f"{n} = {v:g}{' ' + u if u else ''}" for n, v, u in zip(model.constants, row, units)]
    for c, v in _control_values(model, row):
        u = f" {c.unit}" if c.unit else ""
        kind = "steps" if c.kind == "constant" else "points"
        parts.append(f"{c.name} = {v[0]:g}{u}" if np.all(v == v[0]) else
                     f"{c.name}: {v.min():g} .. {v.max():g}{u} on {v.size} {kind}")
    return ", ".join(parts)


def series_style(i: int, n_M: int, horizon: float) -> tuple:
    """(marker, colour, time offset) of series i of n_M: series 1 filled dark circles, the later ones other
    markers and colours, drawn side by side (offset by ``_SERIES_OFFSET`` x horizon) so none hides another."""
    off = (i - (n_M - 1) / 2) * _SERIES_OFFSET * horizon if n_M > 1 else 0.0
    return _SERIES_MARKS[i % len(_SERIES_MARKS)], _SERIES_COLOURS[i % len(_SERIES_COLOURS)], off


def _horizon(traj) -> float:
    return float(traj.t[-1] - traj.t[0]) or 1.0


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
        mk, col, off = series_style(i, data.n_M, _horizon(traj))
        ax.plot(data.times[j, :n] + off, data.z[i, j, :n, k], mk, ms=2.8, color=col, alpha=0.8 if i else 1.0,
                mfc=col if i == 0 else "none", mew=0.8,
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
            mk, _, off = series_style(i, data.n_M, _horizon(traj))
            ax.plot(data.times[j, :n] + off, traj.residuals[i, j, :n, k], mk, ms=2.8, color=cmap(j % 10),
                    mfc="none" if i else cmap(j % 10), alpha=0.8 if i else 1.0,
                    label=f"experiment {j + 1}" if i == 0 else None)
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


def residual_output_plot(traj, data, model, k: int, m: int, ax=None):
    """Standardized residuals (z_k - h_k)/sigma_k of instrument k against the output h_m of the model at the
    estimate at the same reading (``traj.fitted``), one colour per experiment, one marker per series."""
    import matplotlib.pyplot as plt
    ax = _ax(ax)
    cmap = plt.get_cmap("tab10")
    for j in range(data.n_q):
        n = int(np.isfinite(data.times[j]).sum())
        for i in range(data.n_M):
            mk = _SERIES_MARKS[i % len(_SERIES_MARKS)]
            ax.plot(traj.fitted[j, :n, m], traj.residuals[i, j, :n, k], mk, ms=2.5, color=cmap(j % 10),
                    mfc="none" if i else cmap(j % 10), alpha=0.8 if i else 1.0,
                    label=f"experiment {j + 1}" if i == 0 else None)
    for y in (-2, 2):
        ax.axhline(y, color="0.5", ls="--", lw=0.8)
    ax.axhline(0, color="0.3", lw=0.8)
    ax.set_xlabel(f"{model.sensors[m]} at the estimate{_unit(model.sensor_units[m])}", fontsize=7.5)
    ax.set_ylabel(f"(z - h) / sigma of {model.sensors[k]}", fontsize=7.5)
    ax.tick_params(labelsize=6.5)
    ax.grid(alpha=0.3)
    return ax.figure


def control_plot(model, row, horizon: float, ax=None):
    """Experiment inputs against time: each control u(t) as its profile over its grid (piecewise constant:
    steps; linear: lines between the grid points, the last value held to the horizon); the constants
    written in the panel."""
    ax = _ax(ax)
    for n, (c, v) in enumerate(_control_values(model, row)):
        a = ax if n == 0 else ax.twinx()                # a second control on its own axis (its unit)
        t = np.r_[np.asarray(c.grid, float), horizon]
        col = ("tab:purple", "tab:olive", "tab:cyan")[n % 3]
        a.plot(t, np.r_[v, v[-1]], color=col, lw=1.3, label=f"{c.name}(t)",
               drawstyle="steps-post" if c.kind == "constant" else "default")
        a.set_ylabel(f"{c.name}{_unit(c.unit)}", fontsize=8, color=col)
        a.tick_params(labelsize=7)
    units = list(model.input_units) + [""] * len(row)
    consts = "\n".join(f"{n} = {v:g}{' ' + u if u else ''}" for n, v, u in zip(model.constants, row, units))
    if consts:
        ax.text(0.03, 0.95, consts, transform=ax.transAxes, fontsize=7.5, va="top",
                bbox=dict(facecolor="white", alpha=0.85, lw=0.4))
    ax.set_xlim(0.0, horizon)
    ax.set_xlabel(f"time{_unit(model.time_unit)}", fontsize=8)
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
        inputs = 1 if model.controls else 0              # a first column with the experiment's inputs u(t)
        n_col = inputs + min(model.n_S, _COLS)
        k = -(-data.n_q // _ROWS)                       # pages, the experiments shared evenly (4: 2 + 2)
        edges = [round(i * data.n_q / k) for i in range(k + 1)]
        rows = [range(a, b) for a, b in zip(edges, edges[1:])]
        for n, part in enumerate(rows):
            part_of = f" ({n + 1}/{len(rows)})" if len(rows) > 1 else ""
            fig = _page(f"Trajectories of model {v} against time{part_of}")
            axes = fig.subplots(max(len(p) for p in rows), n_col, squeeze=False)
            for ax in axes[len(part):].ravel():         # every page's panels the same height
                ax.axis("off")
            for r, j in enumerate(part):
                if inputs:
                    control_plot(model, s.inputs[j], _horizon(traj) + traj.t[0], ax=axes[r, 0])
                for k in range(min(model.n_S, _COLS)):
                    trajectory_plot(traj, data, model, j, k, _chosen(results), ax=axes[r, inputs + k])
                summary = inputs_summary(model, s.inputs[j])
                axes[r, 0].set_title(f"experiment {j + 1}" + (f": {summary}" if summary else ""), fontsize=8,
                                     loc="left")
            handles, labels = axes[0, inputs].get_legend_handles_labels()
            fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8, frameon=False,
                       bbox_to_anchor=(0.5, 0.1))
            fig.subplots_adjust(left=0.07, right=0.98 if not inputs else 0.985, top=0.9, bottom=0.22,
                                wspace=0.22 if not inputs else 0.32, hspace=0.55)
            said = (" Left column: the experiment's inputs, each control u(t) over its grid (the constants in "
                    "the box; every value in the table 'Experiments')." if inputs else "")
            apart = f"{_SERIES_OFFSET * _horizon(traj):.2g}{' ' + model.time_unit if model.time_unit else ''}"
            series = (f" Series {', '.join(str(i + 1) for i in range(data.n_M))}: "
                      f"{', '.join(_marker_words(i) for i in range(data.n_M))}, drawn side by side ({apart} apart)."
                      if data.n_M > 1 else "")
            _text(fig, 0.04, 0.088, f"Measured readings and the outputs h(x(t)) of {v} at its estimate on a fine time "
                  f"grid ({_grid_error(traj)}). Bands at {100 * traj.level:g} %: h +- q "
                  "sqrt(g^T C g) for the mean (shaded) and h +- q sqrt(g^T C g + sigma^2) for a new reading "
                  f"(dashed), g = dh/dp exact, C the second-order covariance, q the {traj.quantile} quantile. Red "
                  "triangles: the sampling times chosen by the design (for the next campaign)." + series + said)
            figs.append(fig)
    return figs


def _marker_words(i: int) -> str:
    names = {"o": "circles", "s": "squares", "^": "triangles", "D": "diamonds", "v": "down triangles", "P": "plus"}
    mk = series_style(i, i + 1, 1.0)[0]
    return f"{'filled' if i == 0 else 'open'} {names[mk]}"


def _input_table_pages(results):
    """The experiments' inputs once, in full: every constant and every grid value of every control."""
    from .tables import draw_table
    s = results.study
    model = next(iter(s.models.values()))
    Q = np.asarray(s.inputs, float)
    units = list(model.input_units) + [""] * Q.shape[1]
    cols = [(f"{n}{_unit(units[k])}", k) for k, n in enumerate(model.constants)]
    k0 = len(model.constants)
    for c in model.controls:
        cols += [(f"{c.name}(t={g:g}){_unit(c.unit) if i == 0 else ''}", k0 + i)
                 for i, g in enumerate(c.grid)]
        k0 += len(c.grid)
    blocks = [cols[a:a + _TABLE_COLS] for a in range(0, max(len(cols), 1), _TABLE_COLS)]
    rparts = [range(a, min(a + _TABLE_ROWS, Q.shape[0])) for a in range(0, Q.shape[0], _TABLE_ROWS)]
    figs = []
    for bi, blk in enumerate(blocks):
        for ri, rr in enumerate(rparts):
            n = len(blocks) * len(rparts)
            part = f" ({len(figs) + 1}/{n})" if n > 1 else ""
            fig = _page(f"Experiments: the inputs of each experiment{part}")
            head = ["experiment"] + [h for h, _ in blk]
            rows = [[str(j + 1)] + [f"{Q[j, k]:g}" for _, k in blk] for j in rr]
            h = 0.032 * (len(rows) + 1)
            ax = fig.add_axes([0.04, 0.88 - h, 0.92, h])
            draw_table(ax, head, rows, fontsize=8.5, col_widths=[0.1] + [0.9 / max(len(blk), 1)] * len(blk))
            grids = "; ".join(f"{c.name}: {'piecewise constant' if c.kind == 'constant' else 'piecewise linear'} "
                              f"on the grid {', '.join(f'{g:g}' for g in c.grid)}{_unit(model.time_unit)}"
                              for c in model.controls)
            _text(fig, 0.04, 0.84 - h, f"Experiment inputs (model units), numbered from 1 as in every page and file. "
                  f"Constants hold for the whole experiment; controls: {grids}, the last value held to the horizon. "
                  "The trajectory pages draw u(t) beside the outputs.", size=9)
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
              "colour per experiment (filled circles: series 1; open, other markers: later series, drawn side by "
              "side). Dashed: +-2. A trend over time shared by the experiments shows dynamics the model misses (a rate law, a delay, a missing state); residuals "
              "growing with time point at an error that accumulates. Red triangles: the chosen sampling times.")
        figs.append(fig)
    return figs


def _residual_output_pages(results):
    """Per model: the residuals of every instrument against every output of the model at the estimate."""
    figs = []
    s = results.study
    for v, traj in results.trajectories.items():
        model, data = s.models[v], s.data[v]
        if traj.fitted is None or traj.residuals is None:
            continue
        n = min(model.n_S, _COLS)
        fig = _page(f"Residuals of model {v} against its outputs (fit on all study data)")
        axes = fig.subplots(n, n, squeeze=False)
        for k in range(n):
            for m in range(n):
                residual_output_plot(traj, data, model, k, m, ax=axes[k, m])
                if m:
                    axes[k, m].set_ylabel("")
                if k < n - 1:
                    axes[k, m].set_xlabel("")
        handles, labels = axes[0, 0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 8), fontsize=8, frameon=False,
                   bbox_to_anchor=(0.5, 0.075))
        fig.subplots_adjust(left=0.07, right=0.98, top=0.91, bottom=0.2, wspace=0.25, hspace=0.35)
        _text(fig, 0.04, 0.06, "Standardized residuals (z - h)/sigma of each instrument (rows) against each output "
              "of the model at the estimate at the same reading (columns), one colour per experiment (filled: series "
              "1, open: later series). Dashed: +-2. A trend or a step against an output shows an effect the model "
              "misses that depends on that state (e.g. a friction that depends on the sign of a speed: a step of the "
              "residuals where the speed changes sign).")
        figs.append(fig)
    return figs


def _design_page(results):
    from .tables import criteria_units, draw_table
    fig = _page("Sampling-time design")
    plan = results.plan
    if isinstance(plan, (ExperimentPlan, ApproximateTimePlan)):      # the next experiments, approximate times
        import matplotlib.pyplot as plt
        plt.close(fig)
        model = results.study.models[plan.variant]
        if isinstance(plan, ApproximateTimePlan):
            from .design_pages import approximate_pages
            return approximate_pages(plan, f"time{_unit(model.time_unit)}", "sampling-time")
        from .control_design_pages import input_design_pages
        return input_design_pages(plan, model)
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
    out = []
    controlled = any(m.controls for m in results.study.models.values()) and results.study.inputs is not None
    for name, make in pages:
        if name in drop:
            continue
        if name == "loops" and controlled:              # the full input table once, before the trajectories
            out.append(("experiments", partial(_input_table_pages, results)))
        out.append(swap.get(name, (name, make)))
        if name == "residuals":
            out.append(("residuals_outputs", partial(_residual_output_pages, results)))
    return out
