"""Parametric bootstrap intervals (identification.inference.bootstrap, issue 12)."""
from __future__ import annotations

import dataclasses
import io

import casadi as ca
import numpy as np
import pytest
from scipy import stats

from identification import Measurements, identify
from identification.inference.bootstrap import ONE_BY_ONE_REFITS, bootstrap_intervals, bootstrap_replicates
from identification.progress import Progress
from models import Model


def _linear(sigma=0.2, known=True):
    model = Model.explicit(params=["a", "b"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] + p[1] * q[0],
                           name="line")
    x = np.linspace(0, 2, 6)
    z = (1 + 2 * x)[None, :, None] + sigma * np.random.default_rng(4).standard_normal((3, 6, 1))
    z[1, 2, 0] = np.nan                                          # a missing value stays missing
    data = Measurements(x, z, [sigma] if known else None)
    return model, data, identify(model, data, [0.0, 0.0])


def test_bootstrap_of_linear_model_reproduces_the_covariance():
    """Linear model, sigma known: the refits are exactly N(p_hat, cov); their sample covariance agrees."""
    model, data, est = _linear()
    ci = est.conf_int(0.1, method="bootstrap", model=model, data=data, n=200, seed=3)
    assert ci.method == "bootstrap" and ci.n_failed == 0 and ci.replicates.shape == (200, 2)
    S = np.cov(ci.replicates.T)
    # each variance: (n-1) S_ii / C_ii ~ chi2_{n-1}; 99.9 % acceptance band
    for i in range(2):
        ratio = (200 - 1) * S[i, i] / est.cov[i, i]
        assert stats.chi2.ppf(5e-4, 199) < ratio < stats.chi2.ppf(1 - 5e-4, 199), (i, ratio)
    # the mean within 4 standard errors of the mean
    assert np.all(np.abs(ci.replicates.mean(0) - est.p) < 4 * est.stderr / np.sqrt(200))
    np.testing.assert_allclose([ci.lower, ci.upper], np.quantile(ci.replicates, [0.05, 0.95], axis=0))


@pytest.mark.slow
def test_same_seed_same_numbers_serial_and_processes():
    """Per-replicate SeedSequence children: identical numbers serially and on 2 spawned processes
    (slow: most of its time is starting the processes)."""
    model, data, est = _linear(known=False)
    r1 = bootstrap_replicates(model, data, est, n=6, seed=11, workers=1)
    r2 = bootstrap_replicates(model, data, est, n=6, seed=11, workers=2)
    r3 = bootstrap_replicates(model, data, est, n=6, seed=12, workers=1)
    assert r1.errors == r2.errors == () and r1.fallbacks == r2.fallbacks == ()
    assert r1.backend == "serial" and r2.backend == "2 local processes"
    np.testing.assert_array_equal(r1.P, r2.P)
    assert not np.array_equal(r1.P, r3.P)


