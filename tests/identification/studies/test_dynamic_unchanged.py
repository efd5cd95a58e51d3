"""Everything works on a dynamic model unchanged (issue 22, item 4): identify, Bard covariance, curvature,
profile / bootstrap intervals, LR regions, Algorithm 1 with splits by experiment, time window and early vs
late, Monte Carlo on local processes and Dask, sequential design -- on a small batch reactor."""
import numpy as np
import pytest
from scipy import stats

from identification import DynamicMeasurements, MonteCarloSettings, Split, detect, identify, validate
from identification.studies.split_fits import BATCHED, ONE_BY_ONE
from identification.studies.detect import run_split_tests
from identification.fit.dynamic_fit import DiscretisationSettings, simulate_campaign
from identification.inference.profile import lr_region
from identification.studies.splits import early_late_split, time_window_split
from mudoe.example_reactor import P_TRUE, build

Q = np.array([[1.0, 330.0], [2.0, 330.0], [1.0, 370.0], [2.0, 370.0]])     # mol/L, K
TIMES = np.linspace(0.4, 2.0, 5)                                            # h
SIGMA = np.array([0.01, 0.01])                                              # mol/L
BY_EXPERIMENT = Split("cA0 = 1 vs 2", [0, 2], [1, 3])


@pytest.fixture(scope="module")
def fitted():
    model = build()
    data = simulate_campaign(model, P_TRUE, Q, TIMES, SIGMA, n_series=2, seed=3)
    return model, data, identify(model, data, P_TRUE * 1.1)


def test_identify_gives_bard_and_gauss_newton_covariances_and_a_bounded_discretisation(fitted):
    model, data, est = fitted
    assert est.diagnostics.discretisation.bounded
    assert np.all(np.abs(est.p - P_TRUE) / est.stderr < 4.0)
    # Bard (second-order) and Gauss-Newton covariances: symmetric positive definite, close for this
    # nearly linear, well-fitting problem (residual terms are O(sigma))
    for C in (est.cov, est.cov_gn):
        np.testing.assert_allclose(C, C.T, rtol=1e-10, atol=1e-14 * np.abs(C).max())
        assert np.all(np.linalg.eigvalsh(C) > 0)
    np.testing.assert_allclose(np.sqrt(np.diag(est.cov)), np.sqrt(np.diag(est.cov_gn)), rtol=0.1)
    assert est.model.n_S == len(TIMES) * model.n_S and est.data.sensors[:2] == ("cA@0.4", "cB@0.4")


def test_curvature_profile_and_bootstrap_intervals_on_the_collocated_model(fitted):
    _, _, est = fitted
    curv = est.curvature
    assert curv.trustworthy, curv
    wald = est.conf_int(0.05, method="wald")              # (n_p, 2): lower, upper
    prof = est.conf_int(0.05, method="profile")
    width = wald[:, 1] - wald[:, 0]
    # small curvature: profile intervals within 5 % of the Wald width of the Wald ones
    assert np.all(np.abs(np.asarray(prof.lower) - wald[:, 0]) < 0.05 * width)
    assert np.all(np.abs(np.asarray(prof.upper) - wald[:, 1]) < 0.05 * width)
    boot = est.conf_int(0.05, method="bootstrap", n=20, seed=1)
    # 20 refits: the percentile interval's ends are within about half a Wald width of the Wald ones
    assert np.all(np.abs(np.asarray(boot.lower) - wald[:, 0]) < 0.5 * width)
    assert np.all(np.abs(np.asarray(boot.upper) - wald[:, 1]) < 0.5 * width)


def test_lr_region_on_the_collocated_model(fitted):
    _, _, est = fitted
    reg = lr_region(est.model, est.data, est, (0, 1), n_grid=5)
    c = stats.chi2.ppf(0.95, 2)
    assert np.nanmin(reg.statistic) < 1e-6 and np.nanmax(reg.statistic) > c   # the grid straddles the region
    # the statistic is 0 at the estimate (grid centre) and grows along every grid row away from it;
    # inside half the linearised ellipse (quadratic form <= c / 4) the point lies in the LR region
    assert np.all(np.isfinite(reg.statistic)) and np.all(reg.statistic > -1e-6)
    k = reg.statistic.shape[1] // 2
    assert np.all(np.diff(reg.statistic[:, k:], axis=1) > 0) and np.all(np.diff(reg.statistic[:, :k + 1], axis=1) < 0)
    d = np.stack([reg.X - reg.estimate[0], reg.Y - reg.estimate[1]], axis=-1)
    quad = np.einsum("...i,ij,...j->...", d, np.linalg.inv(reg.cov), d)
    assert np.any(quad <= c / 4) and np.all(reg.statistic[quad <= c / 4] <= c)


