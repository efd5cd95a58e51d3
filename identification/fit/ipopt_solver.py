"""The one module that talks to Ipopt (through CasADi's ``nlpsol``).

    min_x f(x)  s.t.  g(x) = 0,  lbx <= x <= ubx

with exact first and second derivatives from CasADi AD.  Ipopt's return
statuses are mapped to one table of messages; a failed solve raises, it never
returns a solution.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from models.cache import Cache
from identification.errors import IdentificationError

__all__ = ["IpoptSettings", "IpoptResult", "NlpProblem", "solve_nlp", "warm_start", "STATUS_MESSAGES", "SOLVER_CACHE"]

#: Ipopt return status -> (accepted as a solution?, message for the user).  ``None`` means
#: "stalled": returned to the caller, who must verify optimality itself before using x.
STATUS_MESSAGES = {
    "Solve_Succeeded": (True, "optimal solution found"),
    "Solved_To_Acceptable_Level": (True, "solved only to Ipopt's acceptable tolerance, not its full tolerance"),
    "Infeasible_Problem_Detected": (False, "the state equation could not be satisfied (locally infeasible)"),
    "Search_Direction_Becomes_Too_Small": (None, "search direction too small: Ipopt stalled"),
    "Diverging_Iterates": (False, "iterates diverge: a parameter or state grows without bound; check bounds and scaling"),
    "User_Requested_Stop": (False, "stopped on request"),
    "Feasible_Point_Found": (False, "only a feasible point was found"),
    "Maximum_Iterations_Exceeded": (False, "maximum number of iterations reached; raise max_iter or improve p0"),
    "Restoration_Failed": (False, "restoration phase failed: Ipopt could not regain feasibility; check the state equation"),
    "Error_In_Step_Computation": (False, "error in the step computation (singular KKT system)"),
    "Maximum_CpuTime_Exceeded": (False, "time limit reached"),
    "Maximum_WallTime_Exceeded": (False, "time limit reached"),
    "Not_Enough_Degrees_Of_Freedom": (False, "not enough degrees of freedom"),
    "Invalid_Problem_Definition": (False, "invalid problem definition"),
    "Invalid_Option": (False, "invalid Ipopt option"),
    "Invalid_Number_Detected": (False, "NaN or Inf in a function or derivative value; check the model near p0"),
    "Unrecoverable_Exception": (False, "Ipopt raised an unrecoverable exception"),
    "NonIpopt_Exception_Thrown": (False, "an exception was thrown during function evaluation"),
    "Insufficient_Memory": (False, "insufficient memory"),
    "Internal_Error": (False, "Ipopt internal error"),
}


@dataclass(frozen=True)
class IpoptSettings:
    """Ipopt settings used by the estimator (defaults tuned for least squares)."""

    tol: float = 1e-10
    constr_viol_tol: float = 1e-10
    acceptable_tol: float = 1e-7
    max_iter: int = 3000
    print_level: int = 0
    linear_solver: str = "mumps"
    #: MUMPS ordering (ICNTL(7)); 6 = QAMD, which detects the quasi-dense rows and columns of
    #: the parameters (they couple to every state): MUMPS's analysis of the spring-chain KKT
    #: matrix (30 000 rows) drops from 0.23 s to 0.007 s per solve.  None keeps Ipopt's default.
    mumps_pivot_order: int | None = 6
    expand: bool | None = None  # None: expand MX to SX when the problem is small (<= 1000 variables)
    extra: tuple = ()  # extra (option, value) pairs passed to nlpsol, e.g. (("ipopt.mu_init", 1e-3),)

    def __post_init__(self):
        for name in ("tol", "constr_viol_tol", "acceptable_tol"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float, np.floating)) and 0 < v < np.inf):
                raise ValueError(f"{name}: expected a positive tolerance, got {v!r}")
        if not (isinstance(self.max_iter, (int, np.integer)) and self.max_iter >= 1):
            raise ValueError(f"max_iter: expected an integer >= 1, got {self.max_iter!r}")
        if not (isinstance(self.print_level, (int, np.integer)) and 0 <= self.print_level <= 12):
            raise ValueError(f"print_level: expected an integer in 0..12 (Ipopt's range), got {self.print_level!r}")
        if not isinstance(self.linear_solver, str) or not self.linear_solver:
            raise ValueError(f"linear_solver: expected an Ipopt linear solver name such as 'mumps', "
                             f"got {self.linear_solver!r}")
        if self.mumps_pivot_order is not None and self.mumps_pivot_order not in range(8):
            raise ValueError(f"mumps_pivot_order: expected None or an integer in 0..7 (MUMPS ICNTL(7)), "
                             f"got {self.mumps_pivot_order!r}")
        if not isinstance(self.extra, tuple) or not all(isinstance(e, tuple) and len(e) == 2 for e in self.extra):
            raise ValueError(f"extra: expected a tuple of (option, value) pairs, got {self.extra!r}")


@dataclass(frozen=True)
class IpoptResult:
    """Ipopt's solution of an NLP (returned only for accepted or stalled solves).

    Attributes
    ----------
    x : ndarray            the solution (scaled variables of the NLP)
    f : float              objective at x
    status, message : str  Ipopt's return status and its meaning (:data:`STATUS_MESSAGES`)
    accepted : bool or None  True: a solution; None: Ipopt stalled and the caller must verify
                           optimality itself before using x
    iterations : int       Ipopt iterations
    wall_time : float      seconds spent in the solver call
    stats : dict           selected entries of the solver's statistics
    """

    x: np.ndarray
    f: float
    status: str
    message: str
    accepted: bool | None
    iterations: int
    wall_time: float
    stats: dict


@dataclass(frozen=True)
class NlpProblem:
    """CasADi statement of  min_x f(x; par)  s.t.  g(x; par) = 0  and its optional exact derivatives.

    Attributes
    ----------
    x, f, g, par : casadi.SX or casadi.MX
        Variables, objective, constraints and parameters (the data) of the NLP.
    hess_lag : casadi.Function or None
        ``(x, par, lam_f, lam_g) -> triu(Hessian of lam_f f + lam_g^T g)``; None: CasADi's AD.
    jac_g : casadi.Function or None
        ``(x, par) -> (g, dg/dx)``; None: CasADi's AD.
    grad_f : casadi.Function or None
        ``(x, par) -> (f, df/dx)``; None: CasADi's AD.
    compiled : bool
        The derivative Functions call JIT-compiled code: the NLP is then not expanded to SX,
        which would drop the compiled code.
    expand : bool or None
        Expand the MX graph to SX for the solver (unless :attr:`IpoptSettings.expand` says
        otherwise); None: expand when the problem has at most 1000 variables.  A problem over
        few variables whose terms are mapped over many data points sets False: expanding would
        copy the map once per point.
    """

    x: object
    f: object
    g: object
    par: object
    hess_lag: ca.Function | None = None
    jac_g: ca.Function | None = None
    grad_f: ca.Function | None = None
    compiled: bool = False
    expand: bool | None = None


def warm_start(settings: IpoptSettings) -> IpoptSettings:
    """``settings`` with Ipopt's ``warm_start_init_point`` on: Ipopt starts from the given
    constraint multipliers (``lam_g0`` of :func:`solve_nlp`) instead of its least-squares
    estimate (which costs one factorisation of the KKT matrix).  For a start that is already
    a primal-dual solution of a problem without bounds Ipopt then stops at iteration 0."""
    if any(k in ("warm_start_init_point", "ipopt.warm_start_init_point") for k, _ in settings.extra):
        return settings
    return dataclasses.replace(settings, extra=settings.extra + (("warm_start_init_point", "yes"),))


#: compiled solvers of problems that no owner object keeps (callers that pass no ``cache``)
SOLVER_CACHE = Cache()
_CACHE_SIZE = 16


def _as_problem(built) -> NlpProblem:
    if isinstance(built, NlpProblem):
        return built
    if isinstance(built, tuple) and len(built) == 4:
        return NlpProblem(*built)
    raise TypeError(f"build: expected it to return an NlpProblem or a tuple (x, f, g, par), "
                    f"got {type(built).__name__}")


def _make_solver(build, settings: IpoptSettings):
    """(solver, build seconds, nlpsol seconds): the problem built by ``build()`` and Ipopt's
    CasADi solver of it (wall times of the two steps)."""
    t0 = time.perf_counter()
    nlp = _as_problem(build())
    t_build = time.perf_counter() - t0
    x = nlp.x
    n = x.size1()
    # expanding the MX graph to SX pays for small problems (press: 18 vs 22 ms per fit) and costs
    # more than it saves for large ones (spring chain d_y = 3000, n_q = 5: nlpsol set-up 1.4 s)
    if settings.expand is not None:
        expand = settings.expand
    elif nlp.expand is not None:
        expand = nlp.expand
    else:
        expand = isinstance(x, ca.MX) and n <= 1000
    opts = {
        "ipopt.tol": settings.tol,
        "ipopt.constr_viol_tol": settings.constr_viol_tol,
        "ipopt.acceptable_tol": settings.acceptable_tol,
        "ipopt.max_iter": settings.max_iter,
        "ipopt.print_level": settings.print_level,
        "ipopt.sb": "yes",
        "ipopt.linear_solver": settings.linear_solver,
        "print_time": False,
        "error_on_fail": False,
        # the multipliers of the NLP parameters (the data) are never read; computing them builds the
        # reverse-mode derivative of f and g w.r.t. the parameters (0.6 s at 1e5 inputs)
        "calc_lam_p": False,
    }
    if isinstance(x, ca.MX):
        opts["expand"] = bool(expand)
    if settings.linear_solver == "mumps" and settings.mumps_pivot_order is not None:
        opts["ipopt.mumps_pivot_order"] = int(settings.mumps_pivot_order)
    if nlp.compiled:
        expand = False                      # JIT-compiled stage functions: keep them compiled
        opts["expand"] = False
    for name, fn in (("hess_lag", nlp.hess_lag), ("jac_g", nlp.jac_g), ("grad_f", nlp.grad_f)):
        if fn is not None:
            opts[name] = fn.expand() if (expand and isinstance(x, ca.MX)) else fn
    for k, v in settings.extra:
        opts[k if "." in k or k in ("expand", "print_time") else f"ipopt.{k}"] = v
    t0 = time.perf_counter()
    solver = ca.nlpsol("mudoe_nlp", "ipopt", {"x": x, "f": nlp.f, "g": nlp.g, "p": nlp.par}, opts)
    return solver, t_build, time.perf_counter() - t0


def solve_nlp(build, x0, lbx, ubx, lbg, ubg, par_value, settings: IpoptSettings = IpoptSettings(),
              what: str = "problem", key=None, cache: Cache | None = None, lam_g0=None) -> IpoptResult:
    """Solve  min f(x; par)  s.t.  lbg <= g(x; par) <= ubg,  lbx <= x <= ubx  with Ipopt.

    ``lam_g0``: start values of the constraint multipliers (CasADi's sign: the Lagrangian is
    f + lam_g^T g); Ipopt uses them only with the option ``warm_start_init_point`` (see
    :func:`warm_start`), otherwise it estimates them by least squares.

    ``build()`` returns an :class:`NlpProblem` (or, for a problem without derivative
    Functions, the tuple ``(x, f, g, par)``); it is called only when no solver with the same
    ``key`` is cached (repeated identifications with new data reuse the compiled derivatives).
    ``cache`` is where the solvers are kept (the owner's :class:`models.cache.Cache`, e.g.
    ``model.cache``, at most 16 per owner); without it they are kept in :data:`SOLVER_CACHE`.
    Without a ``key`` nothing is cached.

    Raises
    ------
    IdentificationError
        When Ipopt's status is not an accepted one (see :data:`STATUS_MESSAGES`).
    """
    store = SOLVER_CACHE if cache is None else cache
    full_key = None if key is None else (key, settings)
    solver = store.get("ipopt_solvers", full_key) if full_key is not None else None
    t_build = t_nlpsol = 0.0
    if solver is None:
        solver, t_build, t_nlpsol = _make_solver(build, settings)
        if full_key is not None:
            store.put("ipopt_solvers", full_key, solver, maxsize=_CACHE_SIZE)
    t0 = time.perf_counter()
    if lam_g0 is None:
        sol = solver(x0=x0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, p=par_value)
    else:
        sol = solver(x0=x0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg, p=par_value, lam_g0=lam_g0)
    wall = time.perf_counter() - t0
    stats = solver.stats()
    status = str(stats.get("return_status", "unknown"))
    accepted, message = STATUS_MESSAGES.get(status, (False, f"unrecognised Ipopt status {status!r}"))
    iters = int(stats.get("iter_count", -1))
    if status == "User_Requested_Stop":
        # Ipopt (3.14+) catches SIGINT itself during a solve and stops "on request": that is the user's
        # Ctrl-C, which Python's own handler never saw.  Re-raise it, or a loop of fits would count a
        # failed fit and go on.
        raise KeyboardInterrupt(f"Ipopt stopped on request (Ctrl-C) during the {what}")
    if accepted is False:
        raise IdentificationError(f"Ipopt failed on the {what}: {status}: {message} (after {iters} iterations)",
                                  status=status)
    xs = np.asarray(sol["x"]).ravel()
    if not np.all(np.isfinite(xs)):
        raise IdentificationError(f"Ipopt returned non-finite values on the {what} (status {status})", status=status)
    return IpoptResult(x=xs, f=float(sol["f"]), status=status, message=message, accepted=accepted,
                       iterations=iters, wall_time=wall,
                       stats=_selected_stats(stats, t_build, t_nlpsol))


#: the derivative callbacks whose wall times Ipopt's statistics report (CasADi's names)
_CALLBACKS = ("nlp_f", "nlp_g", "nlp_grad_f", "nlp_jac_g", "nlp_hess_l")


def _selected_stats(stats: dict, t_build: float, t_nlpsol: float) -> dict:
    """The entries of CasADi's solver statistics kept in :attr:`IpoptResult.stats`, plus the
    wall seconds of building the problem (``t_build``) and creating the solver (``t_nlpsol``;
    both 0 when the solver came from the cache) and ``t_wall_callbacks``, the wall seconds spent
    in the derivative callbacks (the rest of the solve is Ipopt's own work, mostly the linear
    solves of the KKT system)."""
    out = {k: stats[k] for k in ("return_status", "iter_count", "success", "t_wall_total") if k in stats}
    calls = {k: float(stats.get(f"t_wall_{k}", 0.0)) for k in _CALLBACKS}
    out.update(t_build=t_build, t_nlpsol=t_nlpsol, t_wall_callbacks=calls)
    return out
