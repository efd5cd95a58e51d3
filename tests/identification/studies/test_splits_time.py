"""One Split for static and dynamic studies (issue 28, item 2): half-open time windows, the one early/late
rule, the time series cut into (experiment, window) rows, and the deprecated names of the dynamic mirror."""
import math
import warnings

import numpy as np
import pytest

from identification import DataError, DynamicMeasurements, Measurements
from identification.studies.detect import detect
from identification.studies.normality import NormalityError
from identification.studies.splits import (Split, SplitError, early_late_cut, early_late_dynamic_split,
                                           early_late_split, flat_split, time_window_splits, window_rows)
from models.library import linear_model

Q = np.array([[1.0, 330.0], [2.0, 345.0], [1.5, 360.0]])
TIMES = np.array([0.25, 0.5, 1.0, 1.5, 2.0])                   # an odd count: the middle time is late


def series(z=None):
    """A campaign of time series: 2 series x 3 experiments x 5 times x 2 instruments."""
    z = np.arange(2 * 3 * 5 * 2, dtype=float).reshape(2, 3, 5, 2) if z is None else z
    return DynamicMeasurements(Q, TIMES, z, [0.01, 0.02], sensors=["cA", "cB"])


def test_one_early_late_rule_for_columns_and_windows():
    assert early_late_cut(TIMES) == 1.0                        # t_(n // 2): early t < 1.0 = {0.25, 0.5}
    assert early_late_cut(TIMES[:4]) == 1.0                    # even count: half of the times each
    data = series()
    window = early_late_dynamic_split(data)
    assert (window.cal_window, window.val_window) == ((-math.inf, 1.0), (1.0, math.inf))
    cols = early_late_split(data.pairs, data.n_q)
    assert cols.name == "early t < 1 vs late t >= 1"
    flat = flat_split(window, data.pairs, data.n_q)            # the window split as columns of the flat data
    assert (flat.cal_sensors, flat.val_sensors) == (cols.cal_sensors, cols.val_sensors) == ((0, 1, 2, 3),
                                                                                           (4, 5, 6, 7, 8, 9))
    with pytest.raises(SplitError, match="at least two sampling times"):
        early_late_cut([0.5, 0.5])


def test_a_split_by_time_window_is_validated_like_any_split():
    sp = Split("w", None, None, cal_window=(-np.inf, 1.0), val_window=[1.0, np.inf])
    assert sp.timed and sp.val_window == (1.0, math.inf) and sp.edges() == {1.0}
    assert sp.label() == ("all [t < 1]", "all [t >= 1]")
    assert (sp.swapped().cal_window, sp.swapped().val_window) == (sp.val_window, sp.cal_window)
    Split("rows and a window", [0, 1], [0, 1], cal_window=(0.0, 1.0), val_window=(1.0, 2.0))   # disjoint in time
    with pytest.raises(SplitError, match="overlap.*and times 0.5 <= t < 1"):
        Split("bad", [0, 1], [1], cal_window=(0.0, 1.0), val_window=(0.5, 2.0))
    with pytest.raises(SplitError, match="cal_window \\[1.0, 1.0\\] is empty"):
        Split("bad", None, None, cal_window=(1.0, 1.0), val_window=(1.0, 2.0))
    with pytest.raises(SplitError, match="cal_inputs \\(calibration inputs\\) must be given"):
        Split("bad", None, [1])                                 # all rows only with a time window
    with pytest.raises(SplitError, match="takes every instrument's readings"):
        Split("bad", None, None, cal_window=(0.0, 1.0), val_window=(1.0, 2.0), cal_sensors=[0])
    with pytest.raises(SplitError, match="selects readings by time window.*flat_split"):
        sp.calibration(Measurements([[0.0], [1.0]], np.ones((1, 2, 1)), 0.1))


def test_time_series_are_cut_into_experiment_window_rows():
    data = series()
    sp = (Split("exp", [0], [1, 2]),) + time_window_splits([0.75])
    rows, row_splits = window_rows(data, sp)
    assert rows.n_q == 6 and rows.n_M == 2                     # 3 experiments x 2 windows (t < 0.75, t >= 0.75)
    assert row_splits[0].cal_inputs == (0, 1) and row_splits[0].val_inputs == (2, 3, 4, 5)
    assert row_splits[1].cal_inputs == (0, 2, 4) and row_splits[1].val_inputs == (1, 3, 5)
    early = np.isfinite(rows.z[0, 0])                          # experiment 1 before 0.75: times 0.25, 0.5
    assert early.tolist() == [True] * 4 + [False] * 6
    with pytest.raises(SplitError, match="calibration experiment\\(s\\) \\[7\\] out of range"):
        window_rows(data, [Split("far", [7], [1])])


