"""The report's uncertainty pages (issue 12): the README truss measured with one sensor.

configs/truss_one_sensor.toml (data in data/truss_one_sensor, simulated from the model itself):
the fit's linearisation is NOT trustworthy, so the report gets the pages "Uncertainty of linear"
(profile-likelihood intervals next to the Wald ones, the weakest direction, the likelihood-ratio
region next to the ellipse) and summary() says the same.  Checked from the texts drawn on the
pages (``reports.builder.page_texts``), not pixels.
"""
from pathlib import Path
from types import SimpleNamespace

import matplotlib
import numpy as np
import pytest
from scipy import optimize

matplotlib.use("Agg")

from identification import Measurements, identify  # noqa: E402
from identification.inference.profile import lr_region  # noqa: E402
from models import Model  # noqa: E402
from reports.view import fmt_value  # noqa: E402

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "truss_one_sensor.toml"


@pytest.fixture(scope="module")
def truss():
    from mudoe.config import load_config
    from mudoe.study import StudyResults, prepare, run_identify, run_uncertainty
    study = prepare(load_config(CONFIG))
    return run_uncertainty(study, run_identify(study, StudyResults(study)))       # [report] uncertainty: untrusted


@pytest.fixture(scope="module")
def truss_pages(truss):
    import matplotlib.pyplot as plt
    from mudoe.report_record import study_record
    from reports.builder import page_texts, report_pages
    pages = {}
    for name, make in report_pages(study_record(truss), None, False):
        if name.startswith("uncertainty"):
            figs = make()
            for k, fig in enumerate(figs if isinstance(figs, list) else [figs]):
                pages[f"{name}_{k}"] = page_texts(fig)
                plt.close(fig)
    return pages


def _cells(pages):
    return [t for texts in pages.values() for t in texts]


def test_truss_one_sensor_gets_uncertainty_pages_with_profile_intervals(truss, truss_pages):
    e = truss.estimates["linear"]
    assert not e.curvature.trustworthy
    assert len(truss_pages) == 2                     # table + profiles on one page, the k1-k2 region on another
    first = truss_pages["uncertainty1_0"]
    assert first[0] == "Uncertainty of linear: profile likelihood vs linearisation"
    warning = " ".join(first[1].split())
    assert warning.startswith("Do NOT trust the confidence ellipses and the +- standard errors of linear")
    assert "NOT trustworthy" in warning and "profile-likelihood intervals" in warning
    cells = _cells(truss_pages)
    assert "k1 (N/mm)" in cells and "k2 (N/mm)" in cells
    ci = e.conf_int(0.05, method="profile")
    wald = e.conf_int(0.05)
    for i, se in enumerate(e.stderr):
        lo, up = (fmt_value(x, se)[0] for x in (ci.lower[i], ci.upper[i]))
        assert f"[{lo}, {up}]" in cells                                       # the profile interval
        wl, wu = (fmt_value(x, se)[0] for x in wald[i])
        assert f"[{wl}, {wu}]" in cells                                       # next to the Wald one
        v, s = fmt_value(e.p[i], se)
        assert f"{v} +- {s}" in cells
    # the two intervals differ: the profile reaches much further up than the Wald interval
    assert np.all(ci.upper > wald[:, 1] + 2 * e.stderr)
    text = " ".join(" ".join(cells).split())
    assert "weakest direction" in text and "k1 + k2 is determined" in text
    assert "Likelihood-ratio regions of linear next to the linearised ellipses" in cells
    assert "95 % likelihood-ratio region" in cells and "95 % linearised ellipse" in cells
    assert "profile of k1" in cells and "profile of k2" in cells


def test_truss_one_sensor_region_is_resolved_and_longer_than_the_ellipse(truss):
    mu = truss.uncertainty["linear"]                # computed by the study (mudoe.uncertainty_runs)
    (pr,) = mu.regions
    reg = pr.region
    inside = reg.statistic <= reg.threshold
    assert inside.sum() >= 20                       # the valley grid resolves the thin region
    assert not any("edge of the grid" in n for n in reg.notes)
    # along k1 the region reaches beyond the ellipse's extent: the ellipse is a poor picture
    half = np.sqrt(reg.threshold * reg.cov[0, 0])
    assert reg.X[inside].max() > reg.estimate[0] + 1.5 * half


