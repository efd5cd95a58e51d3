"""Stiff models (issue 30, item 9): Robertson's kinetics collocated on log-spaced sampling over 1e5 s.

The collocation against scipy's Radau (rtol 1e-10), log-spaced times as distinct instants, and the rescue of
an element whose plain Newton solve fails (models.element_rescue)."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from models.collocation import Mesh, collocate
from models.dynamic import merge_times, time_tolerance
from models.element_rescue import element_failures, rescue_elements
from models import ModelError
from mudoe.example_robertson import HORIZON, P_TRUE, SIGMA, TIMES, build, jacobian_numpy, rhs_numpy

Q = np.zeros((1, 0))


def radau(k, times):
    """Robertson's y at ``times`` by scipy's Radau, rtol 1e-10, atol 1e-20, exact Jacobian."""
    r = solve_ivp(rhs_numpy, (0.0, float(times[-1])), [1.0, 0.0, 0.0], method="Radau", t_eval=times, rtol=1e-10,
                  atol=1e-20, jac=jacobian_numpy, args=(np.asarray(k, float),))
    assert r.success
    return r.y.T


def test_log_spaced_times_over_a_long_horizon_are_distinct_instants():
    # 1e-5 and 4.9e-5 s differ by less than 1e-9 x the 1e5 s horizon: they were merged as round-off twins
    t = np.logspace(-5, 4, 10)
    m = build()
    assert np.array_equal(m.check_times(t), t)
    b = np.asarray(m.collocate(t, max_step=HORIZON / 10).mesh.boundaries)
    assert all(np.any(b == v) for v in t) and np.diff(b).min() > 0.5e-5
    # round-off twins still merge, near 0 and near the horizon
    assert merge_times([0.35], [0.35000000000000003], horizon=HORIZON).tolist() == [0.35]
    assert merge_times([9e4], [9e4 * (1 + 4e-16)], horizon=HORIZON).tolist() == [9e4]
    assert time_tolerance(HORIZON, 1e-5) == pytest.approx(1e-9 * 1e-6 * HORIZON)
    with pytest.raises(ModelError, match="differ by round-off only"):
        Mesh((0.0, 1e-5, 1e-5 * (1 + 1e-15), 1.0))


def test_collocation_agrees_with_radau_within_the_controlled_error():
    # the mesh whose Richardson estimate (every element halved) is below 1 % of sigma at the true rates:
    # the estimate states the true error against Radau (within a factor 2), and both are far below sigma
    from identification.fit.dynamic_fit import controlled_mesh
    m = build()
    cm, err = controlled_mesh(m, P_TRUE, Q, TIMES, SIGMA)
    h = cm.integrated_outputs(P_TRUE, Q).reshape(TIMES.size, 3)
    true = np.max(np.abs(h - radau(P_TRUE, TIMES)) / SIGMA)
    assert err <= 0.01 and true <= 2 * err and err <= 2 * true
    # the coarse first mesh is refused by the estimate (error above the tolerance), as it should be
    coarse = collocate(m, TIMES, max_step=HORIZON / 10)
    h0 = coarse.integrated_outputs(P_TRUE, Q).reshape(TIMES.size, 3)
    assert np.max(np.abs(h0 - radau(P_TRUE, TIMES)) / SIGMA) > 0.1


def test_rescue_solves_an_element_plain_newton_misses():
    # a rough start's rates on the element [4931, 14045] s of the first mesh: CasADi's plain Newton from the
    # start point stalls (max |R| ~ 0.16); the rescue (halves, then Newton with a line search) solves it, and
    # its end point is the collocation solution on that element (within the element's error of Radau)
    k = np.array([0.12, 1e5, 3e6])
    cm = collocate(build(), TIMES, max_step=HORIZON / 10)
    b = np.asarray(cm.mesh.boundaries)
    e = int(np.flatnonzero(np.isclose(b, TIMES[9]))[0])
    assert b[e + 1] - b[e] > 9e3
    x = radau(k, b[:e + 1])[-1]
    par = np.r_[x, k, b[e + 1] - b[e]]
    rf, R = cm.element_functions()
    V = np.asarray(rf(np.tile(x, 3), par)).ravel()
    assert element_failures(V[None], np.asarray(R(V, par)).T)[0]
    V, Rr = rescue_elements(cm, np.tile(x, 3)[None], par[None])
    assert not element_failures(V, Rr)[0]
    end = radau(k, b[:e + 2])[-1]
    assert np.max(np.abs(V[0, -3:] - end) / end) < 1e-3                   # y2 within 0.1 %, not a spurious root


def test_trajectory_of_a_rough_start_is_marched():
    # the whole trajectory at the rough start (the march rescues the elements plain Newton misses)
    k = np.array([0.12, 1e5, 3e6])
    cm = collocate(build(), TIMES, max_step=HORIZON / 10)
    h = cm.integrated_outputs(k, Q).reshape(TIMES.size, 3)
    ref = radau(k, TIMES)
    assert np.all(np.isfinite(h)) and np.max(np.abs(h[:, [0, 2]] - ref[:, [0, 2]])) < 0.05
    # the same through the mapped outputs and sensitivities (their in-graph march falls back to the rescue)
    from models.trajectory import mapped_outputs, outputs_and_sensitivities
    assert np.allclose(mapped_outputs(cm, k, Q), h.reshape(1, -1), rtol=1e-9, atol=1e-15)
    h2, G = outputs_and_sensitivities(cm, k, Q)
    assert np.allclose(h2, h.reshape(1, -1), rtol=1e-9, atol=1e-15) and np.all(np.isfinite(G))
