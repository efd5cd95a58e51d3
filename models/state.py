"""Numerical evaluation of a :class:`models.Model`: state solves and exact sensitivities.

Solves E(y, p, q) = 0 for y by a damped Newton method with the exact (AD) Jacobian
dE/dy, and evaluates model outputs.  All derivatives come from CasADi; linear
algebra is done in NumPy/SciPy (dense for small states, sparse LU for large ones).
"""
from __future__ import annotations

import atexit
import os
import shutil
import tempfile
import time
import warnings
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla

from .batched import BatchedFunction, batched_function
from .cache import Cache
from .errors import StateSolveError
from .jit_cache import JitCache, JitCompileError, JitStats
from .vectorised import VectorisedSX, vectorisable

__all__ = ["batched_function", "numerics", "solve_state", "solve_states", "solve_states_generic", "simulate", "Numerics", "set_jit",
           "jit_scope", "jit_enabled", "JitConfig", "JIT"]

_DENSE_LIMIT = 60

@dataclass
class JitConfig:
    """Just-in-time compilation of the per-model CasADi functions (C code through the system compiler).

    One process-wide instance, :data:`JIT`, is read by :meth:`Numerics.jit_active`; switch it for the
    process with :func:`set_jit`, or for a block of code in one thread or task with :func:`jit_scope`.
    Off by default: compiling the press functions takes about 1.5 s of ``gcc``, which pays off
    only for many repeated fits (the Monte Carlo workers switch it on).
    Only models stated in SX with at most 60 states are compiled, and only when a C compiler
    (``gcc``) works; otherwise the CasADi virtual machine evaluates the functions as usual
    (same numbers, slower); the trajectories of collocated ODEs with at most 24 unknowns per
    element are compiled as well, their element blocks solved in the same call (to round-off).

    The compiled libraries are kept in an on-disk cache shared by all processes of the user
    (:class:`models.jit_cache.JitCache`, content-addressed by the function, the flags, CasADi and
    the compiler): a function is compiled once per machine, and every other process (each local
    worker, each Dask worker on the machine, the next run) loads it in about 20 ms.

    Attributes
    ----------
    enabled : bool          compile when a model qualifies
    failed : bool           set when no working compiler was found (compilation stays off)
    cache : bool            keep the compiled libraries in the on-disk cache (False: compile in a
                            temporary directory of this process, removed at exit, as before the cache)
    directory : str or None the cache directory (None: :func:`models.jit_cache.default_cache_dir`,
                            ``$MUDOE_JIT_CACHE`` or ``~/.cache/mudoe/jit``)
    scratch : str or None   with ``cache`` False: this process's temporary directory for the generated
                            code and libraries (created on first use, removed at exit)
    flags : tuple of str    compiler flags
    stats : JitStats        this process's compilations and cache loads (counts, seconds)
    """

    enabled: bool = False
    failed: bool = False
    cache: bool = True
    directory: str | None = None
    scratch: str | None = None
    flags: tuple = ("-O1",)
    stats: JitStats = field(default_factory=JitStats)

    def wanted(self) -> bool:
        """The setting in effect here: the innermost :func:`jit_scope` of this context, else
        :attr:`enabled` (the process-wide one of :func:`set_jit`)."""
        scoped = _JIT_SCOPE.get()
        return self.enabled if scoped is None else scoped

    def active(self) -> bool:
        """True when compilation is wanted here (:meth:`wanted`) and a compiler has not failed."""
        return self.wanted() and not self.failed

    def workdir(self) -> str:
        """The temporary directory for generated code without the cache (created on first use,
        removed at exit), so that nothing is written to the working directory."""
        d = self.scratch
        if d is None or not os.path.isdir(d):
            d = tempfile.mkdtemp(prefix="mudoe_jit_")
            atexit.register(shutil.rmtree, d, ignore_errors=True)
            self.scratch = d
        return d

    def compile(self, f: ca.Function) -> ca.Function | None:
        """A C-compiled copy of an SX function (from the cache when :attr:`cache`), or None (no
        working compiler: :attr:`failed` is then set and the virtual machine stays in use)."""
        if shutil.which("gcc") is None:
            self.failed = True
            return None
        if self.cache:
            try:
                return JitCache(self.directory, self.flags, stats=self.stats).get(f)
            except JitCompileError:
                self.failed = True      # no working compiler: keep the virtual machine
                return None
            except OSError as exc:      # the cache directory is not usable: compile in a private one
                warnings.warn(f"JIT cache {self.directory or '(default)'} not usable ({exc}); compiling per process",
                              RuntimeWarning, stacklevel=2)
                self.cache = False
        d = self.workdir()
        t0 = time.perf_counter()
        try:
            g = ca.Function(f"{f.name()}_jit", f.sx_in(), f.call(f.sx_in()), f.name_in(), f.name_out(),
                            {"jit": True, "compiler": "shell", "jit_name": "jit_tmp", "jit_cleanup": False,
                             "jit_options": {"flags": list(self.flags), "verbose": False, "cleanup": False,
                                             "directory": d + os.sep}})
        except RuntimeError:
            self.failed = True          # no working compiler: keep the virtual machine
            return None
        self.stats.compiled += 1
        self.stats.compile_s += time.perf_counter() - t0
        return g


