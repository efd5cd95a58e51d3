"""Start trajectories through the data (identification.fit.data_start, IdentifySettings.init; issue 30 item 1)."""
import warnings

import casadi as ca
import numpy as np
import pytest

from bench import ode_benchmarks as ob
from identification import DynamicMeasurements, IdentifySettings, identify
from identification.fit.data_start import data_trajectories, linear_outputs
from identification.fit.dynamic_fit import collocated_problem
from identification.fit.start import initial_states
from models import Model
from models.contract import Parameter


def _chain(h=None):
    """A -> B -> C, A and B measured (C not); x(0) = (1, 0, 0)."""
    return Model.ode([Parameter("k1", 0.0, 10.0), Parameter("k2", 0.0, 10.0)], states=["A", "B", "C"], inputs=[],
                     sensors=["A", "B"],
                     rhs=lambda x, p, u: ca.vertcat(-p[0] * x[0], p[0] * x[0] - p[1] * x[1], p[1] * x[1]),
                     x0=lambda p, u: ca.vertcat(1.0, 0.0, 0.0), h=h or (lambda x, p, u: x[:2]), name="chain3")


def _data():
    t = np.arange(1, 11) * 0.1
    z = np.column_stack([np.exp(-5 * t), 1.25 * (np.exp(-t) - np.exp(-5 * t))])
    z = z + 0.002 * np.random.default_rng(0).standard_normal(z.shape)
    return DynamicMeasurements(None, t, z[None, None], np.array([0.002, 0.002]), sensors=["A", "B"])


def _start(model, data, p0):
    cm, flat = collocated_problem(model, data)
    p0 = np.asarray(p0, float)
    Y = initial_states(cm, p0, flat.inputs)
    return cm, flat, Y, data_trajectories(cm, flat, p0, Y)


def test_measured_states_pass_through_the_data_unmeasured_keep_the_simulation():
    data = _data()
    cm, flat, Y, Yd = _start(_chain(), data, [0.5, 0.5])
    t = cm.point_times()
    X, Xd = Y.reshape(t.size, 3), Yd.reshape(t.size, 3)
    at = [int(np.argmin(np.abs(t - v))) for v in data.union_times]
    np.testing.assert_allclose(Xd[at, :2], data.z[0, 0], rtol=0, atol=1e-14)    # through the series means
    np.testing.assert_array_equal(Xd[:, 2], X[:, 2])                             # C: not measured
    np.testing.assert_array_equal(Xd[0], X[0])                                   # the initial state x0(p0)
    # between sampling times the correction (data - simulation) is linear in time
    i, j = at[3], at[4]
    mid = (i + j) // 2
    w = (t[mid] - t[i]) / (t[j] - t[i])
    d = Xd[:, :2] - X[:, :2]
    np.testing.assert_allclose(d[mid], (1 - w) * d[i] + w * d[j], rtol=1e-12, atol=1e-15)


def test_states_following_linearly_from_the_outputs_are_moved_by_the_pseudo_inverse():
    # one sensor A + B: only the direction (1, 1, 0) / 2 of the states follows from it
    model = _chain(h=lambda x, p, u: ca.vertcat(x[0] + x[1], x[0]))
    t = np.arange(1, 11) * 0.1
    z = np.column_stack([np.exp(-5 * t) + 1.25 * (np.exp(-t) - np.exp(-5 * t)), np.exp(-5 * t)])
    data = DynamicMeasurements(None, t, z[None, None], np.array([0.01, 0.01]), sensors=["A", "B"])
    cm, flat, Y, Yd = _start(model, data, [0.5, 0.5])
    H, _ = linear_outputs(cm.dynamic)
    np.testing.assert_array_equal(H, [[1.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    X = Yd.reshape(-1, 3)
    at = [int(np.argmin(np.abs(cm.point_times() - v))) for v in t]
    np.testing.assert_allclose(X[at] @ H.T, z, atol=1e-13)                    # both outputs through the data
    np.testing.assert_array_equal(X[:, 2], Y.reshape(-1, 3)[:, 2])


def test_outputs_not_linear_in_the_states_start_from_the_simulation():
    model = _chain(h=lambda x, p, u: ca.vertcat(x[0] ** 2, x[1]))
    assert linear_outputs(model) is None
    _, _, _, Yd = _start(model, _data(), [0.5, 0.5])
    assert Yd is None
    # an output matrix depending on p is not "linear in the states" either
    assert linear_outputs(_chain(h=lambda x, p, u: ca.vertcat(p[0] * x[0], x[1]))) is None


def test_data_start_needs_fewer_ipopt_iterations_and_reaches_the_same_optimum():
    # gas-oil cracking from every rate 1e-6 (COPS data): the reduced-space iteration cannot start there and
    # Ipopt solves the full-space NLP; from the simulated trajectories (nearly constant) it takes 25
    # iterations, from trajectories through the data 5 (this machine; the test asks for half)
    b = ob.benchmark("gasoil")
    model, data, p0 = b.model(), b.data(), (1e-6,) * 3
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = identify(model, data, p0, settings=IdentifySettings(init="simulate"))
        dat = identify(model, data, p0)                      # the default
    assert IdentifySettings().init == "data"
    assert sim.diagnostics.solver == dat.diagnostics.solver == "ipopt"
    assert dat.iterations <= sim.iterations / 2
    assert np.max(np.abs(dat.p - sim.p) / sim.stderr) < 1e-6                     # the same optimum
    np.testing.assert_allclose(dat.objective, sim.objective, rtol=1e-10)


def test_init_is_checked():
    with pytest.raises(ValueError, match="init: expected one of 'data', 'simulate'"):
        IdentifySettings(init="guess")


def test_a_start_on_the_bounds_is_solved_from_the_data_in_few_iterations():
    # alpha-pinene from every rate 0 (COPS's start; moved 1e-3 into the interior): the first mesh goes straight
    # to the full-space NLP through the data (6 Ipopt iterations here); the optimum is the one found from a
    # start near it by the reduced-space iteration
    b = ob.benchmark("pinene")
    model, data = b.model(), b.data()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        on_bound = identify(model, data, (0.0,) * 5)
        near = identify(model, data, (6e-5, 3e-5, 2e-5, 2.7e-4, 4e-5))
    assert on_bound.diagnostics.solver == "ipopt" and on_bound.iterations <= 15
    assert near.diagnostics.solver == "reduced Newton"
    assert np.max(np.abs(on_bound.p - near.p) / near.stderr) < 1e-6
    np.testing.assert_allclose(on_bound.objective, near.objective, rtol=1e-10)
