r"""The plain, immutable record of one fit: estimate, covariances, diagnostics (no inference).

How a fit ran, as typed attributes: :class:`FitDiagnostics` (``est.diagnostics``) instead of ``est.extra[...]``.

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
from dataclasses import dataclass, field, fields
from functools import cached_property
import inspect
import warnings

import numpy as np

from identification.errors import NotBoundedError
from identification.fit.checks import SloppyDirection, sloppy_direction

__all__ = ["FitRecord", "FitDiagnostics", "EXTRA_KEYS", "EXTRA_READERS"]

#: the modules that read ``FitRecord.extra`` without a warning: the package that writes it (identification)
#: and the standard library's copying of a dataclass (``dataclasses.replace``, ``copy``, ``pickle``)
EXTRA_READERS = ("identification.", "dataclasses", "copy", "copyreg", "pickle")

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



@dataclass(frozen=True, eq=False)
class FitRecord:
    """The plain result of one fit (:func:`identification.fit.problem.fit_model`): the numbers, no
    inference.  :class:`identification.Estimate` adds intervals, regions, curvature and the summary.

    Attributes
    ----------
    p : ndarray (n_p,)            estimated parameters
    param_names : tuple of str
    states : ndarray (n_q, n_y)   states y_j(p) at the estimate
    fitted : ndarray (n_q, n_S)   model outputs h(y_j, p, q_j)
    residuals : ndarray (n_M, n_q, n_S)  z - h (NaN where missing), all sensors
    weights : ndarray (n_S,)      sensor weights used
    sigma : ndarray (n_S,)        sensor sigmas used for the covariance (estimated if unknown)
    sigma_estimated : bool        sigma was estimated as s^2 = RSS / (n - n_p)
    n_data, dof : int             number of used values, n - n_p
    rss : float                   unweighted residual sum of squares over the selected sensors
    objective : float             0.5 sum_k w_k sum_ij ((z_ijk - h_jk)/sigma_k)^2 (sigma as used)
    information : ndarray         J^T Omega J (Gauss-Newton information), (n_p, n_p)
    S : ndarray                   second-order term S(Omega), (n_p, n_p)
    H : ndarray                   J^T Omega J + S
    cov : ndarray                 second-order (Bard) covariance H^-1 J^T Omega^2 J H^-T
    cov_gn : ndarray              Gauss-Newton covariance
    G : ndarray (n_q, n_S, n_p)   total sensitivities dh/dp
    status, message : str         Ipopt's status and its meaning
    iterations : int ; solve_time : float (s) ; refinement_steps : int
    grad_norm : float             ||J^T Omega r|| at the estimate (scaled by parameter scale)
    notes : tuple of str          numbered notes printed by summary()
    model, data                   the models.Model and the Measurements of the fit (None when the
                                  Estimate was built by hand; needed by :attr:`curvature`)
    unbounded : Unbounded or None the data do not bound the parameters: the best fit runs off to
                                  infinity along ``unbounded.direction`` (:mod:`identification.fit.unbounded`);
                                  p is then a point on that path, the standard errors of the parameters
                                  that run off are inf, status is "Not_Bounded".  None: a finite optimum
    extra : dict                  the run's record by string keys (deprecated: read the typed :attr:`diagnostics`)
    """

    p: np.ndarray
    param_names: tuple
    param_units: tuple
    sensors: tuple
    states: np.ndarray
    fitted: np.ndarray
    residuals: np.ndarray
    weights: np.ndarray
    sigma: np.ndarray
    sigma_estimated: bool
    n_data: int
    dof: int
    rss: float
    objective: float
    information: np.ndarray
    S: np.ndarray
    H: np.ndarray
    cov: np.ndarray
    cov_gn: np.ndarray
    G: np.ndarray
    status: str
    message: str
    iterations: int
    solve_time: float
    refinement_steps: int
    grad_norm: float
    notes: tuple = ()
    model_name: str = ""
    extra: dict = field(default_factory=dict)
    model: object = field(default=None, repr=False)
    data: object = field(default=None, repr=False)
    unbounded: object = None

    def __getattribute__(self, name):
        """Attribute access; reading :attr:`extra` from outside :mod:`identification` warns (DeprecationWarning,
        one release: read the typed :attr:`diagnostics`)."""
        if name == "extra" and not inspect.currentframe().f_back.f_globals.get("__name__", "").startswith(
                EXTRA_READERS):
            warnings.warn("Estimate.extra / FitRecord.extra is deprecated and goes in the next release: read the "
                          "typed est.diagnostics (identification.fit.record.FitDiagnostics) instead",
                          DeprecationWarning, stacklevel=2)
        return object.__getattribute__(self, name)

    def __post_init__(self):
        for name in ("p", "states", "fitted", "residuals", "weights", "sigma", "information", "S", "H",
                     "cov", "cov_gn", "G"):
            a = np.array(getattr(self, name), dtype=float, copy=True)
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    # ------------------------------------------------------------------ derived, cached
    @property
    def n_p(self) -> int:
        return self.p.size

    @property
    def bounded(self) -> bool:
        """The data bound the parameters (a finite optimum); False: see :attr:`unbounded`."""
        return self.unbounded is None

    def require_bounded(self, what: str) -> None:
        """Raise NotBoundedError naming ``what`` needs a bounded estimate (no-op when bounded)."""
        if self.unbounded is not None:
            raise NotBoundedError(f"{what}: needs a bounded estimate, but {self.unbounded.reason}; use "
                                  "conf_int(method=\"profile\") and summary() for what the data determine")

    @property
    def success(self) -> bool:
        return self.status == "Solve_Succeeded"

    @cached_property
    def stderr(self) -> np.ndarray:
        """Standard errors from the second-order covariance."""
        return np.sqrt(np.diag(self.cov))

    @cached_property
    def stderr_gn(self) -> np.ndarray:
        """Standard errors from the Gauss-Newton covariance."""
        return np.sqrt(np.diag(self.cov_gn))

    @cached_property
    def correlation(self) -> np.ndarray:
        d = self.stderr
        return self.cov / np.outer(d, d)

    @cached_property
    def reduced_chi2(self) -> float:
        """sum_ijk w_k (r_ijk / sigma_k)^2 / (n - n_p) (1 by construction when sigma was estimated)."""
        return 2.0 * self.objective / self.dof if self.dof > 0 else float("nan")

    @cached_property
    def sloppy_direction(self) -> SloppyDirection | None:
        """The worst and best determined combinations of relative parameter changes and their
        standard-error ratio, from the information scaled by max(|p|, standard error) (None for one parameter)."""
        return sloppy_direction(self.information, self.p, self.param_names, self.stderr_gn)

    def record_fields(self) -> dict:
        """The dataclass fields of this record by name (to build a richer result from it)."""
        return {f.name: getattr(self, f.name) for f in fields(FitRecord)}

    @property
    def diagnostics(self) -> FitDiagnostics:
        """How the fit ran, as typed attributes (solver, Newton decrement, singular values, timings, the
        discretisation of a dynamic fit, ...; :class:`FitDiagnostics`): the
        replacement of the string keys of :attr:`extra`."""
        return FitDiagnostics.from_extra(self.extra)

    def __repr__(self):
        if self.unbounded is not None:
            return f"{type(self).__name__}(not bounded: {self.unbounded.reason})"
        vals = ", ".join(f"{n}={v:.6g}" for n, v in zip(self.param_names, self.p))
        return f"{type(self).__name__}({vals}; status={self.status})"
