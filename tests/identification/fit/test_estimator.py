"""Exactness, derivative and agreement checks of the full-space estimator (issue 2, evidence 1 and 3)."""
import casadi as ca
import numpy as np
import pytest
from scipy.optimize import least_squares

from identification import (DataError, IdentifiabilityError, IdentificationError, IdentifySettings, Measurements,
                            identify,
                            information_contributions, simulate, solve_states)
from models import Model, ModelError, Parameter
from models.library import linear_model, spring_chain
from optimum import assert_agree_in_sd, assert_same_optimum


def _chain_data(n_y=5, n_M=2, seed=0, rel_sigma=0.01, p_true=(2.0, 0.5)):
    model = spring_chain(n_y)
    Q = np.array([[f, 0.3 * f] for f in np.linspace(0.4, 3.0, 5)])
    H = simulate(model, p_true, Q)
    sig = rel_sigma * np.abs(H).max(axis=0)
    rng = np.random.default_rng(seed)
    z = H[None] + sig * rng.standard_normal((n_M,) + H.shape)
    return model, Measurements(Q, z, sig, sensors=model.sensors)


def _line_with_bounded_slope():
    """y = a x + b with a in [0, 1] and data of slope 2: the bound on a is active."""
    model = Model.explicit(params=[Parameter("a", 0.0, 1.0), "b"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] * q[0] + p[1])
    x = np.arange(1.0, 8.0)
    return model, Measurements(x, (2.0 * x + 1.0).reshape(1, -1, 1), [0.1])


def _press_data(n_q, seed):
    """Press model and two noisy series at n_q loads (truth k5 = 520, k7 = 480 N/mm)."""
    from models.press import press_model
    model = press_model()
    q = np.linspace(100.0, 1600.0, n_q)[:, None]
    H = simulate(model, [520.0, 480.0], q)
    sig = np.array([0.015, 0.005, 0.004])
    rng = np.random.default_rng(seed)
    return model, Measurements(q, H[None] + sig * rng.standard_normal((2,) + H.shape), sig)


# ------------------------------------------------------------------ evidence 1: exactness
def test_linear_model_covariance_is_exact():
    X = np.array([[1.0, 0.5], [0.3, -1.0], [2.0, -1.0]])
    model = linear_model(X)
    q = np.linspace(0.5, 3.0, 6)
    rng = np.random.default_rng(1)
    sigma = np.array([0.1, 0.2, 0.3])
    z = (q[:, None] * (X @ [1.5, -0.7]))[None] + sigma * rng.standard_normal((3, 6, 3))
    z[1, 2, 0] = np.nan  # a missing value must be excluded
    data = Measurements(q, z, sigma)
    w = np.array([1.0, 0.0, 1.0])
    est = identify(model, data, p0=[1.0, 1.0], weights=w)
    rows, ys, ws = [], [], []
    for i in range(3):
        for j in range(6):
            for k in range(3):
                if w[k] > 0 and np.isfinite(z[i, j, k]):
                    rows.append(q[j] * X[k]); ys.append(z[i, j, k]); ws.append(1 / sigma[k] ** 2)
    A, b, W = np.array(rows), np.array(ys), np.diag(ws)
    C = np.linalg.inv(A.T @ W @ A)
    p_ls = C @ A.T @ W @ b
    np.testing.assert_allclose(est.p, p_ls, rtol=1e-10)
    np.testing.assert_allclose(est.cov, C, rtol=1e-10)
    np.testing.assert_allclose(est.cov_gn, C, rtol=1e-10)
    assert est.n_data == len(ys)
    assert np.allclose(est.S, 0.0, atol=1e-12 * np.abs(est.information).max())


def test_second_order_covariance_matches_finite_difference_of_dp_dz():
    """C = (dp/dz) Sigma^2 (dp/dz)^T; dp/dz by central differences of full re-identifications."""
    model, data = _chain_data(n_y=4, n_M=1, seed=3, rel_sigma=0.03)
    est = identify(model, data, p0=[1.0, 0.1])
    z0 = np.array(data.z)
    D = np.zeros((model.n_p, z0.size))
    for idx in range(z0.size):
        i, j, k = np.unravel_index(idx, z0.shape)
        step = 1e-4 * data.sigma[k]
        ps = []
        for sgn in (1, -1):
            z = z0.copy()
            z[i, j, k] += sgn * step
            ps.append(identify(model, data.with_z(z), p0=est.p).p)
        D[:, idx] = (ps[0] - ps[1]) / (2 * step)
    sig2 = np.broadcast_to(data.sigma ** 2, z0.shape).ravel()
    C_fd = D @ np.diag(sig2) @ D.T
    rel = np.linalg.norm(C_fd - est.cov) / np.linalg.norm(est.cov)
    assert rel < 1e-6, rel
    # and the second-order term matters here: the Gauss-Newton covariance is measurably different
    assert np.linalg.norm(est.cov_gn - est.cov) / np.linalg.norm(est.cov) > 1e-4


