"""Algorithm 1 (detect): the three statistics, Bonferroni / Holm, normality gate, failures, errors."""
import dataclasses
import re

import casadi as ca
import numpy as np
import pytest

from identification import DataError, Measurements, alpha_min, alpha_min_two_sample, identify, simulate
from identification.studies.detect import (DetectSettings, NormalityError, SplitTest, decide, detect, normality_check,
                                   run_split_tests)
from identification.studies.splits import Split, input_range_split, splits_from_scenarios
from models.contract import Model
from models.library import linear_model
from models.press import PRESS_SCENARIOS

Q = np.r_[np.linspace(0.0, 1.6, 15), np.linspace(1.6, 0.0, 15)[1:]][:, None]   # loading-unloading, 29 loads
X = np.array([[1.0, 0.3], [0.2, 1.0]])
P_TRUE = np.array([1.0, 2.0])
SIGMA = np.array([0.01, 0.02])
PAPER_SPLITS = splits_from_scenarios(PRESS_SCENARIOS, len(Q))   # the paper's four scenarios


@pytest.fixture(scope="module")
def model():
    return linear_model(X)


def campaign(model, seed, n_M=2, offset_unloading=0.0):
    rng = np.random.default_rng(seed)
    H = simulate(model, P_TRUE, Q)
    z = H[None] + SIGMA * rng.standard_normal((n_M,) + H.shape)
    z[:, 15:, 0] += offset_unloading        # a "hysteresis": unloading sits higher on sensor 1
    return Measurements(Q, z, SIGMA, sensors=model.sensors)


def test_correct_model_is_accepted_and_statistics_match_regions(model):
    data = campaign(model, 1)
    res = detect(model, data, PAPER_SPLITS, p0=[0.5, 1.5])
    assert res.verdicts[model.name] == "not rejected"
    assert res.decision().statistic == "likelihood_ratio" and res.decision().correction == "bonferroni"
    assert len(res.tests) == 4 and all(t.ok for t in res.tests)
    # every number equals the identification API applied by hand
    for sp, t in zip(PAPER_SPLITS, res.tests):
        ec = identify(model, sp.calibration(data), [0.5, 1.5])
        ev = identify(model, sp.validation(data), [0.5, 1.5])
        assert t.alpha_paper == pytest.approx(alpha_min(ev.p, ec.p, ec.cov), rel=1e-6, abs=1e-12)
        assert t.alpha_two_sample == pytest.approx(alpha_min_two_sample(ev.p, ec.p, ec.cov, ev.cov), rel=1e-6,
                                                   abs=1e-12)
        # C_cal + C_val >= C_cal, so the paper's alpha is never larger
        assert t.alpha_paper <= t.alpha_two_sample + 1e-12
        # linear model, known sigma: the likelihood ratio IS the two-sample Wald statistic
        assert t.lr == pytest.approx(t.d2_two_sample, rel=1e-7, abs=1e-10)
        assert t.alpha_lr == pytest.approx(t.alpha_two_sample, rel=1e-6, abs=1e-12)
        eu = identify(model, sp.pooled(data), [0.5, 1.5])
        assert t.lr == pytest.approx(2 * (eu.objective - ec.objective - ev.objective), rel=1e-8, abs=1e-10)
    text = res.summary()
    assert "alpha paper %" in text and "alpha 2-sample %" in text and "alpha LR %" in text
    assert re.search(r">> likelihood_ratio bonferroni: not rejected +\(", text)
    assert "Normality gate" in text and "sigma_rep" in text
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.tests = ()


def test_hysteresis_is_detected_on_loading_vs_unloading(model):
    data = campaign(model, 2, offset_unloading=0.05)      # 5 sigma offset on the unloading branch
    res = detect(model, data, PAPER_SPLITS, p0=[0.5, 1.5], statistic="paper")
    for st in ("paper", "two_sample", "likelihood_ratio"):
        d = res.decision(statistic=st)
        assert d.decision == "rejected"
        assert "loading vs unloading" in d.flagged
    assert res.decision().statistic == "paper"
    assert re.search(r">> paper +bonferroni: rejected +\(", res.summary())


