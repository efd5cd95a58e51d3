r"""Which inputs to apply: exact designs over candidate rows, then a continuous refinement; static and
dynamic models alike.

Exact design: each candidate c is an input row :math:`q_j` (with every chosen sensor measured there)
or, jointly, an input-sensor pair :math:`(q_j, k)`; its information is

.. math::  F_c = n_\text{series}\sum_{k\in c} G_{jk}^TG_{jk}/\sigma_k^2,\qquad
           G_{jk} = \partial h_k/\partial p\,(y_j(p), p, q_j)\ \ (\text{1/param unit} \times \text{sensor unit}),

(:func:`oed.candidate_information.information`, axis ``inputs`` or ``input_pairs``), and
:func:`oed.design.select_sensors_from_information` chooses ``n_points`` candidates minimising
:math:`\Psi((\sum_c w_cF_c)^{-1})` by the same enumeration / branch-and-bound / SCIP routes as the
sensor selection.  Planned before measuring, the expected residual at the nominal ``p`` is 0, so the
second-order term vanishes and the design is Gauss-Newton.  A dynamic model's experiment j is its
input row (the constants, then every control's values at its grid points) read by every instrument k
at the sampling times t: its rows are evaluated on the Radau IIA collocation of a mesh whose output
error at p is within the discretisation tolerance at every candidate (:class:`oed.candidate_information.InputProblem`),
a static model whose outputs are the (sensor, time) pairs; that is the only difference.

Refinement: the chosen input levels are then moved continuously within bounds to minimise
the same criterion, by Ipopt with exact CasADi derivatives of the criterion of the
information matrix built symbolically from the model's sensitivities (implicit models and
collocated dynamic ones: the states and sensitivities as NLP variables tied by E(y, p, q) = 0 and
E_y y' + E_p = 0, :mod:`oed.input_nlp`).  The E criterion is stated smoothly as
:math:`\max t` s.t. :math:`M - tI = LL^T`.  On a controlled mesh the mesh is controlled again at the
refined rows; should it need refining, the refinement is repeated from the refined rows on the finer
mesh, so that the reported design and value are those of a mesh within tolerance.
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, replace

import numpy as np

from identification.errors import IdentificationError, StateSolveError
from identification.fit.dynamic_fit import DiscretisationSettings
from identification.fit.ipopt_solver import IpoptSettings, solve_nlp
from identification.fit.problem import strategy_for
from identification.results_protocol import ResultProtocol, jsonable, notes_lines
from .approximate import ApproximateSettings, approximate_design, check_approximate_route
from .criteria import DEFAULT_CRITERION, Criterion, Kind
from .design import DesignResult, DesignSettings, select_sensors_from_information
from .candidate_information import (InputProblem, candidate_rows, check_candidates, check_p, check_sigma, information,
                          input_problem, measured_sensors, row_information)
from .input_newton import information_value, newton_refine
from .input_nlp import BuildTimeout, information_nlp, reduced_parts
from .robust_inputs import robust_exact_inputs
from . import refine_child

__all__ = ["InputDesignResult", "RefinedInputs", "RefineSettings", "select_inputs", "refine_inputs",
           "input_information", "dynamic_input_information", "select_dynamic_inputs", "time_limit_notes"]


@dataclass(frozen=True)
class RefineSettings:
    """Settings of :func:`refine_inputs`.

    Attributes
    ----------
    n_starts : int
        Ipopt starts: the exact design's levels, then random points within the bounds.
    seed : int
        Seed of the random starts.
    ipopt : IpoptSettings
        Of the full-space route (``method="ipopt"``, and the E criterion).
    method : {"auto", "newton", "ipopt"}
        "newton": the D and A criteria are refined by the reduced-space projected Newton of
        :mod:`oed.input_newton` (the inputs alone as variables, exact CasADi derivatives; no NLP solver is built;
        a time limit stops it between iterations with the best point reached); "ipopt": the full-space NLP of
        :mod:`oed.input_nlp` solved by Ipopt (the only route before session 13; always for E); "auto" (the
        default): Newton for D, Ipopt for A and E.  (From the same start the two reach the same local optimum
        on the Pyomo.DoE reactor's D designs; for A with two rows Newton's projected steps settled on a worse
        local optimum than Ipopt's interior path, 13.79 against 11.53 with 4 starts, hence Ipopt for A.)
    newton_tol, max_newton : float, int
        The Newton's convergence tolerance (largest projected gradient entry over max(1, |value|)) and its
        iteration limit per start.
    child_above : int or None
        Under a time limit, an NLP with more variables than this (rows x (inputs + states x (1 + n_p))) is
        built and solved in a child process that is killed at the limit (:mod:`oed.refine_child`).  In this
        process the limit is checked between the build's steps and bounds every Ipopt run, so it is exceeded
        by at most one step that cannot be interrupted (a row's Hessian, CasADi's ``nlpsol`` set-up, one
        Ipopt iteration: about 1.5 s at 10 000 variables on the reference machine); the child costs a
        fresh interpreter and a build that is not cached (about 1.6 s CPU at 10 000 variables).  None: always
        in this process.  (20000 since session 12, was 5000.)  The Ipopt route only: the Newton route always runs
        in this process (its steps are one row's derivatives and one iteration; stopped between them it keeps
        the best point reached, which a killed child would lose).
    """

    n_starts: int = 4
    seed: int = 0
    ipopt: IpoptSettings = IpoptSettings(tol=1e-9, acceptable_tol=1e-6, max_iter=500, mumps_pivot_order=None)
    child_above: int | None = 20000
    method: str = "auto"
    newton_tol: float = 1e-9
    max_newton: int = 100

    def __post_init__(self):
        if self.method not in ("auto", "newton", "ipopt"):
            raise ValueError(f"method: expected 'auto', 'newton' or 'ipopt', got {self.method!r}")
        if (isinstance(self.newton_tol, bool) or not isinstance(self.newton_tol, (int, float))
                or not 0 < self.newton_tol < np.inf):
            raise ValueError(f"newton_tol: expected a positive number, got {self.newton_tol!r}")
        if isinstance(self.max_newton, bool) or not isinstance(self.max_newton, (int, np.integer)) or self.max_newton < 1:
            raise ValueError(f"max_newton: expected an integer >= 1, got {self.max_newton!r}")
        if isinstance(self.n_starts, bool) or not isinstance(self.n_starts, (int, np.integer)) or self.n_starts < 1:
            raise ValueError(f"n_starts: expected an integer >= 1, got {self.n_starts!r}")
        if self.child_above is not None and (isinstance(self.child_above, bool)
                                             or not isinstance(self.child_above, (int, np.integer))
                                             or self.child_above < 0):
            raise ValueError(f"child_above: expected None or an integer >= 0, got {self.child_above!r}")


@dataclass(frozen=True)
class RefinedInputs(ResultProtocol):
    """Continuous refinement of the exact design's input levels (the result protocol: :meth:`summary`,
    :meth:`to_frame`, :meth:`to_dict`, ``_repr_html_``).

    Attributes
    ----------
    inputs : ndarray, shape (n_points, d_q)
        Refined input rows (read-only), within ``lower``/``upper``.
    value : float
        Criterion value of the refined design (D: log det C), same scale as the exact design's.
    start_values : tuple of float
        Criterion value reached from each start (``inf`` for a failed start).
    n_failed : int
        Starts whose Ipopt run failed (their messages are in ``messages``).
    messages : tuple of str
    lower, upper : ndarray, shape (d_q,)
        The input bounds used.
    wall_time : float
    """

    inputs: np.ndarray
    value: float
    start_values: tuple
    n_failed: int
    messages: tuple
    lower: np.ndarray
    upper: np.ndarray
    wall_time: float

    def summary(self) -> str:
        """The refined rows, the value reached and the starts, with the failed starts' messages as notes."""
        lines = [f"refined input levels: value {self.value:.10g} ({len(self.start_values)} starts, {self.n_failed} "
                 f"failed), bounds {np.array2string(np.asarray(self.lower), precision=6)} to "
                 f"{np.array2string(np.asarray(self.upper), precision=6)}", ""]
        lines += [f"  row {j}: {np.array2string(np.asarray(r), precision=6)}"
                  for j, r in enumerate(np.atleast_2d(self.inputs))]
        return "\n".join(lines + notes_lines(self.messages))

    def to_frame(self):
        """The refined input rows as a pandas DataFrame (columns ``q0``, ``q1``, ...; model input units)."""
        import pandas as pd
        X = np.atleast_2d(np.asarray(self.inputs, float))
        df = pd.DataFrame(X, columns=[f"q{k}" for k in range(X.shape[1])])
        df.attrs.update(value=self.value, n_failed=self.n_failed)
        return df

    def to_dict(self) -> dict:
        """JSON-safe: inputs (rows), value, start_values, n_failed, messages, lower, upper, wall_time (s)."""
        return jsonable(dict(inputs=self.inputs, value=self.value, start_values=self.start_values,
                             n_failed=self.n_failed, messages=self.messages, lower=self.lower, upper=self.upper,
                             wall_time=self.wall_time))


