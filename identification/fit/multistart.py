r"""Multi-start fits: the least-squares problem solved from N starts, the best local minimum kept (issue 30 item 2).

Every start solves the same problem (paper eq. 3, dimensionless objective units)

.. math::

    \min_p \Phi(p) = \tfrac12 \sum_{ijk} w_k \bigl((z_{ijk} - h_k(y_j, p, q_j)) / \sigma_k\bigr)^2
    \quad \text{s.t.} \quad E(y_j, p, q_j) = 0,\quad \text{lower} \le p \le \text{upper},

with the same settings, by :meth:`identification.fit.problem.Problem.fit` (static and dynamic models alike:
the multi-start wraps the problem's strategy, it is not a second estimator).  Start 1 is ``p0``; starts 2..N are
the first N - 1 points u_s in [0, 1)^n_p of a scrambled Sobol sequence (``scipy.stats.qmc.Sobol``: linear
matrix scrambling and a digital random shift, both drawn from ``seed``), mapped per parameter by the documented
rule of :func:`start_rules` (:func:`starts_from_unit`).  The sequence is generated in blocks of a power of two
(``random_base2``: 2^m >= N - 1 points, the first N - 1 kept), so any N is accepted without scipy's balance
warning; the starts of a smaller N are the first rows of those of a larger one with the same seed (adding starts
keeps the earlier ones).  The first 2^m points of the sequence are stratified in every coordinate (one point in
each interval [k / 2^m, (k + 1) / 2^m)) and, unlike a Latin hypercube, jointly in the first two coordinates (a
(0, m, 2)-net: one point in each elementary box of area 2^-m).  The rules:

* both bounds finite, ``lower > 0`` and ``upper / lower >= 100`` (a positive parameter whose bounds span two
  decades or more): log-uniform in [lower, upper];
* both bounds finite otherwise (a rate bounded at 0 included): uniform in [lower, upper];
* only a lower bound: ``lower + d 10^U`` with U uniform in (-1, 1) and d = p0 - lower (d = the parameter's scale
  when p0 is on the bound): log scale around p0, a decade either way, never below the bound; only an upper
  bound: the mirror image;
* no bound: ``p0 + 3 s U`` with U uniform in (-1, 1) and s the parameter's scale (its declared scale, else
  |p0|, else 1): linear, not log, around p0, because a parameter without bounds may change sign, which a log
  scale around p0 never reaches.

A start *reaches a minimum* when its fit passes every check of the estimator (Ipopt's termination or the exact
Newton verification, the second-order test of a minimum, identifiability, finite standard errors); a start that
raises is recorded with its error (never silent), one whose fit does not bound the parameters is recorded as
"not bounded".  The result is the estimate of the lowest objective; among the starts within the objective
tolerance of it (:data:`OBJECTIVE_RTOL`), the first (p0 first): when p0 reaches the global minimum the estimate
is the single-start one, bit for bit.  Two starts found the same minimum when their objectives agree within the
tolerance and their parameters within :data:`PARAMETER_TOL_SE` standard errors of the best estimate.

*Flat valleys.*  Starts that run along a direction the data do not determine stop at different points of it with
the same objective; the parameter rule above then splits them into many "minima" that are one.  Two minima are
merged (single linkage: a chain of merges is one entry) when their objectives agree within the valley tolerance
:math:`\tau_v = \min(\tau, \chi^2_v / 2)` (:math:`\tau` the objective tolerance above, OBJECTIVE_RTOL
max(1, |Phi_best|); :data:`VALLEY_CHI2` = 0.01, so that :math:`2 \Delta\Phi`, the change of the chi-square statistic
of the likelihood ratio, stays far below 1, let alone the 3.84 of one parameter's 95 % chi-square quantile) *and*
they are connected: for a static model Phi is evaluated at :data:`VALLEY_POINTS` evenly spaced interior points of
the straight segment between the closest members of the two (the outputs h(y(p), p, q_j) by
:func:`models.state.simulate`, the weights and sigmas of the estimate) and the segment rises nowhere more than
:math:`\tau_v` above the higher end (no barrier); for a dynamic model, whose objective at a point needs a
controlled integration, the segment is not evaluated and nothing is merged: equal objectives alone cannot tell a
valley from symmetric minima (the note says the minimum is not unique; :func:`distinct_minima` with ``phi=None``
merges by the objectives alone and says so, for callers that know their minima are connected).  A
merged entry reports the range of each parameter over its starts; the parameters whose range exceeds
:data:`PARAMETER_TOL_SE` standard errors are those that move along the valley, and the note names them, their
range and the objective; for one such parameter of a static model, Phi at its bound (the member nearest the bound
moved onto it) says whether the valley runs on to the bound.  Minima with different objectives, or with a barrier
between them, stay apart.

With sigma unknown every fit estimates its own s, and its objective is 0.5 (n - n_p) by construction; starts are
then compared by 0.5 sum w_k r^2 / s_best^2 (the objective of each start with the best estimate's s), so that
the best start's value is the estimate's objective.

Messages number the starts from 1 (start 1 is p0); the arrays of :class:`MultiStartRecord` are indexed from 0.
The starts run on the replication engine (:mod:`identification.replicate`): serially in this process
(``workers=1``), on local processes or a Dask scheduler; with more than one process the estimate of the best
start is fitted once more in this process (its full record is not shipped back), so the estimate is the same on
every backend.
"""
from __future__ import annotations

