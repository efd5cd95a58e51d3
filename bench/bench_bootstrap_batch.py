"""The parametric bootstrap with the batch engine against one identify call per refit (issue 15).

For each problem the estimate of one data set is bootstrapped twice in this process, serially,
with the same seed: ``bootstrap_replicates(..., refits=BATCH_REFITS)`` (the replicates of a chunk refitted
together by :func:`identification.fit.batch.fit_batch`) and ``refits=ONE_BY_ONE_REFITS`` (one
:func:`identification.identify` per replicate).  The two runs alternate (``--repeats`` times,
medians reported), so both see the same load on a shared machine.  Reported per problem: CPU
and wall time per replicate of each path, the CPU ratio, the largest relative difference of the
refits between the paths, the fallbacks of the batch engine and the failed refits.

Problems: the press model M1 (the paper's 29 loads, n_M = 2, sensors D_y and F_x, the paper's
sigma, known), Michaelis-Menten (8 points, n_M = 2, sigma known) and Rooney-Biegler (6 points,
sigma estimated).

``--profiles`` adds a second table: likelihood-ratio regions
(:func:`identification.inference.profile.lr_region`, ``grid="valley"`` by default, the pair fixed at every
grid point, the third parameter re-optimised) computed with ``batch=False`` (one reduced Newton
per point, warm started from its neighbour) and ``batch=True`` (every row but the centre one as
one :func:`identification.fit.batch.fit_batch` call on the derived model of
:func:`identification.fit.fixed.fixed_model`, per-member inputs), alternating in one process: CPU
and wall per grid point, the largest difference of the statistic D between the paths and the
batched points redone point by point, on a 3-parameter explicit model and the implicit spring
chain (4 states, 3 parameters), 11 x 11 and 25 x 25 grids.

Run ``python -m bench.bench_bootstrap_batch --n 200 --repeats 3 --profiles`` (``--profiles-only``:
only the region table; ``--jit`` compiles the CasADi functions to C for both paths).
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
from identification.inference.bootstrap import BATCH_REFITS, ONE_BY_ONE_REFITS, bootstrap_replicates  # noqa: E402
from identification.inference.likelihood_region import BATCHED_ROWS, PER_POINT  # noqa: E402
from identification.inference.profile import lr_region  # noqa: E402
from identification.studies.montecarlo import ModelCampaign  # noqa: E402
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


#: the two grid strategies of lr_region, keyed as the table's columns (batched or not)
SOLVERS = {False: PER_POINT, True: BATCHED_ROWS}


def region_table(sizes: tuple, repeats: int, grid: str = "valley") -> None:
    """CPU per grid point of lr_region: the per-point solver (PER_POINT) against the rows batched (BATCHED_ROWS)."""
    print(f"\nLikelihood-ratio regions (lr_region, grid = {grid!r}, pair (0, 1), the third parameter re-optimised at "
          f"every point): per-point Newton (solver=PER_POINT) against rows as fit_batch calls with per-member inputs "
          f"(solver=BATCHED_ROWS); medians of {repeats} alternating runs\n")
    print("| problem | grid | per-point CPU / point | batched CPU / point | CPU ratio | per-point wall / point "
          "| batched wall / point | max abs diff of D | points solved | batched points redone point by point |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for label, model, data, est in region_problems():
        for b in (False, True):
            lr_region(model, data, est, (0, 1), n_grid=5, grid=grid, solver=SOLVERS[b])  # build once
        for n in sizes:
            times = {True: [], False: []}
            got = {}
            for _ in range(repeats):
                for b in (False, True):
                    got[b], w, c = _timed(lambda: lr_region(model, data, est, (0, 1), n_grid=n, grid=grid,
                                                            solver=SOLVERS[b]))
                    times[b].append((w, c))
            (wp, cp), (wb, cb) = (np.median(np.array(times[b]), axis=0) for b in (False, True))
            Dp, Db = got[False].statistic, got[True].statistic
            both = np.isfinite(Dp) & np.isfinite(Db)
            same = bool(np.array_equal(np.isfinite(Dp), np.isfinite(Db)))
            diff = float(np.max(np.abs(Dp[both] - Db[both]))) if both.any() else float("nan")
            redo = [note.split()[0] for note in got[True].notes if "point by point" in note]
            k = n * n
            print(f"| {label} | {n} x {n} | {cp / k * 1e3:.2f} ms | {cb / k * 1e3:.2f} ms | {cp / cb:.1f} | "
                  f"{wp / k * 1e3:.2f} ms | {wb / k * 1e3:.2f} ms | {diff:.1e} | {int(both.sum())} of {k}"
                  f"{'' if same else ' (different points solved!)'} | {redo[0] if redo else 0} |", flush=True)


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
    ap.add_argument("--n-grid", type=int, nargs="+", default=[11, 25], help="grid points per axis of the region (--profiles)")
    ap.add_argument("--grid", default="valley", choices=("valley", "axes", "principal"), help="grid of the region")
    ap.add_argument("--profiles-only", action="store_true", help="only the region table")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    print(f"machine: {_machine()}; {time.strftime('%Y-%m-%d %H:%M:%S %Z')}; n = {args.n} replicates, "
          f"{args.repeats} alternating repeats (medians), serial, JIT {'on' if args.jit else 'off'}", flush=True)
    set_jit(bool(args.jit))
    if args.profiles_only:
        region_table(tuple(args.n_grid), args.repeats, args.grid)
        return
    print("\n| problem | identify CPU / replicate | batch CPU / replicate | CPU ratio | identify wall / replicate "
          "| batch wall / replicate | max rel. diff of the refits | batch fallbacks | failed refits |")
    print("|---|---|---|---|---|---|---|---|---|")
    for label, model, data, est in problems():
        jit = bool(args.jit)
        bootstrap_replicates(model, data, est, n=4, seed=0, jit=jit)         # build (and compile) once
        bootstrap_replicates(model, data, est, n=2, seed=0, refits=ONE_BY_ONE_REFITS, jit=jit)
        times = {True: [], False: []}
        got = {}
        for _ in range(args.repeats):
            for batch in (False, True):
                got[batch], w, c = _timed(lambda: bootstrap_replicates(model, data, est, n=args.n, seed=args.seed,
                                                                       refits=BATCH_REFITS if batch
                                                                       else ONE_BY_ONE_REFITS, jit=jit))
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
        region_table(tuple(args.n_grid), args.repeats, args.grid)


if __name__ == "__main__":
    main()
