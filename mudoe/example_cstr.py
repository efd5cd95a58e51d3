r"""An own-model example that is not a press: a continuous stirred tank reactor at steady state.

Reactions A -> B -> C in a CSTR with residence time tau (min) and feed concentration C_A0 of A;
the first reaction follows Arrhenius' law,

.. math::

    k_1(T) = k_{ref} \exp\Bigl(-\frac{E_a}{R}\Bigl(\frac{1}{T} - \frac{1}{T_{ref}}\Bigr)\Bigr),

the second has a temperature-independent rate k_2.  States y = (C_A, C_B) (mmol/L) solve the
steady-state balances E(y, p, T) = 0:

.. math::

    \frac{C_{A0} - C_A}{\tau} - k_1(T) C_A = 0, \qquad -\frac{C_B}{\tau} + k_1(T) C_A - k_2 C_B = 0,

and the sensors read C_A, C_B and C_C = C_A0 - C_A - C_B (mmol/L) and the conversion
X_A = 100 (1 - C_A / C_A0) (%).  Parameters: k_ref (1/min, at
T_ref = 323.15 K), E_a (kJ/mol), k_2 (1/min); input: the temperature T (K).  The study
``configs/cstr.toml`` keeps its data in degC and mol/L, converted once to K and mmol/L.
"""
from __future__ import annotations

import casadi as ca

from models.contract import Model, Parameter

__all__ = ["build", "TAU_MIN", "C_A0", "T_REF", "R_KJ"]

TAU_MIN = 10.0          # residence time (min)
C_A0 = 1000.0           # feed concentration of A (mmol/L)
T_REF = 323.15          # reference temperature (K)
R_KJ = 8.314462618e-3   # gas constant (kJ/(mol K))


def build(variant: str = "arrhenius") -> Model:
    """The CSTR model (variant ``"arrhenius"``; the only one)."""
    if variant not in ("arrhenius", "default"):
        raise ValueError(f"variant: unknown {variant!r}; the CSTR example has 'arrhenius'")

    def k1(p, q):
        return p[0] * ca.exp(-p[1] / R_KJ * (1.0 / q[0] - 1.0 / T_REF))

    def E(y, p, q):
        return ca.vertcat((C_A0 - y[0]) / TAU_MIN - k1(p, q) * y[0],
                          -y[1] / TAU_MIN + k1(p, q) * y[0] - p[2] * y[1])

    def h(y, p, q):
        return ca.vertcat(y[0], y[1], C_A0 - y[0] - y[1], 100.0 * (1.0 - y[0] / C_A0))

    def y_guess(p, q):
        return [C_A0 / 2, C_A0 / 4]

    params = [Parameter("k_ref", 1e-6, 10.0, scale=0.1, unit="1/min"),
              Parameter("E_a", 1.0, 300.0, scale=50.0, unit="kJ/mol"),
              Parameter("k_2", 1e-6, 10.0, scale=0.05, unit="1/min")]
    return Model(params, inputs=["T"], sensors=["C_A", "C_B", "C_C", "X_A"], n_y=2, E=E, h=h,
                 y_guess=y_guess, name=f"CSTR {variant}", sensor_units=("mmol/L",) * 3 + ("%",), input_units=("K",),
                 description="steady-state CSTR, A -> B -> C, Arrhenius first step")
