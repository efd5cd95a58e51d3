"""Dask execution of replication chunks: connect to a scheduler, ship one task, collect the chunks.

The Monte Carlo studies (:mod:`identification.studies.montecarlo`) and the bootstrap
(:mod:`identification.inference.bootstrap`) split their replications into chunks ``[(index,
SeedSequence), ...]`` (:mod:`identification.replicate` drives them); every chunk is one Dask task
``fn(task, chunk) -> [record, ...]``.
The task (models, data, settings) is sent once to every worker, serialised by
:func:`models.shipping.dumps` (cloudpickle: a model whose factory defines local functions is
sent by value; a model that cannot be is rebuilt from its factory in the worker); ``fn`` must
be a module-level function that the workers can import (the same ``mudoe`` installed on them).

Local worker processes leave interrupts to the process that started them: they ignore SIGINT
(a terminal's Ctrl-C reaches the whole process group; the parent decides and ends them), keep
SIGTERM's default action and end themselves when that parent is gone.

Seeds travel with the chunks, so the numbers do not depend on how the scheduler places them.

Local processes are spawned, and a spawned process imports the script that started the run
(``__main__``) before it can take a task.  Where that would fail -- the script read from stdin, or a
script that calls the run from its top level without ``if __name__ == "__main__":`` (the workers
would run it again) -- or where the task cannot be sent (:class:`models.shipping.ShippingError`),
:func:`execute` runs the chunks in this process and says why in one :class:`WorkersWarning`; never a
broken pool.  The default ``workers=None`` is therefore: every core when the script is guarded
(or run with ``python -m``, ``-c``, the ``mudoe`` command, a notebook), else serial with the warning.
"""
from __future__ import annotations

import ast
import inspect
import math
import os
import signal
import sys
import threading
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Callable

import numpy as np

from models import shipping

__all__ = ["Backend", "SchedulerError", "Shipped", "WorkersWarning", "call_locked", "check_scheduler", "connect",
           "execute", "main_rerun_hazard", "n_workers", "run_chunks", "run_local", "seed_chunks", "unpack",
           "worker_start"]

#: how long :func:`connect` waits for at least one worker to join the scheduler (s)
WORKER_WAIT_S = 30.0


class SchedulerError(ConnectionError):
    """The Dask scheduler cannot be used: not installed, unreachable, or without workers."""


class WorkersWarning(RuntimeWarning):
    """Local worker processes cannot be used here; the replications run in this process (the message says why)."""


@dataclass(frozen=True)
class Backend:
    """Where :func:`execute` ran the chunks.

    Attributes
    ----------
    kind : str       "serial" (this process), "local" (this process and spawned ones) or "dask"
    workers : int    processes (serial 1; local: this one included; dask: the scheduler's workers)
    address : str    the Dask scheduler's address ("" otherwise)
    """

    kind: str
    workers: int
    address: str = ""

    def __str__(self) -> str:
        """The backend in words: serial, 2 local processes, dask (tcp://..., 4 workers)."""
        if self.kind == "dask":
            return f"dask ({self.address}, {self.workers} workers)"
        return "serial" if self.kind == "serial" else f"{self.workers} local processes"


def check_scheduler(scheduler, name: str = "scheduler"):
    """``scheduler`` if it is None, a non-empty address string or a ``distributed.Client``; else ValueError."""
    if scheduler is None or hasattr(scheduler, "submit"):
        return scheduler
    if isinstance(scheduler, str) and scheduler.strip():
        return scheduler.strip()
    raise ValueError(f"{name}: expected a Dask scheduler address such as 'tcp://10.0.0.5:8786' (printed by "
                     f"`dask scheduler`), a distributed.Client or None (local), got {scheduler!r}")


def _client_class():
    try:
        from distributed import Client
    except ImportError as exc:
        raise SchedulerError(f"scheduler: Dask is not installed ({exc}); install it with "
                             "pip install 'dask[distributed]' (or pip install -e '.[dist]')") from None
    return Client


