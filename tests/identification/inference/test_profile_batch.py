"""lr_region with the rows of its grid solved as batches of constrained fits (issue 15)."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from identification import Measurements, identify
from identification.studies.montecarlo import ModelCampaign
from identification.inference.likelihood_region import BATCHED_ROWS, PER_POINT, grid_solver
from identification.inference.profile import lr_region
from models import Model
from models.library import spring_chain


def _rise_and_slope():
    model = Model.explicit(params=["a", "b", "c"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])) + p[2] * q[0], name="rise and slope")
    x = np.linspace(0.5, 10.0, 12)
    z = (3 * (1 - np.exp(-0.4 * x)) + 0.1 * x)[None, :, None] + 0.05 * np.random.default_rng(1).standard_normal((2, 12, 1))
    data = Measurements(x, z, [0.05])
    return model, data, identify(model, data, [2.0, 0.5, 0.0])


def _spring():
    model = spring_chain(n_y=4, n_sensors=2, n_groups=2)
    p_true = np.array([2.0, 3.0, 0.05])
    gen = ModelCampaign(model, p_true, np.column_stack([np.linspace(0.5, 3.0, 10), np.linspace(1.0, -1.0, 10)]), 0.01, 2)
    data = gen(np.random.default_rng(5))
    return model, data, identify(model, data, p_true)


@pytest.mark.parametrize("grid", ["valley", "axes"])
@pytest.mark.parametrize("problem", [_rise_and_slope, _spring])
def test_batched_rows_give_the_region_of_the_per_point_solver(problem, grid):
    """Explicit and implicit 3-parameter models: the statistic on a 7 x 7 grid with the rows batched equals
    that of the per-point solver to 1e-8 (relative, 1e-8 absolute near D = 0), the same points solved."""
    model, data, est = problem()
    per = lr_region(model, data, est, (0, 1), n_grid=7, grid=grid, solver=PER_POINT)
    bat = lr_region(model, data, est, (0, 1), n_grid=7, grid=grid, solver=BATCHED_ROWS)
    np.testing.assert_array_equal(bat.X, per.X)
    np.testing.assert_array_equal(bat.Y, per.Y)
    np.testing.assert_array_equal(np.isfinite(bat.statistic), np.isfinite(per.statistic))
    assert np.isfinite(per.statistic).sum() >= 40
    np.testing.assert_allclose(bat.statistic, per.statistic, rtol=1e-8, atol=1e-8)
    assert not any("point by point" in note for note in bat.notes)     # every batched point converged


def test_a_row_the_batch_cannot_solve_falls_back_point_by_point():
    """A bound on c that cuts through the grid: the batch leaves the points whose optimum lies on the bound
    (fit_batch(fallback=False)); they are solved point by point (noted) and agree with the per-point path."""
    model, data, est = _rise_and_slope()
    c_hat = float(est.p[2])
    bounded = model.with_bounds({"c": (c_hat - 0.2 * abs(c_hat) - 1e-3, 10.0)})
    est_b = identify(bounded, data, est.p)
    per = lr_region(bounded, data, est_b, (0, 1), n_grid=7, grid="axes", span=3.0, solver=PER_POINT)
    bat = lr_region(bounded, data, est_b, (0, 1), n_grid=7, grid="axes", span=3.0, solver=BATCHED_ROWS)
    assert any("point by point" in note for note in bat.notes)
    np.testing.assert_array_equal(np.isfinite(bat.statistic), np.isfinite(per.statistic))
    np.testing.assert_allclose(bat.statistic, per.statistic, rtol=1e-8, atol=1e-8)


def test_a_two_parameter_model_takes_the_per_point_path():
    """With the pair fixed nothing is left to fit: batch=True solves every point per point, as batch=False."""
    model = Model.explicit(params=["a", "b"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])))
    x = np.linspace(0.5, 10.0, 12)
    z = (3 * (1 - np.exp(-0.4 * x)))[None, :, None] + 0.05 * np.random.default_rng(2).standard_normal((1, 12, 1))
    data = Measurements(x, z, [0.05])
    est = identify(model, data, [2.0, 0.5])
    bat = lr_region(model, data, est, (0, 1), n_grid=5, grid="axes", solver=BATCHED_ROWS)
    per = lr_region(model, data, est, (0, 1), n_grid=5, grid="axes", solver=PER_POINT)
    assert np.all(np.isfinite(bat.statistic))
    np.testing.assert_array_equal(bat.statistic, per.statistic)


def test_grid_strategy_is_chosen_once():
    """lr_region(solver=...) takes a GridSolver; a pair model has no free parameter to batch; the old
    batch=True/False still works, with a DeprecationWarning naming the replacement."""
    assert grid_solver(BATCHED_ROWS, 3) is BATCHED_ROWS and grid_solver(PER_POINT, 3) is PER_POINT
    assert grid_solver(BATCHED_ROWS, 2) is PER_POINT and grid_solver(PER_POINT, 5) is PER_POINT
    with pytest.raises(TypeError, match="solver: expected a GridSolver"):
        grid_solver(True, 3)
    with pytest.raises(TypeError, match="batch: expected True or False"):
        grid_solver(BATCHED_ROWS, 3, batch="yes")
    with pytest.warns(DeprecationWarning, match="solver=PER_POINT"):
        assert grid_solver(BATCHED_ROWS, 3, batch=False) is PER_POINT
    model, data, est = _rise_and_slope()
    a = lr_region(model, data, est, (0, 1), n_grid=5, grid="axes", solver=PER_POINT)
    with pytest.warns(DeprecationWarning, match="lr_region\\(batch=...\\) is deprecated"):
        b = lr_region(model, data, est, (0, 1), n_grid=5, grid="axes", batch=False)
    np.testing.assert_array_equal(a.statistic, b.statistic)
