r"""Front door for optimal sensor selection.

Solves

.. math::  \min_{w\in\{0,1\}^{n_S}} \Psi(C(w))\quad\text{s.t.}\quad \sum_k w_k \ge 1,\
           \sum_k w_k = m \ (\text{or} \le m_{\max}),\ c^Tw \le B,\ w_I=1,\ w_O=0,

with :math:`C` the second-order covariance :math:`H^{-1}(\sum_k w_k^2F_k)H^{-1}` or the
Gauss-Newton covariance :math:`(\sum_k w_kF_k)^{-1}` and :math:`\Psi` = trace (A),
log det (D) or lambda_max (E).

``method="auto"``: exact enumeration when the number of admissible designs is at most
``DesignSettings.enumeration_limit`` (2e5); otherwise our branch-and-bound for
Gauss-Newton criteria (with or without costs and budget); otherwise (second-order criteria)
screened enumeration whenever its measured cost fits the time limit (designs / second measured
on the problem itself, see :attr:`DesignSettings.enumeration_rate`), and SCIP via Pyomo beyond.
A valid node bound for the second-order criteria is derived in :mod:`oed.bnb.second_order`; it is
finite only once the fixed-in sensors make :math:`\sum_{k\in I}F_k` regular and, on 30 x 4 choose 6,
prunes nothing at depth 2 and under 0.05 % of the designs at depth 3 even with exact Gauss-Newton
node minima, so auto does not route to the branch-and-bound.  If SCIP is unavailable or
fails, enumeration is used when it is affordable (``enumeration_fallback_limit``) and the
fallback is recorded in :attr:`DesignResult.notes`.
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from .bnb import BnBSettings, branch_and_bound
from .constraints import DesignConstraints, make_constraints
from .criteria import (DEFAULT_CRITERION, DEFAULT_SETTINGS, Criterion, CriteriaSettings, Kind, batch_criteria, gap_tolerance,
                       screening_values, validate_information)
from .design_tables import design_frame, design_html, table_frame
from identification.results_protocol import ResultProtocol, jsonable
from .enumeration import EnumerationSettings, enumerate_designs, iter_designs
from .candidate_information import CandidateInformation, information

__all__ = ["DesignSettings", "DesignResult", "DesignRow", "DesignTable", "select_sensors_from_information",
           "design_table", "select_sensors"]

_METHODS = ("auto", "scip", "bnb", "enumerate")
#: how a summary names the candidates of each axis
_AXIS_WORDS = {"sensors": "sensors", "times": "sampling times", "pairs": "readings", "inputs": "input rows",
               "input_pairs": "readings"}


@dataclass(frozen=True)
class DesignSettings:
    """Settings of :func:`select_sensors_from_information`.

    Attributes
    ----------
    enumeration_limit : int
        ``auto`` enumerates when the admissible design count is at most this.
    enumeration_fallback_limit : int
        Largest design count enumerated as a fallback after a SCIP failure.
    gap_tol : float
        Optimality tolerance (relative for A/E, absolute on log det for D).
    criteria : CriteriaSettings
    scip_formulation : str
        Passed to :class:`oed.scip_solver.ScipSettings` (``auto``, ``cuts``, ``naive``, ``second_order``).
    enumeration_rate : float or None
        Designs per second that ``auto`` assumes for enumeration; None measures it on the
        problem (one timed batch of ``calibration_designs`` designs).
    calibration_designs : int
    """

    enumeration_limit: int = 200_000
    enumeration_fallback_limit: int = 5_000_000
    gap_tol: float = 1e-9
    criteria: CriteriaSettings = DEFAULT_SETTINGS
    scip_formulation: str = "auto"
    enumeration_rate: float | None = None
    calibration_designs: int = 4096

    def __post_init__(self):
        for name in ("enumeration_limit", "enumeration_fallback_limit"):
            v = getattr(self, name)
            if not (isinstance(v, (int, np.integer)) and v >= 0):
                raise ValueError(f"{name}: expected an integer >= 0, got {v!r}")
        if not (isinstance(self.gap_tol, (int, float, np.floating)) and 0 <= self.gap_tol < np.inf):
            raise ValueError(f"gap_tol: expected a finite number >= 0, got {self.gap_tol!r}")
        if not isinstance(self.criteria, CriteriaSettings):
            raise TypeError(f"criteria: expected CriteriaSettings, got {type(self.criteria).__name__}")
        if self.enumeration_rate is not None and not (isinstance(self.enumeration_rate, (int, float, np.floating))
                                                      and 0 < self.enumeration_rate < np.inf):
            raise ValueError(f"enumeration_rate: expected None or designs/second > 0, got {self.enumeration_rate!r}")
        if isinstance(self.calibration_designs, bool) or not isinstance(self.calibration_designs, (int, np.integer)) \
                or self.calibration_designs < 1:
            raise ValueError(f"calibration_designs: expected an integer >= 1, got {self.calibration_designs!r}")
        formulations = ("auto", "cuts", "naive", "second_order")
        if self.scip_formulation not in formulations:
            raise ValueError(f"scip_formulation: expected one of {formulations}, got {self.scip_formulation!r}")


@dataclass(frozen=True)
class DesignResult(ResultProtocol):
    """Immutable outcome of a selection of candidates (sensors, sampling times, pairs or input rows; the result
    protocol: :meth:`summary`, :meth:`to_frame`, :meth:`to_dict`, ``_repr_html_``).

    Attributes
    ----------
    chosen : tuple of str
        Labels of the chosen candidates (sensor names, times, ``cA@0.5`` pairs, ``q<j>`` rows).
    indices : tuple of int
    weights : tuple of bool
        Boolean weight per candidate.
    criterion, kind : str
    value : float
        Criterion value (D: log det C).  ``inf`` if no regular design was found.
    det : float or None
        det C for the D criterion.
    lower_bound : float
        Proven lower bound on the optimal value (same scale as ``value``); at least 0 for A and E
        (the covariance is positive semidefinite), so their gap is finite whenever a design is found.
    gap : float
        ``value - lower_bound`` (0 when proven optimal).
    proven_optimal : bool
    method : str
        Method actually used (``enumerate``, ``bnb``, ``scip``).
    status, message : str
    wall_time : float
    near_singular : str
        Reason text when the chosen design is near-singular, else ''.
    notes : tuple of str
        Fallbacks and modelling assumptions.
    candidates : tuple of str
        Names of all candidate sensors (the order of ``weights``).
    costs : tuple of float or None
        Cost per candidate when the design had a budget.
    include, exclude : tuple of int
        Candidates forced in / out.
    information_share : tuple of float
        tr(M^-1 F_k) / n_p per candidate, M the chosen design's Gauss-Newton information
        (dimensionless; the chosen sensors' shares add up to 1); empty when no design was found.
    axis : str
        The candidates' axis (:data:`oed.candidate_information.AXES`): ``"sensors"``, ``"times"``, ``"pairs"``,
        ``"inputs"`` or ``"input_pairs"``.
    sensors : tuple of str
        The chosen sensors: ``chosen`` of a sensor design (deprecated alias, with a warning, on another axis).
    """

    chosen: tuple
    indices: tuple
    weights: tuple
    criterion: str
    kind: str
    value: float
    det: float | None
    lower_bound: float
    gap: float
    proven_optimal: bool
    method: str
    status: str
    message: str
    wall_time: float
    near_singular: str = ""
    notes: tuple = field(default_factory=tuple)
    candidates: tuple = ()
    costs: tuple | None = None
    include: tuple = ()
    exclude: tuple = ()
    information_share: tuple = ()
    axis: str = "sensors"

    @property
    def sensors(self) -> tuple:
        """The chosen sensors (``chosen``); on another axis a deprecated alias of ``chosen``."""
        if self.axis != "sensors":
            warnings.warn(f"DesignResult.sensors of a design over {self.axis} is deprecated; use DesignResult.chosen",
                          DeprecationWarning, stacklevel=2)
        return self.chosen

    def to_frame(self):
        """A pandas DataFrame with one row per candidate sensor: selected, cost (with a budget), fixed
        (forced ``in``/``out``), information share (see :mod:`oed.design_tables`); scalars in ``.attrs``."""
        return design_frame(self)

    def _repr_html_(self) -> str:
        return design_html(self)

    def summary(self) -> str:
        """Human-readable multi-line summary."""
        lines = [
            f"OED ({self.kind}, {self.criterion}-criterion) via {self.method}: status {self.status}"
            + (" (proven optimal)" if self.proven_optimal else ""),
            f"  {_AXIS_WORDS.get(self.axis, self.axis)} ({len(self.indices)}): "
            f"{', '.join(self.chosen) if self.chosen else '-'}",
            f"  value: {self.value:.10g}" + (f"  (det C = {self.det:.6g})" if self.det is not None else ""),
            f"  lower bound: {self.lower_bound:.10g}  gap: {self.gap:.3g}",
            f"  wall time: {self.wall_time:.3f} s",
        ]
        if self.message:
            lines.append(f"  message: {self.message}")
        if self.near_singular:
            lines.append(f"  WARNING: {self.near_singular}")
        for n in self.notes:
            lines.append(f"  note: {n}")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """The chosen design as JSON-safe values (what a report's results.json holds under "oed" / "chosen"):
        sensors, weights, criterion, kind, value (``inf`` as "inf"), proven_optimal, method, status, notes."""
        return jsonable(dict(sensors=self.chosen, weights=self.weights, criterion=self.criterion, kind=self.kind,
                             value=self.value, proven_optimal=self.proven_optimal, method=self.method,
                             status=self.status, notes=list(self.notes)))


def _names(sensor_names, n):
    if sensor_names is None:
        return tuple(f"s{k}" for k in range(n))
    names = tuple(str(s) for s in sensor_names)
    if len(names) != n:
        raise ValueError(f"sensor_names: expected {n} names (one per candidate sensor), got {len(names)}")
    if len(set(names)) != n:
        raise ValueError("sensor_names: names must be unique")
    return names


def select_sensors_from_information(F, S=None, criterion=DEFAULT_CRITERION, kind="gauss_newton", n_sensors=None,
                                    max_sensors=None, costs=None, budget=None, include=(), exclude=(),
                                    method="auto", time_limit=60.0, sensor_names=None, *,
                                    settings: DesignSettings = DesignSettings()) -> DesignResult:
    r"""Optimal sensor subset :math:`\arg\min_{w} \Psi(C(w))` from per-sensor information (or per-candidate
    information on any axis).

    Parameters
    ----------
    F : array_like, shape (n_S, n_p, n_p), or oed.candidate_information.CandidateInformation
        Gauss-Newton information contributions :math:`F_k=J_k^TJ_k` (symmetric PSD); or the candidates'
        information (:func:`oed.candidate_information.information`), whose ``F``, ``S``, ``labels`` and ``axis`` are
        used (``S`` and ``sensor_names`` must then be None).
    S : array_like or None, shape (n_S, n_p, n_p)
        Second-order terms (symmetric); required for ``kind="second_order"`` unless zero.
    criterion : {"A", "D", "E"}
    kind : {"gauss_newton", "second_order"}
    n_sensors : int or None
        Exact number of sensors.
    max_sensors : int or None
        Upper bound on the number of sensors.
    costs, budget : array_like and float, or None
        Per-sensor costs and budget :math:`c^Tw\le B`.
    include, exclude : sequence of int or str
        Forced-in / forced-out sensors (indices or names).
    method : {"auto", "scip", "bnb", "enumerate"}
    time_limit : float
        Seconds for B&B / SCIP (enumeration ignores it).
    sensor_names : sequence of str or None

    Returns
    -------
    DesignResult

    Raises
    ------
    ValueError
        Bad input (message names the argument).
    RuntimeError
        When no method could produce a design (e.g. SCIP failed and enumeration is too big).
    """
    t0 = time.perf_counter()
    axis = "sensors"
    if isinstance(F, CandidateInformation):
        if S is not None or sensor_names is not None:
            raise ValueError("S/sensor_names: given by the CandidateInformation (leave them None)")
        F, S, sensor_names, axis = F.F, F.S, F.labels, F.axis
    req = _design_request(F, S, criterion, kind, n_sensors, max_sensors, costs, budget, include, exclude, method,
                          time_limit, sensor_names, settings)
    chosen, note = _route(req, settings)
    outcome = _run_method(req, chosen, settings)
    if note:
        outcome = replace(outcome, notes=(note,) + outcome.notes)
    return replace(_assemble_result(req, outcome, settings, t0), axis=axis)


@dataclass(frozen=True)
class _DesignRequest:
    """Validated inputs of one selection: information, criterion, constraints and method."""

    F: np.ndarray
    S: np.ndarray | None          # second-order terms used (None for Gauss-Newton)
    crit: Criterion
    kind: Kind
    cons: DesignConstraints
    names: tuple
    count: int                    # number of admissible designs
    method: str                   # as requested ("auto" allowed)
    time_limit: float


@dataclass(frozen=True)
class _MethodOutcome:
    """What a method returned: design, value, bound, status, message, method used, notes."""

    w: np.ndarray | None
    value: float
    lower_bound: float
    status: str
    message: str
    method: str
    notes: tuple = ()


def _design_request(F, S, criterion, kind, n_sensors, max_sensors, costs, budget, include, exclude, method,
                    time_limit, sensor_names, settings) -> _DesignRequest:
    """Validate the arguments of :func:`select_sensors_from_information` (errors name the argument)."""
    crit = Criterion.parse(criterion)
    kind_e = Kind.parse(kind)
    if method not in _METHODS:
        raise ValueError(f"method: unknown {method!r}; valid: {', '.join(_METHODS)}")
    try:
        time_limit = float(time_limit)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"time_limit: must be a number, got {time_limit!r}") from exc
    if not time_limit > 0:
        raise ValueError(f"time_limit: must be positive, got {time_limit}")
    F, S = validate_information(F, S, settings=settings.criteria)
    n, p, _ = F.shape
    names = _names(sensor_names, n)
    cons = make_constraints(n, p, n_sensors=n_sensors, max_sensors=max_sensors, costs=costs, budget=budget,
                            include=include, exclude=exclude, sensor_names=names)
    return _DesignRequest(F=F, S=S if kind_e is Kind.SECOND_ORDER else None, crit=crit, kind=kind_e, cons=cons,
                          names=names, count=cons.count_designs(), method=method, time_limit=time_limit)


def _enumeration_rate(req: _DesignRequest, settings: DesignSettings) -> float:
    """Designs per second of exact (screened) enumeration on this problem: the median of three timed
    batches of ``calibration_designs`` designs after a warm-up, generation + screening + the exact evaluation of
    the seed designs (the few designs evaluated exactly later are not counted)."""
    if settings.enumeration_rate is not None:
        return float(settings.enumeration_rate)
    W = next(iter_designs(req.cons, 64), None)
    if W is None:
        return np.inf
    screening_values(req.F, req.S, W, req.crit, req.kind)
    batch_criteria(req.F, req.S, W[:16], req.kind, settings=settings.criteria, validated=True)
    times = []
    for _ in range(3):      # median of three timed batches: one preempted batch on a shared host does not decide
        t = time.perf_counter()
        W = next(iter_designs(req.cons, settings.calibration_designs))
        screening_values(req.F, req.S, W, req.crit, req.kind)
        batch_criteria(req.F, req.S, W[:64], req.kind, settings=settings.criteria, validated=True)
        times.append(time.perf_counter() - t)
    return len(W) / max(float(np.median(times)), 1e-9)


def _route(req: _DesignRequest, settings: DesignSettings) -> tuple:
    """(method, note): ``auto`` enumerates small problems, else B&B (Gauss-Newton), else enumeration
    when its measured cost fits the time limit, else SCIP."""
    chosen, note = req.method, ""
    if chosen == "auto":
        if req.count <= settings.enumeration_limit:
            chosen = "enumerate"
        elif req.kind is Kind.GAUSS_NEWTON:
            chosen = "bnb"
        else:
            rate = _enumeration_rate(req, settings)
            est = req.count / rate
            if est <= req.time_limit:
                chosen = "enumerate"
                note = (f"auto: enumeration of {req.count} designs estimated at {est:.3g} s ({rate:.3g} designs/s "
                        f"measured) <= time_limit {req.time_limit:g} s")
            else:
                chosen = "scip"
                note = (f"auto: enumeration of {req.count} designs estimated at {est:.3g} s ({rate:.3g} designs/s "
                        f"measured) > time_limit {req.time_limit:g} s; SCIP")
    if chosen == "bnb" and req.kind is not Kind.GAUSS_NEWTON:
        raise ValueError("method: 'bnb' supports only kind='gauss_newton' (no valid bound is derived for the "
                         "second-order covariance with indefinite S); use 'enumerate' or 'scip'")
    return chosen, note


def _run_method(req: _DesignRequest, chosen: str, settings: DesignSettings) -> _MethodOutcome:
    """Run the chosen method; a failed SCIP run falls back to enumeration when affordable."""
    if chosen == "bnb":
        return _solve_bnb(req, settings)
    notes = ()
    if chosen == "scip":
        outcome, failed = _solve_scip(req, settings)
        if not failed:
            return outcome
        notes = outcome.notes + (_scip_fallback_note(req, outcome, settings),)
    return _solve_enumeration(req, settings, notes)


def _solve_bnb(req: _DesignRequest, settings: DesignSettings) -> _MethodOutcome:
    """Our branch-and-bound (Gauss-Newton criteria)."""
    cons = req.cons
    r = branch_and_bound(req.F, cons, req.crit, settings=BnBSettings(time_limit=req.time_limit,
                                                                     gap_tol=settings.gap_tol),
                         criteria_settings=settings.criteria)
    notes = ()
    if cons.max_sensors is not None and cons.n_sensors is None and cons.costs is None:
        notes = (f"sum w <= {cons.max_sensors} solved as sum w = {cons.max_size} (GN criteria are monotone)",)
    message = f"{r.nodes} nodes, root bound {r.root_bound:.6g}, initial incumbent {r.initial_incumbent:.6g}"
    return _MethodOutcome(r.w, r.value, r.lower_bound, r.status, message, "bnb", notes)


def _solve_scip(req: _DesignRequest, settings: DesignSettings):
    """SCIP via Pyomo; returns (outcome, failed)."""
    from . import scip_solver  # the only module importing Pyomo's SolverFactory
    try:
        r = scip_solver.solve_scip(req.F, req.S, req.cons, req.crit, req.kind,
                                   settings=scip_solver.ScipSettings(time_limit=req.time_limit,
                                                                     gap_tol=settings.gap_tol,
                                                                     formulation=settings.scip_formulation),
                                   criteria_settings=settings.criteria)
    except scip_solver.ScipUnavailableError as exc:
        return _MethodOutcome(None, np.inf, np.inf, "error", f"SCIP unavailable: {exc}", "scip"), True
    notes = ("modelling bound: " + r.assumption,) if r.assumption else ()
    failed = r.status in ("error",) or (r.w is None and r.status != "infeasible")
    message = f"{r.formulation}: {r.message} ({r.rounds} SCIP solve(s))"
    return _MethodOutcome(r.w, r.value, r.lower_bound, r.status, message, "scip", notes), failed


def _scip_fallback_note(req: _DesignRequest, failed: _MethodOutcome, settings: DesignSettings) -> str:
    """Note for the fallback to enumeration after a SCIP failure; raises when enumeration is too large."""
    limit = settings.enumeration_fallback_limit
    if req.method == "scip" and req.count > limit:
        raise RuntimeError(f"method: SCIP failed ({failed.message}) and enumeration of {req.count} designs is too large")
    if req.count > limit:
        raise RuntimeError(f"SCIP failed ({failed.status}: {failed.message}) and enumeration of {req.count} designs "
                           f"exceeds enumeration_fallback_limit = {limit}")
    return f"SCIP failed ({failed.status}: {failed.message}); fell back to exact enumeration"


def _solve_enumeration(req: _DesignRequest, settings: DesignSettings, notes: tuple) -> _MethodOutcome:
    """Exact enumeration of every admissible design."""
    if req.count > settings.enumeration_fallback_limit and req.method == "enumerate":
        raise ValueError(f"method: enumeration of {req.count} admissible designs exceeds "
                         f"{settings.enumeration_fallback_limit}; use 'bnb' or 'scip'")
    r = enumerate_designs(req.F, req.S, req.cons, req.crit, req.kind,
                          settings=EnumerationSettings(max_designs=max(settings.enumeration_fallback_limit, req.count)),
                          criteria_settings=settings.criteria)
    status = "optimal" if np.isfinite(r.value) else "infeasible"
    message = (f"enumerated {r.n_evaluated} admissible designs ({r.n_exact} evaluated exactly after screening, "
               f"{r.n_singular} of them singular)")
    return _MethodOutcome(r.w, r.value, r.value, status, message, "enumerate", notes)


def _assemble_result(req: _DesignRequest, out: _MethodOutcome, settings: DesignSettings, t0: float) -> DesignResult:
    """Re-evaluate the design exactly, derive gap and proof, and build the :class:`DesignResult`."""
    crit = req.crit
    w, value, lb, status, message = out.w, out.value, out.lower_bound, out.status, out.message
    if status == "infeasible" or w is None or not np.isfinite(value):
        status = "infeasible"
        message = (message + "; " if message else "") + "no admissible design has full-rank information"
        w = None
    near = ""
    det = None
    if w is not None:
        res = batch_criteria(req.F, req.S, np.asarray(w, dtype=float)[None], req.kind, settings=settings.criteria,
                             validated=True)
        if res.singular[0]:  # never return a singular design
            raise RuntimeError(f"internal error: method {out.method} returned a singular design")
        value = float(res.value(crit)[0])
        near = res.reason[0] if res.near_singular[0] else ""
        if crit is Criterion.D:
            det = float(res.det[0])
    if crit is not Criterion.D:
        lb = max(lb, 0.0)           # C is positive semidefinite: trace and largest eigenvalue are >= 0
    lb = float(min(lb, value)) if np.isfinite(value) else lb
    gap = float(value - lb) if np.isfinite(value) and np.isfinite(lb) else np.inf
    proven = status == "optimal" and gap <= gap_tolerance(crit, value, settings.gap_tol) * 1.000001 + 1e-300
    if status == "optimal" and not proven:
        status = "feasible"
    wt = np.zeros(req.F.shape[0], dtype=bool) if w is None else np.asarray(w, dtype=bool)
    idx = tuple(int(k) for k in np.flatnonzero(wt))
    share = () if w is None else _information_share(req.F, wt)
    return DesignResult(chosen=tuple(req.names[k] for k in idx), indices=idx, weights=tuple(bool(x) for x in wt),
                        criterion=crit.value, kind=req.kind.value, value=float(value), det=det,
                        lower_bound=float(lb), gap=gap, proven_optimal=bool(proven), method=out.method,
                        status=status, message=message, wall_time=time.perf_counter() - t0, near_singular=near,
                        notes=out.notes, candidates=req.names, costs=req.cons.costs, include=req.cons.include,
                        exclude=req.cons.exclude, information_share=share)


def _information_share(F: np.ndarray, w: np.ndarray) -> tuple:
    """tr(M^{-1} F_k) / n_p of every candidate k, M = sum of the chosen F_k (regular: a found design)."""
    M = F[w].sum(axis=0)
    return tuple(float(v) for v in np.trace(np.linalg.solve(M[None], F), axis1=1, axis2=2) / F.shape[1])


@dataclass(frozen=True)
class DesignRow:
    """One admissible sensor combination of :func:`design_table`."""

    mask: str
    sensors: tuple
    A: float
    det: float
    logdet: float
    E: float
    flag: str  # '', 'near-singular' or 'singular'
    reason: str


@dataclass(frozen=True)
class DesignTable(ResultProtocol):
    """All admissible combinations (rows) for a press-style table (the result protocol: :meth:`summary`,
    :meth:`to_frame`, :meth:`to_dict`, ``_repr_html_``)."""

    kind: str
    rows: tuple

    def to_frame(self):
        """A pandas DataFrame, one row per combination (see :func:`oed.design_tables.table_frame`)."""
        return table_frame(self)

    def _repr_html_(self) -> str:
        return self.to_frame().to_html(float_format=lambda v: f"{v:.4e}")

    def to_text(self) -> str:
        """Fixed-width text table (A, det, log det, E, flag)."""
        out = [f"{'combination':<14}{'Psi_A':>14}{'Psi_D (det)':>14}{'log det':>12}{'Psi_E':>14}  flag"]
        for r in self.rows:
            out.append(f"{r.mask:<14}{r.A:>14.4e}{r.det:>14.4e}{r.logdet:>12.4f}{r.E:>14.4e}  "
                       + r.reason)
        return "\n".join(out)

    def summary(self) -> str:
        """A head (the covariance kind, the number of combinations) and the fixed-width :meth:`to_text` table."""
        return f"Sensor combinations ({self.kind} covariance): {len(self.rows)} rows\n\n" + self.to_text()

    def to_dict(self) -> dict:
        """JSON-safe: ``kind`` and ``rows`` (mask, sensors, A, det, logdet, E, flag, reason per combination;
        what a report's results.json holds under "oed" as "kind" and "table")."""
        return jsonable(dict(kind=self.kind, rows=[dict(mask=r.mask, sensors=r.sensors, A=r.A, det=r.det,
                                                        logdet=r.logdet, E=r.E, flag=r.flag, reason=r.reason)
                                                   for r in self.rows]))


def design_table(F, S=None, sensor_names=None, min_sensors=None, *, kind=None, max_rows=100_000,
                 settings: CriteriaSettings = DEFAULT_SETTINGS) -> DesignTable:
    r"""A, D (det and log det), E of :math:`C(w)` for every combination with
    :math:`\sum_k w_k \ge` ``min_sensors`` (default :math:`n_p`), flagged singular/near-singular.

    ``kind`` defaults to ``"second_order"`` when ``S`` is given, else ``"gauss_newton"``.
    Rows are ordered by size (largest first, as in the paper's table) then lexicographically.
    """
    F, S = validate_information(F, S, settings=settings)
    n, p, _ = F.shape
    names = _names(sensor_names, n)
    kind_e = Kind.parse(kind if kind is not None else ("second_order" if S is not None else "gauss_newton"))
    if min_sensors is None:
        min_sensors = p
    if isinstance(min_sensors, bool) or not isinstance(min_sensors, (int, np.integer)) or not 1 <= min_sensors <= n:
        raise ValueError(f"min_sensors: must be an integer in 1..{n}, got {min_sensors!r}")
    cons = DesignConstraints(n_candidates=n, n_params=p, min_sensors=int(min_sensors))
    if cons.count_designs() > max_rows:
        raise ValueError(f"min_sensors: {cons.count_designs()} combinations exceed max_rows = {max_rows}")
    rows = []
    for W in iter_designs(cons):
        res = batch_criteria(F, S, W, kind_e, settings=settings, validated=True)
        for i in range(len(W)):
            flag = "singular" if res.singular[i] else ("near-singular" if res.near_singular[i] else "")
            rows.append(DesignRow(mask="".join("1" if b else "0" for b in W[i]),
                                  sensors=tuple(names[k] for k in np.flatnonzero(W[i])),
                                  A=float(res.A[i]), det=float(res.det[i]), logdet=float(res.logdet[i]),
                                  E=float(res.E[i]), flag=flag, reason=res.reason[i]))
    rows.sort(key=lambda r: (-len(r.sensors), tuple(-int(c) for c in r.mask)))
    return DesignTable(kind=kind_e.value, rows=tuple(rows))


def _robust_sensors(model, p, info_at, prior, robust, kw):
    """The ``prior=`` route of :func:`select_sensors`: the exact robust design of ``n_sensors`` sensors."""
    from .prior import make_prior
    from .robust_exact import METHODS, select_robust_exact
    allowed = ("n_sensors", "criterion", "method", "time_limit", "sensor_names", "kind")
    bad = [k for k, v in kw.items() if k not in allowed and v not in (None, (), [])]
    if bad:
        raise ValueError(f"{bad[0]}: not used by the exact robust design (prior is given: it chooses exactly "
                         "n_sensors sensors); leave it out")
    second = Kind.parse(kw.get("kind", "gauss_newton")) is Kind.SECOND_ORDER
    method = kw.get("method", "auto")
    if method not in METHODS:
        raise ValueError(f"method: the exact robust design takes 'auto', 'enumerate' or 'bnb', got {method!r}")
    pr = make_prior(prior, model, p)
    infos = [info_at(ps) for ps in pr.points]
    F = np.stack([i.F for i in infos], axis=1)
    n = kw.get("n_sensors") or min(model.n_p, F.shape[0])
    names = kw.get("sensor_names") or list(infos[0].labels)
    opts = dict(criterion=kw.get("criterion", DEFAULT_CRITERION), method=method,
                time_limit=kw.get("time_limit", 60.0), names=list(names))
    if second and any(i.S is not None and np.any(i.S) for i in infos):     # data: S at every vector (oed.sequential_robust)
        from .sequential_robust import robust_sensor_design
        return robust_sensor_design(infos, pr, n, kind="second_order", robust=robust, **opts)
    u_star = None
    if robust == "maximin":
        u_star = np.array([select_robust_exact(F[:, [s]], [1.0], n, **opts).value for s in range(F.shape[1])])
    out = select_robust_exact(F, pr.weights, n, robust=robust, u_star=u_star, **opts)
    return out if not second else replace(out, notes=out.notes + (
        "kind='second_order' without residuals (planned): S = 0 at every parameter vector, so the second-order "
        "criterion is the Gauss-Newton one",))


def select_sensors(model, data, p, *, inputs=None, sigma=None, n_series=1, times=None, prior=None, robust="bayes",
                   **kw):
    r"""Model-level front door: :math:`\min_w \Psi(C(w))` with :math:`(F, S)` from the model at ``p``.

    Calls :func:`oed.candidate_information.information` (axis ``sensors``) for the per-sensor information
    (shapes ``(n_S, n_p, n_p)``) and passes it and the other keyword arguments to
    :func:`select_sensors_from_information`.

    Parameters
    ----------
    model : models.Model
        Static, or dynamic (:meth:`models.Model.ode`; then one candidate per instrument, its readings at every
        time summed).
    data : identification.Measurements or None
        Measurements; ``None`` plans the design before measuring, from ``inputs`` and ``sigma``.
    p : array_like, shape (n_p,)
        Parameters (the estimate, or the nominal values when ``data`` is None).
    inputs : array_like, shape (n_q, d_q), optional
        Input rows that will be applied (only with ``data=None``).
    sigma : array_like, shape (n_S,), optional
        Standard deviation of each sensor, in the sensor's unit (only with ``data=None``).
    n_series : int
        Repetitions of every input (only with ``data=None``; default 1).
    times : array_like, optional
        A dynamic model's sampling times (only with ``data=None``).
    prior : None, (P, w), dict or oed.prior.Prior
        Parameter uncertainty (:func:`oed.prior.make_prior` around ``p``): the exact robust design of ``n_sensors``
        sensors (:func:`oed.robust_exact.select_robust_exact`, Gauss-Newton information at every parameter
        vector; ``criterion``, ``method`` ("auto", "enumerate", "bnb"), ``time_limit``, ``sensor_names`` and
        ``kind`` are read from the keyword arguments, the others refused), returned as a
        :class:`oed.robust_exact.RobustExactDesign`.  ``kind="second_order"`` with data: the second-order
        covariance at every vector (residuals of the data there), by enumeration
        (:func:`oed.sequential_robust.robust_sensor_design`); without data S = 0, so it is the Gauss-Newton
        design (noted).
    robust : {"bayes", "maximin"}
        With a prior: the expected criterion or the worst-case efficiency against each vector's own exact optimum.

    Returns
    -------
    DesignResult, or oed.robust_exact.RobustExactDesign with a prior

    Notes
    -----
    Without data the expected residual at ``p`` is zero, so the second-order term ``S``
    vanishes: ``kind="second_order"`` then gives the Gauss-Newton covariance at the nominal
    ``p`` (recorded in :attr:`DesignResult.notes`).
    """
    if data is not None and (inputs is not None or sigma is not None or times is not None):
        raise ValueError("inputs/sigma: give them only with data=None (measurements carry their own)")

    def info_at(pp):
        if data is None:
            return information(model, pp, inputs=inputs, sigma=sigma, n_series=n_series, times=times)
        return information(model, pp, data=data)
    if prior is not None:
        return _robust_sensors(model, p, info_at, prior, robust, kw)
    info = info_at(p)
    names = kw.pop("sensor_names", None)
    if names is not None:
        info = replace(info, labels=tuple(names))
    res = select_sensors_from_information(info, **kw)
    if data is None:
        note = (f"designed without data at the nominal parameters ({n_series} series of {np.atleast_1d(inputs).shape[0]} "
                "inputs): expected residual 0, so S = 0 and the second-order covariance is the Gauss-Newton one")
        res = replace(res, notes=res.notes + (note,))
    return res
