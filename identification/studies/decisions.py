"""Lines 09-17 of Algorithm 1: the verdict of a model from its split tests (Bonferroni, Holm).

A model is rejected when some split has alpha_min < TOL / n_tests (Bonferroni) or by Holm's
step-down procedure; a split without a p-value makes the verdict "undecided" unless another
split rejects.  The primary verdict is the chosen statistic's, or the likelihood ratio's when a
fit's linearisation is not trustworthy (Bates-Watts curvature).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from identification.studies.detect_settings import CORRECTIONS, DEFAULT_STATISTIC, STATISTICS, DetectSettings
from identification.studies.split_tests import SplitTest

__all__ = ["ModelDecision", "decide", "model_decisions"]


@dataclass(frozen=True)
class ModelDecision:
    """The verdict of Algorithm 1 for one model, one statistic and one multiple-test correction.

    Attributes
    ----------
    model : str
    decision : str        "rejected" (model uncertainty detected), "not rejected" or "undecided"
                          (the one vocabulary of terminal, JSON and report)
    statistic, correction : str
    tol : float           family-wise level TOL
    n_tests : int         planned number of tests (all splits, failed ones included)
    threshold : float     TOL / n_tests (the first, smallest threshold of Holm)
    flagged : tuple       splits whose hypothesis is rejected under this correction
    failed : tuple        splits without a p-value
    min_alpha : float     smallest alpha_min over the computed splits (NaN if none)
    reason : str
    """

    model: str
    decision: str
    statistic: str
    correction: str
    tol: float
    n_tests: int
    threshold: float
    flagged: tuple
    failed: tuple
    min_alpha: float
    reason: str


def decide(tests: Sequence[SplitTest], tol: float, statistic: str = DEFAULT_STATISTIC,
           correction: str = "bonferroni") -> ModelDecision:
    """Bonferroni: reject when some alpha_min < TOL / n_tests (lines 09-16).  Holm: step-down.

    Failed splits (or a split whose statistic could not be computed, e.g. a failed pooled
    fit for the likelihood ratio) count in n_tests (the correction covers every planned
    test) and rank last in Holm's ordering.  Without a rejection, a failed split makes the
    verdict "undecided".
    """
    tol = float(tol)
    if not (0.0 < tol < 1.0):
        raise ValueError(f"tol: must lie in (0, 1), got {tol!r}")
    if correction not in CORRECTIONS:
        raise ValueError(f"correction: expected one of {CORRECTIONS}, got {correction!r}")
    if statistic not in STATISTICS:
        raise ValueError(f"statistic: expected one of {STATISTICS}, got {statistic!r}")
    if not tests:
        raise ValueError("tests: no split tests to decide on")
    n = len(tests)
    model = tests[0].model
    a = np.array([t.alpha(statistic) if t.ok else np.nan for t in tests])
    failed = tuple(t.split for t, ai in zip(tests, a) if not np.isfinite(ai))
    if correction == "bonferroni":
        flag = np.isfinite(a) & (a < tol / n)
    else:
        order = np.argsort(np.where(np.isfinite(a), a, np.inf), kind="stable")
        flag = np.zeros(n, bool)
        for rank, i in enumerate(order):
            if np.isfinite(a[i]) and a[i] < tol / (n - rank):
                flag[i] = True
            else:
                break
    flagged = tuple(tests[i].split for i in np.flatnonzero(flag))
    amin = float(np.nanmin(a)) if np.any(np.isfinite(a)) else math.nan
    if flagged:
        dec = "rejected"
        i = int(np.nanargmin(a))
        reason = (f"alpha_min = {100 * a[i]:.3g} % < TOL/n_tests = {100 * tol / n:.3g} % on split "
                  f"{tests[i].split!r}")
    elif failed:
        dec = "undecided"
        reason = "; ".join((f"split {t.split!r} failed at the {t.stage}: {t.error}" if not t.ok else
                            f"split {t.split!r}: {statistic} not computed: {t.lr_error}")
                           for t, ai in zip(tests, a) if not np.isfinite(ai))
    else:
        dec = "not rejected"
        reason = f"every alpha_min >= TOL/n_tests = {100 * tol / n:.3g} % (smallest {100 * amin:.3g} %)"
    return ModelDecision(model=model, decision=dec, statistic=statistic, correction=correction, tol=tol,
                         n_tests=n, threshold=tol / n, flagged=flagged, failed=failed, min_alpha=amin,
                         reason=reason)



def model_decisions(tests: tuple, names: tuple, settings: DetectSettings) -> tuple:
    """(primary decision per model, every model x statistic x correction decision) of split tests
    (lines 09-17; :func:`identification.studies.detect.detect`, for a dynamic model after marking the
    splits whose discretisation error is not bounded undecided)."""
    all_dec, primary = [], []
    for name in names:
        mt = [t for t in tests if t.model == name]
        dec = {}
        for st in STATISTICS:
            for co in CORRECTIONS:
                dec[(st, co)] = decide(mt, settings.tol, st, co)
                all_dec.append(dec[(st, co)])
        primary.append(_primary(mt, dec, settings))
    return tuple(primary), tuple(all_dec)


def _primary(mt: list, dec: dict, settings: DetectSettings) -> ModelDecision:
    """The verdict of one model: the chosen statistic's, or the likelihood ratio's when a fit's
    linearisation is not trustworthy (the Wald statistics then rest on a failed approximation)."""
    bad = [t.split for t in mt if t.trustworthy is False]
    d = dec[(settings.statistic, settings.correction)]
    if not bad:
        return d
    why = (f"the linearisation of split(s) {', '.join(repr(b) for b in bad)} is not trustworthy (Bates-Watts "
           "curvature), so the Wald statistics are unreliable")
    if settings.statistic == "likelihood_ratio":
        return dataclasses.replace(d, reason=f"{d.reason}; decided by the likelihood ratio (parametrisation "
                                             f"invariant): {why}")
    lr = dec[("likelihood_ratio", settings.correction)]
    return dataclasses.replace(lr, reason=f"{lr.reason}; decided by the likelihood ratio instead of "
                                          f"{settings.statistic}: {why}")

