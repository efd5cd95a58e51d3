"""Figures of a study (matplotlib).  Each function takes ``ax=None`` and returns the figure.

Units on every axis come from the study (:mod:`reports.view`): the model's input, sensor
and parameter units (lengths in mm are shown in um); standardized residuals are
dimensionless.  No function writes files (:mod:`reports.builder` does).  The figures draw what the
study put into its :class:`oed.study_record.StudySetup` (``study``) and the records it computed
(:class:`identification.studies.records.PredictionBands`, whose old name here still works, deprecated).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from scipy import stats

import identification.studies.records as _records

from .moved import moved
from .view import input_label, output_display, output_label, phase_labels, sensor_unit, unit_suffix

__all__ = ["measurement_loops", "confidence_ellipses", "ellipse_points", "residuals_plot", "table_figure",
           "VARIANT_STYLE", "prediction_band_plot", "residuals_vs_order", "normal_probability_plot"]

__getattr__ = moved(__name__, _records, ("PredictionBands",))

if TYPE_CHECKING:
    from identification.studies.records import PredictionBands

#: line style per model variant
VARIANT_STYLE = {"M1": dict(color="#1f77b4", ls="-"), "M2": dict(color="#d62728", ls="--"),
                 "M3": dict(color="#2ca02c", ls="-.")}


def _ax(ax, figsize=(6.0, 4.0)):
    import matplotlib.pyplot as plt
    if ax is None:
        fig, ax = plt.subplots(figsize=figsize)
    return ax


def _force_label(study) -> str:
    return input_label(study)


def _style(v, k=0):
    cyc = ["#9467bd", "#8c564b", "#e377c2", "#17becf"]
    return VARIANT_STYLE.get(v, dict(color=cyc[k % len(cyc)], ls=":"))


def measurement_loops(study, estimates: dict, sensor: str, ax=None, all_series: bool = True):
    """Measured series of one sensor over the first input, and each model's output at its estimate.

    Parameters
    ----------
    study : oed.study_record.StudySetup
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
    f = output_display(study).scale
    used = set(range(c.n_M)) if study.config.series is None else set(study.config.series)
    for i in range(c.n_M):
        if i not in used and not all_series:
            continue
        ax.plot(c.q_set, f * c.z[i, :, k], marker="o", ms=2.5, lw=0.6,
                color="0.35" if i in used else "0.8", zorder=1 if i not in used else 2,
                label=None)
    ax.plot([], [], marker="o", ms=2.5, lw=0.6, color="0.35", label="measured (study series)")
    if all_series and len(used) < c.n_M:
        ax.plot([], [], marker="o", ms=2.5, lw=0.6, color="0.8", label="measured (other series)")
    for n, (v, e) in enumerate(estimates.items()):
        st = _style(v, n)
        ax.plot(c.q_set, f * e.fitted[:, k], lw=1.6, label=f"{v} at its estimate", zorder=3, **st)
    ax.set_xlabel(_force_label(study))
    ax.set_ylabel(output_label(study, sensor))
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


def confidence_ellipses(test, level: float, param_names=None, units=None, ax=None,
                        statistic: str = "two_sample", pair=(0, 1), second_statistic: str | None = None):
    """Calibration vs validation estimate of one split in the plane of two parameters.

    Draws G(1 - level, p_cal, C_cal) (the paper's region, solid), the validation estimate's
    region (dashed) and the two-sample region p_cal + {C_cal + C_val} (dotted), projected
    on the parameters ``pair``.  The validation point is red when the split's hypothesis is
    rejected at 1 - level by ``statistic``; the title gives that statistic's alpha_min (and
    ``second_statistic``'s, when given).

    Parameters
    ----------
    test : identification.studies.detect.SplitTest
    level : float
        Confidence level of the drawn regions, e.g. 1 - TOL / n_tests.
    param_names : sequence of str, optional
        Names of all parameters (default p1, p2, ...).
    units : sequence of str or str, optional
        Unit of every parameter (or one for all); empty units are omitted.
    pair : (int, int)
        Indices of the two parameters drawn.
    """
    ax = _ax(ax, (4.0, 3.5))
    i, j = pair
    n = len(test.p_cal) if test.p_cal is not None else max(i, j) + 1
    names = tuple(param_names) if param_names is not None else tuple(f"p{k + 1}" for k in range(n))
    units = (units,) * len(names) if isinstance(units, str) or units is None else tuple(units)
    units = tuple(u or "" for u in units)
    ax.set_xlabel(f"{names[i]}{unit_suffix(units[i])}", fontsize=8)
    ax.set_ylabel(f"{names[j]}{unit_suffix(units[j])}", fontsize=8)
    if not test.ok:
        ax.text(0.5, 0.5, f"{test.split}\nfailed at the {test.stage}", ha="center", va="center",
                transform=ax.transAxes, fontsize=8)
        return ax.figure
    ix = np.ix_([i, j], [i, j])
    pc, pv = test.p_cal[[i, j]], test.p_val[[i, j]]
    Cc, Cv = test.C_cal[ix], test.C_val[ix]
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
    ax.tick_params(labelsize=7)
    short = {"likelihood_ratio": "LR", "two_sample": "2-sample", "paper": "paper"}
    title = f"{test.model}: {test.split}\n{short.get(statistic, statistic)} {_pct(a)}"
    if second_statistic:
        title += f", {short.get(second_statistic, second_statistic)} {_pct(test.alpha(second_statistic))}"
    ax.set_title(title, fontsize=7.5, color="#d62728" if rejected else "black")
    ax.grid(alpha=0.3)
    return ax.figure


