"""The iteration of the batch engine (:mod:`identification.fit.batch`): sweeps until every member
has converged or stopped, with the convergence test of :func:`identification.fit.refinement.refine`
and the step (Gauss-Newton far from the optimum, exact Newton near it) of every member.

One sweep: the members' data terms on the unique inputs (:func:`prepare`), their per-member
iteration state (:class:`Iteration`) and the model terms of a sweep at the active members
(:func:`evaluate`, :func:`evaluate_fused`, :func:`evaluate_shared`): the states' Newton correction,
y', G, the gradient at the corrected states, J^T Omega J and S.

The model at the (member, input) points (:class:`Points`): the per-point CasADi functions (E, h and
their derivatives; the fused sweep function of models in SX with JIT compilation), mapped over the
points and evaluated through reused buffers.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from models.contract import Model
from models.state import numerics
from identification.errors import StateSolveError
from identification.fit import newton as newton_core
from identification.fit.batch_data import LEFT_BOUNDS, BatchData, BatchSettings
from identification.fit.measurements import common_spread, data_terms
from identification.fit.settings import IdentifySettings

__all__ = ["Points", "unique_rows", "Prepared", "prepare", "Iteration", "Sweep", "evaluate", "evaluate_fused",
           "evaluate_shared", "iterate"]


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


@dataclass(frozen=True)
class Prepared:
    """The data terms of all members on the unique inputs (see :func:`prepare`)."""

    first: np.ndarray          # (n_u,) first input row of each group
    group: np.ndarray          # (n_q,) group of each input row
    zb: np.ndarray             # (R, n_u, n_S) pooled means
    wts: np.ndarray            # (R, n_u, n_S) pooled weighted counts / sigma^2
    const: np.ndarray          # (R,) constant part of Phi
    cw: np.ndarray             # (R, n_u, n_S) pooled weighted counts
    sig: np.ndarray            # (R, n_S) sigmas of the objective
    n_data: np.ndarray         # (R,) used values
    selected: np.ndarray       # sensors with w > 0
    w: np.ndarray              # (n_S,) sensor weights
    Z: np.ndarray              # (R, n_M, n_q, n_S) the members' data


def prepare(model, data: BatchData, w, Y_ref) -> Prepared:
    """Data terms of every member, as :meth:`identification.fit.refinement.ReducedProblem.of` computes them
    (c_jk = n_jk w_k, zbar the per-(input, sensor) means, Phi_0 the within-group scatter) and the
    objective's sigmas as identify chooses them, pooled over identical input rows:
    sum_{j in u} c_j (zbar_j - h)^2 = C_u (zbar_u - h)^2 + sum_{j in u} c_j (zbar_j - zbar_u)^2 with
    C_u = sum_j c_j and zbar_u = sum_j c_j zbar_j / C_u (exact)."""
    if data.shared:
        first, group = unique_rows(data.inputs, Y_ref)
    else:                            # per-member inputs: no pooling of rows
        first = group = np.arange(data.inputs.shape[1])
    n_u, R = first.size, data.n_members
    selected = np.flatnonzero(w > 0)
    Z = data.z
    if data.sigma is not None:
        sig = data.sigma
    else:                            # identify's common spread of the selected sensors
        sig = np.empty((R, model.n_S))
        for r in range(R):
            sig[r] = common_spread(Z[r][:, :, selected])
    terms = data_terms(Z, w, sig)                                           # (R, n_q, n_S) and (R,)
    counts, zbar, cw, const = terms.counts, terms.zbar, terms.cw, terms.const
    onehot = np.zeros((n_u, group.size))
    onehot[group, np.arange(group.size)] = 1.0
    C = np.einsum("uj,rjs->rus", onehot, cw)
    S1 = np.einsum("uj,rjs->rus", onehot, cw * zbar)
    zu = np.divide(S1, C, out=np.zeros_like(S1), where=C > 0)
    const = const + 0.5 * np.sum(cw * (zbar - zu[:, group]) ** 2 / sig[:, None, :] ** 2, axis=(1, 2))
    n_data = counts[:, :, w > 0].sum(axis=(1, 2)).astype(int)
    return Prepared(first, group, zu, C / sig[:, None, :] ** 2, const, C, sig, n_data, selected, w, Z)



@dataclass
class Iteration:
    """Per-member state of :func:`iterate` (mutable, private to it); the ``f*`` arrays hold each
    member's last exact point (states converged), where it stops when it has converged."""

    P: np.ndarray              # (R, n_p) current parameters
    Y: np.ndarray              # (R, n_u, n_y) current states
    newton: np.ndarray         # (R,) exact Newton phase
    active: np.ndarray         # (R,) still iterating
    done: np.ndarray           # (R,) converged
    reason: list               # why a member stopped without converging
    sweeps: np.ndarray         # (R,) sweeps taken
    has_final: np.ndarray      # (R,) an exact point was reached
    fp: np.ndarray             # (R, n_p)
    fY: np.ndarray             # (R, n_u, n_y)
    fyp: np.ndarray            # (R, n_u, n_y, n_p) state derivatives y'
    fh: np.ndarray             # (R, n_u, n_S)
    fG: np.ndarray             # (R, n_u, n_S, n_p)
    fF: np.ndarray             # (R, n_p, n_p)
    fS: np.ndarray             # (R, n_p, n_p)
    fobj: np.ndarray           # (R,) Phi
    fdec: np.ndarray           # (R,) Newton decrement (inf where H is not positive definite)
    funit: np.ndarray          # (R,) unit of the decrement (1, or s^2 / sigma_0^2 when sigma is unknown)
    fsweeps: np.ndarray        # (R,)
    halvings: np.ndarray       # (R,) step halvings since the last exact point
    dense_sweeps: int = 0      # sweeps evaluated by the dense path (evaluate)

    @classmethod
    def start(cls, P0, Y0, n_S):
        R, n_p = P0.shape
        n_u, n_y = Y0.shape[1:]
        z = np.zeros
        return cls(P0.copy(), Y0.copy(), z(R, bool), np.ones(R, bool), z(R, bool), [""] * R, z(R, int), z(R, bool),
                   z((R, n_p)), z((R, n_u, n_y)), z((R, n_u, n_y, n_p)), z((R, n_u, n_S)), z((R, n_u, n_S, n_p)),
                   z((R, n_p, n_p)), z((R, n_p, n_p)), np.full(R, np.inf), np.full(R, np.inf), np.ones(R), z(R, int),
                   z(R, int))


