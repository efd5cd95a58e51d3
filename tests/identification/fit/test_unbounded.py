"""Practical non-identifiability as a result (issue 20 item 4, :mod:`identification.fit.unbounded`).

The weak Michaelis-Menten study of ``bench/bench_weak_mm.py``: y = Vm x / (K + x), Vm = 10,
K = 20, x = 0.5..4 (far below saturation), 2 series, sigma = 0.1 known.  Campaigns 3, 5 and 12
raised IdentifiabilityError before (the best fit runs off to infinity along Vm / K = const);
now identify returns an estimate that is not bounded.  The profile checks are exact: the limit of
the objective is the least-squares fit of the linear limit y = a x (closed form) and the finite
lower profile limit is checked by scipy's bounded minimisation over log K.
"""
import math

import casadi as ca
import numpy as np
import pytest
from scipy import optimize, stats

from identification import (IdentifiabilityError, Measurements, NotBoundedError, identify)
from identification.studies.detect import DetectSettings, run_split_tests
from identification.studies.montecarlo import BATCHED, ONE_BY_ONE, MonteCarloSettings, size_study
from identification.studies.splits import series_split
from models import Model

VM, K, SIGMA = 10.0, 20.0, 0.1
X = np.array([0.5, 1.0, 2.0, 3.0, 4.0])


def _model():
    return Model.explicit(params=["Vm", "K"], inputs=["x"], sensors=["y"],
                          h=lambda p, q: p[0] * q[0] / (p[1] + q[0]), name="Michaelis-Menten")


def _campaign(seed, n_M=2):
    rng = np.random.default_rng(seed)
    z = (VM * X / (K + X))[None, :, None] + SIGMA * rng.standard_normal((n_M, X.size, 1))
    return Measurements(inputs=X[:, None], z=z, sigma=[SIGMA])


def _linear_limit(data):
    """(a, Phi_inf) of the least-squares line y = a x through the origin (the limit of the run-off)."""
    zs = data.z[:, :, 0]
    a = float(np.sum(zs * X) / (zs.shape[0] * np.sum(X ** 2)))
    return a, 0.5 * float(np.sum((zs - a * X) ** 2)) / SIGMA ** 2


@pytest.mark.parametrize("seed", [3, 5, 12])
def test_weak_michaelis_menten_is_not_bounded_and_says_what_the_data_determine(seed):
    data = _campaign(seed)
    est = identify(_model(), data, [VM, K])                      # raised IdentifiabilityError before
    assert not est.bounded and est.status == "Not_Bounded"
    u = est.unbounded
    assert u.involved == ("Vm", "K") and u.ends() == {"Vm": "+inf", "K": "+inf"}
    np.testing.assert_allclose(u.direction, [math.sqrt(0.5)] * 2, atol=1e-3)   # Vm/K fixed
    a, phi_inf = _linear_limit(data)
    (text, value, rse), = u.combinations
    assert text == "Vm/K" and abs(value - a) < 1e-5 * a and 0 < rse < 0.1
    assert abs(u.objective_limit - phi_inf) < 1e-6
    assert np.all(np.isinf(est.stderr))
    ci = est.conf_int(0.05, method="profile")
    assert np.all(np.isfinite(ci.lower)) and np.all(ci.upper == np.inf)
    # the finite end: 2 (min_K Phi(Vm = lower, K) - Phi_inf) = chi2_1(0.95), checked by scipy
    lower = float(ci.lower[0])

    def phi(lk):
        r = data.z[:, :, 0] - lower * X / (math.exp(lk) + X)
        return 0.5 * float(np.sum(r ** 2)) / SIGMA ** 2

    best = optimize.minimize_scalar(phi, bounds=(-5.0, 40.0), method="bounded", options={"xatol": 1e-12}).fun
    assert abs(2 * (best - phi_inf) - stats.chi2.ppf(0.95, 1)) < 1e-6
    text = est.summary()
    assert "NOT BOUNDED" in text and "Vm/K =" in text and "-> +inf" in text
    with pytest.raises(NotBoundedError, match="Vm, K"):
        est.ellipsoid(0.05)
    with pytest.raises(NotBoundedError):
        est.curvature


def test_bounded_campaign_is_unchanged():
    est = identify(_model(), _campaign(0), [VM, K])
    assert est.bounded and est.unbounded is None and est.success and np.all(np.isfinite(est.stderr))


def test_structural_rank_deficiency_at_a_finite_point_is_still_an_error_and_says_so():
    model = Model.explicit(params=["a", "b"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] * p[1] * q[0])
    data = Measurements(np.arange(1.0, 6.0), np.arange(1.0, 6.0).reshape(1, 5, 1) * 2, [0.1])
    with pytest.raises(IdentifiabilityError, match="structurally not identifiable at a finite point") as exc:
        identify(model, data, p0=[1.0, 0.5])
    assert set(exc.value.params) == {"a", "b"} and "not data that fail to bound" in str(exc.value)


def _unbounded_series_seed():
    """A campaign whose first series alone does not bound Vm, K (its second does)."""
    m = _model()
    for seed in range(100):
        d = _campaign(seed)
        one = Measurements(inputs=X[:, None], z=d.z[:1], sigma=[SIGMA])
        two = Measurements(inputs=X[:, None], z=d.z[1:], sigma=[SIGMA])
        if not identify(m, one, [VM, K]).bounded and identify(m, two, [VM, K]).bounded:
            return seed
    raise AssertionError("no such campaign among 100")


