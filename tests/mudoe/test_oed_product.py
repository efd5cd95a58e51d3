"""`mudoe oed` beyond sensors and set points (issue 30 item 8, issue 31 item 6): a time-series study's next
experiments (constants and control profiles within [oed] bounds, the time limit stated), its approximate sampling
times, the exact robust sensor design of a static study with data, mode = "both" under a prior; the keys' bad
values (exit 2, one line naming file, line and key) and the design pages."""
import json
import re
from pathlib import Path

import numpy as np
import pytest

from cli_texts import PLANNED_PRESS
from mudoe.cli import main
from mudoe.config import parse_config

REPO = Path(__file__).resolve().parents[2]
PRESS_PRIOR = 'prior = { k5 = ["uniform", 400.0, 700.0], k7 = ["lognormal", 470.0, 0.2] }\n'
MOTOR_INPUTS = 'mode = "inputs"\nbounds = { TL = [0.0, 0.03], u = [-12.0, 12.0] }\nn_candidates = 3\n'


def _config(tmp_path, name: str, extra: str, planned: bool = False) -> Path:
    """configs/NAME.toml with its data folder absolute and ``extra`` at the top of [oed]."""
    text = (REPO / "configs" / f"{name}.toml").read_text()
    text = text.replace(f'directory = "../data/{name}"', f'directory = "{REPO / "data" / name}"')
    text, n = re.subn(r"^\[oed\]\n", "[oed]\n" + ("planned = true\n" if planned else "") + extra, text, flags=re.M)
    assert n == 1
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    return path


def _oed(tmp_path, capsys, path):
    code = main(["oed", str(path), "--out", str(tmp_path / "res"), "--json", "--quiet"])
    out = capsys.readouterr()
    assert code == 0, out.err
    return json.loads(out.out), (tmp_path / "res" / "oed.txt").read_text()


def _motor_candidates(cfg, Q):
    lo = np.r_[0.0, np.full(10, -12.0)]
    hi = np.r_[0.03, np.full(10, 12.0)]
    R = lo + (hi - lo) * np.random.default_rng(cfg.oed.seed).random((cfg.oed.n_candidates, 11))
    return np.vstack([Q, R]), lo, hi


# ---------------------------------------------------------------- a time-series study's next experiments
def test_planned_motor_next_experiment_is_select_inputs_over_the_candidates(tmp_path, capsys):
    from mudoe.example_motor import build
    from mudoe.kind.time_series import experiment_rows
    from oed import criterion_value, information
    from oed.inputs import select_inputs
    path = _config(tmp_path, "motor", MOTOR_INPUTS, planned=True)
    obj, text = _oed(tmp_path, capsys, path)
    cfg = parse_config(path.read_text(), str(path))
    m, Q = build("coulomb"), experiment_rows(cfg, build("coulomb"))
    p = np.array([pc.start for pc in cfg.parameters])
    sigma = np.array([0.02, 0.5, 0.01])
    times = np.array(cfg.dynamic.times)
    C, lo, hi = _motor_candidates(cfg, Q)
    ref = select_inputs(m, p, candidates=C, sigma=sigma, n_points=1, times=times, criterion="D")
    assert obj["mode"] == "inputs" and obj["planned"] and obj["p"] == list(p)
    assert obj["labels"] == [f"experiment {j}" for j in range(1, 5)] + [f"candidate {k}" for k in range(1, 4)]
    assert np.allclose(obj["candidates"], C, rtol=0, atol=0) and obj["lower"] == list(lo) and obj["upper"] == list(hi)
    assert obj["result"]["indices"] == list(ref.indices) and obj["result"]["proven_optimal"]
    assert obj["chosen"] == [obj["labels"][i] for i in ref.indices] and not obj["refined"]
    row = C[ref.indices[0]]
    assert obj["designed_rows"] == [list(row)]
    assert obj["designed"] == [{"TL": row[0], "u": list(row[1:])}]
    # the values: the design (as the engine's), the current campaign, both together, each current one alone
    F = information(m, p, axis="inputs", candidates=C, sigma=sigma, times=times).F
    v = lambda w: criterion_value(F, w=np.asarray(w, float), criterion="D", kind="gauss_newton")  # noqa: E731
    design_w = np.eye(len(C))[ref.indices[0]]
    current_w = np.r_[np.ones(4), np.zeros(3)]
    assert obj["values"]["design"] == pytest.approx(ref.value, rel=1e-9)
    assert obj["values"]["current"] == pytest.approx(v(current_w), rel=1e-9)
    assert obj["values"]["current + design"] == pytest.approx(v(current_w + design_w), rel=1e-9)
    assert obj["current_each"] == pytest.approx([v(np.eye(len(C))[j]) for j in range(4)], rel=1e-9)
    eff = np.exp((v(current_w) - ref.value) / m.n_p) * 4 / 1         # per experiment: (det(M_d/1)/det(M_c/4))^(1/6)
    assert obj["efficiency_per_experiment"] == pytest.approx(eff, rel=1e-9)
    assert not obj["time_limit_hit"] and obj["time_limit"] == 60.0
    assert "designed experiment 1: TL = " in text and "u = [" in text and "time limit" not in text


