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
        # k1 (e1 - e2) / (k2 - k1) = k1 tau e1 phi(-d), phi(z) = (e^z - 1) / z, d = (k2 - k1) tau:
        # no cancellation where k1 = k2 (T = 591.6 K at the nominal parameters)
        d = (k2 - k1) * tau
        phi = 1 - d / 2 + d * d / 6 - d ** 3 / 24 if abs(d) < 1e-4 else np.expm1(-d) / -d
        ca, cb = ca * e1, cb * e2 + ca * k1 * tau * e1 * phi
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
    """log10 det F of a symmetric positive semi-definite matrix; -inf if singular to double precision.

    Singular means an eigenvalue <= 1e-13 times the largest (e.g. the reactor at one constant
    temperature, where A_i and E_i cannot be told apart).
    """
    F = np.asarray(F, dtype=float)
    w = np.linalg.eigvalsh(F)
    if w[0] <= 1e-13 * w[-1]:
        return -np.inf
    return float(2.0 * np.sum(np.log10(np.diag(np.linalg.cholesky(F)))))   # more accurate than sum log w


# ---------------------------------------------------------------------------------------------
# Example models of issue 22: constant experiment inputs, hand-written partial derivatives
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class OdeExample:
    """An ODE model dx/dt = f(x, p, u), x(0) = x0(p, u), y = h(x, p, u) with its partials.

    Every callable is vectorised over experiments: p has shape (n_p,), u shape (n_u, m),
    x shape (n_x, m); f and x0 return (n_x, m), h returns (n_y, m); the partials return
    (rows, columns, m): f_x (n_x, n_x, m), f_p (n_x, n_p, m), x0_p (n_x, n_p, m),
    h_x (n_y, n_x, m), h_p (n_y, n_p, m).
    """

    name: str
    params: tuple
    p_true: tuple
    p_start: tuple
    inputs: tuple
    input_bounds: tuple
    states: tuple
    sensors: tuple
    sigma: tuple
    t_end: float
    f: Callable
    f_x: Callable
    f_p: Callable
    x0: Callable
    x0_p: Callable
    h: Callable
    h_x: Callable
    h_p: Callable


def batch_reactor(t_ref=350.0):
    r"""The A -> B -> C batch reactor with Arrhenius rates (time in h, concentrations in mol/L).

    .. math:: \dot c_A = -k_1 c_A,\ \dot c_B = k_1 c_A - k_2 c_B,\ \dot c_C = k_2 c_B,\quad
              k_i = k_{i,ref} \exp(-E_i / R\, (1/T - 1/T_{ref}))

    R = 8.314e-3 kJ/(mol K), T_ref = ``t_ref`` (K). Parameters k1ref, k2ref (1/h), E1, E2
    (kJ/mol); experiment inputs cA0 (mol/L, cB0 = cC0 = 0) and a constant T (K); sensors cA, cB
    with sigma 0.01 mol/L; horizon 5 h.
    """
    R = 8.314e-3

    def rates(p, u):
        g = -(1.0 / u[1] - 1.0 / t_ref) / R          # d ln k_i / d E_i
        return p[0] * np.exp(p[2] * g), p[1] * np.exp(p[3] * g), g

    def f(x, p, u):
        k1, k2, _ = rates(p, u)
        return np.array([-k1 * x[0], k1 * x[0] - k2 * x[1], k2 * x[1]])

    def f_x(x, p, u):
        k1, k2, _ = rates(p, u)
        z = 0 * k1
        return np.array([[-k1, z, z], [k1, -k2, z], [z, k2, z]])

    def f_p(x, p, u):
        k1, k2, g = rates(p, u)
        r1, r2, z = k1 * x[0], k2 * x[1], 0 * k1     # reaction rates and their log-derivatives
        return np.array([[-r1 / p[0], z, -r1 * g, z],
                         [r1 / p[0], -r2 / p[1], r1 * g, -r2 * g],
                         [z, r2 / p[1], z, r2 * g]])

    def x0(p, u):
        return np.array([u[0], 0 * u[0], 0 * u[0]])

    return OdeExample(
        name="batch_reactor", params=("k1ref", "k2ref", "E1", "E2"), p_true=(1.0, 0.5, 60.0, 80.0),
        p_start=(0.7, 0.7, 50.0, 60.0), inputs=("cA0", "T"), input_bounds=((0.5, 2.0), (330.0, 370.0)),
        states=("cA", "cB", "cC"), sensors=("cA", "cB"), sigma=(0.01, 0.01), t_end=5.0,
        f=f, f_x=f_x, f_p=f_p, x0=x0, x0_p=lambda p, u: np.zeros((3, 4, u.shape[1])),
        h=lambda x, p, u: x[:2], h_x=lambda x, p, u: np.broadcast_to(np.eye(2, 3)[:, :, None], (2, 3) + x.shape[1:]),
        h_p=lambda x, p, u: np.zeros((2, 4) + x.shape[1:]))


