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


# ---------------------------------------------------------------------------- bands at a condition not seen
def _offset_data(offsets, seed: int = 5) -> tuple:
    """Two series at Q per condition, condition g shifted by offsets[g] on both sensors; the rows' conditions."""
    rng = np.random.default_rng(seed)
    q = np.tile(Q, len(offsets))
    cond = np.repeat(np.arange(len(offsets)), Q.size)
    mean = np.stack([2.0 * (1 - np.exp(-1.5 * q)), 2.0 * q / (1 + 1.5 * q)], axis=1) + np.asarray(offsets)[cond, None]
    z = mean[None] + 0.05 * rng.standard_normal((2, q.size, 2))
    return Measurements(q[:, None], z, 0.05, sensors=["y1", "y2"], input_names=["x"]), cond


def _fit(offsets):
    from identification.studies.discrepancy_gp import InputScaling
    from identification.studies.model_error_fit import fit_model_error
    d, cond = _offset_data(offsets)
    scaling = InputScaling.of(d.inputs, {}, ("x",))
    return fit_model_error(_model(), d, P0, np.ones(2), scaling, "discrepancy", groups=cond), d


def test_reml_information_is_half_the_trace_of_p_va_p_vb():
    from identification.studies.discrepancy_gp import _block, reml_information
    from scipy import linalg
    f, d = _fit([0.2, -0.1, 0.3])
    obs, theta = f.gp.obs, f.gp.theta
    from identification.studies.model_error_fit import outputs_at
    G = obs.stack(outputs_at(f.model, f.p, d.inputs)[1])
    V = linalg.block_diag(*[_block(obs, i, theta[3 * i:3 * i + 3], ())[0] for i in range(2)])
    Vi = np.linalg.inv(V)
    P = Vi - Vi @ G @ np.linalg.inv(G.T @ Vi @ G) @ G.T @ Vi
    dense, n = [], obs.sizes
    for i in range(2):
        for dV in _block(obs, i, theta[3 * i:3 * i + 3], ())[1]:
            full = np.zeros_like(V)
            s = sum(n[:i])
            full[s:s + n[i], s:s + n[i]] = dV
            dense.append(full)
    expect = np.array([[0.5 * np.trace(P @ a @ P @ b) for b in dense] for a in dense])
    np.testing.assert_allclose(reml_information(theta, obs, G), expect, rtol=1e-8, atol=1e-10 * np.abs(expect).max())
    np.testing.assert_allclose(f.gp.information, expect, rtol=1e-8, atol=1e-10 * np.abs(expect).max())


def test_spread_of_the_new_draw_variance_is_the_delta_method_over_the_free_hyperparameters():
    from identification.studies.discrepancy_gp import AT_BOUND, BOUNDS
    f, d = _fit([0.2, -0.1, 0.3])
    gp = f.gp
    x = np.array([[0.1], [0.6]])
    lo = np.tile([b[0] for b in BOUNDS], 2)
    hi = np.tile([b[1] for b in BOUNDS], 2)
    free = np.flatnonzero((gp.theta > lo + AT_BOUND) & (gp.theta < hi - AT_BOUND))
    assert free.size < 6                                   # some hyperparameter sits on a bound here
    for i in range(2):
        grad = np.zeros((2, 6))
        grad[:, 3 * i] = 2 * gp.amplitude(i) ** 2
        grad[:, 3 * i + 2] = 2 * gp.rough(i) ** 2
        g = grad[:, free]
        expect = np.einsum("ap,pq,aq->a", g, np.linalg.inv(gp.information[np.ix_(free, free)]), g)
        np.testing.assert_allclose(gp.prior_variance_spread(i, x), expect, rtol=1e-8)
        assert np.all(expect > 0)


def test_student_t_band_at_a_condition_not_seen_and_unchanged_elsewhere():
    from identification.studies.model_error_fit import band_logpdf
    f, d = _fit([0.2, -0.1, 0.3])
    q = np.array([[0.3], [1.1], [1.9]])
    cond = np.array([0, -1, 2])                          # seen, not seen, seen
    plug = f.predict(q, 0.05, True, conditions=cond, variance_aware=False)
    t = f.predict(q, 0.05, True, conditions=cond, variance_aware=True)
    assert plug.dof is None
    np.testing.assert_array_equal(t.mean, plug.mean)
    np.testing.assert_array_equal(t.lower[[0, 2]], plug.lower[[0, 2]])    # seen conditions: the normal band
    assert np.all(np.isinf(t.dof[[0, 2]]))
    var = ((plug.upper - plug.mean) / stats.norm.ppf(0.975)) ** 2
    spread = np.array([f.gp.prior_variance_spread(f.gp.obs.block_of(k), f.scaling(q[[1]]))[0] for k in range(2)])
    nu = 2 * var[1] ** 2 / spread
    np.testing.assert_allclose(t.dof[1], nu, rtol=1e-10)
    np.testing.assert_allclose(t.upper[1] - t.mean[1], stats.t.ppf(0.975, nu) * np.sqrt(var[1]), rtol=1e-10)
    assert np.all(t.upper[1] - t.lower[1] > plug.upper[1] - plug.lower[1])
    z = plug.mean + 0.07
    np.testing.assert_allclose(band_logpdf(plug, z), stats.norm.logpdf(z, plug.mean, np.sqrt(var)), rtol=1e-12)
    lt = band_logpdf(t, z)
    np.testing.assert_allclose(lt[[0, 2]], stats.norm.logpdf(z, plug.mean, np.sqrt(var))[[0, 2]], rtol=1e-12)
    np.testing.assert_allclose(lt[1], stats.t.logpdf(z[1], nu, plug.mean[1], np.sqrt(var[1])), rtol=1e-10)
    disc = f.discrepancy(q, 0.05, conditions=cond, variance_aware=True)
    assert np.all(np.isfinite(disc.dof[1])) and np.all(np.isinf(disc.dof[[0, 2]]))
