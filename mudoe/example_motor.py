r"""A control-driven dynamic example: a DC motor with smoothed Coulomb friction under a voltage profile.

Current i (A), speed w (rad/s) and angle theta (rad) of a DC motor driven by the voltage u(t) (V),
piecewise constant on the grid 0, 0.05, ..., 0.45 s, against a constant load torque T_L (N m) per
experiment, at rest at t = 0:

.. math::

    L \dot i = u(t) - R i - K w, \qquad J \dot w = K i - b w - T_c \tanh(w / w_s) - T_L,
    \qquad \dot\theta = w, \qquad i(0) = w(0) = \theta(0) = 0.

Parameters: the resistance R (ohm), the inductance L (H), the motor constant K (N m/A = V s/rad), the
inertia J (kg m^2), the viscous friction b (N m s/rad) and the Coulomb friction T_c (N m), smoothed
over w_s = 2 rad/s.  Variant ``"coulomb"`` (the model above) or ``"viscous"`` (T_c absent: the rival,
wrong for a motor with dry friction).  Experiment inputs: the load T_L (a constant), then the
voltage at the 10 grid points.  Sensors: i, w and theta, sampled every 20 ms over 0.5 s.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from models.contract import Model, Parameter

__all__ = ["build", "P_TRUE", "TIMES", "HORIZON", "VOLTAGE_GRID", "W_SMOOTH"]

P_TRUE = np.array([2.0, 0.05, 0.1, 1.0e-3, 1.0e-3, 0.02])   # R, L, K, J, b, T_c
TIMES = np.round(np.arange(1, 26) * 0.02, 10)                # s
HORIZON = 0.5                                                # s
VOLTAGE_GRID = tuple(np.arange(10) * 0.05)                   # s (0.35 is 0.35000000000000003: round-off only)
W_SMOOTH = 2.0                                               # rad/s


def build(variant: str = "coulomb"):
    """The DC motor (a :class:`models.dynamic.DynamicModel`); variant ``"coulomb"`` or ``"viscous"``."""
    if variant not in ("coulomb", "viscous", "default"):
        raise ValueError(f"variant: unknown {variant!r}; the DC motor has 'coulomb' and 'viscous'")
    coulomb = variant != "viscous"

    def rhs(x, p, u):
        i, w = x[0], x[1]
        friction = p[4] * w + (p[5] * ca.tanh(w / W_SMOOTH) if coulomb else 0.0)
        return ca.vertcat((u[1] - p[0] * i - p[2] * w) / p[1], (p[2] * i - friction - u[0]) / p[3], w)

    params = [Parameter("R", 1e-3, 100.0, scale=2.0, unit="ohm"), Parameter("L", 1e-4, 10.0, scale=0.05, unit="H"),
              Parameter("K", 1e-3, 10.0, scale=0.1, unit="N m/A"),
              Parameter("J", 1e-6, 1.0, scale=1e-3, unit="kg m^2"),
              Parameter("b", 0.0, 1.0, scale=1e-3, unit="N m s/rad")]
    if coulomb:
        params.append(Parameter("Tc", 0.0, 1.0, scale=0.02, unit="N m"))
    return Model.ode(params, states=["i", "w", "theta"], inputs=["TL"], sensors=["i", "w", "theta"], rhs=rhs,
                     x0=lambda p, u: ca.vertcat(0.0, 0.0, 0.0), h=lambda x, p, u: x,
                     controls={"u": {"grid": VOLTAGE_GRID, "kind": "constant", "unit": "V"}}, horizon=HORIZON,
                     name=f"DC motor {variant}", state_units=("A", "rad/s", "rad"),
                     sensor_units=("A", "rad/s", "rad"), input_units=("N m", "V"), time_unit="s",
                     description="DC motor, voltage profile, load torque, viscous (and Coulomb) friction")