@dataclass(frozen=True)
class Sweep:
    """Terms of one sweep at the active members ``a`` (local index k = position in ``a``)."""

    a: np.ndarray
    P: np.ndarray
    Y: np.ndarray
    h: np.ndarray
    G: np.ndarray
    F: np.ndarray
    S: np.ndarray
    has_S: np.ndarray
    g: np.ndarray
    obj: np.ndarray
    dyE: np.ndarray
    yp: np.ndarray
    gabs: np.ndarray           # (m, n_p) sum over the data of |lambda| |G| (round-off of the gradient)
    state_ok: np.ndarray
    finite: np.ndarray


def _shared_terms_fused(model, points: Points, P1: np.ndarray, Y1: np.ndarray) -> tuple | None:
    """:func:`_shared_terms` by the fused sweep function: one mapped call at the n_u inputs with
    lambda_h = 0 (h, G, y') and with lambda_h = e_k for every sensor k (T_jk); None when E_y is not
    symmetric positive definite (or not finite) at some input (the caller takes the dense path)."""
    n_S, n_u = model.n_S, points.n_u
    Yk = np.repeat(Y1, n_S + 1, axis=0)
    Pk = np.repeat(P1, n_S + 1, axis=0)
    zero = np.zeros((n_S + 1, n_u, n_S))
    c = zero.copy()
    c[1:] = np.eye(n_S)[:, None, :]
    t = Points(model, points.Q_u, n_S + 1).sweep(Yk, Pk, zero, zero, c)
    yp, h, G, S, piv, asym = t.yp, t.h, t.G, t.S, t.pivot, t.asym
    with np.errstate(invalid="ignore"):
        good = (np.all(np.isfinite(h[0])) and np.all(np.isfinite(G[0])) and np.all(np.isfinite(yp[0]))
                and np.all(np.isfinite(S)) and np.all(piv > 0) and np.all(asym <= 1e-12))
    if not good:
        return None
    return h[0], G[0], yp[0], S[1:].transpose(1, 0, 2, 3)


