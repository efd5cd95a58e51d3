"""The planar mechanism builder against hand-solvable structures, AD checks and bad specs."""
import math

import casadi as ca
import numpy as np
import pytest
from scipy.optimize import fsolve

from models.mechanism import (Bar, Beam, Joint, Load, Mass, MechanismError, MechParameter, Mechanism, RigidBody,
                              Support, assemble, build_model, load_toml, linear_analysis, solve_path)


def stiffness(model, p, q):
    y = ca.SX.sym("y", model.n_y)
    f = ca.Function("K", [y], [ca.jacobian(model.E_fun(y, p, q), y)])
    return np.array(f(np.zeros(model.n_y)))


# ------------------------------------------------------------------ two-bar truss
def two_bar(theta_deg=45.0, L=100.0):
    """Symmetric two-bar truss, apex C loaded by (Px, Py); supports very stiff."""
    a = L * math.cos(math.radians(theta_deg))
    h = L * math.sin(math.radians(theta_deg))
    joints = [Joint("A", -a, 0.0), Joint("B", a, 0.0), Joint("C", 0.0, h)]
    els = [Bar("1", "A", "C", "k1"), Bar("2", "B", "C", "k2"),
           Support("sA", "A", kx=1e3, ky=2e3), Support("sB", "B", kx=3e3, ky=4e3),
           Load("Px", "C", fx=1.0, input="Px"), Load("Py", "C", fy=1.0, input="Py")]
    params = [MechParameter("k1", 500.0, 0, 1e5, 500, "N/mm"), MechParameter("k2", 800.0, 0, 1e5, 500, "N/mm")]
    return Mechanism("two_bar", joints, els, params, inputs=("Px", "Py"), sensors=("C_x", "C_y"))


def test_two_bar_truss_small_displacement_matches_hand_solution():
    th = math.radians(45.0)
    m = build_model(two_bar())
    k1, k2 = 500.0, 800.0
    c, s = math.cos(th), math.sin(th)
    # hand solution: bar forces from statics of C, elongations N/k, supports N e/k_s
    for Px, Py in [(1.0, 0.0), (0.0, -1.0), (0.3, 0.7)]:
        # C equilibrium: N1 (-c, -s) + N2 (c, -s) + (Px, Py) = 0, with e1 = (c, s), e2 = (-c, s) from A/B to C
        N1 = 0.5 * (Py / s + Px / c)
        N2 = 0.5 * (Py / s - Px / c)
        # total elongation of bar i (bar + its support) projected: delta_i = N_i/k_i + e_i.(support compliance N_i e_i)
        d1 = N1 / k1 + N1 * (c ** 2 / 1e3 + s ** 2 / 2e3)
        d2 = N2 / k2 + N2 * (c ** 2 / 3e3 + s ** 2 / 4e3)
        # C displacement u with e1.u = d1, e2.u = d2
        u = np.linalg.solve([[c, s], [-c, s]], [d1, d2])
        K = stiffness(m, [k1, k2], [0.0, 0.0])
        y = np.linalg.solve(K, np.r_[0, 0, 0, 0, Px, Py])
        np.testing.assert_allclose(y[4:6], u, rtol=1e-12, atol=1e-16)
        # the nonlinear solve at a tiny load agrees with the linear one
        scale = 1e-4
        yn = solve_path(m, [k1, k2], [[Px * scale, Py * scale]])[0]
        np.testing.assert_allclose(yn[4:6] / scale, u, rtol=1e-7)


