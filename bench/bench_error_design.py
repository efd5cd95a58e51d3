"""Designs that learn the model error (issue 29 item 3): which runs the criterion picks on the press, how much of the
band they remove against a D-optimal or a uniform choice of the same size, and a Monte Carlo check that the
predicted posterior variance is the variance of the prediction error.

On the shipped press study (``configs/press.toml``), M1's model error is computed as the study computes it
(:func:`identification.model_error`, kind auto, the study's splits, the sensors F_x and B0_y of the study's design);
then for new runs of ``--repeats`` series at the candidate press forces 0, 100, ..., 1600 N:

1. **designs**: :func:`oed.error_design.select_error_design` for n = 1, 2, 4, 6 runs over three regions of use (the
   whole range, integrated (21-node Gauss-Legendre) and worst case (21 points); high forces 1200-1600 N
   integrated), against the D-optimal n runs of :func:`oed.select_inputs` (the runs alone, the classical design)
   and n evenly spread candidates: the criterion (mean or largest posterior variance, sigma^2 units), the share
   of the reducible variance removed ((J_before - J) / (J_before - J_irreducible)) and the mean band half-width
   (um) before and after;
2. **search**: enumeration against branch-and-bound on the same problems (same set and value, time); then 33
   candidates (every 50 N) and 8 runs, beyond a quick enumeration: branch-and-bound with its proven gap at the time
   limit against greedy + exchange with its gap to the root bound;
3. **Monte Carlo** (``--n-mc`` replications): the linearised model with the fitted discrepancy simulated jointly at
   the measured rows, the chosen new runs and the region (Gaussian process per sensor with M1's hyperparameters,
   rough part, noise sigma^2 / series), predicted by generalised least squares plus kriging from all readings,
   written here independently of :mod:`oed.error_design`; the empirical mean squared prediction error per region
   point over the predicted posterior variance (ratio 1 expected, standard error sqrt(2 / n) per point), pooled
   with its standard error over replications, before and after the runs.

4. **conditions** (``--skip`` without ``conditions``): M1's model error with the direction of motion named
   (``groups`` loading / unloading: each branch's discrepancy its own draw); the region 0-1600 N on both branches,
   on loading, on unloading (integrated, 21 nodes); runs of ``--repeats`` series at the 17 forces on the loading
   branch only, or on either branch (34 candidates): J before and after, the part no run removes, the share of J
   removed, the runs (N and branch) and the mean half-width per branch before and after; enumeration against
   branch-and-bound on the same problems.

Run ``python -m bench error_design`` (``--quick``: n <= 4 and 1000 replications).
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")      # small dense algebra: threads only contend

import argparse                                                   # noqa: E402
import math                                                       # noqa: E402
import time                                                       # noqa: E402
from pathlib import Path                                          # noqa: E402

import numpy as np                                                # noqa: E402

from identification import model_error                            # noqa: E402
from identification.studies.model_error_fit import outputs_at     # noqa: E402
from mudoe.config import load_config                              # noqa: E402
from mudoe.study import prepare                                   # noqa: E402
from oed import select_inputs                                     # noqa: E402
from oed.error_design import error_design_problem, select_error_design   # noqa: E402
from oed.error_design_search import search                        # noqa: E402
from models.press import PRESS_LOADING_ROWS                       # noqa: E402

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "press.toml"
#: the sensors of the study's E-optimal design ([oed] n_sensors = 2): F_x and B0_y
WEIGHTS = np.array([0.0, 1.0, 1.0])
SENSORS = ("F_x", "B0_y")
CANDIDATES = np.arange(0.0, 1601.0, 100.0)
REGIONS = (("whole range, integrated", {"q_P": (0.0, 1600.0)}, "integrated"),
           ("whole range, worst case", {"q_P": (0.0, 1600.0)}, "worst"),
           ("mid forces 400-1000 N, integrated", {"q_P": (400.0, 1000.0)}, "integrated"),
           ("high forces 1200-1600 N, integrated", {"q_P": (1200.0, 1600.0)}, "integrated"))
#: the model's displacement unit is mm (configs/press.toml converts once); bands are printed in um
UM = 1000.0


def _load():
    return os.getloadavg()[0]


def m1_error(study):
    """M1's ModelErrorResult as the study computes it (kind auto, the study's splits, F_x and B0_y)."""
    t0 = time.perf_counter()
    r = model_error(study.models["M1"], study.data["M1"], study.p0, splits=study.splits, weights=WEIGHTS)
    print(f"model_error of M1: {time.perf_counter() - t0:.1f} s (load {_load():.1f}); kind {r.kind} ({r.how})")
    for d in r.discrepancies:
        print(f"  {d.sensor}: s/sigma {d.amplitude / d.sigma:.3g}, length scale {d.length_scales[0]:.4g} N, "
              f"tau/sigma {d.rough / d.sigma:.3g}, sigma {d.sigma:.4g}")
    return r


def _uniform(n: int) -> tuple:
    return tuple(int(i) for i in np.unique(np.round(np.linspace(0, len(CANDIDATES) - 1, n)).astype(int)))


def _d_optimal(study, r, n: int, repeats: int) -> tuple:
    d = select_inputs(study.models["M1"], r.p, candidates=CANDIDATES[:, None], sigma=r.sigma, n_points=n,
                      sensors=list(SENSORS), criterion="D", n_series=repeats)
    return tuple(sorted(int(i) for i in d.indices))


def designs(study, r, sizes, repeats: int) -> dict:
    """Part 1: the error design against D-optimal and uniform runs, per region and n; returns {(region, n): set}."""
    out = {}
    for label, box, crit in REGIONS:
        prob = error_design_problem(r, CANDIDATES, region=box, criterion=crit, repeats=repeats, region_size=21)
        before, floor = prob.value(()), prob.floor
        hb = prob.half_widths((), r.alpha)
        print(f"\n{label}: J before {before:.4f} sigma^2, of which irreducible {floor:.4f}; mean half-width before "
              f"F_x {UM * prob.region_weights @ hb[:, 0]:.4f}, B0_y {UM * prob.region_weights @ hb[:, 1]:.4f} um")
        print(f"  {'n':>2} {'design':<9} {'runs (N)':<42} {'J':>8} {'removed':>8} {'F_x um':>9} {'B0_y um':>9}")
        for n in sizes:
            t0 = time.perf_counter()
            e = select_error_design(r, CANDIDATES, n, region=box, criterion=crit, repeats=repeats, region_size=21)
            dt = time.perf_counter() - t0
            out[(label, n)] = e.chosen
            for name, s in (("error", e.chosen), ("D-opt", _d_optimal(study, r, n, repeats)), ("uniform", _uniform(n))):
                j = prob.value(s)
                h = prob.half_widths(s, r.alpha)
                runs = ", ".join(f"{CANDIDATES[i]:g}" for i in s)
                print(f"  {n:>2} {name:<9} {runs:<42.42} {j:>8.4f} {100 * (before - j) / (before - floor):>7.1f}% "
                      f"{UM * prob.region_weights @ h[:, 0]:>9.4f} {UM * prob.region_weights @ h[:, 1]:>9.4f}")
            print(f"     ({e.method}, {'proven optimal' if e.proven else 'gap ' + format(e.gap, '.3g')}, "
                  f"{e.n_evaluated} sets, {dt:.2f} s, load {_load():.1f})")
    return out


def search_agreement(r, sizes, repeats: int) -> None:
    """Part 2: enumeration and branch-and-bound on the same problems."""
    print(f"\nenumeration vs branch-and-bound (17 candidates; load {_load():.1f})")
    print(f"  {'region':<38} {'n':>2} {'same set':>8} {'|dJ|':>9} {'enum s':>7} {'bnb s':>7} {'nodes':>6}")
    for label, box, crit in REGIONS:
        prob = error_design_problem(r, CANDIDATES, region=box, criterion=crit, repeats=repeats, region_size=21)
        for n in sizes:
            t0 = time.perf_counter()
            e = search(prob.core, n, "enumerate")
            te = time.perf_counter() - t0
            t0 = time.perf_counter()
            b = search(prob.core, n, "bnb", time_limit=120.0)
            tb = time.perf_counter() - t0
            print(f"  {label:<38.38} {n:>2} {str(e.indices == b.indices):>8} {abs(e.value - b.value):>9.2g} "
                  f"{te:>7.2f} {tb:>7.2f} {b.nodes:>6}{'' if b.proven else ' NOT PROVEN gap %.3g' % b.gap}")


def beyond_enumeration(r, repeats: int, n: int, time_limit: float) -> None:
    """Part 2b: 33 candidates (every 50 N), n runs: too many sets for a quick enumeration; branch-and-bound with its
    proven gap at the time limit, against greedy + exchange and its gap to the root bound."""
    cands = np.arange(0.0, 1601.0, 50.0)
    print(f"\n33 candidates (every 50 N), n = {n} ({math.comb(33, n)} sets); branch-and-bound time limit "
          f"{time_limit:g} s (load {_load():.1f})")
    print(f"  {'region':<38} {'greedy J':>10} {'gap':>8} {'bnb J':>10} {'status':>10} {'gap':>8} {'nodes':>6} {'s':>6}")
    for label, box, crit in REGIONS:
        prob = error_design_problem(r, cands, region=box, criterion=crit, repeats=repeats, region_size=21)
        g = search(prob.core, n, "greedy")
        t0 = time.perf_counter()
        b = search(prob.core, n, "bnb", time_limit=time_limit)
        dt = time.perf_counter() - t0
        print(f"  {label:<38.38} {g.value:>10.6f} {g.gap:>8.2g} {b.value:>10.6f} {b.status:>10} {b.gap:>8.2g} "
              f"{b.nodes:>6} {dt:>6.1f}   runs {', '.join(f'{cands[i]:g}' for i in b.indices)}")


# ---------------------------------------------------------------------------- Monte Carlo (independent of oed)
def _sqrt_psd(K: np.ndarray) -> np.ndarray:
    w, U = np.linalg.eigh(K)
    return U * np.sqrt(np.clip(w, 0.0, None))


def monte_carlo(study, r, chosen: tuple, region: np.ndarray, repeats: int, n_mc: int, seed: int) -> None:
    """Part 3: the empirical mean squared prediction error at the region points against the predicted posterior
    variance, without and with the new runs ``chosen``."""
    if r.exact_at or r.kind != "discrepancy":
        raise SystemExit("bench error_design: the Monte Carlo part is written for an unpinned discrepancy")
    data = study.data["M1"]
    cols = [list(data.sensors).index(s) for s in SENSORS]
    hyp = {d.sensor: (d.amplitude, d.length_scales[0], d.rough) for d in r.discrepancies}
    prob = error_design_problem(r, CANDIDATES, region=np.asarray(region, float).reshape(-1, 1), repeats=repeats)
    rng = np.random.default_rng(seed)
    q_old, counts, region = data.inputs[:, 0], data.counts(), np.asarray(region, float).ravel()
    q_new = CANDIDATES[list(chosen)]
    print(f"\nMonte Carlo ({n_mc} replications, seed {seed}; new runs at {q_new.tolist()} N, {repeats} series)")
    print(f"  {'runs':<7} {'pooled ratio':>12} {'+- se':>7} {'min ratio':>9} {'max ratio':>9} {'|z|>2.58':>8}")
    for label, new in (("before", np.array([])), ("after", q_new)):
        pred_var = prob.variances(() if label == "before" else chosen)          # (n_r, 2), um^2
        q_all = np.concatenate([q_old, new, region])
        G_all = outputs_at(r.fit.model, r.p, q_all[:, None])[1]
        n_o, n_n = len(q_old), len(new)
        err = np.zeros((n_mc, len(region), 2))
        ys, Gs, Vs, Gts, kts, truths = [], [], [], [], [], []
        for j, (s, c) in enumerate(zip(SENSORS, cols)):
            amp, ell, tau = hyp[s]
            K = amp ** 2 * np.exp(-(q_all[:, None] - q_all[None]) ** 2 / (2 * ell ** 2))
            delta = rng.standard_normal((n_mc, len(q_all))) @ _sqrt_psd(K).T
            rough = tau * rng.standard_normal((n_mc, len(q_all)))
            noise_var = np.concatenate([r.sigma[c] ** 2 / counts[:, c], np.full(n_n, r.sigma[c] ** 2 / repeats)])
            g = G_all[:, c, :]
            f = g @ r.p + delta + rough                                        # (n_mc, n_all)
            ys.append(f[:, :n_o + n_n] + np.sqrt(noise_var) * rng.standard_normal((n_mc, n_o + n_n)))
            Gs.append(g[:n_o + n_n])
            Vs.append(K[:n_o + n_n, :n_o + n_n] + np.diag(tau ** 2 + noise_var))
            Gts.append(g[n_o + n_n:])
            kts.append(K[n_o + n_n:, :n_o + n_n])
            truths.append(f[:, n_o + n_n:])
        Vi = [np.linalg.inv(V) for V in Vs]
        A = sum(G.T @ W @ G for G, W in zip(Gs, Vi))
        b = sum(y @ W @ G for y, W, G in zip(ys, Vi, Gs))                   # (n_mc, n_p)
        p_hat = np.linalg.solve(A, b.T).T
        for j in range(2):
            resid = ys[j] - p_hat @ Gs[j].T
            pred = p_hat @ Gts[j].T + resid @ (kts[j] @ Vi[j]).T
            err[:, :, j] = pred - truths[j]
        ratio = err ** 2 / pred_var[None]                                     # (n_mc, n_r, 2)
        per_point = ratio.mean(axis=0)
        pooled = ratio.mean(axis=(1, 2))
        z = (per_point - 1) / np.sqrt(2.0 / n_mc)
        print(f"  {label:<7} {pooled.mean():>12.4f} {pooled.std(ddof=1) / np.sqrt(n_mc):>7.4f} {per_point.min():>9.4f} "
              f"{per_point.max():>9.4f} {int(np.sum(np.abs(z) > 2.58)):>4} of {z.size}")


def press_branches(study) -> list:
    """The branch of every input row of the press data: "loading" (0 .. 1600 N, the peak included) or "unloading"."""
    return ["loading" if j in PRESS_LOADING_ROWS else "unloading" for j in range(study.data["M1"].n_q)]


def conditions(study, sizes, repeats: int) -> None:
    """Part 4: M1's model error with the branches named; runs on the loading branch only or on either branch."""
    t0 = time.perf_counter()
    r = model_error(study.models["M1"], study.data["M1"], study.p0, splits=study.splits, weights=WEIGHTS,
                    groups=press_branches(study), kind="discrepancy")
    print(f"\nM1 with the branches named (groups {list(r.groups)}), kind {r.kind}: {time.perf_counter() - t0:.1f} s "
          f"(load {_load():.1f})")
    for d in r.discrepancies:
        print(f"  {d.sensor}: s/sigma {d.amplitude / d.sigma:.3g}, length scale {d.length_scales[0]:.4g} N, "
              f"tau/sigma {d.rough / d.sigma:.3g}, sigma {d.sigma:.4g}")
    both = ("loading", "unloading")
    for region_label, rc in (("both branches", both), ("loading", "loading"), ("unloading", "unloading")):
        for cand_label, cc in (("loading only", "loading"), ("either branch", None)):
            prob = error_design_problem(r, CANDIDATES, region={"q_P": (0.0, 1600.0)}, region_size=21, repeats=repeats,
                                        candidate_conditions=cc, region_conditions=rc)
            before, floor = prob.value(()), prob.floor
            conds = np.array(prob.region_conditions, object)
            hb = prob.half_widths((), r.alpha)
            print(f"\nregion 0-1600 N on {region_label}, runs on {cand_label} ({prob.n_candidates} candidates): J before "
                  f"{before:.4f} sigma^2, irreducible {floor:.4f} ({100 * floor / before:.1f} %)")
            print(f"  {'n':>2} {'runs (N, branch)':<58} {'J':>8} {'of J':>6} {'reducible':>9} "
                  + " ".join(f"{s + ' ' + b[:2]:>10}" for b in dict.fromkeys(conds) for s in SENSORS) + "  (mean um)")
            print(f"  {0:>2} {'':<58} {before:>8.4f} {'':>6} {'':>9} " + " ".join(
                f"{UM * _mean_half(prob, hb, conds, b, j):>10.3f}" for b in dict.fromkeys(conds)
                for j in range(len(SENSORS))))
            for n in sizes:
                t1 = time.perf_counter()
                e = select_error_design(r, CANDIDATES, n, region={"q_P": (0.0, 1600.0)}, region_size=21,
                                        repeats=repeats, candidate_conditions=cc, region_conditions=rc)
                dt = time.perf_counter() - t1
                b = search(prob.core, n, "bnb", time_limit=120.0)
                runs = ", ".join(f"{x[0]:g} {c[:2]}" for x, c in zip(e.chosen_inputs, e.chosen_conditions))
                ha = prob.half_widths(e.chosen, r.alpha)
                print(f"  {n:>2} {runs:<58.58} {e.value_after:>8.4f} {100 * (before - e.value_after) / before:>5.1f}% "
                      f"{100 * (before - e.value_after) / (before - floor):>8.1f}% " + " ".join(
                          f"{UM * _mean_half(prob, ha, conds, bb, j):>10.3f}" for bb in dict.fromkeys(conds)
                          for j in range(len(SENSORS)))
                      + f"   [{e.method} {dt:.2f} s; bnb same set {b.indices == e.chosen}, |dJ| "
                        f"{abs(b.value - e.value_after):.1e}, {b.nodes} nodes{'' if b.proven else ', NOT proven'}]")


