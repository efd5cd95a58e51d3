r"""The diagnosis of an element without a collocation solution: does x' = f(x, p, u(t)) blow up, or is the element
too stiff for collocation?

Only a diagnostic for the failure message (:func:`models.element_march.march_failure`), never part of the numerics, and
lazy: an :class:`ElementFailure` diagnoses when its message is read (or :func:`blow_up_of` is asked, e.g. at the
start values), so line searches that catch failed state solves and halve pay nothing.  The
failing experiment is integrated from t = 0 (x0(p, u), not the collocation's states, which a blow-up spoils) by
SciPy's ``solve_ivp`` (Radau, implicit: stiff trajectories pass) up to the horizon, stopped where max |x| exceeds
:data:`BLOW_UP_FACTOR` (1 + max |x(0)|).  A trajectory stopped there (or one whose integration stalls with
|x| already large) blows up near the stop time; one that stays finite to the horizon exists, and the element is
too stiff for the collocation polynomial.  Models with algebraic states are not diagnosed (None).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import BlowUpError, StateSolveError

__all__ = ["BlowUp", "diagnose_element", "ElementFailure", "blow_up_of", "BLOW_UP_FACTOR"]

#: |x| above BLOW_UP_FACTOR (1 + max |x(0)|) counts as infinite (x' = x^2 from 1 reaches it 1e-6 before t* = 1)
BLOW_UP_FACTOR = 1e6


@dataclass(frozen=True)
class BlowUp:
    """The diagnosis of a failed element: ``blows_up`` with the last time ``t`` where the trajectory was finite
    (below the bound), or not (the trajectory stays finite through ``t``, the horizon)."""
    blows_up: bool
    t: float

    def phrase(self) -> str:
        """The words of the failure message."""
        if self.blows_up:
            return f"the trajectory blows up (|x| -> inf near t = {self.t:.4g})"
        return f"the trajectory stays finite up to t = {self.t:.4g}: the ODE is too stiff for the element"


def diagnose_element(dyn, p, q, horizon: float) -> BlowUp | None:
    r"""x' = f(x, p, u(t)), x(0) = x0(p, u) integrated over [0, horizon] (solve_ivp, Radau, rtol 1e-8) to tell a
    blow-up from a stiff element; None for a model with algebraic states or when the integration itself fails
    with |x| still moderate (undecided).

    Parameters
    ----------
    dyn : models.dynamic.DynamicModel      the model (``rhs_fun``, ``x0_fun``, ``u_at``)
    p : array (n_p,)                       the parameters
    q : array (n_q,)                       the experiment's input row
    horizon : float                        the end of the experiment (time unit)
    """
    from scipy.integrate import solve_ivp
    if dyn.n_z:
        return None
    p, z = np.asarray(p, float), np.zeros(0)
    x_start = np.asarray(dyn.x0_fun(p, dyn.u_at(q, 0.0, 0.0)), float).ravel()
    bound = BLOW_UP_FACTOR * (1.0 + float(np.max(np.abs(x_start), initial=0.0)))

    jac = _rhs_jacobian(dyn)

    def f(t, x):
        return np.asarray(dyn.rhs_fun(x, z, p, dyn.u_at(q, t, t)), float).ravel()

    def df(t, x):
        return np.asarray(jac(x, p, dyn.u_at(q, t, t)), float)

    def too_large(t, x):
        return bound - float(np.max(np.abs(x))) if np.all(np.isfinite(x)) else -1.0
    too_large.terminal = True
    try:
        with np.errstate(all="ignore"):
            sol = solve_ivp(f, (0.0, horizon), x_start, method="Radau", rtol=1e-8, atol=1e-10, jac=df,
                            events=too_large)
    except (ValueError, ArithmeticError, np.linalg.LinAlgError, RuntimeError):     # e.g. inf in df/dx: undecided
        return None
    if sol.status == 1:
        return BlowUp(True, float(sol.t_events[0][0]))
    x_last = sol.y[:, -1]
    if sol.status == -1:                     # stalled: a blow-up when |x| has already grown a lot
        grown = not np.all(np.isfinite(x_last)) or np.max(np.abs(x_last)) > np.sqrt(bound)
        return BlowUp(True, float(sol.t[-1])) if grown else None
    return BlowUp(False, float(sol.t[-1]))


def _rhs_jacobian(dyn):
    """df/dx of the right-hand side (CasADi, exact), a function of (x, p, u)."""
    import casadi as ca
    x, p, u = ca.SX.sym("x", dyn.n_x), ca.SX.sym("p", dyn.n_p), ca.SX.sym("u", dyn.n_u)
    return ca.Function("rhs_jac", [x, p, u], [ca.jacobian(dyn.rhs_fun(x, ca.SX(0, 1), p, u), x)])


class ElementFailure(StateSolveError):
    """No collocation solution on an element: the message (``where``, the element and experiment) completed on
    first reading by the diagnosis of :func:`diagnose_element` (blows up near t, or too stiff for the element).

    Pickles as a plain :class:`models.errors.StateSolveError` with the full message (workers send it back)."""

    def __init__(self, where: str, dyn, p, q, horizon: float):
        super().__init__(where)
        self.where, self._args = where, (dyn, np.asarray(p, float), np.asarray(q, float), float(horizon))
        self._diagnosis, self._done = None, False

    def diagnosis(self) -> BlowUp | None:
        """The (cached) diagnosis; None for a DAE or an undecided integration."""
        if not self._done:
            self._diagnosis, self._done = diagnose_element(*self._args), True
        return self._diagnosis

    def __str__(self) -> str:
        d = self.diagnosis()
        if d is None:
            return (f"{self.where} (the trajectory blows up or is too stiff for the element); check p and the inputs, "
                    "or give a finer mesh")
        if d.blows_up:
            return f"{self.where}: {d.phrase()}; check p and the inputs"
        return f"{self.where}: {d.phrase()}; give a finer mesh"

    def __reduce__(self):
        return StateSolveError, (str(self), self.status)


def blow_up_of(exc: BaseException) -> BlowUpError | None:
    """The :class:`models.errors.BlowUpError` (message and time) of a failed state solve whose trajectory blows up
    in finite time, else None (diagnosed here if not yet)."""
    if isinstance(exc, BlowUpError):
        return exc
    if isinstance(exc, ElementFailure):
        d = exc.diagnosis()
        if d is not None and d.blows_up:
            return BlowUpError(str(exc), d.t, exc.status)
    return None