import contextlib
import dataclasses
import functools
import math
import time
import warnings
from dataclasses import dataclass

import numpy as np
from scipy.stats import qmc

from models.state import jit_enabled, simulate
from identification import cluster
from identification.errors import IdentificationError
from identification.fit.record import FitRecord
from identification.fit.start import checked_start, param_scale
from identification.replicate import ReplicationTask, replicate
from identification.results_protocol import jsonable

__all__ = ["MultiStartRecord", "LocalMinimum", "MultiStartError", "draw_starts", "start_rules", "fit_starts",
           "check_starts", "sobol_points", "starts_from_unit", "OBJECTIVE_RTOL", "PARAMETER_TOL_SE", "LOG_DECADES",
           "VALLEY_CHI2", "VALLEY_POINTS", "static_objective", "distinct_minima", "StartFit"]

#: a start reached the best minimum when its objective is within this of the best, relative to max(1, |best|)
OBJECTIVE_RTOL = 1e-6
#: two starts at one minimum: parameters within this many standard errors (of the best estimate) of each other
PARAMETER_TOL_SE = 1e-2
#: a positive parameter whose bounds span this ratio (two decades) or more is sampled in log scale
LOG_DECADES = 100.0

#: two minima on one flat valley: 2 x their objective difference (chi-square units) below this, whatever Phi
VALLEY_CHI2 = 1e-2
#: interior points of the segment between two minima at which a static model's objective is evaluated
VALLEY_POINTS = 5

#: the outcomes of a start
MINIMUM, NOT_BOUNDED, FAILED = "minimum", "not bounded", "failed"


class MultiStartError(IdentificationError):
    """Every start of a multi-start fit failed (the message names the first starts' errors).

    Attributes
    ----------
    starts : ndarray (N, n_p)   the start values (row 0: p0)
    errors : tuple of str       per start, why its fit failed
    """

    def __init__(self, message: str, starts=None, errors=()):
        super().__init__(message, status="all starts failed")
        self.starts = starts
        self.errors = tuple(errors)


# ---------------------------------------------------------------------------- the starts
def check_starts(starts) -> int:
    """``starts`` as an int >= 1; ValueError naming the argument otherwise."""
    if isinstance(starts, (bool, np.bool_)) or not isinstance(starts, (int, np.integer)) or starts < 1:
        raise ValueError(f"starts: expected a positive integer (1: the fit from p0 alone), got {starts!r}")
    return int(starts)


def _seed_sequence(seed) -> np.random.SeedSequence:
    if isinstance(seed, np.random.SeedSequence):
        return seed
    if seed is None:
        return np.random.SeedSequence()
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed: expected an integer >= 0, a numpy SeedSequence or None (fresh entropy, recorded), "
                         f"got {seed!r}")
    return np.random.SeedSequence(int(seed))


def start_rules(model, p0) -> tuple:
    """x = rule(u), u uniform in [0, 1): per parameter, how starts 2..N are drawn (see the module docstring):
    (kind, a, b) with kind "fixed" (value a), "log" (a (b / a)^u), "uniform" (a + u (b - a)), "above"
    (a + b 10^(2u - 1)), "below" (a - b 10^(2u - 1)) or "around" (a + 3 b (2u - 1))."""
    p0 = checked_start(model, p0)
    s = param_scale(model, p0)
    rules = []
    for i, par in enumerate(model.params):
        lo, up = par.lower, par.upper
        if math.isfinite(lo) and math.isfinite(up):
            if up == lo:
                rules.append(("fixed", lo, lo))
            elif lo > 0 and up / lo >= LOG_DECADES:
                rules.append(("log", lo, up))
            else:
                rules.append(("uniform", lo, up))
        elif math.isfinite(lo):
            rules.append(("above", lo, p0[i] - lo if p0[i] > lo else s[i]))
        elif math.isfinite(up):
            rules.append(("below", up, up - p0[i] if p0[i] < up else s[i]))
        else:
            rules.append(("around", p0[i], s[i]))
    return tuple(rules)


def _rule_text(name: str, rule: tuple) -> str:
    kind, a, b = rule
    return {"fixed": f"{name} = {a:g} (lower = upper)", "log": f"{name} log-uniform in [{a:g}, {b:g}]",
            "uniform": f"{name} uniform in [{a:g}, {b:g}]", "above": f"{name} = {a:g} + {b:g} 10^U(-1,1)",
            "below": f"{name} = {a:g} - {b:g} 10^U(-1,1)", "around": f"{name} = {a:g} +- 3 x {b:g} U(-1,1)"}[kind]


