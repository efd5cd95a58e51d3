"""The full-space weighted least-squares estimator (paper eq. 3) and its covariance (eq. 7).

    min_{p, y_1..y_nq}  sum_k sum_j sum_i  (w_k / 2) ((z_ijk - h_k(y_j, p, q_j)) / sigma_k)^2
    s.t.                E(y_j, p, q_j) = 0,   j = 1..n_q,      lower <= p <= upper

States and parameters are optimisation variables; Ipopt (through CasADi) solves the
NLP with exact first and second derivatives.  Sums over series are folded into
per-(input, sensor) means, so the NLP size does not grow with n_M.  The result is
refined by at most a few exact reduced-space Newton steps (the same derivatives as
the covariance, accepted only if they decrease the objective) and the second-order
covariance

    C = H^{-1} J^T Omega^2 J H^{-T},    H = J^T Omega J + S(Omega)

is evaluated exactly by AD and the implicit function theorem.

For implicit models with many inputs Ipopt is started at the reduced-space optimum
(:mod:`identification.fit.implicit_start`) with its multipliers, so that it verifies that point
(at iteration 0, or after one step at round-off) instead of iterating on the n_q n_y states.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import time
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import scipy.sparse as sps
from scipy import special

from models.contract import Model
from identification.fit import dense
from identification.fit import unbounded
from identification.fit.factor import estimate_covariances
from identification.fit import secondorder
from identification.errors import DataError, IdentifiabilityError, IdentificationError, StateSolveError
from identification.fit.implicit_start import ImplicitObjective, nlp_multipliers, solve_states_from
from identification.fit.ipopt_solver import IpoptResult, IpoptSettings, NlpProblem, solve_nlp, warm_start
from identification.fit.measurements import Measurements
from identification.fit.explicit_kernel import ExplicitTerms, explicit_terms
from identification.fit.refinement import ReducedPoint, ReducedProblem, Refinement, refine
from identification.fit.record import FitRecord
from models.sensitivity import sensitivities
from models.state import BATCH_START_MIN, numerics, solve_states
from models.trajectory import trajectory_numerics

__all__ = ["identify", "IdentifySettings", "information_contributions", "check_identifiability",
           "covariance_from_terms", "param_scale", "as_start_vector"]


@dataclass(frozen=True)
class IdentifySettings:
    """Settings of :func:`identify` (defaults suit most problems).

    Attributes
    ----------
    ipopt : IpoptSettings
    refine_steps : int        maximum exact reduced Newton refinement steps after Ipopt
    rank_rtol : float         relative singular value of the column-normalised sqrt(Omega) J
                              below which the parameters count as not identifiable
    ill_conditioned : float   condition number of the normalised information that triggers a note
    s_ratio_note : float      ||S|| / ||J^T Omega J|| (normalised) that triggers a note
    decrement_tol : float     Newton decrement g^T H^-1 g (chi^2 units) accepted as optimal when
                              Ipopt stalls (1e-10: within 1e-5 standard errors of the optimum)
    predictor_step : float    largest relative parameter change of the linearised Gauss-Newton
                              predictor that sets Ipopt's start point (0 disables it)
    lazy_bounds : bool        first solve without the parameter bounds (at most LAZY_PASS_MAX_ITER
                              Ipopt iterations) and keep that solution
                              when it lies strictly inside them (else solve with the bounds)
    refine_decrement : float  no refinement step is taken once the Newton decrement g^T H^-1 g
                              (chi^2 units) is below this (1e-18: p within 1e-9 standard errors
                              of the optimum; Ipopt's solutions are typically at 1e-20)
    explicit_newton : bool    explicit models (no state) are first solved by exact reduced-space
                              Gauss-Newton/Newton steps (:func:`_solve_explicit_newton`); Ipopt is
                              the fallback and solves the problem when a bound is active
    reduced_start_inputs : int or None
                              implicit models with small (dense) states and at least this many
                              inputs start Ipopt at the reduced-space optimum with its
                              multipliers (:func:`_reduced_start`; Ipopt verifies it, usually at
                              iteration 0, instead of iterating on the n_q n_y states); None never
    """

    ipopt: IpoptSettings = field(default_factory=IpoptSettings)
    refine_steps: int = 5
    rank_rtol: float = 1e-9
    ill_conditioned: float = 1e8
    s_ratio_note: float = 0.1
    decrement_tol: float = 1e-10
    predictor_step: float = 0.25
    lazy_bounds: bool = True
    refine_decrement: float = 1e-18
    explicit_newton: bool = True
    reduced_start_inputs: int | None = 200

    def __post_init__(self):
        if not isinstance(self.ipopt, IpoptSettings):
            raise TypeError(f"ipopt: expected IpoptSettings, got {type(self.ipopt).__name__}")
        if not (isinstance(self.refine_steps, (int, np.integer)) and self.refine_steps >= 0):
            raise ValueError(f"refine_steps: expected an integer >= 0, got {self.refine_steps!r}")
        for name in ("rank_rtol", "decrement_tol", "refine_decrement", "s_ratio_note"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float, np.floating)) and np.isfinite(v) and v >= 0):
                raise ValueError(f"{name}: expected a finite number >= 0, got {v!r}")
        if not (isinstance(self.ill_conditioned, (int, float, np.floating)) and self.ill_conditioned > 1):
            raise ValueError(f"ill_conditioned: expected a condition number > 1, got {self.ill_conditioned!r}")
        if self.reduced_start_inputs is not None and not (
                isinstance(self.reduced_start_inputs, (int, np.integer)) and self.reduced_start_inputs >= 1):
            raise ValueError(f"reduced_start_inputs: expected None or an integer >= 1, "
                             f"got {self.reduced_start_inputs!r}")
        if not (isinstance(self.predictor_step, (int, float, np.floating)) and 0 <= self.predictor_step < np.inf):
            raise ValueError(f"predictor_step: expected a finite number >= 0 (0 disables the predictor), "
                             f"got {self.predictor_step!r}")


# ---------------------------------------------------------------------------- validation
def _validate(model, data, p0, weights):
    if not isinstance(model, Model):
        raise TypeError(f"model: expected a models.Model, got {type(model).__name__}")
    if not isinstance(data, Measurements):
        raise TypeError(f"data: expected an identification.Measurements, got {type(data).__name__}")
    if data.d_q != model.n_q_dim:
        raise DataError(f"data.inputs: has {data.d_q} columns but model {model.name!r} has inputs "
                        f"({', '.join(model.inputs)})")
    if data.n_S != model.n_S:
        raise DataError(f"data.z: has {data.n_S} sensors but model {model.name!r} has {model.n_S} "
                        f"({', '.join(model.sensors)}); use data.select([...]) to match")
    default_names = tuple(f"s{k + 1}" for k in range(data.n_S))
    if data.sensors != default_names and data.sensors != model.sensors:
        raise DataError(f"data.sensors {list(data.sensors)} do not match the model's sensors "
                        f"{list(model.sensors)}; use data.select(model.sensors)")
    p0 = as_start_vector(model, p0)
    for i, par in enumerate(model.params):
        if not math.isfinite(p0[i]):
            raise DataError(f"p0: start value of {par.name!r} is not finite ({p0[i]})")
        if p0[i] < par.lower or p0[i] > par.upper:
            raise DataError(f"p0: start value {p0[i]:g} of {par.name!r} lies outside its bounds "
                            f"[{par.lower:g}, {par.upper:g}]")
    w = data.sensor_weights(weights)
    if not np.any(w > 0):
        raise DataError("weights: no sensor is selected (all weights are zero)")
    n = data.n_data(w)
    if n < model.n_p:
        raise DataError(f"data: only {n} usable values in the selected sensors for {model.n_p} parameters; "
                        "need at least as many values as parameters")
    if data.sigma is None and n <= model.n_p:
        raise DataError(f"data: sigma is unknown and n = {n} values leave no degree of freedom to estimate it "
                        f"for {model.n_p} parameters; give sigma or more data")
    return p0, w, n


#: entries kept per model of each start-point cache in ``model.cache`` (repeated fits of new data)
_START_CACHE_SIZE = 32


def _initial_states(model, p0, inputs, Y0):
    """States at the start values (kept in ``model.cache`` per p0 and inputs: repeated fits of new data)."""
    if Y0 is not None:
        return solve_states(model, p0, inputs, Y0=Y0)
    key = (p0.tobytes(), inputs.tobytes())
    Y = model.cache.get("identify.initial_states", key)
    if Y is not None:
        return Y
    if numerics(model).dense and inputs.shape[0] >= BATCH_START_MIN:
        # all inputs at once from the model's guesses (faster than solve_states' batched start;
        # the same damped Newton); solve_states is the fallback
        guess = (np.array([model.y_guess(p0, q) for q in inputs]) if model.has_y_guess
                 else np.zeros((inputs.shape[0], model.n_y)))
        try:
            Y = solve_states_from(model, p0, inputs, guess)
        except StateSolveError:
            Y = None
    if Y is None:
        Y = solve_states(model, p0, inputs)
    Y.setflags(write=False)
    model.cache.put("identify.initial_states", key, Y, maxsize=_START_CACHE_SIZE)
    return Y


def _scalings(model, p0, inputs, Y_init, cacheable):
    """(s_y, e_scale) at the start; kept in ``model.cache`` per (p0, inputs) when Y_init is the
    cached state solve at p0 (repeated fits of new data, as in Monte Carlo studies and splits)."""
    key = (p0.tobytes(), inputs.tobytes()) if cacheable else None
    hit = model.cache.get("identify.scalings", key) if key is not None else None
    if hit is None:
        s_y = _state_scale(Y_init)
        hit = (s_y, _equation_scale(model, p0, inputs, Y_init, s_y))
        for a in hit:
            a.setflags(write=False)
        if key is not None:
            model.cache.put("identify.scalings", key, hit, maxsize=_START_CACHE_SIZE)
    return hit


def _predictor(model, p0, inputs, Y0, zbar, cw, sig, s_p, max_step):
    """Start point of Ipopt: one Gauss-Newton step from p0 on the model linearised at p0.

    p1 = p0 + (G^T W G)^{-1} G^T W (zbar - h(p0)) and y_j(p1) ~ y_j(p0) + y_j'(p0)(p1 - p0),
    with G, h, y' at p0 kept in ``model.cache`` per (p0, inputs) (they do not depend on the
    data, so repeated fits of new data pay one einsum).  The step is taken only when it moves
    every scaled parameter by at most ``max_step`` and stays inside the bounds; otherwise
    Ipopt starts at p0 as before.  It only changes where Ipopt starts, not the problem solved.
    """
    if max_step <= 0 or not model.n_y or not numerics(model).dense:
        return p0, Y0
    key = (p0.tobytes(), inputs.tobytes(), Y0.tobytes())
    hit = model.cache.get("identify.start_sensitivities", key)
    if hit is None:
        sens = sensitivities(model, p0, inputs, Y0)
        hit = (sens.h, sens.G, sens.state_derivatives)
        model.cache.put("identify.start_sensitivities", key, hit, maxsize=_START_CACHE_SIZE)
    h0, G, yp = hit
    wts = cw / sig[None, :] ** 2
    A = np.einsum("jk,jkp,jkr->pr", wts, G, G) * np.outer(s_p, s_p)
    b = np.einsum("jk,jk,jkp->p", wts, zbar - h0, G) * s_p
    try:
        L = np.linalg.cholesky(A)
    except np.linalg.LinAlgError:
        return p0, Y0
    d = np.linalg.solve(L.T, np.linalg.solve(L, b))
    if not np.all(np.isfinite(d)) or np.max(np.abs(d)) > max_step:
        return p0, Y0
    p1 = p0 + d * s_p
    if np.any(p1 <= model.lower) or np.any(p1 >= model.upper):
        return p0, Y0
    return p1, Y0 + np.einsum("jyp,p->jy", yp, p1 - p0)


def as_start_vector(model, p0) -> np.ndarray:
    """``p0`` as a float vector of the model's n_p start values; DataError naming ``p0`` otherwise."""
    try:
        p0 = np.asarray(p0, dtype=float).ravel()
    except (TypeError, ValueError):
        raise DataError(f"p0: not numeric: {p0!r}") from None
    if p0.shape != (model.n_p,):
        raise DataError(f"p0: expected {model.n_p} values ({', '.join(model.param_names)}), got {p0.size}")
    return p0