def spring_damper(mass=1.0):
    r"""A mass-spring-damper with a cubic spring under a step force (SI units).

    .. math:: m \ddot x + c \dot x + k x + k_3 x^3 = F,\quad x(0) = \dot x(0) = 0

    m = ``mass`` (kg, known); parameters c (N s/m), k (N/m), k3 (N/m^3); experiment input the
    step force F (N); sensors the displacement x (m, sigma 0.002) and the acceleration
    a = (F - c v - k x - k3 x^3) / m (m/s^2, sigma 0.02); horizon 10 s.
    """
    m = float(mass)

    def acc(x, p, u):
        return (u[0] - p[0] * x[1] - p[1] * x[0] - p[2] * x[0] ** 3) / m

    def acc_x(x, p):
        return -(p[1] + 3 * p[2] * x[0] ** 2) / m, -p[0] / m + 0 * x[0]   # da/dx, da/dv

    def f_x(x, p, u):
        z, one = 0 * x[0], 1 + 0 * x[0]
        ax = acc_x(x, p)
        return np.array([[z, one], [ax[0], ax[1]]])

    def a_p(x):
        return np.array([-x[1], -x[0], -x[0] ** 3]) / m

    def f_p(x, p, u):
        return np.array([np.zeros((3,) + x.shape[1:]), a_p(x)])

    def h_x(x, p, u):
        z, one = 0 * x[0], 1 + 0 * x[0]
        ax = acc_x(x, p)
        return np.array([[one, z], [ax[0], ax[1]]])

    return OdeExample(
        name="spring_damper", params=("c", "k", "k3"), p_true=(0.4, 4.0, 2.0), p_start=(0.3, 3.0, 1.0),
        inputs=("F",), input_bounds=((0.5, 3.0),), states=("x", "v"), sensors=("x", "a"),
        sigma=(0.002, 0.02), t_end=10.0,
        f=lambda x, p, u: np.array([x[1], acc(x, p, u)]), f_x=f_x, f_p=f_p,
        x0=lambda p, u: np.zeros((2,) + u.shape[1:]), x0_p=lambda p, u: np.zeros((2, 3) + u.shape[1:]),
        h=lambda x, p, u: np.array([x[0], acc(x, p, u)]), h_x=h_x,
        h_p=lambda x, p, u: np.array([np.zeros((3,) + x.shape[1:]), a_p(x)]))


def _rhs(ex, p, u, sens):
    """The right-hand side for solve_ivp of m stacked experiments, with sensitivities if sens."""
    n_x, n_p, m = len(ex.states), len(ex.params), u.shape[1]
    if not sens:
        return lambda _, z: ex.f(z.reshape(n_x, m), p, u).ravel()

    def rhs(_, z):
        Z = z.reshape(n_x, 1 + n_p, m)
        x, S = Z[:, 0], Z[:, 1:]
        dS = np.einsum("ijm,jkm->ikm", ex.f_x(x, p, u), S) + ex.f_p(x, p, u)
        return np.concatenate([ex.f(x, p, u)[:, None], dS], axis=1).ravel()
    return rhs


