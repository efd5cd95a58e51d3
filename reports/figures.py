"""Figures of a study (matplotlib).  Each function takes ``ax=None`` and returns the figure.

Units on every axis: forces in N, displacements in um (the model computes in mm),
stiffnesses in N/mm, standardized residuals dimensionless.  No function writes files
(:mod:`reports.builder` does).
"""
from __future__ import annotations

import numpy as np
from scipy import stats

__all__ = ["measurement_loops", "confidence_ellipses", "ellipse_points", "residuals_plot", "table_figure",
           "VARIANT_STYLE"]

#: line style per model variant
VARIANT_STYLE = {"M1": dict(color="#1f77b4", ls="-"), "M2": dict(color="#d62728", ls="--"),
                 "M3": dict(color="#2ca02c", ls="-.")}
_UM = 1e3   # mm -> um


def _ax(ax, figsize=(6.0, 4.0)):
    import matplotlib.pyplot as plt
    if ax is None:
        fig, ax = plt.subplots(figsize=figsize)
    return ax


def _force_label(study) -> str:
    """x-axis label from the first input of the study's model (name and unit, N by default)."""
    m = next(iter(study.models.values()))
    name = m.inputs[0]
    unit = (m.input_units[0] if m.input_units else "") or "N"
    pretty = "process force $q_P$" if name == "q_P" else f"input {name}"
    return f"{pretty} ({unit})"


def _style(v, k=0):
    cyc = ["#9467bd", "#8c564b", "#e377c2", "#17becf"]
    return VARIANT_STYLE.get(v, dict(color=cyc[k % len(cyc)], ls=":"))


def measurement_loops(study, estimates: dict, sensor: str, ax=None, all_series: bool = True):
    """Force-displacement loops of one sensor: the measured series and each model's output.

    Parameters
    ----------
    study : mudoe.study.Study
    estimates : dict {variant: identification.Estimate}
        Model outputs at the estimates (``fitted``, mm) are drawn as lines over the set points.
    sensor : str
    ax : matplotlib Axes, optional
    all_series : bool
        Draw the series not used by the study too (light grey).

    Returns
    -------
    matplotlib Figure
    """
    ax = _ax(ax)
    k = study.sensors.index(sensor)
    c = study.campaign
    used = set(range(c.n_M)) if study.cfg.data.series is None else set(study.cfg.data.series)
    for i in range(c.n_M):
        if i not in used and not all_series:
            continue
        ax.plot(c.q_set, _UM * c.z[i, :, k], marker="o", ms=2.5, lw=0.6,
                color="0.35" if i in used else "0.8", zorder=1 if i not in used else 2,
                label=None)
    ax.plot([], [], marker="o", ms=2.5, lw=0.6, color="0.35", label="measured (study series)")
    if all_series and len(used) < c.n_M:
        ax.plot([], [], marker="o", ms=2.5, lw=0.6, color="0.8", label="measured (other series)")
    for n, (v, e) in enumerate(estimates.items()):
        st = _style(v, n)
        ax.plot(c.q_set, _UM * e.fitted[:, k], lw=1.6, label=f"{v} at its estimate", zorder=3, **st)
    ax.set_xlabel(_force_label(study))
    ax.set_ylabel(f"{sensor} displacement (um)")
    ax.set_title(f"Sensor {sensor}", fontsize=10)
    ax.legend(fontsize=7, loc="best")
    ax.grid(alpha=0.3)
    return ax.figure


def ellipse_points(center, C, level: float, n: int = 200) -> np.ndarray:
    """Boundary (n, 2) of {p : (p - c)^T C^{-1} (p - c) <= chi2_2(level)} (2 parameters)."""
    C = np.asarray(C, float)
    r2 = float(stats.chi2.ppf(level, 2))
    w, V = np.linalg.eigh(0.5 * (C + C.T))
    w = np.clip(w, 0.0, None)
    t = np.linspace(0, 2 * np.pi, n)
    circ = np.vstack([np.cos(t), np.sin(t)])
    return (np.asarray(center, float)[:, None] + V @ (np.sqrt(r2 * w)[:, None] * circ)).T


