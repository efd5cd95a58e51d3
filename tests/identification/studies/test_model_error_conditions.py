"""identification.model_error at a condition the data do not hold (issue 29, the press coverage target).

A condition the model's inputs do not name (a direction of motion, a day) shifts the readings by an offset
the model lacks.  Mechanics only, on a small static model with known truth: which validation rows are a
condition the calibration part has not seen, that the discrepancy predicts them as a new draw of its process
(mean the model, band its prior), that named conditions are independent in the discrepancy's covariance, and a
deterministic case where the kriged band misses a known offset that the new-draw band holds.  The coverage of
these bands over random offsets is a Monte Carlo claim measured in bench/bench_model_error.py
(``--n-offset``), not asserted on one seed here.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from identification import Measurements, Split, model_error
from identification.studies.model_error import unseen_rows
from identification.studies.model_error_fit import outputs_at
from identification.studies.model_error_result import NEW_CONDITION
from models.contract import Model

SIGMA = 0.05
Q = np.linspace(0.2, 2.0, 10)


def _model() -> Model:
    import casadi as ca
    return Model.explicit(["a", "b"], ["x"], ["y1", "y2"],
                          h=lambda p, q: ca.vertcat(p[0] * (1 - ca.exp(-p[1] * q[0])), p[0] * q[0] / (1 + p[1] * q[0])))


def _data(offsets, seed: int = 11) -> Measurements:
    """Two series at the set points Q repeated once per condition; condition g shifts both sensors by offsets[g]."""
    rng = np.random.default_rng(seed)
    q = np.tile(Q, len(offsets))
    shift = np.repeat(np.asarray(offsets, float), Q.size)
    mean = np.stack([2.0 * (1 - np.exp(-1.5 * q)), 2.0 * q / (1 + 1.5 * q)], axis=1) + shift[:, None]
    z = mean[None] + SIGMA * rng.standard_normal((2, q.size, 2))
    return Measurements(q[:, None], z, SIGMA, sensors=["y1", "y2"], input_names=["x"])


FIRST, SECOND = list(range(Q.size)), list(range(Q.size, 2 * Q.size))
P0 = [1.0, 1.0]


def test_unseen_rows_repeat_calibration_inputs_in_other_rows():
    d = _data([0.0, 0.0])
    assert unseen_rows(Split("first vs second", FIRST, SECOND), d).all()
    # interleaved set points: no validation row repeats a calibration row's inputs
    assert not unseen_rows(Split("odd vs even", FIRST[::2], FIRST[1::2]), d).any()
    # calibration rows that repeat inputs measured how rows at one input differ: nothing unseen
    assert not unseen_rows(Split("both vs first", FIRST[:5] + SECOND, FIRST[5:]), d).any()
    # the same rows on both sides (a split by series)
    assert not unseen_rows(Split("series", FIRST, FIRST, cal_series=[0], val_series=[1]), d).any()


def test_unseen_rows_with_named_groups_are_the_groups_without_calibration_rows():
    d = _data([0.0, 0.0, 0.0])
    groups = np.repeat([0, 1, 2], Q.size)
    sp = Split("0, 1 vs 1, 2", FIRST + SECOND[:5], SECOND[5:] + list(range(2 * Q.size, 3 * Q.size)))
    assert unseen_rows(sp, d, groups).tolist() == [False] * 5 + [True] * Q.size


def test_a_condition_not_seen_is_predicted_by_the_model_with_the_discrepancy_prior():
    r = model_error(_model(), _data([0.3]), P0, kind="discrepancy")
    q = np.array([[0.5], [1.0], [1.7]])
    new = r.predict(q, condition=NEW_CONDITION)
    seen = r.predict(q)
    h, G = outputs_at(r.fit.model, r.p, q)
    np.testing.assert_allclose(new.mean, h, rtol=0, atol=1e-12)          # no kriging from the data's condition
    assert np.max(np.abs(seen.mean - h)) > 0.1                             # the data's condition: +0.3 learnt
    c = stats.norm.ppf(0.975)
    prior = np.array([d.amplitude ** 2 + d.rough ** 2 for d in r.discrepancies])
    var = prior[None, :] + np.einsum("jkp,pq,jkq->jk", G, r.cov, G)
    np.testing.assert_allclose((new.upper - new.mean) / c, np.sqrt(var), rtol=1e-10)
    mixed = r.predict(q, condition=[None, NEW_CONDITION, None])             # per row: the data's, not seen
    np.testing.assert_array_equal(mixed.mean[[0, 2]], seen.mean[[0, 2]])
    np.testing.assert_array_equal(mixed.mean[1], new.mean[1])
    disc = r.discrepancy(q, condition=NEW_CONDITION)
    np.testing.assert_allclose(disc.mean, 0.0, atol=1e-12)
    np.testing.assert_allclose((disc.upper - disc.mean) / c, np.sqrt(np.broadcast_to(prior, disc.mean.shape)),
                               rtol=1e-10)


def test_named_conditions_are_independent_in_the_discrepancy():
    groups = np.repeat(["day 1", "day 2"], Q.size)
    r = model_error(_model(), _data([0.2, -0.2]), P0, kind="discrepancy", groups=groups)
    V = r.fit.gp.covariance()
    obs = r.fit.gp.obs
    start = 0
    for i, n in enumerate(obs.sizes):
        code = obs.condition_codes(i)
        block = V[start:start + n, start:start + n]
        assert np.all(block[code[:, None] != code[None, :]] == 0.0)
        assert np.any(block[(code[:, None] == code[None, :]) & ~np.eye(n, dtype=bool)] > 0.0)
        start += n
    assert r.groups == ("day 1", "day 2")
    q = np.array([[1.0]])
    day1, day2, new = (r.predict(q, condition=c) for c in ("day 1", "day 2", "another day"))
    assert np.all(day1.mean > day2.mean)                                   # +0.2 against -0.2, both sensors
    assert np.all(new.upper - new.lower > day1.upper - day1.lower)
    np.testing.assert_allclose(r.predict(q).mean, new.mean, rtol=0, atol=0)   # None with groups: not seen


def test_a_known_offset_of_a_condition_not_seen_is_held_by_the_new_draw_band():
    # calibrated on the first condition (+0.3), validated on the second (-0.3) at the same set points
    d = _data([0.3, -0.3])
    sp = Split("first vs second", FIRST, SECOND)
    after = model_error(_model(), d, P0, splits=sp, kind="discrepancy").heldout[0]
    before = model_error(_model(), d, P0, splits=sp, kind="discrepancy",
                         groups=np.zeros(2 * Q.size, int)).heldout[0]      # one condition named: kriged
    assert after.n_unseen == after.n_values == 40 and before.n_unseen == 0
    assert after.n_conditions == before.n_conditions == 1
    assert after.unseen_from_one and not before.unseen and not before.unseen_from_one
    assert before.coverage_discrepancy < 0.2
    assert after.coverage_discrepancy >= 0.9
    assert after.widening_discrepancy > before.widening_discrepancy


def test_condition_of_the_wrong_length_is_refused():
    r = model_error(_model(), _data([0.3]), P0, kind="discrepancy")
    with pytest.raises(ValueError, match="condition"):
        r.predict(np.array([[0.5], [1.0]]), condition=["a", "b", "c"])


def test_the_table_and_the_note_say_how_many_conditions_a_band_at_a_condition_not_seen_rests_on():
    # three conditions; calibrated on two of them (two conditions) or on one, validated on the third
    d = _data([0.3, -0.3, 0.1])
    third = list(range(2 * Q.size, 3 * Q.size))
    groups = np.repeat(["a", "b", "c"], Q.size)
    splits = [Split("a, b vs c", FIRST + SECOND, third), Split("a vs c", FIRST, third),
              Split("a: odd vs even", FIRST[::2], FIRST[1::2])]
    r = model_error(_model(), d, P0, splits=splits, kind="discrepancy", groups=groups)
    two, one, same = r.heldout
    assert (two.n_conditions, one.n_conditions, same.n_conditions) == (2, 1, 1)
    assert (two.n_unseen, one.n_unseen, same.n_unseen) == (40, 40, 0)
    assert not two.unseen_from_one and one.unseen_from_one and not same.unseen
    note = next(n for n in r.notes if n.startswith("held-out readings in a condition"))
    assert "a, b vs c (40 of 40 readings; 2 conditions in its calibration part)" in note
    assert "a vs c (40 of 40 readings; 1 condition in its calibration part)" in note
    assert "a: odd vs even" not in note and "plug-in from one realisation" in note
    assert "75.7 +- 2.6 / 84.0 +- 2.2 / 89.6 +- 1.9 %" in note and "lower bound" in note
    frame = r.to_frame()
    assert frame["n_conditions"].tolist() == [2, 1, 1] and frame["n_unseen"].tolist() == [40, 40, 0]
    text = r.summary()
    assert "cal. cond." in text and "* readings in a condition not seen, predicted from one condition" in text
    row = next(line for line in text.splitlines() if line.strip().startswith("a vs c"))
    assert "*" in row


def test_no_plug_in_sentence_when_every_calibration_part_holds_several_conditions():
    d = _data([0.3, -0.3, 0.1])
    groups = np.repeat(["a", "b", "c"], Q.size)
    sp = Split("a, b vs c", FIRST + SECOND, list(range(2 * Q.size, 3 * Q.size)))
    r = model_error(_model(), d, P0, splits=sp, kind="discrepancy", groups=groups)
    note = next(n for n in r.notes if n.startswith("held-out readings in a condition"))
    assert "2 conditions in its calibration part" in note and "plug-in from one realisation" not in note
    assert "*" not in r.summary().split("held-out")[1].split("Notes:")[0]