def _integrate(ex, p, u, times, rtol, sens, method):
    """States (n_x, m, n_t) and state sensitivities (n_x, n_p, m, n_t) or None, of m experiments."""
    n_x, n_p, m = len(ex.states), len(ex.params), u.shape[1]
    z0 = ex.x0(p, u)[:, None]
    if sens:
        z0 = np.concatenate([z0, ex.x0_p(p, u)], axis=1)
    sol = solve_ivp(_rhs(ex, p, u, sens), (0.0, times[-1]), z0.ravel(), method=method, t_eval=times,
                    rtol=rtol, atol=1e-2 * rtol)
    if not sol.success:
        raise RuntimeError(f"{ex.name}: solve_ivp failed at p = {p.tolist()}: {sol.message}")
    Z = sol.y.reshape(n_x, 1 + n_p if sens else 1, m, times.size)
    return Z[:, 0], (Z[:, 1:] if sens else None)


def simulate(ex, p, inputs, times, rtol=1e-10, sens=False, method="DOP853", stacked=False):
    r"""Outputs y(t) of every experiment and, with ``sens``, their exact sensitivities dy/dp.

    Integrates dx/dt = f(x, p, u) (and dS/dt = f_x S + f_p, S(0) = dx0/dp) with scipy
    ``solve_ivp``; dy/dp = h_x S + h_p.

    Parameters
    ----------
    ex : OdeExample
    p : array_like, shape (n_p,)
    inputs : array_like, shape (n_exp, n_u)
        One row of constant inputs per experiment.
    times : array_like, shape (n_t,)
        Increasing sampling times >= 0 (the ODE starts at t = 0).
    rtol : float
        solve_ivp's relative tolerance (absolute tolerance 1e-2 rtol).
    sens : bool
        Also integrate the forward sensitivity equations.
    method : str
        solve_ivp's method.
    stacked : bool
        Integrate all experiments as one system (one call, a common step size) instead of one
        ``solve_ivp`` per experiment.

    Returns
    -------
    y : ndarray, shape (n_exp, n_t, n_y)
    S : ndarray, shape (n_exp, n_t, n_y, n_p), only with ``sens``.
    """
    p = np.asarray(p, dtype=float)
    Q = np.atleast_2d(np.asarray(inputs, dtype=float))
    times = np.asarray(times, dtype=float)
    if p.shape != (len(ex.params),):
        raise ValueError(f"p: expected {len(ex.params)} values {ex.params}, got shape {p.shape}")
    if Q.ndim != 2 or Q.shape[1] != len(ex.inputs):
        raise ValueError(f"inputs: expected shape (n_exp, {len(ex.inputs)}) for {ex.inputs}, got {Q.shape}")
    if times.ndim != 1 or times.size == 0 or times[0] < 0 or np.any(np.diff(times) <= 0):
        raise ValueError(f"times: expected increasing sampling times >= 0, got {times!r}")
    blocks = [Q.T] if stacked else [Q[j:j + 1].T for j in range(Q.shape[0])]
    ys, Ss = [], []
    for u in blocks:
        x, S = _integrate(ex, p, u, times, rtol, sens, method)
        m, n_t = u.shape[1], times.size
        xf, uf = x.reshape(x.shape[0], m * n_t), np.repeat(u, n_t, axis=1)
        ys.append(ex.h(xf, p, uf).reshape(-1, m, n_t).transpose(1, 2, 0))
        if sens:
            Sf = S.reshape(S.shape[0], S.shape[1], m * n_t)
            dy = np.einsum("ijk,jpk->ipk", ex.h_x(xf, p, uf), Sf) + ex.h_p(xf, p, uf)
            Ss.append(dy.reshape(dy.shape[0], dy.shape[1], m, n_t).transpose(2, 3, 0, 1))
    y = np.concatenate(ys)
    return (y, np.concatenate(Ss)) if sens else y


