"""The dynamic reference solutions of bench.dynamic_reference (issue 22): independent methods agree."""
import numpy as np
import pytest

from bench import dynamic_reference as dr


def test_pyomo_doe_reactor_fim_three_methods_agree():
    """CVODES forward sensitivities, scipy's augmented system and the complex-step closed form give one FIM."""
    F = {m: dr.pyomo_doe_reactor_fim(method=m) for m in ("closed", "scipy", "cvodes")}
    scale = np.abs(F["closed"]).max()
    assert np.abs(F["scipy"] - F["closed"]).max() / scale < 1e-11
    assert np.abs(F["cvodes"] - F["closed"]).max() / scale < 1e-9
    # the value the issue reports from its own two methods
    assert dr.log10_det(F["closed"]) == pytest.approx(19.240939, abs=1e-6)


def test_pyomo_doe_reactor_closed_form_where_rates_cross():
    """At T = 591.6 K k1 = k2: the closed form stays equal to the integrated one."""
    T = (591.6,) + (300.0,) * 8
    a = dr.pyomo_doe_reactor_sensitivities(5.0, T, method="closed")
    b = dr.pyomo_doe_reactor_sensitivities(5.0, T, method="scipy")
    for u, v in zip(a, b):
        assert np.abs(u - v).max() / np.abs(v).max() < 1e-10


@pytest.mark.parametrize("make", [dr.batch_reactor, dr.spring_damper])
def test_example_sensitivities_match_finite_differences(make):
    """The hand-written partials: exact sensitivities equal central differences; stacked equals per-experiment."""
    ex = make()
    Q = np.array([b[0] + 0.3 * (b[1] - b[0]) for b in ex.input_bounds]) + np.zeros((2, 1))
    Q[1] = [b[1] for b in ex.input_bounds]
    times = np.linspace(0.1, 0.4, 4) * ex.t_end
    p = 1.1 * np.array(ex.p_true)
    _, S = dr.simulate(ex, p, Q, times, rtol=1e-12, sens=True)
    _, S2 = dr.simulate(ex, p, Q, times, rtol=1e-12, sens=True, stacked=True)
    fd = np.zeros_like(S)
    for j in range(p.size):
        e = np.zeros_like(p)
        e[j] = 1e-5 * p[j]
        fd[..., j] = (dr.simulate(ex, p + e, Q, times, rtol=1e-13) - dr.simulate(ex, p - e, Q, times, rtol=1e-13)) / (2 * e[j])
    assert np.abs(S - fd).max() / np.abs(S).max() < 1e-6
    assert np.abs(S2 - S).max() / np.abs(S).max() < 1e-9


def test_reference_fit_is_stationary_and_agrees_with_finite_difference_fit():
    """The reactor fit (exact Jacobian) is a stationary point; scipy's 2-point fit lands on it."""
    ex = dr.batch_reactor()
    data = dr.simulate_data(ex, 4, 6, seed=3)
    fit = dr.reference_fit(ex, data)
    fd = dr.reference_fit(ex, data, jac="2-point")
    y, S = dr.simulate(ex, fit.p, data.inputs, data.times, rtol=1e-10, sens=True)
    r = ((y - data.z) / data.sigma).ravel()
    J = (S / data.sigma[:, None]).reshape(r.size, -1)
    assert np.all(np.abs(J.T @ r) * fit.se < 1e-5)          # gradient in standard-error units
    assert np.all(np.abs(fd.p - fit.p) / fit.se < 1e-3)


def test_simulate_names_bad_arguments():
    ex = dr.batch_reactor()
    with pytest.raises(ValueError, match="inputs"):
        dr.simulate(ex, ex.p_true, [[1.0, 350.0, 2.0]], [1.0])
    with pytest.raises(ValueError, match="times"):
        dr.simulate(ex, ex.p_true, [[1.0, 350.0]], [2.0, 1.0])


def test_missing_pyomo_doe_peer_says_how_to_build_it(monkeypatch, tmp_path):
    from bench import bench_pyomo_doe

    monkeypatch.setenv("MUDOE_PEER_PYTHON", str(tmp_path / "no-python"))
    with pytest.raises(FileNotFoundError, match="MUDOE_PEER_PYTHON.*build_ipopt_ampl.sh"):
        bench_pyomo_doe.find_peer()