def sobol_points(d: int, n: int, seed=0) -> np.ndarray:
    """u_s, s = 1..n: the first ``n`` points of a scrambled Sobol sequence in [0, 1)^d (dimensionless), the
    scrambling drawn from ``seed`` (an int >= 0, a SeedSequence or None).  Generated as 2^m >= n points by
    ``random_base2`` (no balance warning for an ``n`` that is not a power of two), the first ``n`` kept: the points
    of a smaller ``n`` are the first rows of those of a larger one."""
    rng = np.random.default_rng(_seed_sequence(seed))
    try:
        engine = qmc.Sobol(d, scramble=True, rng=rng)
    except TypeError:                       # scipy < 1.15 names the generator ``seed``
        engine = qmc.Sobol(d, scramble=True, seed=rng)
    if n < 1:
        return np.empty((0, d))
    return engine.random_base2(max(0, math.ceil(math.log2(n))))[:n]


def _mapped(rule: tuple, u: np.ndarray) -> np.ndarray:
    """The values x = rule(u) of one parameter (:func:`start_rules`)."""
    kind, a, b = rule
    if kind == "fixed":
        return np.full_like(u, a)
    if kind == "log":
        return a * (b / a) ** u
    if kind == "uniform":
        return a + u * (b - a)
    if kind == "above":
        return a + b * 10.0 ** (2 * u - 1)
    if kind == "below":
        return a - b * 10.0 ** (2 * u - 1)
    return a + 3 * b * (2 * u - 1)                 # "around"


def starts_from_unit(model, p0, u) -> np.ndarray:
    """x_si = rule_i(u_si) (:func:`start_rules`), clipped to the bounds: the starts (parameter units) of the points
    ``u`` (n, n_p) in [0, 1)^n_p (dimensionless), e.g. :func:`sobol_points` or any other design of the unit cube."""
    p0 = checked_start(model, p0)
    u = np.asarray(u, float)
    if u.ndim != 2 or u.shape[1] != model.n_p or np.any(~((u >= 0) & (u <= 1))):
        raise ValueError(f"u: expected points in [0, 1]^{model.n_p} as an array (n, {model.n_p}), got shape "
                         f"{u.shape}")
    out = np.tile(p0, (u.shape[0], 1))
    for i, rule in enumerate(start_rules(model, p0)):
        par = model.params[i]
        out[:, i] = np.clip(_mapped(rule, u[:, i]), par.lower, par.upper)
    return out


def draw_starts(model, p0, n: int, seed=0) -> tuple:
    """x_s = rule(u_s), u_s in [0, 1)^n_p the first n - 1 points of a scrambled Sobol sequence: the ``n`` starts of
    a multi-start fit (parameter units); row 0 is p0, rows 1..n-1 the points :func:`sobol_points` draws from
    ``seed`` (an int >= 0, a SeedSequence, or None for fresh entropy) mapped by :func:`start_rules`.

    Returns
    -------
    starts : ndarray (n, n_p)    parameter units, inside the bounds
    rules : tuple of str         how each parameter was drawn
    entropy : int                the seed's entropy (``seed=entropy`` draws the same starts again)
    """
    n = check_starts(n)
    ss = _seed_sequence(seed)
    p0 = checked_start(model, p0)
    rules = start_rules(model, p0)
    out = np.tile(p0, (n, 1))
    if n > 1:
        out[1:] = starts_from_unit(model, p0, sobol_points(model.n_p, n - 1, ss))
    names = tuple(par.name for par in model.params)
    return out, tuple(_rule_text(nm, r) for nm, r in zip(names, rules)), int(ss.entropy)


# ---------------------------------------------------------------------------- one start
@dataclass(frozen=True, eq=False)
class StartFit:
    """The fit from one start (the record of :class:`StartTask`; ``record`` None when it ran in another process).

    Attributes
    ----------
    index : int              the start (0: p0)
    outcome : str            "minimum", "not bounded" or "failed"
    p : ndarray (n_p,)       the estimate (NaN when failed)
    objective : float        the fit's objective; for a fit that runs off, the infimum its objective tends to
                             (NaN when failed)
    sigma0 : float           the common sigma the fit estimated (sigma unknown), else 1
    status : str             the solver's status, or the error's
    error : str              why the start failed ("" otherwise)
    warnings : tuple of str  the warnings its fit issued (start 1's, when it runs in this process, go to the
                             caller as in a single fit and are not repeated here)
    fit_time : float         s
    record : FitRecord or None
    """

    index: int
    outcome: str
    p: np.ndarray
    objective: float
    sigma0: float
    status: str
    error: str
    warnings: tuple
    fit_time: float
    record: object = None


def _fit_one(problem, p0, index: int, weights, settings, Y0, capture: bool, keep: bool) -> StartFit:
    """Fit ``problem`` from ``p0`` and record the outcome (an error of the solver is recorded, not raised)."""
    t0 = time.perf_counter()
    caught = []
    nan = np.full(np.size(p0), np.nan)
    with warnings.catch_warnings(record=True) if capture else contextlib.nullcontext(()) as got:
        if capture:
            warnings.simplefilter("always")
        try:
            rec = problem.strategy.fit(problem, p0, weights=weights, settings=settings, Y0=Y0)
        except (RuntimeError, ArithmeticError, np.linalg.LinAlgError) as exc:
            # IdentificationError, ConvergenceError, StateSolveError (all RuntimeError), CasADi's evaluation
            # errors; bad input (DataError, TypeError) is not caught: it is the same for every start
            rec = None
            err = f"{type(exc).__name__}: {exc}"
            status = str(getattr(exc, "status", "") or type(exc).__name__)
        if capture:
            caught = [f"{w.category.__name__}: {w.message}" for w in got]
    dt = time.perf_counter() - t0
    if rec is None:
        return StartFit(index, FAILED, nan, float("nan"), 1.0, status, err, tuple(caught), dt)
    outcome = MINIMUM if rec.unbounded is None else NOT_BOUNDED
    sigma0 = float(rec.sigma[0]) if rec.sigma_estimated and np.size(rec.sigma) else 1.0
    phi = float(rec.objective if rec.unbounded is None else rec.unbounded.objective_limit)
    return StartFit(index, outcome, np.array(rec.p, float), phi, sigma0, str(rec.status), "",
                    tuple(caught), dt, rec if keep else None)