def _pct(a) -> str:
    return f"{100 * a:.3g} %" if a is not None and np.isfinite(a) else "failed"


def _standardized(est):
    """(n_M, n_q, n_S) standardized residuals (z - h) / sigma of the used sensors (others NaN)."""
    r = np.asarray(est.residuals, float) / np.asarray(est.sigma, float)
    r = r.copy()
    r[..., np.asarray(est.weights) <= 0] = np.nan
    return r


def _phase_styles(phases):
    """{label: (marker, fill)} for phase labels (None: one style)."""
    if phases is None:
        return {None: ("o", "full")}
    labels = list(dict.fromkeys(phases))
    marks = ["^", "v", "s", "D", "o", "x"]
    return {p: (marks[n % len(marks)], "full" if n % 2 == 0 else "none") for n, p in enumerate(labels)}


def residuals_plot(study, est, variant: str, ax=None):
    """Standardized residuals (z - h) / sigma of one fit against the first input (dimensionless).

    Colour: sensor; marker: phase (loading/unloading for the press, a user-declared phase,
    or one marker).  The band +-2 marks two standard deviations.
    """
    ax = _ax(ax)
    q = study.campaign.q_set
    r = _standardized(est)
    phases = phase_labels(study)
    styles = _phase_styles(phases)
    ph = np.array(phases if phases is not None else [None] * len(q), dtype=object)
    f = output_display(study).scale
    for k, s in enumerate(est.sensors):
        if est.weights[k] <= 0:
            continue
        u = sensor_unit(study, s)
        ax.plot([], [], "o", color=f"C{k}", ms=3, label=f"{s} (sigma {f * est.sigma[k]:.3g}{(' ' + u) if u else ''})")
        for lab, (mk, fill) in styles.items():
            sel = ph == lab if lab is not None else np.ones(len(q), bool)
            for i in range(r.shape[0]):
                ax.plot(q[sel], r[i][sel, k], mk, ms=3, alpha=0.7, color=f"C{k}", fillstyle=fill)
    if phases is not None:
        for lab, (mk, fill) in styles.items():
            ax.plot([], [], mk, color="0.3", ms=3, fillstyle=fill, label=str(lab))
    ax.axhline(0, color="0.3", lw=0.6)
    for y in (-2, 2):
        ax.axhline(y, color="0.5", lw=0.6, ls="--")
    ax.set_xlabel(_force_label(study))
    ax.set_ylabel("standardized residual (z - h)/sigma (-)")
    ax.set_title(f"{variant}: against the input (reduced chi2 {est.reduced_chi2:.3g})", fontsize=9)
    ax.legend(fontsize=6.5, loc="best")
    ax.grid(alpha=0.3)
    return ax.figure


