"""[oed] prior / robust / approximate and `mudoe oed` with a prior (issue 31 item 6)."""
import json
import re

import numpy as np
import pytest

from cli_texts import PLANNED_PRESS, planned_design_pages
from mudoe.cli import main
from mudoe.config import parse_config
from mudoe.config_prior import DISTRIBUTION_ARGS

PLAN = PLANNED_PRESS

PRIOR = 'prior = { k5 = ["uniform", 400.0, 700.0], k7 = ["lognormal", 470.0, 0.2] }\n'
SIGMA_MM = np.array([0.015, 0.005, 0.004])            # the PLAN's sigma (um) in the model's mm


def _run(tmp_path, capsys, extra, name="plan.toml"):
    cfg = tmp_path / name
    cfg.write_text(PLAN + extra)
    code = main(["oed", str(cfg), "--out", str(tmp_path / "res"), "--json", "--quiet"])
    out = capsys.readouterr()
    return code, (json.loads(out.out) if code == 0 else None), out.err


def test_the_distributions_are_the_librarys():
    from oed.prior import DISTRIBUTIONS
    assert DISTRIBUTION_ARGS == DISTRIBUTIONS


@pytest.mark.parametrize("form", [
    'mode = "inputs"\nrobust = "maximin"\n' + PRIOR,
    'mode = "inputs"\nrobust = "maximin"\n[oed.prior]\nk5 = ["uniform", 400.0, 700.0]\nk7 = ["lognormal", 470.0, 0.2]\n',
])
def test_the_config_reads_prior_and_robust_in_either_form(form):
    cfg = parse_config(PLAN + form, "plan.toml")
    assert cfg.oed.prior == {"k5": ("uniform", 400.0, 700.0), "k7": ("lognormal", 470.0, 0.2)}
    assert cfg.oed.robust == "maximin" and not cfg.oed.approximate


def test_without_the_keys_the_defaults_are_local():
    o = parse_config(PLAN + 'mode = "inputs"\nn_points = 2\n', "plan.toml").oed
    assert o.prior == {} and o.robust == "" and o.approximate is False


@pytest.mark.parametrize("extra, key, match", [
    ('mode = "inputs"\nprior = { k5 = ["beta", 1.0, 2.0] }\n', "prior.k5", "unknown distribution 'beta'"),
    ('mode = "inputs"\nprior = { k9 = ["uniform", 1.0, 2.0] }\n', "prior.k9", "no parameter 'k9'"),
    ('mode = "inputs"\nprior = { k5 = ["uniform", 600.0, 700.0] }\n', "prior.k5", "exclude the nominal value 530"),
    ('mode = "inputs"\nprior = { k7 = ["normal", 470.0, nan] }\n', "prior.k7", "finite numbers"),
    ('mode = "inputs"\nprior = { k7 = ["normal", 470.0] }\n', "prior.k7", "takes 2 numbers"),
    ('mode = "inputs"\nn_points = 2\nrobust = "bayes"\n', "robust", "needs a prior"),
    ('mode = "inputs"\nrobust = "minimax"\n' + PRIOR, "robust", "unknown value 'minimax'"),
    ('mode = "both"\n' + PRIOR, "prior", 'a prior gives the exact robust choice of n_points (set point, sensor) '
                                          'pairs: give n_points'),
    ('mode = "both"\nn_points = 2\napproximate = true\n' + PRIOR, "approximate",
     'an approximate joint design of set points and sensors is not available: use mode = "inputs" with approximate'),
    ('mode = "sensors"\napproximate = true\n' + PRIOR, "prior", 'for mode = "inputs"'),
    ('mode = "sensors"\nexclude = ["F_x"]\n' + PRIOR, "exclude", "not used by the exact robust design"),
    ('mode = "inputs"\nexclude = ["F_x"]\n' + PRIOR, "exclude", "not used by an approximate design"),
])
def test_bad_robust_keys_exit_2_naming_key_and_line(tmp_path, capsys, extra, key, match):
    code, _, err = _run(tmp_path, capsys, extra)
    assert code == 2 and len(err.strip().splitlines()) == 1
    text = (PLAN + extra).splitlines()
    name = key.split(".")[-1]
    line = next(i + 1 for i, s in enumerate(text) if re.search(r"(^|[{,]\s*)" + name + r"\s*=", s))
    assert f"plan.toml:{line}: [oed] {key}: " in err and match in err
    assert not (tmp_path / "res" / "oed.json").exists()


