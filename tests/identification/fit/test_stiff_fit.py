"""Stiff models (issue 30, item 9): Robertson's kinetics fitted and designed with the discretisation error controlled."""
import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import oed
from identification import identify
from identification.fit.dynamic_fit import simulate_campaign
from mudoe.example_robertson import (CANDIDATE_TIMES, P_LOG10, P_TRUE, SIGMA, TIMES, build, jacobian_numpy,
                                     rhs_numpy)

Q = np.zeros((1, 0))


@pytest.fixture(scope="module")
def campaign():
    return simulate_campaign(build(), P_TRUE, Q, TIMES, SIGMA, n_series=1, seed=3)


def test_fit_recovers_the_rates_from_the_truth_and_a_rough_start(campaign):
    m = build()
    fits = [identify(m, campaign, p0=P_TRUE * f) for f in (1.0, 3.0, 1 / 3)]
    for est in fits:
        rec = est.diagnostics.discretisation
        assert rec.bounded and rec.error_sigma <= 0.01 and np.max(np.abs(rec.shift_se)) <= 0.01
        assert "discretisation: Radau IIA" in est.summary()
        z = (est.p - P_TRUE) / est.stderr
        assert np.all(np.abs(z) < 4)                     # the truth within 4 standard errors (seed 3: |z| <= 2.3)
        assert np.all(np.abs(est.p - fits[0].p) <= 1e-6 * est.stderr)    # one minimum from every start
    # the collocated trajectory at the estimate against Radau (rtol 1e-10) at the sampling times: within the
    # stated discretisation error (a factor 2), far below sigma
    est = fits[0]
    r = solve_ivp(rhs_numpy, (0.0, TIMES[-1]), [1.0, 0.0, 0.0], method="Radau", t_eval=TIMES, rtol=1e-10,
                  atol=1e-20, jac=jacobian_numpy, args=(est.p,))
    true = np.max(np.abs(est.fitted.reshape(TIMES.size, 3) - r.y.T) / SIGMA)
    assert true <= 2 * est.diagnostics.discretisation.error_sigma <= 0.02


def test_the_log10_parametrisation_gives_the_same_fit(campaign):
    est = identify(build("log10"), campaign, p0=P_LOG10 + np.log10(3.0))
    ref = identify(build(), campaign, p0=P_TRUE)
    assert np.allclose(10 ** est.p, ref.p, rtol=1e-6 * np.max(ref.stderr / ref.p))
    assert np.allclose(np.log(10) * 10 ** est.p * est.stderr_gn, ref.stderr_gn, rtol=1e-6)


def test_information_matches_cvodes_sensitivities_and_select_times_is_finite():
    # F = sum_k G_k^T G_k / sigma_k^2 per candidate time, G = dy/dk by CVODES (BDF, reltol 1e-10) with forward
    # sensitivities, an integrator independent of the collocation: the controlled mesh's information within
    # 1e-3 (relative, per entry scaled by sqrt(F_ii F_jj))
    m = build()
    t = CANDIDATE_TIMES[::3]
    info = oed.information(m, P_TRUE, axis="times", times=t, inputs=Q, sigma=SIGMA)
    x, k = ca.SX.sym("x", 3), ca.SX.sym("k", 3)
    ode = ca.vertcat(-k[0] * x[0] + k[1] * x[1] * x[2], k[0] * x[0] - k[1] * x[1] * x[2] - k[2] * x[1] ** 2,
                     k[2] * x[1] ** 2)
    cvodes = ca.integrator("robertson", "cvodes", {"x": x, "p": k, "ode": ode}, 0.0, t,
                           {"reltol": 1e-10, "abstol": 1e-20})
    kk = ca.MX.sym("k", 3)
    xf = cvodes(x0=ca.DM([1.0, 0.0, 0.0]), p=kk)["xf"]
    G = np.asarray(ca.Function("G", [kk], [ca.jacobian(ca.vec(xf), kk)])(P_TRUE)).reshape(t.size, 3, 3)
    G = G / SIGMA[None, :, None]
    F = np.einsum("tsp,tsq->tpq", G, G)
    d = np.sqrt(np.einsum("tii->ti", F))
    scale = d[:, :, None] * d[:, None, :] + 1e-300
    assert np.max(np.abs(info.F - F) / scale) < 1e-3
    # the exact D-optimal 6 of 25 log-spaced candidates: finite criterion, the same times with the rates or
    # their logarithms (D is invariant to the parametrisation), proven optimal
    rates = oed.select_times(m, P_TRUE, CANDIDATE_TIMES, Q, SIGMA, n_times=6)
    logs = oed.select_times(build("log10"), P_LOG10, CANDIDATE_TIMES, Q, SIGMA, n_times=6)
    assert np.isfinite(rates.value) and rates.proven_optimal and len(rates.chosen) == 6
    assert sorted(rates.chosen) == sorted(logs.chosen)


def test_rates_off_by_ten_in_opposite_directions_need_no_ipopt(campaign, monkeypatch):
    # from k x (3, 10, 0.1) the reduced-space Gauss-Newton step is halved more than five times on the first mesh;
    # Levenberg-Marquardt on the same exact Gauss-Newton model then brings the rates close enough for the
    # iteration to converge (before, Ipopt's full-space NLP took over there).  The same minimum as from the truth.
    import identification.fit.estimator as estimator
    ref = identify(build(), campaign, p0=P_TRUE)
    calls = []
    real = estimator.solve_nlp
    monkeypatch.setattr(estimator, "solve_nlp", lambda *a, **k: calls.append(1) or real(*a, **k))
    est = identify(build(), campaign, p0=P_TRUE * np.array([3.0, 10.0, 0.1]))
    assert calls == [] and "Ipopt was not needed" in est.message
    assert est.diagnostics.discretisation.bounded
    assert np.all(np.abs(est.p - ref.p) <= 1e-6 * ref.stderr)