def test_the_time_limit_of_the_refinement_is_stated_and_the_exact_levels_kept(tmp_path, capsys):
    path = _config(tmp_path, "motor", MOTOR_INPUTS + "refine = true\ntime_limit = 0.5\n", planned=True)
    obj, text = _oed(tmp_path, capsys, path)
    assert obj["time_limit_hit"] and obj["time_limit"] == 0.5 and obj["refined"]
    i = obj["result"]["indices"][0]
    assert obj["designed_rows"] == [obj["candidates"][i]]          # nothing finished: the exact design's levels
    assert re.search(r"time limit \(\[oed\] time_limit = 0.5 s\) reached: .*time limit", text)


def test_planned_reactor_experiments_over_a_prior(tmp_path, capsys):
    from mudoe.example_reactor import build
    from mudoe.kind.time_series import experiment_rows
    from oed.inputs import select_inputs
    extra = ('mode = "inputs"\nn_points = 2\nn_candidates = 2\nbounds = { T = [330.0, 370.0] }\n'
             'prior = { E1 = ["uniform", 45.0, 55.0] }\n')
    path = _config(tmp_path, "reactor", extra, planned=True)
    obj, text = _oed(tmp_path, capsys, path)
    cfg = parse_config(path.read_text(), str(path))
    m = build()
    Q = experiment_rows(cfg, m)
    lo, hi = np.array([1.0, 330.0]), np.array([2.0, 370.0])        # cA0 not bounded: the experiments' range
    C = np.vstack([Q, lo + (hi - lo) * np.random.default_rng(0).random((2, 2))])
    ref = select_inputs(m, np.array([1.5, 50.0, 1.0, 70.0]), candidates=C, sigma=np.array([0.01, 0.01]),
                        n_points=2, times=np.array(cfg.dynamic.times), prior={"E1": ("uniform", 45.0, 55.0)})
    assert obj["lower"] == list(lo) and obj["upper"] == list(hi)
    assert obj["robust"]["indices"] == list(ref.indices) and obj["robust"]["proven_optimal"]
    assert obj["robust"]["value"] == pytest.approx(ref.value, rel=1e-9)
    assert obj["designed_rows"] == [list(C[i]) for i in ref.indices] and obj["result"] is None
    assert "exact robust input design" in text and "designed experiment 2: cA0 = " in text


