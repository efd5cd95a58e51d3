r"""Trajectories of a collocated ODE model for all experiments at once, and their exact sensitivities.

The collocation equations of :mod:`models.collocation` are block lower-triangular in the elements:
element k's unknowns V_k = (x_k1, ..., x_kd) solve

.. math::

    R(V_k, x_{k0}, p, U_k, h_k) = \Bigl(\sum_{j=0}^{d} C_{jr} x_{kj} - h_k f(x_{kr}, p, u_{kr})\Bigr)_{r=1..d} = 0,
    \qquad x_{k0} = x_{k-1,d}, \quad x_{00} = x_0(p, u(0)),

so the state y = (x_00, V_0, ..., V_{N-1}) of one experiment is solved element after element
(Newton on the n_x d unknowns of one element), and its exact sensitivity y'(p) = -(dE/dy)^{-1} dE/dp
by forward substitution through the same blocks,

.. math::

    V_k'(p) = -R_V^{-1} (R_{x_0} x_{k0}'(p) + R_p),

with R_V, R_{x_0}, R_p by CasADi's AD.  Every element is done for all experiments together: one
mapped CasADi evaluation and one batched LAPACK solve of the (n_q, n_x d, n_x d) blocks per Newton
iteration, instead of one sparse LU of the whole trajectory (n_y = n_x (1 + N d)) per experiment.
The numbers are those of the whole-trajectory solve to round-off (the same equations, solved
exactly).  Outputs and G = dh/dy y' + dh/dp come from one mapped evaluation.  ODEs only (no
algebraic states): index-1 DAEs march in :mod:`models.dae_march` (the same scheme with z in every element).
"""
from __future__ import annotations


import casadi as ca
import numpy as np

from .errors import StateSolveError
from .batched import batched_function
from .block_solve import MAX_COMPILED_SIZE, accepted, pivot_order, solve_blocks, solved_function
from .element_march import march, march_failure, march_symbolic
from .element_rescue import RESIDUAL_TOL, element_failures, rescue_elements
from .merged_calls import current_broker
from .sensitivity import Sensitivities
from .state import JIT, numerics, solve_states_generic

__all__ = ["TrajectoryNumerics", "trajectory_numerics", "interpolate_states",
           "element_failures", "output_functions", "RESIDUAL_TOL", "output_sensitivity_function", "mapped_outputs",
           "outputs_and_sensitivities", "REFINED_RESIDUAL_TOL"]


#: Newton iterations per element before the element counts as failed (CasADi's rootfinder of
#: :meth:`models.collocation.CollocatedModel.element_functions` allows the same)
_MAX_ITER = 60


def _params(p, n: int) -> np.ndarray:
    """p shared by all n experiments, shape (n_p,), or one row per experiment, shape (n, n_p)."""
    p = np.asarray(p, float)
    return p.ravel() if p.ndim < 2 else p.reshape(n, -1)


def _per_element(p: np.ndarray, N: int) -> np.ndarray:
    """p at the n N (experiment, element) points, experiment-major."""
    return p if p.ndim == 1 else np.repeat(p, N, axis=0)


def _mapped_call(cache: dict, f: ca.Function, n: int, args) -> list:
    """f at n points: ``args`` are (n, d) arrays (one row a point) or (d,) arrays shared by all
    points; returns one dense (n, r, c) array per output."""
    f = _element_function(cache, f)
    fm = cache.get((f.name(), n))
    if fm is None:
        fm = cache[(f.name(), n)] = batched_function(f, n)
    return fm(*args)


#: the element functions of :class:`TrajectoryNumerics` compiled to C when JIT is on (models.state.set_jit,
#: jit_scope): their size does not grow with the mesh, and every mesh of a model shares them (the outputs'
#: functions, whose size grows with the sampling times, stay on CasADi's virtual machine)
_JIT_NAMES = frozenset({"traj_newton", "traj_blocks", "traj_residual_blocks", "traj_full_blocks", "traj_residual",
                        "traj_x0", "traj_elem_hess", "traj_x0_hess", "traj_blocks_solved",
                        "traj_residual_blocks_solved", "traj_full_blocks_solved"})


def _element_function(cache: dict, f: ca.Function) -> ca.Function:
    """f, or its C-compiled copy when JIT compilation is wanted here (:data:`models.state.JIT`, process-wide
    or in a :func:`models.state.jit_scope`) and f is one of the element functions (:data:`_JIT_NAMES`, SX) of
    an element with at most :data:`models.block_solve.MAX_COMPILED_SIZE` unknowns (n_x d; ``cache["jit_small"]``,
    set by :class:`TrajectoryNumerics`);
    the copy is kept in ``cache`` (the same numbers: the compiled code does the virtual machine's operations
    in the same order).  Without a working compiler, f."""
    name = f.name()
    if name not in _JIT_NAMES or not cache.get("jit_small", False) or not JIT.active():
        return f
    g = cache.get(("jit", name))
    if g is None:
        g = cache[("jit", name)] = JIT.compile(f) or f
    return g


#: one Newton step from another mesh's trajectories is kept when max |R| <= REFINED_RESIDUAL_TOL (1 + max |V|)
#: on every element (:meth:`TrajectoryNumerics.refined_outputs`)
REFINED_RESIDUAL_TOL = 1e-10