def test_several_models_and_sensor_design(model):
    # truth with a curvature c q^2 (c = 0.05 per unit input^2); the linear model misses it
    curved = Model.explicit(["b1", "b2"], ["q"], ["s1", "s2"], name="curved",
                            h=lambda p, q: q[0] * (ca.DM(X) @ p) + 0.05 * q[0] ** 2)
    rng = np.random.default_rng(3)
    H = simulate(curved, P_TRUE, Q)
    data = Measurements(Q, H[None] + SIGMA * rng.standard_normal((2,) + H.shape), SIGMA, sensors=model.sensors)
    splits = PAPER_SPLITS + (input_range_split(Q, exclude=(0, 28)),)
    res = detect({"M_true": curved, "M_linear": model}, data, splits, p0=[0.5, 1.5])
    assert res.verdicts["M_true"] == "not rejected"
    assert res.verdicts["M_linear"] == "rejected"
    # a consistent misfit is invisible to splits with the same load range (both directions, alternate
    # points): only the input-range split sees the curvature
    assert res.decision("M_linear").flagged == (splits[-1].name,)
    assert len(res.normality) == 2 and res.normality[0][1] is res.normality[1][1]   # checked once
    r1 = detect(model, data, PAPER_SPLITS, p0=[0.5, 1.5], design=["s1", "s2"])
    assert r1.design[0][1] == ("s1", "s2")
    with pytest.raises(Exception, match="weights, design"):
        detect(model, data, PAPER_SPLITS, p0=[0.5, 1.5], design=["s1"], weights=[1, 0])
    with pytest.raises(Exception, match="design: unknown sensor"):
        detect(model, data, PAPER_SPLITS, p0=[0.5, 1.5], design=["nope"])


def test_failed_fit_is_recorded_and_makes_the_verdict_undecided(model):
    data = campaign(model, 4)
    # calibration on the unloaded point q = 0 only: no information on p (not identifiable)
    splits = (PAPER_SPLITS[0], Split("degenerate", [0, 28], [1, 2, 3]))
    res = detect(model, data, splits, p0=[0.5, 1.5])
    bad = res.tests[1]
    assert not bad.ok and bad.stage == "calibration fit" and "Identifiab" in bad.error
    assert np.isnan(bad.alpha_two_sample)
    d = res.decision()
    assert d.decision == "undecided" and "degenerate" in d.reason and d.n_tests == 2
    assert "failed" in res.summary()


def test_fits_given_as_errors_or_failure_texts_are_recorded_as_typed_failures(model):
    """run_split_tests(fits=..., pooled=...): a fit's error or a failure text becomes a FitFailure whose reason
    is the split test's error (or lr_error); an estimate given is used as it is."""
    from identification import IdentificationError
    from identification.studies.split_tests import FitFailure
    data = campaign(model, 4)
    sp = PAPER_SPLITS[0]
    ec, ev = identify(model, sp.calibration(data), [0.5, 1.5]), identify(model, sp.validation(data), [0.5, 1.5])
    boom = IdentificationError("no convergence")
    assert FitFailure.of_entry(boom) == FitFailure("IdentificationError: no convergence", "IdentificationError")
    assert FitFailure.of_entry("pooled fit failed: x") == FitFailure("pooled fit failed: x", "")
    assert FitFailure.of_entry(ec) is ec
    with pytest.raises(ZeroDivisionError):
        FitFailure.of_entry(ZeroDivisionError("not a fit error"))
    t, = run_split_tests(model, data, [sp], [0.5, 1.5], fits=[(boom, ev)])
    assert not t.ok and t.stage == "calibration fit" and t.error == "IdentificationError: no convergence"
    t, = run_split_tests(model, data, [sp], [0.5, 1.5], fits=[(ec, FitFailure("validation broke", "DataError"))])
    assert not t.ok and t.stage == "validation fit" and t.error == "validation broke"
    assert np.array_equal(t.p_cal, ec.p) and t.n_cal == ec.n_data
    key = sp.pooled_key(data.n_M)
    t, = run_split_tests(model, data, [sp], [0.5, 1.5], fits=[(ec, ev)], pooled={key: "pooled fit failed: given"})
    assert t.ok and t.lr_error == "pooled fit failed: given" and np.isnan(t.alpha_lr)
    ref, = run_split_tests(model, data, [sp], [0.5, 1.5])
    assert t.alpha_two_sample == ref.alpha_two_sample and np.isfinite(ref.alpha_lr)