def test_planned_reactor_approximate_sampling_times_over_a_prior(tmp_path, capsys):
    from mudoe.example_reactor import build
    from oed import design_efficiencies, select_times
    path = _config(tmp_path, "reactor", 'approximate = true\nprior = { E1 = ["uniform", 45.0, 55.0] }\n',
                   planned=True)
    obj, text = _oed(tmp_path, capsys, path)
    cfg = parse_config(path.read_text(), str(path))
    m = build()
    Q = np.array([[1.0, 330.0], [2.0, 340.0], [1.5, 350.0], [1.0, 360.0], [2.0, 370.0], [1.5, 345.0]])
    p, sigma, cand = np.array([1.5, 50.0, 1.0, 70.0]), np.array([0.01, 0.01]), np.array(cfg.dynamic.times)
    kw = dict(sigma=sigma, criterion="D", approximate=True)
    local = select_times(m, p, cand, Q, **kw)
    robust = select_times(m, p, cand, Q, prior={"E1": ("uniform", 45.0, 55.0)}, **kw)
    assert obj["mode"] == "times" and obj["approximate"] and obj["robust"] == "bayes"
    assert np.allclose(obj["design"]["points"], np.asarray(robust.points), rtol=1e-12)
    assert np.allclose(obj["design"]["weights"], robust.weights, rtol=1e-12)
    assert obj["design"]["sensitivity_max"] == pytest.approx(robust.sensitivity_max, rel=1e-12)
    assert abs(robust.sensitivity_max - m.n_p) < 1e-3                 # the certificate: D maximum = n_p
    eff = design_efficiencies(m, local, robust, sigma=sigma, inputs=Q)
    assert np.allclose(obj["local_efficiencies"], eff, rtol=1e-12)
    assert "approximate sampling-time design" in text and "n_times = 4 not used" in text


# ---------------------------------------------------------------- static: robust sensors with data, mode both
def test_cstr_with_data_gives_the_exact_robust_sensor_design(tmp_path, capsys):
    from mudoe.study import prepare, run_identify, run_oed
    from mudoe.study_base import StudyResults
    from oed import information, make_prior
    from oed.robust_exact import exact_over_prior
    text = (REPO / "configs" / "cstr.toml").read_text().replace('directory = "../data/cstr"',
                                                                f'directory = "{REPO / "data" / "cstr"}"')
    text = text.replace("n_sensors = 3 ", 'n_sensors = 2\nprior = { E_a = ["uniform", 50.0, 70.0] }\n#')
    path = tmp_path / "cstr.toml"
    path.write_text(text)
    obj, out = _oed(tmp_path, capsys, path)
    cfg = parse_config(text, str(path))
    study = prepare(cfg)
    res = run_identify(study, StudyResults(study=study))
    est, data, m = res.estimates["arrhenius"], study.data["arrhenius"], study.models["arrhenius"]
    pr = make_prior({"E_a": ("uniform", 50.0, 70.0)}, m, est.p)
    ref = exact_over_prior(lambda ps: information(m, ps, inputs=data.inputs, sigma=study.sigma,
                                                  n_series=data.n_M).F, pr, est.p, 2, names=list(m.sensors))
    assert obj["mode"] == "sensors" and not obj["planned"] and obj["chosen"] == list(ref.design.names)
    assert obj["value"] == pytest.approx(ref.design.value, rel=1e-9) and obj["proven_optimal"]
    assert obj["sensor_design"]["chosen"] and "The local sensor design at the estimate" in out
    designed = run_oed(study, res)
    # the tests' sensors ([detect] sensors = "oed") are the robust design's
    assert designed.design_sensors == tuple(ref.design.names) and "exact pseudo-Bayesian" in designed.design_how


def test_planned_press_both_over_a_prior_is_select_inputs_joint(tmp_path, capsys):
    from models.press import press_model
    from oed.inputs import select_inputs
    path = tmp_path / "plan.toml"
    path.write_text(PLANNED_PRESS + 'mode = "both"\nn_points = 3\n' + PRESS_PRIOR)
    obj, text = _oed(tmp_path, capsys, path)
    q = np.linspace(0.0, 1600.0, 9)
    ref = select_inputs(press_model(), [530.0, 470.0], candidates=q[:, None], sigma=[0.015, 0.005, 0.004],
                        n_points=3, sensors="joint", criterion="D",
                        prior={"k5": ("uniform", 400.0, 700.0), "k7": ("lognormal", 470.0, 0.2)})
    sensors = ["D_y", "F_x", "B0_y"]
    labels = [f"{v:g}:{s}" for v in q for s in sensors]
    assert obj["mode"] == "both" and obj["candidates"] == labels and obj["indices"] == list(ref.indices)
    assert obj["chosen"] == [labels[i] for i in ref.indices] and obj["proven_optimal"]
    assert obj["value"] == pytest.approx(ref.value, rel=1e-12, abs=1e-12)
    assert "exact robust joint set point x sensor design" in text