def confidence_ellipses(test, level: float, param_names=("k5", "k7"), units: str = "N/mm", ax=None,
                        statistic: str = "two_sample"):
    """Calibration vs validation estimate of one split: ellipses at ``level`` and both points.

    Draws G(1 - level, p_cal, C_cal) (the paper's region, solid), the validation estimate's
    region (dashed) and the two-sample region p_cal + {C_cal + C_val} (dotted).  The
    validation point is red when the split's hypothesis is rejected at 1 - level.

    Parameters
    ----------
    test : identification.detect.SplitTest
    level : float
        Confidence level of the drawn regions, e.g. 1 - TOL / n_tests.
    """
    ax = _ax(ax, (4.0, 3.5))
    if not test.ok:
        ax.text(0.5, 0.5, f"{test.split}\nfailed at the {test.stage}", ha="center", va="center",
                transform=ax.transAxes, fontsize=8)
        ax.set_xlabel(f"{param_names[0]} ({units})")
        ax.set_ylabel(f"{param_names[1]} ({units})")
        return ax.figure
    pc, pv = test.p_cal[:2], test.p_val[:2]
    Cc, Cv = test.C_cal[:2, :2], test.C_val[:2, :2]
    e1 = ellipse_points(pc, Cc, level)
    e2 = ellipse_points(pv, Cv, level)
    e3 = ellipse_points(pc, Cc + Cv, level)
    ax.plot(e1[:, 0], e1[:, 1], color="#1f77b4", lw=1.2, label="calibration region")
    ax.plot(e2[:, 0], e2[:, 1], color="#ff7f0e", lw=1.0, ls="--", label="validation region")
    ax.plot(e3[:, 0], e3[:, 1], color="0.4", lw=0.8, ls=":", label="two-sample region")
    a = test.alpha(statistic)
    rejected = np.isfinite(a) and a < 1 - level
    ax.plot(*pc, "o", color="#1f77b4", ms=4, label="$p_{cal}$")
    ax.plot(*pv, "s", color="#d62728" if rejected else "#ff7f0e", ms=4, label="$p_{val}$")
    ax.set_xlabel(f"{param_names[0]} ({units})", fontsize=8)
    ax.set_ylabel(f"{param_names[1]} ({units})", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.set_title(f"{test.model}: {test.split}\nalpha_min {100 * a:.3g} %" if np.isfinite(a) else test.split,
                 fontsize=8, color="#d62728" if rejected else "black")
    ax.grid(alpha=0.3)
    return ax.figure


def residuals_plot(study, est, variant: str, ax=None):
    """Standardized residuals (z - h) / sigma of one fit against the force, per sensor (dimensionless).

    Residuals of every study series are drawn; the band +-2 marks two standard deviations.
    """
    ax = _ax(ax)
    q = study.campaign.q_set
    markers = ["o", "s", "^", "v", "D", "x"]
    for k, s in enumerate(est.sensors):
        r = est.residuals[:, :, k] / est.sigma[k]
        for i in range(r.shape[0]):
            ax.plot(q, r[i], markers[k % len(markers)], ms=3, alpha=0.7, color=f"C{k}",
                    label=f"{s} (sigma {1e3 * est.sigma[k]:.3g} um)" if i == 0 else None)
    ax.axhline(0, color="0.3", lw=0.6)
    for y in (-2, 2):
        ax.axhline(y, color="0.5", lw=0.6, ls="--")
    ax.set_xlabel(_force_label(study))
    ax.set_ylabel("standardized residual (z - h)/sigma (-)")
    ax.set_title(f"{variant} (reduced chi2 {est.reduced_chi2:.3g})", fontsize=10)
    ax.legend(fontsize=7, loc="best")
    ax.grid(alpha=0.3)
    return ax.figure


def table_figure(head, rows, flags=None, ax=None, title=None, col_widths=None, fontsize=8, chosen=None):
    """A table (from :mod:`reports.tables` rows) drawn as a figure."""
    from .tables import draw_table
    ax = _ax(ax, (8.27, 0.35 * (len(rows) + 2) + 0.6))
    return draw_table(ax, head, rows, flags=flags, col_widths=col_widths, fontsize=fontsize, title=title,
                      chosen=chosen)
