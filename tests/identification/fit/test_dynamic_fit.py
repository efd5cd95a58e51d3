"""identify on dynamic models: collocation with discretisation error control (identification.fit.dynamic_fit)."""
import warnings

import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

from identification import (DataError, DynamicMeasurements, Estimate, Measurements, Split, detect, identify,
                            information_contributions)
from identification.fit.dynamic_fit import (DegenerateStartWarning, DiscretisationRecord, DiscretisationSettings,
                                            collocated_problem, identify_dynamic, simulate_campaign)
from models import Model
from mudoe.example_reactor import HORIZON, P_TRUE, R_KJ, T_REF, TIMES, build

Q = np.array([[1.0, 330.0], [1.0, 340.0], [1.0, 350.0], [2.0, 350.0], [2.0, 360.0], [2.0, 370.0]])
SIGMA = np.array([0.01, 0.008])
P0 = [1.5, 50.0, 1.0, 70.0]


def ivp(p, q, t):
    """c_A, c_B at times t by solve_ivp (rtol 1e-10): the reference integrator."""
    k1, k2 = (p[2 * i] * np.exp(-p[2 * i + 1] / R_KJ * (1 / q[1] - 1 / T_REF)) for i in range(2))
    r = solve_ivp(lambda _, x: [-k1 * x[0], k1 * x[0] - k2 * x[1], k2 * x[1]], (0, t[-1]), [q[0], 0, 0],
                  t_eval=t, rtol=1e-10, atol=1e-13, method="LSODA")
    return r.y[:2].T


def campaign(seed=0, times=None, n_M=1):
    rng = np.random.default_rng(seed)
    times = [TIMES] * len(Q) if times is None else times
    n_t = max(len(t) for t in times)
    z = np.full((n_M, len(Q), n_t, 2), np.nan)
    for j, (q, t) in enumerate(zip(Q, times)):
        z[:, j, :len(t)] = ivp(P_TRUE, q, np.asarray(t)) + SIGMA * rng.standard_normal((n_M, len(t), 2))
    return z


def reference_fit(z, times):
    """scipy least_squares over solve_ivp on the present values (the weighted residuals of identify)."""
    def res(p):
        out = []
        for j, (q, t) in enumerate(zip(Q, times)):
            r = (z[0, j, :len(t)] - ivp(p, q, np.asarray(t))) / SIGMA
            out.append(r[np.isfinite(r)])
        return np.concatenate(out)
    return least_squares(res, P0, x_scale=[1, 50, 1, 50], xtol=1e-12, ftol=1e-12, gtol=1e-12).x


def test_reactor_agrees_with_reference_fit_within_five_hundredths_of_a_standard_error():
    z = campaign()
    est = identify(build(), DynamicMeasurements(Q, TIMES, z, SIGMA, sensors=["cA", "cB"]), P0)
    ref = reference_fit(z, [TIMES] * len(Q))
    assert np.all(np.abs(est.p - ref) / est.stderr < 0.05), (est.p - ref) / est.stderr
    rec = est.diagnostics.discretisation
    assert isinstance(rec, DiscretisationRecord) and rec.bounded
    assert rec.error_sigma <= 0.01 and np.abs(rec.shift_se).max() <= 0.01
    assert any(n.startswith("discretisation: Radau IIA") for n in est.notes) and "discretisation" in est.summary()
    # the estimate is that of the collocated static model: covariance and profiles work on it unchanged
    assert est.model.n_y == 3 * (1 + 3 * rec.n_elements) and est.cov.shape == (4, 4)
    ci = est.conf_int(0.05, method="profile")
    wald = est.conf_int(0.05)
    # curvature is small (relative 0.01 << 0.64): the profile intervals equal the Wald ones to 1 % of their width
    width = wald[:, 1] - wald[:, 0]
    assert np.all(np.abs(np.asarray(ci.lower) - wald[:, 0]) < 0.01 * width)
    assert np.all(np.abs(np.asarray(ci.upper) - wald[:, 1]) < 0.01 * width)