def test_a_set_whose_data_cannot_be_built_is_a_failed_fit_of_that_set(model):
    """A validation set holding no finite value of a sensor: the DataError of building its data is recorded
    at the validation fit (never raised), with the calibration estimate kept."""
    data = campaign(model, 4)
    z = np.array(data.z)
    z[:, 20:, 0] = np.nan
    holes = Measurements(Q, z, SIGMA, sensors=model.sensors)
    t, = run_split_tests(model, holes, [Split("late", range(20), range(20, 29))], [0.5, 1.5])
    assert not t.ok and t.stage == "validation fit" and t.error.startswith("DataError: z: sensor 's1'")
    assert np.all(np.isfinite(t.p_cal)) and np.all(np.isnan(t.p_val))


def test_tol_and_option_errors(model):
    data = campaign(model, 5)
    for tol in (0.0, 1.0, -0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="tol"):
            detect(model, data, PAPER_SPLITS, p0=[1, 2], alpha=tol)
    with pytest.raises(ValueError, match="statistic"):
        detect(model, data, PAPER_SPLITS, p0=[1, 2], statistic="wald")
    with pytest.raises(ValueError, match="correction"):
        detect(model, data, PAPER_SPLITS, p0=[1, 2], correction="sidak")
    with pytest.raises(ValueError, match="normality"):
        detect(model, data, PAPER_SPLITS, p0=[1, 2], normality="skip")
    with pytest.raises(Exception, match="p0"):
        detect(model, data, PAPER_SPLITS, p0=[1, 2, 3])
    with pytest.raises(Exception, match="splits"):
        detect(model, data, [], p0=[1, 2])
    with pytest.raises(Exception, match="val_inputs index 40"):
        detect(model, data, [Split("far", [1], [40])], p0=[1, 2])
    one = Measurements(Q, data.z[:1], SIGMA)
    with pytest.raises(Exception, match="'thin'.*calibration set has 1 points x 1 sensor"):
        detect(model, one, [Split("thin", [3], [4, 5])], p0=[1, 2], weights=[1, 0], normality="override")


def test_normality_gate_raises_or_records_the_override(model):
    rng = np.random.default_rng(6)
    H = simulate(model, P_TRUE, Q)
    # strongly skewed errors: exponential, 6 series
    z = H[None] + SIGMA * (rng.exponential(1.0, (6,) + H.shape) ** 3)
    data = Measurements(Q, z, SIGMA, sensors=model.sensors)
    with pytest.raises(NormalityError, match="line 05.*Shapiro-Wilk") as exc:
        detect(model, data, PAPER_SPLITS, p0=[0.5, 1.5])
    assert not exc.value.check.passed
    res = detect(model, data, PAPER_SPLITS, p0=[0.5, 1.5], normality="override")
    assert res.normality[0][1].overridden
    assert "overridden" in res.summary() and "override" in res.summary()


def test_repeatability_sigma_is_std_of_differences_over_sqrt2(model):
    data = campaign(model, 7, n_M=6)
    chk = normality_check(data)
    assert chk.pairs == ((0, 1), (2, 3), (4, 5))
    for k in range(2):
        d = np.concatenate([data.z[b, :, k] - data.z[a, :, k] for a, b in chk.pairs])
        assert chk.sigma_rep[k] == pytest.approx(np.std(d, ddof=1) / np.sqrt(2), rel=1e-12)
        # 87 differences: the relative standard error of a sample sd is 1/sqrt(2 * 86) = 7.6 %;
        # the band 25 % is 3.3 standard errors
        assert chk.sigma_rep[k] == pytest.approx(SIGMA[k], rel=0.25)
    one = Measurements(Q, data.z[:1], SIGMA)
    assert not normality_check(one).passed


def _t(name, a):
    n = np.full(2, np.nan)
    return SplitTest(model="m", split=name, cal_label="", val_label="", ok=True, stage="", error="", p_cal=n, p_val=n,
                     C_cal=np.eye(2), C_val=np.eye(2), d2_paper=1.0, d2_two_sample=1.0, alpha_paper=a,
                     alpha_two_sample=a, lr=1.0, alpha_lr=a)