class _TrajectorySensitivities(Sensitivities):
    """A collocated ODE (:mod:`models.trajectory`): h, G and y' of all inputs by forward substitution
    through the elements; the adjoints and second derivatives factor dE/dy per input when first asked."""

    __slots__ = ("_yp", "_traj", "_model", "_blocks")

    def __init__(self, h, G, traj, p, inputs, Y, yp, blocks):
        super().__init__(h, G, None, p, inputs, Y, None)
        self._yp, self._traj, self._model, self._blocks = yp, traj, traj.model, blocks

    @property
    def state_derivatives(self) -> np.ndarray:
        return self._yp

    def _filled(self) -> None:
        if self._cache is not None:
            return
        num = numerics(self._model)
        n_p = self.G.shape[2]
        cache = []
        for j in range(self._inputs.shape[0]):
            _, Ey, _, hy, _ = num.point("sens")(self._Y[j], self._p, self._inputs[j])
            cache.append((num.factor(Ey), hy, np.vstack([self._yp[j], np.eye(n_p)])))
        self._num, self._cache = num, cache

    def adjoint(self, lam: np.ndarray) -> np.ndarray:
        self._filled()
        return super().adjoint(lam)

    def hessians(self, lam: np.ndarray) -> np.ndarray:
        return self._traj.hessians(self._p, self._inputs, self._Y, self._yp, *self._blocks, np.asarray(lam, float))

    def output_hessians(self) -> np.ndarray:
        self._filled()
        return super().output_hessians()



def output_functions(cm, p, q, prefix: str) -> tuple:
    r"""(outputs, h, h_terms) of a collocated model's readings h(y, p, q) (CasADi Functions named ``prefix_*``):
    h and G = dh/dy y'(p) + dh/dp from the states y and their sensitivities y' (flattened column by column),
    h alone, and the output's second-order terms of L = lam^T h: (dh/dy)^T lam and Z^T grad^2 L Z with
    Z = [y'; I] (:meth:`TrajectoryNumerics.hessians`)."""
    n_p = p.numel()
    y, yp = ca.SX.sym("y", cm.n_y), ca.SX.sym("yp", cm.n_y * n_p)
    h = cm.h_fun(y, p, q)
    G = ca.mtimes(ca.jacobian(h, y), ca.reshape(yp, cm.n_y, n_p)) + ca.jacobian(h, p)
    lam = ca.SX.sym("lam", cm.n_S)
    Zh = ca.vertcat(ca.reshape(yp, cm.n_y, n_p), ca.DM.eye(n_p))
    Hh = ca.hessian(ca.dot(lam, h), ca.vertcat(y, p))[0]
    return (ca.Function(f"{prefix}_outputs", [y, yp, p, q], [h, G]), ca.Function(f"{prefix}_h", [y, p, q], [h]),
            ca.Function(f"{prefix}_h_terms", [y, yp, p, q, lam],
                        [ca.mtimes(ca.jacobian(h, y).T, lam), ca.mtimes(Zh.T, ca.mtimes(Hh, Zh))]))

