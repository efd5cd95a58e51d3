"""identification.model_error on a small static model (issue 29, first slice).

Mechanics only: a large known additive discrepancy is found and predicted, bands and pins behave,
the result protocol and the bad-input messages.  The calibration of the test (its size) and of the
bands is a Monte Carlo claim measured in bench/bench_model_error.py, not asserted on one seed here.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import stats

from identification import Measurements, Split, model_error
from identification.studies.discrepancy_gp import InputScaling, Observations, reml_objective
from identification.studies.model_error_fit import pure_error_sigma
from models.contract import Model

SIGMA = 0.05
Q = np.linspace(0.0, 2.0, 25)


def _model() -> Model:
    import casadi as ca
    return Model.explicit(["a", "b"], ["x"], ["y1", "y2"],
                          h=lambda p, q: ca.vertcat(p[0] * (1 - ca.exp(-p[1] * q[0])), p[0] * q[0] / (1 + p[1] * q[0])))


def _truth(q: np.ndarray) -> np.ndarray:
    a, b = 2.0, 1.5
    return np.stack([a * (1 - np.exp(-b * q)), a * q / (1 + b * q)], axis=1)


def _discrepancy(q: np.ndarray) -> np.ndarray:
    return np.stack([0.3 * np.sin(3 * q), 0.2 * np.cos(2 * q) - 0.2], axis=1)


def _data(with_error: bool, n_series: int = 2, seed: int = 3, sigma=SIGMA) -> Measurements:
    rng = np.random.default_rng(seed)
    mean = _truth(Q) + (_discrepancy(Q) if with_error else 0.0)
    z = mean[None] + SIGMA * rng.standard_normal((n_series, Q.size, 2))
    return Measurements(Q[:, None], z, sigma, sensors=["y1", "y2"], input_names=["x"])


SPLITS = (Split("interleaved", list(range(0, 25, 2)), list(range(1, 25, 2))),
          Split("low vs high", list(range(0, 13)), list(range(13, 25))))
P0 = [1.0, 1.0]


@pytest.fixture(scope="module")
def found():
    return model_error(_model(), _data(True), P0, splits=SPLITS)


def test_a_known_additive_discrepancy_is_found_and_predicted(found):
    assert found.detected and found.test.p_value < 1e-6
    assert found.kind == "discrepancy"
    inter = found.heldout[0]
    assert inter.coverage_discrepancy >= 0.9 and inter.coverage_discrepancy > inter.coverage_plain + 0.1
    assert inter.log_score_discrepancy > max(inter.log_score_plain, inter.log_score_embedded)
    q = (Q[1:] + Q[:-1]) / 2                     # inputs between the data's
    true = _truth(q) + _discrepancy(q)
    pred = found.predict(q[:, None]).mean
    plain = _model().simulate(found.p_plain, q[:, None])
    assert np.sqrt(np.mean((pred - true) ** 2)) < 0.25 * np.sqrt(np.mean((plain - true) ** 2))
    assert [d.sensor for d in found.discrepancies] == ["y1", "y2"]
    assert found.discrepancies[0].amplitude > 2 * SIGMA          # y1: 0.3 sin(3 x), sigma 0.05


def test_an_embedded_error_names_the_parameter_that_carries_it():
    rng = np.random.default_rng(5)
    a = 2.0 + 0.2 * rng.standard_normal(Q.size)             # a varies between conditions, b = 1.5 does not
    mean = np.stack([a * (1 - np.exp(-1.5 * Q)), a * Q / (1 + 1.5 * Q)], axis=1)
    d = Measurements(Q[:, None], mean[None] + SIGMA * rng.standard_normal((2, Q.size, 2)), SIGMA, sensors=["y1", "y2"])
    r = model_error(_model(), d, P0, splits=SPLITS, kind="embedded")
    assert r.kind == "embedded" and r.discrepancies == ()
    assert [e.name for e in r.embedded] == ["a", "b"]
    assert r.embedded[0].omega > 2 * r.embedded[1].omega
    assert r.embedded[0].relative == pytest.approx(r.embedded[0].omega / abs(r.p[0]))
    assert model_error(_model(), d, P0, kind="embedded", exact_at={"x": 0.0}).notes[-1].startswith("exact_at pins")
    assert all(h.coverage_embedded > h.coverage_plain + 0.1 for h in r.heldout)
    band = r.discrepancy([0.5, 1.5])
    assert np.all(band.mean == 0) and np.all(band.upper > band.lower)
    assert np.all(np.diag(r.cov) > np.diag(r.cov_plain))
    assert "spread between conditions" in r.summary()


def test_embedded_groups_share_their_deviation():
    rng = np.random.default_rng(7)
    groups = np.repeat(["g1", "g2", "g3", "g4", "g5"], 5)
    a = 2.0 + np.repeat(0.2 * rng.standard_normal(5), 5)     # one a per group of five rows
    mean = np.stack([a * (1 - np.exp(-1.5 * Q)), a * Q / (1 + 1.5 * Q)], axis=1)
    d = Measurements(Q[:, None], mean[None] + SIGMA * rng.standard_normal((2, Q.size, 2)), SIGMA, sensors=["y1", "y2"])
    by_group = model_error(_model(), d, P0, kind="embedded", groups=groups)
    by_row = model_error(_model(), d, P0, kind="embedded")
    assert by_group.embedded[0].omega > 2 * by_group.embedded[1].omega
    assert by_group.embedded[0].omega != pytest.approx(by_row.embedded[0].omega, rel=1e-3)
    assert np.sqrt(by_group.cov[0, 0]) > np.sqrt(by_row.cov[0, 0])       # five draws of b, not 25
    assert any("groups" in n for n in model_error(_model(), d, P0, kind="none", groups=groups).notes)
    grouped = model_error(_model(), d, P0, kind="discrepancy", groups=groups)     # the discrepancy uses them too
    assert grouped.groups == ("g1", "g2", "g3", "g4", "g5")
    assert not any("groups" in n for n in grouped.notes)


def test_adequate_model_mechanics():
    r = model_error(_model(), _data(False), P0, splits=SPLITS)
    t = r.test
    assert t.statistic >= 0 and 0 < t.p_value <= 1
    assert t.p_value == (1.0 if t.statistic == 0 else pytest.approx(0.5 * stats.chi2.sf(t.statistic, 1)))
    assert r.detected == (t.p_value < r.alpha)
    assert r.kind in ("none", "discrepancy", "embedded")
    assert r.kind == "none" or r.detected                # auto gives an error model only when the test detects one
    assert np.all(np.isfinite(r.conf_int().lower)) and np.all(np.isfinite(r.conf_int().upper))
    assert len(r.heldout) == 2 and all(0 <= h.coverage_plain <= 1 for h in r.heldout)


def test_kind_none_has_no_discrepancy():
    r = model_error(_model(), _data(True), P0, kind="none")
    assert r.kind == "none" and r.discrepancies == () and r.heldout == ()
    d = r.discrepancy([0.5, 1.0])
    assert np.all(d.mean == 0) and np.all(d.upper == d.lower)
    np.testing.assert_allclose(r.p, r.p_plain)
    assert any("detected" in n for n in r.notes)


def test_a_discrepancy_that_mimics_the_parameters_is_not_identifiable():
    m = Model.explicit(["a", "b"], ["x"], ["y"], h=lambda p, q: p[0] * q[0] + p[1] * q[0] ** 2)
    q = np.linspace(0, 1, 15)
    z = (2 * q + 0.5 * q ** 2 + 0.3 * np.sin(8 * q))[None, :, None] + 0.02 * np.random.default_rng(1).standard_normal((2, 15, 1))
    r = model_error(m, Measurements(q[:, None], z, 0.02, sensors=["y"]), [1.0, 1.0], kind="discrepancy")
    assert not r.identifiable and r.information_kept < 0.01
    assert any(n.startswith("not identifiable") and "exact_at" in n for n in r.notes)
    assert "NOT identifiable" in r.summary()
    assert np.all(np.sqrt(np.diag(r.cov)) > 10 * np.sqrt(np.diag(r.cov_plain)))


def test_predict_shapes_and_the_new_reading_band_is_wider(found):
    q = np.array([[0.1], [0.7], [1.9], [2.5]])
    mean_band = found.predict(q)
    new = found.predict(q, new_reading=True)
    assert mean_band.mean.shape == mean_band.lower.shape == new.upper.shape == (4, 2)
    np.testing.assert_allclose(new.mean, mean_band.mean)
    assert np.all(mean_band.lower < mean_band.mean) and np.all(mean_band.mean < mean_band.upper)
    assert np.all(new.upper - new.lower > mean_band.upper - mean_band.lower)
    assert np.all(found.predict(q, alpha=0.01).upper > mean_band.upper)
    assert found.predict([0.3, 0.4]).mean.shape == (2, 2)       # 1-D inputs of a one-input model


def test_exact_at_pins_the_discrepancy_and_its_slope():
    r = model_error(_model(), _data(True), P0, kind="discrepancy", exact_at={"x": 0.5})
    scale = max(d.amplitude for d in r.discrepancies)
    at = r.discrepancy([0.5])
    assert np.max(np.abs(at.mean)) < 1e-9 * scale and np.max(at.upper - at.lower) < 1e-9 * scale
    one, two = np.abs(r.discrepancy([0.501, 0.502]).mean)     # zero slope: grows like h^2, not h
    assert np.all(two > 3 * one) and np.all(two < 1e-3 * scale)
    far = r.discrepancy([1.5]).mean
    assert np.max(np.abs(far)) > 1e-3 * scale
    assert r.exact_at == {"x": 0.5}


def test_the_reml_gradient_is_exact():
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 2, (10, 1))
    counts = np.full((10, 2), 2.0)
    counts[4, 1] = 0
    sc = InputScaling.of(x, {"x": 0.7}, ("x",))
    obs = Observations.of(counts, np.array([0.1, 0.3]), np.ones(2), sc(x))
    n = sum(obs.sizes)
    G, r = rng.standard_normal((n, 2)), rng.standard_normal(n)
    for pins in ((), sc.pins):
        th = 0.4 * rng.standard_normal(6)
        f, g = reml_objective(th, obs, G, r, pins)
        fd = [(reml_objective(th + 1e-6 * e, obs, G, r, pins)[0] - reml_objective(th - 1e-6 * e, obs, G, r, pins)[0])
              / 2e-6 for e in np.eye(6)]
        np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-6)


def test_sigma_none_takes_the_pure_error_of_repeated_series():
    d = _data(True, n_series=3, sigma=None)
    r = model_error(_model(), d, P0, kind="discrepancy")
    dev = d.z - d.z.mean(axis=0)
    np.testing.assert_allclose(r.sigma, np.sqrt((dev ** 2).sum(axis=(0, 1)) / (2 * Q.size)))
    np.testing.assert_allclose(r.sigma, pure_error_sigma(d.z)[0])
    assert r.sigma_source.startswith("pure error") and any("pure error" in n for n in r.notes)


def test_weights_select_the_sensors():
    r = model_error(_model(), _data(True), P0, kind="discrepancy", weights=[0, 1])
    assert r.sensors == ("y2",) and [d.sensor for d in r.discrepancies] == ["y2"]
    b = r.predict([0.5])
    assert np.isnan(b.mean[0, 0]) and np.isfinite(b.mean[0, 1])


def test_result_protocol(found):
    s = found.summary()
    assert s.startswith("Model error of") and "DETECTED" in s and "interleaved" in s
    df = found.to_frame()
    assert list(df.index) == ["interleaved", "low vs high"]
    assert {"coverage_plain", "coverage_discrepancy", "coverage_embedded", "widening_discrepancy",
            "log_score_embedded"} <= set(df.columns)
    assert df.attrs["kind"] == "discrepancy"
    back = json.loads(json.dumps(found.to_dict()))
    assert back["kind"] == "discrepancy" and back["detected"] is True and len(back["heldout"]) == 2
    assert found._repr_html_().startswith("<pre>Model error of")
    ci = found.conf_int(0.1)
    assert np.all(ci.lower < found.p) and np.all(found.p < ci.upper)
    with pytest.raises(AttributeError):
        found.kind = "none"


@pytest.mark.parametrize("kwargs, data, match", [
    ({"exact_at": {"nope": 1.0}}, None, r"^exact_at: unknown input 'nope'"),
    ({"exact_at": {"x": float("nan")}}, None, r"^exact_at\['x'\]: expected a finite number"),
    ({"exact_at": {"x": "a"}}, None, r"^exact_at\['x'\]: expected a finite number"),
    ({"splits": [Split("tiny", [0], [1, 2])], "weights": [1, 0]}, None, r"^splits: split 'tiny' has 1 calibration"),
    ({"kind": "random"}, None, r"^kind: unknown kind 'random'"),
    ({"alpha": 0.7}, None, r"^alpha: must lie in"),
    ({"weights": [0, 0]}, None, r"^weights: select at least one sensor"),
    ({"groups": [1, 2, 3]}, None, r"^groups: expected one condition label per input row \(25\), got 3"),
    ({}, "three inputs", r"^data: 3 input x sensor means on the selected sensors; model_error needs at least"),
    ({}, "one series", r"^data: sigma is None and the data hold no repeated series"),
])
def test_bad_input_raises_one_clear_value_error(kwargs, data, match):
    d = _data(True, n_series=1, sigma=None) if data == "one series" else _data(True)
    if data == "three inputs":
        d = d.subset(inputs=[0, 5, 10]).select(["y1"])
        kwargs = {"weights": None}
        model = Model.explicit(["a", "b"], ["x"], ["y1"], h=lambda p, q: p[0] * q[0] + p[1])
    else:
        model = _model()
    with pytest.raises(ValueError, match=match) as info:
        model_error(model, d, P0, **kwargs)
    assert "\n" not in str(info.value)
