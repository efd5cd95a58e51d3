r"""Member fits run side by side with their trajectory evaluations merged (:func:`run_merged`).

Each task (e.g. one fit of a collocated model per data set of a Monte Carlo batch) runs in its own thread; a
call of :class:`models.trajectory.TrajectoryNumerics` (states, sweep, Hessian terms, outputs and sensitivities)
made inside one waits until every running task has one pending, and the pending calls are evaluated together,
kind by kind, each experiment at its own task's p: one set of mapped CasADi calls and batched solves of the
element blocks for all tasks, the same numbers as running the tasks one after the other.  The evaluation itself
belongs to the trajectory numerics (:meth:`models.trajectory.TrajectoryNumerics.evaluate_merged`,
:meth:`~models.trajectory.TrajectoryNumerics.evaluate_one`); this module only queues, groups and hands back.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

__all__ = ["PendingCall", "Broker", "current_broker", "merging", "run_merged"]

#: the broker of this thread's member fit in :func:`run_merged` (None outside one)
_LOCAL = threading.local()


def current_broker() -> "Broker | None":
    """The broker of this thread's task of :func:`run_merged`, None outside one."""
    return getattr(_LOCAL, "broker", None)


def merging() -> bool:
    """True inside one fit of :func:`run_merged` (this thread's trajectory evaluations are merged with other
    fits': their numbers depend on the merged batch, so a value computed outside it is not reused inside)."""
    return current_broker() is not None


@dataclass
class PendingCall:
    """One task's call waiting for the merged evaluation: the trajectory numerics ``traj`` it was made on, its
    ``kind`` ("states", "sweep", "hessians", "outputs_and_sensitivities"), p (shared (n_p,) or per experiment),
    the input rows, the remaining arguments ``rest``, and the ``slot`` its result ("out") or error ("error")
    is put into."""
    traj: Any
    kind: str
    p: Any
    inputs: Any
    rest: tuple
    slot: dict = field(default_factory=dict)


class Broker:
    """Merges the trajectory evaluations of the threads of :func:`run_merged`: a thread's call waits
    until every running thread has one pending (or has finished); the calls are then evaluated
    together, grouped by numerics, kind and :meth:`merge_key`, and each thread gets its own rows back.  A
    merged evaluation that fails (a state solve of one thread's p) is redone thread by thread, so that the
    error reaches its own thread only."""

    def __init__(self, n_running: int):
        self._cv = threading.Condition(threading.RLock())
        self._running = n_running
        self._pending: list[PendingCall] = []

    @property
    def turn(self):
        """The lock a task of :func:`run_merged` holds while it runs (released while it waits here)."""
        return self._cv

    def call(self, traj, kind: str, p, inputs, *rest):
        """The result of ``traj``'s call ``kind`` with these arguments, evaluated together with the other
        running tasks' pending calls; re-raises the error of this task's own evaluation."""
        pending = PendingCall(traj, kind, p, inputs, rest)
        with self._cv:
            self._pending.append(pending)
            self._flush_if_ready()
            while "out" not in pending.slot and "error" not in pending.slot:
                self._cv.wait()
        if "error" in pending.slot:
            raise pending.slot["error"]
        return pending.slot["out"]

    def finished(self) -> None:
        """One task ended: the others no longer wait for a call of it."""
        with self._cv:
            self._running -= 1
            self._flush_if_ready()

    def _flush_if_ready(self) -> None:
        if not self._pending or len(self._pending) < self._running:
            return
        pending, self._pending = self._pending, []
        groups: dict = {}
        for c in pending:
            groups.setdefault((id(c.traj), c.kind, c.traj.merge_key(c.kind, c.rest)), []).append(c)
        for calls in groups.values():
            try:
                outs = calls[0].traj.evaluate_merged(calls[0].kind, calls)
            except Exception:                    # noqa: BLE001 - redone one by one: each error to its own thread
                outs = None
            for i, c in enumerate(calls):
                if outs is not None:
                    c.slot["out"] = outs[i]
                    continue
                try:
                    c.slot["out"] = c.traj.evaluate_one(c.kind, c.p, c.inputs, c.rest)
                except Exception as exc:         # noqa: BLE001 - re-raised in the calling thread
                    c.slot["error"] = exc
        self._cv.notify_all()


def run_merged(tasks: Sequence[Callable[[], object]]) -> list:
    """Run the tasks (e.g. one fit of a collocated model per data set) each in its own thread, with
    their evaluations of :class:`models.trajectory.TrajectoryNumerics` merged (see :class:`Broker`): the same
    computations as running them one after the other, with one set of mapped CasADi calls and
    batched solves per step for all of them.  Returns each task's result, or the exception it raised."""
    broker = Broker(len(tasks))
    results = [None] * len(tasks)

    def run(i):
        _LOCAL.broker = broker
        # One thread runs at a time: a task holds the broker's (re-entrant) lock from start to end and
        # gives it up only while it waits in Broker.call for the merged evaluation.  CasADi is not
        # thread-safe (building a Function or an Ipopt solver, or calling one, from two threads at
        # once crashed the process: exit 139/134 in validate on a collocated model), and the merge
        # needs no concurrency, only a pending call of every running task.
        with broker.turn:
            try:
                results[i] = tasks[i]()
            except Exception as exc:             # noqa: BLE001 - handed back to the caller as the task's result
                results[i] = exc
            finally:
                _LOCAL.broker = None
                broker.finished()

    threads = [threading.Thread(target=run, args=(i,), daemon=True) for i in range(len(tasks))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return results