def test_single_bar_exact_nonlinear_equilibrium():
    """Inclined bar A-B, A on springs, B on a horizontal spring, large vertical load at B."""
    XA, XB = np.array([0.0, 0.0]), np.array([60.0, 80.0])
    k, Ka, kB = 400.0, 2000.0, 300.0
    m = build_model(Mechanism("bar", [Joint("A", *XA), Joint("B", *XB)],
                              [Bar("1", "A", "B", "k"), Support("a", "A", kx=Ka, ky=Ka), Support("b", "B", kx=kB),
                               Load("P", "B", fy=1.0, input="P")],
                              [MechParameter("k", k)], inputs=("P",), sensors=("B_x", "B_y")))
    L0 = 100.0
    P = 6000.0    # stretches the bar by about 15 %: strongly nonlinear

    def hand(z, P):
        uA, uB = z[:2], z[2:]
        c = XB + uB - XA - uA
        L = np.hypot(*c)
        N = k * (L - L0)
        e = c / L
        return np.r_[Ka * uA - N * e, -N * e + np.array([-kB * uB[0], P])]

    loads = np.linspace(0, P, 9)[1:, None]
    z = np.zeros(4)
    for Pj in loads[:, 0]:                 # continuation along the load, as for the model
        z = fsolve(hand, z, args=(Pj,), xtol=1e-12)
    assert np.max(np.abs(hand(z, P))) < 1e-9
    y = solve_path(m, [k], loads)[-1]
    assert np.max(np.abs(z)) > 5.0        # really a large displacement
    np.testing.assert_allclose(y, z, rtol=1e-10, atol=1e-10)
    E = np.array(m.E_fun(y, [k], [P])).ravel()
    assert np.max(np.abs(E)) <= 1e-9 * abs(P)


# ------------------------------------------------------------------ cantilever
def cantilever(n_el=4, L=1000.0, EI=2.0e9, EA=4.0e6, Kt=1e7, Kr=1e12):
    xs = np.linspace(0.0, L, n_el + 1)
    joints = [Joint(f"N{i}", x, 0.0) for i, x in enumerate(xs)]
    nodes = tuple(j.name for j in joints)
    els = [Beam("b", nodes, EA=EA, EI="EI", rot_supports={"N0": Kr}),
           Support("clamp", "N0", kx=Kt, ky=Kt),
           Load("P", nodes[-1], fy=1.0, input="P")]
    return Mechanism("cantilever", joints, els, [MechParameter("EI", EI)], inputs=("P",),
                     sensors=(f"{nodes[-1]}_y", f"{nodes[-1]}_x"))


@pytest.mark.parametrize("n_el", [1, 3, 6])
def test_cantilever_tip_deflection_and_rotation(n_el):
    L, EI, Kt, Kr = 1000.0, 2.0e9, 1e7, 1e12
    m = build_model(cantilever(n_el, L, EI, Kt=Kt, Kr=Kr))
    i_tip = m.state_names.index(f"N{n_el}.y")
    i_rot = m.state_names.index(f"b.rot[N{n_el}]")
    P = 1.0
    # linear theory incl. the (known) compliance of the clamp springs
    w_exact = P * L ** 3 / (3 * EI) + P / Kt + P * L * L / Kr
    r_exact = P * L ** 2 / (2 * EI) + P * L / Kr
    K = stiffness(m, [EI], [0.0])
    f = np.zeros(m.n_y)
    f[i_tip] = P
    y = np.linalg.solve(K, f)
    np.testing.assert_allclose(y[i_tip], w_exact, rtol=1e-10)
    np.testing.assert_allclose(y[i_rot], r_exact, rtol=1e-10)
    # nonlinear (co-rotational) solve at a load whose geometric nonlinearity is < 1e-9
    Ps = 0.06   # tip deflection ~ 1e-5 L
    yn = solve_path(m, [EI], [[Ps]])[0]
    np.testing.assert_allclose(yn[i_tip] / Ps, w_exact, rtol=1e-8)
    np.testing.assert_allclose(yn[i_rot] / Ps, r_exact, rtol=1e-8)


