r"""Pyomo models of the sensor-selection MINLP (paper eq. 9) solved by SCIP (``scip_direct``).

.. math::  \min_{w\in\{0,1\}^{n_S}} \Psi(C(w))\quad\text{s.t.}\quad \sum_k w_k\ge s_{\min},\
           \sum_k w_k = m\ (\text{or}\le m),\ c^Tw\le B,\ w_I = 1,\ w_O = 0,

with :math:`s_{\min}` the smallest admissible design size (:attr:`oed.constraints.DesignConstraints.min_size`:
m when the size is fixed, else the larger of ``min_sensors`` (default 1) and the number of forced-in
candidates); a design with singular information is inadmissible by its criterion, not by its size.

This is the only module that imports Pyomo's ``SolverFactory``.  Formulations:

``"cuts"`` (Gauss-Newton, exact, convex-friendly outer approximation)
    MILP master :math:`\min t` over the design constraints plus cuts, re-solved by SCIP:
    D: :math:`t\ge -\log\det\bar M + p - \sum_k w_k\,\mathrm{tr}(\bar M^{-1}F_k)`;
    A: :math:`t\ge 2\,\mathrm{tr}\bar M^{-1} - \sum_k w_k\,\mathrm{tr}(\bar M^{-2}F_k)`;
    E (eigen-cuts): :math:`\max s` with :math:`s\le \sum_k w_k\,u^TF_ku` for eigenvectors
    :math:`u` of :math:`\lambda_{\min}(\bar M)`.  All cuts are valid for every design by
    convexity (concavity of :math:`\lambda_{\min}`); a singular design :math:`\bar S`
    gets the cut :math:`\sum_{k\notin\bar S}w_k\ge1` (subsets of singular designs are
    singular).  Terminates when the master bound meets the incumbent or a design repeats.
``"naive"`` (Gauss-Newton, one nonconvex MINLP)
    E: :math:`\max t` s.t. :math:`\sum_k w_kF_k - tI = LL^T`;  D: :math:`\sum_k w_kF_k = LL^T`,
    :math:`\min -2\sum_i\log L_{ii}`;  A: :math:`(\sum_k w_kF_k)X = I`, :math:`\min\mathrm{tr}X`.
``"second_order"``
    :math:`H(w)X = I`, :math:`Y = G(w)X`, :math:`C = XY`; A: :math:`\min\mathrm{tr}C`;
    E: :math:`tI - C = LL^T`, :math:`\min t`; D: :math:`C = LL^T`, :math:`\min 2\sum\log L_{ii}`.
    Designs with singular :math:`G` returned by SCIP are cut off by the no-good above and
    the model is re-solved.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .bnb import BnBSettings, SelectionProblem, fixings, greedy_exchange
from .constraints import DesignConstraints
from .criteria import DEFAULT_SETTINGS, Criterion, CriteriaSettings, Kind, batch_criteria, gap_tolerance
from .enumeration import iter_designs

__all__ = ["ScipSettings", "ScipResult", "ScipUnavailableError", "scip_available", "solve_scip",
           "STATUS_MESSAGES"]


class ScipUnavailableError(RuntimeError):
    """Pyomo or the ``scip_direct`` interface (PySCIPOpt) is not usable."""


#: One table mapping Pyomo termination conditions to (status, message).
STATUS_MESSAGES = {
    "optimal": ("optimal", "SCIP proved optimality"),
    "globallyOptimal": ("optimal", "SCIP proved global optimality"),
    "locallyOptimal": ("feasible", "SCIP reported only local optimality"),
    "feasible": ("feasible", "SCIP found a feasible design without proof of optimality"),
    "maxTimeLimit": ("time_limit", "SCIP hit the time limit"),
    "maxIterations": ("iteration_limit", "SCIP hit an iteration/node limit"),
    "maxEvaluations": ("iteration_limit", "SCIP hit an evaluation limit"),
    "infeasible": ("infeasible", "SCIP proved the design problem infeasible"),
    "infeasibleOrUnbounded": ("infeasible", "SCIP reported infeasible or unbounded"),
    "unbounded": ("error", "SCIP reported an unbounded problem (formulation error)"),
    "userInterrupt": ("error", "SCIP was interrupted"),
    "resourceInterrupt": ("error", "SCIP ran out of a resource (memory?)"),
    "noSolution": ("error", "SCIP returned no solution"),
    "solverFailure": ("error", "SCIP failed"),
    "internalSolverError": ("error", "SCIP internal error"),
    "error": ("error", "SCIP error"),
    "invalidProblem": ("error", "SCIP rejected the model as invalid"),
    "other": ("error", "SCIP stopped for an unspecified reason"),
    "unknown": ("error", "SCIP termination condition unknown"),
}


@dataclass(frozen=True)
class ScipSettings:
    """Settings for :func:`solve_scip`.

    Attributes
    ----------
    time_limit : float
        Wall-clock seconds for the whole call (all master solves).
    formulation : {"auto", "cuts", "naive", "second_order"}
        ``auto``: ``cuts`` for Gauss-Newton, ``second_order`` otherwise.
    gap_tol : float
        Relative (A, E) / absolute on log det (D) tolerance for the cut loop.
    max_rounds : int
        Maximum master solves of the cut loop / no-good loop.
    scip_options : tuple of (str, value)
        Extra SCIP parameters.
    inverse_bound_factor : float
        ``second_order`` only: SCIP's spatial branch-and-bound needs bounded variables, so
        the entries of :math:`X = H(w)^{-1}` are bounded by this factor times the largest
        entry of :math:`H^{-1}` of a heuristic incumbent.  This is a *modelling assumption*
        (designs with a much larger inverse Hessian are excluded) and is reported in
        ``ScipResult.assumption``.  All other bounds used are rigorous.
    """

    time_limit: float = 60.0
    formulation: str = "auto"
    gap_tol: float = 1e-9
    max_rounds: int = 500
    scip_options: tuple = ()
    inverse_bound_factor: float = 1e3


@dataclass(frozen=True)
class ScipResult:
    """Outcome of :func:`solve_scip`: ``status`` from :data:`STATUS_MESSAGES` plus
    ``"optimal"``; ``message`` explains; ``value``/``w`` from exact re-evaluation."""

    w: np.ndarray | None
    value: float
    lower_bound: float
    status: str
    message: str
    rounds: int
    wall_time: float
    formulation: str
    assumption: str = ""


def _pyomo():
    try:
        import pyomo.environ as pyo
        from pyomo.opt import SolverFactory
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ScipUnavailableError(f"pyomo is not importable: {exc}") from exc
    return pyo, SolverFactory


def scip_available() -> bool:
    """True when Pyomo's ``scip_direct`` interface can run."""
    try:
        _, SolverFactory = _pyomo()
        return bool(SolverFactory("scip_direct").available(exception_flag=False))
    except ScipUnavailableError:
        return False


