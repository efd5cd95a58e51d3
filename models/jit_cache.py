"""On-disk cache of JIT-compiled CasADi functions: compile once per machine, load everywhere else.

A CasADi SX function compiled with ``jit`` (C code through the system compiler) costs 0.3-0.8 s
of ``gcc`` per function for the press model; a Monte Carlo run on N local processes or Dask
workers used to pay it N times, and every run again.  :class:`JitCache` keeps the compiled
shared libraries in a per-user directory, content-addressed:

    key = sha256(function serialisation, compiler flags, CasADi version, compiler binary, machine)

Entry ``<key>.casadi`` is the compiled function serialised by CasADi with
``jit_serialize="link"`` (its text names the shared library ``jit<key>t<token>.so`` next to it),
after a header line with the sha256 of that text and of the library; loading it checks both
hashes (a truncated library would crash ``dlopen``) and is then a ``dlopen``: 10-30 ms for the
press model's functions, no compilation.  The compiled function is the same
:class:`casadi.Function` (an SX function whose evaluation calls the compiled code, with SX
derivatives) that ``jit=True`` gives, built with the same options: same numbers.

Safety under concurrent processes (local pools, Dask workers, several runs):

* an entry is published by ``os.replace`` of a complete temporary file, and the library it
  names is written before, under a fresh name that no other entry uses: a reader sees either
  no entry or a complete one, and a library never changes once written;
* the compiling process holds an exclusive ``fcntl.flock`` on ``<key>.lock``; a second process
  needing the same key waits for it and then loads the entry (one compilation, not one per
  worker).  Without ``fcntl`` (Windows) both compile and the last ``os.replace`` wins;
* CasADi compiles the derivatives of a loaded function (Ipopt's gradients) with the entry's own
  options, into the cache directory, and reserves an (empty) source name on every load; the
  library names carry a random suffix so that each derivative gets its own library, and
  :func:`prune_strays` removes what no entry names once it is an hour old (once per process);
* an entry that cannot be loaded (hash mismatch, truncated, library missing, other signature) is
  replaced by a fresh compilation, never an error; a failing compiler raises
  :class:`JitCompileError` (callers fall back to CasADi's virtual machine).
"""
from __future__ import annotations

import glob
import hashlib
import json
import os
import platform
import secrets
import shutil
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass

import casadi as ca

try:
    import fcntl
except ImportError:     # Windows: no advisory locks; concurrent compilations stay correct (atomic replace)
    fcntl = None

__all__ = ["JitCache", "JitCompileError", "JitStats", "default_cache_dir", "function_key", "CACHE_DIR_ENV"]

#: environment variable naming the cache directory (overrides the default, see :func:`default_cache_dir`)
CACHE_DIR_ENV = "MUDOE_JIT_CACHE"


class JitCompileError(RuntimeError):
    """The C compiler is missing or failed on the generated code."""


@dataclass
class JitStats:
    """Counters of one process's JIT work (read by benchmarks; reset with :meth:`reset`).

    Attributes
    ----------
    compiled : int      functions compiled by this process (cache misses)
    loaded : int        functions loaded from the cache (hits, including after waiting for another process)
    recovered : int     entries found unusable (corrupt, truncated, library gone) and recompiled
    compile_s : float   wall seconds spent compiling (the compiler runs in child processes)
    load_s : float      wall seconds spent reading entries, loading libraries and waiting for locks
    """

    compiled: int = 0
    loaded: int = 0
    recovered: int = 0
    compile_s: float = 0.0
    load_s: float = 0.0

    def reset(self) -> None:
        self.compiled = self.loaded = self.recovered = 0
        self.compile_s = self.load_s = 0.0


def default_cache_dir() -> str:
    """The per-user cache directory: ``$MUDOE_JIT_CACHE``, else ``$XDG_CACHE_HOME/mudoe/jit`` (default
    ``~/.cache/mudoe/jit``), else (not writable) ``<tempdir>/mudoe-jit-<user id>``."""
    env = os.environ.get(CACHE_DIR_ENV)
    if env:
        return env
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    for d in (os.path.join(base, "mudoe", "jit"),
              os.path.join(tempfile.gettempdir(), f"mudoe-jit-{os.getuid() if hasattr(os, 'getuid') else 'user'}")):
        try:
            os.makedirs(d, mode=0o700, exist_ok=True)
        except OSError:
            continue
        if os.access(d, os.W_OK | os.X_OK):
            return d
    raise JitCompileError("no writable directory for the JIT cache; set MUDOE_JIT_CACHE to one")


#: part of every key: entries of an older layout (libraries without a random suffix, whose derivatives
#: could not be loaded) are never used
CACHE_FORMAT = "mudoe-jit-2"

_COMPILER_IDS: dict = {}


