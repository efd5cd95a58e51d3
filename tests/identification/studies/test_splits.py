"""Calibration / validation splits: the paper's four press scenarios, random, input-range, errors."""
import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from identification import Measurements
from identification.studies.splits import (Split, SplitError, input_range_split, random_splits, series_split,
                                   splits_from_scenarios)
from models.press import PRESS_SCENARIO_NAMES, PRESS_SCENARIOS, Q_PAPER, press_scenario_rows


def _zero_based(one_based):
    return tuple(i - 1 for i in one_based)


def test_press_scenarios_match_the_papers_table_testsets():
    # Table "Testsets" of the paper, 1-based q^d_j indices
    paper = {
        "loading: odd vs even": (range(2, 15, 2), range(3, 16, 2)),
        "unloading: odd vs even": (range(15, 28, 2), range(16, 29, 2)),
        "loading vs unloading": (range(2, 15), range(15, 29)),
        "loading+unloading interleaved": (range(3, 28, 2), range(2, 29, 2)),
    }
    sc = splits_from_scenarios(press_scenario_rows, 29)
    assert tuple(s.name for s in sc) == PRESS_SCENARIO_NAMES
    for s in sc:
        cal, val = paper[s.name]
        assert s.cal_inputs == _zero_based(cal), s.name
        assert s.val_inputs == _zero_based(val), s.name
        assert s.cal_series is None and s.val_series is None
        # the unloaded first and last points are never used
        assert 0 not in s.cal_inputs + s.val_inputs and 28 not in s.cal_inputs + s.val_inputs
        s.check(29, 2, n_p=2, n_sensors=2)


def test_press_scenarios_on_the_paper_loads():
    q = np.array(Q_PAPER)
    sc = {s.name: s for s in splits_from_scenarios(press_scenario_rows, 29)}
    load = sc["loading vs unloading"]
    assert np.all(np.diff(q[list(load.cal_inputs)]) > 0)          # calibration: rising loads
    assert q[load.val_inputs[0]] == 1600.0                         # validation starts at the peak
    assert np.all(np.diff(q[list(load.val_inputs)]) < 0)           # then falls
    assert len(sc["loading+unloading interleaved"].cal_inputs) == 13
    assert len(sc["loading+unloading interleaved"].val_inputs) == 14


def test_press_scenarios_with_held_out_series_and_errors():
    sc = splits_from_scenarios(press_scenario_rows, 29, series=[4, 5])
    assert all(s.cal_series == (4, 5) and s.val_series == (4, 5) for s in sc)
    with pytest.raises(SplitError, match="n_q"):
        splits_from_scenarios(press_scenario_rows, 28)
    with pytest.raises(SplitError, match="n_q"):
        splits_from_scenarios(press_scenario_rows, 5)


def test_splits_from_a_constant_scenario_table_and_its_errors():
    # the press's constant table for Q_PAPER gives the same splits as its row function at n_q = 29
    assert splits_from_scenarios(PRESS_SCENARIOS, len(Q_PAPER)) == splits_from_scenarios(press_scenario_rows, 29)
    sc = splits_from_scenarios({"user": ([1, 2], [3, 4])}, 5)
    assert sc[0].cal_inputs == (1, 2) and sc[0].val_inputs == (3, 4) and sc[0].description == ""
    with pytest.raises(SplitError, match="n_q: scenario 'user' uses input row 4"):
        splits_from_scenarios({"user": ([1, 2], [3, 4])}, 4)
    with pytest.raises(SplitError, match=r"scenarios\['user'\]"):
        splits_from_scenarios({"user": ([1, 2],)}, 5)
    with pytest.raises(SplitError, match="scenarios: expected a non-empty mapping"):
        splits_from_scenarios({}, 5)
    with pytest.raises(SplitError, match="overlap"):
        splits_from_scenarios({"user": ([1, 2], [2, 3])}, 5)


def test_split_is_immutable_and_validated():
    s = Split("user", [1, 2, 3], [4, 5])
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.name = "other"
    with pytest.raises(SplitError, match="'bad'.*overlap.*\\[2\\]"):
        Split("bad", [1, 2], [2, 3])
    with pytest.raises(SplitError, match="'e'.*cal_inputs.*empty"):
        Split("e", [], [1])
    with pytest.raises(SplitError, match="'d'.*twice"):
        Split("d", [1, 1], [2])
    with pytest.raises(SplitError, match="'n'.*negative"):
        Split("n", [-1], [2])
    with pytest.raises(SplitError, match="'f'.*integer"):
        Split("f", [0.5], [2])
    with pytest.raises(SplitError, match="name"):
        Split("", [1], [2])
    # same inputs, disjoint series: no overlap
    Split("series", [1, 2], [1, 2], [0], [1])
    with pytest.raises(SplitError, match="overlap"):
        Split("series", [1, 2], [1, 2], [0, 1], [1])
    with pytest.raises(SplitError, match="overlap"):
        Split("all series", [1, 2], [2, 3], None, [1])


