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

Backends: ``serial`` (this process), ``processes2`` (2 local processes: this one and 1 spawned, a new
pool per run: the spawned process's start-up is inside the time, :func:`identification.cluster.run_local`),
``daskN`` (a ``distributed.LocalCluster`` of N worker processes with one thread each, started once per
N; its start-up time and a warm-up run of 2 N replications are reported apart and not in the tables).
The compiled model functions come from the JIT cache (:mod:`models.jit_cache`); ``--jit-cache cold``
starts from an empty one (the first run of every backend then compiles, once per machine).

Run ``python -m bench.bench_workers`` (sizes 10 100 1000, every backend; ``--sizes 10 100 1000 10000``
for the long version, ``--backends serial processes2`` for a subset) and read the two markdown tables
(one row per run; per replication by backend and size), followed by the check against the serial
numbers.
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
    """CPU seconds of this (worker) process and its finished children (the C compiler of the JIT);
    run on every Dask worker by ``client.run``."""
    return _cpu(resource.RUSAGE_SELF) + _cpu(resource.RUSAGE_CHILDREN)


def _machine() -> str:
    load = os.getloadavg()
    return (f"{platform.processor() or platform.machine()}, nproc {os.cpu_count()}, load average "
            f"{load[0]:.1f}/{load[1]:.1f}/{load[2]:.1f}, python {platform.python_version()}")


#: largest alpha / coverage difference to the serial run counted as round-off (different chunks)
ROUND_OFF = 1e-10


def _same(a, b) -> str:
    """"yes" when every alpha and coverage equals the serial run's to the bit; else the largest difference
    and whether the NaN pattern (failed fits) and the decisions of the three statistics agree."""
    if b is None:
        return "n/a"
    fields = ("alpha_lr", "alpha_two_sample", "alpha_paper", "covered")
    if all(np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True) for f in fields):
        return "yes"
    nan_same = all(np.array_equal(np.isnan(getattr(a, f)), np.isnan(getattr(b, f))) for f in fields)
    diff = max(float(np.nanmax(np.abs(getattr(a, f) - getattr(b, f)), initial=0.0)) for f in fields)
    dec = all(np.array_equal(a.decisions(statistic=st), b.decisions(statistic=st), equal_nan=True)
              for st in ("likelihood_ratio", "two_sample", "paper"))
    if nan_same and dec and diff <= ROUND_OFF:
        # other chunks: the batched reductions sum in another order (estimates a few ulps apart)
        return f"round-off: max diff {diff:.1e}, same failed fits and decisions"
    return (f"NO: max diff {diff:.1e}, same failed fits {'yes' if nan_same else 'NO'}, "
            f"same decisions {'yes' if dec else 'NO'}")


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


LABELS = {"serial": "serial (this process)", "processes2": "2 local processes (this one + 1 spawned)",
          "dask1": "Dask LocalCluster, 1 process", "dask2": "Dask LocalCluster, 2 processes",
          "dask4": "Dask LocalCluster, 4 processes"}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10, 100, 1000],
                    help="numbers of replications (e.g. 10 100 1000 10000)")
    ap.add_argument("--backends", nargs="+", choices=BACKENDS, default=list(BACKENDS))
    ap.add_argument("--seed", type=int, default=20261121)
    ap.add_argument("--jit-cache", choices=("keep", "cold"), default="keep",
                    help="keep: the user's JIT cache (models.jit_cache; warm after a first run); cold: a new empty "
                         "cache directory for this benchmark (every backend's first run compiles once)")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    if args.jit_cache == "cold":
        import tempfile
        os.environ["MUDOE_JIT_CACHE"] = tempfile.mkdtemp(prefix="mudoe-jit-bench-")   # inherited by every worker
    print(f"machine: {_machine()}; {time.strftime('%Y-%m-%d %H:%M:%S UTC', time.gmtime())}; "
          f"JIT cache: {os.environ.get('MUDOE_JIT_CACHE', 'default (per user)')}", flush=True)
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
                _, warm, warm_cpu = _timed(2 * n_w, args.seed + 1, client=client)
                setup.append(f"{backend}: cluster start {start:.1f} s, warm-up ({2 * n_w} replications: imports, "
                             f"model, JIT load or compile in every worker) {warm:.1f} s wall, {warm_cpu:.1f} s CPU")
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
    print("\n| backend | replications | wall (s) | wall per replication (ms) | CPU (s) | CPU per replication (ms) "
          "| same numbers as serial |")
    print("|---|---|---|---|---|---|---|")
    for backend, n, wall, cpu, same in rows:
        print(f"| {LABELS[backend]} | {n} | {wall:.1f} | {1e3 * wall / n:.1f} | {cpu:.1f} | {1e3 * cpu / n:.1f} "
              f"| {same} |")
    print("\nPer replication, wall ms (CPU ms), by backend and number of replications:\n")
    print("| backend | " + " | ".join(f"{n} reps" for n in args.sizes) + " |")
    print("|---|" + "---|" * len(args.sizes))
    for backend in args.backends:
        cells = {n: f"{1e3 * w / n:.1f} ({1e3 * c / n:.1f})" for b, n, w, c, _ in rows if b == backend}
        print(f"| {LABELS[backend]} | " + " | ".join(cells.get(n, "") for n in args.sizes) + " |")
    checked = [same for b, _, _, _, same in rows if b != "serial"]
    if checked:
        verdict = ("all equal" if all(x == "yes" for x in checked) else
                   "NOT all equal (see the table)" if any(x.startswith("NO") for x in checked)
                   else f"equal to the bit or to round-off (<= {ROUND_OFF:.0e}, other chunks), same decisions"
                   if all(x == "yes" or x.startswith("round-off") for x in checked)
                   else "not checked for every size (serial not run)")
        print(f"\nSame numbers as the serial run (alpha of the three statistics, coverage): {verdict}")
    if setup:
        print("Not in the tables (once per cluster): " + "; ".join(setup))


if __name__ == "__main__":
    main()
