"""Reference solutions for dynamic (ODE) models (issue 22), independent of mudoe's own code.

Pure numpy / scipy / CasADi: nothing here imports mudoe, so mudoe's dynamic models can be
checked against it in one process.

* The Pyomo.DoE reactor example (pyomo/contrib/doe/examples/reactor_experiment.py): the Fisher
  information of the ODE itself (exact sensitivities, no discretisation), in Pyomo.DoE's
  convention, by three independent methods: CasADi CVODES forward sensitivities, scipy
  ``solve_ivp`` on the augmented sensitivity system with hand-written partial derivatives, and
  the closed-form solution differentiated by complex step.
* Two example models of the issue, each an :class:`OdeExample` with hand-written partial
  derivatives: the A -> B -> C Arrhenius batch reactor (:func:`batch_reactor`) and a
  mass-spring-damper with a cubic spring (:func:`spring_damper`); seeded data simulators
  (:func:`simulate_data`) and the reference fit (:func:`reference_fit`: scipy ``least_squares``
  over ``solve_ivp``, standard errors by Gauss-Newton from the exact-sensitivity Jacobian).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

# ---------------------------------------------------------------------------------------------
# The Pyomo.DoE reactor example
# ---------------------------------------------------------------------------------------------

#: Pyomo.DoE reactor example (pyomo_doe_reactor_result.json and reactor_experiment.py):
#: parameters in Pyomo's order (A1, A2 in 1/h-like time units of t in [0, 1]; E1, E2 in kJ/mol),
#: R in J/(mol K), the nine control times (also the measurement times), the nominal profile
#: (T = 500 K on [0, 0.125), 300 K after) and the measurement standard deviation of CA, CB, CC.
PYOMO_DOE_REACTOR = {
    "params": ("A1", "A2", "E1", "E2"),
    "p": (84.79, 371.72, 7.78, 15.05),
    "R": 8.314,
    "CA0": 5.0,
    "times": tuple(0.125 * i for i in range(9)),
    "T": (500.0,) + (300.0,) * 8,
    "sigma": 1e-2,
}


def _reactor_profile(ca0, temperatures, params):
    """Checked (p, T, t) of the Pyomo.DoE reactor: defaults from :data:`PYOMO_DOE_REACTOR`."""
    ref = PYOMO_DOE_REACTOR
    p = np.asarray(ref["p"] if params is None else params, dtype=float)
    T = np.asarray(ref["T"] if temperatures is None else temperatures, dtype=float)
    t = np.asarray(ref["times"])
    if p.shape != (4,) or np.any(p <= 0):
        raise ValueError(f"params: expected 4 positive values (A1, A2, E1, E2), got {p!r}")
    if T.shape != t.shape or np.any(T <= 0):
        raise ValueError(f"temperatures: expected {t.size} positive values (K) at times {t.tolist()}, got {T!r}")
    if not ca0 > 0:
        raise ValueError(f"ca0: expected a positive initial concentration, got {ca0!r}")
    return p, T, t


def _reactor_closed_form(ca0, p, T, t):
    """(CA, CB, CC) at the times t of dCA/dt = -k1 CA, dCB/dt = k1 CA - k2 CB, exact.

    k_i = A_i exp(-1000 E_i / (R T)); T(t) = T_j on [t_j, t_j+1). Works for complex p (complex
    step). Returns shape (3, n_t).
    """
    R = PYOMO_DOE_REACTOR["R"]
    ca, cb = ca0 + 0 * p[0], 0 * p[0]
    out = [(ca, cb)]
    for j in range(t.size - 1):
        k1 = p[0] * np.exp(-1000.0 * p[2] / (R * T[j]))
        k2 = p[1] * np.exp(-1000.0 * p[3] / (R * T[j]))
        tau = t[j + 1] - t[j]
        e1, e2 = np.exp(-k1 * tau), np.exp(-k2 * tau)
        ca, cb = ca * e1, cb * e2 + ca * k1 / (k2 - k1) * (e1 - e2)
        out.append((ca, cb))
    ca, cb = np.array(out).T
    return np.array([ca, cb, ca0 - ca - cb])


def _reactor_sens_closed(ca0, p, T, t):
    """dy/dln p by complex step on the closed form; (n_y, 4) with y = (CA(t), CB(t), CC(t))."""
    h = 1e-30
    cols = []
    for j in range(4):
        pc = p.astype(complex)
        pc[j] = p[j] * (1 + 1j * h)
        cols.append(_reactor_closed_form(ca0, pc, T, t).imag.ravel() / h)
    return _reactor_closed_form(ca0, p, T, t).ravel(), np.array(cols).T


def _reactor_partials(x, p, T):
    """f, df/dx, df/dp of the Pyomo.DoE reactor ODE at one temperature (hand-written)."""
    R = PYOMO_DOE_REACTOR["R"]
    c = 1000.0 / (R * T)
    k1, k2 = p[0] * np.exp(-p[2] * c), p[1] * np.exp(-p[3] * c)
    ca, cb = x
    f = np.array([-k1 * ca, k1 * ca - k2 * cb])
    fx = np.array([[-k1, 0.0], [k1, -k2]])
    # d k1/d A1 = k1/A1, d k1/d E1 = -c k1 (and the same for k2)
    fp = np.array([[-k1 / p[0] * ca, 0.0, c * k1 * ca, 0.0],
                   [k1 / p[0] * ca, -k2 / p[1] * cb, -c * k1 * ca, c * k2 * cb]])
    return f, fx, fp


def _reactor_sens_scipy(ca0, p, T, t, rtol):
    """dy/dln p by scipy solve_ivp (DOP853) on the augmented sensitivity system, interval by interval."""
    z = np.concatenate([[ca0, 0.0], np.zeros(8)])
    states = [z]
    for j in range(t.size - 1):
        def rhs(_, zz, Tj=T[j]):
            x, S = zz[:2], zz[2:].reshape(2, 4)
            f, fx, fp = _reactor_partials(x, p, Tj)
            return np.concatenate([f, (fx @ S + fp).ravel()])
        sol = solve_ivp(rhs, (t[j], t[j + 1]), z, method="DOP853", rtol=rtol, atol=rtol * 1e-3)
        if not sol.success:
            raise RuntimeError(f"solve_ivp failed on [{t[j]}, {t[j + 1]}]: {sol.message}")
        z = sol.y[:, -1]
        states.append(z)
    Z = np.array(states)
    x, S = Z[:, :2], Z[:, 2:].reshape(-1, 2, 4) * p
    y = np.concatenate([x[:, 0], x[:, 1], ca0 - x[:, 0] - x[:, 1]])
    Sy = np.concatenate([S[:, 0], S[:, 1], -S[:, 0] - S[:, 1]])
    return y, Sy


def _reactor_sens_cvodes(ca0, p, T, t, rtol):
    """dy/dln p by CasADi CVODES forward sensitivities (the integrator's derivative in forward mode)."""
    import casadi as ca

    x, P, Tc, dt = ca.SX.sym("x", 2), ca.SX.sym("p", 4), ca.SX.sym("T"), ca.SX.sym("dt")
    c = 1000.0 / (PYOMO_DOE_REACTOR["R"] * Tc)
    k1, k2 = P[0] * ca.exp(-P[2] * c), P[1] * ca.exp(-P[3] * c)
    ode = dt * ca.vertcat(-k1 * x[0], k1 * x[0] - k2 * x[1])
    opts = {"abstol": rtol * 1e-3, "reltol": rtol, "fsens_err_con": True, "max_num_steps": 100000}
    F = ca.integrator("F", "cvodes", {"x": x, "p": ca.vertcat(P, Tc, dt), "ode": ode}, 0.0, 1.0, opts)
    lnp = ca.MX.sym("lnp", 4)
    pm = ca.exp(lnp)
    xk, ys = ca.MX(ca.DM([ca0, 0.0])), [ca.MX(ca.DM([ca0, 0.0]))]
    for j in range(t.size - 1):
        xk = F(x0=xk, p=ca.vertcat(pm, T[j], t[j + 1] - t[j]))["xf"]
        ys.append(xk)
    X = ca.horzcat(*ys)
    y = ca.vertcat(X[0, :].T, X[1, :].T, ca0 - X[0, :].T - X[1, :].T)
    G = ca.Function("G", [lnp], [y, ca.jacobian(y, lnp)])
    yv, Sv = G(np.log(p))
    return np.asarray(yv).ravel(), np.asarray(Sv)


def pyomo_doe_reactor_sensitivities(ca0=None, temperatures=None, params=None, method="cvodes", rtol=1e-12):
    r"""Outputs and scaled sensitivities of the Pyomo.DoE reactor ODE, without discretisation.

    .. math:: \dot C_A = -k_1 C_A,\quad \dot C_B = k_1 C_A - k_2 C_B,\quad C_C = C_{A0} - C_A - C_B,
              \quad k_i = A_i \exp(-1000 E_i / (R T(t)))

    with T(t) = T_j on [t_j, t_j+1) (K), C_A(0) = ca0 (mol/L), C_B(0) = 0, E_i in kJ/mol.

    Parameters
    ----------
    ca0 : float, optional
        Initial concentration of A (mol/L); default 5.
    temperatures : array_like of 9 floats, optional
        T at the control times 0, 0.125, ..., 1 (K); the last has no effect on the ODE.
        Default: 500 then 300.
    params : array_like of 4 floats, optional
        (A1, A2, E1, E2); default the example's nominal values.
    method : {"cvodes", "scipy", "closed"}
        CasADi CVODES forward sensitivities, scipy DOP853 on the augmented sensitivity system
        (hand-written partials), or the closed-form solution differentiated by complex step.
    rtol : float
        Relative tolerance of the integrators (ignored by "closed").

    Returns
    -------
    y : ndarray, shape (27,)
        (CA(t_0..t_8), CB(t_0..t_8), CC(t_0..t_8)) in mol/L: Pyomo.DoE's output order.
    S : ndarray, shape (27, 4)
        dy/d ln p = (dy/dp) p, Pyomo.DoE's ``scale_nominal_param_value=True`` convention.
    """
    ca0 = PYOMO_DOE_REACTOR["CA0"] if ca0 is None else float(ca0)
    p, T, t = _reactor_profile(ca0, temperatures, params)
    if method == "cvodes":
        return _reactor_sens_cvodes(ca0, p, T, t, rtol)
    if method == "scipy":
        return _reactor_sens_scipy(ca0, p, T, t, rtol)
    if method == "closed":
        return _reactor_sens_closed(ca0, p, T, t)
    raise ValueError(f"method: expected 'cvodes', 'scipy' or 'closed', got {method!r}")


def pyomo_doe_reactor_fim(ca0=None, temperatures=None, params=None, method="cvodes", rtol=1e-12):
    r"""Fisher information of the Pyomo.DoE reactor ODE, in Pyomo.DoE's scaled convention.

    .. math:: F = S^T S / \sigma^2, \quad S = \partial y / \partial \ln p

    over the 27 outputs (CA, CB, CC at the nine control times), sigma = 0.01 mol/L, no prior:
    what ``DesignOfExperiments(..., scale_nominal_param_value=True, scale_constant_value=1,
    prior_FIM=None).compute_FIM()`` approximates on its collocation grid. Arguments as in
    :func:`pyomo_doe_reactor_sensitivities`. Returns the (4, 4) FIM for (A1, A2, E1, E2)
    (dimensionless).
    """
    _, S = pyomo_doe_reactor_sensitivities(ca0, temperatures, params, method, rtol)
    return S.T @ S / PYOMO_DOE_REACTOR["sigma"] ** 2


def log10_det(F):
    """log10 det F of a symmetric positive definite matrix (Cholesky; raises if not SPD)."""
    L = np.linalg.cholesky(np.asarray(F, dtype=float))
    return float(2.0 * np.sum(np.log10(np.diag(L))))
