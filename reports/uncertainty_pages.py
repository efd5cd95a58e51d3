"""The pages "Uncertainty of ...": what the study computed of a fit whose linearisation may not be trusted.

For one model (``results.uncertainty[variant]``, an :class:`identification.studies.records.ModelUncertainty`
the study computed, :mod:`mudoe.uncertainty_runs`): the profile-likelihood intervals next to the
Wald ones with the sentence that says which to believe, the profile-t curves, and the
likelihood-ratio region of every parameter pair next to its ellipse.  Draws only.
"""
from __future__ import annotations

import textwrap

from .page_layout import ROWS_PER_PAGE
from .page_layout import chunks as _chunks, draw_text as _text, new_page as _page, part_label as _part

__all__ = ["uncertainty_pages", "UNC_COLS", "UNC_ROWS", "PROFILE_CAPTION"]


#: panels a row / rows a page of the profile and likelihood-ratio region pages
UNC_COLS, UNC_ROWS = 3, 2
PROFILE_CAPTION = ("Profile-t curves tau(theta) = sign(theta - theta_hat) sqrt(D(theta)) with the other parameters "
                   "re-optimised (solid) and the straight line (theta - theta_hat)/se of the linearised picture "
                   "(dashed). Dotted horizontal lines: +-sqrt(c) of the {pct} level; the profile interval ends where "
                   "the solid curve crosses them, the Wald interval where the dashed line does. A curve that bends "
                   "away from the line, or never reaches the level on one side (unbounded), is the nonlinearity the "
                   "ellipse hides.")


def uncertainty_pages(results, variant):
    """Profile-likelihood vs Wald intervals, the sloppiest direction, the profile-t curves and the
    likelihood-ratio region of every parameter pair next to its ellipse, for one model (as the study
    computed them: ``results.uncertainty[variant]``)."""
    mu = results.uncertainty[variant]
    figs, y, one_page = _interval_pages(mu)
    return figs + _profile_pages(mu, figs[-1], y, one_page) + _region_pages(mu)


def _interval_pages(mu):
    """The interval table pages of one model's uncertainty and their text: (pages, height left on the
    last page, whether the table took one page)."""
    from .tables import draw_table
    e, variant = mu.estimate, mu.variant
    title = f"Uncertainty of {variant}: profile likelihood vs linearisation"
    head, rows, flags = mu.interval_rows()
    figs = []
    parts = _chunks(len(rows), ROWS_PER_PAGE)
    for n, part in enumerate(parts):
        fig = _page(title + _part(n, len(parts)))
        y = 0.9
        y -= 0.024 * _text(fig, 0.04, y, mu.warning(), width=125, size=10.5, color="#b22222" if
                           mu.trust != "trustworthy" else "black", weight="bold") + 0.02
        chunk = [rows[k] for k in part]
        h = min(0.032 * (len(chunk) + 1), 0.6)
        ax = fig.add_axes([0.04, y - h, 0.92, h])
        draw_table(ax, head, chunk, flags=[flags[k] for k in part], fontsize=9,
                   col_widths=[0.14, 0.17, 0.19, 0.25, 0.25])
        y -= h + 0.03
        figs.append(fig)
    txt = (f"Wald: p -+ q se with the second-order covariance (q the {'Student t' if e.sigma_estimated else 'normal'}"
           f" quantile), the interval the ellipses are made of. Profile likelihood: the values theta of a "
           "parameter where 2 (min over the other parameters of Phi with the parameter fixed at theta - Phi(p_hat)) "
           f"stays below {'F(1, n - p)' if e.sigma_estimated else 'chi2_1'}({1 - mu.alpha:g}) "
           "(Phi = chi2/2 with the sensor sigmas): it does not assume the model is linear in the parameters. "
           "Last column: how far each profile end lies from the estimate compared with the Wald end "
           "(1x: they agree; red cells: they differ by more than 20 % or a side is unbounded).")
    sl = mu.sloppy_text()
    if sl:
        txt = sl + "\n\n" + txt
    nts = mu.notes()
    if nts:
        txt += "\n\nNotes: " + " ".join(f"[{k}] {t}" for k, t in enumerate(nts, 1))
    y -= 0.021 * _text(figs[-1], 0.04, y, txt, width=170, size=9)
    return figs, y, len(parts) == 1