def test_truss_one_sensor_summary_warns_and_gives_profile_intervals(truss):
    from mudoe.uncertainty_runs import summary_intervals
    est = truss.estimates["linear"]
    assert "est.summary(intervals=ci)" in est.summary()
    ci = summary_intervals(est)                      # what `mudoe identify` passes: the profile intervals
    np.testing.assert_array_equal(np.asarray(ci), np.asarray(est.conf_int(method="profile")))
    s = est.summary(intervals=ci)
    assert "NOT trustworthy" in s and "conf_int(method=\"profile\")" in s
    assert "95 % profile intervals (trust these, not the Wald columns): k1 [" in s and "k2 [" in s
    assert "weakest direction" in s
    assert summary_intervals(_linear_results().estimates["lin"]) is None      # trustworthy: nothing computed


def test_identify_prints_the_profile_intervals_of_an_untrusted_fit(tmp_path, capsys):
    from mudoe.cli import main
    assert main(["identify", str(CONFIG), "--out", str(tmp_path), "--quiet"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "NOT trustworthy" in out and "95 % profile intervals (trust these, not the Wald columns): k1 [" in out
    assert "95 % profile intervals (trust these" in (tmp_path / "identify.txt").read_text()


def test_verdict_paragraph_points_to_the_uncertainty_pages(truss):
    from mudoe.report_record import study_record
    from reports.builder import verdict_paragraphs
    (v, par), = verdict_paragraphs(study_record(truss))
    assert "linearisation is NOT trustworthy" in par and "'Uncertainty of linear'" in par


def _linear_results():
    model = Model.explicit(params=["a", "b"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] + p[1] * q[0])
    x = np.linspace(0, 1, 6)
    z = (1 + 2 * x)[None, :, None] + 0.1 * np.random.default_rng(0).standard_normal((2, 6, 1))
    est = identify(model, Measurements(x, z, [0.1]), [0.0, 0.0])
    return SimpleNamespace(estimates={"lin": est})


def test_which_models_get_the_pages():
    from mudoe.uncertainty_runs import model_uncertainty, uncertainty_variants
    from record_stub import stub_record
    from reports.uncertainty import uncertainty_models
    r = _linear_results()
    assert uncertainty_variants(r.estimates) == []                 # trustworthy: no pages by default
    assert uncertainty_variants(r.estimates, "all") == ["lin"] and uncertainty_variants(r.estimates, "none") == []
    with pytest.raises(ValueError, match="uncertainty: expected one of"):
        uncertainty_variants(r.estimates, "some")
    mu = model_uncertainty(r.estimates["lin"], "lin", n_grid=7)
    shown = stub_record({"lin": r.estimates["lin"].model}, uncertainty={"lin": mu})   # what the study computed
    assert uncertainty_models(shown) == [] and uncertainty_models(shown, "all") == ["lin"]
    with pytest.raises(ValueError, match="uncertainty: expected one of"):
        uncertainty_models(shown, "some")
    assert mu.trust == "trustworthy" and mu.warning().startswith("The linearisation of lin is trustworthy")
    # a linear model with sigma known: the profile interval is the Wald interval (chi2_1 = z^2)
    np.testing.assert_allclose(mu.profile.array, mu.wald, rtol=1e-6)
    head, rows, flags = mu.interval_rows()
    assert rows[0][4] == "lower 1x, upper 1x" and not any(any(f) for f in flags)


def test_build_report_rejects_an_unknown_uncertainty_option(tmp_path):
    from reports.builder import build_report
    with pytest.raises(ValueError, match="uncertainty"):
        build_report(None, tmp_path, uncertainty="everything")


def test_valley_grid_reoptimises_the_other_parameters_against_scipy():
    """lr_region(grid="valley"): D at grid points equals 2 (min over c of Phi - Phi_hat) from scipy."""
    model = Model.explicit(params=["V", "K", "c"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] * q[0] / (p[1] + q[0]) + p[2], name="mm offset")
    x = np.array([0.5, 1.0, 2.0, 4.0, 8.0, 16.0])
    z = (10 * x / (6 + x) + 1)[None, :, None] + 0.15 * np.random.default_rng(5).standard_normal((2, x.size, 1))
    data = Measurements(x, z, [0.15])
    est = identify(model, data, [8.0, 5.0, 0.5])

    def phi(p):
        return 0.5 * float(np.sum(((z[:, :, 0] - (p[0] * x / (p[1] + x) + p[2])) / 0.15) ** 2))

    reg = lr_region(model, data, est, ("V", "K"), n_grid=7, grid="valley")
    assert reg.notes == () or all("edge" in n for n in reg.notes)
    assert np.all(reg.X[0] == reg.X[-1]) and np.all(np.diff(reg.X[0]) > 0)      # columns: fixed V
    for r, cc in [(0, 0), (3, 3), (6, 5), (2, 1)]:
        m = optimize.minimize_scalar(lambda t: phi([reg.X[r, cc], reg.Y[r, cc], t]), bracket=(0.0, 2.0), tol=1e-12)
        assert abs(reg.statistic[r, cc] - 2 * (m.fun - phi(est.p))) < 1e-6 * max(1, reg.statistic[r, cc])
    # the middle row follows the valley: there D is the profile of V (K and c re-optimised), the minimum over K
    mid = reg.statistic[3]
    assert np.all(mid <= reg.statistic.min(axis=0) + 1e-6)


def test_report_uncertainty_key_selects_the_pages(tmp_path, monkeypatch):
    """[report] uncertainty reaches build_report (default "untrusted"); a bad value names the key."""
    from mudoe.config import ConfigError, load_config
    from mudoe.report_record import study_record
    from mudoe.study import StudyResults, prepare
    import reports.builder as builder
    text = CONFIG.read_text().replace('"../data/truss_one_sensor"',
                                      f'"{(CONFIG.parent.parent / "data" / "truss_one_sensor").as_posix()}"')
    assert load_config(CONFIG).report.uncertainty == "untrusted"
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("[report]", '[report]\nuncertainty = "some"'))
    with pytest.raises(ConfigError, match="uncertainty"):
        load_config(bad)
    none = tmp_path / "none.toml"
    none.write_text(text.replace("[report]", '[report]\nuncertainty = "none"'))
    r = study_record(StudyResults(prepare(load_config(none))))

    class Seen(Exception):
        pass

    def spy(results, diagnosis, with_diagnosis, uncertainty):
        raise Seen(uncertainty)

    monkeypatch.setattr(builder, "report_pages", spy)
    out = tmp_path / "out"
    for given, expected in ((None, "none"), ("all", "all")):
        with pytest.raises(Seen, match=expected):
            builder.build_report(r, out, diagnose=False, uncertainty=given)
    assert list(out.iterdir()) == []                 # nothing half-written


def test_the_uncertainty_pages_only_draw_what_the_study_computed(truss, monkeypatch):
    """No profile, region or fit runs while the pages are drawn: they read ``results.uncertainty``."""
    import matplotlib.pyplot as plt
    import identification.inference.profile as profile
    from mudoe.report_record import study_record
    from reports.builder import page_texts, report_pages
    est = type(truss.estimates["linear"])

    def no_computation(*args, **kwargs):
        raise AssertionError("the report computed")

    monkeypatch.setattr(est, "conf_int", no_computation)
    monkeypatch.setattr(profile, "lr_region", no_computation)
    monkeypatch.setattr(profile, "profile_intervals", no_computation, raising=False)
    texts = []
    for name, make in report_pages(study_record(truss), None, False):
        if name.startswith("uncertainty"):
            for fig in make():
                texts += page_texts(fig)
                plt.close(fig)
    assert "Likelihood-ratio regions of linear next to the linearised ellipses" in texts
