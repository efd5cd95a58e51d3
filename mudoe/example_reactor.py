r"""A dynamic example: the isothermal batch reactor A -> B -> C with Arrhenius rates.

States c_A, c_B, c_C (mol/L) over time t (h):

.. math::

    \dot c_A = -k_1 c_A, \qquad \dot c_B = k_1 c_A - k_2 c_B, \qquad \dot c_C = k_2 c_B,
    \qquad c(0) = (c_{A0}, 0, 0),

    k_i(T) = k_{i,ref} \exp\Bigl(-\frac{E_i}{R}\Bigl(\frac{1}{T} - \frac{1}{T_{ref}}\Bigr)\Bigr),

written in the reference-temperature form (T_ref = 350 K) so that k_{i,ref} (1/h) and E_i (kJ/mol)
are not correlated as A_i and E_i of the plain form are.  Experiment inputs: the initial
concentration c_A0 (mol/L) and the temperature T (K): a constant per experiment (variant
``"isothermal"``) or a piecewise-constant profile on the grid 0, 0.25, ..., 1.75 h (variant
``"profile"``: the input row is c_A0, then T at the 8 grid points).  Sensors: c_A and c_B (mol/L).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from models.contract import Model, Parameter

__all__ = ["build", "T_REF", "R_KJ", "P_TRUE", "TIMES", "HORIZON", "PROFILE_GRID"]

T_REF = 350.0                   # reference temperature (K)
R_KJ = 8.314462618e-3           # gas constant (kJ/(mol K))
P_TRUE = np.array([2.0, 60.0, 0.8, 80.0])   # k1_ref (1/h), E1 (kJ/mol), k2_ref (1/h), E2 (kJ/mol)
TIMES = np.linspace(0.2, 2.0, 10)           # sampling times (h)
HORIZON = 2.0                               # h
PROFILE_GRID = tuple(np.arange(8) * 0.25)   # h


def build(variant: str = "isothermal"):
    """The batch reactor (a :class:`models.dynamic.DynamicModel`); variant ``"isothermal"`` or ``"profile"``."""
    if variant not in ("isothermal", "profile", "default"):
        raise ValueError(f"variant: unknown {variant!r}; the batch reactor has 'isothermal' and 'profile'")
    profile = variant == "profile"

    def k(p, T, i):
        return p[2 * i] * ca.exp(-p[2 * i + 1] / R_KJ * (1.0 / T - 1.0 / T_REF))

    def rhs(x, p, u):
        k1, k2 = k(p, u[1], 0), k(p, u[1], 1)
        return ca.vertcat(-k1 * x[0], k1 * x[0] - k2 * x[1], k2 * x[1])

    params = [Parameter("k1_ref", 1e-6, 100.0, scale=1.0, unit="1/h"),
              Parameter("E1", 0.0, 300.0, scale=50.0, unit="kJ/mol"),
              Parameter("k2_ref", 1e-6, 100.0, scale=1.0, unit="1/h"),
              Parameter("E2", 0.0, 300.0, scale=50.0, unit="kJ/mol")]
    kw = dict(controls={"T": {"grid": PROFILE_GRID, "kind": "constant", "unit": "K"}}) if profile else {}
    return Model.ode(params, states=["cA", "cB", "cC"], inputs=["cA0"] if profile else ["cA0", "T"],
                     sensors=["cA", "cB"], rhs=rhs, x0=lambda p, u: ca.vertcat(u[0], 0.0, 0.0),
                     h=lambda x, p, u: x[:2], horizon=HORIZON, name=f"batch reactor {variant}",
                     state_units=("mol/L",) * 3, sensor_units=("mol/L",) * 2, input_units=("mol/L", "K"),
                     time_unit="h", description="batch reactor A -> B -> C, Arrhenius rates", **kw)