def test_split_check_against_a_campaign():
    s = Split("tiny", [3], [4, 5])
    with pytest.raises(SplitError, match="'tiny'.*calibration set has 1 points x 1 sensor.*2 parameters"):
        s.check(10, 1, n_p=2, n_sensors=1)
    s.check(10, 2, n_p=2, n_sensors=1)                   # 2 series x 1 input = 2 values
    with pytest.raises(SplitError, match="'tiny'.*val_inputs index 5.*5 inputs"):
        s.check(5, 1)
    with pytest.raises(SplitError, match="cal_series index 3"):
        Split("ser", [1], [2], [3], [0]).check(5, 2)


def test_random_splits_are_seeded_disjoint_and_cover():
    a = random_splits(29, 5, seed=3, exclude=(0, 28))
    b = random_splits(29, 5, seed=3, exclude=(0, 28))
    c = random_splits(29, 5, seed=4, exclude=(0, 28))
    assert a == b and a != c
    for s in a:
        assert sorted(s.cal_inputs + s.val_inputs) == list(range(1, 28))
        assert abs(len(s.cal_inputs) - len(s.val_inputs)) <= 1
    with pytest.raises(SplitError, match="cal_fraction"):
        random_splits(29, 2, cal_fraction=1.0)


@settings(max_examples=40, deadline=None)
@given(n_q=st.integers(3, 40), frac=st.floats(0.05, 0.95), seed=st.integers(0, 2 ** 31))
def test_random_splits_property(n_q, frac, seed):
    for s in random_splits(n_q, 3, cal_fraction=frac, seed=seed):
        assert set(s.cal_inputs).isdisjoint(s.val_inputs)
        assert sorted(s.cal_inputs + s.val_inputs) == list(range(n_q))
        assert len(s.cal_inputs) >= 1 and len(s.val_inputs) >= 1


def test_input_range_split_by_magnitude():
    q = np.array(Q_PAPER)
    s = input_range_split(q, exclude=(0, 28))
    thr = np.median(np.abs(q[1:28]))
    assert all(abs(q[j]) <= thr for j in s.cal_inputs)
    assert all(abs(q[j]) > thr for j in s.val_inputs)
    assert sorted(s.cal_inputs + s.val_inputs) == list(range(1, 28))
    s2 = input_range_split(q, threshold=800.0)
    assert max(q[list(s2.cal_inputs)]) <= 800.0 < min(q[list(s2.val_inputs)])
    with pytest.raises(SplitError, match="empty"):
        input_range_split(q, threshold=5000.0)
    with pytest.raises(SplitError, match="column"):
        input_range_split(q, column=2)


def test_series_split_and_labels():
    s = series_split(29, [0, 1], [2])
    assert s.cal_inputs == s.val_inputs == tuple(range(29))
    cal, val = splits_from_scenarios(PRESS_SCENARIOS, 29)[0].label()
    assert cal == "q2,q4..q14" and val == "q3,q5..q15"
    assert s.swapped().cal_series == (2,)


def test_pooled_data_is_the_union_of_both_sets_with_the_rest_missing():
    z = np.arange(3 * 4 * 2, dtype=float).reshape(3, 4, 2)          # 3 series, 4 inputs, 2 sensors
    data = Measurements(np.arange(4.0), z, [1.0, 1.0])
    sp = Split("mixed", cal_inputs=[0, 1], val_inputs=[1, 3], cal_series=[0], val_series=[2])
    pooled = sp.pooled(data)
    assert pooled.n_q == 3 and pooled.n_M == 2                      # inputs 0, 1, 3; series 0, 2
    np.testing.assert_array_equal(pooled.inputs.ravel(), [0.0, 1.0, 3.0])
    np.testing.assert_array_equal(pooled.z[0, :2], z[0, :2])        # calibration: series 0, inputs 0, 1
    np.testing.assert_array_equal(pooled.z[1, 1:], z[2, [1, 3]])    # validation: series 2, inputs 1, 3
    assert np.all(np.isnan(pooled.z[0, 2])) and np.all(np.isnan(pooled.z[1, 0]))
    n_points = sum(len(s.calibration(data).z[:, :, 0].ravel()) for s in (sp,)) + sp.validation(data).z[:, :, 0].size
    assert int(pooled.mask()[:, :, 0].sum()) == n_points
