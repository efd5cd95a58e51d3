"""Prediction bands of every fit, computed by the study for the report's pages (delta method).

:func:`run_bands` puts :func:`prediction_bands` of every estimate into ``StudyResults.bands``;
the report draws them (:func:`reports.figures.prediction_band_plot`).
"""
from __future__ import annotations

import dataclasses

import numpy as np
from scipy import stats

from identification.studies.records import PredictionBands

__all__ = ["prediction_bands", "run_bands", "BAND_LEVEL"]

#: the level of the report's prediction bands
BAND_LEVEL = 0.95


def prediction_bands(est, level: float = 0.95) -> PredictionBands:
    """Delta-method bands of the fitted outputs (like MATLAB's ``nlpredci``).

    With the exact sensitivities g = dh/dp (``est.G``, from the implicit state) and the
    estimate's covariance C: mean band h +- q sqrt(g^T C g), new-observation band
    h +- q sqrt(g^T C g + sigma_k^2), q the two-sided ``level`` quantile of Student's t with
    the fit's degrees of freedom when sigma was estimated, of N(0, 1) when it was given.
    """
    if not 0.5 < level < 1:
        raise ValueError(f"level: a two-sided confidence level in (0.5, 1), got {level}")
    G = np.asarray(est.G, float)
    C = np.asarray(est.cov, float)
    var = np.einsum("jkp,pq,jkq->jk", G, C, G)
    var = np.clip(var, 0, None)
    q = (stats.t.ppf(0.5 + level / 2, est.dof) if est.sigma_estimated and est.dof > 0
         else stats.norm.ppf(0.5 + level / 2))
    sig2 = np.asarray(est.sigma, float) ** 2
    return PredictionBands(np.asarray(est.fitted, float), q * np.sqrt(var), q * np.sqrt(var + sig2[None, :]), q, level)


def run_bands(study, results, level: float = BAND_LEVEL):
    """``results`` with ``bands``: {variant: PredictionBands} of every fit on all study data at ``level`` (a
    static study's; a time-series study's bands are its trajectories', :mod:`mudoe.kind.time_series`)."""
    return dataclasses.replace(results, bands={**results.bands, **{v: prediction_bands(e, level)
                                                                   for v, e in results.estimates.items()}})