@dataclass(frozen=True, eq=False)
class StartTask(ReplicationTask):
    """The starts of one multi-start fit (sent once to every worker): chunk [(index, seed)] -> [StartFit]."""

    problem: object
    starts: np.ndarray
    weights: object
    settings: object
    Y0: object
    keep_records: bool
    jit: bool

    def run_chunk(self, chunk: list) -> list:
        return [_fit_one(self.problem, self.starts[i], i, self.weights, self.settings, self.Y0 if i == 0 else None,
                         capture=i > 0 or not self.keep_records, keep=self.keep_records) for i, _ in chunk]


# ---------------------------------------------------------------------------- the record
@dataclass(frozen=True, eq=False)
class LocalMinimum:
    """One distinct local minimum found by the starts.

    Attributes
    ----------
    objective : float        Phi at the minimum (the estimate's objective units)
    p : ndarray (n_p,)       the parameters there (the best minimum: the estimate's; another: those of its
                             start of lowest objective)
    starts : tuple of int    the starts (0-based rows) that reached it
    p_low, p_high : ndarray (n_p,)   the smallest and largest value of each parameter over those starts (default p)
    objective_high : float   the largest objective over those starts (default ``objective``)
    flat : tuple of str      the parameters that move along a flat valley through its starts (their range exceeds
                             PARAMETER_TOL_SE standard errors); () for an isolated minimum
    connection : str         how the valley's starts were found connected: "segment" (Phi evaluated between
                             them), "objective" (objectives only: a dynamic model); "" when isolated
    valley : str             the sentence of the note on the valley ("" when isolated)
    """

    objective: float
    p: np.ndarray
    starts: tuple
    p_low: np.ndarray | None = None
    p_high: np.ndarray | None = None
    objective_high: float = float("nan")
    flat: tuple = ()
    connection: str = ""
    valley: str = ""

    def __post_init__(self):
        for name in ("p_low", "p_high"):
            if getattr(self, name) is None:
                object.__setattr__(self, name, np.array(self.p, float))
        if math.isnan(self.objective_high):
            object.__setattr__(self, "objective_high", float(self.objective))

    @property
    def count(self) -> int:
        return len(self.starts)

    @property
    def is_valley(self) -> bool:
        """Its starts lie along a flat valley (not an isolated minimum)."""
        return bool(self.flat)


