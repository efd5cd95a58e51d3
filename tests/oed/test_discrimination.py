"""Discrimination designs: brute-force agreement, a known linear-vs-quadratic answer, bad input."""
from itertools import combinations

import casadi as ca
import numpy as np
import pytest

from models import Model
from models.contract import Parameter
from oed import select_discriminating
from oed.discrimination import DiscriminationError, reading_divergences

SENSORS = ("y1", "y2", "y3", "y4")


def _pair_of_models():
    """Two nonlinear explicit models with four sensors and one input."""
    a = Model.explicit(["a1", "a2"], ["x"], SENSORS,
                       h=lambda p, q: ca.vertcat(p[0] * ca.sin(q[0]), p[1] * q[0] ** 2, p[0] * ca.exp(-q[0]),
                                                  p[1] * q[0]))
    b = Model.explicit(["b1", "b2"], ["x"], SENSORS,
                       h=lambda p, q: ca.vertcat(p[0] * q[0], p[1] * ca.cos(q[0]), p[0] + p[1] * q[0],
                                                  p[1] * q[0] ** 3))
    return a, b


def _instance(seed, n_q):
    rng = np.random.default_rng(seed)
    a, b = _pair_of_models()
    Q = np.sort(rng.uniform(-2, 2, n_q))[:, None]
    return a, rng.uniform(0.5, 2, 2), b, rng.uniform(0.5, 2, 2), Q, rng.uniform(0.1, 1, len(SENSORS))


def _brute_joint(d, k, m):
    return max(d[np.ix_(rows, cols)].sum() for rows in combinations(range(d.shape[0]), k)
               for cols in combinations(range(d.shape[1]), m))


@pytest.mark.parametrize("seed", range(6))
def test_joint_design_equals_brute_force(seed):
    a, pa, b, pb, Q, sig = _instance(seed, 9)
    d, _, _ = reading_divergences(a, pa, b, pb, Q, sigma=sig)
    for k, m in ((2, 2), (4, 1), (3, 3), (5, 2)):
        res = select_discriminating(a, pa, b, pb, Q, sigma=sig, n_points=k, n_sensors=m)
        best = _brute_joint(d, k, m)
        assert res.proven_optimal and res.method.startswith("enumerate")
        assert res.value == pytest.approx(best, rel=1e-12)
        assert len(res.indices) == k and len(res.sensors) == m and len(res.readings) == k * m
        cols = [SENSORS.index(s) for s in res.sensors]
        assert d[np.ix_(res.indices, cols)].sum() == pytest.approx(res.value, rel=1e-12)


