r"""A mechanical dynamic example: a mass on a damper and a hardening (cubic) spring under a step force.

Displacement x (m) and velocity v (m/s) of a mass m = 1 kg, at rest at t = 0 when the force F (N) is
switched on:

.. math::

    \dot x = v, \qquad m \dot v = F - c v - k x - k_3 x^3, \qquad x(0) = v(0) = 0.

Parameters: the stiffness k (N/m), the damping c (N s/m) and the cubic stiffness k_3 (N/m^3; at
x = 10 mm it doubles the stiffness of the nominal spring).  Experiment input: the step height F (N).
Sensors: the displacement x in mm and the acceleration a = dv/dt (m/s^2), sampled over 1 s.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from models.contract import Model, Parameter

__all__ = ["build", "MASS", "P_TRUE", "TIMES"]

MASS = 1.0                                   # kg
P_TRUE = np.array([400.0, 4.0, 4.0e6])       # k (N/m), c (N s/m), k3 (N/m^3)
TIMES = np.round(np.arange(1, 51) * 0.02, 10)  # s


def build(variant: str = "cubic"):
    """The spring-damper (a :class:`models.dynamic.DynamicModel`); variant ``"cubic"`` (hardening
    spring) or ``"linear"`` (k3 absent: a wrong model for a hardening spring)."""
    if variant not in ("cubic", "linear", "default"):
        raise ValueError(f"variant: unknown {variant!r}; the spring-damper has 'cubic' and 'linear'")
    cubic = variant != "linear"

    def accel(x, p, u):
        spring = p[0] * x[0] + (p[2] * x[0] ** 3 if cubic else 0.0)
        return (u[0] - p[1] * x[1] - spring) / MASS

    params = [Parameter("k", 1.0, 1e5, scale=400.0, unit="N/m"), Parameter("c", 0.0, 1e3, scale=4.0, unit="N s/m")]
    if cubic:
        params.append(Parameter("k3", -1e9, 1e9, scale=4e6, unit="N/m^3"))
    return Model.ode(params, states=["x", "v"], inputs=["F"], sensors=["x", "a"],
                     rhs=lambda x, p, u: ca.vertcat(x[1], accel(x, p, u)), x0=lambda p, u: ca.vertcat(0.0, 0.0),
                     h=lambda x, p, u: ca.vertcat(1e3 * x[0], accel(x, p, u)),
                     name=f"spring-damper {variant}", state_units=("m", "m/s"), sensor_units=("mm", "m/s^2"),
                     input_units=("N",), time_unit="s", description="mass, damper and cubic spring, step force")
