"""The one record a report draws (issue 28 item 6): filled by the study, holding no study-layer object;
the phases and the config are data, the report calls nothing back; the old record paths still work."""
import dataclasses
import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def truss():
    from mudoe.config import load_config
    from mudoe.study import StudyResults, prepare, run_identify, run_uncertainty
    study = prepare(load_config(REPO / "configs" / "truss_one_sensor.toml"))
    return run_uncertainty(study, run_identify(study, StudyResults(study)))


def _types_from(obj, package: str) -> set:
    """Names of the types defined in ``package`` among ``obj`` and what it holds (dataclass fields, mappings,
    tuples and lists, followed to any depth; other objects are not opened)."""
    found, seen, todo = set(), set(), [obj]
    while todo:
        x = todo.pop()
        if id(x) in seen or isinstance(x, (np.ndarray, str, bytes, int, float)) or x is None:
            continue
        seen.add(id(x))
        t = type(x)
        if t.__module__.split(".")[0] == package:
            found.add(f"{t.__module__}.{t.__qualname__}")
        if dataclasses.is_dataclass(x) and not isinstance(x, type):
            todo += [getattr(x, f.name) for f in dataclasses.fields(x)]
        elif isinstance(x, Mapping):
            todo += list(x.values())
        elif isinstance(x, (tuple, list)):
            todo += list(x)
    return found


@pytest.mark.filterwarnings("ignore:Estimate.extra:DeprecationWarning")   # the walker reads every field
def test_the_record_holds_no_object_of_the_study_layer(truss):
    from mudoe.report_record import study_record
    from oed.study_record import StudyRecord
    before = _types_from(truss, "mudoe")            # what the report used to read: the study's own objects
    assert {"mudoe.study_base.StudyResults", "mudoe.study_base.Study"} <= before
    assert any(t.endswith(".StudyConfig") for t in before)
    record = study_record(truss)
    assert isinstance(record, StudyRecord)
    assert _types_from(record, "mudoe") == set()
    assert record.estimates["linear"] is truss.estimates["linear"]     # the library's results, not copies
    assert record.uncertainty["linear"] is truss.uncertainty["linear"]


def test_the_config_is_data_of_the_record(truss):
    from mudoe.report_record import study_record
    cfg = truss.study.cfg
    c = study_record(truss).study.config
    assert c.values == cfg.as_dict() and c.text == cfg.text and c.path == str(cfg.path)
    assert (c.title, c.dpi, c.uncertainty) == (cfg.report.title, cfg.report.dpi, cfg.report.uncertainty)


def test_phases_are_computed_by_the_study_before_the_report():
    from mudoe.config import DEFAULT_CONFIG, load_config
    from mudoe.report_record import study_setup
    from mudoe.study import prepare
    setup = study_setup(prepare(load_config(DEFAULT_CONFIG)))
    q = np.asarray(setup.campaign.q_set)
    top = int(np.argmax(q))
    assert setup.phases == tuple("loading" if j <= top else "unloading" for j in range(q.size))
    assert setup.presentation.phases is None and setup.presentation.quantity == "displacement"


def test_an_own_model_declares_its_phases_and_a_wrong_count_is_refused(truss):
    from mudoe.report_record import study_phases
    model = truss.study.models["linear"]
    n = np.asarray(truss.study.campaign.q_set).size
    assert study_phases(truss.study) is None                       # no declaration: no phases
    try:
        model.mudoe_phases = lambda q: ["a"] * (len(q) - 2) + ["b", "b"]
        assert study_phases(truss.study) == ("a",) * (n - 2) + ("b", "b")
        model.mudoe_phases = lambda q: ["a"]
        with pytest.raises(ValueError, match=f"returned 1 labels for {n} set points"):
            study_phases(truss.study)
    finally:
        del model.mudoe_phases


def test_the_report_takes_the_record_only(truss, tmp_path):
    from reports.builder import build_report, report_pages
    with pytest.raises(TypeError, match="mudoe.report_record.study_record"):
        build_report(truss, tmp_path / "out")
    with pytest.raises(TypeError, match="StudyRecord"):
        report_pages(truss)
    assert not (tmp_path / "out").exists() or list((tmp_path / "out").iterdir()) == []


@pytest.mark.parametrize("old,name,new", [
    ("reports.view", "FitAssessment", "identification.studies.records"),
    ("reports.view", "Presentation", "identification.studies.records"),
    ("reports.diagnosis", "Explanation", "identification.studies.records"),
    ("reports.figures", "PredictionBands", "identification.studies.records"),
    ("reports.uncertainty", "ModelUncertainty", "identification.studies.records"),
    ("reports.model_error_pages", "ModelErrorView", "identification.studies.records"),
    ("reports.press_figures", "ModelCurve", "identification.studies.records"),
    ("mudoe.dynamic_records", "MeshSummary", "identification.studies.records"),
    ("mudoe.plan_records", "PlannedDesign", "oed.plan_records")])
def test_old_paths_of_the_records_still_work_with_a_warning(old, name, new):
    import importlib
    with pytest.warns(DeprecationWarning, match=f"use {new}.{name}"):
        moved = getattr(importlib.import_module(old), name)
    assert moved is getattr(importlib.import_module(new), name)


def test_a_presentation_with_a_phases_callable_is_deprecated_but_still_honoured(truss):
    from identification.studies.records import Presentation
    from mudoe.report_record import study_phases, study_setup
    with pytest.warns(DeprecationWarning, match="BuiltinModel"):
        shown = Presentation(quantity="q", phases=lambda q: ["p"] * len(q))
    study = dataclasses.replace(truss.study, presentation=shown)
    assert set(study_phases(study)) == {"p"}
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        setup = study_setup(study)
    assert setup.presentation.phases is None and set(setup.phases) == {"p"}
