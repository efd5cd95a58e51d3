"""The ten-best design table (oed.best_designs) and the figures of the dynamic report pages."""
import itertools
from math import comb

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

from identification.studies.records import Trajectories
from oed.best_designs import best_designs
from oed.criteria import batch_criteria
from reports.dynamic_pages import residual_time_plot, trajectory_plot


def _info(n=12, p=3, seed=0):
    g = np.random.default_rng(seed).standard_normal((n, p))
    return np.einsum("ki,kj->kij", g, g)


def test_best_designs_are_the_best_of_every_combination():
    F = _info()
    names = [f"s{k}" for k in range(12)]
    t = best_designs(F, None, names, 3, "D", chosen=(0, 1, 2))
    W = np.array([[1.0 if k in c else 0.0 for k in range(12)] for c in itertools.combinations(range(12), 3)])
    every = np.sort(batch_criteria(F, None, W).logdet)
    assert [r.logdet for r in t.rows[:10]] == pytest.approx(list(every[:10]))
    assert "of all 220 designs of 3" in t.note and len(t.rows) <= 11
    assert ("s0", "s1", "s2") in {r.sensors for r in t.rows}            # the chosen design is always listed


def test_best_designs_of_many_candidates_rank_the_chosen_neighbourhood():
    """60 time-sensors choose 8: 2.6e9 designs are never enumerated (the crash of issue 22)."""
    F = _info(60, 4, 1)
    t = best_designs(F, None, [f"c{k}" for k in range(60)], 8, "A", chosen=tuple(range(8)), max_enumerate=1000)
    assert "its 416 neighbours" in t.note and f"{comb(60, 8):.3g}" in t.note    # 8 out x 52 in
    assert all(a.A <= b.A for a, b in zip(t.rows[:10], t.rows[1:10]))
    assert len(t.rows) == 11 and t.rows[-1].sensors == tuple(f"c{k}" for k in range(8))   # chosen, not among the best


_Traj = Trajectories(t=np.linspace(0, 1, 11), h=np.tile(np.linspace(0, 1, 11)[None, :, None], (2, 1, 2)),
                     half_mean=np.full((2, 11, 2), 0.01), half_new=np.full((2, 11, 2), 0.02), level=0.95,
                     quantile="normal", residuals=np.zeros((1, 2, 3, 2)))


class _Data:
    times = np.array([[0.2, 0.5, 0.9], [0.2, 0.5, 0.9]])
    z = np.zeros((1, 2, 3, 2))
    n_M, n_q = 1, 2


class _Model:
    sensors, sensor_units, time_unit = ("x", "a"), ("mm", "m/s^2"), "s"


def test_dynamic_figures_label_time_and_units_and_return_the_figure():
    fig = trajectory_plot(_Traj, _Data, _Model, 1, 0, chosen_times=(0.2, 0.9))
    ax = fig.axes[0]
    assert ax.get_xlabel() == "time (s)" and ax.get_ylabel() == "x (mm)"
    assert "chosen sampling times" in [t.get_label() for t in ax.lines]
    fig2 = residual_time_plot(_Traj, _Data, _Model, 1)
    assert fig2.axes[0].get_ylabel() == "(z - h) / sigma of a"


def test_design_rows_lists_every_combination_only_while_it_fits_a_page():
    """The static study's design table (run_oed): the paper's full table for few sensors, the ten best
    designs of the chosen size beyond (60 candidates never enumerate 2^60 combinations)."""
    from oed.best_designs import design_rows
    from oed.design import select_sensors_from_information
    F = _info(4, 2, 2)
    res = select_sensors_from_information(F, None, criterion="D", kind="gauss_newton", n_sensors=2)
    full = design_rows(F, None, ["a", "b", "c", "d"], 2, res, "D")
    assert not getattr(full, "ranked", False) and len(full.rows) == 11          # C(4,2)+C(4,3)+C(4,4)
    F = _info(60, 3, 3)
    res = select_sensors_from_information(F, None, criterion="D", kind="gauss_newton", n_sensors=3)
    top = design_rows(F, None, [f"s{k}" for k in range(60)], 1, res, "D")
    assert top.ranked and len(top.rows) == 10 and top.rows[0].sensors == tuple(res.sensors)