def _shared_terms(model, points: Points, P1: np.ndarray, Y1: np.ndarray) -> tuple:
    """The model terms at a common point (P1 (1, n_p), Y1 (1, n_u, n_y), states solved):
    h (n_u, n_S), G (n_u, n_S, n_p), y' (n_u, n_y, n_p) and T (n_u, n_S, n_p, n_p) with
    T_jk = Z_j^T B_jk Z_j, B_jk the Hessian of the Lagrangian for lambda_h = e_k (see
    :func:`evaluate_shared`)."""
    n_p, n_y, n_S = model.n_p, model.n_y, model.n_S
    n_u = points.n_u
    if points.fused:
        got = _shared_terms_fused(model, points, P1, Y1)
        if got is not None:
            return got
    t = points.terms(Y1, P1)
    E, h, Ey, Ep, hy, hp = t.E[0], t.h[0], t.Ey[0], t.Ep[0], t.hy[0], t.hp[0]
    if not (np.all(np.isfinite(h)) and np.all(np.isfinite(Ey)) and np.all(np.isfinite(Ep))):
        raise StateSolveError("the model or its derivatives are not finite at the common start")
    if n_y:
        try:
            yp = -np.linalg.solve(Ey, Ep)
            K = np.linalg.solve(Ey.transpose(0, 2, 1), hy.transpose(0, 2, 1))      # (n_u, n_y, n_S)
        except np.linalg.LinAlgError:
            raise StateSolveError("E_y is singular at the common start") from None
        G = hp + np.einsum("jsy,jyp->jsp", hy, yp)
        Z = np.concatenate([yp, np.broadcast_to(np.eye(n_p), (n_u, n_p, n_p))], axis=1)
    else:
        K, G, Z = np.zeros((n_u, 0, n_S)), hp, np.broadcast_to(np.eye(n_p), (n_u, n_p, n_p))
    eye = np.eye(n_S)
    Yk = np.repeat(Y1, n_S, axis=0).reshape(n_S, n_u, n_y)
    Pk = np.repeat(P1, n_S, axis=0)
    lam_k = np.broadcast_to(eye[:, None, :], (n_S, n_u, n_S))
    mu_k = -K.transpose(2, 0, 1)                                                     # (n_S, n_u, n_y)
    Bk = Points(model, points.Q_u, n_S).lag_hessians(Yk, Pk, lam_k, mu_k)          # (n_S, n_u, v, v)
    T = np.einsum("jva,kjvw,jwb->jkab", Z, Bk, Z, optimize=True)                     # (n_u, n_S, n_p, n_p)
    return h, G, (Z[:, :n_y, :] if n_y else np.zeros((n_u, 0, n_p))), T


