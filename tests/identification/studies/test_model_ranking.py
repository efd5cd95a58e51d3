"""identification.rank_models: which variant to predict with, by held-out predictive log score (issue 29 item 2)."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from identification import Split, model_error, rank_models
from models.contract import Model

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_model_error import P0, SPLITS, _data, _model  # noqa: E402


def _straight() -> Model:
    """y1 = a q, y2 = b q: a wrong model of the saturating truth."""
    return Model.explicit(["a", "b"], ["x"], ["y1", "y2"], h=lambda p, q: ca.vertcat(p[0] * q[0], p[1] * q[0]))


@pytest.fixture(scope="module")
def ranking():
    d = _data(False)
    return rank_models({"straight": model_error(_straight(), d, P0, splits=SPLITS),
                        "saturating": model_error(_model(), d, P0, splits=SPLITS)})


def test_the_right_model_ranks_first_with_a_positive_margin(ranking):
    assert ranking.use == "saturating" and ranking.runner_up == "straight"
    assert ranking.comparable and ranking.margin > 0
    assert ranking.margin_total == pytest.approx(ranking.margin * ranking.rows[0].n_values)
    straight = ranking.rows[1]
    assert straight.kind != "none" and straight.score_error > straight.score_plain   # its error model helps it
    assert "predict with saturating" in ranking.sentence()
    d = ranking.to_dict()
    assert json.loads(json.dumps(d, allow_nan=False)) == d and d["use"] == "saturating"
    assert list(ranking.to_frame().index) == ["saturating", "straight"]


def test_bad_input_and_incomparable_tables():
    d = _data(False)
    with pytest.raises(ValueError, match="results: expected a mapping"):
        rank_models([model_error(_model(), d, P0, kind="none")])
    with pytest.raises(ValueError, match="results: no variant has a held-out table"):
        rank_models({"a": model_error(_model(), d, P0, kind="none")})
    r = rank_models({"a": model_error(_model(), d, P0, splits=SPLITS[:1], kind="none"),
                     "b": model_error(_model(), d, P0, splits=(Split("low", list(range(0, 20)), list(range(20, 25))),),
                                      kind="none"),
                     "c": model_error(_model(), d, P0, kind="none")})
    assert not r.comparable and any("different held-out readings" in n for n in r.notes)
    assert any("c has no held-out table" in n for n in r.notes) and len(r.rows) == 2
    assert np.isfinite(r.margin)