@dataclass(frozen=True)
class Dataset:
    """Simulated measurements: inputs (n_exp, n_u), times (n_t,), z (n_exp, n_t, n_y), sigma (n_y,)."""

    inputs: np.ndarray
    times: np.ndarray
    z: np.ndarray
    sigma: np.ndarray
    p_true: np.ndarray
    seed: int


def simulate_data(ex, n_exp, n_times, seed=0, p=None, rtol=1e-12):
    r"""Seeded measurements z = y(t; p) + sigma e, e ~ N(0, I), of ``n_exp`` random experiments.

    The inputs are uniform in ``ex.input_bounds`` and the sampling times equally spaced,
    t_i = i t_end / n_times (i = 1..n_times); both the inputs and then the noise are drawn from
    ``numpy.random.default_rng(seed)``. The truth p defaults to ``ex.p_true``; the outputs are
    integrated with DOP853 at ``rtol``.
    """
    rng = np.random.default_rng(seed)
    p = np.asarray(ex.p_true if p is None else p, dtype=float)
    lo, hi = np.array(ex.input_bounds, dtype=float).T
    Q = lo + (hi - lo) * rng.random((int(n_exp), len(ex.inputs)))
    times = ex.t_end * np.arange(1, int(n_times) + 1) / int(n_times)
    sigma = np.asarray(ex.sigma, dtype=float)
    y = simulate(ex, p, Q, times, rtol=rtol)
    return Dataset(Q, times, y + sigma * rng.standard_normal(y.shape), sigma, p, int(seed))


@dataclass(frozen=True)
class FitResult:
    """A reference fit: estimate, Gauss-Newton covariance and cost (chi2 = sum of squared weighted residuals)."""

    p: np.ndarray
    se: np.ndarray
    cov: np.ndarray
    chi2: float
    n_data: int
    nfev: int
    njev: int
    fit_seconds: float
    cov_seconds: float
    fit_cpu_seconds: float
    cov_cpu_seconds: float
    message: str


def gauss_newton_covariance(ex, p, data, rtol=1e-10, method="DOP853", stacked=False):
    r"""Cov(p) = (J^T J)^{-1}, J = (dy/dp) / sigma from the exact sensitivities at p (known sigma).

    Raises ``numpy.linalg.LinAlgError`` if J^T J is not positive definite (parameters not
    identifiable from these data).
    """
    _, S = simulate(ex, p, data.inputs, data.times, rtol=rtol, sens=True, method=method, stacked=stacked)
    ok = np.isfinite(data.z)
    J = (S / data.sigma[:, None])[ok]
    L = np.linalg.cholesky(J.T @ J)
    Linv = np.linalg.solve(L, np.eye(L.shape[0]))
    return Linv.T @ Linv


def reference_fit(ex, data, p0=None, rtol=1e-10, jac="sens", method="DOP853", stacked=False, tol=1e-10):
    r"""Weighted least squares min_p sum ((y(t; p, u) - z) / sigma)^2 by scipy over solve_ivp.

    ``least_squares(method="trf", x_scale="jac", ftol=xtol=gtol=tol)``; missing data (NaN in z)
    are left out. The Jacobian is the exact one from the forward sensitivities (``jac="sens"``)
    or scipy's finite differences (``jac="2-point"``, what a typical user writes). Standard errors
    by :func:`gauss_newton_covariance` at the estimate (rtol 1e-10 whatever the fit's rtol),
    timed apart from the fit (wall and CPU seconds of this process).
    """
    if jac not in ("sens", "2-point", "3-point"):
        raise ValueError(f"jac: expected 'sens', '2-point' or '3-point', got {jac!r}")
    ok = np.isfinite(data.z)
    zs = (data.z / data.sigma)[ok]
    last = {}

    def evaluate(p):
        key = p.tobytes()
        if last.get("key") != key:
            out = simulate(ex, p, data.inputs, data.times, rtol, jac == "sens", method, stacked)
            last.update(key=key, out=out if jac == "sens" else (out, None))
        return last["out"]

    def fun(p):
        return (evaluate(p)[0] / data.sigma)[ok] - zs

    def jacobian(p):
        return (evaluate(p)[1] / data.sigma[:, None])[ok]

    p0 = np.asarray(ex.p_start if p0 is None else p0, dtype=float)
    t0, c0 = time.perf_counter(), time.process_time()
    res = least_squares(fun, p0, jac=jacobian if jac == "sens" else jac, method="trf", x_scale="jac",
                        ftol=tol, xtol=tol, gtol=tol)
    t1, c1 = time.perf_counter(), time.process_time()
    if res.status <= 0:
        raise RuntimeError(f"{ex.name}: least_squares failed: {res.message}")
    cov = gauss_newton_covariance(ex, res.x, data, method=method, stacked=stacked)
    t2, c2 = time.perf_counter(), time.process_time()
    return FitResult(res.x, np.sqrt(np.diag(cov)), cov, float(2 * res.cost), int(ok.sum()), int(res.nfev),
                     int(res.njev or 0), t1 - t0, t2 - t1, c1 - c0, c2 - c1, str(res.message))