def _compiler_id(compiler: str) -> str:
    """Path, size and modification time of the compiler binary (an upgraded compiler gets new keys)."""
    got = _COMPILER_IDS.get(compiler)
    if got is None:
        path = shutil.which(compiler)
        if path is None:
            raise JitCompileError(f"no C compiler {compiler!r} on the PATH")
        real = os.path.realpath(path)
        st = os.stat(real)
        got = _COMPILER_IDS[compiler] = f"{real}:{st.st_size}:{st.st_mtime_ns}"
    return got


def function_key(f: ca.Function, flags, compiler: str = "gcc") -> str:
    """sha256 (hex) of ``f``'s serialisation, the compiler flags, CasADi's version, the compiler and machine."""
    h = hashlib.sha256()
    for part in (f.serialize(), CACHE_FORMAT, "\0".join(flags), ca.__version__, _compiler_id(compiler), platform.machine(),
                 platform.system()):
        h.update(part.encode())
        h.update(b"\0\1")
    return h.hexdigest()


#: files older than this (s) that no entry names are removed (the derivatives' generated code and libraries)
STRAY_AGE_S = 3600.0

_PRUNED: set = set()


def prune_strays(directory: str, max_age_s: float = STRAY_AGE_S) -> int:
    """Remove the files of ``directory`` that no entry needs and that are older than ``max_age_s``.

    CasADi compiles the derivatives of a loaded function (Ipopt's gradients and Hessians) with the
    function's own options, so their code and libraries land in the cache directory too, under the
    entry's name and a random suffix; nothing else refers to them once the process that made them
    has loaded them.  Kept: entries (``*.casadi``), locks, the library each entry names, and every
    file younger than ``max_age_s`` (a compilation in progress).  Returns the number removed.
    """
    try:
        names = os.listdir(directory)
    except OSError:
        return 0
    keep = set()
    for n in names:
        if n.endswith(".casadi"):
            try:
                with open(os.path.join(directory, n), "rb") as fh:
                    keep.add(json.loads(fh.readline())["library"])
            except (OSError, ValueError, KeyError, TypeError):
                continue                        # unreadable entry: its library goes when it is old
    now = time.time()
    removed = 0
    for n in names:
        if n in keep or n.endswith((".casadi", ".lock")) or not n.startswith("jit"):
            continue
        path = os.path.join(directory, n)
        try:
            if now - os.path.getmtime(path) > max_age_s:
                os.remove(path)
                removed += 1
        except OSError:
            continue
    return removed


def _remove(path: str) -> None:
    try:
        os.remove(path)
    except FileNotFoundError:
        pass


