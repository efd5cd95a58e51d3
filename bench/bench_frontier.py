"""Second-order frontier (issue 13 item 4): sizes that ``method="auto"`` proves within the time limit.

``python -m bench frontier [--time-limit=60] [--scip-limit=60] [--cases=30x4x6:ADE,35x4x6:ADE,...]
[--scip-cases=30x4x6] [--bound-study] [--out=FILE]``

Instances (seeded, as bench/bench_planning.py): rank-2 F_k = A_k^T A_k, A_k ~ N(0, 1) (2 x p), and
symmetric indefinite S_k with ||S_k||_F = 0.05 ||F_k||_F; n candidates, p parameters, choose k.

Per case and criterion: auto's route and outcome (proven, value, gap, wall and CPU s), the screened
enumeration's measured time (when auto enumerates, that is auto's run), and SCIP's status/time where
auto chose SCIP or the case is listed in ``--scip-cases``.  The branch-and-bound column is "-": its
second-order bound (oed.bnb.second_order) prunes nothing on these instances, see ``--bound-study``.

``--bound-study``: on 30 x 4 choose 6, for the lexicographic set-enumeration tree (node = the first d
chosen sensors), the median radius kappa-bar and how many nodes of depth d the bound would prune
given the *exact* Gauss-Newton minimum of each node and the true optimum as incumbent (an upper
limit on what any branch-and-bound with this bound can prune).
"""
from __future__ import annotations

import argparse
import os
import resource
import time
from math import comb

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402


def _instance(seed, n, p):
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((n, 2, p))
    F = np.einsum("kri,krj->kij", a, a)
    B = rng.standard_normal((n, p, p))
    B = B + B.transpose(0, 2, 1)
    S = 0.05 * B * (np.linalg.norm(F, axis=(1, 2)) / np.linalg.norm(B, axis=(1, 2)))[:, None, None]
    return F, S


def _cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _fmt_gap(crit, r):
    if r.proven_optimal:
        return "0"
    if not np.isfinite(r.gap):
        return "inf"
    return f"{r.gap:.3g}" if crit == "D" else f"{100 * r.gap / abs(r.value):.3g} %"


def frontier(cases, scip_cases, time_limit, scip_limit):
    """Print and return the markdown rows of the frontier table."""
    from oed import select_sensors_from_information
    from oed.scip_solver import scip_available

    hdr = ("| n x p, choose k | designs | crit | auto route | proven | value | gap | auto wall s | auto CPU s | "
           "enumeration rate (designs/s, measured by auto) | B&B | SCIP (limit) |")
    lines = [hdr, "|" + "---|" * 12]
    print("\n".join(lines), flush=True)
    for n, p, k, crits in cases:
        F, S = _instance(n * 100 + k, n, p)
        for crit in crits:
            t, c = time.perf_counter(), _cpu()
            r = select_sensors_from_information(F, S, criterion=crit, kind="second_order", n_sensors=k,
                                                time_limit=time_limit)
            wall, cpu = time.perf_counter() - t, _cpu() - c
            note = next((x for x in r.notes if x.startswith("auto:")), "")
            rate = note.split("(")[1].split(" designs/s")[0] if "designs/s" in note else "-"
            scip = "-"
            if r.method == "scip":
                scip = f"auto's route: {r.status}"
            elif f"{n}x{p}x{k}" in scip_cases and scip_available():
                t = time.perf_counter()
                s = select_sensors_from_information(F, S, criterion=crit, kind="second_order", n_sensors=k,
                                                    method="scip", time_limit=scip_limit)
                same = abs(s.value - r.value) <= 1e-9 * max(abs(r.value), 1.0)
                scip = (f"{s.status}, {time.perf_counter() - t:.1f} s ({scip_limit:g} s), gap {_fmt_gap(crit, s)}, "
                        f"value {'= optimum' if same else f'{s.value:.6g}'}")
            route = f"**{r.method}**"
            line = (f"| {n} x {p}, {k} | {comb(n, k):,} | {crit} | {route} | {'yes' if r.proven_optimal else 'no'} | "
                    f"{r.value:.6g} | {_fmt_gap(crit, r)} | {wall:.1f} | {cpu:.1f} | {rate} | - | {scip} |")
            print(line, flush=True)
            lines.append(line)
    return lines


