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


def test_the_margin_has_a_standard_error_over_the_splits(ranking):
    """margin = sum_s w_s d_s (w_s = n_s / N), SE^2 = S/(S-1) sum_s w_s^2 (d_s - margin)^2: by hand."""
    assert [s for s, _, _ in ranking.split_margins] == ["interleaved", "low vs high"]
    n = np.array([k for _, k, _ in ranking.split_margins], float)
    d = np.array([x for _, _, x in ranking.split_margins])
    w = n / n.sum()
    assert w @ d == pytest.approx(ranking.margin, rel=1e-12)
    se = np.sqrt(2 / 1 * np.sum(w ** 2 * (d - w @ d) ** 2))
    assert ranking.margin_se == pytest.approx(se, rel=1e-12) and ranking.margin_se > 0
    assert ranking.decided == (ranking.margin > 2 * se)
    word = "choose saturating: margin" if ranking.decided else "a tie within 2 SE between saturating and straight"
    assert ranking.verdict().startswith(word) and "standard error over 2 splits" in ranking.verdict()
    assert "Verdict: " + ranking.verdict() in ranking.summary()
    d_ = ranking.to_dict()
    assert d_["margin_se"] == pytest.approx(se) and d_["verdict"] == ranking.verdict()
    assert [s["split"] for s in d_["split_margins"]] == ["interleaved", "low vs high"]
    assert ranking.to_frame().attrs["margin_se"] == ranking.margin_se


def _ranking(margin: float, se: float, splits: int = 4, comparable: bool = True, runner_up: str = "B"):
    from identification.studies.model_ranking import ModelRanking
    return ModelRanking(rows=(), use="A", use_error=False, margin=margin, margin_total=100 * margin,
                        runner_up=runner_up, comparable=comparable, margin_se=se,
                        split_margins=tuple((f"s{k}", 25, margin) for k in range(splits)))


def test_the_verdict_chooses_above_two_standard_errors_and_calls_a_tie_below():
    assert _ranking(0.30, 0.10).verdict() == ("choose A: margin +0.3 +- 0.1 per reading over B (standard error over 4 "
                                              "splits), 3.0 SE")
    tie = _ranking(0.15, 0.10)
    assert not tie.decided and tie.verdict().startswith("a tie within 2 SE between A and B: margin +0.15 +- 0.1")
    assert not _ranking(0.20, 0.10).decided                 # exactly 2 SE is still a tie
    one = _ranking(0.30, float("nan"), splits=1)
    assert not one.decided and "no standard error: 1 split" in one.verdict()
    assert _ranking(0.3, float("nan"), comparable=False).verdict().startswith("no verdict: A and B were not scored")
    assert _ranking(float("nan"), float("nan"), runner_up="").verdict() == \
        "choose A (the only variant with a held-out table)"


def test_incomparable_tables_get_no_standard_error():
    d = _data(False)
    r = rank_models({"a": model_error(_model(), d, P0, splits=SPLITS[:1], kind="none"),
                     "b": model_error(_model(), d, P0, splits=SPLITS, kind="none")})
    assert not r.comparable and np.isnan(r.margin_se) and r.split_margins == () and not r.decided
    assert r.verdict().startswith("no verdict")