def test_algorithm_1_splits_by_experiment_time_window_and_early_late(fitted):
    _, _, est = fitted
    pairs = [(s.split("@")[0], float(s.split("@")[1])) for s in est.data.sensors]
    splits = [BY_EXPERIMENT, time_window_split(pairs, len(Q), (0.4, 0.8), (1.6, 2.0)),
              early_late_split(pairs, len(Q))]
    assert splits[2].name == "early t < 1.2 vs late t >= 1.2"         # 5 times: the middle one (1.2) is late
    res = detect(est.model, est.data, splits, est.p)            # the Holm-corrected normality gate applies
    assert [t.ok for t in res.tests] == [True] * 3 and all(t.alpha_lr > 0.05 / 3 for t in res.tests)
    # each time split fits the early / late columns only: values per fit = experiments x series x columns
    early = splits[2]
    assert (res.tests[2].n_cal, res.tests[2].n_val) == (4 * 2 * len(early.cal_sensors), 4 * 2 * len(early.val_sensors))
    assert res.tests[1].n_cal == res.tests[1].n_val == 4 * 2 * 2 * 2      # two times x two sensors each
    # the early/late likelihood ratio equals the hand computation from three fits
    cal, val = identify(est.model, early.calibration(est.data), est.p), identify(est.model, early.validation(est.data), est.p)
    pooled = identify(est.model, early.pooled(est.data), est.p)
    assert res.tests[2].lr == pytest.approx(2 * (pooled.objective - cal.objective - val.objective), abs=1e-5)


def test_algorithm_1_rejects_a_wrong_rate_law_on_the_early_late_split():
    # data with second-order A consumption (dc_A/dt = -k1 c_A^2), tested with the first-order model
    import casadi as ca
    from models import Model
    from models.contract import Parameter
    from mudoe.example_reactor import R_KJ, T_REF

    def rhs(x, p, u):
        k1, k2 = (p[2 * i] * ca.exp(-p[2 * i + 1] / R_KJ * (1 / u[1] - 1 / T_REF)) for i in (0, 1))
        return ca.vertcat(-k1 * x[0] ** 2, k1 * x[0] ** 2 - k2 * x[1], k2 * x[1])
    second = Model.ode([Parameter(n, 0.0, 300.0) for n in ("k1", "E1", "k2", "E2")], ["cA", "cB", "cC"],
                       ["cA0", "T"], ["cA", "cB"], rhs=rhs, x0=lambda p, u: ca.vertcat(u[0], 0, 0),
                       h=lambda x, p, u: x[:2], horizon=2.0)
    data = simulate_campaign(second, [1.5, 60.0, 0.8, 80.0], Q, TIMES, SIGMA, n_series=2, seed=4)
    est = identify(build(), data, P_TRUE)
    pairs = [(s.split("@")[0], float(s.split("@")[1])) for s in est.data.sensors]
    tests = run_split_tests(est.model, est.data, [early_late_split(pairs, len(Q))], est.p)
    assert tests[0].ok and tests[0].alpha_lr < 1e-6


@pytest.fixture(scope="module")
def mc_problem(fitted):
    _, _, est = fitted
    pairs = [(s.split("@")[0], float(s.split("@")[1])) for s in est.data.sensors]
    return est, [BY_EXPERIMENT, early_late_split(pairs, len(Q))]


@pytest.mark.slow       # process and Dask start-up: as the static model's test in test_montecarlo.py
def test_monte_carlo_validate_same_numbers_serial_local_processes_and_dask(mc_problem):
    est, splits = mc_problem
    common = dict(p=P_TRUE, inputs=est.data.inputs, sigma=est.data.sigma, n_series=2)
    mc = dict(n_rep=4, seed=5, progress=False, jit=False, chunk_size=2)
    serial = validate(est.model, splits, **common, settings=MonteCarloSettings(workers=1, **mc))
    local = validate(est.model, splits, **common, settings=MonteCarloSettings(workers=2, **mc))
    assert "2 workers" in local.backend and not serial.errors
    np.testing.assert_array_equal(serial.alpha_lr, local.alpha_lr)
    assert np.all(np.isfinite(serial.alpha_lr)) and np.all(np.isfinite(serial.covered))
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cl, \
            distributed.Client(cl) as client:
        dk = validate(est.model, splits, **common, settings=MonteCarloSettings(scheduler=client, **mc))
    assert "dask" in dk.backend
    np.testing.assert_array_equal(serial.alpha_lr, dk.alpha_lr)
    np.testing.assert_array_equal(serial.covered, dk.covered)


