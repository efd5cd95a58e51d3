r"""Radau IIA direct collocation: a dynamic model sampled at given times becomes a static Model.

On a mesh 0 = b_0 < b_1 < ... < b_N = T (element k has length h_k = b_{k+1} - b_k) the
trajectory of one experiment is represented by the states at the Radau IIA points
t_kr = b_k + tau_r h_k (tau_0 = 0, tau_1..tau_d the Radau points, tau_d = 1), and the state
equation E(y, p, q) = 0 of the resulting :class:`models.Model` stacks

.. math::

    x_{00} - x_0(p, u(0)) = 0, \qquad
    \sum_{j=0}^{d} C_{jr}\, x_{kj} - h_k f(x_{kr}, z_{kr}, p, u(t_{kr})) = 0, \qquad
    g(x_{kr}, z_{kr}, p, u(t_{kr})) = 0 \quad (r = 1..d),

with x_{k0} the end point x_{k-1,d} of the previous element (continuity) and C_{jr} the
derivative of the j-th Lagrange polynomial on tau at tau_r (the coefficients of CasADi's
``direct_collocation.py`` example).  Radau IIA of degree d is of order 2d - 1 at the element
boundaries, which hold every sampling time and every control grid point, so that a
piecewise-constant control jumps only between elements.  The outputs are the sensors at the
sampling times, named ``sensor@time`` (``cA@0.5``); at a time where a piecewise-constant control
jumps, the outputs take the value before the jump (that of the element ending there) and the
initial state x(0) the value from time 0 on.  The state guess integrates the model
element by element (Newton on each element's collocation equations), so the state solve of the
whole trajectory starts at its solution.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from .contract import Model, ModelError
from .dynamic import DynamicModel, merge_times, register_collocation, same_instant_gaps, time_label, time_tolerance
from .dae_march import dae_numerics
from .element_march import march, march_functions
from .trajectory import trajectory_numerics

__all__ = ["Mesh", "CollocatedModel", "collocate", "radau_coefficients", "pair_name", "DEFAULT_ELEMENTS"]

#: elements of the default mesh over the horizon (before the sampling times and control grid are added)
DEFAULT_ELEMENTS = 10
#: collocated models kept per dynamic model (with their compiled numerics: repeated fits reuse them)
COLLOCATED_CACHE_SIZE = 8


def pair_name(sensor: str, t: float) -> str:
    """The name of the output of ``sensor`` at time t in a collocated model (``cA@0.5``)."""
    return f"{sensor}@{time_label(t)}"


def radau_coefficients(degree: int):
    """(tau, C): tau = [0, Radau IIA points] (length d + 1) and C[j, r] = L_j'(tau_r) of the
    Lagrange basis on tau (derivative per unit of normalised time)."""
    tau = np.r_[0.0, ca.collocation_points(int(degree), "radau")]
    d = tau.size - 1
    C = np.zeros((d + 1, d + 1))
    for j in range(d + 1):
        poly = np.poly1d([1.0])
        for r in range(d + 1):
            if r != j:
                poly *= np.poly1d([1.0, -tau[r]]) / (tau[j] - tau[r])
        C[j] = np.polyder(poly)(tau)
    return tau, C


@dataclass(frozen=True)
class Mesh:
    """Element boundaries 0 = b_0 < ... < b_N = horizon and the Radau IIA degree d (>= 1)."""

    boundaries: tuple
    degree: int = 3

    def __post_init__(self):
        b = np.asarray(self.boundaries, float).ravel()
        if b.size < 2 or b[0] != 0.0 or np.any(np.diff(b) <= 0) or not np.all(np.isfinite(b)):
            raise ModelError("mesh: boundaries must start at 0 and increase strictly (at least one element)")
        short = np.flatnonzero(same_instant_gaps(b, b[-1]))
        if short.size:
            i = int(short[0])
            raise ModelError(f"mesh: the boundaries {float(b[i])!r} and {float(b[i + 1])!r} differ by round-off only "
                             f"(an element shorter than {time_tolerance(b[-1], b[i + 1]):.3g}); give that boundary "
                             "once")
        if isinstance(self.degree, bool) or not isinstance(self.degree, (int, np.integer)) or not 1 <= self.degree <= 9:
            raise ModelError(f"degree: expected an integer in 1..9, got {self.degree!r}")
        object.__setattr__(self, "boundaries", tuple(float(v) for v in b))

    @classmethod
    def covering(cls, breakpoints, horizon: float, max_step: float, degree: int = 3) -> "Mesh":
        """The mesh whose boundaries are the breakpoints in [0, horizon] with every gap split into
        equal elements no longer than ``max_step``."""
        if not (math.isfinite(max_step) and max_step > 0):
            raise ModelError(f"max_step: expected a positive time, got {max_step!r}")
        pts = merge_times([0.0, horizon], breakpoints, horizon=horizon)   # round-off makes no element
        pts = pts[(pts >= 0) & (pts <= horizon)]
        out = [0.0]
        for a, b in zip(pts[:-1], pts[1:]):
            n = max(1, int(math.ceil((b - a) / max_step - 1e-9)))
            out.extend(a + (b - a) * np.arange(1, n) / n)
            out.append(b)                   # exactly the breakpoint (a + (b - a) may differ from b)
        return cls(tuple(out), degree)

    @property
    def n_elements(self) -> int:
        return len(self.boundaries) - 1

    @property
    def max_step(self) -> float:
        return float(np.max(np.diff(self.boundaries)))

    def refined(self, factor: int) -> "Mesh":
        """Every element split into ``factor`` equal parts; an element too short for that (parts of at most twice the
        same-instant tolerance :func:`models.dynamic.time_tolerance` at its end, which the mesh would refuse as one
        instant) into the most equal parts longer than that, itself if none (e.g. two sampling times 5e-10 h
        apart)."""
        b = np.asarray(self.boundaries)
        L = np.diff(b)
        fine = b[:-1, None] + L[:, None] * np.arange(factor)[None, :] / factor
        n = np.clip(np.ceil(L / (2.0 * time_tolerance(b[-1], b[1:]))) - 1, 1, factor).astype(int)
        if np.all(n == factor):
            return Mesh(tuple(np.r_[fine.ravel(), b[-1]]), self.degree)
        parts = [fine[i] if n[i] == factor else b[i] + L[i] * np.arange(n[i]) / n[i] for i in range(L.size)]
        return Mesh(tuple(np.r_[np.concatenate(parts), b[-1]]), self.degree)


class CollocatedModel(Model):
    """The static model of a :class:`models.dynamic.DynamicModel` at given sampling times (see the
    module docstring).  Its inputs are the dynamic model's input rows, its sensors ``sensor@time``
    (by default time-major: all sensors at the first time, then the next time; ``outputs`` picks
    (sensor, time) pairs), its state the trajectory.

    Attributes
    ----------
    dynamic : DynamicModel
    times : ndarray           sampling times
    mesh : Mesh
    """

    def __init__(self, dynamic: DynamicModel, times, mesh: Mesh, outputs=None):
        self.dynamic, self.times, self.mesh = dynamic, np.asarray(times, float), mesh
        if outputs is None:
            outputs = [(s, float(t)) for t in self.times for s in dynamic.sensors]
        self.outputs = tuple((str(s), float(t)) for s, t in outputs)
        unknown = sorted({s for s, _ in self.outputs} - set(dynamic.sensors))
        stray = sorted({t for _, t in self.outputs} - {float(t) for t in self.times})
        if unknown or stray or not self.outputs:
            raise ModelError(f"outputs: every (sensor, time) pair must name a sensor of {dynamic.name!r} and a "
                             f"sampling time; unknown sensors {unknown}, times {stray}")
        units = dict(zip(dynamic.sensors, dynamic.sensor_units))
        labels = [time_label(t) for t in self.times]
        if len(set(labels)) < len(labels):
            i = next(i for i in range(1, len(labels)) if labels[i] == labels[i - 1])
            raise ModelError(f"times: {self.times[i - 1]!r} and {self.times[i]!r} agree to 12 digits (both read "
                             f"{labels[i]}); merge them or give times that differ")
        self.tau, self.C = radau_coefficients(mesh.degree)
        b = np.asarray(mesh.boundaries)
        self._end_of = {float(t): int(np.argmin(np.abs(b - t))) - 1 for t in self.times}
        off = [float(t) for t in self.times if np.min(np.abs(b - t)) > time_tolerance(b[-1], t)]
        if off:
            raise ModelError(f"mesh: sampling time(s) {', '.join(f'{v:g}' for v in off)} are not element boundaries")
        n_w = dynamic.n_x + dynamic.n_z
        n_y = n_w * (1 + mesh.n_elements * mesh.degree)
        c_units = [dynamic.input_units[len(dynamic.constants) + i] for i, c in enumerate(dynamic.controls)
                   for _ in c.grid]
        super().__init__(dynamic.params, dynamic.inputs, [pair_name(s, t) for s, t in self.outputs],
                         n_y, E=self._equations, h=self._outputs, y_guess=self._integrate, symbolic="SX",
                         name=dynamic.name, sensor_units=[units[s] for s, _ in self.outputs],
                         input_units=list(dynamic.input_units[:len(dynamic.constants)]) + c_units,
                         description=dynamic.description)
        self._element_solver = None

    # ------------------------------------------------------------------ layout
    def _point(self, y, k: int, r: int):
        """(x, z) of element k at point r (k = -1, r = d: the initial point; r = 0: the element's start)."""
        dyn, d = self.dynamic, self.mesh.degree
        if r == 0:
            k, r = k - 1, d
        i = 0 if k < 0 else (1 + k * d + r - 1)
        n_w = dyn.n_x + dyn.n_z
        w = y[i * n_w:(i + 1) * n_w]
        return w[:dyn.n_x], w[dyn.n_x:]

    def point_times(self) -> np.ndarray:
        """Times of the stored trajectory points: 0, then t_kr for every element k and r = 1..d."""
        b = np.asarray(self.mesh.boundaries)
        return np.r_[0.0, (b[:-1, None] + np.diff(b)[:, None] * self.tau[None, 1:]).ravel()]

    def trajectory(self, y) -> tuple:
        """(t, X, Z) of one experiment's state y: the point times and the differential and algebraic
        states there, shapes (n_t,), (n_t, n_x), (n_t, n_z)."""
        dyn = self.dynamic
        W = np.asarray(y, float).reshape(-1, dyn.n_x + dyn.n_z)
        return self.point_times(), W[:, :dyn.n_x], W[:, dyn.n_x:]

    # ------------------------------------------------------------------ E and h
    def _equations(self, y, p, q):
        dyn, d, b = self.dynamic, self.mesh.degree, np.asarray(self.mesh.boundaries)
        N, n_x = self.mesh.n_elements, dyn.n_x
        W = ca.reshape(y, n_x + dyn.n_z, 1 + N * d)            # one column per point, the initial point first
        X, Z = W[:n_x, :], W[n_x:, :]
        u0 = self.initial_input(q)
        C = ca.DM(self.C[:, 1:])
        # element k holds the columns k d .. k d + d (its start is the previous element's end)
        XP = ca.horzcat(*[ca.mtimes(X[:, k * d:k * d + d + 1], C) for k in range(N)])
        hk = np.repeat(np.diff(b), d)
        U = ca.horzcat(*self.point_inputs(q))
        n = N * d
        F = dyn.rhs_fun.map(n)(X[:, 1:], Z[:, 1:], ca.repmat(p, 1, n), U)
        G = dyn.alg_fun.map(n)(X[:, 1:], Z[:, 1:], ca.repmat(p, 1, n), U)
        R = XP - F * ca.repmat(ca.DM(hk).T, n_x, 1)
        return ca.vertcat(X[:, 0] - dyn.x0_fun(p, u0), dyn.alg_fun(X[:, 0], Z[:, 0], p, u0), ca.vec(ca.vertcat(R, G)))

    def _outputs(self, y, p, q):
        dyn, d, b = self.dynamic, self.mesh.degree, np.asarray(self.mesh.boundaries)
        at = {}
        for t in self.times:
            k = self._end_of[float(t)]
            tm = 0.5 * (b[1] if k < 0 else b[k] + b[k + 1])
            x, z = self._point(y, k, d)
            at[float(t)] = dyn.h_fun(x, z, p, dyn.u_at(q, float(t), tm))
        return ca.vertcat(*[at[t][self.dynamic.sensors.index(s)] for s, t in self.outputs])

    def integrated_outputs(self, p, inputs) -> np.ndarray:
        """Outputs (n_q, n_S) of the collocation solution obtained element by element (Newton on each
        element, no solve of the whole trajectory: cheaper than :meth:`simulate` for a model used once)."""
        p = np.asarray(p, float).ravel()
        inputs = np.atleast_2d(np.asarray(inputs, float))
        return self.state_numerics.integrated_outputs(p, inputs)

    @property
    def state_numerics(self):
        """The element marcher of an ODE (:class:`models.trajectory.TrajectoryNumerics`: all experiments at once,
        element by element) or of an index-1 DAE (:func:`models.dae_march.dae_numerics`: the generic solves,
        with the reason, for a DAE whose dg/dz is structurally singular)."""
        return dae_numerics(self) if self.dynamic.n_z else trajectory_numerics(self)

    # ------------------------------------------------------------------ state guess
    def element_symbols(self) -> tuple:
        """SX symbols (V, xs, p, U, h) of one element's equations: the unknowns V = (x_r, z_r), r = 1..d,
        the element's start x_start, the parameters, u at the d points and the element's length."""
        dyn, d = self.dynamic, self.mesh.degree
        return (ca.SX.sym("V", (dyn.n_x + dyn.n_z) * d), ca.SX.sym("xs", dyn.n_x), ca.SX.sym("p", dyn.n_p),
                ca.SX.sym("U", dyn.n_u * d), ca.SX.sym("h"))

    def element_residual(self, V, xs, p, U, hk):
        r"""The collocation equations of one element (module docstring), r = 1..d:
        :math:`\sum_j C_{jr} x_j - h f(x_r, z_r, p, u_r)` and :math:`g(x_r, z_r, p, u_r)`, stacked point
        after point, as an expression of (V, xs, p, U, h) (see :meth:`element_symbols`)."""
        dyn, d = self.dynamic, self.mesh.degree
        n_w = dyn.n_x + dyn.n_z
        X = [xs] + [V[(r - 1) * n_w:(r - 1) * n_w + dyn.n_x] for r in range(1, d + 1)]
        res = []
        for r in range(1, d + 1):
            z, u = V[(r - 1) * n_w + dyn.n_x:r * n_w], U[(r - 1) * dyn.n_u:r * dyn.n_u]
            res += [sum(self.C[j, r] * X[j] for j in range(d + 1)) - hk * dyn.rhs_fun(X[r], z, p, u),
                    dyn.alg_fun(X[r], z, p, u)]
        return ca.vertcat(*res)

    def element_functions(self):
        """(rootfinder, residual) of one element: unknowns V = (x_r, z_r), r = 1..d; parameters
        (x_start, p, U = u at the d points, h); Newton to max |R| <= 1e-13 in at most 60 iterations."""
        if self._element_solver is None:
            V, xs, p, U, hk = self.element_symbols()
            par = ca.vertcat(xs, p, U, hk)
            R = ca.Function("R", [V, par], [self.element_residual(V, xs, p, U, hk)])
            rf = ca.rootfinder("element", "newton", R, {"error_on_fail": False, "abstol": 1e-13,
                                                         "max_iter": 60})
            self._element_solver = (rf, R)
        return self._element_solver

    def _initial_algebraic(self, x0, p, u0):
        dyn = self.dynamic
        if not dyn.n_z:
            return np.zeros(0)
        z = ca.SX.sym("z", dyn.n_z)
        rf = ca.rootfinder("z0", "newton", ca.Function("g", [z, ca.SX.sym("c", 0)],
                                                       [dyn.alg_fun(x0, z, p, u0)]), {"error_on_fail": False})
        return np.asarray(rf(np.ones(dyn.n_z), ca.DM(0, 1))).ravel()

    def march_functions(self):
        """(march, residuals, Umap) of the element marcher (:func:`models.element_march.march_functions`)."""
        return march_functions(self)

    # ------------------------------------------------------------------ inputs at the points
    def initial_input(self, q):
        """u(0) from the input row q (an expression or array): the value from time 0 on."""
        return self.dynamic.u_at(q, 0.0, 0.5 * np.asarray(self.mesh.boundaries)[1])

    def point_inputs(self, q) -> list:
        """u(t_kr) from the input row q at every collocation point (element k, r = 1..d), element after
        element; a control's jump at an element boundary takes the element's own side."""
        dyn, d, N, b = self.dynamic, self.mesh.degree, self.mesh.n_elements, np.asarray(self.mesh.boundaries)
        entries, symbolic = dyn.input_entries(q), isinstance(q, (ca.SX, ca.MX))      # split q once, not per point
        at = [(b[k] + self.tau[r] * (b[k + 1] - b[k]), 0.5 * (b[k] + b[k + 1]))
              for k in range(N) for r in range(1, d + 1)]
        if symbolic and dyn.n_u:     # one stack of every point's entries, split into the points' columns
            flat = [e for t, t_ref in at for e in dyn.u_parts(entries, t, t_ref)]
            return ca.horzsplit(ca.reshape(ca.vertcat(*flat), dyn.n_u, len(at)))
        return [dyn.u_from(entries, t, t_ref, symbolic) for t, t_ref in at]

    def point_input_map(self) -> np.ndarray:
        """Umap (N d n_u, d_q): the inputs at every point, stacked, are Umap q (linear in the input row)."""
        q = ca.SX.sym("q", self.dynamic.n_q_dim)
        U = ca.vertcat(*self.point_inputs(q))
        return np.asarray(ca.evalf(ca.jacobian(U, q))) if self.dynamic.n_q_dim else np.zeros((U.size1(), 0))

    def _integrate(self, p, q) -> np.ndarray:
        """The collocation solution at (p, q), element by element (:func:`models.element_march.march`)."""
        dyn, N = self.dynamic, self.mesh.n_elements
        p, q = np.asarray(p, float).ravel(), np.asarray(q, float).ravel()
        Umap = march_functions(self)[2]
        u0 = self.initial_input(q)
        x0 = np.asarray(dyn.x0_fun(p, u0)).ravel()
        w0 = np.r_[x0, self._initial_algebraic(x0, p, u0)]
        V = march(self, w0[None, :], p, (Umap @ q).reshape(N, -1)[None], q[None, :])[0]
        return np.r_[w0, V.ravel()]


def collocate(dynamic: DynamicModel, times, mesh: Mesh | None = None, degree: int = 3,
              max_step: float | None = None, outputs=None) -> CollocatedModel:
    """The static model of ``dynamic`` sampled at ``times`` by Radau IIA collocation.

    Parameters
    ----------
    dynamic : DynamicModel
    times : array_like          sampling times (strictly increasing, >= 0, within the horizon)
    mesh : Mesh, optional       element boundaries; must contain every sampling time and control grid
                                point (default: :meth:`Mesh.covering` with ``max_step``)
    degree : int                Radau IIA points per element (ignored when a mesh is given)
    max_step : float, optional  longest element of the default mesh (default horizon / 10)
    outputs : sequence of (sensor, time), optional
                                the model's outputs (default every sensor at every time, time-major)

    Raises
    ------
    ModelError
        Bad times or a mesh that misses a sampling time or control grid point (names the argument).
    """
    if not isinstance(dynamic, DynamicModel):
        raise ModelError(f"dynamic: expected a DynamicModel, got {type(dynamic).__name__}")
    call = _call_key(times, mesh, degree, max_step, outputs)
    got = None if call is None else dynamic.cache.get("collocate_call", call)
    if got is not None:            # the same arguments checked before (every refit): the same collocated model
        return got
    t = dynamic.check_times(times)
    horizon = dynamic.horizon if dynamic.horizon is not None else float(t[-1])
    if horizon <= 0:
        raise ModelError("times: with the only sampling time at 0 the experiment has no duration; "
                         "give later sampling times or the model's horizon")
    tol = time_tolerance(horizon)
    grid = [g for c in dynamic.controls for g in c.grid if g <= horizon + tol]
    if mesh is None:       # the sampling times stay exact; a grid point within round-off of one merges into it
        mesh = Mesh.covering(merge_times(t, grid, horizon=horizon), horizon, max_step or horizon / DEFAULT_ELEMENTS,
                             degree)
    elif not isinstance(mesh, Mesh):
        raise ModelError(f"mesh: expected a models.collocation.Mesh, got {type(mesh).__name__}")
    b = np.asarray(mesh.boundaries)
    missing = [v for v in merge_times(t, grid, horizon=horizon) if np.min(np.abs(b - v)) > time_tolerance(horizon, v)]
    if missing or abs(b[-1] - horizon) > tol:
        raise ModelError(f"mesh: its boundaries must contain every sampling time and control grid point and end "
                         f"at the horizon {horizon:g}; missing {', '.join(f'{v:g}' for v in missing) or 'the end'}")
    key = (t.tobytes(), mesh, None if outputs is None else tuple((str(k), float(v)) for k, v in outputs))
    cm = dynamic.cache.get_or_make("collocated", key, lambda: CollocatedModel(dynamic, t, mesh, outputs),
                                   maxsize=COLLOCATED_CACHE_SIZE)
    if call is not None:
        dynamic.cache.put("collocate_call", call, cm, maxsize=COLLOCATED_CACHE_SIZE)
    return cm


def _call_key(times, mesh, degree, max_step, outputs):
    """The arguments of :func:`collocate` as a cache key (times' float64 bytes, the mesh, degree, max_step,
    outputs), or None when they do not make one (the checks then run and name the bad argument): a call with
    arguments that passed the checks before returns the same collocated model without checking them again
    (the checks and the default mesh depend on nothing else; about 1 ms a call, two calls a refit)."""
    try:
        key = (np.asarray(times, float).tobytes(), np.shape(times), mesh, int(degree),
               None if max_step is None else float(max_step),
               None if outputs is None else tuple((str(k), float(v)) for k, v in outputs))
        hash(key)
    except (TypeError, ValueError):
        return None
    return key


register_collocation(collocate)
