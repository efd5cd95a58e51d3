"""The model contract shared by identification and optimal design of experiments.

A model is the state equation

    E(y, p, q) = 0,      E: R^{d_y} x R^{n_p} x R^{d_q} -> R^{d_y}

together with the observation operator

    h(y, p, q) in R^{n_S}   (one named output per candidate sensor),

both held symbolically as CasADi functions so that exact first and second
derivatives are available by algorithmic differentiation.  An explicit model
y = f(p, q) without a state is the special case d_y = 0 (see :meth:`Model.explicit`).
"""
from __future__ import annotations

import threading
from contextlib import contextmanager
from typing import Callable, Iterable, Sequence

import casadi as ca
import numpy as np

from .cache import Cache
from .labels import LabelledModel, ModelError, Parameter, as_column, as_parameters, check_names
from .sensitivity import StateSolve

__all__ = ["Parameter", "LabelledModel", "Model", "ModelError", "pickling_as_recipe", "recipe_reducer"]

#: this thread's reducer of models with an origin while :func:`pickling_as_recipe` is active
#: (:func:`models.shipping.dumps` installs it; that module builds on this one, so it is handed in)
_RECIPE = threading.local()


@contextmanager
def pickling_as_recipe(reduce: Callable):
    """While active (in this thread), a model with an :attr:`Model.origin` pickles as ``reduce(model)``
    (a ``__reduce__`` value: :func:`models.shipping.dumps` sends it as its factory's recipe)."""
    _RECIPE.reduce = reduce
    try:
        yield
    finally:
        _RECIPE.reduce = None


def recipe_reducer() -> Callable | None:
    """The reducer of :func:`pickling_as_recipe` active in this thread, or None."""
    return getattr(_RECIPE, "reduce", None)