def test_monte_carlo_batched_fits_equal_identify_per_fit_on_the_time_split(mc_problem):
    est, splits = mc_problem
    common = dict(n_rep=2, seed=7, workers=1, progress=False, jit=False, chunk_size=2)
    args = (est.model, P_TRUE, est.data.inputs, est.data.sigma)
    from identification import size_study
    batched = size_study(*args, splits[1:], settings=MonteCarloSettings(fits=BATCHED, **common))
    single = size_study(*args, splits[1:], settings=MonteCarloSettings(fits=ONE_BY_ONE, **common))
    np.testing.assert_allclose(batched.alpha_lr, single.alpha_lr, rtol=1e-5, atol=1e-8)
    np.testing.assert_allclose(batched.alpha_two_sample, single.alpha_two_sample, rtol=1e-5, atol=1e-8)


def test_sequential_design_on_the_collocated_model(fitted):
    from oed.sequential import sequential_design
    model, _, est = fitted
    experiments = [simulate_campaign(model, P_TRUE, Q, TIMES, SIGMA, n_series=2, seed=s) for s in (10, 11)]
    flat = [e.flat() for e in experiments]
    res = sequential_design(est.model, flat, P_TRUE * 1.1, criterion="D", n_sensors=6)
    assert len(res.steps) == 2
    for step in res.steps:
        assert int(np.count_nonzero(step.design.weights)) == 6
        assert np.all(np.abs(step.p - P_TRUE) / step.stderr < 5.0)


def test_dynamic_measurements_flat_is_what_detect_sees(fitted):
    _, data, est = fitted
    assert isinstance(data, DynamicMeasurements)
    np.testing.assert_array_equal(est.data.z, data.flat().z)


def test_linearized_size_of_a_time_split_is_the_nominal_level(mc_problem):
    # under the linearised model the two-sample Wald statistic of the early / late split is exactly
    # chi2_{n_p}: its rejection rate at TOL / n_tests = 5 % is 5 % (a map ignoring the sensors would give
    # identical calibration and validation estimates, p_val - p_cal = 0, and a rate of 0)
    from identification import linearized_size
    est, splits = mc_problem
    lin = linearized_size(est.model, P_TRUE, est.data.inputs, est.data.sigma, splits[1:], n_draws=20000, seed=2)
    assert abs(lin.split_two_sample[0] - 0.05) < 4 * lin.mc_se, lin


def test_discretisation_error_is_not_reported_as_model_inadequacy_with_control_but_is_without():
    # noise-free data of the correct model: the likelihood ratio of the early / late split is then its
    # noncentrality (the mean of the statistic is n_p + that).  On the controlled mesh of identify it is
    # negligible; with implicit Euler and one step between sampling times (a fixed coarse mesh, no
    # control) the discretisation error alone makes it large: the correct model would be rejected
    from identification.fit.dynamic_fit import collocated_problem, predict
    model = build()
    h = predict(model, P_TRUE, Q, TIMES, SIGMA, DiscretisationSettings(tol_sigma=1e-4))
    data = DynamicMeasurements(Q, TIMES, np.stack([h, h]), SIGMA, sensors=["cA", "cB"])
    est = identify(model, data, P_TRUE)
    pairs = [(s.split("@")[0], float(s.split("@")[1])) for s in est.data.sensors]
    split = [early_late_split(pairs, len(Q))]
    ok = run_split_tests(est.model, est.data, split, est.p)[0]
    coarse, flat = collocated_problem(model, data, degree=1, elements=1)
    bad = run_split_tests(coarse, flat, split, est.p)[0]
    assert ok.ok and ok.lr < 0.01
    assert bad.ok and bad.lr > 10.0 and bad.alpha_lr < 0.05


def test_validate_on_a_dynamic_model_says_what_to_do(fitted):
    from identification import DataError
    model, _, _ = fitted
    with pytest.raises(DataError, match="a dynamic model is validated by a size study on its campaign: give data="):
        validate(model, [BY_EXPERIMENT], p=P_TRUE, inputs=Q, sigma=SIGMA, n_rep=2)
    with pytest.raises(DataError, match="data: validate on a dynamic model needs the campaign"):
        validate(model, [BY_EXPERIMENT], p=P_TRUE, n_rep=2)
