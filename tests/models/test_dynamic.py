"""Dynamic models (models.dynamic) and their Radau IIA collocation (models.collocation)."""
import pickle

import casadi as ca
import numpy as np
import pytest

from models import Model, ModelError
from models.collocation import CollocatedModel, Mesh, radau_coefficients
from models.blow_up import blow_up_of
from models.errors import BlowUpError, StateSolveError
from mudoe.example_reactor import P_TRUE, R_KJ, T_REF, TIMES, build


def decay(**kw):
    return Model.ode(["k"], ["x"], ["x0"], ["x"], rhs=lambda x, p, u: -p[0] * x, x0=lambda p, u: u[0],
                     h=lambda x, p, u: x, **kw)


def reactor_closed_form(p, q, t):
    """c_A, c_B of A -> B -> C at constant T (k1 != k2)."""
    k1, k2 = (p[2 * i] * np.exp(-p[2 * i + 1] / R_KJ * (1 / q[1] - 1 / T_REF)) for i in range(2))
    cA = q[0] * np.exp(-k1 * t)
    cB = q[0] * k1 / (k2 - k1) * (np.exp(-k1 * t) - np.exp(-k2 * t))
    return np.stack([cA, cB], axis=-1)


def test_radau_coefficients_integrate_polynomials_exactly():
    # the collocation equations of degree d reproduce x(t) = t^m exactly for m <= d
    tau, C = radau_coefficients(3)
    assert tau[-1] == 1.0 and tau.size == 4
    for m in range(4):
        assert np.allclose(C.T @ tau ** m, m * tau ** max(m - 1, 0) if m else 0 * tau, atol=1e-12)


def test_first_order_decay_converges_with_order_2d_minus_1():
    # x' = -k x, x(0) = x0: x(t) = x0 exp(-k t); Radau IIA degree 3 is of order 5 at the boundaries
    m, t = decay(), np.array([0.5, 1.0, 2.0, 3.0])
    errs = []
    for h in (0.5, 0.25, 0.125):
        out = m.collocate(t, max_step=h).simulate([1.3], [[2.0]])
        errs.append(np.abs(out[0] - 2.0 * np.exp(-1.3 * t)).max())
    assert errs[-1] < 2e-8
    ratios = np.array(errs[:-1]) / np.array(errs[1:])
    assert np.all((ratios > 2 ** 5 * 0.7) & (ratios < 2 ** 5 * 1.4)), ratios


def test_reactor_matches_closed_form_at_constant_temperature():
    # k1 = 6.1/h at 370 K: k1 h = 0.15 on elements of 0.025 h, error ~ (k1 h)^5 / 5! ~ 1e-6 relative
    m = build()
    cm = m.collocate(TIMES, max_step=0.025)
    assert isinstance(cm, CollocatedModel) and cm.sensors[:3] == ("cA@0.2", "cB@0.2", "cA@0.4")
    Q = np.array([[1.0, 330.0], [2.0, 370.0]])
    out = cm.simulate(P_TRUE, Q).reshape(2, TIMES.size, 2)
    ref = np.array([reactor_closed_form(P_TRUE, q, TIMES) for q in Q])
    assert np.abs(out - ref).max() < 5e-8


def test_control_profiles_constant_and_linear():
    # x' = -k u(t) x: x(T) = x0 exp(-k int_0^T u)
    grid = [0.0, 0.5, 1.0, 1.5]
    vals = np.array([1.0, 3.0, 2.0, 0.5])
    for kind in ("constant", "linear"):
        m = Model.ode(["k"], ["x"], ["x0"], ["x"], rhs=lambda x, p, u: -p[0] * u[1] * x, x0=lambda p, u: u[0],
                      h=lambda x, p, u: x, controls={"u": {"grid": grid, "kind": kind}}, horizon=2.0)
        assert m.inputs == ("x0", "u@0", "u@0.5", "u@1", "u@1.5")
        t = np.array([0.25, 0.5, 1.2, 2.0])
        out = m.collocate(t, max_step=0.05).simulate([0.7], [np.r_[1.5, vals]])[0]
        ends = np.r_[grid[1:], np.inf]
        if kind == "constant":      # exact integrals of u over [0, t]
            integral = np.array([np.sum(vals * np.clip(np.minimum(tt, ends) - grid, 0, None)) for tt in t])
        else:                       # trapezoid over the breakpoints is exact for piecewise-linear u
            integral = np.array([np.trapezoid(np.interp(s, grid, vals), s)
                                 for s in (np.union1d(np.r_[grid][np.r_[grid] < tt], [tt]) for tt in t)])
        exact = 1.5 * np.exp(-0.7 * integral)
        assert np.abs(out - exact).max() < 1e-7, kind