class TrajectoryNumerics:
    """The numerics of one collocated ODE model (:attr:`models.Model.state_numerics`; see the module
    docstring): its trajectories marched element by element, all experiments at once, and their exact
    sensitivities by forward substitution through the elements.  The same operations as the generic
    strategy :class:`models.sensitivity.StateSolve`.

    Attributes
    ----------
    model : models.collocation.CollocatedModel
    reduced_space : bool    True: the states are solved to round-off for any number of experiments, so a
                            fit stays in the reduced space (no NLP, no state scalings)
    merges_fits : bool      True: batched fits run every member's fit with their evaluations merged
                            (:func:`models.merged_calls.run_merged`)
    """

    reduced_space = True
    merges_fits = True

    def __init__(self, cm):
        dyn, d, N = cm.dynamic, cm.mesh.degree, cm.mesh.n_elements
        self.model, self.d, self.N = cm, d, N
        n_x, n_p = dyn.n_x, dyn.n_p
        b = np.asarray(cm.mesh.boundaries)
        V, xs, p, U, hk = cm.element_symbols()
        R = cm.element_residual(V, xs, p, U, hk)
        RV = ca.jacobian(R, V)
        self.newton = ca.Function("traj_newton", [V, xs, p, U, hk], [R, RV])
        self.blocks = ca.Function("traj_blocks", [V, xs, p, U, hk], [RV, ca.jacobian(R, xs), ca.jacobian(R, p)])
        self.residual_blocks = ca.Function("traj_residual_blocks", [V, xs, p, U, hk], [R, RV, ca.jacobian(R, xs)])
        self.full_blocks = ca.Function("traj_full_blocks", [V, xs, p, U, hk],
                                       [R, RV, ca.jacobian(R, xs), ca.jacobian(R, p)])
        self.residual = ca.Function("traj_residual", [V, xs, p, U, hk], [R])
        q = ca.SX.sym("q", dyn.n_q_dim)
        x0 = dyn.x0_fun(p, cm.initial_input(q))
        self.init = ca.Function("traj_x0", [p, q], [x0, ca.jacobian(x0, p)])
        self.Umap = cm.point_input_map()
        # second order: Z^T grad^2 L Z of L = lam^T h + mu^T E, term by term (see hessians)
        self.output_terms, self.h_only, self.h_terms = output_functions(cm, p, q, "traj")
        mu = ca.SX.sym("mu", n_x * d)
        ze = ca.SX.sym("Z", (n_x * d + n_x) * n_p)
        Ze = ca.vertcat(ca.reshape(ze, n_x * d + n_x, n_p), ca.DM.eye(n_p))
        He = ca.hessian(ca.dot(mu, R), ca.vertcat(V, xs, p))[0]
        self.element_hessian = ca.Function("traj_elem_hess", [V, xs, p, U, hk, mu, ze],
                                           [ca.mtimes(Ze.T, ca.mtimes(He, Ze))])
        mu0 = ca.SX.sym("mu0", n_x)
        self.x0_hessian = ca.Function("traj_x0_hess", [p, q, mu0], [ca.hessian(ca.dot(mu0, x0), p)[0]])
        self.steps = np.diff(b)
        # the rows' order for the element blocks' compiled elimination (models.block_solve, JIT only): partial
        # pivoting of R_V as the element length goes to 0, sum_j C_jr x_j (the collocation matrix times I)
        A0 = np.kron(np.asarray(cm.C, float)[1:, 1:].T, np.eye(n_x))
        small = n_x * d <= MAX_COMPILED_SIZE          # larger element blocks: LAPACK and the virtual machine
        self.pivot_rows, self.pivot_rows_t = (pivot_order(A0), pivot_order(A0.T)) if small else (None, None)
        self._maps = {"jit_small": small}

    # ------------------------------------------------------------------ the strategy's operations
    def solve_states(self, p: np.ndarray, inputs: np.ndarray, Y0=None) -> np.ndarray:
        """The collocation solution (n_q, n_y) at p (:meth:`states`); when that fails from a guess ``Y0``,
        the generic solves from it (:func:`models.state.solve_states_generic`)."""
        try:
            return self.states(p, inputs, Y0)
        except StateSolveError:
            if Y0 is None:
                raise
        return solve_states_generic(self.model, p, inputs, Y0)

    def sensitivities(self, p: np.ndarray, inputs: np.ndarray, Y) -> Sensitivities:
        """h, G = dh/dp and y'(p) of every experiment at the states Y (:meth:`sweep`, one forward
        substitution through the elements for all experiments)."""
        Y = np.asarray(Y, float)
        yp, RV, Rx = self.sweep(p, inputs, Y)
        h, G = self.outputs_and_sensitivities(p, inputs, Y, yp)
        return _TrajectorySensitivities(h, G, self, p, inputs, Y, yp, (RV, Rx))

    def marched_states(self, p, inputs, guess) -> np.ndarray:
        """The states at p from a predicted ``guess`` (Newton on all trajectories), else marched (:meth:`states`)."""
        return self.states(p, inputs, guess)

    def integrated_outputs(self, p, inputs, guess=None) -> np.ndarray:
        """h (n_q, n_S) of the collocation solution at p, from the states ``guess`` when given (e.g.
        another mesh's trajectories interpolated, :func:`interpolate_states`)."""
        if guess is None:
            return self.outputs(p, inputs)
        return self.outputs(p, inputs, self.states(p, inputs, guess))

    def refined_outputs(self, p, inputs, guess) -> np.ndarray:
        r"""h (n_q, n_S) of the collocation solution at p from a ``guess`` within the discretisation error of it
        (another mesh's trajectories interpolated, :func:`interpolate_states`): one Newton step on all
        trajectories, kept when every element's residual after it is at most
        :data:`REFINED_RESIDUAL_TOL` (1 + max |V|) (Newton converges quadratically: from a start at a relative
        distance delta the step leaves O(delta^2), and the residual test bounds what is left); else Newton to
        convergence as :meth:`integrated_outputs`."""
        inputs = np.atleast_2d(np.asarray(inputs, float))
        if current_broker() is not None:
            return self.integrated_outputs(p, inputs, guess)
        n, N = inputs.shape[0], self.N
        pv = _params(p, n)
        x0 = _mapped_call(self._maps, self.init, n, [pv, inputs])[0][:, :, 0]
        n_x = x0.shape[1]
        Y = np.array(guess, float)
        if Y.shape == (n, n_x * (1 + N * self.d)):
            Y[:, :n_x] = x0
            U, pe, steps = self._controls(inputs).reshape(n * N, -1), _per_element(pv, N), np.tile(self.steps, n)[:, None]
            W, XS = self._elements(Y, n_x)
            args = [W.reshape(n * N, -1), XS.reshape(n * N, -1), pe, U, steps]
            fused = self._solved("residual_blocks")
            if fused is not None:
                R, RV, Rx, X, fails = _mapped_call(self._maps, fused, n * N, args)
            else:
                (R, RV, Rx), X, fails = _mapped_call(self._maps, self.residual_blocks, n * N, args), None, None
            E = np.concatenate([np.zeros((n, n_x)), R.reshape(n, -1)], axis=1)
            Y -= self._stacked_solve(RV, Rx, E.reshape(-1, 1), None if X is None else (X, fails)).reshape(n, -1)
            W, XS = self._elements(Y, n_x)
            W = W.reshape(n * N, -1)
            R = _mapped_call(self._maps, self.residual, n * N, [W, XS.reshape(n * N, -1), pe, U, steps])[0][:, :, 0]
            with np.errstate(invalid="ignore"):
                ok = np.all(np.isfinite(W)) and np.all(np.max(np.abs(R), axis=1) <= REFINED_RESIDUAL_TOL
                                                        * (1 + np.max(np.abs(W), axis=1)))
            if ok:
                return self.outputs(pv, inputs, Y)
        return self.integrated_outputs(p, inputs, guess)

    # ------------------------------------------------------------------ states
    def _elements(self, Y: np.ndarray, n_x: int) -> tuple:
        """(W, XS) of the trajectories Y (n, n_y): every element's unknowns (n, N, n_x d) and its start
        (n, N, n_x), the previous element's end (x(0) for the first)."""
        W = Y[:, n_x:].reshape(Y.shape[0], self.N, n_x * self.d)
        return W, np.concatenate([Y[:, None, :n_x], W[:, :-1, -n_x:]], axis=1)

    def _controls(self, inputs: np.ndarray) -> np.ndarray:
        """U of every experiment and element, shape (n_q, N, n_u d)."""
        return (inputs @ self.Umap.T).reshape(inputs.shape[0], self.N, -1)

    def states(self, p, inputs, guess=None) -> np.ndarray:
        """The collocation solution y_j (n_q, n_y) of every experiment at p (shared, or a row per
        experiment): with a ``guess`` of the states (e.g. predicted from a nearby p), Newton on all
        trajectories at once (:meth:`_newton`); else, or when that fails, element after element.

        Raises StateSolveError naming the experiment and the element where Newton fails (the
        trajectory blows up or is too stiff for the element)."""
        inputs = np.atleast_2d(np.asarray(inputs, float))
        broker = current_broker()
        if broker is not None:
            return broker.call(self, "states", p, inputs, guess)
        return self._states(_params(p, inputs.shape[0]), inputs, guess)

    def _states(self, p, inputs, guess=None) -> np.ndarray:
        if guess is not None:
            Y = self._newton(p, inputs, np.asarray(guess, float))
            if Y is not None:
                return Y
        n = inputs.shape[0]
        x0 = _mapped_call(self._maps, self.init, n, [p, inputs])[0][:, :, 0]
        return np.concatenate([x0, march(self.model, x0, p, self._controls(inputs), inputs).reshape(n, -1)], axis=1)

    def _stacked_solve(self, RV, Rx, B, solved=None):
        """dE/dy^{-1} B for the stacked experiments (B: (n n_y, k)) by forward substitution through the
        block-bidiagonal dE/dy: one batched solve gives R_V^{-1} R_x0 and R_V^{-1} B of every
        (experiment, element) (LAPACK, or with JIT the compiled elimination of :mod:`models.block_solve`), then
        v_k = R_V^{-1} B_k - R_V^{-1} R_x0 v_{k-1, end} element after element (small batched products).
        ``solved``: (X, fails) of an element function with its solves (:meth:`_solved`, JIT only), whose first
        n_x + k columns are R_V^{-1} (R_x0, B's element rows)."""
        n_x = Rx.shape[-1]
        nd, N = n_x * self.d, self.N
        n_y = n_x * (1 + N * self.d)
        n, k = B.shape[0] // n_y, B.shape[1]
        B = B.reshape(n, n_y, k)

        def rhs():
            return np.concatenate([Rx.reshape(n * N, nd, n_x), B[:, n_x:].reshape(n * N, nd, k)], axis=2)
        if solved is None:
            X = solve_blocks(RV.reshape(n * N, nd, nd), rhs(), self._maps, self.pivot_rows)
        else:
            X = accepted(solved[0][..., :n_x + k], solved[1], RV.reshape(n * N, nd, nd), rhs)
        M, C = X[..., :n_x].reshape(n, N, nd, n_x), X[..., n_x:].reshape(n, N, nd, k)
        out = np.empty_like(B)
        out[:, :n_x] = prev = B[:, :n_x]                    # the rows of x(0) - x0: identity
        if solved is not None:       # JIT: the recurrence on the elements' end points, then every element at once
            Ml, Cl, starts = M[:, :, -n_x:], C[:, :, -n_x:], np.empty((n, N, n_x, k))
            for e in range(N):
                starts[:, e] = prev
                prev = Cl[:, e] - Ml[:, e] @ prev
            out[:, n_x:] = (C - M @ starts).reshape(n, N * nd, k)
            return out.reshape(n * n_y, k)
        for e in range(N):
            v = C[:, e] - M[:, e] @ prev
            out[:, n_x + e * nd:n_x + (e + 1) * nd] = v
            prev = v[:, -n_x:]
        return out.reshape(n * n_y, k)

    def _solved(self, name: str):
        """The element function ``name`` (an attribute: blocks, residual_blocks or full_blocks) with the solves
        of its blocks R_V^{-1} (R_x0, R, -R_p) (the columns it has) in the same compiled evaluation
        (:func:`models.block_solve.solved_function`); None unless JIT compilation is wanted here and the element
        has at most :data:`models.block_solve.MAX_COMPILED_SIZE` unknowns."""
        if not JIT.active() or self.pivot_rows is None:
            return None
        f = self._maps.get(("solved", name))
        if f is None:
            base = getattr(self, name)
            cols = {"blocks": (0, ((1, 1), (2, -1))), "residual_blocks": (1, ((2, 1), (0, 1))),
                    "full_blocks": (1, ((2, 1), (0, 1), (3, -1)))}[name]
            f = self._maps[("solved", name)] = solved_function(base, cols[0], cols[1], self.pivot_rows,
                                                               f"{base.name()}_solved")
        return f

    def _newton(self, p, inputs, Y, sweep: bool = False):
        """Newton on the whole collocation system of every experiment from the guess Y (one mapped
        evaluation and one :meth:`_stacked_solve` per iteration); the states, or None when it does not converge
        (at most 8 iterations, the residual not decreasing, or non-finite values).  Converged when
        the step satisfies |dy| <= 1e-12 (1 + |y|) at every experiment (the test of
        :func:`models.state.solve_state`).  With ``sweep``: (Y, y'(p), R_V, R_x0) with y'(p) solved with every
        step from the same blocks (see :meth:`states_and_sensitivities`)."""
        n, d, N = inputs.shape[0], self.d, self.N
        x0 = _mapped_call(self._maps, self.init, n, [p, inputs])[0][:, :, 0]
        n_x = x0.shape[1]
        U = self._controls(inputs).reshape(n * N, -1)
        pe, steps = _per_element(p, N), np.tile(self.steps, n)[:, None]
        Y = np.array(Y, float)
        if Y.shape != (n, n_x * (1 + N * d)):
            return None
        Y[:, :n_x] = x0                                   # x(0) - x0(p, u(0)) = 0 exactly
        prev, force = np.inf, False
        if sweep:
            x0p = _mapped_call(self._maps, self.init, n, [p, inputs])[1]
        fused = self._solved("full_blocks" if sweep else "residual_blocks")
        solved = None
        for _ in range(8):
            W, XS = self._elements(Y, n_x)
            args = [W.reshape(n * N, -1), XS.reshape(n * N, -1), pe, U, steps]
            if fused is not None:
                *blocks, X, fails = _mapped_call(self._maps, fused, n * N, args)
                solved = (X, fails)
            else:
                blocks = _mapped_call(self._maps, self.full_blocks if sweep else self.residual_blocks, n * N, args)
            R, RV, Rx = blocks[:3]
            Rp = blocks[3] if sweep else None
            norm = float(np.max(np.abs(R)))
            if not (np.isfinite(norm) and np.all(np.isfinite(RV)) and norm <= prev):
                return None
            prev = norm
            E = np.concatenate([np.zeros((n, n_x)), R.reshape(n, -1)], axis=1)
            yp = None
            # y'(p) is solved along only where this step may be the last: |R| <= 1e-10 (1 + |y|) (a step of at
            # most 1e-12 (1 + |y|) has |R| = |R_V dy| below it unless |R_V| > 100); else in a later iteration
            if sweep and (force or norm <= 1e-10 * (1 + float(np.max(np.abs(Y))))):
                n_p = Rp.shape[-1]
                B = np.concatenate([E[:, :, None], np.concatenate([x0p, -Rp.reshape(n, -1, n_p)], axis=1)], axis=2)
                out = self._stacked_solve(RV, Rx, B.reshape(-1, 1 + n_p), solved).reshape(n, -1, 1 + n_p)
                dY, yp = out[:, :, 0], out[:, :, 1:]
            else:
                dY = self._stacked_solve(RV, Rx, E.reshape(-1, 1), solved).reshape(n, -1)
            if not np.all(np.isfinite(dY)):
                return None
            Y -= dY
            if np.all(np.max(np.abs(dY), axis=1) <= 1e-12 * (1 + np.max(np.abs(Y), axis=1))):
                if not sweep:
                    return Y
                if yp is not None:
                    return Y, yp, RV.reshape((n, N) + RV.shape[1:]), Rx.reshape((n, N) + Rx.shape[1:])
                prev, force = np.inf, True                # converged without y'(p): one more step, with it
        return None

    def states_and_sensitivities(self, p, inputs, guess):
        r"""(Y, sensitivities) of every experiment at p by Newton on all trajectories from ``guess`` (as
        :meth:`_newton`), with y'(p) from the last Newton iteration's blocks: each iteration solves
        R_V^{-1} (E, R_p) of every element in one batched solve and substitutes forwards for the Newton step
        and y' = -(dE/dy)^{-1} dE/dp together.  The last iteration's blocks are evaluated at the states
        before its step, which is |dy| <= 1e-12 (1 + |y|), so y'(p) differs from the sweep's at the
        converged states (:meth:`sensitivities`) by O(1e-12) relative: one mapped evaluation and one
        batched solve fewer per point.  None when Newton does not converge from ``guess`` (or inside
        :func:`models.merged_calls.run_merged`, whose evaluations are merged call by call): the caller then solves the
        states and sweeps as usual."""
        if current_broker() is not None or guess is None:
            return None
        inputs = np.atleast_2d(np.asarray(inputs, float))
        p = _params(p, inputs.shape[0])
        got = self._newton(p, inputs, np.asarray(guess, float), sweep=True)
        if got is None:
            return None
        Y, yp, RV, Rx = got
        h, G = self._outputs_and_sensitivities(p, inputs, Y, yp)
        return Y, _TrajectorySensitivities(h, G, self, p, inputs, Y, yp, (RV, Rx))

    def element_newton(self, xs, p, U, hk, inputs, k):
        """The NumPy step of :func:`march` for many experiments of an ODE: Newton on element k for every
        experiment from V = (x_start, ..., x_start), batched (one mapped evaluation and one batched LAPACK
        solve per iteration); an experiment
        stops when max |R| <= 1e-13 or its step is below 1e-12 (the tests of CasADi's rootfinder in
        :meth:`models.collocation.CollocatedModel.element_functions`), and is then left as it is."""
        n = xs.shape[0]
        V = np.tile(xs, (1, self.d))
        active = np.ones(n, bool)
        h = np.array([hk])
        for _ in range(_MAX_ITER + 1):
            R, RV = _mapped_call(self._maps, self.newton, n, [V, xs, p, U, h])
            R = R[:, :, 0]
            fresh = True
            rmax = np.max(np.abs(R), axis=1)                # NaN or inf when R is not finite
            if not np.all(np.isfinite(rmax[active])):
                self._fail(inputs, int(np.flatnonzero(active & ~np.isfinite(rmax))[0]), k, p)
            active &= rmax > 1e-13
            if not np.any(active):
                break
            try:
                step = np.linalg.solve(RV[active], R[active][:, :, None])[:, :, 0]
            except np.linalg.LinAlgError:
                self._fail(inputs, int(np.flatnonzero(active)[0]), k, p)
            V[active] -= step
            fresh = False
            tiny = np.zeros(n, bool)
            tiny[active] = np.max(np.abs(step), axis=1) <= 1e-12
            active &= ~tiny
            if not np.any(active):
                break
        if not fresh:
            R = _mapped_call(self._maps, self.newton, n, [V, xs, p, U, h])[0][:, :, 0]
        bad = element_failures(V, R)
        if np.any(bad):                 # Newton with a line search where plain Newton failed (a stiff model)
            pb = p if p.ndim == 1 else p[bad]
            par = np.concatenate([xs[bad], np.broadcast_to(pb, (int(bad.sum()), p.shape[-1])), U[bad],
                                  np.full((int(bad.sum()), 1), hk)], axis=1)
            V[bad], R[bad] = rescue_elements(self.model, np.tile(xs[bad], (1, self.d)), par)
            bad = element_failures(V, R)
        if np.any(bad):
            self._fail(inputs, int(np.flatnonzero(bad)[0]), k, p)
        return V

    def _fail(self, inputs, j, k, p):
        raise march_failure(self.model, p, inputs, j, k)

    # ------------------------------------------------------------------ sensitivities
    def state_derivatives(self, p, inputs, Y) -> np.ndarray:
        """y'(p) = -(dE/dy)^{-1} dE/dp at the states Y of every experiment, shape (n_q, n_y, n_p)."""
        return self.sweep(p, inputs, Y)[0]

    def sweep(self, p, inputs, Y):
        """(y'(p) (n_q, n_y, n_p), R_V (n_q, N, n_x d, n_x d), R_x0 (n_q, N, n_x d, n_x)) at the states Y."""
        inputs = np.atleast_2d(np.asarray(inputs, float))
        broker = current_broker()
        if broker is not None:
            return broker.call(self, "sweep", p, inputs, np.asarray(Y, float))
        return self._sweep(_params(p, inputs.shape[0]), inputs, np.asarray(Y, float))

    def _sweep(self, p, inputs, Y):
        n, d, N, n_p = inputs.shape[0], self.d, self.N, p.shape[-1]
        _, x0p = _mapped_call(self._maps, self.init, n, [p, inputs])
        n_x = x0p.shape[1]
        W, XS = self._elements(Y, n_x)
        U = self._controls(inputs)
        m = n * N
        args = [W.reshape(m, -1), XS.reshape(m, -1), _per_element(p, N), U.reshape(m, -1),
                np.tile(self.steps, n)[:, None]]
        fused = self._solved("blocks")
        solved = None
        if fused is not None:
            RV, Rx, Rp, X, fails = _mapped_call(self._maps, fused, m, args)
            solved = (X, fails)
        else:
            RV, Rx, Rp = _mapped_call(self._maps, self.blocks, m, args)
        RV, Rx, Rp = (a.reshape((n, N) + a.shape[1:]) for a in (RV, Rx, Rp))
        B = np.concatenate([x0p, -Rp.reshape(n, N * n_x * d, n_p)], axis=1)      # -dE/dp
        out = self._stacked_solve(RV, Rx, B.reshape(-1, n_p), solved).reshape(n, -1, n_p)
        return out, RV, Rx

    def hessians(self, p, inputs, Y, yp, RV, Rx, lam) -> np.ndarray:
        """See :meth:`hessian_terms`: their sum over the experiments, shape (m, n_p, n_p)."""
        broker = current_broker()
        if broker is not None:
            return broker.call(self, "hessians", p, inputs, Y, yp, RV, Rx, lam)
        return self.hessian_terms(_params(p, inputs.shape[0]), inputs, Y, yp, RV, Rx, lam).sum(axis=1)

    def hessian_terms(self, p, inputs, Y, yp, RV, Rx, lam) -> np.ndarray:
        r"""sum_j d^2/dp^2 [lam_j^T h(y_j(p), p, q_j)] for weight sets ``lam`` (m, n_q, n_S), shape (m, n_p, n_p):
        Z^T grad^2 (lam^T h + mu^T E) Z with Z = (y', I) and the adjoint (dE/dy)^T mu = -(dh/dy)^T lam
        solved backwards through the elements (R_V,k^T mu_k = b_k - R_x0,k+1^T mu_k+1 on element k's
        end point; mu of x(0) - x_0(p, u(0)) = b_0 - R_x0,0^T mu_0); the Hessian of mu^T E is that of
        every element's mu_k^T R_k in (V_k, x_k0, p) and of -mu_0^T x_0(p, u(0)) in p."""
        n, d, N, n_p = inputs.shape[0], self.d, self.N, yp.shape[2]
        p = _params(p, n)
        n_x = Rx.shape[3]
        W, XS = self._elements(Y, n_x)
        U = self._controls(inputs)
        m = n * N
        Vp = yp[:, n_x:].reshape(n, N, n_x * d, n_p)
        XSp = np.concatenate([yp[:, None, :n_x], Vp[:, :-1, -n_x:]], axis=1)
        Ze = np.ascontiguousarray(np.concatenate([Vp, XSp], axis=2).transpose(0, 1, 3, 2)).reshape(m, -1)
        ypv = np.ascontiguousarray(yp.transpose(0, 2, 1)).reshape(n, -1)
        out = np.zeros((lam.shape[0], n, n_p, n_p))
        for a in range(lam.shape[0]):
            hyl, Hh = _mapped_call(self._maps, self.h_terms, n, [Y, ypv, p, inputs, lam[a]])
            b = -hyl[:, :, 0]
            bV = b[:, n_x:].reshape(n, N, n_x * d)
            if JIT.active() and self.pivot_rows_t is not None:
                mu, nxt = self._adjoint_compiled(RV, Rx, bV)
            else:
                mu = np.empty((n, N, n_x * d))
                nxt = np.zeros((n, n_x))                       # R_x0,k+1^T mu_k+1
                for k in range(N - 1, -1, -1):
                    rhs = bV[:, k].copy()
                    rhs[:, -n_x:] -= nxt
                    mu[:, k] = np.linalg.solve(RV[:, k].transpose(0, 2, 1), rhs[:, :, None])[:, :, 0]
                    nxt = np.einsum("jvx,jv->jx", Rx[:, k], mu[:, k])
            mu0 = b[:, :n_x] - nxt
            He = _mapped_call(self._maps, self.element_hessian, m,
                              [W.reshape(m, -1), XS.reshape(m, -1), _per_element(p, N), U.reshape(m, -1),
                               np.tile(self.steps, n)[:, None], mu.reshape(m, -1), Ze])[0]
            H0 = _mapped_call(self._maps, self.x0_hessian, n, [p, inputs, mu0])[0]
            out[a] = Hh + He.reshape(n, N, n_p, n_p).sum(axis=1) - H0
        return 0.5 * (out + out.transpose(0, 1, 3, 2))

    def _adjoint_compiled(self, RV, Rx, bV) -> tuple:
        r"""(mu (n, N, n_x d), R_x0,0^T mu_0 (n, n_x)) of :meth:`hessian_terms`' backward substitution with every
        element's transposed block solved at once (:func:`models.block_solve.solve_blocks`, compiled with JIT):
        Z_k = R_V,k^{-T} (b_k, P) with P the last n_x rows (the element's end point), then backwards
        mu_k = Z_k^b - Z_k^P nu_k+1 and nu_k = R_x0,k^T mu_k (nu_N = 0), the small recurrence on nu alone."""
        n, N, nd, n_x = Rx.shape
        P = np.zeros((nd, n_x))
        P[-n_x:] = np.eye(n_x)
        rhs = np.concatenate([bV.reshape(n * N, nd, 1), np.broadcast_to(P, (n * N, nd, n_x))], axis=2)
        Z = solve_blocks(RV.reshape(n * N, nd, nd).transpose(0, 2, 1), rhs, self._maps, self.pivot_rows_t)
        Z = Z.reshape(n, N, nd, 1 + n_x)
        RxT = Rx.transpose(0, 1, 3, 2)
        Qb, T = (RxT @ Z[..., :1])[..., 0], RxT @ Z[..., 1:]          # R_x0^T Z^b (n, N, n_x), R_x0^T Z^P
        nus = np.empty((n, N, n_x))
        nxt = np.zeros((n, n_x))
        for k in range(N - 1, -1, -1):
            nus[:, k] = nxt
            nxt = Qb[:, k] - (T[:, k] @ nxt[:, :, None])[:, :, 0]
        return Z[..., 0] - (Z[..., 1:] @ nus[..., None])[..., 0], nxt

    def outputs_and_sensitivities(self, p, inputs, Y, Yp):
        """(h (n_q, n_S), G (n_q, n_S, n_p)) from the states and their derivatives."""
        broker = current_broker()
        if broker is not None:
            return broker.call(self, "outputs_and_sensitivities", p, inputs, Y, Yp)
        return self._outputs_and_sensitivities(p, inputs, Y, Yp)

    def _outputs_and_sensitivities(self, p, inputs, Y, Yp):
        n = inputs.shape[0]
        p = _params(p, n)
        ypv = np.ascontiguousarray(Yp.transpose(0, 2, 1)).reshape(n, -1)     # column-major per experiment
        h, G = _mapped_call(self._maps, self.output_terms, n, [Y, ypv, p, inputs])
        return h[:, :, 0], G

    def outputs(self, p, inputs, Y=None) -> np.ndarray:
        """h (n_q, n_S) at the states Y (solved at p when None)."""
        inputs = np.atleast_2d(np.asarray(inputs, float))
        Y = self.states(p, inputs) if Y is None else Y
        return _mapped_call(self._maps, self.h_only, inputs.shape[0], [Y, _params(p, inputs.shape[0]), inputs])[0][:, :, 0]

    # ------------------------------------------------------------------ merged calls (models.merged_calls)
    def merge_key(self, kind: str, rest: tuple) -> int:
        """Calls of one kind merge when this key agrees too: the number of multiplier sets of a Hessian call."""
        return int(np.shape(rest[-1])[0]) if kind == "hessians" else 0

    def evaluate_one(self, kind: str, p, inputs, rest: tuple):
        """One task's call ``kind`` evaluated alone (a merged evaluation failed: each error to its own task)."""
        n = inputs.shape[0]
        if kind == "states":
            return self._states(_params(p, n), inputs, rest[0])
        if kind == "sweep":
            return self._sweep(_params(p, n), inputs, *rest)
        if kind == "outputs_and_sensitivities":
            return self._outputs_and_sensitivities(p, inputs, *rest)
        return self.hessian_terms(_params(p, n), inputs, *rest).sum(axis=1)

    def evaluate_merged(self, kind: str, calls) -> list:
        """The pending calls of one kind (:class:`models.merged_calls.PendingCall`) evaluated together, every
        experiment at its own call's p; each call's rows back, in order."""
        sizes = [c.inputs.shape[0] for c in calls]
        n_p = self.model.n_p
        P = np.concatenate([np.broadcast_to(_params(c.p, n), (n, n_p)) for c, n in zip(calls, sizes)])
        Q = np.concatenate([c.inputs for c in calls])
        if kind == "states":
            guesses = [c.rest[0] for c in calls]
            guess = None if any(g is None for g in guesses) else np.concatenate(guesses)
            return _split(self._states(P, Q, guess), sizes)
        if kind == "sweep":
            outs = self._sweep(P, Q, np.concatenate([c.rest[0] for c in calls]))
            return list(zip(*(_split(o, sizes) for o in outs)))
        if kind == "outputs_and_sensitivities":
            outs = self._outputs_and_sensitivities(P, Q, *(np.concatenate([c.rest[i] for c in calls])
                                                           for i in range(2)))
            return list(zip(*(_split(o, sizes) for o in outs)))
        Y, yp, RV, Rx = (np.concatenate([c.rest[i] for c in calls]) for i in range(4))
        lam = np.concatenate([c.rest[4] for c in calls], axis=1)
        terms = self.hessian_terms(P, Q, Y, yp, RV, Rx, lam)          # (m, n, n_p, n_p)
        return [t.sum(axis=1) for t in np.split(terms, np.cumsum(sizes)[:-1], axis=1)]



