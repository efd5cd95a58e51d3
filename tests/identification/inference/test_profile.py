"""Profile-likelihood intervals and likelihood-ratio regions (identification.inference.profile, issue 12).

Checked against independent computations: scipy.optimize.minimize of the objective with the
parameter fixed (small explicit model, sigma known) and lmfit's ``conf_interval`` (F test,
sigma estimated) on NIST StRD problems; the pair region against the exact quadratic form of a
linear model and against scipy on a curved one.
"""
from __future__ import annotations

import dataclasses
import importlib.util
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from scipy import optimize, stats

from identification import Measurements, identify
from identification.inference.profile import (ConfidenceIntervals, ProfileError, ProfileSettings, lr_region,
                                    profile_intervals)
from models import Model


def _nist():
    name = "_mudoe_tests_nist_strd"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, Path(__file__).resolve().parents[1] / "fit" / "nist.py")
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    return sys.modules[name]


def _exp_problem(sigma=0.4, seed=2):
    """y = b1 (1 - exp(-b2 x)), 8 inputs, 3 series, sigma known: curved, well identified."""
    model = Model.explicit(params=["b1", "b2"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])), name="exp rise")
    x = np.linspace(0.2, 3.0, 8)
    b = np.array([10.0, 0.7])
    h = b[0] * (1 - np.exp(-b[1] * x))
    z = h[None, :, None] + sigma * np.random.default_rng(seed).standard_normal((3, x.size, 1))
    data = Measurements(x, z, [sigma])
    return model, data, identify(model, data, [8.0, 1.0])


def _mm_problem(seed=5):
    """Michaelis-Menten below saturation, 3 parameters (an offset), sigma known."""
    model = Model.explicit(params=["V", "K", "c"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] * q[0] / (p[1] + q[0]) + p[2], name="mm offset")
    x = np.array([0.5, 1.0, 2.0, 4.0, 8.0, 16.0])
    b = np.array([10.0, 6.0, 1.0])
    h = b[0] * x / (b[1] + x) + b[2]
    sig = 0.15
    z = h[None, :, None] + sig * np.random.default_rng(seed).standard_normal((2, x.size, 1))
    data = Measurements(x, z, [sig])
    return model, data, identify(model, data, [8.0, 5.0, 0.5])


# ---------------------------------------------------------------------------- conf_int arguments
def test_conf_int_wald_default_unchanged_and_validated():
    model, data, est = _exp_problem()
    c = stats.norm.ppf(0.975)
    ci = est.conf_int()
    # one result type whatever the method: ConfidenceIntervals, an (m, 2) array through np.asarray, a DataFrame
    assert isinstance(ci, ConfidenceIntervals) and ci.method == "wald" and np.asarray(ci).shape == (2, 2)
    frame = ci.to_frame()
    assert list(frame.index) == ["b1", "b2"] and list(frame.columns) == ["estimate", "lower", "upper"]
    np.testing.assert_array_equal(frame[["lower", "upper"]].to_numpy(), np.asarray(ci))
    assert ci["b2"] == (ci.lower[1], ci.upper[1]) and ci[1, 0] == ci.lower[1]
    np.testing.assert_allclose(ci, np.column_stack([est.p - c * est.stderr, est.p + c * est.stderr]), rtol=1e-14)
    np.testing.assert_array_equal(est.conf_int(0.05, params=["b2"]), np.asarray(ci)[[1]])
    with pytest.raises(ValueError, match="alpha is the miss probability: 0.05 gives a 95 % interval"):
        est.conf_int(0.95)
    with pytest.raises(ValueError, match="alpha"):
        est.conf_int(0.0)
    with pytest.raises(ValueError, match="method.*'wald', 'profile', 'bootstrap'"):
        est.conf_int(method="likelihood")
    with pytest.raises(ValueError, match="params: unknown parameter 'b3'; the parameters are b1, b2"):
        est.conf_int(params=["b3"])
    with pytest.raises(ValueError, match="model, data"):          # an Estimate not made by identify()
        dataclasses.replace(est, model=None, data=None).conf_int(method="profile")
    # identify() keeps the model and the data: the profile needs no arguments
    np.testing.assert_array_equal(est.conf_int(method="profile").array,
                                  est.conf_int(method="profile", model=model, data=data).array)


