"""The noise of a study's model error (issue 29, session 13): a composed sigma sqrt(sigma_rep^2 + sigma_man^2)
enters the model error with sigma_rep (sigma_man is systematic, held by the model error); a sigma given directly
is kept; detection keeps the study's sigma."""
from pathlib import Path

import numpy as np
import pytest

from identification import model_error
from mudoe.config import load_config
from mudoe.model_error_runs import SIGMA_REP_SOURCE, error_data, error_noise, run_model_error
from mudoe.study import StudyResults, prepare

REPO = Path(__file__).resolve().parents[2]
PRESS = REPO / "configs" / "press.toml"
#: the press's composed sigmas (um) given directly instead (configs/press.toml's sigma_man lines replaced)
GIVEN_UM = {"14.142": "15.41", "3.6055": "4.92"}


def _press(tmp_path: Path, replace: dict) -> Path:
    """configs/press.toml with its data folder made absolute and the [[sensors]] lines in ``replace`` rewritten."""
    text = PRESS.read_text().replace('directory = "../data/press_campaign"',
                                     f'directory = "{REPO / "data" / "press_campaign"}"')
    for old, new in replace.items():
        assert old in text
        text = text.replace(old, new)
    cfg = tmp_path / "press.toml"
    cfg.write_text(text)
    return cfg


@pytest.fixture(scope="module")
def press():
    return prepare(load_config(PRESS))


def test_a_composed_sigma_enters_the_model_error_as_sigma_rep(press):
    rep = np.array([r["sigma_rep"] for r in press.sigma_table])
    man = np.array([r["sigma_man"] for r in press.sigma_table])
    assert np.allclose(press.sigma, np.sqrt(rep ** 2 + man ** 2))       # the study's (detection's) sigma
    noise = error_noise(press, ["F_x", "B0_y"])
    assert noise.composed == ("D_y", "F_x", "B0_y")
    assert np.array_equal(noise.sigma, rep)
    assert np.array_equal(error_data(press, "M1", noise).sigma, rep)
    assert np.array_equal(press.data["M1"].sigma, press.sigma)           # detection's data keep the composed sigma
    assert noise.sentence.startswith("The model-error bands take sigma_rep, the repeatability of the series "
                                     "(F_x 3.35 um, B0_y 1.44 um), as the noise of a new reading, not the composed "
                                     "sigma sqrt(sigma_rep^2 + sigma_man^2) of the detection (F_x 4.92 um, B0_y "
                                     "3.88 um): sigma_man is taken as a systematic error")
    assert "D_y" not in noise.sentence                                   # only the sensors named


def test_the_study_model_error_is_model_error_with_sigma_rep(press):
    w = np.array([0.0, 1.0, 1.0])                                        # the study's test sensors F_x, B0_y
    r = run_model_error(press, StudyResults(press), variants=("M1",), embedded=False).model_error["M1"]
    rep = np.array([row["sigma_rep"] for row in press.sigma_table])
    direct = model_error(press.models["M1"], press.data["M1"].with_sigma(rep), press.p0, splits=press.splits,
                         weights=w)
    assert np.array_equal(r.sigma, direct.sigma) and np.array_equal(r.p, direct.p) and r.kind == direct.kind
    assert [h.to_dict() for h in r.heldout] == [h.to_dict() for h in direct.heldout]
    assert r.test.statistic == direct.test.statistic
    assert r.sigma_source == SIGMA_REP_SOURCE
    assert r.notes[0] == error_noise(press, r.sensors).sentence
    assert r.pure_error == () and all("stated sigma" not in n for n in r.notes)   # sigma_rep is no stated sigma
    assert set(direct.notes) - set(r.notes) == {n for n in direct.notes if "stated sigma" in n}


def test_a_sigma_given_directly_is_kept(tmp_path):
    study = prepare(load_config(_press(tmp_path, {f"sigma_man = {k}": f"sigma = {v}" for k, v in GIVEN_UM.items()})))
    assert [r["how"] for r in study.sigma_table] == ["given"] * 3
    noise = error_noise(study, ["F_x", "B0_y"])
    assert noise.composed == () and np.array_equal(noise.sigma, study.sigma)
    assert error_data(study, "M1", noise) is study.data["M1"]
    assert noise.sentence == ("The model-error bands take the sigma given in [[sensors]] (F_x 4.92 um, B0_y 4.92 um) "
                              "as the noise of a new reading, as the user states it.")
    r = run_model_error(study, StudyResults(study), variants=("M1",), embedded=False).model_error["M1"]
    w = np.array([1.0 if s in r.sensors else 0.0 for s in study.sensors])      # the study's design of this sigma
    direct = model_error(study.models["M1"], study.data["M1"], study.p0, splits=study.splits, weights=w)
    assert np.array_equal(r.sigma, direct.sigma) and np.array_equal(r.p, direct.p)
    assert [h.to_dict() for h in r.heldout] == [h.to_dict() for h in direct.heldout]
    assert r.sigma_source == "given" == direct.sigma_source
    assert r.sensors == ("D_y", "F_x")                                  # the E-optimal design under this sigma
    assert r.notes == (error_noise(study, r.sensors).sentence,) + direct.notes       # the pure-error note kept
    assert [c.to_dict() for c in r.pure_error] == [c.to_dict() for c in direct.pure_error] and r.pure_error


def test_sensors_given_and_composed_each_keep_their_own(tmp_path):
    """F_x given directly, D_y and B0_y composed: sigma_rep for the composed ones, F_x's sigma as given."""
    text = PRESS.read_text()
    i = text.index('name = "F_x"')
    cfg = _press(tmp_path, {text[i:i + 40]: text[i:i + 40].replace("sigma_man = 3.6055", "sigma = 4.0")})
    study = prepare(load_config(cfg))
    noise = error_noise(study, ["F_x", "B0_y"])
    rows = {r["sensor"]: r for r in study.sigma_table}
    assert noise.composed == ("D_y", "B0_y")
    assert noise.sigma.tolist() == [rows["D_y"]["sigma_rep"], study.sigma[1], rows["B0_y"]["sigma_rep"]]
    assert study.sigma[1] == pytest.approx(0.004)                       # 4.0 um in the model's mm
    assert "(B0_y 1.44 um), as the noise of a new reading, and for the others the sigma given in [[sensors]] " \
           "(F_x 4 um) as stated, not the composed" in noise.sentence