def _base_model(pyo, cons: DesignConstraints):
    mdl = pyo.ConcreteModel()
    n = cons.n_candidates
    mdl.K = pyo.RangeSet(0, n - 1)
    mdl.w = pyo.Var(mdl.K, within=pyo.Binary)
    mdl.cuts = pyo.ConstraintList()
    tot = sum(mdl.w[k] for k in mdl.K)
    mdl.min_np = pyo.Constraint(expr=tot >= cons.min_size)
    if cons.n_sensors is not None:
        mdl.card = pyo.Constraint(expr=tot == cons.n_sensors)
    elif cons.max_sensors is not None:
        mdl.card = pyo.Constraint(expr=tot <= cons.max_sensors)
    if cons.costs is not None:
        mdl.budget = pyo.Constraint(expr=sum(cons.costs[k] * mdl.w[k] for k in mdl.K) <= cons.budget)
    for k in cons.include:
        mdl.w[k].fix(1)
    for k in cons.exclude:
        mdl.w[k].fix(0)
    return mdl


def _solve(SolverFactory, mdl, time_left, options):
    """Solve; return (status, message, loaded: bool, lower bound or None)."""
    opt = SolverFactory("scip_direct")
    if not opt.available(exception_flag=False):
        raise ScipUnavailableError("Pyomo's scip_direct interface is not available (is PySCIPOpt installed?)")
    opts = {"limits/time": max(float(time_left), 1.0), "display/verblevel": 0}
    opts.update(dict(options))
    try:
        res = opt.solve(mdl, load_solutions=False, options=opts)
    except Exception as exc:  # PySCIPOpt raises plain Exception on bad input data; never silent
        return "error", f"SCIP raised {type(exc).__name__}: {exc}", False, None
    tc = str(res.solver.termination_condition.value if hasattr(res.solver.termination_condition, "value")
             else res.solver.termination_condition)
    status, msg = STATUS_MESSAGES.get(tc, ("error", f"SCIP returned unmapped termination condition {tc!r}"))
    loaded = False
    if status in ("optimal", "feasible", "time_limit", "iteration_limit") and len(res.solution) > 0:
        mdl.solutions.load_from(res)
        loaded = True
    lb = None
    try:
        lbv = res.problem.lower_bound
        lb = float(lbv) if lbv is not None else None
    except (AttributeError, TypeError, ValueError):
        lb = None
    return status, msg, loaded, lb


