"""The one record a report draws (oed.study_record): typed fields, empty results by default."""
import dataclasses
import typing

import pytest

from oed.study_record import ConfigRecord, DataSource, StudyRecord, StudySetup


@pytest.mark.parametrize("cls", [ConfigRecord, DataSource, StudySetup, StudyRecord], ids=lambda c: c.__name__)
def test_fields_are_typed_frozen_and_documented(cls):
    assert cls.__dataclass_params__.frozen
    hints = typing.get_type_hints(cls)
    assert all(hints[f.name] is not object for f in dataclasses.fields(cls))
    assert all(f.name in cls.__doc__ for f in dataclasses.fields(cls))


def test_a_record_without_results_is_empty():
    setup = StudySetup(config=ConfigRecord("s.toml", "", {}, "t", 150, "untrusted"),
                       source=DataSource("none", (), "", 0, 0), campaign=None, sensors=(), sigma=None,
                       sigma_table=(), normality=None, models={}, data={}, p0=None, splits=())
    r = StudyRecord(study=setup)
    assert r.plan is None and r.detection is None and dict(r.estimates) == {} and r.notes == ()
    assert setup.phases is None and setup.presentation.quantity == "" and setup.pages == "fits"
