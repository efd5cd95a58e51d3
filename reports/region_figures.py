"""Figures of likelihood-ratio regions and parameter profiles (matplotlib, issue 12).

Each function takes ``ax=None`` and returns the figure; none writes files.  They show where
the linearised picture (the ellipse of the covariance, the straight Wald profile) departs
from the likelihood-ratio one, so that an engineer sees when the ellipse is a poor picture.
"""
from __future__ import annotations

import numpy as np

from identification.inference.regions import Ellipsoid

__all__ = ["lr_region_figure", "profile_figure"]


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