def _read_w(mdl, n):
    return np.array([round(mdl.w[k].value) == 1 if mdl.w[k].value is not None else False for k in range(n)])


def solve_scip(F, S, cons: DesignConstraints, criterion, kind="gauss_newton", *,
               settings: ScipSettings = ScipSettings(),
               criteria_settings: CriteriaSettings = DEFAULT_SETTINGS) -> ScipResult:
    r"""Solve :math:`\min_w \Psi(C(w))` subject to the design constraints with SCIP.

    ``F``/``S`` must already be validated.  The returned ``value`` is always the exact
    criterion of the returned design (re-evaluated in numpy), never SCIP's objective.

    Raises
    ------
    ScipUnavailableError
        If Pyomo/SCIP cannot be used.
    ValueError
        ``formulation``: unknown or incompatible with ``kind``.
    """
    crit = Criterion.parse(criterion)
    kind = Kind.parse(kind)
    form = settings.formulation
    if form == "auto":
        form = "cuts" if kind is Kind.GAUSS_NEWTON else "second_order"
    if form not in ("cuts", "naive", "second_order"):
        raise ValueError(f"formulation: unknown {form!r}; valid: 'auto', 'cuts', 'naive', 'second_order'")
    if kind is Kind.SECOND_ORDER and form != "second_order":
        raise ValueError(f"formulation: {form!r} is for Gauss-Newton criteria; use 'second_order'")
    if kind is Kind.GAUSS_NEWTON and form == "second_order":
        S = None
    pyo, SolverFactory = _pyomo()
    t0 = time.perf_counter()
    if form == "cuts":
        return _solve_cuts(pyo, SolverFactory, F, cons, crit, settings, criteria_settings, t0)
    return _solve_minlp(pyo, SolverFactory, F, S, cons, crit, kind, form, settings, criteria_settings, t0)


def _exact(F, S, w, crit, kind, cs):
    res = batch_criteria(F, S, w[None].astype(float), kind, settings=cs, validated=True)
    return float(res.value(crit)[0]), bool(res.singular[0])


def _cut_master(pyo, F, cons, crit):
    r"""MILP master of the cut loop: :math:`\min t` (A, D) or :math:`\max s` (E, with
    :math:`0\le s\le\lambda_{\max}(\sum_kF_k)`) over the design constraints; cuts go to ``mdl.cuts``."""
    mdl = _base_model(pyo, cons)
    if crit is Criterion.E:
        mdl.s = pyo.Var(bounds=(0.0, float(np.max(np.linalg.eigvalsh(F.sum(0))))))
        mdl.obj = pyo.Objective(expr=mdl.s, sense=pyo.maximize)
    else:
        mdl.t = pyo.Var()
        mdl.obj = pyo.Objective(expr=mdl.t, sense=pyo.minimize)
    return mdl