def test_bonferroni_and_holm():
    tests = [_t("a", 0.001), _t("b", 0.015), _t("c", 0.3), _t("d", 0.5)]
    b = decide(tests, 0.05, "two_sample", "bonferroni")
    h = decide(tests, 0.05, "two_sample", "holm")
    assert b.flagged == ("a",) and h.flagged == ("a", "b")       # 0.015 < 0.05/3 but >= 0.05/4
    assert b.decision == h.decision == "rejected" and b.threshold == pytest.approx(0.0125)
    ok = [_t("a", 0.0126), _t("b", 0.9)]
    assert decide(ok, 0.05).decision == "rejected"                 # 0.0126 < 0.025
    assert decide([_t("a", 0.0126)] * 4, 0.05).decision == "not rejected"
    with pytest.raises(ValueError, match="tol"):
        decide(tests, 1.0)
    with pytest.raises(ValueError, match="correction"):
        decide(tests, 0.05, correction="x")
    assert DetectSettings().statistic == "likelihood_ratio"
    for st in ("likelihood_ratio", "paper"):
        assert decide(tests, 0.05, st).flagged == ("a",)
    with pytest.raises(ValueError, match="statistic"):
        decide(tests, 0.05, "wald")
    # a split whose pooled fit failed: LR undecided, the Wald statistics still decide
    lost = dataclasses.replace(_t("a", 0.5), alpha_lr=float("nan"), lr_error="pooled fit failed: x")
    d = decide([lost, _t("b", 0.4)], 0.05, "likelihood_ratio")
    assert d.decision == "undecided" and d.failed == ("a",) and "pooled fit failed" in d.reason
    assert decide([lost, _t("b", 0.4)], 0.05, "two_sample").decision == "not rejected"


def test_design_from_the_oed_front_door():
    pytest.importorskip("oed.design", reason="oed.design (issue 4) not available")
    X3 = np.array([[1.0, 0.3], [0.2, 1.0], [1.0, 1.02]])     # sensor 3 nearly repeats a combination
    m3 = linear_model(X3)
    rng = np.random.default_rng(8)
    H = simulate(m3, P_TRUE, Q)
    sig = np.array([0.01, 0.02, 0.01])
    data = Measurements(Q, H[None] + sig * rng.standard_normal((2,) + H.shape), sig, sensors=m3.sensors)
    # lines 02-03 first (the OED at the fit on all sensors), then detect on the chosen sensors
    from oed import select_sensors
    est = identify(m3, data, [0.5, 1.5])
    des = select_sensors(m3, data, est.p, criterion="E", n_sensors=m3.n_p, sensor_names=list(m3.sensors))
    res = detect(m3, data, PAPER_SPLITS, p0=[0.5, 1.5], design=des.sensors,
                 design_how=f"{des.criterion}-optimal design of {len(des.sensors)} sensors")
    used = res.design[0][1]
    assert len(used) == 2 and "E-optimal" in res.design[0][2]
    assert res.verdicts[m3.name] == "not rejected"


def test_a_criterion_as_design_asks_for_the_oed_first(model):
    data = campaign(model, 9)
    for crit in ("E", "D", "s1"):
        with pytest.raises(DataError, match=r"oed\.select_sensors\(model, data, p, criterion="):
            detect(model, data, PAPER_SPLITS, p0=[0.5, 1.5], design=crit)


def test_keywords_and_settings_together_are_an_error(model):
    data = campaign(model, 10)
    s = DetectSettings(tol=0.1)
    with pytest.raises(TypeError, match="settings and tol"):
        detect(model, data, PAPER_SPLITS, p0=[0.5, 1.5], alpha=0.05, settings=s)
    with pytest.raises(TypeError, match="settings and statistic, normality"):
        detect(model, data, PAPER_SPLITS, p0=[0.5, 1.5], statistic="paper", normality="override", settings=s)
    with pytest.raises(TypeError, match="settings: expected DetectSettings"):
        detect(model, data, PAPER_SPLITS, p0=[0.5, 1.5], settings={"tol": 0.1})
    res = detect(model, data, PAPER_SPLITS[:1], p0=[0.5, 1.5], settings=s)
    assert res.settings is s and res.decision().tol == 0.1
    assert detect(model, data, PAPER_SPLITS[:1], p0=[0.5, 1.5], alpha=0.1).settings == s


