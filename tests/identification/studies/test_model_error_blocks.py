"""The model error's REML by blocks (issue 30 item 7): the blockwise log-determinant, quadratic form and gradient
equal the dense ones of the full block-diagonal covariance, and identification.model_error gives the same result
with the blockwise objectives as with the dense reference on a small static and a small dynamic case."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import linalg

from identification import model_error
from identification.studies import discrepancy_gp, embedded_error
from identification.studies.discrepancy_gp import InputScaling, Observations, reml_objective
from identification.studies.embedded_error import (block_reml, condition_blocks, embedded_block_objective,
                                                   embedded_objective, general_reml)
from identification.studies.splits import time_window_splits

sys.path.insert(0, str(Path(__file__).resolve().parent))
import test_model_error as static  # noqa: E402
import test_model_error_dynamic as dynamic  # noqa: E402


def _spd(rng, n: int) -> np.ndarray:
    a = rng.standard_normal((n, n))
    return a @ a.T / n + np.diag(rng.uniform(0.5, 2.0, n))


def _scattered_blocks(rng, sizes: list) -> list:
    """A partition of range(sum(sizes)) into index arrays of the given sizes, interleaved (not contiguous)."""
    perm = rng.permutation(sum(sizes))
    return [np.sort(perm[a:b]) for a, b in zip(np.cumsum([0] + sizes[:-1]), np.cumsum(sizes))]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_block_reml_equals_the_dense_reml_on_random_block_diagonal_cases(seed):
    rng = np.random.default_rng(seed)
    sizes = list(rng.integers(1, 7, size=5))
    index = _scattered_blocks(rng, sizes)
    N, n_p, n_theta = sum(sizes), 3, 4
    G, r = rng.standard_normal((N, n_p)), rng.standard_normal(N)
    Vs = [_spd(rng, n) for n in sizes]
    dVs = []
    for b, n in enumerate(sizes):                       # hyperparameters acting on some blocks only
        which = np.array([m for m in range(n_theta) if (m + b) % 3 != 0])
        dVs.append((which, np.array([_spd(rng, n) - np.eye(n) for _ in which])))
    V = np.zeros((N, N))
    dense = [np.zeros((N, N)) for _ in range(n_theta)]
    for idx, Vb, (which, dV) in zip(index, Vs, dVs):
        V[np.ix_(idx, idx)] = Vb
        for m, d in zip(which, dV):
            dense[m][np.ix_(idx, idx)] = d
    f_ref, g_ref = general_reml(V, dense, G, r)
    f, g = block_reml(Vs, dVs, index, G, r, n_theta)
    assert f == pytest.approx(f_ref, rel=1e-10, abs=1e-10)
    np.testing.assert_allclose(g, g_ref, rtol=1e-10, atol=1e-10 * np.abs(g_ref).max())
    logdet = sum(np.linalg.slogdet(Vb)[1] for Vb in Vs)             # the parts: log|V| and r^T P r
    Vinv = np.linalg.inv(V)
    P = Vinv - Vinv @ G @ np.linalg.solve(G.T @ Vinv @ G, G.T @ Vinv)
    assert np.linalg.slogdet(V)[1] == pytest.approx(logdet, rel=1e-10)
    assert f == pytest.approx(logdet + np.linalg.slogdet(G.T @ Vinv @ G)[1] + r @ P @ r, rel=1e-10)


def test_block_reml_reports_a_failed_cholesky():
    f, g = block_reml([np.eye(2), -np.eye(2)], [(np.array([0]), np.eye(2)[None])] * 2,
                      [np.array([0, 1]), np.array([2, 3])], np.ones((4, 1)), np.ones(4), 2)
    assert f == np.inf and np.all(g == 0)


def test_condition_blocks_in_order_of_first_appearance():
    out = condition_blocks(np.array(["b", "a", "b", "c", "a"]))
    assert [list(i) for i in out] == [[0, 2], [1, 4], [3]]


def test_embedded_objective_by_conditions_equals_the_dense_one():
    rng = np.random.default_rng(4)
    rows = rng.integers(0, 6, size=30)
    Gs, r = rng.standard_normal((30, 3)), rng.standard_normal(30)
    noise, se = rng.uniform(0.5, 1.5, 30), rng.uniform(0.1, 1.0, 3)
    same_row = (rows[:, None] == rows[None, :]).astype(float)
    for c in (np.zeros(3), np.array([1.0, -2.0, 0.5])):
        f_ref, g_ref = embedded_objective(c, Gs, same_row, noise, se, r)
        f, g = embedded_block_objective(c, Gs, condition_blocks(rows), noise, se, r)
        assert f == pytest.approx(f_ref, rel=1e-10)
        np.testing.assert_allclose(g, g_ref, rtol=1e-10, atol=1e-10 * np.abs(g_ref).max())


def _dense_reml_objective(theta, obs, G, r, pins=()):
    """The dense reference: the full V = blockdiag_k V_k and its derivatives, one Cholesky of N x N."""
    theta = np.asarray(theta, float)
    parts = [discrepancy_gp._block(obs, i, theta[3 * i:3 * i + 3], pins) for i in range(len(obs.blocks))]
    V = linalg.block_diag(*[p[0] for p in parts])
    dense = []
    for i, (_, dV) in enumerate(parts):
        for d in dV:
            dense.append(linalg.block_diag(*[d if j == i else np.zeros_like(parts[j][0]) for j in range(len(parts))]))
    return general_reml(V, dense, G, r)


def _dense_embedded(c, Gs, index, noise, se, r):
    rows = np.empty(len(r), int)
    for k, idx in enumerate(index):
        rows[idx] = k
    return embedded_objective(c, Gs, (rows[:, None] == rows[None, :]).astype(float), noise, se, r)


def test_discrepancy_objective_with_conditions_equals_the_dense_one():
    rng = np.random.default_rng(6)
    counts = rng.integers(0, 3, size=(12, 3))
    counts[:, 0] = np.maximum(counts[:, 0], 1)
    x = rng.uniform(0, 1, (12, 1))
    obs = Observations.of(counts, np.array([0.1, 0.2, 0.3]), np.ones(3), x, conditions=rng.integers(0, 3, 12))
    N = sum(obs.sizes)
    G, r = rng.standard_normal((N, 2)), rng.standard_normal(N)
    pins = InputScaling.of(x, {"x": 0.2}, ("x",)).pins
    theta = np.tile([0.5, np.log(0.4), -1.0], 3)
    f_ref, g_ref = _dense_reml_objective(theta, obs, G, r, pins)
    f, g = reml_objective(theta, obs, G, r, pins)
    assert f == pytest.approx(f_ref, rel=1e-10)
    np.testing.assert_allclose(g, g_ref, rtol=1e-10, atol=1e-10 * np.abs(g_ref).max())


def _leaves(result) -> tuple:
    """The numbers of a ModelErrorResult: ({p, cov, the REML optimum and hyperparameters} of the fit on all data,
    {the held-out table})."""
    fit = result.fit
    err = fit.gp if fit.gp is not None else fit.embedded
    V = err.covariance() if fit.gp is not None else err.V
    full = {"p": result.p, "cov": result.cov, "reml": err.reml, "V": V,
            "theta": err.theta if fit.gp is not None else err.c}
    table = {f"{h.split}.{k}": v for h in result.heldout for k, v in vars(h).items() if not isinstance(v, str)}
    return full, table


def _compare(run):
    blocks = run()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(discrepancy_gp, "reml_objective", _dense_reml_objective)
        mp.setattr(embedded_error, "embedded_block_objective", _dense_embedded)
        dense = run()
    (a, ta), (b, tb) = _leaves(blocks), _leaves(dense)
    assert a.keys() == b.keys() and ta.keys() == tb.keys() and len(ta) > 4
    for k in ("p", "cov", "reml"):
        np.testing.assert_allclose(a[k], b[k], rtol=1e-8, atol=1e-12, err_msg=k)
    np.testing.assert_allclose(a["V"], b["V"], rtol=1e-8, atol=1e-8 * np.abs(b["V"]).max())
    # the log hyperparameters: a component the REML hardly sees (a rough part tau ~ 1e-3 sigma) stops where
    # L-BFGS-B's gradient test is met, which round-off moves (measured 1.3e-7 in log tau, dynamic case); the
    # covariance they give (above) is the same to 1e-8
    np.testing.assert_allclose(a["theta"], b["theta"], rtol=0, atol=1e-6)
    # the held-out table: counts and coverages equal; the splits' REML fits stop where L-BFGS-B's tests
    # (pgtol 1e-5 on the gradient, factr on f) are met, and an objective changed at round-off may stop one
    # iteration apart on a flat likelihood (measured: 5e-7 relative in one widening of the static case)
    for k in ta:
        if "coverage" in k or "n_" in k:
            assert ta[k] == tb[k], k
        else:
            np.testing.assert_allclose(ta[k], tb[k], rtol=1e-5, err_msg=k)


@pytest.mark.parametrize("kind", ["discrepancy", "embedded"])
def test_model_error_is_the_same_by_blocks_on_a_small_static_case(kind):
    groups = np.repeat(["g1", "g2", "g3", "g4", "g5"], 5)
    _compare(lambda: model_error(static._model(), static._data(True), static.P0, splits=static.SPLITS, kind=kind,
                                 groups=groups))


def test_model_error_is_the_same_by_blocks_on_a_small_dynamic_case():
    _compare(lambda: model_error(dynamic._model(True), dynamic._data(), [1.0], splits=time_window_splits([1.5]),
                                 kind="discrepancy"))
