"""Published ODE parameter-estimation benchmarks as mudoe models, with their data (issue 30 items 1 and 6).

Four problems of the Floudas et al. "Handbook of test problems in local and global optimization" (1999,
ch. 9.2, after Tjoa & Biegler 1991) as stated in the COPS 3.0 collection (Dolan, Moré & Munson 2004), every
rate bounded below by 0 and unbounded above, a single batch experiment without inputs, unweighted least
squares (sigma unknown and common: ``sigma=None``):

* ``chain``: first-order irreversible chain A -> B -> C, dA/dt = -k1 A, dB/dt = k1 A - k2 B, x(0) = (1, 0),
  A and B measured at t = 0.1, ..., 1.  Data: the handbook's table is the exact solution at (k1, k2) =
  (5, 1) rounded to 3 decimals; it is generated here by that rule (optimum (5.0016, 0.99996); the
  handbook prints (5.0035, 1.0000), so its table may differ from this rounding in a digit).  Bounds [0, 10].
* ``gasoil``: catalytic cracking of gas oil, dy1/dt = -(k1 + k3) y1^2, dy2/dt = k1 y1^2 - k2 y2, y(0) =
  (1, 0); COPS's 20 data at t = 0.025 ... 0.95 (the t = 0 point, equal to y(0), left out).
* ``methanol``: methanol to hydrocarbons, 3 states, 5 rates (rational rate laws); COPS's 16 data at t =
  0.05 ... 1.122 (the t = 0 point left out).
* ``pinene``: thermal isomerisation of alpha-pinene (Box et al. 1973), linear, 5 states all measured,
  5 rates; COPS's 8 data at t = 1230 ... 36420 (min).

``PUBLISHED_START``: COPS's start values (every rate 0 on its lower bound; methanol: every rate 1).
:func:`scipy_fit` is the peer: scipy ``least_squares`` (trf, 2-point Jacobian, tolerances 1e-10) over
``solve_ivp`` (rtol 1e-8, atol 1e-10 of the data's scale) with a given method.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

__all__ = ["Benchmark", "BENCHMARKS", "benchmark", "PUBLISHED_START", "scipy_fit"]

GASOIL_T = (0.025, 0.05, 0.075, 0.10, 0.125, 0.150, 0.175, 0.20, 0.225, 0.250, 0.30, 0.35, 0.40, 0.45, 0.50,
            0.55, 0.65, 0.75, 0.85, 0.95)
GASOIL_Z = ((0.8105, 0.2000), (0.6208, 0.2886), (0.5258, 0.3010), (0.4345, 0.3215), (0.3903, 0.3123),
            (0.3342, 0.2716), (0.3034, 0.2551), (0.2735, 0.2258), (0.2405, 0.1959), (0.2283, 0.1789),
            (0.2071, 0.1457), (0.1669, 0.1198), (0.1530, 0.0909), (0.1339, 0.0719), (0.1265, 0.0561),
            (0.1200, 0.0460), (0.0990, 0.0280), (0.0870, 0.0190), (0.0770, 0.0140), (0.0690, 0.0100))
METHANOL_T = (0.050, 0.065, 0.080, 0.123, 0.233, 0.273, 0.354, 0.397, 0.418, 0.502, 0.553, 0.681, 0.750, 0.916,
              0.937, 1.122)
METHANOL_Z = ((0.7085, 0.1621, 0.0811), (0.5971, 0.1855, 0.0965), (0.5537, 0.1989, 0.1198),
              (0.3684, 0.2845, 0.1535), (0.1712, 0.3491, 0.2097), (0.1198, 0.3098, 0.2628),
              (0.0747, 0.3576, 0.2467), (0.0529, 0.3347, 0.2884), (0.0415, 0.3388, 0.2757),
              (0.0261, 0.3557, 0.3167), (0.0208, 0.3483, 0.2954), (0.0085, 0.3836, 0.2950),
              (0.0053, 0.3611, 0.2937), (0.0019, 0.3609, 0.2831), (0.0018, 0.3485, 0.2846),
              (0.0006, 0.3698, 0.2899))
PINENE_T = (1230.0, 3060.0, 4920.0, 7800.0, 10680.0, 15030.0, 22620.0, 36420.0)
PINENE_Z = ((88.35, 7.3, 2.3, 0.4, 1.75), (76.4, 15.6, 4.5, 0.7, 2.8), (65.1, 23.1, 5.3, 1.1, 5.8),
            (50.4, 32.9, 6.0, 1.5, 9.3), (37.5, 42.7, 6.0, 1.9, 12.0), (25.9, 49.1, 5.9, 2.2, 17.0),
            (14.0, 57.4, 5.1, 2.6, 21.0), (4.5, 63.1, 3.8, 2.9, 25.7))

PUBLISHED_START = {"chain": (0.0, 0.0), "gasoil": (0.0, 0.0, 0.0), "methanol": (1.0,) * 5, "pinene": (0.0,) * 5}


@dataclass(frozen=True)
class Benchmark:
    """One problem: its right-hand side (for both mudoe and scipy), initial state, data and bounds."""

    name: str
    rhs: object            # rhs(x, p) -> list of expressions (CasADi or NumPy)
    x0: tuple
    times: np.ndarray
    z: np.ndarray          # (n_t, n_x): every state measured
    lower: float
    upper: float

    @property
    def n_p(self) -> int:
        return len(PUBLISHED_START[self.name])

    def model(self):
        """The problem as a mudoe ``Model.ode`` (no inputs, every state a sensor)."""
        from models import Model
        from models.contract import Parameter
        n_x = len(self.x0)
        names = [f"x{i + 1}" for i in range(n_x)]
        return Model.ode([Parameter(f"k{i + 1}", self.lower, self.upper) for i in range(self.n_p)], states=names,
                         inputs=[], sensors=names, rhs=lambda x, p, u: ca.vertcat(*self.rhs(x, p)),
                         x0=lambda p, u: ca.DM(self.x0), h=lambda x, p, u: x, name=self.name)

    def data(self):
        """One experiment, one series, sigma unknown (unweighted least squares)."""
        from identification import DynamicMeasurements
        names = [f"x{i + 1}" for i in range(len(self.x0))]
        return DynamicMeasurements(None, self.times, self.z[None, None], None, sensors=names)


def _chain(x, p):
    return [-p[0] * x[0], p[0] * x[0] - p[1] * x[1]]


def _gasoil(x, p):
    return [-(p[0] + p[2]) * x[0] ** 2, p[0] * x[0] ** 2 - p[1] * x[1]]


def _methanol(y, p):
    d = (p[1] + p[4]) * y[0] + y[1]
    return [-(2 * p[0] - p[0] * y[1] / d + p[2] + p[3]) * y[0], p[0] * y[0] * (p[1] * y[0] - y[1]) / d + p[2] * y[0],
            p[0] * y[0] * (y[1] + p[4] * y[0]) / d + p[3] * y[0]]


def _pinene(y, p):
    return [-(p[0] + p[1]) * y[0], p[0] * y[0], p[1] * y[0] - (p[2] + p[3]) * y[2] + p[4] * y[4], p[2] * y[2],
            p[3] * y[2] - p[4] * y[4]]


def _chain_data():
    t = np.arange(1, 11) * 0.1
    return t, np.column_stack([np.round(np.exp(-5 * t), 3), np.round(1.25 * (np.exp(-t) - np.exp(-5 * t)), 3)])


def benchmark(name: str) -> Benchmark:
    """The benchmark ``name`` (one of :data:`BENCHMARKS`)."""
    if name == "chain":
        t, z = _chain_data()
        return Benchmark("chain", _chain, (1.0, 0.0), t, z, 0.0, 10.0)
    if name == "gasoil":
        return Benchmark("gasoil", _gasoil, (1.0, 0.0), np.array(GASOIL_T), np.array(GASOIL_Z), 0.0, np.inf)
    if name == "methanol":
        return Benchmark("methanol", _methanol, (1.0, 0.0, 0.0), np.array(METHANOL_T), np.array(METHANOL_Z), 0.0,
                         np.inf)
    if name == "pinene":
        return Benchmark("pinene", _pinene, (100.0, 0.0, 0.0, 0.0, 0.0), np.array(PINENE_T), np.array(PINENE_Z), 0.0,
                         np.inf)
    raise ValueError(f"name: expected one of {', '.join(BENCHMARKS)}, got {name!r}")


BENCHMARKS = ("chain", "gasoil", "methanol", "pinene")


def scipy_fit(b: Benchmark, p0, method: str = "LSODA", rtol: float = 1e-8) -> dict:
    """scipy ``least_squares`` (trf, 2-point Jacobian, ftol = xtol = gtol = 1e-10, the bounds) over
    ``solve_ivp(method, rtol, atol = 1e-10 max |z|)``; returns p, the sum of squares, nfev and the CPU and
    wall seconds of the fit."""
    atol = 1e-10 * float(np.max(np.abs(b.z)))
    t_end = float(b.times[-1])

    def residuals(p):
        sol = solve_ivp(lambda t, x: b.rhs(x, p), (0.0, t_end), b.x0, method=method, t_eval=b.times, rtol=rtol,
                        atol=atol)
        if not sol.success or sol.y.shape[1] != b.times.size:
            return np.full(b.z.size, 1e6)
        return (sol.y.T - b.z).ravel()

    c0, w0 = time.process_time(), time.perf_counter()
    res = least_squares(residuals, np.asarray(p0, float), bounds=(b.lower, b.upper), method="trf", ftol=1e-10,
                        xtol=1e-10, gtol=1e-10)
    return {"p": res.x, "sse": float(2 * res.cost), "nfev": int(res.nfev), "status": int(res.status),
            "cpu_s": time.process_time() - c0, "wall_s": time.perf_counter() - w0}
