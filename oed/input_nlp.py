r"""The full-space NLP of the continuous input refinement: states and sensitivities as variables.

For n input rows q_i = lo + span * u_i (u_i in [0, 1]) with states y_i and scaled state
sensitivities S_i = (dy_i/dp) D (D = diag of the parameters' magnitudes, a constant), the
refinement solves

.. math::

    \min_{u, y, S}\ \Psi\bigl(M^{-1}\bigr),\qquad
    M = D^{-1}\Bigl[\sum_i \tilde G_i^T W \tilde G_i\Bigr] D^{-1},\quad
    \tilde G_i = h_y S_i + h_p D,

    \text{s.t.}\quad E(y_i, p, q_i) = 0,\qquad E_y(y_i, p, q_i)\, S_i + E_p(y_i, p, q_i)\, D = 0,

W = diag(n_series / sigma_k^2) over the measured sensors.  The NLP's variables are u, y / s and S / s with
s = max(1, sqrt(n_y) / 2) (:func:`variable_scale`): Ipopt's inertia correction adds delta I over every variable,
which in the space of the inputs acts as delta (I + sum ||d(y, S)/du||^2), a sum over all states; far from the
optimum, where the criterion is not convex and delta is large, the steps in u were then tiny (437 iterations
for one start at 363 states per experiment, 14-42 with the scaling; the optimum is the same).  Every term is sparse (E_y of a collocated
dynamic model is block-banded), so Ipopt's exact-Hessian steps cost one sparse factorisation of the
KKT matrix: no dense inverse of E_y appears, and the NLP stays fast at hundreds of states per
experiment.  An explicit model (no states) has G = h_p.

The exact Hessian of the Lagrangian is assembled from small parts rather than differentiated as one
graph (:func:`_hessian_of_lagrangian`): with :math:`\tilde M = \sum_i \tilde M_i(x_i)` and the criterion's
Lagrangian :math:`\ell(\tilde M, z)` (z: the E criterion's extra variables),

.. math::

    \nabla^2 L = \mathrm{blockdiag}_i\,\nabla^2_{x_i}\bigl(\lambda_i^T c_i + \langle \nabla_{\tilde M}\ell,
    \tilde M_i\rangle\bigr) + J^T\,\nabla^2_{(\tilde M, z)}\ell\,J,\qquad J = \partial(\tilde M, z)/\partial x,

where c_i are row i's constraints.  The row block is differentiated once for one row and called per row,
and :math:`\ell` once over the n_p^2 entries of the matrix, so the construction grows linearly with the
rows (differentiating -log det of the whole graph took 20 s for one row of the DC motor, n_p = 6, and
grew faster than the rows).  :func:`information_nlp` checks a deadline between these steps.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from identification.fit.ipopt_solver import NlpProblem
from models.sensitivity import sensitivities
from models.state import solve_states
from .criteria import Criterion

__all__ = ["InformationNlp", "information_nlp", "BuildTimeout", "variable_scale", "LIFT_ABOVE", "ReducedParts",
           "reduced_parts"]


class BuildTimeout(RuntimeError):
    """The deadline passed while the refinement's NLP was being built (``phase``: the step it was in)."""

    def __init__(self, phase: str):
        super().__init__(f"time limit reached while building the refinement's NLP ({phase})")
        self.phase = phase