# ------------------------------------------------------------------ evidence 3: agreement
def test_full_space_equals_reduced_space_least_squares():
    model, data = _chain_data(n_y=8, n_M=2, seed=5)
    est = identify(model, data, p0=[1.0, 0.1])
    mask = data.mask()

    def resid(p):
        H = simulate(model, p, data.inputs, Y=solve_states(model, p, data.inputs))  # inner Newton on E
        return ((data.z - H[None]) / data.sigma)[mask]

    ls = least_squares(resid, x0=[1.0, 0.1], method="trf", xtol=1e-15, ftol=1e-15, gtol=1e-15,
                       x_scale="jac", max_nfev=2000)
    assert ls.success
    assert_agree_in_sd(est, ls.x)
    assert est.objective == pytest.approx(0.5 * float(ls.fun @ ls.fun), rel=1e-10)


def test_unknown_sigma_uses_rss_over_dof():
    model, data = _chain_data(n_y=5, n_M=3, seed=7)
    est_known = identify(model, data, p0=[1.0, 0.1], weights=[1, 0, 0, 0])
    est = identify(model, data.with_sigma(None), p0=[1.0, 0.1], weights=[1, 0, 0, 0])
    np.testing.assert_allclose(est.p, est_known.p, rtol=1e-9)
    s2 = est.rss / (est.n_data - model.n_p)
    np.testing.assert_allclose(est.cov_gn, est_known.cov_gn * s2 / data.sigma[0] ** 2, rtol=1e-8)
    assert est.sigma_estimated and np.allclose(est.sigma, np.sqrt(s2))
    assert est.reduced_chi2 == pytest.approx(1.0, rel=1e-10)


def test_information_contributions_reassemble_the_estimate_terms():
    model, data = _chain_data(n_y=5, n_M=2, seed=11)
    w = np.array([1.0, 0.0, 1.0, 1.0])
    est = identify(model, data, p0=[1.0, 0.1], weights=w)
    F, S = information_contributions(model, data, est.p)
    np.testing.assert_allclose(np.einsum("k,kij->ij", w, F), est.information, rtol=1e-9)
    np.testing.assert_allclose(np.einsum("k,kij->ij", w, S), est.S, rtol=1e-7,
                               atol=1e-9 * np.abs(est.information).max())


def test_large_parameter_scales_are_handled():
    """Parameters from 1e-6 to 1e6 and residuals of very different size in one fit."""
    model = Model.explicit(params=["a", "b"], inputs=["x"], sensors=["big", "small"],
                           h=lambda p, q: ca.vertcat(p[0] * ca.exp(-p[1] * q[0]), 1e-9 * p[0] * q[0]))
    x = np.linspace(0, 4e5, 12)
    p_true = np.array([3e6, 4e-6])
    H = np.array([[p_true[0] * np.exp(-p_true[1] * xi), 1e-9 * p_true[0] * xi] for xi in x])
    sigma = np.array([1e3, 1e-5])
    rng = np.random.default_rng(2)
    data = Measurements(x, H[None] + sigma * rng.standard_normal((2, 12, 2)), sigma)
    est = identify(model, data, p0=[1e6, 1e-5])
    assert np.all(np.abs(est.p - p_true) < 5 * est.stderr)


# ------------------------------------------------------------------ diagnostics and errors
def test_identifiability_error_names_parameters_and_sensors():
    model = Model.explicit(params=["a", "b"], inputs=["x"], sensors=["y"], h=lambda p, q: (p[0] + p[1]) * q[0])
    data = Measurements(np.arange(1.0, 6.0), np.arange(1.0, 6.0).reshape(1, 5, 1) * 2, [0.1])
    with pytest.raises(IdentifiabilityError) as exc:
        identify(model, data, p0=[1.0, 0.5])
    assert set(exc.value.params) == {"a", "b"} and exc.value.sensors == ("y",)
    assert "a" in str(exc.value) and "y" in str(exc.value)


