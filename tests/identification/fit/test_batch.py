"""The batch engine (identification.fit.batch.fit_batch) against identify, member by member.

Agreement targets: estimates to 1e-8 relative, covariances to 1e-6 relative (identify itself
stops at a Newton decrement of 1e-18 chi^2 units, i.e. within 1e-9 standard errors of the
optimum, and so does the batch iteration; both are then a few 1e-11 apart on the press).
"""
import contextlib

import casadi as ca
import numpy as np
import pytest

from identification import DataError, IdentifySettings, Measurements, identify
from identification.fit.batch import BatchFit, BatchMember, fit_batch
from identification.studies.montecarlo import BATCHED, ONE_BY_ONE, ModelCampaign, MonteCarloSettings, size_study
from identification.studies.detect import DetectSettings
from identification.studies.splits import splits_from_scenarios
from models.contract import Model, Parameter
from models.press import PRESS_SCENARIOS, Q_PAPER, press_model
from models.state import simulate, solve_states

SIGMA_MM = np.array([1.518e-05, 4.895e-06, 3.904e-06]) * 1e3
W = np.array([1.0, 1.0, 0.0])
P0 = np.array([450.0, 550.0])
SPLITS = splits_from_scenarios(PRESS_SCENARIOS, len(Q_PAPER))


@pytest.fixture(scope="module")
def press():
    return press_model()


@pytest.fixture(scope="module")
def press_data(press):
    gen = ModelCampaign(press, press.p_nominal, np.array(Q_PAPER)[:, None], SIGMA_MM, 2)
    rng = np.random.default_rng(5)
    return [gen(rng) for _ in range(4)]


def _assert_same_as_identify(model, data, p0, weights, fit, rtol_p=1e-8, rtol_cov=1e-6):
    for r, d in enumerate(data):
        est = identify(model, d, p0, weights=weights)
        got = fit.result(r)
        np.testing.assert_allclose(got.p, est.p, rtol=rtol_p, atol=0)
        np.testing.assert_allclose(fit.p[r], est.p, rtol=rtol_p, atol=0)
        np.testing.assert_allclose(got.cov, est.cov, rtol=rtol_cov, atol=1e-14 * np.abs(est.cov).max())
        np.testing.assert_allclose(got.cov_gn, est.cov_gn, rtol=rtol_cov, atol=1e-14 * np.abs(est.cov_gn).max())
        np.testing.assert_allclose(got.information, est.information, rtol=rtol_cov)
        assert got.objective == pytest.approx(est.objective, rel=1e-9)
        assert got.rss == pytest.approx(est.rss, rel=1e-8)
        assert (got.n_data, got.dof, got.sigma_estimated) == (est.n_data, est.dof, est.sigma_estimated)
        np.testing.assert_allclose(got.states, est.states, rtol=1e-8, atol=1e-10)


def test_press_batch_equals_identify(press, press_data):
    # the interleaved scenario's calibration set repeats loads (q3 .. q27 visit each load twice):
    # identical input rows are evaluated once per member, which must not change the result
    for split in (SPLITS[0], SPLITS[3]):
        cal = [split.calibration(d) for d in press_data]
        fit = fit_batch(press, cal, P0, W)
        assert isinstance(fit, BatchFit) and fit.converged.all() and fit.ok.all() and not fit.fallbacks
        assert np.all(fit.decrement <= 1e-18)
        assert isinstance(fit.result(0), BatchMember)
        _assert_same_as_identify(press, cal, P0, W, fit)
    with pytest.raises(ValueError):
        fit.p[0, 0] = 1.0                        # read-only result


