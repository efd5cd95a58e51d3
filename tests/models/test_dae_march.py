"""models.dae_march: collocated index-1 DAEs marched element by element, against the generic whole-trajectory
solves (the same discrete equations), identify's estimates with and without the marcher, and the fallbacks."""
import casadi as ca
import numpy as np
import pytest

from identification import identify
from identification.fit.dynamic_fit import simulate_campaign
from models import Model
from models.collocation import collocate
from models.dae_march import DAETrajectoryNumerics, GenericDAESolve, dae_march_scope
from models.errors import StateSolveError
from models.library import equilibrium_dae
from models.sensitivity import generic_sensitivities
from models.state import solve_states_generic

TIMES = [0.5, 1.0, 2.0, 3.0]


def toy():
    """x' = -k w, 0 = w - x^2 (x = x0 / (1 + k x0 t)), one input x0."""
    return Model.ode(["k"], ["x"], ["x0"], ["x", "w"], rhs=lambda x, z, p, u: -p[0] * z[0],
                     alg=lambda x, z, p, u: z[0] - x[0] ** 2, algebraic=["w"], x0=lambda p, u: u[0],
                     h=lambda x, z, p, u: ca.vertcat(x[0], z[0]), horizon=3.0)


def equilibrium():
    """A -> S (k1), S = B + C in fast equilibrium C = K B^2, B consumed (k2); a piecewise-constant feed of A."""
    return equilibrium_dae()


CASES = {
    "toy": (toy, np.array([0.8]), np.array([[1.0], [2.0], [0.5]])),
    # 12 experiments: more than MARCH_IN_CASADI_MAX
    "equilibrium": (equilibrium, np.array([1.2, 0.7, 2.0]),
                    np.array([[1.0, 0.2, 0.0, 0.5], [2.0, 0.0, 0.4, 0.1], [0.5, 1.0, 0.3, 0.0]] * 4)
                    * np.linspace(1.0, 1.3, 12)[:, None]),
}


def rel(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / np.max(np.abs(b)))


@pytest.mark.parametrize("name", sorted(CASES))
def test_states_and_sensitivities_equal_the_generic_solves(name):
    make, p, Q = CASES[name]
    cm = collocate(make(), TIMES, max_step=0.25)
    num = cm.state_numerics
    assert isinstance(num, DAETrajectoryNumerics) and num.reduced_space and num.merges_fits
    Yg = solve_states_generic(cm, p, Q)
    Y = num.solve_states(p, Q)
    assert rel(Y, Yg) <= 1e-9
    Sg, S = generic_sensitivities(cm, p, Q, Yg), num.sensitivities(p, Q, Y)
    assert rel(S.h, Sg.h) <= 1e-9 and rel(S.G, Sg.G) <= 1e-9
    assert rel(S.state_derivatives, Sg.state_derivatives) <= 1e-9
    lam = np.random.default_rng(1).standard_normal((2,) + S.h.shape)
    assert rel(S.hessians(lam), Sg.hessians(lam)) <= 1e-9          # the DAE adjoint through the elements
    assert rel(S.adjoint(lam[0]), Sg.adjoint(lam[0])) <= 1e-9
    # from a predicted guess (Newton on all trajectories at once, z(0) included)
    Yn = num.marched_states(p * 1.01, Q, Y)
    assert rel(Yn, solve_states_generic(cm, p * 1.01, Q)) <= 1e-9
    assert rel(num.integrated_outputs(p, Q), Sg.h) <= 1e-9
    assert num.fallbacks == []


def test_z0_and_every_point_are_consistent():
    make, p, Q = CASES["equilibrium"]
    cm = collocate(make(), TIMES, max_step=0.25)
    Y = cm.state_numerics.solve_states(p, Q)
    _, X, Z = cm.trajectory(Y[4])
    assert np.max(np.abs(Z[:, 0] + Z[:, 1] - X[:, 1])) <= 1e-12
    assert np.max(np.abs(Z[:, 1] - p[2] * Z[:, 0] ** 2)) <= 1e-12


@pytest.mark.parametrize("name", sorted(CASES))
def test_identify_gives_the_estimates_of_the_generic_path(name):
    make, p, Q = CASES[name]
    sigma = [0.01] * len(make().sensors)
    data = simulate_campaign(make(), p, Q, TIMES, sigma, seed=3)
    p0 = p * 0.8
    est = identify(make(), data, p0)
    with dae_march_scope(False):
        model = make()
        assert isinstance(collocate(model, TIMES).state_numerics, GenericDAESolve)
        ref = identify(model, data, p0)
    # both converged to the same optimum: within solver tolerance, far below the standard errors
    assert np.all(np.abs(est.p - ref.p) <= 1e-6 * ref.stderr)
    assert rel(est.stderr, ref.stderr) <= 1e-5


