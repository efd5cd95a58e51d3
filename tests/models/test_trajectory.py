"""models.trajectory: trajectories and sensitivities of collocated ODEs for all experiments at once,
against the generic whole-trajectory solves (sparse LU of dE/dy), and identify's reduced-space path."""
import dataclasses

import casadi as ca
import numpy as np
import pytest

import models.element_march as element_march
import models.trajectory as trajectory
from identification import DynamicMeasurements, IdentifySettings, identify
from identification.fit.dynamic_fit import simulate_campaign
from models import Model
from models.collocation import collocate
from models.merged_calls import run_merged
from models.state import numerics, solve_state
from models.trajectory import trajectory_numerics
from mudoe.example_reactor import P_TRUE, TIMES, build

Q = np.array([[1.0, 330.0], [1.0, 340.0], [1.5, 345.0], [2.0, 350.0], [2.0, 360.0], [2.0, 370.0],
              [1.2, 335.0], [1.8, 355.0], [0.8, 365.0], [1.1, 350.0]])
P = np.array([1.5, 50.0, 1.0, 70.0])


def generic(cm, p, inputs):
    """States by damped Newton on the whole trajectory and y' = -(dE/dy)^{-1} dE/dp, h, G by sparse LU."""
    num = numerics(cm)
    Y, Yp, H, G = [], [], [], []
    for q in inputs:
        y = solve_state(cm, p, q)
        h, Ey, Ep, hy, hp = num.point("sens")(y, p, q)
        yp = -num.factor(Ey)(Ep.toarray())
        Y.append(y), Yp.append(yp), H.append(h), G.append(hy @ yp + hp.toarray())
    return np.array(Y), np.array(Yp), np.array(H), np.array(G)


@pytest.mark.parametrize("in_casadi", [True, False])
def test_states_and_sensitivities_equal_the_whole_trajectory_solve(monkeypatch, in_casadi):
    cm = collocate(build(), TIMES, max_step=0.25)
    traj = trajectory_numerics(cm)
    monkeypatch.setattr(element_march, "MARCH_IN_CASADI_MAX", 100 if in_casadi else 0)
    Y = traj.states(P, Q)
    Yp = traj.state_derivatives(P, Q, Y)
    h, G = traj.outputs_and_sensitivities(P, Q, Y, Yp)
    Yg, Ypg, hg, Gg = generic(cm, P, Q)
    assert np.abs(Y - Yg).max() <= 1e-12 * np.abs(Yg).max()
    assert np.abs(Yp - Ypg).max() <= 1e-10 * np.abs(Ypg).max()
    assert np.abs(h - hg).max() <= 1e-12 and np.abs(G - Gg).max() <= 1e-10 * np.abs(Gg).max()
    # Newton on all trajectories at once from a perturbed guess converges to the same states
    Yn = traj._newton(P, Q, Y * (1 + 1e-3))
    assert Yn is not None and np.abs(Yn - Yg).max() <= 1e-12 * np.abs(Yg).max()
    assert traj._newton(P, Q, np.full_like(Y, np.nan)) is None          # a failed Newton is left to the march
    # the per-experiment integration of the collocated model (its state guess) is the same trajectory
    assert np.abs(Y[3] - cm._integrate(P, Q[3])).max() <= 1e-12


def test_blow_up_names_the_experiment_and_element(monkeypatch):
    m = Model.ode(["k"], ["x"], ["x0"], ["x"], rhs=lambda x, p, u: p[0] * x ** 2, x0=lambda p, u: u[0],
                  h=lambda x, p, u: x, horizon=2.0)
    cm = collocate(m, [0.5, 1.0, 2.0])
    for limit in (100, 0):
        monkeypatch.setattr(element_march, "MARCH_IN_CASADI_MAX", limit)
        with pytest.raises(Exception, match=r"inputs \[1.0\]: no collocation solution on the element .* of experiment 2"):
            trajectory_numerics(cm).states([1.0], [[0.1], [1.0]])


