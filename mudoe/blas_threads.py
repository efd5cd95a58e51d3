"""One BLAS thread in the command line's process and in the worker processes it starts, unless the user chose.

A study's linear algebra is many small dense factorisations (Cholesky of 100 x 100 covariance blocks, the
parameters' Hessians); OpenBLAS's default of one thread per core makes every call wake, and on a loaded
machine wait for, threads that have almost nothing to do: 2-20x the CPU of one thread (bench/RESULTS.md,
"Issue 30 item 7").  ``mudoe`` therefore runs its commands with one BLAS thread:

* the variables ``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS`` and ``MKL_NUM_THREADS`` are set to 1 for the
  run, so the BLAS libraries loaded later in the process and every worker process it spawns start with one
  thread (OpenBLAS reads them once, when it is loaded);
* the BLAS libraries already loaded (``mudoe.cli.main`` called from a Python session that imported numpy)
  are limited to one thread by threadpoolctl for the run, and given back their threads afterwards.

A user who sets any of :data:`USER_VARIABLES` (e.g. ``OPENBLAS_NUM_THREADS=2 mudoe report ...``) keeps that
choice: nothing is changed.  The numbers do not depend on it beyond round-off (threaded BLAS sums in another
order).
"""
from __future__ import annotations

import contextlib
import os
import sys

__all__ = ["USER_VARIABLES", "PINNED_VARIABLES", "user_choice", "one_blas_thread"]

#: variables by which a user chooses the BLAS/OpenMP threads; any of them set (non-empty) is respected
USER_VARIABLES = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS",
                  "BLIS_NUM_THREADS", "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")
#: variables set to "1" for the run when the user chose none
PINNED_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def user_choice(environ=None) -> str | None:
    """The first of :data:`USER_VARIABLES` set in ``environ`` (default ``os.environ``) as ``NAME=value``, or None.

    Parameters
    ----------
    environ : mapping, optional
        The environment to read (default the process's).

    Returns
    -------
    str or None
        ``"NAME=value"`` of the user's choice; None when the user set none of them.
    """
    env = os.environ if environ is None else environ
    for name in USER_VARIABLES:
        if env.get(name, "").strip():
            return f"{name}={env[name]}"
    return None


@contextlib.contextmanager
def one_blas_thread():
    """Run the block with n_threads = 1 for every BLAS library (see the module docstring), unless the user chose.

    Sets :data:`PINNED_VARIABLES` to "1" (restored on exit) and, when numpy is already imported, limits the
    loaded BLAS libraries with ``threadpoolctl.threadpool_limits(1, user_api="blas")`` (restored on exit).
    Does nothing when :func:`user_choice` finds a user's setting.

    Yields
    ------
    str
        What was done, one line (for ``--debug``).
    """
    chosen = user_choice()
    if chosen is not None:
        yield f"BLAS threads as the user set them ({chosen})"
        return
    saved = {name: os.environ.get(name) for name in PINNED_VARIABLES}
    os.environ.update({name: "1" for name in PINNED_VARIABLES})
    try:
        if "numpy" in sys.modules:          # BLAS already loaded: the variables above come too late for it
            from threadpoolctl import threadpool_limits
            with threadpool_limits(limits=1, user_api="blas"):
                yield "one BLAS thread (loaded libraries limited by threadpoolctl)"
        else:
            yield "one BLAS thread (" + ", ".join(f"{n}=1" for n in PINNED_VARIABLES) + ")"
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