class Model(LabelledModel):
    """A parametrised quasi-static model ``E(y, p, q) = 0``, ``z ~ h(y, p, q)``.

    Parameters
    ----------
    params : sequence of str, dict or Parameter
        Unknown parameters p (order defines the vector p).
    inputs : sequence of str
        Names of the input components q (d_q of them).
    sensors : sequence of str
        Names of the candidate sensors, one per component of h.
    n_y : int
        State dimension d_y (0 for an explicit model).
    E : callable (y, p, q) -> vector of length n_y
        State equation residual, written with CasADi operations.
    h : callable (y, p, q) -> vector of length n_S
        Observation operator.
    y_guess : callable (p, q) -> array, optional
        Initial guess of the state for the Newton solve of E; zeros by default.
    symbolic : {"SX", "MX"}
        CasADi symbol type; SX (default) is fastest for scalar-heavy models.
    name : str
        Model name for reports.
    sensor_units, input_units : sequence of str, optional
        Units for reports.

    Attributes
    ----------
    E_fun, h_fun : casadi.Function
        ``(y, p, q) -> E`` and ``(y, p, q) -> h``.
    cache : models.cache.Cache
        Values computed from this model and kept with it (its numerics, compiled NLP
        functions and solvers, start states of repeated fits).  Code that derives further
        objects from a model stores them here under its own namespace, e.g.
        ``model.cache.get_or_make("inverse_functions", None, build)``, instead of setting
        attributes on the model or keeping module-level tables keyed on it.
    """

    def __init__(self, params, inputs, sensors, n_y: int, E: Callable | None, h: Callable,
                 y_guess: Callable | None = None, symbolic: str = "SX", name: str = "model",
                 sensor_units: Sequence[str] | None = None, input_units: Sequence[str] | None = None,
                 description: str = ""):
        self.params = as_parameters(params)
        check_names("params", [p.name for p in self.params])
        self.inputs = check_names("inputs", inputs)
        self.sensors = check_names("sensors", sensors)
        if not self.params:
            raise ModelError("params: a model needs at least one parameter")
        if not self.sensors:
            raise ModelError("sensors: a model needs at least one sensor")
        if isinstance(n_y, bool) or not isinstance(n_y, (int, np.integer)) or n_y < 0:
            raise ModelError(f"n_y must be a non-negative integer, got {n_y!r}")
        if symbolic not in ("SX", "MX"):
            raise ModelError(f"symbolic must be 'SX' or 'MX', got {symbolic!r}")
        self.n_y = int(n_y)
        self.name = str(name)
        self.description = description
        self.symbolic = symbolic
        self.sensor_units = tuple(sensor_units) if sensor_units is not None else ("",) * len(self.sensors)
        self.input_units = tuple(input_units) if input_units is not None else ("",) * len(self.inputs)
        if len(self.sensor_units) != len(self.sensors):
            raise ModelError(f"sensor_units has {len(self.sensor_units)} entries, sensors has {len(self.sensors)}")
        if len(self.input_units) != len(self.inputs):
            raise ModelError(f"input_units has {len(self.input_units)} entries, inputs has {len(self.inputs)}")
        S = ca.SX if symbolic == "SX" else ca.MX
        y = S.sym("y", self.n_y)
        p = S.sym("p", self.n_p)
        q = S.sym("q", self.n_q_dim)
        if self.n_y > 0:
            if E is None:
                raise ModelError(f"E: a model with n_y={self.n_y} states needs a state equation")
            e_expr = as_column(E(y, p, q), "E", S)
            if e_expr.size1() != self.n_y:
                raise ModelError(f"E returns {e_expr.size1()} equations but n_y = {self.n_y}; "
                                 "the state equation must be square")
        else:
            if E is not None:
                raise ModelError("E: an explicit model (n_y = 0) has no state equation; pass E=None")
            e_expr = S(0, 1)
        h_expr = as_column(h(y, p, q), "h", S)
        if h_expr.size1() != self.n_S:
            raise ModelError(f"h returns {h_expr.size1()} outputs but {self.n_S} sensors are named "
                             f"({', '.join(self.sensors)})")
        self.E_fun = ca.Function("E", [y, p, q], [e_expr], ["y", "p", "q"], ["E"])
        self.h_fun = ca.Function("h", [y, p, q], [h_expr], ["y", "p", "q"], ["h"])
        self._y_guess = y_guess
        self.cache = Cache()
        #: where the model came from (a :class:`models.shipping.ModelSource`: factory and variant), or None;
        #: worker processes rebuild the model from it when it cannot be sent by value
        self.origin = None
        self._check_finite_structure()

    # ------------------------------------------------------------------ constructors
    @classmethod
    def explicit(cls, params, inputs, sensors, h: Callable, **kw) -> "Model":
        """An explicit model ``z ~ f(p, q)`` (no state): ``h`` takes ``(p, q)``."""
        return cls(params, inputs, sensors, n_y=0, E=None, h=lambda y, p, q: h(p, q), **kw)

    @classmethod
    def ode(cls, params, states, inputs, sensors, rhs: Callable, x0: Callable, h: Callable, **kw):
        """A dynamic model dx/dt = rhs(x, p, u), x(0) = x0(p, u), outputs h(x, p, u) (with ``algebraic``
        states and ``alg``: an index-1 DAE); returns a :class:`models.dynamic.DynamicModel`, which
        :meth:`~models.dynamic.DynamicModel.collocate` turns into a Model at given sampling times.

        A model without inputs (a batch run: x0 and the rates depend on p only) takes ``inputs=[]`` (or
        None); its experiments are input rows of length 0, ``np.zeros((n_q, 0))``, or ``inputs=None`` in
        :class:`identification.DynamicMeasurements`, and empty ``[[dynamic.experiments]]`` tables in a study."""
        from .dynamic import DynamicModel
        return DynamicModel(params, states, inputs, sensors, rhs, x0, h, **kw)

    # ------------------------------------------------------------------ sizes (n_p, n_S, n_q_dim, param_names: LabelledModel)
    @property
    def lower(self) -> np.ndarray:
        return np.array([p.lower for p in self.params])

    @property
    def upper(self) -> np.ndarray:
        return np.array([p.upper for p in self.params])

    def with_bounds(self, bounds: dict) -> "Model":
        """A copy of this model with other parameter bounds, ``{name: (lower, upper)}``.

        The symbolic functions are shared; only the parameter metadata changes.
        """
        import copy
        unknown = [n for n in bounds if n not in self.param_names]
        if unknown:
            raise ModelError(f"bounds: unknown parameter(s) {', '.join(unknown)}; the model has "
                             f"{', '.join(self.param_names)}")
        new = copy.copy(self)
        new.cache = Cache()
        new.params = tuple(Parameter(p.name, *bounds[p.name], scale=p.scale, unit=p.unit) if p.name in bounds
                           else p for p in self.params)
        return new

    def sensor_index(self, names: Iterable[str]) -> list[int]:
        """Indices of sensors by name; unknown names raise listing the valid ones."""
        idx = []
        for n in names:
            if n not in self.sensors:
                raise ModelError(f"unknown sensor {n!r}; this model has {', '.join(self.sensors)}")
            idx.append(self.sensors.index(n))
        return idx

    @property
    def state_numerics(self):
        """How this model's states and sensitivities are computed (one strategy per model, cached): the generic
        solves of E(y, p, q) = 0 (:class:`models.sensitivity.StateSolve`) here; a collocated ODE marches its
        elements (:class:`models.trajectory.TrajectoryNumerics`), a collocated index-1 DAE too
        (:class:`models.dae_march.DAETrajectoryNumerics`).  Operations: ``solve_states``,
        ``sensitivities``, ``marched_states``, ``integrated_outputs``; capabilities ``reduced_space`` and
        ``merges_fits``."""
        return self.cache.get_or_make("state_numerics", None, lambda: StateSolve(self))

    @property
    def has_y_guess(self) -> bool:
        """True when the model gives its own state guess (else :meth:`y_guess` returns zeros)."""
        return self._y_guess is not None

    def y_guess(self, p, q) -> np.ndarray:
        """Initial guess of the state for input q (zeros unless the model gives one)."""
        if self._y_guess is None:
            return np.zeros(self.n_y)
        g = np.asarray(self._y_guess(np.asarray(p, float), np.asarray(q, float)), float).ravel()
        if g.shape != (self.n_y,):
            raise ModelError(f"y_guess returns {g.size} values, expected n_y = {self.n_y}")
        return g

    def _check_finite_structure(self):
        # The state Jacobian must be structurally square and not structurally singular.
        if self.n_y:
            y, p, q = self.E_fun.sx_in() if self.symbolic == "SX" else self.E_fun.mx_in()
            jac = ca.jacobian(self.E_fun(y, p, q), y)
            sp = jac.sparsity()
            srank = ca.sprank(sp)
            if srank < self.n_y:
                raise ModelError(f"the state Jacobian dE/dy is structurally singular (structural rank "
                                 f"{srank} < n_y = {self.n_y}); some state does not enter E")

    # ------------------------------------------------------------------ numerics
    def solve_state(self, p, q, y0=None, tol: float = 1e-12, max_iter: int = 100) -> np.ndarray:
        """Solve E(y, p, q) = 0 for y by damped Newton (exact Jacobian).

        Raises :class:`models.errors.StateSolveError` when it does not converge.
        """
        from .state import solve_state
        return solve_state(self, p, q, y0=y0, tol=tol, max_iter=max_iter)

    def simulate(self, p, inputs) -> np.ndarray:
        """Model outputs h(y_j(p), p, q_j) for every input row, shape (n_q, n_S)."""
        from .state import simulate
        return simulate(self, p, inputs)

    def __reduce_ex__(self, protocol):
        """Pickled by value; while :func:`models.shipping.dumps` sends models as recipes, a model with an
        :attr:`origin` is its factory and variant plus the metadata changed after building."""
        reduce = recipe_reducer()
        if getattr(self, "origin", None) is not None and reduce is not None:
            return reduce(self)
        return super().__reduce_ex__(protocol)

    def __repr__(self):
        return (f"Model({self.name!r}, params={list(self.param_names)}, inputs={list(self.inputs)}, "
                f"sensors={list(self.sensors)}, n_y={self.n_y})")
