"""Covariances from the QR factor of the weighted Jacobian (identification.fit.factor, issue 20 item 3),
checked against exact rational arithmetic (fractions.Fraction) on the stored double matrices."""
from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from identification.fit.estimator import covariance_from_terms
from identification.fit.factor import estimate_covariances, weighted_factor, weighted_rows


def _exact_inverse(A):
    """Exact inverse of a small matrix of Fractions (Gauss-Jordan)."""
    n = len(A)
    M = [list(row) + [Fraction(int(i == j)) for j in range(n)] for i, row in enumerate(A)]
    for c in range(n):
        piv = next(r for r in range(c, n) if M[r][c] != 0)
        M[c], M[piv] = M[piv], M[c]
        inv = 1 / M[c][c]
        M[c] = [v * inv for v in M[c]]
        for r in range(n):
            if r != c and M[r][c] != 0:
                f = M[r][c]
                M[r] = [a - f * b for a, b in zip(M[r], M[c])]
    return [row[n:] for row in M]


def _mat(A):
    return [[Fraction(float(v)) for v in row] for row in A]


def _mul(A, B):
    return [[sum(a * b for a, b in zip(row, col)) for col in zip(*B)] for row in A]


def _exact_cov(G, cw, w, sig, S):
    """(cov, cov_gn) of eq. 7 in exact arithmetic from the double inputs."""
    n_p = G.shape[-1]
    rows = G.reshape(-1, n_p)
    c1 = (cw / sig ** 2).reshape(-1)                  # exact: cw and sig are powers of two
    c2 = (cw * w[None, :] / sig ** 2).reshape(-1)
    R = _mat(rows)
    F = [[sum(Fraction(float(c1[k])) * R[k][i] * R[k][j] for k in range(len(R))) for j in range(n_p)]
         for i in range(n_p)]
    F2 = [[sum(Fraction(float(c2[k])) * R[k][i] * R[k][j] for k in range(len(R))) for j in range(n_p)]
          for i in range(n_p)]
    H = [[F[i][j] + Fraction(float(S[i, j])) for j in range(n_p)] for i in range(n_p)]
    Fi, Hi = _exact_inverse(F), _exact_inverse(H)
    cov_gn = _mul(_mul(Fi, F2), Fi)
    cov = _mul(_mul(Hi, F2), Hi)
    return np.array(cov, dtype=float), np.array(cov_gn, dtype=float)


def _problem(rng, ill: float):
    """G (20 inputs, 2 sensors, 3 parameters) whose third column is the first plus ``ill`` times
    noise (cond(sqrt(Omega) J) ~ 1/ill), power-of-two counts, weights and sigmas (exact square roots)."""
    G = rng.normal(size=(20, 2, 3))
    G[:, :, 2] = G[:, :, 0] + ill * rng.normal(size=(20, 2))
    cw = rng.choice([1.0, 4.0, 0.25], size=(20, 2))
    w = np.array([1.0, 0.25])
    sig = np.array([1.0, 2.0])
    return G, cw * w[None, :], w, sig


def _rel(a, ref):
    d = np.sqrt(np.abs(np.diag(ref)))
    return float(np.max(np.abs(a - ref) / np.outer(d, d)))


@pytest.mark.parametrize("ill", [1e-1, 1e-7])
def test_covariances_from_qr_match_exact_arithmetic(ill):
    """cov_gn and the second-order cov from the QR factor agree with exact arithmetic to
    ~cond * eps (at cond ~1e7: below 1e-7; the normal equations lose ~cond^2 * eps there)."""
    rng = np.random.default_rng(3)
    G, cw, w, sig = _problem(rng, ill)
    F = (weighted_rows(G, cw, sig).T @ weighted_rows(G, cw, sig))
    A = rng.normal(size=(3, 3))
    S = 0.2 * np.max(np.abs(F)) * ill * (A + A.T)      # S small in the ill-determined direction too
    cov, cov_gn, ok, sv, K_eig = estimate_covariances(G, cw, w, sig, S)
    ex_cov, ex_gn = _exact_cov(G, cw, w, sig, S)
    cond = sv[0] / sv[-1]
    assert ok and np.all(K_eig > 0)
    tol = 1e3 * np.finfo(float).eps * cond
    assert _rel(cov_gn, ex_gn) <= tol, (_rel(cov_gn, ex_gn), cond)
    assert _rel(cov, ex_cov) <= tol, (_rel(cov, ex_cov), cond)
    if ill == 1e-1:                                  # well conditioned: the normal equations agree
        ne_cov, ne_gn = covariance_from_terms(F, weighted_rows(G, cw * w, sig).T @ weighted_rows(G, cw * w, sig),
                                              S)[:2]
        assert _rel(ne_gn, cov_gn) <= 1e-12 and _rel(ne_cov, cov) <= 1e-12


def test_singular_values_are_those_of_the_column_normalised_jacobian():
    rng = np.random.default_rng(5)
    G, cw, w, sig = _problem(rng, 1e-4)
    rows = weighted_rows(G, cw, sig)
    fac = weighted_factor(rows[None])
    Jn = rows / np.linalg.norm(rows, axis=0)
    np.testing.assert_allclose(fac.sv[0], np.linalg.svd(Jn, compute_uv=False), rtol=1e-10)
    assert fac.full_rank[0]


def test_rank_deficient_jacobian_gives_nan_not_a_pseudo_inverse():
    rng = np.random.default_rng(7)
    G, cw, w, sig = _problem(rng, 0.0)               # third column = first: rank 2
    G[:, :, 1] = 0.0                                 # and a dead column
    cov, cov_gn, ok, sv, _ = estimate_covariances(G, cw, w, sig, np.zeros((3, 3)))
    assert not ok and np.all(np.isnan(cov)) and np.all(np.isnan(cov_gn))