def test_index1_dae():
    # x' = -k w, 0 = w - x^2: x(t) = x0 / (1 + k x0 t); output w
    m = Model.ode(["k"], ["x"], ["x0"], ["x", "w"], rhs=lambda x, z, p, u: -p[0] * z[0],
                  alg=lambda x, z, p, u: z[0] - x[0] ** 2, algebraic=["w"], x0=lambda p, u: u[0],
                  h=lambda x, z, p, u: ca.vertcat(x[0], z[0]))
    t = np.array([0.0, 0.5, 1.0, 2.0])
    out = m.collocate(t, max_step=0.05).simulate([0.8], [[2.0]])[0].reshape(t.size, 2)
    x = 2.0 / (1 + 0.8 * 2.0 * t)
    assert np.abs(out[:, 0] - x).max() < 1e-8 and np.abs(out[:, 1] - x ** 2).max() < 1e-8


@pytest.mark.parametrize("kw, match", [
    (dict(rhs=lambda x, p, u: ca.vertcat(-p[0] * x, x)), "rhs returns 2 derivatives"),
    (dict(x0=lambda p, u: ca.vertcat(u[0], 1.0)), "x0 returns 2 initial values"),
    (dict(h=lambda x, p, u: ca.vertcat(x, x)), "h returns 2 outputs"),
    (dict(controls={"u": {"grid": [0.0, 0.5, 0.5]}}), r"controls\['u'\].*strictly increasing"),
    (dict(controls={"u": {"grid": [0.1, 0.5]}}), r"controls\['u'\].*start at time 0"),
    (dict(controls={"u": {"grid": [0.0, 0.5], "kind": "cubic"}}), r"controls\['u'\].*'kind'"),
    (dict(controls={"u": {"grid": [0.0, 3.0]}}, horizon=2.0), "beyond the horizon"),
    (dict(horizon=-1.0), "horizon"),
    (dict(algebraic=["w"]), "alg:"),
])
def test_bad_definitions_name_the_argument(kw, match):
    base = dict(rhs=lambda x, p, u: -p[0] * x, x0=lambda p, u: u[0], h=lambda x, p, u: x)
    base.update(kw)
    with pytest.raises(ModelError, match=match):
        Model.ode(["k"], ["x"], ["x0"], ["x"], **base)


@pytest.mark.parametrize("times, match", [([0.5, 0.4], "strictly increasing"), ([-0.1, 1.0], ">= 0"),
                                          ([0.5, 0.5 + 1e-14, 1.0], "differ by round-off only"),
                                          ([0.5, 3.0], "beyond the horizon"), ([np.nan], "finite"),
                                          ([], "no sampling time")])
def test_bad_times(times, match):
    with pytest.raises(ModelError, match=f"times: .*{match}"):
        decay(horizon=2.0).collocate(times)


def test_mesh_must_hold_the_sampling_times():
    with pytest.raises(ModelError, match="mesh: .*missing 0.3"):
        decay().collocate([0.3, 1.0], mesh=Mesh((0.0, 0.5, 1.0)))
    cm = decay().collocate([0.5, 1.0], mesh=Mesh((0.0, 0.5, 1.0), degree=2).refined(3))
    assert cm.mesh.n_elements == 6 and cm.n_y == 1 + 6 * 2