# ---------------------------------------------------------------------------- against scipy
def test_profile_matches_scipy_fixed_parameter_minimisation():
    """Interval ends == roots of 2 (min_{b_other} Phi - Phi_hat) = chi2_1(0.95), the inner minimum by scipy."""
    model, data, est = _exp_problem()
    x, z, sig = data.inputs[:, 0], data.z[:, :, 0], float(data.sigma[0])

    def phi(b1, b2):
        return 0.5 * float(np.sum(((z - b1 * (1 - np.exp(-b2 * x)))[...] / sig) ** 2))

    phi_hat = phi(*est.p)
    c = stats.chi2.ppf(0.95, 1)

    def prof(i, v):
        other = 1 - i
        f = (lambda t: phi(v, t[0])) if i == 0 else (lambda t: phi(t[0], v))
        r = optimize.minimize(f, [est.p[other]], method="Nelder-Mead",
                              options={"xatol": 1e-12, "fatol": 1e-14, "maxiter": 4000})
        return 2 * (r.fun - phi_hat) - c

    ci = est.conf_int(0.05, method="profile", model=model, data=data)
    assert isinstance(ci, ConfidenceIntervals) and ci.method == "profile" and ci.notes == ()
    wald = est.conf_int(0.05)
    for i in range(2):
        half = wald[i, 1] - est.p[i]
        lo = optimize.brentq(lambda v: prof(i, v), est.p[i] - 3 * half, est.p[i], xtol=1e-10)
        up = optimize.brentq(lambda v: prof(i, v), est.p[i], est.p[i] + 3 * half, xtol=1e-10)
        assert abs(ci.lower[i] - lo) < 1e-6 * half, (i, ci.lower[i], lo)
        assert abs(ci.upper[i] - up) < 1e-6 * half, (i, ci.upper[i], up)
        # the profile is asymmetric here: it differs from Wald by more than the tolerance
        assert abs(ci.upper[i] - wald[i, 1]) > 1e-3 * half
        # and every point of the recorded path is a constrained minimum
        pr = ci.profiles[i]
        for v, D in zip(pr.values[::3], pr.statistic[::3]):
            assert abs(prof(i, v) + c - D) < 1e-7 * max(1.0, D)


def test_profile_three_parameters_against_scipy():
    model, data, est = _mm_problem()
    x, z, sig = data.inputs[:, 0], data.z[:, :, 0], float(data.sigma[0])

    def phi(p):
        return 0.5 * float(np.sum(((z - (p[0] * x / (p[1] + x) + p[2])) / sig) ** 2))

    phi_hat = phi(est.p)
    ci = est.conf_int(0.05, method="profile", model=model, data=data, params=["K"])
    assert ci.param_names == ("K",)
    assert np.isfinite(ci.lower[0]) and np.isfinite(ci.upper[0])
    for v in (ci.lower[0], ci.upper[0]):
        r = optimize.minimize(lambda t: phi([t[0], v, t[1]]), est.p[[0, 2]], method="BFGS",
                              options={"gtol": 1e-10})
        assert abs(2 * (r.fun - phi_hat) - stats.chi2.ppf(0.95, 1)) < 1e-5


# ---------------------------------------------------------------------------- against lmfit (F test)
@pytest.mark.parametrize("name", ["Misra1a", "BoxBOD", "DanWood", "Rat42"])
def test_profile_matches_lmfit_conf_interval_on_nist(name):
    lmfit = pytest.importorskip("lmfit")
    nist = _nist()
    d = nist.load(name)
    fun = nist.MODELS[name]
    model = Model.explicit(params=[f"b{i + 1}" for i in range(d.n_p)], inputs=["x"], sensors=["y"],
                           h=lambda p, q: fun(p, q[0]), name=name)
    data = Measurements(d.x.reshape(-1, 1), d.y.reshape(1, -1, 1), sigma=None)
    est = identify(model, data, d.start1.copy())
    ci = est.conf_int(0.05, method="profile", model=model, data=data)

    def resid(params):
        b = np.array([params[f"b{i + 1}"].value for i in range(d.n_p)])
        return np.asarray(fun(b, d.x)).ravel() - d.y

    params = lmfit.Parameters()
    for i in range(d.n_p):
        params.add(f"b{i + 1}", value=float(d.certified[i]))
    mini = lmfit.Minimizer(resid, params)
    res = mini.minimize(method="leastsq", xtol=1e-14, ftol=1e-14)
    ref = lmfit.conf_interval(mini, res, sigmas=[0.95])
    for i in range(d.n_p):
        lo = ref[f"b{i + 1}"][0][1]
        up = ref[f"b{i + 1}"][-1][1]
        half = up - lo
        # lmfit stops its root finder at rtol 5e-4 in the parameter
        assert abs(ci.lower[i] - lo) < 1e-3 * half + 5e-4 * abs(lo), (name, i, ci.lower[i], lo)
        assert abs(ci.upper[i] - up) < 1e-3 * half + 5e-4 * abs(up), (name, i, ci.upper[i], up)