def test_dae_models_march_in_their_own_numerics():
    from models.dae_march import DAETrajectoryNumerics
    m = Model.ode(["k"], ["x"], ["x0"], ["w"], rhs=lambda x, z, p, u: -p[0] * z[0],
                  alg=lambda x, z, p, u: z[0] - x[0] ** 2, algebraic=["w"], x0=lambda p, u: u[0],
                  h=lambda x, z, p, u: z, horizon=1.0)
    cdae = collocate(m, [0.5, 1.0])
    assert trajectory_numerics(cdae) is None             # the ODE marcher's numerics: ODEs only
    assert isinstance(cdae.state_numerics, DAETrajectoryNumerics)     # models.dae_march (tests/models/test_dae_march.py)
    assert trajectory_numerics(build()) is None          # not collocated


def test_every_model_carries_one_numerics_strategy_with_the_same_operations():
    from models.sensitivity import StateSolve
    from models.state import solve_states
    dae = Model.ode(["k"], ["x"], ["x0"], ["w"], rhs=lambda x, z, p, u: -p[0] * z[0],
                    alg=lambda x, z, p, u: z[0] - x[0] ** 2, algebraic=["w"], x0=lambda p, u: u[0],
                    h=lambda x, z, p, u: z, horizon=1.0)
    cm, cdae = collocate(build(), TIMES), collocate(dae, [0.5, 1.0])
    assert isinstance(cm.state_numerics, trajectory.TrajectoryNumerics) and cm.state_numerics is trajectory_numerics(cm)
    static = Model(["k"], ["q"], ["y"], 1, E=lambda y, p, q: y - p[0] * q[0], h=lambda y, p, q: y)
    assert isinstance(static.state_numerics, StateSolve) and not static.state_numerics.reduced_space
    assert cm.state_numerics.reduced_space and cm.state_numerics.merges_fits
    assert cdae.state_numerics.reduced_space and cdae.state_numerics.merges_fits     # an index-1 DAE marches too
    for num in (cm.state_numerics, cdae.state_numerics, static.state_numerics):
        assert all(callable(getattr(num, op)) for op in ("solve_states", "sensitivities", "marched_states",
                                                          "integrated_outputs"))
    # the DAE's integrated outputs are its marched states; from a guess, the same states
    h = cdae.integrated_outputs([0.8], [[2.0]])
    Y = solve_states(cdae, [0.8], [[2.0]])
    assert np.abs(h - np.asarray(cdae.h_fun(Y[0], [0.8], [2.0])).T).max() <= 1e-10
    Ym = cdae.state_numerics.marched_states([0.8], np.array([[2.0]]), Y * (1 + 1e-6))
    assert np.abs(Ym - Y).max() <= 1e-12 * np.abs(Y).max()
    # the ODE's marched states from a guess are its states
    Yo = solve_states(cm, P_TRUE, Q[:2])
    assert np.abs(cm.state_numerics.marched_states(P_TRUE, Q[:2], Yo * (1 + 1e-6)) - Yo).max() <= 1e-12 * np.abs(Yo).max()


def _campaign(seed):
    return simulate_campaign(build(), P_TRUE, Q[:6], TIMES, [0.01, 0.008], n_series=1, seed=seed)


def test_identify_by_reduced_newton_equals_the_ipopt_fit():
    data = _campaign(0)
    est = identify(build(), data, P)
    assert est.diagnostics.solver == "reduced Newton"
    ipopt = identify(build(), data, P, settings=IdentifySettings(reduced_start_inputs=None))
    assert ipopt.diagnostics.solver == "ipopt"
    assert np.all(np.abs(est.p - ipopt.p) <= 1e-8 * ipopt.stderr)
    assert np.allclose(est.cov, ipopt.cov, rtol=1e-7)


