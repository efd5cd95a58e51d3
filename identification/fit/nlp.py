"""The scaled full-space NLP of the estimator (paper eq. 3) as CasADi expressions and Functions.

    min_{p~, y~_1..y~_nq}  sum_j 1/2 sum_k c_jk (h_k(s_y y~_j, s_p p~, q_j) - zbar_jk)^2
    s.t.                  e * E(s_y y~_j, s_p p~, q_j) = 0

with the data (zbar, c / sigma^2) as NLP parameters, so that one compiled solver serves many
data sets with the same inputs and scaling (:func:`build_nlp`).
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from models.state import numerics
from identification.fit.ipopt_solver import NlpProblem

__all__ = ["build_nlp", "build_nlp_explicit", "build_nlp_staged", "build_nlp_glued", "stage_hessian"]


def stage_hessian(model, y, p, q, zb, c, sf, lg, s_p, s_y, e_scale, stage_f=None, stage_E=None, terms=None):
    r"""Hessian of  sf f_j + lg^T E_j  w.r.t. the scaled (p, y) of one stage (symbolic SX).

    With D = diag(s_p, s_y), J = [dh/dp, dh/dy], r = c ⊙ (h - zbar) and
    f = 1/2 sum_k c_k (h_k - zbar_k)^2:

    .. math::  \tilde H = D\,[\,s_f J^T \mathrm{diag}(c) J
               + \nabla^2_{(p,y)} (\lambda^T h + \mu^T E)\,]\,D,\quad
               \lambda = s_f\, r,\ \mu = e \odot l_g,

    where the second term is the model's cached ``lag_hess`` (built once per model for the
    sensitivities), so no second symbolic Hessian is formed (0.3 s for the spring chain with
    d_y = 3000).  The scalings may be numbers or SX symbols.  ``terms`` = (h, dh/dy, dh/dp) at the
    unscaled point when the caller has them already (saves inlining ``sens`` a second time).
    Models stated in MX fall back to ``casadi.hessian`` of the stage Lagrangian (``stage_f``,
    ``stage_E``).
    """
    n_y, n_p = model.n_y, model.n_p
    if model.symbolic != "SX":
        L_stage = sf * stage_f + (ca.dot(lg, stage_E) if n_y else 0)
        return ca.hessian(L_stage, ca.vertcat(p, y))[0]
    sp, sy, e = (v if isinstance(v, ca.SX) else ca.DM(np.asarray(v, float).reshape(-1, 1))
                 for v in (s_p, s_y, e_scale))
    num = numerics(model)
    y_un, p_un = y * sy, p * sp
    if terms is None:
        h, _, _, hy, hp = num.sens(y_un, p_un, q)
    else:
        h, hy, hp = terms
    Hl = num.lag_hess(y_un, p_un, q, sf * c * (h - zb), e * lg if n_y else ca.SX(0, 1))   # order (y, p)
    perm = list(range(n_y, n_y + n_p)) + list(range(n_y))
    J = ca.horzcat(hp, hy)
    H = sf * ca.mtimes(J.T, c * J) + Hl[perm, perm]                                       # order (p, y)
    d = ca.vertcat(sp, sy)
    return _scale_nz(H, d, d)


def _scale_nz(M, r, c):
    """diag(r) M diag(c) for a sparse SX matrix M, computed on its nonzeros (same sparsity)."""
    sp = M.sparsity()
    # vec(): indexing a 1-element r or c by a list gives a row, not a column (models with one state)
    return ca.SX(sp, ca.vec(M.nz[:]) * ca.vec(r[sp.row()]) * ca.vec(c[sp.get_col()]))


def _stage_functions(model):
    r"""Per-model CasADi functions of one stage (load case) of the scaled NLP, built once.

    Inputs (ỹ, p̃, q, zbar, c, s_y, s_p, e[, s_f, l_g]) with the scalings as arguments, so the
    same functions (JIT-compiled when :func:`models.state.set_jit` is on) serve every
    data set, input set and scaling of the model:

    * ``stage``: (e ⊙ E(s_y ⊙ ỹ, s_p ⊙ p̃, q),  f = 1/2 sum_k c_k (h_k - zbar_k)^2)
    * ``jac``:   ((diag(e) E_p diag(s_p))^T, diag(e) E_y diag(s_y))
    * ``hess``:  the blocks (H_pp, H_py, H_yy) of
      D [s_f J^T diag(c) J + lag_hess(s_f r, e ⊙ l_g)] D in the order (p, y)

    for models stated in SX from the model's cached ``sens`` and ``lag_hess`` (no further
    symbolic derivatives); for models stated in MX the stage Hessian is ``casadi.hessian`` of
    the stage Lagrangian.  Explicit models (no state) get ``stage`` and ``hess`` with empty
    state arguments and no ``jac``.  Returns a dict of Functions, kept in ``model.cache``.
    """
    num = numerics(model)
    compiled = num.jit_active()
    got = model.cache.get("identify.nlp_stage", compiled)
    if got is not None:
        return got
    n_y, n_p = model.n_y, model.n_p
    S, (y, p, q, zb, c, sy, sp, e) = _stage_symbols(model)
    sf, lg = S.sym("sigma_f"), S.sym("lam_g", n_y)
    y_un, p_un = y * sy, p * sp
    base = [y, p, q, zb, c, sy, sp, e]
    if model.symbolic == "SX":
        h, Ey, Ep, hy, hp = num.sens(y_un, p_un, q)
        E = model.E_fun(y_un, p_un, q) * e
        f = 0.5 * ca.dot(c * (h - zb), h - zb)
        H = stage_hessian(model, y, p, q, zb, c, sf, lg, sp, sy, e, terms=(h, hy, hp))
        Jp, Jy = _scale_nz(ca.SX(Ep), e, sp), _scale_nz(ca.SX(Ey), e, sy)
    else:
        h = model.h_fun(y_un, p_un, q)
        E = model.E_fun(y_un, p_un, q) * e
        f = 0.5 * ca.sum1(c * (h - zb) ** 2)
        H = ca.hessian(sf * f + (ca.dot(lg, E) if n_y else 0), ca.vertcat(p, y))[0]
        Jp, Jy = ca.jacobian(E, p), ca.jacobian(E, y)
    fns = {"stage": ca.Function("nlp_stage", base, [E, f]),
           "hess": ca.Function("nlp_stage_hess", base + [sf, lg], [H[:n_p, :n_p], H[:n_p, n_p:], H[n_p:, n_p:]])}
    if n_y:
        fns["jac"] = ca.Function("nlp_stage_jac", [y, p, q, sy, sp, e], [Jp.T, Jy])
    fns = {k: num.compiled(f"nlp_stage_{k}", fn) for k, fn in fns.items()}
    return model.cache.put("identify.nlp_stage", compiled, fns)


def _stage_symbols(model) -> tuple:
    """(S, (ỹ, p̃, q, zbar, c, s_y, s_p, e)): the symbol class of the model (SX or MX) and the arguments of
    one stage's functions (scaled states and parameters, inputs, mean readings, counts, scales)."""
    n_y, n_p, n_S = model.n_y, model.n_p, model.n_S
    S = ca.SX if model.symbolic == "SX" else ca.MX
    y, p, q = S.sym("y", n_y), S.sym("p", n_p), S.sym("q", model.n_q_dim)
    zb, c = S.sym("zbar", n_S), S.sym("c", n_S)
    sy, sp, e = S.sym("s_y", n_y), S.sym("s_p", n_p), S.sym("e", n_y)
    return S, (y, p, q, zb, c, sy, sp, e)


