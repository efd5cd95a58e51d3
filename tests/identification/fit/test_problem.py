"""The one estimation problem (identification.fit.problem): a strategy per kind of model, the verbs written once."""
import numpy as np
import pytest

import identification.fit
from identification import DiscretisationSettings, Measurements, Problem, identify, information_contributions, simulate
from identification.fit.dynamic_fit import collocated_problem, simulate_campaign
from identification.fit.problem import CollocatedStrategy, StaticStrategy
from models.library import spring_chain
from mudoe.example_reactor import P_TRUE, TIMES, build

Q = np.array([[1.0, 330.0], [2.0, 360.0]])
SIGMA = np.array([0.01, 0.008])


def static_case():
    model = spring_chain(4, n_sensors=4, n_groups=1)
    q = np.array([[f, 0.3 * f] for f in np.linspace(0.2, 3.0, 5)])
    H = simulate(model, [2.0, 0.5], q)
    sig = 0.01 * np.abs(H).max(axis=0)
    z = H[None] + sig * np.random.default_rng(0).standard_normal((2,) + H.shape)
    return model, Measurements(q, z, sig, sensors=model.sensors)


def test_a_static_problem_is_its_own_static_problem_and_fits_as_identify():
    model, data = static_case()
    problem = Problem(model, data)
    assert isinstance(problem.strategy, StaticStrategy) and problem.kind == "static"
    assert identification.fit.Problem is Problem
    m, d = problem.static([2.0, 0.5])
    assert m is model and d is data
    rec = problem.fit([1.0, 0.1])
    est = identify(model, data, [1.0, 0.1])
    assert np.array_equal(rec.p, est.p) and np.array_equal(rec.cov, est.cov)
    F, S = problem.information(rec.p)
    F2, S2 = information_contributions(model, data, rec.p)
    assert np.array_equal(F, F2) and np.array_equal(S, S2)


def test_a_dynamic_problem_is_collocated_on_a_mesh_controlled_at_p():
    data = simulate_campaign(build(), P_TRUE, Q, TIMES, SIGMA, seed=1)
    problem = Problem(build(), data, DiscretisationSettings(tol_sigma=0.02))
    assert isinstance(problem.strategy, CollocatedStrategy) and problem.kind == "collocated"
    cm, flat = problem.static(P_TRUE)
    cm2, flat2 = collocated_problem(build(), data, p=P_TRUE, discretisation=DiscretisationSettings(tol_sigma=0.02))
    assert cm.mesh == cm2.mesh and np.array_equal(flat.z, flat2.z, equal_nan=True)
    first, _ = problem.static()            # no p: the first mesh of the settings
    assert first.mesh.n_elements <= cm.mesh.n_elements
    F, _ = problem.information(P_TRUE)
    assert F.shape == (len(data.pairs), 4, 4) and np.all(np.linalg.eigvalsh(F.sum(axis=0)) > 0)


def test_arguments_of_the_other_kind_are_refused():
    model, data = static_case()
    with pytest.raises(TypeError, match="discretisation: only for a dynamic model"):
        Problem(model, data, DiscretisationSettings())
    with pytest.raises(TypeError, match="times: only for a dynamic model"):
        Problem(model, data).information([2.0, 0.5], times=[1.0])
    dyn = Problem(build(), simulate_campaign(build(), P_TRUE, Q, TIMES, SIGMA, seed=1))
    with pytest.raises(TypeError, match="Y0: not used for a dynamic model"):
        dyn.fit(P_TRUE, Y0=np.zeros((2, 3)))
    with pytest.raises(TypeError, match="states: not used for a dynamic model"):
        dyn.information(P_TRUE, states=np.zeros((2, 3)))