def test_a_bound_at_the_optimum_falls_back_to_ipopt():
    # E2 held below its estimate: the reduced optimum lies outside the bounds, Ipopt solves the bounded problem
    m = build()
    bounded = [dataclasses.replace(p, upper=75.0) if p.name == "E2" else p for p in m.params]
    m2 = Model.ode(bounded, states=list(m.states), inputs=list(m.inputs), sensors=list(m.sensors),
                   rhs=lambda x, p, u: m.rhs_fun(x, ca.SX(0, 1), p, u), x0=lambda p, u: m.x0_fun(p, u),
                   h=lambda x, p, u: m.h_fun(x, ca.SX(0, 1), p, u), horizon=m.horizon)
    est = identify(m2, _campaign(1), [1.5, 50.0, 1.0, 70.0])
    assert est.diagnostics.solver != "reduced Newton" and abs(est.p[3] - 75.0) <= 1e-6


def test_second_derivatives_equal_the_generic_adjoint():
    from models.sensitivity import Sensitivities, sensitivities
    cm = collocate(build(), TIMES, max_step=0.25)
    Y = trajectory_numerics(cm).states(P, Q)
    fast = sensitivities(cm, P, Q, Y)
    lam = np.random.default_rng(0).standard_normal((2, Q.shape[0], cm.n_S))
    H = fast.hessians(lam)
    fast._filled()                                       # the generic per-experiment adjoints (sparse LU)
    Hg = Sensitivities.hessians(fast, lam)
    assert np.abs(H - Hg).max() <= 1e-10 * np.abs(Hg).max()
    assert np.allclose(fast.adjoint(lam[0]).shape, (Q.shape[0], cm.n_y))


def test_batch_members_of_a_collocated_model_equal_identify():
    from identification import Measurements
    from identification.fit.batch import fit_batch
    est = identify(build(), _campaign(2), P)
    base = est.data
    rng = np.random.default_rng(3)
    sets = [Measurements(base.inputs, base.z + 0.01 * rng.standard_normal(base.z.shape), base.sigma,
                         sensors=base.sensors) for _ in range(4)]
    fit = fit_batch(est.model, sets, est.p)
    assert est.model.n_y > 60 and fit.ok.all() and not fit.fallbacks
    for r in range(4):
        single = identify(est.model, sets[r], est.p)
        assert np.all(np.abs(fit.p[r] - single.p) <= 1e-8 * single.stderr)
        assert np.allclose(fit.cov[r], single.cov, rtol=1e-8)


def test_interpolated_trajectories_start_newton_on_the_halved_mesh():
    from models.trajectory import interpolate_states
    coarse = collocate(build(), TIMES, max_step=0.25)
    fine = collocate(build(), TIMES, mesh=coarse.mesh.refined(2))
    Yc = trajectory_numerics(coarse).states(P, Q)
    guess = interpolate_states(coarse, fine, Yc)
    traj = trajectory_numerics(fine)
    exact = traj._states(P, Q)                                         # marched, no guess
    # the guess is within the discretisation error, and Newton from it reaches the marched states
    assert np.abs(guess - exact).max() < 1e-2 and np.abs(guess[:, :3] - exact[:, :3]).max() == 0
    assert np.abs(traj._newton(P, Q, guess) - exact).max() <= 1e-12 * np.abs(exact).max()


def test_fused_newton_sensitivities_equal_the_separate_sweep():
    """y'(p) from the last Newton iteration's blocks (states_and_sensitivities) equals the sweep at the converged
    states to 1e-10 relative, from a far guess (several iterations) and from the converged states (one); no guess,
    a guess that Newton cannot start from, or a call inside run_merged: None (the caller solves as before)."""
    cm = collocate(build(), TIMES, max_step=0.25)
    traj = trajectory_numerics(cm)
    Yg, Ypg, hg, Gg = generic(cm, P, Q)
    for guess in (Yg * (1 + 1e-3), Yg):
        Y, sens = traj.states_and_sensitivities(P, Q, guess)
        assert np.abs(Y - Yg).max() <= 1e-12 * np.abs(Yg).max()
        assert np.abs(sens.state_derivatives - Ypg).max() <= 1e-10 * np.abs(Ypg).max()
        assert np.abs(sens.h - hg).max() <= 1e-12 and np.abs(sens.G - Gg).max() <= 1e-10 * np.abs(Gg).max()
    assert traj.states_and_sensitivities(P, Q, None) is None
    assert traj.states_and_sensitivities(P, Q, np.full_like(Yg, np.nan)) is None
    assert run_merged([lambda: traj.states_and_sensitivities(P, Q, Yg)]) == [None]