#: the process-wide JIT configuration (see :class:`JitConfig` and :func:`set_jit`)
JIT = JitConfig()
#: the JIT setting of the running context (None: the process-wide one), see :func:`jit_scope`
_JIT_SCOPE: ContextVar = ContextVar("mudoe_jit_scope", default=None)


def set_jit(enabled: bool) -> bool:
    """Switch JIT compilation of small (dense) models' functions on or off; returns the previous state.

    Sets :attr:`JitConfig.enabled` of :data:`JIT`.  Only models stated in SX with at most 60
    states are compiled, and only when a C compiler (``cc``/``gcc``) is on the PATH; otherwise
    the CasADi virtual machine evaluates them as usual (same numbers, slower).  Collocated ODEs with at
    most 24 unknowns per element (n_x d) also get their element functions compiled, with the solves of
    their element blocks in the same compiled call (:mod:`models.block_solve`: numbers equal to LAPACK's
    to round-off, not bit for bit).
    """
    prev = JIT.enabled
    JIT.enabled = bool(enabled)
    return prev


def jit_enabled() -> bool:
    """The JIT setting in effect here (:meth:`JitConfig.wanted` of :data:`JIT`; whether a compiler works
    is :attr:`JitConfig.failed`)."""
    return JIT.wanted()


@contextmanager
def jit_scope(enabled: bool):
    """JIT compilation on or off for the code run inside the block, in this thread (or task) only.

    A :class:`contextvars.ContextVar` overrides :data:`JIT`'s process-wide setting while the block
    runs, so that a setting carried by a task (the replication engine's chunks) never changes what
    other threads of the process (a threaded Dask worker's other tasks) evaluate, and nothing is left
    switched afterwards (an exception included).
    """
    token = _JIT_SCOPE.set(bool(enabled))
    try:
        yield
    finally:
        _JIT_SCOPE.reset(token)


def _to_scipy(dm: ca.DM):
    """CasADi sparse DM -> scipy CSC matrix (keeps structural zeros out)."""
    sp = dm.sparsity()
    colind, row = sp.get_ccs()
    return sps.csc_matrix((np.asarray(dm.nonzeros(), float), np.asarray(row), np.asarray(colind)), shape=dm.shape)


