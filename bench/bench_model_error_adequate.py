"""Model error of adequate models (issue 29, item 5): how often it is found, how much it widens the bands.

On campaigns simulated from an adequate model -- the shipped study's own model at its ``[simulate] truth``
(completed with the [[parameters]] starts, as ``mudoe simulate`` does), with the study's inputs (experiments and
sampling times), series and sigma, z = h(p_true) + sigma e, e ~ N(0, 1) -- every campaign gets what ``mudoe
quantify`` computes for the variant (:func:`mudoe.model_error_runs.run_model_error`'s call of
:func:`identification.model_error`: kind auto, the study's splits, the sensors of its tests, alpha 5 %):

- **found**: the rate of campaigns where the 'no model error' test detects an error (target <= 5 %), and the
  rate where an error model is then also chosen for the bands (kind auto not "none"), each with its
  Clopper-Pearson 95 % interval;
- **widening**: per campaign, the median over its held-out readings of the ratio of the widths of the chosen
  95 % new-reading band and of the plain one (1 when no error model is chosen; the median over the splits'
  medians, weighted by their readings); reported: its median over campaigns (target <= 1.05), its mean, the
  fraction of campaigns above 1.05, and the median over the campaigns where an error model was chosen;
- on the campaigns where the error is found, the pooled held-out coverage of the plain and of the chosen 95 %
  bands (mean over those campaigns +- its standard error).

Only the test runs on every campaign; the held-out table (three error models fitted on every split) only on the
campaigns where the test finds an error (:func:`_one`), which makes a campaign about ten times cheaper.

Studies: ``cstr`` (configs/cstr.toml, static: 13 temperatures x 4 series, the 3 sensors of its D-optimal design,
3 random splits and "cool vs hot") and ``reactor`` (configs/reactor.toml, dynamic: 6 experiments x 10 sampling
times x 2 series, cA and cB, splits early/late, t < 0.7 h and "cool vs hot").

Run ``python -m bench model_error_adequate --n=200`` (``--studies=cstr`` for one; ``--quick``: 10 each).

``--test-only``: the size of the 'no model error' test alone (the plain fit and the test on every campaign, no
held-out table): the rate p < alpha under the shipped reference (the 50:50 mixture of chi2_0 and chi2_1) with its
Clopper-Pearson interval, P(LR = 0) and the LR quantiles against that mixture's (1/2; 0.5 P(chi2_1 > q)) and against
the exact null distribution of the REML LR for the study's layout (:func:`identification.studies.discrepancy_gp.
white_lr_null`, the model linearised at the truth, ``--n-ref`` draws), and the rate under that exact reference.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from scipy import stats

from identification import model_error
from identification.fit.problem import Problem
from identification.studies.discrepancy_gp import Observations, white_lr_null
from identification.studies.model_error_fit import outputs_at
from identification.studies.montecarlo import clopper_pearson
from mudoe.config import load_config
from mudoe.study import Progress, StudyResults, design_sensors, prepare, start_values

CONFIGS = Path(__file__).resolve().parent.parent / "configs"
STUDIES = ("cstr", "reactor")


def _truth(study, variant: str) -> np.ndarray:
    """The [simulate] truth of the study's config completed with the variant's start values (model units)."""
    m = study.models[variant]
    truth = dict(zip(m.param_names, (float(v) for v in start_values(study, variant))))
    truth.update({k: float(v) for k, v in study.cfg.simulate.truth.items()})
    return np.array([truth[n] for n in m.param_names], float)


def _simulator(study, variant: str, p: np.ndarray):
    """A function rng -> campaign of the study's layout simulated from ``variant`` at ``p``."""
    m, d = study.models[variant], study.data[variant]
    if hasattr(d, "union_times"):                          # a time-series study
        from identification.fit.dynamic_fit import simulate_campaign
        times = d.union_times

        def campaign(rng):
            sim = simulate_campaign(m, p, d.inputs, times, d.sigma, n_series=d.n_M, seed=int(rng.integers(2 ** 32)))
            return d.with_z(sim.z)
        return campaign
    from models.state import simulate
    h = simulate(m, p, d.inputs)
    return lambda rng: d.with_z(h[None] + np.asarray(d.sigma) * rng.standard_normal(d.z.shape))