def test_explicit_model_known_and_unknown_sigma():
    model = Model.explicit(params=["b1", "b2"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])))
    x = np.linspace(50.0, 800.0, 14)
    rng = np.random.default_rng(2)
    truth = np.array(230.0, float), np.array(5e-4)
    y0 = truth[0] * (1 - np.exp(-truth[1] * x))
    for sigma in (np.array([0.5]), None):
        data = [Measurements(inputs=x, z=(y0 + 0.5 * rng.standard_normal((2, 14)))[:, :, None], sigma=sigma)
                for _ in range(3)]
        fit = fit_batch(model, data, [200.0, 4e-4])
        assert fit.converged.all() and not fit.fallbacks
        _assert_same_as_identify(model, data, [200.0, 4e-4], None, fit)


def test_failing_members_fall_back_to_identify_and_are_recorded():
    # bounded exponential model: member 1's data want b1 far beyond its upper bound (the batch
    # iteration leaves the bounds, identify solves the bounded problem); member 2 has too few
    # values (identify raises DataError, kept as the member's result, never dropped)
    model = Model.explicit(params=[Parameter("b1", 0.0, 300.0), Parameter("b2", 0.0, 1.0)], inputs=["x"],
                           sensors=["y"], h=lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])))
    x = np.linspace(50.0, 800.0, 10)
    rng = np.random.default_rng(4)

    def campaign(b1):
        return (b1 * (1 - np.exp(-5e-4 * x)) + 0.5 * rng.standard_normal((2, 10)))[:, :, None]

    z_sparse = campaign(230.0)
    z_sparse[:, 1:] = np.nan
    z_sparse[1, 0] = np.nan                              # one value for two parameters
    data = [Measurements(x, campaign(230.0), [0.5]), Measurements(x, campaign(900.0), [0.5]),
            Measurements(x, z_sparse, [0.5]), Measurements(x, campaign(240.0), [0.5])]
    fit = fit_batch(model, data, [200.0, 4e-4])
    assert fit.n_members == 4
    assert fit.converged.tolist() == [True, False, False, True]
    assert fit.ok.tolist() == [True, True, False, True]
    rec = {f.member: f for f in fit.fallbacks}
    assert set(rec) == {1, 2}
    assert "bound" in rec[1].reason and rec[1].error == ""
    assert "too few values" in rec[2].reason and rec[2].error.startswith("DataError")
    est = identify(model, data[1], [200.0, 4e-4])
    np.testing.assert_allclose(fit.p[1], est.p, rtol=1e-12)
    assert fit.p[1, 0] == pytest.approx(300.0)          # at the bound, identify's bounded solution
    assert np.all(np.isnan(fit.p[2]))
    with pytest.raises(DataError):
        fit.result(2)


def test_members_with_a_singular_information_fall_back_one_by_one(monkeypatch):
    """Every member's J^T W J singular (b2 has no effect): no LinAlgError for the batch, each member
    is handed to identify with its reason; a member that left the bounds is refitted by identify
    with the bounds from the start (lazy_bounds off: the unbounded pass may run to max_iter)."""
    import identification.fit.batch as batch
    model = Model.explicit(params=["b1", "b2"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] * q[0] + 0 * p[1])
    x = np.linspace(1.0, 5.0, 6)
    rng = np.random.default_rng(3)
    data = [Measurements(x, (2.0 * x + 0.1 * rng.standard_normal((2, 6)))[:, :, None], [0.1]) for _ in range(3)]
    fit = fit_batch(model, data, [1.0, 1.0])
    assert fit.n_members == 3 and not fit.ok.any()
    assert {f.member for f in fit.fallbacks} == {0, 1, 2}
    assert all(f.error for f in fit.fallbacks)          # identify's own failure, named
    seen = []

    def spy(model, data, p0, weights=None, settings=None, Y0=None):
        seen.append(settings.lazy_bounds)
        return identify(model, data, p0, weights=weights, settings=settings, Y0=Y0)

    monkeypatch.setattr(batch, "fit_static", spy)
    bounded = Model.explicit(params=[Parameter("b1", 0.0, 300.0), Parameter("b2", 0.0, 1.0)], inputs=["x"],
                             sensors=["y"], h=lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])))
    xs = np.linspace(50.0, 800.0, 10)
    far = Measurements(xs, (900.0 * (1 - np.exp(-5e-4 * xs)) + 0.5 * rng.standard_normal((2, 10)))[:, :, None],
                       [0.5])
    fit = fit_batch(bounded, [far], [200.0, 4e-4])
    assert [f.reason for f in fit.fallbacks] == [batch.LEFT_BOUNDS] and seen == [False]
    assert fit.p[0, 0] == pytest.approx(300.0)


