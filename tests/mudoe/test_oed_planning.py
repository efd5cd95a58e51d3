"""`mudoe oed` on a study without data, and the [oed] design keys (issue 13 item 6)."""
import json

import numpy as np
import pytest

from cli_texts import PLANNED_PRESS
from mudoe.cli import main

PLAN = PLANNED_PRESS


def _run(tmp_path, capsys, extra):
    cfg = tmp_path / "plan.toml"
    cfg.write_text(PLAN + extra)
    code = main(["oed", str(cfg), "--out", str(tmp_path / "res"), "--json", "--quiet"])
    out = capsys.readouterr()
    return code, (json.loads(out.out) if code == 0 else None), out.err


def test_planned_sensor_design_without_data_matches_the_library(tmp_path, capsys):
    from models.press import press_model
    from oed import select_sensors
    code, obj, err = _run(tmp_path, capsys, 'mode = "sensors"\nn_sensors = 1\nn_series = 4\n')
    assert code == 0, err
    q = np.linspace(0, 1600, 9)[:, None]
    from mudoe.units import convert
    sigma = convert(np.array([15.0, 5.0, 4.0]), "um", "mm", difference=True)    # the study's one unit conversion
    ref = select_sensors(press_model(), None, [530.0, 470.0], inputs=q, sigma=sigma,
                         n_series=4, criterion="D", kind="gauss_newton", n_sensors=1)
    assert obj["planned"] and obj["sensors"] == list(ref.sensors) and obj["proven_optimal"]
    assert obj["value"] == pytest.approx(ref.value, rel=1e-12)
    assert (tmp_path / "res" / "oed.json").is_file() and (tmp_path / "res" / "oed.txt").is_file()


@pytest.mark.parametrize("mode", ["inputs", "both"])
def test_planned_input_designs(tmp_path, capsys, mode):
    code, obj, err = _run(tmp_path, capsys, f'mode = "{mode}"\nn_points = 2\n')
    assert code == 0, err
    assert obj["proven_optimal"] and obj["mode"] == mode
    assert len(obj["pairs"]) == (2 if mode == "both" else 2 * 3)       # inputs: every sensor at 2 points
    assert all(0.0 <= s <= 1600.0 for s in obj["set_points"])


def test_costs_budget_and_max_sensors_reach_the_design(tmp_path, capsys):
    code, obj, err = _run(tmp_path, capsys, 'mode = "sensors"\nmax_sensors = 2\ncosts = [1.0, 5.0, 1.0]\n'
                                            'budget = 2.0\n')
    assert code == 0, err
    assert "F_x" not in obj["sensors"] and 1 <= len(obj["sensors"]) <= 2


@pytest.mark.parametrize("extra, match", [
    ('mode = "inputs"\n', "needs n_points"),
    ('candidates = [1.0, 2.0]\n', "candidates or candidates_range, not both"),
    ('budget = 3.0\n', "give both costs and budget"),
    ('mode = "everything"\n', "mode"),
])
def test_bad_oed_keys_exit_2(tmp_path, capsys, extra, match):
    code, _, err = _run(tmp_path, capsys, extra)
    assert code == 2 and match in err


def test_bad_candidates_range_exit_2(tmp_path, capsys):
    cfg = tmp_path / "plan.toml"
    cfg.write_text(PLAN.replace("candidates_range = [0.0, 1600.0, 9]", "candidates_range = [0.0, 1600.0, 2.5]"))
    assert main(["oed", str(cfg), "--out", str(tmp_path / "r"), "--quiet"]) == 2
    assert "candidates_range" in capsys.readouterr().err


RIVALS = 'mode = "discrimination"\nvariant = "M3"\nrival = "M2"\n'


def _run_rivals(tmp_path, capsys, extra, variants='["M2", "M3"]'):
    cfg = tmp_path / "rivals.toml"
    cfg.write_text(PLAN.replace('variants = ["M1"]', f"variants = {variants}") + extra)
    code = main(["oed", str(cfg), "--out", str(tmp_path / "res"), "--json", "--quiet"])
    out = capsys.readouterr()
    return code, (json.loads(out.out) if code == 0 else None), out.err


def test_planned_discrimination_design_matches_the_library(tmp_path, capsys):
    from models.friction import candidate_models, model_inputs
    from mudoe.units import convert
    from oed import select_discriminating
    code, obj, err = _run_rivals(tmp_path, capsys, RIVALS + "n_readings = 4\nn_series = 2\n")
    assert code == 0, err
    q = np.linspace(0, 1600, 9)
    sigma = dict(zip(("D_y", "F_x", "B0_y"), convert(np.array([15.0, 5.0, 4.0]), "um", "mm", difference=True)))
    m = candidate_models()
    ref = select_discriminating(m["M3"], [530.0, 470.0], m["M2"], [530.0, 470.0],
                                (model_inputs("M3", q), model_inputs("M2", q)), sigma=sigma, n_readings=4)
    assert obj["mode"] == "discrimination" and obj["planned"] and obj["rival"] == "M2" and obj["proven_optimal"]
    assert obj["readings"] == [[float(q[j]), s] for j, s in ref.readings]
    assert obj["value"] == pytest.approx(2 * ref.value, rel=1e-9)          # two series
    assert obj["values"]["T"] == pytest.approx(obj["value"], rel=1e-12) and "divergence" not in obj["values"]
    even = obj["references"]["evenly spread"]
    assert len(even["readings"]) == 4 and even["values"]["T"] <= obj["value"]    # 2 set points x 3 sensors, first 4
    assert [r[0] for r in even["readings"]] == [0.0, 0.0, 0.0, 1600.0]
    assert (tmp_path / "res" / "oed.json").is_file() and "rival M2" in (tmp_path / "res" / "oed.txt").read_text()