@dataclass(frozen=True, eq=False)
class MultiStartRecord:
    r"""How the starts of a multi-start fit ended (``est.diagnostics.starts``; see the module docstring).

    Attributes
    ----------
    param_names : tuple of str
    starts : ndarray (N, n_p)     the start values (row 0: p0), parameter units
    p : ndarray (N, n_p)          each start's estimate (NaN where it failed)
    objective : ndarray (N,)      each start's Phi in the estimate's objective units: at its minimum, or for a
                                  fit the data do not bound the infimum its objective tends to; NaN when failed
    outcome : tuple of str        per start: "minimum", "not bounded" or "failed"
    status : tuple of str         per start: the solver's status, or the error's
    errors : tuple of str         per start: why it failed ("" otherwise)
    warnings : tuple of tuple     per start: the warnings its fit issued (start 1's in this process: issued to
                                  the caller as in a single fit instead)
    fit_time : ndarray (N,)       per start, s
    best : int                    the start whose estimate is returned
    reached_best : int            starts whose objective is within ``objective_tol`` of the best
    minima : tuple of LocalMinimum    the distinct minima, best first
    objective_tol : float         absolute, objective units (OBJECTIVE_RTOL max(1, |best|))
    parameter_tol_se : float      PARAMETER_TOL_SE
    rules : tuple of str          how each parameter's starts were drawn
    seed : int                    the entropy of the seed (``seed=`` draws the same starts)
    backend : str                 where the starts ran ("serial", "2 local processes", ...)
    wall_time : float             s, all starts
    valley_tol : float            objective units: minima on one flat valley agree within this (min(objective_tol,
                                  VALLEY_CHI2 / 2)); NaN: nothing merged (a dynamic model, no minimum, not recorded)
    """

    param_names: tuple
    starts: np.ndarray
    p: np.ndarray
    objective: np.ndarray
    outcome: tuple
    status: tuple
    errors: tuple
    warnings: tuple
    fit_time: np.ndarray
    best: int
    reached_best: int
    minima: tuple
    objective_tol: float
    parameter_tol_se: float
    rules: tuple
    seed: int
    backend: str
    wall_time: float
    valley_tol: float = float("nan")

    @property
    def n_starts(self) -> int:
        return int(self.starts.shape[0])

    @property
    def failed(self) -> tuple:
        """The 0-based rows of the starts that failed."""
        return tuple(i for i, o in enumerate(self.outcome) if o == FAILED)

    def note(self) -> str:
        """The summary's note: how many starts reached the best minimum, the other minima, the failures."""
        n, m = self.n_starts, len(self.minima)
        parts = [f"multi-start: {self.reached_best} of {n} starts reached the best minimum (objective "
                 f"{self.minima[0].objective:.6g}, within {self.objective_tol:.2g}); {m} distinct local "
                 f"minim{'um' if m == 1 else 'a'}"]
        if m > 1:
            nxt = self.minima[1]
            same = " (the same objective at other parameters: the minimum is not unique)" \
                if nxt.objective - self.minima[0].objective <= self.objective_tol else ""
            parts[0] += (f", the next best at objective {nxt.objective:.6g}{same} ("
                         + ", ".join(f"{nm} = {v:.4g}" for nm, v in zip(self.param_names, nxt.p))
                         + f"; {nxt.count} start{'s' if nxt.count > 1 else ''})")
        parts += [m.valley for m in self.minima if m.valley]
        if self.best != 0:
            p0_end = (f"ended at objective {self.objective[0]:.6g}" if self.outcome[0] == MINIMUM
                      else f"{self.outcome[0]} ({self.status[0]})")
            parts.append(f"the estimate is that of start {self.best + 1}; p0 (start 1) {p0_end}")
        bad = self.failed
        if bad:
            parts.append(f"{len(bad)} start{'s' if len(bad) > 1 else ''} failed ("
                         + "; ".join(f"start {i + 1}: {_short(self.errors[i])}" for i in bad[:3])
                         + ("; ..." if len(bad) > 3 else "") + ")")
        nb = [i for i, o in enumerate(self.outcome) if o == NOT_BOUNDED]
        if nb:
            limit = float(np.min(self.objective[nb]))
            below = (": below the best minimum, which is then only local; the lowest objective is approached at "
                     "infinity, where the data do not bound the parameters"
                     if limit < self.minima[0].objective - self.objective_tol else "")
            parts.append(f"{len(nb)} start{'s' if len(nb) > 1 else ''} ended on a fit the data do not bound "
                         f"(start{'s' if len(nb) > 1 else ''} {', '.join(str(i + 1) for i in nb[:5])}; the "
                         f"objective tends to {limit:.6g} as the parameters run off{below})")
        parts.append(f"starts: p0 and {n - 1} Sobol points ({'; '.join(self.rules)}; seed {self.seed}), "
                     f"{self.backend}; the tables: est.diagnostics.starts.to_frame() and .minima_frame()")
        return "; ".join(parts)

    def to_dict(self) -> dict:
        """The record as JSON-safe values (a report's results.json): per start (lists in start order, start 1 =
        p0 first) its values, estimate, objective, outcome, status, error and time; the distinct minima (best
        first: objective, parameters, the 1-based starts that reached each); best (1-based), reached_best, the
        tolerances, rules, seed, backend and wall time (NaN as null)."""
        return jsonable(dict(param_names=list(self.param_names), n_starts=self.n_starts, starts=self.starts,
                             p=self.p, objective=self.objective, outcome=list(self.outcome),
                             status=list(self.status), errors=list(self.errors), fit_time=self.fit_time,
                             best=self.best + 1, reached_best=self.reached_best,
                             minima=[dict(objective=m.objective, p=m.p, starts=[i + 1 for i in m.starts],
                                          p_low=m.p_low, p_high=m.p_high, objective_high=m.objective_high,
                                          flat=list(m.flat), connection=m.connection, valley=m.valley)
                                     for m in self.minima],
                             objective_tol=self.objective_tol, parameter_tol_se=self.parameter_tol_se,
                             valley_tol=self.valley_tol,
                             rules=list(self.rules), seed=self.seed, backend=self.backend,
                             wall_time=self.wall_time))

    def minima_frame(self):
        """The distinct local minima, best first (``minimum`` 1, 2, ...): objective, how many starts reached each,
        which (numbered from 1), the parameters there, the parameters that move along a flat valley through its
        starts ("" when isolated) and each parameter's range over its starts (``<name> low``, ``<name> high``)."""
        import pandas as pd
        cols = {"objective": [m.objective for m in self.minima], "starts": [m.count for m in self.minima],
                "reached from": [", ".join(str(i + 1) for i in m.starts) for m in self.minima]}
        cols.update({nm: [m.p[i] for m in self.minima] for i, nm in enumerate(self.param_names)})
        cols["flat"] = [", ".join(m.flat) for m in self.minima]
        for i, nm in enumerate(self.param_names):
            cols[f"{nm} low"] = [m.p_low[i] for m in self.minima]
            cols[f"{nm} high"] = [m.p_high[i] for m in self.minima]
        return pd.DataFrame(cols, index=pd.Index(np.arange(1, len(self.minima) + 1), name="minimum"))

    def to_frame(self):
        """One row per start (1-based ``start``): its values, outcome, status, objective, estimate, the minimum it
        reached (1 = best, 0 = none) and the error."""
        import pandas as pd
        rank = np.zeros(self.n_starts, int)
        for k, mnm in enumerate(self.minima, 1):
            rank[list(mnm.starts)] = k
        cols = {"outcome": list(self.outcome), "status": list(self.status), "objective": self.objective,
                "minimum": rank}
        cols.update({f"start {nm}": self.starts[:, i] for i, nm in enumerate(self.param_names)})
        cols.update({nm: self.p[:, i] for i, nm in enumerate(self.param_names)})
        cols["error"] = list(self.errors)
        return pd.DataFrame(cols, index=pd.Index(np.arange(1, self.n_starts + 1), name="start"))


