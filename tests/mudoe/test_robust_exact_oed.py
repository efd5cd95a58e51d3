"""`mudoe oed` with [oed] prior and mode = "sensors" (approximate = false): the exact robust n-run design of a static
study's sensors (planned) and of a dynamic study's sampling times, its records and design page (issue 31 item 4).
With data (no longer refused): tests/mudoe/test_oed_product.py."""
import json
import re
from pathlib import Path

import numpy as np
import pytest

from cli_texts import PLANNED_PRESS, planned_design_pages
from mudoe.cli import main
from mudoe.config import ConfigError, parse_config

REPO = Path(__file__).resolve().parents[2]
PRIOR = 'prior = { k5 = ["uniform", 400.0, 700.0], k7 = ["lognormal", 470.0, 0.2] }\n'
SIGMA_MM = np.array([0.015, 0.005, 0.004])            # PLANNED_PRESS's sigma (um) in the model's mm


def _oed(tmp_path, capsys, path):
    code = main(["oed", str(path), "--out", str(tmp_path / "res"), "--json", "--quiet"])
    out = capsys.readouterr()
    assert code == 0, out.err
    return json.loads(out.out)


@pytest.mark.parametrize("robust", ["bayes", "maximin"])
def test_planned_press_sensors_over_a_prior_match_the_library(tmp_path, capsys, robust):
    from models.press import press_model
    from oed import information, make_prior
    from oed.robust_exact import exact_over_prior
    cfg = tmp_path / "plan.toml"
    cfg.write_text(PLANNED_PRESS + f'n_sensors = 2\nrobust = "{robust}"\n' + PRIOR)
    obj = _oed(tmp_path, capsys, cfg)
    m, p = press_model(), np.array([530.0, 470.0])
    Q = np.linspace(0.0, 1600.0, 9)[:, None]
    pr = make_prior({"k5": ("uniform", 400.0, 700.0), "k7": ("lognormal", 470.0, 0.2)}, m, p)
    ref = exact_over_prior(lambda ps: information(m, ps, inputs=Q, sigma=SIGMA_MM).F, pr, p, 2, criterion="D",
                           robust=robust, names=list(m.sensors))
    assert obj["mode"] == "sensors" and obj["approximate"] is False and obj["robust"] == robust
    assert obj["chosen"] == list(ref.design.names) and obj["proven_optimal"] and obj["status"] == "optimal"
    assert obj["value"] == pytest.approx(ref.design.value, rel=1e-12, abs=1e-12)
    assert len(obj["local_efficiencies"]) == pr.n == len(obj["prior_weights"])
    assert np.allclose(obj["local_efficiencies"], ref.local_efficiencies, rtol=1e-12)
    e, w = np.array(obj["local_efficiencies"]), np.array(obj["prior_weights"])
    if robust == "bayes":                     # D: the robust set is best in expected log det over the prior
        assert w @ np.log(e) <= 1e-12
    else:                                     # maximin: its worst case is at least the local design's
        assert obj["design"]["efficiency"] <= 1.0 + 1e-12
    text = (tmp_path / "res" / "oed.txt").read_text()
    assert "exact robust sensor design" in text and "efficiency of the local design" in text
    assert json.loads((tmp_path / "res" / "oed.json").read_text())["chosen"] == obj["chosen"]


def _reactor(tmp_path, extra):
    text = (REPO / "configs" / "reactor.toml").read_text()
    text = text.replace('directory = "../data/reactor"', f'directory = "{REPO / "data" / "reactor"}"')
    text, n = re.subn(r"^\[oed\]\n", "[oed]\n" + extra, text, flags=re.M)
    assert n == 1
    path = tmp_path / "reactor.toml"
    path.write_text(text)
    return path


