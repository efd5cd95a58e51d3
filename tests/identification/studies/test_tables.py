"""pandas tables and Jupyter views of the results users copy: Estimate.to_frame / _repr_html_,
DetectionResult.to_frame / _repr_html_ (every value of a frame is the result's own number)."""
from html import escape

import numpy as np
import pandas as pd
import pytest

from identification import Measurements, identify, simulate
from identification.studies.detect import detect
from identification.studies.splits import Split
from models.contract import Model
from models.library import linear_model

X = np.array([[1.0, 0.3], [0.2, 1.0]])
SIGMA = np.array([0.01, 0.02])
Q = np.linspace(0.0, 1.6, 12)[:, None]


@pytest.fixture(scope="module")
def case():
    model = linear_model(X)
    H = simulate(model, [1.0, 2.0], Q)
    z = H[None] + SIGMA * np.random.default_rng(5).standard_normal((2,) + H.shape)
    return model, Measurements(Q, z, SIGMA, sensors=model.sensors)


def test_estimate_frame_holds_the_estimate_its_standard_errors_and_wald_intervals(case):
    model, data = case
    est = identify(model, data, [0.5, 1.5])
    df = est.to_frame(alpha=0.1)
    assert list(df.index) == list(est.param_names) and df.index.name == "parameter"
    assert list(df.columns) == ["estimate", "stderr", "stderr_gn", "wald_lower", "wald_upper", "unit"]
    ci = est.conf_int(0.1)
    assert np.array_equal(df["estimate"].to_numpy(), est.p)
    assert np.array_equal(df["stderr"].to_numpy(), est.stderr)
    assert np.array_equal(df["stderr_gn"].to_numpy(), est.stderr_gn)
    assert np.array_equal(df["wald_lower"].to_numpy(), ci.lower)
    assert np.array_equal(df["wald_upper"].to_numpy(), ci.upper)
    assert list(df["unit"]) == list(est.param_units)
    assert df.attrs["alpha"] == 0.1 and df.attrs["kind"] == "second_order"
    gn = est.to_frame(kind="gauss_newton")
    assert np.array_equal(gn["wald_upper"].to_numpy(), est.conf_int(0.05, kind="gauss_newton").upper)


def test_estimate_html_shows_the_parameters_values_and_notes(case):
    model, data = case
    est = identify(model, data, [0.5, 1.5])
    html = est._repr_html_()
    assert html.count("<table") == 1
    for i, name in enumerate(est.param_names):
        assert f"<th>{name}</th>" in html
        assert f"{est.p[i]:.7g}" in html and f"{est.stderr[i]:.7g}" in html


def test_estimate_html_lists_the_summary_notes():
    """Michaelis-Menten far below saturation: the curvature notes of the summary appear in the HTML."""
    mm = Model.explicit(params=["Vm", "K"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] * q[0] / (p[1] + q[0]))
    x = np.linspace(0.2, 1.0, 8)[:, None]
    z = simulate(mm, [1.0, 5.0], x)[None] + 0.01 * np.random.default_rng(1).standard_normal((2, 8, 1))
    est = identify(mm, Measurements(x, z, [0.01], sensors=mm.sensors), [1.0, 5.0])
    notes = est._summary_notes(None)
    assert notes and any("NOT trustworthy" in n for n in notes)
    html = est._repr_html_()
    assert "<ol>" in html and all(f"<li>{escape(n)}</li>" in html for n in notes)


def test_detection_frame_has_one_row_per_split_test_with_its_alphas_and_decision(case):
    model, data = case
    splits = [Split("low vs high", range(6), range(6, 12)), Split("even vs odd", range(0, 12, 2), range(1, 12, 2))]
    res = detect(model, data, splits, [0.5, 1.5])
    df = res.to_frame()
    assert list(df.index) == [(t.model, t.split) for t in res.tests]
    for col in ("alpha_lr", "alpha_two_sample", "alpha_paper", "lr", "d2_two_sample", "d2_paper"):
        assert np.array_equal(df[col].to_numpy(), np.array([getattr(t, col) for t in res.tests]))
    st = res.settings.statistic
    assert np.array_equal(df[f"alpha_{'lr' if st == 'likelihood_ratio' else st}"].to_numpy(), res.alphas())
    assert list(df["n_cal"]) == [t.n_cal for t in res.tests] and list(df["ok"]) == [t.ok for t in res.tests]
    assert list(df["model_decision"]) == [res.verdicts[model.name]] * len(res.tests)
    assert list(df["split_rejected"]) == [t.split in res.decision().flagged for t in res.tests]
    assert "rejected" not in df.columns and "decision" not in df.columns     # issue 30: the level is named
    assert df.attrs["tol"] == res.settings.tol and df.attrs["statistic"] == st
    html = res._repr_html_()
    assert res.verdicts[model.name] in html and "low vs high" in html and "even vs odd" in html
    assert f"{res.tests[0].alpha_lr:.4g}" in html and "<details>" in html
    assert isinstance(df, pd.DataFrame)


def test_html_of_an_estimate_the_data_do_not_bound_shows_the_run_off():
    """Michaelis-Menten far below saturation with few data (seed 3 runs off to Vm, K -> inf): infinite
    standard errors in the frame, the text summary (where the parameters run off) in the HTML."""
    mm = Model.explicit(params=["Vm", "K"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] * q[0] / (p[1] + q[0]))
    x = np.array([0.5, 1.0, 2.0, 3.0, 4.0])
    z = (10.0 * x / (20.0 + x))[None, :, None] + 0.1 * np.random.default_rng(3).standard_normal((2, x.size, 1))
    est = identify(mm, Measurements(inputs=x[:, None], z=z, sigma=[0.1]), [10.0, 20.0])
    assert not est.bounded
    df = est.to_frame()
    assert np.all(np.isinf(df["stderr"].to_numpy())) and np.array_equal(df["estimate"].to_numpy(), est.p)
    html = est._repr_html_()
    assert "<table" in html and escape(est.summary()) in html