def trajectory_numerics(cm) -> TrajectoryNumerics | None:
    """The :class:`TrajectoryNumerics` of a collocated model (kept in its cache), or None for a model
    that is not a collocated ODE (DAE models and static models)."""
    dyn = getattr(cm, "dynamic", None)
    if dyn is None or dyn.n_z:
        return None
    num = cm.cache.get("trajectory", None)
    if num is None:
        num = cm.cache.put("trajectory", None, TrajectoryNumerics(cm))
    return num


def _split(a: np.ndarray, sizes) -> list:
    return np.split(a, np.cumsum(sizes)[:-1], axis=0)


def interpolate_states(coarse, fine, Y) -> np.ndarray:
    """The trajectories Y (n_q, n_y) of the collocated model ``coarse`` at the collocation points of
    ``fine`` (same dynamic model and horizon, e.g. every element halved), by coarse's collocation
    polynomials (Lagrange on each element's d + 1 points): a start for :meth:`TrajectoryNumerics.states`
    on the fine mesh within the discretisation error."""
    b = np.asarray(coarse.mesh.boundaries)
    d, N = coarse.mesh.degree, coarse.mesh.n_elements
    tf = fine.point_times()
    k = np.clip(np.searchsorted(b, tf, side="left") - 1, 0, N - 1)
    s = (tf - b[k]) / (b[k + 1] - b[k])
    tau = coarse.tau
    basis = np.ones((tf.size, d + 1))
    for j in range(d + 1):
        for r in range(d + 1):
            if r != j:
                basis[:, j] *= (s - tau[r]) / (tau[j] - tau[r])
    L = np.zeros((tf.size, 1 + N * d))
    for j in range(d + 1):
        np.add.at(L, (np.arange(tf.size), k * d + j), basis[:, j])
    n, n_w = Y.shape[0], coarse.dynamic.n_x + coarse.dynamic.n_z
    return np.matmul(L, np.asarray(Y, float).reshape(n, -1, n_w)).reshape(n, -1)


