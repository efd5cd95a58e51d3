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


def test_the_strategy_answers_what_differs_between_the_kinds():
    """Issue 28: the layers above read these instead of asking whether a model is dynamic."""
    from identification import DataError
    from identification.fit.problem import strategy_for
    model, data = static_case()
    static, dyn = strategy_for(model), strategy_for(build())
    assert (static.design_axis, dyn.design_axis) == ("inputs", "times")
    assert (static.takes_time_series, dyn.takes_time_series) == (False, True)
    assert isinstance(model, static.model_type) and isinstance(build(), dyn.model_type)
    static.check_data(data)
    with pytest.raises(TypeError, match=r"^data: expected an identification.Measurements, got list$"):
        static.check_data([1.0])
    with pytest.raises(TypeError, match=r"^data\['m'\]: a dynamic model needs identification."
                                        r"DynamicMeasurements \(values over sampling times\), got Measurements$"):
        dyn.check_data(data, "data['m']")
    with pytest.raises(DataError, match=r"^data: validate needs a campaign, got NoneType$"):
        dyn.check_data(None, need="validate needs a campaign", error=DataError)
    with pytest.raises(TypeError, match="data: a dynamic model needs identification.DynamicMeasurements"):
        Problem(build(), data)


def test_per_instrument_sums_the_readings_of_each_instrument():
    campaign = simulate_campaign(build(), P_TRUE, Q, TIMES, SIGMA, seed=1)
    problem = Problem(build(), campaign)
    F, _ = problem.information(P_TRUE)
    by_instrument = problem.strategy.per_instrument(problem.model, F, campaign)
    for k, s in enumerate(build().sensors):
        assert np.array_equal(by_instrument[k], sum(F[i] for i, (name, _) in enumerate(campaign.pairs) if name == s))
    model, data = static_case()
    static = Problem(model, data)
    F, _ = static.information([2.0, 0.5])
    assert static.strategy.per_instrument(model, F, data) is F
