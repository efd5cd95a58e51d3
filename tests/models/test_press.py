"""The press linkage model: size, equilibrium along the paper's 29 loads, targets, identifiability, friction hook."""
import casadi as ca
import numpy as np
import pytest

from models.mechanism import MechanismError, linear_analysis, solve_path
from models.press import PRESS_SENSORS, press_mechanism, press_model

Q29 = np.r_[np.linspace(0.0, 1600.0, 15), np.linspace(1600.0, 0.0, 15)[1:]][:, None]


@pytest.fixture(scope="module")
def model():
    return press_model()


@pytest.fixture(scope="module")
def path(model):
    return solve_path(model, model.p_nominal, Q29)


def sens_at(model, y, p, q):
    """Implicit-function sensitivity dh/dp = h_p - h_y E_y^{-1} E_p at a solved state."""
    ys = ca.SX.sym("y", model.n_y)
    ps = ca.SX.sym("p", model.n_p)
    qs = ca.SX.sym("q", model.n_q_dim)
    E, h = model.E_fun(ys, ps, qs), model.h_fun(ys, ps, qs)
    f = ca.Function("f", [ys, ps, qs], [ca.jacobian(E, ys), ca.jacobian(E, ps), ca.jacobian(h, ys),
                                         ca.jacobian(h, ps)])
    Ey, Ep, hy, hp = (np.array(a) for a in f(y, p, q))
    return hp - hy @ np.linalg.solve(Ey, Ep)


def test_state_has_34_components_as_in_the_paper(model):
    assert model.n_y == 34
    names = model.state_names
    assert sum(n.endswith((".x", ".y")) and n.split(".")[0] in {j.name for j in press_mechanism().joints}
               for n in names) == 24                       # 10 joints + 2 anchors, x and y
    assert sum(".rot[" in n for n in names) == 3            # lever rotations
    assert {"ecc.x", "ecc.y", "ecc.rot", "carrier.x", "carrier.y", "carrier.rot", "drive.phi"} <= set(names)
    assert model.sensors == PRESS_SENSORS
    assert model.param_names == ("k5", "k7") and model.inputs == ("q_P",)
    assert all(p.lower > 0 and p.scale == 500.0 and p.unit == "N/mm" for p in model.params)


def test_equilibrium_residual_at_29_loads(model, path):
    for y, q in zip(path, Q29):
        E = np.array(model.E_fun(y, model.p_nominal, q)).ravel()
        assert np.max(np.abs(E)) <= 1e-9 * max(1.0, abs(q[0])), (q, np.max(np.abs(E)))
    # unloading retraces loading (no friction in M1): same state at the same force
    np.testing.assert_allclose(path[14 + 7], path[7], atol=1e-12)


def test_targets_ram_and_D_compliance(model, path):
    full = press_model(extra_sensors=True)
    h = np.array(full.h_fun(path[14], full.p_nominal, Q29[14])).ravel()
    hs = dict(zip(full.sensors, h))
    assert 1.4 < hs["R_y"] < 1.8                             # about 1.6 mm at 1.6 kN
    c, _ = linear_analysis(full, full.p_nominal)
    cs = dict(zip(full.sensors, c * 1e3))                   # mm/kN
    assert 0.85 < cs["D_y"] < 0.95
    assert hs["D_y"] > 0 and hs["R_y"] > 0                   # positive q_P pushes the ram up


def test_extra_sensors_cover_every_joint_direction():
    full = press_model(extra_sensors=True)
    assert full.sensors[:3] == PRESS_SENSORS
    assert len(full.sensors) == 20 and len(set(full.sensors)) == 20
    assert not any(s.startswith(("E0_", "F0_")) for s in full.sensors)


def test_sensor_pairs_identify_k5_k7_as_in_the_paper(model, path):
    """Linear regime: (D_y, B0_y) exactly collinear, (D_y, F_x) and (F_x, B0_y) full rank."""
    _, S = linear_analysis(model, model.p_nominal)
    S = S * 500.0                                           # per unit of the parameter scale

    def ratio(rows):
        s = np.linalg.svd(S[rows], compute_uv=False)
        return s[1] / s[0]

    assert ratio([0, 1]) > 0.1                              # 110 identifies
    assert ratio([1, 2]) > 0.03                             # 011 identifies
    assert ratio([0, 2]) < 1e-12                            # 101 singular at small loads
    # at the largest load only the geometric nonlinearity separates D_y and B0_y, weakly
    Sn = sens_at(model, path[14], model.p_nominal, Q29[14]) * 500.0
    s = np.linalg.svd(Sn[[0, 2]], compute_uv=False)
    assert 1e-4 < s[1] / s[0] < 3e-2


def test_state_jacobian_matches_finite_differences(model, path):
    y0 = path[10]
    p, q = model.p_nominal, Q29[10]
    ys = ca.SX.sym("y", model.n_y)
    J = np.array(ca.Function("J", [ys], [ca.jacobian(model.E_fun(ys, p, q), ys)])(y0))
    h = 1e-6
    Jfd = np.column_stack([(np.array(model.E_fun(y0 + h * e, p, q)) - np.array(model.E_fun(y0 - h * e, p, q))).ravel()
                           / (2 * h) for e in np.eye(model.n_y)])
    np.testing.assert_allclose(J, Jfd, rtol=1e-5, atol=1e-6 * np.abs(J).max())


class ConstantFriction:
    """Stand-in: q_fric = c * q_dir (q_dir = +1 loading, -1 unloading)."""

    input_names = ("q_dir",)

    def __init__(self, c):
        self.c = c

    def force(self, qvec):
        return self.c * qvec[1]


def test_friction_hook_reduces_the_force_at_R(model):
    fm = press_model(friction=ConstantFriction(50.0))
    assert fm.inputs == ("q_P", "q_dir") and fm.n_y == 34
    p = fm.p_nominal
    q_load = np.array([[800.0, 1.0]])
    q_unload = np.array([[800.0, -1.0]])
    y_l = solve_path(fm, p, q_load)[0]
    y_u = solve_path(fm, p, q_unload)[0]
    y_750 = solve_path(model, p, [[750.0]])[0]
    y_850 = solve_path(model, p, [[850.0]])[0]
    np.testing.assert_allclose(y_l, y_750, atol=1e-12)
    np.testing.assert_allclose(y_u, y_850, atol=1e-12)


def test_friction_hook_rejects_bad_objects():
    class NoForce:
        input_names = ()
    with pytest.raises(MechanismError, match="force"):
        press_model(friction=NoForce())


def test_documented_numbers_match(model):
    """The tables in docs/press_geometry.md."""
    from models.press import press_identifiability
    r = press_identifiability(sensors=("D_y", "F_x", "B0_y", "R_y"))
    np.testing.assert_allclose(r["compliance"], [0.890, -0.0897, 0.0549, 0.992], atol=6e-4)
    np.testing.assert_allclose(r["h_load"] * 1e3, [1422.1, -137.6, 88.1, 1585.5], atol=0.06)
    pr = r["pairs"]
    assert abs(pr[("D_y", "F_x")]["ratio_load"] - 0.253) < 1e-3
    assert abs(pr[("F_x", "B0_y")]["ratio_load"] - 0.064) < 1e-3
    assert abs(pr[("D_y", "B0_y")]["ratio_load"] - 0.0063) < 1e-4
    assert pr[("D_y", "B0_y")]["ratio_lin"] < 1e-12


def test_model_pickles(model):
    import pickle
    m2 = pickle.loads(pickle.dumps(model))
    assert m2.state_names == model.state_names and m2.mechanism.name == "press_linkage"