def test_sensor_that_sees_nothing_is_reported():
    model, data = _chain_data(n_y=5)
    m2 = Model.explicit(params=["a", "b"], inputs=["x"], sensors=["s1", "s2"],
                        h=lambda p, q: ca.vertcat(p[0] * q[0], p[0] * q[0] ** 2 + p[1] * q[0]))
    d2 = Measurements(np.arange(1.0, 5.0), np.ones((1, 4, 2)), [0.1, 0.1])
    with pytest.raises(IdentifiabilityError, match="b") as exc:
        identify(m2, d2, p0=[1.0, 1.0], weights=[1, 0])
    assert exc.value.sensors == ("s1",)


def test_ipopt_failure_raises_with_status():
    model, data = _chain_data(n_y=5)
    from identification import IdentifySettings, IpoptSettings
    settings = IdentifySettings(ipopt=IpoptSettings(max_iter=1))
    with pytest.raises(IdentificationError) as exc:
        identify(model, data, p0=[0.2, 3.0], settings=settings)
    assert exc.value.status == "Maximum_Iterations_Exceeded"
    assert "Maximum_Iterations_Exceeded" in str(exc.value)


def test_summary_has_table_and_numbered_notes():
    model, data = _chain_data(n_y=5)
    est = identify(model, data.with_sigma(None), p0=[1.0, 0.1])
    text = est.summary()
    assert "k" in text and "std err" in text and "[1] sigma unknown" in text
    ci = np.asarray(est.conf_int(0.05))
    assert ci.shape == (2, 2) and np.all(ci[:, 0] < est.p) and np.all(est.p < ci[:, 1])
    ell = est.ellipsoid(0.05)
    assert ell.contains(est.p) and ell.boundary().shape == (200, 2)


def test_parameter_at_bound_is_noted():
    model, data = _line_with_bounded_slope()
    est = identify(model, data, p0=[0.5, 0.0])
    assert est.p[0] == pytest.approx(1.0)
    assert any("at a bound" in n for n in est.notes)


def test_poor_fit_is_noted():
    model = Model.explicit(params=["a", "b"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] * q[0] + p[1])
    x = np.linspace(0, 2, 15)
    data = Measurements(x, (x ** 3).reshape(1, -1, 1), [0.01])
    est = identify(model, data, p0=[1.0, 0.0])
    assert any("residuals exceed the sensor sigmas" in n for n in est.notes)


@pytest.mark.parametrize("kwargs, match", [
    (dict(p0=[1.0]), "p0: expected 2 values"),
    (dict(p0=[np.nan, 0.1]), "p0: start value of 'k' is not finite"),
    (dict(p0=[-1.0, 0.1]), "outside its bounds"),
    (dict(p0=[1.0, 0.1], weights=[0, 0, 0, 0]), "no sensor is selected"),
    (dict(p0=[1.0, 0.1], weights=[1, 1]), "weights: expected 4"),
])
def test_bad_arguments_name_the_argument(kwargs, match):
    model, data = _chain_data(n_y=5)
    with pytest.raises(DataError, match=match):
        identify(model, data, **kwargs)


def test_fewer_data_than_parameters():
    model = Model.explicit(params=["a", "b", "c"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] + p[1] * q[0] + p[2] * q[0] ** 2)
    data = Measurements([1.0, 2.0], np.ones((1, 2, 1)), [0.1])
    with pytest.raises(DataError, match="only 2 usable values .* 3 parameters"):
        identify(model, data, p0=[0, 0, 0])


def test_data_model_mismatch():
    model, data = _chain_data(n_y=5)
    with pytest.raises(DataError, match="inputs: has 1 columns"):
        identify(model, Measurements(np.ones(5), np.ones((1, 5, 4)), None), p0=[1, 0.1])
    with pytest.raises(DataError, match="has 2 sensors"):
        identify(model, Measurements(data.inputs, np.ones((1, 5, 2)), None), p0=[1, 0.1])
    with pytest.raises(TypeError, match="model: expected"):
        identify("chain", data, p0=[1, 0.1])


def test_model_with_wrong_E_size_is_rejected_at_build():
    with pytest.raises(ModelError, match="E returns 1 equations but n_y = 2"):
        Model(["a"], ["q"], ["y"], n_y=2, E=lambda y, p, q: y[0] - p[0], h=lambda y, p, q: y[0])
    with pytest.raises(ModelError, match="h returns 2 outputs but 1 sensors"):
        Model(["a"], ["q"], ["y"], n_y=1, E=lambda y, p, q: y - p[0], h=lambda y, p, q: ca.vertcat(y, y))
    with pytest.raises(ModelError, match="structurally singular"):
        Model(["a"], ["q"], ["y"], n_y=2, E=lambda y, p, q: ca.vertcat(y[0] - p[0], y[0] + q[0]),
              h=lambda y, p, q: y[1])
    with pytest.raises(ModelError, match="appears twice"):
        Model.explicit(["a", "a"], ["q"], ["y"], h=lambda p, q: p[0])
    with pytest.raises(ModelError, match="lower bound"):
        Parameter("k", 2.0, 1.0)