class Numerics:
    """Cached CasADi functions of one model.

    Attributes
    ----------
    E_y : casadi.Function  (y, p, q) -> (E, dE/dy)
    sens : casadi.Function (y, p, q) -> (h, dE/dy, dE/dp, dh/dy, dh/dp)
    lag_hess : casadi.Function (y, p, q, lam_h, mu) -> Hessian of lam_h^T h + mu^T E w.r.t. (y, p)
    """

    def __init__(self, model):
        self.model = model
        S = ca.SX if model.symbolic == "SX" else ca.MX
        y = S.sym("y", model.n_y)
        p = S.sym("p", model.n_p)
        q = S.sym("q", model.n_q_dim)
        E = model.E_fun(y, p, q)
        h = model.h_fun(y, p, q)
        Ey = ca.jacobian(E, y)
        self.E_y = ca.Function("E_y", [y, p, q], [E, Ey])
        self.sens = ca.Function("sens", [y, p, q], [h, Ey, ca.jacobian(E, p), ca.jacobian(h, y), ca.jacobian(h, p)])
        lam = S.sym("lam", model.n_S)
        mu = S.sym("mu", model.n_y)
        v = ca.vertcat(y, p)
        L = ca.dot(lam, h) + (ca.dot(mu, E) if model.n_y else 0)
        self.lag_hess = ca.Function("lag_hess", [y, p, q, lam, mu], [ca.hessian(L, v)[0]])
        self.h = model.h_fun
        self.dense = model.n_y <= _DENSE_LIMIT
        self._functions = Cache()       # compiled copies and point / batched evaluators

    def jit_active(self) -> bool:
        """True when :func:`set_jit` is on and this model qualifies (SX, at most 60 states)."""
        return JIT.active() and self.dense and self.model.symbolic == "SX"

    def compiled(self, name: str, f: ca.Function | None = None) -> ca.Function:
        """``getattr(self, name)`` (or ``f``), JIT-compiled when :meth:`jit_active`; cached per name."""
        f = getattr(self, name) if f is None else f
        if not self.jit_active():
            return f
        g = self._functions.get("jit", name)
        if g is None:
            g = JIT.compile(f)
            if g is None:
                return f
            self._functions.put("jit", name, g)
        return g

    def point(self, name: str) -> "_Point":
        """Evaluator of ``getattr(self, name)`` at one point, NumPy in, NumPy/SciPy out.

        Column-vector outputs come back as 1-D arrays; matrices as dense arrays for small
        (dense) models and as SciPy CSC matrices otherwise, read straight from CasADi's
        nonzero buffer (no DM conversion).
        """
        base = self.compiled(name)
        key = (name, base is not getattr(self, name))
        f = self._functions.get("point", key)
        if f is None:
            f = self._functions.put("point", key, _Point(base, self.dense))
        return f

    def batched(self, name: str, n: int) -> "BatchedFunction":
        """Evaluator of ``getattr(self, name)`` at n points at once, NumPy in, NumPy out.

        ``batched(name, n)(a_1, ..., a_k)`` takes arrays of shape (n, d_i) (row j = the i-th
        argument at point j; a 1-D array of length d_i is broadcast to all points) and returns
        one dense array of shape (n, r, c) per output.  It evaluates the mapped CasADi
        function through a ``FunctionBuffer`` (no DM conversion: about 5x less overhead
        than ``Function.__call__`` plus ``DM.full`` for the press model); from
        :data:`VECTORISE_MIN` points on, an SX function of scalar operations (not JIT-compiled)
        is replayed by NumPy over all points instead (:class:`models.vectorised.VectorisedSX`,
        3-6x faster than the serial map there; same numbers to the last bit or two).
        """
        base = self.compiled(name)
        if n >= VECTORISE_MIN and base is getattr(self, name):
            v = self._functions.get("vectorised", name)
            if v is None:
                v = self._functions.put("vectorised", name, _VectorisedBatched.of(base))
            if v is not False:
                return _AtN(v, n)
        key = (name, min(n, BATCH_CHUNK), base is not getattr(self, name))
        f = self._functions.get("batched", key)
        if f is None:
            f = self._functions.put("batched", key, BatchedFunction(base, min(n, BATCH_CHUNK)))
        return f if n <= BATCH_CHUNK else _Chunked(f, n)

    def factor(self, Ey_dm):
        """A solver x = Ey^{-1} b (and its transpose) for the state Jacobian.

        ``Ey_dm``: a CasADi DM, a NumPy array or a SciPy sparse matrix.
        """
        n = Ey_dm.shape[0]
        if n == 0:
            return None
        if self.dense:
            A = np.asarray(ca.densify(Ey_dm).full()) if isinstance(Ey_dm, ca.DM) else (
                Ey_dm.toarray() if sps.issparse(Ey_dm) else np.asarray(Ey_dm, float))
            try:
                import scipy.linalg as sla
                lu = sla.lu_factor(A, check_finite=True)
            except (ValueError, np.linalg.LinAlgError) as exc:
                raise StateSolveError(f"dE/dy cannot be factorised: {exc}") from None
            if np.any(np.abs(np.diag(lu[0])) <= 1e-300):
                raise StateSolveError("dE/dy is singular (Assumption 2 (ii) of the paper fails)")
            import scipy.linalg as sla
            return lambda b, trans=0: sla.lu_solve(lu, b, trans=trans)
        A = _to_scipy(Ey_dm) if isinstance(Ey_dm, ca.DM) else sps.csc_matrix(Ey_dm)
        try:
            lu = spla.splu(A)
        except RuntimeError as exc:
            raise StateSolveError(f"dE/dy is singular: {exc}") from None
        return lambda b, trans=0: lu.solve(np.asarray(b, float), trans="T" if trans else "N")