def test_detect_counts_a_fit_that_is_not_bounded_as_undecided_with_its_reason():
    from identification.studies.detect import decide
    data = _campaign(_unbounded_series_seed())
    split = series_split(X.size, [0], [1], name="series 1 vs 2")
    t, = run_split_tests(_model(), data, [split], [VM, K], settings=DetectSettings(normality="override"))
    assert not t.ok and t.stage == "calibration fit" and t.error.startswith("not bounded: the data do not bound Vm, K")
    d = decide([t], 0.05)
    assert d.decision == "undecided" and "not bounded" in d.reason and d.failed == ("series 1 vs 2",)


@pytest.mark.parametrize("fits", [BATCHED, ONE_BY_ONE])
def test_monte_carlo_counts_fits_that_are_not_bounded(fits):
    split = series_split(X.size, [0], [1], name="series 1 vs 2")
    settings = MonteCarloSettings(n_rep=40, seed=3, workers=1, progress=False, fits=fits,
                                  detect=DetectSettings(normality="override"))
    res = size_study(_model(), [VM, K], X[:, None], [SIGMA], [split], settings=settings)
    nb = res.n_not_bounded()
    assert nb >= 1                      # a single series of 5 points far below saturation: often unbounded
    assert nb == sum(1 for e in res.errors if "not bounded:" in e[4])
    assert res.n_undecided() >= nb and "did not bound the parameters" in res.summary()


def test_sigma_unknown_run_off_is_not_bounded_with_the_F_profile():
    """With sigma estimated (s^2 = RSS / (n - n_p) at the limit) the profile threshold is F(1, n - n_p)."""
    d = _campaign(3)
    data = Measurements(inputs=d.inputs, z=d.z, sigma=None)
    est = identify(_model(), data, [VM, K])
    assert not est.bounded and est.sigma_estimated
    ci = est.conf_int(0.05, method="profile")
    assert np.all(np.isfinite(ci.lower)) and np.all(ci.upper == np.inf)
    a, _ = _linear_limit(data)
    (text, value, _), = est.unbounded.combinations
    assert text == "Vm/K" and abs(value - a) < 1e-5 * a


def test_batch_keeps_an_unbounded_member_as_not_ok_with_its_reason():
    from identification.fit.batch import fit_batch
    fit = fit_batch(_model(), [_campaign(s) for s in (0, 3, 1)], [VM, K])
    assert list(fit.ok) == [True, False, True] and np.all(np.isnan(fit.p[1]))
    rec, = [f for f in fit.fallbacks if f.member == 1]
    assert rec.error.startswith("not bounded:") and not fit.result(1).bounded


def test_profile_of_a_bounded_fit_whose_constrained_fits_run_off():
    """y = c + Vm x / (K + x) with x = 0..4: the profile of c fixes c at values where the other two run
    off; the constrained infimum is the profile's value there (this raised LinAlgError before)."""
    m3 = Model.explicit(params=["c", "Vm", "K"], inputs=["x"], sensors=["y"],
                        h=lambda p, q: p[0] + p[1] * q[0] / (p[2] + q[0]), name="MM3")
    x3 = np.array([0.0, 0.5, 1, 2, 3, 4.0])
    rng = np.random.default_rng(23)
    z = (1 + VM * x3 / (K + x3))[None, :, None] + SIGMA * rng.standard_normal((2, x3.size, 1))
    est = identify(m3, Measurements(x3[:, None], z, [SIGMA]), [1.0, VM, K])
    assert est.bounded
    ci = est.conf_int(0.05, method="profile")
    assert ci.lower[0] < est.p[0] < ci.upper[0] and np.isfinite(ci.lower[0]) and np.isfinite(ci.upper[0])


def test_the_other_side_of_infinity_is_named_unless_bounds_exclude_it():
    """Without bounds a finite minimum with Vm, K < 0 can lie beyond infinity (seed 3: Vm = -10.1,
    K = -26.5, objective 10.46 < 11.19); the estimate says so, and not once Vm, K >= 0 are declared."""
    data = _campaign(3)
    free = identify(_model(), data, [VM, K])
    assert any("no bound excludes the other sign of Vm, K" in n for n in free.notes)
    positive = _model().with_bounds({"Vm": (0.0, math.inf), "K": (0.0, math.inf)})
    est = identify(positive, data, [VM, K])
    assert not est.bounded and not any("other sign" in n for n in est.notes)
    np.testing.assert_allclose(est.conf_int(0.05, method="profile").lower,
                               free.conf_int(0.05, method="profile").lower, rtol=1e-8)


def test_an_ill_conditioned_success_far_out_on_a_run_off_is_not_bounded():
    """Campaign 1844 (bounds Vm, K >= 0): the Newton iteration stopped at Vm = 2.4e6 with a tiny step and
    reported success; the objective still decreases beyond it.  Its K profile's finite end is checked in
    closed form (the profile of K is a linear least-squares problem in Vm)."""
    positive = _model().with_bounds({"Vm": (0.0, math.inf), "K": (0.0, math.inf)})
    data = _campaign(1844)
    est = identify(positive, data, [VM, K])
    assert not est.bounded and est.unbounded.involved == ("Vm", "K")
    lo_k = est.conf_int(0.05, method="profile", params="K").lower[0]
    zs = data.z[:, :, 0]
    g = X / (lo_k + X)
    vm = np.sum(zs * g) / (2 * np.sum(g * g))
    _, phi_inf = _linear_limit(data)
    D = 2 * (0.5 * np.sum((zs - vm * g) ** 2) / SIGMA ** 2 - phi_inf)
    assert abs(D - stats.chi2.ppf(0.95, 1)) < 1e-6