def test_error_control_refines_a_coarse_mesh():
    z = campaign(seed=1)
    data = DynamicMeasurements(Q, TIMES, z, SIGMA, sensors=["cA", "cB"])
    coarse = DiscretisationSettings(degree=2, elements=1)       # order 3 on the sampling grid (10 elements)
    est = identify_dynamic(build(), data, P0, discretisation=coarse)
    rec = est.diagnostics.discretisation
    assert len(rec.history) >= 2 and rec.history[0][1] > 0.01 and rec.bounded
    assert rec.n_elements > rec.history[0][0] and rec.error_sigma <= 0.01
    ref = reference_fit(z, [TIMES] * len(Q))
    assert np.all(np.abs(est.p - ref) / est.stderr < 0.05)
    # no refinement allowed: the fit says that its discretisation error is not bounded
    est = identify_dynamic(build(), data, P0, discretisation=DiscretisationSettings(degree=2, elements=1,
                                                                                    max_refinements=0))
    rec = est.diagnostics.discretisation
    assert not rec.bounded and rec.error_sigma > 0.01
    assert "discretisation error NOT bounded" in Estimate.from_record(est).summary()


def test_ragged_times_and_missing_values():
    times = [TIMES, TIMES[::2], TIMES[1:7], TIMES, np.r_[0.1, TIMES[3:]], TIMES[:4]]
    z = campaign(seed=2, times=times)
    z[0, 0, 3, 1] = np.nan                     # a missing reading
    times_ref = [np.asarray(t) for t in times]
    data = DynamicMeasurements(Q, times, z, SIGMA, sensors=["cA", "cB"])
    flat = data.flat()
    assert flat.n_data() == int(np.isfinite(z).sum())
    assert ("cA", 0.1) in data.pairs and np.isnan(flat.z[0, 0, flat.sensors.index("cA@0.1")])
    est = identify(build(), data, P0)
    ref = reference_fit(z, times_ref)
    assert np.all(np.abs(est.p - ref) / est.stderr < 0.05)
    assert est.n_data == int(np.isfinite(z).sum())
    sub = data.subset(inputs=[1, 2])
    assert sub.times.shape == (2, 6) and np.isnan(sub.times[0, 5])


def test_collocated_problem_is_a_static_model():
    data = DynamicMeasurements(Q, TIMES, campaign(seed=3), SIGMA)        # default sensor names s1, s2
    cm, flat = collocated_problem(build(), data)
    assert isinstance(flat, Measurements) and flat.sensors[:2] == ("cA@0.2", "cB@0.2")
    assert cm.sensors == flat.sensors and cm.mesh.boundaries[-1] == HORIZON
    est = identify(cm, flat, P0)                # no error control: the caller's mesh
    assert est.diagnostics.discretisation is None and np.all(np.abs(est.p - P_TRUE) / est.stderr < 4)


@pytest.mark.parametrize("make, exc, match", [
    (lambda: DynamicMeasurements(Q, TIMES[::-1], np.zeros((1, 6, 10, 2)), SIGMA), DataError,
     "times: experiment 1: sampling times must be strictly increasing"),
    (lambda: DynamicMeasurements(Q, np.r_[-0.1, TIMES[1:]], np.zeros((1, 6, 10, 2)), SIGMA), DataError,
     "times: experiment 1 has a negative sampling time"),
    (lambda: DynamicMeasurements(Q, TIMES, np.zeros((1, 6, 10, 2)), np.ones((10, 2))), DataError,
     "sigma: expected 2 values .one per instrument"),
    (lambda: DynamicMeasurements(Q, [TIMES, TIMES[:5]] + [TIMES] * 4, np.zeros((1, 6, 10, 2)), SIGMA),
     DataError, "z: experiment 2 has a value at sample 6"),
    (lambda: DynamicMeasurements(Q, TIMES, np.zeros((1, 6, 9, 2)), SIGMA), DataError, "z: expected shape"),
    (lambda: identify(build(), DynamicMeasurements(Q, TIMES + 0.5, campaign(), SIGMA), P0), DataError,
     "data.times: sampling time 2.5 lies beyond the horizon 2"),
    (lambda: identify(build("profile"), DynamicMeasurements(Q, TIMES, campaign(), SIGMA), P0), DataError,
     r"data.inputs: has 2 columns but model .* takes 9 \(cA0, T@0"),
    (lambda: identify(build(), Measurements(Q, np.zeros((1, 6, 2)), SIGMA), P0), TypeError,
     "data: a dynamic model needs identification.DynamicMeasurements"),
])
def test_bad_data_names_the_argument(make, exc, match):
    with pytest.raises(exc, match=match):
        make()


