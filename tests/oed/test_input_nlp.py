"""oed.input_nlp: the refinement NLP's assembled exact Hessian, its lifted form and its time-limited build."""
from dataclasses import replace

import casadi as ca
import numpy as np
import pytest

from bench.bench_dynamic_doe import GRID, LOWER, NOMINAL, P, UPPER, reactor
from oed import RefineSettings, refine_inputs, select_inputs
from oed import input_nlp
from oed.criteria import Criterion
from oed.input_nlp import BuildTimeout, information_nlp

ROWS = np.array([NOMINAL, np.r_[2.0, [450.0] * 4, [350.0] * 5]])

#: the full-space route (Ipopt on the NLP of oed.input_nlp), one or two starts
FULL1 = RefineSettings(n_starts=1, method="ipopt")
FULL2 = RefineSettings(n_starts=2, method="ipopt")


def _coarse():
    cm = reactor().collocate(GRID, max_step=0.125)
    return cm, np.full(cm.n_S, 1.0 / 0.01 ** 2)


def _whole_graph_hessian(nlp, x, par, lam_f, lam_g):
    """CasADi's Hessian of the whole Lagrangian lam_f f + lam_g^T g (the reference), upper triangle."""
    pr = nlp.problem
    H = ca.hessian(lam_f * pr.f + ca.dot(ca.DM(lam_g), pr.g), pr.x)[0]
    return np.triu(np.array(ca.Function("H", [pr.x, pr.par], [H])(x, par)))


@pytest.mark.parametrize("crit", [Criterion.D, Criterion.A, Criterion.E])
@pytest.mark.parametrize("lift_above", [input_nlp.LIFT_ABOVE, 0])
def test_assembled_hessian_equals_the_whole_lagrangians(crit, lift_above, monkeypatch):
    # the Hessian assembled from one row's Hessian and the criterion's (chain rule over the matrix entries, or
    # the lifted matrix) is the exact Hessian of the Lagrangian, at a point off the constraints with any multipliers
    monkeypatch.setattr(input_nlp, "LIFT_ABOVE", lift_above)
    cm, w = _coarse()
    nlp = information_nlp(cm, P, w, 2, LOWER, UPPER - LOWER, crit)
    assert (nlp.n_m > 0) == (lift_above == 0)
    x0 = nlp.start(cm, P, ROWS, LOWER, UPPER - LOWER)
    M = nlp.matrix(x0)
    b = nlp.parameter(M)
    n = nlp.n_u + nlp.n_y + nlp.n_s
    x0[n:n + nlp.n_m] = nlp.lifted(M, b)
    rng = np.random.default_rng(3)
    x = x0 * (1 + 1e-3 * rng.standard_normal(x0.size))
    x[n + nlp.n_m:] = 0.1 + rng.random(nlp.n_extra)
    lam_f, lam_g = 0.7, rng.standard_normal(nlp.n_g)
    got = np.array(nlp.problem.hess_lag(x, b, lam_f, lam_g))
    ref = _whole_graph_hessian(nlp, x, b, lam_f, lam_g)
    assert np.max(np.abs(got - ref)) <= 1e-9 * max(1.0, np.max(np.abs(ref)))


def test_lifted_refinement_reaches_the_same_design(monkeypatch):
    # two rows: the information of both lifted into m, m = tril(sum_i Mt_i) / bb
    cm, _ = _coarse()
    sig = np.full(cm.n_S, 0.01)
    plain = refine_inputs(cm, P, ROWS, sig, bounds=(LOWER, UPPER), settings=FULL1)
    monkeypatch.setattr(input_nlp, "LIFT_ABOVE", 0)
    cm2, _ = _coarse()                          # a fresh model: no NLP cached
    lifted = refine_inputs(cm2, P, ROWS, sig, bounds=(LOWER, UPPER), settings=FULL1)
    assert plain.n_failed == 0 and lifted.n_failed == 0
    assert lifted.value == pytest.approx(plain.value, abs=1e-7)
    assert np.allclose(lifted.inputs, plain.inputs, rtol=1e-4, atol=1e-3 * (UPPER - LOWER))