@dataclass(frozen=True)
class InputDesignResult(ResultProtocol):
    """An exact input design (and optionally its continuous refinement; the result protocol: :meth:`summary`,
    :meth:`to_frame`, :meth:`to_dict`, ``_repr_html_``).

    Attributes
    ----------
    indices : tuple of int
        Chosen candidate rows (joint designs: the row of each chosen pair, repeated per sensor).
    pairs : tuple of (int, str)
        Chosen (row, sensor) pairs; without ``sensors="joint"`` every chosen row with every measured sensor.
    inputs : ndarray, shape (len(indices), d_q)
        The chosen input rows (read-only).
    value, lower_bound, gap : float
        Criterion value (D: log det C), proven lower bound and gap.
    proven_optimal : bool
    criterion, method, status : str
    design : DesignResult
        The engine's result over the candidates (names ``q<j>`` or ``q<j>:<sensor>``).
    refined : RefinedInputs or None
    notes : tuple of str
    axis : str
        The design's candidate axis: ``"inputs"`` (rows) or ``"input_pairs"`` ((row, sensor) pairs).
    chosen : tuple of str
        The chosen candidates' labels (``q<j>`` or ``q<j>:<sensor>``, as ``design.chosen``).
    """

    indices: tuple
    pairs: tuple
    inputs: np.ndarray
    value: float
    lower_bound: float
    gap: float
    proven_optimal: bool
    criterion: str
    method: str
    status: str
    design: DesignResult
    refined: RefinedInputs | None
    notes: tuple = ()
    axis: str = "inputs"
    chosen: tuple = ()

    def summary(self) -> str:
        """Human-readable multi-line summary (exact design next to its refinement)."""
        lines = [f"input design ({self.criterion}) via {self.method}: status {self.status}"
                 + (" (proven optimal)" if self.proven_optimal else ""),
                 f"  rows: {list(self.indices)}  value {self.value:.10g}  lower bound {self.lower_bound:.10g}"]
        if self.refined is not None:
            lines.append(f"  refined levels: {np.array2string(self.refined.inputs.ravel(), precision=6)}  value "
                         f"{self.refined.value:.10g} ({len(self.refined.start_values)} starts, "
                         f"{self.refined.n_failed} failed)")
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)

    def to_frame(self):
        """One row per chosen candidate (joint designs: per chosen (row, sensor) pair): the candidate ``row``,
        its ``sensor`` ("" for a whole row) and the input levels ``q0``, ``q1``, ... (model input units);
        ``.attrs``: criterion, value, lower_bound, gap, proven_optimal, method, status."""
        import pandas as pd
        X = np.asarray(self.inputs, float).reshape(len(self.indices), -1)
        sensors = [s for _, s in self.pairs] if len(self.pairs) == len(self.indices) else [""] * len(self.indices)
        df = pd.DataFrame(X, columns=[f"q{k}" for k in range(X.shape[1])])
        df.insert(0, "sensor", sensors)
        df.insert(0, "row", [int(j) for j in self.indices])
        df.attrs.update(criterion=self.criterion, value=self.value, lower_bound=self.lower_bound, gap=self.gap,
                        proven_optimal=self.proven_optimal, method=self.method, status=self.status)
        return df

    def to_dict(self) -> dict:
        """JSON-safe: indices, pairs, inputs, value, lower_bound, gap, proven_optimal, criterion, method, status,
        design (the engine's :meth:`DesignResult.to_dict`), refined (:meth:`RefinedInputs.to_dict` or None),
        notes."""
        return jsonable(dict(indices=self.indices, pairs=self.pairs, inputs=self.inputs, value=self.value,
                             lower_bound=self.lower_bound, gap=self.gap, proven_optimal=self.proven_optimal,
                             criterion=self.criterion, method=self.method, status=self.status,
                             design=self.design.to_dict(),
                             refined=None if self.refined is None else self.refined.to_dict(), notes=self.notes))


