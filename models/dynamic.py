r"""Dynamic models: ODEs and semi-explicit index-1 DAEs with experiment inputs and control profiles.

A dynamic model is

.. math::

    \dot x = f(x, z, p, u(t)),\qquad 0 = g(x, z, p, u(t)),\qquad x(0) = x_0(p, u(0)),
    \qquad \text{outputs } h(x, z, p, u(t)),

with differential states x, algebraic states z (none for an ODE), parameters p and the
experiment inputs u(t): constants (an initial concentration, a load level) followed by controls
given by their values on a time grid (piecewise constant or piecewise linear).  One experiment is
one row q of the input table: the constants, then each control's values at its grid points.

It is not itself a :class:`models.Model`: outputs exist only at sampling times.
:meth:`DynamicModel.collocate` turns it, for given sampling times and a mesh, into an ordinary
static Model whose state is the whole trajectory (Radau IIA collocation,
:mod:`models.collocation`), which estimation, design and detection use unchanged.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import casadi as ca
import numpy as np

from .cache import Cache
from .labels import LabelledModel, ModelError, as_column, as_parameters, check_names

__all__ = ["Control", "DynamicModel", "time_label", "register_collocation", "TIME_RTOL", "TIME_FLOOR",
           "time_tolerance", "same_instant_gaps", "merge_times"]

#: two times a, b of an experiment of length T closer than TIME_RTOL x max(|a|, |b|, TIME_FLOOR T) are one
#: instant (round-off: 0.35 and 0.35000000000000003 from ``np.arange(10) * 0.05``); sampling times, control grid
#: points and mesh boundaries are compared and merged with :func:`time_tolerance`, so round-off never makes an
#: element.  The tolerance is relative to the size of the times compared (round-off is), so log-spaced times
#: (1e-5, 4.9e-5, ... of a 1e5 s horizon: a stiff model's sampling) stay distinct instants.
TIME_RTOL = 1e-9
#: times below TIME_FLOOR x the horizon share the tolerance of TIME_FLOOR x the horizon (a time near 0 computed
#: with numbers of the horizon's size carries their round-off, ~1e-16 x the horizon)
TIME_FLOOR = 1e-6

#: the collocation behind :meth:`DynamicModel.collocate` (:func:`models.collocation.collocate`, which
#: registers itself here when :mod:`models.collocation` is imported; the ``models`` package imports it,
#: so it is registered before any DynamicModel exists).  Held here so that this module does not import
#: the collocation, which builds on it.
_COLLOCATION = []


def register_collocation(collocate: Callable) -> None:
    """Make ``collocate(dynamic, times, mesh=, degree=, max_step=, outputs=)`` the function behind
    :meth:`DynamicModel.collocate` (called by :mod:`models.collocation` when it is imported)."""
    _COLLOCATION[:] = [collocate]


def time_label(t: float) -> str:
    """t to 12 significant digits (``0.5``, ``1``, ``0.125``; 0.6000000000000001 reads ``0.6``)."""
    return f"{float(t):.12g}"


def time_tolerance(horizon, at=None):
    """tol = TIME_RTOL max(|at|, TIME_FLOOR T): the distance (time unit of the model) under which two times of
    size ``at`` of an experiment of length T = ``horizon`` are the same instant.

    ``at`` None: the times at the horizon, TIME_RTOL T (the largest tolerance of the experiment); an array:
    one tolerance per time.  T not positive or not finite: T = 1."""
    h = abs(float(horizon))
    h = h if math.isfinite(h) and h > 0 else 1.0
    if at is None:
        return TIME_RTOL * h
    tol = TIME_RTOL * np.maximum(np.abs(np.asarray(at, float)), TIME_FLOOR * h)
    return float(tol) if tol.ndim == 0 else tol


def same_instant_gaps(t, horizon) -> np.ndarray:
    """Which gaps of the sorted times t (one per neighbouring pair, ``t.size - 1``) are round-off only:
    t[i + 1] - t[i] <= :func:`time_tolerance` at the larger of the two."""
    t = np.asarray(t, float).ravel()
    if t.size < 2:
        return np.zeros(0, bool)
    return np.diff(t) <= time_tolerance(horizon, np.maximum(np.abs(t[:-1]), np.abs(t[1:])))


def merge_times(*groups, tol: float | None = None, horizon: float | None = None) -> np.ndarray:
    """The sorted distinct times of ``groups`` with times of one instant merged into one value.

    One instant: neighbours within :func:`time_tolerance` of the experiment's ``horizon`` (relative to the
    times' size), or, given ``tol`` instead, within that absolute distance.  A group of times within the
    tolerance of their neighbours becomes one value: the one of the earliest group that holds one (pass the
    times that must stay exact first, e.g. 0 and the horizon, then the sampling times, then control grid
    points), within that group the one that reads shortest (0.35 rather than 0.35000000000000003)."""
    if (tol is None) == (horizon is None):
        raise TypeError("merge_times: give one of tol= (an absolute distance) and horizon= (the experiment's length)")
    vals, rank = [], []
    for g, times in enumerate(groups):
        v = np.asarray(times, float).ravel()
        vals.append(v)
        rank.append(np.full(v.size, g))
    v, r = np.concatenate(vals) if vals else np.zeros(0), np.concatenate(rank) if rank else np.zeros(0, int)
    if v.size == 0:
        return v
    order = np.argsort(v, kind="stable")
    v, r = v[order], r[order]
    apart = np.diff(v) > tol if horizon is None else ~same_instant_gaps(v, horizon)
    starts = np.r_[0, np.flatnonzero(apart) + 1]
    out = []
    for a, b in zip(starts, np.r_[starts[1:], v.size]):
        cand = v[a:b][r[a:b] == r[a:b].min()]
        out.append(min(cand, key=lambda x: (len(repr(float(x))), x)))
    return np.asarray(out, float)


@dataclass(frozen=True)
class Control:
    """A time-varying experiment input given by its values at grid points.

    Attributes
    ----------
    name : str
    grid : tuple of float       strictly increasing times, the first 0 (time unit of the model)
    kind : str                  ``"constant"``: u(t) = u_i on [t_i, t_{i+1}) (the last value to the horizon);
                                ``"linear"``: linear between grid points, the last value held after the grid
    unit : str
    """

    name: str
    grid: tuple
    kind: str = "constant"
    unit: str = ""

    def __post_init__(self):
        g = np.asarray(self.grid, float).ravel()
        where = f"controls[{self.name!r}]"
        if g.size == 0:
            raise ModelError(f"{where}: 'grid' is empty; give the times at which the control's values are set")
        if not np.all(np.isfinite(g)):
            raise ModelError(f"{where}: 'grid' holds a non-finite time")
        if g[0] != 0.0:
            raise ModelError(f"{where}: 'grid' must start at time 0, got {g[0]:g}")
        if np.any(np.diff(g) <= 0):
            i = int(np.flatnonzero(np.diff(g) <= 0)[0])
            raise ModelError(f"{where}: 'grid' must be strictly increasing; {g[i + 1]:g} follows {g[i]:g}")
        if self.kind not in ("constant", "linear"):
            raise ModelError(f"{where}: 'kind' must be 'constant' or 'linear', got {self.kind!r}")
        object.__setattr__(self, "grid", tuple(float(v) for v in g))

    @property
    def input_names(self) -> tuple:
        """Names of this control's columns in the input row, ``T@0``, ``T@0.125``, ..."""
        return tuple(f"{self.name}@{time_label(t)}" for t in self.grid)

    def value(self, values, t: float, t_ref: float):
        """u(t) as an expression of the grid values, on the grid interval that holds t_ref.

        t_ref picks the side of a jump (an element's midpoint: the element's own interval);
        t is where the value is taken (a collocation point of that element)."""
        g = np.asarray(self.grid)
        i = max(int(np.searchsorted(g, t_ref, side="right")) - 1, 0)
        if self.kind == "constant" or i == g.size - 1:
            return values[i]
        w = (t - g[i]) / (g[i + 1] - g[i])
        return (1.0 - w) * values[i] + w * values[i + 1]