@dataclass(frozen=True)
class InformationNlp:
    """The refinement NLP of :func:`information_nlp` and what its starts need.

    Attributes
    ----------
    problem : NlpProblem       for :func:`identification.fit.ipopt_solver.solve_nlp` (with its Hessian)
    n_u, n_y, n_s, n_extra, n_g : int
        sizes of the blocks of x = (u, y, S, m, criterion extras) and of g
    n_m : int
        entries of the lifted information m (0: not lifted)
    information : casadi.Function
        ``(u, y, S) -> M`` (n_p, n_p), model units
    scale : ndarray (n_p,)     the diagonal of D
    """

    problem: tuple
    n_u: int
    n_y: int
    n_s: int
    n_extra: int
    n_g: int
    information: ca.Function
    scale: np.ndarray
    n_m: int = 0

    def start(self, model, p, Q, lo, span) -> np.ndarray:
        """x0 at the input rows Q (n_pts, d_q): their states, sensitivities and criterion extras."""
        U = ((Q - lo) / span).ravel()
        if model.n_y:
            Y = solve_states(model, p, Q)
            S = sensitivities(model, p, Q, Y).state_derivatives * self.scale[None, None, :]
            # S_i stored column-major (n_y, n_p) as CasADi's vec
            sv = variable_scale(model.n_y)
            ys, ss = Y.ravel() / sv, np.concatenate([s.T.ravel() for s in S]) / sv
        else:
            ys, ss = np.zeros(0), np.zeros(0)
        return np.concatenate([U, ys, ss, np.zeros(self.n_m + self.n_extra)])

    def parameter(self, M) -> np.ndarray:
        """The NLP parameter b at the information M (model units): sqrt(diag(D M D)) when lifted, else empty."""
        if not self.n_m:
            return np.zeros(0)
        d = self.scale ** 2 * np.diag(np.asarray(M, float))
        return np.sqrt(np.where(d > 0, d, 1.0))

    def lifted(self, M, b) -> np.ndarray:
        """The lifted m at the information M (model units): tril(B^-1 D M D B^-1), column-major."""
        if not self.n_m:
            return np.zeros(0)
        Ms = (self.scale / b)[:, None] * np.asarray(M, float) * (self.scale / b)[None, :]
        return Ms.T.ravel()[_tril_index(Ms.shape[0])]

    def matrix(self, x) -> np.ndarray:
        """M at the NLP point x."""
        x = np.asarray(x, float).ravel()
        n = self.n_u + self.n_y + self.n_s
        return np.array(self.information(x[:self.n_u], x[self.n_u:self.n_u + self.n_y], x[self.n_u + self.n_y:n]))


def variable_scale(n_y: int) -> float:
    """sigma = max(1, sqrt(n_y) / 2): the NLP's state and sensitivity variables are y / sigma and S / sigma
    (module docstring)."""
    return max(1.0, 0.5 * float(np.sqrt(n_y)))