# ---------------------------------------------------------------------------- the driver
def _clusters(fits, objective, tol, se, chosen: int) -> list:
    """The starts that reached a minimum, grouped by the point rule (objectives within ``tol``, parameters within
    PARAMETER_TOL_SE ``se``): [objective, p, members], the group of the ``chosen`` start first (its objective and
    parameters), then the others by objective (each with its lowest start's values)."""
    order = [chosen] + sorted((f.index for f in fits if f.outcome == MINIMUM and f.index != chosen),
                              key=lambda i: (objective[i], i))
    groups = []
    for i in order:
        p = fits[i].p
        for g in groups:
            if abs(objective[i] - g[0]) <= tol and np.all(np.abs(p - g[1]) <= PARAMETER_TOL_SE * se):
                g[2].append(i)
                break
        else:
            groups.append((objective[i], p, [i]))
    return groups[:1] + sorted(groups[1:], key=lambda g: g[0])


def static_objective(problem, weights, sigma):
    r"""p -> Phi(p) = 0.5 sum_k w_k sum_ij ((z_ijk - h_k(y_j(p), p, q_j)) / sigma_k)^2 (dimensionless, paper eq. 3)
    of a static problem, the states solved at p (:func:`models.state.simulate`), ``weights`` and ``sigma`` (n_S,)
    those of the estimate; NaN values of z are skipped; inf where the states cannot be solved or h is not
    finite."""
    z = np.asarray(problem.data.z, float)
    c = np.asarray(weights, float) / np.asarray(sigma, float) ** 2
    inputs = problem.data.inputs

    def phi(p) -> float:
        try:
            h = simulate(problem.model, p, inputs)
        except (RuntimeError, ArithmeticError, np.linalg.LinAlgError):
            return float("inf")
        if not np.all(np.isfinite(h)):
            return float("inf")
        return 0.5 * float(np.nansum(c * (z - h[None]) ** 2))
    return phi


def _connected(phi, pa: np.ndarray, pb: np.ndarray, tol: float) -> bool:
    """No barrier between pa and pb: Phi at VALLEY_POINTS interior points of the straight segment rises at most
    ``tol`` (objective units) above the higher of Phi(pa), Phi(pb) (both evaluated by ``phi`` as well)."""
    ends = max(phi(pa), phi(pb))
    if not math.isfinite(ends):
        return False
    for t in np.arange(1, VALLEY_POINTS + 1) / (VALLEY_POINTS + 1):
        if not phi(pa + t * (pb - pa)) - ends <= tol:
            return False
    return True


def _merged(groups, fits, objective, se, vtol: float, phi) -> list:
    """Single linkage of the point groups along flat valleys: two groups join when the closest pair of their starts
    (in standard errors) has objectives within ``vtol`` and, with ``phi`` (a static model), no barrier between
    them (:func:`_connected`).  [root group, members] per entry, in the order of ``groups``."""
    root = list(range(len(groups)))

    def find(a):
        while root[a] != a:
            a = root[a]
        return a
    for a in range(len(groups)):
        for b in range(a + 1, len(groups)):
            if find(a) == find(b):
                continue
            i, j = min(((i, j) for i in groups[a][2] for j in groups[b][2]),
                       key=lambda ij: float(np.sum(((fits[ij[0]].p - fits[ij[1]].p) / se) ** 2)))
            if abs(objective[i] - objective[j]) <= vtol and (phi is None or _connected(phi, fits[i].p, fits[j].p,
                                                                                          vtol)):
                root[find(b)] = find(a)
    out = []
    for a in range(len(groups)):
        if find(a) == a:
            out.append((groups[a], [i for b in range(len(groups)) if find(b) == a for i in groups[b][2]]))
    return out