@contextmanager
def connect(scheduler, worker_wait: float = WORKER_WAIT_S):
    """A ``distributed.Client`` for ``scheduler`` (an address, or a Client used as is and not closed).

    The connection timeout is Dask's (``distributed.comm.timeouts.connect``, 30 s by default;
    environment ``DASK_DISTRIBUTED__COMM__TIMEOUTS__CONNECT=5s``).

    Raises
    ------
    SchedulerError
        Dask is not installed, the scheduler cannot be reached, or no worker joined it
        within ``worker_wait`` seconds.
    """
    check_scheduler(scheduler)
    if scheduler is None:
        raise ValueError("scheduler: None means local processes; connect() needs an address or a Client")
    if hasattr(scheduler, "submit"):
        yield scheduler
        return
    client_class = _client_class()
    try:
        client = client_class(scheduler, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise SchedulerError(f"scheduler: cannot reach the Dask scheduler at {scheduler!r} "
                             f"({type(exc).__name__}: {' '.join(str(exc).split())[:200]}); start one with "
                             "`dask scheduler` and give the address it prints, e.g. tcp://HOST:8786") from None
    try:
        try:
            client.wait_for_workers(1, timeout=worker_wait)
        except (OSError, TimeoutError) as exc:
            raise SchedulerError(f"scheduler: no Dask worker joined the scheduler at {scheduler!r} within "
                                 f"{worker_wait:g} s ({type(exc).__name__}); start workers with "
                                 f"`dask worker {scheduler} --nworkers N --nthreads 1`") from None
        yield client
    finally:
        client.close()


def n_workers(client) -> int:
    """Workers connected to the scheduler of ``client`` (at least 1)."""
    return max(1, len(client.scheduler_info().get("workers", {})))


#: one chunk at a time per process: CasADi functions and Ipopt solvers are not thread-safe, and a
#: worker's threads (``dask worker --nthreads 2``, or an in-process LocalCluster) share the
#: unpickled task.  Workers started with ``--nthreads 1`` never wait on it.
_PROCESS_LOCK = threading.Lock()


class Shipped:
    """A task serialised once by :func:`models.shipping.dumps` (``blob``), with a ``key`` naming it."""

    def __init__(self, task):
        import uuid
        self.blob = shipping.dumps(task)
        self.key = uuid.uuid4().hex


#: the task this process last unpacked from a :class:`Shipped` ({key: task}; one entry), and its lock
_UNPACKED: dict = {}
_UNPACK_LOCK = threading.Lock()


def unpack(task):
    """``task`` itself, or the task of a :class:`Shipped` (unpacked once per process and key)."""
    if not isinstance(task, Shipped):
        return task
    with _UNPACK_LOCK:
        if task.key not in _UNPACKED:
            _UNPACKED.clear()
            _UNPACKED[task.key] = shipping.loads(task.blob)
        return _UNPACKED[task.key]


def call_locked(fn: Callable, task, chunk):
    """``fn(task, chunk)`` holding this process's chunk lock (the Dask task of :func:`run_chunks`);
    ``task`` may be a :class:`Shipped` (unpacked once per process)."""
    with _PROCESS_LOCK:
        return fn(unpack(task), chunk)


def run_chunks(client, fn: Callable, task, chunks: list, on_result: Callable) -> None:
    """``on_result(fn(task, chunk))`` for every chunk, as the Dask tasks finish (task sent once).

    ``task`` is serialised here by :func:`models.shipping.dumps` (a :class:`Shipped`: a model that
    cannot be pickled by value is rebuilt from its factory on the workers); ``fn`` runs under a
    per-process lock (:func:`call_locked`).  A chunk that raises re-raises here (the remaining
    futures are cancelled).
    """
    from distributed import as_completed
    tf = client.scatter(Shipped(task), broadcast=True, hash=False)  # own key: no release race
    futs = client.map(call_locked, [fn] * len(chunks), [tf] * len(chunks), chunks, pure=False)
    try:
        for fut in as_completed(futs, loop=client.loop):
            on_result(fut.result())
    finally:
        client.cancel(futs)


def execute(fn: Callable, task, make_chunks: Callable, on_result: Callable, workers: int | None = 1,
            scheduler=None, install: Callable | None = None) -> Backend:
    """Run every chunk ``fn(task, chunk)`` serially, on local processes or on a Dask scheduler.

    Parameters
    ----------
    fn : module-level callable (task or None, chunk) -> list
        ``task`` None means "the task installed in this process" (local processes).
    task : picklable
    make_chunks : callable (n_workers) -> list of chunks
    on_result : callable (list) -> None, called with every chunk's result as it finishes
    workers : int or None   processes (1: serial in this process; None: all cores; N > 1: this process and
                            N - 1 spawned ones, :func:`run_local`)
    scheduler : None, a Dask scheduler address or a distributed.Client (then ``workers`` is ignored)
    install : module-level callable (task) -> None
        Stores ``task`` in a spawned process (the pool initializer); needed when ``workers`` > 1.

    Returns
    -------
    Backend : the backend used (``str()``: "serial", "2 local processes" (this one and 1 spawned),
    "dask (tcp://..., 4 workers)").
    """
    if scheduler is not None:
        with connect(scheduler) as client:
            n_w = n_workers(client)
            run_chunks(client, fn, task, make_chunks(n_w), on_result)
            return Backend("dask", n_w, str(client.scheduler.address))
    n_w = int(workers or os.cpu_count() or 1)
    blob = None
    if n_w > 1:
        blob, why = _shipped_or_why(task)
        if why:
            warnings.warn(f"running the replications in this process, not on {n_w} local processes: {why}",
                          WorkersWarning, stacklevel=_caller_level())
            n_w = 1
    if n_w == 1:
        for ch in make_chunks(1):
            on_result(fn(task, ch))
        return Backend("serial", 1)
    if install is None:
        raise ValueError("install: local processes need the function that stores the task in a worker")
    run_local(fn, task, make_chunks(n_w), on_result, n_w, install, blob=blob)
    return Backend("local", n_w)


def _shipped_or_why(task) -> tuple:
    """(the task serialised for spawned processes, "") or (None, why they cannot take it)."""
    why = main_rerun_hazard()
    if why:
        return None, why
    try:
        return shipping.dumps(task), ""
    except shipping.ShippingError as exc:
        return None, str(exc).split(";")[0]


def main_rerun_hazard() -> str:
    """Why a spawned process cannot start in this program ("" when it can): it imports ``__main__`` first,
    which fails for a script read from stdin and runs the run again for a script calling it from its top
    level without ``if __name__ == "__main__":`` (see the module docstring)."""
    main = sys.modules.get("__main__")
    spec = getattr(main, "__spec__", None)
    name = getattr(spec, "name", None)
    if name is not None and (name == "__main__" or name.endswith(".__main__")):
        return ""                   # python -m pkg: the workers do not import it
    path = getattr(spec, "origin", None) if name is not None else getattr(main, "__file__", None)
    if not path:
        return ""                   # python -c, an interactive session, a notebook: nothing to import
    if not os.path.isfile(path):
        return (f"the script was read from standard input ({path}), which spawned worker processes cannot import; "
                "save it as a file with its work under `if __name__ == \"__main__\":` to use them")
    frame = inspect.currentframe()
    while frame is not None and not (frame.f_globals is vars(main) and frame.f_code.co_name == "<module>"):
        frame = frame.f_back
    if frame is None or _guarded(path, frame.f_lineno):
        return ""
    return (f"{os.path.basename(path)} starts it from its top level (line {frame.f_lineno}) without "
            "`if __name__ == \"__main__\":`, and every spawned worker process would run the script again; put the "
            "script's work under that guard to use them")


def _guarded(path: str, line: int) -> bool:
    """Line ``line`` of the script ``path`` lies in a top-level ``if __name__ == "__main__":`` block."""
    try:
        with open(path, "rb") as f:
            tree = ast.parse(f.read())
    except (OSError, SyntaxError, ValueError):
        return False

    def is_main_test(t) -> bool:
        parts = [t.left] + list(t.comparators) if isinstance(t, ast.Compare) else []
        return (len(parts) == 2 and isinstance(t.ops[0], ast.Eq)
                and {type(v).__name__ for v in parts} == {"Name", "Constant"}
                and any(isinstance(v, ast.Name) and v.id == "__name__" for v in parts)
                and any(isinstance(v, ast.Constant) and v.value == "__main__" for v in parts))
    return any(isinstance(n, ast.If) and is_main_test(n.test) and n.body[0].lineno <= line <= n.body[-1].end_lineno
               for n in tree.body)


def _caller_level() -> int:
    """The ``stacklevel`` of a warning that points at the first caller outside mudoe's packages."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    ours = tuple(os.path.join(root, pkg) + os.sep for pkg in ("identification", "models", "oed", "reports", "mudoe"))
    frame, level = inspect.currentframe().f_back, 1     # level 1: the function calling warnings.warn
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(ours):
        frame, level = frame.f_back, level + 1
    return level


def run_local(fn: Callable, task, chunks: list, on_result: Callable, n_workers: int, install: Callable,
              blob: bytes | None = None) -> None:
    """``on_result(fn(task, chunk))`` for every chunk, on this process and ``n_workers - 1`` spawned ones.

    This process is one of the workers: it has imported everything and built the models
    already, so it starts on the first chunk at once, and the C code it JIT-compiles on the
    way lands in the on-disk cache (:mod:`models.jit_cache`) from which the spawned processes
    load it (they pay the interpreter start and the imports, about 1 s each, meanwhile).
    Chunks are handed out one at a time, in order, to whichever worker is free, a spawned one
    from the moment it is ready (one feeder thread per spawned process waits on its results;
    this process's main thread runs chunks between them): a short run is not held up by a
    starting process, and the last chunk ends at most one chunk after the others.  The chunks
    themselves do not change, so neither do the numbers.

    Parameters
    ----------
    fn : module-level callable (task or None, chunk) -> list
        Called here as ``fn(task, chunk)``; in a spawned process as ``fn(None, chunk)`` after
        ``install(task)`` (the pool initializer).  Resetting what ``fn(task, chunk)`` leaves in
        this process (a worker state, a JIT switch) is the caller's job.
    task : any object :func:`models.shipping.dumps` can send (serialised once, here)
    chunks : list
    on_result : callable (list) -> None, called with every chunk's result (in this thread)
    n_workers : int >= 2    processes in all, this one included
    install : module-level callable (task) -> None
    blob : bytes, optional  ``task`` already serialised by :func:`models.shipping.dumps`

    Raises
    ------
    models.shipping.ShippingError
        ``task`` cannot be sent (before any process is started).
    """
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor
    if int(n_workers) < 2:
        raise ValueError(f"n_workers: run_local needs at least 2 processes (this one and 1 spawned), got {n_workers}")
    blob = shipping.dumps(task) if blob is None else blob
    _start_resource_tracker()
    run = _Dispatch(chunks, on_result)
    with ProcessPoolExecutor(max_workers=int(n_workers) - 1, mp_context=mp.get_context("spawn"),
                             initializer=worker_start, initargs=(install, blob, os.getpid())) as pool:
        feeders = [threading.Thread(target=run.feed, args=(pool, fn), daemon=True, name=f"mudoe-feed-{k}")
                   for k in range(int(n_workers) - 1)]
        try:
            for t in feeders:
                t.start()
            while (ch := run.take()) is not None:
                on_result(fn(task, ch))
                run.deliver(0)
            while any(t.is_alive() for t in feeders) or not run.done.empty():
                run.deliver(0.05)
        finally:
            run.stop.set()
            for t in feeders:
                t.join()


def _start_resource_tracker() -> None:
    """Start multiprocessing's resource tracker now, keeping this thread's signal mask.

    The standard library starts it with the first pool and unblocks SIGINT and SIGTERM in the
    starting thread afterwards, whatever the mask was: a program that takes these signals in a
    thread of its own (``sigwait``, the CLI) would then get them in this thread, where a C
    library running ``system()`` (CasADi's JIT compiler) ignores them.
    """
    from multiprocessing import resource_tracker
    if not hasattr(signal, "pthread_sigmask"):
        resource_tracker.ensure_running()
        return
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    try:
        resource_tracker.ensure_running()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)


#: seconds between a spawned worker's checks that the process that started it still runs
PARENT_POLL_S = 0.5

#: what went wrong while this spawned worker unpacked and installed its task (raised by :func:`_ready`)
_START_ERRORS: list = []


def worker_start(install: Callable, blob: bytes, parent: int) -> None:
    """A spawned worker's initializer: signals (see the module docstring), then ``install(task)``.

    SIGINT is ignored (the parent ends its workers), SIGTERM has its default action and is not
    blocked (a spawned process inherits the parent's signal mask), and a daemon thread ends the
    process when ``parent`` is gone (its parent id changes), so that no worker outlives a
    parent that was killed.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})
    threading.Thread(target=_exit_with_parent, args=(parent,), daemon=True, name="mudoe-parent-watch").start()
    try:
        install(shipping.loads(blob))
    except Exception as exc:  # noqa: BLE001 -- raised by _ready() instead: the parent then sees this error
        _START_ERRORS.append(exc)           # (an initializer's error only breaks the pool without a reason)


def _exit_with_parent(parent: int) -> None:
    """Daemon thread of a spawned worker: end the process once ``parent`` no longer is its parent."""
    import time
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


def _ready() -> int:
    """A spawned worker's first call: returns once it is started and its task installed (its pid), or
    raises what failed while it unpacked or installed the task (e.g. a model's factory)."""
    if _START_ERRORS:
        raise _START_ERRORS[0]
    return os.getpid()


class _Dispatch:
    """The chunks of one :func:`run_local` call, handed out in order to whichever worker is free."""

    def __init__(self, chunks: list, on_result: Callable):
        import queue
        from collections import deque
        self.todo = deque(chunks)
        self.lock = threading.Lock()
        self.done = queue.Queue()      # (result, None) or (None, exception) from the feeder threads
        self.stop = threading.Event()
        self.on_result = on_result

    def take(self):
        """The next chunk, or None when none is left (or a worker failed)."""
        with self.lock:
            return self.todo.popleft() if self.todo and not self.stop.is_set() else None

    def feed(self, pool, fn: Callable) -> None:
        """Hand one spawned process one chunk at a time (feeder thread), from the moment it is ready (started
        and its task installed: no chunk waits on a starting process); results or the error go to ``done``."""
        try:
            pool.submit(_ready).result()
            while (ch := self.take()) is not None:
                self.done.put((pool.submit(fn, None, ch).result(), None))
        except Exception as exc:        # re-raised in the main thread (a chunk's error, a broken pool)
            self.stop.set()
            self.done.put((None, exc))

    def deliver(self, timeout: float) -> None:
        """Pass the finished results to ``on_result`` (main thread), waiting up to ``timeout`` s for the first."""
        import queue
        try:
            while True:
                res, exc = self.done.get(timeout=timeout) if timeout else self.done.get_nowait()
                if exc is not None:
                    raise exc
                self.on_result(res)
                timeout = 0
        except queue.Empty:
            return


def seed_chunks(n: int, seed, n_workers: int, chunk_size: int | None = None, per_worker: int = 4,
                max_size: int = 20) -> list:
    """Replications 0..n-1 with their seeds, cut into chunks [[(r, SeedSequence(seed).spawn(n)[r]), ...], ...].

    ``chunk_size`` replications per chunk (None: about ``per_worker`` chunks per worker, at most
    ``max_size`` each).  The seeds do not depend on the chunks.
    """
    items = list(enumerate(np.random.SeedSequence(seed).spawn(int(n))))
    size = chunk_size or max(1, min(max_size, math.ceil(n / (per_worker * max(1, n_workers)))))
    return [items[k:k + size] for k in range(0, len(items), size)]
