"""The iteration of the batch engine (:mod:`identification.fit.batch`): sweeps until every member
has converged or stopped, with the convergence test of :func:`identification.fit.refinement.refine`
and the step (Gauss-Newton far from the optimum, exact Newton near it) of every member.

One sweep: the members' data terms on the unique inputs (:func:`prepare`), their per-member
iteration state (:class:`Iteration`) and the model terms of a sweep at the active members
(:func:`evaluate`, :func:`evaluate_fused`, :func:`evaluate_shared`): the states' Newton correction,
y', G, the gradient at the corrected states, J^T Omega J and S.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from identification.errors import StateSolveError
from identification.fit import newton as newton_core
from identification.fit.batch_data import LEFT_BOUNDS, BatchData, BatchSettings
from identification.fit.batch_points import Points, unique_rows
from identification.fit.measurements import common_spread, data_terms
from identification.fit.settings import IdentifySettings

__all__ = ["Prepared", "prepare", "Iteration", "Sweep", "evaluate", "evaluate_fused", "evaluate_shared", "iterate"]


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
