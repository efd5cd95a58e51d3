"""cluster.run_local: this process and N-1 spawned ones share the chunks; errors are not lost."""
import os
import time

import pytest

from identification import cluster

_INSTALLED = {}


def _install(task):
    _INSTALLED["task"] = task


def _square(task, chunk):
    t = _INSTALLED["task"] if task is None else task
    if isinstance(t, dict):                         # wait here until the spawned process has run a chunk
        if task is None:
            open(t["flag"], "w").close()
        else:
            end = time.monotonic() + 600            # a hang guard: a loaded machine may start it slowly
            while not os.path.exists(t["flag"]) and time.monotonic() < end:
                time.sleep(0.02)
    if t == "fail" and chunk == [3]:
        raise ArithmeticError("chunk 3 failed")
    return [(i, i * i, os.getpid()) for i in chunk]


def test_every_chunk_once_some_in_this_process_some_spawned():
    got = []
    cluster.run_local(_square, "ok", [[i] for i in range(12)], got.extend, 2, _install)
    assert sorted(i for i, _, _ in got) == list(range(12))
    assert all(v == i * i for i, v, _ in got)
    pids = {pid for _, _, pid in got}
    assert os.getpid() in pids                     # this process worked (it starts at once)
    assert len(pids) in (1, 2)                     # and the spawned one joined unless the parent finished first


def test_a_ready_spawned_process_takes_chunks(tmp_path):
    """This process waits for the spawned one (no race with its start-up, issue 27)."""
    got = []
    cluster.run_local(_square, {"flag": str(tmp_path / "spawned_ran")}, [[i] for i in range(12)], got.extend, 2,
                      _install)
    assert sorted(i for i, _, _ in got) == list(range(12))
    assert len({pid for _, _, pid in got}) == 2


def test_an_error_in_a_chunk_is_raised_here():
    with pytest.raises(ArithmeticError, match="chunk 3 failed"):
        cluster.run_local(_square, "fail", [[i] for i in range(8)], lambda r: None, 2, _install)


def test_run_local_needs_two_processes():
    with pytest.raises(ValueError, match="n_workers"):
        cluster.run_local(_square, "ok", [[0]], lambda r: None, 1, _install)