def evaluate_shared(model, prep: Prepared, points: Points, it: Iteration, a: np.ndarray) -> Sweep:
    """:func:`evaluate` when every member in ``a`` is at the same (p, states) with the states solved
    (the common start p0): the model terms are evaluated once and only the data terms differ.

    With K = E_y^{-T} h_y^T the adjoint of member r is mu_r = -K lambda_r, and since the Lagrangian
    Hessian is linear in (lambda, mu), S_r = sum_jk lambda_r,jk Z_j^T B_jk Z_j with
    B_jk = lag_hess(e_k, -K_j e_k) (one evaluation per input and sensor).
    """
    n_p, n_y = model.n_p, model.n_y
    m, n_u = a.size, points.n_u
    P1, Y1 = it.P[a[:1]], it.Y[a[:1]]
    h, G, yp, T = _shared_terms(model, points, P1, Y1)
    zb, wts = prep.zb[a], prep.wts[a]
    lam = -wts * (zb - h[None])
    g = np.einsum("mjs,jsp->mp", lam, G)
    gabs = np.einsum("mjs,jsp->mp", np.abs(lam), np.abs(G))
    F = np.broadcast_to(np.einsum("mjs,jsp,jsr->mpr", wts, G, G), (m, n_p, n_p))
    with np.errstate(over="ignore", invalid="ignore"):
        obj = 0.5 * np.einsum("mjs,mjs->m", wts, (zb - h[None]) ** 2) + prep.const[a]
    S = np.einsum("mjs,jsab->mab", lam, T)
    S = 0.5 * (S + S.transpose(0, 2, 1))
    ones = np.ones(m, bool)
    return Sweep(a, np.repeat(P1, m, axis=0), np.repeat(Y1, m, axis=0), np.broadcast_to(h, (m,) + h.shape),
                  np.broadcast_to(G, (m,) + G.shape), np.array(F), S, ones, g, obj,
                  np.zeros((m, n_u, n_y)), np.broadcast_to(yp, (m, n_u, n_y, n_p)), gabs, ones, ones.copy())


def evaluate_fused(model, prep: Prepared, points: Points, it: Iteration, a: np.ndarray,
                    bs: BatchSettings) -> Sweep | None:
    """:func:`evaluate` by one mapped call of the fused sweep function (:func:`_sweep_function`):
    every per-point term (states' Newton correction, y', G, the gradient at the corrected states,
    J^T Omega J and S) comes from CasADi and NumPy only sums over the inputs.  None when E_y is not
    certified symmetric positive definite at some point (a pivot that is not positive and finite,
    or asymmetry): the caller then takes the dense path for this sweep."""
    n_p = model.n_p
    P, Y = it.P[a], it.Y[a]
    t = points.sweep(Y, P, prep.wts[a], prep.zb[a], members=a)
    dyE, yp, h, G, g, F, S, obj, gabs = t.dyE, t.yp, t.h, t.G, t.g, t.F, t.S, t.obj, t.gabs
    piv, asym = t.pivot, t.asym
    with np.errstate(invalid="ignore", over="ignore"):
        spd = np.all((piv[..., 0] > 0) & (asym[..., 0] <= 1e-12))
        finite = (np.isfinite(h).all(axis=(1, 2)) & np.isfinite(G).all(axis=(1, 2, 3))
                  & np.isfinite(dyE).all(axis=(1, 2)) & np.isfinite(yp).all(axis=(1, 2, 3)))
    if not spd:                      # a zero, negative or non-finite pivot, or E_y not symmetric
        return None
    g, F, S, gabs = g.sum(axis=1), F.sum(axis=1), S.sum(axis=1), gabs.sum(axis=1)
    with np.errstate(over="ignore", invalid="ignore"):
        obj = obj[..., 0].sum(axis=1) + prep.const[a]
        ynorm = 1.0 + np.abs(Y).max(axis=2)
        state_ok = np.all(np.abs(dyE).max(axis=2) <= bs.state_tol * ynorm, axis=1)
    if not np.all(finite):           # neutral values where a member is not finite (it stops this sweep)
        bad = ~finite
        for arr in (dyE, yp, h, G, g, S, gabs):
            arr[bad] = 0.0
        F[bad] = np.eye(n_p)
        state_ok &= finite
    has_S = (it.newton[a] | state_ok) & finite
    S = np.where(has_S[:, None, None], 0.5 * (S + S.transpose(0, 2, 1)), 0.0)
    return Sweep(a, P, Y, h, G, F, S, has_S, g, obj, dyE, yp, gabs, state_ok, finite)


