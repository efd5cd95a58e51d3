"""Report pages of control-driven experiments (issue 30 item 8): short titles, u(t) beside the trajectories,
repeated series apart, every parameter pair on one grid, residuals against the outputs, the truth of
simulated data, a progress bar over the pages written -- on small synthetic records and the motor model."""
import json
import shutil
from pathlib import Path

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402

from identification.studies.records import Trajectories  # noqa: E402
from mudoe.example_motor import build  # noqa: E402
from reports.dynamic_pages import control_plot, inputs_summary, residual_output_plot, series_style  # noqa: E402
from reports.region_figures import split_pair_grid  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
ROW = np.r_[0.02, [12.0, 12.0, 12.0, 6.0, 6.0, 3.0, 3.0, 0.0, 0.0, -6.0]]      # TL, then u at the 10 grid points


@pytest.fixture(scope="module")
def motor():
    return build("coulomb")


def test_title_summarises_the_inputs_instead_of_listing_them(motor):
    text = inputs_summary(motor, ROW)
    assert text == "TL = 0.02 N m, u: -6 .. 12 V on 10 steps"
    assert inputs_summary(motor, np.r_[0.0, np.full(10, 3.0)]) == "TL = 0 N m, u = 3 V"


def test_control_profile_is_drawn_as_steps_over_its_grid_with_the_constants(motor):
    fig = control_plot(motor, ROW, 0.5)
    ax = fig.axes[0]
    line = ax.lines[0]
    assert line.get_drawstyle() == "steps-post"
    assert list(line.get_xdata()) == pytest.approx(list(np.arange(10) * 0.05) + [0.5])
    assert list(line.get_ydata()) == pytest.approx(list(ROW[1:]) + [ROW[-1]])
    assert ax.get_ylabel() == "u (V)" and [t.get_text() for t in ax.texts] == ["TL = 0.02 N m"]
    plt.close(fig)


def test_repeated_series_differ_in_marker_and_colour_and_sit_side_by_side():
    styles = [series_style(i, 3, 0.5) for i in range(3)]
    assert len({s[0] for s in styles}) == 3 and len({s[1] for s in styles}) == 3
    assert [s[2] for s in styles] == pytest.approx([-0.002, 0.0, 0.002])
    assert series_style(0, 1, 0.5)[2] == 0.0


class _Test:
    """A split test as split_pair_grid reads it (identification.studies.detect.SplitTest's fields)."""

    def __init__(self, name, shift, alpha, n=6):
        self.split, self.model, self.ok, self.stage = name, "m", True, ""
        self.p_cal = np.arange(1.0, n + 1)
        self.p_val = self.p_cal + shift
        self.C_cal = np.diag(np.full(n, 0.01))
        self.C_val = np.diag(np.full(n, 0.02))
        self._a = alpha

    def alpha(self, statistic):
        return self._a


def test_every_pair_of_six_parameters_fits_one_grid_with_the_truth_marked():
    fig = plt.figure(figsize=(11.69, 8.27))
    axes = split_pair_grid(fig, [_Test("a", 0.05, 0.3), _Test("b", 0.5, 1e-6)], 0.975, list("ABCDEF"),
                           ["m", "", "", "", "", "s"], statistic="likelihood_ratio",
                           second_statistic="two_sample", truth=np.arange(1.0, 7.0))
    assert len(axes) == 15                                          # 6 parameters: 15 pairs on one page
    stars = [ln for ax in axes for ln in ax.lines if ln.get_marker() == "*"]
    assert len(stars) == 15 and stars[0].get_xdata()[0] == 1.0
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert legend[0] == "a: LR 30 %, 2-sample 30 %" and legend[1].endswith("REJECTED")
    assert "truth (simulated data)" in legend
    labelled = [ax for ax in axes if ax.get_xlabel()]
    assert [ax.get_xlabel() for ax in labelled] == ["A (m)", "B", "C", "D", "E"]      # the bottom row only
    plt.close(fig)
    with pytest.raises(ValueError, match="tests: at most 5 splits"):
        split_pair_grid(plt.figure(), [_Test(str(k), 0.1, 0.5) for k in range(6)], 0.9, list("ABC"))


