r"""Trajectories of a collocated index-1 DAE for all experiments at once, element by element, and their exact
sensitivities (the element marcher of :mod:`models.trajectory` extended to algebraic states).

A DAE dx/dt = f(x, z, p, u), 0 = g(x, z, p, u) is collocated by :mod:`models.collocation` into the state
y = (w_00, V_0, ..., V_{N-1}) of one experiment, w_00 = (x(0), z(0)) and V_k = (x_k1, z_k1, ..., x_kd, z_kd)
the differential and algebraic states at element k's Radau points, solving

.. math::

    x_{00} - x_0(p, u(0)) = 0, \qquad g(x_{00}, z_{00}, p, u(0)) = 0, \qquad
    R(V_k, x_{k0}, p, U_k, h_k) = \Bigl(\sum_{j=0}^{d} C_{jr} x_{kj} - h_k f(x_{kr}, z_{kr}, p, u_{kr}),\;
    g(x_{kr}, z_{kr}, p, u_{kr})\Bigr)_{r=1..d} = 0,

with x_{k0} = x_{k-1,d} (only the differential states carry over an element boundary).  These are exactly
the discrete equations of :meth:`models.collocation.CollocatedModel.element_residual` (the same residual
function), block lower-triangular in the elements: z(0) by Newton on g at t = 0 (from z = 1, as the
collocated model's own state guess), then element after element Newton on the (n_x + n_z) d unknowns of
one element (:func:`models.element_march.march`), and the exact sensitivity y'(p) = -(dE/dy)^{-1} dE/dp by
forward substitution through the same blocks,

.. math::

    x_{00}' = x_0'(p), \quad z_{00}' = -g_z^{-1} (g_x x_{00}' + g_p), \quad
    V_k' = -R_V^{-1} (R_{x_0} x_{k0}' + R_p).

For an index-1 DAE g_z is nonsingular, so R_V is (a DAE whose dg/dz is structurally singular is refused when
it is built, :class:`models.dynamic.DynamicModel`).  A state solve or sensitivity whose blocks fail (an element's
Newton, or g_z singular at a point of the trajectory: not of index 1 there) falls back to the generic solves of
:mod:`models.state` with the reason kept in :attr:`DAETrajectoryNumerics.fallbacks` and a
:class:`RuntimeWarning` (never silent).
"""
from __future__ import annotations

import warnings
from contextlib import contextmanager
from contextvars import ContextVar

import casadi as ca
import numpy as np

from .batched import batched_function
from .errors import StateSolveError
from .sensitivity import Sensitivities, StateSolve, generic_sensitivities
from .state import solve_states_generic
from .element_march import march
from .trajectory import RESIDUAL_TOL, TrajectoryNumerics, output_functions

__all__ = ["DAETrajectoryNumerics", "GenericDAESolve", "dae_numerics", "dae_march_scope", "MAX_FALLBACKS_KEPT"]

#: Newton iterations on z(0) (as the element solves of :meth:`models.collocation.CollocatedModel.element_functions`)
_MAX_ITER = 60
#: fallback reasons kept per numerics (the latest ones)
MAX_FALLBACKS_KEPT = 20
#: whether collocated index-1 DAEs march here (:func:`dae_march_scope`)
_MARCH_SCOPE: ContextVar = ContextVar("mudoe_dae_march", default=True)


@contextmanager
def dae_march_scope(enabled: bool):
    """The element marcher of index-1 DAEs on (the default) or off for the code run inside the block, in this
    thread (or task) only: off, a collocated DAE's :attr:`models.Model.state_numerics` is the generic solves
    (:class:`GenericDAESolve`, reason "switched off by dae_march_scope"); for comparisons and benchmarks."""
    token = _MARCH_SCOPE.set(bool(enabled))
    try:
        yield
    finally:
        _MARCH_SCOPE.reset(token)


class GenericDAESolve(StateSolve):
    """The generic solves (:class:`models.sensitivity.StateSolve`) of a collocated DAE the marcher does not take;
    ``reason`` says why (:func:`dae_march_scope` switched the marcher off)."""

    def __init__(self, model, reason: str):
        super().__init__(model)
        self.reason = reason