def test_refining_keeps_an_element_too_short_to_split():
    """Two sampling times 5.4e-10 h apart (distinct: above the 4.76e-10 same-instant tolerance at 0.476 of a 2 h
    horizon) and the halved mesh of the Richardson check: the short element stays whole (its halves would be one
    instant), every other element is halved exactly as before (the reactor's approximate sampling times under a
    prior stopped at `mesh: ... differ by round-off only` before)."""
    b = (0.0, 0.4760351561, 0.4760937497, 0.47609375024000006, 0.47615234366, 2.0)
    fine = Mesh(b).refined(2).boundaries
    old = np.r_[(np.asarray(b)[:-1, None] + np.diff(b)[:, None] * np.arange(2) / 2).ravel(), 2.0]
    assert fine == tuple(float(v) for v in np.delete(old, 5))           # the short element's midpoint dropped
    assert Mesh((0.0, 0.5, 1.0)).refined(3).boundaries == tuple(
        float(v) for v in np.r_[(np.array([0.0, 0.5])[:, None] + 0.5 * np.arange(3) / 3).ravel(), 1.0])
    cm = decay(horizon=2.0).collocate([0.4760937497, 0.47609375024000006, 2.0])
    half = decay(horizon=2.0).collocate(cm.times, mesh=cm.mesh.refined(2))
    assert half.mesh.n_elements == 2 * cm.mesh.n_elements - 1
    assert np.allclose(half.simulate([1.3], [[2.0]]), cm.simulate([1.3], [[2.0]]), rtol=1e-6)

def test_blow_up_names_the_element():
    m = Model.ode(["k"], ["x"], ["x0"], ["x"], rhs=lambda x, p, u: p[0] * x ** 2, x0=lambda p, u: u[0],
                  h=lambda x, p, u: x, horizon=2.0)
    with pytest.raises(StateSolveError, match=r"integration .* on the element \[0.5, 1\]") as info:
        m.collocate([0.5, 2.0], max_step=0.5).simulate([1.0], [[1.0]])
    # x = x0 / (1 - k x0 t): t* = 1 for k = x0 = 1, t* = 0.8 for x0 = 1.25 (element [0.5, 1] too)
    blow = blow_up_of(info.value)                       # the message's diagnosis, made when read
    assert isinstance(blow, BlowUpError) and abs(blow.t - 1.0) < 1e-4   # printed to 4 digits
    assert "(|x| -> inf near t = 1); check p and the inputs" in str(info.value)
    with pytest.raises(StateSolveError, match=r"element \[0.5, 1\] of experiment 1: the trajectory blows up "
                                              r"\(\|x\| -> inf near t = 0.8\)") as info:
        m.collocate([0.5, 2.0], max_step=0.5).simulate([1.0], [[1.25]])
    assert abs(blow_up_of(info.value).t - 0.8) < 1e-4
    # a worker sends it back as a plain StateSolveError with the whole message
    back = pickle.loads(pickle.dumps(info.value))
    assert type(back) is StateSolveError and str(back) == str(info.value)


def test_a_finite_trajectory_on_a_failed_element_is_called_too_stiff():
    # the diagnosis of the message: x' = -k x stays finite, so an element without a collocation solution is
    # too stiff for the element, not a blow-up (no BlowUpError; a finer mesh is the advice)
    from models.blow_up import diagnose_element
    from models.element_march import march_failure
    m = Model.ode(["k"], ["x"], ["x0"], ["x"], rhs=lambda x, p, u: -p[0] * x, x0=lambda p, u: u[0],
                  h=lambda x, p, u: x, horizon=2.0)
    cm = m.collocate([0.5, 2.0], max_step=0.5)
    diag = diagnose_element(cm.dynamic, [1e4], [1.0], 2.0)
    assert not diag.blows_up and diag.t == 2.0
    err = march_failure(cm, [1e4], [[1.0]], 0, 1)
    assert isinstance(err, StateSolveError) and blow_up_of(err) is None
    assert str(err).endswith("element [0.5, 1] of experiment 1: the trajectory stays finite up to t = 2: the ODE is "
                             "too stiff for the element; give a finer mesh"), str(err)
    blowing = Model.ode(["k"], ["x"], ["x0"], ["x"], rhs=lambda x, p, u: p[0] * x ** 2, x0=lambda p, u: u[0],
                        h=lambda x, p, u: x, horizon=2.0)
    blow = march_failure(blowing.collocate([0.5, 2.0], max_step=0.5), [1.0], [[1.0]], 0, 1)
    assert isinstance(blow_up_of(blow), BlowUpError) and abs(blow_up_of(blow).t - 1.0) < 1e-4


