r"""Reduced-space projected Newton for the continuous input refinement (D and A criteria).

For n input rows with scaled inputs u_i in [0, ub_i] (ub = 1, or 0 for an input whose bounds are equal), the
states and scaled sensitivities w_i = (y_i, S_i) are functions of u_i through c_i(u_i, w_i) = 0
(:mod:`oed.input_nlp`), so the refinement is the bound-constrained problem in the inputs alone

.. math::

    \min_{0 \le u \le ub}\ \phi(u) = \Psi\Bigl(\sum_i \tilde M_i\bigl(u_i, w_i(u_i)\bigr)\Bigr),

solved by a projected Newton method (Bertsekas 1982) with the exact reduced derivatives: with
:math:`Z_i = -c_{w}^{-1} c_{u}` (the inputs' directional sensitivities of (y, S)), :math:`T_i = \partial_u \tilde M_i
+ \partial_w \tilde M_i Z_i`, :math:`\Lambda = \partial\Psi/\partial \mathrm{vec}\,\tilde M` and the adjoint
:math:`c_w^T\lambda_i = -(\partial_w \mathrm{vec}\,\tilde M_i)^T\Lambda`,

.. math::

    \nabla\phi = T^T\Lambda,\qquad
    \nabla^2\phi = T^T\,\nabla^2\Psi\,T + \mathrm{blockdiag}_i\,[I; Z_i]^T\,\nabla^2_{x_i}\bigl(\lambda_i^T c_i +
    \Lambda^T \mathrm{vec}\,\tilde M_i\bigr)\,[I; Z_i],

every derivative from CasADi (:func:`oed.input_nlp.reduced_parts`).  c_w is block lower-triangular with dE/dy on
its diagonal blocks, so one sparse LU of dE/dy per row and point serves every solve, the sensitivities
S = -(dE/dy)^-1 E_p D at each trial point included (the states come from :func:`models.state.solve_states`).  The
Hessian is n_u x n_u (the inputs only): a step costs a state solve per trial point and d + 1 sparse solves per
row, against the full-space KKT system of every state and sensitivity that Ipopt factorises at each of its (more)
iterations.

On the free inputs the step is Newton's along the Hessian's eigenvectors of positive curvature and goes downhill
by at least the trust radius along those of negative curvature, so that it descends where the criterion is not
convex; the active inputs (within min(1e-3, projected gradient) of a bound, the gradient pointing out) move onto
that bound.  The step is capped at a trust radius (no scaled input moves more than 0.25 at first, up to 1),
projected on the box and halved until Armijo's condition holds.  Converged when the projected gradient's largest
entry is below ``tol`` x max(1, |phi|), or where the Hessian is positive semi-definite on the free inputs and the
step predicts a decrease below the criterion's accuracy (:data:`NOISE` x max(1, |phi|)).
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csc_matrix
from scipy.sparse.linalg import splu

from identification.errors import StateSolveError
from models.state import solve_states
from .criteria import Criterion
from .input_nlp import ReducedParts, variable_scale

__all__ = ["NewtonOutcome", "newton_refine", "information_value", "reduced_point"]

#: Armijo's sufficient-decrease fraction and the number of step halvings before a step is refused
ARMIJO = 1e-4
MAX_HALVINGS = 40
#: the criterion's relative accuracy as evaluated (its states solved by Newton on the collocation equations:
#: ~1e-11 relative on the Pyomo.DoE reactor); a Newton step predicting less decrease has converged
NOISE = 1e-12
#: the largest move of any scaled input in one step (a trust radius on [0, 1]): at first, its bounds, and the
#: factor it grows by after a full step that reached it (it shrinks to the move of a step that needed halving)
START_RADIUS, MIN_RADIUS, MAX_RADIUS = 0.25, 1e-3, 1.0


@dataclass(frozen=True)
class NewtonOutcome:
    """One start of :func:`newton_refine`: the rows reached (scaled inputs u), the criterion there (inf when the
    start had no state solution), whether it converged, the iterations and a message."""

    u: np.ndarray
    value: float
    converged: bool
    iterations: int
    message: str


def information_value(crit: Criterion, M) -> float:
    """Psi(M^-1) evaluated exactly from the eigenvalues of M (D: log det C = -log det M); inf when M is singular."""
    ev = np.linalg.eigvalsh(0.5 * (M + M.T))
    if ev[0] <= 0:
        return np.inf
    if crit is Criterion.A:
        return float(np.sum(1.0 / ev))
    if crit is Criterion.D:
        return float(-np.sum(np.log(ev)))
    return float(1.0 / ev[0])


class _Call:
    """A CasADi Function evaluated into NumPy buffers (``Function.buffer``: no DM conversion); sparse outputs are
    read as CSC matrices with the output's fixed pattern.  The results are the buffers themselves (copy to keep)."""

    def __init__(self, fn):
        self.buf, self.trigger = fn.buffer()
        self.args = [np.zeros(fn.nnz_in(i)) for i in range(fn.n_in())]
        self.res = [np.zeros(fn.nnz_out(i)) for i in range(fn.n_out())]
        for i, a in enumerate(self.args):
            self.buf.set_arg(i, memoryview(a))
        for i, r in enumerate(self.res):
            self.buf.set_res(i, memoryview(r))
        # one CSC matrix per output with its fixed pattern (CasADi's column-compressed order is SciPy's canonical
        # one), whose values are overwritten at each call
        self.matrices = [csc_matrix((np.zeros(fn.nnz_out(i)), np.array(fn.sparsity_out(i).row(), dtype=np.int32),
                                     np.array(fn.sparsity_out(i).colind(), dtype=np.int32)),
                                    shape=fn.sparsity_out(i).shape) for i in range(fn.n_out())]

    def __call__(self, *args):
        for a, v in zip(self.args, args):
            a[:] = np.ravel(v, order="F")
        self.trigger()
        return self.res

    def sparse(self, i: int) -> csc_matrix:
        """Output i as a CSC matrix: the same object at every call, holding the last call's values."""
        m = self.matrices[i]
        m.data[:] = self.res[i]
        return m

    def dense(self, i: int) -> np.ndarray:
        """Output i as a dense array (a copy)."""
        return self.sparse(i).toarray()


