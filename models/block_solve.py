r"""Many small dense systems A_i X_i = B_i solved at once, by compiled Gaussian elimination when JIT is on.

The trajectories of a collocated ODE (:mod:`models.trajectory`) solve one (n_x d, n_x d) block per
experiment and element in every Newton iteration: 600 blocks of 9 x 9 for the reactor's 20 experiments of
30 elements.  ``numpy.linalg.solve`` calls LAPACK once per block, and its per-block overhead (about 1.5 us,
copies included) is most of the time.  When JIT compilation is wanted (:data:`models.state.JIT`:
:func:`models.state.set_jit` or :func:`models.state.jit_scope`), :func:`solve_blocks` instead evaluates one
C-compiled CasADi function of Gaussian elimination in a fixed row order (static pivoting: the caller's order,
e.g. partial pivoting of the blocks' limit as the element length goes to 0), mapped over the blocks, and keeps
a block's solution only when every multiplier satisfies

.. math:: |l_{ic}| = |a^{(c)}_{ic} / a^{(c)}_{cc}| \le \tau = 2

and every pivot is non-zero and every entry of X finite: threshold partial pivoting with threshold 1/tau (with tau = 1
exactly the factorisation of LAPACK's partial pivoting; sparse LU codes accept pivots down to 0.1 of the
column's largest), so the solution has the backward stability of LAPACK's up to the growth factor's bound
(1 + tau)^(m-1) instead of 2^(m-1).  A block that fails the test is solved by LAPACK.  Without JIT (the
default), LAPACK solves every block, as before.  The numbers differ from LAPACK's by round-off only (the same
elimination in another order of operations).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from .batched import batched_function
from .state import JIT

__all__ = ["solve_blocks", "elimination_function", "pivot_order", "eliminate", "solved_function", "accepted", "MULTIPLIER_BOUND", "MAX_COMPILED_SIZE"]

#: a compiled block's solution is kept when every multiplier of its elimination is at most this in magnitude
MULTIPLIER_BOUND = 2.0
#: blocks larger than this (m x m) are always solved by LAPACK (the elimination's code grows like m^3)
MAX_COMPILED_SIZE = 24


def eliminate(A: ca.SX, B: ca.SX, rows, tau: float) -> tuple:
    r"""(X, fails) of X = A^{-1} B (SX expressions, A m x m, B m x k) by Gaussian elimination of the rows in
    the order ``rows`` without further pivoting: forward elimination with multipliers l_ic = a_ic / a_cc,
    back substitution x_ij = (b_ij - sum_{q > i} a_iq x_qj) / a_ii (structural zeros of A stay out of the
    operations); ``fails`` counts the multipliers with |l_ic| > ``tau`` and the zero pivots (comparisons
    only: a zero pivot makes its column's multipliers infinite, or NaN for 0 / 0, which no comparison
    counts, but the pivot itself is counted)."""
    A, B = ca.densify(A), ca.densify(B)
    m, k = B.shape
    a = [[A[i, j] for j in range(m)] for i in rows]
    b = [[B[i, j] for j in range(k)] for i in rows]
    fails = ca.SX(0)
    for c in range(m):
        fails = fails + (a[c][c] == 0)
        for i in range(c + 1, m):
            l = a[i][c] / a[c][c]
            fails = fails + (l > tau) + (l < -tau)
            a[i] = a[i][:c + 1] + [a[i][j] - l * a[c][j] for j in range(c + 1, m)]
            b[i] = [b[i][j] - l * b[c][j] for j in range(k)]
    X = [[None] * k for _ in range(m)]
    for i in range(m - 1, -1, -1):
        for j in range(k):
            s = b[i][j]
            for q in range(i + 1, m):
                s = s - a[i][q] * X[q][j]
            X[i][j] = s / a[i][i]
    return ca.vertcat(*[ca.horzcat(*row) for row in X]), fails


def elimination_function(m: int, k: int, rows, tau: float = MULTIPLIER_BOUND) -> ca.Function:
    """The SX function ``(a, b) -> (x, fails)`` of :func:`eliminate` with A and B given by their
    column-major entries a (m m) and b (m k), and x = X's column-major entries."""
    a, b = ca.SX.sym("a", m * m), ca.SX.sym("b", m * k)
    X, fails = eliminate(ca.reshape(a, m, m), ca.reshape(b, m, k), rows, tau)
    return ca.Function(f"block_solve_{m}_{k}_" + "_".join(str(int(r)) for r in rows), [a, b],
                       [ca.vec(X), fails])