def test_planned_information_per_sensor_and_time():
    # planning before data: one matrix per (sensor, time) pair, on an error-controlled mesh
    m = build()
    F, S = information_contributions(m, None, P_TRUE, inputs=Q, times=TIMES, sigma=SIGMA)
    assert F.shape == (2 * TIMES.size, 4, 4) and not S.any()
    data = DynamicMeasurements(Q, TIMES, campaign(seed=4), SIGMA, sensors=["cA", "cB"])
    est = identify(m, data, P0)
    # with data, at the estimate: the matrices sum to the estimate's information and S
    F2, S2 = information_contributions(m, data, est.p)
    assert np.allclose(F2.sum(axis=0), est.information, rtol=1e-8)
    assert np.allclose(S2.sum(axis=0), est.S, rtol=1e-6, atol=1e-9 * np.abs(est.information).max())
    # the planned information at the true p is that at the estimate up to the estimation error
    assert abs(np.linalg.slogdet(F.sum(axis=0))[1] - np.linalg.slogdet(est.information)[1]) < 0.1
    with pytest.raises(DataError, match="times="):
        information_contributions(m, None, P_TRUE, inputs=Q, sigma=SIGMA)


def test_detect_splits_by_experiment_on_the_collocated_model():
    # Algorithm 1 runs unchanged on the estimate's collocated model and flat data (a correct model)
    z = campaign(seed=5, n_M=2)
    est = identify(build(), DynamicMeasurements(Q, TIMES, z, SIGMA, sensors=["cA", "cB"]), P0)
    res = detect(est.model, est.data, [Split("cA0 = 1 vs 2", (0, 1, 2), (3, 4, 5))], est.p, normality="override")
    test = res.tests[0]
    assert test.ok and test.alpha_lr > 0.025 and "likelihood_ratio bonferroni: not rejected" in res.summary()


def test_spring_damper_with_cubic_spring_agrees_with_reference_fit():
    from mudoe.example_oscillator import MASS, P_TRUE as P_OSC, TIMES as T_OSC, build as oscillator
    F, sig = np.array([[2.0], [8.0]]), np.array([0.05, 0.05])       # N; mm, m/s^2
    T_OSC = T_OSC[:25]                                                # 0.5 s, 1.6 periods

    def ivp_osc(p, f):
        def rhs(_, s):
            return [s[1], (f - p[1] * s[1] - p[0] * s[0] - p[2] * s[0] ** 3) / MASS]
        x, v = solve_ivp(rhs, (0, T_OSC[-1]), [0, 0], t_eval=T_OSC, rtol=1e-10, atol=1e-13, method="DOP853").y
        return np.c_[1e3 * x, (f - p[1] * v - p[0] * x - p[2] * x ** 3) / MASS]

    z = np.array([ivp_osc(P_OSC, f[0]) for f in F])[None]
    z = z + sig * np.random.default_rng(6).standard_normal(z.shape)
    est = identify(oscillator(), DynamicMeasurements(F, T_OSC, z, sig, sensors=["x", "a"]), [300.0, 3.0, 2e6])
    assert est.diagnostics.discretisation.bounded
    # the reference optimum: scipy least_squares over solve_ivp (rtol 1e-10) to tight tolerances, started at
    # the estimate to keep the test fast (it converges to its own optimum, not to the start)
    ref = least_squares(lambda p: ((z[0] - np.array([ivp_osc(p, f[0]) for f in F])) / sig).ravel(), est.p * 1.01,
                        x_scale=[400, 4, 4e6], xtol=1e-12, ftol=1e-12, gtol=1e-12).x
    assert np.all(np.abs(est.p - ref) / est.stderr < 0.05), (est.p - ref) / est.stderr


def pyomo_doe_reactor():
    """Pyomo.DoE's reactor example (pyomo/contrib/doe/examples/reactor_experiment.py): A -> B -> C,
    k_i = A_i exp(-1000 E_i / (R T)), T piecewise constant on 9 grid points, CA, CB, CC = CA0 - CA - CB
    measured at the grid points with sigma 0.01."""
    import casadi as ca
    from models import Model

    def rhs(x, p, u):
        k1, k2 = p[0] * ca.exp(-p[2] * 1000 / (8.314 * u[1])), p[1] * ca.exp(-p[3] * 1000 / (8.314 * u[1]))
        return ca.vertcat(-k1 * x[0], k1 * x[0] - k2 * x[1])
    grid = np.arange(9) * 0.125
    return Model.ode(["A1", "A2", "E1", "E2"], ["CA", "CB"], ["CA0"], ["CA", "CB", "CC"], rhs=rhs,
                     x0=lambda p, u: ca.vertcat(u[0], 0), h=lambda x, p, u: ca.vertcat(x[0], x[1], u[0] - x[0] - x[1]),
                     controls={"T": {"grid": grid, "kind": "constant"}}, horizon=1.0), grid