# ---------------------------------------------------------------- bad keys: exit 2, one line, file:line, key
@pytest.mark.parametrize("name, extra, key, match", [
    ("motor", MOTOR_INPUTS.replace("TL = [", "TX = ["), "bounds", "unknown input 'TX'; the model"),
    ("motor", 'mode = "inputs"\nbounds = { u = [12.0, -12.0] }\n', "bounds", "lower 12 > upper -12"),
    ("motor", 'mode = "inputs"\nbounds = { u = [-12.0] }\n', "bounds", "expected [lower, upper]"),
    ("motor", 'mode = "inputs"\nn_candidates = 0\n', "n_candidates", "must be positive"),
    ("motor", 'mode = "inputs"\ntime_limit = -1.0\n', "time_limit", "must be positive"),
    ("motor", 'mode = "inputs"\ncandidates = [1.0, 2.0]\n', "candidates", "set points are a static study's"),
    ("motor", 'mode = "inputs"\nexclude = ["i"]\n', "exclude", "not used by the design of a dynamic study"),
    ("motor", 'mode = "both"\n', "mode", "a joint design of a dynamic study's experiments and instruments is "
                                         "not available in mudoe oed: use mode = \"inputs\""),
    ("motor", 'mode = "inputs"\napproximate = true\n', "approximate", "approximate designs of a dynamic study's "
                                                                     "experiments"),
    ("motor", 'mode = "inputs"\nrefine = true\nprior = { R = ["uniform", 1.9, 2.1] }\n', "refine",
     "refinement under a prior is not implemented"),
    ("motor", 'n_candidates = 4\n', "n_candidates", "only for the design of a dynamic study's experiments"),
    ("cstr", 'bounds = { T = [300.0, 350.0] }\n', "bounds", "a static study's inputs are the set points"),
])
def test_bad_design_keys_exit_2_naming_file_line_and_key(tmp_path, capsys, name, extra, key, match):
    path = _config(tmp_path, name, extra, planned=name == "motor")    # no data read, no fit
    code = main(["oed", str(path), "--out", str(tmp_path / "res"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    lines = path.read_text().splitlines()
    line = next(i + 1 for i, s in enumerate(lines) if re.match(key + r"\s*=", s))
    assert f"{path}:{line}: [oed] {key}: " in err and match in err, err
    assert not (tmp_path / "res" / "oed.json").exists()


# ---------------------------------------------------------------- the pages
def test_the_pages_draw_the_profiles_the_constants_and_the_certificate(tmp_path):
    import matplotlib.pyplot as plt
    from mudoe.config import load_config
    from mudoe.study import plan_without_data
    from mudoe.study_models import build_models
    from reports.builder import report_pages
    from tests.reports.record_stub import stub_record
    path = _config(tmp_path, "motor", MOTOR_INPUTS, planned=True)
    cfg = load_config(path)
    plan = plan_without_data(cfg)
    models = {k: b.model for k, b in build_models(cfg).items()}
    figs = dict(report_pages(stub_record(models, pages="trajectories", plan=plan), with_diagnosis=False))[
        "time_design"]()
    assert len(figs) == 1
    fig = figs[0]
    assert fig._suptitle.get_text() == "Design of the next experiment (D, coulomb)"
    assert {"u(t) (V)"} <= {ax.get_ylabel() for ax in fig.axes}
    assert any("constants within their bounds" in ax.get_title() for ax in fig.axes)
    words = " ".join(t.get_text() for t in fig.texts)
    assert "log det C: designed" in words and "Designed experiment 1: TL = " in words
    plt.close(fig)
    path = _config(tmp_path, "reactor", "approximate = true\n", planned=True)
    cfg = load_config(path)
    plan = plan_without_data(cfg)
    models = {k: b.model for k, b in build_models(cfg).items()}
    figs = dict(report_pages(stub_record(models, pages="trajectories", plan=plan), with_diagnosis=False))[
        "time_design"]()
    assert figs[0]._suptitle.get_text() == "Approximate sampling-time design (D, local, isothermal)"
    assert any(ax.get_xlabel() == "time (h)" for ax in figs[0].axes)
    assert any("Certificate (equivalence theorem)" in t.get_text() for t in figs[0].texts)
    plt.close(figs[0])
