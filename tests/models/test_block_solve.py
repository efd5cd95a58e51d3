"""models.block_solve: many small systems by Gaussian elimination in a fixed row order (compiled with JIT),
checked block by block (multipliers at most 2, no zero pivot, finite), LAPACK for the blocks that fail."""
import casadi as ca
import numpy as np

from models.block_solve import elimination_function, pivot_order, solve_blocks, solved_function
from models.state import jit_scope

RNG = np.random.default_rng(7)


def _blocks(n=50, m=6, k=3):
    A = RNG.standard_normal((n, m, m)) + 4 * np.eye(m)
    return A, RNG.standard_normal((n, m, k))


def _eval(f, A, B):
    """f at every block through CasADi's virtual machine (no compiler needed): (X, fails)."""
    n, m, k = B.shape
    X, fails = np.empty_like(B), np.empty(n)
    for i in range(n):
        x, c = f(A[i].T.ravel(), B[i].T.ravel())
        X[i], fails[i] = np.asarray(x).reshape(k, m).T, np.asarray(c).item()
    return X, fails


def test_elimination_equals_lapack_and_counts_large_multipliers_and_zero_pivots():
    A, B = _blocks()
    X0 = np.linalg.solve(A, B)
    X, fails = _eval(elimination_function(6, 3, range(6)), A, B)
    assert np.all(fails == 0) and np.abs(X - X0).max() <= 1e-12 * np.abs(X0).max()
    A[3, 0, 0] = 0.0                                   # zero first pivot
    A[5, 0, 0], A[5, 2, 0] = 0.1, 1.0                  # multiplier 10 > MULTIPLIER_BOUND
    _, fails = _eval(elimination_function(6, 3, range(6)), A, B)
    assert fails[3] >= 1 and fails[5] >= 1 and np.all(np.delete(fails, [3, 5]) == 0)


def test_pivot_order_gives_multipliers_at_most_one():
    A0 = np.kron(np.array([[3.3, 1.2, -0.25], [-3.6, 0.85, 1.05], [5.5, -7.5, 5.0]]), np.eye(3))
    rows = pivot_order(A0)
    assert sorted(rows) == list(range(9))
    natural = _eval(elimination_function(9, 1, range(9), tau=1.0), A0[None], np.ones((1, 9, 1)))[1][0]
    ordered = _eval(elimination_function(9, 1, rows, tau=1.0), A0[None], np.ones((1, 9, 1)))[1][0]
    assert natural > 0 and ordered == 0                # the natural order needs a multiplier of 4.6 here


def test_solve_blocks_with_jit_equals_lapack_and_falls_back_on_failed_blocks():
    A, B = _blocks()
    A[7, 0, 0] = 0.0
    A[9, 0, 0], A[9, 4, 0] = 1e-3, 1.0
    X0 = np.linalg.solve(A, B)
    cache = {}
    with jit_scope(True):                              # without a compiler: LAPACK, the same test holds
        X = solve_blocks(A, B, cache)
    assert np.abs(X - X0).max() <= 1e-12 * np.abs(X0).max()
    assert np.abs(X[[7, 9]] - X0[[7, 9]]).max() == 0   # the failed blocks are LAPACK's
    with jit_scope(False):
        assert np.array_equal(solve_blocks(A, B, cache), X0)    # without JIT: LAPACK, bit for bit


def test_solved_function_appends_the_solves_of_its_blocks():
    v = ca.SX.sym("v", 3)
    R = ca.vertcat(4 * v[0] + v[1] - 1, v[0] + 5 * v[1] + v[2] ** 2, v[1] + 6 * v[2])
    f = ca.Function("f", [v], [R, ca.jacobian(R, v)])
    g = solved_function(f, 1, ((0, 1), (0, -2)), range(3), "g")
    r, J, X, fails = (np.asarray(o) for o in g([0.3, -0.2, 0.5]))
    assert fails.item() == 0
    assert np.abs(X - np.linalg.solve(J, np.hstack([r, -2 * r]))).max() <= 1e-14
