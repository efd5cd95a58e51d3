"""Bates-Watts relative curvature (identification.inference.curvature, Estimate.curvature)."""
import casadi as ca
import numpy as np
import pytest
from scipy import linalg, stats

from identification import Measurements, identify
from identification.inference.curvature import relative_curvature
from models import Model
from models.sensitivity import sensitivities

# Bates & Watts (1988), appendix A1.3: Puromycin, treated cells
CONC = np.array([0.02, 0.02, 0.06, 0.06, 0.11, 0.11, 0.22, 0.22, 0.56, 0.56, 1.10, 1.10])
RATE = np.array([76, 47, 97, 107, 123, 139, 159, 152, 191, 201, 207, 200.0])


def _mm(inverse_k=False):
    if inverse_k:
        return Model.explicit(params=["Vm", "iK"], inputs=["x"], sensors=["y"],
                              h=lambda p, q: p[0] * q[0] / (1 / p[1] + q[0]))
    return Model.explicit(params=["Vm", "K"], inputs=["x"], sensors=["y"],
                          h=lambda p, q: p[0] * q[0] / (p[1] + q[0]))


def _puromycin_fit(inverse_k=False):
    data = Measurements(inputs=CONC, z=RATE.reshape(1, -1, 1), sigma=None)
    return identify(_mm(inverse_k), data, p0=[200.0, 10.0] if inverse_k else [200.0, 0.1])


def _independent_curvatures(f, p, s, n_angles=20000):
    """Bates-Watts curvatures by central finite differences of f and a brute-force angle search
    with the full QR (Q2 for the normal part): an implementation independent of the library's."""
    p = np.asarray(p, float)
    n_p = p.size
    h = 1e-4 * np.abs(p)
    V1 = np.column_stack([(f(p + h[a] * np.eye(n_p)[a]) - f(p - h[a] * np.eye(n_p)[a])) / (2 * h[a])
                          for a in range(n_p)])
    V2 = np.zeros((V1.shape[0], n_p, n_p))
    for a in range(n_p):
        for b in range(n_p):
            ea, eb = h[a] * np.eye(n_p)[a], h[b] * np.eye(n_p)[b]
            V2[:, a, b] = (f(p + ea + eb) - f(p + ea - eb) - f(p - ea + eb) + f(p - ea - eb)) / (4 * h[a] * h[b])
    Q, R = linalg.qr(V1)
    Rinv = linalg.inv(R[:n_p])
    rho = s * np.sqrt(n_p)
    t = np.linspace(0, np.pi, n_angles, endpoint=False)
    D = Rinv @ np.vstack([np.cos(t), np.sin(t)])           # parameter directions of unit tangent length
    acc = np.einsum("nab,ak,bk->nk", V2, D, D)
    proj = Q.T @ acc
    gT = rho * np.max(np.linalg.norm(proj[:n_p], axis=0))
    gN = rho * np.max(np.linalg.norm(proj[n_p:], axis=0))
    return gN, gT


def test_linear_model_has_zero_curvature():
    x = np.linspace(0, 1, 9)
    model = Model.explicit(params=["a", "b"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] + p[1] * q[0])
    z = 1 + 2 * x + 0.01 * np.random.default_rng(0).standard_normal(x.size)
    est = identify(model, Measurements(inputs=x, z=z.reshape(1, -1, 1), sigma=[0.01]), p0=[0.0, 0.0])
    c = est.curvature
    assert c.intrinsic == 0.0 and c.parameter_effects == 0.0 and c.trustworthy
    assert c.critical == pytest.approx(1 / np.sqrt(stats.f.ppf(0.95, 2, x.size - 2)))


def test_puromycin_matches_independent_finite_difference_computation():
    est = _puromycin_fit()
    s = np.sqrt(est.rss / est.dof)
    gN, gT = _independent_curvatures(lambda p: p[0] * CONC / (p[1] + CONC), est.p, s)
    c = est.curvature
    assert c.intrinsic == pytest.approx(gN, rel=1e-4)
    assert c.parameter_effects == pytest.approx(gT, rel=1e-4)
    assert c.trustworthy            # Puromycin is the textbook close-to-linear example
    assert c.critical == pytest.approx(1 / np.sqrt(stats.f.ppf(0.95, 2, 10)))


def test_intrinsic_curvature_is_invariant_under_reparametrisation():
    c1 = _puromycin_fit().curvature
    c2 = _puromycin_fit(inverse_k=True).curvature        # K -> 1/K
    assert c2.intrinsic == pytest.approx(c1.intrinsic, rel=1e-6)
    assert abs(c2.parameter_effects - c1.parameter_effects) > 0.5 * c1.parameter_effects


def test_output_hessians_of_an_implicit_model_match_finite_differences_of_G():
    model = Model(params=["k", "c"], inputs=["F"], sensors=["u", "v"], n_y=1,
                  E=lambda y, p, q: p[0] * y[0] + p[1] * y[0] ** 3 - q[0],
                  h=lambda y, p, q: ca.vertcat(y[0], p[0] * y[0] ** 2))
    F = np.linspace(0.5, 3.0, 6)[:, None]
    p = np.array([2.0, 0.7])

    def G_at(pp):
        Y = np.array([[np.roots([pp[1], 0, pp[0], -f])[np.isreal(np.roots([pp[1], 0, pp[0], -f]))].real[0]]
                      for f in F[:, 0]])
        return sensitivities(model, pp, F, Y)

    Hh = G_at(p).output_hessians()
    eps = 1e-6
    for a in range(2):
        e = eps * np.eye(2)[a]
        fd = (G_at(p + e).G - G_at(p - e).G) / (2 * eps)        # (n_q, n_S, n_p): d G[..., b] / dp_a
        np.testing.assert_allclose(Hh[:, :, a, :], fd, rtol=1e-6, atol=1e-8)