def test_discrimination_design_at_the_estimates(capsys, campaign_dirs):
    cfg = campaign_dirs["root"] / "rivals.toml"
    text = campaign_dirs["paper_cfg"].read_text().replace('variants = ["M1"]', 'variants = ["M1", "M2"]')
    cfg.write_text(text.replace('variant = "M1"', 'variant = "M2"') + 'mode = "discrimination"\nrival = "M1"\n'
                   'n_points = 3\nn_sensors = 1\ndiscrimination_criterion = "divergence"\n')
    assert main(["oed", str(cfg), "--out", str(campaign_dirs["root"] / "r"), "--json", "--quiet"]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert not obj["planned"] and obj["criterion"] == "divergence" and obj["proven_optimal"]
    assert len(obj["set_points"]) == 3 and len(obj["sensors"]) == 1 and len(obj["readings"]) == 3
    assert set(obj["values"]) == {"T", "divergence", "T_refit"}
    assert obj["values"]["divergence"] == pytest.approx(obj["value"], rel=1e-12)
    assert obj["values"]["divergence"] >= obj["references"]["evenly spread"]["values"]["divergence"]


@pytest.mark.parametrize("extra, key, match", [
    ('mode = "discrimination"\nvariant = "M3"\n', "rival", "needs rival"),
    (RIVALS.replace('"M2"\n', '"M9"\n'), "rival", "unknown variant 'M9'"),
    (RIVALS.replace('rival = "M2"', 'rival = "M3"'), "rival", "assumed true"),
    ('mode = "discrimination"\nrival = "M3"\n', "rival", "defaults to the last"),
    (RIVALS + "n_readings = 4\nn_points = 2\n", "n_readings", "not both"),
    (RIVALS + 'discrimination_criterion = "divergence"\n', "discrimination_criterion", "covariances"),
    ('rival = "M2"\n', "rival", "only for mode"),
    (RIVALS + "n_readings = 1000\n", "n_readings", "at most the 27 candidate readings"),
])
def test_bad_discrimination_keys_exit_2_one_line(tmp_path, capsys, extra, key, match):
    code, _, err = _run_rivals(tmp_path, capsys, extra)
    assert code == 2 and match in err and key in err, err
    assert len(err.strip().splitlines()) == 1


def test_input_design_at_the_estimate_with_data(capsys, campaign_dirs):
    cfg = campaign_dirs["root"] / "inputs.toml"
    text = campaign_dirs["paper_cfg"].read_text()          # ends in the [oed] section
    assert text.rstrip().endswith('variant = "M1"')
    cfg.write_text(text + 'mode = "inputs"\nn_points = 2\ncandidates = [0.0, 400.0, 800.0, 1600.0]\n'
                          'kind = "gauss_newton"\n')
    assert main(["oed", str(cfg), "--out", str(campaign_dirs["root"] / "r"), "--json", "--quiet"]) == 0
    obj = json.loads(capsys.readouterr().out)
    assert not obj["planned"] and len(obj["indices"]) == 2 and obj["proven_optimal"]


def test_sensor_include_with_an_input_design_exit_2(tmp_path, capsys):
    code, _, err = _run(tmp_path, capsys, 'mode = "inputs"\nn_points = 2\ninclude = ["D_y"]\n')
    assert code == 2 and "include/exclude name sensors" in err


def test_refitted_discrimination_design_and_its_enumeration_limit(tmp_path, capsys):
    code, obj, err = _run_rivals(tmp_path, capsys, RIVALS + 'n_points = 2\ndiscrimination_criterion = "T_refit"\n')
    assert code == 0, err
    assert obj["criterion"] == "T_refit" and obj["method"] == "enumerate-refit" and obj["proven_optimal"]
    assert obj["values"]["T_refit"] == pytest.approx(obj["value"], rel=1e-12)
    assert obj["values"]["T_refit"] <= obj["values"]["T"] * (1 + 1e-12)        # refitting only lowers T
    even = obj["references"]["evenly spread"]["values"]["T_refit"]
    assert np.isnan(even) or even <= obj["value"] * (1 + 1e-12)
    code, _, err = _run_rivals(tmp_path, capsys, RIVALS + 'n_readings = 12\ndiscrimination_criterion = "T_refit"\n')
    assert code == 2 and "enumeration_limit" in err and len(err.strip().splitlines()) == 1


def test_one_sensor_study_designs_without_min_sensors(tmp_path):
    """A study with fewer sensors than parameters needs no min_sensors/n_sensors keys (default capped)."""
    from pathlib import Path
    root = Path(__file__).resolve().parents[2]
    text = (root / "configs" / "truss_one_sensor.toml").read_text()
    text = text.replace("n_sensors = 1", "").replace('"../', f'"{root}/')
    cfg = tmp_path / "truss.toml"
    cfg.write_text(text)
    assert main(["oed", str(cfg), "--out", str(tmp_path / "r"), "--quiet"]) == 0
    assert "P_x" in (tmp_path / "r" / "oed.txt").read_text()
