"""Ctrl-C and SIGTERM at any moment: exit 130 / 143, no process left, nothing half-written (how fast: bench).

Issue 20 item 8: Ctrl-C (``kill -INT``) while the model compiled was lost 8 of 8 times (CasADi runs
the compiler through ``system()``, which ignores SIGINT meanwhile); a terminal's Ctrl-C (the
whole process group) gave exit 1 ``BrokenProcessPool``; SIGTERM left the worker and the
resource tracker running.  Each test runs the CLI as a process, sends the signal at a moment
it can see (a compiler process running, the worker process fitting, report files being
written), and checks the exit code, the time to exit, that every process the CLI started is
gone and that ``--out`` holds no file.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import psutil
import pytest

from mudoe.outdir import MARKER

REPO = Path(__file__).resolve().parents[2]
ENV = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=str(REPO))
#: How long to wait for the exit after the signal before calling the run hung.  Not a requirement: the speed
#: goal (exit within a second) is measured by ``python -m bench signals`` (bench/RESULTS.md).  A lost signal is
#: told from an acted-on one by the exit code and the last line ("mudoe: interrupted" / "terminated"), which a
#: run that goes on to its end never gives; this bound only stops a hung run (issue 27: no test decides on
#: the wall clock).
HANG_S = 600.0
#: how long the processes left may take to notice that their parent is gone, after the exit (s): polled, so a
#: passing run does not wait for it; generous, since a loaded machine may not schedule them for seconds
TRACKER_S = 120.0
COMPILERS = {"gcc", "cc", "cc1", "as", "collect2", "ld"}


class _Run:
    """The CLI as a process: its stderr lines (read by a thread) and every descendant seen."""

    def __init__(self, args, env, group: bool = False):
        self.p = subprocess.Popen([sys.executable, "-m", "mudoe", *args], cwd=REPO, env=env, stdout=subprocess.DEVNULL,
                                  stderr=subprocess.PIPE, text=True, start_new_session=group)
        self.proc = psutil.Process(self.p.pid)
        self.lines, self.seen = [], {}
        self.reader = threading.Thread(target=lambda: self.lines.extend(self.p.stderr), daemon=True)
        self.reader.start()

    def children(self) -> list:
        try:
            kids = self.proc.children(recursive=True)
        except psutil.Error:
            return []
        for k in kids:
            self.seen.setdefault(k.pid, k)
        return kids

    def wait_for(self, ready, timeout: float = 180.0) -> None:
        """Poll until ``ready(children)`` is true (the CLI still running)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            assert self.p.poll() is None, "".join(self.lines)
            if ready(self.children()):
                self.children()
                return
            time.sleep(0.01)
        self.p.kill()
        pytest.fail("the moment to signal never came: " + "".join(self.lines)[-2000:])

    def signal(self, signum, group: bool = False) -> None:
        """Send ``signum`` (to the process group: a terminal's Ctrl-C) and wait for the exit."""
        if group:
            os.killpg(self.p.pid, signum)
        else:
            self.p.send_signal(signum)
        try:
            self.p.wait(timeout=HANG_S)
        except subprocess.TimeoutExpired:
            self.p.kill()
            raise

    def left_over(self) -> list:
        """The descendants seen that still run (zombies count as gone) TRACKER_S seconds after the exit."""
        end = time.monotonic() + TRACKER_S
        while True:
            alive = [k for k in self.seen.values() if _running(k)]
            if not alive or time.monotonic() > end:
                return alive
            time.sleep(0.05)


def _running(proc) -> bool:
    try:
        return proc.is_running() and proc.status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False


def _is_compiler(proc) -> bool:
    try:
        return proc.name() in COMPILERS
    except psutil.Error:
        return False


def _is_worker(proc) -> bool:
    try:
        return "multiprocessing.spawn" in " ".join(proc.cmdline())
    except psutil.Error:
        return False


def _check(run: _Run, code: int, word: str, out: Path) -> None:
    run.reader.join(timeout=HANG_S)              # its last lines: the pipe closes with the last process
    err = "".join(run.lines)
    assert run.p.returncode == code, err[-2000:]
    assert "Traceback" not in err and f"mudoe: {word}" in err.splitlines()[-1], err[-2000:]
    assert run.left_over() == [], f"processes left: {run.left_over()}"
    # no output: at most the folder's ownership marker (complete, written before any work)
    assert not out.exists() or sorted(p.name for p in out.iterdir() if p.name != MARKER) == [], sorted(out.iterdir())


@pytest.mark.parametrize("group", [False, True], ids=["kill -INT", "terminal Ctrl-C"])
def test_ctrl_c_while_the_model_compiles(tmp_path, group):
    """An empty JIT cache: the press model's functions are compiled (gcc) at the start of the Monte Carlo run."""
    env = dict(ENV, MUDOE_JIT_CACHE=str(tmp_path / "jit"))
    out = tmp_path / "out"
    run = _Run(["validate", "configs/press.toml", "--runs", "40", "--workers", "2", "--out", str(out)], env, group)
    run.wait_for(lambda kids: any(_is_compiler(k) for k in kids))
    run.signal(signal.SIGINT, group)
    _check(run, 130, "interrupted", out)


def test_sigterm_while_the_workers_fit(tmp_path):
    out = tmp_path / "out"
    run = _Run(["validate", "configs/cstr.toml", "--runs", "2000", "--workers", "2", "--out", str(out)], ENV)
    # the spawned worker process runs, and some replications are done
    run.wait_for(lambda kids: any(_is_worker(k) for k in kids) and any("rep/s" in ln and " 0/" not in ln
                                                                         for ln in run.lines))
    run.signal(signal.SIGTERM)
    _check(run, 143, "terminated", out)


def test_ctrl_c_while_the_report_is_written(tmp_path):
    out = tmp_path / "out"
    run = _Run(["report", "configs/cstr.toml", "--out", str(out)], ENV)
    # the report's pages are being written into its temporary folder inside --out
    run.wait_for(lambda kids: out.is_dir() and any(any(d.iterdir()) for d in out.glob(".report-*")))
    run.signal(signal.SIGINT)
    _check(run, 130, "interrupted", out)


def test_workers_end_when_the_cli_is_killed(tmp_path):
    """SIGKILL cannot be handled: the spawned worker notices its parent is gone and ends (no orphan fitting on)."""
    out = tmp_path / "out"
    run = _Run(["validate", "configs/cstr.toml", "--runs", "2000", "--workers", "2", "--out", str(out)], ENV)
    run.wait_for(lambda kids: any(_is_worker(k) for k in kids) and any("rep/s" in ln and " 0/" not in ln
                                                                         for ln in run.lines))
    run.signal(signal.SIGKILL)
    assert run.p.returncode == -signal.SIGKILL
    assert run.left_over() == [], f"processes left: {run.left_over()}"
