"""Practical non-identifiability (issue 20 item 4): the weak Michaelis-Menten study.

y = Vm x / (K + x) observed far below saturation: Vm = 10, K = 20, x = 0.5, 1, 2, 3, 4 (x <= K / 5),
2 series, sigma = 0.1 known, start values the truth, the physical bounds Vm, K >= 0 (``--no-bounds``:
none).  In about 10 % of the campaigns the
least-squares fit has no finite minimum: the best fit runs off to infinity along Vm / K = const
(the data look linear or convex).  Before issue 20 identify raised IdentifiabilityError there.

For ``--reps`` campaigns (campaign r: ``numpy.random.default_rng(seed + r)``, z = h(p*) + sigma eps)
the script records

* every exception of identify or of the 95 % profile intervals, by type (target: none);
* how many estimates are not bounded (``Estimate.bounded`` False);
* the coverage of the 95 % profile-likelihood intervals of Vm and K (the truth inside; for an
  unbounded fit the interval is [lower, +inf)), with the binomial standard error
  sqrt(c (1 - c) / n) and the Clopper-Pearson 95 % interval;
* for the unbounded fits, an independent check of the finite lower profile limit of Vm:
  scipy's bounded scalar minimisation of Phi over log K at Vm = lower, against the infimum
  Phi_inf (the least-squares fit of the linear limit y = a x, closed form): 2 (Phi - Phi_inf)
  must equal chi2_1(0.95) = 3.841.

Run ``python -m bench.bench_weak_mm --reps 400`` (about a minute).  Against a tree without
issue 20's change the same script counts the exceptions of the old behaviour.
"""
from __future__ import annotations

import argparse
import collections
import math
import platform
import time

import numpy as np
from scipy import optimize, stats

from identification import IdentificationError, Measurements, identify
from identification.studies.montecarlo import clopper_pearson
from models import Model

VM, K, SIGMA = 10.0, 20.0, 0.1
X = np.array([0.5, 1.0, 2.0, 3.0, 4.0])
N_SERIES = 2


def model(bounds: bool = True, offset: bool = False) -> Model:
    """The Michaelis-Menten model, explicit, parameters Vm and K, with the physical bounds Vm, K >= 0
    (``bounds=False``: none; then a finite least-squares minimum with Vm, K < 0 exists beyond infinity
    for convex-looking data, which identify, following the path from the start, does not examine);
    ``offset``: y = c + Vm x / (K + x) with a third parameter c (true 1) that stays finite."""
    if offset:
        m = Model.explicit(params=["c", "Vm", "K"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] + p[1] * q[0] / (p[2] + q[0]), name="Michaelis-Menten + offset")
    else:
        m = Model.explicit(params=["Vm", "K"], inputs=["x"], sensors=["y"],
                           h=lambda p, q: p[0] * q[0] / (p[1] + q[0]), name="Michaelis-Menten")
    return m.with_bounds({"Vm": (0.0, math.inf), "K": (0.0, math.inf)}) if bounds else m


#: the offset variant's inputs (x = 0 added: it sees c alone) and its offset
X_OFFSET, C_OFFSET = np.r_[0.0, X], 1.0


def campaign(seed: int, offset: bool = False) -> Measurements:
    """Campaign ``seed``: z = (c +) Vm x / (K + x) + sigma eps, 2 series x 5 (6 with the offset) inputs."""
    rng = np.random.default_rng(seed)
    x = X_OFFSET if offset else X
    h = VM * x / (K + x) + (C_OFFSET if offset else 0.0)
    z = h[None, :, None] + SIGMA * rng.standard_normal((N_SERIES, x.size, 1))
    return Measurements(inputs=x[:, None], z=z, sigma=[SIGMA])


def _phi(data: Measurements, vm: float, k: float) -> float:
    r = data.z[:, :, 0] - vm * X / (k + X)
    return 0.5 * float(np.sum(r ** 2)) / SIGMA ** 2


