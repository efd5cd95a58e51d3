"""The inputs, settings and results of the batch engine (:func:`identification.fit.batch.fit_batch`):
R data sets of one model stacked (:class:`BatchData`), the estimates (:class:`BatchMember`,
:class:`BatchFit`) and the members fitted by identify instead (:class:`FallbackRecord`)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from identification.errors import DataError
from identification.fit.measurements import Measurements

__all__ = ["BatchData", "BatchFit", "BatchMember", "FallbackRecord", "BatchSettings", "LEFT_BOUNDS"]

#: the fallback reason of a member whose Newton iteration left the parameter bounds
LEFT_BOUNDS = "the iteration left the parameter bounds"


@dataclass(frozen=True)
class BatchSettings:
    """Settings of the batched Newton iteration (the estimator's own settings are IdentifySettings).

    Attributes
    ----------
    max_sweeps : int        sweeps (model evaluations at all points) before a member falls back
    newton_step : float     after a step shorter than this (parameter scales, inf-norm) a member
                            takes exact Newton steps (before: Gauss-Newton)
    max_step : float        steps longer than this (inf-norm of |dp| / max(s_p, |p|)) are shortened to it
    state_tol : float       state convergence |dy_E|_inf <= state_tol (1 + |y|_inf) at every input
                            (the test of models.state.solve_states)
    """

    max_sweeps: int = 30
    newton_step: float = 0.25
    max_step: float = 0.5
    state_tol: float = 1e-12

    def __post_init__(self):
        if not (isinstance(self.max_sweeps, (int, np.integer)) and self.max_sweeps >= 1):
            raise ValueError(f"max_sweeps: expected an integer >= 1, got {self.max_sweeps!r}")
        for name in ("newton_step", "max_step", "state_tol"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float, np.floating)) and np.isfinite(v) and v > 0):
                raise ValueError(f"{name}: expected a finite number > 0, got {v!r}")


@dataclass(frozen=True)
class FallbackRecord:
    """A member fitted by :func:`identification.identify` instead of the batch iteration.

    Attributes
    ----------
    member : int      index of the data set
    reason : str      why the batch iteration did not give its estimate
    error : str       "" when identify succeeded, else its error ("ExceptionType: message"), or
                      "not bounded: ..." when identify returned an estimate the data do not bound
    """

    member: int
    reason: str
    error: str = ""


def _readonly(a) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class BatchData:
    """R data sets of one model, stacked (the input of :func:`fit_batch`).

    Attributes
    ----------
    inputs : ndarray (n_q, d_q)      the common inputs, or (R, n_q, d_q): each member's own inputs
                                     (same shape; e.g. profile points, whose fixed parameter values
                                     are input columns, :func:`identification.fit.fixed.fixed_model`)
    z : ndarray (R, n_M, n_q, n_S)   values (NaN: missing)
    sigma : ndarray (R, n_S) or None sensor sigmas (None: a common unknown sigma for every member)
    make : callable or None          member -> its Measurements (the data of a fallback fit; None:
                                     ``Measurements(inputs, z[r], sigma[r])``)

    Build it with :meth:`of` from Measurements, or directly from arrays (cheaper for many small
    data sets: no Measurements is built unless a member falls back).
    """

    inputs: np.ndarray
    z: np.ndarray
    sigma: np.ndarray | None
    make: Callable | None = None

    def __post_init__(self):
        q = np.asarray(self.inputs, float)
        z = np.asarray(self.z, float)
        if q.ndim not in (2, 3) or z.ndim != 4 or z.shape[2] != q.shape[-2] or z.shape[0] < 1:
            raise DataError(f"z, inputs: expected z of shape (R >= 1, n_M, n_q, n_S) and inputs (n_q, d_q) or "
                            f"(R, n_q, d_q), got {z.shape} and {q.shape}")
        if q.ndim == 3 and q.shape[0] != z.shape[0]:
            raise DataError(f"inputs: per-member inputs need one (n_q, d_q) array per member of z: expected shape "
                            f"({z.shape[0]}, {q.shape[1]}, {q.shape[2]}), got {q.shape}")
        if self.sigma is not None:
            sig = np.asarray(self.sigma, float)
            if sig.shape != (z.shape[0], z.shape[3]) or not np.all(np.isfinite(sig) & (sig > 0)):
                raise DataError(f"sigma: expected positive finite values of shape {(z.shape[0], z.shape[3])} "
                                f"or None, got {sig.shape}")
            object.__setattr__(self, "sigma", sig)
        object.__setattr__(self, "inputs", q)
        object.__setattr__(self, "z", z)

    @classmethod
    def of(cls, data: Sequence[Measurements]) -> "BatchData":
        """Stack Measurements (all sigmas given or all unknown; members with fewer series are padded
        with missing values).  Inputs of the same shape (n_q, d_q): when they are all equal the batch
        has common inputs, else each member keeps its own (``inputs`` of shape (R, n_q, d_q))."""
        data = tuple(data)
        if not data:
            raise DataError("data: the batch is empty; give at least one Measurements")
        for r, d in enumerate(data):
            if not isinstance(d, Measurements):
                raise TypeError(f"data[{r}]: expected an identification.Measurements, got {type(d).__name__}")
        d0 = data[0]
        for r, d in enumerate(data[1:], 1):
            if d.inputs.shape != d0.inputs.shape:
                raise DataError(f"data[{r}]: its inputs have shape {d.inputs.shape}, data[0]'s {d0.inputs.shape}; a "
                                "batch fits data sets whose inputs have one shape (n_q, d_q) (group the data sets "
                                "by shape, or call identify per data set)")
            if (d.sigma is None) != (d0.sigma is None):
                raise DataError(f"data[{r}]: sigma is {'unknown' if d.sigma is None else 'given'} but not for "
                                "data[0]; a batch needs all sigmas given or all unknown")
            if d.n_S != d0.n_S:
                raise DataError(f"data[{r}]: has {d.n_S} sensors, data[0] has {d0.n_S}")
        n_M = max(d.n_M for d in data)
        z = np.full((len(data), n_M) + d0.z.shape[1:], np.nan)
        for r, d in enumerate(data):
            z[r, :d.n_M] = d.z
        sig = None if d0.sigma is None else np.stack([np.asarray(d.sigma, float) for d in data])
        shared = all(np.array_equal(d.inputs, d0.inputs) for d in data[1:])
        inputs = d0.inputs if shared else np.stack([d.inputs for d in data])
        return cls(inputs, z, sig, data.__getitem__)

    @property
    def n_members(self) -> int:
        return self.z.shape[0]

    @property
    def shared(self) -> bool:
        """True when all members have the same inputs (``inputs`` of shape (n_q, d_q))."""
        return self.inputs.ndim == 2

    def member_inputs(self, r: int) -> np.ndarray:
        """The inputs (n_q, d_q) of member r."""
        return self.inputs if self.shared else self.inputs[r]

    def member(self, r: int) -> Measurements:
        """The Measurements of member r."""
        if self.make is not None:
            return self.make(r)
        return Measurements(self.member_inputs(r), self.z[r], None if self.sigma is None else self.sigma[r])

    def weights(self, weights=None) -> np.ndarray:
        """Validated sensor weights (n_S,): ones for None, else finite and >= 0 (as Measurements.sensor_weights)."""
        n_S = self.z.shape[3]
        if weights is None:
            return np.ones(n_S)
        w = np.asarray(weights, dtype=float)
        if w.shape != (n_S,):
            raise DataError(f"weights: expected {n_S} sensor weights, got shape {w.shape}")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise DataError(f"weights: must be finite and non-negative, got {w.tolist()}")
        return w


@dataclass(frozen=True, eq=False)
class BatchMember:
    """The estimate of one member, with the fields of :class:`identification.Estimate` that the
    split tests and Monte Carlo studies read (same meaning and units).

    Attributes
    ----------
    p : ndarray (n_p,)                estimate
    cov, cov_gn : ndarray (n_p, n_p)  second-order (Bard) and Gauss-Newton covariances
    information, S, H : ndarray       J^T Omega J, the second-order term and their sum
    objective : float                 0.5 sum w ((z - h)/sigma)^2 (sigma as used, as Estimate.objective)
    rss : float                       unweighted residual sum of squares over the selected sensors
    n_data, dof : int                 used values and n - n_p
    sigma_estimated : bool
    sigma : ndarray (n_S,)            sigmas of the covariance (estimated when unknown)
    states : ndarray (n_q, n_y)       states at the estimate
    fitted : ndarray (n_q, n_S)       model outputs at the estimate
    decrement : float                 Newton decrement g^T H^-1 g at the estimate (chi^2 units)
    iterations : int                  sweeps of the batch iteration
    state_derivatives : ndarray       y'(p) = -E_y^{-1} E_p at the estimate, (n_q, n_y, n_p)
    notes : tuple                     always empty: the batch engine does not write the
                                      estimator's diagnostic notes (identify's summary does)
    """

    p: np.ndarray
    cov: np.ndarray
    cov_gn: np.ndarray
    information: np.ndarray
    S: np.ndarray
    H: np.ndarray
    objective: float
    rss: float
    n_data: int
    dof: int
    sigma_estimated: bool
    sigma: np.ndarray
    states: np.ndarray
    fitted: np.ndarray
    decrement: float
    iterations: int
    state_derivatives: np.ndarray
    notes: tuple = ()

    def __post_init__(self):
        for name in ("p", "cov", "cov_gn", "information", "S", "H", "sigma", "states", "fitted", "state_derivatives"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))


@dataclass(frozen=True, eq=False)
class BatchFit:
    """Estimates of R data sets of one model (:func:`fit_batch`); NaN rows where a member failed.

    Attributes
    ----------
    p : ndarray (R, n_p)                 estimates
    cov, cov_gn : ndarray (R, n_p, n_p)  second-order (Bard) and Gauss-Newton covariances
    information : ndarray (R, n_p, n_p)  J^T Omega J (rescaled by s^2 / sigma_0^2 when sigma is estimated)
    objective : ndarray (R,)             objective at the estimate (as Estimate.objective)
    rss : ndarray (R,)                   residual sums of squares over the selected sensors
    decrement : ndarray (R,)             Newton decrements at the estimates (NaN for fallbacks)
    iterations : ndarray (R,) int        sweeps of the batch iteration (0 for fallbacks)
    converged : ndarray (R,) bool        the batch iteration gave the estimate
    ok : ndarray (R,) bool               an estimate exists (batch or fallback; False for an estimate
                                         that is not bounded, kept in ``results``)
    fallbacks : tuple of FallbackRecord  members fitted by identify instead (which, why, outcome)
    results : tuple                      per member a BatchMember, an Estimate (fallback) or the
                                         exception identify raised (read with :meth:`result`)
    dense_sweeps : int                   sweeps evaluated by the dense path (NumPy LAPACK solves of
                                         E_y) instead of the fused compiled sweep function (used for
                                         models in SX with JIT compilation on, where E_y is
                                         symmetric positive definite; the shared first
                                         sweep is not counted)
    """

    p: np.ndarray
    cov: np.ndarray
    cov_gn: np.ndarray
    information: np.ndarray
    objective: np.ndarray
    rss: np.ndarray
    decrement: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray
    ok: np.ndarray
    fallbacks: tuple
    results: tuple = field(repr=False)
    dense_sweeps: int = 0

    def __post_init__(self):
        for name in ("p", "cov", "cov_gn", "information", "objective", "rss", "decrement"):
            object.__setattr__(self, name, _readonly(getattr(self, name)))
        for name, dt in (("iterations", int), ("converged", bool), ("ok", bool)):
            a = np.array(getattr(self, name), dtype=dt, copy=True)
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    @property
    def n_members(self) -> int:
        return len(self.results)

    def result(self, member: int):
        """The estimate of one member (a BatchMember, or identify's Estimate for a fallback).

        Raises
        ------
        IdentificationError, DataError
            The error identify raised for a member whose fallback failed too.
        """
        r = self.results[member]
        if isinstance(r, Exception):
            raise r
        return r
