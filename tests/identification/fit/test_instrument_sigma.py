"""One sigma per instrument (identification.fit.dynamic_data.instrument_sigma), the one place oed, mudoe and
the estimate over sensor@time readings turn their sigma into the (n_S,) array."""
import numpy as np
import pytest

from identification.fit.dynamic_data import instrument_sigma


def test_a_scalar_is_broadcast_and_a_list_is_kept():
    np.testing.assert_array_equal(instrument_sigma(["cA", "cB"], 0.2), [0.2, 0.2])
    np.testing.assert_array_equal(instrument_sigma(["cA", "cB"], [0.1, 0.3]), [0.1, 0.3])


def test_the_sigma_of_the_readings_is_that_of_each_instruments_first_reading():
    readings = ["cA@0.5", "cB@0.5", "cA@1", "cB@1"]
    got = instrument_sigma(["cB", "cA"], [0.1, 0.2, 0.1, 0.2], readings=readings)
    np.testing.assert_array_equal(got, [0.2, 0.1])
    with pytest.raises(ValueError, match="readings: no reading of instrument"):
        instrument_sigma(["cA", "T"], [0.1, 0.2, 0.1, 0.2], readings=readings)


def test_bad_values_name_sigma_and_missing_ones_are_nan_only_when_allowed():
    with pytest.raises(ValueError, match=r"sigma: expected 2 positive finite values \(one per instrument: cA, cB\)"):
        instrument_sigma(["cA", "cB"], [0.1, -1.0])
    with pytest.raises(ValueError, match="sigma: expected 2"):
        instrument_sigma(["cA", "cB"], [0.1, 0.2, 0.3])
    with pytest.raises(ValueError, match="sigma: expected 2"):
        instrument_sigma(["cA", "cB"], [0.1, np.nan])
    got = instrument_sigma(["cA", "cB"], [0.1, np.nan], missing=True)
    assert got[0] == 0.1 and np.isnan(got[1])