def test_beam_linearisation_is_consistent_6x6_matrix():
    """K of one free element (no supports) equals the consistent Euler-Bernoulli matrix, rotated."""
    L, EA, EI, ang = 250.0, 3e6, 5e8, math.radians(30)
    mech = Mechanism("el", [Joint("I", 10.0, 20.0), Joint("J", 10 + L * math.cos(ang), 20 + L * math.sin(ang))],
                     [Beam("b", ("I", "J"), EA=EA, EI=EI)], [MechParameter("dummy", 1.0)], inputs=(), sensors=("J_x",))
    asm = assemble(mech, unknowns=("dummy",), check_rank=False)
    K = np.array(ca.Function("K", [asm.y], [ca.jacobian(asm.E, asm.y)])(np.zeros(asm.n_y)))
    ka, kb = EA / L, 12 * EI / L ** 3
    Kl = np.array([[ka, 0, 0, -ka, 0, 0],
                   [0, kb, kb * L / 2, 0, -kb, kb * L / 2],
                   [0, kb * L / 2, kb * L ** 2 / 3, 0, -kb * L / 2, kb * L ** 2 / 6],
                   [-ka, 0, 0, ka, 0, 0],
                   [0, -kb, -kb * L / 2, 0, kb, -kb * L / 2],
                   [0, kb * L / 2, kb * L ** 2 / 6, 0, -kb * L / 2, kb * L ** 2 / 3]])
    c, s = math.cos(ang), math.sin(ang)
    T3 = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])
    T = np.block([[T3, np.zeros((3, 3))], [np.zeros((3, 3)), T3]])
    Kg = T.T @ Kl @ T
    # reorder builder state (I.x, I.y, J.x, J.y, rot[I], rot[J]) -> (I.x, I.y, rot I, J.x, J.y, rot J)
    perm = [0, 1, 4, 2, 3, 5]
    np.testing.assert_allclose(K[np.ix_(perm, perm)], Kg, rtol=1e-12, atol=1e-12 * np.abs(Kg).max())


# ------------------------------------------------------------------ AD vs finite differences
def test_state_equation_is_energy_gradient_and_jacobian_fd():
    mech = Mechanism(
        "mix", [Joint("A", 0, 0), Joint("B", 100, 10), Joint("C", 200, 0), Joint("D", 100, -80)],
        [Beam("b", ("A", "B", "C"), EA=1e6, EI=1e8), RigidBody("r", ("A", "D", "C"), bearing="kb", gap={"D": 0.02}, gap_residual=1e-3),
         Bar("1", "B", "D", 700.0), Support("s", "A", kx=1e3, ky=1e3), Support("t", "C", ky=2e3),
         Load("P", "B", fx=0.3, fy=-1.0, input="P"), Mass("m", "D", 5.0)],
        [MechParameter("kb", 4000.0)], inputs=("P",), sensors=("B_y",), gravity=9.80665)
    m = build_model(mech)
    asm = assemble(mech)
    assert asm.state_names == m.state_names
    rng = np.random.default_rng(1)
    y0 = rng.normal(scale=0.05, size=m.n_y)
    p, q = [4000.0], [123.0]
    Uf = ca.Function("U", [asm.y, asm.p], [asm.U])
    Q = np.array(ca.Function("Q", [asm.q], [asm.Q])(q)).ravel()
    E = np.array(m.E_fun(y0, p, q)).ravel()
    h = 1e-5
    fd = np.array([(float(Uf(y0 + h * e, p)) - float(Uf(y0 - h * e, p))) / (2 * h) for e in np.eye(m.n_y)]) - Q
    np.testing.assert_allclose(E, fd, rtol=1e-6, atol=1e-6 * np.abs(E).max())
    J = np.array(ca.Function("J", [asm.y, asm.p, asm.q], [ca.jacobian(asm.E, asm.y)])(y0, p, q))
    Jfd = np.column_stack([(np.array(m.E_fun(y0 + h * e, p, q)) - np.array(m.E_fun(y0 - h * e, p, q))).ravel() / (2 * h)
                           for e in np.eye(m.n_y)])
    np.testing.assert_allclose(J, Jfd, rtol=1e-6, atol=1e-6 * np.abs(J).max())
    assert np.allclose(J, J.T, rtol=1e-10, atol=1e-10 * np.abs(J).max())   # conservative system


