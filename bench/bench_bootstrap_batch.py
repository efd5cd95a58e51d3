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

``--profiles`` adds a second table: the constrained fits of a likelihood-ratio region
(:func:`identification.profile.lr_region`, ``grid="axes"``, the pair fixed at every grid point,
the other parameters re-optimised) computed by lr_region (one reduced Newton per point, warm
started from its neighbour) and by :func:`identification.batch.fit_batch` on the derived model
of :func:`identification.fixed.fixed_model` (K grid points per batch, their rows stacked by
:func:`identification.fixed.stacked_fixed_batch`), CPU per grid point and the largest relative
difference of the objectives, on a 3-parameter explicit model and the implicit spring chain
(4 states, 3 parameters).

Run ``python -m bench.bench_bootstrap_batch --n 200 --repeats 3 --profiles`` (``--jit`` compiles
the CasADi functions to C for both paths).
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
from identification.batch import fit_batch  # noqa: E402
from identification.bootstrap import bootstrap_replicates  # noqa: E402
from identification.fixed import fixed_model, stacked_fixed_batch  # noqa: E402
from identification.profile import lr_region  # noqa: E402
from identification.montecarlo import ModelCampaign  # noqa: E402
from models import Model  # noqa: E402
from models.library import spring_chain  # noqa: E402
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


def region_problems() -> list:
    """(label, model, data, estimate) of the region benchmark (3 parameters each)."""
    out = []
    rs = Model.explicit(params=["a", "b", "c"], inputs=["x"], sensors=["y"],
                        h=lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])) + p[2] * q[0], name="rise and slope")
    x = np.linspace(0.5, 10.0, 12)
    z = (3 * (1 - np.exp(-0.4 * x)) + 0.1 * x)[None, :, None] + 0.05 * np.random.default_rng(1).standard_normal((2, 12, 1))
    d = Measurements(x, z, [0.05])
    out.append(("explicit y = a (1 - exp(-b x)) + c x (12 points, n_M = 2)", rs, d, identify(rs, d, [2.0, 0.5, 0.0])))
    ch = spring_chain(n_y=4, n_sensors=2, n_groups=2)
    p_true = np.array([2.0, 3.0, 0.05])
    gen = ModelCampaign(ch, p_true, np.column_stack([np.linspace(0.5, 3.0, 10), np.linspace(1.0, -1.0, 10)]),
                        0.01, 2)
    d = gen(np.random.default_rng(5))
    out.append(("implicit spring chain (4 states, 10 loads, 2 sensors)", ch, d, identify(ch, d, p_true)))
    return out


def region_table(n_grid: int, sizes: tuple) -> None:
    """CPU per grid point: lr_region (per-point Newton) against fit_batch on the derived model."""
    print(f"\nConstrained fits of an {n_grid} x {n_grid} likelihood-ratio region (pair (0, 1) fixed, the third "
          "parameter re-optimised)\n")
    print("| problem | lr_region CPU / point | " + " | ".join(f"fit_batch, K = {k}: CPU / point" for k in sizes)
          + " | max rel. diff of the objectives | batch fallbacks |")
    print("|---|---|" + "---|" * len(sizes) + "---|---|")
    for label, model, data, est in region_problems():
        lr_region(model, data, est, (0, 1), n_grid=3, grid="axes")
        reg, _, c_lr = _timed(lambda: lr_region(model, data, est, (0, 1), n_grid=n_grid, grid="axes"))
        values = np.column_stack([reg.X.ravel(), reg.Y.ravel()])
        fm = fixed_model(model, [0, 1])
        target = est.objective + reg.statistic.ravel() / 2
        cells, diff, n_fb = [], 0.0, 0
        for k in sizes:
            fit_batch(fm, stacked_fixed_batch(data.inputs, data.z, est.sigma, values[:k]), est.p[2:], est.weights)

            def run():
                return [fit_batch(fm, stacked_fixed_batch(data.inputs, data.z, est.sigma, values[a:a + k]),
                                  est.p[2:], est.weights) for a in range(0, len(values), k)]
            fits, _, c_b = _timed(run)
            obj = np.concatenate([f.objective for f in fits])
            diff = max(diff, float(np.nanmax(np.abs(obj - target) / np.abs(target))))
            n_fb += sum(len(f.fallbacks) for f in fits)
            cells.append(f"{c_b / len(values) * 1e3:.2f} ms")
        print(f"| {label} | {c_lr / len(values) * 1e3:.2f} ms | " + " | ".join(cells) + f" | {diff:.1e} | {n_fb} |",
              flush=True)


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
    ap.add_argument("--profiles", action="store_true", help="also the constrained fits of a likelihood-ratio region")
    ap.add_argument("--n-grid", type=int, default=11, help="grid points per axis of the region (--profiles)")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    print(f"machine: {_machine()}; {time.strftime('%Y-%m-%d %H:%M:%S %Z')}; n = {args.n} replicates, "
          f"{args.repeats} alternating repeats (medians), serial, JIT {'on' if args.jit else 'off'}", flush=True)
    set_jit(bool(args.jit))
    print("\n| problem | identify CPU / replicate | batch CPU / replicate | CPU ratio | identify wall / replicate "
          "| batch wall / replicate | max rel. diff of the refits | batch fallbacks | failed refits |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label, model, data, est in problems():
        jit = bool(args.jit)
        bootstrap_replicates(model, data, est, n=4, seed=0, jit=jit)         # build (and compile) once
        bootstrap_replicates(model, data, est, n=2, seed=0, batch=False, jit=jit)
        times = {True: [], False: []}
        got = {}
        for _ in range(args.repeats):
            for batch in (False, True):
                got[batch], w, c = _timed(lambda: bootstrap_replicates(model, data, est, n=args.n, seed=args.seed,
                                                                       batch=batch, jit=jit))
                times[batch].append((w, c))
        (wi, ci), (wb, cb) = (np.median(np.array(times[b]), axis=0) for b in (False, True))
        Pf, Pb = got[False].P, got[True].P
        ok = np.all(np.isfinite(Pf), axis=1) & np.all(np.isfinite(Pb), axis=1)
        diff = float(np.max(np.abs(Pb[ok] - Pf[ok]) / np.abs(Pf[ok]))) if ok.any() else float("nan")
        n = args.n
        print(f"| {label} | {ci / n * 1e3:.2f} ms | {cb / n * 1e3:.2f} ms | {ci / cb:.1f} | {wi / n * 1e3:.2f} ms "
              f"| {wb / n * 1e3:.2f} ms | {diff:.1e} | {len(got[True].fallbacks)} | "
              f"{len(got[True].errors)} (identify path: {len(got[False].errors)}) |", flush=True)
    if args.profiles:
        region_table(args.n_grid, (3, 11, 33))


if __name__ == "__main__":
    main()