def test_a_dae_singular_on_the_trajectory_falls_back_with_the_reason():
    # 0 = w x - 1: dg/dw = x vanishes at x(0) = 0 (not of index 1 there, and no consistent w(0))
    m = Model.ode(["k"], ["x"], ["x0"], ["x"], rhs=lambda x, z, p, u: -p[0] * z[0],
                  alg=lambda x, z, p, u: z[0] * x[0] - 1.0, algebraic=["w"], x0=lambda p, u: u[0],
                  h=lambda x, z, p, u: x[0], horizon=1.0)
    num = collocate(m, [0.5, 1.0]).state_numerics
    # the generic path fails too (its z(0) rootfinder refuses dg/dw = x = 0 as structurally singular)
    with pytest.raises((StateSolveError, RuntimeError)):
        num.solve_states(np.array([0.2]), np.array([[1.0], [0.0]]))
    assert len(num.fallbacks) == 1
    assert "singular at t = 0 for experiment 2" in num.fallbacks[0] and "not of index 1" in num.fallbacks[0]
    with dae_march_scope(False):
        assert isinstance(collocate(m, [0.5, 1.0]).state_numerics, GenericDAESolve)


def test_an_element_that_fails_falls_back_to_the_generic_path_with_the_reason():
    # x' = k w, w = x^2: x = x0 / (1 - k x0 t) blows up at t = 1 / (k x0) = 0.5
    m = Model.ode(["k"], ["x"], ["x0"], ["x"], rhs=lambda x, z, p, u: p[0] * z[0],
                  alg=lambda x, z, p, u: z[0] - x[0] ** 2, algebraic=["w"], x0=lambda p, u: u[0],
                  h=lambda x, z, p, u: x[0], horizon=1.0)
    cm = collocate(m, [0.5, 1.0])
    num = cm.state_numerics
    # the generic path fails too: its error says that the marcher failed first, and why
    with pytest.raises(StateSolveError, match="fell back to the generic solves: integration .* failed too"):
        num.solve_states(np.array([2.0]), np.array([[1.0]]))
    assert len(num.fallbacks) == 1 and "no collocation solution on the element" in num.fallbacks[0]
    # a good start needs no fallback
    assert np.all(np.isfinite(num.solve_states(np.array([0.1]), np.array([[1.0]]))))
    assert len(num.fallbacks) == 1


def test_batch_fits_of_a_dae_merge_their_marches_and_equal_the_generic_fits():
    from identification import Measurements
    from identification.fit.batch import fit_batch
    make, p, Q = CASES["equilibrium"]
    data = simulate_campaign(make(), p, Q, TIMES, [0.01] * 3, seed=5)
    est = identify(make(), data, p)
    rng = np.random.default_rng(4)
    sets = [Measurements(est.data.inputs, est.data.z + 0.01 * rng.standard_normal(est.data.z.shape), est.data.sigma,
                         sensors=est.data.sensors) for _ in range(3)]
    fit = fit_batch(est.model, sets, est.p)
    assert est.model.state_numerics.merges_fits and fit.ok.all() and not fit.fallbacks
    with dae_march_scope(False):
        ref_est = identify(make(), data, p)
        ref = fit_batch(ref_est.model, sets, ref_est.p)
    assert ref.ok.all()
    for r in range(3):
        assert np.all(np.abs(fit.p[r] - ref.p[r]) <= 1e-6 * np.sqrt(np.diag(ref.cov[r])))


def test_a_generic_solve_that_succeeds_after_the_marcher_failed_is_announced(monkeypatch):
    make, p, Q = CASES["toy"]
    num = collocate(make(), TIMES).state_numerics
    Y = num.solve_states(p, Q)

    def fail(*args):
        raise StateSolveError("no collocation solution on the element [0, 0.25] (forced)")
    monkeypatch.setattr(num, "states", fail)
    with pytest.warns(RuntimeWarning, match=r"fell back to the generic solves: no collocation .*\(forced\)"):
        Yg = num.solve_states(p, Q)
    assert rel(Yg, Y) <= 1e-9 and len(num.fallbacks) == 1