# ---------------------------------------------------------------------------- unbounded and failure
def test_unbounded_side_is_infinite_with_note():
    """Michaelis-Menten far below saturation: V and K are only known through V/K; no upper end."""
    model = Model.explicit(params=["V", "K"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] * q[0] / (p[1] + q[0]), name="mm")
    x = np.array([0.5, 1.0, 2.0, 3.0, 5.0])
    h = 10.0 * x / (20.0 + x)
    z = h[None, :, None] + 0.05 * np.random.default_rng(3).standard_normal((2, x.size, 1))
    data = Measurements(x, z, [0.05])
    est = identify(model, data, [8.0, 15.0])
    ci = est.conf_int(0.05, method="profile", model=model, data=data)
    assert np.all(np.isposinf(ci.upper)) and np.all(np.isfinite(ci.lower))
    assert len(ci.notes) == 2 and all("upper end is unbounded" in n for n in ci.notes)
    assert np.all(ci.lower > est.conf_int(0.05)[:, 0])


def test_profile_failure_names_the_value_where_it_stopped():
    model, data, est = _mm_problem()
    with pytest.raises(ProfileError, match=r"profile of V: stopped at V = [-0-9.e+]+ \((lower|upper) side\).*"
                                           r"Ipopt fallback is disabled"):
        profile_intervals(model, data, est, 0.05, ["V"],
                          settings=ProfileSettings(max_newton=1, ipopt_fallback=False, newton_tol=1e-30))


# ---------------------------------------------------------------------------- pair regions
def test_region_of_linear_model_is_the_ellipse():
    model = Model.explicit(params=["a", "b", "c"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] + p[1] * q[0] + p[2] * q[0] ** 2, name="quadratic")
    x = np.linspace(-1, 2, 7)
    z = (1 + 2 * x - 0.5 * x ** 2)[None, :, None] + 0.1 * np.random.default_rng(1).standard_normal((2, 7, 1))
    data = Measurements(x, z, [0.1])
    est = identify(model, data, [0.0, 0.0, 0.0])
    reg = lr_region(model, data, est, ("a", "c"), n_grid=9)
    assert reg.statistic.shape == (9, 9) and reg.notes == ()
    np.testing.assert_allclose(reg.statistic, reg.linearised(), rtol=1e-7, atol=1e-8)
    assert reg.threshold == pytest.approx(stats.chi2.ppf(0.95, 2))


def test_region_of_curved_model_against_scipy():
    model, data, est = _mm_problem()
    x, z, sig = data.inputs[:, 0], data.z[:, :, 0], float(data.sigma[0])

    def phi(p):
        return 0.5 * float(np.sum(((z - (p[0] * x / (p[1] + x) + p[2])) / sig) ** 2))

    reg = lr_region(model, data, est, ("V", "K"), n_grid=7)
    phi_hat = phi(est.p)
    for r, cc in [(0, 0), (3, 5), (6, 6), (2, 1)]:
        r_min = optimize.minimize_scalar(lambda t: phi([reg.X[r, cc], reg.Y[r, cc], t]), bracket=(0.0, 2.0),
                                         tol=1e-12)
        assert abs(reg.statistic[r, cc] - 2 * (r_min.fun - phi_hat)) < 1e-6 * max(1, reg.statistic[r, cc])
    # curved: the LR statistic differs from the quadratic form somewhere on the grid
    assert np.nanmax(np.abs(reg.statistic - reg.linearised())) > 0.1


