"""One BLAS thread in the command line's process and its workers, unless the user chose (mudoe.blas_threads)."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy  # noqa: F401 -- loaded first, as in a Python session calling mudoe.cli.main
import threadpoolctl

from mudoe.blas_threads import PINNED_VARIABLES, USER_VARIABLES, one_blas_thread, user_choice

REPO = Path(__file__).resolve().parents[2]


def _blas_threads() -> dict:
    return {p["filepath"]: p["num_threads"] for p in threadpoolctl.threadpool_info() if p["user_api"] == "blas"}


def _clear(monkeypatch):
    for name in USER_VARIABLES:
        monkeypatch.delenv(name, raising=False)


def test_user_choice_names_the_first_variable_set():
    assert user_choice({}) is None
    assert user_choice({"OPENBLAS_NUM_THREADS": " "}) is None
    assert user_choice({"OMP_NUM_THREADS": "4", "HOME": "/x"}) == "OMP_NUM_THREADS=4"
    assert user_choice({"MKL_NUM_THREADS": "2", "OPENBLAS_NUM_THREADS": "3"}) == "OPENBLAS_NUM_THREADS=3"


def test_one_thread_in_the_block_then_restored(monkeypatch):
    _clear(monkeypatch)
    monkeypatch.setenv("MKL_NUM_THREADS", "")            # empty: not a choice; restored as it was
    before = _blas_threads()
    assert before, "numpy's BLAS is loaded, threadpoolctl must see it"
    with one_blas_thread() as what:
        assert "threadpoolctl" in what
        assert all(os.environ[name] == "1" for name in PINNED_VARIABLES)
        assert set(_blas_threads().values()) == {1}
    assert _blas_threads() == before
    assert "OPENBLAS_NUM_THREADS" not in os.environ and "OMP_NUM_THREADS" not in os.environ
    assert os.environ["MKL_NUM_THREADS"] == ""


def test_the_user_choice_is_kept(monkeypatch):
    _clear(monkeypatch)
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    before = _blas_threads()
    with one_blas_thread() as what:
        assert "OMP_NUM_THREADS=3" in what
        assert "OPENBLAS_NUM_THREADS" not in os.environ and os.environ["OMP_NUM_THREADS"] == "3"
        assert _blas_threads() == before


_PROBE = """
import json, multiprocessing, os, sys
import mudoe.cli as cli

def info():
    import numpy, scipy.linalg, threadpoolctl
    return dict(threads=sorted(p["num_threads"] for p in threadpoolctl.threadpool_info() if p["user_api"] == "blas"),
                env=os.environ.get("OPENBLAS_NUM_THREADS"))

def worker(queue):
    queue.put(info())

def run(args):
    queue = multiprocessing.get_context("spawn").Queue()
    proc = multiprocessing.get_context("spawn").Process(target=worker, args=(queue,))
    proc.start()
    spawned = queue.get(timeout=120)
    proc.join()
    print(json.dumps(dict(main=info(), worker=spawned, numpy_before="numpy" in sys.modules)))
    return 0

if __name__ == "__main__":
    assert "numpy" not in sys.modules
    cli._run = run
    sys.exit(cli.main(["identify", "configs/motor.toml"]))
"""


def _probe(tmp_path, **env_vars) -> dict:
    script = tmp_path / "probe.py"
    script.write_text(_PROBE)
    env = {k: v for k, v in os.environ.items() if k not in USER_VARIABLES}
    env.update(PYTHONPATH=str(REPO), **env_vars)
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, cwd=REPO, env=env, timeout=300)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


def test_the_command_line_and_its_spawned_workers_run_one_blas_thread(tmp_path):
    got = _probe(tmp_path)
    assert got["main"]["threads"] and set(got["main"]["threads"]) == {1}
    assert got["worker"]["threads"] and set(got["worker"]["threads"]) == {1}
    assert got["main"]["env"] == got["worker"]["env"] == "1"


def test_the_command_line_keeps_a_user_setting(tmp_path):
    got = _probe(tmp_path, OPENBLAS_NUM_THREADS="2")
    assert got["main"]["env"] == got["worker"]["env"] == "2"
    # OpenBLAS caps the threads at the machine's cores: 2 on any machine with two cores or more
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    expected = min(2, cores)
    assert set(got["main"]["threads"]) == {expected} and set(got["worker"]["threads"]) == {expected}