def _readonly(a):
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def select_inputs(model, p, *, candidates, sigma, n_points=None, sensors=None, criterion=DEFAULT_CRITERION, kind="gauss_newton",
                  costs=None, budget=None, include=(), exclude=(), n_series=1, method="auto", time_limit=60.0,
                  refine=False, bounds=None, refine_settings: RefineSettings = RefineSettings(),
                  settings: DesignSettings = DesignSettings(), times=None,
                  discretisation: DiscretisationSettings | None = None, approximate: bool = False, prior=None,
                  robust: str = "bayes", approx_settings: ApproximateSettings = ApproximateSettings()):
    r"""Exact optimal choice of ``n_points`` input rows (or input-sensor pairs),
    :math:`\min_{w\in\{0,1\}^{n_c},\ \sum_c w_c = n} \Psi((\sum_c w_cF_c)^{-1})` (module docstring), optionally
    refined; or, with ``approximate=True``, the approximate design :math:`\max_\xi \sum_s \pi_s u(M_s(\xi))` (or
    its maximin) on the continuous input range (:func:`oed.approximate.approximate_design`).

    Parameters
    ----------
    model : models.Model
        Static, or dynamic (:meth:`models.Model.ode`).
    p : array_like, shape (n_p,)
        Nominal parameters (within the model's bounds).
    candidates : array_like, shape (n_candidates, d_q)
        Candidate input rows (finite, no duplicates).
    sigma : array_like, shape (n_S,) or float
        Sensor standard deviations (sensor units; a dynamic model: one per instrument).
    n_points : int
        (Exact designs, required.)  Number of candidates chosen: input rows, or (row, sensor) pairs
        with ``sensors="joint"``.
    sensors : None, "joint" or sequence of str
        None: every sensor measured at each chosen input; names: those sensors (instruments); ``"joint"``:
        the candidates are all (row, sensor) pairs (a dynamic model's: (row, sensor@time)) and the sensors
        are chosen with the inputs.
    criterion : {"A", "D", "E"}
    kind : {"gauss_newton", "second_order"}
        Without data both are the Gauss-Newton criterion (S = 0 at the nominal p; noted).
    costs, budget, include, exclude
        As in :func:`oed.design.select_sensors_from_information`, per candidate (row or pair index).
    n_series : int
        Repetitions of every chosen input.
    method, time_limit, settings
        Engine route (``auto``, ``enumerate``, ``bnb``, ``scip``) and its limits; ``time_limit`` (s) bounds
        the whole design, a dynamic model's mesh control and the refinement included.
    refine : bool
        Also refine the chosen levels continuously (:func:`refine_inputs`, not for joint designs).
    bounds : (array_like, array_like) or None
        Input bounds for the refinement, shape (d_q,) each; default the candidates' range.
    times : array_like or None
        Dynamic models only (required): the sampling times of every experiment.
    discretisation : identification.fit.dynamic_fit.DiscretisationSettings or None
        Dynamic models: the collocation's tolerance.
    approximate : bool
        Static models: return the approximate design (support points and weights with the
        equivalence-theorem certificate) on ``bounds`` (default the candidates' range), not an exact
        n-run design; ``n_points``, costs, budget, include/exclude, refine and method are then not used.
    prior : None, (P, w), dict or oed.prior.Prior
        Parameter uncertainty (:func:`oed.prior.make_prior`): with ``approximate=True`` the robust approximate
        design; else the exact robust design of ``n_points`` candidates (:mod:`oed.robust_inputs`: the
        information of every candidate at every parameter vector, then
        :func:`oed.robust_exact.select_robust_exact` by enumeration or branch-and-bound with a proven gap,
        ``method`` "auto", "enumerate" or "bnb", ``time_limit`` per solve), with the local exact design at ``p``
        and its efficiency across the prior; ``refine=True`` then refines the chosen rows continuously within
        ``bounds`` (:func:`oed.robust_inputs.refine_robust_inputs`, the result's ``refined``); ``costs``,
        ``budget``, ``include`` and ``exclude`` are refused.
    robust : {"bayes", "maximin"}
        With a prior: pseudo-Bayesian or standardized maximin criterion (exact designs: the worst-case
        efficiency against each parameter vector's own exact n-run optimum).
    approx_settings : oed.approximate.ApproximateSettings

    Returns
    -------
    InputDesignResult, oed.approximate.ApproximateDesign with ``approximate=True``, or
    oed.robust_exact.RobustExactDesign with a prior and ``approximate=False``

    Raises
    ------
    ValueError
        Bad input (the message names the argument).
    """
    if prior is not None and not approximate:
        return robust_exact_inputs(model, p, candidates=candidates, sigma=sigma, n_points=n_points, sensors=sensors,
                                   criterion=criterion, prior=prior, robust=robust, n_series=n_series, times=times,
                                   discretisation=discretisation, method=method, time_limit=time_limit,
                                   unused=dict(refine=refine, kind=kind, costs=costs, budget=budget, bounds=bounds,
                                               include=include, exclude=exclude))
    if approximate:
        exact_args = dict(n_points=n_points, costs=costs, budget=budget, include=include, exclude=exclude,
                          refine=refine, times=times)
        return _approximate_inputs(model, p, candidates, sigma, sensors, n_series, bounds, approximate, prior, robust,
                                   approx_settings, criterion, exact_args)
    t0 = time.perf_counter()
    problem = input_problem(model, p, candidates, sigma, sensors, times=times, discretisation=discretisation)
    m = problem.model
    Q = check_candidates(m, candidates)
    k_idx, joint = measured_sensors(m, problem.sensors)
    n_cand = Q.shape[0] * (len(k_idx) if joint else 1)
    if isinstance(n_points, bool) or not isinstance(n_points, (int, np.integer)) or not 1 <= n_points <= n_cand:
        raise ValueError(f"n_points: expected an integer in 1..{n_cand} (the number of candidate "
                         f"{'pairs' if joint else 'rows'}), got {n_points!r}")
    kind_e = Kind.parse(kind)
    info = candidate_rows(problem, p, Q, n_series, "input_pairs" if joint else "inputs")
    left = max(time_limit - (time.perf_counter() - t0), 0.05 * time_limit) if problem.controlled else time_limit
    res = select_sensors_from_information(info, None, criterion=criterion, kind="gauss_newton", n_sensors=n_points,
                                          costs=costs, budget=budget, include=include, exclude=exclude,
                                          method=method, time_limit=left, settings=settings)
    if not res.indices:
        raise ValueError(f"n_points: no admissible design of {n_points} "
                         f"{'pairs' if joint else 'input rows'} identifies the parameters ({res.message}); "
                         "give more points or other candidates")
    notes = list(res.notes)
    if kind_e is Kind.SECOND_ORDER:
        notes.append("kind='second_order' planned without data: expected residual 0, S = 0, so the design is "
                     "Gauss-Newton at the nominal p")
    if joint:
        pair_of = [(j, m.sensors[k]) for j in range(Q.shape[0]) for k in k_idx]
        pairs = tuple(pair_of[c] for c in res.indices)
        rows = tuple(j for j, _ in pairs)
    else:
        rows = tuple(res.indices)
        pairs = tuple((j, m.sensors[k]) for j in rows for k in k_idx)
    refined = None
    if refine and res.indices:
        if joint:
            raise ValueError("refine: the continuous refinement is for input designs (sensors=None or names), "
                             "not for joint input-sensor designs")
        refined = refine_inputs(m, p, Q[list(rows)], problem.sigma, criterion=criterion, sensors=problem.sensors,
                                n_series=n_series, bounds=bounds if bounds is not None else (Q.min(0), Q.max(0)),
                                settings=refine_settings,
                                time_limit=max(time_limit - (time.perf_counter() - t0), 0.05 * time_limit))
        notes += time_limit_notes(refined, time_limit)
    notes += problem.notes()
    if refined is not None and problem.controlled:
        refined, note = _controlled_refinement(problem, p, refined, (sigma, sensors, n_series),
                                               replace(refine_settings, n_starts=1), res.criterion, (time_limit, t0))
        notes.append(note)
    return InputDesignResult(indices=rows, pairs=pairs, inputs=_readonly(Q[list(rows)].reshape(len(rows), -1)),
                             value=res.value, lower_bound=res.lower_bound, gap=res.gap,
                             proven_optimal=res.proven_optimal, criterion=res.criterion, method=res.method,
                             status=res.status, design=res, refined=refined, notes=tuple(notes), axis=info.axis,
                             chosen=res.chosen)