class _Numerics:
    """The Functions of :class:`oed.input_nlp.ReducedParts` as buffered calls, for one Newton run."""

    def __init__(self, parts: ReducedParts):
        self.row, self.jac, self.hess, self.crit, self.state_jac = (
            _Call(f) for f in (parts.row, parts.row_jacobian, parts.row_hessian, parts.criterion, parts.state_jacobian))


#: the buffered calls of the last few ReducedParts (the parts are cached per model and reused), per thread: a
#: buffer holds one evaluation at a time
_NUMERICS: dict = {}


def _numerics(parts: ReducedParts) -> _Numerics:
    key = (id(parts), threading.get_ident())
    got = _NUMERICS.get(key)
    if got is None or got[0] is not parts:
        if len(_NUMERICS) >= 8:
            _NUMERICS.pop(next(iter(_NUMERICS)))
        got = _NUMERICS[key] = (parts, _Numerics(parts))
    return got[1]


class _Rows:
    """The rows' states and sensitivities at the scaled inputs U (n_pts, d) and the information there."""

    def __init__(self, model, p, parts: ReducedParts, num: _Numerics, U, box):
        lo, span = box
        Q = lo + span * U
        n_p = model.n_p
        self.lu = [None] * len(U)
        if model.n_y:
            # the scaled sensitivities from the rows' own equations: c_S = A S + vec(E_p D) = 0, A = dE/dy (scaled)
            Y = solve_states(model, p, Q) / variable_scale(model.n_y)
            zero = np.zeros((model.n_y, n_p))
            self.rows = []
            for i in range(len(U)):
                cS0 = num.row(U[i], Y[i], zero)[0][model.n_y:].reshape(n_p, model.n_y).T
                num.state_jac(U[i], Y[i])
                self.lu[i] = splu(num.state_jac.sparse(0).copy())
                self.rows.append((U[i], Y[i], -self.lu[i].solve(np.ascontiguousarray(cS0))))
        else:
            self.rows = [(U[i], np.zeros(0), np.zeros((0, n_p))) for i in range(len(U))]
        self.mv = sum(num.row(*r)[1].copy() for r in self.rows)
        Dinv = 1.0 / parts.scale
        self.M = Dinv[:, None] * self.mv.reshape(n_p, n_p, order="F") * Dinv[None, :]