def _stage_gradient(model) -> ca.Function:
    """(ỹ, p̃, q, zbar, c, s_y, s_p, e) -> (f, df/dp̃, df/dỹ) of one stage (see
    :func:`_stage_functions`), by AD of the stage objective; built once per model and kept in
    ``model.cache`` (only large NLPs use it, so it is neither built nor compiled with the others)."""
    got = model.cache.get("identify.nlp_stage_grad", None)
    if got is not None:
        return got
    _, (y, p, q, zb, c, sy, sp, e) = _stage_symbols(model)
    r = model.h_fun(y * sy, p * sp, q) - zb
    f = 0.5 * ca.dot(c * r, r)
    fn = ca.Function("nlp_stage_grad", [y, p, q, zb, c, sy, sp, e], [f, ca.gradient(f, p), ca.gradient(f, y)])
    return model.cache.put("identify.nlp_stage_grad", None, fn)


#: NLPs with more variables than this get the objective gradient assembled from a mapped stage
#: gradient (:func:`_stage_gradient`); smaller ones are expanded to SX and differentiated by nlpsol
_ASSEMBLED_GRADIENT_MIN = 1000


def build_nlp(model, inputs, s_p, s_y, e_scale) -> NlpProblem:
    """The scaled full-space problem as CasADi expressions and derivative Functions.

    The data enter as NLP parameters (zbar, c / sigma^2 per input and sensor) so that one
    compiled solver serves many data sets with the same inputs and scaling.  Every term is a
    per-model stage Function mapped over the inputs (the inputs are the columns), with the sums
    over inputs done by the map's reduction, so building the NLP costs a few MX nodes whatever
    the number of inputs:

    * explicit models (no state): the NLP is over p only (:func:`build_nlp_explicit`);
    * small (dense) states stated in SX or MX: :func:`build_nlp_staged`;
    * large (sparse) states stated in SX: :func:`build_nlp_glued`, from the model's own
      cached Functions.
    """
    if not model.n_y:
        return build_nlp_explicit(model, inputs, s_p)
    if model.symbolic == "SX" and not numerics(model).dense:
        return build_nlp_glued(model, inputs, s_p, s_y, e_scale)
    return build_nlp_staged(model, inputs, s_p, s_y, e_scale)