def _mean_half(prob, h: np.ndarray, conds: np.ndarray, branch: str, j: int) -> float:
    """The weighted mean half-width of sensor column j over the region's points on ``branch``."""
    m = conds == branch
    w = prob.region_weights[m]
    return float(w @ h[m, j] / w.sum())


def main(argv=None):
    ap = argparse.ArgumentParser(prog="bench error_design")
    ap.add_argument("--repeats", type=int, default=2, help="series per new run (the study measured 2)")
    ap.add_argument("--n-mc", type=int, default=20000, help="Monte Carlo replications")
    ap.add_argument("--seed", type=int, default=293)
    ap.add_argument("--quick", action="store_true", help="n <= 4 and 1000 replications")
    ap.add_argument("--skip", default="", help="comma list of parts to skip: designs,search,mc,conditions")
    args = ap.parse_args(argv or [])
    sizes = (1, 2, 4) if args.quick else (1, 2, 4, 6)
    n_mc = 1000 if args.quick else args.n_mc
    skip = set(filter(None, args.skip.split(",")))
    print(f"load {_load():.1f} at start")
    study = prepare(load_config(CONFIG))
    r = m1_error(study)
    if "designs" not in skip:
        designs(study, r, sizes, args.repeats)
    if "search" not in skip:
        search_agreement(r, sizes, args.repeats)
        beyond_enumeration(r, args.repeats, 8, 20.0 if args.quick else 60.0)
    if "mc" not in skip:
        region = np.linspace(0.0, 1600.0, 21)[:, None]
        e = select_error_design(r, CANDIDATES, 4, region=region, repeats=args.repeats)
        monte_carlo(study, r, e.chosen, region, args.repeats, n_mc, args.seed)
    if "conditions" not in skip:
        conditions(study, sizes, args.repeats)


if __name__ == "__main__":
    main()
