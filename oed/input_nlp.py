r"""The full-space NLP of the continuous input refinement: states and sensitivities as variables.

For n input rows q_i = lo + span * u_i (u_i in [0, 1]) with states y_i and scaled state
sensitivities S_i = (dy_i/dp) D (D = diag of the parameters' magnitudes, a constant), the
refinement solves

.. math::

    \min_{u, y, S}\ \Psi\bigl(M^{-1}\bigr),\qquad
    M = D^{-1}\Bigl[n_\text{series}\sum_i \tilde G_i^T W \tilde G_i\Bigr] D^{-1},\quad
    \tilde G_i = h_y S_i + h_p D,

    \text{s.t.}\quad E(y_i, p, q_i) = 0,\qquad E_y(y_i, p, q_i)\, S_i + E_p(y_i, p, q_i)\, D = 0,

W = diag(1 / sigma_k^2) over the measured sensors.  Every term is sparse (E_y of a collocated
dynamic model is block-banded), so Ipopt's exact-Hessian steps cost one sparse factorisation of the
KKT matrix: no dense inverse of E_y appears, and the NLP stays fast at hundreds of states per
experiment.  An explicit model (no states) has G = h_p.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from identification.fit.ipopt_solver import NlpProblem
from models.sensitivity import sensitivities
from models.state import solve_states
from .criteria import Criterion

__all__ = ["InformationNlp", "information_nlp"]


@dataclass(frozen=True)
class InformationNlp:
    """The refinement NLP of :func:`information_nlp` and what its starts need.

    Attributes
    ----------
    problem : NlpProblem       for :func:`identification.fit.ipopt_solver.solve_nlp` (with its Hessian)
    n_u, n_y, n_s, n_extra, n_g : int
        sizes of the blocks of x = (u, y, S, criterion extras) and of g
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

    def start(self, model, p, Q, lo, span) -> np.ndarray:
        """x0 at the input rows Q (n_pts, d_q): their states, sensitivities and criterion extras."""
        U = ((Q - lo) / span).ravel()
        if model.n_y:
            Y = solve_states(model, p, Q)
            S = sensitivities(model, p, Q, Y).state_derivatives * self.scale[None, None, :]
            # S_i stored column-major (n_y, n_p) as CasADi's vec
            ys, ss = Y.ravel(), np.concatenate([s.T.ravel() for s in S])
        else:
            ys, ss = np.zeros(0), np.zeros(0)
        return np.concatenate([U, ys, ss, np.zeros(self.n_extra)])

    def matrix(self, x) -> np.ndarray:
        """M at the NLP point x."""
        x = np.asarray(x, float).ravel()
        n = self.n_u + self.n_y + self.n_s
        return np.array(self.information(x[:self.n_u], x[self.n_u:self.n_u + self.n_y], x[self.n_u + self.n_y:n]))


def _criterion(X, crit: Criterion, M, n_p):
    """(objective, extra variables, extra equality constraints) of Psi(M^-1) (D: log det C)."""
    if crit is Criterion.A:
        return ca.trace(ca.solve(M, X.eye(n_p))), [], []
    if crit is Criterion.D:
        return -ca.log(ca.det(M)), [], []
    t = X.sym("t")
    L = X.sym("L", n_p * (n_p + 1) // 2)
    Lm = X(ca.Sparsity.lower(n_p), L)
    R = M - t * X.eye(n_p) - ca.mtimes(Lm, Lm.T)
    return -t, [t, L], [R[i, j] for i in range(n_p) for j in range(i + 1)]


def _hessian_of_lagrangian(X, x, f, g, par) -> ca.Function:
    """``(x, par, lam_f, lam_g) -> triu(lam_f f_xx + sum lam_g g_xx)``, the objective's and the
    constraints' Hessians taken apart (CasADi's Hessian of the whole Lagrangian colours the dense
    block of the criterion together with the sparse constraints: 4x slower to build here)."""
    lam_f, lam_g = X.sym("lam_f"), X.sym("lam_g", g.size1())
    H = lam_f * ca.hessian(f, x)[0] + ca.hessian(ca.dot(lam_g, g), x)[0]
    return ca.Function("hess_lag", [x, par, lam_f, lam_g], [ca.triu(H)])


def information_nlp(model, p, weights, n_pts: int, lo, span, crit: Criterion) -> InformationNlp:
    """The NLP of the module docstring for ``n_pts`` rows of ``model`` at the nominal ``p``.

    ``weights`` (n_S,): n_series / sigma_k^2 for measured sensors, 0 otherwise; ``lo``, ``span``
    (d_q,) map the scaled inputs u in [0, 1] to q."""
    X = ca.SX if model.symbolic == "SX" else ca.MX
    n_y, n_p, d = model.n_y, model.n_p, model.n_q_dim
    scale = np.where(np.abs(p) > 0, np.abs(p), 1.0)
    Dm, pp = ca.DM(np.diag(scale)), ca.DM(p)
    ys, qs, ps = X.sym("y", n_y), X.sym("q", d), X.sym("p", n_p)
    h = model.h_fun(ys, ps, qs)
    hy, hp = ca.jacobian(h, ys), ca.jacobian(h, ps)
    if n_y:
        E = model.E_fun(ys, ps, qs)
        Ey, Ep = ca.jacobian(E, ys), ca.jacobian(E, ps)
    else:
        E = Ey = Ep = X.zeros(0, 1)
    parts = ca.Function("parts", [ys, ps, qs], [E, Ey, Ep, hy, hp])
    Us = [X.sym(f"u{i}", d) for i in range(n_pts)]
    Ys = [X.sym(f"y{i}", n_y) for i in range(n_pts)]
    Ss = [X.sym(f"S{i}", n_y, n_p) for i in range(n_pts)]
    W = ca.DM(np.diag(weights))
    Mt, g = X.zeros(n_p, n_p), []
    for u, y, S in zip(Us, Ys, Ss):
        q = ca.DM(lo) + ca.DM(span) * u
        Ei, Eyi, Epi, hyi, hpi = parts(y, pp, q)
        G = ca.mtimes(hpi, Dm) + (ca.mtimes(hyi, S) if n_y else 0)
        Mt = Mt + ca.mtimes([G.T, W, G])
        if n_y:
            g += [Ei, ca.vec(ca.mtimes(Eyi, S) + ca.mtimes(Epi, Dm))]
    Dinv = ca.DM(np.diag(1.0 / scale))
    M = ca.mtimes([Dinv, Mt, Dinv])
    if crit is Criterion.D:      # log det M = log det Mt - 2 sum log d: the same optimum, better scaled
        f, extra, cons = -ca.log(ca.det(Mt)) + 2.0 * float(np.sum(np.log(scale))), [], []
    else:
        f, extra, cons = _criterion(X, crit, M, n_p)
    U, Y, S = ca.vertcat(*Us), ca.vertcat(*Ys), ca.vertcat(*[ca.vec(s) for s in Ss])
    x = ca.vertcat(U, Y, S, *extra)
    gg = ca.vertcat(*g, *cons) if (g or cons) else X.zeros(0, 1)
    info = ca.Function("M", [U, Y, S], [M])
    par = X.sym("par", 0)
    return InformationNlp(NlpProblem(x, f, gg, par, hess_lag=_hessian_of_lagrangian(X, x, f, gg, par)),
                          U.size1(), Y.size1(), S.size1(),
                          x.size1() - U.size1() - Y.size1() - S.size1(), gg.size1(), info, scale)
