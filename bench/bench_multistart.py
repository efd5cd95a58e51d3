"""Benchmark (issue 30 item 2): the cost of a multi-start fit, ``identify(..., starts=10)``, against one fit.

* ``press``: the press M1 (frictionless, parameters k5, k7 in [1e-6, 1e6] N/mm: log-uniform starts over 12
  decades) on the shipped campaign's training series (``models.prototype.TRAIN_SERIES``), sensors D_y and F_x,
  start K_NOMINAL, as :func:`mudoe.press.fit_candidates` fits it.
* ``reactor``: the batch reactor of :mod:`mudoe.example_reactor` (k_ref in [1e-6, 100] log-uniform, E in
  [0, 300] uniform), 6 experiments x 10 samples simulated with seed 0, start (1.5, 50, 1, 70).

* ``sinusoid``: y = a sin(w t), a in [-10, 10], w in [0.1, 5], 41 readings (tests/identification/fit/
  test_multistart.py): a local minimum near every aliasing frequency; p0 (1, 0.5) misses the global one.

Each fit is repeated ``--rep`` times after one warm-up fit (the model's caches built); the median wall time of
one fit (starts=1), of ``starts=10`` serially and of ``starts=10`` on ``--workers`` local processes is printed
with their ratio, the starts that reached the best minimum, the failed ones and the distinct minima.

Sobol against Latin hypercube (issue 30 item 2, ``compare``): for each seed 0..``--seeds``-1 the 9 drawn starts
of ``starts=10`` as the library draws them (scrambled Sobol, :func:`identification.fit.multistart.draw_starts`)
and as it drew them before (a scrambled Latin hypercube, ``scipy.stats.qmc.LatinHypercube`` from the same seed,
mapped by the same rules), each fitted once on one Problem as the multi-start does, serially: the CPU of the 9
fits, how many reach the global minimum (the lowest objective of all fits of the case, within
OBJECTIVE_RTOL max(1, |Phi|)), how many fail, and in how many seeds the 10 starts (p0 included) find it.

The sinusoid is cheap: ``--sinusoid-seeds`` (200) seeds, with a Clopper-Pearson 95 % interval for the share of
seeds whose 10 starts find the global minimum and the standard error over seeds of the per-start rate.

Run: ``python -m bench multistart [--rep=3] [--workers=2] [--seeds=5] [--sinusoid-seeds=200]
[--only=press,batch,sinusoid]``; prints one JSON document.
"""
from __future__ import annotations

import json
import os
import platform
import statistics
import time

import numpy as np


def _arg(argv, name, default):
    for a in argv or ():
        if a.startswith(f"--{name}="):
            return int(a.split("=", 1)[1])
    return default


def _press():
    from mudoe.press import campaign_measurements
    from models.press import K_NOMINAL, press_model
    from models.prototype import TRAIN_SERIES, read_campaign
    model = press_model()
    data = campaign_measurements(read_campaign(), series=tuple(TRAIN_SERIES))
    return model, data, np.array(K_NOMINAL, float), dict(weights=[1.0 if s in ("D_y", "F_x") else 0.0
                                                                  for s in model.sensors])


def _reactor():
    from identification.fit.dynamic_fit import simulate_campaign
    from mudoe.example_reactor import P_TRUE, TIMES, build
    Q = np.array([[1.0, 330.0], [1.0, 340.0], [1.0, 350.0], [2.0, 350.0], [2.0, 360.0], [2.0, 370.0]])
    return build(), simulate_campaign(build(), P_TRUE, Q, TIMES, np.array([0.01, 0.008]), seed=0), \
        np.array([1.5, 50.0, 1.0, 70.0]), {}


def _sinusoid():
    import casadi as ca
    from identification import Measurements
    from models import Model, Parameter
    t = np.linspace(0.0, 10.0, 41)
    model = Model.explicit(params=[Parameter("a", -10.0, 10.0), Parameter("w", 0.1, 5.0)], inputs=["t"],
                           sensors=["y"], h=lambda p, q: p[0] * ca.sin(p[1] * q[0]), name="sinusoid")
    z = (2.0 * np.sin(1.7 * t))[None, :, None] + 0.1 * np.random.default_rng(1).standard_normal((1, t.size, 1))
    return model, Measurements(t, z, [0.1]), np.array([1.0, 0.5]), {}


def _lhs_starts(model, p0, n, seed):
    """The n - 1 drawn starts as the library drew them before Sobol: a scrambled Latin hypercube from ``seed``."""
    from scipy.stats import qmc
    from identification.fit.multistart import starts_from_unit
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    try:
        engine = qmc.LatinHypercube(model.n_p, rng=rng)
    except TypeError:                       # scipy < 1.15
        engine = qmc.LatinHypercube(model.n_p, seed=rng)
    return starts_from_unit(model, p0, engine.random(n - 1))


def _fit_each(problem, X, kw):
    """(CPU s, wall s, [objective of each start, NaN when it failed or ran off]) of fitting every row of X once."""
    phi = []
    t0, w0 = time.process_time(), time.perf_counter()
    for x in X:
        try:
            rec = problem.fit(x, **kw)
        except (RuntimeError, ArithmeticError, np.linalg.LinAlgError):
            phi.append(float("nan"))
            continue
        s2 = float(rec.sigma[0]) ** 2 if rec.sigma_estimated else 1.0
        phi.append(float(rec.objective) * s2 if rec.unbounded is None else float("nan"))
    return time.process_time() - t0, time.perf_counter() - w0, phi


