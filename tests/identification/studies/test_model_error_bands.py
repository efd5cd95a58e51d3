"""identification.model_error: the stated sigma against the pure error of repeated series, and the bands at a
condition not seen (issue 29, the press bands).

Deterministic properties only: the chi-square check of the stated sigma against the repeated series on data whose
pure error is known exactly, and the note it gives.  How well the bands cover is a Monte Carlo claim measured in
bench/bench_model_error.py, not asserted here.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from identification import Measurements, model_error
from models.contract import Model

Q = np.linspace(0.2, 2.0, 12)
P0 = [1.0, 1.0]


def _model() -> Model:
    import casadi as ca
    return Model.explicit(["a", "b"], ["x"], ["y1", "y2"],
                          h=lambda p, q: ca.vertcat(p[0] * (1 - ca.exp(-p[1] * q[0])), p[0] * q[0] / (1 + p[1] * q[0])))


def _data(spread, sigma, n_series: int = 2) -> Measurements:
    """The model at a = 2, b = 1.5 with readings +-spread[k] about it (alternating sign between rows): the pure
    error of sensor k is spread[k] * sqrt(2) exactly (two series, one dof per row)."""
    q = Q[:, None]
    mean = np.stack([2.0 * (1 - np.exp(-1.5 * Q)), 2.0 * Q / (1 + 1.5 * Q)], axis=1)
    sign = np.where(np.arange(Q.size) % 2 == 0, 1.0, -1.0)[:, None]
    dev = sign * np.asarray(spread, float)[None, :]
    z = np.stack([mean + dev, mean - dev][:n_series])
    return Measurements(q, z, sigma, sensors=["y1", "y2"], input_names=["x"])


def test_pure_error_check_is_the_chi_square_test_of_the_ratio():
    spread = np.array([0.01, 0.03])
    stated = np.array([0.04, 0.04])
    r = model_error(_model(), _data(spread, stated), P0, kind="none")
    assert [c.sensor for c in r.pure_error] == ["y1", "y2"]
    for c, s, sig in zip(r.pure_error, spread * np.sqrt(2), stated):
        assert c.dof == Q.size
        assert c.pure_error == pytest.approx(s, rel=1e-12)
        assert c.sigma == pytest.approx(sig, rel=1e-12)
        x = Q.size * s ** 2 / sig ** 2
        assert c.p_below == pytest.approx(stats.chi2.cdf(x, Q.size), rel=1e-12)
        assert c.p_above == pytest.approx(stats.chi2.sf(x, Q.size), rel=1e-12)
    # y1: pure error 0.0141 against 0.04 (ratio 0.35, p ~ 1e-6) is named; y2: 0.0424 against 0.04 is not
    below = [n for n in r.notes if n.startswith("the repeated series scatter clearly less")]
    assert len(below) == 1 and "y1 (pure error" in below[0] and "y2" not in below[0]
    assert "p = " in below[0] and "sigma=None" in below[0]
    assert r.to_dict()["pure_error"][0]["ratio"] == pytest.approx(np.sqrt(2) * 0.01 / 0.04)


def test_pure_error_clearly_above_the_stated_sigma_is_named_too():
    r = model_error(_model(), _data([0.05, 0.002], 0.01), P0, kind="none")
    above = [n for n in r.notes if n.startswith("the repeated series scatter clearly more")]
    assert len(above) == 1 and "y1 (pure error" in above[0] and "y2" not in above[0]
    assert any(n.startswith("the repeated series scatter clearly less") and "y2 (pure error" in n for n in r.notes)


def test_no_pure_error_check_without_repeats_or_with_sigma_from_the_repeats():
    one = model_error(_model(), _data([0.01, 0.01], 0.04, n_series=1), P0, kind="none")
    assert one.pure_error == () and not any("repeated series scatter" in n for n in one.notes)
    pure = model_error(_model(), _data([0.01, 0.01], None), P0, kind="none")
    assert pure.sigma_source != "given" and pure.pure_error == ()
    np.testing.assert_allclose(pure.sigma[:2], 0.01 * np.sqrt(2), rtol=1e-12)


def test_an_unselected_sensor_is_not_checked():
    r = model_error(_model(), _data([0.01, 0.01], 0.04), P0, kind="none", weights=[0, 1])
    assert [c.sensor for c in r.pure_error] == ["y2"]
