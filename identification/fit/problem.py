r"""The one estimation problem every verb takes: a model, its data and, for a dynamic model, its discretisation.

Every verb solves, at some p, the static problem

.. math::

    \min_p \tfrac12 \sum_{ijk} w_k \bigl((z_{ijk} - h_k(y_j, p, q_j)) / \sigma_k\bigr)^2
    \quad \text{s.t.} \quad E(y_j, p, q_j) = 0 \qquad \text{(paper eq. 3)}.

A static model states E and h directly.  A dynamic model dx/dt = f(x, z, p, u), 0 = g(x, z, p, u)
becomes one by Radau IIA collocation on a mesh (:mod:`models.collocation`) whose discretisation
error is controlled at p (:mod:`identification.fit.dynamic_fit`).  :class:`Problem` holds the
model and its data and asks its :class:`ProblemStrategy` for that static problem; the verbs
(:func:`fit_model`, :func:`information_contributions`, and through them identify, detect,
validate, the designs) are written once against it.  The only difference between the kinds is
in the strategy: :class:`StaticStrategy` (the identity) and :class:`CollocatedStrategy` (the
discretisation and its error control).  A third kind of model (e.g. a PDE discretised by the
user) adds a strategy and its entry in :func:`strategy_for`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from models.contract import Model
from models.dynamic import DynamicModel
from identification.fit.dynamic_data import DynamicMeasurements
from identification.fit.dynamic_fit import (DiscretisationSettings, collocated_problem, dynamic_information,
                                            identify_dynamic)
from identification.fit.estimator import IdentifySettings, fit_static, static_information
from identification.fit.measurements import Measurements
from identification.fit.multistart import check_starts, fit_starts
from identification.fit.record import FitRecord

__all__ = ["Problem", "ColumnLayout", "ProblemStrategy", "StaticStrategy", "CollocatedStrategy", "strategy_for", "fit_model",
           "information_contributions"]


@dataclass(frozen=True, eq=False)
class ColumnLayout:
    """What the columns of the static problem's data are: column c holds instrument ``names[instrument[c]]`` at
    the coordinates ``coords[c]`` (e.g. its sampling time, in the model's time unit).

    A static model: one column per sensor, no coordinates.  A dynamic model: one column per (instrument,
    sampling time) pair, the coordinate the time ``t``.  The verbs that treat an instrument's readings
    together (a model error over time, an instrument's pure error) ask for it instead of the kind of model.

    Attributes
    ----------
    instrument : ndarray (n_cols,) of int   the instrument of every column
    names : tuple of str                    the instruments (n_inst)
    coords : ndarray (n_cols, d_c)          the coordinates of every column (d_c = 0 for a static model)
    coord_names : tuple of str              their names (d_c)
    """

    instrument: np.ndarray
    names: tuple
    coords: np.ndarray
    coord_names: tuple = ()

    def column_weights(self, w) -> np.ndarray:
        """The weight of every column (n_cols,) from one per instrument ``w`` (n_inst,)."""
        return np.asarray(w, float)[self.instrument]

    @property
    def grid(self) -> tuple:
        """The sorted distinct values of every coordinate (d_c arrays): the axes of :meth:`arrange`."""
        return tuple(np.unique(self.coords[:, c]) for c in range(self.coords.shape[1]))

    def arrange(self, a) -> np.ndarray:
        """Values a (n, n_cols) per column as (n, len(grid[0]), ..., n_inst): NaN where no column holds the
        instrument at those coordinates.  A static model (no coordinates, one column per instrument in
        order): ``a`` itself."""
        a = np.asarray(a)
        if not self.coord_names and np.array_equal(self.instrument, np.arange(len(self.names))):
            return a
        pos = tuple(np.searchsorted(g, self.coords[:, c]) for c, g in enumerate(self.grid))
        out = np.full((a.shape[0],) + tuple(len(g) for g in self.grid) + (len(self.names),), np.nan)
        out[(slice(None),) + pos + (self.instrument,)] = a
        return out


class ProblemStrategy:
    """How a kind of model becomes the static problem E(y, p, q) = 0, z = h(y, p, q) + eps at p.

    A strategy is stateless; :class:`Problem` passes itself to every method.  Subclasses
    implement :meth:`static`, :meth:`fit` and :meth:`information`, :meth:`check` for the
    arguments only their kind takes, and :meth:`per_instrument`.  The layers above (the studies,
    the designs, mudoe's study kind) ask :func:`strategy_for` and read these attributes instead of
    asking whether a model is dynamic: what differs between the kinds is answered here.

    Attributes
    ----------
    kind : str
        "static" or "collocated" (printed, never compared by the verbs).
    model_type : type
        The type of the kind's models (:class:`models.Model`, :class:`models.dynamic.DynamicModel`).
    data_type : type
        The type of the kind's data (:class:`identification.Measurements`,
        :class:`identification.DynamicMeasurements`); :meth:`check_data` checks it.
    data_need : str
        What :meth:`check_data` says the data must be.
    takes_time_series : bool
        The data are time series: a campaign's splits select experiments and time windows and every fit
        takes a discretisation (:func:`identification.studies.detect.detect`, ``validate``), rather than
        input rows.
    design_axis : str
        The candidate axis of an approximate design (:mod:`oed.approximate`): "inputs" (input rows, a
        static model) or "times" (sampling times, a dynamic model); the information axes "times" and
        "pairs" (:func:`oed.information`) exist only where it is "times".
    """

    kind = ""
    model_type: type = object
    data_type: type = object
    data_need = ""
    takes_time_series = False
    design_axis = ""

    def check(self, problem: "Problem") -> None:
        """Raise TypeError for an argument this kind does not take (e.g. a discretisation of a static model)."""

    def check_data(self, data, argument: str = "data", *, need: str | None = None,
                   error: type[Exception] = TypeError) -> None:
        """Check that ``data`` is a :attr:`data_type` (the kind's measurements z_ijk).

        Raises
        ------
        TypeError (or ``error``)
            "<argument>: <need>, got <type of data>", ``need`` defaulting to :attr:`data_need` (which names
            the expected type).
        """
        if not isinstance(data, self.data_type):
            raise error(f"{argument}: {need or self.data_need}, got {type(data).__name__}")

    def per_instrument(self, model, M: np.ndarray, data=None, times=None) -> np.ndarray:
        """M_l = sum over the outputs k of instrument l of M_k: the matrices per output of :meth:`information`
        (n_outputs, ...), e.g. F_k (1 / (unit of p)^2), summed per instrument (n_S, ...).  A static model's
        outputs are its instruments; a dynamic model's are its (sensor, time) readings."""
        raise NotImplementedError

    def static(self, problem: "Problem", p=None) -> tuple:
        """(static model, static data) of the problem, on a discretisation controlled at p when p is given."""
        raise NotImplementedError

    def fit(self, problem: "Problem", p0, weights=None, settings: IdentifySettings | None = None,
            Y0=None) -> FitRecord:
        """The weighted least-squares fit (paper eq. 3) and its covariance (eq. 7) from ``p0``."""
        raise NotImplementedError

    def information(self, problem: "Problem", p, states=None, *, inputs=None, sigma=None, n_series=1,
                    times=None) -> tuple:
        """(F, S) per sensor (static) or per (sensor, time) pair (collocated) at p."""
        raise NotImplementedError

    def columns(self, problem: "Problem") -> ColumnLayout:
        """The :class:`ColumnLayout` of the static problem's data (which instrument, at which coordinates)."""
        raise NotImplementedError


class StaticStrategy(ProblemStrategy):
    """A static model E(y, p, q) = 0: its own static problem (the identity); fitted by
    :func:`identification.fit.estimator.fit_static`, its information by
    :func:`identification.fit.estimator.static_information`."""

    kind = "static"
    model_type = Model
    data_type = Measurements
    data_need = "expected an identification.Measurements"
    design_axis = "inputs"

    def check(self, problem: "Problem") -> None:
        if problem.discretisation is not None:
            raise TypeError("discretisation: only for a dynamic model")

    def per_instrument(self, model, M: np.ndarray, data=None, times=None) -> np.ndarray:
        return M

    def static(self, problem: "Problem", p=None) -> tuple:
        return problem.model, problem.data

    def fit(self, problem: "Problem", p0, weights=None, settings: IdentifySettings | None = None,
            Y0=None) -> FitRecord:
        return fit_static(problem.model, problem.data, p0, weights=weights, settings=settings, Y0=Y0)

    def information(self, problem: "Problem", p, states=None, *, inputs=None, sigma=None, n_series=1,
                    times=None) -> tuple:
        if times is not None:
            raise TypeError("times: only for a dynamic model")
        return static_information(problem.model, problem.data, p, states, inputs=inputs, sigma=sigma,
                                  n_series=n_series)

    def columns(self, problem: "Problem") -> ColumnLayout:
        """One column per sensor, no coordinates."""
        n = len(problem.data.sensors)
        return ColumnLayout(np.arange(n), tuple(problem.data.sensors), np.zeros((n, 0)))


class CollocatedStrategy(ProblemStrategy):
    """A dynamic model dx/dt = f(x, z, p, u), 0 = g(x, z, p, u): Radau IIA collocation on a mesh whose
    output error at p is within the discretisation tolerance (:mod:`identification.fit.dynamic_fit`).
    The fit refines the mesh until the error at the estimate is bounded
    (:func:`identification.fit.dynamic_fit.identify_dynamic`); the information is that of the
    collocated model on a mesh controlled at p, per (sensor, time) pair."""

    kind = "collocated"
    model_type = DynamicModel
    data_type = DynamicMeasurements
    data_need = "a dynamic model needs identification.DynamicMeasurements (values over sampling times)"
    takes_time_series = True
    design_axis = "times"

    def check(self, problem: "Problem") -> None:
        if problem.data is not None:
            self.check_data(problem.data)

    def per_instrument(self, model, M: np.ndarray, data=None, times=None) -> np.ndarray:
        """Sum over the readings (sensor, time): ``data.pairs``, or without data every instrument at each of
        the planned ``times`` (time-major, as :meth:`information` returns them)."""
        readings = data.pairs if data is not None else [(s, v) for v in np.asarray(times, float).ravel()
                                                         for s in model.sensors]
        acc = np.zeros((model.n_S,) + M.shape[1:])
        np.add.at(acc, np.array([model.sensors.index(s) for s, _ in readings]), M)
        return acc

    def static(self, problem: "Problem", p=None) -> tuple:
        ds = problem.discretisation or DiscretisationSettings()
        return collocated_problem(problem.model, problem.data, degree=ds.degree, elements=ds.elements, p=p,
                                  discretisation=problem.discretisation)

    def fit(self, problem: "Problem", p0, weights=None, settings: IdentifySettings | None = None,
            Y0=None) -> FitRecord:
        if Y0 is not None:
            raise TypeError("Y0: not used for a dynamic model (its trajectories start from an integration at p0)")
        return identify_dynamic(problem.model, problem.data, p0, weights=weights, settings=settings,
                                discretisation=problem.discretisation)

    def information(self, problem: "Problem", p, states=None, *, inputs=None, sigma=None, n_series=1,
                    times=None) -> tuple:
        if states is not None:
            raise TypeError("states: not used for a dynamic model")
        return dynamic_information(problem.model, problem.data, p, inputs=inputs, times=times, sigma=sigma,
                                   n_series=n_series, discretisation=problem.discretisation)

    def columns(self, problem: "Problem") -> ColumnLayout:
        """One column per (instrument, sampling time) pair of the data (:attr:`DynamicMeasurements.pairs`),
        the coordinate the time ``t``."""
        names = tuple(problem.data.sensors)
        pairs = problem.data.pairs
        return ColumnLayout(np.array([names.index(k) for k, _ in pairs], int), names,
                            np.array([[float(t)] for _, t in pairs]).reshape(len(pairs), 1), ("t",))


#: the strategies, one per kind of model
STATIC, COLLOCATED = StaticStrategy(), CollocatedStrategy()


def strategy_for(model) -> ProblemStrategy:
    """The strategy of a model: :class:`CollocatedStrategy` for a dynamic model (an ODE/DAE,
    :class:`models.dynamic.DynamicModel`), else :class:`StaticStrategy`.  The one place where the
    kind of a model is asked: the layers above read what differs from the strategy (its attributes)."""
    return COLLOCATED if getattr(model, "is_dynamic", False) else STATIC


class Problem:
    r"""An estimation problem: a model with its data and, for a dynamic model, its discretisation control.

    Asked at p it gives the static problem E(y_j, p, q_j) = 0, z_ijk = h_k(y_j, p, q_j) + eps_ijk
    (:meth:`static`): a static model and its data as they are; a dynamic model dx/dt = f(x, z, p, u),
    0 = g(x, z, p, u) collocated (Radau IIA) on a mesh whose output error at p is within
    ``discretisation.tol_sigma`` sigmas, with its data flattened to (sensor, time) pairs.  The verbs
    are written once against it: :meth:`fit` solves paper eq. 3 (min_p 0.5 sum_ijk w_k ((z_ijk -
    h_k) / sigma_k)^2) with the covariance of eq. 7; :meth:`information` gives the per-sensor
    information F_k = sum_j c_jk G_jk^T G_jk / sigma_k^2 (1 / (unit of p)^2) and second-order terms S_k.

    Parameters
    ----------
    model : models.Model
        A static model, or a dynamic one (:meth:`models.Model.ode`, :class:`models.dynamic.DynamicModel`).
    data : identification.Measurements or identification.DynamicMeasurements or None
        The measurements (a dynamic model needs DynamicMeasurements); None to plan without data
        (:meth:`information` then takes ``inputs``, ``sigma`` and, for a dynamic model, ``times``).
    discretisation : identification.DiscretisationSettings, optional
        The collocation and its error control (dynamic models only; default DiscretisationSettings()).

    Attributes
    ----------
    model, data, discretisation : as given
    strategy : ProblemStrategy
        :class:`StaticStrategy` or :class:`CollocatedStrategy` (:func:`strategy_for`).

    Raises
    ------
    TypeError
        A discretisation for a static model; data of a dynamic model that are not DynamicMeasurements.

    Examples
    --------
    >>> problem = Problem(model, data)                       # doctest: +SKIP
    >>> record = problem.fit(p0)                             # doctest: +SKIP
    >>> static_model, static_data = problem.static(record.p)  # doctest: +SKIP
    """

    def __init__(self, model, data=None, discretisation: DiscretisationSettings | None = None):
        self.model, self.data, self.discretisation = model, data, discretisation
        self.strategy = strategy_for(model)
        self.strategy.check(self)

    @property
    def kind(self) -> str:
        """The strategy's kind: "static" or "collocated"."""
        return self.strategy.kind

    def __repr__(self) -> str:
        return f"Problem({getattr(self.model, 'name', type(self.model).__name__)!r}, {self.kind})"

    def static(self, p=None) -> tuple:
        """(static model, static data) at p: a static model and its data as they are; a dynamic one
        collocated on a mesh whose output error at p is within the tolerance (without p: the first mesh
        of the discretisation settings) and its data as (sensor, time) pairs (Measurements)."""
        return self.strategy.static(self, None if p is None else np.asarray(p, float))

    def columns(self) -> ColumnLayout:
        """The :class:`ColumnLayout` of :meth:`static`'s data: which instrument every column holds and at which
        coordinates (a dynamic model: its sampling time)."""
        return self.strategy.columns(self)

    def fit(self, p0, weights=None, settings: IdentifySettings | None = None, Y0=None, *, starts: int = 1, seed=0,
            workers: int | None = 1, scheduler=None) -> FitRecord:
        """min_p 0.5 sum_ijk w_k ((z_ijk - h_k(y_j, p, q_j)) / sigma_k)^2 s.t. E(y_j, p, q_j) = 0 (paper
        eq. 3) from ``p0`` (units of the parameters), with the second-order covariance (eq. 7).

        ``weights`` (n_S,) are the sensor (instrument) weights, ``Y0`` (n_q, n_y) a guess of the states
        (static models only; used for the start p0 only).  A dynamic model's mesh is refined until its error at
        the estimate is within the tolerances (``record.diagnostics.discretisation``).  Returns the plain
        :class:`identification.fit.record.FitRecord` (:func:`identification.identify` wraps it as an Estimate).

        ``starts`` > 1: a multi-start fit (:mod:`identification.fit.multistart`): besides p0, ``starts - 1``
        starts drawn from ``seed`` (an int >= 0, a numpy SeedSequence, or None for fresh entropy, recorded) in
        the bounds, each fitted with the same settings on ``workers`` local processes (1: serially here; None:
        every core) or a Dask ``scheduler``; the record of the best local minimum is returned with every start in
        ``record.diagnostics.starts`` (a MultiStartRecord) and a note.  ``starts=1``
        (default) is the single fit from p0 (``seed``, ``workers`` and ``scheduler`` unused).
        """
        if check_starts(starts) == 1:
            return self.strategy.fit(self, p0, weights=weights, settings=settings, Y0=Y0)
        return fit_starts(self, p0, starts, weights=weights, settings=settings, Y0=Y0, seed=seed, workers=workers,
                          scheduler=scheduler)

    def information(self, p, states=None, *, inputs=None, sigma=None, n_series=1, times=None) -> tuple:
        """Per-sensor information F_k = sum_j c_jk G_jk^T G_jk / sigma_k^2 and second-order terms S_k at p
        (:func:`identification.fit.estimator.static_information`), shapes (n_S, n_p, n_p); for a dynamic
        model one matrix per (sensor, time) pair on a mesh controlled at p, with ``times`` the common
        sampling times when planning (data None).  ``states`` (static models) are the states at p."""
        return self.strategy.information(self, p, states, inputs=inputs, sigma=sigma, n_series=n_series,
                                         times=times)


def fit_model(model, data, p0, weights=None, settings: IdentifySettings | None = None, Y0=None,
              discretisation=None, *, starts: int = 1, seed=0, workers: int | None = 1, scheduler=None) -> FitRecord:
    """min_p 0.5 sum_ijk w_k ((z_ijk - h_k(y_j, p, q_j)) / sigma_k)^2 s.t. E(y_j, p, q_j) = 0 (paper eq. 3),
    with the second-order covariance (eq. 7): ``Problem(model, data, discretisation).fit(p0, ...)``
    (:meth:`Problem.fit`; ``starts``, ``seed``, ``workers``, ``scheduler``: a multi-start fit there).  ``Y0``
    static models only, ``discretisation`` (a :class:`identification.fit.dynamic_fit.DiscretisationSettings`)
    dynamic models only.
    """
    return Problem(model, data, discretisation).fit(p0, weights=weights, settings=settings, Y0=Y0, starts=starts,
                                                    seed=seed, workers=workers, scheduler=scheduler)


def information_contributions(model, data, p, states=None, *, inputs=None, sigma=None, n_series=1, times=None):
    """Per-sensor information F_k = sum_j c_jk G_jk^T G_jk / sigma_k^2 and second-order terms S_k at p
    (1 / (unit of p)^2): ``Problem(model, data).information(p, ...)`` (:meth:`Problem.information`).  A
    dynamic model takes ``times`` (sampling times, when data is None) and returns one matrix per (sensor,
    time) pair (:func:`identification.fit.dynamic_fit.dynamic_information`).

    Returns
    -------
    F, S : ndarray (n_S, n_p, n_p)
    """
    return Problem(model, data).information(p, states, inputs=inputs, sigma=sigma, n_series=n_series, times=times)