def test_bad_batches_are_refused(press, press_data):
    other = Measurements(np.array(Q_PAPER)[:10, None], press_data[0].z[:, :10], SIGMA_MM)
    with pytest.raises(DataError, match=r"data\[1\].*inputs"):
        fit_batch(press, [press_data[0], other], P0, W)
    with pytest.raises(DataError, match="empty"):
        fit_batch(press, [], P0, W)
    with pytest.raises(DataError, match="p0"):
        fit_batch(press, press_data[:1], [1.0], W)


def test_monte_carlo_decisions_batch_equal_per_fit(press):
    # scenarios 3 and 4 pool the same points: one pooled batch serves both
    res = {}
    for batch in (True, False):
        s = MonteCarloSettings(n_rep=2, seed=9, workers=1, progress=False, jit=False,
                               fits=BATCHED if batch else ONE_BY_ONE,
                               detect=DetectSettings(tol=0.05, normality="override"))
        res[batch] = size_study(press, press.p_nominal, np.array(Q_PAPER)[:, None], SIGMA_MM, SPLITS[2:],
                                p0=P0, weights=W, settings=s, name="M1")
    b, f = res[True], res[False]
    assert not b.errors and not f.errors
    for name in ("alpha_paper", "alpha_two_sample", "alpha_lr"):
        np.testing.assert_allclose(getattr(b, name), getattr(f, name), rtol=0, atol=1e-6)
    np.testing.assert_array_equal(b.covered, f.covered)
    for st in ("paper", "two_sample", "likelihood_ratio"):
        np.testing.assert_array_equal(b.decisions(statistic=st), f.decisions(statistic=st))


def _two_state(E, name, h=lambda y, p, q: y):
    return Model(params=[Parameter("a", 0.1, 10.0), Parameter("b", 0.1, 10.0)], inputs=["q"], sensors=["u", "v"],
                 n_y=2, E=E, h=h, name=name)


@contextlib.contextmanager
def jit_on():
    """JIT compilation switched on (only around the batch fits: identify's own functions are not
    compiled, which keeps the test fast; identify's numbers do not depend on it)."""
    from models.state import JIT, set_jit
    prev = set_jit(True)
    try:
        if not JIT.active():
            pytest.skip("no C compiler: the fused sweep function needs JIT compilation")
        yield
    finally:
        set_jit(prev)