#: explicit NLPs with at most this many inputs are expanded to SX by nlpsol (fast callbacks,
#: a set-up that grows with the inputs); larger ones keep the mapped MX graph (flat set-up)
_EXPAND_EXPLICIT_MAX = 2000


@dataclass(frozen=True)
class _Symbols:
    """MX symbols of the NLP: scaled p̃ (n_p), scaled states ỹ (n_y, n_q), zbar and c (n_S, n_q),
    the multipliers lam_f and lam_g (n_y n_q)."""

    p: ca.MX
    y: ca.MX
    zbar: ca.MX
    c: ca.MX
    lam_f: ca.MX
    lam_g: ca.MX


def _symbols(model, n_q) -> _Symbols:
    """The :class:`_Symbols` of a model's NLP over n_q inputs."""
    n_y, n_p, n_S = model.n_y, model.n_p, model.n_S
    return _Symbols(p=ca.MX.sym("p_scaled", n_p), y=ca.MX.sym("y_scaled", n_y, n_q),
                    zbar=ca.MX.sym("zbar", n_S, n_q), c=ca.MX.sym("c", n_S, n_q), lam_f=ca.MX.sym("lam_f"),
                    lam_g=ca.MX.sym("lam_g", n_y * n_q))


def build_nlp_explicit(model, inputs, s_p) -> NlpProblem:
    r""":func:`build_nlp` for an explicit model: min over p̃ of
    f = sum_j 1/2 sum_k c_jk (h_k(s_p ⊙ p̃, q_j) - zbar_jk)^2, no constraints, no states.

    f and the Hessian lam_f sum_j ∇²f_j are one stage Function each, mapped over the inputs
    with the sum over j as the map's reduction.
    """
    fns = _stage_functions(model)
    n_q = inputs.shape[0]
    sym = _symbols(model, n_q)
    pt, Zb, Cw, lam_f, lam_g = sym.p, sym.zbar, sym.c, sym.lam_f, sym.lam_g
    Q = ca.DM(inputs.T)
    e0 = ca.MX(0, 1)
    scal = (e0, ca.DM(s_p), e0)
    par = ca.vertcat(ca.vec(Zb), ca.vec(Cw))
    _, f = fns["stage"].map("nlp_stage_sum", "serial", n_q, [0, 1, 5, 6, 7], [1])(
        e0, pt, Q, Zb, Cw, *scal)
    H_pp = fns["hess"].map("nlp_hess_sum", "serial", n_q, [0, 1, 5, 6, 7, 8, 9], [0, 1, 2])(
        e0, pt, Q, Zb, Cw, *scal, lam_f, e0)[0]
    hess_lag = ca.Function("nlp_hess_l", [pt, par, lam_f, lam_g], [ca.triu(H_pp)],
                           ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
    return NlpProblem(pt, f, ca.MX(0, 1), par, hess_lag=hess_lag, compiled=numerics(model).jit_active(),
                      expand=n_q <= _EXPAND_EXPLICIT_MAX and not numerics(model).jit_active())


def _blockdiag(blocks_h, n_q, block_sparsity):
    """blockdiag(B_1, .., B_nq) from horzcat(B_1, .., B_nq) when all blocks share one sparsity.

    Column-major, column j n + c of both matrices holds the nonzeros of column c of B_j in
    the same order, so the block diagonal is the same nonzero vector with another sparsity
    (one ``sparsity_cast``, no per-block slicing).
    """
    return ca.sparsity_cast(blocks_h, ca.kron(ca.Sparsity.diag(n_q), block_sparsity))


def _assemble_kkt(x, par, g, Jp_t, Jy_h, H_pp, H_py, H_yy_h, lam_f, lam_g, n_p, n_y, n_q, jac_sp, hyy_sp):
    r"""Constraint Jacobian and upper-triangular Lagrangian Hessian Functions of the full-space NLP
    from the mapped per-input blocks (the inputs couple only through p).

    With x = (p̃, ỹ_1, .., ỹ_nq), ``Jp_t`` = [J_p^1{}^T .. J_p^{n_q}{}^T] (n_p, n_q n_y) or None (no
    Jacobian Function is built), ``Jy_h`` = [J_y^1 .. J_y^{n_q}], ``H_pp`` = sum_j H_pp^j,
    ``H_py`` = [H_py^1 .. H_py^{n_q}], ``H_yy_h`` = [H_yy^1 .. H_yy^{n_q}] and ``jac_sp``, ``hyy_sp``
    the sparsities of one block J_y^j and H_yy^j:

    .. math::  J = \begin{bmatrix} J_p^1 & J_y^1 & & \\ \vdots & & \ddots & \\ J_p^{n_q} & & & J_y^{n_q}
               \end{bmatrix},\qquad
               \mathrm{triu}\,H = \begin{bmatrix} \sum_j H_{pp}^j & H_{py}^1 & \cdots & H_{py}^{n_q} \\
               & H_{yy}^1 & & \\ & & \ddots & \\ & & & H_{yy}^{n_q} \end{bmatrix}.
    """
    jac_g = None
    if Jp_t is not None:
        J = ca.horzcat(Jp_t.T, _blockdiag(Jy_h, n_q, jac_sp))
        jac_g = ca.Function("nlp_jac_g", [x, par], [g, J], ["x", "p"], ["g", "jac_g_x"])
    H = ca.vertcat(ca.horzcat(ca.triu(H_pp), H_py),
                   ca.horzcat(ca.MX(n_y * n_q, n_p), ca.triu(_blockdiag(H_yy_h, n_q, hyy_sp))))
    hess_lag = ca.Function("nlp_hess_l", [x, par, lam_f, lam_g], [H],
                           ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])
    return jac_g, hess_lag


