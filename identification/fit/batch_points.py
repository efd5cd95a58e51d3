"""Mapped evaluation of one model at many (member, input) points for the batch engine
(:mod:`identification.fit.batch`): the per-point CasADi functions (E, h and their derivatives; the
fused sweep function of models in SX with JIT compilation), mapped over the points and evaluated
through reused buffers."""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from models.contract import Model
from models.state import numerics
from identification.errors import StateSolveError

__all__ = ["Points", "unique_rows"]




def unique_rows(inputs: np.ndarray, Y: np.ndarray) -> tuple:
    """(first row of each group, group of each row): rows with equal q and equal states at p0."""
    n = inputs.shape[0]
    group = np.full(n, -1)
    firsts = []
    scale = 1.0 + (np.abs(Y).max() if Y.size else 0.0)
    for j in range(n):
        for g, i in enumerate(firsts):
            if np.array_equal(inputs[j], inputs[i]) and (not Y.size or np.max(np.abs(Y[j] - Y[i])) <= 1e-10 * scale):
                group[j] = g
                break
        else:
            group[j] = len(firsts)
            firsts.append(j)
    return np.array(firsts, int), group


def _padded(m: int, R: int) -> int:
    """Members of one mapped evaluation: R when more than half are active, else the next power of two
    (few distinct map sizes, so few mapped CasADi functions are built)."""
    if 2 * m > R:
        return R
    return 1 << max(0, (m - 1).bit_length())


class _Mapped:
    """A CasADi function mapped over n points, evaluated through one reused FunctionBuffer.

    Arguments are C-contiguous (n, d_i) arrays (row = point); outputs are the dense C arrays
    (n, cols, rows) of CasADi's column-major (rows, cols n) results (transpose the last two axes).
    """

    def __init__(self, f, n: int):
        fm = f.map(n)
        sym = fm.mx_in()
        self._f = ca.Function(f"{f.name()}_batch_{n}", sym, [ca.densify(o) for o in fm.call(sym)])
        self.n = n
        self._in = [f.size1_in(i) for i in range(f.n_in())]
        self._out = [(f.size1_out(i), f.size2_out(i)) for i in range(f.n_out())]
        self._buf, self._ev = self._f.buffer()

    def __call__(self, *args) -> list:
        keep = []
        for i, (a, r) in enumerate(zip(args, self._in)):
            a = np.ascontiguousarray(a, dtype=float)
            if a.size != self.n * r:
                raise ValueError(f"argument {i}: expected {self.n} x {r} values, got {a.shape}")
            keep.append(a)
            self._buf.set_arg(i, memoryview(a.reshape(-1)))
        outs = [np.empty((self.n, c, r)) for r, c in self._out]
        for i, o in enumerate(outs):
            self._buf.set_res(i, memoryview(o.reshape(-1)))
        self._ev()
        if self._buf.ret() != 0:
            raise StateSolveError(f"evaluation of {self._f.name()} failed (CasADi return code {self._buf.ret()})")
        return outs


def _point_functions(model) -> dict:
    """The per-point functions of the batch engine (JIT-compiled as the model's others when
    models.state.set_jit is on): ``terms`` (y, p, q) -> (E, h, E_y, E_p, h_y, h_p) and ``lag_hess``."""
    num = numerics(model)
    compiled = num.jit_active()
    got = model.cache.get("batch.point_functions", compiled)
    if got is not None:
        return got
    S = ca.SX if model.symbolic == "SX" else ca.MX
    y, p, q = S.sym("y", model.n_y), S.sym("p", model.n_p), S.sym("q", model.n_q_dim)
    h, Ey, Ep, hy, hp = num.sens(y, p, q)
    terms = ca.Function("batch_terms", [y, p, q], [model.E_fun(y, p, q), h, Ey, Ep, hy, hp])
    fns = {"terms": num.compiled("batch_terms", terms), "lag_hess": num.compiled("lag_hess")}
    return model.cache.put("batch.point_functions", compiled, fns)


#: the outputs of :func:`_sweep_function` that are matrices (y', G, F, S); the others are vectors
_SWEEP_MATRICES = (1, 3, 5, 6)


@dataclass(frozen=True)
class SweepTerms:
    """The outputs of :func:`_sweep_function` at every (member, input) point, each (m, n_u, ...), named
    as the function's outputs: state correction dyE, y' (yp), h, G, gradient g, F = G^T W G, S, obj,
    gabs, the LDL pivot ratio and the asymmetry of E_y."""

    dyE: np.ndarray
    yp: np.ndarray
    h: np.ndarray
    G: np.ndarray
    g: np.ndarray
    F: np.ndarray
    S: np.ndarray
    obj: np.ndarray
    gabs: np.ndarray
    pivot: np.ndarray
    asym: np.ndarray


@dataclass(frozen=True)
class ModelTerms:
    """E, h and their derivatives E_y, E_p, h_y, h_p at every (member, input) point, each (m, n_u, ...)."""

    E: np.ndarray
    h: np.ndarray
    Ey: np.ndarray
    Ep: np.ndarray
    hy: np.ndarray
    hp: np.ndarray


