"""A large input refinement in a child process that is ended at its time limit.

Building the refinement's NLP (:mod:`oed.input_nlp`) checks the time limit between its steps, but one step (a
row's Hessian, CasADi's ``nlpsol`` set-up) and one Ipopt iteration are single calls that Python cannot interrupt;
before the Hessian was assembled from one row's (session 12) the construction grew faster than the number of rows
(the DC motor of issue 30, 120 elements: 17 s for one row, 187 s for two, over 11 minutes for four).
:func:`oed.inputs.refine_inputs` therefore runs an NLP with more than :attr:`oed.inputs.RefineSettings.child_above`
variables under a time limit here:
a fresh interpreter (``python -c``: it imports no ``__main__``, so a plain script needs no guard) reads the
problem from its stdin (:func:`models.shipping.dumps`), builds and solves it, and writes the result to its
own copy of stdout (Ipopt's output goes to stderr).  At the time limit the child is killed, whatever phase
it is in, and :func:`run` returns None: the caller keeps the exact design's levels and says so.
"""
from __future__ import annotations

import os
import pickle
import subprocess
import sys

from models import shipping

__all__ = ["run", "main", "GRACE_S"]

#: seconds of the time limit left to the child for its last Ipopt iteration and its answer (its own
#: refinement runs under the limit less this, at least 90 % of it)
GRACE_S = 1.0
#: a limit longer than this (s) waits without a timeout: the OS's poll takes milliseconds in 32 bits (24.8 days)
#: and overflows on a larger one (``time_limit=1e9`` or ``inf``)
UNBOUNDED_S = 1e6


def run(call: tuple, time_limit: float):
    """The value of ``fn(*args, **kwargs)`` (``call`` = (fn, args, kwargs); ``fn`` a module-level function, sent
    by reference) computed in a child process, or None when it was not done within ``time_limit`` seconds (the
    child is then killed).

    Raises
    ------
    RuntimeError, ValueError
        What the refinement raised in the child (its type and message).
    """
    blob = shipping.dumps(call)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p), OPENBLAS_NUM_THREADS="1")
    proc = subprocess.Popen([sys.executable, "-c", "from oed.refine_child import main; main()"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    try:
        limit = float(time_limit)
        out, err = proc.communicate(blob, timeout=limit if limit <= UNBOUNDED_S else None)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        return None
    if proc.returncode != 0 or not out:
        last = err.decode(errors="replace").strip().splitlines()[-1:] or ["no message"]
        raise RuntimeError(f"refine: the child process running the refinement ended with code {proc.returncode} "
                           f"({last[0]})")
    kind, value = pickle.loads(out)
    if kind == "ok":
        return value
    raise (ValueError if kind == "ValueError" else RuntimeError)(value)


def main() -> None:
    """The child's side of :func:`run`: the call from stdin, the answer ("ok", result) or (error type, message)
    to the original stdout; everything printed meanwhile (Ipopt) goes to stderr."""
    answer = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    fn, args, kwargs = shipping.loads(sys.stdin.buffer.read())
    try:
        result = ("ok", fn(*args, **kwargs))
    except (ValueError, RuntimeError) as exc:
        result = (type(exc).__name__ if isinstance(exc, ValueError) else "RuntimeError", str(exc))
    answer.write(pickle.dumps(result))
    answer.flush()