def build_nlp_staged(model, inputs, s_p, s_y, e_scale):
    """:func:`build_nlp` from the per-model stage functions (see :func:`_stage_functions`),
    mapped over the inputs; the Jacobian and Hessian blocks are assembled by :func:`_assemble_kkt`
    (for models stated in MX the constraint Jacobian is left to CasADi's AD)."""
    fns = _stage_functions(model)
    n_q, n_y, n_p = inputs.shape[0], model.n_y, model.n_p
    sym = _symbols(model, n_q)
    pt, yt, Zb, Cw, lam_f, lam_g = sym.p, sym.y, sym.zbar, sym.c, sym.lam_f, sym.lam_g
    Q = ca.DM(inputs.T)
    scal = (ca.DM(s_y), ca.DM(s_p), ca.DM(e_scale))
    x = ca.vertcat(pt, ca.vec(yt))
    par = ca.vertcat(ca.vec(Zb), ca.vec(Cw))
    # plain maps (the shared arguments broadcast, the sums over inputs by repsum): building a map
    # with reduced arguments and outputs costs 0.1-0.2 s per map at 1e5 inputs, a plain one ~0
    E_all, f_j = fns["stage"].map(n_q, "serial")(yt, pt, Q, Zb, Cw, *scal)
    f = ca.sum2(f_j)
    g = ca.vec(E_all)
    grad_f = None
    if n_p + n_q * n_y > _ASSEMBLED_GRADIENT_MIN:
        # reverse mode through the mapped graph costs 2-4x the mapped stage gradient (1e5 inputs);
        # the assembled gradient must be dense: with a sparse output Ipopt received misplaced entries
        f_g, gp_j, gy = _stage_gradient(model).map(n_q, "serial")(yt, pt, Q, Zb, Cw, *scal)
        grad_f = ca.Function("nlp_grad_f", [x, par], [ca.sum2(f_g), ca.densify(ca.vertcat(ca.sum2(gp_j), ca.vec(gy)))],
                             ["x", "p"], ["f", "grad_f_x"])
    H_pp, H_py, H_yy = fns["hess"].map(n_q, "serial")(yt, pt, Q, Zb, Cw, *scal, lam_f, ca.reshape(lam_g, n_y, n_q))
    H_pp = ca.repsum(H_pp, 1, n_q)
    hyy_sp = fns["hess"].sparsity_out(2)
    if "jac" in fns and model.symbolic == "SX":
        Jp_t, Jy_h = fns["jac"].map(n_q, "serial")(yt, pt, Q, *scal)
        jac_sp = fns["jac"].sparsity_out(1)
    else:
        Jp_t = Jy_h = jac_sp = None
    jac_g, hess_lag = _assemble_kkt(x, par, g, Jp_t, Jy_h, H_pp, H_py, H_yy, lam_f, lam_g, n_p, n_y, n_q,
                                    jac_sp, hyy_sp)
    return NlpProblem(x, f, g, par, hess_lag=hess_lag, jac_g=jac_g, grad_f=grad_f,
                      compiled=numerics(model).jit_active())