def evaluate(model, prep: Prepared, points: Points, it: Iteration, a: np.ndarray, sym: bool,
              bs: BatchSettings) -> Sweep:
    """One sweep's model terms at the members ``a``: state correction dy_E, y', G, the gradient at
    the Newton-corrected states, J^T Omega J and (Newton phase or converged states) S."""
    n_p, n_y = model.n_p, model.n_y
    P, Y = it.P[a], it.Y[a]
    m, n_u = a.size, points.n_u
    t = points.terms(Y, P, a)
    E, h, Ey, Ep, hy, hp = t.E, t.h, t.Ey, t.Ep, t.hy, t.hp
    zb, wts = prep.zb[a], prep.wts[a]
    with np.errstate(invalid="ignore", over="ignore"):
        finite = (np.isfinite(h).all(axis=(1, 2)) & np.isfinite(E).all(axis=(1, 2))
                  & np.isfinite(Ey).all(axis=(1, 2, 3)) & np.isfinite(Ep).all(axis=(1, 2, 3)))
    if not np.all(finite):           # neutral values where a member is not finite (it stops this sweep)
        fin3, fin4 = finite[:, None, None], finite[:, None, None, None]
        h, E = np.where(fin3, h, 0.0), np.where(fin3, E, 0.0)
        Ey, Ep, hy = np.where(fin4, Ey, np.eye(n_y)), np.where(fin4, Ep, 0.0), np.where(fin4, hy, 0.0)
    lam_h = -wts * (zb - h)                                               # dPhi/dh at the current states
    mu = None
    if n_y:
        Eyf = Ey
        rhs = [-E[..., None], -Ep]
        if sym:                      # E_y symmetric: the adjoint needs no second factorisation
            rhs.append(-np.matmul(lam_h[:, :, None, :], hy).swapaxes(2, 3))
        B = np.concatenate(rhs, axis=3)
        try:
            X = np.linalg.solve(Eyf, B)
        except np.linalg.LinAlgError:          # a singular E_y: find the members it belongs to
            X = np.full(B.shape, np.nan)
            for k in range(m):
                try:
                    X[k] = np.linalg.solve(Eyf[k], B[k])
                except np.linalg.LinAlgError:
                    finite[k] = False
        dyE, yp = X[..., 0], X[..., 1:1 + n_p]
        if sym and np.abs(Ey - Ey.swapaxes(2, 3)).max() <= 1e-12 * np.abs(Ey).max():
            mu = X[..., -1]          # (symmetry checked at every point; else the transpose solve below)
        G = hp + np.matmul(hy, yp)
        h_lin = h + np.matmul(hy, dyE[..., None])[..., 0]
        ynorm = 1.0 + np.abs(Y).max(axis=2)
        state_ok = np.all(np.abs(dyE).max(axis=2) <= bs.state_tol * ynorm, axis=1)
    else:
        dyE, yp = np.zeros((m, n_u, 0)), np.zeros((m, n_u, 0, n_p))
        G, h_lin = hp, h
        state_ok = np.ones(m, bool)
    finite &= np.isfinite(G).all(axis=(1, 2, 3)) & np.isfinite(dyE).all(axis=(1, 2))
    lam = -wts * (zb - h_lin)
    g = np.einsum("mjs,mjsp->mp", lam, G)
    F = np.einsum("mjs,mjsp,mjsr->mpr", wts, G, G)
    with np.errstate(over="ignore", invalid="ignore"):
        obj = 0.5 * np.einsum("mjs,mjs->m", wts, (zb - h) ** 2) + prep.const[a]
    has_S = (it.newton[a] | state_ok) & finite
    S = np.zeros((m, n_p, n_p))
    if np.any(has_S):
        b = np.flatnonzero(has_S)
        if n_y and mu is None:
            rhs_mu = -np.einsum("mjsy,mjs->mjy", hy[b], lam_h[b])
            mu_b = np.linalg.solve(Ey[b].transpose(0, 1, 3, 2), rhs_mu[..., None])[..., 0]
        else:
            mu_b = mu[b] if n_y else np.zeros((b.size, n_u, 0))
        Hl = points.lag_hessians(Y[b], P[b], lam_h[b], mu_b, a[b])         # order (y, p)
        if n_y:                      # Z^T Hl Z with Z = [y'; I], summed over the inputs
            ypb = yp[b]
            T = np.matmul(Hl[..., :n_y], ypb) + Hl[..., n_y:]                # (b, n_u, n_y + n_p, n_p)
            Sb = (np.matmul(ypb.swapaxes(2, 3), T[..., :n_y, :]) + T[..., n_y:, :]).sum(axis=1)
        else:
            Sb = Hl.sum(axis=1)
        S[b] = 0.5 * (Sb + Sb.transpose(0, 2, 1))
    gabs = np.einsum("mjs,mjsp->mp", np.abs(lam), np.abs(G))
    return Sweep(a, P, Y, h, G, F, S, has_S, g, obj, dyE, yp, gabs, state_ok, finite)