def param_scale(model, p0) -> np.ndarray:
    """Parameter scales s_p: the declared scale, else |p0|, else the bound range, else 1."""
    s = np.empty(model.n_p)
    for i, par in enumerate(model.params):
        if par.scale is not None:
            s[i] = par.scale
        elif p0[i] != 0:
            s[i] = abs(p0[i])
        elif math.isfinite(par.lower) and math.isfinite(par.upper) and par.upper > par.lower:
            s[i] = par.upper - par.lower
        else:
            s[i] = 1.0
    return s


def _state_scale(Y):
    if Y.size == 0:
        return np.ones(Y.shape[1])
    s = np.abs(Y).max(axis=0)
    top = s.max() if s.size else 0.0
    floor = top * 1e-6 if top > 0 else 1.0
    return np.where(s > floor, s, floor)


def _equation_scale(model, p0, inputs, Y, s_y):
    """1 / max_j max_i |dE_r/dy_i (y_j, p0, q_j)| s_y,i per equation r (1 where a row is zero)."""
    if not model.n_y:
        return np.ones(0)
    num = numerics(model)
    if num.dense:
        Ey = num.batched("E_y", inputs.shape[0])(Y, p0, inputs)[1]
        rowmax = np.abs(Ey * s_y[None, None, :]).max(axis=(0, 2))
    else:
        rowmax = np.zeros(model.n_y)
        for j in range(inputs.shape[0]):
            Ey = num.point("E_y")(Y[j], p0, inputs[j])[1]
            Ey = abs(sps.csr_matrix(Ey) @ sps.diags(s_y))
            rowmax = np.maximum(rowmax, Ey.max(axis=1).toarray().ravel())
    return np.where(rowmax > 0, 1.0 / np.where(rowmax > 0, rowmax, 1.0), 1.0)


# ---------------------------------------------------------------------------- the NLP
def _stage_hessian(model, y, p, q, zb, c, sf, lg, s_p, s_y, e_scale, stage_f=None, stage_E=None, terms=None):
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
    n_y, n_p, n_S = model.n_y, model.n_p, model.n_S
    S = ca.SX if model.symbolic == "SX" else ca.MX
    y, p, q = S.sym("y", n_y), S.sym("p", n_p), S.sym("q", model.n_q_dim)
    zb, c = S.sym("zbar", n_S), S.sym("c", n_S)
    sy, sp, e = S.sym("s_y", n_y), S.sym("s_p", n_p), S.sym("e", n_y)
    sf, lg = S.sym("sigma_f"), S.sym("lam_g", n_y)
    y_un, p_un = y * sy, p * sp
    base = [y, p, q, zb, c, sy, sp, e]
    if model.symbolic == "SX":
        h, Ey, Ep, hy, hp = num.sens(y_un, p_un, q)
        E = model.E_fun(y_un, p_un, q) * e
        f = 0.5 * ca.dot(c * (h - zb), h - zb)
        H = _stage_hessian(model, y, p, q, zb, c, sf, lg, sp, sy, e, terms=(h, hy, hp))
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


def _stage_gradient(model) -> ca.Function:
    """(ỹ, p̃, q, zbar, c, s_y, s_p, e) -> (f, df/dp̃, df/dỹ) of one stage (see
    :func:`_stage_functions`), by AD of the stage objective; built once per model and kept in
    ``model.cache`` (only large NLPs use it, so it is neither built nor compiled with the others)."""
    got = model.cache.get("identify.nlp_stage_grad", None)
    if got is not None:
        return got
    n_y, n_p, n_S = model.n_y, model.n_p, model.n_S
    S = ca.SX if model.symbolic == "SX" else ca.MX
    y, p, q = S.sym("y", n_y), S.sym("p", n_p), S.sym("q", model.n_q_dim)
    zb, c = S.sym("zbar", n_S), S.sym("c", n_S)
    sy, sp, e = S.sym("s_y", n_y), S.sym("s_p", n_p), S.sym("e", n_y)
    r = model.h_fun(y * sy, p * sp, q) - zb
    f = 0.5 * ca.dot(c * r, r)
    fn = ca.Function("nlp_stage_grad", [y, p, q, zb, c, sy, sp, e], [f, ca.gradient(f, p), ca.gradient(f, y)])
    return model.cache.put("identify.nlp_stage_grad", None, fn)