def bound_study(n=30, p=4, k=6, depths=(2, 3, 4)):
    """Median kappa-bar and prunable nodes per depth of the set-enumeration tree (see the module doc)."""
    from oed.constraints import make_constraints
    from oed.criteria import Criterion, batch_criteria
    from oed.enumeration import iter_designs

    F, S = _instance(n * 100 + k, n, p)
    W = np.concatenate(list(iter_designs(make_constraints(n, p, n_sensors=k))))
    idx = np.nonzero(W)[1].reshape(len(W), k)
    so = batch_criteria(F, S, W, "second_order")
    gn = batch_criteria(F, S, W, "gauss_newton")
    G = (W @ F.reshape(n, -1)).reshape(-1, p, p)
    Sw = (W @ S.reshape(n, -1)).reshape(-1, p, p)
    true_kappa = np.abs(np.linalg.eigvals(np.linalg.solve(G, Sw)).real).max(axis=1)
    lines = [f"true kappa of the {len(W):,} designs: median {np.median(true_kappa):.3g}, 99 % quantile "
             f"{np.quantile(true_kappa, 0.99):.3g}, max {true_kappa.max():.3g}", "",
             "| depth d | nodes | median kappa-bar | A: pruned nodes (designs) | D: pruned nodes (designs) | "
             "E: pruned nodes (designs) |", "|---|---|---|---|---|---|"]
    for d in depths:
        pre = idx[:, :d]
        start = np.r_[0, 1 + np.flatnonzero(np.any(pre[1:] != pre[:-1], axis=1))]
        size = np.diff(np.r_[start, len(W)])
        P = pre[start]
        GI = F[P].sum(axis=1)
        lam, U = np.linalg.eigh(GI)
        ok = lam[:, 0] > 1e-13 * lam[:, -1]
        V = (U / np.sqrt(np.where(ok[:, None], lam, 1.0))[:, None, :]) @ U.transpose(0, 2, 1)
        eI = np.abs(np.linalg.eigvalsh(V @ S[P].sum(axis=1) @ V))
        eR = np.abs(np.linalg.eigvalsh(V[:, None] @ S[None] @ V[:, None]))          # (nodes, n, p)
        later = np.arange(n)[None, :] > P[:, -1:]
        r = k - d
        kap_k = np.sort(np.where(later, eR.max(axis=2), 0.0), axis=1)[:, ::-1][:, :r].sum(axis=1)
        tau_k = np.sort(np.where(later, eR.sum(axis=2), 0.0), axis=1)[:, ::-1][:, :r].sum(axis=1)
        kap = np.where(ok, eI.max(axis=1) + kap_k, np.inf)
        tau = np.minimum(np.where(ok, eI.sum(axis=1) + tau_k, np.inf), p * kap)
        cells = []
        for c in "ADE":
            crit = Criterion.parse(c)
            g = np.minimum.reduceat(gn.value(crit), start)
            opt = so.value(crit).min()
            with np.errstate(invalid="ignore", divide="ignore"):
                b = (g - 2 * p * np.log1p(np.minimum(kap, tau / p)) if c == "D"
                     else np.where(ok, np.maximum(g, 0) / (1 + kap) ** 2, 0.0))
            pr = b >= opt
            cells.append(f"{int(pr.sum())} ({int(size[pr].sum()):,})")
        lines.append(f"| {d} | {len(start):,} | {np.median(kap[ok]):.3g} | " + " | ".join(cells) + " |")
        print(lines[-1], flush=True)
    return lines


def main(argv=None):
    """Run the frontier table (and optionally the bound study) and print markdown."""
    ap = argparse.ArgumentParser(prog="bench frontier", description=__doc__.splitlines()[0])
    ap.add_argument("--time-limit", type=float, default=60.0)
    ap.add_argument("--scip-limit", type=float, default=60.0)
    ap.add_argument("--cases", default="30x4x6:ADE,35x4x6:ADE,40x4x6:D,45x4x6:D,30x4x8:D,20x6x8:ADE")
    ap.add_argument("--scip-cases", default="30x4x6")
    ap.add_argument("--bound-study", action="store_true")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    cases = []
    for c in args.cases.split(","):
        size, crits = c.split(":")
        n, p, k = (int(v) for v in size.split("x"))
        cases.append((n, p, k, crits))
    lines = frontier(cases, set(args.scip_cases.split(",")), args.time_limit, args.scip_limit)
    if args.bound_study:
        print()
        lines += [""] + bound_study()
    if args.out:
        with open(args.out, "w") as fh:
            fh.write("\n".join(lines) + "\n")
    return 0