# ------------------------------------------------------------------ lazy bounds and the predictor
def test_lazy_bounds_interior_solution_equals_bounded_solve():
    """Pass 1 (no parameter bounds) is kept only inside the bounds; it is the bounded optimum."""
    model, data = _chain_data(n_y=6, n_M=2, seed=11)
    bounded = model.with_bounds({"k": (0.5, 10.0), "c": (0.01, 5.0)})
    lazy = identify(bounded, data, p0=[1.0, 0.1])
    strict = identify(bounded, data, p0=[1.0, 0.1], settings=IdentifySettings(lazy_bounds=False))
    assert lazy.diagnostics.ipopt_passes == 1 and strict.diagnostics.ipopt_passes == 1
    np.testing.assert_allclose(lazy.p, strict.p, rtol=1e-9)
    np.testing.assert_allclose(lazy.cov, strict.cov, rtol=1e-7)


def test_lazy_bounds_falls_back_to_the_bounded_problem_when_a_bound_is_active():
    model, data = _line_with_bounded_slope()
    lazy = identify(model, data, p0=[0.5, 0.0])
    strict = identify(model, data, p0=[0.5, 0.0], settings=IdentifySettings(lazy_bounds=False))
    assert lazy.diagnostics.ipopt_passes == 2
    np.testing.assert_allclose(lazy.p, strict.p, rtol=1e-9, atol=1e-9)
    assert lazy.p[0] <= 1.0


def test_predictor_changes_only_the_start_point():
    model, data = _press_data(8, 4)
    a = identify(model, data, p0=[450.0, 550.0])
    b = identify(model, data, p0=[450.0, 550.0], settings=IdentifySettings(predictor_step=0.0))
    np.testing.assert_allclose(a.p, b.p, rtol=1e-10)
    assert a.iterations <= b.iterations


@pytest.mark.parametrize("which", ["press", "chain"])
def test_stage_hessian_from_cached_derivatives_equals_casadi_hessian(which):
    """The NLP's stage Hessian, assembled from the model's lag_hess and dh/d(p, y), is exact."""
    from identification.fit.nlp import stage_hessian as _stage_hessian
    from models.press import press_model
    model = press_model() if which == "press" else spring_chain(7, n_sensors=4, n_groups=2)
    n_y, n_p, n_S = model.n_y, model.n_p, model.n_S
    y, p, q = ca.SX.sym("y", n_y), ca.SX.sym("p", n_p), ca.SX.sym("q", model.n_q_dim)
    zb, c, sf, lg = ca.SX.sym("zb", n_S), ca.SX.sym("c", n_S), ca.SX.sym("sf"), ca.SX.sym("lg", n_y)
    rng = np.random.default_rng(0)
    s_p, s_y, e = rng.uniform(0.5, 2, n_p), rng.uniform(0.5, 2, n_y), rng.uniform(0.5, 2, n_y)
    y_un, p_un = y * ca.DM(s_y), p * ca.DM(s_p)
    f = 0.5 * ca.sum1(c * (model.h_fun(y_un, p_un, q) - zb) ** 2)
    E = model.E_fun(y_un, p_un, q) * ca.DM(e)
    H_ref = ca.hessian(sf * f + ca.dot(lg, E), ca.vertcat(p, y))[0]
    H = _stage_hessian(model, y, p, q, zb, c, sf, lg, s_p, s_y, e, f, E)
    F = ca.Function("F", [y, p, q, zb, c, sf, lg], [ca.densify(H_ref), ca.densify(H)])
    scale_p = 500.0 if which == "press" else 1.0
    args = [rng.uniform(0, 1, n_y), rng.uniform(1, 3, n_p) * scale_p, rng.uniform(1, 3, model.n_q_dim) * 100,
            rng.uniform(0, 1, n_S), rng.uniform(0, 1, n_S), 0.7, rng.uniform(-1, 1, n_y)]
    a, b = (np.array(v) for v in F(*args))
    assert np.abs(a - b).max() <= 1e-12 * np.abs(a).max()


def _coupled_model():
    """A small implicit model whose outputs depend on p directly (dh/dp != 0) and nonlinearly on y."""
    def E(y, p, q):
        return ca.vertcat(p[0] * y[0] + y[0] ** 3 - q[0], y[1] - p[1] * ca.sin(y[0]) - q[1], y[2] * p[0] - y[1] ** 2)

    def h(y, p, q):
        return ca.vertcat(y[0] * p[1], y[1] + p[0] ** 2, ca.exp(0.1 * y[2]) * p[0])

    return Model(["a", "b"], ["u", "v"], ["s1", "s2", "s3"], n_y=3, E=E, h=h)


