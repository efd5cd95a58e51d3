"""Sequential design on a dynamic model directly (issue 22, item 4): per-instrument designs from the
(sensor, time) information of its collocation, identification with instrument weights."""
import numpy as np
import pytest

from identification import information_contributions
from identification.fit.dynamic_fit import simulate_campaign
from mudoe.example_reactor import P_TRUE, build
from oed.sequential import sequential_design

Q = np.array([[1.0, 330.0], [2.0, 330.0], [1.0, 370.0], [2.0, 370.0]])     # mol/L, K
TIMES = np.linspace(0.4, 2.0, 5)                                            # h
SIGMA = np.array([0.01, 0.01])                                              # mol/L


@pytest.fixture(scope="module")
def problem():
    model = build()
    return model, [simulate_campaign(model, P_TRUE, Q, TIMES, SIGMA, n_series=2, seed=s) for s in (10, 11)]


def test_sequential_design_takes_the_dynamic_model_and_weights_instruments(problem):
    model, experiments = problem
    res = sequential_design(model, experiments, P_TRUE * 1.1, criterion="D", n_sensors=1)
    assert len(res.steps) == 2 and res.sensor_names == model.sensors
    for step in res.steps:
        assert np.asarray(step.design.weights).shape == (model.n_S,)
        assert int(np.count_nonzero(step.design.weights)) == 1
        assert np.all(np.abs(step.p - P_TRUE) / step.stderr < 5.0)
    # the design at step 2 is the D-best single instrument of the summed (sensor, time) information at
    # the first estimate
    F, _ = information_contributions(model, experiments[0], res.steps[1].p_design)
    pairs = experiments[0].pairs
    per = [sum(F[k] for k, (s, _) in enumerate(pairs) if s == name) for name in model.sensors]
    logdet = [np.linalg.slogdet(M)[1] if np.linalg.slogdet(M)[0] > 0 else -np.inf for M in per]
    assert res.steps[1].design.sensors == (model.sensors[int(np.argmax(logdet))],)


def test_sequential_design_of_the_dynamic_model_under_a_prior(problem):
    """A point prior gives the local sequential design bit for bit; a spread prior on E1 designs per instrument over
    the prior moved to each estimate (the reactor's instrument choice does not depend on E1 here)."""
    model, experiments = problem
    p0 = P_TRUE * 1.1
    local = sequential_design(model, experiments, p0, criterion="D", n_sensors=1)
    point = sequential_design(model, experiments, p0, criterion="D", n_sensors=1, prior=(p0[None, :], [1.0]))
    for a, b in zip(local.steps, point.steps):
        assert a.design.chosen == b.design.chosen and np.array_equal(a.p, b.p) and np.array_equal(a.cov, b.cov)
    rob = sequential_design(model, experiments, p0, criterion="D", n_sensors=1, prior={"E1": ("uniform", 60.0, 72.0)},
                            robust="maximin")
    assert rob.steps[1].robust.prior.n == 5 and np.allclose(rob.steps[1].robust.prior.nominal, rob.steps[0].p)
    assert all(0 < s.robust.worst_case_efficiency <= 1 + 1e-12 for s in rob.steps)
