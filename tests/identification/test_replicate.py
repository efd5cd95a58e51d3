"""The replication engine (identification.replicate): records by index whatever the backend, the JIT setting
travelling with the task, a lost record named; the strategies of the studies chosen once."""
from __future__ import annotations

import functools
import os
from dataclasses import dataclass

import numpy as np
import pytest

from identification import cluster
from identification.replicate import ReplicationTask, replicate, run_chunk
from models.state import JIT, jit_enabled, jit_scope, set_jit


@dataclass(frozen=True)
class _Draw:
    index: int
    value: float
    jit_seen: bool
    pid: int


@dataclass(frozen=True, eq=False)
class _DrawTask(ReplicationTask):
    """Replication r: one standard normal draw of its seed, with the JIT setting the chunk ran under."""

    jit: bool
    drop: int = -1

    def run_chunk(self, chunk: list) -> list:
        return [_Draw(i, float(np.random.default_rng(s).standard_normal()), jit_enabled(), os.getpid())
                for i, s in chunk if i != self.drop]


def _chunks(n: int, size: int, n_workers: int) -> list:
    return cluster.seed_chunks(n, 42, n_workers, chunk_size=size)


def test_records_by_index_whatever_the_chunks():
    """(Local processes and Dask: test_montecarlo, test_bootstrap, test_detect_bootstrap, tests/mudoe/test_dask.)"""
    a = replicate(_DrawTask(jit=False), 10, functools.partial(_chunks, 10, 3))
    b = replicate(_DrawTask(jit=False), 10, functools.partial(_chunks, 10, 1))
    assert [r.index for r in a.records] == list(range(10)) == [r.index for r in b.records]
    assert [r.value for r in a.records] == [r.value for r in b.records]
    assert [r.value for r in a.records] == [float(np.random.default_rng(s).standard_normal())
                                            for s in np.random.SeedSequence(42).spawn(10)]
    assert a.backend == cluster.Backend("serial", 1) and str(a.backend) == "serial"
    assert str(cluster.Backend("local", 2)) == "2 local processes"


@pytest.mark.parametrize("outside", [False, True])
def test_the_jit_setting_travels_with_the_task_and_is_restored(outside):
    prev = set_jit(outside)
    try:
        got = replicate(_DrawTask(jit=not outside), 4, functools.partial(_chunks, 4, 2))
        assert all(r.jit_seen is (not outside) for r in got.records)
        assert JIT.enabled is outside and jit_enabled() is outside      # the process setting never touched
        assert run_chunk(_DrawTask(jit=not outside), _chunks(2, 2, 1)[0])[0].jit_seen is (not outside)
        assert JIT.enabled is outside and jit_enabled() is outside
    finally:
        set_jit(prev)


def test_jit_scope_is_local_to_its_thread_and_undone_by_an_exception():
    """Chunks of tasks with different JIT settings in two threads (a threaded Dask worker) each see their own."""
    import threading
    prev = set_jit(False)
    try:
        barrier = threading.Barrier(2, timeout=30)
        seen = {}

        def chunk(setting):
            with jit_scope(setting):
                barrier.wait()                    # both scopes open at once
                seen[setting] = jit_enabled()
                barrier.wait()

        threads = [threading.Thread(target=chunk, args=(v,)) for v in (True, False)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert seen == {True: True, False: False} and jit_enabled() is False
        with pytest.raises(ZeroDivisionError):
            with jit_scope(True):
                assert jit_enabled() and JIT.enabled is False
                1 / 0
        assert jit_enabled() is False
    finally:
        set_jit(prev)


def test_a_lost_record_is_named():
    with pytest.raises(RuntimeError, match=r"no record for replication\(s\) \[2\]"):
        replicate(_DrawTask(jit=False, drop=2), 4, functools.partial(_chunks, 4, 2))


def test_the_strategies_are_checked_where_they_are_chosen():
    from identification.inference.bootstrap import BATCH_REFITS, ONE_BY_ONE_REFITS
    from identification.studies.montecarlo import MonteCarloSettings
    from identification.studies.split_fits import BATCHED, ONE_BY_ONE
    assert MonteCarloSettings().fits is BATCHED and MonteCarloSettings(fits=ONE_BY_ONE).fits is ONE_BY_ONE
    with pytest.raises(TypeError, match="fits: expected BATCHED or ONE_BY_ONE"):
        MonteCarloSettings(fits=True)
    assert BATCH_REFITS.max_chunk == 100 and ONE_BY_ONE_REFITS.max_chunk == 20