def test_likelihood_ratio_with_unknown_sigma_is_the_chow_f_test(model):
    """sigma estimated: F = ((RSS_pooled - RSS_c - RSS_v) / n_p) / ((RSS_c + RSS_v) / (n_c + n_v - 2 n_p))."""
    from scipy import stats
    rng = np.random.default_rng(7)
    H = simulate(model, P_TRUE, Q)
    z = H[None] + 0.01 * rng.standard_normal((2,) + H.shape)
    data = Measurements(Q, z, None, sensors=model.sensors)
    sp = PAPER_SPLITS[2]
    t = detect(model, data, [sp], p0=[0.5, 1.5]).tests[0]

    def rss(d):
        A = np.concatenate([np.kron(np.ones((d.n_M, 1)), d.inputs[:, :1] * X[k]) for k in range(2)])
        b = np.concatenate([d.z[:, :, k].ravel() for k in range(2)])
        ok = np.isfinite(b)
        res = np.linalg.lstsq(A[ok], b[ok], rcond=None)
        return float(np.sum((A[ok] @ res[0] - b[ok]) ** 2)), int(ok.sum())

    (rc, nc), (rv, nv), (ru, _) = rss(sp.calibration(data)), rss(sp.validation(data)), rss(sp.pooled(data))
    F = ((ru - rc - rv) / 2) / ((rc + rv) / (nc + nv - 4))
    assert t.lr == pytest.approx(F, rel=1e-6)
    assert t.alpha_lr == pytest.approx(stats.f.sf(F, 2, nc + nv - 4), rel=1e-6)


def test_pooled_newton_equals_the_pooled_ipopt_fit_on_the_press():
    """The likelihood ratio's pooled minimum (reduced Newton from p_bar) is the full-space fit's."""
    from identification.studies.split_tests import pooled_newton
    from identification.studies.montecarlo import ModelCampaign
    from models.press import Q_PAPER, press_model
    model = press_model()
    sigma = np.array([1.518e-02, 4.895e-03, 3.904e-03])
    w = np.array([1.0, 1.0, 0.0])
    gen = ModelCampaign(model, model.p_nominal, np.array(Q_PAPER)[:, None], sigma, 2)
    for r in range(2):
        data = gen(np.random.default_rng(100 + r))
        for sp in PAPER_SPLITS:
            ec = identify(model, sp.calibration(data), [450.0, 550.0], w)
            ev = identify(model, sp.validation(data), [450.0, 550.0], w)
            pm = pooled_newton(model, sp.pooled(data), sp, ec, ev, w)
            eu = identify(model, sp.pooled(data), [450.0, 550.0], w)
            assert pm is not None
            np.testing.assert_allclose(pm.p, eu.p, rtol=1e-7)
            assert pm.objective == pytest.approx(eu.objective, rel=1e-9)


# ---------------------------------------------------------------- linearisation failures (issue 12, item 5)
def _weak_campaign(seed):
    """Michaelis-Menten observed far below saturation (x << K): Vm and K nearly confounded."""
    mm = Model.explicit(params=["Vm", "K"], inputs=["x"], sensors=["y"],
                        h=lambda p, q: p[0] * q[0] / (p[1] + q[0]))
    x = np.linspace(0.2, 1.0, 8)[:, None]
    h = simulate(mm, [1.0, 5.0], x)
    z = h[None] + 0.01 * np.random.default_rng(seed).standard_normal((2,) + h.shape)
    return mm, Measurements(x, z, [0.01], sensors=mm.sensors)


