"""oed.times: choosing sampling times of a dynamic model."""
import itertools

import numpy as np
import pytest

from mudoe.example_reactor import P_TRUE, TIMES, build
from oed.times import select_times, time_information

Q = np.array([[1.0, 330.0], [2.0, 350.0], [2.0, 370.0]])
SIGMA = np.array([0.01, 0.008])


def test_select_times_is_the_d_optimal_subset():
    m = build()
    res = select_times(m, P_TRUE, TIMES, Q, SIGMA, n_times=3, criterion="D")
    F, names = time_information(m, P_TRUE, TIMES, Q, SIGMA)
    best = min(itertools.combinations(range(TIMES.size), 3),
               key=lambda c: -np.linalg.slogdet(F[list(c)].sum(axis=0))[1])
    assert sorted(res.sensors) == sorted(names[i] for i in best)
    assert res.proven_optimal


def test_select_time_sensor_pairs_and_instrument_subset():
    m = build()
    F, names = time_information(m, P_TRUE, TIMES, Q, SIGMA, pairs=True)
    assert F.shape == (2 * TIMES.size, 4, 4) and names[:2] == ["cA@0.2", "cB@0.2"]
    res = select_times(m, P_TRUE, TIMES, Q, SIGMA, n_times=4, pairs=True, criterion="A")
    assert len(res.sensors) == 4 and all("@" in s for s in res.sensors)
    Fb, _ = time_information(m, P_TRUE, TIMES, Q, SIGMA, sensors=["cB"])
    assert np.allclose(Fb, F[1::2])
    with pytest.raises(ValueError, match="sensors: unknown"):
        time_information(m, P_TRUE, TIMES, Q, SIGMA, sensors=["cC"])