def distinct_minima(fits, objective, tol, se, chosen: int, *, vtol: float = -1.0, phi=None, names=(), model=None) -> tuple:
    """The distinct minima among the starts that reached one (:func:`_clusters`), those along one flat valley merged
    (:func:`_merged`, objectives within ``vtol``, objective units, < 0: no merging, the point rule alone; ``phi``
    the static objective p -> Phi (:func:`static_objective`), None: objectives only): the minimum of the ``chosen``
    start first, then the others by objective.  ``fits``: StartFit per start; ``objective`` (N,) their Phi; ``tol``
    and ``se`` (n_p,) the point rule's objective tolerance and scale; ``names`` the parameters; ``model`` (its
    bounds) for the note's bound test."""
    out = []
    for (obj, p, _), members in _merged(_clusters(fits, objective, tol, se, chosen), fits, objective, se, vtol, phi):
        P = np.array([fits[i].p for i in members])
        lo, hi = P.min(axis=0), P.max(axis=0)
        flat = tuple(nm for nm, d, s in zip(names, hi - lo, se) if d > PARAMETER_TOL_SE * s)
        ohi = float(max(objective[i] for i in members))
        m = LocalMinimum(float(obj), np.array(p), tuple(sorted(members)), lo, hi, ohi, flat,
                         ("segment" if phi is not None else "objective") if flat else "")
        if flat:
            m = dataclasses.replace(m, valley=_valley_text(m, P, tuple(names), model, phi, vtol))
        out.append(m)
    return tuple(out)


def _to_bound(P: np.ndarray, k: int, phi_high: float, model, phi, vtol: float) -> str:
    """"upper" / "lower" when Phi is as low (within ``vtol`` of ``phi_high``, the valley's highest objective) at
    parameter k's bound, the valley's start nearest that bound moved onto it (``P``: the starts' parameters, one row
    each), as along the valley; "" otherwise, when the starts end far from the bound (farther than their own range)
    or without ``phi``."""
    if phi is None or model is None:
        return ""
    par = model.params[k]
    span = float(np.ptp(P[:, k]))
    for side, bound, row in (("upper", par.upper, int(np.argmax(P[:, k]))),
                             ("lower", par.lower, int(np.argmin(P[:, k])))):
        if not math.isfinite(bound) or abs(bound - P[row, k]) > span:
            continue
        q = np.array(P[row], float)
        q[k] = bound
        if phi(q) - phi_high <= vtol:
            return side
    return ""


def _valley_text(m: LocalMinimum, P: np.ndarray, names: tuple, model, phi, vtol: float) -> str:
    """The note's sentence on a flat valley: which parameters move, over what range, at what objective, how the
    starts were found connected."""
    idx = [names.index(nm) for nm in m.flat]
    n = m.count
    rest = [f"{nm} stays between {m.p_low[i]:.6g} and {m.p_high[i]:.6g}" if m.p_high[i] > m.p_low[i] else
            f"{nm} stays at {m.p[i]:.6g}" for i, nm in enumerate(names) if nm not in m.flat]
    kept = f"; along it {', '.join(rest)}" if rest else ""
    if len(idx) == 1:
        k, nm = idx[0], m.flat[0]
        lo, hi = m.p_low[k], m.p_high[k]
        side = _to_bound(P, k, m.objective_high, model, phi, vtol)
        if side:
            b = model.params[k].upper if side == "upper" else model.params[k].lower
            head = (f"{nm} is not determined by the data {'above' if side == 'upper' else 'below'} "
                    f"{_num(lo if side == 'upper' else hi)}: {n} starts ended along a flat valley from {_num(lo)} to "
                    f"{_num(hi)}, which runs on to its {side} bound {_num(b)} (the objective there is the same)")
        else:
            head = (f"{nm} is not determined by the data between {_num(lo)} and {_num(hi)}: {n} starts ended along "
                    f"a flat valley over that range")
    else:
        head = (f"{' and '.join(m.flat)} are not determined separately by the data: {n} starts ended along a flat "
                f"valley (" + ", ".join(f"{names[k]} from {_num(m.p_low[k])} to {_num(m.p_high[k])}" for k in idx)
                + ")")
    how = (f"no barrier at {VALLEY_POINTS} points of the segment between neighbouring starts" if m.connection ==
           "segment" else "the objective between them not evaluated (a dynamic model): merged by the objectives alone")
    return (f"{head}{kept} (objective {m.objective:.8g} to {m.objective_high:.8g} over starts "
            f"{', '.join(str(i + 1) for i in m.starts[:8])}{', ...' if n > 8 else ''}: equal within "
            f"{_num(m.objective_high - m.objective, 2)}, below the valley tolerance {_num(vtol, 2)} ("
            f"{_num(2 * vtol, 2)} in chi-square units, far below 1), and {how}: one valley, not distinct minima)")


def _num(x: float, digits: int = 3) -> str:
    """x with ``digits`` significant digits, an exponent without '+' and leading zeros (3.1e4, 1e5, 2.5e-6)."""
    text = f"{x:.{digits}g}"
    if "e" not in text:
        return text
    mant, exp = text.split("e")
    return f"{mant}e{int(exp)}"


def _short(text: str, limit: int = 160) -> str:
    return text if len(text) <= limit else text[:limit].rsplit(" ", 1)[0] + " ..."


def _failure(fits, n: int, X: np.ndarray) -> MultiStartError:
    lines = "; ".join(f"start {f.index + 1}{' (p0)' if f.index == 0 else ''}: {_short(f.error, 300)}"
                      for f in fits[:3])
    more = f"; and {n - 3} more" if n > 3 else ""
    return MultiStartError(f"all {n} starts failed: {lines}{more}; try other start values, bounds on the "
                           "parameters or more starts", X, tuple(f.error for f in fits))