class _Point:
    """A CasADi function evaluated through a FunctionBuffer at one point (see Numerics.point)."""

    def __init__(self, f: ca.Function, dense: bool):
        sym = f.mx_in()
        outs = f.call(sym)
        outs = [ca.densify(o) if (dense or o.size2() == 1) else o for o in outs]
        self._f = ca.Function(f"{f.name()}_point", sym, outs)
        self._in = [f.nnz_in(i) for i in range(f.n_in())]
        self._out = []
        for i in range(self._f.n_out()):
            sp = self._f.sparsity_out(i)
            colind, row = sp.get_ccs()
            self._out.append((sp.size1(), sp.size2(), sp.nnz(), np.asarray(row, np.int32),
                              np.asarray(colind, np.int32)))

    def __call__(self, *args) -> list:
        buf, ev = self._f.buffer()
        keep = []
        for i, (a, n) in enumerate(zip(args, self._in)):
            a = np.ascontiguousarray(np.asarray(a, float).ravel())
            if a.size != n:
                raise ValueError(f"argument {i}: expected {n} values, got {a.size}")
            keep.append(a)
            buf.set_arg(i, memoryview(a))
        data = [np.empty(nnz) for (_, _, nnz, _, _) in self._out]
        for i, d in enumerate(data):
            buf.set_res(i, memoryview(d))
        ev()
        if buf.ret() != 0:
            raise StateSolveError(f"evaluation of {self._f.name()} failed (CasADi return code {buf.ret()})")
        res = []
        for d, (r, c, nnz, row, colind) in zip(data, self._out):
            if c == 1:
                res.append(d)
            elif nnz == r * c:
                res.append(d.reshape(c, r).T)
            else:
                res.append(sps.csc_matrix((d, row, colind), shape=(r, c)))
        return res


#: largest number of points of one mapped evaluation; more points are evaluated in chunks of
#: this size (building ``Function.map(n)`` costs time linear in n: 0.4 s for n = 1e6, 3 ms for 1e4)
BATCH_CHUNK = 16384


class _Chunked:
    """A :class:`models.batched.BatchedFunction` evaluator of ``BATCH_CHUNK`` points applied to
    n > BATCH_CHUNK points chunk by chunk (the last chunk padded with its last point), same call and results."""

    def __init__(self, f: "BatchedFunction", n: int):
        self._f, self.n = f, n

    def __call__(self, *args) -> list:
        n, m = self.n, self._f.n
        args = [np.asarray(a, float) for a in args]
        per_point = [a.ndim == 2 and a.shape[0] == n for a in args]
        outs = None
        for start in range(0, n, m):
            stop = min(start + m, n)
            idx = np.minimum(np.arange(start, start + m), stop - 1) if stop - start < m else slice(start, stop)
            res = self._f(*[a[idx] if pp else a for a, pp in zip(args, per_point)])
            if outs is None:
                outs = [np.empty((n,) + r.shape[1:]) for r in res]
            for o, r in zip(outs, res):
                o[start:stop] = r[:stop - start]
        return outs


