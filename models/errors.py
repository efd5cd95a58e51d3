"""Exceptions of the model layer's numerics (the state solve)."""


class NumericsError(RuntimeError):
    """A numerical solve failed (base of the state-solve and the estimator's solver errors).

    Attributes
    ----------
    status : str
        The solver's return status (e.g. Ipopt's ``return_status``), or "" if it has none.
    """

    def __init__(self, message: str, status: str = ""):
        super().__init__(message)
        self.status = status


class StateSolveError(NumericsError):
    """Newton's method on E(y, p, q) = 0 did not converge, or dE/dy could not be factorised."""


class BlowUpError(StateSolveError):
    """The state solve failed because x(t) blows up in finite time (|x| -> inf near ``t``, within the horizon).

    Attributes
    ----------
    t : float
        The last time where the trajectory was finite (below the bound of :mod:`models.blow_up`), time unit.
    """

    def __init__(self, message: str, t: float, status: str = ""):
        super().__init__(message, status)
        self.t = t
