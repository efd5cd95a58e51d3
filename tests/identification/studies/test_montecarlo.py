"""Monte Carlo validation of Algorithm 1: size of both statistics, coverage, determinism across backends.

Model: the linear two-sensor model h = q X p (exact Wald statistics, so the linearised
prediction of :func:`linearized_size` is exact up to its own 200 000-draw Monte Carlo error,
< 0.1 %).  The full Monte Carlo (fits by :func:`identify`) uses N = 200 replications of the
interleaved loading+unloading split of a 29-load campaign (13 vs 14 loads, so C_cal != C_val); a rejection rate r then has binomial standard error
sqrt(r (1 - r) / N) (1.5 % at r = 5 %, 2.9 % at r = 22 %).  The bands below are 3.5 such
standard errors (a fixed seed keeps the test deterministic).
"""
import math

import numpy as np
import pytest
from scipy import stats

from identification.studies.detect import DetectSettings
from identification.studies.montecarlo import (MonteCarloSettings, ModelCampaign, clopper_pearson, linearized_size,
                                       run_monte_carlo, size_study, validate)
from identification.studies.normality import gate_fails
from identification.studies.splits import splits_from_scenarios
from models.library import linear_model
from models.press import PRESS_SCENARIOS

Q = np.r_[np.linspace(0.0, 1.6, 15), np.linspace(1.6, 0.0, 15)[1:]][:, None]
X = np.array([[1.0, 0.3], [0.2, 1.0]])
P_TRUE = np.array([1.0, 2.0])
SIGMA = np.array([0.01, 0.02])
N_REP = 200
PAPER_SPLITS = splits_from_scenarios(PRESS_SCENARIOS, len(Q))   # the paper's four scenarios


@pytest.fixture(scope="module")
def model():
    return linear_model(X)


def test_clopper_pearson_matches_scipy():
    for k, n in ((0, 10), (3, 10), (10, 10), (47, 2000)):
        r = clopper_pearson(k, n)
        ci = stats.binomtest(k, n).proportion_ci(0.95, method="exact")
        assert r.lo == pytest.approx(ci.low, abs=1e-12) and r.hi == pytest.approx(ci.high, abs=1e-12)
    assert clopper_pearson(0, 10).hi == pytest.approx(1 - 0.025 ** 0.1)
    with pytest.raises(ValueError, match="k, n"):
        clopper_pearson(5, 3)
    with pytest.warns(DeprecationWarning, match="level= is deprecated, use alpha="):
        old = clopper_pearson(3, 10, level=0.9)           # the old keyword: a confidence level
    assert (old.lo, old.hi, old.level) == (clopper_pearson(3, 10, alpha=0.1).lo, clopper_pearson(3, 10, alpha=0.1).hi, 0.9)


def test_linearized_size_is_exact_for_equal_information(model):
    # calibration and validation at the same loads (loading vs unloading without the peak is
    # the same set of loads mirrored): C_cal = C_val, so d2_paper = 2 chi2_2 and
    # P(2 chi2_2 > chi2_2(1 - a)) = exp(-chi2_2(1 - a) / 4)
    from identification.studies.splits import Split
    sp = Split("mirror", range(1, 14), range(15, 28))
    r = linearized_size(model, P_TRUE, Q, SIGMA, [sp], alpha=0.05, n_draws=200_000)
    thr = stats.chi2.ppf(0.95, 2)
    assert np.allclose(r.eig_ratio[0], 2.0)
    assert r.split_paper[0] == pytest.approx(math.exp(-thr / 4), abs=4 * r.mc_se)   # 22.4 %
    assert r.split_two_sample[0] == pytest.approx(0.05, abs=4 * r.mc_se)


