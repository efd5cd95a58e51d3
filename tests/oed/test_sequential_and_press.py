"""Sequential design and the press OED table (issue 4)."""
import numpy as np
import pytest

from identification import Measurements, information_contributions, simulate
from models.press import press_model
from oed.design import design_table, select_sensors_from_information
from oed.sequential import sequential_design

SIGMA_MM = np.array([15.18e-3, 4.895e-3, 3.904e-3])   # the paper's sensor sigmas, mm


def _experiments(model, p_true, n_exp=2, seed=0):
    q = np.concatenate([np.linspace(0, 1600, 15), np.linspace(1600, 0, 15)[1:]])[:, None]
    H = simulate(model, p_true, q)
    rng = np.random.default_rng(seed)
    return [Measurements(q, H[None] + SIGMA_MM * rng.standard_normal((2,) + H.shape), SIGMA_MM,
                         sensors=model.sensors) for _ in range(n_exp)]


def test_press_oed_table_ranks_the_collinear_pair_last_and_picks_an_identifying_pair():
    model = press_model()
    data = _experiments(model, [530.0, 470.0], n_exp=1)[0]
    F, S = information_contributions(model, data, [500.0, 500.0])
    table = design_table(F, None, sensor_names=model.sensors, min_sensors=2)      # Gauss-Newton
    rows = {tuple(r.sensors): r for r in table.rows}
    assert set(rows) == {("D_y", "F_x"), ("D_y", "B0_y"), ("F_x", "B0_y"), ("D_y", "F_x", "B0_y")}
    # D_y and B0_y see nearly the same combination of k5 and k7 (forces through the fulcrum C):
    # only geometric nonlinearity separates them, so their E value is orders of magnitude worse
    pairs = {k: r.E for k, r in rows.items() if len(k) == 2}
    others = [v for k, v in pairs.items() if k != ("D_y", "B0_y")]
    assert pairs[("D_y", "B0_y")] > 1e3 * max(others)
    best = select_sensors_from_information(F, None, criterion="E", kind="gauss_newton", n_sensors=2,
                                           sensor_names=model.sensors)
    assert best.proven_optimal and tuple(best.sensors) == min(pairs, key=pairs.get) == ("D_y", "F_x")


def test_second_order_criterion_can_favour_the_collinear_pair_on_noisy_data():
    """A documented pitfall, not a feature: S from noisy residuals regularises H(w)."""
    model = press_model()
    data = _experiments(model, [530.0, 470.0], n_exp=1)[0]
    F, S = information_contributions(model, data, [500.0, 500.0])
    so = {tuple(r.sensors): r.E for r in design_table(F, S, sensor_names=model.sensors, min_sensors=2).rows}
    gn = {tuple(r.sensors): r.E for r in design_table(F, None, sensor_names=model.sensors, min_sensors=2).rows}
    assert so[("D_y", "B0_y")] < 1e-3 * gn[("D_y", "B0_y")]


def test_sequential_design_redesigns_at_identified_parameters():
    model = press_model()
    exps = _experiments(model, [560.0, 430.0], n_exp=2, seed=3)
    res = sequential_design(model, exps, p0=[500.0, 500.0], criterion="E", n_sensors=2)
    assert len(res.steps) == 2
    s1, s2 = res.steps
    np.testing.assert_allclose(s1.p_design, [500.0, 500.0])
    np.testing.assert_allclose(s2.p_design, s1.p)          # the second design uses the first estimate
    for s in res.steps:                                     # each design is the enumeration optimum there
        F, S = information_contributions(model, exps[0], s.p_design)   # both designs use experiment 1
        rows = design_table(F, None, sensor_names=model.sensors, min_sensors=2).rows   # Gauss-Newton, as designed
        pairs = {tuple(r.sensors): r.E for r in rows if len(r.sensors) == 2}
        assert tuple(s.design.sensors) == min(pairs, key=pairs.get)
        assert np.all(np.abs(s.p - [560.0, 430.0]) < 5 * s.stderr)
        assert s.ellipsoid_volume > 0
    assert "Sequential design" in res.summary() and "design" in res.summary()
    with pytest.raises(ValueError, match="data: give at least one experiment"):
        sequential_design(model, [], p0=[500.0, 500.0])
