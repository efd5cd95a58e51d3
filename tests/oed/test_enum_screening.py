"""Screened enumeration (cheap lower values first, exact evaluation only where the incumbent may be
beaten) returns the same design and value as evaluating every design exactly."""
import numpy as np
import pytest

from oed.constraints import make_constraints
from oed.criteria import Criterion, batch_criteria, screening_values, validate_information
from oed.enumeration import EnumerationSettings, enumerate_designs, iter_designs



def rank_one(rng, n, p):
    a = rng.standard_normal((n, p))
    return np.einsum("ki,kj->kij", a, a)


def low_rank(rng, n, p):
    a = rng.standard_normal((n, 2, p))
    return np.einsum("kri,krj->kij", a, a)


def second_order_terms(rng, F, scale):
    """Symmetric indefinite S_k of norm ``scale`` * ||F_k||."""
    b = rng.standard_normal(F.shape)
    S = b + b.transpose(0, 2, 1)
    return scale * S * (np.linalg.norm(F, axis=(1, 2)) / np.linalg.norm(S, axis=(1, 2)))[:, None, None]


@pytest.mark.parametrize("kind", ["gauss_newton", "second_order"])
@pytest.mark.parametrize("crit", "ADE")
def test_screened_enumeration_equals_full_enumeration(crit, kind):
    for seed in range(12):
        rng = np.random.default_rng([seed, ord(crit), len(kind)])
        p = int(rng.integers(2, 5))
        n = int(rng.integers(p + 2, 13))
        F = rank_one(rng, n, p) if seed % 2 else low_rank(rng, n, p)
        if seed % 4 == 3:
            F[:2] = F[2]                      # duplicated candidates: exact ties between designs
        S = second_order_terms(rng, F, scale=float(rng.choice([0.05, 0.5])))
        F, S = validate_information(F, S)
        # max_sensors: small designs are singular, so the screen meets singular matrices too
        cons = make_constraints(n, p, max_sensors=int(rng.integers(p, n)))
        small = EnumerationSettings(batch_size=int(rng.integers(5, 200)))
        a = enumerate_designs(F, S, cons, crit, kind, settings=small)
        b = enumerate_designs(F, S, cons, crit, kind, settings=EnumerationSettings(screen=False))
        # equal up to the rounding of batched LAPACK calls on different batch shapes (1 ulp seen)
        assert abs(a.value - b.value) <= 1e-12 * max(abs(b.value), 1.0)
        if not np.array_equal(a.w, b.w):       # only an exact tie may pick another design
            va, vb = batch_criteria(F, S, np.stack([a.w, b.w]), kind, validated=True).value(Criterion.parse(crit))
            assert abs(va - vb) <= 1e-12 * max(abs(vb), 1.0)
        assert a.n_evaluated == b.n_evaluated == cons.count_designs() and a.n_exact <= a.n_evaluated


@pytest.mark.parametrize("kind", ["gauss_newton", "second_order"])
@pytest.mark.parametrize("crit", "ADE")
def test_screening_values_never_exceed_the_criterion(crit, kind):
    rng = np.random.default_rng(ord(crit))
    F = low_rank(rng, 10, 4)
    F, S = validate_information(F, second_order_terms(rng, F, scale=0.3))
    W = np.concatenate(list(iter_designs(make_constraints(10, 4, n_sensors=5))))
    exact = batch_criteria(F, S, W, kind, validated=True).value(Criterion.parse(crit))
    sv = screening_values(F, S, W, crit, kind)
    ok = np.isfinite(exact)
    assert ok.sum() > 100
    tol = 1e-9 * np.maximum(np.abs(exact[ok]), 1.0)
    assert np.all(sv[ok] <= exact[ok] + tol)


@pytest.mark.parametrize("kind", ["gauss_newton", "second_order"])
@pytest.mark.parametrize("crit", "ADE")
def test_parameters_in_very_different_units_keep_the_screen_exact(crit, kind):
    """F_k = T A_k T with T = diag(1, 1e-2, 5e3), the spread of the cstr study (a rate in 1/min, an
    energy in kJ/mol, ...): the
    information spans 14 decades, the unscaled log det / inverse rounded far beyond the screening
    margin and every design was screened out (found on an input design of the cstr study)."""
    rng = np.random.default_rng(ord(crit) + len(kind))
    T = np.diag([1.0, 1e-2, 5e3])
    A = low_rank(rng, 13, 3)
    F = T @ A @ T
    F, S = validate_information(F, second_order_terms(rng, F, scale=0.1))
    cons = make_constraints(13, 3, n_sensors=6)
    a = enumerate_designs(F, S, cons, crit, kind)
    b = enumerate_designs(F, S, cons, crit, kind, settings=EnumerationSettings(screen=False))
    assert a.w is not None and np.isfinite(a.value)
    assert abs(a.value - b.value) <= 1e-9 * max(abs(b.value), 1.0)
    W = np.concatenate(list(iter_designs(cons)))
    exact = batch_criteria(F, S, W, kind, validated=True).value(Criterion.parse(crit))
    sv = screening_values(F, S, W, crit, kind)
    ok = np.isfinite(exact)
    assert np.all(sv[ok] <= exact[ok] + 1e-9 * np.maximum(np.abs(exact[ok]), 1.0))