def test_clearance_bearing_force_law():
    """Radial force of a gap bearing is k (d - g tanh(d/g)) + r k d, also near d = 0."""
    mech = Mechanism("gap", [Joint("A", 0, 0), Joint("B", 50, 0)],
                     [RigidBody("r", ("A", "B"), bearing=1000.0, gap={"B": 0.025}, gap_residual=1e-3),
                      Support("s", "A", kx=1e3, ky=1e3), Support("t", "B", kx=1e3, ky=1e3)],
                     [MechParameter("x", 1.0)], sensors=("B_x",))
    asm = assemble(mech, unknowns=("x",))
    Uf = ca.Function("U", [asm.y], [ca.gradient(asm.U, asm.y)])
    ib = [asm.state_names.index(n) for n in ("r.x", "r.y", "r.rot")]
    for d in [0.0, 1e-6, 1e-3, 0.02, 0.1]:
        y = np.zeros(asm.n_y)
        # move the pin node B so the gap vector is (-d*0.6, -d*0.8): force on body pulls it along the gap
        y[asm.state_names.index("B.x")] = 0.6 * d
        y[asm.state_names.index("B.y")] = 0.8 * d
        g = np.array(Uf(y)).ravel()
        F = np.hypot(g[asm.state_names.index("B.x")] - 1e3 * 0.6 * d, g[asm.state_names.index("B.y")] - 1e3 * 0.8 * d)
        expected = 1000.0 * (d - 0.025 * math.tanh(d / 0.025)) + 1.0 * d
        assert np.all(np.isfinite(g))
        np.testing.assert_allclose(F, expected, rtol=1e-9, atol=1e-15)
        assert np.all(np.isfinite(g[ib]))


# ------------------------------------------------------------------ bad specs
def test_dangling_joint_is_named():
    mech = two_bar()
    mech.joints = list(mech.joints) + [Joint("Z", 5.0, 5.0)]
    with pytest.raises(MechanismError, match="joint 'Z' is dangling"):
        build_model(mech)


def test_zero_length_bar_is_named():
    mech = two_bar()
    mech.joints = list(mech.joints) + [Joint("Z", mech.joints[0].x, mech.joints[0].y)]
    mech.elements = list(mech.elements) + [Bar("short", "A", "Z", 10.0)]
    with pytest.raises(MechanismError, match="bar 'short': zero length"):
        build_model(mech)