def test_halved_mesh_outputs_by_one_newton_step_equal_the_converged_ones():
    """refined_outputs (one Newton step from the coarse trajectories interpolated, residual checked) gives the
    halved mesh's outputs of the converged Newton solve to 1e-12; from a guess where the step fails (not finite) it
    falls back to that solve."""
    from models.trajectory import interpolate_states
    coarse = collocate(build(), TIMES, max_step=0.25)
    fine = collocate(build(), TIMES, mesh=coarse.mesh.refined(2))
    guess = interpolate_states(coarse, fine, trajectory_numerics(coarse).states(P, Q))
    traj = trajectory_numerics(fine)
    exact = traj.outputs(P, Q, traj._states(P, Q))
    calls = []
    original = traj.integrated_outputs
    traj.integrated_outputs = lambda *a: calls.append(1) or original(*a)
    try:
        assert np.abs(traj.refined_outputs(P, Q, guess) - exact).max() <= 1e-12 * np.abs(exact).max()
        assert not calls                                                # one step was enough
        bad = guess.copy()
        bad[:, -1] = np.nan
        assert np.abs(traj.refined_outputs(P, Q, bad) - exact).max() <= 1e-12 * np.abs(exact).max() and calls
    finally:
        del traj.integrated_outputs


def test_halved_mesh_one_step_is_rejected_by_its_residual_on_a_nonlinear_model():
    """Logistic growth on a coarse mesh: after one Newton step from the interpolated trajectories an element's
    residual is above 1e-10 (1 + |V|), so refined_outputs solves to convergence: the same outputs."""
    from models.trajectory import interpolate_states
    m = Model.ode(["k"], ["x"], ["x0"], ["x"], rhs=lambda x, p, u: p[0] * x * (1 - x), x0=lambda p, u: u[0],
                  h=lambda x, p, u: x, horizon=4.0)
    coarse = collocate(m, [1.0, 2.0, 3.0, 4.0], max_step=0.5)
    fine = collocate(m, [1.0, 2.0, 3.0, 4.0], mesh=coarse.mesh.refined(2))
    p, q = np.array([3.0]), np.array([[0.01], [0.02]])
    guess = interpolate_states(coarse, fine, trajectory_numerics(coarse).states(p, q))
    traj = trajectory_numerics(fine)
    calls = []
    original = traj.integrated_outputs
    traj.integrated_outputs = lambda *a: calls.append(1) or original(*a)
    try:
        h = traj.refined_outputs(p, q, guess)
    finally:
        del traj.integrated_outputs
    assert calls == [1] and np.abs(h - traj.outputs(p, q, traj._states(p, q))).max() <= 1e-11


