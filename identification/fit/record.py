"""The plain, immutable record of one fit: estimate, covariances, diagnostics (no inference)."""
from __future__ import annotations

from dataclasses import dataclass, field, fields
from functools import cached_property

import numpy as np

from identification.errors import NotBoundedError
from identification.fit.diagnostics import FitDiagnostics
from identification.fit.checks import SloppyDirection, sloppy_direction

__all__ = ["FitRecord"]


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
        discretisation of a dynamic fit, ...; :class:`identification.fit.diagnostics.FitDiagnostics`): the
        replacement of the string keys of :attr:`extra`."""
        return FitDiagnostics.from_extra(self.extra)

    def __repr__(self):
        if self.unbounded is not None:
            return f"{type(self).__name__}(not bounded: {self.unbounded.reason})"
        vals = ", ".join(f"{n}={v:.6g}" for n, v in zip(self.param_names, self.p))
        return f"{type(self).__name__}({vals}; status={self.status})"
