"""Model error of the press (issue 29, first slice): held-out coverage, widening, size of the test, runtime.

Three measurements on the shipped press study (``configs/press.toml``: series 4 and 5, the paper's four
split scenarios, the sensors F_x and B0_y of the study's E-optimal design, sigma = sqrt(sigma_rep^2 +
sigma_man^2)):

1. **coverage**: for every variant M1/M2/M3 and every split, the validation readings predicted from a fit
   on the calibration part, by the plain 95 % new-reading delta-method bands (h +- 1.96 sqrt(g^T C g +
   sigma^2), the baseline of issue 29) and by :func:`identification.model_error`'s bands with the output
   discrepancy and with the embedded error; the median widening (ratio of band widths) per variant; the
   runtime of ``model_error`` (kind auto, with the held-out table); once more with the discrepancy pinned to
   zero with zero slope at zero press force (``exact_at={"q_P": 0}``).
2. **size** of the 'no model error' test (alpha 5 %): ``--n`` campaigns simulated from an adequate model
   (the variant ``--size-variant`` at its fit on the shipped data, z = h(p_hat) + sigma eps, 2 series x 29
   inputs), the rejection rate with its binomial (Clopper-Pearson 95 %) interval.
3. **adequate-model coverage** (``--n-coverage`` campaigns of the same kind): the held-out coverage and the
   widening of the model-error bands when there is no model error.

4. **oscillator** (issue 29's dynamic target, ``mudoe/example_oscillator.py`` with the design of
   ``configs/oscillator.toml``: steps F = 2, 4, 6, 8 N, x (sigma 0.02 mm) and a (sigma 0.05 m/s^2) every 40 ms
   over 1 s, 2 series): ``--oscillator-n`` campaigns simulated from the cubic spring at its true parameters,
   the rate at which the cubic model's error is *not* found (alpha 5 %) with its Clopper-Pearson interval; and
   ``--oscillator-n-coverage`` campaigns on which the linear spring (the wrong model) is given to
   ``model_error`` with the time-window splits t < e vs t >= e (e = :data:`OSC_EDGES`): the held-out
   coverage of the 95 % new-reading bands with the chosen model error (kind auto) and without, pooled over
   campaigns and splits, with the standard error over campaigns.

Run ``python -m bench model_error --n=1000 --n-coverage=50`` (``--quick``: 100 and 10); the oscillator alone:
``python -m bench model_error --skip=coverage,size,adequate --oscillator-n=1000 --oscillator-n-coverage=20``.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from identification import model_error
from identification.fit.dynamic_fit import simulate_campaign
from identification.studies.splits import time_window_splits
from identification.studies.montecarlo import clopper_pearson
from mudoe.config import load_config
from mudoe.study import prepare
from models.state import simulate

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "press.toml"
#: the sensors of the study's E-optimal design ([oed] n_sensors = 2): F_x and B0_y
WEIGHTS = np.array([0.0, 1.0, 1.0])


def coverage_table(study, exact_at=None) -> dict:
    """{variant: ModelErrorResult (kind auto)} on the study's data and splits; prints the held-out table: coverage
    of the plain, discrepancy and embedded 95 % new-reading bands (%) and their median widening."""
    out = {}
    print(f"exact_at = {exact_at}")
    print(f"{'variant':<8} {'split':<32} {'n':>4} {'plain':>6} {'discr.':>6} {'widen':>6} {'embed.':>6} {'widen':>6}")
    for v, m in study.models.items():
        t0 = time.perf_counter()
        r = model_error(m, study.data[v], study.p0, splits=study.splits, weights=WEIGHTS, exact_at=exact_at)
        dt = time.perf_counter() - t0
        for h in r.heldout:
            print(f"{v:<8} {h.split:<32} {h.n_values:>4} {100 * h.coverage_plain:>6.1f} "
                  f"{100 * h.coverage_discrepancy:>6.1f} {h.widening_discrepancy:>6.2f} "
                  f"{100 * h.coverage_embedded:>6.1f} {h.widening_embedded:>6.2f}")
        n = sum(h.n_values for h in r.heldout)
        pooled = {k: sum(h.coverage(k) * h.n_values for h in r.heldout) / n for k in ("none", "discrepancy", "embedded")}
        print(f"{v:<8} {'pooled / median widening':<32} {n:>4} {100 * pooled['none']:>6.1f} "
              f"{100 * pooled['discrepancy']:>6.1f} {np.median([h.widening_discrepancy for h in r.heldout]):>6.2f} "
              f"{100 * pooled['embedded']:>6.1f} {np.median([h.widening_embedded for h in r.heldout]):>6.2f}")
        print(f"         model_error {dt:.2f} s; test LR {r.test.statistic:.4g}, p = {r.test.p_value:.3g}; "
              f"{r.how} -> {r.kind}; identifiable {r.identifiable} (information kept {r.information_kept:.3f})")
        for block in r.summary().split("\n\n")[1:3]:          # the parameters, the discrepancy / embedded error
            print("         " + block.replace("\n", "\n         "))
        out[v] = r
    return out


def _campaigns(study, variant: str, n: int, seed: int):
    """Campaigns simulated from ``variant`` at its plain fit on the shipped data (2 series, sigma given)."""
    m, d = study.models[variant], study.data[variant]
    fit = model_error(m, d, study.p0, kind="none", weights=WEIGHTS)
    h = simulate(m, fit.p_plain, d.inputs)
    rng = np.random.default_rng(seed)
    for _ in range(n):
        yield m, d.with_z(h[None] + d.sigma * rng.standard_normal(d.z.shape)), fit.p_plain


def size_study(study, variant: str, n: int, seed: int) -> None:
    """The rejection rate of the 'no model error' test at alpha 5 % on campaigns of an adequate model."""
    t0 = time.perf_counter()
    rej, pv = 0, []
    for i, (m, d, p) in enumerate(_campaigns(study, variant, n, seed)):
        r = model_error(m, d, p, kind="none", weights=WEIGHTS)
        rej += r.detected
        pv.append(r.test.p_value)
        if (i + 1) % 100 == 0:
            print(f"  {i + 1} campaigns, {rej} rejections", file=sys.stderr, flush=True)
    rate = clopper_pearson(rej, n)
    pv = np.array(pv)
    print(f"size ({variant} adequate, {n} campaigns, seed {seed}): {100 * rej / n:.2f} % "
          f"[95 % CI {100 * rate.lo:.2f}, {100 * rate.hi:.2f}] at alpha 5 %; P(LR = 0) = {np.mean(pv == 1):.3f}; "
          f"rate at 1 % {100 * np.mean(pv < 0.01):.2f} %, at 10 % {100 * np.mean(pv < 0.1):.2f} %; "
          f"{time.perf_counter() - t0:.0f} s")


def adequate_coverage(study, variant: str, n: int, seed: int) -> None:
    """Held-out coverage and widening of the model-error bands on campaigns without model error."""
    rows, kinds = [], {}
    for m, d, p in _campaigns(study, variant, n, seed):
        r = model_error(m, d, p, splits=study.splits, weights=WEIGHTS)
        rows += [(h.coverage_plain, h.coverage_discrepancy, h.coverage_embedded, h.widening_discrepancy,
                  h.widening_embedded) for h in r.heldout]
        kinds[r.kind] = kinds.get(r.kind, 0) + 1
    a = np.array(rows)
    se = a[:, :3].std(axis=0) / np.sqrt(len(a))
    print(f"adequate {variant}, {n} campaigns x {len(study.splits)} splits: held-out coverage plain "
          f"{100 * a[:, 0].mean():.1f} (+- {100 * se[0]:.1f}) %, discrepancy {100 * a[:, 1].mean():.1f} "
          f"(+- {100 * se[1]:.1f}) %, embedded {100 * a[:, 2].mean():.1f} (+- {100 * se[2]:.1f}) %; median widening "
          f"discrepancy {np.median(a[:, 3]):.2f}, embedded {np.median(a[:, 4]):.2f}; kind auto chose {kinds}")


#: the time-window edges of the oscillator's held-out splits (s): t < e calibrates, t >= e validates
OSC_EDGES = (0.36, 0.52, 0.68)
OSC_TIMES = np.round(np.arange(1, 26) * 0.04, 10)       # s, as configs/oscillator.toml
OSC_STEPS = np.array([[2.0], [4.0], [6.0], [8.0]])      # N
OSC_SIGMA = np.array([0.02, 0.05])                      # mm, m/s^2


def _oscillator_campaign(rng):
    from mudoe.example_oscillator import P_TRUE, build
    return simulate_campaign(build("cubic"), P_TRUE, OSC_STEPS, OSC_TIMES, OSC_SIGMA, n_series=2,
                             seed=int(rng.integers(2 ** 32)))


def oscillator_adequate(n: int, seed: int) -> None:
    """The rate at which model_error finds no error of the cubic spring on its own campaigns (alpha 5 %)."""
    from mudoe.example_oscillator import P_TRUE, build
    model, rng, t0 = build("cubic"), np.random.default_rng(seed), time.perf_counter()
    found = 0
    for i in range(n):
        found += model_error(model, _oscillator_campaign(rng), P_TRUE, kind="none").detected
        if (i + 1) % 100 == 0:
            print(f"  {i + 1} campaigns, {found} with model error found", file=sys.stderr, flush=True)
    ci = clopper_pearson(n - found, n)
    print(f"oscillator cubic (adequate), {n} campaigns, seed {seed}: no model error found in {100 * (n - found) / n:.2f} % "
          f"[Clopper-Pearson 95 % {100 * ci.lo:.2f}, {100 * ci.hi:.2f}] (target >= 95 %); {time.perf_counter() - t0:.0f} s")


def oscillator_wrong(n: int, seed: int) -> None:
    """Held-out coverage of the linear spring's 95 % new-reading bands on cubic-spring campaigns, time windows."""
    from mudoe.example_oscillator import build
    model, rng, t0 = build("linear"), np.random.default_rng(seed), time.perf_counter()
    splits = time_window_splits(OSC_EDGES)
    rows, kinds = [], {}
    for i in range(n):
        r = model_error(model, _oscillator_campaign(rng), [350.0, 3.0], splits=splits)
        kinds[r.kind] = kinds.get(r.kind, 0) + 1
        rows.append([[h.coverage(r.kind), h.coverage_plain, h.coverage_discrepancy, h.coverage_embedded,
                      h.widening(r.kind), h.n_values] for h in r.heldout])
        print(f"  campaign {i + 1}: " + ", ".join(f"{h.split}: {100 * h.coverage(r.kind):.1f} %" for h in r.heldout)
              + f" ({r.kind}, {time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)
    a = np.array(rows)                                     # (campaign, split, 6)
    w = a[:, :, 5]
    per = (a[:, :, :4] * w[:, :, None]).sum(axis=1) / w.sum(axis=1)[:, None]   # pooled per campaign
    se = per.std(axis=0, ddof=1) / np.sqrt(n) if n > 1 else np.full(4, np.nan)
    print(f"oscillator linear on cubic data, {n} campaigns x {len(splits)} time-window splits (edges {OSC_EDGES} s), "
          f"seed {seed}: held-out coverage of the 95 % new-reading bands with the chosen model error "
          f"{100 * per[:, 0].mean():.1f} (+- {100 * se[0]:.1f}) % (target [90, 99]); plain {100 * per[:, 1].mean():.1f} "
          f"(+- {100 * se[1]:.1f}) %, discrepancy {100 * per[:, 2].mean():.1f} (+- {100 * se[2]:.1f}) %, embedded "
          f"{100 * per[:, 3].mean():.1f} (+- {100 * se[3]:.1f}) %; per split (chosen) "
          + ", ".join(f"{sp.name}: {100 * np.average(a[:, j, 0], weights=w[:, j]):.1f} %" for j, sp in enumerate(splits))
          + f"; median widening {np.median(a[:, :, 4]):.1f}; kind auto chose {kinds}; {time.perf_counter() - t0:.0f} s")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="bench model_error")
    ap.add_argument("--n", type=int, default=1000, help="campaigns of the size study")
    ap.add_argument("--n-coverage", type=int, default=50, help="campaigns of the adequate-model coverage")
    ap.add_argument("--size-variant", default="M1")
    ap.add_argument("--seed", type=int, default=29)
    ap.add_argument("--quick", action="store_true", help="--n=100 --n-coverage=10")
    ap.add_argument("--oscillator-n", type=int, default=0, help="campaigns of the cubic oscillator (adequate)")
    ap.add_argument("--oscillator-n-coverage", type=int, default=0,
                    help="campaigns of the linear oscillator on cubic data (held-out coverage)")
    ap.add_argument("--skip", default="", help="comma list of parts to skip: coverage,size,adequate")
    args = ap.parse_args(argv or [])
    if args.quick:
        args.n, args.n_coverage = 100, 10
    skip = set(filter(None, args.skip.split(",")))
    study = prepare(load_config(CONFIG)) if not {"coverage", "size", "adequate"} <= skip else None
    if "coverage" not in skip:
        coverage_table(study)
        coverage_table(study, {"q_P": 0.0})          # the linkage is exact at zero press force
    if "size" not in skip and args.n:
        size_study(study, args.size_variant, args.n, args.seed)
    if "adequate" not in skip and args.n_coverage:
        adequate_coverage(study, args.size_variant, args.n_coverage, args.seed + 1)
    if args.oscillator_n:
        oscillator_adequate(args.oscillator_n, args.seed + 2)
    if args.oscillator_n_coverage:
        oscillator_wrong(args.oscillator_n_coverage, args.seed + 3)


if __name__ == "__main__":
    main(sys.argv[1:])
