"""CPU per replication of the batch engine on the press four-scenario test, measured in one process.

The timing study of :mod:`bench.bench_detect` (``--study timing``) pays the per-worker start-up
(spawn, JIT compile) inside its wall time; this benchmark isolates the compute per replication:
the task of ``bench_detect --study timing`` is installed in this process, a warm-up chunk runs
(compilation, caches), then ``--n-rep`` replications run in chunks of ``--chunk`` (50, the chunk
size of a 1000-replication run on 2 workers) and the CPU time (user + system, ``resource.getrusage``)
per replication is printed.  ``--profile FILE`` writes a cProfile of the measured part.

Run ``python -m bench.bench_batchcpu --n-rep 300``.
"""
from __future__ import annotations

import argparse
import os
import resource
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from bench.bench_detect import P0, PAPER_SPLITS, SIGMA_PAPER_MM, WEIGHTS_110, _machine  # noqa: E402
from identification.studies import montecarlo as mc  # noqa: E402
from identification.studies.detect import DetectSettings  # noqa: E402
from models.press import Q_PAPER, press_model  # noqa: E402
from identification.replicate import run_chunk  # noqa: E402


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def make_task(jit: bool = True) -> "mc.SizeStudyTask":
    """The task of bench_detect's size/timing study (M1 on its own campaigns, the paper's splits)."""
    model = press_model()
    gen = mc.ModelCampaign(model, model.p_nominal, np.array(Q_PAPER)[:, None], SIGMA_PAPER_MM, 2)
    return mc.SizeStudyTask(names=("M1",), models=(model,), p0s=(np.asarray(P0, float),),
                    weights=(WEIGHTS_110,), splits=tuple(PAPER_SPLITS), generator=gen, truth=(gen.p_true,),
                    detect=DetectSettings(tol=0.05, normality="override"), coverage_alpha=0.05, fits=mc.BATCHED,
                    jit=jit)


def run(n_rep: int, chunk: int, seed: int, profile: str | None = None, jit: bool = True):
    """(CPU seconds per replication, the per-replication records) of ``n_rep`` replications after a warm-up
    (the chunks run by :func:`identification.replicate.run_chunk`, the task's JIT setting around each)."""
    task = make_task(jit)
    children = np.random.SeedSequence(seed).spawn(n_rep + chunk)
    items = list(enumerate(children))
    run_chunk(task, items[n_rep:])                              # warm-up (other seeds)
    chunks = [items[i:i + chunk] for i in range(0, n_rep, chunk)]
    prof = None
    if profile:
        import cProfile
        prof = cProfile.Profile()
        prof.enable()
    c0, t0 = _cpu(), time.perf_counter()
    out = [r for ch in chunks for r in run_chunk(task, ch)]
    cpu, wall = _cpu() - c0, time.perf_counter() - t0
    if prof is not None:
        prof.disable()
        prof.dump_stats(profile)
    return cpu / n_rep, wall / n_rep, out


def main(argv=None):
    ap = argparse.ArgumentParser(prog="bench batchcpu")
    ap.add_argument("--n-rep", type=int, default=300)
    ap.add_argument("--chunk", type=int, default=50)
    ap.add_argument("--seed", type=int, default=20261121)
    ap.add_argument("--profile", default=None)
    ap.add_argument("--save", default=None, help="write alpha_lr/alpha_two_sample/alpha_paper to this .npz")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    print(f"machine: {_machine()}; {time.strftime('%Y-%m-%d %H:%M:%S %Z')}", flush=True)
    cpu, wall, out = run(args.n_rep, args.chunk, args.seed, args.profile)
    print(f"| replications | chunk | CPU per replication | wall per replication |\n|---|---|---|---|\n"
          f"| {args.n_rep} | {args.chunk} | {cpu * 1e3:.1f} ms | {wall * 1e3:.1f} ms |")
    if args.save:
        np.savez(args.save, errors=np.array([repr((f.model, f.split, f.stage, f.message)) for r in out
                                             for f in r.failures], dtype=str),
                 **{f: np.stack([getattr(r, f) for r in out]) for f in ("alpha_lr", "alpha_two_sample", "alpha_paper",
                                                                        "covered", "shapiro")})


if __name__ == "__main__":
    main()
