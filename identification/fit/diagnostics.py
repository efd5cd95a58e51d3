r"""How a fit ran, as typed attributes: :class:`FitDiagnostics` (``est.diagnostics``) instead of ``est.extra[...]``.

The estimator records its run in the string-keyed dict ``FitRecord.extra`` (kept working, deprecated: read
``est.diagnostics`` instead).  :class:`FitDiagnostics` is the same record with one typed, documented attribute
per key: the solver that ran, the Newton decrement :math:`\delta = g^T H^{-1} g` at the estimate (the predicted
decrease of the objective, dimensionless objective units), Ipopt's iterations and passes, the singular values of
the column-normalised weighted Jacobian :math:`W^{1/2} J D` (their ratio is the condition of the fit), the
eigenvalues of the scaled Hessian, why the Newton refinement stopped, the saddle points escaped, the timings,
for a dynamic model the discretisation record and, for a multi-start fit, the record of its starts.  Keys it does
not know are kept in ``other``.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

__all__ = ["FitDiagnostics", "EXTRA_KEYS"]

#: the keys of ``FitRecord.extra`` that :class:`FitDiagnostics` turns into attributes of the same name
EXTRA_KEYS = ("solver", "newton_decrement", "ipopt_iterations", "ipopt_passes", "singular_values",
              "hessian_eigenvalues", "refinement_stop", "saddle_escapes", "ipopt_timing", "timing", "discretisation",
              "starts")


def _array(v):
    if v is None:
        return None
    a = np.array(v, dtype=float, copy=True)
    a.setflags(write=False)
    return a


def _mapping(v):
    return None if v is None else dict(v)


@dataclass(frozen=True)
class FitDiagnostics:
    """The diagnostics of one fit (typed view of ``FitRecord.extra``; None / NaN / empty where the path did not
    record them, e.g. a fit by the batch engine or the valley walk of an unbounded fit).

    Attributes
    ----------
    solver : str                   the solver that gave the estimate ("ipopt", "reduced Newton", "valley walk
                                   (identification.fit.unbounded)"); "" when not recorded
    newton_decrement : float       g^T H^-1 g at the estimate after the Newton refinement (objective units; NaN)
    ipopt_iterations : int         Ipopt iterations (0 when Ipopt did not run)
    ipopt_passes : int             Ipopt runs (restarts included; 0 when not recorded)
    singular_values : ndarray or None    of the column-normalised weighted Jacobian (descending)
    hessian_eigenvalues : ndarray or None    of the Hessian H = J^T W J + S in the same scaling
    refinement_stop : str          why the Newton refinement stopped ("" when not recorded)
    saddle_escapes : tuple of Mapping     each saddle point the solver stopped at and left ("rss", "eigenvalue")
    ipopt_timing : Mapping or None  Ipopt's build / nlpsol / solve / callback times (s)
    timing : Mapping or None       {phase: (wall s, CPU s)} of identify (``IdentifySettings`` timing on)
    discretisation : DiscretisationRecord or None   the mesh and its error (dynamic models)
    starts : MultiStartRecord or None   every start of a multi-start fit (``identify(..., starts=N)``,
                                   :mod:`identification.fit.multistart`); None for a single start
    other : Mapping                the keys of ``extra`` not listed above
    """

    solver: str = ""
    newton_decrement: float = float("nan")
    ipopt_iterations: int = 0
    ipopt_passes: int = 0
    singular_values: np.ndarray | None = None
    hessian_eigenvalues: np.ndarray | None = None
    refinement_stop: str = ""
    saddle_escapes: tuple = ()
    ipopt_timing: Mapping | None = None
    timing: Mapping | None = None
    discretisation: object = None
    starts: object = None
    other: Mapping = field(default_factory=dict)

    @classmethod
    def from_extra(cls, extra: Mapping | None) -> "FitDiagnostics":
        """The typed view of a fit's ``extra`` dict (unknown keys go to ``other``)."""
        e = dict(extra or {})
        return cls(solver=str(e.get("solver", "")), newton_decrement=float(e.get("newton_decrement", np.nan)),
                   ipopt_iterations=int(e.get("ipopt_iterations", 0)), ipopt_passes=int(e.get("ipopt_passes", 0)),
                   singular_values=_array(e.get("singular_values")),
                   hessian_eigenvalues=_array(e.get("hessian_eigenvalues")),
                   refinement_stop=str(e.get("refinement_stop", "") or ""),
                   saddle_escapes=tuple(dict(s) for s in e.get("saddle_escapes", ())),
                   ipopt_timing=_mapping(e.get("ipopt_timing")), timing=_mapping(e.get("timing")),
                   discretisation=e.get("discretisation"), starts=e.get("starts"),
                   other={k: v for k, v in e.items() if k not in EXTRA_KEYS})

    @property
    def condition(self) -> float:
        """sigma_max / sigma_min of the column-normalised weighted Jacobian (NaN when not recorded; inf when
        rank-deficient)."""
        sv = self.singular_values
        if sv is None or sv.size == 0:
            return float("nan")
        return float(np.max(sv) / np.min(sv)) if np.min(sv) > 0 else float("inf")
