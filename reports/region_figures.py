"""Figures of likelihood-ratio regions and parameter profiles (matplotlib, issue 12).

Each function takes ``ax=None`` and returns the figure; none writes files.  They show where
the linearised picture (the ellipse of the covariance, the straight Wald profile) departs
from the likelihood-ratio one, so that an engineer sees when the ellipse is a poor picture.
"""
from __future__ import annotations

import numpy as np

from identification.inference.regions import Ellipsoid

__all__ = ["lr_region_figure", "profile_figure", "split_pair_grid", "SPLIT_COLOURS"]


def _ax(ax, figsize=(5.5, 4.5)):
    import matplotlib.pyplot as plt
    if ax is None:
        _, ax = plt.subplots(figsize=figsize)
    return ax


def _label(name: str, unit: str) -> str:
    return f"{name} ({unit})" if unit else name


def lr_region_figure(region, units=("", ""), profiles=(), ax=None, title: str | None = None):
    """The likelihood-ratio region {D(a, b) <= c} of a pair next to the linearised ellipse.

    Parameters
    ----------
    region : identification.inference.profile.LikelihoodRegion
        D on the grid (the other parameters re-optimised), the threshold c and the covariance block.
    units : (str, str)   units of the two parameters (axis labels)
    profiles : sequence of identification.inference.profile.ParameterProfile, optional
        Profiles of the two parameters (``conf_int(method="profile").profiles``): their traces
        (the other parameter re-optimised along each profile) are drawn; they follow the valley of
        the objective even where the region is thinner than the grid.
    ax : matplotlib Axes, optional

    The solid contour is D = c; the dashed curve the ellipse d^T C^-1 d = c of the same
    threshold (they coincide for a model linear in the parameters); the dot the estimate.
    Grid points that could not be solved are left blank; ``region.notes`` (unsolved points, a region
    reaching the edge of the grid, a region too thin to draw) are written in the axes.
    """
    ax = _ax(ax)
    X, Y, D = region.X, region.Y, region.statistic
    pct = f"{100 * (1 - region.alpha):g} %"
    notes = list(region.notes)
    inside = int(np.sum(D[np.isfinite(D)] <= region.threshold))
    if inside >= 4 and np.nanmax(D) >= region.threshold:
        ax.contour(X, Y, D, levels=[region.threshold], colors="#d62728", linewidths=1.8, zorder=4)
        ax.plot([], [], color="#d62728", lw=1.8, label=f"{pct} likelihood-ratio region")
    else:
        notes.append(f"only {inside} grid point(s) inside the likelihood-ratio region: it is thinner than the "
                     "grid and is not drawn (see the profile traces)")
    cols = list(region.indices)
    for pr, style in zip(profiles, ("-", "-.")):
        if pr.name not in region.names:
            raise ValueError(f"profiles: {pr.name!r} is not one of the region's parameters {tuple(region.names)}")
        ax.plot(pr.params[:, cols[0]], pr.params[:, cols[1]], style, color="#2ca02c", lw=0.8, marker=".", ms=2.5,
                label=f"profile trace of {pr.name}", zorder=2)
    ell = Ellipsoid(np.asarray(region.estimate), np.asarray(region.cov), region.alpha, region.threshold,
                    tuple(region.names))
    b = ell.boundary(0, 1)
    ax.plot(b[:, 0], b[:, 1], color="#1f77b4", ls="--", lw=1.4, label=f"{pct} linearised ellipse")
    ax.plot(*region.estimate, "o", color="k", ms=4, label="estimate")
    ax.set_xlim(float(np.min(X)), float(np.max(X)))          # the grid's extent (traces may run further)
    ax.set_ylim(float(np.min(Y)), float(np.max(Y)))
    ax.set_xlabel(_label(region.names[0], units[0]))
    ax.set_ylabel(_label(region.names[1], units[1]))
    if title:
        ax.set_title(title)
    if notes:
        ax.text(0.02, 0.02, "\n".join(f"[{k}] {n[:90]}" for k, n in enumerate(notes, 1)), transform=ax.transAxes,
                fontsize=6.5, va="bottom", bbox=dict(facecolor="white", alpha=0.8, lw=0))
    ax.legend(fontsize=8, loc="best")
    ax.grid(alpha=0.3)
    return ax.figure


