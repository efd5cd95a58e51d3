"""oed.input_newton: the reduced-space Newton of the continuous input refinement (issue 30 item 6)."""
from types import SimpleNamespace

import numpy as np
import pytest

from bench.bench_dynamic_doe import GRID, LOWER, NOMINAL, P, UPPER, reactor
from oed import RefineSettings, refine_inputs, select_inputs
from oed import input_newton
from oed.criteria import Criterion
from oed.input_newton import newton_refine, reduced_point
from oed.input_nlp import BuildTimeout, reduced_parts

ROWS = np.array([NOMINAL, np.r_[2.0, [450.0] * 4, [350.0] * 5]])
SPAN = UPPER - LOWER


def _coarse():
    cm = reactor().collocate(GRID, max_step=0.125)
    return cm, np.full(cm.n_S, 1.0 / 0.01 ** 2)


@pytest.mark.parametrize("crit", [Criterion.D, Criterion.A])
def test_reduced_gradient_and_hessian_are_the_criterions_derivatives(crit):
    # two rows at an interior point: the gradient against central differences of the criterion (h = 1e-4; the
    # criterion is evaluated to ~1e-10, the differences' error is ~1e-6 of the gradient), the Hessian against
    # central differences of the exact gradient
    cm, w = _coarse()
    parts = reduced_parts(cm, P, w, LOWER, SPAN, crit)
    rng = np.random.default_rng(1)
    U = 0.2 + 0.6 * rng.random((2, LOWER.size))
    U[:, 0] = [0.9, 0.4]
    f, g, H = reduced_point(cm, P, parts, U, (LOWER, SPAN), crit)
    assert np.isfinite(f) and g.shape == (U.size,) and H.shape == (U.size, U.size)
    h, fd_g, fd_H = 1e-4, np.zeros(U.size), np.zeros((U.size, U.size))
    for j in range(U.size):
        e = np.zeros(U.size)
        e[j] = h
        up, dn = (reduced_point(cm, P, parts, (U.ravel() + s * e).reshape(U.shape), (LOWER, SPAN), crit)
                  for s in (1, -1))
        fd_g[j] = (up[0] - dn[0]) / (2 * h)
        fd_H[:, j] = (up[1] - dn[1]) / (2 * h)
    assert np.max(np.abs(g - fd_g)) <= 1e-5 * np.max(np.abs(g)), (g, fd_g)
    assert np.max(np.abs(H - fd_H)) <= 1e-4 * np.max(np.abs(H)), np.max(np.abs(H - fd_H))
    assert np.allclose(H, H.T, rtol=0, atol=1e-12 * np.max(np.abs(H)))


@pytest.mark.parametrize("crit, rows", [("D", [NOMINAL]), ("D", ROWS), ("A", [NOMINAL])])
def test_newton_reaches_the_full_space_optimum(crit, rows):
    # the same start, the same local optimum as Ipopt on the full-space NLP, to the criterion's accuracy (the
    # last control acts after the last reading: its level is free, Ipopt leaves it mid-range, Newton where it was)
    cm, _ = _coarse()
    sig = np.full(cm.n_S, 0.01)
    full = refine_inputs(cm, P, rows, sig, criterion=crit, bounds=(LOWER, UPPER),
                         settings=RefineSettings(n_starts=1, method="ipopt"))
    newton = refine_inputs(cm, P, rows, sig, criterion=crit, bounds=(LOWER, UPPER),
                           settings=RefineSettings(n_starts=1, method="newton"))
    assert full.n_failed == 0 and newton.n_failed == 0
    assert newton.messages[0].startswith("converged"), newton.messages
    assert newton.value == pytest.approx(full.value, rel=1e-9, abs=1e-9)
    assert np.allclose(newton.inputs[:, :-1], full.inputs[:, :-1], rtol=0, atol=1e-4 * SPAN[:-1])


def test_routes_by_criterion():
    # "auto": Newton for D, Ipopt for A and E; "newton" takes A too, never E
    cm, _ = _coarse()
    sig = np.full(cm.n_S, 0.01)
    for crit, method, newton in [("D", "auto", True), ("A", "auto", False), ("E", "auto", False),
                                 ("A", "newton", True), ("E", "newton", False)]:
        r = refine_inputs(cm, P, [NOMINAL], sig, criterion=crit, bounds=(LOWER, UPPER),
                          settings=RefineSettings(n_starts=1, method=method))
        assert r.messages[0].startswith("converged (") == newton and (newton or r.messages == ("Solve_Succeeded",))
    with pytest.raises(ValueError, match="criterion: the reduced-space Newton takes D or A"):
        reduced_parts(cm, P, np.ones(cm.n_S), LOWER, SPAN, Criterion.E)


def test_time_limit_stops_newton_with_its_best_point(monkeypatch):
    # a clock that ticks once per reading (no wall clock): the deadline passes before the fourth iteration; the
    # point reached so far is returned, better than the start, not converged, and said so
    cm, w = _coarse()
    parts = reduced_parts(cm, P, w, LOWER, SPAN, Criterion.D)
    U0 = np.r_[0.5, 0.6, [0.1] * (LOWER.size - 2)].reshape(1, -1)     # T varies: A_i and E_i both identified
    box = (LOWER, SPAN, np.where(UPPER > LOWER, 1.0, 0.0))
    free = newton_refine(cm, P, parts, U0, box, Criterion.D)
    ticks = iter(range(1, 10 ** 6))
    monkeypatch.setattr(input_newton, "time", SimpleNamespace(perf_counter=lambda: float(next(ticks))))
    stopped = newton_refine(cm, P, parts, U0, box, Criterion.D, deadline=3.0)
    start = reduced_point(cm, P, parts, U0, box[:2], Criterion.D)[0]
    assert free.converged and free.iterations > 3 and not stopped.converged and stopped.iterations == 3
    assert stopped.message.startswith("stopped by the time limit after 3 Newton iterations: the best point")
    assert free.value <= stopped.value < start