def fit_starts(problem, p0, starts: int, *, weights=None, settings=None, Y0=None, seed=0, workers: int | None = 1,
               scheduler=None) -> FitRecord:
    """min over the local minima p_s of Phi (paper eq. 3, objective units) reached from p0 and ``starts - 1`` drawn
    starts (see the module docstring): the record of the best with ``diagnostics.starts`` a
    :class:`MultiStartRecord` and its note.

    Parameters
    ----------
    problem : identification.fit.problem.Problem
    p0 : array_like (n_p,)          start 1 (inside the bounds), parameter units
    starts : int >= 1               the number of starts, p0 included
    weights, settings, Y0           as for :meth:`Problem.fit` (``Y0`` for start 1 only)
    seed : int >= 0, SeedSequence or None   draws starts 2..N (:func:`draw_starts`)
    workers : int or None           local processes (1: serially here; None: every core)
    scheduler : Dask address or distributed.Client, optional

    Raises
    ------
    ValueError
        ``starts``, ``seed`` or ``workers`` malformed (the message names it).
    MultiStartError
        Every start failed (the message names each error).
    """
    n = check_starts(starts)
    if workers is not None and (isinstance(workers, (bool, np.bool_)) or not isinstance(workers, (int, np.integer))
                                or workers < 1):
        raise ValueError(f"workers: must be an integer >= 1 or None (all cores), got {workers!r}")
    scheduler = cluster.check_scheduler(scheduler)
    model = problem.model
    X, rules, entropy = draw_starts(model, p0, n, seed)
    t0 = time.perf_counter()
    keep = scheduler is None and workers == 1
    task = StartTask(problem, X, weights, settings, Y0, keep, jit_enabled())
    reps = replicate(task, n, functools.partial(cluster.seed_chunks, n, 0, chunk_size=1), workers=workers,
                     scheduler=scheduler)
    fits = list(reps.records)
    ok = [f for f in fits if f.outcome == MINIMUM]
    if not ok:
        unb = [f for f in fits if f.outcome == NOT_BOUNDED]
        if not unb:
            raise _failure(fits, n, X)
        chosen = unb[0].index       # no finite minimum: the first fit that runs off, as one start would give
        objective = np.array([f.objective if f.outcome == NOT_BOUNDED else np.nan for f in fits])
        tol, vtol, minima, reached = float("nan"), float("nan"), (), 0
        rec = _record(problem, fits[chosen], X, weights, settings, Y0)
    else:
        raw = np.array([f.objective * f.sigma0 ** 2 for f in fits])
        low = min(ok, key=lambda f: (raw[f.index], f.index))
        objective = np.where([f.outcome != FAILED for f in fits], raw / low.sigma0 ** 2, np.nan)
        tol = OBJECTIVE_RTOL * max(1.0, abs(objective[low.index]))
        near = [f.index for f in ok if objective[f.index] - objective[low.index] <= tol]
        chosen, reached = near[0], len(near)
        rec = _record(problem, fits[chosen], X, weights, settings, Y0)
        se = np.where(np.isfinite(rec.stderr) & (rec.stderr > 0), rec.stderr, param_scale(model, X[0]))
        phi = None if problem.strategy.takes_time_series else static_objective(problem, rec.weights, rec.sigma)
        vtol = min(tol, VALLEY_CHI2 / 2) if phi is not None else float("nan")      # dynamic: no valley merging
        minima = distinct_minima(fits, objective, tol, se, chosen, vtol=vtol if phi is not None else -1.0, phi=phi,
                         names=tuple(par.name for par in model.params), model=model)
    ms = MultiStartRecord(param_names=tuple(par.name for par in model.params), starts=X,
                          p=np.array([f.p for f in fits]), objective=objective,
                          outcome=tuple(f.outcome for f in fits), status=tuple(f.status for f in fits),
                          errors=tuple(f.error for f in fits), warnings=tuple(f.warnings for f in fits),
                          fit_time=np.array([f.fit_time for f in fits]), best=chosen, reached_best=reached,
                          minima=minima, objective_tol=tol, parameter_tol_se=PARAMETER_TOL_SE, rules=rules,
                          seed=entropy, backend=str(reps.backend), wall_time=time.perf_counter() - t0,
                          valley_tol=vtol)
    note = ms.note() if minima else (f"multi-start: none of the {n} starts reached a finite minimum; the estimate is "
                                     f"that of start {chosen + 1}, whose fit the data do not bound")
    return _with_starts(rec, ms, note)


def _record(problem, fit: StartFit, X: np.ndarray, weights, settings, Y0) -> FitRecord:
    """The full record of the start ``fit``: its own, or (when it ran in another process) its fit again here."""
    if fit.record is not None:
        return fit.record
    i = fit.index
    again = _fit_one(problem, X[i], i, weights, settings, Y0 if i == 0 else None, capture=i > 0, keep=True)
    if again.record is None:
        raise IdentificationError(f"multi-start: the fit of start {i + 1} succeeded on a worker but failed "
                                  f"again in this process: {again.error}", status=again.status)
    return again.record


def _with_starts(rec: FitRecord, ms: MultiStartRecord, note: str) -> FitRecord:
    return dataclasses.replace(rec, notes=tuple(rec.notes) + (note,), extra={**rec.extra, "starts": ms})