def test_trajectory_and_outputs_subset():
    cm = decay().collocate([0.5, 1.0], max_step=0.25, outputs=[("x", 1.0)])
    assert cm.sensors == ("x@1",)
    y = cm.solve_state([1.0], [1.0])
    t, X, Z = cm.trajectory(y)
    assert t.shape == (1 + 4 * 3,) and X.shape == (t.size, 1) and Z.shape == (t.size, 0)
    err = np.abs(X[:, 0] - np.exp(-t))
    assert err[::3].max() < 1e-7        # element boundaries: order 2d - 1 = 5
    assert err.max() < 1e-5             # interior Radau points: stage order d = 3
    with pytest.raises(ModelError, match="outputs: "):
        decay().collocate([0.5, 1.0], outputs=[("x", 0.7)])


def test_reactor_temperature_profile_matches_piecewise_integration():
    # T(t) piecewise constant on the 0.25 h grid: solve_ivp restarted at every jump is the reference
    from scipy.integrate import solve_ivp
    from mudoe.example_reactor import PROFILE_GRID
    m = build("profile")
    T = np.array([330.0, 345.0, 360.0, 370.0, 355.0, 340.0, 335.0, 350.0])
    q = np.r_[1.5, T]
    out = m.collocate(TIMES, max_step=0.025).simulate(P_TRUE, [q])[0].reshape(TIMES.size, 2)
    x, ref = [1.5, 0.0, 0.0], []
    edges = np.r_[PROFILE_GRID, 2.0]
    for i, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        k1, k2 = (P_TRUE[2 * j] * np.exp(-P_TRUE[2 * j + 1] / R_KJ * (1 / T[i] - 1 / T_REF)) for j in range(2))
        ts = TIMES[(TIMES > a) & (TIMES <= b)]
        r = solve_ivp(lambda _, c: [-k1 * c[0], k1 * c[0] - k2 * c[1], k2 * c[1]], (a, b), x,
                      t_eval=np.r_[ts, b] if ts.size == 0 or ts[-1] != b else ts, rtol=1e-11, atol=1e-14)
        ref.extend(r.y[:2, :ts.size].T)
        x = r.y[:, -1]
    assert np.abs(out - np.array(ref)).max() < 5e-8


def test_round_off_in_grids_and_times_makes_no_element():
    # issue 30: np.arange(10) * 0.05 holds 0.30000000000000004 and 0.35000000000000003; the sampling
    # times 0.3 and 0.35 (and a drawing grid holding the other spelling) must not make 4e-17 s elements
    from models.dynamic import TIME_RTOL, merge_times
    grid = np.arange(10) * 0.05
    assert grid[6] != 0.3 and grid[7] != 0.35
    vals = np.linspace(1.0, 2.0, 10)
    m = Model.ode(["k"], ["x"], ["x0"], ["x"], rhs=lambda x, p, u: -p[0] * u[1] * x, x0=lambda p, u: u[0],
                  h=lambda x, p, u: x, controls={"u": {"grid": grid}})
    m_clean = Model.ode(["k"], ["x"], ["x0"], ["x"], rhs=lambda x, p, u: -p[0] * u[1] * x, x0=lambda p, u: u[0],
                        h=lambda x, p, u: x, controls={"u": {"grid": np.round(grid, 12)}})
    for t in (np.array([0.1, 0.3, 0.35, 0.5]), np.array([0.1, 0.30000000000000004, 0.35000000000000003, 0.5])):
        cm = m.collocate(t, max_step=0.05)
        b = np.asarray(cm.mesh.boundaries)
        assert np.diff(b).min() > 0.01                       # no round-off element
        assert all(np.any(b == v) for v in t)                 # the sampling times stay exact boundaries
        q = np.r_[2.0, vals][None, :]
        ref = m_clean.collocate(np.round(t, 12), max_step=0.05).simulate([1.3], q)
        edges = np.r_[grid, np.inf]
        exact = 2.0 * np.exp(-1.3 * np.array([np.sum(vals * np.clip(np.minimum(edges[1:], s) - edges[:-1], 0, None))
                                               for s in t]))
        assert np.allclose(cm.simulate([1.3], q), ref, rtol=1e-12, atol=0)
        assert np.allclose(cm.simulate([1.3], q)[0], exact, rtol=1e-9)
    # the merge keeps the earlier group's value (sampling times before grid points), else the shorter one
    tol = TIME_RTOL * 0.5
    assert merge_times([0.3], [0.30000000000000004, 0.4], tol=tol).tolist() == [0.3, 0.4]
    assert merge_times([0.30000000000000004], [0.3], tol=tol).tolist() == [0.30000000000000004]
    assert merge_times([0.30000000000000004, 0.3], tol=tol).tolist() == [0.3]
    with pytest.raises(ModelError, match="differ by round-off only"):
        Mesh((0.0, 0.35, 0.35000000000000003, 0.5))
    with pytest.raises(ModelError, match="differ by round-off only"):
        decay().collocate([0.3, 0.30000000000000004])