def _add_cut(mdl, F, crit, x):
    """Add a tangent/eigen cut at (possibly fractional) x with regular M(x) to the master ``mdl``;
    False if the cut is numerically unusable (non-finite or > 1e15 coefficients) and was not added."""
    n, p, _ = F.shape
    Fflat = F.reshape(n, -1)
    M = (x @ Fflat).reshape(p, p)
    if crit is Criterion.E:
        lam, U = np.linalg.eigh(M)
        for j in range(p):
            if lam[j] > lam[0] + 1e-9 * max(abs(lam[-1]), 1e-300) and j > 0:
                break
            q = np.einsum("i,kij,j->k", U[:, j], F, U[:, j])
            if not np.all(np.isfinite(q)) or np.max(np.abs(q)) > 1e15:
                return False
            mdl.cuts.add(mdl.s <= sum(float(q[k]) * mdl.w[k] for k in range(n) if q[k] != 0.0))
        return True
    Minv = np.linalg.inv(M)
    Minv = 0.5 * (Minv + Minv.T)
    if crit is Criterion.D:
        f = -np.linalg.slogdet(M)[1]
        q = Fflat @ Minv.ravel()
        c0 = f + p
    else:
        f = float(np.trace(Minv))
        q = Fflat @ (Minv @ Minv).ravel()
        c0 = 2.0 * f
    if not (np.all(np.isfinite(q)) and np.isfinite(c0)) or max(np.max(np.abs(q)), abs(c0)) > 1e15:
        return False
    mdl.cuts.add(mdl.t >= c0 - sum(float(q[k]) * mdl.w[k] for k in range(n) if q[k] != 0.0))
    return True


def _solve_cuts(pyo, SolverFactory, F, cons, crit, settings, cs, t0):
    n, p, _ = F.shape
    Fflat = F.reshape(n, -1)
    """Outer-approximation cut loop (``"cuts"``): re-solve the MILP master, adding a cut at every new design."""
    mdl = _cut_master(pyo, F, cons, crit)
    # initial cut at the uniform relaxation point over available sensors
    avail = np.ones(n)
    avail[list(cons.exclude)] = 0.0
    m0 = cons.max_size
    x0 = avail * (m0 / avail.sum())
    x0[list(cons.include)] = 1.0
    if np.linalg.eigvalsh((x0 @ Fflat).reshape(p, p))[0] <= 0:
        return ScipResult(None, np.inf, np.inf, "infeasible",
                          "no admissible design has full-rank information (all available sensors are singular)",
                          0, time.perf_counter() - t0, "cuts")
    _add_cut(mdl, F, crit, x0)
    best_w, best_v = None, np.inf
    with_cut = set()
    lb = -np.inf
    status, msg = "error", "no SCIP round completed"
    rounds = 0
    while rounds < settings.max_rounds:
        left = settings.time_limit - (time.perf_counter() - t0)
        if left <= 0:
            status, msg = "time_limit", "time limit reached in the cut loop"
            break
        st, m_msg, loaded, _ = _solve(SolverFactory, mdl, left, settings.scip_options)
        rounds += 1
        if st == "infeasible":
            if best_w is None:
                status, msg = "infeasible", m_msg + " (no admissible regular design)"
            else:
                status, msg = "optimal", "all remaining designs cut off"
                lb = best_v
            break
        if st != "optimal" or not loaded:
            status, msg = st, m_msg + " (master problem of the cut loop)"
            break
        w = _read_w(mdl, n)
        obj = float(pyo.value(mdl.obj))
        master_lb = (1.0 / obj if obj > 0 else np.inf) if crit is Criterion.E else obj
        v, sing = _exact(F, None, w, crit, Kind.GAUSS_NEWTON, cs)
        key = w.tobytes()
        if sing or not np.isfinite(v):
            mdl.cuts.add(sum(mdl.w[k] for k in range(n) if not w[k]) >= 1)
            continue
        if v < best_v:
            best_w, best_v = w, v
        # global bound: every design not yet excluded by a no-good has value >= master_lb
        lb = min(master_lb, best_v)
        if key in with_cut:
            status, msg = "optimal", ("master repeated a design: incumbent optimal up to SCIP's "
                                      "feasibility tolerance on the cuts")
            break
        if lb >= best_v - gap_tolerance(crit, best_v, settings.gap_tol):
            status, msg = "optimal", "master bound meets the incumbent"
            break
        if _add_cut(mdl, F, crit, w.astype(float)):
            with_cut.add(key)
        else:  # numerically unusable cut: exclude exactly this (evaluated) design
            mdl.cuts.add(sum(1 - mdl.w[k] for k in range(n) if w[k]) + sum(mdl.w[k] for k in range(n) if not w[k]) >= 1)
    else:
        status, msg = "iteration_limit", f"cut loop reached max_rounds = {settings.max_rounds}"
    return ScipResult(best_w, best_v, lb, status, msg, rounds, time.perf_counter() - t0, "cuts")


