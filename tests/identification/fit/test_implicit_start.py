"""Ipopt started at the reduced-space optimum of an implicit model with many inputs (issue 15)."""
import casadi as ca
import numpy as np
import pytest
from scipy.optimize import least_squares

from identification import IdentifySettings, Measurements, StateSolveError, identify
from identification.fit.implicit_start import solve_states_from
from models import Model
from models.state import solve_states
from optimum import assert_same_optimum

SIG = np.array([0.002, 0.004])


def _springs():
    """Two springs in series under a load F, the second hardening (bench/bench_scale.py)."""
    def E(y, p, q):
        u2 = y[1] - y[0]
        return ca.vertcat(p[0] * y[0] - q[0], p[1] * u2 + p[2] * u2 ** 3 - q[0])
    return Model(["k1", "k2", "k3"], ["F"], ["u1", "y"], n_y=2, E=E, h=lambda y, p, q: y)


def _data(n, seed=3):
    rng = np.random.default_rng(seed)
    F = rng.uniform(0.1, 3.0, n)
    Y = solve_states(_springs(), [2.0, 1.5, 0.8], F[:, None])
    return F, Y + SIG * rng.standard_normal((n, 2))


def _scipy_fit(F, z):
    """Reduced-space peer: states by NumPy Newton, exact Jacobian by the implicit function theorem."""
    def states(p):
        u = F / p[1]
        for _ in range(60):
            u = u - (p[1] * u + p[2] * u ** 3 - F) / (p[1] + 3 * p[2] * u ** 2)
        return F / p[0], u

    def fun(p):
        u1, u2 = states(p)
        return ((np.column_stack([u1, u1 + u2]) - z) / SIG).ravel()

    def jac(p):
        u1, u2 = states(p)
        d = p[1] + 3 * p[2] * u2 ** 2
        J = np.zeros((F.size, 2, 3))
        J[:, 0, 0] = J[:, 1, 0] = -F / p[0] ** 2
        J[:, 1, 1] = -u2 / d
        J[:, 1, 2] = -u2 ** 3 / d
        return (J / SIG[None, :, None]).reshape(-1, 3)

    r = least_squares(fun, [1.5, 1.0, 0.5], jac=jac, method="trf", xtol=1e-14, ftol=1e-14, gtol=1e-14)
    return r.x, np.linalg.inv(r.jac.T @ r.jac), fun, jac


def test_reduced_start_gives_the_estimate_and_covariance_of_the_plain_ipopt_path():
    """With at least ``reduced_start_inputs`` inputs Ipopt starts at the reduced-space optimum with
    its multipliers and stops within one iteration; the estimate, the second-order and the
    Gauss-Newton covariance equal those of the path without it (Ipopt from the predictor, 4-5
    iterations) and the reduced-space scipy peer."""
    n = 400
    F, z = _data(n)
    model = _springs()
    data = Measurements(F, z.reshape(1, n, 2), SIG)
    warm = identify(model, data, p0=[1.5, 1.0, 0.5])
    plain = identify(model, data, p0=[1.5, 1.0, 0.5], settings=IdentifySettings(reduced_start_inputs=None))
    assert warm.success and plain.success
    assert warm.diagnostics.ipopt_iterations <= 1 < plain.diagnostics.ipopt_iterations
    np.testing.assert_allclose(warm.p, plain.p, rtol=1e-10)
    np.testing.assert_allclose(warm.cov, plain.cov, rtol=1e-8)
    np.testing.assert_allclose(warm.cov_gn, plain.cov_gn, rtol=1e-8)
    np.testing.assert_allclose(warm.states, plain.states, rtol=1e-10)
    p_ref, cov_ref, fun, jac = _scipy_fit(F, z)
    assert_same_optimum(warm.p, p_ref, fun, jac)      # in standard errors: holds on any CPU
    np.testing.assert_allclose(warm.cov_gn, cov_ref, rtol=1e-6)
    assert not np.allclose(warm.cov, warm.cov_gn, rtol=1e-6, atol=0)     # the second-order term S is in cov
    timing = warm.diagnostics.timing
    assert "start point of Ipopt" in timing and all(w >= 0 and c >= 0 for w, c in timing.values())


def test_few_inputs_keep_the_plain_ipopt_path():
    n = 50
    F, z = _data(n, seed=4)
    est = identify(_springs(), Measurements(F, z.reshape(1, n, 2), SIG), p0=[1.5, 1.0, 0.5])
    assert est.diagnostics.ipopt_iterations > 1


def test_batched_state_solve_from_a_guess_equals_solve_states_and_fails_clearly():
    model = _springs()
    F = np.linspace(0.1, 3.0, 300)[:, None]
    p = np.array([1.7, 1.2, 0.6])
    Y = solve_states_from(model, p, F, np.zeros((300, 2)))
    np.testing.assert_allclose(Y, solve_states(model, p, F), rtol=1e-12, atol=1e-14)
    with pytest.raises(StateSolveError, match="state solve at p"):
        solve_states_from(model, np.array([1.7, 0.0, 0.0]), F, np.zeros((300, 2)))   # dE/dy singular


def test_reduced_start_inputs_is_validated():
    with pytest.raises(ValueError, match="reduced_start_inputs"):
        IdentifySettings(reduced_start_inputs=0)


def test_batched_state_solve_of_a_larger_state_uses_lapack_and_equals_solve_states():
    from models.library import spring_chain
    model = spring_chain(4)
    n = 300
    Q = np.column_stack([np.linspace(0.2, 3.0, n), np.linspace(0.0, 0.9, n)])
    p = np.array([2.0, 0.5])
    Y_ref = solve_states(model, p, Q)
    Y = solve_states_from(model, p, Q, np.zeros_like(Y_ref))
    np.testing.assert_allclose(Y, Y_ref, rtol=1e-11, atol=1e-12 * np.abs(Y_ref).max())