def _u_by_index(dyn, q, t, t_ref):
    """u(t) built entry by entry as q[i] (the construction before the one split of q)."""
    n_c, parts, k = len(dyn.constants), [], len(dyn.constants)
    parts = [q[i] for i in range(n_c)]
    for c in dyn.controls:
        parts.append(c.value([q[k + i] for i in range(len(c.grid))], t, t_ref))
        k += len(c.grid)
    return ca.vertcat(*parts)


@pytest.mark.parametrize("kind", ["constant", "linear"])
def test_point_inputs_split_q_once_give_the_same_expressions(kind):
    # the inputs at the collocation points from one split of q are the expressions of q[i] entry by entry
    grid = [0.0, 0.5, 1.0, 1.5]
    m = Model.ode(["k"], ["x"], ["x0"], ["x"], rhs=lambda x, p, u: -p[0] * u[1] * x, x0=lambda p, u: u[0],
                  h=lambda x, p, u: x, controls={"u": {"grid": grid, "kind": kind}}, horizon=2.0)
    cm = m.collocate(np.array([0.25, 0.5, 1.2, 2.0]), max_step=0.1)
    q = ca.SX.sym("q", m.n_q_dim)
    b, d = np.asarray(cm.mesh.boundaries), cm.mesh.degree
    old = [_u_by_index(m, q, b[k] + cm.tau[r] * (b[k + 1] - b[k]), 0.5 * (b[k] + b[k + 1]))
           for k in range(cm.mesh.n_elements) for r in range(1, d + 1)]
    new = cm.point_inputs(q)
    assert len(new) == len(old) == cm.mesh.n_elements * d
    assert [str(e) for e in new] == [str(e) for e in old]
    assert str(m.u_at(q, 0.7, 0.75)) == str(_u_by_index(m, q, 0.7, 0.75))
    qn = np.r_[1.5, 1.0, 3.0, 2.0, 0.5]         # numeric rows take the same path as before
    assert np.array_equal(m.u_at(qn, 0.7, 0.75), np.asarray(ca.evalf(ca.substitute(
        _u_by_index(m, q, 0.7, 0.75), q, ca.DM(qn)))).ravel())


@pytest.mark.parametrize("kind", ["constant", "linear"])
def test_point_inputs_of_an_mx_row_evaluate_to_the_numeric_inputs(kind):
    # the MX graph from one split of q gives, at a numeric row, exactly the inputs of the numeric path
    grid = [0.0, 0.5, 1.0, 1.5]
    m = Model.ode(["k"], ["x"], ["x0"], ["x"], rhs=lambda x, p, u: -p[0] * u[1] * x, x0=lambda p, u: u[0],
                  h=lambda x, p, u: x, controls={"u": {"grid": grid, "kind": kind}}, horizon=2.0)
    cm = m.collocate(np.array([0.25, 0.5, 1.2, 2.0]), max_step=0.1)
    q = ca.MX.sym("q", m.n_q_dim)
    f = ca.Function("U", [q], [ca.horzcat(*cm.point_inputs(q))])
    qn = np.array([1.5, 1.0, 3.3, 2.0, 0.7])
    U = np.asarray(f(qn))
    assert U.shape == (m.n_u, cm.mesh.n_elements * cm.mesh.degree)
    assert np.array_equal(U, np.column_stack(cm.point_inputs(qn)))
    # the linear map Umap is another arithmetic (a matrix product: its sums round differently for linear controls)
    np.testing.assert_allclose(U.T.ravel(), cm.point_input_map() @ qn, rtol=1e-15, atol=1e-15)