class JitCache:
    """Compiled copies of CasADi SX functions, kept in ``directory`` across processes and runs.

    Parameters
    ----------
    directory : str or None   the cache directory (None: :func:`default_cache_dir`, resolved on first use)
    flags : tuple of str      compiler flags (part of the key)
    compiler : str            the compiler command CasADi's ``shell`` plugin calls (part of the key)
    stats : JitStats or None  counters to add this cache's work to (None: new ones, :attr:`stats`)
    """

    def __init__(self, directory: str | None = None, flags=("-O1",), compiler: str = "gcc",
                 stats: JitStats | None = None):
        self._directory = directory
        self.flags = tuple(flags)
        self.compiler = compiler
        self.stats = JitStats() if stats is None else stats

    @property
    def directory(self) -> str:
        """The cache directory (created on first use)."""
        if self._directory is None:
            self._directory = default_cache_dir()
        os.makedirs(self._directory, mode=0o700, exist_ok=True)
        if self._directory not in _PRUNED:      # once per process and directory
            _PRUNED.add(self._directory)
            prune_strays(self._directory)
        return self._directory

    def entry_path(self, key: str) -> str:
        """The entry file of ``key`` (the serialised compiled function)."""
        return os.path.join(self.directory, f"{key}.casadi")

    def get(self, f: ca.Function, name: str | None = None) -> ca.Function:
        """The compiled copy of the SX function ``f`` (named ``name``, default ``<f.name()>_jit``):
        loaded from the cache, or compiled (once across processes, see the module docstring) and stored.

        Raises
        ------
        JitCompileError
            No compiler, or the compiler failed.
        """
        name = name or f"{f.name()}_jit"
        wrapped = ca.Function(name, f.sx_in(), f.call(f.sx_in()), f.name_in(), f.name_out())
        key = function_key(wrapped, self.flags, self.compiler)
        t0 = time.perf_counter()
        g = self._load(key, wrapped)
        if g is not None:
            self.stats.loaded += 1
            self.stats.load_s += time.perf_counter() - t0
            return g
        with self._locked(key):
            g = self._load(key, wrapped)        # compiled by another process while we waited
            if g is not None:
                self.stats.loaded += 1
                self.stats.load_s += time.perf_counter() - t0
                return g
            if os.path.exists(self.entry_path(key)):
                self.stats.recovered += 1       # present but unusable: replaced below
            t1 = time.perf_counter()
            self.stats.load_s += t1 - t0
            g = self._compile(key, wrapped)
            self.stats.compiled += 1
            self.stats.compile_s += time.perf_counter() - t1
            return g

    # ---------------------------------------------------------------- internals
    @contextmanager
    def _locked(self, key: str):
        """Exclusive advisory lock on ``<key>.lock`` (no-op without fcntl)."""
        if fcntl is None:
            yield
            return
        fd = os.open(os.path.join(self.directory, f"{key}.lock"), os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            yield
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)

    def _load(self, key: str, wrapped: ca.Function) -> ca.Function | None:
        """The function of entry ``key`` if the entry and its library are intact (sha256 of both as
        recorded) and it has ``wrapped``'s signature, else None (missing or damaged)."""
        try:
            with open(self.entry_path(key), "rb") as fh:
                header, _, body = fh.read().partition(b"\n")
            meta = json.loads(header)
            lib = os.path.join(self.directory, meta["library"])
            if hashlib.sha256(body).hexdigest() != meta["entry_sha256"] or _file_sha256(lib) != meta["library_sha256"]:
                return None                     # truncated or altered: never hand it to dlopen
            g = ca.Function.deserialize(body.decode())
        except (OSError, ValueError, KeyError, TypeError, RuntimeError):
            return None                         # missing, unreadable or not ours
        if not _same_signature(g, wrapped):
            return None
        return g

    def _compile(self, key: str, wrapped: ca.Function) -> ca.Function:
        """Compile ``wrapped`` to a fresh library ``jit<key>t<token>.so`` and publish its entry atomically
        (a JSON header line: library name and the sha256 of library and entry text; then CasADi's text)."""
        d = self.directory
        stem = f"jit{key}t{secrets.token_hex(4)}"   # a valid CasADi name
        try:
            g = ca.Function(wrapped.name(), wrapped.sx_in(), wrapped.call(wrapped.sx_in()), wrapped.name_in(),
                            wrapped.name_out(),
                            {"jit": True, "compiler": "shell", "jit_name": stem, "jit_temp_suffix": True,
                             "jit_cleanup": False, "jit_serialize": "link",
                             "jit_options": {"flags": list(self.flags), "verbose": False, "cleanup": False,
                                             "directory": d + os.sep, "name": stem, "temp_suffix": True,
                                             "compiler": self.compiler}})
        except RuntimeError as exc:
            for path in glob.glob(os.path.join(d, stem + "*")):
                _remove(path)
            raise JitCompileError(f"compiling {wrapped.name()} with {self.compiler} failed: "
                                  f"{' '.join(str(exc).split())[:300]}") from None
        # The names carry a random suffix (``temp_suffix``): the derivatives CasADi compiles later from
        # the loaded function (Ipopt's gradients, with these same options) then get libraries of their
        # own; a fixed name made dlopen return this library again and the derivative failed to load.
        libs = glob.glob(os.path.join(d, stem + "*.so"))
        for path in glob.glob(os.path.join(d, stem + "*.c")) + glob.glob(os.path.join(d, stem + "*.o")):
            _remove(path)
        if len(libs) != 1:
            raise JitCompileError(f"compiling {wrapped.name()}: expected one library {stem}*.so in {d}, "
                                  f"found {len(libs)}")
        lib = os.path.basename(libs[0])
        body = g.serialize().encode()
        header = json.dumps({"library": lib, "library_sha256": _file_sha256(libs[0]),
                             "entry_sha256": hashlib.sha256(body).hexdigest(), "function": wrapped.name()})
        tmp = os.path.join(d, f"{stem}.tmp")
        with open(tmp, "wb") as fh:
            fh.write(header.encode() + b"\n" + body)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.entry_path(key))
        for old in os.listdir(d):               # libraries of replaced (damaged) entries of this key
            if old.startswith(f"jit{key}t") and old.endswith(".so") and old != lib:
                _remove(os.path.join(d, old))   # a process that still maps one keeps it (unlink)
        return g


def _file_sha256(path: str) -> str:
    with open(path, "rb") as fh:
        return hashlib.sha256(fh.read()).hexdigest()


def _same_signature(g: ca.Function, f: ca.Function) -> bool:
    """Same name, numbers of inputs and outputs, and sparsities."""
    if g.name() != f.name() or g.n_in() != f.n_in() or g.n_out() != f.n_out():
        return False
    return (all(g.sparsity_in(i) == f.sparsity_in(i) for i in range(f.n_in()))
            and all(g.sparsity_out(i) == f.sparsity_out(i) for i in range(f.n_out())))
