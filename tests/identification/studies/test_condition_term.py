"""The discrepancy's offset per condition (``condition_term``, issue 29: bands for a condition not seen).

With ``condition_term`` the third hyperparameter of every sensor is the variance omega_k^2 of a constant per
condition, V_k = s_k^2 C o S + omega_k^2 S + D_k (S_oo' = [g(o) = g(o')]), instead of the rough part.  Mechanics
only: the covariance, the exact REML gradient and information, the kriging cross-covariance and prior at a
condition seen and not seen, the refusal with exact_at, and that the default is unchanged.  Whether its bands
cover is a Monte Carlo claim (bench/RESULTS.md, "Issue 29: bands for a condition not seen").
"""
from __future__ import annotations

import numpy as np
import pytest

from identification import Measurements
from identification.studies.discrepancy_gp import (InputScaling, Observations, kernel_blocks, reml_information,
                                                   reml_objective)
from identification.studies.model_error_fit import fit_model_error
from models.contract import Model

Q = np.linspace(0.2, 2.0, 8)


def _obs(condition_term: bool):
    rng = np.random.default_rng(3)
    x = np.tile(Q, 3)[:, None]
    counts = np.full((x.shape[0], 2), 2.0)
    counts[5, 1] = 0
    cond = np.repeat([0, 1, 2], Q.size)
    sc = InputScaling.of(x, {}, ("x",))
    obs = Observations.of(counts, np.array([0.1, 0.3]), np.ones(2), sc(x), conditions=cond,
                          condition_term=condition_term)
    n = sum(obs.sizes)
    return obs, rng.standard_normal((n, 2)), rng.standard_normal(n), sc


def test_the_covariance_is_smooth_times_same_condition_plus_an_offset_per_condition():
    from identification.studies.discrepancy_gp import GPFit
    obs, G, r, _ = _obs(True)
    th = np.array([0.2, np.log(0.4), -0.5, -0.3, np.log(0.8), 0.4])
    V = GPFit(th, obs, (), 0.0, True).covariance()
    start = 0
    for i, n in enumerate(obs.sizes):
        sig = obs.sigma[i]
        s2, ell, w2 = (sig * np.exp(th[3 * i])) ** 2, np.exp(th[3 * i + 1]), (sig * np.exp(th[3 * i + 2])) ** 2
        c = obs.condition_codes(i)
        S = (c[:, None] == c[None, :]).astype(float)
        expect = s2 * kernel_blocks(obs.x[i], obs.x[i], ell)[0] * S + w2 * S + np.diag(obs.noise[i])
        np.testing.assert_allclose(V[start:start + n, start:start + n], expect, rtol=1e-13)
        start += n


def test_the_reml_gradient_and_information_are_exact_with_the_offset_term():
    obs, G, r, _ = _obs(True)
    th = np.array([0.2, np.log(0.4), -0.5, -0.3, np.log(0.8), 0.4])
    f, g = reml_objective(th, obs, G, r)
    fd = [(reml_objective(th + 1e-6 * e, obs, G, r)[0] - reml_objective(th - 1e-6 * e, obs, G, r)[0]) / 2e-6
          for e in np.eye(6)]
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-6)
    from identification.studies.discrepancy_gp import GPFit
    from scipy import linalg
    V = GPFit(th, obs, (), 0.0, True).covariance()
    Vi = np.linalg.inv(V)
    P = Vi - Vi @ G @ np.linalg.inv(G.T @ Vi @ G) @ G.T @ Vi
    dense = []
    for i in range(2):
        for k in range(3):
            e = np.zeros(6)
            e[3 * i + k] = 1e-6
            dV = (GPFit(th + e, obs, (), 0.0, True).covariance() - GPFit(th - e, obs, (), 0.0, True).covariance()) / 2e-6
            dense.append(dV)
    expect = np.array([[0.5 * np.trace(P @ a @ P @ b) for b in dense] for a in dense])
    np.testing.assert_allclose(reml_information(th, obs, G), expect, rtol=1e-5, atol=1e-8 * np.abs(expect).max())
    assert linalg.norm(reml_information(th, _obs(False)[0], G) - reml_information(th, obs, G)) > 1e-3