def _one(study, variant: str, data, w) -> dict:
    """What one campaign gives: detected, the chosen kind, the widening and the pooled coverages.

    The test first (kind "none", no splits: the plain fit on all data, the same test as kind auto's); kind auto
    with the held-out table only when it detects an error (otherwise kind auto reports "none": widening 1 and
    the plain bands, by construction), so the held-out coverages are those of the detected campaigns.
    """
    m, p0 = study.models[variant], start_values(study, variant)
    test = model_error(m, data, p0, kind="none", weights=w)
    if not test.detected:
        return dict(detected=False, kind="none", p_value=float(test.test.p_value), widening=1.0, plain=np.nan,
                    chosen=np.nan)
    r = model_error(m, data, p0, splits=study.splits, weights=w)
    n = np.array([h.n_values for h in r.heldout], float)
    widen = np.array([h.widening(r.kind) for h in r.heldout])
    order = np.argsort(widen)
    cum = np.cumsum(n[order])
    median = float(widen[order][np.searchsorted(cum, 0.5 * cum[-1])])     # weighted median over the splits
    return dict(detected=bool(r.detected), kind=r.kind, p_value=float(r.test.p_value), widening=median,
                plain=float(np.sum(n * [h.coverage_plain for h in r.heldout]) / n.sum()),
                chosen=float(np.sum(n * [h.coverage(r.kind) for h in r.heldout]) / n.sum()))


def _setup(name: str):
    """The study ``name``, its simulated variant, its sensor design, the sensor weights and the truth."""
    study = prepare(load_config(CONFIGS / f"{name}.toml"))
    variant = study.cfg.simulate.variant or next(iter(study.models))
    results = design_sensors(study, StudyResults(study), Progress(False))
    used = set(results.design_sensors)
    w = np.array([1.0 if s in used else 0.0 for s in study.sensors])
    return study, variant, results, w, _truth(study, variant)