def residuals_vs_order(study, est, variant: str, ax=None):
    """Standardized residuals in measurement order (series after series, set points in order).

    Vertical lines separate the series; markers distinguish the phases as in
    :func:`residuals_plot`.  A trend or a drift shows as a pattern across the order.
    """
    ax = _ax(ax)
    r = _standardized(est)
    n_M, n_q, _ = r.shape
    phases = phase_labels(study)
    styles = _phase_styles(phases)
    ph = np.array(phases if phases is not None else [None] * n_q, dtype=object)
    order = np.arange(n_M * n_q).reshape(n_M, n_q)
    for k, s in enumerate(est.sensors):
        if est.weights[k] <= 0:
            continue
        for lab, (mk, fill) in styles.items():
            sel = ph == lab if lab is not None else np.ones(n_q, bool)
            ax.plot(order[:, sel].ravel(), r[:, sel, k].ravel(), mk, ms=2.5, color=f"C{k}", fillstyle=fill,
                    alpha=0.8, label=s if lab == next(iter(styles)) else None)
    for i in range(1, n_M):
        ax.axvline(i * n_q - 0.5, color="0.6", lw=0.6)
    for y in (-2, 2):
        ax.axhline(y, color="0.5", lw=0.6, ls="--")
    ax.axhline(0, color="0.3", lw=0.6)
    ax.set_xlabel("measurement order (series by series; lines separate the series)")
    ax.set_ylabel("standardized residual (-)")
    ax.set_title(f"{variant}: in measurement order", fontsize=9)
    ax.legend(fontsize=6.5, loc="best")
    ax.grid(alpha=0.3)
    return ax.figure


def normal_probability_plot(est, variant: str, ax=None):
    """Normal probability plot of all standardized residuals of the used sensors (Filliben positions).

    Points on the line: Gaussian errors with the assumed sigma (slope 1 when sigma is right).
    """
    ax = _ax(ax)
    r = _standardized(est).ravel()
    r = r[np.isfinite(r)]
    (osm, osr), (slope, icpt, rr) = stats.probplot(r, dist="norm")
    ax.plot(osm, osr, "o", ms=2.5, color="0.3", label="standardized residuals")
    lim = np.array([osm.min(), osm.max()])
    ax.plot(lim, lim, color="#d62728", lw=1, label="N(0, 1): slope 1")
    ax.plot(lim, icpt + slope * lim, color="#1f77b4", lw=0.8, ls="--", label=f"fitted line, slope {slope:.2g}")
    ax.set_xlabel("theoretical quantile of N(0, 1) (-)")
    ax.set_ylabel("ordered standardized residual (-)")
    ax.set_title(f"{variant}: normal probability plot (r = {rr:.3f})", fontsize=9)
    ax.legend(fontsize=6.5, loc="upper left")
    ax.grid(alpha=0.3)
    return ax.figure


def prediction_band_plot(study, est, variant: str, sensor: str, bands: PredictionBands, ax=None):
    """One sensor: measured values, the fitted output, its mean band and its new-observation band.

    Shaded: band of the mean response; dashed: band of a new observation (both at ``bands.level``,
    delta method with exact sensitivities, as the study computed them: :func:`mudoe.band_runs.prediction_bands`).
    Set points are joined in measurement order, so loading and unloading branches (or other phases) stay apart.
    """
    ax = _ax(ax)
    k = list(est.sensors).index(sensor)
    b, level = bands, bands.level
    f = output_display(study).scale
    c = study.campaign
    q = c.q_set
    used = range(c.n_M) if study.config.series is None else study.config.series
    for n, i in enumerate(used):
        ax.plot(q, f * c.z[i, :, k], "o", ms=2.5, color="0.45", label="measured (study series)" if n == 0 else None)
    st = _style(variant)
    h, m, w = f * b.h[:, k], f * b.half_mean[:, k], f * b.half_new[:, k]
    ax.fill_between(q, h - m, h + m, color=st["color"], alpha=0.3, lw=0, label=f"{100 * level:g} % band, mean")
    ax.plot(q, h - w, color=st["color"], lw=0.7, ls="--", label=f"{100 * level:g} % band, new observation")
    ax.plot(q, h + w, color=st["color"], lw=0.7, ls="--")
    ax.plot(q, h, color=st["color"], lw=1.2, label=f"{variant} at its estimate")
    ax.set_xlabel(_force_label(study), fontsize=8)
    ax.set_ylabel(output_label(study, sensor), fontsize=8)
    ax.tick_params(labelsize=7)
    ax.set_title(f"{variant}, sensor {sensor}", fontsize=9)
    ax.legend(fontsize=6, loc="best")
    ax.grid(alpha=0.3)
    return ax.figure


def table_figure(head, rows, flags=None, ax=None, title=None, col_widths=None, fontsize=8, chosen=None):
    """A table (from :mod:`reports.tables` rows) drawn as a figure."""
    from .tables import draw_table
    ax = _ax(ax, (8.27, 0.35 * (len(rows) + 2) + 0.6))
    return draw_table(ax, head, rows, flags=flags, col_widths=col_widths, fontsize=fontsize, title=title,
                      chosen=chosen)
