"""Algorithm 1 on a dynamic model called with the dynamic model and DynamicMeasurements directly:
splits by experiment, by time window and early vs late; a split whose discretisation error is not
bounded is undecided, never a rejection."""
import dataclasses

import numpy as np

from identification.studies.detect import detect
from identification.fit.dynamic_fit import simulate_campaign
from identification.studies.splits import Split, early_late_dynamic_split, time_window_splits
from mudoe import example_reactor as R


def _campaign(seed=3):
    Q = np.array([[1.0, 330.0], [2.0, 345.0], [1.5, 360.0], [1.0, 370.0]])
    t = np.array([0.25, 0.5, 1.0, 1.5, 2.0])
    return R.build(), simulate_campaign(R.build(), R.P_TRUE, Q, t, [0.01, 0.01], n_series=2, seed=seed)


def test_detect_dispatches_on_a_dynamic_model():
    m, d = _campaign()
    splits = [Split("exp 1-2 vs 3-4", [0, 1], [2, 3]), early_late_dynamic_split(d)] + list(time_window_splits([0.75]))
    res = detect(m, d, splits, R.P_TRUE * 1.1)
    assert [t.cal_label for t in res.tests] == ["experiment(s) 1, 2", "all experiments; t < 1",
                                                "all experiments; t < 0.75"]
    assert all(t.ok and 0 <= t.alpha_lr <= 1 for t in res.tests)
    assert res.normality[0][1].sensors == ("cA", "cB")                    # pooled per instrument
    assert res.normality[0][1].n_diff.tolist() == [20, 20]               # 4 experiments x 5 times
    assert res.verdicts[m.name] in ("not rejected", "rejected")


def test_unbounded_discretisation_makes_a_split_undecided():
    from identification.studies.detect import DetectSettings
    from identification.fit.dynamic_fit import DiscretisationSettings
    m, d = _campaign()
    never = DiscretisationSettings(tol_sigma=1e-12, max_refinements=0)     # an error that cannot be bounded
    res = detect(m, d, [Split("exp 1-2 vs 3-4", [0, 1], [2, 3])], R.P_TRUE, settings=DetectSettings(),
                 discretisation=never)
    t = res.tests[0]
    assert not t.ok and t.stage == "discretisation" and "not bounded" in t.error and np.isnan(t.alpha_lr)
    assert res.verdicts[m.name] == "undecided"
