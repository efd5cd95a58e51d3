"""Benchmark (issue 22): reference fits of the two dynamic example models by scipy, no mudoe code.

bench.dynamic_reference's batch reactor (A -> B -> C, Arrhenius, inputs cA0 and T, sensors
cA and cB) and cubic spring-damper (input the step force F, sensors x and acceleration), seeded
data (``simulate_data``), fitted by scipy ``least_squares`` (trf, x_scale="jac", tolerances
1e-10) over ``solve_ivp`` (DOP853); standard errors by Gauss-Newton from the exact-sensitivity
Jacobian.

* Accuracy references (rtol 1e-10, exact-sensitivity Jacobian): the reactor with 6 experiments
  x 10 samples and the spring-damper with 6 x 50, seed 0; the estimate, standard errors, the
  truth's distance in standard errors, chi2 / n; the finite-difference-Jacobian fit beside it.
* Speed peer (rtol 1e-8): the reactor with 20 experiments x 30 samples, seed 0, fitted
  ``--rep`` times (default 3) with scipy's 2-point Jacobian (a typical user), the exact
  sensitivity Jacobian (one solve_ivp per experiment) and the same with all experiments stacked
  into one solve_ivp; each against the rtol 1e-10 reference, in standard errors. Wall and CPU
  seconds of the fit (the covariance at rtol 1e-10 timed apart).

Run: ``python -m bench dynamic_reference [--rep=3]``; prints one JSON document.
"""
from __future__ import annotations

import json
import os
import platform
import statistics
import sys
import time

import numpy as np

from bench import dynamic_reference as dr


def _fit_summary(fit, truth):
    return {"p": fit.p.tolist(), "se": fit.se.tolist(), "truth_minus_p_in_se": ((truth - fit.p) / fit.se).tolist(),
            "chi2_over_n": fit.chi2 / fit.n_data, "n_data": fit.n_data, "nfev": fit.nfev, "njev": fit.njev,
            "fit_s": fit.fit_seconds, "cov_s": fit.cov_seconds, "fit_cpu_s": fit.fit_cpu_seconds,
            "cov_cpu_s": fit.cov_cpu_seconds, "message": fit.message}


def accuracy(ex, n_exp, n_times, seed=0):
    """The rtol 1e-10 reference fit (exact and 2-point Jacobians) of one example's seeded data."""
    data = dr.simulate_data(ex, n_exp, n_times, seed=seed)
    ref = dr.reference_fit(ex, data, rtol=1e-10, jac="sens")
    fd = dr.reference_fit(ex, data, rtol=1e-10, jac="2-point")
    return {"model": ex.name, "params": ex.params, "p_true": list(ex.p_true), "p_start": list(ex.p_start),
            "n_exp": n_exp, "n_times": n_times, "seed": seed, "sigma": list(ex.sigma),
            "inputs": ex.inputs, "input_bounds": ex.input_bounds, "t_end": ex.t_end,
            "sens": _fit_summary(ref, data.p_true), "2-point": _fit_summary(fd, data.p_true),
            "2-point_minus_sens_in_se": ((fd.p - ref.p) / ref.se).tolist()}


def speed(rep=3, n_exp=20, n_times=30, seed=0, rtol=1e-8):
    """The reactor fit at ``rtol`` by three scipy variants, ``rep`` times each, against the rtol 1e-10 fit."""
    ex = dr.batch_reactor()
    data = dr.simulate_data(ex, n_exp, n_times, seed=seed)
    ref = dr.reference_fit(ex, data, rtol=1e-10, jac="sens")
    out = {"n_exp": n_exp, "n_times": n_times, "seed": seed, "rtol": rtol, "reference_1e-10": _fit_summary(ref, data.p_true)}
    variants = {"2-point": {"jac": "2-point"}, "sens": {"jac": "sens"}, "sens_stacked": {"jac": "sens", "stacked": True}}
    for name, kw in variants.items():
        fits = [dr.reference_fit(ex, data, rtol=rtol, **kw) for _ in range(rep)]
        t, cpu = [f.fit_seconds for f in fits], [f.fit_cpu_seconds for f in fits]
        out[name] = {"fit_s": {"median": statistics.median(t), "min": min(t), "max": max(t), "all": t},
                     "fit_cpu_s": {"median": statistics.median(cpu), "min": min(cpu), "max": max(cpu)},
                     "cov_s": statistics.median(f.cov_seconds for f in fits), "nfev": fits[0].nfev,
                     "njev": fits[0].njev,
                     "max_abs_dev_from_reference_in_se": float(np.max(np.abs((fits[0].p - ref.p) / ref.se)))}
    return out


def _machine():
    return {"date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()), "platform": platform.platform(),
            "nproc": os.cpu_count(), "loadavg": os.getloadavg()}


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    opts = dict(a[2:].split("=", 1) for a in argv if a.startswith("--") and "=" in a)
    rep = int(opts.get("rep", 3))
    out = {"machine_before": _machine(),
           "accuracy": [accuracy(dr.batch_reactor(), 6, 10), accuracy(dr.spring_damper(), 6, 50)],
           "speed_reactor_20x30": speed(rep)}
    out["machine_after"] = _machine()
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