def time_limit_notes(refined: RefinedInputs, time_limit: float) -> list:
    """The note on a refinement that the time limit stopped (none when every start finished): the exact design's
    levels kept, or the best point reached returned (a Newton run or Ipopt's ``Maximum_WallTime_Exceeded``).

    Parameters
    ----------
    refined : RefinedInputs
        The refinement (:func:`refine_inputs`), read through its ``messages`` and ``n_failed``.
    time_limit : float
        The limit it ran under (s), quoted in the note.

    Returns
    -------
    list of str
        One note (the notes of :func:`select_inputs`), or none.
    """
    timed = [("time limit" in msg or "WallTime" in msg) for msg in refined.messages]
    if refined.n_failed and all(msg.startswith("not finished: time limit") for msg in refined.messages):
        return [f"refinement {refined.messages[0]}: the refined design is the exact design's levels "
                "(raise time_limit to refine them)"]
    if refined.n_failed == len(refined.messages) and all(timed):
        return [f"refinement not finished: every start stopped by the time limit ({time_limit:.3g} s) before reaching "
                "a point; the refined design is the exact design's levels (raise time_limit to refine them)"]
    if any(timed):
        return [f"refinement stopped by the time limit ({time_limit:.3g} s) before every start converged: the refined "
                "design is the best point reached (see its messages; raise time_limit to finish)"]
    return []