def _chol_solve(M: np.ndarray, b: np.ndarray, s_p: np.ndarray) -> tuple:
    """(x, decrement, good) with M x = b and b^T M^{-1} b for a stack M (m, n_p, n_p), through the
    Cholesky factor of diag(s_p) M diag(s_p); ``good`` False (x, decrement NaN) where M is not
    positive definite."""
    m, n_p = b.shape
    Ms = M * np.outer(s_p, s_p)[None]
    good = np.ones(m, bool)
    try:
        L = np.linalg.cholesky(Ms)
    except np.linalg.LinAlgError:
        L = np.broadcast_to(np.eye(n_p), Ms.shape).copy()
        for i in range(m):
            try:
                L[i] = np.linalg.cholesky(Ms[i])
            except np.linalg.LinAlgError:
                good[i] = False
    v = np.linalg.solve(L, (b * s_p)[:, :, None])
    x = s_p * np.linalg.solve(L.transpose(0, 2, 1), v)[:, :, 0]
    dec = np.einsum("ip,ip->i", v[:, :, 0], v[:, :, 0])
    x[~good] = np.nan
    dec[~good] = np.nan
    return x, dec, good, L




def _advance(model, prep: Prepared, it: Iteration, sw: Sweep, s_p: np.ndarray, settings: IdentifySettings,
             bs: BatchSettings, sigma_unknown: bool) -> None:
    """Convergence test (that of identification.fit.refinement.refine) and the next step of every member."""
    n_p = model.n_p
    a = sw.a
    unit = newton_core.decrement_unit(sw.obj, prep.n_data[a] - n_p) if sigma_unknown else np.ones(a.size)
    dN, decN, goodN, LN = _chol_solve(sw.F + sw.S, -sw.g, s_p)
    dG, _, goodG, _ = _chol_solve(sw.F, -sw.g, s_p)
    # the decrement that round-off in the gradient's sum over the data alone produces
    round_off = newton_core.gradient_roundoff(lambda b: np.linalg.solve(LN, b[:, :, None])[:, :, 0], sw.gabs * s_p)
    dec = np.where(goodN, decN, np.inf)
    bad = ~sw.finite
    exact = sw.state_ok & sw.has_S & ~bad
    with np.errstate(invalid="ignore"):
        increased = exact & ~newton_core.no_increase(sw.obj, it.fobj[a])
    # refine's test: a step may not increase Phi.  In the quadratic region (previous decrement below
    # decrement_tol) Phi cannot resolve the decrease any more: the step is kept while the decrement
    # falls, else the previous point is the optimum
    quadratic = it.has_final[a] & newton_core.in_quadratic_region(it.fdec[a], settings.decrement_tol * it.funit[a])
    with np.errstate(invalid="ignore"):
        keep_inc = increased & newton_core.keep_step(sw.obj, it.fobj[a], quadratic, dec, it.fdec[a])
    # outside the quadratic region an increase halves the step from the last exact point (the
    # backtracking of identify's explicit Newton; at most 30 halvings)
    back = increased & ~quadratic & (it.halvings[a] < newton_core.BATCH_MAX_HALVINGS)
    stop_inc = increased & ~keep_inc & ~back
    update = exact & ~stop_inc & ~back
    b = a[update]
    it.halvings[b] = 0
    it.has_final[b] = True
    it.fp[b], it.fY[b], it.fyp[b], it.fh[b], it.fG[b] = sw.P[update], sw.Y[update], sw.yp[update], sw.h[update], \
        sw.G[update]
    it.fF[b], it.fS[b], it.fobj[b], it.fdec[b], it.funit[b] = sw.F[update], sw.S[update], sw.obj[update], \
        dec[update], unit[update]
    it.fsweeps[b] = it.sweeps[b]
    conv = update & goodN & (newton_core.converged(decN, settings.refine_decrement * unit, round_off)
                             | newton_core.tiny_step(dN / s_p))
    it.done[a[conv | (stop_inc & quadratic)]] = True
    step = ~bad & ~stop_inc & ~conv & goodG
    use_N = it.newton[a] & sw.has_S & goodN
    dp = np.where(use_N[:, None], dN, dG)
    big = np.max(np.abs(dp / s_p), axis=1)
    it.newton[a[step & (big < bs.newton_step)]] = True
    # steps are limited relative to max(s_p, |p|): far optima (a wrong model) are reached geometrically
    rel = np.max(np.abs(dp) / np.maximum(s_p, np.abs(sw.P)), axis=1)
    dp = dp * np.where(rel > bs.max_step, bs.max_step / np.where(rel > 0, rel, 1.0), 1.0)[:, None]
    p_new = sw.P + dp
    inside = np.all((p_new > model.lower) & (p_new < model.upper), axis=1)
    for k in np.flatnonzero(back):
        i = a[k]
        d = newton_core.halved_step(it.fp[i], sw.P[k])
        it.P[i] = it.fp[i] + d
        it.Y[i] = it.fY[i] + it.fyp[i] @ d if model.n_y else it.Y[i]
        it.halvings[i] += 1
    step &= ~back
    for k in np.flatnonzero(~step & ~back | ~inside & step):
        i = a[k]
        if bad[k]:
            it.reason[i] = "the model or its derivatives are not finite (or E_y is singular) at the iterate"
        elif stop_inc[k] and not quadratic[k]:
            it.reason[i] = "a Newton step increased the objective before the optimum was reached"
        elif not (conv[k] or stop_inc[k]) and not goodG[k]:
            it.reason[i] = "J^T Omega J is singular at the iterate"
        elif step[k]:
            it.reason[i] = LEFT_BOUNDS
    step &= inside
    it.active[a[~step & ~back]] = False
    b = a[step]
    it.P[b] = p_new[step]
    if model.n_y:
        it.Y[b] = sw.Y[step] + sw.dyE[step] + np.einsum("mjyp,mp->mjy", sw.yp[step], dp[step])


