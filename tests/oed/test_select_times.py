"""oed.times: choosing sampling times of a dynamic model (information on axes "times" and "pairs")."""
import itertools

import numpy as np
import pytest

from mudoe.example_reactor import P_TRUE, TIMES, build
from oed import information
from oed.times import select_times

Q = np.array([[1.0, 330.0], [2.0, 350.0], [2.0, 370.0]])
SIGMA = np.array([0.01, 0.008])


def test_select_times_is_the_d_optimal_subset():
    m = build()
    res = select_times(m, P_TRUE, TIMES, Q, SIGMA, n_times=3, criterion="D")
    info = information(m, P_TRUE, axis="times", times=TIMES, inputs=Q, sigma=SIGMA)
    F, names = info.F, info.labels
    best = min(itertools.combinations(range(TIMES.size), 3),
               key=lambda c: -np.linalg.slogdet(F[list(c)].sum(axis=0))[1])
    assert sorted(res.chosen) == sorted(names[i] for i in best)
    assert res.proven_optimal and res.axis == "times"


def test_select_time_sensor_pairs_and_instrument_subset():
    m = build()
    info = information(m, P_TRUE, axis="pairs", times=TIMES, inputs=Q, sigma=SIGMA)
    F, names = info.F, info.labels
    assert F.shape == (2 * TIMES.size, 4, 4) and names[:2] == ("cA@0.2", "cB@0.2")
    res = select_times(m, P_TRUE, TIMES, Q, SIGMA, n_times=4, pairs=True, criterion="A")
    assert len(res.chosen) == 4 and all("@" in s for s in res.chosen) and res.axis == "pairs"
    Fb = information(m, P_TRUE, axis="times", times=TIMES, inputs=Q, sigma=SIGMA, sensors=["cB"]).F
    assert np.allclose(Fb, F[1::2])
    with pytest.raises(ValueError, match="sensors: unknown"):
        information(m, P_TRUE, axis="times", times=TIMES, inputs=Q, sigma=SIGMA, sensors=["cC"])
