"""Splits over sensors: time windows of a dynamic model's flat data (sensor@time columns)."""
import numpy as np
import pytest

from identification import DataError, Measurements
from identification.studies.splits import Split, SplitError, early_late_split, time_window_split

PAIRS = [(s, t) for t in (0.5, 1.0, 1.5, 2.0) for s in ("cA", "cB")]      # time-major flat columns


def campaign(n_M=2, n_q=3):
    z = np.arange(n_M * n_q * len(PAIRS), dtype=float).reshape(n_M, n_q, len(PAIRS))
    return Measurements(np.arange(n_q, dtype=float)[:, None], z, 0.1, sensors=[f"{s}@{t:g}" for s, t in PAIRS])


def test_early_late_split_masks_the_other_times_and_pools_exactly_the_union():
    data = campaign()
    sp = early_late_split(PAIRS, data.n_q)
    assert sp.cal_sensors == (0, 1, 2, 3) and sp.val_sensors == (4, 5, 6, 7)
    assert sp.name == "early t < 1.5 vs late t >= 1.5" and sp.label()[0] == "q1,q2,q3 [sensors s1,s2,s3,s4]"
    cal, val, pooled = sp.calibration(data), sp.validation(data), sp.pooled(data)
    np.testing.assert_array_equal(np.isfinite(cal.z), np.broadcast_to(np.arange(8) < 4, cal.z.shape))
    np.testing.assert_array_equal(np.isfinite(val.z), np.broadcast_to(np.arange(8) >= 4, val.z.shape))
    np.testing.assert_array_equal(cal.z[..., :4], data.z[..., :4])
    np.testing.assert_array_equal(pooled.z, data.z)          # the windows cover every time: all values
    assert cal.n_data() + val.n_data() == pooled.n_data() == data.z.size
    # the pooled key differs from that of a split pooling the same points with all sensors
    assert sp.pooled_key(2) != Split("x", [0], [1, 2]).pooled_key(2)
    sw = sp.swapped()
    assert (sw.cal_sensors, sw.val_sensors) == (sp.val_sensors, sp.cal_sensors)


def test_time_windows_leaving_times_out_pool_only_the_two_windows():
    data = campaign()
    sp = time_window_split(PAIRS, data.n_q, (0.5, 0.5), (2.0, 2.0), inputs=[0, 2], series=[1])
    assert sp.cal_sensors == (0, 1) and sp.val_sensors == (6, 7)
    pooled = sp.pooled(data)
    assert pooled.n_q == 2 and pooled.n_M == 1
    expect = np.full((1, 2, 8), np.nan)
    expect[..., [0, 1, 6, 7]] = data.z[np.ix_([1], [0, 2], [0, 1, 6, 7])]
    np.testing.assert_array_equal(pooled.z, expect)


def test_same_points_are_allowed_when_the_sensors_are_disjoint_but_not_when_they_overlap():
    Split("ok", [0, 1], [0, 1], cal_sensors=[0, 1], val_sensors=[2])
    with pytest.raises(SplitError, match="overlap.*sensors \\[1\\]"):
        Split("bad", [0, 1], [0, 1], cal_sensors=[0, 1], val_sensors=[1, 2])
    with pytest.raises(SplitError, match="overlap"):
        Split("bad", [0, 1], [0, 1], cal_sensors=[0, 1])          # validation: every sensor


def test_sensor_split_errors_name_the_argument():
    data = campaign()
    with pytest.raises(SplitError, match="cal_sensors index 9 is out of range.*8 sensors"):
        Split("x", [0], [0], cal_sensors=[9], val_sensors=[0]).calibration(data)
    with pytest.raises(SplitError, match="cal_window: no sampling time lies in \\(3, 4\\)"):
        time_window_split(PAIRS, 3, (3, 4), (0, 1))
    with pytest.raises(SplitError, match="val_window: the window \\(2, 1\\) ends before it starts"):
        time_window_split(PAIRS, 3, (0, 1), (2, 1))
    with pytest.raises(SplitError, match="t_split: 2.5 leaves the late set empty"):
        early_late_split(PAIRS, 3, t_split=2.5)
    with pytest.raises(SplitError, match="t_split: 0.5 leaves the early set empty"):
        early_late_split(PAIRS, 3, t_split=0.5)              # early is t < t_split (half-open)
    with pytest.raises(SplitError, match="pairs: expected the \\(sensor, time\\) pairs"):
        early_late_split(["cA@0.5", "cB@0.5"], 3)
    # too few values: 1 input x 1 series x 2 columns = 2 values for 4 parameters
    with pytest.raises(SplitError, match="calibration set has 1 points x 2 sensor\\(s\\) = 2 values for 4"):
        time_window_split(PAIRS, 3, (0.5, 0.5), (2.0, 2.0), inputs=[0], series=[0]).check(3, 2, 4, 8)


def test_measurements_refuse_an_empty_sensor_unless_asked():
    z = np.ones((1, 2, 2))
    z[..., 1] = np.nan
    with pytest.raises(DataError, match="sensor 's2' \\(index 1\\) has no finite value"):
        Measurements([[0.0], [1.0]], z, 0.1)
    m = Measurements([[0.0], [1.0]], z, 0.1, allow_empty_sensors=True)
    assert m.n_data() == 2 and m.subset(inputs=[0]).allow_empty_sensors and m.with_sigma(0.2).allow_empty_sensors
    import pickle
    assert pickle.loads(pickle.dumps(m)).allow_empty_sensors
