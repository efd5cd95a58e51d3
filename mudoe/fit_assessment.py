"""What the study says of each fit beside its numbers: goodness of fit and the trust of its linearisation.

:func:`assess` gives an :class:`identification.studies.records.FitAssessment` per estimate; :func:`mudoe.study.run_identify`
keeps one per fit in ``StudyResults.assessments`` and the report's verdict table, verdict paragraphs
and residual pages read them.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import stats

from identification.studies.records import FitAssessment, GoodnessOfFit

__all__ = ["assess", "goodness_of_fit", "linearisation_trust"]


def assess(est) -> FitAssessment:
    """The goodness of fit and the trust of the linearisation of one estimate."""
    return FitAssessment(goodness_of_fit(est), linearisation_trust(est))


def linearisation_trust(est) -> str:
    """Trust of the linearised covariance of one estimate (verdict table column).

    From ``est.curvature`` (Bates-Watts relative curvatures against 1/sqrt(F(p, n-p; 0.05))):
    "trustworthy", "NOT trustworthy", or "not assessed" when the estimate carries no model/data,
    has no residual degrees of freedom, or the curvature could not be computed.
    """
    if est.model is None or est.data is None or est.dof < 1:
        return "not assessed"
    try:
        ok = est.curvature.trustworthy
    except (np.linalg.LinAlgError, ValueError):
        return "not assessed"
    return "trustworthy" if ok else "NOT trustworthy"



def goodness_of_fit(est) -> GoodnessOfFit:
    """Chi-square goodness-of-fit test of one fit: P(chi2_dof >= observed) with the sensors' sigma."""
    r = np.asarray(est.residuals, float) / np.asarray(est.sigma, float)
    used = np.asarray(est.weights) > 0
    chi2 = float(np.nansum(r[..., used] ** 2))
    dof = int(est.dof)
    if est.sigma_estimated or dof <= 0:
        return GoodnessOfFit(chi2, dof, math.nan)
    return GoodnessOfFit(chi2, dof, float(stats.chi2.sf(chi2, dof)))