def test_pyomo_doe_reactor_information_equals_the_odes():
    # planned FIM at Pyomo.DoE's nominal design, scaled by the nominal parameters as Pyomo.DoE does;
    # the reference: forward sensitivities by solve_ivp (rtol 1e-11), interval by interval
    model, grid = pyomo_doe_reactor()
    p = np.array([84.79, 371.72, 7.78, 15.05])
    T = np.r_[500.0, [300.0] * 8]
    F, _ = information_contributions(model, None, p, inputs=[np.r_[5.0, T]], times=grid, sigma=0.01)
    D = np.diag(p)
    logdet = np.linalg.slogdet(D @ F.sum(axis=0) @ D)[1] / np.log(10)

    def sens_rhs(_, w, temp):
        x, s = w[:2], w[2:].reshape(2, 4)
        e1, e2 = np.exp(-p[2] * 1000 / (8.314 * temp)), np.exp(-p[3] * 1000 / (8.314 * temp))
        k1, k2 = p[0] * e1, p[1] * e2
        fx = np.array([[-k1, 0], [k1, -k2]])
        dk1 = np.array([e1, 0, -k1 * 1000 / (8.314 * temp), 0])
        dk2 = np.array([0, e2, 0, -k2 * 1000 / (8.314 * temp)])
        fp = np.array([-dk1 * x[0], dk1 * x[0] - dk2 * x[1]])
        return np.r_[fx @ x, (fx @ s + fp).ravel()]
    w, G = np.r_[5.0, 0.0, np.zeros(8)], [np.zeros((3, 4))]
    for i in range(8):
        w = solve_ivp(sens_rhs, (grid[i], grid[i + 1]), w, args=(T[i],), rtol=1e-11, atol=1e-14).y[:, -1]
        s = w[2:].reshape(2, 4)
        G.append(np.vstack([s, -s.sum(axis=0)]))
    G = np.concatenate(G) @ D / 0.01
    ref = np.linalg.slogdet(G.T @ G)[1] / np.log(10)
    assert abs(ref - 19.240939) < 1e-5          # the ODE's value quoted in issue 22
    assert abs(logdet - ref) < 1e-4, (logdet, ref)


def test_collocated_problem_with_a_mesh_controlled_at_p():
    data = DynamicMeasurements(Q, TIMES, campaign(seed=8), SIGMA, sensors=["cA", "cB"])
    cm, flat = collocated_problem(build(), data, p=P_TRUE)
    est = identify(build(), data, P0)
    h = np.array([ivp(P_TRUE, q, TIMES).ravel() for q in Q])
    assert np.max(np.abs(cm.simulate(P_TRUE, Q) - h) / np.tile(SIGMA, TIMES.size)) < 0.01
    assert cm.mesh.n_elements <= est.diagnostics.discretisation.n_elements * 2


def test_index1_dae_identify():
    # x' = -k w, 0 = w - x^2 (x = x0 / (1 + k x0 t)); sensors x and w
    import casadi as ca
    from models import Model
    m = Model.ode(["k"], ["x"], ["x0"], ["x", "w"], rhs=lambda x, z, p, u: -p[0] * z[0],
                  alg=lambda x, z, p, u: z[0] - x[0] ** 2, algebraic=["w"], x0=lambda p, u: u[0],
                  h=lambda x, z, p, u: ca.vertcat(x[0], z[0]))
    t, q = np.array([0.5, 1.0, 2.0, 3.0]), np.array([[1.0], [2.0]])
    x = q / (1 + 0.8 * q * t)
    z = np.stack([x, x ** 2], axis=-1)[None] + 0.01 * np.random.default_rng(9).standard_normal((1, 2, 4, 2))
    est = identify(m, DynamicMeasurements(q, t, z, [0.01, 0.01]), [0.5])
    ref = least_squares(lambda k: ((z[0] - np.stack([q / (1 + k * q * t), (q / (1 + k * q * t)) ** 2], -1)) / 0.01)
                        .ravel(), [0.5], xtol=1e-14, ftol=1e-14, gtol=1e-14).x
    assert abs(est.p[0] - ref[0]) / est.stderr[0] < 0.05 and est.diagnostics.discretisation.bounded