def _controlled_refinement(problem: InputProblem, p, refined: RefinedInputs, asked, settings: RefineSettings,
                           criterion: str, clock) -> tuple:
    """(refined design, note): the mesh of a controlled problem checked at the refined rows; beyond the tolerance
    it is controlled there and the refinement repeated from them on the finer mesh (``asked`` = the caller's
    sigma, sensors, n_series; ``clock`` = (time limit, start))."""
    err = problem.output_error(p, refined.inputs)
    if err <= (problem.discretisation or DiscretisationSettings()).tol_sigma:
        return refined, f"refined design: output error at p within {err:.2g} sigma on the same mesh"
    sigma, sensors, n_series = asked
    time_limit, t0 = clock
    fine = input_problem(problem.source, p, refined.inputs, sigma, sensors, times=problem.times,
                         discretisation=problem.discretisation)
    left = max(time_limit - (time.perf_counter() - t0), 0.05 * time_limit)
    again = refine_inputs(fine.model, p, refined.inputs, problem.sigma, criterion=criterion, sensors=fine.sensors,
                          n_series=n_series, bounds=(refined.lower, refined.upper), time_limit=left, settings=settings)
    refined = replace(again, start_values=refined.start_values + again.start_values,
                      messages=refined.messages + again.messages, n_failed=refined.n_failed + again.n_failed,
                      wall_time=time.perf_counter() - t0)
    return refined, (f"refined design: the mesh was refined to {fine.model.mesh.n_elements} elements (output error "
                     f"{fine.error:.2g} sigma) and the refinement repeated on it")


def _approximate_inputs(model, p, candidates, sigma, sensors, n_series, bounds, approximate, prior, robust, settings,
                        criterion, exact_args):
    """The ``approximate=True`` route of :func:`select_inputs` (arguments checked, then
    :func:`oed.approximate.approximate_design` on the input range)."""
    check_approximate_route(approximate, exact_args)
    if strategy_for(model).design_axis != "inputs":
        raise ValueError("approximate: for a dynamic model the approximate design is over sampling times "
                         "(oed.select_times(..., approximate=True)); approximate input profiles are not implemented")
    if isinstance(sensors, str) and sensors == "joint":
        raise ValueError("sensors: approximate designs take None or sensor names, not 'joint'")
    if bounds is None:
        Q = np.asarray(candidates, float)
        Q = Q[:, None] if Q.ndim == 1 else Q
        if Q.ndim != 2 or Q.shape[0] == 0 or Q.shape[1] != model.n_q_dim or not np.all(np.isfinite(Q)):
            raise ValueError(f"candidates: expected finite rows of shape (n, {model.n_q_dim}) spanning the range")
        if not np.any(Q.max(axis=0) > Q.min(axis=0)):
            raise ValueError("candidates: approximate designs need a continuous range, but every candidate row is "
                             "the same point; give bounds=(lower, upper) or candidates spanning a range")
        bounds = (Q.min(axis=0), Q.max(axis=0))
    return approximate_design(model, p, sigma=sigma, bounds=bounds, criterion=criterion, prior=prior,
                              robust=robust, sensors=sensors, n_series=n_series, settings=settings)


# ---------------------------------------------------------------------------- deprecated names (one release)
def _deprecated(old: str, new: str) -> None:
    warnings.warn(f"{old} is deprecated; use {new}", DeprecationWarning, stacklevel=3)


def input_information(model, p, candidates, sigma, n_series=1) -> np.ndarray:
    r"""Deprecated: :func:`oed.information` with ``axis="input_pairs"``.  Per-(input, sensor) information
    :math:`F_{jk} = n_\text{series}G_{jk}^TG_{jk}/\sigma_k^2`, shape (n_candidates, n_S, n_p, n_p)."""
    _deprecated("oed.input_information", 'oed.information(model, p, axis="input_pairs", candidates=..., sigma=...)')
    info = information(model, p, axis="input_pairs", candidates=candidates, sigma=sigma, n_series=n_series)
    return info.F.reshape(-1, model.n_S, model.n_p, model.n_p)


