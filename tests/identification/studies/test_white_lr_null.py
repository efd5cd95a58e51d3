"""The exact null distribution of the 'no model error' test (:func:`identification.studies.discrepancy_gp.
white_lr_null`): the closed form of a balanced layout, and the statistic of :func:`white_lr_test` on residuals built
from the same contrasts on an unbalanced one.  Its use (the size of the shipped test against it) is measured in
bench/bench_model_error_adequate.py (``--test-only``)."""
from __future__ import annotations

import numpy as np
from scipy import linalg

from identification.studies.discrepancy_gp import Observations, white_lr_null, white_lr_test


def _layout(counts):
    sigma = np.array([0.004, 0.01, 0.02])
    x = np.linspace(0.0, 1.0, counts.shape[0])[:, None]
    obs = Observations.of(counts, sigma, np.ones(3), x)
    G = np.random.default_rng(5).standard_normal((int((counts > 0).sum()), 3))
    return obs, G


def test_balanced_layout_is_the_chi_square_closed_form():
    """Every mean of 4 series: LR = nu (x - 1 - log x) for x = chi2_nu / nu > 1, else 0 (nu = 39 - 3)."""
    obs, G = _layout(np.full((13, 3), 4))
    draws = white_lr_null(obs, G, 5000, seed=3)
    w2 = np.random.default_rng(3).standard_normal((5000, 36)) ** 2      # the same contrasts
    x = w2.sum(axis=1) / 36
    np.testing.assert_allclose(draws, np.where(x > 1, 36 * (x - 1 - np.log(x)), 0.0), rtol=0, atol=1e-9)
    assert 0.45 < np.mean(draws == 0) < 0.60


def test_unbalanced_layout_matches_the_test_statistic():
    """Unequal series counts (1 to 5): residuals y = D^1/2 K U w (K the complement of D^-1/2 G, U the eigenvectors of
    K^T M K) give white_lr_test's LR equal to the draw of the same w."""
    counts = np.random.default_rng(2).integers(1, 6, size=(13, 3))
    obs, G = _layout(counts)
    draws = white_lr_null(obs, G, 6, seed=9)
    noise = np.concatenate(obs.noise)
    m = np.concatenate([np.full(len(nz), s ** 2) for nz, s in zip(obs.noise, obs.sigma)]) / noise
    Q, _ = linalg.qr(G / np.sqrt(noise)[:, None], mode="full")
    K = Q[:, 3:]
    _, U = linalg.eigh(K.T @ (K * m[:, None]))
    w = np.random.default_rng(9).standard_normal((6, K.shape[1]))
    for i in range(6):
        y = np.sqrt(noise) * (K @ (U @ w[i]))
        assert abs(white_lr_test(obs, G, y).statistic - draws[i]) <= 1e-6 * max(1.0, draws[i])
    assert np.any(draws > 0)