def test_unknown_element_kind_in_toml(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text('name = "bad"\n[joints]\nA = [0.0, 0.0]\nB = [1.0, 0.0]\n'
                 '[[elements]]\nkind = "bar"\nname = "1"\ni = "A"\nj = "B"\nk = 1.0\n'
                 '[[elements]]\nkind = "spring3d"\nname = "weird"\n')
    with pytest.raises(MechanismError, match=r"elements\[1\] \('weird'\): unknown element kind 'spring3d'"):
        load_toml(f)


def test_toml_roundtrip_matches_python_spec(tmp_path):
    f = tmp_path / "truss.toml"
    f.write_text('''name = "two_bar"
inputs = ["Px", "Py"]
sensors = ["C_x", "C_y"]
[joints]
A = [-70.71067811865476, 0.0]
B = [70.71067811865476, 0.0]
C = [0.0, 70.71067811865476]
[[parameters]]
name = "k1"
nominal = 500.0
lower = 0.0
upper = 1e5
scale = 500.0
unit = "N/mm"
[[parameters]]
name = "k2"
nominal = 800.0
[[elements]]
kind = "bar"
name = "1"
i = "A"
j = "C"
k = "k1"
[[elements]]
kind = "bar"
name = "2"
i = "B"
j = "C"
k = "k2"
[[elements]]
kind = "support"
name = "sA"
joint = "A"
kx = 1e3
ky = 2e3
[[elements]]
kind = "support"
name = "sB"
joint = "B"
kx = 3e3
ky = 4e3
[[elements]]
kind = "load"
name = "Px"
joint = "C"
fx = 1.0
input = "Px"
[[elements]]
kind = "load"
name = "Py"
joint = "C"
fy = 1.0
input = "Py"
''')
    mt = build_model(load_toml(f))
    mp = build_model(two_bar())
    assert mt.params[0].unit == "N/mm" and mt.sensors == mp.sensors
    ct, _ = linear_analysis(mt, [500.0, 800.0], load_input=1)
    cp, _ = linear_analysis(mp, [500.0, 800.0], load_input=1)
    np.testing.assert_allclose(ct, cp, rtol=1e-12)


def test_singular_stiffness_names_free_direction():
    mech = Mechanism("loose", [Joint("A", 0, 0), Joint("B", 100, 0)],
                     [Bar("1", "A", "B", 100.0), Support("s", "A", kx=1e3, ky=1e3), Load("P", "B", fx=1.0, input="P")],
                     [MechParameter("k", 1.0)], inputs=("P",), sensors=("B_x",))
    with pytest.raises(MechanismError, match=r"singular.*B\.y"):
        build_model(mech)


def test_under_constrained_body_rotation_is_detected():
    mech = Mechanism("spin", [Joint("A", 0, 0)],
                     [RigidBody("r", ("A",), bearing=100.0), Support("s", "A", kx=1e3, ky=1e3)],
                     [MechParameter("k", 1.0)], sensors=("A_x",))
    with pytest.raises(MechanismError, match=r"r\.rot"):
        build_model(mech)


def test_sensor_on_missing_joint_is_named():
    with pytest.raises(MechanismError, match="sensor 'Q_y': refers to joint 'Q'"):
        build_model(two_bar(), sensors=("C_x", "Q_y"))
    with pytest.raises(MechanismError, match="sensor 'C_z'"):
        build_model(two_bar(), sensors=("C_z",))


def test_unknown_parameter_and_joint_references_are_named():
    mech = two_bar()
    mech.elements = list(mech.elements) + [Bar("extra", "A", "B", "k9")]
    with pytest.raises(MechanismError, match="bar 'extra': unknown parameter 'k9'"):
        build_model(mech)
    mech = two_bar()
    mech.elements = list(mech.elements) + [Bar("ghost", "A", "X", 1.0)]
    with pytest.raises(MechanismError, match="bar 'ghost': refers to joint 'X'"):
        build_model(mech)
    assert issubclass(MechanismError, ValueError)


def test_clearance_bearing_without_other_support_is_reported_and_residual_fixes_it():
    joints = [Joint("A", 0, 0), Joint("B", 50, 0), Joint("C", 100, 0)]

    def mech(r):
        return Mechanism("gapfree", joints,
                         [RigidBody("r", ("A", "B", "C"), bearing=1000.0, gap={"B": 0.02}, gap_residual=r),
                          Support("s", "A", kx=1e3, ky=1e3), Support("t", "C", kx=1e3, ky=1e3),
                          Load("P", "B", fy=1.0, input="P")],
                         [MechParameter("x", 1.0)], inputs=("P",), sensors=("B_y",))
    with pytest.raises(MechanismError, match=r"clearance bearings \(r@B\).*B\.[xy]"):
        build_model(mech(0.0))
    m = build_model(mech(1e-3))
    y = solve_path(m, [1.0], [[0.0], [1.0], [10.0]])
    # small load sits inside the gap (soft), a larger one closes it
    assert y[1, 3] > 1.0 / 1000.0 and np.isfinite(y).all()


def test_body_named_like_a_joint_is_rejected():
    mech = two_bar()
    mech.elements = list(mech.elements) + [RigidBody("C", ("A", "B"), bearing=1.0)]
    with pytest.raises(MechanismError, match="body 'C': name clashes with a joint"):
        build_model(mech)