def profile_figure(profile, stderr: float, unit: str = "", ax=None, title: str | None = None):
    """The profile-t curve tau(theta) = sign(theta - theta_hat) sqrt(D) of one parameter.

    Parameters
    ----------
    profile : identification.inference.profile.ParameterProfile
    stderr : float          the Wald standard error of the parameter (for the straight line
                            (theta - theta_hat) / se of the linearised picture)
    unit : str              the parameter's unit (axis label)

    The horizontal lines are +-sqrt(c); where the curve crosses them are the profile interval
    ends, where the straight line crosses them the Wald ends.
    """
    ax = _ax(ax)
    th, tau = profile.values, profile.tau
    i0 = int(np.argmin(np.abs(tau)))
    theta_hat = th[i0]
    ax.plot(th, tau, "-o", color="#d62728", ms=3, lw=1.5, label="profile")
    ax.plot(th, (th - theta_hat) / stderr, "--", color="#1f77b4", lw=1.2, label="linearised (Wald)")
    r = np.sqrt(profile.threshold)
    for s in (-r, r):
        ax.axhline(s, color="0.4", lw=0.8, ls=":")
    for end in (profile.lower, profile.upper):
        if np.isfinite(end):
            ax.axvline(end, color="#d62728", lw=0.8, ls=":")
    ax.set_xlabel(_label(profile.name, unit))
    ax.set_ylabel(r"profile $\tau$")
    if title:
        ax.set_title(title)
    ax.legend(fontsize=8, loc="best")
    ax.grid(alpha=0.3)
    return ax.figure


#: colours of the splits on one grid of pair panels (at most this many splits a page)
SPLIT_COLOURS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#9467bd", "#8c564b")