def _glued_stage_functions(model):
    r"""Per-model MX stage functions of :func:`build_nlp_glued` (large sparse states), kept in
    ``model.cache``.  With D_y = diag(s_y), D_p = diag(s_p), e the equation scale,
    y = D_y ỹ and p = D_p p̃:

    .. math::  g_j = e \odot E(y_j, p, q_j),\qquad
               \partial g_j / \partial(\tilde p, \tilde y_j)
                 = \mathrm{diag}(e)\,[E_p D_p,\ E_y D_y],

    .. math::  \nabla^2 L_j = D\,[\,\mathrm{lag\_hess}(\sigma_f c \odot r_j,\ e \odot \lambda_j)
               + \sigma_f J_j^T \mathrm{diag}(c_j) J_j\,]\,D,\qquad J_j = [h_y, h_p],

    by calling the model's ``E``, ``h``, ``sens`` and ``lag_hess`` (built once per model for the
    state solves and sensitivities), with the scalings as constant-sparsity products.
    """
    got = model.cache.get("identify.nlp_glued", None)
    if got is not None:
        return got
    num = numerics(model)
    n_y, n_p, n_S = model.n_y, model.n_p, model.n_S
    y, p, q = ca.MX.sym("y", n_y), ca.MX.sym("p", n_p), ca.MX.sym("q", model.n_q_dim)
    zb, c = ca.MX.sym("zbar", n_S), ca.MX.sym("c", n_S)
    sy, sp, e = ca.MX.sym("s_y", n_y), ca.MX.sym("s_p", n_p), ca.MX.sym("e", n_y)
    sf, lg = ca.MX.sym("sigma_f"), ca.MX.sym("lam_g", n_y)
    yu, pu = y * sy, p * sp
    r = model.h_fun(yu, pu, q) - zb
    base = [y, p, q, zb, c, sy, sp, e]
    stage = ca.Function("nlp_glued_stage", base, [model.E_fun(yu, pu, q) * e, 0.5 * ca.sum1(c * r * r)])
    _, Ey, Ep, hy, hp = num.sens(yu, pu, q)
    De, Dy, Dp = ca.diag(e), ca.diag(sy), ca.diag(sp)
    jac = ca.Function("nlp_glued_jac", [y, p, q, sy, sp, e],
                      [ca.mtimes(De, ca.mtimes(Ep, Dp)).T, ca.mtimes(De, ca.mtimes(Ey, Dy))])
    Hl = num.lag_hess(yu, pu, q, sf * c * r, lg * e)                       # order (y, p), unscaled
    J = ca.horzcat(hy, hp)
    Hj = Hl + sf * ca.mtimes(J.T, ca.mtimes(ca.diag(c), J))
    D = ca.diag(ca.vertcat(sy, sp))
    b = ca.mtimes(D, ca.mtimes(Hj, D))
    hess = ca.Function("nlp_glued_hess", base + [sf, lg], [b[n_y:, n_y:], b[n_y:, :n_y], b[:n_y, :n_y]])
    return model.cache.put("identify.nlp_glued", None, {"stage": stage, "jac": jac, "hess": hess})


