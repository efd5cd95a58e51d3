"""Benchmark (issue 30, item 9): a stiff model fitted with the discretisation error controlled, against scipy.

Robertson's kinetics (``mudoe.example_robertson``, rates k = (0.04, 1e4, 3e7) 1/s, y(0) = (1, 0, 0), horizon
1e5 s), one batch run sampled at 12 log-spaced times 0.4 ... 4e4 s, sensors y1, y2, y3 with sigma (1e-3,
1e-7, 1e-3).  The data: scipy's Radau (rtol 1e-10, atol 1e-20, exact Jacobian) at the truth plus Gaussian
noise (seed 3), independent of the collocation.

* mudoe: ``identify`` from the truth (first fit on a fresh model: building included), from all rates x3 and
  all rates /3 (wall and CPU seconds, iterations, meshes fitted), and the discretisation error it states
  against the true error of its outputs (Radau rtol 1e-10 at the estimate), in sigmas;
* scipy: ``least_squares`` (trf, 2-point Jacobian) on ln k over ``solve_ivp`` with the exact Jacobian of the
  right-hand side (rtol 1e-8, atol 1e-14: y2 to 1e-6 of its sigma) by BDF, Radau and LSODA, from the same
  starts; the estimates against mudoe's in its standard errors, and the ratio of the fastest scipy method's
  CPU (and wall) time to mudoe's, also of the fastest that reaches mudoe's minimum within 0.1 standard errors
  (LSODA at rtol 1e-8 may stop short of it).

Run: ``python -m bench stiff [--rep=3]`` (times: the median of ``--rep`` repeats after the first fit; the first
fit of the truth on a fresh model separately); prints one JSON document.
"""
from __future__ import annotations

import json
import os
import platform
import statistics
import sys
import time

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

from mudoe.example_robertson import HORIZON, P_TRUE, SIGMA, TIMES, build, jacobian_numpy, rhs_numpy

STARTS = {"truth": 1.0, "rates x3": 3.0, "rates /3": 1.0 / 3.0}
METHODS = ("BDF", "Radau", "LSODA")


def reference(k, rtol=1e-10, atol=1e-20, method="Radau") -> np.ndarray:
    """Robertson's y (n_t, 3) at the sampling times by scipy's solve_ivp with the exact Jacobian."""
    r = solve_ivp(rhs_numpy, (0.0, float(TIMES[-1])), [1.0, 0.0, 0.0], method=method, t_eval=TIMES, rtol=rtol,
                  atol=atol, jac=jacobian_numpy, args=(np.asarray(k, float),))
    if not r.success:
        raise RuntimeError(f"solve_ivp ({method}) failed at k = {k}: {r.message}")
    return r.y.T


def campaign(seed: int = 3):
    """The data: Radau at the truth plus noise, as DynamicMeasurements."""
    from identification import DynamicMeasurements
    z = reference(P_TRUE) + SIGMA * np.random.default_rng(seed).standard_normal((TIMES.size, 3))
    return DynamicMeasurements(np.zeros((1, 0)), TIMES, z[None, None], SIGMA, sensors=("y1", "y2", "y3"))


def _clock():
    return time.perf_counter(), time.process_time()


def _since(c):
    return time.perf_counter() - c[0], time.process_time() - c[1]


def mudoe_fit(model, data, p0):
    """(estimate, wall s, CPU s) of one identify."""
    from identification import identify
    c = _clock()
    est = identify(model, data, p0=p0)
    wall, cpu = _since(c)
    return est, wall, cpu


def scipy_fit(data, k0, method):
    """least_squares on ln k over solve_ivp: (k, nfev, wall s, CPU s)."""
    z = np.asarray(data.z)[0, 0]

    def residuals(lnk):
        try:
            y = reference(np.exp(lnk), rtol=1e-8, atol=1e-14, method=method)
        except RuntimeError:
            return np.full(z.size, 1e6)
        return ((y - z) / SIGMA).ravel()

    c = _clock()
    r = least_squares(residuals, np.log(k0), method="trf", x_scale=1.0)
    wall, cpu = _since(c)
    return np.exp(r.x), int(r.nfev), wall, cpu


def main(argv=None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    rep = next((int(a.split("=", 1)[1]) for a in argv if a.startswith("--rep=")), 3)
    data = campaign()
    out = {"machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "load": os.getloadavg()},
           "problem": {"rates": P_TRUE.tolist(), "times": TIMES.tolist(), "horizon": HORIZON,
                       "sigma": SIGMA.tolist()}, "mudoe": {}, "scipy": {}, "ratio": {}}
    est, wall, cpu = mudoe_fit(build(), data, P_TRUE)
    out["mudoe"]["first fit (fresh model, truth)"] = {"wall_s": wall, "cpu_s": cpu}
    model = build()
    mudoe_fit(model, data, P_TRUE)                  # warm: the collocated models of this model are compiled
    fits = {}
    for name, f in STARTS.items():
        runs = [mudoe_fit(model, data, P_TRUE * f) for _ in range(rep)]
        est = runs[0][0]
        rec = est.diagnostics.discretisation
        true = np.max(np.abs(est.fitted.reshape(TIMES.size, 3) - reference(est.p)) / SIGMA)
        fits[name] = est
        out["mudoe"][name] = {
            "wall_s": statistics.median(r[1] for r in runs), "cpu_s": statistics.median(r[2] for r in runs),
            "iterations": int(est.iterations), "solver": est.diagnostics.solver, "meshes": len(rec.history),
            "elements": rec.n_elements, "error_sigma_stated": rec.error_sigma, "error_sigma_true": float(true),
            "shift_se": float(np.max(np.abs(rec.shift_se))), "bounded": rec.bounded,
            "z_truth": ((est.p - P_TRUE) / est.stderr).tolist()}
    ref = fits["truth"]
    for name, f in STARTS.items():
        out["scipy"][name] = {}
        for method in METHODS:
            k, nfev, wall, cpu = scipy_fit(data, P_TRUE * f, method)
            out["scipy"][name][method] = {"wall_s": wall, "cpu_s": cpu, "nfev": nfev,
                                          "vs_mudoe_se": float(np.max(np.abs(k - ref.p) / ref.stderr))}
        sc, mu = out["scipy"][name], out["mudoe"][name]
        fastest = min(METHODS, key=lambda m: sc[m]["cpu_s"])
        at_min = [m for m in METHODS if sc[m]["vs_mudoe_se"] <= 0.1] or list(METHODS)
        best = min(at_min, key=lambda m: sc[m]["cpu_s"])
        out["ratio"][name] = {"fastest_scipy": fastest,
                              "scipy_over_mudoe_cpu": sc[fastest]["cpu_s"] / mu["cpu_s"],
                              "scipy_over_mudoe_wall": sc[fastest]["wall_s"] / mu["wall_s"],
                              "fastest_scipy_at_the_minimum (within 0.1 se)": best,
                              "at_the_minimum_scipy_over_mudoe_cpu": sc[best]["cpu_s"] / mu["cpu_s"]}
    out["machine"]["load_after"] = os.getloadavg()
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