def test_untrustworthy_fits_switch_the_decision_to_the_likelihood_ratio():
    mm, data = _weak_campaign(5)
    splits = (Split("odd vs even", tuple(range(0, 8, 2)), tuple(range(1, 8, 2))),)
    res = detect(mm, data, splits, p0=[1.0, 5.0], statistic="two_sample", normality="override")
    t = res.tests[0]
    assert t.ok and t.trustworthy is False and "parameter-effects" in t.curvature_note
    d = res.decision()
    assert d.statistic == "likelihood_ratio" and "instead of two_sample" in d.reason
    assert res.verdicts[mm.name] == d.decision
    assert res.decision(statistic="two_sample").statistic == "two_sample"     # still reported
    text = res.summary()
    assert "NOT trustworthy" in text and "~" in text and "the likelihood ratio decides" in text
    assert "the likelihood ratio decides instead" in text.splitlines()[2]
    # the default statistic keeps its decision and says why it is the right one here
    res_lr = detect(mm, data, splits, p0=[1.0, 5.0], normality="override")
    assert res_lr.decision().statistic == "likelihood_ratio"
    assert "parametrisation invariant" in res_lr.decision().reason


def test_split_tests_skip_curvature_unless_asked(model):
    data = campaign(model, 1)
    t = run_split_tests(model, data, PAPER_SPLITS[:1], [0.5, 1.5])[0]
    assert t.trustworthy is None
    t = run_split_tests(model, data, PAPER_SPLITS[:1], [0.5, 1.5], curvature=True)[0]
    assert t.trustworthy is True and t.curvature_note == ""      # a linear model has zero curvature


def test_statistics_disagreeing_by_orders_of_magnitude_get_a_note(model):
    data = campaign(model, 1)
    res = detect(model, data, PAPER_SPLITS, p0=[0.5, 1.5])
    assert "disagree" not in res.summary()
    t = dataclasses.replace(res.tests[0], alpha_lr=0.3, alpha_two_sample=0.2, alpha_paper=1e-4)
    bad = dataclasses.replace(res, tests=(t,) + res.tests[1:])
    text = bad.summary()
    assert "disagree by orders of magnitude" in text and "ratio 3e+03" in text
    assert re.search(r"\[\d+\] .*loading: odd vs even: the statistics disagree", text)
    # a factor 1000 on the same side of the line (all reject) is no alarm
    t2 = dataclasses.replace(res.tests[0], alpha_lr=1e-3, alpha_two_sample=1e-4, alpha_paper=1e-6)
    assert "disagree" not in dataclasses.replace(res, tests=(t2,) + res.tests[1:]).summary()


def test_progress_bar_counts_every_split_and_is_off_by_default(model, capsys):
    import io

    from identification.progress import Progress
    data = campaign(model, 1)
    stream = io.StringIO()
    res = detect(model, data, PAPER_SPLITS, p0=[0.5, 1.5], progress=Progress(stream=stream))
    shown = stream.getvalue()
    assert f"detect {model.name}" in shown and "4/4" in shown and "split" in shown
    quiet = detect(model, data, PAPER_SPLITS, p0=[0.5, 1.5])
    assert capsys.readouterr().err == ""
    assert [t.alpha_lr for t in quiet.tests] == [t.alpha_lr for t in res.tests]
    with pytest.raises(TypeError, match="progress"):
        detect(model, data, PAPER_SPLITS, p0=[0.5, 1.5], progress=True)


def test_normality_check_names_the_series_it_ran_on(model):
    """The gate says which series were differenced (labels of the data), so that terminal, JSON and
    report can label its p-values; sigma_rep is shown in a caller's unit."""
    data = campaign(model, 4, n_M=6)
    chk = normality_check(data)
    assert chk.series_text() == "1-6" and chk.pairs_text() == "z2-z1, z4-z3, z6-z5"
    held = normality_check(data.subset(series=[4, 5]))
    assert held.series == ("5", "6") and held.series_text() == "5, 6" and held.pairs_text() == "z6-z5"
    named = normality_check(Measurements(Q, data.z[:2], SIGMA, sensors=model.sensors, series=["run A", "run B"]))
    assert named.series_text() == "run A, run B" and named.pairs_text() == "z(run B)-z(run A)"
    text = held.table(units={s: (1e3, "um") for s in model.sensors}, data_name="study series")
    head, first = text.splitlines()[:2]
    assert "SW p % (study series)" in head and "sigma_rep (study series)" in head
    assert first.split()[2:4] == [f"{1e3 * held.sigma_rep[0]:.4g}", "um"]