class _Constraints:
    r"""Solves with c_w = dc/d(y, S) of one row, block lower-triangular: [[A, 0], [X, I (x) A]] with A = dE/dy
    (the S-rows' diagonal blocks are A too: c_S = vec(E_y S + E_p D) is E_y on every column of S), so one sparse
    LU of A (n_y x n_y) serves every solve."""

    def __init__(self, lu, X: csc_matrix, n_p: int):
        self.n_y, self.n_p = X.shape[1], n_p
        self.lu = lu
        self.X = X.copy()

    def _blocks(self, R, trans: str) -> np.ndarray:
        m = R.shape[1]
        B = R.reshape(self.n_p, self.n_y, m).transpose(1, 0, 2).reshape(self.n_y, self.n_p * m)
        Z = self.lu.solve(np.ascontiguousarray(B), trans=trans)
        return Z.reshape(self.n_y, self.n_p, m).transpose(1, 0, 2).reshape(self.n_p * self.n_y, m)

    def solve(self, R) -> np.ndarray:
        """c_w^{-1} R (R: n_y (1 + n_p) x m)."""
        zy = self.lu.solve(np.ascontiguousarray(R[:self.n_y]))
        return np.vstack([zy, self._blocks(R[self.n_y:] - self.X @ zy, "N")])

    def solve_transposed(self, b) -> np.ndarray:
        """c_w^{-T} b (b: n_y (1 + n_p))."""
        ls = self._blocks(b[self.n_y:, None], "T")[:, 0]
        return np.concatenate([self.lu.solve(b[:self.n_y] - self.X.T @ ls, trans="T"), ls])


def _derivatives(num: _Numerics, rows: _Rows, dims):
    """(gradient, Hessian) of phi over the rows' scaled inputs (module docstring); ``dims`` = (d, n_y, n_p)."""
    d, n_y, n_p = dims
    num.crit(rows.mv, 1.0)
    gM, HM = num.crit.res[0].copy(), num.crit.dense(1)
    T, blocks = [], []
    for (u, y, S), lu in zip(rows.rows, rows.lu):
        num.jac(u, y, S)
        Jm = num.jac.dense(3)
        if n_y:
            cw = _Constraints(lu, num.jac.sparse(1), n_p)
            Z = -cw.solve(num.jac.dense(2))
            lam = cw.solve_transposed(-(Jm[:, d:].T @ gM))
            E = np.vstack([np.eye(d), Z])
            T.append(Jm[:, :d] + Jm[:, d:] @ Z)
        else:
            lam, E = np.zeros(0), np.eye(d)
            T.append(Jm)
        num.hess(u, y, S, lam, gM)
        blocks.append(E.T @ (num.hess.sparse(0) @ E))
    Ta = np.hstack(T)
    Hr = Ta.T @ HM @ Ta
    for i, B in enumerate(blocks):
        Hr[i * d:(i + 1) * d, i * d:(i + 1) * d] += B
    return Ta.T @ gM, 0.5 * (Hr + Hr.T)


def reduced_point(model, p, parts: ReducedParts, U, box, crit: Criterion):
    """(phi, its gradient, its Hessian) at the scaled rows U (n_pts, d) (module docstring); ``box`` = (lo, span) with
    q = lo + span * u.  Raises :class:`identification.errors.StateSolveError` when the rows have no state
    solution."""
    U = np.atleast_2d(np.asarray(U, float))
    num = _numerics(parts)
    rows = _Rows(model, p, parts, num, U, box)
    g, H = _derivatives(num, rows, (U.shape[1], model.n_y, model.n_p))
    return information_value(crit, rows.M), g, H


def _direction(g, H, free, radius: float):
    """(step, whether the free block of H is positive semi-definite): the step on the free variables (zero elsewhere): Newton's along the Hessian's eigenvectors of positive
    curvature (eigenvalues at least 1e-8 of the largest magnitude), and along those of negative curvature downhill
    by at least ``radius`` (the criterion falls faster than linearly there)."""
    dvec = np.zeros_like(g)
    if not np.any(free):
        return dvec, True
    w, V = np.linalg.eigh(H[np.ix_(free, free)])
    a = V.T @ g[free]
    size = np.abs(a) / np.maximum(np.abs(w), 1e-8 * max(float(np.max(np.abs(w))), 1e-300))
    size = np.where(w < 0, np.maximum(size, radius), size)
    dvec[free] = -V @ (np.sign(a) * size)
    return dvec, bool(np.all(w >= 0))