def test_planned_reactor_sampling_times_over_a_prior(tmp_path, capsys):
    from mudoe.example_reactor import build
    from oed import information, make_prior
    from oed.robust_exact import select_robust_exact
    obj = _oed(tmp_path, capsys, _reactor(tmp_path, 'planned = true\nprior = { E1 = ["uniform", 45.0, 55.0] }\n'))
    assert obj["mode"] == "times" and obj["planned"] and obj["p"] == [1.5, 50.0, 1.0, 70.0]
    assert len(obj["chosen"]) == 4 and obj["proven_optimal"] and len(obj["prior_weights"]) == 5
    m = build()
    Q = np.array([[1.0, 330.0], [2.0, 340.0], [1.5, 350.0], [1.0, 360.0], [2.0, 370.0], [1.5, 345.0]])
    times = np.round(np.arange(0.2, 2.01, 0.2), 10)
    cfg = parse_config((tmp_path / "reactor.toml").read_text(), str(tmp_path / "reactor.toml"))
    sigma = np.array([s.sigma for s in cfg.sensors], float)
    pr = make_prior({"E1": ("uniform", 45.0, 55.0)}, m, np.array(obj["p"]))
    F = np.stack([information(m, ps, axis="times", times=times, inputs=Q, sigma=sigma).F for ps in pr.points], 1)
    ref = select_robust_exact(F, pr.weights, 4, names=[f"{t:g}" for t in times])
    assert obj["chosen"] == list(ref.names) and obj["value"] == pytest.approx(ref.value, rel=1e-9)


def test_the_design_page_of_an_exact_robust_plan(tmp_path):
    import matplotlib.pyplot as plt
    _, figs = planned_design_pages(PLANNED_PRESS + "n_sensors = 2\n" + PRIOR, tmp_path / "plan.toml")
    assert len(figs) == 1
    labels = [t.get_text() for ax in figs[0].axes for t in ax.get_xticklabels()]
    assert {"D_y", "F_x", "B0_y"} <= set(labels)
    assert any("efficiency" in ax.get_ylabel() for ax in figs[0].axes)
    assert any("proven optimal by complete enumeration" in t.get_text() for t in figs[0].texts)
    plt.close(figs[0])


# ---------------------------------------------------------------- mode = "inputs": the exact robust input rows
@pytest.mark.parametrize("robust", ["bayes", "maximin"])
def test_planned_press_input_rows_over_a_prior_match_the_library(tmp_path, capsys, robust):
    from models.press import press_model
    from oed.inputs import select_inputs
    cfg = tmp_path / "plan.toml"
    cfg.write_text(PLANNED_PRESS + f'mode = "inputs"\nn_points = 3\nrobust = "{robust}"\n' + PRIOR)
    obj = _oed(tmp_path, capsys, cfg)
    q = np.linspace(0.0, 1600.0, 9)
    ref = select_inputs(press_model(), [530.0, 470.0], candidates=q[:, None], sigma=SIGMA_MM, n_points=3,
                        criterion="D", prior={"k5": ("uniform", 400.0, 700.0), "k7": ("lognormal", 470.0, 0.2)},
                        robust=robust)
    assert obj["mode"] == "inputs" and obj["approximate"] is False and obj["robust"] == robust
    assert obj["candidates"] == [f"{v:g}" for v in q] and obj["indices"] == list(ref.indices)
    assert obj["chosen"] == [f"{q[i]:g}" for i in ref.indices] and obj["proven_optimal"]
    assert obj["value"] == pytest.approx(ref.value, rel=1e-12, abs=1e-12)
    assert obj["local"]["indices"] == list(ref.local_indices)
    assert np.allclose(obj["local_efficiencies"], ref.local_efficiencies, rtol=1e-12)
    text = (tmp_path / "res" / "oed.txt").read_text()
    assert "exact robust input design" in text and "efficiency of the local design" in text
    assert json.loads((tmp_path / "res" / "oed.json").read_text())["chosen"] == obj["chosen"]


def test_more_exact_robust_input_rows_than_candidates_is_refused_naming_the_key(tmp_path, capsys):
    from cli_texts import one_line_error
    cfg = tmp_path / "plan.toml"
    cfg.write_text(PLANNED_PRESS + 'mode = "inputs"\nn_points = 12\n' + PRIOR)
    one_line_error(capsys, ["oed", str(cfg), "--out", str(tmp_path / "res"), "--quiet"], "plan.toml:", "[oed] n_points", "n_points <= 9")


def test_the_design_page_of_an_exact_robust_input_plan(tmp_path):
    import matplotlib.pyplot as plt
    _, figs = planned_design_pages(PLANNED_PRESS + 'mode = "inputs"\nn_points = 3\n' + PRIOR, tmp_path / "plan.toml")
    assert len(figs) == 1 and "Exact robust input design" in figs[0].texts[0].get_text()
    assert any(ax.get_xlabel().startswith("set point") for ax in figs[0].axes)
    assert any("efficiency" in ax.get_ylabel() for ax in figs[0].axes)
    assert any("proven optimal" in t.get_text() for t in figs[0].texts)
    figs[0].savefig(tmp_path / "page.pdf")
    plt.close(figs[0])
