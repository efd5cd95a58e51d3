"""Small reference models used in tests, benchmarks and examples."""
from __future__ import annotations

import casadi as ca
import numpy as np

from .contract import Model, Parameter

__all__ = ["spring_chain", "linear_model", "two_bar_truss", "equilibrium_dae"]


def spring_chain(n_y: int = 30, n_sensors: int = 4, n_groups: int = 1) -> Model:
    """A chain of n_y nodes joined by hardening springs, fixed at one end.

    State equation (N): for node i = 1..n_y with displacement u_i (mm), u_0 = 0,

        E_i = f_i(u_i - u_{i-1}) - f_{i+1}(u_{i+1} - u_i) - Q_i(q) = 0,
        f_i(d) = k a_i d + c k a_i d^3,   a_i = 1 + 0.5 sin(i)   (f_{n_y+1} = 0),

    loads Q: q_1 (N) at the free end, q_2 (N) at the middle node.  Parameters: k (N/mm),
    c (1/mm^2).  Sensors: displacements (mm) of n_sensors nodes spread along the chain.
    With ``n_groups > 1`` the springs fall into that many consecutive groups with their own
    stiffness k1..kG (N/mm), for benchmarks with more parameters.
    """
    if n_y < 2:
        raise ValueError(f"n_y must be at least 2, got {n_y}")
    n_sensors = int(min(n_sensors, n_y))
    if not 1 <= n_groups <= n_y:
        raise ValueError(f"n_groups must lie in [1, n_y], got {n_groups}")
    a = 1.0 + 0.5 * np.sin(np.arange(1, n_y + 1))
    nodes = np.unique(np.linspace(n_y - 1, 0, n_sensors, endpoint=False).round().astype(int))[::-1]
    mid = n_y // 2

    groups = np.minimum(np.arange(n_y) * n_groups // n_y, n_groups - 1)

    def E(y, p, q):
        k = ca.vertcat(*[p[g] for g in groups]) if n_groups > 1 else p[0]
        c = p[n_groups]
        d = y - ca.vertcat(0, y[:-1])                     # elongation of spring i (between i-1 and i)
        f = k * ca.DM(a) * (d + c * d ** 3)               # spring forces
        f_next = ca.vertcat(f[1:], 0)
        load = ca.SX.zeros(n_y)
        load[n_y - 1] = q[0]
        load[mid] = load[mid] + q[1]
        return f - f_next - load

    def h(y, p, q):
        return ca.vertcat(*[y[i] for i in nodes])

    ks = [Parameter("k", 1e-9, 1e9, unit="N/mm")] if n_groups == 1 else \
        [Parameter(f"k{g + 1}", 1e-9, 1e9, unit="N/mm") for g in range(n_groups)]
    return Model(ks + [Parameter("c", -1e9, 1e9, unit="1/mm^2")],
                 inputs=["q_tip", "q_mid"], sensors=[f"u{i + 1}" for i in nodes], n_y=n_y, E=E, h=h,
                 name=f"spring chain (n_y={n_y})", sensor_units=["mm"] * len(nodes), input_units=["N", "N"])


def linear_model(X_by_sensor) -> Model:
    """An explicit linear model z_k = x_k(q)^T p with a fixed design per sensor (for exactness tests).

    ``X_by_sensor`` is an array (n_S, n_p); the input q scales the design: h_k = q * X[k] @ p.
    """
    X = np.asarray(X_by_sensor, float)
    n_S, n_p = X.shape
    return Model.explicit([f"b{i + 1}" for i in range(n_p)], ["q"], [f"s{k + 1}" for k in range(n_S)],
                          h=lambda p, q: q[0] * (ca.DM(X) @ p), name="linear")


def two_bar_truss(name: str = "two-bar truss", sensors: tuple = ("P_x", "P_y")) -> Model:
    """The README's two-bar truss: bars of stiffness k1, k2 (N/mm) from walls A (0, 0) and
    B (800, 0) mm to the hook P (300, -400) mm, loaded by F (N) downwards; sensors a subset of
    P_x, P_y (mm)."""
    from .mechanism import Bar, Joint, Load, MechParameter, Mechanism, Support, build_model
    mech = Mechanism(
        "two_bar_truss",
        joints=[Joint("A", 0.0, 0.0), Joint("B", 800.0, 0.0), Joint("P", 300.0, -400.0)],
        elements=[Bar("1", "A", "P", "k1"), Bar("2", "B", "P", "k2"),
                  Support("wall_A", "A", kx=1e6, ky=1e6), Support("wall_B", "B", kx=1e6, ky=1e6),
                  Load("hook", "P", fy=-1.0, input="F")],
        parameters=[MechParameter("k1", 200.0, 1.0, 1e5, 200.0, "N/mm"),
                    MechParameter("k2", 300.0, 1.0, 1e5, 300.0, "N/mm")],
        inputs=("F",), sensors=tuple(sensors))
    return build_model(mech, unknowns=("k1", "k2"), name=name)


def equilibrium_dae(name: str = "dynamic model"):
    r"""An index-1 DAE: A -> S (k1), S = B + C in fast equilibrium C = K B^2, B consumed (k2).

    .. math::

        c_A' = -k_1 c_A + u_\mathrm{feed}(t), \quad c_S' = k_1 c_A - k_2 c_B, \quad
        0 = c_B + c_C - c_S, \quad 0 = c_C - K c_B^2   \qquad [\mathrm{mol/L},\ \mathrm{h}],

    c_A(0) = cA0 (the input), c_S(0) = 0; a piecewise-constant feed of A on the grid 0, 1, 2 h over a horizon of
    3 h; outputs cA, cB, cC.  Parameters k1, k2 (1/h), K (L/mol).  Used by the DAE tests and benchmark.
    """
    return Model.ode(["k1", "k2", "K"], ["cA", "cS"], ["cA0"], ["cA", "cB", "cC"],
                     rhs=lambda x, z, p, u: ca.vertcat(-p[0] * x[0] + u[1], p[0] * x[0] - p[1] * z[0]),
                     alg=lambda x, z, p, u: ca.vertcat(z[0] + z[1] - x[1], z[1] - p[2] * z[0] ** 2),
                     algebraic=["cB", "cC"], x0=lambda p, u: ca.vertcat(u[0], 0.0),
                     h=lambda x, z, p, u: ca.vertcat(x[0], z[0], z[1]),
                     controls={"feed": {"grid": [0.0, 1.0, 2.0]}}, horizon=3.0, name=name)