def build_nlp_glued(model, inputs, s_p, s_y, e_scale):
    r""":func:`build_nlp` for large (sparse) states: the stage functions of
    :func:`_glued_stage_functions` mapped over the inputs and assembled by :func:`_assemble_kkt`.

    No new SX graph of the model is formed, so the set-up costs a few MX nodes instead of
    inlining the model's Hessian (spring chain with d_y = 3000, n_q = 5: build 0.05 s instead
    of 0.20 s).  For small (dense) models the per-model SX stage functions
    (:func:`build_nlp_staged`) are faster and are used instead.
    """
    fns = _glued_stage_functions(model)
    n_q, n_y, n_p = inputs.shape[0], model.n_y, model.n_p
    sym = _symbols(model, n_q)
    pt, yt, Zb, Cw, lam_f, lam_g = sym.p, sym.y, sym.zbar, sym.c, sym.lam_f, sym.lam_g
    Q = ca.DM(inputs.T)
    scal = (ca.DM(s_y), ca.DM(s_p), ca.DM(e_scale))
    x = ca.vertcat(pt, ca.vec(yt))
    par = ca.vertcat(ca.vec(Zb), ca.vec(Cw))
    E_all, f = fns["stage"].map("nlp_glued_stage_map", "serial", n_q, [1, 5, 6, 7], [1])(yt, pt, Q, Zb, Cw, *scal)
    Jp_t, Jy_h = fns["jac"].map("nlp_glued_jac_map", "serial", n_q, [1, 3, 4, 5], [])(yt, pt, Q, *scal)
    H_pp, H_py, H_yy = fns["hess"].map("nlp_glued_hess_map", "serial", n_q, [1, 5, 6, 7, 8], [0])(
        yt, pt, Q, Zb, Cw, *scal, lam_f, ca.reshape(lam_g, n_y, n_q))
    jac_g, hess_lag = _assemble_kkt(x, par, ca.vec(E_all), Jp_t, Jy_h, H_pp, H_py, H_yy, lam_f, lam_g,
                                    n_p, n_y, n_q, fns["jac"].sparsity_out(1), fns["hess"].sparsity_out(2))
    return NlpProblem(x, f, ca.vec(E_all), par, hess_lag=hess_lag, jac_g=jac_g)
