"""What the report shows of a fit whose linearisation cannot be trusted, computed by the study (issue 12).

For one model's fit on all study data (:func:`model_uncertainty`): the (1 - alpha) Wald and
profile-likelihood intervals, the profiles at the pair regions' level (the extent of every
region) and the likelihood-ratio region of every parameter pair (the other parameters
re-optimised), as an :class:`identification.studies.records.ModelUncertainty`.  :func:`run_uncertainty`
computes it for the fits the ``[report] uncertainty`` option selects (:func:`uncertainty_variants`)
into ``StudyResults.uncertainty``; :func:`summary_intervals` gives the profile intervals
``Estimate.summary(intervals=...)`` shows for a fit whose curvature is not trustworthy.
"""
from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from identification.errors import IdentificationError
from identification.inference.profile import lr_region
from identification.studies.records import UNTRUSTED, ModelUncertainty, PairRegion
from reports.uncertainty import UNCERTAINTY_CHOICES

from .fit_assessment import linearisation_trust

__all__ = ["uncertainty_variants", "run_uncertainty", "model_uncertainty", "region_limits", "region_alpha",
           "summary_intervals"]


def uncertainty_variants(estimates, which: str = "untrusted") -> list:
    """The fitted variants of ``estimates`` ({variant: Estimate}) that get uncertainty pages (``which`` one of
    :data:`reports.uncertainty.UNCERTAINTY_CHOICES`): "untrusted" those whose linearisation is NOT
    trustworthy, "all" every fit with model and data, "none" none."""
    if which not in UNCERTAINTY_CHOICES:
        raise ValueError(f"uncertainty: expected one of {', '.join(repr(c) for c in UNCERTAINTY_CHOICES)}, "
                         f"got {which!r}")
    if which == "none":
        return []
    out = []
    for v, e in estimates.items():
        if e.n_p < 1 or e.model is None or e.data is None:
            continue
        if which == "all" or linearisation_trust(e) == UNTRUSTED:
            out.append(v)
    return out


def run_uncertainty(study, results, which: str | None = None, progress=None):
    """``results`` with ``uncertainty``: {variant: ModelUncertainty} of the fits ``which`` selects
    (:func:`uncertainty_variants`; default the config's ``[report] uncertainty``); ``progress`` shows a
    bar per model."""
    which = study.cfg.report.uncertainty if which is None else which
    out = dict(results.uncertainty)
    for v in uncertainty_variants(results.estimates, which):
        out[v] = model_uncertainty(results.estimates[v], v, progress=progress)
    return dataclasses.replace(results, uncertainty=out)


def summary_intervals(est, alpha: float = 0.05):
    """The (1 - alpha) profile-likelihood intervals ``est.summary(intervals=...)`` shows, computed only when
    the Bates-Watts curvature says the linearisation is not trustworthy (else, or when the curvature or
    the profile cannot be computed, None: the summary then says so)."""
    if est.model is None or est.data is None or est.dof < 1:
        return None
    try:
        if est.curvature.trustworthy:
            return None
        return est.conf_int(alpha, method="profile")
    except (IdentificationError, ValueError, np.linalg.LinAlgError):
        return None


def region_alpha(alpha: float, sigma_estimated: bool, dof: int) -> float:
    """The miss probability alpha' whose single-parameter profile threshold equals the pair-region one.

    The projection of the pair region {D_ij <= c_2} on p_i is {a : D_i(a) <= c_2} exactly (D_i is
    the minimum of D_ij over p_j), i.e. the profile interval at the level whose threshold is c_2:
    alpha' = P(chi2_1 > chi2_2(1 - alpha)) (sigma known) or P(F(1, dof) > 2 F(2, dof; 1 - alpha)).
    """
    from scipy import stats
    from identification.inference.profile import region_threshold
    c2 = region_threshold(alpha, sigma_estimated, dof)
    return float(stats.f.sf(c2, 1, dof) if sigma_estimated else stats.chi2.sf(c2, 1))


def region_limits(estimate, extent, pair, span: float = 1.3, cap: float = 8.0) -> tuple:
    """Grid rectangle of a pair region: the linearised ellipse's extent (``span`` x its half-widths)
    joined with the extent of the likelihood-ratio region (``extent``: the profile intervals at
    :func:`region_alpha`, and their traces), 10 % margin, each side capped at ``cap`` ellipse
    half-widths from the estimate (an unbounded region reaches the cap)."""
    from scipy import stats
    p = np.asarray(estimate.p, float)
    se = np.asarray(estimate.stderr, float)
    half = math.sqrt(stats.chi2.ppf(0.95, 2)) * se
    names = (estimate.param_names[pair[0]], estimate.param_names[pair[1]])
    lim = []
    for k in pair:
        lo, hi = p[k] - span * half[k], p[k] + span * half[k]
        if extent is not None:
            if estimate.param_names[k] in extent.param_names:
                e_lo, e_hi = extent[estimate.param_names[k]]
                lo, hi = min(lo, e_lo), max(hi, e_hi)
            for pr in extent.profiles:
                if pr.name in names:
                    col = pr.params[:, k]
                    lo, hi = min(lo, float(np.min(col))), max(hi, float(np.max(col)))
        lo, hi = max(lo, p[k] - cap * half[k]), min(hi, p[k] + cap * half[k])
        width = hi - lo
        lim.append((lo - 0.1 * width, hi + 0.1 * width))
    return tuple(lim)


def model_uncertainty(estimate, variant: str, alpha: float = 0.05, n_grid: int | None = None,
                      progress=None) -> ModelUncertainty:
    """Profile intervals, Wald intervals and the likelihood-ratio region of every pair of one model.

    Parameters
    ----------
    estimate : identification.Estimate     the fit of ``variant`` (it carries model and data)
    variant : str
    alpha : float                           miss probability (0.05: 95 %)
    n_grid : int, optional                  grid points per axis of the pair regions (default 21, 15
                                            beyond 6 pairs)
    progress : identification.progress.Progress, optional   a bar over the profiles and pairs

    A failed profile or region is recorded with its reason (shown on the page), never dropped.
    """
    from identification.inference.profile import ProfileError
    t0 = time.perf_counter()
    e = estimate
    n = e.n_p
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    if n_grid is None:
        n_grid = 21 if len(pairs) <= 6 else 15
    bar = progress.bar(len(pairs) + 1, f"uncertainty of {variant}", unit="step") if progress is not None else None
    wald = np.asarray(e.conf_int(alpha), float)
    try:
        prof, perr = e.conf_int(alpha, method="profile"), ""
    except (ProfileError, IdentificationError, ValueError, np.linalg.LinAlgError) as exc:
        prof, perr = None, str(exc).splitlines()[0]
    extent, eerr = None, ""
    if pairs:
        try:
            extent = e.conf_int(region_alpha(alpha, e.sigma_estimated, e.dof), method="profile")
        except (ProfileError, IdentificationError, ValueError, np.linalg.LinAlgError) as exc:
            eerr = str(exc).splitlines()[0]
    if bar is not None:
        bar.update(1)
    regions = []
    for pair in pairs:
        try:
            reg = lr_region(e.model, e.data, e, pair, alpha, n_grid=n_grid, grid="valley",
                            limits=region_limits(e, extent, pair))
            regions.append(PairRegion(pair, reg))
        except (IdentificationError, ValueError, np.linalg.LinAlgError) as exc:
            regions.append(PairRegion(pair, None, str(exc).splitlines()[0]))
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return ModelUncertainty(variant, e, linearisation_trust(e), wald, prof, perr, tuple(regions), alpha,
                            time.perf_counter() - t0, extent, eerr)
