"""The NumPy replay of SX functions (models/vectorised.py) against CasADi's own evaluation."""
import casadi as ca
import numpy as np
import pytest

from models import Model
from models.state import VECTORISE_MIN, numerics
from models.vectorised import VectorisedSX, vectorisable


def _many_ops():
    p, q = ca.SX.sym("p", 3), ca.SX.sym("q", 2)
    h = ca.vertcat(
        p[0] * (1 - ca.exp(-p[1] * q[0])) + ca.sin(q[1]) * p[2] ** 2 - ca.cos(p[0] * q[1]) / ca.sqrt(1 + q[0] ** 2),
        ca.if_else(q[0] > 1, ca.sqrt(q[0]) * p[1], ca.log(1 + q[1] ** 2) / p[0]) + ca.fabs(q[0] - p[2]),
        ca.fmax(q[0], p[2]) * ca.atan2(q[1], p[0]) + ca.tanh(p[1] * q[1]) + ca.fmin(q[1], 0.5) * ca.erf(q[0]),
        ca.power(q[0] + 1, p[2]) + ca.sinh(0.1 * q[1]) + ca.atan(q[0] * p[1]) + ca.sign(q[1] - 1) * ca.floor(q[0]))
    lam = ca.SX.sym("lam", 4)
    return ca.Function("f", [p, q, lam], [h, ca.jacobian(h, p), ca.hessian(ca.dot(lam, h), p)[0]])


def test_replay_equals_casadi_at_every_point():
    f = _many_ops()
    assert vectorisable(f)
    rng = np.random.default_rng(3)
    n = 3000
    P, Q, L = rng.uniform(0.5, 2, 3), rng.uniform(0, 3, (n, 2)), rng.normal(size=(n, 4))
    outs = VectorisedSX(f)(P, Q, L, n=n)
    for j in (0, 1, 17, 1234, n - 1):
        ref = f(P, Q[j], L[j])
        for o, r in zip(outs, ref):
            want = np.array(r.nonzeros())
            np.testing.assert_allclose(o[:, j], want, rtol=1e-14, atol=1e-14 * max(1.0, np.abs(want).max()))


def test_unsupported_functions_are_refused():
    x = ca.MX.sym("x")
    g = ca.Function("g", [x], [ca.sin(x)])
    assert not vectorisable(g)
    with pytest.raises(ValueError, match="not an SX function"):
        VectorisedSX(g)


def test_batched_evaluation_switches_to_the_replay_with_the_same_numbers():
    model = Model.explicit(["a", "b"], ["x"], ["y"], h=lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])))
    num = numerics(model)
    n = VECTORISE_MIN + 3
    x = np.linspace(0.1, 8, n)[:, None]
    p = np.array([2.0, 0.7])
    Y = np.zeros((n, 0))
    big = num.batched("sens", n)(Y, p, x)                       # replayed by NumPy
    small = [num.batched("sens", 1)(Y[j:j + 1], p, x[j:j + 1]) for j in (0, n // 2, n - 1)]
    for k, j in enumerate((0, n // 2, n - 1)):
        for a, b in zip(big, small[k]):
            np.testing.assert_allclose(a[j], b[0], rtol=1e-14, atol=1e-300)