def _as_controls(controls) -> tuple:
    if controls is None:
        return ()
    if not isinstance(controls, Mapping):
        raise ModelError("controls: expected a dict {name: {'grid': [...], 'kind': 'constant' | 'linear'}}, "
                         f"got {type(controls).__name__}")
    out = []
    for name, spec in controls.items():
        if isinstance(spec, Control):
            out.append(spec)
            continue
        if not isinstance(spec, Mapping) or "grid" not in spec:
            raise ModelError(f"controls[{name!r}]: expected a dict with 'grid' (and 'kind', 'unit'), got {spec!r}")
        unknown = set(spec) - {"grid", "kind", "unit"}
        if unknown:
            raise ModelError(f"controls[{name!r}]: unknown key(s) {', '.join(sorted(unknown))}; "
                             "allowed: grid, kind, unit")
        out.append(Control(str(name), tuple(np.asarray(spec["grid"], float).ravel()), spec.get("kind", "constant"),
                           spec.get("unit", "")))
    return tuple(out)


def _units(arg: str, units, n: int) -> tuple:
    if units is None:
        return ("",) * n
    units = tuple(units)
    if len(units) != n:
        raise ModelError(f"{arg}: {len(units)} units given for {n} names")
    return units


class DynamicModel(LabelledModel):
    r"""A parametrised ODE / index-1 DAE model with experiment inputs (see the module docstring).

    Build it with :meth:`models.Model.ode`; the arguments are documented there.

    Attributes
    ----------
    params : tuple of Parameter
    states, algebraic, constants, sensors : tuple of str
    controls : tuple of Control
    inputs : tuple of str           names of the input row: the constants, then ``name@t`` of every control grid point
    horizon : float or None         end of the experiment (None: the last sampling time)
    rhs_fun, alg_fun, x0_fun, h_fun : casadi.Function
        ``(x, z, p, u) -> dx/dt``, ``(x, z, p, u) -> g``, ``(p, u) -> x(0)``, ``(x, z, p, u) -> h``
        with u = (constants, control values at t).
    cache : models.cache.Cache   collocated models of this model (per times, mesh and outputs)
    """

    is_dynamic = True

    def __init__(self, params, states, inputs, sensors, rhs: Callable, x0: Callable, h: Callable,
                 algebraic: Sequence[str] | None = None, alg: Callable | None = None, controls=None,
                 horizon: float | None = None, name: str = "dynamic model", state_units=None, sensor_units=None,
                 input_units=None, time_unit: str = "", description: str = ""):
        self.params = as_parameters(params)
        check_names("params", [p.name for p in self.params])
        if not self.params:
            raise ModelError("params: a model needs at least one parameter")
        self.states = check_names("states", states)
        if not self.states:
            raise ModelError("states: a dynamic model needs at least one differential state")
        self.algebraic = check_names("algebraic", algebraic or ())
        if self.algebraic and alg is None:
            raise ModelError("alg: algebraic states are named but no algebraic equation alg(x, z, p, u) is given")
        if alg is not None and not self.algebraic:
            raise ModelError("algebraic: alg(x, z, p, u) is given but no algebraic states are named")
        self.constants = check_names("inputs", () if inputs is None else inputs)    # None, []: no inputs
        self.controls = _as_controls(controls)
        check_names("inputs and controls", list(self.constants) + [c.name for c in self.controls])
        self.sensors = check_names("sensors", sensors)
        if not self.sensors:
            raise ModelError("sensors: a model needs at least one sensor")
        self.inputs = self.constants + tuple(n for c in self.controls for n in c.input_names)
        if horizon is not None:
            if not (isinstance(horizon, (int, float, np.floating, np.integer)) and math.isfinite(horizon)
                    and horizon > 0):
                raise ModelError(f"horizon: expected a positive finite time, got {horizon!r}")
            late = [c.name for c in self.controls if c.grid[-1] > horizon + time_tolerance(horizon)]
            if late:
                raise ModelError(f"controls: the grid of {', '.join(late)} extends beyond the horizon {horizon:g}")
            horizon = float(horizon)
        self.horizon = horizon
        self.name, self.description, self.time_unit = str(name), description, time_unit
        self.state_units = _units("state_units", state_units, self.n_x)
        self.sensor_units = _units("sensor_units", sensor_units, self.n_S)
        n_u = len(self.constants) + len(self.controls)
        self.input_units = _units("input_units", input_units, n_u)
        self._build(rhs, x0, h, alg)
        self.cache = Cache()

    def _build(self, rhs, x0, h, alg):
        x, z = ca.SX.sym("x", self.n_x), ca.SX.sym("z", self.n_z)
        p, u = ca.SX.sym("p", self.n_p), ca.SX.sym("u", self.n_u)
        dae = self.n_z > 0

        def call(fn, arg, *args):
            try:
                return fn(*args)
            except ModelError:
                raise
            except Exception as exc:    # a user callable failing on symbols: name the argument
                raise ModelError(f"{arg}: calling it with CasADi symbols failed ({type(exc).__name__}: {exc}); "
                                 f"expected {arg}{'(x, z, p, u)' if dae and arg != 'x0' else '(x, p, u)'}") from exc

        f = as_column(call(rhs, "rhs", *((x, z, p, u) if dae else (x, p, u))), "rhs", ca.SX)
        if f.size1() != self.n_x:
            raise ModelError(f"rhs returns {f.size1()} derivatives but {self.n_x} states are named "
                             f"({', '.join(self.states)})")
        x_init = as_column(call(x0, "x0", p, u), "x0", ca.SX)
        if x_init.size1() != self.n_x:
            raise ModelError(f"x0 returns {x_init.size1()} initial values but {self.n_x} states are named "
                             f"({', '.join(self.states)})")
        if ca.depends_on(x_init, ca.vertcat(x, z)):
            raise ModelError("x0 must depend on (p, u) only")
        g = as_column(call(alg, "alg", x, z, p, u), "alg", ca.SX) if dae else ca.SX(0, 1)
        if g.size1() != self.n_z:
            raise ModelError(f"alg returns {g.size1()} equations but {self.n_z} algebraic states are named")
        if dae and ca.sprank(ca.jacobian(g, z).sparsity()) < self.n_z:
            raise ModelError("alg: dg/dz is structurally singular; the DAE is not of index 1 in the named "
                             "algebraic states")
        y = as_column(call(h, "h", *((x, z, p, u) if dae else (x, p, u))), "h", ca.SX)
        if y.size1() != self.n_S:
            raise ModelError(f"h returns {y.size1()} outputs but {self.n_S} sensors are named "
                             f"({', '.join(self.sensors)})")
        self.rhs_fun = ca.Function("rhs", [x, z, p, u], [f], ["x", "z", "p", "u"], ["xdot"])
        self.alg_fun = ca.Function("alg", [x, z, p, u], [g], ["x", "z", "p", "u"], ["g"])
        self.x0_fun = ca.Function("x0", [p, u], [x_init], ["p", "u"], ["x0"])
        self.h_fun = ca.Function("h", [x, z, p, u], [y], ["x", "z", "p", "u"], ["h"])

    # ------------------------------------------------------------------ sizes
    @property
    def n_x(self) -> int:
        return len(self.states)

    @property
    def n_z(self) -> int:
        return len(self.algebraic)

    @property
    def n_u(self) -> int:
        """Length of u(t): the constants and one value per control."""
        return len(self.constants) + len(self.controls)

    def u_at(self, q, t: float, t_ref: float):
        """u(t) = (constants, control values at t) from the input row q (an expression or array);
        t_ref selects the side of a control jump (see :meth:`Control.value`)."""
        return self.u_from(self.input_entries(q), t, t_ref, isinstance(q, (ca.SX, ca.MX)))

    def input_entries(self, q) -> Sequence:
        """The entries q_0, q_1, ... of the input row q: one split of a dense SX or MX column (the same
        entries as q[i], without one Python call per entry and time), else q itself."""
        if isinstance(q, (ca.SX, ca.MX)) and q.is_dense() and q.is_column():
            return ca.vertsplit(q)
        return q

    def u_from(self, entries, t: float, t_ref: float, symbolic: bool):
        """u(t) of :meth:`u_at` from the entries of the input row (:meth:`input_entries`); an
        expression when ``symbolic``, else an array."""
        parts = self.u_parts(entries, t, t_ref)
        return ca.vertcat(*parts) if symbolic else np.array(parts, float)

    def u_parts(self, entries, t: float, t_ref: float) -> list:
        """The n_u entries of u(t) (constants, then each control's value at t) from the entries of the
        input row, as a list (:meth:`u_from` stacks them)."""
        n_c = len(self.constants)
        parts = [entries[i] for i in range(n_c)]
        k = n_c
        for c in self.controls:
            vals = [entries[k + i] for i in range(len(c.grid))]
            parts.append(c.value(vals, t, t_ref))
            k += len(c.grid)
        return parts

    def check_times(self, times, arg: str = "times") -> np.ndarray:
        """Validated sampling times: finite, >= 0, strictly increasing, within the horizon."""
        t = np.asarray(times, float).ravel()
        if t.size == 0:
            raise ModelError(f"{arg}: no sampling time given")
        if not np.all(np.isfinite(t)):
            raise ModelError(f"{arg}: sampling times must be finite")
        if t[0] < 0:
            raise ModelError(f"{arg}: sampling times must be >= 0, got {t[0]:g}")
        if np.any(np.diff(t) <= 0):
            i = int(np.flatnonzero(np.diff(t) <= 0)[0])
            raise ModelError(f"{arg}: sampling times must be strictly increasing; {t[i + 1]:g} follows {t[i]:g}")
        horizon = self.horizon if self.horizon is not None else t[-1]
        tol = time_tolerance(horizon)
        twins = same_instant_gaps(t, horizon)
        if np.any(twins):
            i = int(np.flatnonzero(twins)[0])
            raise ModelError(f"{arg}: sampling times {float(t[i])!r} and {float(t[i + 1])!r} differ by round-off only "
                             f"(less than {TIME_RTOL:g} of their size); give that time once")
        if self.horizon is not None and t[-1] > self.horizon + tol:
            raise ModelError(f"{arg}: sampling time {t[-1]:g} lies beyond the horizon {self.horizon:g}")
        return t

    def collocate(self, times, mesh=None, degree: int = 3, max_step: float | None = None, outputs=None):
        """The static :class:`models.Model` of this model sampled at ``times`` (Radau IIA collocation).

        See :func:`models.collocation.collocate`."""
        if not _COLLOCATION:
            raise RuntimeError("DynamicModel.collocate: models.collocation is not imported; import models "
                               "(the package imports it) or models.collocation first")
        return _COLLOCATION[0](self, times, mesh=mesh, degree=degree, max_step=max_step, outputs=outputs)

    def __repr__(self):
        return (f"DynamicModel({self.name!r}, params={list(self.param_names)}, states={list(self.states)}, "
                f"algebraic={list(self.algebraic)}, inputs={list(self.inputs)}, sensors={list(self.sensors)})")