def dynamic_input_information(model, p, candidates, times, sigma, n_series=1,
                              discretisation: DiscretisationSettings | None = None) -> np.ndarray:
    r"""Deprecated: :func:`oed.information` with ``axis="inputs"`` and ``times``.  Per-experiment information
    :math:`F_j = n_\text{series}\sum_t\sum_k G_{jkt}^TG_{jkt}/\sigma_k^2` of every candidate row of a dynamic
    model, all instruments at all ``times``, shape (n_candidates, n_p, n_p)."""
    _deprecated("oed.dynamic_input_information", 'oed.information(model, p, axis="inputs", candidates=..., '
                'times=..., sigma=...)')
    return information(model, p, axis="inputs", candidates=candidates, times=times, sigma=sigma, n_series=n_series,
                       discretisation=discretisation).F


def select_dynamic_inputs(model, p, *, times, candidates, sigma, n_points, **kwargs) -> InputDesignResult:
    """Deprecated: :func:`select_inputs` (which takes dynamic models with ``times``)."""
    _deprecated("oed.select_dynamic_inputs", "oed.select_inputs(model, p, times=..., ...)")
    return select_inputs(model, p, times=times, candidates=candidates, sigma=sigma, n_points=n_points, **kwargs)


# ---------------------------------------------------------------------------- continuous refinement
def _extras(crit: Criterion, M) -> np.ndarray:
    """Start values of the E criterion's extra variables (t, L with M - t I = L L^T); none otherwise."""
    if crit is not Criterion.E:
        return np.zeros(0)
    n_p = M.shape[0]
    t_init = 0.5 * float(np.linalg.eigvalsh(M)[0])
    Lc = np.linalg.cholesky(M - t_init * np.eye(n_p) + 1e-14 * np.eye(n_p))
    return np.array([t_init] + [Lc[i, j] for j in range(n_p) for i in range(j, n_p)])


def _share(seconds: float) -> float:
    """An equal share of the time per start, rounded down to 1, 2 or 5 x 10^k s: Ipopt's wall-time
    limit is a solver setting, and few distinct values let the compiled solver be reused."""
    e = 10.0 ** np.floor(np.log10(seconds))
    return float(max(m for m in (1.0, 2.0, 5.0, 10.0) if m * e <= seconds * (1 + 1e-12)) * e)


def _check_bounds(model, start, bounds):
    """(X0, lo, hi) checked: start rows within finite bounds lo <= hi."""
    X0 = np.atleast_2d(np.asarray(start, float))
    lo, hi = (np.broadcast_to(np.asarray(b, float).ravel(), (model.n_q_dim,)) for b in bounds)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo <= hi)):
        raise ValueError(f"bounds: expected finite lower <= upper of shape ({model.n_q_dim},), got {bounds!r}")
    if X0.shape[1] != model.n_q_dim or np.any(X0 < lo - 1e-12) or np.any(X0 > hi + 1e-12):
        raise ValueError("start: input rows must lie within the bounds")
    return X0, lo, hi


