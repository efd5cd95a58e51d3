"""Exceptions of the identification package (all subclass ValueError or RuntimeError)."""


class DataError(ValueError):
    """Measurements are malformed (shape, NaN-only sensor, non-positive sigma, ...)."""


class IdentificationError(RuntimeError):
    """The estimator could not produce a trustworthy result (solver failure).

    Attributes
    ----------
    status : str
        The solver's return status (e.g. Ipopt's ``return_status``).
    """

    def __init__(self, message: str, status: str = ""):
        super().__init__(message)
        self.status = status


class IdentifiabilityError(IdentificationError):
    """Assumption 3 of the paper fails: rank(Omega J) < n_p.

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


class StateSolveError(IdentificationError):
    """Newton's method on E(y, p, q) = 0 did not converge."""