#: number of points from which :meth:`Numerics.batched` replays SX functions with NumPy
#: (:class:`models.vectorised.VectorisedSX`); below it the mapped CasADi call is faster
VECTORISE_MIN = 512


class _VectorisedBatched:
    """An SX function of column-vector arguments replayed by NumPy at n points, with the call and
    the dense (n, r, c) results of :class:`models.batched.BatchedFunction` (see :meth:`Numerics.batched`)."""

    def __init__(self, f: ca.Function):
        self._v = VectorisedSX(f)
        self._in = [f.size1_in(i) for i in range(f.n_in())]
        self._out = []
        for i in range(f.n_out()):
            sp = f.sparsity_out(i)
            r, c = sp.size1(), sp.size2()
            lin = None if sp.nnz() == r * c else np.asarray(sp.get_col(), np.intp) * r + np.asarray(sp.row(), np.intp)
            self._out.append((r, c, lin))

    @classmethod
    def of(cls, f: ca.Function):
        """The evaluator of ``f``, or False when ``f`` is not an SX function of scalar operations
        with dense column-vector arguments."""
        if not vectorisable(f) or any(f.size2_in(i) != 1 or f.nnz_in(i) != f.size1_in(i) for i in range(f.n_in())):
            return False
        return cls(f)

    def __call__(self, n: int, *args) -> list:
        if len(args) != len(self._in):
            raise ValueError(f"expected {len(self._in)} arguments, got {len(args)}")
        conv = []
        for i, (a, r) in enumerate(zip(args, self._in)):
            a = np.asarray(a, float)
            if a.ndim == 1 or a.shape[0] != n:
                a = a.reshape(r)                     # shared by all points
            elif a.shape != (n, r):
                raise ValueError(f"argument {i}: expected shape ({n}, {r}), got {a.shape}")
            conv.append(a)
        res = []
        for o, (r, c, lin) in zip(self._v(*conv, n=n), self._out):
            if lin is not None:
                d = np.zeros((r * c, n))
                d[lin] = o
                o = d
            res.append(np.ascontiguousarray(o.T).reshape(n, c, r).transpose(0, 2, 1))
        return res


class _AtN:
    """A :class:`_VectorisedBatched` evaluator bound to n points (the call of
    :class:`models.batched.BatchedFunction`)."""

    def __init__(self, v: _VectorisedBatched, n: int):
        self._v, self.n = v, n

    def __call__(self, *args) -> list:
        return self._v(self.n, *args)


def numerics(model) -> Numerics:
    """The :class:`Numerics` of a model, built once and kept in ``model.cache``."""
    num = model.cache.get("numerics", None)
    if num is None:
        num = model.cache.put("numerics", None, Numerics(model))
    return num


def solve_state(model, p, q, y0=None, tol: float = 1e-12, max_iter: int = 100) -> np.ndarray:
    """Solve E(y, p, q) = 0 for the state y by damped Newton with the exact Jacobian.

    Converged when the Newton step satisfies ||dy||_inf <= tol (1 + ||y||_inf) and the
    residual did not grow.  Backtracking halves the step while ||E|| increases.

    Raises
    ------
    StateSolveError
        When Newton does not converge in ``max_iter`` iterations or dE/dy is singular.
    """
    num = numerics(model)
    p = np.asarray(p, float).ravel()
    q = np.asarray(q, float).ravel()
    if model.n_y == 0:
        return np.zeros(0)
    y = model.y_guess(p, q) if y0 is None else np.array(y0, float).ravel()
    f = num.point("E_y")
    E, Ey = f(y, p, q)
    nE = np.linalg.norm(E, np.inf)
    for it in range(max_iter):
        if not np.all(np.isfinite(E)):
            raise StateSolveError(f"E(y, p, q) is not finite during the state solve at q={q.tolist()}, p={p.tolist()}")
        solve = num.factor(Ey)
        dy = -solve(E)
        step = 1.0
        for _ in range(30):
            y_new = y + step * dy
            E_new, Ey_new = f(y_new, p, q)
            n_new = np.linalg.norm(E_new, np.inf)
            if np.isfinite(n_new) and (n_new <= nE * (1 - 1e-4 * step) or n_new <= 1e-300
                                       or np.linalg.norm(step * dy, np.inf) <= 1e-14 * (1 + np.linalg.norm(y, np.inf))):
                break
            step *= 0.5
        else:
            raise StateSolveError(f"state solve: line search failed at q={q.tolist()}, p={p.tolist()} "
                                  f"(||E|| = {nE:.3e})")
        y, E, Ey, nE = y_new, E_new, Ey_new, n_new
        if np.linalg.norm(step * dy, np.inf) <= tol * (1 + np.linalg.norm(y, np.inf)):
            return y
    raise StateSolveError(f"state solve: Newton did not converge in {max_iter} iterations at q={q.tolist()}, "
                          f"p={p.tolist()} (||E||_inf = {nE:.3e})")