def test_blow_up_at_p0_names_the_experiment_and_time():
    import casadi as ca
    from identification import IdentificationError
    from identification.errors import BadStartError
    from models import Model
    m = Model.ode(["k"], ["x"], ["x0"], ["x"], rhs=lambda x, p, u: p[0] * x ** 2, x0=lambda p, u: u[0],
                  h=lambda x, p, u: x, horizon=2.0)
    t, q = np.array([0.5, 1.0, 2.0]), np.array([[0.1], [1.0]])
    z = (q / (1 - 0.1 * q * t))[None, :, :, None]
    with pytest.raises(IdentificationError, match=r"inputs \[1.0\]: no collocation solution on the element") as info:
        identify(m, DynamicMeasurements(q, t, z, [0.01]), [1.0])
    # issue 30: x = 1 / (1 - t) from x(0) = 1 at k = 1 blows up at t* = 1: bad input (not a failed fit) naming
    # the time, found by the message's diagnostic integration (models.blow_up)
    assert isinstance(info.value, BadStartError)
    assert "of experiment 2: the trajectory blows up (|x| -> inf near t = 1); check p" in str(info.value)


def test_detect_rejects_a_linear_spring_on_hardening_spring_data():
    # step responses of the cubic spring-damper; a linear spring cannot explain small and large steps at once
    from mudoe.example_oscillator import P_TRUE as P_OSC, TIMES as T_OSC, build as oscillator
    F, t = np.array([[1.0], [2.0], [6.0], [8.0]]), T_OSC[:15]
    Y = oscillator().collocate(t, max_step=0.005).simulate(P_OSC, F).reshape(len(F), t.size, 2)   # 1e-4 sigma
    z = Y[None] + 0.05 * np.random.default_rng(1).standard_normal((1,) + Y.shape)
    data = DynamicMeasurements(F, t, z, [0.05, 0.05], sensors=["x", "a"])
    split = [Split("small vs large steps", (0, 1), (2, 3))]
    wrong = identify(oscillator("linear"), data, [300.0, 3.0])
    right = identify(oscillator(), data, [300.0, 3.0, 2e6])
    assert wrong.diagnostics.discretisation.bounded and right.diagnostics.discretisation.bounded
    assert detect(wrong.model, wrong.data, split, wrong.p, normality="override").tests[0].alpha_lr < 1e-6
    assert detect(right.model, right.data, split, right.p, normality="override").tests[0].alpha_lr > 0.05


def test_instrument_weights_equal_dropping_the_instrument():
    z = campaign(seed=10)
    m = build()
    weighted = identify(m, DynamicMeasurements(Q, TIMES, z, SIGMA, sensors=["cA", "cB"]), P0, weights=[0.0, 1.0])
    z_a = z.copy()
    z_a[..., 0] = np.nan                         # cA never read (cB alone identifies all four)
    dropped = identify(m, DynamicMeasurements(Q, TIMES, z_a, SIGMA, sensors=["cA", "cB"]), P0)
    assert np.allclose(weighted.p, dropped.p, rtol=1e-7) and np.allclose(weighted.cov, dropped.cov, rtol=1e-6)
    with pytest.raises(DataError, match="weights: expected 2 instrument weights"):
        identify(m, DynamicMeasurements(Q, TIMES, z, SIGMA, sensors=["cA", "cB"]), P0, weights=[1.0] * 20)


def test_normality_gate_pooled_per_instrument():
    from identification import normality_check
    times = [TIMES, TIMES[::2], TIMES, TIMES, TIMES[:4], TIMES]
    data = DynamicMeasurements(Q, times, campaign(seed=11, times=times, n_M=2), SIGMA, sensors=["cA", "cB"])
    view = data.by_instrument()
    n_rows = sum(len(t) for t in times)
    assert view.z.shape == (2, n_rows, 2) and view.input_names == ("experiment", "time")
    check = normality_check(view)       # one Shapiro-Wilk test per instrument over all its times
    assert np.all(check.n_diff == n_rows) and np.all(np.isfinite(check.pvalue))
    # the repeatability estimate from 49 differences: within 30 % of sigma (its standard error is 10 %)
    assert np.allclose(check.sigma_rep, SIGMA, rtol=0.3)


