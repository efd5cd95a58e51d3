"""Time per replication of the press timing study vs the number of replications and the backend (issue 15).

The study is ``bench.bench_detect``'s size study: the press model M1, the paper's 29 loads, 2 series,
sensors D_y and F_x, the paper's four scenarios (11 fits per replication).  For every backend and
every ``--sizes`` n it runs n replications from one seed and records

* wall time (s) and wall time per replication (ms);
* CPU time (s) of everything that worked: this process (serial), the spawned pool processes
  (local processes, ``RUSAGE_CHILDREN`` after the pool is shut down) or the Dask workers
  (``resource.getrusage`` read on every worker before and after, by ``client.run``);
* whether the numbers (alpha_min of the three statistics, coverage) equal the serial run's
  of the same n (same seed: they must).

Backends: ``serial`` (this process), ``processes2`` (2 spawned local processes, a new pool per run:
its start-up and the per-process model compilation are inside the time), ``daskN`` (a
``distributed.LocalCluster`` of N worker processes with one thread each, started once per N; its
start-up time and a warm-up run of 2 N replications are reported apart and not in the table).

Run ``python -m bench.bench_workers`` (sizes 10 100 1000, every backend; ``--sizes 10 100 1000 10000``
for the long version) and read the markdown table.
"""
from __future__ import annotations

import argparse
import os
import platform
import resource
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from bench.bench_detect import run_size  # noqa: E402

BACKENDS = ("serial", "processes2", "dask1", "dask2", "dask4")


def _cpu(who: int) -> float:
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


def _worker_cpu() -> float:
    """CPU seconds of this (worker) process; run on every Dask worker by ``client.run``."""
    return _cpu(resource.RUSAGE_SELF)


def _machine() -> str:
    load = os.getloadavg()
    return (f"{platform.processor() or platform.machine()}, nproc {os.cpu_count()}, load average "
            f"{load[0]:.1f}/{load[1]:.1f}/{load[2]:.1f}, python {platform.python_version()}")


def _same(a, b) -> str:
    if b is None:
        return "n/a"
    return "yes" if all(np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True)
                        for f in ("alpha_lr", "alpha_two_sample", "alpha_paper", "covered")) else "NO"


def _timed(n: int, seed: int, workers=None, client=None) -> tuple:
    """(result, wall s, CPU s) of one size study."""
    if client is not None:
        c0 = sum(client.run(_worker_cpu).values())
    else:
        c0 = _cpu(resource.RUSAGE_SELF) + _cpu(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    res = run_size(n, workers, seed, client, progress=False)
    wall = time.perf_counter() - t0
    if client is not None:
        cpu = sum(client.run(_worker_cpu).values()) - c0
    else:
        cpu = _cpu(resource.RUSAGE_SELF) + _cpu(resource.RUSAGE_CHILDREN) - c0
    return res, wall, cpu


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10, 100, 1000])
    ap.add_argument("--backends", nargs="+", choices=BACKENDS, default=list(BACKENDS))
    ap.add_argument("--seed", type=int, default=20261121)
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    print(f"machine: {_machine()}; {time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}", flush=True)
    rows, serial, setup = [], {}, []
    for backend in args.backends:
        if backend.startswith("dask"):
            import distributed
            n_w = int(backend[4:])
            t0 = time.perf_counter()
            with distributed.LocalCluster(n_workers=n_w, threads_per_worker=1, processes=True,
                                          dashboard_address=None) as cl, \
                    distributed.Client(cl, set_as_default=False) as client:
                start = time.perf_counter() - t0
                _, warm, _ = _timed(2 * n_w, args.seed + 1, client=client)
                setup.append(f"{backend}: cluster start {start:.1f} s, warm-up ({2 * n_w} replications, model "
                             f"compiled in every worker) {warm:.1f} s")
                print(setup[-1], flush=True)
                for n in args.sizes:
                    res, wall, cpu = _timed(n, args.seed, client=client)
                    rows.append((backend, n, wall, cpu, _same(res, serial.get(n))))
                    print(rows[-1], flush=True)
        else:
            workers = 1 if backend == "serial" else 2
            for n in args.sizes:
                res, wall, cpu = _timed(n, args.seed, workers=workers)
                if backend == "serial":
                    serial[n] = res
                rows.append((backend, n, wall, cpu, _same(res, serial.get(n)) if backend != "serial" else "-"))
                print(rows[-1], flush=True)
    print()
    print("| backend | replications | wall (s) | wall per replication (ms) | CPU (s) | CPU per replication (ms) "
          "| same numbers as serial |")
    print("|---|---|---|---|---|---|---|")
    for backend, n, wall, cpu, same in rows:
        print(f"| {backend} | {n} | {wall:.1f} | {1e3 * wall / n:.0f} | {cpu:.1f} | {1e3 * cpu / n:.0f} | {same} |")
    print()
    print("Not in the table: " + "; ".join(setup) if setup else "")


if __name__ == "__main__":
    main()