def test_size_of_both_statistics_and_coverage(model):
    splits = PAPER_SPLITS[3:]            # loading+unloading interleaved
    settings = MonteCarloSettings(n_rep=N_REP, seed=7, workers=1, progress=False)
    res = size_study(model, P_TRUE, Q, SIGMA, splits, p0=[0.5, 1.5], settings=settings)
    pred = linearized_size(model, P_TRUE, Q, SIGMA, splits, alpha=0.05, n_draws=200_000)
    assert res.n_rep == N_REP and not res.errors
    for st, p in (("paper", pred.family_paper), ("two_sample", pred.family_two_sample)):
        r = res.rejection_rate(statistic=st)
        se = math.sqrt(p * (1 - p) / N_REP)
        assert abs(r.rate - p) <= 3.5 * se + 4 * pred.mc_se, (st, r, p)
    # the key finding: the paper's statistic is inflated far above TOL, the two-sample one is not
    assert pred.family_paper > 0.2 and abs(pred.family_two_sample - 0.05) < 0.01
    assert res.rejection_rate(statistic="paper").lo > 0.05
    # every alpha_min of the two-sample statistic is Uniform(0, 1) for a linear model
    a = res.alpha_two_sample[:, 0, 0]
    assert stats.kstest(a, "uniform").pvalue > 1e-3
    # 95 % ellipsoids: coverage of the calibration fits of one split (binomial, N = 200)
    cov = res.coverage(split=0, which="cal")
    assert abs(cov.rate - 0.95) <= 3.5 * math.sqrt(0.95 * 0.05 / N_REP), cov
    text = res.summary()
    assert "family-wise rejection rate" in text and "Coverage" in text
    # the normality gate (Holm over both sensors, as detect's): its failure rate from the stored p-values
    gate = res.gate_failure_rate()
    assert res.normality_correction == "holm" and res.gated == (True, True)
    assert gate.k == int(np.sum(gate_fails(res.shapiro, 0.05, "holm")))
    assert abs(gate.rate - 0.05) <= 3.5 * math.sqrt(0.05 * 0.95 / N_REP), gate
    assert "family-wise 5 % over 2 sensors (Holm)) failure rate" in text


def test_same_seeds_same_numbers_serial_processes_and_dask(model):
    splits = PAPER_SPLITS[2:3]
    common = dict(n_rep=6, seed=11, progress=False, chunk_size=2)
    serial = size_study(model, P_TRUE, Q, SIGMA, splits, settings=MonteCarloSettings(workers=1, **common))
    local = size_study(model, P_TRUE, Q, SIGMA, splits, settings=MonteCarloSettings(workers=2, **common))
    assert "2 workers" in local.backend
    np.testing.assert_array_equal(serial.alpha_two_sample, local.alpha_two_sample)
    np.testing.assert_array_equal(serial.alpha_paper, local.alpha_paper)
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cl, \
            distributed.Client(cl) as client:
        dk = size_study(model, P_TRUE, Q, SIGMA, splits, settings=MonteCarloSettings(scheduler=client, **common))
    assert "dask" in dk.backend
    np.testing.assert_array_equal(serial.alpha_two_sample, dk.alpha_two_sample)
    np.testing.assert_array_equal(serial.covered, dk.covered)


def test_power_against_a_wrong_model_and_errors(model):
    # data with a hysteresis offset on the unloading branch (2 sigma on sensor 1)
    class Hysteresis(ModelCampaign):
        pass

    gen = ModelCampaign(model, P_TRUE, Q, SIGMA, n_M=2)
    gen.H = gen.H.copy()
    gen.H[15:, 0] += 0.02
    res = run_monte_carlo(model, gen, PAPER_SPLITS[2:3], [0.5, 1.5], kind="power",
                          settings=MonteCarloSettings(n_rep=20, seed=3, workers=1, progress=False))
    assert res.rejection_rate().rate >= 0.9
    r = res.rejection_rate()                      # the intervals of a study are 95 % ones (ci_level)
    ci = stats.binomtest(r.k, r.n).proportion_ci(0.95, method="exact")
    assert r.level == 0.95 and r.lo == pytest.approx(ci.low, abs=1e-12) and r.hi == pytest.approx(ci.high, abs=1e-12)
    with pytest.raises(ValueError, match="n_rep"):
        MonteCarloSettings(n_rep=0)
    with pytest.raises(TypeError, match="generator"):
        run_monte_carlo(model, 3, PAPER_SPLITS, [1, 2])
    with pytest.raises(Exception, match="p, inputs, sigma: a size study needs the truth"):
        validate(model, PAPER_SPLITS, inputs=Q, sigma=SIGMA)
    with pytest.raises(Exception, match="p_true"):
        ModelCampaign(model, [1.0], Q, SIGMA)
    with pytest.raises(ValueError, match="tol"):
        DetectSettings(tol=0.0)


def test_validate_keywords_and_settings_together_are_an_error(model):
    s = MonteCarloSettings(n_rep=2, workers=1, progress=False)
    common = dict(p=P_TRUE, inputs=Q, sigma=SIGMA)
    with pytest.raises(TypeError, match="settings and n_rep, seed"):
        validate(model, PAPER_SPLITS[2:3], n_rep=5, seed=3, settings=s, **common)
    with pytest.raises(TypeError, match="settings and tol"):
        validate(model, PAPER_SPLITS[2:3], alpha=0.1, settings=s, **common)
    res = validate(model, PAPER_SPLITS[2:3], n_rep=2, workers=1, progress=False, alpha=0.1, **common)
    assert res.n_rep == 2 and res.tol == 0.1
    assert validate(model, PAPER_SPLITS[2:3], settings=s, **common).tol == 0.05


