"""Designs before data (issue 13): no measurements, fewer sensors than parameters."""
import itertools

import numpy as np
import pytest

from identification import Measurements, identify, information_contributions
from identification.errors import DataError
from models.friction import candidate_models, memory_inputs
from models.prototype import read_campaign
from oed import select_sensors, select_sensors_from_information
from oed.criteria import Criterion, batch_criteria


SIGMA_MM = np.array([15.18e-3, 4.895e-3, 3.904e-3])   # the paper's sensor sigmas, mm


def low_rank(rng, n, p, r=2):
    """n random PSD matrices of rank r."""
    a = rng.standard_normal((n, r, p))
    return np.einsum("kri,krj->kij", a, a)


def second_order_terms(rng, F, scale=0.1):
    """Symmetric indefinite S_k of a tenth of ||F_k||."""
    B = rng.standard_normal(F.shape)
    B = B + B.transpose(0, 2, 1)
    return scale * B * (np.linalg.norm(F, axis=(1, 2)) / np.linalg.norm(B, axis=(1, 2)))[:, None, None]


@pytest.fixture(scope="module")
def press_m3():
    """M3, the shipped campaign (6 series x 29 loads) and the M3 estimate on it."""
    campaign = read_campaign()
    model = candidate_models()["M3"]
    data = Measurements(memory_inputs(campaign.q_set), campaign.z, SIGMA_MM, sensors=model.sensors)
    est = identify(model, data, [500.0, 500.0])
    return model, data, est.p


@pytest.mark.parametrize("criterion", ["A", "D", "E"])
@pytest.mark.parametrize("n_sensors", [1, 2])
def test_press_design_without_data_equals_the_design_from_the_shipped_data(press_m3, criterion, n_sensors):
    model, data, p = press_m3
    with_data = select_sensors(model, data, p, criterion=criterion, kind="gauss_newton", n_sensors=n_sensors)
    planned = select_sensors(model, None, p, inputs=data.inputs, sigma=SIGMA_MM, n_series=data.n_M,
                             criterion=criterion, kind="gauss_newton", n_sensors=n_sensors)
    assert planned.sensors == with_data.sensors and planned.proven_optimal and with_data.proven_optimal
    assert planned.value == pytest.approx(with_data.value, rel=1e-9)
    assert any("without data" in n for n in planned.notes)


def test_planned_information_is_the_gauss_newton_information_of_the_data(press_m3):
    model, data, p = press_m3
    F, S = information_contributions(model, data, p)
    F0, S0 = information_contributions(model, None, p, inputs=data.inputs, sigma=SIGMA_MM, n_series=data.n_M)
    np.testing.assert_allclose(F0, F, rtol=1e-9)
    assert np.all(S0 == 0) and np.abs(S).max() > 0        # with data S comes from the residuals


def test_second_order_without_data_is_gauss_newton_and_can_differ_from_the_data_design(press_m3):
    """Documented: without data S = 0, so kind='second_order' plans the Gauss-Newton design; with the
    shipped data the residuals' S changes the one-sensor E design (B0_y instead of F_x)."""
    model, data, p = press_m3
    kw = dict(criterion="E", n_sensors=1)
    planned_so = select_sensors(model, None, p, inputs=data.inputs, sigma=SIGMA_MM, n_series=data.n_M,
                                kind="second_order", **kw)
    planned_gn = select_sensors(model, None, p, inputs=data.inputs, sigma=SIGMA_MM, n_series=data.n_M,
                                kind="gauss_newton", **kw)
    data_so = select_sensors(model, data, p, kind="second_order", **kw)
    assert planned_so.sensors == planned_gn.sensors == ("F_x",)
    assert planned_so.value == pytest.approx(planned_gn.value, rel=1e-9)   # H^-1 F H^-1 vs F^-1 rounding
    assert data_so.sensors == ("B0_y",)