def _solve_states_batched(model, p, inputs, Y0, tol: float = 1e-12, max_iter: int = 8):
    """Newton on all inputs at once (dense states, good guesses); None when it does not converge.

    One mapped CasADi call per iteration evaluates E and dE/dy at every input; full Newton
    steps are taken only while every residual decreases, else the caller falls back to the
    damped per-input solve.
    """
    num = numerics(model)
    n = inputs.shape[0]
    f = num.batched("E_y", n)
    Y = np.array(Y0, float)
    E, Ey = f(Y, p, inputs)
    E = E[:, :, 0]
    nE = np.abs(E).max(axis=1)
    for _ in range(max_iter):
        if not np.all(np.isfinite(E)):
            return None
        try:
            dY = -np.linalg.solve(Ey, E[:, :, None])[:, :, 0]
        except np.linalg.LinAlgError:
            return None
        Y = Y + dY
        if np.abs(dY).max() <= tol * (1 + np.abs(Y).max()):
            return Y
        E, Ey = f(Y, p, inputs)
        E = E[:, :, 0]
        nE_new = np.abs(E).max(axis=1)
        if np.any(nE_new > nE) and np.any(nE_new > 1e-300):
            return None
        nE = nE_new
    return None


def _solve_states_damped(model, p, inputs, tol: float = 1e-12, max_iter: int = 60):
    """Damped Newton on all inputs at once from the model's guesses (dense states).

    Every input has its own step length (halved while its residual ||E_j||_inf does not
    decrease by the Armijo fraction 1e-4), so one mapped CasADi call per trial evaluates E and
    dE/dy at every input; the linear algebra is batched NumPy.  Returns (Y, converged) with a
    boolean per input; inputs that do not converge are left to the per-input solve.
    """
    num = numerics(model)
    n = inputs.shape[0]
    f = num.batched("E_y", n)
    if not model.has_y_guess:
        Y = np.zeros((n, model.n_y))
    else:
        Y = np.array([model.y_guess(p, q) for q in inputs])
    E, Ey = f(Y, p, inputs)
    E = E[:, :, 0]
    nE = np.abs(E).max(axis=1)
    done = np.zeros(n, bool)
    for _ in range(max_iter):
        ok = np.isfinite(nE) & np.all(np.isfinite(Ey.reshape(n, -1)), axis=1)
        active = ok & ~done
        if not np.any(active):
            break
        dY = np.zeros_like(Y)
        try:
            dY[active] = -np.linalg.solve(Ey[active], E[active][:, :, None])[:, :, 0]
        except np.linalg.LinAlgError:
            break
        step = np.where(active, 1.0, 0.0)
        for _ in range(30):
            Y_new = Y + step[:, None] * dY
            E_new, Ey_new = f(Y_new, p, inputs)
            E_new = E_new[:, :, 0]
            n_new = np.abs(E_new).max(axis=1)
            small = np.abs(step[:, None] * dY).max(axis=1) <= 1e-14 * (1 + np.abs(Y).max(axis=1))
            good = np.isfinite(n_new) & ((n_new <= nE * (1 - 1e-4 * step)) | (n_new <= 1e-300) | small)
            retry = active & ~good
            if not np.any(retry):
                break
            step = np.where(retry, 0.5 * step, step)
        accept = active & good
        Y[accept], E[accept], Ey[accept], nE[accept] = Y_new[accept], E_new[accept], Ey_new[accept], n_new[accept]
        conv = accept & (np.abs(step[:, None] * dY).max(axis=1) <= tol * (1 + np.abs(Y).max(axis=1)))
        done |= conv
        if np.all(done) or not np.any(accept):
            break
    return Y, done