def test_oed_with_a_prior_writes_the_robust_design(tmp_path, capsys):
    code, obj, err = _run(tmp_path, capsys, 'mode = "inputs"\n' + PRIOR)
    assert code == 0, err
    assert obj["approximate"] and obj["robust"] == "bayes" and obj["criterion"] == "D"
    d = obj["design"]
    assert d["n_parameter_vectors"] == 25 and abs(d["gap"]) < 1e-6 and d["efficiency_bound"] > 0.999
    assert np.isclose(sum(d["weights"]), 1.0) and all(0.0 <= x[0] <= 1600.0 for x in d["points"])
    assert obj["local"]["robust"] == "local" and len(obj["local_efficiencies"]) == 25
    assert np.isclose(sum(obj["prior_weights"]), 1.0)
    e, w = np.array(obj["local_efficiencies"]), np.array(obj["prior_weights"])
    assert np.all(e > 0) and w @ np.log(e) <= 1e-9       # D: the robust design is best in expected log det
    assert json.loads((tmp_path / "res" / "oed.json").read_text())["design"]["gap"] == d["gap"]
    assert "efficiency of the local design" in (tmp_path / "res" / "oed.txt").read_text()


def test_oed_maximin_matches_the_library(tmp_path, capsys):
    from models.press import press_model
    from oed.inputs import select_inputs
    code, obj, err = _run(tmp_path, capsys, 'mode = "inputs"\nrobust = "maximin"\n'
                          'prior = { k5 = ["uniform", 400.0, 700.0] }\n')
    assert code == 0, err
    ref = select_inputs(press_model(), [530.0, 470.0], candidates=np.linspace(0, 1600, 9)[:, None], sigma=SIGMA_MM,
                        criterion="D", approximate=True, prior={"k5": ("uniform", 400.0, 700.0)}, robust="maximin")
    d = obj["design"]
    assert d["robust"] == "maximin" and np.allclose(d["points"], ref.points) and np.allclose(d["weights"], ref.weights)
    assert d["worst_case_bound"] == pytest.approx(ref.worst_case_bound, rel=1e-9)


def test_approximate_without_a_prior_is_the_local_design(tmp_path, capsys):
    code, obj, err = _run(tmp_path, capsys, 'mode = "inputs"\napproximate = true\n')
    assert code == 0, err
    assert obj["robust"] == "local" and "local" not in obj and abs(obj["design"]["gap"]) < 1e-6
    assert obj["notes"] == []                       # planned (Gauss-Newton either way), no n_points


def test_an_unused_n_points_is_noted(tmp_path, capsys):
    code, obj, err = _run(tmp_path, capsys, 'mode = "inputs"\nn_points = 2\napproximate = true\n' + PRIOR)
    assert code == 0, err
    assert any("n_points = 2 not used" in n for n in obj["notes"])


def test_without_a_prior_the_output_is_the_local_route(tmp_path, capsys):
    from models.press import press_model
    from oed.inputs import select_inputs
    code, obj, err = _run(tmp_path, capsys, 'mode = "inputs"\nn_points = 2\n')
    assert code == 0, err
    ref = select_inputs(press_model(), [530.0, 470.0], candidates=np.linspace(0, 1600, 9)[:, None], sigma=SIGMA_MM,
                        n_points=2, criterion="D", kind="gauss_newton")
    assert "approximate" not in obj and "design" not in obj
    assert obj["indices"] == list(ref.indices) and obj["value"] == pytest.approx(ref.value, rel=1e-12)