def test_time_limit_reached_while_building_keeps_the_start_and_says_so():
    # any machine takes more than a microsecond to build the first CasADi Function: the deadline is checked
    # after it and the refinement returns the start's levels with the reason, no Ipopt run begun
    cm, w = _coarse()
    with pytest.raises(BuildTimeout, match="the rows' equations"):
        information_nlp(cm, P, w, 1, LOWER, UPPER - LOWER, Criterion.D, deadline=0.0)
    sig = np.full(cm.n_S, 0.01)
    r = refine_inputs(cm, P, [NOMINAL], sig, bounds=(LOWER, UPPER),
                      settings=RefineSettings(n_starts=3, child_above=None, method="ipopt"), time_limit=1e-6)
    assert r.n_failed == 3 and np.array_equal(r.inputs, [NOMINAL]) and np.isfinite(r.value)
    assert all(m.startswith("not finished: time limit (1e-06 s) reached while building the refinement's NLP (after")
               and "no Ipopt run started" in m for m in r.messages), r.messages
    free = refine_inputs(cm, P, [NOMINAL], sig, bounds=(LOWER, UPPER), settings=FULL1)
    assert free.value < r.value
    res = select_inputs(reactor(), P, times=GRID, candidates=[NOMINAL], sigma=0.01, n_points=1, refine=True,
                        bounds=(LOWER, UPPER), refine_settings=replace(FULL1, child_above=None),
                        time_limit=1e-6)
    assert any(n.startswith("refinement not finished: time limit") and "building the refinement's NLP" in n
               for n in res.notes), res.notes
    assert np.array_equal(res.refined.inputs, res.inputs)


@pytest.mark.parametrize("crit", [Criterion.D, Criterion.A, Criterion.E])
@pytest.mark.parametrize("lift_above", [input_nlp.LIFT_ABOVE, 0])
def test_assembled_jacobian_equals_the_whole_constraints(crit, lift_above, monkeypatch):
    # the constraint Jacobian assembled per row (and through the criterion's constraints) is CasADi's Jacobian of
    # the whole constraint vector, at a point off the constraints; its g output is the NLP's g
    monkeypatch.setattr(input_nlp, "LIFT_ABOVE", lift_above)
    cm, w = _coarse()
    nlp = information_nlp(cm, P, w, 2, LOWER, UPPER - LOWER, crit)
    x0 = nlp.start(cm, P, ROWS, LOWER, UPPER - LOWER)
    M = nlp.matrix(x0)
    b = nlp.parameter(M)
    n = nlp.n_u + nlp.n_y + nlp.n_s
    x0[n:n + nlp.n_m] = nlp.lifted(M, b)
    rng = np.random.default_rng(5)
    x = x0 * (1 + 1e-3 * rng.standard_normal(x0.size))
    x[n + nlp.n_m:] = 0.1 + rng.random(nlp.n_extra)
    pr = nlp.problem
    g_got, J_got = (np.array(v) for v in pr.jac_g(x, b))
    ref = ca.Function("J", [pr.x, pr.par], [pr.g, ca.jacobian(pr.g, pr.x)])
    g_ref, J_ref = (np.array(v) for v in ref(x, b))
    assert J_got.shape == J_ref.shape == (nlp.n_g, x.size)
    assert np.max(np.abs(J_got - J_ref)) <= 1e-9 * max(1.0, np.max(np.abs(J_ref)))
    assert np.max(np.abs(g_got - g_ref)) <= 1e-9 * max(1.0, np.max(np.abs(g_ref)))


def test_refinement_without_mumps_scaling_reaches_the_same_design(monkeypatch):
    # above oed.inputs.UNSCALED_MUMPS_ABOVE variables MUMPS factorises without its own scaling: forced on the
    # small reactor (below the threshold by default), the refinement reaches the default's value and levels
    from oed import inputs

    cm, _ = _coarse()
    sig = np.full(cm.n_S, 0.01)
    plain = refine_inputs(cm, P, [NOMINAL], sig, bounds=(LOWER, UPPER), settings=FULL1)
    monkeypatch.setattr(inputs, "UNSCALED_MUMPS_ABOVE", 0)
    seen, solve = [], inputs.solve_nlp
    monkeypatch.setattr(inputs, "solve_nlp", lambda *a, **k: seen.append(k["settings"].extra) or solve(*a, **k))
    cm2, _ = _coarse()
    unscaled = refine_inputs(cm2, P, [NOMINAL], sig, bounds=(LOWER, UPPER), settings=FULL1)
    assert seen and all(("mumps_scaling", 0) in extra for extra in seen)
    assert plain.n_failed == 0 and unscaled.n_failed == 0
    assert unscaled.value == pytest.approx(plain.value, abs=1e-7)
    assert np.allclose(unscaled.inputs, plain.inputs, rtol=1e-4, atol=1e-3 * (UPPER - LOWER))