def run_study(name: str, n: int, seed: int) -> dict:
    """``n`` campaigns of the study ``name``; prints and returns the summary numbers."""
    study, variant, results, w, p = _setup(name)
    campaign, rng, t0 = _simulator(study, variant, p), np.random.default_rng(seed), time.perf_counter()
    rows = []
    for i in range(n):
        rows.append(_one(study, variant, campaign(rng), w))
        if (i + 1) % 20 == 0:
            print(f"  {name}: {i + 1} campaigns, {sum(r['detected'] for r in rows)} detected, "
                  f"{time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    return _summary(name, variant, results, rows, seed, time.perf_counter() - t0)


def _summary(name, variant, results, rows, seed, seconds) -> dict:
    n = len(rows)
    found = sum(r["detected"] for r in rows)
    chosen = sum(r["kind"] != "none" for r in rows)
    ci_f, ci_c = clopper_pearson(found, n), clopper_pearson(chosen, n)
    widen = np.array([r["widening"] for r in rows])
    with_model = widen[[r["kind"] != "none" for r in rows]]
    cov = np.array([[r["plain"], r["chosen"]] for r in rows if r["detected"]]).reshape(-1, 2)
    se = cov.std(axis=0, ddof=1) / np.sqrt(len(cov)) if len(cov) > 1 else np.full(2, np.nan)
    kinds = {k: sum(r["kind"] == k for r in rows) for k in ("none", "discrepancy", "embedded")}
    print(f"{name} ({variant} adequate, sensors {', '.join(results.design_sensors)}; {n} campaigns, seed {seed}, "
          f"{seconds:.0f} s):\n"
          f"  error found (test, alpha 5 %): {found}/{n} = {100 * found / n:.2f} % [Clopper-Pearson 95 % "
          f"{100 * ci_f.lo:.2f}, {100 * ci_f.hi:.2f}] (target <= 5 %)\n"
          f"  error model chosen for the bands (kind auto): {chosen}/{n} = {100 * chosen / n:.2f} % "
          f"[{100 * ci_c.lo:.2f}, {100 * ci_c.hi:.2f}]; kinds {kinds}\n"
          f"  widening of the 95 % new-reading band: median {np.median(widen):.4f} (target <= 1.05), mean "
          f"{widen.mean():.4f}, above 1.05 in {100 * np.mean(widen > 1.05):.2f} % of campaigns; median where an error "
          f"model was chosen {np.median(with_model) if with_model.size else float('nan'):.3f} ({with_model.size})\n"
          f"  held-out coverage of the 95 % bands on the {len(cov)} campaigns where the error was found: plain "
          f"{100 * np.mean(cov[:, 0]) if len(cov) else np.nan:.2f} (+- {100 * se[0]:.2f}) %, chosen "
          f"{100 * np.mean(cov[:, 1]) if len(cov) else np.nan:.2f} (+- {100 * se[1]:.2f}) %", flush=True)
    return dict(n=n, found=found, chosen=chosen, median_widening=float(np.median(widen)))


def exact_reference(study, variant: str, data, w: np.ndarray, p: np.ndarray, n_draws: int, seed: int) -> np.ndarray:
    """Draws of the exact null distribution of the test's LR for the study's layout, the model linear at ``p``."""
    problem = Problem(study.models[variant], data)
    layout = problem.columns()
    model, flat = problem.static(p)
    cw = layout.column_weights(np.asarray(w, float))
    G = outputs_at(model, p, flat.inputs)[1]
    obs = Observations.of(flat.counts(), np.broadcast_to(np.asarray(flat.sigma, float), (flat.n_S,)), cw,
                          np.zeros((flat.n_q, 1)))
    return white_lr_null(obs, obs.stack(G), n_draws, seed)


def run_size(name: str, n: int, seed: int, n_ref: int, alpha: float = 0.05) -> dict:
    """The size of the 'no model error' test alone on ``n`` campaigns, against the mixture and the exact reference."""
    study, variant, results, w, p = _setup(name)
    campaign, rng = _simulator(study, variant, p), np.random.default_rng(seed)
    m, p0 = study.models[variant], start_values(study, variant)
    ref = exact_reference(study, variant, study.data[variant], w, p, n_ref, seed + 1)
    t0, c0 = time.perf_counter(), time.process_time()
    lr, pv = np.empty(n), np.empty(n)
    for i in range(n):
        t = model_error(m, campaign(rng), p0, kind="none", weights=w).test
        lr[i], pv[i] = t.statistic, t.p_value
        if (i + 1) % 100 == 0:
            print(f"  {name}: {i + 1} campaigns, {int(np.sum(pv[:i + 1] < alpha))} detected, "
                  f"{time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    k = int(np.sum(pv < alpha))
    ref_sorted = np.sort(ref)
    p_exact = 1.0 - np.searchsorted(ref_sorted, lr, side="left") / len(ref)      # P_ref(LR_ref >= lr)
    p_exact = np.where(lr > 0, p_exact, 1.0)
    k_ex = int(np.sum(p_exact < alpha))
    ci, ci_ex = clopper_pearson(k, n), clopper_pearson(k_ex, n)
    p0_obs = float(np.mean(lr == 0))
    se0 = math.sqrt(p0_obs * (1 - p0_obs) / n)
    print(f"{name} ({variant} adequate, sensors {', '.join(results.design_sensors)}; test only; {n} campaigns, seed "
          f"{seed}; wall {wall:.0f} s, CPU {cpu:.0f} s = {cpu / n:.3f} s per campaign):\n"
          f"  size, mixture reference (shipped): {k}/{n} = {100 * k / n:.2f} % [Clopper-Pearson 95 % {100 * ci.lo:.2f}, "
          f"{100 * ci.hi:.2f}]\n"
          f"  size, exact reference ({n_ref} draws): {k_ex}/{n} = {100 * k_ex / n:.2f} % [{100 * ci_ex.lo:.2f}, "
          f"{100 * ci_ex.hi:.2f}]; the exact reference's own size under the mixture's critical value "
          f"{100 * np.mean(ref > stats.chi2.isf(2 * alpha, 1)):.2f} %\n"
          f"  P(LR = 0): campaigns {p0_obs:.4f} +- {se0:.4f}, mixture 0.5, exact {np.mean(ref == 0):.4f}")
    print(f"  {'quantile':>8} {'campaigns':>10} {'mixture':>8} {'exact':>8}")
    for q in (0.5, 0.75, 0.9, 0.95, 0.99):
        mix = stats.chi2.isf(2 * (1 - q), 1) if q > 0.5 else 0.0
        print(f"  {q:>8.2f} {np.quantile(lr, q):>10.4f} {mix:>8.4f} {np.quantile(ref, q):>8.4f}", flush=True)
    return dict(n=n, found=k, found_exact=k_ex, p_lr0=p0_obs)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="bench model_error_adequate")
    ap.add_argument("--n", type=int, default=200, help="campaigns per study")
    ap.add_argument("--studies", default=",".join(STUDIES), help=f"comma list of {', '.join(STUDIES)}")
    ap.add_argument("--seed", type=int, default=2912)
    ap.add_argument("--quick", action="store_true", help="--n=10")
    ap.add_argument("--test-only", action="store_true", help="the size of the test alone, against the exact reference")
    ap.add_argument("--n-ref", type=int, default=200000, help="draws of the exact reference (--test-only)")
    args = ap.parse_args(argv or [])
    names = [s for s in args.studies.split(",") if s]
    unknown = [s for s in names if s not in STUDIES]
    if unknown:
        ap.error(f"--studies: unknown study {unknown[0]!r}; choose from {', '.join(STUDIES)}")
    n = 10 if args.quick else args.n
    if n < 1:
        ap.error(f"--n: need at least one campaign, got {n}")
    for k, name in enumerate(names):
        if args.test_only:
            run_size(name, n, args.seed + k, args.n_ref)
        else:
            run_study(name, n, args.seed + k)


if __name__ == "__main__":
    main(sys.argv[1:])