def test_residuals_against_an_output_use_the_fitted_values_at_the_readings(motor):
    t = np.linspace(0, 0.5, 6)
    fitted = np.arange(12.0).reshape(2, 2, 3)
    traj = Trajectories(t, np.zeros((2, 6, 3)), np.zeros((2, 6, 3)), np.zeros((2, 6, 3)), 0.95, "normal",
                        residuals=np.ones((2, 2, 2, 3)), fitted=fitted)

    class Data:
        times, n_M, n_q = np.array([[0.1, 0.2], [0.1, 0.2]]), 2, 2

    fig = residual_output_plot(traj, Data, motor, 0, 1)
    ax = fig.axes[0]
    pts = [ln for ln in ax.lines if ln.get_linestyle() == "None"]
    assert list(pts[0].get_xdata()) == [1.0, 4.0]                   # h_w of experiment 1 at its two readings
    assert ax.get_xlabel() == "w at the estimate (rad/s)" and ax.get_ylabel() == "(z - h) / sigma of i"
    plt.close(fig)


def test_truth_is_known_only_for_the_configs_own_simulation(tmp_path):
    from mudoe.config import parse_config
    from mudoe.kind.time_series import build_dynamic, simulation_truth
    from mudoe.study_models import build_models
    shutil.copytree(ROOT / "data" / "motor", tmp_path / "data" / "motor")
    (tmp_path / "configs").mkdir()
    text = (ROOT / "configs" / "motor.toml").read_text()
    cfg = parse_config(text, str(tmp_path / "configs" / "motor.toml"), tmp_path / "configs")
    models, p0s, _ = build_dynamic(cfg, {v: b.model for v, b in build_models(cfg).items()})
    truth = simulation_truth(cfg, models, p0s)
    assert truth.variant == "coulomb" and truth.values == dict(R=2.0, L=0.05, K=0.1, J=1e-3, b=1e-3, Tc=0.02)
    rec = tmp_path / "data" / "motor" / "simulate.json"
    told = json.loads(rec.read_text())
    told["truth"]["Tc"] = 0.03                                      # the data are another simulation
    rec.write_text(json.dumps(told))
    assert simulation_truth(cfg, models, p0s) is None
    rec.unlink()                                                    # real data beside a [simulate] section
    assert simulation_truth(cfg, models, p0s) is None


def test_progress_bar_counts_the_pages_written_not_the_page_makers(tmp_path, monkeypatch, motor):
    import io

    import reports.builder as b
    import reports.serialize as ser
    from identification.progress import Progress
    from tests.reports.record_stub import stub_record

    def pages(*args, **kw):
        return [("a", lambda: [plt.figure(), plt.figure(), plt.figure()]), ("b", plt.figure), ("c", lambda: [])]

    monkeypatch.setattr(b, "report_pages", pages)
    monkeypatch.setattr(ser, "results_dict", lambda results: {})
    stream = io.StringIO()
    paths = b.build_report(stub_record({"coulomb": motor}), tmp_path, progress=Progress(True, stream=stream))
    assert len([p for p in paths if p.suffix == ".png"]) == 4
    assert "4/4" in stream.getvalue().split("\r")[-1]           # the estimate grows as makers give several pages


@pytest.mark.parametrize("n_p", [3, 6, 7, 11])
def test_grids_of_many_parameters_cover_every_pair_with_at_most_six_a_grid(n_p):
    import itertools

    from reports.builder import pair_grid_sets as sets
    plan = sets(n_p)
    assert all(len(s) <= 6 for s in plan) and len(plan) == (1 if n_p <= 6 else {7: 3, 11: 6}[n_p])
    covered = {pair for s in plan for pair in itertools.combinations(sorted(s), 2)}
    assert covered == set(itertools.combinations(range(n_p), 2))


def test_a_grid_of_some_parameters_draws_their_pairs_only():
    fig = plt.figure(figsize=(11.69, 8.27))
    axes = split_pair_grid(fig, [_Test("a", 0.05, 0.3, n=9)], 0.975, list("ABCDEFGHI"), truth=np.arange(1.0, 10.0),
                           indices=(0, 1, 2, 6, 7, 8))
    assert len(axes) == 15 and [ax.get_xlabel() for ax in axes if ax.get_xlabel()] == list("ABCGH")
    star = [ln for ln in axes[-1].lines if ln.get_marker() == "*"][0]       # panel (I, H): truth 8, 9
    assert (star.get_xdata()[0], star.get_ydata()[0]) == (8.0, 9.0)
    plt.close(fig)
