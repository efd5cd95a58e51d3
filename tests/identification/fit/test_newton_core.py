"""The one Newton core (identification.fit.newton): its rules on scalars and on stacks."""
from __future__ import annotations

import numpy as np
import pytest

from identification.fit import newton as nc


def test_armijo_and_no_increase_rules_agree_on_scalars_and_stacks():
    f, dec = 10.0, 2.0
    assert nc.sufficient_decrease(10.0 - 1e-4 * 2.0, f, 1.0, dec)
    assert not nc.sufficient_decrease(10.0 - 1e-4 * 2.0 + 1e-9, f, 1.0, dec)
    assert nc.no_increase(f * (1 + 1e-15), f) and not nc.no_increase(f * (1 + 1e-13), f)
    fs = np.array([9.0, 10.0 * (1 + 1e-13), np.nan])
    np.testing.assert_array_equal(nc.no_increase(fs, np.full(3, f)), [True, False, False])
    # a step that raised Phi is kept only in the quadratic region and when the decrement falls
    keep = nc.keep_step(fs, np.full(3, f), np.array([False, True, True]), np.array([5.0, 1.0, 3.0]),
                        np.array([1.0, 2.0, 2.0]))
    np.testing.assert_array_equal(keep, [True, True, False])


def test_backtrack_halves_until_accepted_and_reports_failure_and_abort():
    seen = []

    def trial(t):
        seen.append(t)
        return None if t > 0.3 else {"f": t}        # evaluation fails for long steps

    cand, t = nc.backtrack(trial, lambda c, t: True)
    assert seen == [1.0, 0.5, 0.25] and t == 0.25 and cand == {"f": 0.25}
    cand, t = nc.backtrack(lambda t: {"f": 1.0}, lambda c, t: False, max_halvings=3)
    assert cand is None and t == 0.125
    cand, _ = nc.backtrack(lambda t: nc.ABORT, lambda c, t: True)
    assert cand is nc.ABORT


def test_convergence_test_roundoff_and_active_set():
    assert nc.converged(1e-20, 1e-18, 0.0) and nc.converged(1e-17, 1e-18, 1e-16) and not nc.converged(1e-17, 1e-18, 0.0)
    np.testing.assert_array_equal(nc.tiny_step(np.array([[1e-14, -2e-14], [1e-12, 0.0]])), [True, False])
    L = np.linalg.cholesky(np.array([[4.0, 1.0], [1.0, 3.0]]))
    g_abs = np.array([1.0, 2.0])
    u = np.linalg.solve(L, 16 * np.finfo(float).eps * g_abs)
    assert nc.gradient_roundoff(lambda b: np.linalg.solve(L, b), g_abs) == pytest.approx(float(u @ u), rel=1e-15)
    lo, up = np.array([0.0, 0.0, 0.0]), np.array([1.0, 1.0, 1.0])
    p, g = np.array([0.0, 0.5, 1.0]), np.array([1.0, 1.0, 1.0])
    assert nc.active_set(p, g, lo, up, [0, 1, 2]) == [1, 2]          # p_0 at its lower bound, pushed outwards
    np.testing.assert_array_equal(nc.trial_point(p, np.array([2.0]), 0.5, lo, up, [1]), [0.0, 1.0, 1.0])
    np.testing.assert_array_equal(nc.trial_point(p, -g, 1.0, lo, up), [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(nc.halved_step(np.zeros(2), np.array([1.0, -3.0])), [0.5, -1.5])
