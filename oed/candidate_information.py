r"""One information function for every candidate axis of a design.

A design chooses candidates c on one axis: sensors, sampling times, (time, sensor) pairs of a dynamic
model, input rows, or (row, sensor) pairs.  Each candidate's information at p is

.. math::  F_c = \sum_{(j, k, t)\in c} c_{jk}\, G_{jkt}^T G_{jkt} / \sigma_k^2
           \quad (\text{1/param unit}^2),\qquad
           G_{jkt} = \partial h_k(y_j(t; p), p, q_j) / \partial p\ \ (\text{sensor unit/param unit}),

summed over the readings (row j, sensor k, time t) the candidate makes, with :math:`c_{jk}` the
number of series (``n_series`` when planned, the data's replicates when measured), and with data the
second-order terms :math:`S_c = \sum d^2/dp^2[-c_{jk}(\bar z_{jk} - h_k)/\sigma_k^2]` (planned before
measuring the expected residual is 0 and S vanishes).  :func:`information` returns them as one
:class:`CandidateInformation` (``axis``, ``labels``, ``F`` of shape (n_c, n_p, n_p), ``S`` or None),
which :func:`oed.design.select_sensors_from_information` takes as it is.

Static and dynamic models differ only in how the readings' sensitivities are computed: a static
model solves E(y, p, q) = 0 at every row (:mod:`models.state`); a dynamic one is collocated on a
mesh whose output error at p is within the discretisation tolerance at every candidate
(:func:`identification.fit.dynamic_fit.controlled_mesh`), a static model whose outputs are the
(sensor, time) pairs (:class:`InputProblem`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from identification import information_contributions
from identification.fit.dynamic_fit import DiscretisationSettings, controlled_mesh
from identification.fit.dynamic_data import instrument_sigma
from identification.fit.problem import strategy_for
from models.collocation import collocate, pair_name
from models.trajectory import mapped_outputs
from models.contract import ModelError
from models.dynamic import time_label
from models.sensitivity import sensitivities
from models.state import solve_states

__all__ = ["AXES", "CandidateInformation", "information", "InputProblem", "input_problem",
           "row_information", "candidate_rows", "check_candidates", "check_p", "check_sigma", "measured_sensors"]

#: the candidate axes of a design: sensors, sampling times, (time, sensor) pairs, input rows, (row, sensor) pairs
AXES = ("sensors", "times", "pairs", "inputs", "input_pairs")


@dataclass(frozen=True)
class CandidateInformation:
    """The information of every candidate of one design axis (module docstring).

    Attributes
    ----------
    axis : str
        One of :data:`AXES`.
    labels : tuple of str
        One name per candidate: the sensor (``cA``), the time (``0.5``), the pair (``cA@0.5``), the row
        (``q3``) or the row and sensor (``q3:cA``).
    F : ndarray, shape (n_c, n_p, n_p)
        Gauss-Newton information per candidate (1/param unit^2).
    S : ndarray, shape (n_c, n_p, n_p), or None
        Second-order terms (None: planned designs, where they vanish and none are passed on).
    """

    axis: str
    labels: tuple
    F: np.ndarray
    S: np.ndarray | None = None

    def __post_init__(self):
        if self.axis not in AXES:
            raise ValueError(f"axis: expected one of {AXES}, got {self.axis!r}")
        if len(self.labels) != np.shape(self.F)[0]:
            raise ValueError(f"labels: expected {np.shape(self.F)[0]} (one per candidate), got {len(self.labels)}")


# ---------------------------------------------------------------------------- argument checks
def check_candidates(model, candidates) -> np.ndarray:
    """Candidate input rows, shape (n_c, d_q): finite, no duplicates (errors name ``candidates``)."""
    try:
        Q = np.asarray(candidates, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"candidates: not numeric ({exc})") from None
    if Q.ndim == 1 and model.n_q_dim == 1:
        Q = Q[:, None]
    if Q.ndim != 2 or Q.shape[0] == 0 or Q.shape[1] != model.n_q_dim:
        raise ValueError(f"candidates: expected shape (n_candidates, {model.n_q_dim}) (one row per input point), "
                         f"got {Q.shape}")
    bad = np.argwhere(~np.isfinite(Q))
    if bad.size:
        raise ValueError(f"candidates: non-finite value at row {bad[0][0]}, column {bad[0][1]}; remove the row")
    _, first, counts = np.unique(Q, axis=0, return_index=True, return_counts=True)
    if np.any(counts > 1):
        dup = sorted(int(i) for i in np.flatnonzero(np.all(Q == Q[first[np.argmax(counts > 1)]], axis=1)))
        raise ValueError(f"candidates: duplicate rows {dup}; list every input point once (use n_series for repeats)")
    return Q


def check_p(model, p) -> np.ndarray:
    """Nominal parameters, shape (n_p,): finite and within the model's bounds."""
    p = np.asarray(p, dtype=float).ravel()
    if p.shape != (model.n_p,) or not np.all(np.isfinite(p)):
        raise ValueError(f"p: expected {model.n_p} finite nominal parameter values, got {p}")
    out = (p < model.lower) | (p > model.upper)
    if np.any(out):
        names = [model.param_names[i] for i in np.flatnonzero(out)]
        raise ValueError(f"p: nominal parameters {names} lie outside their bounds "
                         f"[{model.lower[out]}, {model.upper[out]}]")
    return p