#: NLPs with more variables than this get the objective gradient assembled from a mapped stage
#: gradient (:func:`_stage_gradient`); smaller ones are expanded to SX and differentiated by nlpsol
_ASSEMBLED_GRADIENT_MIN = 1000


def _build_nlp(model, inputs, s_p, s_y, e_scale) -> NlpProblem:
    """The scaled full-space problem as CasADi expressions and derivative Functions.

    The data enter as NLP parameters (zbar, c / sigma^2 per input and sensor) so that one
    compiled solver serves many data sets with the same inputs and scaling.  Every term is a
    per-model stage Function mapped over the inputs (the inputs are the columns), with the sums
    over inputs done by the map's reduction, so building the NLP costs a few MX nodes whatever
    the number of inputs:

    * explicit models (no state): the NLP is over p only (:func:`_build_nlp_explicit`);
    * small (dense) states stated in SX or MX: :func:`_build_nlp_staged`;
    * large (sparse) states stated in SX: :func:`_build_nlp_glued`, from the model's own
      cached Functions.
    """
    if not model.n_y:
        return _build_nlp_explicit(model, inputs, s_p)
    if model.symbolic == "SX" and not numerics(model).dense:
        return _build_nlp_glued(model, inputs, s_p, s_y, e_scale)
    return _build_nlp_staged(model, inputs, s_p, s_y, e_scale)


#: explicit NLPs with at most this many inputs are expanded to SX by nlpsol (fast callbacks,
#: a set-up that grows with the inputs); larger ones keep the mapped MX graph (flat set-up)
_EXPAND_EXPLICIT_MAX = 2000
#: Ipopt iterations of identify's unbounded first pass (lazy_bounds); the press needs 3-4
LAZY_PASS_MAX_ITER = 100


def _symbols(model, n_q):
    """MX symbols of the NLP: scaled p̃ (n_p), scaled states ỹ (n_y, n_q), zbar and c (n_S, n_q),
    the multipliers lam_f and lam_g (n_y n_q)."""
    n_y, n_p, n_S = model.n_y, model.n_p, model.n_S
    return (ca.MX.sym("p_scaled", n_p), ca.MX.sym("y_scaled", n_y, n_q), ca.MX.sym("zbar", n_S, n_q),
            ca.MX.sym("c", n_S, n_q), ca.MX.sym("lam_f"), ca.MX.sym("lam_g", n_y * n_q))


def _build_nlp_explicit(model, inputs, s_p) -> NlpProblem:
    r""":func:`_build_nlp` for an explicit model: min over p̃ of
    f = sum_j 1/2 sum_k c_jk (h_k(s_p ⊙ p̃, q_j) - zbar_jk)^2, no constraints, no states.

    f and the Hessian lam_f sum_j ∇²f_j are one stage Function each, mapped over the inputs
    with the sum over j as the map's reduction.
    """
    fns = _stage_functions(model)
    n_q, n_p = inputs.shape[0], model.n_p
    pt, _, Zb, Cw, lam_f, lam_g = _symbols(model, n_q)
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


