"""The study's results record (issue 21): frozen, built step by step, typed; built-in studies looked up by name."""
import dataclasses
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def truss_study():
    from mudoe.config import load_config
    from mudoe.study import prepare
    return prepare(load_config(REPO / "configs" / "truss_one_sensor.toml"))


def test_every_run_returns_a_new_record_and_leaves_the_old_one(truss_study):
    from mudoe.study import StudyResults, run_identify, run_uncertainty
    empty = StudyResults(truss_study)
    fitted = run_identify(truss_study, empty)
    assert list(fitted.estimates) == ["linear"] and dict(empty.estimates) == {} and fitted.study is truss_study
    a = fitted.assessments["linear"]                 # what the verdict table shows, assessed by the study
    assert a.trust == "NOT trustworthy" and a.goodness.dof == fitted.estimates["linear"].dof
    with pytest.raises(dataclasses.FrozenInstanceError):
        fitted.estimates = {}
    full = run_uncertainty(truss_study, fitted, "all")
    assert list(full.uncertainty) == ["linear"] and dict(fitted.uncertainty) == {}
    assert full.uncertainty["linear"].estimate is fitted.estimates["linear"]
    assert run_uncertainty(truss_study, fitted, "none").uncertainty == {}
    noted = full.with_note("a note")
    assert noted.notes == ("a note",) and full.notes == ()


def test_results_fields_are_typed_not_object():
    from mudoe.study import StudyResults
    untyped = [f.name for f in dataclasses.fields(StudyResults) if f.type in (object, "object")]
    assert untyped == []


def test_built_in_studies_are_looked_up_by_name():
    from identification.studies.splits import Split
    from models.press import PRESS_SCENARIO_NAMES
    from mudoe.registry import builtin_model, scenario_splits
    assert builtin_model("press").name == "press" and builtin_model("mytoy_pkg.model:build") is None
    paper = scenario_splits(29, ["paper"])
    assert [s.name for s in paper] == [n for n in PRESS_SCENARIO_NAMES] and all(isinstance(s, Split) for s in paper)
    assert [s.name for s in scenario_splits(29, [PRESS_SCENARIO_NAMES[1]])] == [PRESS_SCENARIO_NAMES[1]]


def test_variant_model_reads_the_set_points():
    import numpy as np
    from models import Model
    from mudoe.study import VariantModel
    m = Model.explicit(params=["a"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] * q[0])
    q = np.array([0.0, 1.0, 2.0])
    np.testing.assert_array_equal(VariantModel(m).inputs(q), q[:, None])
    two = VariantModel(m, lambda s: np.column_stack([s, s ** 2]))
    np.testing.assert_array_equal(two.inputs(q), [[0, 0], [1, 1], [2, 4]])


def test_validate_fits_only_its_variant_with_the_same_estimate():
    # validate uses the fit of its own variant only (issue 30 item 7): the others are not fitted, and the fit
    # is the one of all variants bit for bit
    from mudoe.config import load_config
    from mudoe.study import StudyResults, prepare, require_fit, run_identify
    study = prepare(load_config(REPO / "configs" / "press.toml"))
    empty = StudyResults(study)
    alone = require_fit(study, empty, "M2", None, "validate", alone=True)
    assert list(alone.estimates) == ["M2"]
    every = run_identify(study, empty)
    assert list(every.estimates) == list(study.models) and len(study.models) == 3
    assert np.array_equal(alone.estimates["M2"].p, every.estimates["M2"].p)
    assert np.array_equal(alone.estimates["M2"].cov, every.estimates["M2"].cov)
    assert list(require_fit(study, empty, "M2", None, "oed").estimates) == list(study.models)   # default: all
    with pytest.raises(ValueError, match="variants: unknown 'M9'"):
        run_identify(study, empty, variants=("M9",))