def test_progress_bar_and_timed_steps():
    import io
    from identification.progress import Progress
    out = io.StringIO()
    p = Progress(True, stream=out, prefix="run: ")
    with p.step("fit"):
        pass
    bar = p.bar(3, "size study")
    bar.update(3)
    bar.close()
    text = out.getvalue()
    assert "run: fit ...\n" in text and "run: fit done in" in text and "3/3" in text
    assert set(p.timing) == {"fit"}
    quiet = io.StringIO()
    q = Progress(False, stream=quiet)
    with q.step("fit"):
        pass
    b = q.bar(2, "x")
    b.update(2)
    b.close()
    assert quiet.getvalue() == "" and "fit" in q.timing


def _mm_campaigns(n, known=True, seed=11):
    """``n`` Michaelis-Menten campaigns y = Vm x / (K + x) at 8 inputs, 2 series, one missing value."""
    from identification import Measurements
    from models import Model
    mm = Model.explicit(params=["Vm", "K"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] * q[0] / (p[1] + q[0]),
                        name="MM")
    x = np.linspace(0.5, 8.0, 8)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        z = (x / (5.0 + x))[None, :, None] + 0.01 * rng.standard_normal((2, 8, 1))
        z[1, 3, 0] = np.nan
        out.append(Measurements(x, z, [0.01] if known else None))
    return mm, out


@pytest.mark.parametrize("known", [True, False])
def test_batched_split_tests_are_run_split_tests_of_each_data_set(known):
    """Every field of every SplitTest as run_split_tests gives it (estimates 1e-7, statistics 1e-8 relative),
    and a rank-deficient split fails in both with the same stage and message."""
    from identification.studies.detect import run_split_tests
    from identification.studies.montecarlo import batched_split_tests
    from identification.studies.splits import Split
    mm, ds = _mm_campaigns(6, known)
    splits = (Split("low/high", range(0, 4), range(4, 8)), Split("odd/even", range(0, 8, 2), range(1, 8, 2)))
    one = Split("one input", range(0, 7), [7])          # Vm, K not identifiable from one input
    for sp, regular in ((splits, True), (splits + (one,), False)):
        got = batched_split_tests(mm, "mm", ds, sp, [1.0, 5.0])
        assert len(got) == len(ds)
        for d, tests in zip(ds, got):
            ref = run_split_tests(mm, d, sp, [1.0, 5.0], model_name="mm")
            assert [t.split for t in tests] == [s.name for s in sp]
            for t, r in zip(tests, ref):
                assert (t.ok, t.stage, t.error, t.lr_error, t.n_cal, t.n_val) == (r.ok, r.stage, r.error, r.lr_error,
                                                                                 r.n_cal, r.n_val)
                for f in ("p_cal", "p_val", "C_cal", "C_val"):
                    np.testing.assert_allclose(getattr(t, f), getattr(r, f), rtol=1e-7, atol=1e-14)
                for f in ("d2_paper", "d2_two_sample", "lr", "alpha_paper", "alpha_two_sample", "alpha_lr"):
                    np.testing.assert_allclose(getattr(t, f), getattr(r, f), rtol=1e-8)
            assert all(t.ok for t in tests) == regular
        if not regular:
            assert got[0][2].stage == "validation fit"
            assert ("not identifiable" if known else "no degree of freedom") in got[0][2].error


def test_batched_split_tests_bad_input_names_the_argument():
    from identification import Measurements
    from identification.studies.montecarlo import batched_split_tests
    from identification.studies.splits import Split
    mm, ds = _mm_campaigns(2)
    sp = [Split("low/high", range(0, 4), range(4, 8))]
    other = Measurements(ds[0].inputs + 1.0, ds[0].z, [0.01])
    unknown = Measurements(ds[0].inputs, ds[0].z, None)
    for args, exc, match in (((mm, None, [], sp, [1, 5]), Exception, "datasets"),
                             ((mm, None, ds[0], sp, [1, 5]), TypeError, "datasets"),
                             ((mm, None, [ds[0], other], sp, [1, 5]), Exception, "datasets: data set 1 has other inputs"),
                             ((mm, None, [ds[0], unknown], sp, [1, 5]), Exception, "sigma"),
                             ((mm, None, ds, [], [1, 5]), Exception, "splits"),
                             ((mm, None, ds, sp, [1, 5, 3]), Exception, "p0"),
                             ((mm, None, ds, sp, [1, 5], None, "x"), TypeError, "detect_settings"),
                             ((mm, None, ds, sp, [1, 5], None, None, np.zeros((3, 1))), Exception, "start_states"),
                             (("mm", None, ds, sp, [1, 5]), TypeError, "model")):
        with pytest.raises(exc, match=match):
            batched_split_tests(*args)
