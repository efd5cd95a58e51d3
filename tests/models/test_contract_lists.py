"""A model's E and h may return Python lists or tuples of scalar expressions (stacked with vertcat)."""
import casadi as ca
import numpy as np
import pytest

from models.contract import Model, ModelError

Q = np.linspace(0.5, 2.0, 6)[:, None]


def _state_model(as_list: bool, symbolic: str) -> Model:
    """y1 = a q / (1 + y2), y2 = b y1 (two states); sensors y1, y1 + y2 and a constant offset 0.5."""
    def E(y, p, q):
        eqs = [y[0] * (1 + y[1]) - p[0] * q[0], y[1] - p[1] * y[0]]
        return eqs if as_list else ca.vertcat(*eqs)

    def h(y, p, q):
        outs = (y[0], y[0] + y[1], 0.5) if as_list else ca.vertcat(y[0], y[0] + y[1], 0.5)
        return outs

    return Model(["a", "b"], ["q"], ["s1", "s2", "s3"], n_y=2, E=E, h=h, symbolic=symbolic,
                 y_guess=lambda p, q: np.array([q[0], 0.1]))


@pytest.mark.parametrize("symbolic", ["SX", "MX"])
def test_lists_equal_vertcat(symbolic):
    listed, stacked = _state_model(True, symbolic), _state_model(False, symbolic)
    p = [1.3, 0.4]
    out = listed.simulate(p, Q)
    np.testing.assert_allclose(out, stacked.simulate(p, Q), rtol=1e-12)
    assert out.shape == (len(Q), 3) and np.all(out[:, 2] == 0.5)


def test_explicit_model_with_numbers_and_numpy_scalars():
    m = Model.explicit(["a", "b"], ["q"], ["s1", "s2", "s3"],
                       h=lambda p, q: [p[0] * q[0], np.float64(2.0), ca.DM(1.5) * p[1]])
    np.testing.assert_allclose(m.simulate([2.0, 4.0], np.array([[3.0]])), [[6.0, 2.0, 6.0]])


@pytest.mark.parametrize("h, match", [
    (lambda p, q: [p, q[0]], r"h: entry 0 of the returned list has shape \(2, 1\); a list may hold scalars only"),
    (lambda p, q: (p[0], "x"), r"h: entry 1 of the returned tuple is a str; expected a scalar ca.SX"),
    (lambda p, q: [p[0], ca.MX.sym("m")], r"h: entry 1 of the returned list is a MX"),
])
def test_bad_entries_are_named(h, match):
    with pytest.raises(ModelError, match=match):
        Model.explicit(["a", "b"], ["q"], ["s1", "s2"], h=h)