def test_compiled_element_functions_and_block_solves_equal_the_whole_trajectory_solve():
    """With JIT (jit_scope(True), as Monte Carlo runs): the element functions compiled and their blocks solved in
    the same compiled call (models.block_solve, LAPACK for blocks that fail its check); states, y'(p), h and G equal
    the generic whole-trajectory solve to the tolerances of the LAPACK path, through every solve of the strategy:
    Newton with y' (states_and_sensitivities), the sweep, the halved mesh's one step.  Without a compiler the
    virtual machine and LAPACK run: the same test."""
    from models.sensitivity import Sensitivities
    from models.state import JIT, jit_scope
    from models.trajectory import interpolate_states
    coarse = collocate(build(), TIMES, max_step=0.25)
    Yg, Ypg, hg, Gg = generic(coarse, P, Q)
    with jit_scope(True):
        traj = trajectory_numerics(coarse)
        Y, sens = traj.states_and_sensitivities(P, Q, Yg * (1 + 1e-3))
        assert np.abs(Y - Yg).max() <= 1e-12 * np.abs(Yg).max()
        assert np.abs(sens.state_derivatives - Ypg).max() <= 1e-10 * np.abs(Ypg).max()
        assert np.abs(sens.h - hg).max() <= 1e-12 and np.abs(sens.G - Gg).max() <= 1e-10 * np.abs(Gg).max()
        assert np.abs(traj.state_derivatives(P, Q, Yg) - Ypg).max() <= 1e-10 * np.abs(Ypg).max()
        lam = np.random.default_rng(0).standard_normal((2, Q.shape[0], coarse.n_S))
        H = sens.hessians(lam)                         # the adjoint with every transposed block solved at once
        sens._filled()                                 # the generic per-experiment adjoints (sparse LU)
        Hg = Sensitivities.hessians(sens, lam)
        assert np.abs(H - Hg).max() <= 1e-10 * np.abs(Hg).max()
        if JIT.active():                               # a compiler works: the compiled path was taken
            assert {("solved", "full_blocks"), ("solved", "blocks")} <= set(traj._maps)
        fine = collocate(build(), TIMES, mesh=coarse.mesh.refined(2))
        tf = trajectory_numerics(fine)
        guess = interpolate_states(coarse, fine, Yg)
        with jit_scope(False):
            exact = tf.outputs(P, Q, tf._states(P, Q))
        assert np.abs(tf.refined_outputs(P, Q, guess) - exact).max() <= 1e-12 * np.abs(exact).max()


def test_collocate_with_arguments_checked_before_returns_the_same_model_and_still_checks_new_ones():
    """collocate's cache of checked calls (two calls a refit): the same arguments give the same collocated model
    (times as a list or an array alike); other arguments are checked as before."""
    from models.contract import ModelError
    m = build()
    cm = collocate(m, TIMES, max_step=0.25)
    assert collocate(m, list(np.asarray(TIMES, float)), max_step=0.25) is cm
    assert collocate(m, TIMES, max_step=0.1) is not cm
    with pytest.raises(ModelError, match="increasing"):
        collocate(m, np.asarray(TIMES, float)[::-1], max_step=0.25)
    with pytest.raises(ModelError, match="mesh"):
        collocate(m, TIMES, mesh=[0.0, 1.0])


def test_elements_with_many_unknowns_stay_on_the_virtual_machine_and_lapack_under_jit():
    """An element of 10 states x 3 points (30 unknowns > MAX_COMPILED_SIZE): with JIT on nothing of the trajectory
    numerics is compiled, and the states and sensitivities are bit for bit those without JIT."""
    from models.state import jit_scope
    n = 10
    m = Model.ode(["k"], [f"x{i}" for i in range(n)], ["a"], [f"x{n - 1}"],
                  rhs=lambda x, p, u: ca.vertcat(-p[0] * x[0], *[p[0] * (x[i - 1] - x[i]) for i in range(1, n)]),
                  x0=lambda p, u: ca.vertcat(u[0], *([0.0] * (n - 1))), h=lambda x, p, u: x[n - 1], horizon=2.0)
    cm = collocate(m, [0.5, 1.0, 2.0])
    q = np.array([[1.0], [2.0]])
    traj = trajectory_numerics(cm)
    Y = traj.states([0.7], q)
    yp = traj.state_derivatives([0.7], q, Y)
    with jit_scope(True):
        Yj = traj.states([0.7], q)
        assert np.array_equal(Yj, Y) and np.array_equal(traj.state_derivatives([0.7], q, Yj), yp)
        assert traj._solved("full_blocks") is None
    assert not any(isinstance(k, tuple) and k[0] in ("jit", "solved", "block_solve") for k in traj._maps)
