"""Bootstrap p-values of the split tests (identification.studies.detect_bootstrap, issue 12 item 6).

The uniformity of the bootstrap p-values under the null is a Monte Carlo study in
``bench/bench_detect_bootstrap.py`` (too long for a unit test); here: the definition on a
case computed by hand from the returned statistics, a clear alternative, the backends giving
identical numbers, and bad input.
"""
from __future__ import annotations

import io

import numpy as np
import pytest

from identification import Measurements
from identification.studies.detect import STATISTICS, run_split_tests
from identification.studies.detect_bootstrap import bootstrap_detect
from identification.progress import Progress
from identification.studies.split_fits import ONE_BY_ONE
from identification.studies.splits import Split
from models import Model

X = np.linspace(0.0, 2.0, 8)
SPLITS = (Split("low/high", range(0, 4), range(4, 8)), Split("odd/even", range(0, 8, 2), range(1, 8, 2)))


def _line(offset=0.0, sigma=0.1, known=True, seed=3):
    """y = a + b x, 2 series; ``offset`` is added to the high half of the inputs (a model error)."""
    model = Model.explicit(params=["a", "b"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] + p[1] * q[0],
                           name="line")
    truth = 1.0 + 2.0 * X + offset * (X > 1.0)
    z = truth[None, :, None] + sigma * np.random.default_rng(seed).standard_normal((2, X.size, 1))
    return model, Measurements(X, z, [sigma] if known else None)


def test_pvalues_follow_the_definition_and_match_the_observed_tests():
    model, data = _line()
    res = bootstrap_detect(model, data, SPLITS, [0.0, 0.0], n_rep=19, seed=5)
    obs = run_split_tests(model, data, SPLITS, [0.0, 0.0])
    assert res.statistics == STATISTICS and res.splits == ("low/high", "odd/even")
    np.testing.assert_allclose(res.asymptotic[:, 0], [t.alpha_lr for t in obs], rtol=1e-10)
    np.testing.assert_allclose(res.observed[:, 1], [t.d2_two_sample for t in obs], rtol=1e-10)
    assert res.boot_statistics.shape == (19, 2, 3) and not res.errors and np.all(res.n_valid == 19)
    for s in range(2):
        for k in range(3):
            k_ge = np.count_nonzero(res.boot_statistics[:, s, k] >= res.observed[s, k])
            assert res.pvalue[s, k] == (1 + k_ge) / 20
    fam = np.min(res.boot_asymptotic, axis=1)
    np.testing.assert_array_equal(res.family_asymptotic, np.min(res.asymptotic, axis=0))
    np.testing.assert_array_equal(res.family_pvalue,
                                  (1 + np.count_nonzero(fam <= res.family_asymptotic, axis=0)) / 20)
    assert np.all((res.pvalue >= 1 / 20) & (res.pvalue <= 1))
    # a linear model, sigma known: the two-sample Wald statistic equals the likelihood ratio, campaign by campaign
    np.testing.assert_allclose(res.boot_statistics[:, :, 0], res.boot_statistics[:, :, 1], rtol=1e-6, atol=1e-9)
    text = res.summary()
    assert "family (min-p)" in text and "1/(B+1) = 5 %" in text


def test_a_model_error_gives_the_smallest_bootstrap_pvalue():
    """An offset of 10 sigma on the high inputs: no bootstrap campaign reaches the observed statistic."""
    model, data = _line(offset=1.0, known=False)
    res = bootstrap_detect(model, data, SPLITS[:1], [0.0, 0.0], n_rep=9, seed=1)
    assert res.sigma_estimated
    assert res.pvalues("likelihood_ratio")[0] == pytest.approx(0.1)      # 1 / (B + 1)
    assert res.rejected(0.1) and not res.rejected(0.05)                  # 0.1 is the smallest attainable


def test_same_seed_same_numbers_serial_and_dask():
    distributed = pytest.importorskip("distributed", reason="dask[distributed] is in the test extras (make setup)")
    model, data = _line(known=False)
    a = bootstrap_detect(model, data, SPLITS, [0.0, 0.0], n_rep=6, seed=7)
    out = io.StringIO()
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as cl:
        b = bootstrap_detect(model, data, SPLITS, [0.0, 0.0], n_rep=6, seed=7, scheduler=cl.scheduler_address,
                             chunk_size=2, progress=Progress(stream=out))
    assert a.backend == "serial" and b.backend.startswith("dask (")
    np.testing.assert_array_equal(a.boot_statistics, b.boot_statistics)
    np.testing.assert_array_equal(a.pvalue, b.pvalue)
    assert "bootstrap campaigns" in out.getvalue() and "6/6" in out.getvalue()
    c = bootstrap_detect(model, data, SPLITS, [0.0, 0.0], n_rep=6, seed=8)
    assert not np.array_equal(a.boot_statistics, c.boot_statistics)


