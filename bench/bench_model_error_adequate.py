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
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from identification import model_error
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


def run_study(name: str, n: int, seed: int) -> dict:
    """``n`` campaigns of the study ``name``; prints and returns the summary numbers."""
    study = prepare(load_config(CONFIGS / f"{name}.toml"))
    variant = study.cfg.simulate.variant or next(iter(study.models))
    results = design_sensors(study, StudyResults(study), Progress(False))
    used = set(results.design_sensors)
    w = np.array([1.0 if s in used else 0.0 for s in study.sensors])
    p = _truth(study, variant)
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


def main(argv=None):
    ap = argparse.ArgumentParser(prog="bench model_error_adequate")
    ap.add_argument("--n", type=int, default=200, help="campaigns per study")
    ap.add_argument("--studies", default=",".join(STUDIES), help=f"comma list of {', '.join(STUDIES)}")
    ap.add_argument("--seed", type=int, default=2912)
    ap.add_argument("--quick", action="store_true", help="--n=10")
    args = ap.parse_args(argv or [])
    names = [s for s in args.studies.split(",") if s]
    unknown = [s for s in names if s not in STUDIES]
    if unknown:
        ap.error(f"--studies: unknown study {unknown[0]!r}; choose from {', '.join(STUDIES)}")
    n = 10 if args.quick else args.n
    if n < 1:
        ap.error(f"--n: need at least one campaign, got {n}")
    for k, name in enumerate(names):
        run_study(name, n, args.seed + k)


if __name__ == "__main__":
    main(sys.argv[1:])