@pytest.mark.parametrize("builder", ["build_nlp_glued", "build_nlp_staged"])
@pytest.mark.parametrize("which", ["chain", "coupled"])
def test_assembled_nlp_derivatives_equal_casadi_ad(builder, which):
    """The constraint Jacobian and Lagrangian Hessian handed to Ipopt equal CasADi's AD of (f, g)."""
    import identification.fit.nlp as est_mod
    model = spring_chain(9, n_sensors=4, n_groups=3) if which == "chain" else _coupled_model()
    rng = np.random.default_rng(3)
    n_q = 4
    inputs = np.column_stack([rng.uniform(0.5, 2.0, n_q), rng.uniform(0.1, 0.6, n_q)])
    s_p, s_y, e = rng.uniform(0.5, 2, model.n_p), rng.uniform(0.5, 2, model.n_y), rng.uniform(0.5, 2, model.n_y)
    nlp = getattr(est_mod, builder)(model, inputs, s_p, s_y, e)
    x, f, g, par, hess_lag, jac_g = nlp.x, nlp.f, nlp.g, nlp.par, nlp.hess_lag, nlp.jac_g
    lam_f, lam_g = ca.MX.sym("lf"), ca.MX.sym("lg", g.size1())
    L = lam_f * f + ca.dot(lam_g, g)
    ref = ca.Function("ref", [x, par, lam_f, lam_g], [ca.jacobian(g, x), ca.triu(ca.hessian(L, x)[0])])
    xv, pv = rng.uniform(0.2, 1.5, x.size1()), rng.uniform(0, 1, par.size1())
    lf, lg = 0.8, rng.uniform(-1, 1, g.size1())
    J_ref, H_ref = (np.array(ca.densify(v)) for v in ref(xv, pv, lf, lg))
    J = np.array(ca.densify(jac_g(xv, pv)[1]))
    H = np.array(ca.densify(hess_lag(xv, pv, lf, lg)))
    np.testing.assert_allclose(J, J_ref, rtol=0, atol=1e-12 * np.abs(J_ref).max())
    np.testing.assert_allclose(H, H_ref, rtol=0, atol=1e-12 * np.abs(H_ref).max())


def test_large_state_model_uses_the_glued_nlp_and_agrees_with_the_reduced_fit(monkeypatch):
    """Models with more than 60 states take the MX-glued NLP; the estimate matches the reduced space."""
    import identification.fit.nlp as est_mod
    calls = []
    orig = est_mod.build_nlp_glued
    monkeypatch.setattr(est_mod, "build_nlp_glued", lambda *a: calls.append(1) or orig(*a))
    model = spring_chain(80, n_sensors=4, n_groups=2)
    q = np.array([[f, 0.3 * f] for f in np.linspace(0.2, 3.0, 4)])
    p_true = np.array([2.0, 2.2, 0.5])
    H = simulate(model, p_true, q)
    sig = 0.01 * np.abs(H).max(axis=0)
    data = Measurements(q, H[None] + sig * np.random.default_rng(5).standard_normal((2,) + H.shape), sig)
    est = identify(model, data, p0=[1.0, 1.0, 0.1])
    assert calls, "the glued NLP was not used for an 80-state model"
    ref = least_squares(lambda p: ((data.z - simulate(model, p, q)[None]) / sig).ravel(), [1.0, 1.0, 0.1],
                        xtol=1e-14, ftol=1e-14, gtol=1e-14)
    assert_agree_in_sd(est, ref.x)


def test_jit_compiled_functions_give_the_same_numbers():
    """set_jit(True) compiles the press model's functions to C: identical estimates (to round-off)."""
    import shutil
    from models.state import set_jit
    if shutil.which("gcc") is None and shutil.which("cc") is None:
        pytest.skip("no C compiler on the PATH")
    model, data = _press_data(6, 9)
    ref = identify(model, data, p0=[450.0, 550.0])
    prev = set_jit(True)
    try:
        est = identify(model, data, p0=[450.0, 550.0])
    finally:
        set_jit(prev)
    np.testing.assert_allclose(est.p, ref.p, rtol=1e-12)
    np.testing.assert_allclose(est.cov, ref.cov, rtol=1e-9)


