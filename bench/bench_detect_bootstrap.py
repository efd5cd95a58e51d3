"""Monte Carlo: are the bootstrap p-values of the split tests uniform under the null? (issue 12 item 6)

Model (cheap, nonlinear): Michaelis-Menten y = Vm x / (K + x), Vm = 1, K = 5, observed at 8 inputs
x = 0.5 .. 8 (around K), 2 series, sigma = 0.01 known.  Splits: "low/high" (inputs 0-3 vs 4-7) and
"odd/even" (alternate inputs).  Each of ``--n-rep`` campaigns is simulated from the model at the truth
(the null hypothesis holds) and given to :func:`identification.studies.detect_bootstrap.bootstrap_detect`
with ``--n-boot`` B bootstrap campaigns.

Reported per statistic (likelihood ratio, two-sample Wald, paper) and for the family-wise min-p:
the rejection rate at 5 % and 10 % of the asymptotic p-values and of the bootstrap p-values
(Clopper-Pearson 95 % intervals; with B = 39 the levels 5 % = 2/40 and 10 % = 4/40 are attainable
exactly, so a calibrated bootstrap rejects at those rates), and the KS p-value against U(0, 1) of
the randomised bootstrap p-value p - U/(B + 1) (U ~ U(0, 1)), which is continuous uniform when the
bootstrap is exact.  Campaigns whose observed test failed are counted apart.

Run ``python -m bench.bench_detect_bootstrap --n-rep 200 --n-boot 39 --workers 2``.

``--compare`` instead measures the CPU per bootstrap campaign of one-fit-at-a-time
(``bootstrap_detect(fits=ONE_BY_ONE)``: one run_split_tests, i.e. identify per fit, per campaign) against
the batch engine (``fits=BATCHED``: the campaigns of a chunk fitted together), in this process and in
the same run, on two cases: the Michaelis-Menten campaign above (2 splits) and the press model M1 of
the paper on a campaign simulated at its nominal stiffnesses (29 loads, 2 series, sensors D_y and
F_x, the paper's four scenarios).  Each case runs once untimed with another seed (compilation, caches,
the batch engine's functions mapped once per batch size), then
``fits=ONE_BY_ONE`` and ``fits=BATCHED`` with ``--n-boot`` campaigns each and the same seed; the CPU
(user + system, ``resource.getrusage``) of the whole call divided by B is reported (the observed
split tests and the null fit, one campaign's worth, are included in both), with the largest
relative difference of the bootstrap statistics T* and whether p-values and failures agree.  Both
paths run twice: with the CasADi virtual machine and with the models JIT-compiled to C
(``bootstrap_detect(..., jit=True)``, the default, what Monte Carlo workers use).
Run ``python -m bench.bench_detect_bootstrap --compare --n-boot 200``.
"""
from __future__ import annotations

import argparse
import os
import platform
import resource
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

from identification import Measurements  # noqa: E402
from identification.studies.detect import STATISTICS  # noqa: E402
from identification.studies.detect_bootstrap import bootstrap_detect  # noqa: E402
from identification.studies.split_fits import BATCHED, ONE_BY_ONE  # noqa: E402
from identification.studies.montecarlo import clopper_pearson  # noqa: E402
from identification.studies.splits import Split  # noqa: E402
from models import Model  # noqa: E402
from models.state import set_jit  # noqa: E402

P_TRUE = np.array([1.0, 5.0])
X = np.linspace(0.5, 8.0, 8)
SIGMA = 0.01
SPLITS = (Split("low/high", range(0, 4), range(4, 8)), Split("odd/even", range(0, 8, 2), range(1, 8, 2)))


def mm_model() -> Model:
    return Model.explicit(params=["Vm", "K"], inputs=["x"], sensors=["y"], h=lambda p, q: p[0] * q[0] / (p[1] + q[0]),
                          name="Michaelis-Menten")


def one_campaign(args: tuple) -> tuple:
    """(r, asymptotic (n_splits + 1, 3), bootstrap (n_splits + 1, 3), bootstrap failures) of campaign r;
    the last row is the family-wise min-p."""
    r, seed, n_boot = args
    model = mm_model()
    rng = np.random.default_rng(seed)
    h = P_TRUE[0] * X / (P_TRUE[1] + X)
    z = h[None, :, None] + SIGMA * rng.standard_normal((2, X.size, 1))
    data = Measurements(X, z, [SIGMA])
    res = bootstrap_detect(model, data, SPLITS, P_TRUE, n_rep=n_boot, seed=int(seed.generate_state(1)[0]))
    a = np.vstack([res.asymptotic, res.family_asymptotic])
    p = np.vstack([res.pvalue, res.family_pvalue])
    return r, a, p, len(res.errors)


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def compare_cases(seed: int) -> list:
    """[(label, model, data, splits, p0, weights), ...] of the ``--compare`` study."""
    from bench.bench_detect import P0, PAPER_SPLITS, SIGMA_PAPER_MM, WEIGHTS_110
    from identification.studies.montecarlo import ModelCampaign
    from models.press import Q_PAPER, press_model
    rng = np.random.default_rng(seed)
    h = P_TRUE[0] * X / (P_TRUE[1] + X)
    mm = Measurements(X, h[None, :, None] + SIGMA * rng.standard_normal((2, X.size, 1)), [SIGMA])
    press = press_model()
    gen = ModelCampaign(press, press.p_nominal, np.array(Q_PAPER)[:, None], SIGMA_PAPER_MM, 2)
    return [("Michaelis-Menten, 2 splits (8 inputs, 2 series)", mm_model(), mm, SPLITS, P_TRUE, None),
            ("press M1, the paper's 4 scenarios (29 loads, 2 series, D_y + F_x)", press, gen(rng), PAPER_SPLITS,
             P0, WEIGHTS_110)]