# ---------------------------------------------------------------------------- outputs and sensitivities, mapped
def output_sensitivity_function(cm, derivatives: bool = True) -> ca.Function:
    r"""``(p, q) -> (h (n_S,), G (n_S, n_p), residual (1, N))`` of a collocated ODE model, or without G
    (``derivatives=False``); cached on the model.  The outputs h at the sampling times of the marched
    solution (:func:`march_functions`) and G = dh/dp = h_y dy/dp + h_p by CasADi's derivative of that chain
    (the implicit-function theorem on every element: one small dense solve per element, i.e. the
    block-bidiagonal solve of E_y S = -E_p); each element's relative residual after Newton is returned as
    well, so that a failed element is never silent."""
    if cm.dynamic.n_z:
        raise ValueError("cm: the mapped outputs are for ODE models (no algebraic states)")

    def build():
        p, q = ca.MX.sym("p", cm.n_p), ca.MX.sym("q", cm.n_q_dim)
        y, bad = march_symbolic(cm, p, q)
        h = cm.h_fun(y, p, q)
        if derivatives:
            return ca.Function("outputs", [p, q], [h, ca.jacobian(h, p), bad], ["p", "q"], ["h", "G", "residual"])
        return ca.Function("outputs", [p, q], [h, bad], ["p", "q"], ["h", "residual"])
    return cm.cache.get_or_make("output_sensitivity_function", derivatives, build)


