"""The normality gate's multiplicity correction (Algorithm 1, line 05; issue 20 item 5).

Known p-values check the adjustment itself; a Monte Carlo on exactly Gaussian data (4 series,
12 inputs, 20 sensors, N = 300 data sets, fixed seed) checks the gate's family-wise size.  With
uniform p-values the Holm/Bonferroni gate fails with probability 1 - (1 - 0.05/20)^20 = 4.9 %
(binomial standard error sqrt(0.049 * 0.951 / 300) = 1.25 %), the uncorrected gate with
1 - 0.95^20 = 64.2 % (standard error 2.8 %); the bands are 4 standard errors.
"""
import math

import numpy as np
import pytest

from identification import Measurements
from identification.studies.detect import DetectSettings, NormalityError, detect, normality_check
from identification.studies.montecarlo import shapiro_pvalues   # the batched gate p-values of the Monte Carlo
from identification.studies.normality import GATE_CORRECTIONS, adjusted_pvalues, correction_text, gate_fails

P = np.array([0.01, 0.04, 0.03, 0.5])


def test_adjusted_pvalues_of_known_values():
    # Holm: sorted 0.01, 0.03, 0.04, 0.5 -> 4*0.01, max(., 3*0.03), max(., 2*0.04), max(., 1*0.5)
    assert np.allclose(adjusted_pvalues(P, "holm"), [0.04, 0.09, 0.09, 0.5])
    assert np.allclose(adjusted_pvalues(P, "bonferroni"), [0.04, 0.16, 0.12, 1.0])
    assert np.array_equal(adjusted_pvalues(P, "none"), P)
    # Holm flags 0.01 only at 5 %; the per-sensor gate flags three sensors; both fail the gate
    assert gate_fails(P, 0.05, "holm") and gate_fails(P, 0.05, "none")
    assert not gate_fails(np.array([0.02, 0.04, 0.9]), 0.05, "holm")        # 3 * 0.02 = 0.06
    assert gate_fails(np.array([0.02, 0.04, 0.9]), 0.05, "none")


def test_gated_sensors_and_missing_pvalues():
    gated = [True, False, True, True]               # the family is 3 sensors: m = 3
    adj = adjusted_pvalues(P, "holm", gated)
    assert np.isnan(adj[1]) and np.allclose(adj[[0, 2, 3]], [0.03, 0.06, 0.5])
    # a sensor without a p-value counts in m, ranks last and fails the gate
    with_nan = np.array([0.2, np.nan, 0.3])
    assert np.allclose(adjusted_pvalues(with_nan, "holm")[[0, 2]], [0.6, 0.6])
    assert gate_fails(with_nan, 0.05, "holm") and not gate_fails(with_nan, 0.05, "holm", [True, False, True])
    # batched: one row per data set, the same decision as row by row
    rows = np.array([P, [0.2, 0.3, 0.4, 0.9], [0.011, 0.9, 0.9, 0.9]])
    for c in GATE_CORRECTIONS:
        assert np.array_equal(gate_fails(rows, 0.05, c), [gate_fails(r, 0.05, c) for r in rows])
    assert list(gate_fails(rows, 0.05, "holm")) == [True, False, True]
    assert not gate_fails(P, 0.05, "holm", [False] * 4)
    with pytest.raises(ValueError, match="correction"):
        adjusted_pvalues(P, "sidak")
    assert correction_text("holm", 0.05, 3) == "family-wise 5 % over 3 sensors (Holm)"


def _gaussian(rng, n_sensors, n_sets, n_series=4, n_inputs=12):
    q = np.linspace(0.0, 1.0, n_inputs)[:, None]
    return [Measurements(q, rng.standard_normal((n_series, n_inputs, n_sensors)), None,
                         sensors=[f"s{k}" for k in range(n_sensors)]) for _ in range(n_sets)]


def test_normality_check_applies_the_correction_and_names_it():
    rng = np.random.default_rng(3)
    data = _gaussian(rng, 20, 1)[0]
    # one sensor with a gross outlier in its differences: the gate fails under every correction
    z = data.z.copy()
    z[1, 4, 7] += 30.0
    bad = Measurements(data.inputs, z, None, sensors=data.sensors)
    for c in GATE_CORRECTIONS:
        chk = normality_check(bad, correction=c)
        assert not chk.passed and "s7" in chk.failing() and chk.correction == c
    holm = normality_check(bad)
    assert holm.correction == "holm" and np.allclose(holm.adjusted, adjusted_pvalues(holm.pvalue, "holm"))
    assert "family-wise 5 % over 20 sensors (Holm)" in holm.gate_text() and "holm p %" in holm.table()
    # the gate over the selected sensors only: m = 2
    w = np.zeros(20)
    w[[0, 1]] = 1.0
    sel = normality_check(data, weights=w)
    assert sel.gated == ("s0", "s1") and np.all(np.isnan(sel.adjusted[2:]))
    assert np.allclose(sel.adjusted[:2], adjusted_pvalues(sel.pvalue[:2], "holm"))
    with pytest.raises(ValueError, match="normality_correction"):
        DetectSettings(normality_correction="sidak")


def test_detect_gate_message_gives_adjusted_pvalues():
    from identification.studies.montecarlo import ModelCampaign
    from identification.studies.splits import Split
    from models.library import linear_model
    model = linear_model(np.array([[1.0, 0.3], [0.2, 1.0]]))
    data = ModelCampaign(model, [1.0, 2.0], np.linspace(0.1, 1.5, 12)[:, None], [0.01, 0.01], n_M=4)(
        np.random.default_rng(5))
    z = data.z.copy()
    z[1, 3, 0] += 1.0
    bad = Measurements(data.inputs, z, data.sigma, sensors=model.sensors)
    with pytest.raises(NormalityError, match=r"holm-adjusted over 2 sensors") as exc:
        detect(model, bad, [Split("a", range(6), range(6, 12))], p0=[1.0, 2.0])
    assert exc.value.check.correction == "holm" and not exc.value.check.passed


def test_gate_size_on_gaussian_data_is_family_wise():
    """300 Gaussian data sets, 20 sensors: Holm near 5 %, per-sensor gate near 64 % (bands 4 SE);
    the Monte Carlo's batched p-values give the same gate decision as normality_check."""
    n, m = 300, 20
    ds = _gaussian(np.random.default_rng(20), m, n)
    checks = [normality_check(d) for d in ds]
    pv = np.array([c.pvalue for c in checks])
    batched = np.array(shapiro_pvalues(ds))
    assert np.allclose(batched, pv, rtol=1e-9, atol=1e-12)
    fail_holm = np.array([not c.passed for c in checks])
    assert np.array_equal(fail_holm, gate_fails(batched, 0.05, "holm"))
    assert np.array_equal(fail_holm, gate_fails(batched, 0.05, "bonferroni"))   # same family decision
    p_holm = 1 - (1 - 0.05 / m) ** m
    se = math.sqrt(p_holm * (1 - p_holm) / n)
    assert abs(fail_holm.mean() - p_holm) <= 4 * se, fail_holm.mean()
    fail_none = gate_fails(batched, 0.05, "none")
    p_none = 1 - 0.95 ** m
    assert abs(fail_none.mean() - p_none) <= 4 * math.sqrt(p_none * (1 - p_none) / n), fail_none.mean()