def test_detect_checks_the_split_against_the_kind_of_campaign():
    from mudoe import example_reactor as R
    m = linear_model(np.array([[1.0, 0.3], [0.2, 1.0]]))
    data = Measurements(np.linspace(0, 1, 6)[:, None], np.ones((2, 6, 2)) + 0.01 * np.arange(24).reshape(2, 6, 2),
                        [0.1, 0.1])
    with pytest.raises(SplitError, match="a static model's data have no sampling times"):
        detect(m, data, time_window_splits([0.5]), [1.0, 1.0], normality="override")
    with pytest.raises(DataError, match="only the fits of a dynamic model take a discretisation"):
        detect(m, data, [Split("a", [0, 1, 2], [3, 4, 5])], [1.0, 1.0], discretisation=object())
    with pytest.raises(DataError, match="mix static and dynamic models"):
        detect({"static": m, "dynamic": R.build()}, data, [Split("a", [0, 1, 2], [3, 4, 5])], [1.0, 1.0])
    with pytest.raises(SplitError, match="splits of series are not supported on dynamic data"):
        detect(R.build(), series(), [Split("s", [0], [1], cal_series=[0], val_series=[1])], R.P_TRUE)
    from identification import linearized_size, size_study
    with pytest.raises(SplitError, match="select readings by time window; a Monte Carlo study"):
        size_study(m, [1.0, 1.0], data.inputs, [0.1, 0.1], time_window_splits([0.5]))
    with pytest.raises(SplitError, match="select readings by time window"):
        linearized_size(m, [1.0, 1.0], data.inputs, [0.1, 0.1], time_window_splits([0.5]))


def test_one_normality_gate_pooled_per_instrument_on_time_series():
    from mudoe import example_reactor as R
    rng = np.random.default_rng(0)
    z = np.zeros((4, 3, 5, 2))
    z[..., 0] = rng.standard_normal((4, 3, 5))
    z[..., 1] = rng.standard_exponential((4, 3, 5)) ** 3        # strongly skewed differences
    with pytest.raises(NormalityError) as err:                   # raised before any fit
        detect(R.build(), series(z), time_window_splits([0.75]), R.P_TRUE)
    msg = str(err.value)
    assert msg.startswith("normality gate (Algorithm 1, line 05) failed for sensor(s) cB: Shapiro-Wilk")
    assert "(pooled per instrument over every (experiment, time) reading)" in msg
    chk = err.value.check
    assert chk.sensors == ("cA", "cB") and chk.n_diff.tolist() == [30, 30]     # 2 pairs x 3 experiments x 5 times


def test_the_dynamic_mirror_names_warn_and_still_work():
    data = series()
    with pytest.warns(DeprecationWarning, match="DynamicSplit is deprecated; use identification.studies.splits.Split"):
        from identification.studies.dynamic_detect import DynamicSplit
        sp = DynamicSplit("el", None, None, (-np.inf, 1.0), (1.0, np.inf), "early vs late")
    assert sp == Split("el", None, None, description="early vs late", cal_window=(-np.inf, 1.0),
                       val_window=(1.0, np.inf))
    with pytest.warns(DeprecationWarning, match="import it from identification.studies.splits"):
        from identification.studies.dynamic_detect import early_late_dynamic_split as old
    assert old(data) == early_late_dynamic_split(data)
    with pytest.warns(DeprecationWarning, match="cal_experiments is deprecated; use Split.cal_inputs"):
        assert Split("e", [0], [1]).cal_experiments == (0,)
    with pytest.warns(DeprecationWarning, match="flat_size_study"):
        from identification.studies.dynamic_validate import dynamic_size_study
        with pytest.raises(DataError, match="needs the campaign as identification.DynamicMeasurements"):
            dynamic_size_study(None, data.flat(), [sp])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        from identification.studies.detect import detect as new_detect      # the new names do not warn
    assert callable(new_detect)