def test_kriging_at_a_condition_seen_and_not_seen():
    from identification.studies.discrepancy_gp import GPFit
    obs, _, _, sc = _obs(True)
    th = np.array([0.2, np.log(0.4), -0.5, -0.3, np.log(0.8), 0.4])
    f = GPFit(th, obs, (), 0.0, True)
    xs = sc(np.array([[0.5], [1.1]]))
    for i in range(2):
        sig = obs.sigma[i]
        s2, ell, w2 = (sig * np.exp(th[3 * i])) ** 2, np.exp(th[3 * i + 1]), (sig * np.exp(th[3 * i + 2])) ** 2
        k, prior = f.cross(i, xs, np.array([1, 7]))             # condition 1 (seen), 7 (not seen)
        np.testing.assert_allclose(prior, s2 + w2, rtol=1e-13)
        start = sum(obs.sizes[:i])
        kb = k[:, start:start + obs.sizes[i]]
        same = obs.condition_codes(i) == 1
        expect = s2 * kernel_blocks(xs[:1], obs.x[i], ell)[0][0] * same + w2 * same
        np.testing.assert_allclose(kb[0], expect, rtol=1e-13)
        assert np.all(k[1] == 0.0)


def _model() -> Model:
    import casadi as ca
    return Model.explicit(["a", "b"], ["x"], ["y1", "y2"],
                          h=lambda p, q: ca.vertcat(p[0] * (1 - ca.exp(-p[1] * q[0])), p[0] * q[0] / (1 + p[1] * q[0])))


def _data():
    rng = np.random.default_rng(8)
    q = np.tile(Q, 3)
    cond = np.repeat([0, 1, 2], Q.size)
    mean = np.stack([2.0 * (1 - np.exp(-1.5 * q)), 2.0 * q / (1 + 1.5 * q)], axis=1) + np.array([0.2, -0.1, 0.15])[cond, None]
    z = mean[None] + 0.05 * rng.standard_normal((2, q.size, 2))
    return Measurements(q[:, None], z, 0.05, sensors=["y1", "y2"], input_names=["x"]), cond


def test_the_offset_term_is_an_option_and_refuses_exact_at():
    d, cond = _data()
    sc = InputScaling.of(d.inputs, {}, ("x",))
    off = fit_model_error(_model(), d, [1.0, 1.0], np.ones(2), sc, "discrepancy", groups=cond, condition_term=True)
    ship = fit_model_error(_model(), d, [1.0, 1.0], np.ones(2), sc, "discrepancy", groups=cond)
    assert off.gp.obs.condition_term and not ship.gp.obs.condition_term
    assert off.gp.rough(0) > 0.02                              # the offsets (0.2, -0.1, 0.15 about their mean)
    pinned = InputScaling.of(d.inputs, {"x": 0.2}, ("x",))
    with pytest.raises(ValueError, match="condition_term"):
        fit_model_error(_model(), d, [1.0, 1.0], np.ones(2), pinned, "discrepancy", groups=cond, condition_term=True)


def test_the_band_on_c_minus_1_dof_at_a_condition_not_seen():
    from scipy import stats
    d, cond = _data()
    sc = InputScaling.of(d.inputs, {}, ("x",))
    f = fit_model_error(_model(), d, [1.0, 1.0], np.ones(2), sc, "discrepancy", groups=cond, condition_term=True)
    q = np.array([[0.5], [1.2]])
    codes = np.array([1, 9])                                      # condition 1 seen, 9 not seen
    plug = f.predict(q, 0.05, True, conditions=codes)
    band = f.predict(q, 0.05, True, conditions=codes, variance_aware="conditions")
    np.testing.assert_allclose(band.mean, plug.mean, rtol=0, atol=0)
    var = ((plug.upper - plug.mean) / stats.norm.ppf(0.975)) ** 2
    A = np.array([f.gp.cross(i, sc(q[1:]), codes[1:])[1][0] for i in range(2)])
    nu = var[1] ** 2 * (3 - 1) / A ** 2                              # three conditions in the data
    np.testing.assert_allclose(band.dof[1], nu, rtol=1e-12)
    np.testing.assert_allclose(band.upper[1] - band.mean[1], stats.t.ppf(0.975, nu) * np.sqrt(var[1]), rtol=1e-10)
    assert np.all(np.isinf(band.dof[0]))                          # a condition seen: the normal band
    np.testing.assert_allclose(band.upper[0], plug.upper[0], rtol=1e-14)
    one = fit_model_error(_model(), d, [1.0, 1.0], np.ones(2), sc, "discrepancy", condition_term=True)
    b1 = one.predict(q, 0.05, True, conditions=np.array([-1, -1]), variance_aware="conditions")
    assert np.all(np.isinf(b1.upper)) and np.all(b1.dof == 0)    # one condition: nothing calibrates a band
    with pytest.raises(ValueError, match="variance_aware"):
        f.predict(q, 0.05, True, conditions=codes, variance_aware="c-1")
    with pytest.raises(ValueError, match="variance_aware: expected one of"):      # a truthy typo is no True
        f.discrepancy(q, 0.05, conditions=codes, variance_aware="condition")
