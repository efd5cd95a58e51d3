"""The second-order test and the escape along negative curvature (identification.fit.secondorder)."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from identification import ConvergenceError, Measurements
from identification.fit import secondorder
from identification.fit.refinement import ReducedProblem, refine
from models import Model


def _mgh10_problem():
    """MGH10 with the scales of its start 1, sigma unknown (the objective's sigma: spread of y)."""
    name = "_mudoe_tests_nist_strd"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, Path(__file__).with_name("nist.py"))
        sys.modules[name] = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(sys.modules[name])
    nist = sys.modules[name]
    d = nist.load("MGH10")
    model = Model.explicit(params=["b1", "b2", "b3"], inputs=["x"], sensors=["y"], h=nist.h_of("MGH10"))
    data = Measurements(inputs=d.x.reshape(-1, 1), z=d.y.reshape(1, -1, 1), sigma=None)
    return d, ReducedProblem.of(model, data, np.ones(1), np.array([np.std(d.y)]), np.abs(d.start1))


def _S(point):
    return point.sens.hessians(point.lam[None])[0]


def test_certified_optimum_is_a_minimum_with_finite_decrement():
    d, problem = _mgh10_problem()
    at = problem.evaluate(d.certified)
    so = secondorder.check(problem, at, _S(at), np.ones(3, bool))
    assert so.minimum and abs(so.eigenvalue - 1) < 1e-3 and np.isfinite(so.decrement)


def test_negative_curvature_is_found_and_escaped():
    """1e-6 (relative) off MGH10's optimum along p the Hessian is indefinite (mu_1 = -0.67): the
    direction of negative curvature gives a lower objective, and from there Newton reaches the optimum."""
    d, problem = _mgh10_problem()
    at = problem.evaluate(d.certified * (1 + 1e-6))
    so = secondorder.check(problem, at, _S(at), np.ones(3, bool))
    assert not so.minimum and so.eigenvalue < -0.5 and so.decrement == np.inf
    assert so.direction @ at.gradient <= 0
    new = secondorder.escape(problem, at, so)
    assert new is not None and new.objective < at.objective
    assert secondorder.check(problem, at, _S(at), np.zeros(3, bool)) is None       # nothing free


def test_rank_deficient_point_is_left_to_the_identifiability_test():
    d, problem = _mgh10_problem()
    at = problem.evaluate(d.certified)
    assert secondorder.check(problem, at, _S(at), np.ones(3, bool), rank_rtol=1.0) is None


def test_ensure_minimum_keeps_a_minimum_and_raises_without_descent(monkeypatch):
    d, problem = _mgh10_problem()
    ref = refine(problem, problem.evaluate(d.certified), 0)
    same, escaped = secondorder.ensure_minimum(problem, ref, np.ones(3, bool), None, np.array([0]))
    assert same is ref and escaped == ()
    bad = refine(problem, problem.evaluate(d.certified * (1 + 1e-6)), 0)
    monkeypatch.setattr(secondorder, "escape", lambda *a: None)
    with pytest.raises(ConvergenceError, match="saddle point") as exc:
        secondorder.ensure_minimum(problem, bad, np.ones(3, bool), None, np.array([0]))
    assert exc.value.eigenvalue < -0.5 and np.allclose(exc.value.p, bad.point.p)
