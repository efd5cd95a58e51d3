"""Friction models M1/M2/M3: memory inputs, Coulomb, Preisach network, inverse model (training: tests/mudoe/test_press.py)."""
import casadi as ca
import numpy as np
import pytest

from identification import solve_states
from models.friction import (Coulomb, FrictionError, PreisachNetwork, direction_inputs, fit_coulomb, inverse_forces,
                             memory_inputs, model_inputs)
from models.press import K_NOMINAL, Q_PAPER, press_model

Q = np.array(Q_PAPER)


# ---------------------------------------------------------------------------- inputs
def test_direction_inputs_of_the_paper_sequence():
    d = direction_inputs(Q)
    assert d[0] == 0                                  # at rest
    assert np.all(d[1:15] == 1) and np.all(d[15:] == -1)
    assert model_inputs("M2", Q).shape == (29, 2)


def test_memory_inputs_follow_the_recursions_by_hand():
    q = [0.0, 100.0, 200.0, 150.0, 50.0, 120.0, 80.0]
    U = memory_inputs(q)
    expected = np.array([
        # q, q_prev, q_min, q_max
        [0, 0, 0, 0],
        [100, 0, 0, 100],        # loading: q_min keeps the lower turning point, q_max = q
        [200, 100, 0, 200],
        [150, 200, 150, 200],    # unloading: q_min = q, q_max keeps the upper turning point (max, not min)
        [50, 150, 50, 200],
        [120, 50, 50, 120],      # loading again: q_min = min(q, q_min_prev) = 50
        [80, 120, 80, 120],      # unloading: q_max = max(q, q_max_prev) = 120
    ], float)
    np.testing.assert_array_equal(U, expected)


def test_memory_inputs_of_the_paper_sequence_keep_the_peak_on_unloading():
    U = memory_inputs(Q)
    np.testing.assert_array_equal(U[:, 0], Q)
    np.testing.assert_array_equal(U[1:, 1], Q[:-1])
    assert np.all(U[:15, 2] == 0) and np.all(U[:15, 3] == Q[:15])
    assert np.all(U[15:, 3] == 1600.0) and np.all(U[15:, 2] == Q[15:])


def test_input_errors_name_the_argument():
    with pytest.raises(FrictionError, match="q_sequence"):
        memory_inputs([])
    with pytest.raises(FrictionError, match="q_sequence"):
        direction_inputs([0.0, np.nan])
    with pytest.raises(FrictionError, match="name"):
        model_inputs("M4", Q)
    with pytest.raises(FrictionError, match="q_c"):
        Coulomb(-1.0)
    with pytest.raises(FrictionError, match="W, b, c"):
        PreisachNetwork(np.zeros((2, 3)), np.zeros(2), np.zeros(2), 0.0)


# ---------------------------------------------------------------------------- models
def test_coulomb_enters_the_press_as_a_force_at_R():
    m1, m2 = press_model(), press_model(friction=Coulomb(60.0))
    assert m2.inputs == ("q_P", "dir")
    assert m1.input_units == ("N",) and m2.input_units == ("N", "")       # dir is a sign: no unit ("dir = 1 N" before)
    p = np.array(K_NOMINAL)
    U = model_inputs("M2", Q)
    y2 = solve_states(m2, p, U)
    y1 = solve_states(m1, p, (Q - 60.0 * U[:, 1])[:, None])
    np.testing.assert_allclose(y2, y1, atol=1e-12)


def test_preisach_network_symbolic_equals_numeric_and_round_trips():
    rng = np.random.default_rng(1)
    net = PreisachNetwork(rng.normal(size=(3, 4)), rng.normal(size=3), rng.normal(size=3), 0.2)
    U = memory_inputs(Q)
    qv = ca.SX.sym("q", 4)
    f = ca.Function("f", [qv], [net.force(qv)])
    sym = np.array([float(f(u)) for u in U])
    np.testing.assert_allclose(sym, net(U), rtol=1e-13, atol=1e-10)
    back = PreisachNetwork.from_dict(net.to_dict())
    np.testing.assert_array_equal(back(U), net(U))
    m3 = press_model(friction=net)
    assert m3.inputs == ("q_P", "q_prev", "q_min", "q_max") and m3.input_units == ("N",) * 4    # forces


# ---------------------------------------------------------------------------- inverse model and Coulomb force
def test_inverse_model_recovers_the_applied_force():
    m = press_model()
    p = np.array([520.0, 460.0])
    q_true = Q - 40.0 * direction_inputs(Q)
    z = np.array(m.simulate(p, q_true[:, None]))[None]
    q_hat = inverse_forces(m, p, z, ("D_y", "F_x"), [0.015, 0.005], Q)
    np.testing.assert_allclose(q_hat[0], q_true, atol=1e-6)
    q_hat1 = inverse_forces(m, p, z, ("D_y",), [0.015], Q)
    np.testing.assert_allclose(q_hat1[0], q_true, atol=1e-6)
    with pytest.raises(FrictionError, match="model"):
        inverse_forces(press_model(friction=Coulomb(1.0)), p, z, ("D_y",), [0.015], Q)


def test_fit_coulomb_is_the_least_squares_force():
    d = direction_inputs(Q)
    rng = np.random.default_rng(3)
    f = 55.0 * d[None, :] + rng.normal(0, 5, (4, Q.size))
    qc = fit_coulomb(Q, f)
    grid = np.linspace(40, 70, 3001)
    best = grid[np.argmin([np.sum((g * d[None, :] - f) ** 2) for g in grid])]
    assert abs(qc - best) <= 0.01
    assert fit_coulomb(Q, 55.0 * d) == pytest.approx(55.0, rel=1e-14)