def compare(n_boot: int, seed: int) -> None:
    """Print the CPU per bootstrap campaign of ONE_BY_ONE vs BATCHED (markdown table)."""
    print(f"CPU per bootstrap campaign, one identify per fit (ONE_BY_ONE) vs the batch engine (BATCHED), "
          f"B = {n_boot}, seed {seed}, serial in one process; {platform.node()}, {os.cpu_count()} CPUs, "
          f"load average {os.getloadavg()[0]:.1f}, {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    print()
    print("| case | JIT | per fit: CPU / campaign | batched: CPU / campaign | speed-up | max rel. diff of T* | "
          "p-values identical | failed fits (per fit / batched) |")
    print("|---|---|---|---|---|---|---|---|")
    for jit in (False, True):
        prev = set_jit(jit)
        try:
            for label, model, data, splits, p0, w in compare_cases(seed):
                # warm-up (compilation, caches; the batch engine maps its functions once per batch size)
                bootstrap_detect(model, data, splits, p0, w, n_rep=4, seed=seed + 1, fits=ONE_BY_ONE, jit=jit)
                bootstrap_detect(model, data, splits, p0, w, n_rep=n_boot, seed=seed + 1, jit=jit)
                res, cpu = {}, {}
                for batch in (False, True):
                    c0 = _cpu()
                    res[batch] = bootstrap_detect(model, data, splits, p0, w, n_rep=n_boot, seed=seed,
                                                  fits=BATCHED if batch else ONE_BY_ONE, jit=jit)
                    cpu[batch] = (_cpu() - c0) / n_boot
                a, b = res[False].boot_statistics, res[True].boot_statistics
                both = np.isfinite(a) & np.isfinite(b)
                rel = float(np.max(np.abs(b[both] - a[both]) / np.abs(a[both]))) if both.any() else float("nan")
                same_p = (np.array_equal(res[False].pvalue, res[True].pvalue, equal_nan=True)
                          and np.array_equal(res[False].family_pvalue, res[True].family_pvalue, equal_nan=True)
                          and np.array_equal(np.isnan(a), np.isnan(b)))
                print(f"| {label} | {'on' if jit else 'off'} | {1e3 * cpu[False]:.1f} ms | {1e3 * cpu[True]:.1f} ms | "
                      f"{cpu[False] / cpu[True]:.1f}x | {rel:.1e} | {'yes' if same_p else 'no'} | "
                      f"{len(res[False].errors)} / {len(res[True].errors)} |", flush=True)
        finally:
            set_jit(prev)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n-rep", type=int, default=200)
    ap.add_argument("--n-boot", type=int, default=39)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=20261123)
    ap.add_argument("--compare", action="store_true",
                    help="CPU per bootstrap campaign of fits=ONE_BY_ONE vs BATCHED (Michaelis-Menten, press M1)")
    args = ap.parse_args(argv)
    if args.compare:
        compare(args.n_boot, args.seed)
        return
    seeds = np.random.SeedSequence(args.seed).spawn(args.n_rep)
    jobs = [(r, s, args.n_boot) for r, s in enumerate(seeds)]
    t0 = time.perf_counter()
    if args.workers > 1:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor
        with ProcessPoolExecutor(args.workers, mp_context=mp.get_context("spawn")) as pool:
            out = list(pool.map(one_campaign, jobs, chunksize=4))
    else:
        out = [one_campaign(j) for j in jobs]
    wall = time.perf_counter() - t0
    A = np.stack([o[1] for o in out])          # (R, n_splits + 1, 3)
    P = np.stack([o[2] for o in out])
    n_fail = sum(o[3] for o in out)
    B = args.n_boot
    U = np.random.default_rng(args.seed + 1).uniform(size=P.shape)
    P_rand = P - U / (B + 1)
    rows = [sp.name for sp in SPLITS] + ["family (min-p)"]
    print(f"Bootstrap p-values under the null: Michaelis-Menten (Vm = 1, K = 5, 8 inputs 0.5..8, 2 series, "
          f"sigma {SIGMA} known), {args.n_rep} campaigns x B = {B} bootstrap campaigns, seed {args.seed}; "
          f"{args.workers} workers, {wall:.0f} s wall; {platform.node()}, {os.cpu_count()} CPUs, "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    print(f"failed fits inside the bootstrap campaigns (excluded from their p-values): {n_fail} of "
          f"{args.n_rep * B * len(SPLITS)} split tests")
    print()
    print("| split | statistic | asymptotic: reject at 5 % | asymptotic: at 10 % | bootstrap: at 5 % | "
          "bootstrap: at 10 % | KS p (randomised bootstrap p vs U(0,1)) |")
    print("|---|---|---|---|---|---|---|")
    for s, name in enumerate(rows):
        for k, st in enumerate(STATISTICS):
            a, p, pr = A[:, s, k], P[:, s, k], P_rand[:, s, k]
            ok_a, ok_p = np.isfinite(a), np.isfinite(p)
            cells = [clopper_pearson(int(np.sum(a[ok_a] < lev)), int(ok_a.sum())) for lev in (0.05, 0.10)]
            cells += [clopper_pearson(int(np.sum(p[ok_p] <= lev + 1e-12)), int(ok_p.sum())) for lev in (0.05, 0.10)]
            ks = stats.kstest(pr[ok_p], "uniform").pvalue if ok_p.any() else float("nan")
            print(f"| {name} | {st} | " + " | ".join(str(c) for c in cells) + f" | {ks:.3g} |")


if __name__ == "__main__":
    main()