def _sweep_function(model) -> ca.Function | None:
    r"""The fused per-point function of a sweep, or None when the model does not qualify.

    (y, p, q, wts, zb, c) -> (dy_E, y', h, G, g, F, S, obj, gabs, pivot, asym) at one (member,
    input) point, with lambda_h = c - wts (zb - h) (dPhi/dh at the current states; c = 0 in a
    sweep, unit vectors for the basis of the shared first sweep) and, through one sparse LDL^T
    factorisation of E_y (CasADi ``ldl`` with AMD ordering, no pivoting; valid where E_y is
    symmetric positive definite, which ``pivot`` > 0 and ``asym`` <= 1e-12 certify):

    dy_E = -E_y^{-1} E, y' = -E_y^{-1} E_p, mu = -E_y^{-1} h_y^T lambda_h, G = h_p + h_y y',
    h_lin = h + h_y dy_E, lambda = -wts (zb - h_lin), g = G^T lambda, F = G^T diag(wts) G,
    S = Z^T (d^2/dv^2 (lambda_h^T h + mu^T E)) Z with v = (y, p), Z = [y'; I] (exact AD,
    forward over reverse), obj = 1/2 sum wts (zb - h)^2, gabs = |G|^T |lambda|,
    pivot = min D / max |D|, asym = max |E_y - E_y^T| / max |E_y|.

    Qualifies: a model in SX with states (n_y > 0, dense numerics), a symmetric sparsity pattern of
    E_y, and JIT compilation active (the CasADi virtual machine evaluates this function slower
    than the dense path evaluates its parts).  Kept in ``model.cache``."""
    num = numerics(model)
    if not (model.n_y and num.jit_active()):
        return None
    got = model.cache.get("batch.sweep_function", True)
    if got is not None:
        return got or None
    n_y, n_p, n_S = model.n_y, model.n_p, model.n_S
    y, p, q = ca.SX.sym("y", n_y), ca.SX.sym("p", n_p), ca.SX.sym("q", model.n_q_dim)
    wts, zb, c = ca.SX.sym("wts", n_S), ca.SX.sym("zb", n_S), ca.SX.sym("c", n_S)
    E = model.E_fun(y, p, q)
    h, Ey, Ep, hy, hp = num.sens(y, p, q)
    if not Ey.sparsity().is_symmetric():
        return model.cache.put("batch.sweep_function", True, False) or None
    D, LT, perm = ca.ldl(Ey, True)
    lam_h = c - wts * (zb - h)
    X = ca.ldl_solve(ca.horzcat(-E, -Ep, -ca.mtimes(hy.T, lam_h)), D, LT, perm)
    dyE, yp, mu = X[:, 0], X[:, 1:1 + n_p], X[:, 1 + n_p]
    G = hp + ca.mtimes(hy, yp)
    lam = -wts * (zb - h - ca.mtimes(hy, dyE))
    v = ca.vertcat(y, p)
    lam_s, mu_s, Z_s = ca.SX.sym("lam", n_S), ca.SX.sym("mu", n_y), ca.SX.sym("Z", n_y + n_p, n_p)
    L = ca.dot(lam_s, h) + ca.dot(mu_s, E)
    SZ = ca.Function("sz", [v, q, lam_s, mu_s, Z_s], [ca.mtimes(Z_s.T, ca.jtimes(ca.gradient(L, v), v, Z_s))])
    S = SZ(v, q, lam_h, mu, ca.vertcat(yp, ca.SX.eye(n_p)))
    absD = ca.fabs(D)
    outs = [dyE, yp, h, G, ca.mtimes(G.T, lam), ca.mtimes(G.T, ca.mtimes(ca.diag(wts), G)), S,
            0.5 * ca.dot(wts, (zb - h) ** 2), ca.mtimes(ca.fabs(G).T, ca.fabs(lam)),
            ca.mmin(D) / ca.mmax(absD), ca.mmax(ca.fabs(Ey - Ey.T)) / ca.mmax(ca.fabs(Ey))]
    f = ca.Function("batch_sweep", [y, p, q, wts, zb, c], [ca.densify(o) for o in outs],
                    ["y", "p", "q", "wts", "zb", "c"],
                    ["dyE", "yp", "h", "G", "g", "F", "S", "obj", "gabs", "pivot", "asym"])
    g = num.compiled("batch_sweep", f)
    if g is f:                          # no compiler after all: the dense path
        return model.cache.put("batch.sweep_function", True, False) or None
    return model.cache.put("batch.sweep_function", True, g)


def _mapped(model, name: str, n: int) -> _Mapped:
    """The :class:`_Mapped` evaluator of a point function over n points (kept in ``model.cache``)."""
    key = (name, n, numerics(model).jit_active())
    f = model.cache.get("batch.mapped", key)
    if f is None:
        base = _sweep_function(model) if name == "sweep" else _point_functions(model)[name]
        f = model.cache.put("batch.mapped", key, _Mapped(base, n), maxsize=256)
    return f