def _profile_pages(mu, last, y, one_page):
    """The profile-t curves: under the table on its page ``last`` when they fit (``y``: height left), else
    on pages of their own (returned)."""
    from matplotlib.ticker import MaxNLocator
    from .region_figures import profile_figure
    e, variant = mu.estimate, mu.variant
    figs = []
    per = UNC_COLS * UNC_ROWS
    profiles = mu.profile.profiles if mu.profile is not None else ()
    if 0 < len(profiles) <= UNC_COLS and one_page and y > 0.42:      # the profiles fit under the table
        for k, pr in enumerate(profiles):
            ax = last.add_axes([0.06 + k * 0.32, 0.14, 0.25, min(y - 0.22, 0.28)])
            i = list(e.param_names).index(pr.name)
            profile_figure(pr, float(e.stderr[i]), e.param_units[i], ax=ax, title=f"profile of {pr.name}")
            ax.xaxis.set_major_locator(MaxNLocator(4))
            ax.title.set_fontsize(9)
        _text(last, 0.04, 0.065, PROFILE_CAPTION.format(pct=mu.pct), width=175, size=8)
        profiles = ()
    if profiles:
        pparts = _chunks(len(profiles), per)
        for n, part in enumerate(pparts):
            fig = _page(f"Profiles of {variant}: profile-likelihood (solid) vs linearised (dashed)"
                        + _part(n, len(pparts)))
            axes = fig.subplots(UNC_ROWS, UNC_COLS, squeeze=False).ravel()
            for ax, k in zip(axes, part):
                pr = profiles[k]
                i = list(e.param_names).index(pr.name)
                profile_figure(pr, float(e.stderr[i]), e.param_units[i], ax=ax, title=f"{variant}: {pr.name}")
                ax.xaxis.set_major_locator(MaxNLocator(4))
            for ax in axes[len(part):]:
                ax.axis("off")
            fig.subplots_adjust(left=0.07, right=0.98, top=0.88, bottom=0.14, hspace=0.45, wspace=0.3)
            _text(fig, 0.04, 0.07, PROFILE_CAPTION.format(pct=mu.pct), width=175, size=8)
            figs.append(fig)
    return figs


def _region_pages(mu):
    """The likelihood-ratio region of every parameter pair next to its ellipse, at most UNC_ROWS x UNC_COLS
    panels a page."""
    from matplotlib.ticker import MaxNLocator
    from .region_figures import lr_region_figure
    e, variant = mu.estimate, mu.variant
    per = UNC_COLS * UNC_ROWS
    figs = []
    rparts = _chunks(len(mu.regions), per)
    for n, part in enumerate(rparts):
        fig = _page(f"Likelihood-ratio regions of {variant} next to the linearised ellipses" + _part(n, len(rparts)))
        shape = (1, max(len(part), 2)) if len(part) <= UNC_COLS else (UNC_ROWS, UNC_COLS)
        axes = fig.subplots(*shape, squeeze=False).ravel()
        handles = {}
        for ax, k in zip(axes, part):
            pr = mu.regions[k]
            i, j = pr.pair
            names = (e.param_names[i], e.param_names[j])
            if pr.region is None:
                ax.axis("off")
                ax.text(0.0, 0.5, "\n".join(textwrap.wrap(f"{variant}: ({names[0]}, {names[1]}) not computed: "
                                                          f"{pr.error[:300]}", 50)), fontsize=8, va="center")
                continue
            traced = mu.extent if mu.extent is not None else mu.profile
            profs = [q for q in (traced.profiles if traced is not None else ()) if q.name in names]
            lr_region_figure(pr.region, units=(e.param_units[i], e.param_units[j]), profiles=profs, ax=ax,
                             title=f"{variant}: {names[0]} vs {names[1]}")
            ax.title.set_fontsize(9)
            ax.xaxis.set_major_locator(MaxNLocator(4))
            ax.yaxis.set_major_locator(MaxNLocator(5))
            for h, lab in zip(*ax.get_legend_handles_labels()):
                if lab.startswith("profile trace of "):
                    lab = ("profile trace of the x-axis parameter" if lab.endswith(names[0])
                           else "profile trace of the y-axis parameter")
                handles.setdefault(lab, h)
            ax.get_legend().remove()
        for ax in axes[len(part):]:
            ax.axis("off")
        fig.legend(list(handles.values()), list(handles), loc="upper right", ncol=3, fontsize=8, frameon=False,
                   bbox_to_anchor=(0.98, 0.935))
        fig.subplots_adjust(left=0.07, right=0.98, top=0.84 if shape[0] == 1 else 0.85,
                            bottom=0.30 if shape[0] == 1 else 0.14, hspace=0.45, wspace=0.3)
        _text(fig, 0.04, 0.07, f"Joint {mu.pct} regions of each parameter pair (fit on all study data). Solid red: "
              f"the likelihood-ratio region {{D <= {'2 F(2, n - p)' if e.sigma_estimated else 'chi2_2'}}} with every "
              "other parameter re-optimised at each grid point; "
              "dashed blue: the ellipse of the covariance at the same level; green: the profile traces (the other "
              "parameters re-optimised along each profile, followed to the level of the region: the extent of the "
              "region along each axis). Where the red contour and the dashed ellipse differ, the "
              "ellipse (and every Wald-based number of this model) is a poor picture; believe the red contour.",
              width=175, size=8)
        figs.append(fig)
    return figs