def test_the_design_page_draws_the_certificate_and_the_efficiencies(tmp_path):
    import matplotlib.pyplot as plt
    plan, figs = planned_design_pages(PLAN + 'mode = "inputs"\n' + PRIOR, tmp_path / "plan.toml")
    assert len(figs) == 1
    axes = [ax for ax in figs[0].axes if ax.get_xlabel()]
    assert [ax.get_xlabel() for ax in axes][0] == "set point (N)"
    assert any("efficiency" in ax.get_ylabel() for ax in axes)
    sens = axes[0]
    assert any(abs(line.get_ydata()[0] - plan.design.reference) < 1e-12 for line in sens.get_lines()
               if len(set(np.atleast_1d(line.get_ydata()))) == 1)          # the line at the optimum value n_p
    plt.close(figs[0])


@pytest.mark.parametrize("old, new, extra, key, match", [
    ("candidates_range = [0.0, 1600.0, 9]", "candidates = [500.0]", 'mode = "inputs"\napproximate = true\n',
     "candidates", "(approximate = true) places its support points on the range [min, max] of the candidate set "
                   "points, but they span no range (every one is 500)"),
    ("candidates_range = [0.0, 1600.0, 9]", "candidates_range = [500.0, 500.0, 3]",
     'mode = "inputs"\napproximate = true\n', "candidates_range", "span no range (every one is 500)"),
    ("candidates_range = [0.0, 1600.0, 9]", "candidates = [500.0, 500.0]", 'mode = "inputs"\n' + PRIOR,
     "candidates", "(a prior without n_points) places its support points"),
])
def test_approximate_designs_without_a_range_exit_2_naming_key_and_line(tmp_path, capsys, old, new, extra, key,
                                                                         match):
    text = PLAN.replace(old, new) + extra
    cfg = tmp_path / "plan.toml"
    cfg.write_text(text)
    code = main(["oed", str(cfg), "--out", str(tmp_path / "res"), "--json", "--quiet"])
    err = capsys.readouterr().err
    line = next(i + 1 for i, s in enumerate(text.splitlines()) if s.startswith(key + " ="))
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert f"plan.toml:{line}: [oed] {key}: the approximate design " in err and match in err
    assert not (tmp_path / "res" / "oed.json").exists()


def test_exact_robust_inputs_need_no_range():
    o = parse_config(PLAN.replace("candidates_range = [0.0, 1600.0, 9]", "candidates = [500.0, 500.0]")
                     + 'mode = "inputs"\nn_points = 1\n' + PRIOR, "plan.toml").oed
    assert o.n_points == 1 and not o.approximate


def test_approximate_sampling_times_without_a_range_exit_2_naming_key_and_line(tmp_path, capsys):
    from pathlib import Path
    repo = Path(__file__).resolve().parents[2]
    text = (repo / "configs" / "reactor.toml").read_text()
    text = re.sub(r"^times = .*$", "times = [1.0]", text, count=1, flags=re.M)
    text = re.sub(r"^n_times = .*\n", "", text, count=1, flags=re.M)
    text = text.replace("[oed]\n", '[oed]\nplanned = true\napproximate = true\nprior = { E1 = ["uniform", 45.0, '
                                   '55.0] }\n')
    cfg = tmp_path / "reactor.toml"
    cfg.write_text(text)
    code = main(["oed", str(cfg), "--out", str(tmp_path / "res"), "--json", "--quiet"])
    err = capsys.readouterr().err
    line = next(i + 1 for i, s in enumerate(text.splitlines()) if s.startswith("times ="))
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert (f"reactor.toml:{line}: [dynamic] times: the approximate design (approximate = true) places its support "
            "points on the range [min, max] of the candidate sampling times, but they span no range (every one is 1)"
            in err)
