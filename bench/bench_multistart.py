"""Benchmark (issue 30 item 2): the cost of a multi-start fit, ``identify(..., starts=10)``, against one fit.

* ``press``: the press M1 (frictionless, parameters k5, k7 in [1e-6, 1e6] N/mm: log-uniform starts over 12
  decades) on the shipped campaign's training series (``models.prototype.TRAIN_SERIES``), sensors D_y and F_x,
  start K_NOMINAL, as :func:`mudoe.press.fit_candidates` fits it.
* ``reactor``: the batch reactor of :mod:`mudoe.example_reactor` (k_ref in [1e-6, 100] log-uniform, E in
  [0, 300] uniform), 6 experiments x 10 samples simulated with seed 0, start (1.5, 50, 1, 70).

Each fit is repeated ``--rep`` times after one warm-up fit (the model's caches built); the median wall time of
one fit (starts=1), of ``starts=10`` serially and of ``starts=10`` on ``--workers`` local processes is printed
with their ratio, the starts that reached the best minimum, the failed ones and the distinct minima.

Run: ``python -m bench multistart [--rep=3] [--workers=2]``; prints one JSON document.
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
    rep, workers = _arg(argv, "rep", 3), _arg(argv, "workers", 2)
    rows = [case("press M1 (shipped campaign, training series)", _press, rep, workers),
            case("batch reactor 6 x 10 (mudoe.example_reactor)", _reactor, rep, workers)]
    print(json.dumps({"machine": f"{platform.machine()} {platform.processor() or ''}".strip(),
                      "nproc": os.cpu_count(), "rep": rep, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