def _mapped(cm, derivatives, n):
    f = output_sensitivity_function(cm, derivatives)
    return cm.cache.get_or_make("output_sensitivity_map", (derivatives, n), lambda: f.map(n), maxsize=8)


def mapped_outputs(cm, p, inputs, tol: float = RESIDUAL_TOL) -> np.ndarray:
    """Outputs (n_q, n_S) of a collocated ODE model at p for every input row (one mapped call; the
    collocation solution of :meth:`models.collocation.CollocatedModel.integrated_outputs`).  When an element's
    plain Newton solve fails in that call, the trajectories are marched with the rescue of :func:`march`
    (:meth:`TrajectoryNumerics.outputs`)."""
    Q = np.atleast_2d(np.asarray(inputs, float))
    p = np.asarray(p, float).ravel()
    h, bad = (np.asarray(a) for a in _mapped(cm, False, Q.shape[0])(p, Q.T))
    if _failed(h, bad, Q.shape[0], tol):
        return trajectory_numerics(cm).outputs(p, Q)
    return h.T


def _failed(h, bad, n: int, tol: float) -> bool:
    """True when an element's relative residual (``bad``, n x N) is above ``tol`` or not finite, or an output
    is not finite: the in-graph march failed somewhere."""
    bad = bad.reshape(n, -1)
    return bool(np.any(~np.isfinite(bad) | (bad > tol)) or not np.all(np.isfinite(h)))


