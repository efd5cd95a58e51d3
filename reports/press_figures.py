"""Force-displacement figures of the press campaign and the candidate models M1, M2, M3.

Every function takes ``ax``/``axes=None`` (then it makes its own figure, without pyplot)
and returns the matplotlib figure.  The figures only draw: the fits and the friction samples
they show are computed by the press study (:mod:`mudoe.press`) and passed in.
Displacements are plotted in um, forces in N, like the paper's Figure "Repeated
measurements of the force-displacement curve".
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
from matplotlib.figure import Figure

import identification.studies.records as _records
from models.prototype import TEST_SERIES, read_campaign

from .moved import moved

__all__ = ["plot_campaign", "plot_models", "plot_friction"]

__getattr__ = moved(__name__, _records, ("ModelCurve",))

_SERIES_MARKERS = ("s", "D", "^", "v", "o", "*")
_MODEL_STYLE = {"M1": dict(color="tab:red", ls="-"), "M2": dict(color="tab:orange", ls="--"),
                "M3": dict(color="tab:blue", ls="-.")}


def _axes(ax, nrows=1, ncols=1, size=(5.0, 3.6)):
    if ax is None:
        fig = Figure(figsize=(size[0] * ncols, size[1] * nrows), layout="constrained")
        axs = fig.subplots(nrows, ncols, squeeze=False)
        return fig, axs
    axs = np.atleast_2d(np.asarray(ax, dtype=object))
    if axs.shape != (nrows, ncols):
        axs = axs.reshape(nrows, ncols)
    return axs.flat[0].figure, axs


def plot_campaign(ax=None, sensor: str = "D_y", campaign=None):
    """The six measured series of one sensor: corrected reading (um) over the set force (N)."""
    c = read_campaign() if campaign is None else campaign
    if sensor not in c.sensors:
        raise ValueError(f"sensor: {sensor!r} is not one of {c.sensors}")
    k = c.sensors.index(sensor)
    fig, axs = _axes(ax)
    a = axs[0, 0]
    for i in range(c.n_M):
        a.plot(c.q_set, 1e3 * c.z[i, :, k], marker=_SERIES_MARKERS[i % 6], ms=3, lw=0.7,
               color=str(0.2 + 0.6 * i / max(c.n_M - 1, 1)), label=f"series {i + 1}")
    a.set_xlabel("force $q_P$ in N")
    a.set_ylabel(f"displacement {sensor} in µm")
    a.legend(fontsize=7, loc="upper left")
    return fig


def plot_models(campaign, curves: dict, axes=None,
                sensors: Sequence[str] = ("D_y", "F_x", "B0_y"), series: Sequence[int] | None = None):
    """Measured series and the outputs of M1, M2, M3 at their estimates, one panel per sensor.

    Parameters
    ----------
    campaign : Campaign
    curves : dict {name: identification.studies.records.ModelCurve}
        The fitted outputs to draw (:func:`mudoe.press.model_curves` of the fits, e.g.
        :func:`mudoe.press.fit_candidates` on the held-out series); this function computes nothing.
    axes : array of Axes (len(sensors),), optional
    sensors : sensors to plot
    series : 0-based series shown as data (default the held-out ones)
    """
    c = campaign
    series = TEST_SERIES if series is None else tuple(series)
    fig, axs = _axes(axes, 1, len(sensors))
    for col, sensor in enumerate(sensors):
        a = axs[0, col]
        k = c.sensors.index(sensor)
        for n, i in enumerate(series):
            a.plot(c.q_set, 1e3 * c.z[i, :, k], ls="none", marker=_SERIES_MARKERS[n % 6], ms=3.5, mfc="none",
                   color="0.45", label=f"series {i + 1}")
        for name, cv in curves.items():
            a.plot(c.q_set, 1e3 * cv.outputs[:, cv.sensors.index(sensor)], lw=1.2, label=f"{name} ($\\chi^2_r$ = "
                   f"{cv.reduced_chi2:.2f})", **_MODEL_STYLE.get(name, {}))
        a.set_xlabel("force $q_P$ in N")
        a.set_ylabel(f"{sensor} in µm")
        if col == 0:
            a.legend(fontsize=7, loc="upper left")
    return fig


def plot_friction(samples: dict, curves: dict, ax=None):
    """Friction forces attributed by the inverse model to the training series, with M2 and M3 (N over N).

    Parameters
    ----------
    samples : dict
        :func:`mudoe.press.friction_samples` (keys ``q_set``, ``f``, ``series``).
    curves : dict
        :func:`mudoe.press.friction_curves` at ``samples["q_set"]``: keys ``"M2"`` (Coulomb) and ``"M3"``
        (Preisach network), friction force (N) per set point; this function computes nothing.
    ax : Axes, optional
    """
    s = samples
    fig, axs = _axes(ax)
    a = axs[0, 0]
    for n, i in enumerate(s["series"]):
        a.plot(s["q_set"], s["f"][n], ls="none", marker=_SERIES_MARKERS[n % 6], ms=3, color="0.5",
               label=f"inverse model, series {i + 1}")
    a.plot(s["q_set"], curves["M2"], **_MODEL_STYLE["M2"], label="M2 (Coulomb)")
    a.plot(s["q_set"], curves["M3"], **_MODEL_STYLE["M3"], label="M3 (Preisach network)")
    a.axhline(0, color="0.8", lw=0.5)
    a.set_xlabel("force $q_P$ in N")
    a.set_ylabel("friction force $q_{fric}$ in N")
    a.legend(fontsize=7)
    return fig
