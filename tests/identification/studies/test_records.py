"""The records a study fills for its report (identification.studies.records): frozen, documented data whose
few methods only word what they hold."""
import dataclasses
import inspect
import math

import numpy as np
import pytest

import identification.studies.records as records

RECORDS = [obj for name in records.__all__ if inspect.isclass(obj := getattr(records, name))]


@pytest.mark.parametrize("cls", RECORDS, ids=lambda c: c.__name__)
def test_every_record_is_a_frozen_dataclass_with_documented_attributes(cls):
    assert dataclasses.is_dataclass(cls) and cls.__dataclass_params__.frozen
    doc = inspect.getdoc(cls)
    assert "Attributes" in doc
    assert all(f.name in doc for f in dataclasses.fields(cls)), [f.name for f in dataclasses.fields(cls)
                                                                   if f.name not in doc]


def test_prediction_bands_hold_floats_and_cannot_change():
    b = records.PredictionBands(np.zeros((2, 1)), np.ones((2, 1)), 2 * np.ones((2, 1)), np.float64(1.96), 0.95)
    assert type(b.quantile) is float and b.quantile == 1.96 and b.level == 0.95
    with pytest.raises(dataclasses.FrozenInstanceError):
        b.level = 0.9


def test_goodness_of_fit_words():
    assert records.GoodnessOfFit(12.0, 10, 0.2851).text() == "chi2 = 12 on 10 dof, p = 0.29"
    assert records.GoodnessOfFit(10.0, 10, math.nan).text().startswith("not testable")


def test_findings_name_the_split_and_follow_with_the_study_explanation():
    rows = (records.DiagnosisRow("M", "low vs high input", "input range", 1e-4, 3e-4, True),
            records.DiagnosisRow("M", "s1", "study split", 1e-5, 1e-5, True))
    d = records.Diagnosis("two_sample", 0.05, rows, (records.Explanation("M", "input range", "Gauges."),))
    (found,) = d.misses("M")                        # the study's own split is not a finding
    assert "input dependence" in found and "'low vs high input'" in found and found.endswith("Gauges.")
    with pytest.raises(ValueError, match="words"):
        records.Explanation("M", "phase", "  ")