@pytest.mark.parametrize("kw, match", [
    (dict(n_rep=0), "n_rep"), (dict(n_rep=2.5), "n_rep"), (dict(workers=0), "workers"),
    (dict(scheduler=""), "scheduler"), (dict(chunk_size=0), "chunk_size"), (dict(seed=-1), "seed"),
    (dict(settings="lr"), "settings"),
])
def test_bad_arguments_name_the_argument(kw, match):
    model, data = _line()
    with pytest.raises((ValueError, TypeError), match=match):
        bootstrap_detect(model, data, SPLITS, [0.0, 0.0], **kw)
    with pytest.raises(Exception, match="splits"):
        bootstrap_detect(model, data, [], [0.0, 0.0])
    with pytest.raises(TypeError, match="data"):
        bootstrap_detect(model, np.zeros(3), SPLITS, [0.0, 0.0])
    res = bootstrap_detect(model, data, SPLITS[:1], [0.0, 0.0], n_rep=2, seed=0)
    with pytest.raises(ValueError, match="statistic"):
        res.pvalues("wald")
    with pytest.raises(ValueError, match="tol"):
        res.rejected(1.5)


def _mm(known=True, seed=4):
    """Michaelis-Menten y = Vm x / (K + x) at 8 inputs, 2 series, sigma 0.01, one missing value."""
    mm = Model.explicit(params=["Vm", "K"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] * q[0] / (p[1] + q[0]),
                        name="MM")
    x = np.linspace(0.5, 8.0, 8)
    z = (x / (5.0 + x))[None, :, None] + 0.01 * np.random.default_rng(seed).standard_normal((2, 8, 1))
    z[1, 3, 0] = np.nan
    return mm, Measurements(x, z, [0.01] if known else None)


@pytest.mark.parametrize("known", [True, False])
def test_batched_campaigns_give_the_numbers_of_one_fit_at_a_time(known):
    """fits=BATCHED (the chunk's campaigns fitted together) vs fits=ONE_BY_ONE (identify per fit), same seed:
    T* to 1e-8 relative with the same NaN pattern, identical p-values, failures counted and named alike
    (a split whose validation input cannot identify Vm and K fails in every campaign)."""
    mm, data = _mm(known)
    splits = SPLITS + (Split("one input", range(0, 7), [7]),)
    kw = dict(n_rep=12, seed=9, chunk_size=6)
    a = bootstrap_detect(mm, data, splits, [1.0, 5.0], fits=ONE_BY_ONE, **kw)
    b = bootstrap_detect(mm, data, splits, [1.0, 5.0], **kw)
    assert np.array_equal(np.isnan(a.boot_statistics), np.isnan(b.boot_statistics))
    assert np.all(np.isfinite(b.boot_statistics[:, :2])) and np.all(np.isnan(b.boot_statistics[:, 2]))
    np.testing.assert_allclose(b.boot_statistics, a.boot_statistics, rtol=1e-8)
    np.testing.assert_allclose(b.boot_asymptotic, a.boot_asymptotic, rtol=1e-7)
    np.testing.assert_array_equal(b.pvalue, a.pvalue)
    np.testing.assert_array_equal(b.family_pvalue, a.family_pvalue)
    np.testing.assert_array_equal(b.n_valid, a.n_valid)
    assert b.errors == a.errors and len(b.errors) == 12
    assert all(sp == "one input" and text.startswith("validation fit: ") for _, sp, text in b.errors)


def test_fits_must_be_a_strategy():
    mm, data = _mm()
    with pytest.raises(TypeError, match="fits: expected BATCHED"):
        bootstrap_detect(mm, data, SPLITS, [1.0, 5.0], n_rep=2, fits=True)


def test_jit_gives_the_same_numbers_and_restores_the_setting():
    """jit=True (the default: compiled model functions, as Monte Carlo) vs jit=False (the virtual
    machine): the same statistics to round-off; the process-wide JIT setting is left as it was."""
    import shutil
    from models.state import JIT
    mm, data = _mm()
    kw = dict(n_rep=6, seed=4, chunk_size=3)
    before = JIT.enabled
    a = bootstrap_detect(mm, data, SPLITS, [1.0, 5.0], jit=False, **kw)
    used = JIT.stats.compiled + JIT.stats.loaded
    b = bootstrap_detect(mm, data, SPLITS, [1.0, 5.0], **kw)
    assert JIT.enabled == before
    np.testing.assert_allclose(b.boot_statistics, a.boot_statistics, rtol=1e-10)
    np.testing.assert_array_equal(b.pvalue, a.pvalue)
    if shutil.which("gcc") is not None:
        assert JIT.stats.compiled + JIT.stats.loaded > used      # the compiled path was really taken
    with pytest.raises(TypeError, match="jit"):
        bootstrap_detect(mm, data, SPLITS, [1.0, 5.0], n_rep=2, jit="yes")