def test_predict_and_simulate_campaign():
    from identification.fit.dynamic_fit import predict, simulate_campaign
    h = predict(build(), P_TRUE, Q, TIMES, SIGMA, DiscretisationSettings(tol_sigma=1e-3))
    ref = np.array([ivp(P_TRUE, q, TIMES) for q in Q])
    assert h.shape == (6, 10, 2) and np.max(np.abs(h - ref) / SIGMA) < 1e-3
    data = simulate_campaign(build(), P_TRUE, Q, TIMES, SIGMA, n_series=3, seed=4)
    assert data.z.shape == (3, 6, 10, 2) and data.sensors == ("cA", "cB") and np.allclose(data.sigma, SIGMA)
    resid = (data.z - ref[None]) / SIGMA
    assert abs(resid.mean()) < 4 / np.sqrt(resid.size) and abs(resid.std() - 1) < 4 / np.sqrt(2 * resid.size)


def test_round_off_times_across_experiments_are_one_instant():
    # issue 30: experiment 1 sampled at 0.3, experiment 2 at 0.1 * 3 = 0.30000000000000004: one time of
    # the campaign (one sensor@time column), the value that reads shortest; within one experiment an error
    z = np.zeros((1, 2, 2, 1))
    data = DynamicMeasurements([[1.0], [2.0]], [[0.1, 0.3], [0.1, 0.1 * 3]], z, sigma=[0.1])
    assert data.union_times.tolist() == [0.1, 0.3]
    assert data.times[1, 1] == 0.3 and len(data.flat().sensors) == 2
    with pytest.raises(DataError, match="experiment 1: the sampling times 0.3 and 0.30000000000000004 differ"):
        DynamicMeasurements([[1.0]], [0.1, 0.3, 0.30000000000000004], np.zeros((1, 1, 3, 1)), sigma=[0.1])


def _chain(lower):
    from models.contract import Parameter
    return Model.ode([Parameter("k1", lower, 10.0, scale=1.0), Parameter("k2", lower, 10.0, scale=1.0)],
                     ["cA", "cB"], [], ["cA", "cB"],
                     rhs=lambda x, p, u: ca.vertcat(-p[0] * x[0], p[0] * x[0] - p[1] * x[1]),
                     x0=lambda p, u: ca.vertcat(1.0, 0.0), h=lambda x, p, u: x)


def test_degenerate_start_is_named_before_solving():
    # issue 30: k1 = 0 (inside its bounds) makes cB = 0 at every time, so the outputs do not depend on k2
    # at the start (exact AD sensitivities): one warning naming the start and what to try, and a note
    t = np.linspace(0.2, 2.0, 8)
    data = simulate_campaign(_chain(-10.0), [2.0, 0.5], np.zeros((1, 0)), t, [0.01, 0.01], n_series=2, seed=2)
    with pytest.warns(DegenerateStartWarning, match=r"p0: at the start \(k1 = 0, k2 = 1\) the outputs do not "
                                                    r"depend on k2 \(their sensitivities are exactly zero"):
        est = identify(_chain(-10.0), data, p0=[0.0, 1.0])
    assert any("do not depend on k2" in n for n in est.notes)
    assert np.allclose(est.p, [2.0, 0.5], atol=0.05)


def test_start_on_a_bound_moves_into_the_interior_with_a_note():
    t = np.linspace(0.2, 2.0, 8)
    data = simulate_campaign(_chain(0.0), [2.0, 0.5], np.zeros((1, 0)), t, [0.01, 0.01], n_series=2, seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DegenerateStartWarning)     # moved off 0: no longer degenerate
        p0 = np.zeros(2)
        est = identify(_chain(0.0), data, p0=p0)
    assert p0.tolist() == [0.0, 0.0]                                # the caller's start is not changed
    assert est.notes[0].startswith("start values on a bound moved 0.001 of their scale into the interior: "
                                   "k1 = 0.001, k2 = 0.001")
    assert np.allclose(est.p, [2.0, 0.5], atol=0.05)
    interior = identify(_chain(0.0), data, p0=[1.0, 1.0])
    assert not any("on a bound" in n for n in interior.notes)