#: number of inputs from which the states at the model's guesses are solved all at once
#: (:func:`_solve_states_damped`); below it each solve starts from the previous input's state
BATCH_START_MIN = 256


def solve_states(model, p, inputs, Y0=None) -> np.ndarray:
    """States for every input row, shape (n_q, n_y).

    With a guess ``Y0`` for every input and a small (dense) state, all inputs are first
    solved together by undamped Newton; the damped per-input solve is the fallback.  Without
    ``Y0``, each solve starts from the previous input's state (continuation); with at least
    :data:`BATCH_START_MIN` inputs and a dense state, all inputs are first solved at once by
    damped Newton from the model's guesses and only the inputs where that fails are solved one
    by one (:func:`solve_states_generic`).  A collocated ODE marches its elements instead, all inputs
    at once: the model's numerics (:attr:`models.Model.state_numerics`) solve.  An explicit model (no
    state) returns an (n_q, 0) array.
    """
    inputs = np.atleast_2d(np.asarray(inputs, float))
    p = np.asarray(p, float).ravel()
    if not model.n_y:
        return np.zeros((inputs.shape[0], 0))
    return model.state_numerics.solve_states(p, inputs, Y0)


def solve_states_generic(model, p: np.ndarray, inputs: np.ndarray, Y0=None) -> np.ndarray:
    """:func:`solve_states` by the generic solves (batched dense Newton, or input by input with continuation);
    ``inputs`` (n_q, d_q) and ``p`` (n_p,) as arrays, a model with states."""
    dense = numerics(model).dense
    if Y0 is not None and dense:
        Y = _solve_states_batched(model, p, inputs, Y0)
        if Y is not None:
            return Y
    if Y0 is None and dense and inputs.shape[0] >= BATCH_START_MIN:
        Y, done = _solve_states_damped(model, p, inputs)
        for j in np.flatnonzero(~done):
            Y[j] = solve_state(model, p, inputs[j], y0=Y[j - 1] if j and done[j - 1] else None)
            done[j] = True
        return Y
    Y = np.zeros((inputs.shape[0], model.n_y))
    prev = None
    for j, q in enumerate(inputs):
        guess = Y0[j] if Y0 is not None else prev
        try:
            Y[j] = solve_state(model, p, q, y0=guess)
        except StateSolveError:
            if guess is None:
                raise
            Y[j] = solve_state(model, p, q, y0=None)  # retry from the model's own guess
        prev = Y[j]
    return Y


def simulate(model, p, inputs, Y=None) -> np.ndarray:
    """Model outputs h(y_j(p), p, q_j) for every input row, shape (n_q, n_S)."""
    inputs = np.atleast_2d(np.asarray(inputs, float))
    if inputs.shape[1] != model.n_q_dim:
        raise ValueError(f"inputs: expected {model.n_q_dim} columns ({', '.join(model.inputs)}), got {inputs.shape[1]}")
    p = np.asarray(p, float).ravel()
    if p.shape != (model.n_p,):
        raise ValueError(f"p: expected {model.n_p} values ({', '.join(model.param_names)}), got {p.size}")
    if Y is None:
        Y = solve_states(model, p, inputs)
    num = numerics(model)
    if num.dense:
        return num.batched("h", inputs.shape[0])(Y, p, inputs)[0][:, :, 0]
    return np.array([np.asarray(model.h_fun(Y[j], p, inputs[j])).ravel() for j in range(inputs.shape[0])])
