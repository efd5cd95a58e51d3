"""identification.model_error on a small dynamic model (issue 29): the same path as a static model, through the
Problem (a discrepancy per instrument over inputs and time, time-window splits, predictions experiments x times x
sensors) and the bad-input cases of time series.

Mechanics only, on a toy with a known missing term; the calibration (coverage on the oscillator's time windows,
the rate of no error found on an adequate model) is a Monte Carlo claim in bench/bench_model_error.py.
"""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from identification import Split, model_error
from identification.fit.dynamic_data import DynamicMeasurements
from identification.fit.dynamic_fit import simulate_campaign
from identification.fit.problem import Problem
from identification.studies.splits import SplitError, time_window_splits
from models.contract import Model, Parameter

TIMES = np.round(np.linspace(0.2, 3.0, 12), 10)
STEPS = np.array([[1.0], [2.0], [3.0]])
SIGMA = np.array([0.01, 0.02])


def _model(missing: bool) -> Model:
    """dx/dt = u - k x (- q x^2 in the truth): the model without q misses a known term; sensors x and 2 x."""
    params = [Parameter("k", 0.01, 100.0, scale=1.0)] + ([] if missing else [Parameter("q", -10.0, 10.0, scale=1.0)])

    def rhs(x, p, u):
        return ca.vertcat(u[0] - p[0] * x[0] - (0.0 if missing else p[1] * x[0] ** 2))
    return Model.ode(params, states=["x"], inputs=["u"], sensors=["y", "w"], rhs=rhs,
                     x0=lambda p, u: ca.vertcat(0.0), h=lambda x, p, u: ca.vertcat(x[0], 2 * x[0]),
                     name="decay missing q" if missing else "decay", time_unit="s")


def _data(n_series: int = 2, seed: int = 4, sigma=SIGMA) -> DynamicMeasurements:
    d = simulate_campaign(_model(False), [1.0, 0.3], STEPS, TIMES, SIGMA, n_series=n_series, seed=seed)
    return d if sigma is not None else d.with_sigma(None)


@pytest.fixture(scope="module")
def wrong():
    return model_error(_model(True), _data(), [1.0], splits=time_window_splits([1.5]))


def test_the_missing_term_is_found_as_a_discrepancy_over_time(wrong):
    assert wrong.detected and wrong.kind == "discrepancy"
    assert [d.sensor for d in wrong.discrepancies] == ["y", "w"]        # one process per instrument, not per time
    assert len(wrong.discrepancies[0].length_scales) == 2                # over the input u and the time t
    h = wrong.heldout[0]
    assert h.coverage_discrepancy > h.coverage_plain + 0.2 and h.coverage_discrepancy >= 0.85


def test_predict_is_experiments_by_times_by_sensors(wrong):
    band = wrong.predict([[1.5], [2.5]], new_reading=True)
    assert band.mean.shape == band.lower.shape == band.upper.shape == (2, TIMES.size, 2)
    np.testing.assert_array_equal(band.grid[0], TIMES)
    assert band.sensors == ("y", "w")
    assert np.all(band.lower < band.mean) and np.all(band.mean < band.upper)
    plain = model_error(_model(True), _data(), [1.0], kind="none").predict([[1.5], [2.5]], new_reading=True)
    assert np.all(band.upper - band.lower > plain.upper - plain.lower)   # the model error widens the band


def test_exact_at_time_zero_pins_the_discrepancy():
    r = model_error(_model(True), _data(), [1.0], kind="discrepancy", exact_at={"t": 0.0})
    assert r.exact_at == {"t": 0.0}
    early = r.discrepancy([[2.0]])                                       # grid: the sampling times
    late = np.abs(early.upper - early.lower)[0, -1]
    assert np.all(np.abs(early.upper - early.lower)[0, 0] < late)        # narrower near t = 0 than at the end


def test_the_adequate_model_gives_its_own_fit_without_error():
    r = model_error(_model(False), _data(), [1.0, 0.3], kind="none")
    assert r.kind == "none" and r.sensors == ("y", "w")
    np.testing.assert_allclose(r.p, [1.0, 0.3], atol=0.05)


def test_sigma_from_repeated_series_is_one_per_instrument():
    r = model_error(_model(False), _data(n_series=3, sigma=None), [1.0, 0.3], kind="none")
    assert r.sigma_source.startswith("pure error")
    lay = Problem(_model(False), _data()).columns()
    for g in range(2):
        s = r.sigma[lay.instrument == g]
        assert np.all(s == s[0]) and 0.5 * SIGMA[g] < s[0] < 1.5 * SIGMA[g]


def test_column_layout_arranges_pairs_as_times_by_instruments():
    lay = Problem(_model(True), _data()).columns()
    assert lay.coord_names == ("t",) and lay.names == ("y", "w") and len(lay.instrument) == 2 * TIMES.size
    a = np.arange(2 * TIMES.size, dtype=float)[None]
    out = lay.arrange(a)
    assert out.shape == (1, TIMES.size, 2)
    t_index = np.searchsorted(TIMES, lay.coords[:, 0])
    np.testing.assert_array_equal(out[0, t_index, lay.instrument], a[0])


def test_bad_input_of_time_series():
    m, d = _model(True), _data()
    with pytest.raises(ValueError, match="exact_at: unknown input 'time'"):
        model_error(m, d, [1.0], exact_at={"time": 0.0})
    with pytest.raises(SplitError, match="holds no sampling time"):
        model_error(m, d, [1.0], splits=Split("late", None, None, cal_window=(0.0, 1.0), val_window=(5.0, 6.0)))
    with pytest.raises(ValueError, match="weights: expected 2 sensor weights"):
        model_error(m, d, [1.0], weights=np.ones(2 * TIMES.size))
    with pytest.raises(ValueError, match="sigma is None"):
        model_error(m, _data(n_series=1, sigma=None), [1.0])
    with pytest.raises(SplitError, match="model_error needs at least"):
        model_error(m, d, [1.0], splits=Split("first sample", [0], [1], cal_window=(0.0, 0.25), val_window=(0.25, 9.0)))