def test_model_stated_in_mx_gives_the_same_estimate_as_in_sx():
    """MX-stated models take the generic NLP builder (CasADi's own constraint Jacobian, the
    assembled stage Hessian); SX-stated ones the staged builder: same estimate and covariance."""
    def E(y, p, q):
        return ca.vertcat(p[0] * y[0] + y[0] ** 3 - q[0], y[1] - p[1] * ca.sin(y[0]) - q[1])

    def h(y, p, q):
        return ca.vertcat(y[0], y[1] + 0.1 * p[0])

    Q = np.column_stack([np.linspace(0.5, 3, 8), np.linspace(0.1, 0.5, 8)])
    sig = np.array([0.01, 0.01])
    est = {}
    for sym in ("SX", "MX"):
        m = Model(["a", "b"], ["u", "v"], ["s1", "s2"], n_y=2, E=E, h=h, symbolic=sym)
        H = simulate(m, [2.0, 0.7], Q)
        data = Measurements(Q, H[None] + sig * np.random.default_rng(1).standard_normal((2,) + H.shape), sig)
        est[sym] = identify(m, data, [1.5, 0.5])
    np.testing.assert_allclose(est["MX"].p, est["SX"].p, rtol=1e-10)
    np.testing.assert_allclose(est["MX"].cov, est["SX"].cov, rtol=1e-8)


def test_public_refinement_reproduces_the_estimate_and_converges_from_a_nearby_point():
    """identification.fit.refinement: at the estimate no step is taken and the terms are the
    estimate's; from a perturbed point the exact Newton steps return to it."""
    from identification.fit.refinement import ReducedProblem, refine
    model, data = _press_data(8, 4)
    est = identify(model, data, p0=[450.0, 550.0])
    problem = ReducedProblem.of(model, data, est.weights, est.sigma, np.abs(est.p))
    at = refine(problem, problem.evaluate(est.p, est.states), 5, stop_decrement=1e-18)
    assert at.steps == 0
    assert at.point.objective == pytest.approx(est.objective, rel=1e-12)
    np.testing.assert_allclose(at.information, est.information, rtol=1e-12)
    np.testing.assert_allclose(at.S, est.S, rtol=1e-9, atol=1e-12 * np.abs(est.S).max())
    far = refine(problem, problem.evaluate(est.p * 1.02, est.states), 10)
    assert far.steps >= 1 and far.decrement < 1e-12
    np.testing.assert_allclose(far.point.p, est.p, rtol=1e-8)


def test_model_cache_holds_the_fits_caches_and_is_empty_in_copies():
    """Numerics, stage functions, start states and Ipopt solvers live in model.cache; a
    pickled or re-bounded copy starts empty and gives the same estimate."""
    import pickle
    from models.cache import Cache
    model, data = _press_data(6, 2)
    est = identify(model, data, p0=[450.0, 550.0])
    assert isinstance(model.cache, Cache)
    for name in ("numerics", "identify.initial_states", "identify.scalings", "ipopt_solvers"):
        assert model.cache.size(name) == 1, name
    identify(model, data, p0=[450.0, 550.0])
    assert model.cache.size("ipopt_solvers") == 1            # the compiled solver is reused
    for copy in (pickle.loads(pickle.dumps(model)), model.with_bounds({"k5": (100.0, 1000.0)})):
        assert copy.cache is not model.cache and copy.cache.size("numerics") == 0
        np.testing.assert_array_equal(identify(copy, data, p0=[450.0, 550.0]).p, est.p)


def test_cache_is_bounded_per_namespace():
    from models.cache import Cache
    c = Cache()
    for i in range(5):
        c.put("lru", i, i * i, maxsize=3)
    assert c.size("lru") == 3 and c.get("lru", 0) is None and c.get("lru", 4) == 16
    assert c.get_or_make("once", "k", lambda: [1]) is c.get_or_make("once", "k", lambda: [2])
    with pytest.raises(ValueError, match="maxsize"):
        c.put("bad", 0, 0, maxsize=0)


def test_set_jit_switches_the_documented_configuration():
    from models.state import JIT, set_jit
    prev = set_jit(True)
    try:
        assert JIT.enabled and set_jit(False) is True and not JIT.enabled
    finally:
        set_jit(prev)


