"""Speed of a dynamic study's commands: `mudoe detect`, `report` and `validate` on the DC motor
(configs/motor.toml) against the batch reactor (configs/reactor.toml), issue 30 item 7.

Each command runs in a fresh process (``python -m mudoe COMMAND CONFIG --out TMP --quiet``, at niceness 10) and
is timed by wall clock and by CPU (user + system of the child, ``resource.getrusage(RUSAGE_CHILDREN)``,
which counts the spawned validate workers once they have finished).  The machine may be shared: the load
average (``os.getloadavg``) is printed beside every row and the motor is compared with the reactor of the
same run as a ratio (CPU ratios are the ones to read under load).  The children inherit this process's
environment: with OPENBLAS_NUM_THREADS or OMP_NUM_THREADS set, a tree before mudoe.blas_threads runs with that
many threads too (the header line names them).  ``--trees A,B`` times the same
commands on other source trees (e.g. an export of the integration commit) interleaved with this one, so a
before/after table comes from one run::

    python -m bench.bench_study_speed                         # this tree: detect, report, validate
    python -m bench.bench_study_speed --commands detect --trees /tmp/base,.
    python -m bench.bench_study_speed --runs 20 --workers 1   # validate's replications and workers
    python -m bench.bench_study_speed --commands report --trees /tmp/base,. --repeat 2   # A B A B

Prints a markdown table (one row per tree, command and config).
"""
from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
CONFIGS = ("motor", "reactor")
COMMANDS = ("detect", "report", "validate")


def run_command(tree: Path, command: str, config: str, runs: int, workers: int, keep: Path | None = None) -> dict:
    """Wall and CPU seconds (user + system of the child process and its workers) of one command on ``tree``,
    and the one-minute load average before it; raises RuntimeError naming the command when it fails.  The
    command's output folder is ``keep/<tree>/<command>_<config>`` when ``keep`` is given (to compare the
    results of two trees), else a temporary folder."""
    with tempfile.TemporaryDirectory(prefix="bench_study_speed_") as tmp:
        out = tmp if keep is None else str(keep / tree.name / f"{command}_{config}")
        cmd = ["nice", "-n", str(max(10 - os.nice(0), 0)), sys.executable, "-m", "mudoe", command,
               str(tree / "configs" / f"{config}.toml"), "--out", out, "--quiet"]
        if command == "validate":
            cmd += ["--runs", str(runs), "--workers", str(workers)]
        env = dict(os.environ, PYTHONPATH=str(tree))
        load = os.getloadavg()[0]
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}): {proc.stderr.strip()[-500:]}")
    cpu = (r1.ru_utime + r1.ru_stime) - (r0.ru_utime + r0.ru_stime)
    return {"wall": wall, "cpu": cpu, "load": load}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="bench_study_speed", description=__doc__.splitlines()[0])
    ap.add_argument("--commands", default=",".join(COMMANDS),
                    help="comma-separated subset of detect,report,validate")
    ap.add_argument("--configs", default=",".join(CONFIGS), help="comma-separated configs of configs/ (motor,reactor)")
    ap.add_argument("--trees", default=".", help="comma-separated source trees (default this one)")
    ap.add_argument("--runs", type=int, default=20, help="validate: replications (default 20)")
    ap.add_argument("--workers", type=int, default=1, help="validate: local workers (default 1)")
    ap.add_argument("--keep", default=None, help="keep every command's output under this folder")
    ap.add_argument("--repeat", type=int, default=1,
                    help="run the trees this many times, interleaved (A B A B ...; default 1)")
    args = ap.parse_args(argv)
    commands = [c for c in args.commands.split(",") if c]
    bad = [c for c in commands if c not in COMMANDS]
    if bad:
        raise SystemExit(f"bench_study_speed: --commands: unknown {bad[0]!r}; choose from {', '.join(COMMANDS)}")
    trees = [(HERE if t == "." else Path(t).resolve()) for t in args.trees.split(",") if t]
    configs = [c for c in args.configs.split(",") if c]
    when = time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())
    threads = ", ".join(f"{v}={os.environ[v]}" for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")
                        if v in os.environ) or "no BLAS thread variable set (mudoe then uses one thread)"
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} CPUs, {when}; validate --runs {args.runs} "
          f"--workers {args.workers}; {threads}")
    print("| tree | command | config | wall s | CPU s | load | CPU / reactor's |")
    print("|---|---|---|---|---|---|---|")
    if args.repeat < 1:
        raise SystemExit(f"bench_study_speed: --repeat: need at least 1, got {args.repeat}")
    for command in commands:
        for tree in trees * args.repeat:
            keep = None if args.keep is None else Path(args.keep)
            got = {c: run_command(tree, command, c, args.runs, args.workers, keep) for c in configs}
            ref = got.get("reactor")
            for c, g in got.items():
                ratio = f"{g['cpu'] / ref['cpu']:.2f}" if ref and ref["cpu"] > 0 else "-"
                print(f"| {tree.name} | {command} | {c} | {g['wall']:.1f} | {g['cpu']:.1f} | {g['load']:.1f} | "
                      f"{ratio} |", flush=True)


if __name__ == "__main__":
    main()