def check_sigma(model, sigma) -> np.ndarray:
    """Standard deviation per sensor of a static model, shape (n_S,) (a dynamic model's, one per instrument:
    :func:`identification.fit.dynamic_data.instrument_sigma`)."""
    sig = np.asarray(sigma, dtype=float).ravel()
    if sig.size == 1:
        sig = np.full(model.n_S, float(sig[0]))
    if sig.shape != (model.n_S,) or not np.all(np.isfinite(sig) & (sig > 0)):
        raise ValueError(f"sigma: expected {model.n_S} positive finite values (one per sensor), got {sigma!r}")
    return sig


def _check_n_series(n_series) -> None:
    if isinstance(n_series, bool) or not isinstance(n_series, (int, np.integer)) or n_series < 1:
        raise ValueError(f"n_series: expected an integer >= 1, got {n_series!r}")


def measured_sensors(model, sensors) -> tuple:
    """(sensor indices measured, joint?) from ``sensors`` (None, 'joint' or names of ``model``)."""
    if sensors is None:
        return tuple(range(model.n_S)), False
    if isinstance(sensors, str) and sensors == "joint":
        return tuple(range(model.n_S)), True
    names = [sensors] if isinstance(sensors, str) else list(sensors)
    unknown = [s for s in names if s not in model.sensors]
    if unknown or not names:
        raise ValueError(f"sensors: expected None, 'joint' or names of {list(model.sensors)}, got {sensors!r}")
    return tuple(model.sensors.index(s) for s in names), False


# ---------------------------------------------------------------------------- the problem behind input rows
@dataclass(frozen=True)
class InputProblem:
    """The static problem whose rows are the candidates: a static model itself, or a dynamic model's Radau IIA
    collocation on a mesh controlled at p over every candidate row (its outputs the (sensor, time) pairs).

    Attributes
    ----------
    model : models.Model
        The static model the rows are evaluated on (the collocated model of a dynamic one).
    sigma : ndarray or the caller's value
        Standard deviation per output of ``model`` (a static model's is checked where it is used).
    sensors : None, "joint" or sequence of str
        The measured sensors in ``model``'s names (a dynamic model's instruments as their pairs).
    source : models.Model
        The model the caller gave.
    times : ndarray or None
        A dynamic model's sampling times.
    discretisation : identification.fit.dynamic_fit.DiscretisationSettings or None
    error : float or None
        A dynamic model's output error at p, in sigmas, on the controlled mesh (None: static).
    """

    model: object
    sigma: object
    sensors: object
    source: object
    times: np.ndarray | None = None
    discretisation: DiscretisationSettings | None = None
    error: float | None = None

    @property
    def controlled(self) -> bool:
        """True when the rows are evaluated on a discretisation whose error is controlled at p."""
        return self.error is not None

    def notes(self) -> tuple:
        """What the problem adds to a design's notes (the mesh and its error)."""
        if not self.controlled:
            return ()
        cm = self.model
        return (f"dynamic model: Radau IIA collocation of degree {cm.mesh.degree} on {cm.mesh.n_elements} elements, "
                f"output error at p within {self.error:.2g} sigma at every candidate",)

    def output_error(self, p, inputs) -> float:
        """Richardson's estimate of the output error of the collocation at p and ``inputs``, in sigmas (the
        mesh against every element halved, as :func:`identification.fit.dynamic_fit.controlled_mesh`)."""
        cm, model = self.model, self.source
        half = collocate(model, cm.times, mesh=cm.mesh.refined(2), outputs=cm.outputs)
        order = 2 * cm.mesh.degree - 1
        if model.n_z:
            diff = half.integrated_outputs(p, inputs) - cm.integrated_outputs(p, inputs)
        else:
            diff = mapped_outputs(half, p, inputs) - mapped_outputs(cm, p, inputs)
        return float(np.max(np.abs(diff) / self.sigma)) * 2 ** order / (2 ** order - 1)