def newton_refine(model, p, parts: ReducedParts, U0, box, crit: Criterion, *, tol: float = 1e-9,
                  max_iter: int = 100, deadline: float = np.inf) -> NewtonOutcome:
    r"""u* = argmin over 0 <= u <= ub of phi(u) = Psi(sum_i Mt_i(u_i, w_i(u_i))) (the criterion of the scaled
    information, dimensionless; u the scaled inputs, q = lo + span * u in the inputs' units) by the projected Newton
    of the module docstring, from the scaled rows U0.

    Parameters
    ----------
    model, p
        The model and its parameters (those of ``parts``).
    parts : ReducedParts
        :func:`oed.input_nlp.reduced_parts` of the same p, weights, bounds and criterion.
    U0 : ndarray (n_pts, d)
        The start: scaled inputs in [0, ub] (clipped onto it).
    box : tuple
        (lo, span, ub) with q = lo + span * u; ub (d,) is 1, or 0 for an input whose bounds are equal.
    crit : Criterion
        D or A.
    tol : float
        Converged when the largest entry of the projected gradient is below ``tol`` x max(1, |phi|).
    max_iter : int
        Newton iterations at most.
    deadline : float
        A ``time.perf_counter()`` value (s), checked before each iteration: past it the run stops and returns the
        best point reached so far (every point is a design within the bounds), not converged, saying so.

    Returns
    -------
    NewtonOutcome
        The rows reached, phi there (inf without a state solution at the start), whether it converged, the
        iterations and why it stopped.
    """
    lo, span, ub = box
    n_pts, d = np.shape(U0)
    u = np.clip(np.asarray(U0, float).ravel(), 0.0, np.tile(ub, n_pts))
    ubx = np.tile(ub, n_pts)
    num = _numerics(parts)
    try:
        cur = _Rows(model, p, parts, num, u.reshape(n_pts, d), (lo, span))
    except StateSolveError as exc:
        return NewtonOutcome(u.reshape(n_pts, d), np.inf, False, 0, f"no state solution at the start ({exc})")
    f = information_value(crit, cur.M)
    if not np.isfinite(f):
        return NewtonOutcome(u.reshape(n_pts, d), np.inf, False, 0, "singular information at the start")
    radius = START_RADIUS
    for k in range(max_iter):
        if time.perf_counter() > deadline:
            return NewtonOutcome(u.reshape(n_pts, d), f, False, k, f"stopped by the time limit after {k} Newton "
                                 "iterations: the best point so far is kept (not converged)")
        g, H = _derivatives(num, cur, (d, model.n_y, model.n_p))
        pg = u - np.clip(u - g, 0.0, ubx)
        pgn = float(np.max(np.abs(pg))) if pg.size else 0.0
        if pgn <= tol * max(1.0, abs(f)):
            return NewtonOutcome(u.reshape(n_pts, d), f, True, k, f"converged ({k} Newton iterations)")
        eps = min(1e-3, pgn)
        low, high = (u <= eps) & (g > 0), (u >= ubx - eps) & (g < 0)
        free = ~(low | high | (ubx <= 0))
        step, convex = _direction(g, H, free, radius)
        step[low], step[high] = -u[low], (ubx - u)[high]         # the active inputs onto their bounds
        if convex and -(g @ step + 0.5 * step @ H @ step) <= NOISE * max(1.0, abs(f)):
            return NewtonOutcome(u.reshape(n_pts, d), f, True, k, f"converged ({k} Newton iterations; the Newton "
                                 f"step's predicted decrease is below the criterion's accuracy, projected gradient "
                                 f"{pgn:.2g})")
        if not g @ (np.clip(u + step, 0.0, ubx) - u) < 0:     # not a descent once projected: the gradient's
            step = -g * (1.0 / max(float(np.max(np.abs(np.diag(H)))), 1e-300))
        step *= min(1.0, radius / max(float(np.max(np.abs(step))), 1e-300))
        for h in range(MAX_HALVINGS):
            un = np.clip(u + step, 0.0, ubx)
            try:
                trial = _Rows(model, p, parts, num, un.reshape(n_pts, d), (lo, span))
                fn = information_value(crit, trial.M)
            except StateSolveError:
                fn = np.inf
            if np.isfinite(fn) and fn <= f + ARMIJO * float(g @ (un - u)):
                break
            step = 0.5 * step
        else:
            return NewtonOutcome(u.reshape(n_pts, d), f, pgn <= 1e-6 * max(1.0, abs(f)), k,
                                 f"no decrease along the step after {k} Newton iterations (projected gradient "
                                 f"{pgn:.2g}): the point is kept")
        moved = float(np.max(np.abs(un - u)))
        radius = min(2.0 * radius, MAX_RADIUS) if h == 0 and moved >= 0.5 * radius else (
            radius if h == 0 else max(moved, MIN_RADIUS))
        u, f, cur = un, fn, trial
    return NewtonOutcome(u.reshape(n_pts, d), f, False, max_iter, f"not converged in {max_iter} Newton iterations "
                         "(the point reached is kept)")