def refine_inputs(model, p, start, sigma, *, criterion=DEFAULT_CRITERION, sensors=None, n_series=1, bounds,
                  settings: RefineSettings = RefineSettings(), time_limit: float | None = None) -> RefinedInputs:
    r"""Move ``n_points`` input rows continuously within ``bounds`` to minimise :math:`\Psi(M(q)^{-1})`.

    Multi-start Ipopt (the exact design's levels, then random points in the bounds) on the
    full-space NLP of :mod:`oed.input_nlp` (states and sensitivities as variables, exact sparse
    CasADi derivatives); the best start is returned.  D is reported as log det C
    (= -log det M), E as :math:`1/\lambda_{\min}(M)`, A as trace :math:`M^{-1}`.  ``time_limit``
    (seconds, None: none) bounds the whole refinement, the NLP's construction included: each start's
    Ipopt run has an equal share of the time left after the construction (rounded down, :func:`_share`)
    as its wall-time limit, no start begins after it, and the first start's levels are kept if nothing
    better was reached.  A large NLP (``settings.child_above``) is built and solved in a child process
    killed at the limit (:mod:`oed.refine_child`); then the start's levels are kept, stated in the
    messages.

    Raises
    ------
    ValueError
        Bad bounds or start.
    RuntimeError
        When every start fails for another reason than the time limit (Ipopt's messages are given).
    """
    crit = Criterion.parse(criterion)
    p = check_p(model, p)
    sig = check_sigma(model, sigma)
    k_idx, joint = measured_sensors(model, sensors)
    if joint:
        raise ValueError("sensors: the refinement takes None or sensor names, not 'joint'")
    if time_limit is not None and not (isinstance(time_limit, (int, float)) and time_limit > 0):
        raise ValueError(f"time_limit: expected a positive number of seconds or None, got {time_limit!r}")
    X0, lo, hi = _check_bounds(model, start, bounds)
    t0 = time.perf_counter()
    if (settings.method == "newton" and crit is not Criterion.E) or (settings.method == "auto" and crit is Criterion.D):
        return _refine_newton(model, p, X0, sig, (crit, k_idx, n_series), (lo, hi), settings, time_limit, t0)
    n_vars = X0.shape[0] * (model.n_q_dim + model.n_y * (1 + model.n_p))
    if time_limit is not None and settings.child_above is not None and n_vars > settings.child_above:
        inner = max(0.9 * time_limit, time_limit - refine_child.GRACE_S)     # its Ipopt runs end before the kill
        call = (refine_inputs, (model, p, X0, sig),
                dict(criterion=criterion, sensors=sensors, n_series=n_series, bounds=(lo, hi),
                     settings=replace(settings, child_above=None), time_limit=inner))
        got = refine_child.run(call, time_limit)
        return got if got is not None else _kept(model, p, X0, sig, (crit, k_idx, n_series), (lo, hi), settings,
                                                 f"time limit ({time_limit:.3g} s) reached while building or solving "
                                                 f"the refinement's NLP ({n_vars} variables) in its child process", t0)
    deadline = np.inf if time_limit is None else t0 + float(time_limit)
    n_pts, d = X0.shape
    span = np.where(hi > lo, hi - lo, 1.0)
    weights = np.array([float(n_series) / sig[k] ** 2 if k in k_idx else 0.0 for k in range(model.n_S)])
    key = ("refine_nlp", np.asarray(p).tobytes(), weights.tobytes(), n_pts, lo.tobytes(), span.tobytes(), crit)
    try:
        nlp = model.cache.get_or_make("refine_nlp", key, lambda: information_nlp(model, p, weights, n_pts, lo, span,
                                                                                 crit, deadline), maxsize=4)
    except BuildTimeout as exc:
        return _kept(model, p, X0, sig, (crit, k_idx, n_series), (lo, hi), settings,
                     f"time limit ({time_limit:.3g} s) reached while building the refinement's NLP (after "
                     f"{exc.phase}; no Ipopt run started)", t0)
    rng = np.random.default_rng(settings.seed)
    starts = [X0] + [lo + (hi - lo) * rng.random((n_pts, d)) for _ in range(settings.n_starts - 1)]
    M0 = nlp.matrix(nlp.start(model, p, X0, lo, span))
    best, best_v = X0, _value(crit, M0)
    b = nlp.parameter(M0)            # the lifted information's scale (if lifted), the same for every start
    values, messages = [], []
    n_free = nlp.n_y + nlp.n_s + nlp.n_m + nlp.n_extra
    lbx = np.r_[np.zeros(nlp.n_u), np.full(n_free, -np.inf)]
    ubx = np.r_[np.tile(np.where(hi > lo, 1.0, 0.0), n_pts), np.full(n_free, np.inf)]
    # each start's share of the time left once the NLP is built (its construction is part of the limit)
    share = None if time_limit is None else _share(max(deadline - time.perf_counter(), 1e-3) / len(starts))
    ipopt = _kkt_settings(settings.ipopt, nlp.n_u + n_free)
    ipopt = ipopt if share is None else replace(ipopt, extra=ipopt.extra + (("max_wall_time", share),))
    for Xs in starts:
        left = deadline - time.perf_counter()
        if left <= 0:
            messages.append("not started: time limit reached")
            values.append(np.inf)
            continue
        v, msg, Xr = _one_start(model, p, nlp, Xs, (lo, hi, span), crit, (lbx, ubx, b), ipopt, key)
        values.append(v)
        messages.append(msg)
        if v < best_v:
            best, best_v = Xr, v
    if not any(np.isfinite(values)) and not any("time limit" in m for m in messages):
        raise RuntimeError(f"refine: every Ipopt start failed: {'; '.join(messages)}")
    return RefinedInputs(inputs=_readonly(best), value=float(best_v), start_values=tuple(float(v) for v in values),
                         n_failed=int(sum(not np.isfinite(v) for v in values)), messages=tuple(messages),
                         lower=_readonly(lo), upper=_readonly(hi), wall_time=time.perf_counter() - t0)


def _refine_newton(model, p, X0, sig, design, box, settings: RefineSettings, time_limit, t0) -> RefinedInputs:
    """:func:`refine_inputs` by the reduced-space Newton (:mod:`oed.input_newton`) from the same starts; each start
    may use the time left divided by the starts left; a start stopped by the limit keeps its best point (said in
    its message); ``design`` = (criterion, measured sensor indices, n_series), ``box`` = (lo, hi)."""
    crit, k_idx, n_series = design
    lo, hi = box
    deadline = np.inf if time_limit is None else t0 + float(time_limit)
    span, ub = np.where(hi > lo, hi - lo, 1.0), np.where(hi > lo, 1.0, 0.0)
    weights = np.array([float(n_series) / sig[k] ** 2 if k in k_idx else 0.0 for k in range(model.n_S)])
    key = ("refine_newton", np.asarray(p).tobytes(), weights.tobytes(), lo.tobytes(), span.tobytes(), crit)
    try:
        parts = model.cache.get_or_make("refine_newton", key, lambda: reduced_parts(model, p, weights, lo, span, crit,
                                                                                    deadline), maxsize=4)
    except BuildTimeout as exc:
        return _kept(model, p, X0, sig, design, box, settings, f"time limit ({time_limit:.3g} s) reached while "
                     f"building the refinement's derivatives (after {exc.phase}; no Newton step taken)", t0)
    n_pts, d = X0.shape
    rng = np.random.default_rng(settings.seed)
    starts = [X0] + [lo + (hi - lo) * rng.random((n_pts, d)) for _ in range(settings.n_starts - 1)]
    best, best_v = X0, np.inf          # a Newton run never ends above its start: the first start's value is X0's or less
    values, messages = [], []
    for i, Xs in enumerate(starts):
        left = deadline - time.perf_counter()
        if left <= 0:
            messages.append("not started: time limit reached")
            values.append(np.inf)
            continue
        out = newton_refine(model, p, parts, (Xs - lo) / span, (lo, span, ub), crit, tol=settings.newton_tol,
                            max_iter=settings.max_newton, deadline=time.perf_counter() + left / (len(starts) - i))
        values.append(out.value)
        messages.append(out.message)
        if out.value < best_v:
            best, best_v = lo + span * out.u * (hi > lo), out.value
    if not any(np.isfinite(values)) and not any("time limit" in m for m in messages):
        raise RuntimeError(f"refine: every Newton start failed: {'; '.join(messages)}")
    if not np.isfinite(best_v):       # no start began or every start failed: X0 kept, valued from its sensitivities
        best_v = _value(crit, row_information(model, p, X0, sig, n_series)[:, list(k_idx)].sum(axis=(0, 1)))
    return RefinedInputs(inputs=_readonly(best), value=float(best_v), start_values=tuple(float(v) for v in values),
                         n_failed=int(sum(not np.isfinite(v) for v in values)), messages=tuple(messages),
                         lower=_readonly(lo), upper=_readonly(hi), wall_time=time.perf_counter() - t0)


