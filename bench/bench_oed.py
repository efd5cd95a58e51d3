"""OED scale benchmark (issue 4): our branch-and-bound vs enumeration vs naive Pyomo/SCIP.

Solves min_w Psi((sum_k w_k F_k)^{-1}), sum w = m, for seeded random instances
F_k = a_k a_k^T, a_k ~ N(0, I_p), Psi in {A (trace), D (log det), E (lambda_max)}.

Usage: ``python -m bench oed [--quick] [--time-limit=60] [--scip-limit=20] [--scip-max-n=20] [--scip-form=naive|cuts]
[--enum-max=2000000] [--sizes=20x5,50x10] [--ms=10,20] [--crits=ADE] [--seed=0] [--out=FILE] [--press]
[--budget=FRACTION]``
(``--budget=0.8``: per-sensor costs c_k ~ U[0.5, 3] (seeded) and c^T w <= 0.8 m mean(c) with
sum w <= m instead of sum w = m, so the optimum may use fewer than m sensors)
(``--press``: the press with all 20 joint directions as candidates, e.g. ``--press --ms=2,3,4,6``)
(use the ``--opt=value`` form: ``python -m bench`` treats bare words as benchmark names).

For each instance: B&B (time limit), enumeration when C(n, m) <= enum-max, and the naive
single-MINLP Pyomo/SCIP formulation (Cholesky of M - tI for E, M = LL^T for D, M X = I
for A) with its own time limit for n <= scip-max-n.  Values are cross-checked: a
disagreement between methods that both claim optimality is printed as MISMATCH.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from math import comb

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # tiny matrices: BLAS threads only add contention
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402


def _instance(n, p, seed):
    rng = np.random.default_rng([seed, n, p])
    a = rng.standard_normal((n, p))
    return np.einsum("ki,kj->kij", a, a)


def _close(crit, a, b):
    if not (np.isfinite(a) and np.isfinite(b)):
        return False
    return abs(a - b) <= (1e-8 if crit == "D" else 1e-8 * max(abs(a), abs(b)))


def main(argv=None):
    """Run the benchmark and print a markdown table plus the frontier."""
    ap = argparse.ArgumentParser(prog="bench oed", description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small grid (20x5, 50x5; m=10) for smoke runs")
    ap.add_argument("--time-limit", type=float, default=60.0)
    ap.add_argument("--scip-limit", type=float, default=20.0)
    ap.add_argument("--scip-max-n", type=int, default=20)
    ap.add_argument("--scip-form", default="naive", choices=("naive", "cuts"),
                    help="SCIP formulation compared: the naive single MINLP or our convex-friendly cut loop")
    ap.add_argument("--enum-max", type=int, default=2_000_000)
    ap.add_argument("--sizes", default="20x5,20x10,50x5,50x10,100x5,100x10")
    ap.add_argument("--ms", default="10,20")
    ap.add_argument("--crits", default="ADE")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=None, help="also write the markdown table to this file")
    ap.add_argument("--budget", type=float, default=None,
                    help="costs U[0.5, 3] and budget FRACTION x m x mean cost, with sum w <= m")
    ap.add_argument("--press", action="store_true",
                    help="the press with every joint direction as a candidate sensor instead of random instances")
    args = ap.parse_args(argv)
    if args.press:
        return _press(args)
    if args.quick:
        args.sizes, args.ms, args.time_limit, args.scip_limit = "20x5,50x5", "10", 20.0, 5.0

    from oed.bnb import BnBSettings, branch_and_bound
    from oed.constraints import make_constraints
    from oed.criteria import validate_information
    from oed.enumeration import EnumerationSettings, enumerate_designs
    from oed.scip_solver import ScipSettings, scip_available, solve_scip

    have_scip = scip_available()
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    ms = [int(v) for v in args.ms.split(",")]
    rows = []
    hdr = ("| n | p | m | crit | B&B status | B&B s | nodes | gap | root gap | enum s | "
           f"{args.scip_form} SCIP status | SCIP s | enum/B&B | SCIP/B&B | check |")
    sep = "|" + "---|" * 15
    print(hdr)
    print(sep, flush=True)
    lines = [hdr, sep]
    for (n, p) in sizes:
        F, _ = validate_information(_instance(n, p, args.seed))
        for m in ms:
            if m < p or m > n:
                continue
            if args.budget is None:
                cons = make_constraints(n, p, n_sensors=m)
            else:
                costs = np.random.default_rng([args.seed, n, p, 7]).uniform(0.5, 3.0, n)
                cons = make_constraints(n, p, max_sensors=m, costs=costs, budget=args.budget * m * costs.mean())
            for crit in args.crits:
                b = branch_and_bound(F, cons, crit, settings=BnBSettings(time_limit=args.time_limit))
                rel = (lambda x: x) if crit == "D" else (lambda x: x / abs(b.value))
                e_t = e_v = None
                if cons.count_designs() <= args.enum_max:
                    e = enumerate_designs(F, None, cons, crit, settings=EnumerationSettings(max_designs=args.enum_max))
                    e_t, e_v = e.wall_time, e.value
                s_t = s_v = None
                s_status = "skipped"
                if have_scip and n <= args.scip_max_n:
                    t0 = time.perf_counter()
                    s = solve_scip(F, None, cons, crit, "gauss_newton",
                                   settings=ScipSettings(formulation=args.scip_form, time_limit=args.scip_limit))
                    s_t, s_v, s_status = time.perf_counter() - t0, s.value, s.status
                elif not have_scip:
                    s_status = "unavailable"
                checks = []
                if e_v is not None:
                    checks.append("enum=" + ("ok" if _close(crit, e_v, b.value) else "MISMATCH")
                                  if b.status == "optimal" else "enum:" + ("B&B-worse" if b.value > e_v else "ok"))
                if s_v is not None and s_status == "optimal" and b.status == "optimal":
                    checks.append("scip=" + ("ok" if _close(crit, s_v, b.value) else "MISMATCH"))
                fmt = lambda x: "-" if x is None else f"{x:.2f}"  # noqa: E731
                ratio = lambda x: "-" if x is None else f"{x / max(b.wall_time, 1e-3):.2g}"  # noqa: E731
                root_gap = rel(b.value - b.root_bound)
                line = (f"| {n} | {p} | {m} | {crit} | {b.status} | {b.wall_time:.2f} | {b.nodes} | {rel(b.gap):.2g} | "
                        f"{root_gap:.2g} | {fmt(e_t)} | {s_status} | {fmt(s_t)} | {ratio(e_t)} | "
                        f"{ratio(s_t) if s_status != 'skipped' else '-'} | {' '.join(checks) or '-'} |")
                print(line, flush=True)
                lines.append(line)
                rows.append((n, p, m, crit, b.status, b.wall_time))
    print()
    front = ["", "Frontier (largest n x p, m solved to proof by B&B within the time limit):"]
    for crit in args.crits:
        solved = [(n * p, n, p, m) for (n, p, m, c, st, _) in rows if c == crit and st == "optimal"]
        failed = [f"{n}x{p} m={m}" for (n, p, m, c, st, _) in rows if c == crit and st != "optimal"]
        best = max(solved, default=None)
        front.append(f"- {crit}: largest proven {best[1]}x{best[2]} m={best[3]}" if best else f"- {crit}: none")
        if failed:
            front[-1] += f"; not proven within the limit: {', '.join(failed)}"
    for f in front:
        print(f)
    lines += front
    if args.out:
        with open(args.out, "w") as fh:
            fh.write("\n".join(lines) + "\n")
    return 0


def _press(args):
    """B&B vs enumeration vs naive SCIP on the press with all 20 joint-direction candidates.

    F_k = sum_j G_jk^T G_jk / sigma^2 at k5 = k7 = 500 N/mm over the paper's 29 loads, 2
    series; sigma = 3.904 um (the paper's B0_y sensor) for every candidate except D_y and F_x
    (their paper values), so the candidates differ by what they see, not by their quality.
    """
    from identification import Measurements, information_contributions, simulate
    from models.press import Q_PAPER, press_model
    from oed.bnb import BnBSettings, branch_and_bound
    from oed.constraints import make_constraints
    from oed.criteria import validate_information
    from oed.enumeration import enumerate_designs
    from oed.scip_solver import ScipSettings, scip_available, solve_scip

    model = press_model(extra_sensors=True)
    q = np.asarray(Q_PAPER, float)[:, None]
    sig = np.full(model.n_S, 3.904e-3)
    sig[list(model.sensors).index("D_y")] = 1.518e-2
    sig[list(model.sensors).index("F_x")] = 4.895e-3
    H = simulate(model, model.p_nominal, q)
    F, _ = information_contributions(model, Measurements(q, np.stack([H, H]), sig), model.p_nominal)
    F, _ = validate_information(F)
    n = model.n_S
    hdr = ("| m | crit | B&B status | B&B s | nodes | enum s | enum designs | naive SCIP status | SCIP s | "
           "chosen sensors | check |")
    lines = [f"press, {n} candidates ({', '.join(model.sensors)}), n_p = {model.n_p}", "", hdr, "|" + "---|" * 11]
    for line in lines:
        print(line)
    for m in [int(v) for v in args.ms.split(",")]:
        if m < model.n_p or m > n:
            continue
        cons = make_constraints(n, model.n_p, n_sensors=m)
        for crit in args.crits:
            b = branch_and_bound(F, cons, crit, settings=BnBSettings(time_limit=args.time_limit))
            e = enumerate_designs(F, None, cons, crit)
            s_st, s_t = "unavailable", None
            if scip_available():
                t0 = time.perf_counter()
                sres = solve_scip(F, None, cons, crit, "gauss_newton",
                                  settings=ScipSettings(formulation=args.scip_form, time_limit=args.scip_limit))
                s_st, s_t = sres.status, time.perf_counter() - t0
                s_ok = "" if sres.status != "optimal" else (" scip=" + ("ok" if _close(crit, sres.value, b.value)
                                                                         else "MISMATCH"))
            else:
                s_ok = ""
            chosen = ", ".join(model.sensors[k] for k in np.flatnonzero(b.w))
            check = ("enum=" + ("ok" if _close(crit, e.value, b.value) else "MISMATCH")) + s_ok
            line = (f"| {m} | {crit} | {b.status} | {b.wall_time:.3f} | {b.nodes} | {e.wall_time:.3f} | {comb(n, m)} | "
                    f"{s_st} | {'-' if s_t is None else f'{s_t:.2f}'} | {chosen} | {check} |")
            print(line, flush=True)
            lines.append(line)
    if args.out:
        with open(args.out, "w") as fh:
            fh.write("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
