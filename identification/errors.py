"""Exceptions of the identification package (all subclass ValueError or RuntimeError)."""
from models.errors import BlowUpError, NumericsError, StateSolveError

__all__ = ["DataError", "IdentificationError", "BadStartError", "BlowUpError", "IdentifiabilityError",
           "NotBoundedError", "StateSolveError", "ConvergenceError"]


class DataError(ValueError):
    """Measurements are malformed (shape, NaN-only sensor, non-positive sigma, ...)."""


class IdentificationError(NumericsError):
    """The estimator could not produce a trustworthy result (solver failure).

    Attributes
    ----------
    status : str
        The solver's return status (e.g. Ipopt's ``return_status``).
    """


class BadStartError(IdentificationError):
    """The start values p0 are bad input: the trajectory blows up in finite time within the horizon at p0
    (a :class:`models.errors.BlowUpError` of the state solve at the start)."""


class IdentifiabilityError(IdentificationError):
    """Assumption 3 of the paper fails: rank(Omega J) < n_p at a finite point (structural).

    Data that do not bound the parameters (the best fit runs off to infinity) are not this error:
    :func:`identification.identify` returns them as an Estimate with ``bounded`` False.

    Attributes
    ----------
    params : tuple of str
        Parameters that cannot be told apart (largest entries of a null vector).
    sensors : tuple of str
        Sensors that were selected.
    """

    def __init__(self, message: str, params=(), sensors=()):
        super().__init__(message, status="not identifiable")
        self.params = tuple(params)
        self.sensors = tuple(sensors)


class ConvergenceError(IdentificationError):
    """The solver stopped at a stationary point that is not a minimum (a saddle point, or a
    Hessian singular to working precision) and no descent was found from it.

    Attributes
    ----------
    p : ndarray               the point
    eigenvalue : float        smallest eigenvalue of the Hessian in the Gauss-Newton metric
    direction : ndarray       its direction in parameter units
    """

    def __init__(self, message: str, p=None, eigenvalue: float = float("nan"), direction=None, status: str = ""):
        super().__init__(message, status=status or "not a minimum")
        self.p = p
        self.eigenvalue = eigenvalue
        self.direction = direction


class NotBoundedError(IdentificationError):
    """An operation needs a bounded estimate (a finite optimum) but the data do not bound the
    parameters (``Estimate.bounded`` is False): e.g. a confidence ellipsoid, the curvature, a design
    at the estimate.  The message names the parameters that run off."""

    def __init__(self, message: str, status: str = "not bounded"):
        super().__init__(message, status=status)