def iterate(model, prep: Prepared, points: Points, s_p, P0, Y0, settings: IdentifySettings,
             bs: BatchSettings, sigma_unknown: bool, start_solved: bool) -> Iteration:
    """Sweeps until every member has converged or stopped (see the module docstring).

    ``start_solved``: the start states solve E = 0 at the start values (the first sweep of
    members sharing the start is then evaluated once, :func:`evaluate_shared`)."""
    it = Iteration.start(P0, Y0, model.n_S)
    first = bool(start_solved)
    for _ in range(bs.max_sweeps):
        a = np.flatnonzero(it.active)
        if not a.size:
            break
        it.sweeps[a] += 1
        shared = first and a.size > 1 and np.all(it.P[a] == it.P[a[0]]) and np.all(it.Y[a] == it.Y[a[0]])
        first = False
        try:
            sw = evaluate_shared(model, prep, points, it, a) if shared else None
            if sw is None and points.fused:
                sw = evaluate_fused(model, prep, points, it, a, bs)
            if sw is None:
                it.dense_sweeps += 1
                sw = evaluate(model, prep, points, it, a, points.symmetric(), bs)
        except StateSolveError as exc:
            for i in a:
                it.reason[i] = f"model evaluation failed: {exc}"
            it.active[a] = False
            break
        _advance(model, prep, it, sw, s_p, settings, bs, sigma_unknown)
    for i in np.flatnonzero(it.active):
        it.reason[i] = f"no convergence in {bs.max_sweeps} sweeps"
    it.active[:] = False
    return it