def solved_function(f: ca.Function, a: int, rhs, rows, name: str, tau: float = MULTIPLIER_BOUND) -> ca.Function:
    r"""f (SX) with two more outputs: X = A^{-1} [s_1 F_1, s_2 F_2, ...] and its ``fails`` (:func:`eliminate`),
    A = f's output ``a`` and (F_i, s_i) its outputs and signs ``rhs`` = ((index, sign), ...): the element
    blocks and their solves in one (compiled) evaluation."""
    sx = f.sx_in()
    outs = f.call(sx)
    X, fails = eliminate(outs[a], ca.horzcat(*[s * outs[i] for i, s in rhs]), rows, tau)
    return ca.Function(name, sx, list(outs) + [X, fails])


def accepted(X: np.ndarray, fails: np.ndarray, A: np.ndarray, B) -> np.ndarray:
    """X (n, m, k) from the compiled elimination with its ``fails`` (n,), the blocks that failed (a multiplier
    above the bound, a zero pivot, an entry not finite) solved again by LAPACK: ``B()`` gives the right-hand
    sides (n, m, k) (built only when needed)."""
    bad = np.asarray(fails).reshape(-1) != 0
    if not np.all(np.isfinite(X)):
        bad |= ~np.all(np.isfinite(X.reshape(X.shape[0], -1)), axis=1)
    if np.any(bad):
        X = np.array(X)
        X[bad] = np.linalg.solve(A[bad], B()[bad])
    return X


def pivot_order(A0: np.ndarray) -> tuple:
    """The row order of partial pivoting on the matrix A0 (m x m): Gaussian elimination of A0's rows in this
    order has every multiplier |l| <= 1 (the first largest entry of the column is the pivot).  Blocks near
    A0 (e.g. a collocated model's element blocks near their limit as the element length goes to 0) keep
    their multipliers near those; :func:`solve_blocks` checks them block by block."""
    A = np.array(A0, float)
    m = A.shape[0]
    order = list(range(m))
    for c in range(m):
        i = c + int(np.argmax(np.abs(A[c:, c])))
        A[[c, i]], order[c], order[i] = A[[i, c]], order[i], order[c]
        if A[c, c] != 0:
            A[c + 1:] -= np.outer(A[c + 1:, c] / A[c, c], A[c])
    return tuple(order)


def solve_blocks(A: np.ndarray, B: np.ndarray, cache: dict, rows=None) -> np.ndarray:
    r"""X (n, m, k) with A_i X_i = B_i for the blocks A (n, m, m) and right-hand sides B (n, m, k).

    When JIT compilation is wanted here (:data:`models.state.JIT`) and m <= :data:`MAX_COMPILED_SIZE`: the
    compiled elimination in the row order ``rows`` (default 0, ..., m - 1; :func:`elimination_function`,
    kept in ``cache``) for every block, and LAPACK for the blocks with a multiplier above
    :data:`MULTIPLIER_BOUND`, a zero pivot or an entry of X that is not finite; otherwise ``numpy.linalg.solve``.  Raises
    ``numpy.linalg.LinAlgError`` where LAPACK finds a block singular."""
    n, m, k = B.shape
    if not JIT.active() or m > MAX_COMPILED_SIZE or n == 0:
        return np.linalg.solve(A, B)
    rows = tuple(range(m)) if rows is None else tuple(int(r) for r in rows)
    key = ("block_solve", m, k, n, rows)
    f = cache.get(key)
    if f is None:
        g = JIT.compile(elimination_function(m, k, rows, MULTIPLIER_BOUND))
        if g is None:                      # no working compiler: LAPACK
            return np.linalg.solve(A, B)
        f = cache[key] = batched_function(g, n)
    # column-major entries of every block: A_i^T and B_i^T in C order
    a = np.ascontiguousarray(A.transpose(0, 2, 1)).reshape(n, m * m)
    b = np.ascontiguousarray(B.transpose(0, 2, 1)).reshape(n, m * k)
    x, fails = f(a, b)
    return accepted(x.reshape(n, k, m).transpose(0, 2, 1), fails, A, lambda: B)