def outputs_and_sensitivities(cm, p, inputs, tol: float = RESIDUAL_TOL):
    """(h (n_q, n_S), G (n_q, n_S, n_p)) of a collocated ODE model at p for every input row, one
    mapped call (:func:`output_sensitivity_function`).  When an element's Newton solve in that call does not
    converge (relative residual above ``tol``), the trajectories are marched with the rescue of :func:`march`
    and y' found by forward substitution (:meth:`TrajectoryNumerics.sensitivities`); raises
    :class:`models.errors.StateSolveError` naming the experiment and element when even that fails."""
    Q = np.atleast_2d(np.asarray(inputs, float))
    p = np.asarray(p, float).ravel()
    h, G, bad = (np.asarray(a) for a in _mapped(cm, True, Q.shape[0])(p, Q.T))
    if _failed(h, bad, Q.shape[0], tol):        # marched with the rescue of march, y' by forward substitution
        num = trajectory_numerics(cm)
        sens = num.sensitivities(p, Q, num.states(p, Q))
        return _finite_sensitivities(cm, p, sens.h, sens.G)
    return _finite_sensitivities(cm, p, h.T, G.reshape(cm.n_S, Q.shape[0], cm.n_p).transpose(1, 0, 2))


def _finite_sensitivities(cm, p, h, G) -> tuple:
    """(h, G) when G is finite, else StateSolveError."""
    if not np.all(np.isfinite(G)):
        raise StateSolveError(f"sensitivities of {cm.dynamic.name!r} at p = {p.tolist()} are not finite")
    return h, G