def pyomo_doe_reactor_factorial(ca0_grid=None, t0_grid=None, method="closed"):
    """log10 det of the ODE's FIM on the (CA0, T0) grid of Pyomo.DoE's factorial (T = 300 K after t = 0.125).

    Defaults: 9 x 9 points, CA0 in linspace(1, 5, 9) (mol/L), T0 in linspace(300, 700, 9) (K).
    Returns ``(ca0, t0, log10det)``, each of shape (n_ca0 * n_t0,), CA0 varying slowest (Pyomo's
    order).
    """
    ca0_grid = np.linspace(1, 5, 9) if ca0_grid is None else np.asarray(ca0_grid, dtype=float)
    t0_grid = np.linspace(300, 700, 9) if t0_grid is None else np.asarray(t0_grid, dtype=float)
    rest = PYOMO_DOE_REACTOR["T"][1:]
    C, T0 = (g.ravel() for g in np.meshgrid(ca0_grid, t0_grid, indexing="ij"))
    d = [log10_det(pyomo_doe_reactor_fim(c, (t,) + rest, method=method)) for c, t in zip(C, T0)]
    return C, T0, np.array(d)


def pyomo_doe_reactor_optimal_design(starts=None, bounds_ca0=(1.0, 5.0), bounds_t=(300.0, 700.0)):
    r"""The ODE's D-optimal design of the Pyomo.DoE reactor: max log10 det F(CA0, T_0..T_7).

    T_8 (at t = 1) has no effect on the ODE and is left out. Bounded L-BFGS-B on the closed-form
    FIM from each start (default: Pyomo.DoE's nominal design, its run_doe optimum and two
    linear ramps); the best local optimum is returned as ``(x, log10det)`` with
    x = (CA0, T_0, ..., T_7). A reference only: local search, finite-difference gradients.
    """
    from scipy.optimize import minimize

    rest = np.array(PYOMO_DOE_REACTOR["T"][1:-1])
    if starts is None:
        starts = [np.r_[5.0, 500.0, rest], np.r_[5.0, 481.88, rest], np.r_[3.0, np.linspace(650, 350, 8)],
                  np.r_[3.0, np.linspace(350, 650, 8)]]

    def neg(x):
        v = log10_det(pyomo_doe_reactor_fim(x[0], np.r_[x[1:], x[-1]], method="closed"))
        return -v if np.isfinite(v) else 1e3        # a singular FIM (constant T): rejected

    best = None
    for x0 in starts:
        r = minimize(neg, x0, method="L-BFGS-B", bounds=[bounds_ca0] + [bounds_t] * 8,
                     options={"ftol": 1e-14, "gtol": 1e-10, "maxiter": 2000})
        if best is None or r.fun < best.fun:
            best = r
    return best.x, float(-best.fun)