def test_weak_model_is_flagged_and_summary_names_profile():
    # Michaelis-Menten far below saturation (x << K): Vm and K are nearly confounded
    model = Model.explicit(params=["Vm", "K"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] * q[0] / (p[1] + q[0]))
    # (x in [0.2, 1] instead leaves the least-squares minimum at infinity for some noise draws, seed 3
    # among them: identify now reports those as failed fits, see test_estimator's absurd-estimate test)
    x = np.linspace(0.5, 2.0, 5)
    truth = np.array([1.0, 5.0])
    h = truth[0] * x / (truth[1] + x)
    z = h + 0.01 * np.random.default_rng(3).standard_normal((2, x.size))
    est = identify(model, Measurements(inputs=x, z=z[:, :, None], sigma=[0.01]), p0=truth)
    c = est.curvature
    assert not c.trustworthy and c.parameter_effects > c.critical
    text = est.summary()
    assert "NOT trustworthy" in text and 'conf_int(method="profile")' in text


def test_bad_input_names_the_argument():
    with pytest.raises(ValueError, match="alpha"):
        relative_curvature(np.eye(3)[:, :2], np.zeros((3, 2, 2)), 1, alpha=1.5)
    with pytest.raises(ValueError, match="V2"):
        relative_curvature(np.eye(3)[:, :2], np.zeros((3, 2, 3)), 1)


def test_sloppy_direction_names_the_confounded_combination():
    from identification.fit.checks import sloppy_direction
    # information of y = a (k1 + k2) measured precisely plus k1 - k2 measured poorly: relative scale 1
    u, v = np.array([1.0, 1.0]) / np.sqrt(2), np.array([1.0, -1.0]) / np.sqrt(2)
    F = 1e6 * np.outer(u, u) + 1.0 * np.outer(v, v)
    sd = sloppy_direction(F, [1.0, 1.0], ["k1", "k2"])
    assert sd.ratio == pytest.approx(1000.0)
    assert sd.combination(sd.sloppy) == "k1 - k2" and sd.combination(sd.stiff) == "k1 + k2"
    assert "k1 - k2 is determined 1000x worse than k1 + k2" in str(sd)
    # scaling by |p|: the same information at p = (1, 100) names relative changes
    sd2 = sloppy_direction(F / np.outer([1, 100], [1, 100]), [1.0, 100.0], ["k1", "k2"])
    assert sd2.ratio == pytest.approx(1000.0) and sd2.combination(sd2.sloppy) == "k1 - k2"
    assert sloppy_direction(np.eye(1), [2.0], ["a"]) is None
    with pytest.raises(ValueError, match="information"):
        sloppy_direction(np.eye(3), [1.0, 2.0], ["a", "b"])


def test_sloppy_direction_of_a_parameter_at_zero_uses_its_standard_error():
    # issue 30: Tc = 0 on its bound (se 1e-5 N m) next to R = 1 ohm (se 1e-2): dividing by 1 (its unit) made
    # Tc "determined 1e3x better"/"worse" by the unit chosen; scaled by its standard error it is one se
    from identification.fit.checks import sloppy_direction
    se = np.array([1e-2, 1e-5])
    F = np.diag(1.0 / se ** 2)
    old = sloppy_direction(F, [1.0, 0.0], ["R", "Tc"])
    assert old.ratio == pytest.approx(1e3) and old.by_stderr == ()
    sd = sloppy_direction(F, [1.0, 0.0], ["R", "Tc"], stderr=se)
    assert sd.scale.tolist() == [1.0, 1e-5] and sd.by_stderr == ("Tc",)
    assert sd.ratio == pytest.approx(100.0) and sd.combination(sd.sloppy) == "Tc"
    assert "(relative changes dp/|p|, dp/se for Tc): Tc is determined 100x worse than R" in str(sd)
    # |p| above its standard error: unchanged; a non-finite standard error is ignored
    same = sloppy_direction(F, [1.0, 2.0], ["R", "Tc"], stderr=[1e-2, np.inf])
    assert same.ratio == pytest.approx(sloppy_direction(F, [1.0, 2.0], ["R", "Tc"]).ratio) and same.by_stderr == ()


def test_summary_shows_the_weakest_direction():
    est = _puromycin_fit()
    sd = est.sloppy_direction
    lam = np.linalg.eigvalsh(est.information * np.outer(est.p, est.p))
    assert sd.ratio == pytest.approx(np.sqrt(lam[-1] / lam[0]))
    assert str(sd) in est.summary()


def test_summary_of_an_untrusted_fit_shows_the_profile_intervals():
    # the same weak Michaelis-Menten fit: summary() only reads; it says how to get the profile intervals and
    # shows them when given
    model = Model.explicit(params=["Vm", "K"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] * q[0] / (p[1] + q[0]))
    x = np.linspace(0.5, 2.0, 5)
    truth = np.array([1.0, 5.0])
    z = truth[0] * x / (truth[1] + x) + 0.01 * np.random.default_rng(3).standard_normal((2, x.size))
    est = identify(model, Measurements(inputs=x, z=z[:, :, None], sigma=[0.01]), p0=truth)
    ci = est.conf_int(method="profile")
    assert "est.summary(intervals=ci)" in est.summary() and "Vm [" not in est.summary()
    text = est.summary(intervals=ci)
    assert "95 % profile intervals (trust these, not the Wald columns)" in text
    assert f"Vm [{ci.lower[0]:.5g}, {ci.upper[0]:.5g}]" in text and f"K [{ci.lower[1]:.5g}, {ci.upper[1]:.5g}]" in text
