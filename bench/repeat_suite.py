"""Run the test suite many times and say which runs failed and why (issue 27: a suite that passes every time).

    python bench/repeat_suite.py --runs 5                     # five runs of `make test` in this checkout
    python bench/repeat_suite.py --runs 10 --fresh            # each in a fresh clone of HEAD: make setup, make test
    python bench/repeat_suite.py --runs 10 --fresh --beside   # in pairs: each run with a second suite beside it
    python bench/repeat_suite.py --runs 4 --random-order      # pytest-randomly, a new seed per run
    python bench/repeat_suite.py --runs 2 --slow-clock 8      # clocks 8x fast: time-limit dependence shows at once

`make test-repeat N=20` is the first form.  A fresh clone is what CI runs (`.ci/run`: `make setup`, then
`make test`) on a clean checkout of the last commit: uncommitted changes are not in it.  Each run prints one
line (run, seconds of `make test`, passed/failed counts, the failed tests); every run's output is kept
(`--log DIR`, else a temporary folder it names); the exit code is 1 when any run failed.  `--random-order`
installs pytest-randomly into a fresh clone's environment (it is not a test dependency: `make test` keeps the
file order; in this checkout install it yourself).
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SUMMARY = re.compile(r"^=*\s*(?P<body>(\d+ (passed|failed|errors?|skipped|deselected|xfailed|xpassed|warnings?)"
                     r"(, )?)+) in [\d.]+s")


@dataclass(frozen=True)
class Run:
    """One run of the suite: its number, the seconds of `make test`, the exit code and what pytest said."""

    index: int
    seconds: float
    returncode: int
    counts: dict = field(default_factory=dict)
    failed: tuple = ()
    beside: bool = False

    @property
    def ok(self) -> bool:
        return self.returncode == 0 and not self.failed

    def line(self) -> str:
        counts = ", ".join(f"{v} {k}" for k, v in self.counts.items()) or "no pytest summary"
        extra = "" if self.ok else "  FAILED: " + (", ".join(self.failed) or f"exit code {self.returncode}")
        return f"run {self.index:2d}{' (beside)' if self.beside else ''}: {self.seconds:6.0f} s  {counts}{extra}"


def parse(output: str) -> tuple:
    """(counts, failed test ids) from pytest's output (its -ra short summary and closing line)."""
    counts, failed = {}, []
    for ln in output.splitlines():
        m = SUMMARY.match(ln.strip())
        if m:
            for part in m.group("body").split(", "):
                n, word = part.split(" ", 1)
                counts[word] = int(n)
        if ln.startswith(("FAILED ", "ERROR ")):
            failed.append(ln.split(" ", 2)[1])
    return counts, tuple(failed)


def _prepare(fresh: bool, random_order: bool, work: Path, k: int) -> Path:
    """The checkout to test: this one, or a fresh clone of HEAD with its own `make setup`."""
    if not fresh:
        return ROOT
    tree = work / f"clone{k}"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(tree)], check=True)
    subprocess.run(["make", "setup"], cwd=tree, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT)
    if random_order:
        subprocess.run([str(tree / ".venv/bin/python"), "-m", "pip", "install", "-q", "pytest-randomly"], check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT)
    return tree


def _start(tree: Path, k: int, args, log: Path):
    """Start `make test` in ``tree``; pytest options go through PYTEST_ADDOPTS."""
    opts = []
    if args.random_order:
        opts += ["-p", "randomly", "-p", "no:cacheprovider", f"--randomly-seed={args.seed + k}"]
    env = dict(os.environ, PYTEST_ADDOPTS=" ".join(opts))
    if args.slow_clock:
        env["MUDOE_TEST_SLOW_CLOCK"] = str(args.slow_clock)
    fh = open(log, "w")
    return subprocess.Popen(["make", "test"], cwd=tree, env=env, stdout=fh, stderr=subprocess.STDOUT), fh


def _wait_all(procs: list, t0: float) -> list:
    """The seconds from ``t0`` at which each process ended (polled, so each run gets its own time)."""
    ended = [None] * len(procs)
    while None in ended:
        for i, p in enumerate(procs):
            if ended[i] is None and p.poll() is not None:
                ended[i] = time.monotonic() - t0
        time.sleep(0.5)
    return ended


def _finish(proc, fh, seconds: float, k: int, log: Path, beside: bool) -> Run:
    fh.close()
    counts, failed = parse(log.read_text(errors="replace"))
    return Run(index=k, seconds=seconds, returncode=proc.returncode, counts=counts, failed=failed, beside=beside)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1, help="how many runs (with --beside: in pairs)")
    ap.add_argument("--fresh", action="store_true", help="each run in a fresh clone of HEAD, as CI")
    ap.add_argument("--beside", action="store_true", help="run two suites at once (two fresh clones)")
    ap.add_argument("--random-order", action="store_true", help="pytest-randomly with seed --seed + run")
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--slow-clock", type=float, default=None, help="MUDOE_TEST_SLOW_CLOCK for the runs")
    ap.add_argument("--log", type=Path, default=None, help="keep each run's output in this folder")
    args = ap.parse_args(argv)
    if args.runs < 1:
        ap.error("--runs: expected a positive integer")
    if args.beside and not args.fresh:
        ap.error("--beside needs --fresh (two suites in one checkout share its files)")
    work = Path(tempfile.mkdtemp(prefix="mudoe-repeat-"))
    logs = args.log or work / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    runs, width = [], 2 if args.beside else 1
    try:
        for first in range(1, args.runs + 1, width):
            ks = list(range(first, min(first + width, args.runs + 1)))
            trees = [_prepare(args.fresh, args.random_order, work, k) for k in ks]
            t0 = time.monotonic()
            started = [(_start(t, k, args, logs / f"run{k:02d}.log"), k) for t, k in zip(trees, ks)]
            ended = _wait_all([proc for (proc, _), _ in started], t0)
            for ((proc, fh), k), seconds in zip(started, ended):
                run = _finish(proc, fh, seconds, k, logs / f"run{k:02d}.log", beside=len(ks) > 1)
                runs.append(run)
                print(run.line(), flush=True)
            for t in trees:
                if t != ROOT:
                    shutil.rmtree(t, ignore_errors=True)
    finally:
        for t in work.glob("clone*"):
            shutil.rmtree(t, ignore_errors=True)
    print(f"every run's output: {logs}")
    bad = [r for r in runs if not r.ok]
    secs = sorted(r.seconds for r in runs)
    print(f"{len(runs) - len(bad)} of {len(runs)} runs passed; make test took {secs[0]:.0f}-{secs[-1]:.0f} s "
          f"(median {secs[len(secs) // 2]:.0f} s)")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
