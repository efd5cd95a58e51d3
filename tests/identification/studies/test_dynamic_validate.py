"""Monte Carlo validate on a DynamicModel with its DynamicMeasurements (issue 22, item 4): the size study
runs on the collocation at the campaign fit, with splits by experiment, time window and early vs late."""
import numpy as np
import pytest

from identification import MonteCarloSettings, Split, identify, validate
from identification.fit.dynamic_fit import simulate_campaign
from identification.studies.split_fits import ONE_BY_ONE
from identification.studies.splits import SplitError, flat_split, time_window_split
from mudoe.example_reactor import P_TRUE, build

Q = np.array([[1.0, 330.0], [2.0, 330.0], [1.0, 370.0], [2.0, 370.0]])     # mol/L, K
TIMES = np.linspace(0.4, 2.0, 5)                                            # h
SIGMA = np.array([0.01, 0.01])                                              # mol/L
EARLY_LATE = Split("early vs late", None, None, description="early vs late", cal_window=(-np.inf, 1.2),
                   val_window=(1.2, np.inf))


@pytest.fixture(scope="module")
def campaign():
    model = build()
    return model, simulate_campaign(model, P_TRUE, Q, TIMES, SIGMA, n_series=2, seed=3)


def test_flat_split_of_a_time_window_masks_the_columns_of_its_times(campaign):
    model, data = campaign
    sp = flat_split(EARLY_LATE, data.pairs, data.n_q)
    ref = time_window_split(data.pairs, data.n_q, (0.4, 0.8), (1.2, 2.0))
    assert (sp.cal_sensors, sp.val_sensors) == (ref.cal_sensors, ref.val_sensors)
    assert sp.cal_inputs == sp.val_inputs == (0, 1, 2, 3)
    by_exp = Split("exp", (0, 2), (1, 3), cal_window=(-np.inf, 1.0))
    sp2 = flat_split(by_exp, data.pairs, data.n_q)
    assert sp2.cal_inputs == (0, 2) and sp2.val_sensors is None and sp2.cal_sensors == (0, 1, 2, 3)
    with pytest.raises(SplitError, match="holds no sampling time"):
        flat_split(Split("none", None, None, cal_window=(5.0, 6.0), val_window=(0.0, 1.0)), data.pairs, data.n_q)


def test_validate_takes_the_dynamic_model_and_its_campaign(campaign):
    model, data = campaign
    splits = [Split("cA0 = 1 vs 2", [0, 2], [1, 3]), EARLY_LATE,
              time_window_split(data.pairs, data.n_q, (0.4, 0.8), (1.6, 2.0))]
    # the per-fit path is what this test is about (the merged batch path: the test below)
    mc = dict(n_rep=3, seed=5, workers=1, progress=False, jit=False, chunk_size=3, fits=ONE_BY_ONE)
    res = validate(model, splits, P_TRUE, p=P_TRUE, data=data, n_series=2, settings=MonteCarloSettings(**mc))
    assert not res.errors and res.alpha_lr.shape[-1] == 3 and np.all(np.isfinite(res.alpha_lr))
    # the same numbers as the size study written by hand on the collocation of the campaign fit
    est = identify(model, data, P_TRUE)
    by_hand = validate(est.model, [flat_split(sp, est.model.outputs, data.n_q) for sp in splits], P_TRUE,
                       p=P_TRUE, inputs=est.data.inputs, sigma=est.data.sigma, n_series=2,
                       settings=MonteCarloSettings(**mc))
    # (equal up to rounding: the two collocated models are separate CasADi functions on the same mesh)
    np.testing.assert_allclose(res.alpha_lr, by_hand.alpha_lr, rtol=1e-10, atol=1e-14)
    np.testing.assert_array_equal(res.covered, by_hand.covered)


BATCH_SCRIPT = """
import json, sys
import numpy as np
from identification import MonteCarloSettings, Split, identify, validate
from identification.fit.dynamic_fit import simulate_campaign
from identification.studies.splits import time_window_split
from mudoe.example_reactor import P_TRUE, build
Q = np.array(json.loads(sys.argv[1]))
model = build()
data = simulate_campaign(model, P_TRUE, Q, np.linspace(0.4, 2.0, 5), np.array([0.01, 0.01]), n_series=2, seed=3)
est = identify(model, data, P_TRUE)
splits = [Split("cA0 = 1 vs 2", [0, 2], [1, 3]), time_window_split(data.pairs, 4, (0.4, 0.8), (1.2, 2.0)),
          time_window_split(data.pairs, 4, (0.4, 0.8), (1.6, 2.0))]
r = validate(est.model, splits, P_TRUE, p=P_TRUE, inputs=est.data.inputs, sigma=est.data.sigma, n_series=2,
             settings=MonteCarloSettings(n_rep=3, seed=5, workers=1, progress=False, jit=False, chunk_size=3))
print(json.dumps(np.asarray(r.alpha_lr).tolist()))
"""


def test_merged_batch_fits_of_a_collocated_model_run_and_equal_the_per_fit_path(campaign):
    """The batch engine fits a collocated model's members in threads with merged evaluations
    (models.merged_calls.run_merged).  Two threads in CasADi at once crashed the interpreter (exit 139 in
    4 of 4 runs of this script); one thread now runs at a time.  In a subprocess, so a crash fails the test."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path
    repo = Path(__file__).resolve().parents[3]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=str(repo))
    run = subprocess.run([sys.executable, "-c", BATCH_SCRIPT, json.dumps(Q.tolist())], cwd=repo, env=env,
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    batched = np.array(json.loads(run.stdout.strip().splitlines()[-1]))
    model, data = campaign
    est = identify(model, data, P_TRUE)
    splits = [Split("cA0 = 1 vs 2", [0, 2], [1, 3]), time_window_split(data.pairs, 4, (0.4, 0.8), (1.2, 2.0)),
              time_window_split(data.pairs, 4, (0.4, 0.8), (1.6, 2.0))]
    per_fit = validate(est.model, splits, P_TRUE, p=P_TRUE, inputs=est.data.inputs, sigma=est.data.sigma,
                       n_series=2, settings=MonteCarloSettings(n_rep=3, seed=5, workers=1, progress=False, jit=False,
                                                          chunk_size=3, fits=ONE_BY_ONE))
    # the same fits to round-off (1.4e-13 relative measured): 1e-9 leaves room for other BLAS kernels
    np.testing.assert_allclose(batched, per_fit.alpha_lr, rtol=1e-9, atol=1e-14)