def _pair_sensors(model, cm, sensors):
    """Instrument names (or None / 'joint') as the collocated model's (sensor, time) pair names."""
    if sensors is None or (isinstance(sensors, str) and sensors == "joint"):
        return sensors
    names = [sensors] if isinstance(sensors, str) else list(sensors)
    unknown = [s for s in names if s not in model.sensors]
    if unknown or not names:
        raise ValueError(f"sensors: expected None, 'joint' or instruments of {list(model.sensors)}, got {sensors!r}")
    return [pair_name(s, t) for t in cm.times for s in model.sensors if s in names]


def input_problem(model, p, candidates, sigma, sensors=None, *, times=None,
                  discretisation: DiscretisationSettings | None = None) -> InputProblem:
    """The :class:`InputProblem` of candidate rows: a static model as it is (``times`` and ``discretisation``
    must be None); a dynamic model sampled at ``times`` (one ``sigma`` per instrument, ``sensors`` instrument
    names) collocated on a mesh controlled at p over every candidate row."""
    if strategy_for(model).design_axis == "inputs":
        if times is not None or discretisation is not None:
            raise ValueError("times/discretisation: only for a dynamic model (models.Model.ode)")
        return InputProblem(model=model, sigma=sigma, sensors=sensors, source=model)
    if times is None:
        raise ValueError("times: a dynamic model needs the sampling times of its experiments")
    sig = instrument_sigma(model.sensors, sigma)
    try:
        t = model.check_times(times)
    except ModelError as exc:
        raise ValueError(str(exc)) from None
    Q = np.atleast_2d(np.asarray(candidates, dtype=float))
    if Q.shape[1] != model.n_q_dim:
        raise ValueError(f"candidates: expected shape (n_candidates, {model.n_q_dim}) ({', '.join(model.inputs)}: "
                         f"the constants, then every control's values at its grid points), got {Q.shape}")
    cm, err = controlled_mesh(model, np.asarray(p, float).ravel(), Q, t, sig, discretisation=discretisation)
    return InputProblem(model=cm, sigma=np.tile(sig, t.size), sensors=_pair_sensors(model, cm, sensors), source=model,
                        times=cm.times, discretisation=discretisation, error=err)


def row_information(model, p, candidates, sigma, n_series=1) -> np.ndarray:
    r"""Per-(row, sensor) information :math:`F_{jk} = n_\text{series}G_{jk}^TG_{jk}/\sigma_k^2` of a static
    model (an :attr:`InputProblem.model`), shape (n_candidates, n_S, n_p, n_p)."""
    Q = check_candidates(model, candidates)
    p = check_p(model, p)
    sig = check_sigma(model, sigma)
    _check_n_series(n_series)
    G = sensitivities(model, p, Q, solve_states(model, p, Q)).G           # (n_q, n_S, n_p)
    return float(n_series) * np.einsum("k,jkp,jkr->jkpr", 1.0 / sig ** 2, G, G)


def candidate_rows(problem: InputProblem, p, candidates, n_series, axis) -> CandidateInformation:
    """Axis ``inputs`` (every measured sensor at each row) or ``input_pairs`` ((row, sensor) pairs) of the rows
    ``candidates`` of ``problem``."""
    m = problem.model
    k_idx, joint = measured_sensors(m, problem.sensors)
    if joint != (axis == "input_pairs"):
        raise ValueError(f"sensors: 'joint' (every (row, sensor) pair a candidate) is axis 'input_pairs', not {axis!r}")
    Fjk = row_information(m, p, candidates, problem.sigma, n_series)
    n = Fjk.shape[0]
    if joint:
        return CandidateInformation(axis, tuple(f"q{j}:{m.sensors[k]}" for j in range(n) for k in k_idx),
                                    Fjk[:, list(k_idx)].reshape(-1, m.n_p, m.n_p))
    return CandidateInformation(axis, tuple(f"q{j}" for j in range(n)), Fjk[:, list(k_idx)].sum(axis=1))


# ---------------------------------------------------------------------------- sensors, times, pairs
def _instrument_names(model, sensors) -> list:
    names = list(model.sensors) if sensors is None else ([sensors] if isinstance(sensors, str) else list(sensors))
    unknown = [s for s in names if s not in model.sensors]
    if unknown or not names:
        raise ValueError(f"sensors: unknown {unknown or 'empty selection'}; the model has {', '.join(model.sensors)}")
    return names


