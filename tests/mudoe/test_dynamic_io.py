"""mudoe.kind.long_csv: the long-format CSV of time-series campaigns."""
import numpy as np
import pytest

from identification import DynamicMeasurements
from mudoe.data_io import DataFileError
from mudoe.kind.long_csv import read_long_csv, write_long_csv

Q = np.array([[1.0, 330.0], [2.0, 350.0]])


def test_round_trip_ragged_with_missing(tmp_path):
    times = [np.array([0.2, 0.4, 0.8]), np.array([0.1, 0.4])]
    z = np.full((2, 2, 3, 2), np.nan)
    z[:, 0] = np.arange(12).reshape(2, 3, 2)
    z[:, 1, :2] = -np.arange(8).reshape(2, 2, 2)
    z[1, 0, 1, 0] = np.nan
    data = DynamicMeasurements(Q, times, z, [0.1, 0.2], sensors=["cA", "cB"])
    path = write_long_csv(tmp_path / "c.csv", data, units=["mol/L", "mol/L"])
    back = read_long_csv(path, Q, ["cA", "cB"], units=["mol/L", "mol/L"], sigma=[0.1, 0.2])
    assert np.array_equal(back.times, data.times, equal_nan=True)
    assert np.array_equal(back.z, data.z, equal_nan=True) and back.pairs == data.pairs


def test_unit_conversion_and_errors(tmp_path):
    p = tmp_path / "c.csv"
    p.write_text("experiment,time,sensor,value,unit\n1,0.5,cA,1000,mmol/L\n2,0.5,cA,2,mol/L\n")
    d = read_long_csv(p, Q, ["cA"], units=["mol/L"])
    assert np.allclose(d.z[0, :, 0, 0], [1.0, 2.0])
    for text, match in [("experiment,time,value\n", "missing column.*sensor"),
                        ("experiment,time,sensor,value\n3,0.5,cA,1\n", "line 2: experiment 3"),
                        ("experiment,time,sensor,value\n1,0.5,cX,1\n", "line 2: unknown sensor 'cX'"),
                        ("experiment,time,sensor,value\n1,x,cA,1\n", "line 2: column 'time'"),
                        ("experiment,time,sensor,value\n1,0.5,cA,1\n1,0.5,cA,2\n2,0.5,cA,1\n",
                         "line 3: .* already given on line 2"),
                        ("experiment,time,sensor,value\n1,0.5,cA,1\n", "experiment.s. 2 .* no reading")]:
        p.write_text(text)
        with pytest.raises(DataFileError, match=match):
            read_long_csv(p, Q, ["cA"])


def test_the_old_module_path_still_answers_with_a_warning():
    import mudoe.dynamic_io as old
    with pytest.warns(DeprecationWarning, match="use mudoe.kind.long_csv.read_long_csv"):
        assert old.read_long_csv is read_long_csv
