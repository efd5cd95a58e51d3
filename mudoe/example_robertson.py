r"""A stiff dynamic example: Robertson's chemical kinetics (H. H. Robertson, 1966).

Three species, one batch run (no experiment inputs), time t in s:

.. math::

    \dot y_1 = -k_1 y_1 + k_2 y_2 y_3, \qquad
    \dot y_2 = k_1 y_1 - k_2 y_2 y_3 - k_3 y_2^2, \qquad
    \dot y_3 = k_3 y_2^2, \qquad y(0) = (1, 0, 0),

with k = (0.04 1/s, 1e4 1/s, 3e7 1/s) (per unit mole fraction for the second-order steps).  The
intermediate y_2 rises within ~1e-3 s to a quasi-steady level of ~3.6e-5 while y_1 decays over ~1e4 s: time
scales 1e-3 s to 1e5 s (the Jacobian's eigenvalues reach -1e4 1/s).  The collocation (Radau IIA, L-stable)
takes elements of 1e3-1e4 s where the sampling asks for them; the error of the mesh is estimated against
every element halved and refined until below 1 % of sigma (:mod:`identification.fit.dynamic_fit`), and an
element whose plain Newton solve fails is solved by Newton with a line search (:mod:`models.element_rescue`).

Sensors: the mole fractions y_1, y_2, y_3 (instrument sigmas :data:`SIGMA`: 1e-3 for y_1 and y_3, 1e-7 for
the trace intermediate y_2).  Without y_2 only k_1 and k_2 / sqrt(k_3) are determined (the quasi-steady state
hides the fast pair), which ``identify`` reports as a run-off.

Parametrisations (``build(variant)``):

* ``"rates"`` (default): p = (k_1, k_2, k_3), each :class:`models.Parameter` with its typical magnitude as
  ``scale`` (0.04, 1e4, 3e7) and the lower bound 0.  The scales make the fit and the designs well
  conditioned; give them for your own rates of very different sizes.
* ``"log10"``: p = (log10 k_1, log10 k_2, log10 k_3) (-1.398, 4, 7.477), unbounded, scale 1: standard errors
  read as relative errors / ln 10, and no bound can be hit.  Both give the same fit (the same minimum, the
  rates' standard errors ln 10 k se(log10 k) to first order).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from models.contract import Model, Parameter

__all__ = ["build", "rates", "RATES", "P_TRUE", "P_LOG10", "SIGMA", "TIMES", "HORIZON", "CANDIDATE_TIMES", "rhs_numpy",
           "jacobian_numpy"]

RATES = np.array([0.04, 1e4, 3e7])                          # k1, k2, k3 (1/s)
P_TRUE = RATES                                              # the "rates" variant's truth
P_LOG10 = np.log10(RATES)                                   # the "log10" variant's truth
SIGMA = np.array([1e-3, 1e-7, 1e-3])                        # y1, y2, y3 (mole fractions)
HORIZON = 1e5                                               # s
TIMES = np.logspace(np.log10(0.4), np.log10(4e4), 12)       # sampling times (s), log-spaced
CANDIDATE_TIMES = np.logspace(-3, 5, 25)                    # candidate sampling times of a design (s)


def rates(p, variant: str = "rates"):
    """k (1/s) from the parameters of a variant (CasADi expressions or arrays)."""
    if variant == "log10":
        return 10.0 ** p if isinstance(p, np.ndarray) else ca.power(10.0, p)
    return p


def build(variant: str = "rates"):
    """Robertson's kinetics (a :class:`models.dynamic.DynamicModel`); variant ``"rates"`` or ``"log10"``."""
    if variant not in ("rates", "log10", "default"):
        raise ValueError(f"variant: unknown {variant!r}; the Robertson example has 'rates' and 'log10'")
    log = variant == "log10"

    def rhs(x, p, u):
        k = rates(p, "log10" if log else "rates")
        r1, r2, r3 = k[0] * x[0], k[1] * x[1] * x[2], k[2] * x[1] ** 2
        return ca.vertcat(-r1 + r2, r1 - r2 - r3, r3)

    if log:
        params = [Parameter(f"log10_k{i + 1}", -np.inf, np.inf, scale=1.0, unit="log10(1/s)") for i in range(3)]
    else:
        params = [Parameter(f"k{i + 1}", 0.0, np.inf, scale=float(k), unit="1/s") for i, k in enumerate(RATES)]
    return Model.ode(params, states=["y1", "y2", "y3"], inputs=[], sensors=["y1", "y2", "y3"], rhs=rhs,
                     x0=lambda p, u: ca.vertcat(1.0, 0.0, 0.0), h=lambda x, p, u: x, horizon=HORIZON,
                     name=f"Robertson {'log10' if log else 'rates'}", state_units=("mol/mol",) * 3,
                     sensor_units=("mol/mol",) * 3, time_unit="s",
                     description="Robertson's stiff kinetics A -> B, B + C -> A + C, 2B -> B + C")


def rhs_numpy(t, y, k):
    """dy/dt of Robertson's kinetics for scipy's ``solve_ivp`` (k: the three rates, 1/s)."""
    return [-k[0] * y[0] + k[1] * y[1] * y[2], k[0] * y[0] - k[1] * y[1] * y[2] - k[2] * y[1] ** 2,
            k[2] * y[1] ** 2]


def jacobian_numpy(t, y, k):
    """d(dy/dt)/dy of :func:`rhs_numpy` (for the implicit methods of ``solve_ivp``)."""
    return np.array([[-k[0], k[1] * y[2], k[1] * y[1]],
                     [k[0], -k[1] * y[2] - 2 * k[2] * y[1], -k[1] * y[1]],
                     [0.0, 2 * k[2] * y[1], 0.0]])
