"""The settings of Algorithm 1 (:func:`identification.studies.detect.detect`): the statistics, the
multiple-test corrections and :class:`DetectSettings`."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from identification.fit.estimator import IdentifySettings
from identification.studies.normality import GATE_CORRECTIONS, check_correction

__all__ = ["DetectSettings", "STATISTICS", "CORRECTIONS", "DEFAULT_STATISTIC", "alpha_field"]

STATISTICS = ("likelihood_ratio", "two_sample", "paper")
#: the statistic that decides unless the user chooses another (all are always reported)
DEFAULT_STATISTIC = "likelihood_ratio"
_ALPHA_FIELDS = {"likelihood_ratio": "alpha_lr", "two_sample": "alpha_two_sample", "paper": "alpha_paper"}


def alpha_field(statistic: str) -> str:
    """Name of the attribute holding a statistic's alpha_min (SplitTest, MonteCarloResult)."""
    try:
        return _ALPHA_FIELDS[statistic]
    except (KeyError, TypeError):
        raise ValueError(f"statistic: expected one of {STATISTICS}, got {statistic!r}") from None


#: the multiple-test corrections of lines 09-16
CORRECTIONS = ("bonferroni", "holm")


@dataclass(frozen=True)
class DetectSettings:
    """Settings of :func:`~identification.studies.detect.detect` (defaults follow the paper, with the calibrated statistic).

    Attributes
    ----------
    tol : float                family-wise test level TOL in (0, 1) (paper: 5 %)
    statistic : str            "likelihood_ratio" (default), "two_sample" (Wald, C_cal + C_val) or
                               "paper" (Wald, C_cal only)
    correction : str           "bonferroni" (paper) or "holm"
    normality : str            "check" (raise NormalityError on failure) or "override" (record only)
    normality_level : float    family-wise level of the Shapiro-Wilk gate (paper: 5 % per sensor)
    normality_correction : str "holm" (default), "bonferroni" or "none" (the paper's per-sensor gate,
                               family-wise level 1 - (1 - level)^m over m sensors)
    covariance : str           "second_order" (paper eq. 7) or "gauss_newton"
    identify : IdentifySettings | None  passed to identify()
    """

    tol: float = 0.05
    statistic: str = DEFAULT_STATISTIC
    correction: str = "bonferroni"
    normality: str = "check"
    normality_level: float = 0.05
    normality_correction: str = GATE_CORRECTIONS[0]
    covariance: str = "second_order"
    identify: IdentifySettings | None = None

    def __post_init__(self):
        tol = float(self.tol) if isinstance(self.tol, (int, float, np.floating)) else float("nan")
        if not (0.0 < tol < 1.0):
            raise ValueError(f"tol: the test level TOL must lie in (0, 1), got {self.tol!r}")
        if self.statistic not in STATISTICS:
            raise ValueError(f"statistic: expected one of {STATISTICS}, got {self.statistic!r}")
        if self.correction not in CORRECTIONS:
            raise ValueError(f"correction: expected one of {CORRECTIONS}, got {self.correction!r}")
        if self.normality not in ("check", "override"):
            raise ValueError(f"normality: expected 'check' or 'override', got {self.normality!r}")
        if not (0.0 < float(self.normality_level) < 1.0):
            raise ValueError(f"normality_level: must lie in (0, 1), got {self.normality_level!r}")
        check_correction(self.normality_correction)
        if self.covariance not in ("second_order", "gauss_newton"):
            raise ValueError(f"covariance: expected 'second_order' or 'gauss_newton', got {self.covariance!r}")
        object.__setattr__(self, "tol", tol)