class Points:
    """Mapped evaluation of the model at (member, unique input) points: E, h and derivatives.

    ``Q_u`` (n_u, d_q): the inputs of every member; (R, n_u, d_q): each member's own (the methods
    then take ``members``, the members' positions in Q_u)."""

    def __init__(self, model: Model, Q_u: np.ndarray, R: int, p0: np.ndarray | None = None,
                 Y_u: np.ndarray | None = None):
        self.model, self.Q_u, self.R = model, Q_u, R
        self.n_u = Q_u.shape[-2]
        self.fused = _sweep_function(model) is not None
        self._start = (p0, Y_u)
        self._sym = None

    def symmetric(self) -> bool:
        """:func:`_symmetric` at the start (p0, Y_u), evaluated once, when the dense path first needs it."""
        if self._sym is None:
            p0, Y_u = self._start
            self._sym = p0 is not None and _symmetric(self.model, self, p0, Y_u if Y_u.ndim == 2 else Y_u[0],
                                                      None if self.Q_u.ndim == 2 else np.zeros(1, int))
        return self._sym

    def sweep(self, Y: np.ndarray, P: np.ndarray, wts: np.ndarray, zb: np.ndarray,
              c: np.ndarray | None = None, members: np.ndarray | None = None) -> SweepTerms:
        """The outputs of :func:`_sweep_function` at Y (m, n_u, n_y), P (m, n_p) and the data terms
        wts, zb, c (m, n_u, n_S) (c None: zero), each (m, n_u, ...) (matrices in row-major order)."""
        m, n, Yf, Pf, Qf = self._args(Y, P, members)
        mp = n // self.n_u
        idx = np.minimum(np.arange(mp), m - 1)
        W, Zb = wts[idx].reshape(n, -1), zb[idx].reshape(n, -1)
        C = np.zeros_like(W) if c is None else c[idx].reshape(n, -1)
        outs = _mapped(self.model, "sweep", n)(Yf, Pf, Qf, W, Zb, C)
        k, sh = m * self.n_u, (m, self.n_u)
        res = []
        for i, o in enumerate(outs):
            o = o[:k].reshape(sh + o.shape[1:])
            res.append(o.swapaxes(2, 3) if i in _SWEEP_MATRICES else o[..., 0, :])
        return SweepTerms(*res)                 # in the order of the function's outputs

    def _args(self, Y, P, members=None):
        m = P.shape[0]
        mp = _padded(m, self.R)
        idx = np.minimum(np.arange(mp), m - 1)
        n = mp * self.n_u
        Yf = Y[idx].reshape(n, -1)
        Pf = np.repeat(P[idx], self.n_u, axis=0)
        if self.Q_u.ndim == 2:
            Qf = np.tile(self.Q_u, (mp, 1))
        else:                        # per-member inputs: the rows of each evaluated member
            Qf = self.Q_u[np.asarray(members)[idx]].reshape(n, -1)
        return m, n, Yf, Pf, Qf

    def terms(self, Y: np.ndarray, P: np.ndarray, members: np.ndarray | None = None) -> ModelTerms:
        """The :class:`ModelTerms` at Y (m, n_u, n_y), P (m, n_p)."""
        m, n, Yf, Pf, Qf = self._args(Y, P, members)
        E, h, Ey, Ep, hy, hp = _mapped(self.model, "terms", n)(Yf, Pf, Qf)      # the outputs of "terms"
        k, sh = m * self.n_u, (m, self.n_u)

        def matrix(a):
            return a[:k].reshape(sh + a.shape[1:]).swapaxes(2, 3)
        return ModelTerms(E=E[:k, 0].reshape(sh + (-1,)), h=h[:k, 0].reshape(sh + (-1,)), Ey=matrix(Ey),
                          Ep=matrix(Ep), hy=matrix(hy), hp=matrix(hp))

    def lag_hessians(self, Y, P, lam, mu, members: np.ndarray | None = None) -> np.ndarray:
        """Hessians of lam^T h + mu^T E w.r.t. (y, p) at every point, (m, n_u, n_y + n_p, n_y + n_p)."""
        m, n, Yf, Pf, Qf = self._args(Y, P, members)
        mp = n // self.n_u
        idx = np.minimum(np.arange(mp), m - 1)
        L = lam[idx].reshape(n, -1)
        Mu = mu[idx].reshape(n, -1)
        Hl = _mapped(self.model, "lag_hess", n)(Yf, Pf, Qf, L, Mu)[0]       # symmetric: no transpose
        k = m * self.n_u
        return Hl[:k].reshape((m, self.n_u) + Hl.shape[1:])



def _symmetric(model, points: Points, p0: np.ndarray, Y_u: np.ndarray, members=None) -> bool:
    """True when E_y is symmetric at the start (checked at every unique input to 1e-12 relative; with
    per-member inputs at those of ``members``): the adjoint E_y^{-T} h_y^T lambda then shares the
    factorisation of the other solves."""
    if not model.n_y:
        return False
    try:
        Ey = points.terms(Y_u[None], p0[None], members).Ey[0]
    except StateSolveError:
        return False
    return bool(np.all(np.abs(Ey - Ey.transpose(0, 2, 1)) <= 1e-12 * np.abs(Ey).max(axis=(1, 2))[:, None, None]))