def test_region_matches_lmfit_conf_interval2d_on_nist():
    """Rat42 (3 parameters, sigma estimated): sqrt(D) on the grid == lmfit's sqrt((chi2 - chi2_0) / redchi)."""
    lmfit = pytest.importorskip("lmfit")
    nist = _nist()
    d = nist.load("Rat42")
    fun = nist.MODELS["Rat42"]
    model = Model.explicit(params=["b1", "b2", "b3"], inputs=["x"], sensors=["y"], h=lambda p, q: fun(p, q[0]))
    data = Measurements(d.x.reshape(-1, 1), d.y.reshape(1, -1, 1), sigma=None)
    est = identify(model, data, d.start1.copy())
    reg = lr_region(model, data, est, ("b1", "b3"), n_grid=5, grid="axes")
    assert reg.threshold == pytest.approx(2 * stats.f.ppf(0.95, 2, d.n - 3))

    def resid(params):
        b = np.array([params[f"b{i + 1}"].value for i in range(3)])
        return np.asarray(fun(b, d.x)).ravel() - d.y

    params = lmfit.Parameters()
    for i in range(3):
        params.add(f"b{i + 1}", value=float(d.certified[i]))
    mini = lmfit.Minimizer(resid, params)
    res = mini.minimize(method="leastsq", xtol=1e-14, ftol=1e-14)
    x, y, grid = lmfit.conf_interval2d(mini, res, "b1", "b3", nx=5, ny=5,
                                       limits=((reg.X[0, -1], reg.X[0, 0]), (reg.Y[-1, 0], reg.Y[0, 0])))
    np.testing.assert_allclose(np.meshgrid(x, y), [reg.X, reg.Y], rtol=1e-14)
    np.testing.assert_allclose(np.sqrt(reg.statistic), grid, rtol=1e-4, atol=1e-4)


def test_one_parameter_profile_is_the_likelihood_ratio_interval():
    """n_p = 1 (nothing to re-optimise): the ends solve 2 (Phi(b) - Phi_hat) = chi2_1(0.9) exactly."""
    model = Model.explicit(params=["k"], inputs=["t"], sensors=["y"], h=lambda p, q: ca.exp(-p[0] * q[0]))
    t = np.linspace(0.1, 2.0, 6)
    z = np.exp(-1.3 * t)[None, :, None] + 0.05 * np.random.default_rng(7).standard_normal((2, 6, 1))
    data = Measurements(t, z, [0.05])
    est = identify(model, data, [1.0])

    def D(k):
        return float(np.sum(((z[:, :, 0] - np.exp(-k * t)) / 0.05) ** 2)) - 2 * est.objective

    ci = est.conf_int(0.1, method="profile", model=model, data=data)
    c = stats.chi2.ppf(0.9, 1)
    lo = optimize.brentq(lambda k: D(k) - c, est.p[0] - 1, est.p[0], xtol=1e-12)
    up = optimize.brentq(lambda k: D(k) - c, est.p[0], est.p[0] + 1, xtol=1e-12)
    assert abs(ci.lower[0] - lo) < 1e-6 * est.stderr[0] and abs(ci.upper[0] - up) < 1e-6 * est.stderr[0]
    assert ci["k"] == (ci.lower[0], ci.upper[0]) and "90 % profile intervals" in str(ci)


def test_estimate_short_of_the_minimum_is_refined_and_said():
    """An estimate moved off the minimum: the profile finds lower objectives, re-minimises, and gives the
    intervals of the true minimum with a note (never intervals relative to a wrong reference)."""
    model, data, est = _exp_problem()
    ref = est.conf_int(0.05, method="profile", model=model, data=data)
    off = dataclasses.replace(est, p=est.p + np.array([0.0, 0.5]) * est.stderr)
    ci = off.conf_int(0.05, method="profile", model=model, data=data)
    assert ci.notes and ci.notes[0].startswith("the estimate is not the minimum of the objective")
    np.testing.assert_allclose(ci.lower, ref.lower, atol=1e-5 * est.stderr.min())
    np.testing.assert_allclose(ci.upper, ref.upper, atol=1e-5 * est.stderr.min())
