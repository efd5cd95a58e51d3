r"""The diagnosis of an element without a collocation solution: does x' = f(x, p, u(t)) blow up, or is the element
too stiff for collocation?

Only a diagnostic for the failure message (:func:`models.trajectory.march_failure`), never part of the numerics: the
failing experiment is integrated from t = 0 (x0(p, u), not the collocation's states, which a blow-up spoils) by
SciPy's ``solve_ivp`` (Radau, implicit: stiff trajectories pass) up to the horizon, stopped where max |x| exceeds
:data:`BLOW_UP_FACTOR` (1 + max |x(0)|).  A trajectory stopped there (or one whose integration stalls with
|x| already large) blows up near the stop time; one that stays finite to the horizon exists, and the element is
too stiff for the collocation polynomial.  Models with algebraic states are not diagnosed (None).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BlowUp", "diagnose_element", "BLOW_UP_FACTOR"]

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

    def f(t, x):
        return np.asarray(dyn.rhs_fun(x, z, p, dyn.u_at(q, t, t)), float).ravel()

    def too_large(t, x):
        return bound - float(np.max(np.abs(x))) if np.all(np.isfinite(x)) else -1.0
    too_large.terminal = True
    with np.errstate(all="ignore"):
        sol = solve_ivp(f, (0.0, horizon), x_start, method="Radau", rtol=1e-8, atol=1e-10, events=too_large)
    if sol.status == 1:
        return BlowUp(True, float(sol.t_events[0][0]))
    x_last = sol.y[:, -1]
    if sol.status == -1:                     # stalled: a blow-up when |x| has already grown a lot
        grown = not np.all(np.isfinite(x_last)) or np.max(np.abs(x_last)) > np.sqrt(bound)
        return BlowUp(True, float(sol.t[-1])) if grown else None
    return BlowUp(False, float(sol.t[-1]))