def test_failed_refits_are_counted_and_named():
    """h = sqrt(a) x + b with a true slope near 0: refits whose a goes negative fail (NaN); they are reported."""
    model = Model.explicit(params=["a", "b"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: ca.sqrt(p[0]) * q[0] + p[1], name="sqrt slope")
    x = np.linspace(0, 1, 4)
    data = Measurements(x, (0.01 * x)[None, :, None], [0.5])
    est = identify(model, data, [0.01, 0.0])
    out = io.StringIO()
    ci = est.conf_int(method="bootstrap", model=model, data=data, n=16, seed=0, progress=Progress(stream=out))
    reps = bootstrap_replicates(model, data, est, n=16, seed=0)
    P, errors = reps.P, reps.errors
    assert "bootstrap refits" in out.getvalue() and "16/16" in out.getvalue()
    assert 0 < ci.n_failed == len(errors) < 15
    assert ci.n_failed + ci.replicates.shape[0] == 16
    assert np.isnan(P[[i for i, _ in errors]]).all()
    assert any(n.startswith(f"{ci.n_failed} of 16 bootstrap refits failed and are excluded") for n in ci.notes)
    assert "IdentificationError" in ci.notes[0]
    # every failed refit was first left by the batch engine to identify, and says why
    failed = {i for i, _ in errors}
    assert failed <= {i for i, _ in reps.fallbacks} and all(why for _, why in reps.fallbacks)
    assert ci.fallbacks == reps.fallbacks
    assert any(n.startswith(f"{len(reps.fallbacks)} of 16 bootstrap refits were not converged by the batch engine")
               for n in ci.notes)
    # the per-refit path fails on the same replicates, with no fallbacks
    per_fit = bootstrap_replicates(model, data, est, n=16, seed=0, refits=ONE_BY_ONE_REFITS)
    assert [i for i, _ in per_fit.errors] == [i for i, _ in errors] and per_fit.fallbacks == ()


def test_bad_arguments():
    model, data, est = _linear()
    with pytest.raises(ValueError, match="n: the number of bootstrap replicates"):
        est.conf_int(method="bootstrap", model=model, data=data, n=1)
    with pytest.raises(ValueError, match="workers"):
        est.conf_int(method="bootstrap", model=model, data=data, n=5, workers=0)
    with pytest.raises(ValueError, match="model, data"):          # an Estimate not made by identify()
        dataclasses.replace(est, model=None, data=None).conf_int(method="bootstrap", n=5)


def test_same_seed_same_numbers_on_a_dask_cluster():
    """Serial and a Dask LocalCluster (2 in-process workers, chunks of 2 and of 3 replicates): identical refits;
    the interval from conf_int(..., scheduler=client) equals the serial one."""
    distributed = pytest.importorskip("distributed", reason="dask[distributed] is in the test extras (make setup)")
    model, data, est = _linear(known=False)
    r1 = bootstrap_replicates(model, data, est, n=7, seed=11, workers=1)
    P1, e1 = r1.P, r1.errors
    ci1 = est.conf_int(0.2, method="bootstrap", model=model, data=data, n=7, seed=11)
    out = io.StringIO()
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0") as cl, \
            distributed.Client(cl, set_as_default=False) as client:
        r2 = bootstrap_replicates(model, data, est, n=7, seed=11, scheduler=client, chunk_size=2,
                                  progress=Progress(stream=out))
        P2, e2 = r2.P, r2.errors
        P3 = bootstrap_replicates(model, data, est, n=7, seed=11, scheduler=cl.scheduler_address, chunk_size=3).P
        ci2 = est.conf_int(0.2, method="bootstrap", model=model, data=data, n=7, seed=11, scheduler=client)
        assert client.status == "running"                  # a Client passed in is used, not closed
    assert e1 == e2 == () and np.all(np.isfinite(P1)) and r2.backend.startswith("dask")
    np.testing.assert_array_equal(P1, P2)
    np.testing.assert_array_equal(P1, P3)
    np.testing.assert_array_equal([ci1.lower, ci1.upper], [ci2.lower, ci2.upper])
    assert "7/7" in out.getvalue()


def test_bad_scheduler_and_chunk_size_name_the_argument():
    model, data, est = _linear()
    with pytest.raises(ValueError, match="scheduler: expected a Dask scheduler address"):
        bootstrap_replicates(model, data, est, n=4, scheduler="")
    with pytest.raises(ValueError, match="chunk_size"):
        bootstrap_replicates(model, data, est, n=4, chunk_size=0)
    with pytest.raises(TypeError, match="refits: expected BATCH_REFITS"):
        bootstrap_replicates(model, data, est, n=4, refits="yes")


def _michaelis_menten(known: bool):
    model = Model.explicit(params=["Vm", "K"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] * q[0] / (p[1] + q[0]), name="Michaelis-Menten")
    x = np.linspace(0.5, 8.0, 8)
    z = (x / (5.0 + x))[None, :, None] + 0.02 * np.random.default_rng(7).standard_normal((2, 8, 1))
    z[0, 3, 0] = np.nan
    data = Measurements(x, z, [0.02] if known else None)
    return model, data, identify(model, data, [1.0, 5.0])


@pytest.mark.parametrize("known", [True, False])
def test_batch_engine_gives_the_refits_of_identify(known):
    """The batch engine's refits equal identify's per-refit ones to 1e-8 relative (same seeds), whatever
    the chunks; so do the percentile intervals."""
    model, data, est = _michaelis_menten(known)
    per_fit = bootstrap_replicates(model, data, est, n=24, seed=5, refits=ONE_BY_ONE_REFITS)
    batched = bootstrap_replicates(model, data, est, n=24, seed=5, chunk_size=10)
    whole = bootstrap_replicates(model, data, est, n=24, seed=5)
    assert per_fit.errors == batched.errors == () and batched.fallbacks == ()
    assert np.all(np.isfinite(per_fit.P))
    np.testing.assert_allclose(batched.P, per_fit.P, rtol=1e-8, atol=0)
    np.testing.assert_array_equal(batched.P, whole.P)
    ci_b = bootstrap_intervals(model, data, est, 0.1, n=24, seed=5)
    ci_f = bootstrap_intervals(model, data, est, 0.1, n=24, seed=5, refits=ONE_BY_ONE_REFITS)
    np.testing.assert_allclose([ci_b.lower, ci_b.upper], [ci_f.lower, ci_f.upper], rtol=1e-8, atol=0)
