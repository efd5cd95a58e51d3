"""The replication engine: a task's seeded replications, cut into chunks and run by :func:`cluster.execute`.

Monte Carlo (:mod:`identification.studies.montecarlo`), the parametric bootstrap
(:mod:`identification.inference.bootstrap`) and bootstrap detection
(:mod:`identification.studies.detect_bootstrap`) are :class:`ReplicationTask` objects: a picklable,
frozen description of one replication whose :meth:`ReplicationTask.run_chunk` turns a chunk
``[(index, numpy.random.SeedSequence), ...]`` into one named record per replication (a frozen
dataclass with an ``index`` field).  :func:`replicate` runs every chunk serially, on local
processes or on a Dask scheduler (:func:`identification.cluster.execute`) and returns the records
ordered by index.

The JIT setting travels with the task: :func:`run_chunk` runs each chunk inside
:func:`models.state.jit_scope` (``task.jit``), a context-local setting in whatever process or thread
runs it; the process-wide :func:`models.state.set_jit` is never touched.
Replication r draws from ``SeedSequence(seed).spawn(n)[r]`` whatever the chunks, the workers or
the backend.

This module imports no floor of :mod:`identification` (it is below fit, inference and studies).
"""
from __future__ import annotations

import os
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Callable

from models.state import jit_scope
from identification import cluster

__all__ = ["ReplicationTask", "Replications", "replicate", "run_chunk"]


class ReplicationTask(ABC):
    """One replication, described once and sent once to every worker (subclassed by frozen dataclasses).

    Attributes
    ----------
    jit : bool
        Evaluate small models' CasADi functions as compiled C while the chunks run
        (:func:`models.state.jit_scope`; the same numbers either way).
    """

    jit: bool

    @abstractmethod
    def run_chunk(self, chunk: list) -> list:
        """The replications ``[(index, SeedSequence), ...]`` -> one record per replication (with ``index``)."""


class _Installed:
    """The task of this spawned worker process (set once by the pool initializer :func:`install`)."""

    task: ReplicationTask | None = None


def install(task: ReplicationTask) -> None:
    """Pool initializer of a spawned worker: keep ``task`` for :func:`run_chunk` (one BLAS thread per process)."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    _Installed.task = task


def run_chunk(task: ReplicationTask | None, chunk: list) -> list:
    """``task.run_chunk(chunk)`` with the task's JIT setting (task None: the one installed in this process)."""
    t = _Installed.task if task is None else task
    if t is None:
        raise RuntimeError("run_chunk: no task given and none installed in this process")
    with jit_scope(t.jit):
        return t.run_chunk(chunk)


@dataclass(frozen=True, eq=False)
class Replications:
    """The records of every replication, ordered by index, and where they ran.

    Attributes
    ----------
    records : tuple     one record per replication (``records[r].index == r``)
    backend : identification.cluster.Backend
    """

    records: tuple
    backend: cluster.Backend


def replicate(task: ReplicationTask, n: int, make_chunks: Callable, *, workers: int | None = 1, scheduler=None,
              bar=None) -> Replications:
    """Run the ``n`` replications of ``task`` (see the module docstring).

    Parameters
    ----------
    task : ReplicationTask
    n : int                  replications
    make_chunks : callable (n_workers) -> list of chunks [[(index, SeedSequence), ...], ...]
        covering the indices 0..n-1 (e.g. :func:`identification.cluster.seed_chunks`)
    workers : int or None    local processes (1: serial in this process; None: all cores)
    scheduler : None, a Dask scheduler address or a distributed.Client (then ``workers`` is ignored)
    bar : tqdm-like, optional    advanced by the replications of every finished chunk

    Raises
    ------
    identification.cluster.SchedulerError
        Dask is not installed or the scheduler cannot be reached.
    RuntimeError
        A chunk returned a record of another index than its replications (a task's error).
    """
    records = [None] * int(n)

    def collect(chunk_records: list) -> None:
        for rec in chunk_records:
            records[rec.index] = rec
        if bar is not None:
            bar.update(len(chunk_records))

    backend = cluster.execute(run_chunk, task, make_chunks, collect, workers, scheduler, install)
    missing = [r for r, rec in enumerate(records) if rec is None]
    if missing:
        raise RuntimeError(f"replicate: no record for replication(s) {missing[:5]} (the task's run_chunk "
                           "must return one record per replication of its chunk)")
    return Replications(tuple(records), backend)