def _times(model, p, times, inputs, sigma, sensors, n_series, axis) -> CandidateInformation:
    """Axis ``times`` (every chosen instrument at each time) or ``pairs`` ((time, sensor), time-major), summed
    over the experiments ``inputs``."""
    if strategy_for(model).design_axis != "times":
        raise TypeError(f"model: expected a dynamic model (models.Model.ode), got {type(model).__name__}")
    names = _instrument_names(model, sensors)
    t = np.asarray(times, float).ravel()
    F, _ = information_contributions(model, None, p, inputs=inputs, times=t, sigma=sigma, n_series=n_series)
    F = F.reshape(t.size, model.n_S, model.n_p, model.n_p)[:, [model.sensors.index(s) for s in names]]
    if axis == "pairs":
        return CandidateInformation(axis, tuple(pair_name(s, v) for v in t for s in names),
                                    F.reshape(-1, model.n_p, model.n_p))
    return CandidateInformation(axis, tuple(time_label(v) for v in t), F.sum(axis=1))


def _sensors(model, p, data, inputs, times, sigma, n_series, states) -> CandidateInformation:
    r"""Axis ``sensors``: a static model's F_k, S_k (:func:`identification.information_contributions`); a dynamic
    model's per instrument l, :math:`F_l = \sum_t F_{(l, t)}` (and S) over its (sensor, time) readings."""
    F, S = information_contributions(model, data, p, states, inputs=inputs, sigma=sigma, n_series=n_series,
                                     times=times)
    strategy = strategy_for(model)
    return CandidateInformation("sensors", tuple(model.sensors), strategy.per_instrument(model, F, data, times),
                                strategy.per_instrument(model, S, data, times))


def information(model, p, *, axis: str = "sensors", data=None, inputs=None, candidates=None, times=None, sigma=None,
                sensors=None, n_series: int = 1, states=None,
                discretisation: DiscretisationSettings | None = None) -> CandidateInformation:
    r"""The information :math:`F_c` (and second-order terms :math:`S_c`) of every candidate c on ``axis`` at p
    (module docstring), static or dynamic model alike.

    Parameters
    ----------
    model : models.Model
        Static, or dynamic (:meth:`models.Model.ode`).
    p : array_like, shape (n_p,)
        Parameters (the estimate, or the nominal values when planning).
    axis : {"sensors", "times", "pairs", "inputs", "input_pairs"}
        ``sensors``: one candidate per sensor (instrument), from ``data`` or planned from ``inputs`` and
        ``sigma`` (a dynamic model also ``times``; its readings summed per instrument); ``times`` /
        ``pairs``: a dynamic model's sampling times / (time, sensor) pairs, planned for the experiments
        ``inputs``; ``inputs`` / ``input_pairs``: the ``candidates`` rows / (row, sensor) pairs, planned.
    data : identification.Measurements or None
        Measurements (axis ``sensors`` only); None plans before measuring (S = 0).
    inputs : array_like, shape (n_q, d_q), optional
        The experiments applied (planned axes ``sensors``, ``times``, ``pairs``).
    candidates : array_like, shape (n_c, d_q), optional
        Candidate input rows (axes ``inputs``, ``input_pairs``).
    times : array_like, optional
        Sampling times of a dynamic model (candidates on axes ``times`` / ``pairs``).
    sigma : float or array_like, optional
        Standard deviation per sensor (instrument), in its unit.
    sensors : None or sequence of str
        The sensors (instruments) measured, default all (not on axis ``sensors``).
    n_series : int
        Repeated series of every experiment (planned).
    states : ndarray, optional
        Start values of a static model's states (axis ``sensors``).
    discretisation : identification.fit.dynamic_fit.DiscretisationSettings or None
        A dynamic model's collocation tolerance (axes ``inputs``, ``input_pairs``).

    Returns
    -------
    CandidateInformation
        ``F`` of shape (n_c, n_p, n_p); ``S`` on axis ``sensors`` (zero when planned), else None.

    Raises
    ------
    ValueError
        Bad input (the message names the argument).
    TypeError
        Axis ``times`` / ``pairs`` for a static model.
    """
    if axis not in AXES:
        raise ValueError(f"axis: expected one of {AXES}, got {axis!r}")
    if axis == "sensors":
        if sensors is not None:
            raise ValueError("sensors: the candidates of axis 'sensors' are every sensor (exclude= leaves some out)")
        return _sensors(model, p, data, inputs, times, sigma, n_series, states)
    if data is not None:
        raise ValueError(f"data: axis {axis!r} is planned before measuring (data=None)")
    if axis in ("times", "pairs"):
        return _times(model, p, times, inputs, sigma, sensors, n_series, axis)
    if candidates is None:
        raise ValueError(f"candidates: axis {axis!r} needs the candidate input rows")
    if axis == "input_pairs" and sensors is None:
        sensors = "joint"
    problem = input_problem(model, p, candidates, sigma, sensors, times=times, discretisation=discretisation)
    return candidate_rows(problem, p, candidates, n_series, axis)