# ------------------------------------------------------------------ issue 15: mapped NLP, explicit path, absurd fits
def test_explicit_nlp_is_over_p_only_and_its_hessian_equals_casadi_ad():
    """An explicit model's NLP has the parameters as its only variables, no constraints, and the
    mapped (reduced) stage Hessian equals CasADi's AD of the mapped objective."""
    import identification.fit.nlp as est_mod
    model = Model.explicit(["a", "b", "c"], ["x", "u"], ["y1", "y2"],
                           h=lambda p, q: ca.vertcat(p[0] * ca.exp(-p[1] * q[0]) + p[2] * q[1],
                                                     p[1] ** 2 * ca.sin(q[0])))
    rng = np.random.default_rng(2)
    inputs = rng.uniform(0.1, 2.0, (37, 2))
    nlp = est_mod.build_nlp(model, inputs, rng.uniform(0.5, 2, 3), np.ones(0), np.ones(0))
    assert nlp.x.size1() == model.n_p and nlp.g.size1() == 0
    lam_f = ca.MX.sym("lf")
    ref = ca.Function("ref", [nlp.x, nlp.par, lam_f], [ca.triu(ca.hessian(lam_f * nlp.f, nlp.x)[0])])
    xv, pv = rng.uniform(0.2, 1.5, 3), rng.uniform(0, 1, nlp.par.size1())
    H_ref = np.array(ca.densify(ref(xv, pv, 0.8)))
    H = np.array(ca.densify(nlp.hess_lag(xv, pv, 0.8, np.zeros(0))))
    np.testing.assert_allclose(H, H_ref, rtol=0, atol=1e-12 * np.abs(H_ref).max())


def test_many_point_explicit_fit_equals_scipy_exact_jacobian():
    """y = a (1 - exp(-b x)) on 40 000 points (more than one evaluation chunk): the estimate equals
    scipy least_squares with the exact Jacobian (in standard errors; mudoe's point is the optimum), and the covariance equals (J^T W J)^-1 to the
    second-order term's size."""
    n = 40_000
    model = Model.explicit(["a", "b"], ["x"], ["y"], h=lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])))
    rng = np.random.default_rng(11)
    x = rng.uniform(0.05, 8.0, n)
    sig = 0.02
    z = 2.0 * (1 - np.exp(-0.7 * x)) + sig * rng.standard_normal(n)
    est = identify(model, Measurements(x, z.reshape(1, -1, 1), [sig]), p0=[1.0, 1.0])

    def res(p):
        return (p[0] * (1 - np.exp(-p[1] * x)) - z) / sig

    def jac(p):
        e = np.exp(-p[1] * x)
        return np.column_stack([1 - e, p[0] * x * e]) / sig

    ref = least_squares(res, [1.0, 1.0], jac=jac, xtol=1e-15, ftol=1e-15, gtol=1e-15)
    # scipy stops where its tolerances are met, which depends on the CPU's kernels (on one machine
    # 7e-10 sd short of the optimum): agreement in standard errors and mudoe's optimality hold anywhere
    assert_same_optimum(est.p, ref.x, res, jac)
    J = jac(ref.x)
    np.testing.assert_allclose(est.cov_gn, np.linalg.inv(J.T @ J), rtol=1e-8)
    assert est.fitted.shape == (n, 1) and est.G.shape == (n, 1, 2)


def test_many_inputs_states_are_solved_at_once_and_equal_the_per_input_solve():
    """With at least BATCH_START_MIN inputs the states at p are solved together by damped Newton
    from the model's guesses; they equal the per-input solves to round-off."""
    from models import state
    model = spring_chain(4)
    n = state.BATCH_START_MIN + 13
    Q = np.column_stack([np.linspace(0.2, 3.0, n), np.linspace(0.0, 0.9, n)])
    p = np.array([2.0, 0.5])
    Y = solve_states(model, p, Q)
    Y_ref = np.array([state.solve_state(model, p, q) for q in Q])
    np.testing.assert_allclose(Y, Y_ref, rtol=1e-11, atol=1e-12 * np.abs(Y_ref).max())


def test_estimate_at_absurd_values_is_not_bounded():
    """Data that do not bound k (y = c + 1/(1 + k x) with constant data: k runs to infinity) used to
    return an accepted estimate k ~ 1e12 with NaN standard errors, then an IdentificationError
    ("absurd values"); it is now a result that says so (issue 20 item 4): k -> +inf, c finite."""
    model = Model.explicit(["c", "k"], ["x"], ["y"], h=lambda p, q: p[0] + 1 / (1 + p[1] * q[0]))
    x = np.linspace(0.5, 5, 20)
    data = Measurements(x, (1.0 + 0.01 * np.sin(7 * x)).reshape(1, -1, 1), [0.01])
    est = identify(model, data, p0=[1.0, 1.0])
    assert not est.bounded and est.status == "Not_Bounded" and not est.success
    assert est.unbounded.involved == ("k",) and est.unbounded.ends() == {"k": "+inf"}
    assert np.isinf(est.stderr[1]) and np.isfinite(est.stderr[0])
    assert any("absurd values" in n for n in est.notes)          # where the solver stopped, kept as a note
    good = Measurements(x, (1.0 + 1 / (1 + 2.0 * x) + 0.001 * np.sin(7 * x)).reshape(1, -1, 1), [0.01])
    est = identify(model, good, p0=[1.0, 1.0])
    assert np.all(np.isfinite(est.stderr)) and abs(est.p[1] - 2.0) < 0.1