@pytest.mark.parametrize("kw, match", [
    (dict(inputs=None, sigma=SIGMA_MM), "data: None needs inputs"),
    (dict(inputs=np.zeros((3, 4)), sigma=None), "data: None needs inputs"),
    (dict(inputs=np.full((3, 4), np.nan), sigma=SIGMA_MM), "inputs: expected a finite array"),
    (dict(inputs=np.zeros((3, 4)), sigma=[1.0, -1.0, 1.0]), "sigma: expected 3 positive"),
    (dict(inputs=np.zeros((3, 4)), sigma=SIGMA_MM, n_series=0), "n_series: expected an integer"),
])
def test_planned_information_bad_input(press_m3, kw, match):
    model, _, p = press_m3
    with pytest.raises(DataError, match=match):
        information_contributions(model, None, p, **kw)


def test_select_sensors_rejects_inputs_next_to_data(press_m3):
    model, data, p = press_m3
    with pytest.raises(ValueError, match="inputs/sigma: give them only with data=None"):
        select_sensors(model, data, p, inputs=data.inputs, n_sensors=1)


# ---------------------------------------------------------------------------- fewer sensors than parameters
def _brute(F, S, kind, crit, sizes, exclude=()):
    best, arg = np.inf, None
    n = F.shape[0]
    for m in sizes:
        for c in itertools.combinations([k for k in range(n) if k not in exclude], m):
            w = np.zeros((1, n), bool)
            w[0, list(c)] = True
            v = float(batch_criteria(F, S, w, kind).value(Criterion.parse(crit))[0])
            if v < best:
                best, arg = v, c
    return best, arg


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("criterion", ["A", "D", "E"])
def test_fewer_sensors_than_parameters_match_brute_force(seed, criterion):
    """Rank-2 sensors, 3 parameters: one sensor is singular, every pair may be regular."""
    rng = np.random.default_rng(seed)
    n, p = 9, 3
    F = low_rank(rng, n, p, r=2)
    S = second_order_terms(rng, F)
    for kind, SS in (("gauss_newton", None), ("second_order", S)):
        best, arg = _brute(F, SS, kind, criterion, [2])
        res = select_sensors_from_information(F, S, criterion=criterion, kind=kind, n_sensors=2)
        assert res.proven_optimal and res.indices == arg
        assert res.value == pytest.approx(best, rel=1e-9, abs=1e-12)
        best, arg = _brute(F, SS, kind, criterion, [1, 2])
        res = select_sensors_from_information(F, S, criterion=criterion, kind=kind, max_sensors=2,
                                              method="enumerate")
        assert res.proven_optimal and res.value == pytest.approx(best, rel=1e-9, abs=1e-12)
    res = select_sensors_from_information(F, None, criterion=criterion, n_sensors=2, method="bnb")
    best, arg = _brute(F, None, "gauss_newton", criterion, [2])
    assert res.proven_optimal and res.indices == arg


def test_one_sensor_design_is_chosen_when_its_information_is_regular():
    rng = np.random.default_rng(3)
    F = np.concatenate([low_rank(rng, 1, 3, r=3), low_rank(rng, 5, 3, r=1)])    # sensor 0 alone is regular
    res = select_sensors_from_information(F, criterion="D", n_sensors=1)
    assert res.proven_optimal and res.indices == (0,)
    res = select_sensors_from_information(F, criterion="D", n_sensors=1, exclude=[0])
    assert res.status == "infeasible" and res.value == np.inf     # every remaining single sensor is singular


@pytest.mark.parametrize("kw, match", [
    (dict(n_sensors=0), "n_sensors: must be at least 1"),
    (dict(max_sensors=0), "max_sensors: must be at least 1"),
    (dict(exclude=list(range(5))), "exclude: every candidate is excluded"),
])
def test_size_arguments_bad_input(kw, match):
    F = low_rank(np.random.default_rng(0), 5, 3)
    with pytest.raises(ValueError, match=match):
        select_sensors_from_information(F, **kw)