def _build_nlp_staged(model, inputs, s_p, s_y, e_scale):
    """:func:`_build_nlp` from the per-model stage functions (see :func:`_stage_functions`),
    mapped over the inputs; the Jacobian and Hessian blocks are assembled by :func:`_assemble_kkt`
    (for models stated in MX the constraint Jacobian is left to CasADi's AD)."""
    fns = _stage_functions(model)
    n_q, n_y, n_p = inputs.shape[0], model.n_y, model.n_p
    pt, yt, Zb, Cw, lam_f, lam_g = _symbols(model, n_q)
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
    r"""Per-model MX stage functions of :func:`_build_nlp_glued` (large sparse states), kept in
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


def _build_nlp_glued(model, inputs, s_p, s_y, e_scale):
    r""":func:`_build_nlp` for large (sparse) states: the stage functions of
    :func:`_glued_stage_functions` mapped over the inputs and assembled by :func:`_assemble_kkt`.

    No new SX graph of the model is formed, so the set-up costs a few MX nodes instead of
    inlining the model's Hessian (spring chain with d_y = 3000, n_q = 5: build 0.05 s instead
    of 0.20 s).  For small (dense) models the per-model SX stage functions
    (:func:`_build_nlp_staged`) are faster and are used instead.
    """
    fns = _glued_stage_functions(model)
    n_q, n_y, n_p = inputs.shape[0], model.n_y, model.n_p
    pt, yt, Zb, Cw, lam_f, lam_g = _symbols(model, n_q)
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


def check_identifiability(model, G, cw, sig, s_p, rtol, selected, sv=None):
    """Assumption 3: rank(sqrt(Omega) J) = n_p, checked on the column-normalised matrix.

    ``sv``: its singular values when the caller has them (the QR factor of
    :mod:`identification.fit.factor`); a full rank is then confirmed without another pass over the data.
    Returns the condition number of the normalised matrix; raises IdentifiabilityError.
    """
    if sv is not None and sv.size == model.n_p and sv[-1] > 0 and sv[-1] >= rtol * sv[0]:
        return float(sv[0] / sv[-1])
    rows = (np.sqrt(cw) / sig)[:, :, None] * G * s_p[None, None, :]
    J = rows.reshape(-1, model.n_p)
    norms = np.linalg.norm(J, axis=0)
    sens_names = tuple(model.sensors[k] for k in selected)
    dead = [model.param_names[i] for i in range(model.n_p) if not norms[i] > 0]
    if dead:
        raise IdentifiabilityError(
            f"not identifiable: parameter(s) {', '.join(dead)} do not influence the selected sensors "
            f"({', '.join(sens_names)}) at any input (Assumption 3, rank(Omega J) = n_p, fails)",
            params=dead, sensors=sens_names)
    Jn = J / norms
    sv = dense.singular_values(Jn)
    ratio = sv[-1] / sv[0] if sv[0] > 0 else 0.0
    if J.shape[0] < model.n_p or ratio < rtol:
        v = np.linalg.svd(Jn, full_matrices=False)[2][-1] if J.shape[0] >= model.n_p else np.ones(model.n_p)
        involved = [model.param_names[i] for i in np.flatnonzero(np.abs(v) >= 0.1 * np.abs(v).max())]
        raise IdentifiabilityError(
            f"not identifiable: parameters {', '.join(involved)} cannot be told apart with sensors "
            f"({', '.join(sens_names)}): rank(Omega J) < n_p = {model.n_p} (smallest relative singular value "
            f"{ratio:.2e}); add a sensor or input that separates them, or fix one of them",
            params=involved, sensors=sens_names)
    return 1.0 / ratio


def covariance_from_terms(F, F2, S):
    """C = H^{-1} F2 H^{-T} with H = F + S (second order) and (F^{-1} F2 F^{-1}) (Gauss-Newton).

    F = J^T Omega J, F2 = J^T Omega^2 J.  Returns (cov, cov_gn, H, H_ok) where H_ok is False when
    H is singular (condition number of the normalised D H D above 1e15, D = diag(F)^-1/2; cov
    is then NaN).
    """
    H = F + S
    n = F.shape[0]
    Finv_F2 = dense.solve(F, F2)
    cov_gn = dense.solve(F, Finv_F2.T).T
    try:
        # singular means singular after normalising the parameters (D H D with D = diag(F)^-1/2):
        # the condition number of H itself also measures the parameters' units (NIST Hahn1: 1e17)
        d = 1.0 / np.sqrt(np.diag(F))
        sv = dense.singular_values(H * np.outer(d, d))
        with np.errstate(divide="ignore"):
            cond = sv[0] / sv[-1]
        if not np.isfinite(cond) or cond > 1e15:
            raise np.linalg.LinAlgError
        A = dense.solve(H, F2)
        cov = dense.solve(H, A.T).T
        ok = True
    except np.linalg.LinAlgError:
        cov, ok = np.full((n, n), np.nan), False
    return 0.5 * (cov + cov.T), 0.5 * (cov_gn + cov_gn.T), H, ok


class _PhaseClock:
    """Wall and CPU seconds (``time.perf_counter``, ``time.process_time``) of the phases of one
    :func:`identify`, recorded in ``Estimate.extra["timing"]`` as {phase: (wall s, CPU s)}."""

    def __init__(self):
        self._wall, self._cpu = time.perf_counter(), time.process_time()
        self.phases: dict = {}

    def lap(self, name: str) -> None:
        """Charge the time since the previous lap (or the start) to phase ``name``."""
        w, c = time.perf_counter(), time.process_time()
        old = self.phases.get(name, (0.0, 0.0))
        self.phases[name] = (old[0] + w - self._wall, old[1] + c - self._cpu)
        self._wall, self._cpu = w, c


# ---------------------------------------------------------------------------- the pipeline of identify
@dataclass(frozen=True)
class _Start:
    """The validated problem of one identification and its start point.

    ``w`` sensor weights, ``n`` usable values, ``selected`` sensors with w > 0, ``sig`` the
    sigmas used in the objective (a common spread when sigma is unknown), ``Y_init`` the
    states at p0, ``s_p``/``s_y``/``e_scale`` the scalings of parameters, states and
    equations, ``problem`` the reduced-space problem (data terms) shared by all steps.
    """

    model: Model
    data: Measurements
    p0: np.ndarray
    w: np.ndarray
    n: int
    selected: np.ndarray
    sig: np.ndarray
    Y_init: np.ndarray
    s_p: np.ndarray
    s_y: np.ndarray
    e_scale: np.ndarray
    problem: ReducedProblem


def _start(model, data, p0, weights, Y0) -> _Start:
    """Step 1 of :func:`identify`: validate, choose the sigmas, solve the start states, scale."""
    p0, w, n = _validate(model, data, p0, weights)
    selected = np.flatnonzero(w > 0)
    if data.sigma is None:
        zs = data.z[:, :, selected]
        if math.isfinite(zs.sum()):         # no missing value: np.std is nanstd's number, 10x faster
            spread = float(np.std(zs)) or float(np.mean(np.abs(zs))) or 1.0
        else:
            spread = float(np.nanstd(zs)) or float(np.nanmean(np.abs(zs))) or 1.0
        sig = np.full(model.n_S, spread)
    else:
        sig = np.asarray(data.sigma, float)
    s_p = param_scale(model, p0)
    if not model.n_y:                       # explicit: no states to solve or scale
        Y_init, s_y, e_scale = np.zeros((data.n_q, 0)), np.ones(0), np.ones(0)
    else:
        try:
            Y_init = _initial_states(model, p0, data.inputs, Y0)
        except StateSolveError as exc:
            raise IdentificationError(f"p0: the state equation cannot be solved at the start values: {exc}",
                                      status="state solve failed") from None
        # a collocated ODE is solved in the reduced space (no NLP): its scalings are made when Ipopt needs them
        s_y, e_scale = ((None, None) if trajectory_numerics(model) is not None
                        else _scalings(model, p0, data.inputs, Y_init, Y0 is None))
    return _Start(model, data, p0, w, n, selected, sig, Y_init, s_p, s_y, e_scale,
                  ReducedProblem.of(model, data, w, sig, s_p))


@dataclass(frozen=True)
class _FullSpaceSolution:
    """Ipopt's solution of the full-space NLP: its result, the number of passes (1: the
    unbounded pass was kept, 2: the bounded problem was solved), p clipped to the bounds, the
    states, the parameters found at a bound and, when the reduced-space Newton solved it, its
    reduced point at p and the second-order term S there (None when not evaluated)."""

    result: IpoptResult
    passes: int
    p: np.ndarray
    states: np.ndarray | None
    at_bound: np.ndarray
    point: ReducedPoint | None = None
    S: np.ndarray | None = None


#: at most this many Gauss-Newton/Newton iterations and objective evaluations of
#: :func:`_solve_explicit_newton` (then Ipopt takes over: a far start should not cost twice)
_NEWTON_MAX_ITER = 60
_NEWTON_MAX_EVALS = 50
#: a Gauss-Newton step halved more often than this ends the line-searched iteration (the
#: Gauss-Newton model is poor there: :func:`_levenberg_marquardt` takes over)
_GN_MAX_HALVINGS = 5


class _ExplicitObjective:
    """Phi(s_p ⊙ x) of an explicit model with the sums of its derivatives w.r.t. the scaled
    parameters x (an :class:`identification.fit.explicit_kernel.ExplicitTerms` with Phi_0 included
    in ``f``): one evaluation of the least-squares kernel for models stated in SX, else the
    reduced point of :class:`ReducedProblem` and NumPy sums (models stated in MX)."""

    def __init__(self, st: _Start):
        problem = st.problem
        self._problem, self._sp = problem, st.s_p
        self._outer = np.outer(st.s_p, st.s_p)
        self._kernel = explicit_terms(st.model, st.data.inputs, problem.zbar, problem.cw / st.sig[None, :] ** 2,
                                      st.s_p)

    def point(self, x: np.ndarray) -> ReducedPoint:
        """The reduced point at p = s_p ⊙ x."""
        return self._problem.evaluate(x * self._sp)

    def __call__(self, x: np.ndarray, second_order: bool) -> ExplicitTerms:
        """The terms at p = s_p ⊙ x (``S`` when ``second_order``); raises StateSolveError when
        the evaluation fails."""
        problem = self._problem
        if self._kernel is not None:
            t = self._kernel(x, second_order)
            return t._replace(f=t.f + problem.const)
        sp = self._sp
        point = problem.evaluate(x * sp)
        G = point.sens.G.reshape(-1, sp.size)
        S = point.sens.hessians(point.lam[None])[0] * self._outer if second_order else None
        return ExplicitTerms(point.objective, point.gradient * sp, problem.information(point) * self._outer,
                             (np.abs(point.lam).reshape(-1) @ np.abs(G)) * sp, S)


#: at most this many evaluations of :func:`_levenberg_marquardt`
_LM_MAX_EVALS = 200


def _levenberg_marquardt(st: _Start, objective: "_ExplicitObjective"):
    r"""Levenberg-Marquardt iterations on the exact Gauss-Newton model, for starts where the
    line-searched Gauss-Newton/Newton iteration of :func:`_solve_explicit_newton` fails.

    In the scaled parameters x: d = -(F + mu diag(F))^{-1} g (F = J^T Omega J, g the gradient,
    both exact by AD), accepted when the objective decreases by at least 1e-4 of the decrease
    the Gauss-Newton model predicts; mu is updated by Nielsen's rule (mu <- mu max(1/3,
    1 - (2 rho - 1)^3) on success, mu <- nu mu and nu <- 2 nu on failure; start mu = 1e-3
    max diag F).  Stops once an undamped-size step (mu < 1e-6) is accepted with the Gauss-Newton
    decrement g^T F^{-1} g below 1e-2 of the objective, or when the objective stalls (relative
    decrease below 1e-10); at most :data:`_LM_MAX_EVALS` evaluations.  Returns the point reached
    (the Newton iteration then finishes from it), or None.
    """
    x = st.p0 / st.s_p
    try:
        cur = objective(x, False)
    except StateSolveError:
        return None
    if not math.isfinite(cur.f):
        return None
    D = np.diag(cur.F).copy()
    mu, nu = 1e-3 * float(D.max()), 2.0
    if not (math.isfinite(mu) and mu > 0):
        return None
    for _ in range(_LM_MAX_EVALS):
        D = np.maximum(D, np.diag(cur.F))               # Marquardt's scaling, never shrinking
        L = dense.cholesky_lower(cur.F + mu * np.diag(D))
        if L is None:
            mu, nu = mu * nu, 2 * nu
            if not math.isfinite(mu):
                return None
            continue
        d = -dense.tri_solve(L, dense.tri_solve(L, cur.g), trans=1)
        pred = -(cur.g @ d + 0.5 * d @ (cur.F @ d))     # decrease predicted by the Gauss-Newton model
        try:
            new = objective(x + d, False)
        except StateSolveError:
            new = None
        rho = (cur.f - new.f) / pred if new is not None and math.isfinite(new.f) and pred > 0 else -1.0
        if rho > 1e-4:
            stalled = cur.f - new.f <= 1e-10 * abs(cur.f)
            x, cur = x + d, new
            mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
            if stalled:
                return x
            if mu < 1e-6 * float(D.max()):
                Lf = dense.cholesky_lower(cur.F)
                if Lf is not None:
                    v = dense.tri_solve(Lf, cur.g)
                    if float(v @ v) < 1e-2 * max(cur.f, 1e-300):
                        return x
        else:
            mu, nu = mu * nu, 2 * nu
            if not math.isfinite(mu):
                return None
    return None


def _solve_explicit_newton(st: _Start, settings: IdentifySettings):
    r"""Minimise the reduced objective Phi(p) of an explicit model by exact Newton steps.

    In the scaled parameters x = p / s_p: far from the optimum Gauss-Newton steps d = -F^{-1} g
    (F = J^T Omega J); once a step changes Phi by less than 10 % of the Gauss-Newton
    decrement's prediction, or that decrement is below 1e-4 (chi^2 units), exact Newton steps
    d = -(F + S)^{-1} g with the second-order term S by AD (Gauss-Newton again where F + S is
    not positive definite).  Backtracking (Armijo, halving) on Phi.  Converged when the
    decrement g^T M^{-1} g of the matrix used is below ``settings.refine_decrement`` after a
    Newton step, or a step below 1e-13 parameter scales.  At most 60 iterations and 50
    evaluations.  From a far start (a Gauss-Newton step halved more than
    :data:`_GN_MAX_HALVINGS` times, or no convergence) Levenberg-Marquardt steps on the same
    exact Gauss-Newton model (:func:`_levenberg_marquardt`) bring p closer and the iteration
    restarts from there; when that fails too, the iteration runs once more from p0 with the full
    line search (40 halvings).  Every evaluation is one call of the least-squares kernel over the data
    (:mod:`identification.fit.explicit_kernel`: Phi, g, F and, in the Newton phase, S together), so
    an iteration costs O(n) with a small constant and no NLP is built.

    Returns (result, point, S): the solution as an :class:`IpoptResult` (status
    ``Solve_Succeeded``, the same acceptance as Ipopt's: a stationary point at the tolerance),
    its reduced point and the second-order term S there (unscaled; None when not evaluated), or
    None when the iteration fails (singular F, failed line search, no convergence): the caller
    then solves with Ipopt.  The result may lie outside the parameter bounds (the caller checks).
    """
    t0 = time.perf_counter()
    objective = _ExplicitObjective(st)
    x0 = st.p0 / st.s_p
    got = _newton_from(st, settings, objective, x0, t0, _GN_MAX_HALVINGS)
    if got is None:
        x = _levenberg_marquardt(st, objective)
        if x is not None:
            got = _newton_from(st, settings, objective, x, t0)
    if got is None:                                # e.g. BoxBOD start1: LM stalls on a plateau
        got = _newton_from(st, settings, objective, x0, t0)
    return got


def _newton_from(st: _Start, settings: IdentifySettings, objective: "_ExplicitObjective", x: np.ndarray,
                 t0: float, max_halvings: int = 40):
    """The iteration of :func:`_solve_explicit_newton` from the scaled start x (same returns);
    it gives up when a Gauss-Newton step needs more than ``max_halvings`` halvings."""
    s_p = st.s_p
    dof = st.n - st.model.n_p
    known = st.data.sigma is not None
    refine_dec, dec_tol = settings.refine_decrement, settings.decrement_tol
    try:
        cur = objective(x, False)
    except StateSolveError:
        return None
    newton = False
    prev_dec = None
    evals = 1
    round_off = 16 * np.finfo(float).eps
    for it in range(1, _NEWTON_MAX_ITER + 1):
        if not math.isfinite(cur.f):
            return None
        if newton and cur.S is None:
            cur = objective(x, True)
        L = dense.cholesky_lower(cur.F + cur.S if newton else cur.F)
        if L is None:
            if not newton:
                return None
            L = dense.cholesky_lower(cur.F)
            if L is None:
                return None
        v = dense.tri_solve(L, cur.g)
        dec = float(v @ v)
        # the decrement in units of the standard errors: with sigma unknown the objective's sigma is
        # a common spread and s^2 = RSS / (n - n_p) is what the standard errors use
        unit = 1.0 if known else 2 * cur.f / dof
        if newton:
            # the decrement that round-off in the gradient's sum over the data alone produces
            u = dense.tri_solve(L, round_off * cur.g_abs)
            if dec <= max(refine_dec * unit, float(u @ u)):
                break
            if dec <= dec_tol * unit and prev_dec is not None and dec > 0.1 * prev_dec:
                break                              # no more progress at round-off, within 1e-5 std errors
        prev_dec = dec if newton else None
        d = dense.tri_solve(L, v, trans=1)
        d *= -1.0
        if abs(d).max() < 1e-13:
            break
        step, new = 1.0, None
        if newton and dec <= dec_tol * unit:
            x_new = x + d
            try:                                   # quadratic region: the objective cannot resolve
                new = objective(x_new, True)       # the decrease any more; take the full step
            except StateSolveError:
                new = None
            if new is not None and not math.isfinite(new.f):
                new = None
        for k in range(40 if new is None else 0):
            evals += 1
            if evals > _NEWTON_MAX_EVALS or (not newton and k > max_halvings):
                return None                        # far from the optimum: Levenberg-Marquardt's turn
            x_new = x + step * d
            try:
                trial = objective(x_new, newton)
            except StateSolveError:
                trial = None
            if trial is not None and trial.f <= cur.f - 1e-4 * step * dec:
                new = trial
                break
            step *= 0.5
        if new is None:
            if newton and dec <= dec_tol * unit:
                break                              # at round-off: the decrement certifies the optimum
            if not newton:
                newton = True                      # Gauss-Newton cannot descend further: try Newton
                continue
            return None
        gain = cur.f - new.f
        if not newton and (dec < 1e-4 * unit or gain < 0.05 * dec):
            newton = True
        x, cur = x_new, new
    else:
        return None
    try:
        point = objective.point(x)
    except StateSolveError:
        return None
    res = IpoptResult(x=x, f=point.objective, status="Solve_Succeeded",
                      message=f"exact reduced-space Newton converged in {it} iterations (Newton decrement "
                              f"{dec:.1e}); Ipopt was not needed", accepted=True, iterations=it,
                      wall_time=time.perf_counter() - t0, stats={"solver": "reduced Newton"})
    return res, point, None if cur.S is None else cur.S / np.outer(s_p, s_p)


def _reduced_start(st: _Start, settings: IdentifySettings):
    r"""The reduced-space optimum of an implicit model with small (dense) states, as Ipopt's start.

    The Gauss-Newton/Newton iteration of explicit models (:func:`_newton_from`, the same line
    search and convergence test) on the reduced objective Phi(p) with the states eliminated
    (:class:`identification.fit.implicit_start.ImplicitObjective`: states by batched damped Newton
    from the nearest point evaluated, sensitivities by the implicit function theorem, S by
    adjoints, all inputs at once).  Used for models with at least
    ``settings.reduced_start_inputs`` inputs.  Returns (result, point, S) as
    :func:`_solve_explicit_newton`, or None (not used, or the iteration failed: Ipopt then
    starts from the predictor as before).
    """
    model = st.model
    min_inputs = settings.reduced_start_inputs
    trajectory = trajectory_numerics(model) is not None     # a collocated ODE: any number of inputs
    if (not model.n_y or min_inputs is None or
            not (trajectory or (st.data.n_q >= min_inputs and numerics(model).dense))):
        return None
    x0 = st.p0 / st.s_p
    objective = ImplicitObjective(st.problem, x0, st.Y_init)
    # to round-off (no decrement threshold): Ipopt's test is on the gradient, which a decrement of
    # 1e-24 can leave at 1e-8 when the information is large (many inputs)
    return _newton_from(st, dataclasses.replace(settings, refine_decrement=0.0), objective, x0,
                        time.perf_counter(), _GN_MAX_HALVINGS)


def _solve_full_space(st: _Start, settings: IdentifySettings, clock: _PhaseClock | None = None) -> _FullSpaceSolution:
    """Step 2 of :func:`identify`: build (or reuse) the scaled NLP and solve it with Ipopt.

    An explicit model is first solved by exact reduced-space Newton steps
    (:func:`_solve_explicit_newton`, with ``explicit_newton``); that solution is kept when it lies
    strictly inside the bounds (no NLP is built), else the bounded problem is solved by Ipopt
    (pass 2), and Ipopt solves it as below when the Newton iteration fails.
    With ``lazy_bounds``, pass 1 solves without the parameter bounds: a pure equality-
    constrained problem, which Ipopt solves by Newton steps without a barrier (3-4 instead of
    6-8 iterations for the press).  Its solution is kept only when it lies strictly inside the
    bounds: it is then a KKT point of the bounded problem too (zero bound multipliers).
    Otherwise, and on any failure, pass 2 solves the bounded problem from the same start.

    An implicit model with small (dense) states and at least ``reduced_start_inputs`` inputs
    starts Ipopt at the reduced-space optimum (:func:`_reduced_start`) with the multipliers that
    make it a primal-dual solution (warm start, no barrier: pass 1 without bounds), so Ipopt
    verifies it at iteration 0 or after one step at round-off; the estimate is then that point
    (and its S), else Ipopt's solution as usual.  When the reduced iteration fails, Ipopt starts
    from the predictor as before.
    """
    model, data, s_p, s_y = st.model, st.data, st.s_p, st.s_y
    newton_passes = None
    if not model.n_y and settings.explicit_newton:
        got = _solve_explicit_newton(st, settings)
        if got is not None:
            r0, point, S = got
            margin = 1e-6 * s_p
            lo, up = model.lower, model.upper
            if np.all(point.p > lo + margin) and np.all(point.p < up - margin):
                if clock is not None:
                    clock.lap("reduced-space Newton (explicit model)")
                return _FullSpaceSolution(r0, 1, point.p, None, np.zeros(model.n_p, bool), point, S)
            newton_passes = 2                   # outside the bounds: solve the bounded problem
    zbar, cw = st.problem.zbar, st.problem.cw
    par_value = np.concatenate([zbar.ravel(), (cw / st.sig[None, :] ** 2).ravel()])  # column-major of (n_S, n_q)
    bounded = np.any(np.isfinite(model.lower)) or np.any(np.isfinite(model.upper))
    warm = None                                 # (reduced point, S) of the reduced-space optimum
    if newton_passes is None and (settings.lazy_bounds or not bounded):
        got = _reduced_start(st, settings)
        if got is not None and np.all(got[1].p > model.lower + 1e-6 * s_p) and \
                np.all(got[1].p < model.upper - 1e-6 * s_p):
            warm = got[1], got[2]
            if trajectory_numerics(model) is not None:
                # a collocated ODE: the reduced optimum (states solved to round-off element by element,
                # decrement at round-off) is the estimate, as for explicit models; no NLP is built
                if clock is not None:
                    clock.lap("reduced-space Newton (collocated trajectories)")
                return _FullSpaceSolution(got[0], 1, got[1].p, got[1].states, np.zeros(model.n_p, bool), got[1],
                                          got[2])
    if s_y is None:                             # scalings left for the NLP (see _start)
        s_y, e_scale = _scalings(model, st.p0, data.inputs, st.Y_init, False)
        st = dataclasses.replace(st, s_y=s_y, e_scale=e_scale)
    key = (data.inputs.tobytes(), s_p.tobytes(), s_y.tobytes(), st.e_scale.tobytes())
    if warm is not None:
        p_start, Y_start = warm[0].p, warm[0].states
    else:
        p_start, Y_start = _predictor(model, st.p0, data.inputs, st.Y_init, zbar, cw, st.sig, s_p,
                                      settings.predictor_step)
    if clock is not None:
        clock.lap("start point of Ipopt")
    x0 = np.concatenate([p_start / s_p, (Y_start / s_y[None, :]).ravel()])   # vec(yt) is column-major: y_j stacked
    free_y = np.full(data.n_q * model.n_y, np.inf)

    def solve(x_start, lbx, ubx, lam_g0=None, ipopt=settings.ipopt):
        return solve_nlp(functools.partial(_build_nlp, model, data.inputs, s_p, s_y, st.e_scale), x_start, lbx, ubx,
                         0.0, 0.0, par_value, ipopt if lam_g0 is None else warm_start(ipopt),
                         what=f"identification of {model.name}", key=key, cache=model.cache, lam_g0=lam_g0)

    res = None
    passes = 1 if newton_passes is None else newton_passes
    if passes == 1 and ((settings.lazy_bounds and bounded) or warm is not None):
        free_p = np.full(model.n_p, np.inf)
        try:
            # a capped pass: when the unbounded optimum lies at infinity Ipopt would otherwise
            # run to max_iter (seconds) before pass 2 solves the bounded problem
            r1 = solve(x0, np.concatenate([-free_p, -free_y]), np.concatenate([free_p, free_y]),
                       None if warm is None else nlp_multipliers(warm[0], st.e_scale),
                       dataclasses.replace(settings.ipopt, max_iter=min(settings.ipopt.max_iter, LAZY_PASS_MAX_ITER)))
        except IdentificationError:
            r1 = None
        if r1 is not None and r1.accepted:
            p1 = r1.x[:model.n_p] * s_p
            margin = 1e-6 * s_p
            if np.all(p1 > model.lower + margin) and np.all(p1 < model.upper - margin):
                res = r1
        passes = 1 if res is not None else 2
    if res is None:
        res = solve(x0 if passes == 1 else np.concatenate([st.p0 / s_p, (st.Y_init / s_y[None, :]).ravel()]),
                    np.concatenate([model.lower / s_p, -free_y]), np.concatenate([model.upper / s_p, free_y]))
    if clock is not None:
        clock.lap("NLP build, Ipopt set-up and solve")
    p = np.clip(res.x[:model.n_p] * s_p, model.lower, model.upper)  # Ipopt relaxes bounds by ~1e-8
    Y = res.x[model.n_p:].reshape(data.n_q, model.n_y) * s_y[None, :] if model.n_y else None
    at_bound = (np.abs(p - model.lower) <= 1e-7 * s_p) | (np.abs(p - model.upper) <= 1e-7 * s_p)
    if warm is not None and passes == 1 and np.max(np.abs(res.x[:model.n_p] - x0[:model.n_p])) <= 1e-12:
        # Ipopt verified the reduced-space optimum without a step or with a step at round-off (the
        # gradient of a fit to many inputs stays above Ipopt's tolerance at one ulp of p): its point
        # and S are the estimate's
        return _FullSpaceSolution(res, passes, warm[0].p, warm[0].states, at_bound, warm[0], warm[1])
    return _FullSpaceSolution(res, passes, p, Y, at_bound)


def _decrement_unit(st: _Start, objective: float) -> float:
    """Objective units per chi^2 unit of the decrement: 1 with sigma known, else 2 Phi / (n - n_p)
    (the objective's sigma is a common spread; the standard errors use s^2 = RSS / (n - n_p))."""
    return 1.0 if st.data.sigma is not None else 2.0 * objective / max(st.n - st.model.n_p, 1)


def _refine_solution(st: _Start, sol: _FullSpaceSolution, settings: IdentifySettings) -> Refinement:
    """Step 3 of :func:`identify`: states consistent with Ipopt's p, then at most
    ``refine_steps`` exact reduced Newton steps (none when a parameter is at a bound), and
    the Newton decrement g^T H^-1 g, the squared distance to the optimum in standard errors.

    Raises IdentificationError when the states cannot be solved at p, or when Ipopt stalled
    and the refinement did not reach the optimum (decrement above ``decrement_tol``).
    """
    res = sol.result
    try:
        point = sol.point if sol.point is not None else st.problem.evaluate(sol.p, sol.states)
    except StateSolveError as exc:
        raise IdentificationError(f"the state equation cannot be solved at the estimate: {exc}",
                                  status=res.status) from None
    ref = refine(st.problem, point, settings.refine_steps if not np.any(sol.at_bound) else 0,
                 stop_decrement=settings.refine_decrement, start_S=sol.S,
                 dof=st.n - st.model.n_p if st.data.sigma is None else None,
                 quadratic_decrement=settings.decrement_tol)
    unit = _decrement_unit(st, ref.point.objective)
    if res.accepted is None and not (ref.decrement <= settings.decrement_tol * unit):
        raise IdentificationError(
            f"Ipopt stalled on the identification of {st.model.name} ({res.status}) and the exact Newton "
            f"refinement did not reach the optimum (Newton decrement {ref.decrement / unit:.2e} > "
            f"{settings.decrement_tol:.0e}; refinement stopped: {ref.stop_reason}); try other start values",
            status=res.status)
    return ref


def _second_order(st: _Start, sol: _FullSpaceSolution, ref: Refinement, settings: IdentifySettings,
                  clock: _PhaseClock | None = None) -> tuple:
    """Second-order optimality before success (:func:`identification.fit.secondorder.ensure_minimum`):
    from a point found below a saddle along its negative curvature the problem is solved again
    (:func:`_solve_full_space`, :func:`_refine_solution`).  Returns (st, sol, ref, escaped);
    raises ConvergenceError when no descent is found."""
    state = {"st": st, "sol": sol}

    def resolve(new):
        s = dataclasses.replace(state["st"], p0=new.p, Y_init=new.states if st.model.n_y else st.Y_init)
        state["st"], state["sol"] = s, _solve_full_space(s, settings, clock)
        return ~state["sol"].at_bound, _refine_solution(s, state["sol"], settings)

    ref, escaped = secondorder.ensure_minimum(st.problem, ref, ~sol.at_bound, resolve, st.selected,
                                             settings.rank_rtol)
    return state["st"], state["sol"], ref, escaped


def _estimate(st: _Start, sol: _FullSpaceSolution, ref: Refinement, settings: IdentifySettings,
              t_start: float, clock: _PhaseClock | None = None, escaped: tuple = ()) -> FitRecord:
    """Step 4 of :func:`identify`: identifiability, covariance (eq. 7) and the result.

    With sigma unknown the covariance, information and objective are rescaled by
    s^2 / sigma_0^2 with s^2 = RSS / (n - n_p).
    """
    model, data, point = st.model, st.data, ref.point
    sens = point.sens
    cond = check_identifiability(model, sens.G, st.problem.cw, st.sig, st.s_p, settings.rank_rtol, st.selected,
                                 None if ref.factor is None else ref.factor.sv[0])
    F = ref.information
    resid = data.z - sens.h[None]
    rss = float(np.nansum(resid[:, :, st.selected] ** 2))
    dof = st.n - model.n_p
    if data.sigma is None:
        s2 = rss / dof
        factor = s2 / st.sig[0] ** 2
        sig_used = np.full(model.n_S, math.sqrt(s2))
    else:
        factor = 1.0
        sig_used = st.sig
    # from the QR factor of sqrt(Omega) J (not the normal equations): issue 20
    cov, cov_gn, H_ok, sv, K_eig = estimate_covariances(sens.G, st.problem.cw, st.w, st.sig, ref.S, ref.factor)
    H = F + ref.S
    cov, cov_gn = cov * factor, cov_gn * factor
    _check_plausible(st, point.p, cov, cov_gn, sol.result.status)
    objective = point.objective / factor if data.sigma is None else point.objective
    notes = _notes(st, sol, ref, settings, cond, H, H_ok, objective, rss, dof)
    for e in escaped:
        notes += (f"the solver first stopped at a saddle point (RSS {e['rss']:.6g}, Hessian "
                  f"eigenvalue {e['eigenvalue']:.3g} in Gauss-Newton units); restarted from a lower point along "
                  "its direction of negative curvature",)
    res = sol.result
    extra = {"newton_decrement": ref.decrement / factor, "solver": res.stats.get("solver", "ipopt"),
             "ipopt_iterations": 0 if "solver" in res.stats else res.iterations, "ipopt_passes": sol.passes,
             "singular_values": sv, "hessian_eigenvalues": K_eig, "refinement_stop": ref.stop_reason,
             "saddle_escapes": escaped}
    if "t_wall_callbacks" in res.stats:
        extra["ipopt_timing"] = {"build": res.stats["t_build"], "nlpsol": res.stats["t_nlpsol"],
                                 "solve": res.wall_time, "callbacks": dict(res.stats["t_wall_callbacks"])}
    if clock is not None:
        clock.lap("identifiability, covariance, notes")
        extra["timing"] = dict(clock.phases)
    return FitRecord(
        p=point.p, param_names=model.param_names, param_units=tuple(par.unit for par in model.params),
        sensors=model.sensors, states=point.states, fitted=sens.h, residuals=resid, weights=st.w, sigma=sig_used,
        sigma_estimated=data.sigma is None, n_data=st.n, dof=dof, rss=rss, objective=objective,
        information=F / factor, S=ref.S / factor, H=H / factor, cov=cov, cov_gn=cov_gn, G=sens.G,
        status=res.status, message=res.message, iterations=res.iterations,
        solve_time=time.perf_counter() - t_start, refinement_steps=ref.steps,
        grad_norm=float(np.linalg.norm(point.gradient * st.s_p)), notes=notes, model_name=model.name,
        extra=extra, model=model, data=data)


#: an estimate farther than this many parameter scales from zero is a failed fit
ABSURD_SCALES = 1e6


def _check_plausible(st: _Start, p: np.ndarray, cov: np.ndarray, cov_gn: np.ndarray, status: str) -> None:
    """Reject an estimate at absurd values: |p_i| > :data:`ABSURD_SCALES` max(s_p,i, 1) (s_p the
    parameter's declared scale, else |p0_i|), a non-finite p, or non-finite standard errors
    (second-order or Gauss-Newton).  Such a point is where the solver stopped while the
    parameters ran off (the data do not bound them), not an estimate.

    Raises
    ------
    IdentificationError
        Naming the parameters and what to do.
    """
    names = st.model.param_names
    ref = np.maximum(st.s_p, 1.0)      # a start value near 0 (e.g. 1e-16) must not make every value absurd
    far = [i for i in range(p.size) if not (np.isfinite(p[i]) and abs(p[i]) <= ABSURD_SCALES * ref[i])]
    if far:
        what = ", ".join(f"{names[i]} = {p[i]:.3g} (scale {ref[i]:.3g})" for i in far)
        raise IdentificationError(
            f"the fit failed: the estimate ran off to absurd values ({what}: more than {ABSURD_SCALES:.0e} "
            "times the parameter's scale); the data do not bound these parameters from p0. Try other start "
            "values, bounds on the parameters, or a reparametrisation", status=f"absurd estimate ({status})")
    bad = [names[i] for i in range(p.size)
           if not (np.isfinite(cov[i, i]) and cov[i, i] >= 0 and np.isfinite(cov_gn[i, i]) and cov_gn[i, i] >= 0)]
    if bad:
        raise IdentificationError(
            f"the fit failed: the standard errors of {', '.join(bad)} are not finite at p = {np.array2string(p)} "
            "(the Hessian J^T Omega J + S is singular there); the point is not a strict minimum. Try other "
            "start values or bounds on the parameters", status=f"non-finite standard errors ({status})")


def _notes(st, sol, ref, settings, cond, H, H_ok, objective, rss, dof) -> tuple:
    """The diagnostic notes of an estimate: solver status, unknown sigma, bounds, conditioning,
    size of the second-order term, definiteness of H and the chi^2 test of the residuals."""
    model, data, res = st.model, st.data, sol.result
    notes = []
    if res.accepted is None:
        dec = ref.decrement / _decrement_unit(st, ref.point.objective)
        notes.append(f"Ipopt stalled ({res.status}); the exact Newton refinement verified the optimum "
                     f"(Newton decrement {dec:.1e}, i.e. within {math.sqrt(max(dec, 0)):.1e} "
                     "standard errors)")
    elif res.status != "Solve_Succeeded":
        notes.append(f"not converged to full tolerance: Ipopt status {res.status} ({res.message})")
    if data.sigma is None:
        s2 = rss / dof
        notes.append(f"sigma unknown: estimated s = {math.sqrt(s2):.4g} from RSS / (n - n_p) with {dof} dof; "
                     "intervals use Student t, the ellipsoid n_p F(n_p, dof) quantiles")
    for i in np.flatnonzero(sol.at_bound):
        notes.append(f"parameter {model.param_names[i]} is at a bound ({ref.point.p[i]:g}): the covariance assumes "
                     "an interior optimum and is not valid for it")
    F, S = ref.information, ref.S
    Dn = 1.0 / np.sqrt(np.diag(F))
    Fn = F * np.outer(Dn, Dn)
    Sn = S * np.outer(Dn, Dn)
    if cond ** 2 > settings.ill_conditioned:
        notes.append(f"ill-conditioned: the normalised information J^T Omega J has condition number "
                     f"{cond ** 2:.2e}; parameters are strongly correlated and their errors large")
    s_ratio = dense.singular_values(Sn)[0] / dense.singular_values(Fn)[0]     # ||Sn||_2 / ||Fn||_2
    if s_ratio > settings.s_ratio_note:
        notes.append(f"second-order term large: ||S|| is {100 * s_ratio:.3g} % of ||J^T Omega J|| (normalised); "
                     "the model fits poorly or is strongly nonlinear, so cov and cov_gn differ")
    if H_ok and dense.sym_eigenvalues(H * np.outer(Dn, Dn))[0] <= 0:
        notes.append("H = J^T Omega J + S is not positive definite: the estimate is not a strict local "
                     "minimum in the reduced space; treat cov with caution")
    if data.sigma is not None and dof > 0:
        chi2 = 2.0 * objective
        pval = float(special.chdtrc(dof, chi2))           # = stats.chi2.sf(chi2, dof), without its overhead
        if pval < 1e-3:
            notes.append(f"residuals exceed the sensor sigmas: reduced chi2 = {chi2 / dof:.3g} "
                         f"(chi2 test p = {pval:.2g}); the model or the sigmas are inadequate and cov "
                         "understates the uncertainty")
    return tuple(notes)


def fit_static(model: Model, data: Measurements, p0, weights=None,
               settings: IdentifySettings | None = None, Y0=None) -> FitRecord:
    """Weighted nonlinear least squares in full space (paper eq. 3), with covariance (eq. 7).

    The pipeline: validate and start (:func:`_start`), solve the scaled full-space NLP with
    Ipopt (:func:`_solve_full_space`), refine by exact reduced Newton steps
    (:func:`identification.fit.refinement.refine`), then identifiability, covariance and the
    result (:func:`_estimate`).

    Parameters
    ----------
    model : models.Model
        A static model; a dynamic one (:meth:`models.Model.ode`) goes through
        :func:`identification.fit.entry.fit_model` (collocation with error control).
    data : Measurements
        z (n_M, n_q, n_S); sigma per sensor, or None for a common unknown sigma.
    p0 : array_like (n_p,)
        Start values (inside the bounds).  States start from the solution of E(y, p0, q_j) = 0.
    weights : array_like (n_S,), optional
        Sensor weights omega (0/1 selects sensors; default all ones).
    settings : IdentifySettings, optional
    Y0 : array (n_q, n_y), optional
        Initial guess of the states (else solved from the model's own guess).

    Returns
    -------
    FitRecord
        The plain record; :func:`identification.identify` returns it as an :class:`identification.Estimate`
        (intervals, regions, summary).

    Raises
    ------
    DataError, TypeError
        Bad input (the message names the argument).
    IdentificationError
        Ipopt failed (carries Ipopt's status), or the state equation could not be solved.
    IdentifiabilityError
        rank(Omega J) < n_p at a finite estimate (structural; names the parameters and sensors).
        When the data do not bound the parameters (the best fit runs off to infinity along a
        direction, :mod:`identification.fit.unbounded`) the result is returned instead, with
        ``Estimate.bounded`` False and the direction in ``Estimate.unbounded``.
    ConvergenceError
        The solver stopped at a stationary point that is not a minimum (the reduced Hessian
        J^T Omega J + S is not positive definite) and no lower point was found along its negative
        curvature (names the point and the eigenvalue); from such a point with descent the problem
        is solved again (:mod:`identification.fit.secondorder`; ``extra["saddle_escapes"]`` and a note).
    """
    settings = settings or IdentifySettings()
    t_start = time.perf_counter()
    clock = _PhaseClock()
    st = _start(model, data, p0, weights, Y0)
    clock.lap("validation, data, states at p0")
    sol = ref = None
    try:
        sol = _solve_full_space(st, settings, clock)
        ref = _refine_solution(st, sol, settings)
        st, sol, ref, escaped = _second_order(st, sol, ref, settings, clock)
        clock.lap("refinement (states, sensitivities, S at the estimate)")
        est = _estimate(st, sol, ref, settings, t_start, clock, escaped)
    except (IdentificationError, np.linalg.LinAlgError) as exc:
        # did the fit run off to infinity (the data do not bound p: a result) or is the rank
        # deficiency structural (a finite point: the error, saying so)?  identification.fit.unbounded
        # follows the valley from where the fit stopped (from p0 when the solver failed on its way)
        if ref is not None:
            p_stop, y_stop = ref.point.p, ref.point.states
        elif sol is not None:
            p_stop, y_stop = sol.p, sol.states
        else:
            p_stop, y_stop = st.p0, (st.Y_init if model.n_y else None)
        diag = unbounded.diagnose(st.problem, p_stop, y_stop)
        if diag.kind == "unbounded":
            return unbounded.estimate_not_bounded(st, diag, f"{type(exc).__name__}: {exc}", t_start)
        if isinstance(exc, IdentifiabilityError):
            raise unbounded.identifiability_error(exc, diag, p_stop, model.param_names) from None
        raise
    sloppy = est.sloppy_direction
    if sloppy is not None and not np.any(sol.at_bound) and sloppy.ratio ** 2 > settings.ill_conditioned:
        # an ill-conditioned "optimum" may be a point far out on a run-off where the steps became too small
        diag = unbounded.diagnose(st.problem, est.p, est.states)
        if diag.kind == "unbounded":
            return unbounded.estimate_not_bounded(
                st, diag, f"{est.status} at {', '.join(f'{n} = {v:.4g}' for n, v in zip(est.param_names, est.p))} "
                "(ill-conditioned; the objective still decreased beyond it)", t_start)
    return est


def static_information(model: Model, data: Measurements | None, p, states=None, *, inputs=None,
                       sigma=None, n_series=1):
    """Per-sensor Gauss-Newton information and second-order terms at p.

    F_k = sum_j c_jk G_jk^T G_jk / sigma_k^2,
    S_k = sum_j d^2/dp^2 [ -c_jk (zbar_jk - h_k(y_j(p), p, q_j)) / sigma_k^2 ]

    so that for sensor weights w:  J^T Omega J = sum_k w_k F_k,  S(Omega) = sum_k w_k S_k and
    J^T Omega^2 J = sum_k w_k^2 F_k.

    Without data (``data=None``; ``inputs``, ``sigma`` and ``n_series`` given) the design is
    planned before measuring: c_jk = n_series and the expected residual zbar - h is 0 at the
    nominal p, so S_k = 0 and the second-order covariance equals the Gauss-Newton one.

    A dynamic model goes through :func:`identification.fit.entry.information_contributions`.

    Returns
    -------
    F, S : ndarray (n_S, n_p, n_p)
    """
    p = np.asarray(p, float).ravel()
    if p.shape != (model.n_p,):
        raise DataError(f"p: expected {model.n_p} values, got {p.size}")
    if data is None:
        return _planned_information(model, p, inputs, sigma, n_series, states)
    if inputs is not None or sigma is not None:
        raise DataError("inputs/sigma: give them only when data is None (the data carry their own)")
    if data.sigma is None:
        raise DataError("data.sigma: information contributions need known sensor sigmas")
    sig = np.asarray(data.sigma, float)
    w = np.ones(model.n_S)
    Y = solve_states(model, p, data.inputs, Y0=states)
    sens = sensitivities(model, p, data.inputs, Y)
    terms = ReducedProblem.of(model, data, w, sig, np.ones(model.n_p))
    zbar, cw = terms.zbar, terms.cw
    F = np.einsum("jk,jkp,jkr->kpr", cw / sig ** 2, sens.G, sens.G)
    lam = -cw * (zbar - sens.h) / sig ** 2
    lam_k = np.zeros((model.n_S, data.n_q, model.n_S))
    for k in range(model.n_S):
        lam_k[k, :, k] = lam[:, k]
    S = sens.hessians(lam_k)
    return F, S


def _planned_information(model: Model, p, inputs, sigma, n_series, states):
    """F_k = n_series sum_j G_jk^T G_jk / sigma_k^2 and S_k = 0 (no data: expected residual 0)."""
    if inputs is None or sigma is None:
        raise DataError("data: None needs inputs= (candidate input rows) and sigma= (one per sensor)")
    q = np.asarray(inputs, float)
    q = q[:, None] if q.ndim == 1 else q
    if q.ndim != 2 or q.shape[0] == 0 or not np.all(np.isfinite(q)):
        raise DataError(f"inputs: expected a finite array (n_q, d_q) with n_q >= 1, got shape {q.shape}")
    sig = np.broadcast_to(np.asarray(sigma, float), (model.n_S,))
    if not np.all(np.isfinite(sig) & (sig > 0)):
        raise DataError(f"sigma: expected {model.n_S} positive finite values, got {np.asarray(sigma)!r}")
    if isinstance(n_series, bool) or not isinstance(n_series, (int, np.integer)) or n_series < 1:
        raise DataError(f"n_series: expected an integer >= 1, got {n_series!r}")
    Y = solve_states(model, p, q, Y0=states)
    G = sensitivities(model, p, q, Y).G
    F = float(n_series) * np.einsum("k,jkp,jkr->kpr", 1.0 / sig ** 2, G, G)
    return F, np.zeros_like(F)