def _heuristic_incumbent(F, S, cons, crit, kind, cs, max_designs=20000):
    """Best design among the first ``max_designs`` admissible designs (lexicographic) and
    the Gauss-Newton greedy/exchange design (if admissible); (w, value) or (None, inf)."""
    best_w, best_v = None, np.inf
    seen = 0
    for W in iter_designs(cons, 5000):
        res = batch_criteria(F, S, W, kind, settings=cs, validated=True)
        v = res.value(crit)
        j = int(np.argmin(v))
        if v[j] < best_v:
            best_w, best_v = W[j].copy(), float(v[j])
        seen += len(W)
        if seen >= max_designs:
            break
    prob = SelectionProblem(F, crit, BnBSettings().gap_tol, cs)
    wg, _ = greedy_exchange(prob, fixings(cons, F.shape[0]), cons.max_size)
    if cons.is_admissible(wg):
        v, _s = _exact(F, S, wg, crit, kind, cs)
        if v < best_v:
            best_w, best_v = wg, v
    return best_w, best_v


def _naive_formulation(pyo, mdl, F, crit, M, U):
    r"""Single nonconvex MINLP for Gauss-Newton criteria on ``mdl`` (``M``: :math:`\sum_kw_kF_k` as
    Pyomo expressions, ``U``: a heuristic upper bound, possibly inf): Cholesky of :math:`M-tI` (E),
    of :math:`M` (D) or :math:`MX=I` (A)."""
    p = F.shape[1]
    P = range(p)
    tri = [(i, j) for i in P for j in P if j <= i]
    Mdiag_max = float(np.max(np.einsum("kii->i", F)))
    delta = 1e-6 * np.sqrt(float(np.max(np.abs(F))))
    lb_ = np.sqrt(Mdiag_max)  # rigorous: M = LL^T (or M - tI = LL^T, t >= 0) => |L_ij| <= sqrt(M_ii)
    mdl.L = pyo.Var(tri, bounds=(-lb_, lb_))
    for i in P:
        mdl.L[i, i].setlb(delta)
    if crit is Criterion.E:
        mdl.t = pyo.Var(bounds=(0.0, float(np.max(np.linalg.eigvalsh(F.sum(0))))))
        mdl.eq = pyo.Constraint(tri, rule=lambda m_, i, j: M[i, j] - (mdl.t if i == j else 0.0)
                                == sum(mdl.L[i, l] * mdl.L[j, l] for l in range(j + 1)))
        mdl.obj = pyo.Objective(expr=mdl.t, sense=pyo.maximize)
    elif crit is Criterion.D:
        mdl.eq = pyo.Constraint(tri, rule=lambda m_, i, j: M[i, j]
                                == sum(mdl.L[i, l] * mdl.L[j, l] for l in range(j + 1)))
        mdl.obj = pyo.Objective(expr=-2.0 * sum(pyo.log(mdl.L[i, i]) for i in P), sense=pyo.minimize)
    else:
        # rigorous: X = M^{-1} is PD, so trace(X) <= U implies |X_ij| <= U
        xb = U if np.isfinite(U) else None
        mdl.X = pyo.Var(P, P, bounds=(None if xb is None else -xb, xb))
        mdl.eq = pyo.Constraint(P, P, rule=lambda m_, i, j: sum(M[i, l] * mdl.X[l, j] for l in P)
                                == (1.0 if i == j else 0.0))
        mdl.obj = pyo.Objective(expr=sum(mdl.X[i, i] for i in P), sense=pyo.minimize)
        if xb is not None:
            mdl.cutoff = pyo.Constraint(expr=sum(mdl.X[i, i] for i in P) <= U * (1 + 1e-9))


