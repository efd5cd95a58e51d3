"""The parametric bootstrap with the batch engine against one identify call per refit (issue 15).

For each problem the estimate of one data set is bootstrapped twice in this process, serially,
with the same seed: ``bootstrap_replicates(..., batch=True)`` (the replicates of a chunk refitted
together by :func:`identification.batch.fit_batch`) and ``batch=False`` (one
:func:`identification.identify` per replicate).  The two runs alternate (``--repeats`` times,
medians reported), so both see the same load on a shared machine.  Reported per problem: CPU
and wall time per replicate of each path, the CPU ratio, the largest relative difference of the
refits between the paths, the fallbacks of the batch engine and the failed refits.

Problems: the press model M1 (the paper's 29 loads, n_M = 2, sensors D_y and F_x, the paper's
sigma, known), Michaelis-Menten (8 points, n_M = 2, sigma known) and Rooney-Biegler (6 points,
sigma estimated).

Run ``python -m bench.bench_bootstrap_batch --n 200 --repeats 3`` (``--jit`` compiles the
CasADi functions to C for both paths).
"""
from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import casadi as ca  # noqa: E402
import numpy as np  # noqa: E402

from bench.bench_detect import P0, SIGMA_PAPER_MM, WEIGHTS_110, _machine  # noqa: E402
from identification import Measurements, identify  # noqa: E402
from identification.bootstrap import bootstrap_replicates  # noqa: E402
from identification.montecarlo import ModelCampaign  # noqa: E402
from models import Model  # noqa: E402
from models.press import Q_PAPER, press_model  # noqa: E402
from models.state import set_jit  # noqa: E402


def problems() -> list:
    """(label, model, data, estimate) of every problem."""
    out = []
    press = press_model()
    gen = ModelCampaign(press, press.p_nominal, np.array(Q_PAPER)[:, None], SIGMA_PAPER_MM, 2)
    d = gen(np.random.default_rng(3))
    out.append(("press M1 (29 loads, n_M = 2, 2 sensors)", press, d, identify(press, d, P0, weights=WEIGHTS_110)))
    mm = Model.explicit(params=["Vm", "K"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] * q[0] / (p[1] + q[0]),
                        name="Michaelis-Menten")
    x = np.linspace(0.5, 8.0, 8)
    z = (x / (5.0 + x))[None, :, None] + 0.01 * np.random.default_rng(4).standard_normal((2, 8, 1))
    d = Measurements(x, z, [0.01])
    out.append(("Michaelis-Menten (8 points, n_M = 2)", mm, d, identify(mm, d, [1.0, 5.0])))
    rb = Model.explicit(params=["b1", "b2"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])),
                        name="Rooney-Biegler")
    d = Measurements(np.array([1.0, 2, 3, 5, 7, 10]), np.array([8.3, 10.3, 19.0, 16.0, 15.6, 19.8])[None, :, None], None)
    out.append(("Rooney-Biegler (6 points, sigma estimated)", rb, d, identify(rb, d, [15.0, 0.5])))
    return out


def _timed(f):
    c, t = time.process_time(), time.perf_counter()
    out = f()
    return out, time.perf_counter() - t, time.process_time() - c


def main(argv=None):
    ap = argparse.ArgumentParser(prog="bench bootstrap_batch")
    ap.add_argument("--n", type=int, default=200, help="bootstrap replicates")
    ap.add_argument("--repeats", type=int, default=3, help="alternating runs of each path (medians)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--jit", action="store_true", help="compile the CasADi functions to C (both paths)")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    print(f"machine: {_machine()}; {time.strftime('%Y-%m-%d %H:%M:%S %Z')}; n = {args.n} replicates, "
          f"{args.repeats} alternating repeats (medians), serial, JIT {'on' if args.jit else 'off'}", flush=True)
    set_jit(bool(args.jit))
    print("\n| problem | identify CPU / replicate | batch CPU / replicate | CPU ratio | identify wall / replicate "
          "| batch wall / replicate | max rel. diff of the refits | batch fallbacks | failed refits |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label, model, data, est in problems():
        bootstrap_replicates(model, data, est, n=4, seed=0)                  # build (and compile) once
        bootstrap_replicates(model, data, est, n=2, seed=0, batch=False)
        times = {True: [], False: []}
        got = {}
        for _ in range(args.repeats):
            for batch in (False, True):
                got[batch], w, c = _timed(lambda: bootstrap_replicates(model, data, est, n=args.n, seed=args.seed,
                                                                       batch=batch))
                times[batch].append((w, c))
        (wi, ci), (wb, cb) = (np.median(np.array(times[b]), axis=0) for b in (False, True))
        Pf, Pb = got[False].P, got[True].P
        ok = np.all(np.isfinite(Pf), axis=1) & np.all(np.isfinite(Pb), axis=1)
        diff = float(np.max(np.abs(Pb[ok] - Pf[ok]) / np.abs(Pf[ok]))) if ok.any() else float("nan")
        n = args.n
        print(f"| {label} | {ci / n * 1e3:.2f} ms | {cb / n * 1e3:.2f} ms | {ci / cb:.1f} | {wi / n * 1e3:.2f} ms "
              f"| {wb / n * 1e3:.2f} ms | {diff:.1e} | {len(got[True].fallbacks)} | "
              f"{len(got[True].errors)} (identify path: {len(got[False].errors)}) |", flush=True)


if __name__ == "__main__":
    main()