def split_pair_grid(fig, tests, level: float, param_names, units=None, statistic: str = "two_sample",
                    second_statistic: str | None = None, truth=None, rect=(0.08, 0.1, 0.97, 0.88), indices=None):
    """Every parameter pair of one model in one lower-triangular grid of panels, the splits overlaid.

    Panel (a, b), b < a, holds parameter b across and a up; for every split (one colour each) the region
    G(1 - level, p_cal, C_cal) (solid), the validation region (dashed) and the two-sample region around
    p_cal with C_cal + C_val (dotted), projected on the pair, with p_cal (dot) and p_val (square, red edge
    when the split's hypothesis is rejected at 1 - level by ``statistic``); the true parameters, when
    given (``truth``: one value per parameter), as a black star.  Tick labels only on the outer panels,
    at most three a side; the legend (upper right) names each split with its alpha_min.

    Parameters
    ----------
    fig : matplotlib Figure        drawn into ``rect`` = (left, bottom, right, top) in figure fractions
    tests : sequence of identification.studies.detect.SplitTest   the splits of one model
    level : float                  confidence level of the regions (1 - TOL / n_tests)
    param_names, units : sequences of str   every parameter of the model
    truth : sequence of float or None
    indices : sequence of int, optional   the parameters drawn (default all; a model of many parameters
                                   draws its pairs on several grids)

    Returns
    -------
    list of matplotlib Axes        the panels, row by row
    """
    from matplotlib.lines import Line2D
    from matplotlib.ticker import MaxNLocator

    from .figures import ellipse_points
    every = tuple(param_names)
    idx = list(range(len(every)) if indices is None else indices)
    names = tuple(every[k] for k in idx)
    n = len(names)
    if n < 2:
        raise ValueError(f"param_names: a grid of pairs needs at least two parameters, got {n}")
    if len(tests) > len(SPLIT_COLOURS):
        raise ValueError(f"tests: at most {len(SPLIT_COLOURS)} splits on one grid, got {len(tests)}")
    units = tuple(u or "" for u in (units if units is not None else ("",) * len(every)))
    units = tuple(units[k] for k in idx)
    left, bottom, right, top = rect
    gs = fig.add_gridspec(n - 1, n - 1, left=left, bottom=bottom, right=right, top=top, wspace=0.12, hspace=0.12)
    short = {"likelihood_ratio": "LR", "two_sample": "2-sample", "paper": "paper"}
    axes, cols, rows = [], {}, {}
    for a in range(1, n):
        for b in range(a):
            ax = fig.add_subplot(gs[a - 1, b], sharex=cols.get(b), sharey=rows.get(a))
            cols.setdefault(b, ax)
            rows.setdefault(a, ax)
            axes.append(ax)
            for s, t in enumerate(tests):
                if not t.ok:
                    continue
                c = SPLIT_COLOURS[s]
                pair = [idx[b], idx[a]]
                ix = np.ix_(pair, pair)
                pc, pv = t.p_cal[pair], t.p_val[pair]
                for pts, style in ((ellipse_points(pc, t.C_cal[ix], level), dict(ls="-", lw=1.0)),
                                   (ellipse_points(pv, t.C_val[ix], level), dict(ls="--", lw=0.8)),
                                   (ellipse_points(pc, t.C_cal[ix] + t.C_val[ix], level),
                                    dict(ls=":", lw=0.7, alpha=0.8))):
                    ax.plot(pts[:, 0], pts[:, 1], color=c, **style)
                al = t.alpha(statistic)
                rejected = np.isfinite(al) and al < 1 - level
                ax.plot(*pc, "o", color=c, ms=3)
                ax.plot(*pv, "s", color=c, ms=3.5, mec="#d62728" if rejected else c, mew=1.5 if rejected else 0.5)
            if truth is not None:
                ax.plot(truth[idx[b]], truth[idx[a]], "*", color="k", ms=7, zorder=5)
            ax.xaxis.set_major_locator(MaxNLocator(3))
            ax.yaxis.set_major_locator(MaxNLocator(3))
            ax.tick_params(labelsize=6.5, length=2)
            ax.grid(alpha=0.3)
            if a == n - 1:
                ax.set_xlabel(f"{names[b]}{f' ({units[b]})' if units[b] else ''}", fontsize=7.5)
                for lab in ax.get_xticklabels():
                    lab.set_rotation(30)
                    lab.set_ha("right")
            else:
                ax.tick_params(labelbottom=False)
            if b == 0:
                ax.set_ylabel(f"{names[a]}{f' ({units[a]})' if units[a] else ''}", fontsize=7.5)
            else:
                ax.tick_params(labelleft=False)
            ax.xaxis.get_offset_text().set_fontsize(6)
            ax.yaxis.get_offset_text().set_fontsize(6)
    handles = []
    for s, t in enumerate(tests):
        al = t.alpha(statistic) if t.ok else float("nan")
        rejected = t.ok and np.isfinite(al) and al < 1 - level
        text = (f"{t.split}: {short.get(statistic, statistic)} {_pct(al)}"
                + (f", {short.get(second_statistic, second_statistic)} {_pct(t.alpha(second_statistic))}"
                   if second_statistic and t.ok else "")
                + (" REJECTED" if rejected else "") + ("" if t.ok else f" (failed at the {t.stage})"))
        handles.append(Line2D([], [], color=SPLIT_COLOURS[s], lw=2, label=text))
    handles += [Line2D([], [], color="0.3", lw=1.0, label="calibration region G (paper)"),
                Line2D([], [], color="0.3", lw=0.8, ls="--", label="validation region"),
                Line2D([], [], color="0.3", lw=0.7, ls=":", label="two-sample region (C_cal + C_val)"),
                Line2D([], [], color="0.3", marker="o", ls="none", ms=3, label="$p_{cal}$"),
                Line2D([], [], color="0.3", marker="s", ls="none", ms=3.5, label="$p_{val}$ (red edge: rejected)")]
    if truth is not None:
        handles.append(Line2D([], [], color="k", marker="*", ls="none", ms=7, label="truth (simulated data)"))
    fig.legend(handles=handles, loc="upper right", bbox_to_anchor=(right, top), fontsize=7.5, frameon=False)
    return axes


def _pct(a) -> str:
    return f"{100 * a:.3g} %" if a is not None and np.isfinite(a) else "failed"