def test_select_inputs_says_when_the_time_limit_stopped_the_refinement(monkeypatch):
    # every Newton run finds its deadline passed (a clock far ahead in oed.input_newton alone): each start keeps
    # its first point, the design is the exact design's levels, and the note says why
    monkeypatch.setattr(input_newton, "time", SimpleNamespace(perf_counter=lambda: 1e300))
    res = select_inputs(reactor(), P, times=GRID, candidates=[NOMINAL], sigma=0.01, n_points=1, refine=True,
                        bounds=(LOWER, UPPER), refine_settings=RefineSettings(n_starts=2), time_limit=1e9)
    assert all(m.startswith("stopped by the time limit after 0 Newton iterations") for m in res.refined.messages)
    assert any(n.startswith("refinement stopped by the time limit") for n in res.notes), res.notes
    assert np.array_equal(res.refined.inputs, res.inputs)


def test_build_past_its_deadline_keeps_the_start():
    cm, w = _coarse()
    with pytest.raises(BuildTimeout, match="the rows' equations"):
        reduced_parts(cm, P, w, LOWER, SPAN, Criterion.D, deadline=0.0)
    r = refine_inputs(cm, P, [NOMINAL], np.full(cm.n_S, 0.01), bounds=(LOWER, UPPER),
                      settings=RefineSettings(n_starts=2), time_limit=1e-6)
    assert r.n_failed == 2 and np.array_equal(r.inputs, [NOMINAL]) and np.isfinite(r.value)
    assert all("building the refinement's derivatives" in m for m in r.messages), r.messages


@pytest.mark.parametrize("kw, match", [(dict(method="bfgs"), "method: expected"),
                                       (dict(newton_tol=0.0), "newton_tol: expected"),
                                       (dict(newton_tol=True), "newton_tol: expected"),
                                       (dict(newton_tol=float("inf")), "newton_tol: expected"),
                                       (dict(max_newton=0), "max_newton: expected")])
def test_bad_settings_name_the_argument(kw, match):
    with pytest.raises(ValueError, match=match):
        RefineSettings(**kw)


def test_time_limit_notes_name_what_was_returned():
    # Ipopt's wall-time stop on every start (the motor under load before session 13: no note then), a Newton run
    # stopped with its best point, a finished refinement
    from oed.inputs import RefinedInputs, time_limit_notes

    def refined(values, messages):
        return RefinedInputs(inputs=np.zeros((1, 2)), value=1.0, start_values=tuple(values),
                             n_failed=sum(not np.isfinite(v) for v in values), messages=tuple(messages),
                             lower=np.zeros(2), upper=np.ones(2), wall_time=0.0)

    wall = "Ipopt failed on the input refinement: Maximum_WallTime_Exceeded"
    assert time_limit_notes(refined([np.inf] * 2, [wall] * 2), 60.0)[0].startswith(
        "refinement not finished: every start stopped by the time limit (60 s)")
    stopped = "stopped by the time limit after 3 Newton iterations: the best point so far is kept (not converged)"
    assert time_limit_notes(refined([1.0, 2.0], ["converged (3 Newton iterations)", stopped]), 5.0)[0].startswith(
        "refinement stopped by the time limit (5 s) before every start converged: the refined design is the best")
    assert time_limit_notes(refined([1.0], ["converged (3 Newton iterations)"]), 5.0) == []


@pytest.mark.parametrize("symbolic", ["SX", "MX"])
def test_implicit_static_model_in_either_symbolic_type(symbolic):
    # E(y, p, q) = y + p0 y^3 - p1 q = 0, h = y, two rows: Newton's design equals Ipopt's (on the SX model: the
    # full-space route cannot expand an MX model's criterion, "eval_sx not defined for LinsolQr") from the same start
    from models import Model

    def model(sym):
        return Model(params=["a", "b"], inputs=["q"], sensors=["y"], n_y=1, symbolic=sym,
                     E=lambda y, p, q: y[0] + p[0] * y[0] ** 3 - p[1] * q[0], h=lambda y, p, q: y[0])

    kw = dict(bounds=(0.1, 3.0), criterion="D")
    full = refine_inputs(model("SX"), [0.3, 1.2], [[1.0], [2.0]], [0.01],
                         settings=RefineSettings(n_starts=1, method="ipopt"), **kw)
    newton = refine_inputs(model(symbolic), [0.3, 1.2], [[1.0], [2.0]], [0.01], settings=RefineSettings(n_starts=1),
                           **kw)
    assert newton.messages[0].startswith("converged") and full.n_failed == 0
    assert newton.value == pytest.approx(full.value, rel=1e-9, abs=1e-9)
    assert np.allclose(np.sort(newton.inputs.ravel()), np.sort(full.inputs.ravel()), atol=1e-5)