def test_fused_sweeps_equal_identify_and_dense_path_where_E_y_is_not_spd():
    # E_y SPD: every sweep by the fused compiled function (sparse LDL^T); symmetric indefinite
    # E_y (negative pivot), a zero pivot (no pivoting in LDL^T) and a non-symmetric E_y with a
    # symmetric pattern: the dense path
    spd = _two_state(lambda y, p, q: ca.vertcat(3 * y[0] + y[1] + 0.1 * y[0] ** 3 - p[0] * q[0],
                                                y[0] + 2 * y[1] - p[0] * p[1] * q[0] ** 2), "spd",
                     h=lambda y, p, q: ca.vertcat(y[0] + 0.1 * y[1] ** 2, p[1] * y[1]))   # h nonlinear in (y, p)
    indefinite = _two_state(lambda y, p, q: ca.vertcat(y[0] + 2 * y[1] - p[0] * q[0],
                                                       2 * y[0] + y[1] - p[0] * p[1] * q[0] ** 2), "indefinite")
    asymmetric = _two_state(lambda y, p, q: ca.vertcat(3 * y[0] + y[1] - p[0] * q[0],
                                                       2 * y[0] + 2 * y[1] - p[0] * p[1] * q[0] ** 2), "asymmetric")
    zero_pivot = _two_state(lambda y, p, q: ca.vertcat(y[1] - p[0] * q[0], y[0] - p[0] * p[1] * q[0] ** 2),
                            "zero_pivot")
    q = np.linspace(0.5, 3.0, 8)
    rng = np.random.default_rng(11)
    for model, fused in ((spd, True), (indefinite, False), (asymmetric, False), (zero_pivot, False)):
        H = simulate(model, np.array([2.0, 1.5]), q[:, None])
        data = [Measurements(q, H[None] + 0.01 * rng.standard_normal((2, 8, 2)), [0.01, 0.01]) for _ in range(3)]
        Y0 = solve_states(model, np.array([1.5, 1.0]), q[:, None])
        with jit_on():
            fit = fit_batch(model, data, [1.5, 1.0], Y0=Y0)
        assert fit.converged.all() and not fit.fallbacks, model.name
        assert (fit.dense_sweeps == 0) if fused else (fit.dense_sweeps > 0), (model.name, fit.dense_sweeps)
        _assert_same_as_identify(model, data, [1.5, 1.0], None, fit)


def test_press_fused_sweeps_equal_identify(press, press_data):
    cal = [SPLITS[3].calibration(d) for d in press_data[:2]]
    Y0 = solve_states(press, P0, cal[0].inputs)
    with jit_on():
        fit = fit_batch(press, cal, P0, W, Y0=Y0)
    assert fit.converged.all() and not fit.fallbacks and fit.dense_sweeps == 0
    _assert_same_as_identify(press, cal, P0, W, fit)


class _ExpCampaign:
    """Campaigns of y = b1 (1 - exp(-b2 x)) with unknown sigma; every third replication has its
    validation inputs of the first split (x_4 .. x_7) missing, so that split's validation fit fails."""

    def __init__(self):
        self.x = np.linspace(50.0, 800.0, 8)
        self.calls = 0

    def __call__(self, rng):
        z = (230.0 * (1 - np.exp(-5e-4 * self.x)) + 0.5 * rng.standard_normal((2, 8)))[:, :, None]
        if rng.uniform() < 0.3:
            z[:, 4:] = np.nan
        return Measurements(self.x, z, None)


def test_monte_carlo_batched_statistics_equal_per_fit_with_failures_and_unknown_sigma():
    # the batched statistics (F test of the pooled fit, Wald distances, coverage, Shapiro-Wilk) and
    # the replications they leave to run_split_tests (a failed fit: same error records)
    from identification.studies.montecarlo import run_monte_carlo
    from identification.studies.splits import Split
    model = Model.explicit(params=["b1", "b2"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])))
    splits = (Split("halves", [0, 1, 2, 3], [4, 5, 6, 7]), Split("odd/even", [0, 2, 4, 6], [1, 3, 5, 7]),
              Split("series", list(range(8)), list(range(8)), [0], [1]))
    res = {}
    for batch in (True, False):
        s = MonteCarloSettings(n_rep=12, seed=3, workers=1, progress=False, jit=False,
                               fits=BATCHED if batch else ONE_BY_ONE,
                               detect=DetectSettings(tol=0.05, normality="override"))
        res[batch] = run_monte_carlo(model, _ExpCampaign(), splits, [200.0, 4e-4], truth=[230.0, 5e-4],
                                     kind="size", settings=s)
    b, f = res[True], res[False]
    assert f.errors and b.errors == f.errors                      # some replications fail, recorded alike
    for name in ("alpha_paper", "alpha_two_sample", "alpha_lr"):
        np.testing.assert_allclose(getattr(b, name), getattr(f, name), rtol=0, atol=1e-6)
    assert np.isfinite(b.alpha_lr).sum() > 20
    np.testing.assert_array_equal(b.covered, f.covered)
    np.testing.assert_array_equal(b.shapiro, f.shapiro)