def _second_order_formulation(pyo, mdl, F, S, crit, M, U, w_inc, settings):
    r"""MINLP for the second-order covariance :math:`C = XY`, :math:`H(w)X = I`, :math:`Y = G(w)X` on
    ``mdl``; the bounds on X come from the heuristic design ``w_inc`` (value ``U``).  Returns the
    modelling assumption text ('' when ``U`` is inf)."""
    n, p, _ = F.shape
    P = range(p)
    tri = [(i, j) for i in P for j in P if j <= i]
    Mabs = np.abs(F).sum(axis=0)
    assumption = ""
    Sx = np.zeros_like(F) if S is None else S
    Hm = {(i, j): sum(float(F[k, i, j] + Sx[k, i, j]) * mdl.w[k] for k in range(n)
                      if F[k, i, j] + Sx[k, i, j] != 0.0) for i in P for j in P}
    xb = yb = cb = None
    if np.isfinite(U):
        Hinc = ((w_inc.astype(float)) @ (F + Sx).reshape(n, -1)).reshape(p, p)
        xb = settings.inverse_bound_factor * float(np.max(np.abs(np.linalg.inv(Hinc))))
        yb = float(np.max(Mabs.sum(axis=1))) * xb  # |(G X)_ij| <= sum_l |G_il| xb
        cb = p * xb * yb
        if crit in (Criterion.A, Criterion.E):
            cb = min(cb, U * (1 + 1e-9))  # rigorous: C PSD, trace/lambda_max <= U
        assumption = (f"|H(w)^-1|_ij <= {xb:.3g} (= {settings.inverse_bound_factor:g} x the largest entry "
                      "for a heuristic design); designs violating it are excluded")
    bnd = lambda b: (None if b is None else -b, b)  # noqa: E731
    mdl.X = pyo.Var(P, P, bounds=bnd(xb))
    mdl.Y = pyo.Var(P, P, bounds=bnd(yb))
    mdl.C = pyo.Var(P, P, bounds=bnd(cb))
    mdl.hx = pyo.Constraint(P, P, rule=lambda m_, i, j: sum(Hm[i, l] * mdl.X[l, j] for l in P)
                            == (1.0 if i == j else 0.0))
    mdl.gx = pyo.Constraint(P, P, rule=lambda m_, i, j: mdl.Y[i, j] == sum(M[i, l] * mdl.X[l, j] for l in P))
    mdl.cc = pyo.Constraint(P, P, rule=lambda m_, i, j: mdl.C[i, j] == sum(mdl.X[i, l] * mdl.Y[l, j] for l in P))
    if crit is Criterion.A:
        mdl.obj = pyo.Objective(expr=sum(mdl.C[i, i] for i in P), sense=pyo.minimize)
        if np.isfinite(U):
            mdl.cutoff = pyo.Constraint(expr=sum(mdl.C[i, i] for i in P) <= U * (1 + 1e-9))
    else:
        if crit is Criterion.E:
            lbd = None if cb is None else np.sqrt(2 * cb)  # t - C_ii <= 2 cb
            mdl.L = pyo.Var(tri, bounds=bnd(lbd))
            for i in P:
                mdl.L[i, i].setlb(0.0)
            mdl.t = pyo.Var(bounds=(0.0, None if not np.isfinite(U) else U * (1 + 1e-9)))
            mdl.eq = pyo.Constraint(tri, rule=lambda m_, i, j: (mdl.t if i == j else 0.0) - mdl.C[i, j]
                                    == sum(mdl.L[i, l] * mdl.L[j, l] for l in range(j + 1)))
            mdl.obj = pyo.Objective(expr=mdl.t, sense=pyo.minimize)
        else:
            lbd = None if cb is None else np.sqrt(cb)  # C = LL^T => |L_ij| <= sqrt(C_ii)
            mdl.L = pyo.Var(tri, bounds=bnd(lbd))
            for i in P:
                mdl.L[i, i].setlb(1e-12)
            mdl.eq = pyo.Constraint(tri, rule=lambda m_, i, j: mdl.C[i, j]
                                    == sum(mdl.L[i, l] * mdl.L[j, l] for l in range(j + 1)))
            mdl.obj = pyo.Objective(expr=2.0 * sum(pyo.log(mdl.L[i, i]) for i in P), sense=pyo.minimize)
    return assumption