def _criterion(X, crit: Criterion, Mt, scale):
    """(objective, extra variables, extra equality constraints) of Psi(M^-1), M = D^-1 Mt D^-1 (D: -log det M)."""
    n_p = Mt.size1()
    if crit is Criterion.D:      # log det M = log det Mt - 2 sum log d: the same optimum, better scaled
        return -ca.log(ca.det(Mt)) + 2.0 * float(np.sum(np.log(scale))), [], []
    Dinv = ca.DM(np.diag(1.0 / scale))
    M = ca.mtimes([Dinv, Mt, Dinv])
    if crit is Criterion.A:
        return ca.trace(ca.solve(M, X.eye(n_p))), [], []
    t = X.sym("t")
    L = X.sym("L", n_p * (n_p + 1) // 2)
    Lm = X(ca.Sparsity.lower(n_p), L)
    R = M - t * X.eye(n_p) - ca.mtimes(Lm, Lm.T)
    return -t, [t, L], [R[i, j] for i in range(n_p) for j in range(i + 1)]


def _row_functions(model, p, weights, lo, span, X) -> ca.Function:
    """``row(u, y / sigma, S / sigma) -> (c, vec Mt_i)``: one row's constraints c = (E; vec(E_y S + E_p D)) and its
    information Mt_i = G^T W G (D-scaled units), sigma = :func:`variable_scale`."""
    n_y, n_p, d = model.n_y, model.n_p, model.n_q_dim
    scale = np.where(np.abs(p) > 0, np.abs(p), 1.0)
    Dm = ca.DM(np.diag(scale))
    ys, qs, ps = X.sym("y", n_y), X.sym("q", d), X.sym("p", n_p)
    h = model.h_fun(ys, ps, qs)
    hy, hp = ca.jacobian(h, ys), ca.jacobian(h, ps)
    if n_y:
        E = model.E_fun(ys, ps, qs)
        Ey, Ep = ca.jacobian(E, ys), ca.jacobian(E, ps)
    else:
        E = Ey = Ep = X.zeros(0, 1)
    parts = ca.Function("parts", [ys, ps, qs], [E, Ey, Ep, hy, hp])
    u, y_, S_ = X.sym("u", d), X.sym("y", n_y), X.sym("S", n_y, n_p)
    y, S = variable_scale(n_y) * y_, variable_scale(n_y) * S_
    Ei, Eyi, Epi, hyi, hpi = parts(y, ca.DM(p), ca.DM(lo) + ca.DM(span) * u)
    G = ca.mtimes(hpi, Dm) + (ca.mtimes(hyi, S) if n_y else 0)
    Mt = ca.mtimes([G.T, ca.DM(np.diag(weights)), G])
    c = ca.vertcat(Ei, ca.vec(ca.mtimes(Eyi, S) + ca.mtimes(Epi, Dm))) if n_y else X.zeros(0, 1)
    return ca.Function("row", [u, y_, S_], [c, ca.vec(Mt)])


def _row_hessian(row: ca.Function, X) -> ca.Function:
    """``(u, y, S, lam_c, Lam) -> (Hessian of lam_c^T c + Lam^T vec Mt_i over (u, y, vec S),
    d vec Mt_i / d(u, y, vec S))`` of one row, built once and called per row."""
    u, y, S = X.sym("u", row.size_in(0)), X.sym("y", row.size_in(1)), X.sym("S", row.size_in(2))
    c, mt = row(u, y, S)
    lam, Lam = X.sym("lam", c.size1()), X.sym("Lam", mt.size1())
    xr = ca.vertcat(u, y, ca.vec(S))
    H = ca.hessian(ca.dot(lam, c) + ca.dot(Lam, mt), xr)[0]
    return ca.Function("row_hess", [u, y, S, lam, Lam], [H, ca.jacobian(mt, xr)])


def _row_jacobian(row: ca.Function, X) -> ca.Function:
    """``(u, y, S) -> (c, vec Mt_i, dc/d(u, y, vec S), d vec Mt_i/d(u, y, vec S))`` of one row, built once and
    called per row by :func:`_jacobian_of_constraints`."""
    u, y, S = X.sym("u", row.size_in(0)), X.sym("y", row.size_in(1)), X.sym("S", row.size_in(2))
    c, mt = row(u, y, S)
    xr = ca.vertcat(u, y, ca.vec(S))
    return ca.Function("row_jac", [u, y, S], [c, mt, ca.jacobian(c, xr), ca.jacobian(mt, xr)])


def _criterion_parts(X, crit: Criterion, n_p: int, scale, lift: bool):
    """(criterion Function ``(vec Mt, z) -> (f, cons)``, extra variables, parts Function): not lifted,
    ``parts(vec Mt, z, lam_f, lam_cons) -> (gradient over vec Mt, Hessian over (vec Mt, z))`` of
    ell = lam_f f + lam_cons^T cons; lifted, ``parts(m, z, b, lam_f, lam_cons) -> Hessian over (m, z)`` of ell at
    Mt = B sym(m) B."""
    mv = X.sym("Mt", n_p * n_p)
    f, extra, cons = _criterion(X, crit, ca.reshape(mv, n_p, n_p), scale)
    z = ca.vertcat(*extra) if extra else X.zeros(0, 1)
    fun = ca.Function("crit", [mv, z], [f, ca.vertcat(*cons) if cons else X.zeros(0, 1)])
    lam_f, lam_c = X.sym("lam_f"), X.sym("lam_cons", len(cons))
    cv = ca.vertcat(*cons) if cons else X.zeros(0, 1)
    if lift:
        m, b = X.sym("m", n_p * (n_p + 1) // 2), X.sym("b", n_p)
        fm, cm = fun(ca.vec(_unlift(X, m, b)), z)
        w = ca.vertcat(m, z)
        H = ca.hessian(lam_f * fm + (ca.dot(lam_c, cm) if cons else 0), w)[0]
        jac = ca.Function("crit_jac", [m, z, b], [cm, ca.jacobian(cm, w)])
        return fun, extra, (ca.Function("crit_parts", [m, z, b, lam_f, lam_c], [H]), jac)
    ell = lam_f * f + (ca.dot(lam_c, cv) if cons else 0)
    H, g = ca.hessian(ell, ca.vertcat(mv, z))
    jac = ca.Function("crit_jac", [mv, z], [cv, ca.jacobian(cv, ca.vertcat(mv, z))])
    return fun, extra, (ca.Function("crit_parts", [mv, z, lam_f, lam_c], [g[:n_p * n_p], H]), jac)


def _unlift(X, m, b):
    """Mt = B sym(m) B from the lower triangle m (column-major) and b."""
    n_p = b.size1()
    Ms = X(ca.Sparsity.lower(n_p), m)
    return ca.mtimes([ca.diag(b), Ms + ca.tril(Ms, False).T, ca.diag(b)])


def _tril_index(n_p: int) -> list:
    """Positions in vec (column-major) of the lower triangle's entries, in CasADi's ``Sparsity.lower`` order."""
    return [i + j * n_p for j in range(n_p) for i in range(j, n_p)]


#: lift the information matrix into variables when more NLP variables than this enter it: its dense block
#: in the unlifted Hessian (the squared count) would dominate the KKT factorisation
LIFT_ABOVE = 400


def _check(deadline: float, phase: str) -> None:
    if time.perf_counter() > deadline:
        raise BuildTimeout(phase)


def information_nlp(model, p, weights, n_pts: int, lo, span, crit: Criterion,
                    deadline: float = np.inf) -> InformationNlp:
    """The NLP of the module docstring for ``n_pts`` rows of ``model`` at the nominal ``p``.

    ``weights`` (n_S,): n_series / sigma_k^2 for measured sensors, 0 otherwise; ``lo``, ``span``
    (d_q,) map the scaled inputs u in [0, 1] to q; ``deadline`` (a ``time.perf_counter()`` value) is checked
    between the steps of the construction.

    Raises
    ------
    BuildTimeout
        When the deadline passed during the construction (its step named).
    """
    X = ca.SX if model.symbolic == "SX" else ca.MX
    n_y, n_p, d = model.n_y, model.n_p, model.n_q_dim
    scale = np.where(np.abs(p) > 0, np.abs(p), 1.0)
    row = _row_functions(model, p, weights, lo, span, X)
    _check(deadline, "the rows' equations")
    hess_row = _row_hessian(row, X)
    _check(deadline, "one row's Hessian")
    n_dense = n_pts * int(np.count_nonzero(np.asarray(hess_row.sparsity_out(1).colind()[1:])
                                           - np.asarray(hess_row.sparsity_out(1).colind()[:-1])))
    lift = n_dense > LIFT_ABOVE
    crit_fun, extra, (crit_parts, crit_jac) = _criterion_parts(X, crit, n_p, scale, lift)
    _check(deadline, "the criterion's derivatives")
    Us = [X.sym(f"u{i}", d) for i in range(n_pts)]
    Ys = [X.sym(f"y{i}", n_y) for i in range(n_pts)]
    Ss = [X.sym(f"S{i}", n_y, n_p) for i in range(n_pts)]
    g, mv = [], 0
    for u, y, S in zip(Us, Ys, Ss):
        c, mt = row(u, y, S)
        mv = mv + mt
        if n_y:
            g.append(c)
    z = ca.vertcat(*extra) if extra else X.zeros(0, 1)
    n_m = n_p * (n_p + 1) // 2 if lift else 0
    m, b = X.sym("m", n_m), X.sym("b", n_p if lift else 0)
    if lift:
        tri = _tril_index(n_p)
        bb = ca.vec(ca.mtimes(b, b.T))[tri]
        g.append(mv[tri] / bb - m)
        f, cons = crit_fun(ca.vec(_unlift(X, m, b)), z)
    else:
        f, cons = crit_fun(mv, z)
    U, Y, S = ca.vertcat(*Us), ca.vertcat(*Ys), ca.vertcat(*[ca.vec(s) for s in Ss])
    x = ca.vertcat(U, Y, S, m, z)
    gg = ca.vertcat(*g, cons)
    Dinv = ca.DM(np.diag(1.0 / scale))
    info = ca.Function("M", [U, Y, S], [ca.mtimes([Dinv, ca.reshape(mv, n_p, n_p), Dinv])])
    _check(deadline, "the rows' constraints")
    n_c = [c.size1() for c in g[:n_pts]] if n_y else [0] * n_pts
    hess = _hessian_of_lagrangian((n_pts, d, n_y, n_p, n_m), x.size1(), (row, hess_row, crit_parts), n_c,
                                  cons.size1())
    _check(deadline, "the Hessian of the Lagrangian")
    jac = _jacobian_of_constraints((n_pts, d, n_y, n_p, n_m), x.size1(), (_row_jacobian(row, X), crit_jac), n_c)
    _check(deadline, "the constraints' Jacobian")
    return InformationNlp(NlpProblem(x, f, gg, b, hess_lag=hess, jac_g=jac), U.size1(), Y.size1(), S.size1(),
                          z.size1(), gg.size1(), info, scale, n_m)


@dataclass(frozen=True)
class ReducedParts:
    """One row's CasADi Functions for the reduced-space Newton of :mod:`oed.input_newton` (x_i = (u, y / s,
    vec S / s), s = :func:`variable_scale`; c and Mt_i as in :func:`_row_functions`).

    Attributes
    ----------
    row : casadi.Function          ``(u, y, S) -> (c, vec Mt_i)``
    row_jacobian : casadi.Function ``(u, y, S) -> (dE/dy, dc_S/dy, dc/du, d vec Mt_i/dx_i)`` (c = (E; c_S), c_S =
                                   vec(E_y S + E_p D); dc/dS is dE/dy on every column of S and not formed)
    row_hessian : casadi.Function  ``(u, y, S, lam, Lam) -> Hessian over x_i of lam^T c + Lam^T vec Mt_i``
    state_jacobian : casadi.Function ``(u, y) -> dE/dy`` (the first output of ``row_jacobian``)
    criterion : casadi.Function    ``(vec Mt, lam_f) -> (d f/d vec Mt, d^2 f/d vec Mt^2)`` scaled by lam_f
    scale : ndarray (n_p,)         the diagonal of D
    """

    row: ca.Function
    row_jacobian: ca.Function
    row_hessian: ca.Function
    criterion: ca.Function
    scale: np.ndarray
    state_jacobian: ca.Function


def reduced_parts(model, p, weights, lo, span, crit: Criterion, deadline: float = np.inf) -> ReducedParts:
    """The Functions of :class:`ReducedParts` for the D or A criterion (arguments as :func:`information_nlp`;
    the E criterion has extra variables and stays with the full-space NLP).

    Raises
    ------
    ValueError
        For the E criterion.
    BuildTimeout
        When the deadline passed during the construction (its step named).
    """
    if crit is Criterion.E:
        raise ValueError("criterion: the reduced-space Newton takes D or A (E is refined in the full space)")
    X = ca.SX if model.symbolic == "SX" else ca.MX
    scale = np.where(np.abs(p) > 0, np.abs(p), 1.0)
    row = _row_functions(model, p, weights, lo, span, X)
    _check(deadline, "the rows' equations")
    u, y, S = X.sym("u", row.size_in(0)), X.sym("y", row.size_in(1)), X.sym("S", row.size_in(2))
    c, mt = row(u, y, S)
    lam, Lam = X.sym("lam", c.size1()), X.sym("Lam", mt.size1())
    xr = ca.vertcat(u, y, ca.vec(S))
    hess = ca.Function("row_hess", [u, y, S, lam, Lam], [ca.hessian(ca.dot(lam, c) + ca.dot(Lam, mt), xr)[0]])
    _check(deadline, "one row's Hessian")
    n_y, d = row.size_in(1)[0], row.size_in(0)[0]
    Jc = ca.jacobian(c, ca.vertcat(u, y))
    jac = ca.Function("row_jac_blocks", [u, y, S], [Jc[:n_y, d:], Jc[n_y:, d:], Jc[:, :d], ca.jacobian(mt, xr)])
    # dE/dy alone: SX's slice of Jc is free of S; an MX graph still holds S, so E is differentiated at S = 0
    A = Jc[:n_y, d:] if X is ca.SX else ca.jacobian(row(u, y, X.zeros(n_y, S.size2()))[0][:n_y], y)
    state_jac = ca.Function("row_state_jac", [u, y], [A])
    _check(deadline, "one row's Jacobian")
    n_p = model.n_p
    _, _, (parts, _) = _criterion_parts(X, crit, n_p, scale, False)
    mv, lam_f = X.sym("Mt", n_p * n_p), X.sym("lam_f")
    g, H = parts(mv, X.zeros(0, 1), lam_f, X.zeros(0, 1))
    _check(deadline, "the criterion's derivatives")
    return ReducedParts(row, jac, hess, ca.Function("crit_derivatives", [mv, lam_f], [g, H]), scale, state_jac)


def _hessian_of_lagrangian(dims, n_x: int, functions, n_c: list, n_cons: int) -> ca.Function:
    """``(x, b, lam_f, lam_g) -> triu(lam_f f_xx + sum lam_g g_xx)`` assembled (module docstring) in an MX graph
    that calls the row's and the criterion's Functions: ``functions`` = (row, its Hessian, the criterion's
    parts), ``n_c`` the rows' constraint counts, ``n_cons`` the criterion's; ``dims`` = (rows, inputs per row,
    states, parameters, lifted entries)."""
    n_pts, d, n_y, n_p, n_m = dims
    row, hess_row, crit_parts = functions
    x, lam_f = ca.MX.sym("x", n_x), ca.MX.sym("lam_f")
    lam_g, b = ca.MX.sym("lam_g", sum(n_c) + n_m + n_cons), ca.MX.sym("b", n_p if n_m else 0)
    n_u, n_s = n_pts * d, n_y * n_p
    n_w = n_x - n_u - n_pts * (n_y + n_s)                  # (m, z): the criterion's own variables
    mv, rows, idx = 0, [], []
    for i in range(n_pts):
        ix = (list(range(i * d, (i + 1) * d)) + list(range(n_u + i * n_y, n_u + (i + 1) * n_y))
              + list(range(n_u + n_pts * n_y + i * n_s, n_u + n_pts * n_y + (i + 1) * n_s)))
        xi = (x[ix[:d]], x[ix[d:d + n_y]], ca.reshape(x[ix[d + n_y:]], n_y, n_p))
        if not n_m:
            mv = mv + row(*xi)[1]
        rows.append(xi)
        idx += ix
    idx += list(range(n_x - n_w, n_x))
    w = x[n_x - n_w:]
    lam_cons = lam_g[sum(n_c) + n_m:]
    if n_m:
        tri = _tril_index(n_p)
        sel = ca.DM(ca.Sparsity.triplet(n_p * n_p, n_m, tri, list(range(n_m))), 1.0)
        Lam = ca.mtimes(sel, lam_g[sum(n_c):sum(n_c) + n_m] / ca.vec(ca.mtimes(b, b.T))[tri])
        Hw = crit_parts(w[:n_m], w[n_m:], b, lam_f, lam_cons)
    else:
        Lam, Hw = crit_parts(mv, w, lam_f, lam_cons)
    off = np.cumsum([0] + list(n_c))
    blocks, jacs = [], []
    for i, xi in enumerate(rows):
        Hi, Ji = hess_row(*xi, lam_g[int(off[i]):int(off[i + 1])], Lam)
        blocks.append(Hi)
        jacs.append(Ji)
    inv = list(np.argsort(idx))
    if n_m:
        H = ca.diagcat(*blocks, Hw)[inv, inv]
    else:
        blocks.append(ca.MX(n_w, n_w))
        # J: d(vec Mt, z)/dx, the rows' Jacobians side by side, then the identity on z; columns in x's order
        J = ca.diagcat(ca.horzcat(*jacs), ca.MX.eye(n_w))[:, inv] if n_w else ca.horzcat(*jacs)[:, inv]
        H = ca.diagcat(*blocks)[inv, inv] + ca.mtimes([J.T, Hw, J])
    return ca.Function("hess_lag", [x, b, lam_f, lam_g], [ca.triu(H)])


def _row_slices(x, dims, n_x: int):
    """(per row (u_i, y_i, S_i) sliced from x, the positions in x of the rows' variables then (m, z))."""
    n_pts, d, n_y, n_p, _ = dims
    n_u, n_s = n_pts * d, n_y * n_p
    rows, idx = [], []
    for i in range(n_pts):
        ix = (list(range(i * d, (i + 1) * d)) + list(range(n_u + i * n_y, n_u + (i + 1) * n_y))
              + list(range(n_u + n_pts * n_y + i * n_s, n_u + n_pts * n_y + (i + 1) * n_s)))
        rows.append((x[ix[:d]], x[ix[d:d + n_y]], ca.reshape(x[ix[d + n_y:]], n_y, n_p)))
        idx += ix
    return rows, idx + list(range(len(idx), n_x))


def _jacobian_of_constraints(dims, n_x: int, functions, n_c: list) -> ca.Function:
    r"""``(x, b) -> (g, dg/dx)`` assembled in an MX graph: the rows' constraints' Jacobian is block-diagonal
    (row i's block from one row's Jacobian Function, called per row), the lifted rows
    :math:`\mathrm{tril}(\sum_i \tilde M_i)/bb - m` read :math:`\partial \mathrm{vec}\,\tilde M_i/\partial x_i`
    side by side (and -I on m), the criterion's constraints (E) the chain rule through (vec Mt, z) or (m, z).
    ``functions`` = (:func:`_row_jacobian`'s Function, the criterion's ``crit_jac``); ``n_c`` the rows'
    constraint counts; ``dims`` = (rows, inputs per row, states, parameters, lifted entries).  The same matrix as
    CasADi's Jacobian of the whole constraint vector, without differentiating the whole graph at ``nlpsol``."""
    n_pts, _, _, n_p, n_m = dims
    row_jac, crit_jac = functions
    x, b = ca.MX.sym("x", n_x), ca.MX.sym("b", n_p if n_m else 0)
    rows, idx = _row_slices(x, dims, n_x)
    n_w = n_x - sum(r[0].size1() + r[1].size1() + r[2].numel() for r in rows)
    w = x[n_x - n_w:]
    parts = [row_jac(*xi) for xi in rows]
    mv = sum((pt[1] for pt in parts), ca.MX.zeros(n_p * n_p, 1))
    JM = ca.horzcat(*[pt[3] for pt in parts])                     # d vec Mt / d(rows' variables)
    g = [pt[0] for pt in parts]
    Jc = ca.horzcat(ca.diagcat(*[pt[2] for pt in parts]), ca.MX(sum(n_c), n_w))
    blocks = [Jc]
    if n_m:
        tri = _tril_index(n_p)
        bb = ca.vec(ca.mtimes(b, b.T))[tri]
        g.append(mv[tri] / bb - w[:n_m])
        lifted = ca.horzcat(ca.mtimes(ca.diag(1.0 / bb), JM[tri, :]), -ca.MX.eye(n_m), ca.MX(n_m, n_w - n_m))
        blocks.append(lifted)
        cons, Jcons = crit_jac(w[:n_m], w[n_m:], b)
        blocks.append(ca.horzcat(ca.MX(Jcons.size1(), JM.size2()), Jcons))
    else:
        cons, Jcons = crit_jac(mv, w)
        n_mm = n_p * n_p
        blocks.append(ca.horzcat(ca.mtimes(Jcons[:, :n_mm], JM), Jcons[:, n_mm:]))
    g.append(cons)
    inv = list(np.argsort(idx))
    J = ca.vertcat(*blocks)[:, inv]
    return ca.Function("nlp_jac_g", [x, b], [ca.vertcat(*g), J], ["x", "p"], ["g", "jac_g_x"])