class DAETrajectoryNumerics(TrajectoryNumerics):
    """The numerics of one collocated index-1 DAE (:attr:`models.Model.state_numerics`; see the module
    docstring): the operations and capabilities of :class:`models.trajectory.TrajectoryNumerics` (it is one),
    with the algebraic states in every element's unknowns and z(0) solved at t = 0.

    Attributes
    ----------
    fallbacks : list of str   why a solve fell back to the generic path (the latest :data:`MAX_FALLBACKS_KEPT`)
    """

    def __init__(self, cm):
        dyn, d, N = cm.dynamic, cm.mesh.degree, cm.mesh.n_elements
        self.model, self.d, self.N = cm, d, N
        n_x, n_z, n_p = dyn.n_x, dyn.n_z, dyn.n_p
        self.n_x, self.n_w = n_x, n_x + n_z
        nd = self.n_w * d
        V, xs, p, U, hk = cm.element_symbols()
        R = cm.element_residual(V, xs, p, U, hk)
        RV = ca.jacobian(R, V)
        self.newton = ca.Function("dae_newton", [V, xs, p, U, hk], [R, RV])
        self.blocks = ca.Function("dae_blocks", [V, xs, p, U, hk], [RV, ca.jacobian(R, xs), ca.jacobian(R, p)])
        self.residual_blocks = ca.Function("dae_residual_blocks", [V, xs, p, U, hk], [R, RV, ca.jacobian(R, xs)])
        q = ca.SX.sym("q", dyn.n_q_dim)
        u0 = cm.initial_input(q)
        x0 = dyn.x0_fun(p, u0)
        self.init = ca.Function("dae_x0", [p, q], [x0, ca.jacobian(x0, p)])
        xa, za = ca.SX.sym("x00", n_x), ca.SX.sym("z00", n_z)
        g0 = dyn.alg_fun(xa, za, p, u0)
        self.alg0 = ca.Function("dae_g0", [xa, za, p, q],
                                [g0, ca.jacobian(g0, za), ca.jacobian(g0, xa), ca.jacobian(g0, p)])
        self.Umap = cm.point_input_map()
        self.output_terms, self.h_only, self.h_terms = output_functions(cm, p, q, "dae")
        mu, ze = ca.SX.sym("mu", nd), ca.SX.sym("Z", (nd + n_x) * n_p)
        Ze = ca.vertcat(ca.reshape(ze, nd + n_x, n_p), ca.DM.eye(n_p))
        He = ca.hessian(ca.dot(mu, R), ca.vertcat(V, xs, p))[0]
        self.element_hessian = ca.Function("dae_elem_hess", [V, xs, p, U, hk, mu, ze],
                                           [ca.mtimes(Ze.T, ca.mtimes(He, Ze))])
        mu0 = ca.SX.sym("mu0", n_x)
        self.x0_hessian = ca.Function("dae_x0_hess", [p, q, mu0], [ca.hessian(ca.dot(mu0, x0), p)[0]])
        mug, z0 = ca.SX.sym("mug", n_z), ca.SX.sym("Z0", self.n_w * n_p)
        Z0 = ca.vertcat(ca.reshape(z0, self.n_w, n_p), ca.DM.eye(n_p))
        Hg = ca.hessian(ca.dot(mug, g0), ca.vertcat(xa, za, p))[0]
        self.g0_hessian = ca.Function("dae_g0_hess", [xa, za, p, q, mug, z0], [ca.mtimes(Z0.T, ca.mtimes(Hg, Z0))])
        self.steps = np.diff(np.asarray(cm.mesh.boundaries))
        self._maps = {}
        self.fallbacks = []

    # ------------------------------------------------------------------ helpers

    def states_and_sensitivities(self, p, inputs, guess):
        """None: the fused states and sensitivities of :class:`models.trajectory.TrajectoryNumerics` hold the
        ODE's blocks only; the caller solves the states and sweeps the DAE's elements as usual."""
        return None

    def refined_outputs(self, p, inputs, guess) -> np.ndarray:
        """h (n_q, n_S) of the collocation solution at p from ``guess`` by Newton to convergence
        (:meth:`integrated_outputs`; the one-step shortcut of the ODE marcher is not implemented for DAEs)."""
        return self.integrated_outputs(p, inputs, guess)
    def _call(self, f: ca.Function, n: int, args) -> list:
        """f at n points (rows of the (n, .) arguments; (.,) arguments shared), one dense (n, r, c) array per output."""
        fm = self._maps.get((f.name(), n))
        if fm is None:
            fm = self._maps[(f.name(), n)] = batched_function(f, n)
        return fm(*args)

    def _fell_back(self, what: str, exc: Exception, warn: bool = True) -> str:
        """Keep (and by default warn) why ``what`` fell back to the generic solves; returns the reason."""
        reason = f"{what} of {self.model.dynamic.name!r} fell back to the generic solves: {exc}"
        self.fallbacks = (self.fallbacks + [reason])[-MAX_FALLBACKS_KEPT:]
        if warn:
            warnings.warn(reason, RuntimeWarning, stacklevel=3)
        return reason

    def _w_elements(self, Y: np.ndarray) -> tuple:
        """(W (n, N, n_w d), XS (n, N, n_x)): every element's unknowns and its start (the x part of the previous
        element's last point; x(0) for the first)."""
        nd, n_x, n_w = self.n_w * self.d, self.n_x, self.n_w
        W = Y[:, n_w:].reshape(Y.shape[0], self.N, nd)
        return W, np.concatenate([Y[:, None, :n_x], W[:, :-1, nd - n_w:nd - n_w + n_x]], axis=1)

    def _per_element(self, p: np.ndarray) -> np.ndarray:
        return p if p.ndim == 1 else np.repeat(p, self.N, axis=0)

    # ------------------------------------------------------------------ the strategy's operations
    def solve_states(self, p: np.ndarray, inputs: np.ndarray, Y0=None) -> np.ndarray:
        """The collocation solution (n_q, n_y) at p (:meth:`states`); when the marcher fails, the generic solves
        (:func:`models.state.solve_states_generic`, from ``Y0`` or the model's own guess), the reason kept in
        :attr:`fallbacks`: with a warning when they succeed, else in their StateSolveError (raised)."""
        try:
            return self.states(p, inputs, Y0)
        except (StateSolveError, np.linalg.LinAlgError) as exc:
            first = exc
        reason = self._fell_back("the state solve", first, warn=False)
        try:
            Y = solve_states_generic(self.model, p, inputs, Y0)
        except StateSolveError as exc:
            raise StateSolveError(f"{exc} ({reason}, which failed too)") from first
        warnings.warn(reason, RuntimeWarning, stacklevel=2)
        return Y

    def sensitivities(self, p: np.ndarray, inputs: np.ndarray, Y) -> Sensitivities:
        """h, G = dh/dp and y'(p) by forward substitution through the elements; the generic sensitivities
        (:func:`models.sensitivity.generic_sensitivities`) when a block is singular, the reason kept."""
        try:
            out = super().sensitivities(p, inputs, Y)
            if np.all(np.isfinite(out.G)):
                return out
            problem = StateSolveError("non-finite sensitivities (a singular dg/dz: not of index 1 on the trajectory)")
        except (StateSolveError, np.linalg.LinAlgError) as exc:
            problem = exc
        self._fell_back("the sensitivities", problem)
        return generic_sensitivities(self.model, np.asarray(p, float).ravel(), np.atleast_2d(inputs), Y)

    # ------------------------------------------------------------------ states
    def initial_points(self, p, inputs) -> np.ndarray:
        """w_00 = (x(0), z(0)) of every experiment (n, n_w): x_0(p, u(0)) and z(0) by batched Newton on
        g(x(0), z, p, u(0)) = 0 from z = 1 (the start of the collocated model's state guess); raises
        StateSolveError naming the experiment when no consistent z(0) is found."""
        n, n_x = inputs.shape[0], self.n_x
        x0 = self._call(self.init, n, [p, inputs])[0][:, :, 0]
        z = np.ones((n, self.n_w - n_x))
        for _ in range(_MAX_ITER):
            g, gz = self._call(self.alg0, n, [x0, z, p, inputs])[:2]
            g = g[:, :, 0]
            if not np.all(np.isfinite(g)) or np.max(np.abs(g)) <= 1e-13:
                break
            try:
                step = np.linalg.solve(gz, g[:, :, None])[:, :, 0]
            except np.linalg.LinAlgError:
                j = int(np.argmin(np.abs(np.linalg.det(gz))))
                raise StateSolveError(f"initial algebraic states of {self.model.dynamic.name!r}: dg/dz is singular "
                                      f"at t = 0 for experiment {j + 1} (inputs {inputs[j].tolist()}): the DAE is "
                                      "not of index 1 there") from None
            z = z - step
            if np.max(np.abs(step)) <= 1e-12 * (1 + np.max(np.abs(z))):
                g = self._call(self.alg0, n, [x0, z, p, inputs])[0][:, :, 0]
                break
        small = np.max(np.abs(g), axis=1) <= RESIDUAL_TOL * (1 + np.max(np.abs(z), axis=1))
        bad = ~(np.all(np.isfinite(z), axis=1) & small)
        if np.any(bad):
            j = int(np.flatnonzero(bad)[0])
            raise StateSolveError(f"initial algebraic states of {self.model.dynamic.name!r}: no z(0) with "
                                  f"g(x(0), z, p, u(0)) = 0 for experiment {j + 1} (inputs {inputs[j].tolist()})")
        return np.concatenate([x0, z], axis=1)

    def _states(self, p, inputs, guess=None) -> np.ndarray:
        if guess is not None:
            Y = self._newton(p, inputs, np.asarray(guess, float))
            if Y is not None:
                return Y
        W0 = self.initial_points(p, inputs)
        V = march(self.model, W0, p, self._controls(inputs), inputs)
        return np.concatenate([W0, V.reshape(inputs.shape[0], -1)], axis=1)

    def _stacked_solve(self, RV, Rx, gz, gx, B):
        """dE/dy^{-1} B for the stacked experiments (B (n n_y, k)): x(0) rows the identity, z(0) by
        g_z^{-1} (B_z - g_x v_x0), then forward substitution v_k = R_V^{-1} (B_k - R_x0 v_{k-1,end,x})."""
        n_x, n_w, N = self.n_x, self.n_w, self.N
        nd = n_w * self.d
        n_y = n_w * (1 + N * self.d)
        n, k = B.shape[0] // n_y, B.shape[1]
        B = B.reshape(n, n_y, k)
        rhs = np.concatenate([Rx.reshape(n * N, nd, n_x), B[:, n_w:].reshape(n * N, nd, k)], axis=2)
        X = np.linalg.solve(RV.reshape(n * N, nd, nd), rhs)
        M, C = X[..., :n_x].reshape(n, N, nd, n_x), X[..., n_x:].reshape(n, N, nd, k)
        out = np.empty_like(B)
        out[:, :n_x] = prev = B[:, :n_x]
        out[:, n_x:n_w] = np.linalg.solve(gz, B[:, n_x:n_w] - gx @ prev)
        for e in range(N):
            v = C[:, e] - M[:, e] @ prev
            out[:, n_w + e * nd:n_w + (e + 1) * nd] = v
            prev = v[:, nd - n_w:nd - n_w + n_x]
        return out.reshape(n * n_y, k)

    def _newton(self, p, inputs, Y):
        """Newton on every experiment's whole collocation system from the guess Y (the test and limits of
        :meth:`models.trajectory.TrajectoryNumerics` ``_newton``); the states, or None when it does not converge."""
        n, N = inputs.shape[0], self.N
        x0 = self._call(self.init, n, [p, inputs])[0][:, :, 0]
        n_x, n_w = self.n_x, self.n_w
        Y = np.array(Y, float)
        if Y.shape != (n, n_w * (1 + N * self.d)):
            return None
        U = self._controls(inputs).reshape(n * N, -1)
        pe, steps = self._per_element(p), np.tile(self.steps, n)[:, None]
        Y[:, :n_x] = x0
        prev = np.inf
        for _ in range(8):
            W, XS = self._w_elements(Y)
            R, RV, Rx = self._call(self.residual_blocks, n * N, [W.reshape(n * N, -1), XS.reshape(n * N, -1), pe, U,
                                                                 steps])
            g0, gz, gx = self._call(self.alg0, n, [Y[:, :n_x], Y[:, n_x:n_w], p, inputs])[:3]
            norm = max(float(np.max(np.abs(R))), float(np.max(np.abs(g0))))
            if not (np.isfinite(norm) and np.all(np.isfinite(RV)) and norm <= prev):
                return None
            prev = norm
            E = np.concatenate([np.zeros((n, n_x)), g0[:, :, 0], R.reshape(n, -1)], axis=1)
            try:
                dY = self._stacked_solve(RV, Rx, gz, gx, E.reshape(-1, 1)).reshape(n, -1)
            except np.linalg.LinAlgError:
                return None
            if not np.all(np.isfinite(dY)):
                return None
            Y -= dY
            if np.all(np.max(np.abs(dY), axis=1) <= 1e-12 * (1 + np.max(np.abs(Y), axis=1))):
                return Y
        return None

    # ------------------------------------------------------------------ sensitivities
    def _sweep(self, p, inputs, Y):
        n, N, n_p = inputs.shape[0], self.N, p.shape[-1]
        n_x, n_w = self.n_x, self.n_w
        x0p = self._call(self.init, n, [p, inputs])[1]
        W, XS = self._w_elements(Y)
        U = self._controls(inputs)
        m = n * N
        RV, Rx, Rp = self._call(self.blocks, m, [W.reshape(m, -1), XS.reshape(m, -1), self._per_element(p),
                                                 U.reshape(m, -1), np.tile(self.steps, n)[:, None]])
        RV, Rx, Rp = (a.reshape((n, N) + a.shape[1:]) for a in (RV, Rx, Rp))
        _, gz, gx, gp = self._call(self.alg0, n, [Y[:, :n_x], Y[:, n_x:n_w], p, inputs])
        B = np.concatenate([x0p, -gp, -Rp.reshape(n, N * n_w * self.d, n_p)], axis=1)      # -dE/dp
        out = self._stacked_solve(RV, Rx, gz, gx, B.reshape(-1, n_p)).reshape(n, -1, n_p)
        return out, RV, Rx

    def hessian_terms(self, p, inputs, Y, yp, RV, Rx, lam) -> np.ndarray:
        r"""sum_j d^2/dp^2 [lam_j^T h(y_j(p), p, q_j)] per experiment, shape (m, n_q, n_p, n_p), as
        :meth:`models.trajectory.TrajectoryNumerics.hessian_terms` with the algebraic rows: the adjoint solved
        backwards through the elements, then mu_g of g(x(0), z(0)) = 0 from g_z^T mu_g = b_z0 and
        mu_x0 = b_x0 - R_x0,0^T mu_0 - g_x^T mu_g; the Hessian adds that of mu_g^T g(x(0), z(0), p, u(0))."""
        n, d, N, n_p = inputs.shape[0], self.d, self.N, yp.shape[2]
        p = p.ravel() if np.ndim(p) < 2 else np.asarray(p).reshape(n, -1)
        n_x, n_w = self.n_x, self.n_w
        nd = n_w * d
        W, XS = self._w_elements(Y)
        U = self._controls(inputs)
        m = n * N
        Vp = yp[:, n_w:].reshape(n, N, nd, n_p)
        XSp = np.concatenate([yp[:, None, :n_x], Vp[:, :-1, nd - n_w:nd - n_w + n_x]], axis=1)
        Ze = np.ascontiguousarray(np.concatenate([Vp, XSp], axis=2).transpose(0, 1, 3, 2)).reshape(m, -1)
        Z0 = np.ascontiguousarray(yp[:, :n_w].transpose(0, 2, 1)).reshape(n, -1)
        ypv = np.ascontiguousarray(yp.transpose(0, 2, 1)).reshape(n, -1)
        x00, z00 = Y[:, :n_x], Y[:, n_x:n_w]
        gz, gx = self._call(self.alg0, n, [x00, z00, p, inputs])[1:3]
        out = np.zeros((lam.shape[0], n, n_p, n_p))
        for a in range(lam.shape[0]):
            hyl, Hh = self._call(self.h_terms, n, [Y, ypv, p, inputs, lam[a]])
            b = -hyl[:, :, 0]
            bV = b[:, n_w:].reshape(n, N, nd)
            mu = np.empty((n, N, nd))
            nxt = np.zeros((n, n_x))                       # R_x0,k+1^T mu_k+1
            for k in range(N - 1, -1, -1):
                rhs = bV[:, k].copy()
                rhs[:, nd - n_w:nd - n_w + n_x] -= nxt
                mu[:, k] = np.linalg.solve(RV[:, k].transpose(0, 2, 1), rhs[:, :, None])[:, :, 0]
                nxt = np.einsum("jvx,jv->jx", Rx[:, k], mu[:, k])
            mug = np.linalg.solve(gz.transpose(0, 2, 1), b[:, n_x:n_w, None])[:, :, 0]
            mu0 = b[:, :n_x] - nxt - np.einsum("jzx,jz->jx", gx, mug)
            He = self._call(self.element_hessian, m,
                            [W.reshape(m, -1), XS.reshape(m, -1), self._per_element(p), U.reshape(m, -1),
                             np.tile(self.steps, n)[:, None], mu.reshape(m, -1), Ze])[0]
            H0 = self._call(self.x0_hessian, n, [p, inputs, mu0])[0]
            Hg = self._call(self.g0_hessian, n, [x00, z00, p, inputs, mug, Z0])[0]
            out[a] = Hh + He.reshape(n, N, n_p, n_p).sum(axis=1) - H0 + Hg
        return 0.5 * (out + out.transpose(0, 1, 3, 2))


def dae_numerics(cm):
    """The numerics of a collocated DAE: :class:`DAETrajectoryNumerics` (kept in its cache); the generic solves
    (:class:`GenericDAESolve`) inside ``dae_march_scope(False)``.  A DAE whose dg/dz is structurally singular is
    refused when it is built (:class:`models.dynamic.DynamicModel`); one singular on the trajectory falls back
    in the solves (module docstring)."""
    if not _MARCH_SCOPE.get():
        return GenericDAESolve(cm, "the DAE element marcher is switched off by dae_march_scope(False)")
    num = cm.cache.get("dae_trajectory", None)
    if num is None:
        num = cm.cache.put("dae_trajectory", None, DAETrajectoryNumerics(cm))
    return num
