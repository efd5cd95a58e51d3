"""oed.information: one information function for every candidate axis, design results that name their axis,
and the deprecated names that wrap it (issue 28, item 3)."""
import casadi as ca
import numpy as np
import pytest

from identification import information_contributions
from models import Model
from mudoe.example_reactor import P_TRUE, TIMES, build
from oed import (CandidateInformation, dynamic_input_information, information, input_information,
                 select_dynamic_inputs, select_inputs, select_sensors, select_sensors_from_information, select_times,
                 time_information)

Q = np.array([[1.0, 330.0], [2.0, 350.0], [2.0, 370.0]])
SIGMA = np.array([0.01, 0.008])
P = np.array([240.0, 5e-3])


def _exp_model():
    return Model.explicit(params=["b1", "b2"], inputs=["x"], sensors=["y1", "y2"],
                          h=lambda p, q: ca.vertcat(p[0] * (1 - ca.exp(-p[1] * q[0])), p[0] * ca.exp(-p[1] * q[0])))


def test_static_axes_share_one_return_type():
    m = _exp_model()
    X = np.array([[10.0], [200.0], [900.0]])
    rows = information(m, P, axis="inputs", candidates=X, sigma=[1.0, 2.0])
    pairs = information(m, P, axis="input_pairs", candidates=X, sigma=[1.0, 2.0])
    sens = information(m, P, inputs=X, sigma=[1.0, 2.0])
    for info, axis, n in ((rows, "inputs", 3), (pairs, "input_pairs", 6), (sens, "sensors", 2)):
        assert isinstance(info, CandidateInformation) and info.axis == axis
        assert info.F.shape == (n, 2, 2) and len(info.labels) == n
    # the axes are sums of the same (row, sensor) readings
    np.testing.assert_array_equal(rows.F, pairs.F.reshape(3, 2, 2, 2).sum(axis=1))
    np.testing.assert_allclose(sens.F, pairs.F.reshape(3, 2, 2, 2).sum(axis=0), rtol=1e-12)
    assert rows.labels == ("q0", "q1", "q2") and sens.labels == ("y1", "y2") and rows.S is None
    only = information(m, P, axis="inputs", candidates=X, sigma=[1.0, 2.0], sensors=["y2"])
    np.testing.assert_array_equal(only.F, pairs.F[1::2])
    with pytest.raises(TypeError, match="model: expected a dynamic model"):
        information(m, P, axis="times", times=[1.0], inputs=X, sigma=1.0)
    with pytest.raises(ValueError, match="axis: expected one of"):
        information(m, P, axis="rows", candidates=X, sigma=1.0)
    with pytest.raises(ValueError, match="times/discretisation: only for a dynamic model"):
        information(m, P, axis="inputs", candidates=X, sigma=1.0, times=[1.0])


def test_dynamic_axes_are_the_collocations_readings():
    m = build()
    times = information(m, P_TRUE, axis="times", times=TIMES, inputs=Q, sigma=SIGMA)
    pairs = information(m, P_TRUE, axis="pairs", times=TIMES, inputs=Q, sigma=SIGMA)
    F, _ = information_contributions(m, None, P_TRUE, inputs=Q, times=TIMES, sigma=SIGMA)
    np.testing.assert_array_equal(pairs.F, F)
    np.testing.assert_array_equal(times.F, F.reshape(TIMES.size, m.n_S, m.n_p, m.n_p).sum(axis=1))
    assert pairs.labels[:2] == ("cA@0.2", "cB@0.2") and times.axis == "times" and pairs.axis == "pairs"
    # a dynamic model's sensors are its instruments, every reading of one summed
    sens = information(m, P_TRUE, inputs=Q, times=TIMES, sigma=SIGMA)
    assert sens.labels == m.sensors
    np.testing.assert_allclose(sens.F, F.reshape(TIMES.size, m.n_S, m.n_p, m.n_p).sum(axis=0), rtol=1e-12)
    # one experiment row's information over all readings: the sum of its pairs
    rows = information(m, P_TRUE, axis="inputs", candidates=Q, times=TIMES, sigma=SIGMA)
    one = information(m, P_TRUE, axis="pairs", times=TIMES, inputs=Q[:1], sigma=SIGMA)
    assert rows.F.shape == (3, m.n_p, m.n_p) and rows.labels == ("q0", "q1", "q2")
    np.testing.assert_allclose(rows.F[0], one.F.sum(axis=0), rtol=1e-6)


def test_design_results_name_their_axis():
    m = build()
    t = select_times(m, P_TRUE, TIMES, Q, SIGMA, n_times=3, criterion="D")
    assert t.axis == "times" and all("@" not in c for c in t.chosen) and len(t.chosen) == 3
    with pytest.warns(DeprecationWarning, match="use DesignResult.chosen"):
        assert t.sensors == t.chosen
    s = select_sensors(m, None, P_TRUE, inputs=Q, times=TIMES, sigma=SIGMA, n_sensors=1, criterion="D")
    assert s.axis == "sensors" and s.sensors == s.chosen and s.chosen[0] in m.sensors
    r = select_inputs(_exp_model(), P, candidates=np.linspace(1, 1000, 8), sigma=[1.0, 2.0], n_points=3)
    assert r.axis == "inputs" and r.chosen == tuple(f"q{j}" for j in r.indices) == r.design.chosen
    info = information(_exp_model(), P, axis="input_pairs", candidates=np.linspace(1, 1000, 8), sigma=1.0)
    d = select_sensors_from_information(info, criterion="D", n_sensors=3)
    assert d.axis == "input_pairs" and d.chosen == tuple(info.labels[k] for k in d.indices)
    with pytest.raises(ValueError, match="S/sensor_names"):
        select_sensors_from_information(info, sensor_names=list(info.labels), n_sensors=3)


def test_old_information_functions_warn_and_agree():
    m = _exp_model()
    X = np.array([[10.0], [200.0], [900.0]])
    with pytest.warns(DeprecationWarning, match="oed.input_information is deprecated"):
        old = input_information(m, P, X, [1.0, 2.0])
    np.testing.assert_array_equal(old.reshape(-1, 2, 2),
                                  information(m, P, axis="input_pairs", candidates=X, sigma=[1.0, 2.0]).F)
    d = build()
    with pytest.warns(DeprecationWarning, match="oed.time_information is deprecated"):
        F, names = time_information(d, P_TRUE, TIMES, Q, SIGMA, pairs=True)
    new = information(d, P_TRUE, axis="pairs", times=TIMES, inputs=Q, sigma=SIGMA)
    np.testing.assert_array_equal(F, new.F)
    assert names == list(new.labels)
    with pytest.warns(DeprecationWarning, match="oed.dynamic_input_information is deprecated"):
        Fq = dynamic_input_information(d, P_TRUE, Q, TIMES, SIGMA)
    np.testing.assert_array_equal(Fq, information(d, P_TRUE, axis="inputs", candidates=Q, times=TIMES,
                                                  sigma=SIGMA).F)
    with pytest.warns(DeprecationWarning, match="oed.select_dynamic_inputs is deprecated"):
        old = select_dynamic_inputs(d, P_TRUE, times=TIMES, candidates=Q, sigma=SIGMA, n_points=2)
    assert old.indices == select_inputs(d, P_TRUE, times=TIMES, candidates=Q, sigma=SIGMA, n_points=2).indices