@pytest.mark.parametrize("seed", range(6))
def test_alternating_ascent_respects_its_bound(seed):
    a, pa, b, pb, Q, sig = _instance(100 + seed, 9)
    d, _, _ = reading_divergences(a, pa, b, pb, Q, sigma=sig)
    for k, m in ((3, 2), (4, 3)):
        res = select_discriminating(a, pa, b, pb, Q, sigma=sig, n_points=k, n_sensors=m, enumeration_limit=0)
        best = _brute_joint(d, k, m)
        assert res.method == "alternating"
        assert res.value <= best * (1 + 1e-12)
        assert res.upper_bound >= best * (1 - 1e-12)
        if res.proven_optimal:
            assert res.value == pytest.approx(best, rel=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_separable_designs_equal_brute_force(seed):
    a, pa, b, pb, Q, sig = _instance(200 + seed, 8)
    d, _, _ = reading_divergences(a, pa, b, pb, Q, sigma=sig)
    n_q, n_S = d.shape
    res = select_discriminating(a, pa, b, pb, Q, sigma=sig, n_points=3)
    assert res.value == pytest.approx(max(d[list(r)].sum() for r in combinations(range(n_q), 3)), rel=1e-12)
    assert res.sensors == SENSORS and res.proven_optimal
    res = select_discriminating(a, pa, b, pb, Q, sigma=sig, n_sensors=2)
    assert res.value == pytest.approx(max(d[:, list(c)].sum() for c in combinations(range(n_S), 2)), rel=1e-12)
    assert res.indices == tuple(range(n_q))
    flat = d.ravel()
    res = select_discriminating(a, pa, b, pb, Q, sigma=sig, n_readings=3)
    assert res.value == pytest.approx(max(flat[list(c)].sum() for c in combinations(range(flat.size), 3)),
                                      rel=1e-12)
    assert len(res.readings) == 3 and res.proven_optimal


def _poly_models():
    quad = Model.explicit(["c0", "c1", "c2"], ["x"], ["y"], h=lambda p, q: p[0] + p[1] * q[0] + p[2] * q[0] ** 2)
    lin = Model.explicit(["c0", "c1"], ["x"], ["y"], h=lambda p, q: p[0] + p[1] * q[0])
    return quad, lin


def test_linear_against_quadratic_known_answer():
    """Quadratic x^2 true, the linear model at its least-squares fit to x^2 on a symmetric grid,
    i.e. the constant c = mean(x^2): d_i = (x_i^2 - c)^2 / sigma^2, largest at the ends, then at
    the points farthest from |x| = sqrt(c)."""
    quad, lin = _poly_models()
    x = np.linspace(-1, 1, 21)
    c = np.mean(x ** 2)
    sigma = 0.1
    res = select_discriminating(quad, [0, 0, 1], lin, [c, 0], x, sigma=sigma, n_points=2)
    assert res.indices == (0, 20)
    assert res.value == pytest.approx(2 * (1 - c) ** 2 / sigma ** 2, rel=1e-12)
    np.testing.assert_allclose(res.divergences[:, 0], (x ** 2 - c) ** 2 / sigma ** 2, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(res.difference[:, 0], x ** 2 - c, atol=1e-14)
    expected = np.sort(np.argsort(-((x ** 2 - c) ** 2), kind="stable")[:5])
    assert res.indices != expected.tolist()
    assert select_discriminating(quad, [0, 0, 1], lin, [c, 0], x, sigma=sigma, n_points=5).indices == \
        tuple(expected)


def test_divergence_criterion_uses_prediction_variances():
    quad, lin = _poly_models()
    x = np.linspace(-1, 1, 7)
    Ca = np.diag([0.01, 0.02, 0.03])
    Cb = np.array([[0.02, 0.005], [0.005, 0.01]])
    sigma = 0.2
    res = select_discriminating(quad, [0.1, 0.2, 1.0], lin, [0.3, 0.1], x, sigma=sigma, n_points=3,
                                criterion="divergence", cov_a=Ca, cov_b=Cb)
    ga = np.column_stack([np.ones_like(x), x, x ** 2])
    gb = np.column_stack([np.ones_like(x), x])
    va = np.einsum("jp,pr,jr->j", ga, Ca, ga)
    vb = np.einsum("jp,pr,jr->j", gb, Cb, gb)
    diff = 0.1 + 0.2 * x + x ** 2 - (0.3 + 0.1 * x)
    d = diff ** 2 / (2 * sigma ** 2 + va + vb)
    np.testing.assert_allclose(res.divergences[:, 0], d, rtol=1e-12)
    assert res.indices == tuple(np.sort(np.argsort(-d, kind="stable")[:3]))
    assert not res.divergences.flags.writeable


def test_pair_of_input_matrices():
    """Models that read one experiment point through different input vectors."""
    a = Model.explicit(["k"], ["x", "s"], ["y"], h=lambda p, q: p[0] * q[0] + q[1])
    b = Model.explicit(["k"], ["x"], ["y"], h=lambda p, q: p[0] * q[0])
    x = np.linspace(0, 1, 5)
    qa = np.column_stack([x, [0, 1, 0, -3, 0]])
    res = select_discriminating(a, [2.0], b, [2.0], (qa, x[:, None]), sigma=1.0, n_points=1)
    assert res.indices == (3,) and res.value == pytest.approx(9.0)


def test_bad_input_names_the_argument():
    quad, lin = _poly_models()
    x = np.linspace(-1, 1, 5)
    args = (quad, [0, 0, 1], lin, [0, 0])
    with pytest.raises(DiscriminationError, match="candidates"):
        select_discriminating(*args, np.array([0.0, np.nan, 1.0]), n_points=1)
    with pytest.raises(DiscriminationError, match="duplicate"):
        select_discriminating(*args, np.array([0.0, 0.5, 0.5]), n_points=1)
    with pytest.raises(DiscriminationError, match="n_points"):
        select_discriminating(*args, x, n_points=6)
    with pytest.raises(DiscriminationError, match="n_sensors"):
        select_discriminating(*args, x, n_sensors=2)
    with pytest.raises(DiscriminationError, match="sigma"):
        select_discriminating(*args, x, sigma=-1.0, n_points=1)
    with pytest.raises(DiscriminationError, match="criterion"):
        select_discriminating(*args, x, criterion="D", n_points=1)
    with pytest.raises(DiscriminationError, match="cov_a, cov_b"):
        select_discriminating(*args, x, criterion="divergence", n_points=1)
    with pytest.raises(DiscriminationError, match="sensors"):
        select_discriminating(*args, x, sensors=["z"], n_points=1)
    with pytest.raises(DiscriminationError, match="n_readings"):
        select_discriminating(*args, x, n_points=1, n_readings=2)
    with pytest.raises(DiscriminationError, match="p_b"):
        select_discriminating(quad, [0, 0, 1], lin, [0, 0, 0], x, n_points=1)
    bounded = Model.explicit([Parameter("c0", 0.0, 1.0), "c1"], ["x"], ["y"], h=lambda p, q: p[0] + p[1] * q[0])
    with pytest.raises(DiscriminationError, match="p_b: parameter.*c0.*bounds"):
        select_discriminating(quad, [0, 0, 1], bounded, [2.0, 0.0], x, n_points=1)
    with pytest.raises(DiscriminationError, match="Q_a has 5 rows"):
        select_discriminating(*args, (x[:, None], x[:4, None]), n_points=1)


def _linear_rival():
    """A rival linear in its parameters: its linearised refit is exact."""
    return Model.explicit(["c1", "c2"], ["x"], SENSORS,
                          h=lambda p, q: ca.vertcat(p[0] * q[0], p[1] * ca.cos(q[0]), p[0] + p[1] * q[0],
                                                     p[1] * q[0] ** 3))


@pytest.mark.parametrize("seed", range(4))
def test_refit_criterion_equals_the_exact_refit_of_a_linear_rival_by_brute_force(seed):
    a, pa, _, _, Q, sig = _instance(seed, 7)
    b, pb = _linear_rival(), np.array([1.0, 1.0])
    res = select_discriminating(a, pa, b, pb, Q, sigma=sig, n_points=3, criterion="T_refit")
    ha = a.simulate(pa, Q)
    Xb = np.stack([b.simulate(e, Q) for e in np.eye(2)], axis=-1)      # h_b = Xb @ p (linear)

    def refit(rows, cols):
        y = (ha[np.ix_(rows, cols)] / sig[cols]).ravel()
        X = (Xb[np.ix_(rows, cols)] / sig[cols][None, :, None]).reshape(-1, 2)
        coef = np.linalg.lstsq(X, y, rcond=None)[0]
        return float(((y - X @ coef) ** 2).sum())

    cols = list(range(len(SENSORS)))
    values = {rows: refit(list(rows), cols) for rows in combinations(range(len(Q)), 3)}
    best = max(values, key=values.get)
    assert res.indices == best and res.proven_optimal and res.method == "enumerate-refit"
    assert res.value == pytest.approx(values[best], rel=1e-8)
    assert res.value <= select_discriminating(a, pa, b, pb, Q, sigma=sig, n_points=3).value * (1 + 1e-12)


def test_refit_criterion_free_readings_and_the_enumeration_limit():
    a, pa, _, _, Q, sig = _instance(11, 5)
    b = _linear_rival()
    res = select_discriminating(a, pa, b, [1.0, 1.0], Q, sigma=sig, n_readings=3, criterion="T_refit")
    assert len(res.readings) == 3 and res.n_designs == 1140                 # C(20, 3)
    with pytest.raises(DiscriminationError, match="enumeration_limit"):
        select_discriminating(a, pa, b, [1.0, 1.0], Q, sigma=sig, n_readings=3, criterion="T_refit",
                              enumeration_limit=1000)
    with pytest.raises(DiscriminationError, match="no design identifies"):
        select_discriminating(a, pa, b, [1.0, 1.0], Q, sigma=sig, n_readings=1, criterion="T_refit")