def scipy_lower_check(data: Measurements, lower: float) -> float:
    """2 (min_K Phi(lower, K) - Phi_inf) by scipy (bounded minimisation over log K); Phi_inf is the
    least-squares fit of the linear limit y = a x."""
    zs = data.z[:, :, 0]
    a = float(np.sum(zs * X) / (N_SERIES * np.sum(X ** 2)))
    phi_inf = 0.5 * float(np.sum((zs - a * X) ** 2)) / SIGMA ** 2
    res = optimize.minimize_scalar(lambda lk: _phi(data, lower, math.exp(lk)), bounds=(-5.0, 40.0),
                                   method="bounded", options={"xatol": 1e-12})
    best = min(res.fun, min(_phi(data, lower, math.exp(t)) for t in np.linspace(-5, 40, 2000)))
    return 2.0 * (best - phi_inf)


def run(reps: int, seed: int, bounds: bool = True, offset: bool = False) -> dict:
    m = model(bounds, offset)
    truth = np.array([C_OFFSET, VM, K] if offset else [VM, K])
    errors = collections.Counter()
    examples = {}
    covered = np.zeros((reps, truth.size), bool)
    done = np.zeros(reps, bool)
    unbounded, checks, cov_unb = [], [], []
    for r in range(reps):
        data = campaign(seed + r, offset)
        try:
            est = identify(m, data, truth)
            ci = est.conf_int(0.05, method="profile")
        except (IdentificationError, ValueError, np.linalg.LinAlgError) as exc:
            errors[type(exc).__name__] += 1
            examples.setdefault(type(exc).__name__, (seed + r, str(exc).splitlines()[0][:200]))
            continue
        done[r] = True
        covered[r] = (ci.lower <= truth) & (truth <= ci.upper)
        if not getattr(est, "bounded", True):
            unbounded.append(seed + r)
            cov_unb.append(covered[r].copy())
            if not offset:
                checks.append(scipy_lower_check(data, float(ci.lower[0])))
    return {"errors": errors, "examples": examples, "covered": covered[done], "n_done": int(done.sum()),
            "unbounded": unbounded, "checks": np.array(checks), "covered_unbounded": np.array(cov_unb),
            "names": tuple(m.param_names)}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=400)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-bounds", action="store_true", help="no parameter bounds (default: Vm, K >= 0)")
    ap.add_argument("--offset", action="store_true", help="y = c + Vm x / (K + x), x = 0, 0.5..4 (c = 1)")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    out = run(args.reps, args.seed, not args.no_bounds, args.offset)
    wall = time.perf_counter() - t0
    n = out["n_done"]
    print(f"weak Michaelis-Menten{' + offset c = 1 (x = 0 added)' if args.offset else ''}: Vm = {VM:g}, K = {K:g}, x = {', '.join(f'{x:g}' for x in X)}, {N_SERIES} series, "
          f"sigma = {SIGMA:g} known, {'no bounds' if args.no_bounds else 'bounds Vm, K >= 0'}; {args.reps} campaigns (seeds {args.seed}..{args.seed + args.reps - 1}); "
          f"{wall:.1f} s on {platform.machine()} ({platform.python_version()})")
    print(f"exceptions: {sum(out['errors'].values())} {dict(out['errors'])}")
    for name, (s, msg) in out["examples"].items():
        print(f"  e.g. {name} (seed {s}): {msg}")
    print(f"estimates not bounded: {len(out['unbounded'])} of {n} (seeds {out['unbounded'][:12]}"
          f"{' ...' if len(out['unbounded']) > 12 else ''})")
    print("| parameter | 95 % profile coverage | binomial s.e. | Clopper-Pearson 95 % |")
    print("|---|---|---|---|")
    for i, name in enumerate(out["names"]):
        k = int(out["covered"][:, i].sum())
        c = k / n if n else math.nan
        se = math.sqrt(c * (1 - c) / n) if n else math.nan
        cp = clopper_pearson(k, n)
        print(f"| {name} | {100 * c:.2f} % ({k}/{n}) | {100 * se:.2f} % | [{100 * cp.lo:.2f}, {100 * cp.hi:.2f}] % |")
    cu = out["covered_unbounded"]
    if cu.size:
        print("of which the unbounded fits: " + ", ".join(f"{n} covered {int(cu[:, i].sum())}/{len(cu)}"
                                                          for i, n in enumerate(out["names"])))
    if out["checks"].size:
        dev = np.abs(out["checks"] - stats.chi2.ppf(0.95, 1))
        print(f"scipy check of the finite lower limit of Vm on the {out['checks'].size} unbounded fits: "
              f"2 (Phi - Phi_inf) = chi2_1(0.95) to max |dev| {dev.max():.2e}")


if __name__ == "__main__":
    main()