def test_explicit_model_solved_by_reduced_newton_equals_the_ipopt_path():
    """The reduced-space Newton path of explicit models gives Ipopt's estimate and covariance;
    an active bound sends it to the bounded Ipopt solve (pass 2)."""
    x = np.array([1.0, 2.0, 3.0, 5.0, 7.0, 10.0])
    y = np.array([8.3, 10.3, 19.0, 16.0, 15.6, 19.8])                  # Rooney-Biegler
    model = Model.explicit(["a", "b"], ["x"], ["y"], h=lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])))
    data = Measurements(x, y.reshape(1, -1, 1), sigma=None)
    newton = identify(model, data, p0=[15.0, 0.5])
    ipopt = identify(model, data, p0=[15.0, 0.5], settings=IdentifySettings(explicit_newton=False))
    assert newton.diagnostics.solver == "reduced Newton" and ipopt.diagnostics.solver == "ipopt"
    assert newton.success and newton.diagnostics.newton_decrement < 1e-18
    np.testing.assert_allclose(newton.p, ipopt.p, rtol=1e-10)
    np.testing.assert_allclose(newton.cov, ipopt.cov, rtol=1e-8)
    bounded, bdata = _line_with_bounded_slope()
    est = identify(bounded, bdata, p0=[0.5, 0.0])
    assert est.diagnostics.solver == "ipopt" and est.diagnostics.ipopt_passes == 2 and est.p[0] <= 1.0


def test_one_state_model_fits_like_its_explicit_twin():
    """A model with n_y = 1 (a scalar state; the stage scalings index 1-element vectors) gives the
    estimate and covariance of the same model written explicitly."""
    import casadi as ca
    from identification import Measurements, identify
    from models import Model
    x = np.linspace(0.1, 2.0, 8)
    truth = np.array([1.0, 0.3])
    z = (truth[0] * x / (1 + truth[1] * x))[None, :, None] + 0.001 * np.random.default_rng(0).standard_normal((2, 8, 1))
    data = Measurements(x, z, [0.001])
    implicit = Model(["a", "b"], ["x"], ["y"], n_y=1, E=lambda y, p, q: y[0] * (1 + p[1] * q[0]) - p[0] * q[0],
                     h=lambda y, p, q: y[0])
    explicit = Model.explicit(params=["a", "b"], inputs=["x"], sensors=["y"],
                              h=lambda p, q: p[0] * q[0] / (1 + p[1] * q[0]))
    ei, ee = identify(implicit, data, [0.8, 0.2]), identify(explicit, data, [0.8, 0.2])
    np.testing.assert_allclose(ei.p, ee.p, rtol=1e-8)
    np.testing.assert_allclose(ei.cov, ee.cov, rtol=1e-6)


def test_far_start_stays_on_the_reduced_newton_path_and_equals_the_ipopt_fit():
    """Eckerle4 from NIST's far start1: the Newton iteration alone fails there; Levenberg-Marquardt
    steps on the exact Gauss-Newton model bring it into reach, and the estimate and covariance
    equal the full-space Ipopt fit (explicit_newton off) and the certified values."""
    import importlib.util
    import pathlib
    import sys
    path = pathlib.Path(__file__).with_name("nist.py")
    spec = importlib.util.spec_from_file_location("nist_data", path)
    nist = importlib.util.module_from_spec(spec)
    sys.modules["nist_data"] = nist
    spec.loader.exec_module(nist)
    d = nist.load("Eckerle4")
    fun = nist.MODELS["Eckerle4"]
    model = Model.explicit(["b1", "b2", "b3"], ["x"], ["y"], h=lambda p, q: fun(p, q[0]))
    data = Measurements(d.x, d.y.reshape(1, -1, 1), sigma=None)
    est = identify(model, data, p0=d.start1)
    ref = identify(model, data, p0=d.start1, settings=IdentifySettings(explicit_newton=False))
    assert est.diagnostics.solver == "reduced Newton"
    assert ref.diagnostics.solver == "ipopt"
    np.testing.assert_allclose(est.p, d.certified, rtol=1e-9)
    np.testing.assert_allclose(est.p, ref.p, rtol=1e-10)
    np.testing.assert_allclose(est.cov, ref.cov, rtol=1e-8)
    assert est.notes == ref.notes
