"""Criterion values, singular / near-singular handling, input validation."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from oed.criteria import Criterion, batch_criteria, criterion_value, validate_information


def _inst(seed, n=5, p=3):
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((n, p))
    F = np.einsum("ki,kj->kij", a, a)
    b = rng.standard_normal((n, p, p)) * 0.05
    return F, b + b.transpose(0, 2, 1)


@given(st.integers(0, 10_000))
@settings(max_examples=40, deadline=None)
def test_values_match_direct_formulas(seed):
    F, S = _inst(seed)
    w = np.array([1, 1, 0, 1, 1.0])
    G = np.einsum("k,kij->ij", w, F)
    H = np.einsum("k,kij->ij", w, F + S)
    C = np.linalg.inv(H) @ G @ np.linalg.inv(H)
    Cgn = np.linalg.inv(G)
    assert criterion_value(F, S, w, "A") == pytest.approx(np.trace(C), rel=1e-9)
    assert criterion_value(F, S, w, "D") == pytest.approx(np.linalg.slogdet(C)[1], rel=1e-9, abs=1e-9)
    assert criterion_value(F, S, w, "E") == pytest.approx(np.linalg.eigvalsh(C)[-1], rel=1e-9)
    assert criterion_value(F, S, w, "A", "gauss_newton") == pytest.approx(np.trace(Cgn), rel=1e-9)
    assert criterion_value(F, S, w, "D", "gauss_newton") == pytest.approx(-np.linalg.slogdet(G)[1], rel=1e-9, abs=1e-9)
    assert criterion_value(F, S, w, "E", "gauss_newton") == pytest.approx(1 / np.linalg.eigvalsh(G)[0], rel=1e-9)


def test_second_order_equals_gn_when_s_is_zero():
    F, _ = _inst(1)
    w = np.array([1, 0, 1, 1, 0.0])
    for c in "ADE":
        assert criterion_value(F, None, w, c, "second_order") == pytest.approx(
            criterion_value(F, None, w, c, "gauss_newton"), rel=1e-12)


def test_singular_design_is_infinite_and_flagged():
    F, S = _inst(2)
    w = np.array([1, 1, 0, 0, 0.0])  # rank 2 < n_p = 3
    for kind in ("gauss_newton", "second_order"):
        res = batch_criteria(F, S, w[None], kind)
        assert res.singular[0] and "singular" in res.reason[0]
        assert np.isinf(res.A[0]) and np.isinf(res.logdet[0]) and np.isinf(res.E[0])


def test_near_singular_flagged_with_reason():
    rng = np.random.default_rng(3)
    a = rng.standard_normal((3, 2))
    a[1] = a[0] + 1e-5 * rng.standard_normal(2)  # nearly parallel sensors (cond ~ 1e11)
    F = np.einsum("ki,kj->kij", a, a)
    res = batch_criteria(F, None, np.array([[1, 1, 0], [1, 0, 1.0]]))
    assert res.near_singular[0] and not res.singular[0]
    assert "near-singular" in res.reason[0] and "1e+10" in res.reason[0]
    assert np.isfinite(res.A[0]) and not res.near_singular[1] and res.reason[1] == ""


def test_det_reported_with_logdet():
    F, S = _inst(4)
    res = batch_criteria(F, S, np.ones((1, 5)), "second_order")
    assert res.det[0] == pytest.approx(np.exp(res.logdet[0]), rel=1e-12)


def test_criterion_parser():
    assert Criterion.parse("e") is Criterion.E and Criterion.parse(Criterion.A) is Criterion.A
    with pytest.raises(ValueError, match=r"criterion: .*'X'.*A, D, E"):
        Criterion.parse("X")


@pytest.mark.parametrize("bad, arg, msg", [
    (np.ones((3, 2)), "F", "shape"),
    (np.full((3, 2, 2), np.nan), "F", "NaN"),
    (np.array([[[1.0, 2.0], [0.0, 1.0]]] * 3), "F", "not symmetric"),
    (np.array([[[1.0, 0.0], [0.0, -1.0]]] * 3), "F", "positive semidefinite"),
])
def test_bad_information_matrices(bad, arg, msg):
    with pytest.raises(ValueError, match=rf"^{arg}: .*{msg}"):
        validate_information(bad)


def test_psd_tolerance_is_relative_to_norm():
    F = np.array([[[1e6, 0.0], [0.0, -1e-5]]] * 3)  # -1e-5 is round-off relative to 1e6
    validate_information(F)
    with pytest.raises(ValueError, match="S: .*shape"):
        validate_information(F, np.zeros((3, 3, 3)))
    with pytest.raises(ValueError, match="S: .*NaN"):
        validate_information(F, np.full((3, 2, 2), np.nan))
    with pytest.raises(ValueError, match="w: "):
        criterion_value(F, None, np.ones(4), "A")
    with pytest.raises(ValueError, match="w: "):
        criterion_value(F, None, None, "A")