def _solve_minlp(pyo, SolverFactory, F, S, cons, crit, kind, form, settings, cs, t0):
    """One MINLP (``"naive"`` or ``"second_order"``) solved by SCIP, re-solved after no-good cuts
    of singular designs; a better heuristic design replaces SCIP's."""
    n, p, _ = F.shape
    mdl = _base_model(pyo, cons)
    P = range(p)
    assumption = ""
    w_inc, U = _heuristic_incumbent(F, S if form == "second_order" else None, cons, crit, kind, cs)
    M = {(i, j): sum(float(F[k, i, j]) * mdl.w[k] for k in range(n) if F[k, i, j] != 0.0) for i in P for j in P}
    if form == "naive":
        _naive_formulation(pyo, mdl, F, crit, M, U)
    else:
        assumption = _second_order_formulation(pyo, mdl, F, S, crit, M, U, w_inc, settings)
    rounds = 0
    status, msg = "error", "no SCIP solve completed"
    best_w, best_v, lb = None, np.inf, -np.inf
    while rounds < settings.max_rounds:
        left = settings.time_limit - (time.perf_counter() - t0)
        if left <= 0:
            status, msg = "time_limit", "time limit reached"
            break
        st, msg, loaded, slb = _solve(SolverFactory, mdl, left, settings.scip_options)
        rounds += 1
        status = st
        if not loaded:
            break
        w = _read_w(mdl, n)
        v, sing = _exact(F, S if form == "second_order" else None, w, crit, kind, cs)
        if sing:
            # rank-deficient G: cut off this design and all its subsets, re-solve
            mdl.cuts.add(sum(mdl.w[k] for k in range(n) if not w[k]) >= 1)
            status, msg = "error", "SCIP returned a singular design; cut off and re-solved"
            continue
        best_w, best_v = w, v
        if slb is not None and status == "optimal":
            if form == "naive" and crit is Criterion.E:
                lb = v  # maximisation of t; SCIP proved optimality
            else:
                lb = v
        break
    else:
        status, msg = "iteration_limit", f"no-good loop reached max_rounds = {settings.max_rounds}"
    if best_w is None and w_inc is not None and status != "infeasible":
        msg += "; SCIP found no design, returning the heuristic incumbent"
        best_w, best_v = w_inc, U
    elif best_w is not None and w_inc is not None and U < best_v - gap_tolerance(crit, best_v, 1e-9):
        if status == "optimal":
            status = "feasible"
            msg += "; a heuristic design beats SCIP's 'optimal' one (numerical tolerance?), proof discarded"
        best_w, best_v = w_inc, U
    return ScipResult(best_w, best_v, lb, status, msg, rounds, time.perf_counter() - t0, form, assumption)
