"""The derived model with fixed parameters as input columns (identification.fit.fixed, issue 15)."""
from __future__ import annotations

import pickle

import casadi as ca
import numpy as np
import pytest

from identification import Measurements, identify
from identification.fit.batch import BatchData, fit_batch
from identification.fit.fixed import fixed_batch, fixed_model, full_parameters
from identification.inference.profile import lr_region
from models import Model
from models.library import spring_chain


def _derivatives(model: Model):
    """(h, dh/dy, dh/dp, E_y, E_p, Hessian of lam^T h + mu^T E in (y, p)) as one CasADi function of (y, p, q, lam, mu)."""
    y, p, q = (ca.SX.sym(n, k) for n, k in (("y", model.n_y), ("p", model.n_p), ("q", model.n_q_dim)))
    lam, mu = ca.SX.sym("lam", model.n_S), ca.SX.sym("mu", model.n_y)
    h, E = model.h_fun(y, p, q), model.E_fun(y, p, q)
    v = ca.vertcat(y, p)
    L = ca.dot(lam, h) + (ca.dot(mu, E) if model.n_y else 0)
    return ca.Function("d", [y, p, q, lam, mu], [h, ca.jacobian(h, y), ca.jacobian(h, p), ca.jacobian(E, y),
                                                 ca.jacobian(E, p), ca.hessian(L, v)[0]])


@pytest.mark.parametrize("fixed", [[1], [0, 2]])
def test_derived_model_has_the_values_and_exact_derivatives_of_the_model(fixed):
    """Implicit 3-parameter spring chain: h', E' and their first and second derivatives (CasADi AD) at
    (y, p_R, (q, c)) equal the model's at (y, P(p_R, c), q) -- the free columns, the same numbers."""
    model = spring_chain(n_y=4, n_sensors=2, n_groups=2)
    fm = fixed_model(model, fixed)
    free = [k for k in range(model.n_p) if k not in fixed]
    assert fm.param_names == tuple(model.param_names[k] for k in free) and fm.n_y == model.n_y
    assert fm.inputs == model.inputs + tuple(f"{model.param_names[k]} (fixed)" for k in fixed)
    np.testing.assert_array_equal(fm.lower, model.lower[free])
    assert fixed_model(model, fixed) is fm                                # kept in the model's cache
    rng = np.random.default_rng(2)
    f, fd = _derivatives(model), _derivatives(fm)
    v_free = np.r_[np.arange(model.n_y), model.n_y + np.array(free)]
    for _ in range(3):
        y, p, q = rng.normal(size=model.n_y), rng.uniform(0.5, 2.0, model.n_p), rng.normal(size=2)
        lam, mu = rng.normal(size=model.n_S), rng.normal(size=model.n_y)
        a = [np.array(t) for t in f(y, p, q, lam, mu)]
        b = [np.array(t) for t in fd(y, p[free], np.r_[q, p[fixed]], lam, mu)]
        np.testing.assert_array_equal(b[0], a[0])                         # h
        np.testing.assert_array_equal(b[1], a[1])                         # h_y
        np.testing.assert_array_equal(b[2], a[2][:, free])                # h_p (free columns)
        np.testing.assert_array_equal(b[3], a[3])                         # E_y
        np.testing.assert_array_equal(b[4], a[4][:, free])                # E_p
        np.testing.assert_array_equal(b[5], a[5][np.ix_(v_free, v_free)])  # Lagrangian Hessian
    pickle.loads(pickle.dumps(fm))                                        # ships to worker processes


def test_full_parameters_and_bad_fixed_indices():
    np.testing.assert_array_equal(full_parameters(4, [1, 3], np.array([[1.0, 2.0]]), np.array([[7.0, 8.0]])),
                                  [[1.0, 7.0, 2.0, 8.0]])
    model = spring_chain(n_y=3, n_sensors=1)
    for bad in ([], [0, 1], [2], [0, 0]):
        with pytest.raises(ValueError, match="fixed"):
            fixed_model(model, bad)
    with pytest.raises(TypeError, match="model"):
        fixed_model("press", [0])


def _rise_and_slope():
    model = Model.explicit(params=["a", "b", "c"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])) + p[2] * q[0], name="rise and slope")
    x = np.linspace(0.5, 10.0, 12)
    z = (3 * (1 - np.exp(-0.4 * x)) + 0.1 * x)[None, :, None] + 0.05 * np.random.default_rng(1).standard_normal((2, 12, 1))
    data = Measurements(x, z, [0.05])
    return model, data, identify(model, data, [2.0, 0.5, 0.0])


def _spring():
    from identification.studies.montecarlo import ModelCampaign
    model = spring_chain(n_y=4, n_sensors=2, n_groups=2)
    p_true = np.array([2.0, 3.0, 0.05])
    gen = ModelCampaign(model, p_true, np.column_stack([np.linspace(0.5, 3.0, 10), np.linspace(1.0, -1.0, 10)]), 0.01, 2)
    data = gen(np.random.default_rng(5))
    return model, data, identify(model, data, p_true)


@pytest.mark.parametrize("problem", [_rise_and_slope, _spring])
def test_a_batch_with_per_member_inputs_gives_the_constrained_fits(problem):
    """Explicit and implicit 3-parameter models, (p_0, p_1) fixed at the 16 points of a 4 x 4 grid: fit_batch
    with per-member inputs (each member its own rows (q, c)) gives the objectives of lr_region's per-point
    Newton (to 1e-8) and of the stacked batch, and each member's estimate is that of a one-member batch."""
    model, data, est = problem()
    reg = lr_region(model, data, est, (0, 1), n_grid=4, grid="axes")
    assert np.all(np.isfinite(reg.statistic))
    values = np.column_stack([reg.X.ravel(), reg.Y.ravel()])
    fm = fixed_model(model, [0, 1])
    bd = fixed_batch(data.inputs, data.z, est.sigma, values)
    assert not bd.shared and bd.inputs.shape == (16, data.n_q, data.inputs.shape[1] + 2)
    bf = fit_batch(fm, bd, est.p[2:], est.weights)
    assert bf.fallbacks == () and np.all(bf.converged)
    np.testing.assert_allclose(bf.objective, est.objective + reg.statistic.ravel() / 2, rtol=1e-8)
    for r in (0, 7):
        one = fit_batch(fm, [bd.member(r)], est.p[2:], est.weights)
        np.testing.assert_allclose(bf.p[r], one.p[0], rtol=1e-9)
        np.testing.assert_allclose(bf.objective[r], one.objective[0], rtol=1e-12)


def test_per_member_inputs_of_another_shape_are_refused():
    model, data, est = _rise_and_slope()
    with pytest.raises(Exception, match="inputs"):
        BatchData(np.zeros((3, data.n_q, 2)), np.zeros((2,) + data.z.shape), None)
    other = Measurements(data.inputs[:5], data.z[:, :5], [0.05])
    with pytest.raises(Exception, match=r"data\[1\].*shape"):
        BatchData.of([data, other])
    shifted = Measurements(data.inputs + 0.1, data.z, [0.05])
    bd = BatchData.of([data, shifted])
    assert not bd.shared
    np.testing.assert_array_equal(bd.member_inputs(1), shifted.inputs)
    ch, cd, cest = _spring()
    moved = Measurements(cd.inputs * 1.1, cd.z, cd.sigma)
    with pytest.raises(Exception, match="Y0"):
        fit_batch(ch, [cd, moved], cest.p, Y0=np.zeros((cd.n_q, ch.n_y)))     # per member: (2, n_q, n_y)
