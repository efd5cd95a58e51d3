"""What a report draws of a dynamic study, as records: trajectories with bands, the mesh of each fit.

Computed by :mod:`mudoe.kind.time_series` into ``StudyResults.trajectories`` and ``.discretisation``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Trajectories", "MeshSummary"]


@dataclass(frozen=True)
class Trajectories:
    """Outputs of every experiment on a fine time grid and their delta-method half-widths.

    t (n_t,), h, half_mean, half_new (n_q, n_t, n_S) in the model's units; level, quantile name."""

    t: np.ndarray
    h: np.ndarray
    half_mean: np.ndarray
    half_new: np.ndarray
    level: float
    quantile: str
    residuals: np.ndarray = None     # (n_M, n_q, n_t_data, n_S): (z - h) / sigma at the data's times
    error_sigma: float = math.nan    # largest discretisation error of h on the fine grid, in sigmas
    tol_sigma: float = math.nan      # its tolerance


@dataclass(frozen=True)
class MeshSummary:
    """What a report shows of the discretisation of a dynamic fit (from its
    :class:`identification.fit.dynamic_fit.DiscretisationRecord`).

    degree, n_elements : the Radau IIA mesh; error_pct : largest estimated output error at the
    readings, % of sigma (tol_pct its tolerance); shift_se : largest linearised shift of the estimate
    without discretisation error, in standard errors (tol_se its tolerance); bounded : both within
    their tolerances; reason : why not ("" when bounded).
    """

    degree: int
    n_elements: int
    error_pct: float
    tol_pct: float
    shift_se: float
    tol_se: float
    bounded: bool
    reason: str = ""
    method: str = "Radau IIA collocation"

    def text(self) -> str:
        """One line: mesh, largest output error in % of sigma, bounded or NOT bounded (and why)."""
        head = (f"{self.method}, degree {self.degree}, {self.n_elements} elements; largest discretisation error "
                f"{self.error_pct:.2g} % of sigma")
        if self.bounded:
            return (f"{head} (bounded below {self.tol_pct:.2g} %), estimate shifted by at most {self.shift_se:.2g} "
                    f"standard errors (below {self.tol_se:.2g})")
        why = self.reason or "no finer mesh was tried"
        return (f"{head}, estimate shift {self.shift_se:.3g} standard errors: discretisation error NOT bounded "
                f"(tolerances {self.tol_pct:.2g} % of sigma, {self.tol_se:.2g} standard errors: {why}); the "
                "estimate and its verdicts may reflect the discretisation, not the model")