#: above this many NLP variables MUMPS factorises the refinement's KKT matrix without its own row and column
#: scaling (Ipopt's ``mumps_scaling`` 0 instead of 77, its automatic choice), unless the settings name it: the
#: NLP's variables are already scaled (:func:`oed.input_nlp.variable_scale`), and the scaling was more than half of
#: each factorisation (reactor ``profile``, 939 states x 2 experiments: 80 -> 35 ms CPU per iteration, the same
#: optimum); smaller refinements keep Ipopt's default (bit for bit as before)
UNSCALED_MUMPS_ABOVE = 2000


def _kkt_settings(ipopt: IpoptSettings, n_x: int) -> IpoptSettings:
    """``ipopt`` with ``mumps_scaling`` 0 when the NLP has more than :data:`UNSCALED_MUMPS_ABOVE` variables,
    uses MUMPS and the settings do not set the option themselves."""
    named = any(k in ("mumps_scaling", "ipopt.mumps_scaling") for k, _ in ipopt.extra)
    if n_x <= UNSCALED_MUMPS_ABOVE or named or ipopt.linear_solver != "mumps":
        return ipopt
    return replace(ipopt, extra=ipopt.extra + (("mumps_scaling", 0),))


def _kept(model, p, X0, sig, design, box, settings: RefineSettings, why: str, t0: float) -> RefinedInputs:
    """The refinement that kept the start rows X0 (no start finished: ``why``), valued exactly from the
    sensitivities at X0 (``design`` = (criterion, measured sensor indices, n_series))."""
    crit, k_idx, n_series = design
    F = row_information(model, p, X0, sig, n_series)[:, list(k_idx)].sum(axis=(0, 1))
    msg = f"not finished: {why}; the start's levels are kept"
    return RefinedInputs(inputs=_readonly(X0), value=_value(crit, F), start_values=(np.inf,) * settings.n_starts,
                         n_failed=settings.n_starts, messages=(msg,) * settings.n_starts, lower=_readonly(box[0]),
                         upper=_readonly(box[1]), wall_time=time.perf_counter() - t0)


def _one_start(model, p, nlp, Xs, box, crit, var_bounds, ipopt, key):
    """(criterion value, message, refined rows) of one Ipopt run of the refinement from the rows Xs
    (value inf for a failed run; a stalled run's point is still a design, re-evaluated exactly); ``var_bounds`` =
    (lbx, ubx, the NLP parameter b of :meth:`oed.input_nlp.InformationNlp.parameter`)."""
    lo, hi, span = box
    n_pts, d = Xs.shape
    zero = np.zeros(nlp.n_g)
    try:
        x0 = nlp.start(model, p, Xs, lo, span)
        M, n = nlp.matrix(x0), nlp.n_u + nlp.n_y + nlp.n_s
        x0[n:n + nlp.n_m] = nlp.lifted(M, var_bounds[2])
        x0[n + nlp.n_m:] = _extras(crit, M)
        r = solve_nlp(lambda: nlp.problem, x0, var_bounds[0], var_bounds[1], zero, zero, var_bounds[2],
                      settings=ipopt, what="input refinement", key=key, cache=model.cache)
    except (IdentificationError, StateSolveError) as exc:
        return np.inf, str(exc), Xs
    Xr = lo + span * np.clip(np.asarray(r.x[: n_pts * d]).reshape(n_pts, d), 0.0, 1.0) * (hi > lo)
    try:
        v = _value(crit, nlp.matrix(nlp.start(model, p, Xr, lo, span)))
    except StateSolveError as exc:
        return np.inf, f"the refined point has no state solution ({exc})", Xs
    return v, (r.status if r.accepted else f"stalled ({r.status}); point re-evaluated"), Xr


def _value(crit: Criterion, M) -> float:
    """Psi(M^-1) evaluated exactly (D: log det C); inf when M is singular (:func:`oed.input_newton.information_value`)."""
    return information_value(crit, M)
