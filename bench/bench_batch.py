"""The batch engine (identification.fit.batch.fit_batch) against one identify call per fit (issue 15).

R simulated press campaigns (the paper's 29 loads, n_M = 2, sensors D_y and F_x, the paper's
sigma) are fitted on the calibration points of each of the paper's four scenarios, once with
``fit_batch`` (all R together) and once with ``identify`` per data set, in this process, JIT
on for both.  Reported per scenario: wall and CPU time per fit of each path, their ratio,
the largest relative difference of the estimates and of the second-order covariances, the
sweeps of the batch iteration and the fallbacks.  ``--explicit`` adds the README's
exponential model y = b1 (1 - exp(-b2 x)) with 14 points.

Run ``python -m bench.bench_batch --n-rep 200 --identify-rep 40``.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from bench.bench_detect import P0, PAPER_SPLITS, SIGMA_PAPER_MM, WEIGHTS_110, _machine  # noqa: E402
from identification import Measurements, identify  # noqa: E402
from identification.fit.batch import fit_batch  # noqa: E402
from identification.studies.montecarlo import ModelCampaign  # noqa: E402
from models.press import Q_PAPER, press_model  # noqa: E402
from models.state import set_jit  # noqa: E402


def _timed(f):
    c, t = time.process_time(), time.perf_counter()
    out = f()
    return out, time.perf_counter() - t, time.process_time() - c


def _compare(label, model, data, p0, weights, n_id):
    fit_batch(model, data[:2], p0, weights)                       # builds and compiles once
    identify(model, data[0], p0, weights=weights)
    bf, wb, cb = _timed(lambda: fit_batch(model, data, p0, weights))
    ests, wi, ci = _timed(lambda: [identify(model, d, p0, weights=weights) for d in data[:n_id]])
    P = np.array([e.p for e in ests])
    C = np.array([e.cov for e in ests])
    dp = float(np.max(np.abs(bf.p[:n_id] - P) / np.abs(P)))
    dc = float(np.max(np.abs(bf.cov[:n_id] - C) / np.abs(C).max(axis=(1, 2))[:, None, None]))
    R = len(data)
    sweeps = np.bincount(bf.iterations).tolist()
    print(f"| {label} | {R} | {wb / R * 1e3:.2f} ms | {cb / R * 1e3:.2f} ms | {n_id} | {wi / n_id * 1e3:.1f} ms "
          f"| {ci / n_id * 1e3:.1f} ms | {(ci / n_id) / (cb / R):.1f} | {dp:.1e} | {dc:.1e} | {sweeps} "
          f"| {len(bf.fallbacks)} |", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="bench batch")
    ap.add_argument("--n-rep", type=int, default=200, help="data sets per batch")
    ap.add_argument("--identify-rep", type=int, default=40, help="data sets fitted by identify (the first ones)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--explicit", action="store_true", help="also the README's exponential model")
    args = ap.parse_args(sys.argv[1:] if argv is None else argv)
    print(f"machine: {_machine()}; {time.strftime('%Y-%m-%d %H:%M:%S %Z')}", flush=True)
    set_jit(True)
    model = press_model()
    gen = ModelCampaign(model, model.p_nominal, np.array(Q_PAPER)[:, None], SIGMA_PAPER_MM, 2)
    rng = np.random.default_rng(args.seed)
    camps = [gen(rng) for _ in range(args.n_rep)]
    n_id = min(args.identify_rep, args.n_rep)
    print("\n| fits | R | batch wall per fit | batch CPU per fit | identify fits | identify wall per fit "
          "| identify CPU per fit | CPU ratio | max rel. diff p | max rel. diff cov | batch sweeps (histogram) "
          "| fallbacks |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for sp in PAPER_SPLITS:
        _compare(f"press, calibration of {sp.name}", model, [sp.calibration(c) for c in camps], P0, WEIGHTS_110, n_id)
    if args.explicit:
        import casadi as ca
        from models.contract import Model
        expo = Model.explicit(params=["b1", "b2"], inputs=["x"], sensors=["y"],
                              h=lambda p, q: p[0] * (1 - ca.exp(-p[1] * q[0])))
        x = np.linspace(50.0, 800.0, 14)
        y = 230.0 * (1 - np.exp(-5e-4 * x))
        data = [Measurements(x, (y + 0.5 * rng.standard_normal((1, 14)))[:, :, None], [0.5])
                for _ in range(args.n_rep)]
        _compare("exponential model, 14 points", expo, data, [200.0, 4e-4], None, n_id)


if __name__ == "__main__":
    main()