def compare(name, build, seeds, n=10):
    """Sobol against Latin-hypercube starts (see the module docstring)."""
    from identification.fit.multistart import OBJECTIVE_RTOL, draw_starts
    from identification.fit.problem import Problem
    model, data, p0, kw = build()
    problem = Problem(model, data)
    _, _, (phi0,) = _fit_each(problem, [p0], kw)                           # warm-up and start 1 (p0)
    runs = {"sobol": [], "lhs": []}
    for seed in range(seeds):
        sets = {"sobol": draw_starts(model, p0, n, seed)[0][1:], "lhs": _lhs_starts(model, p0, n, seed)}
        for method, X in sets.items():
            runs[method].append(_fit_each(problem, X, kw))
    best = np.nanmin([phi0] + [v for m in runs.values() for _, _, phi in m for v in phi])
    tol = OBJECTIVE_RTOL * max(1.0, abs(best))
    row = {"case": name, "n": n, "seeds": seeds, "global_minimum": float(best), "p0_reaches": bool(phi0 - best <= tol)}
    for method, rs in runs.items():
        hit = np.array([int(np.sum(np.asarray(phi) - best <= tol)) for _, _, phi in rs])
        found = int(np.sum((hit > 0) | (phi0 - best <= tol)))
        rate = hit / (n - 1)
        row[method] = {"cpu_s_9_fits_median": round(statistics.median(c for c, _, _ in rs), 4),
                       "cpu_s_all": round(sum(c for c, _, _ in rs), 3),
                       "wall_s_all": round(sum(w for _, w, _ in rs), 3),
                       "drawn_reaching_global": f"{int(hit.sum())} of {hit.size * (n - 1)}",
                       "rate_per_start": round(float(rate.mean()), 4),
                       "rate_se_over_seeds": round(float(rate.std(ddof=1) / np.sqrt(seeds)), 4) if seeds > 1 else None,
                       "per_seed_sd": round(float(hit.std(ddof=1)), 3) if seeds > 1 else None,
                       "per_seed": hit.tolist() if seeds <= 20 else None,
                       "failed_or_run_off": int(sum(np.sum(np.isnan(phi)) for _, _, phi in rs)),
                       "seeds_finding_global": found, "seeds_finding_global_cp95": _clopper_pearson(found, seeds)}
    return row


def _clopper_pearson(k, n, level=0.95):
    from scipy.stats import beta
    a = (1 - level) / 2
    lo = 0.0 if k == 0 else float(beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1 - a, k + 1, n - k))
    return [round(lo, 4), round(hi, 4)]


def _median_time(fn, rep):
    times, out = [], None
    for _ in range(rep):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def case(name, build, rep, workers):
    from identification import identify
    model, data, p0, kw = build()
    identify(model, data, p0, **kw)                                     # warm-up: the model's caches
    t1, one = _median_time(lambda: identify(model, data, p0, **kw), rep)
    t10, ten = _median_time(lambda: identify(model, data, p0, starts=10, **kw), rep)
    tw, par = _median_time(lambda: identify(model, data, p0, starts=10, workers=workers, **kw), rep)
    ms = ten.diagnostics.starts
    return {"case": name, "one_fit_s": round(t1, 4), "starts10_serial_s": round(t10, 4),
            "ratio_serial": round(t10 / t1, 2), f"starts10_workers{workers}_s": round(tw, 4),
            "ratio_workers": round(tw / t1, 2), "reached_best": ms.reached_best, "failed": len(ms.failed),
            "distinct_minima": len(ms.minima), "best_start": ms.best + 1,
            "same_estimate_as_one_fit": bool(np.array_equal(one.p, ten.p)),
            "workers_same_estimate": bool(np.array_equal(ten.p, par.p)), "backend": par.diagnostics.starts.backend,
            "rules": list(ms.rules)}


def main(argv=None) -> None:
    rep, workers, seeds = _arg(argv, "rep", 3), _arg(argv, "workers", 2), _arg(argv, "seeds", 5)
    sin_seeds = _arg(argv, "sinusoid-seeds", 200)
    only = [a.split("=", 1)[1] for a in argv or () if a.startswith("--only=")]
    cases = [("press M1 (shipped campaign, training series)", _press),
             ("batch reactor 6 x 10 (mudoe.example_reactor)", _reactor),
             ("sinusoid a sin(w t), 41 readings", _sinusoid)]
    if only:
        cases = [c for c in cases if c[0].split()[0] in only[0].split(",")]
    rows = [case(name, build, rep, workers) for name, build in cases]
    comp = [compare(name, build, sin_seeds if build is _sinusoid else seeds) for name, build in cases]
    print(json.dumps({"machine": f"{platform.machine()} {platform.processor() or ''}".strip(),
                      "nproc": os.cpu_count(), "rep": rep, "load": os.getloadavg(), "rows": rows, "compare": comp},
                     indent=1))


if __name__ == "__main__":
    main()
